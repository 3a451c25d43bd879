"""The output directory of a sweep shared by its runs and ranks: the lock that keeps a second sweep out, and the
removal of what a killed run left (claims, temporary files). The status files and the manifest are written by
the runner (:mod:`soro.sweep.runner`)."""
import json
import logging
import os
import socket
import time

from sorofem.errors import ParameterError
from sorofem.io import process_alive

__all__ = ["take_lock", "clean", "LOCK"]

log = logging.getLogger(__name__)

#: The lock file of a running sweep (process id and host).
LOCK = ".sweep.lock"
#: The manifest's name (its temporary files ``.manifest.json.*`` are removed by :func:`clean`).
MANIFEST = "manifest.json"


def take_lock(out):
    """Take ``out/.sweep.lock`` (exclusive creation); a lock whose process is gone (same host) is stale
    and taken over. Another live sweep in the same directory is refused."""
    path = out / LOCK
    me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    for _ in range(3):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                other = json.loads(path.read_text())
                pid, host = int(other["pid"]), str(other["host"])
            except (OSError, ValueError, KeyError, TypeError):
                pid = host = None
            if pid is not None and host == me["host"] and pid != os.getpid() and not process_alive(pid):
                log.warning("removing the lock of a sweep that is gone (process %d): %s", pid, path)
                path.unlink(missing_ok=True)
                continue
            owner = f"process {pid} on {host}" if pid is not None else "an unknown process"
            raise ParameterError(
                f"another sweep is running in {out} ({owner}, lock {path}): wait for it to finish or use "
                f"another output directory (--out); if no sweep runs there any more, remove {path}")
        os.write(fd, json.dumps(me).encode())
        os.close(fd)
        return path
    raise ParameterError(f"could not take the lock {path}: remove it if no sweep runs in {out}")


def clean(out):
    """Remove what a killed run may have left: claims and temporary files (never a finished file)."""
    for f in out.iterdir():
        n = f.name
        if f.is_file() and (n.startswith(".case_") or n.startswith(f".{MANIFEST}.")):
            f.unlink(missing_ok=True)
