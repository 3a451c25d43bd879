"""Small file helpers shared by every layer: atomic writes, file digests and JSON reports.

A result file is either complete or absent: writers go to a temporary file in the destination directory
and ``os.replace`` it into place, which is atomic on POSIX file systems. The temporary file is flushed to
disk (``fsync``) before the rename and the directory after it, so a power loss leaves the old file or the
new one, never an empty or half-written one under the final name. An exception inside the ``with`` block
removes the temporary file and leaves any previous version of the destination untouched; a full disk is
reported as :class:`~sorofem.errors.DataError` naming the path and the free space.
"""
import contextlib
import errno
import hashlib
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

from .errors import DataError

__all__ = ["atomic_path", "write_json", "save_figure", "on_root", "file_digest", "fsync_path", "is_disk_full",
           "disk_full_error", "process_alive", "Progress"]

_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def is_disk_full(exc):
    """Whether ``exc`` (or an exception it was raised from) says the disk or quota is full.

    HDF5 reports a failed write as an ``OSError`` without ``errno`` whose message carries ``errno = 28``, so
    the message is read too.
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in _FULL:
            return True
        text = str(exc)
        if "No space left on device" in text or "errno = 28" in text or "Disk quota exceeded" in text:
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def disk_full_error(path, exc=None):
    """The :class:`DataError` for a write to ``path`` that failed on a full disk: names the path, the file
    system's free space and what to do."""
    path = Path(path)
    where = path.parent if path.parent.exists() else Path(".")
    try:
        usage = shutil.disk_usage(where)
        free = f"{usage.free / 2**20:.1f} MiB free of {usage.total / 2**20:.1f} MiB on {where.resolve()}"
    except OSError:
        free = f"the free space on {where} is unknown"
    detail = f" ({type(exc).__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''})" if exc else ""
    return DataError(f"no space left writing {path}: {free}{detail}. Free some space (or write to another "
                     "disk) and run again; nothing was left under that name")


def process_alive(pid):
    """Whether process ``pid`` runs on this host (a zombie, dead but not yet reaped, does not run); used to tell
    the lock file of a live process from one a killed process left."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):
        return False
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] != "Z"
    except (OSError, IndexError):
        return True  # no /proc (not Linux): the signal test is all we have


def fsync_path(path):
    """Flush a file or a directory to disk (``os.fsync``); directories are skipped where they cannot be
    opened (not POSIX)."""
    flags = os.O_RDONLY | (os.O_DIRECTORY if Path(path).is_dir() and hasattr(os, "O_DIRECTORY") else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        if Path(path).is_dir():
            return
        raise
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def file_digest(path, algorithm="sha256", chunk=1 << 20):
    """Hex digest of a file's bytes (``sha256`` by default), read in 1 MiB chunks."""
    h = hashlib.new(algorithm)
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


@contextlib.contextmanager
def atomic_path(path, suffix=None):
    """Yield a temporary path next to ``path``; on success rename it onto ``path``.

    Parameters
    ----------
    path : str or Path
        Final destination. Its parent directory is created if needed.
    suffix : str, optional
        Suffix of the temporary file (some writers choose the format from it); defaults to ``path``'s.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> with atomic_path(os.path.join(d, "a.npz")) as tmp:
    ...     np.savez(tmp, x=np.arange(3))
    >>> sorted(os.listdir(d))
    ['a.npz']
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix if suffix is not None else path.suffix,
                               dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; results are ordinary files
    try:
        yield Path(tmp)
        fsync_path(tmp)                 # the data is on disk before the name points at it
        os.replace(tmp, path)
        fsync_path(path.parent)         # and the rename itself survives a power loss
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(e, Exception) and not isinstance(e, DataError) and is_disk_full(e):
            raise disk_full_error(path, e) from e
        raise


def _finite(obj, where="summary"):
    """Raise ``ValueError`` if ``obj`` (nested dicts/lists of numbers) holds a NaN or infinity."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            _finite(v, f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _finite(v, f"{where}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"{where} is {obj}: refusing to write a non-finite number into a report")


def write_json(path, data):
    """Write ``data`` as indented JSON, atomically; numpy scalars and arrays are converted to Python.

    Non-finite floats are refused (``ValueError`` naming the key) rather than written as ``NaN``.
    """
    def default(o):
        if hasattr(o, "tolist"):
            return o.tolist()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"cannot write {type(o).__name__} to JSON")

    text = json.dumps(data, indent=2, default=default, allow_nan=True)
    _finite(json.loads(text))
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n")
    return Path(path)


def save_figure(fig, path, dpi=110):
    """Lay out a matplotlib figure, write it as PNG to ``path`` atomically and close it (if pyplot manages
    it; a ``matplotlib.figure.Figure`` made directly needs no closing); returns the path. The process's
    matplotlib backend is left as it is."""
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    if getattr(fig.canvas, "manager", None) is not None:
        import matplotlib.pyplot as plt
        plt.close(fig)
    return path


def on_root(comm, fn):
    """Run ``fn()`` on rank 0 of ``comm`` and raise its exception, if any, on every rank.

    Returns ``fn()``'s result on rank 0 and ``None`` elsewhere. Use it for work that only rank 0 does
    (meshing, writing a gathered file) so that a failure stops every rank with the same error instead of
    leaving the others waiting in a collective call.
    """
    out = err = None
    if comm.rank == 0:
        try:
            out = fn()
        except Exception as e:  # noqa: BLE001 - re-raised on every rank below
            err = e
    err = comm.bcast(err, root=0)
    if err is not None:
        raise err
    return out


class Progress:
    """Progress of long work (a load march, a time integration) on rank 0 of ``comm``.

    ``enabled=None`` (the solvers' default): a ``tqdm`` bar when standard error is a terminal and tqdm is
    installed (the ``extras``), nothing otherwise (batch jobs, tests and notebooks' captured streams stay
    quiet). ``True``: a bar on a terminal, else one line per update on standard error. ``False``: nothing.
    Use as a context manager; :meth:`to` moves to an absolute position in [0, ``total``].
    """

    def __init__(self, total, description, enabled=None, comm=None, unit=""):
        import sys

        self.total, self.description, self.unit = float(total), description, unit
        self._bar = self._lines = None
        if enabled is False or (comm is not None and comm.rank != 0):
            return
        tty = bool(getattr(sys.stderr, "isatty", lambda: False)())
        if tty:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self._bar = tqdm(total=self.total, desc=description, unit=unit, leave=False,
                                 bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.4g}/{total:.4g} {unit} "
                                            "[{elapsed}<{remaining}{postfix}]")
                return
        if enabled or (enabled is None and tty):
            self._lines = sys.stderr

    def to(self, value, **info):
        """Move to ``value`` (same unit as ``total``); ``info`` is shown beside the bar (or on the line)."""
        if self._bar is not None:
            self._bar.set_postfix(info, refresh=False)
            self._bar.update(float(value) - self._bar.n)
        elif self._lines is not None:
            extra = "  ".join(f"{k} {v}" for k, v in info.items())
            print(f"  {self.description}: {float(value):.4g}/{self.total:.4g} {self.unit}  {extra}".rstrip(),
                  file=self._lines, flush=True)

    def close(self):
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

