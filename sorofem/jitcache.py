"""The FFCx JIT cache: find and remove the locks that a killed form compilation leaves behind.

DOLFINx compiles each form into a C module in its cache directory (``~/.cache/fenics`` unless
``XDG_CACHE_HOME`` or the DOLFINx JIT parameters say otherwise). FFCx uses the files of a module as its lock:
the process that creates ``<module>.c`` (exclusive creation) compiles it and then creates
``<module>.c.cached``; any other process that finds the ``.c`` file waits for ``.c.cached`` to appear, for
the JIT ``timeout`` (10 s by default), and then raises ``TimeoutError``. A compilation interrupted by Ctrl-C
or killed leaves the ``.c`` file without ``.c.cached`` for ever: every later run that needs the same form
times out until the file is deleted by hand.

This module makes those locks visible and removable:

* :func:`track` (called by the sweep runner, :meth:`soro.sweep.Sweep.run`) records the owner of each lock this process
  creates in ``<module>.c.owner`` (process id, host, time), and :func:`release_owned` removes this process's
  unfinished locks (on an interrupt);
* :func:`scan` lists the locks (``.c`` without ``.c.cached``) and says which are *stale*: their owner process
  no longer runs on this host, or, with no known owner (a compile not started through :func:`track`, or
  another host), nothing in the module changed for ``threshold`` seconds;
* :func:`remove_stale` deletes the stale ones (``soro sweep`` does at start; ``soro doctor`` reports them).

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = (d / "libffcx_forms_x.c").write_text("")                     # a compile that never finished
>>> _ = (d / "libffcx_forms_x.c.owner").write_text('{"pid": 999999999, "host": "%s"}' % _HOST)
>>> [(lock.module, lock.stale) for lock in scan(d)]
[('libffcx_forms_x', True)]
>>> [p.name for p in remove_stale(d)], sorted(p.name for p in d.iterdir())
(['libffcx_forms_x.c'], [])
"""
import contextlib
import dataclasses
import json
import logging
import os
import socket
import time
from pathlib import Path

__all__ = ["JitLock", "cache_dir", "scan", "remove_stale", "track", "release_owned", "is_jit_timeout",
           "STALE_AFTER_S"]

log = logging.getLogger(__name__)

#: Seconds without any change to a lock of unknown owner before it counts as stale (a large form compiles in
#: well under a minute; a live compile rewrites its .c, .o and .so files as it goes).
STALE_AFTER_S = 600.0
_HOST = socket.gethostname()
_OWNED = set()        # lock files (.c) this process created
_INSTALLED = False


def cache_dir():
    """The DOLFINx JIT cache directory (from DOLFINx's JIT parameters if DOLFINx imports, else its default)."""
    try:
        import dolfinx.jit
        return Path(str(dolfinx.jit.get_parameters()["cache_dir"])).expanduser()
    except Exception:  # noqa: BLE001 - no DOLFINx, or another layout: DOLFINx's documented default
        return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "fenics"


@dataclasses.dataclass(frozen=True)
class JitLock:
    """One unfinished module in the cache: ``path`` (the ``.c`` lock file), ``age_s`` (seconds since any of
    the module's files last changed), ``pid`` and ``host`` of the owner (None if unknown), ``stale`` and
    ``reason`` (why it is, or is not, stale)."""

    path: Path
    module: str
    age_s: float
    pid: int | None
    host: str | None
    stale: bool
    reason: str


def _alive(pid):
    from .io import process_alive

    return pid == os.getpid() or process_alive(pid)


def _owner(c_file):
    try:
        data = json.loads(c_file.with_suffix(".c.owner").read_text())
        return int(data["pid"]), str(data["host"])
    except (OSError, ValueError, KeyError, TypeError):
        return None, None


