"""Small file helpers shared by every layer: atomic writes and JSON reports.

A result file is either complete or absent: writers go to a temporary file in the destination directory
and ``os.replace`` it into place, which is atomic on POSIX file systems. An exception inside the ``with``
block removes the temporary file and leaves any previous version of the destination untouched.
"""
import contextlib
import json
import math
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "write_json", "save_figure", "on_root"]


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
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
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
    """Lay out a matplotlib figure, write it as PNG to ``path`` atomically and close it; returns the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
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