def scan(directory=None, threshold=STALE_AFTER_S, now=None):
    """The unfinished modules (locks) in the JIT cache ``directory`` (default :func:`cache_dir`).

    Parameters
    ----------
    threshold : float
        Seconds without change after which a lock of unknown owner is stale [s].
    now : float, optional
        The current time (``time.time()``), for tests.

    Returns
    -------
    list of :class:`JitLock`, sorted by file name.
    """
    directory = Path(directory) if directory is not None else cache_dir()
    if not directory.is_dir():
        return []
    now = time.time() if now is None else now
    locks = []
    for c_file in sorted(directory.glob("*.c")):
        module = c_file.name[:-2]
        if c_file.with_suffix(".c.cached").exists():
            continue
        stamps = []
        for f in (c_file, directory / f"{module}.o", c_file.with_suffix(".c.owner"),
                  *directory.glob(f"{module}.*.so")):
            with contextlib.suppress(OSError):
                stamps.append(f.stat().st_mtime)
        if not stamps:
            continue  # finished or removed meanwhile
        age = max(0.0, now - max(stamps))
        pid, host = _owner(c_file)
        if c_file in _OWNED:
            stale, reason = False, "compiling in this process"
        elif pid is not None and host == _HOST and pid != os.getpid():
            alive = _alive(pid)
            stale, reason = (not alive, f"owner process {pid} is {'running' if alive else 'gone'}")
        elif pid is not None and host == _HOST:
            stale, reason = True, f"owner process {pid} is this process, which did not create it (an old run)"
        else:
            who = f"owner {pid} on {host}" if pid is not None else "owner unknown"
            stale = age > threshold
            reason = f"{who}; unchanged for {age:.0f} s (stale after {threshold:.0f} s)"
        locks.append(JitLock(c_file, module, age, pid, host, stale, reason))
    return locks


def _remove(c_file):
    for f in (c_file, c_file.with_suffix(".c.owner")):
        with contextlib.suppress(FileNotFoundError):
            f.unlink()


def remove_stale(directory=None, threshold=STALE_AFTER_S, now=None):
    """Delete the stale locks of :func:`scan` (the ``.c`` file and its owner record); return their paths.

    The next compile of each module starts afresh (FFCx recreates the ``.c`` file and compiles it)."""
    removed = []
    directory = Path(directory) if directory is not None else cache_dir()
    for owner in directory.glob("*.c.owner") if directory.is_dir() else ():
        if owner.with_name(owner.name[:-len(".owner")] + ".cached").exists():
            with contextlib.suppress(FileNotFoundError):
                owner.unlink()  # the compile finished: its owner record is no longer needed
    for lock in scan(directory, threshold, now):
        if lock.stale:
            _remove(lock.path)
            log.warning("removed a stale JIT lock %s (%s)", lock.path, lock.reason)
            removed.append(lock.path)
    return removed


def track():
    """Record the owner of every JIT lock this process creates from now on (``<module>.c.owner``), so that a
    later run can tell a killed compile from a live one. Idempotent; without DOLFINx/FFCx it does nothing."""
    global _INSTALLED
    if _INSTALLED:
        return
    try:
        import ffcx.codegeneration.jit as ffcx_jit
    except ImportError:  # pragma: no cover - the FEM layer is not installed
        return
    original = ffcx_jit.get_cached_module

    def get_cached_module(module_name, object_names, cache_dir, timeout):
        result = original(module_name, object_names, cache_dir, timeout)
        if result[0] is None:  # this process created the lock and compiles now
            c_file = Path(cache_dir).joinpath(module_name).with_suffix(".c")
            _OWNED.add(c_file)
            with contextlib.suppress(OSError):
                c_file.with_suffix(".c.owner").write_text(json.dumps(
                    {"pid": os.getpid(), "host": _HOST, "time": time.time()}))
        return result

    get_cached_module.__wrapped__ = original
    ffcx_jit.get_cached_module = get_cached_module
    _INSTALLED = True


def release_owned():
    """Remove the locks this process created whose compile did not finish (after an interrupt); return them."""
    removed = []
    for c_file in sorted(_OWNED):
        if not c_file.with_suffix(".c.cached").exists() and c_file.exists():
            _remove(c_file)
            removed.append(c_file)
            log.warning("removed the JIT lock %s of an interrupted compile", c_file)
    _OWNED.clear()
    return removed


def is_jit_timeout(message):
    """Whether an error message is FFCx's JIT timeout (on the compiling rank or relayed to the others)."""
    return "JIT compilation timed out" in str(message)
