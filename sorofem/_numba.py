r"""numba's ``njit`` with an on-disk cache that several processes may fill at once.

Every kernel of the platform is compiled with ``cache=True``, and many processes compile the same kernels at the
same time: the test suite and the simulated board server it starts, a sweep's MPI ranks, a demo and its board.
numba (0.56 to 0.61) keeps one index file per function (``name-line.pyXY.nbi``: signature -> data file) and one
data file per signature (``name-line.pyXY.N.nbc``), and its ``IndexDataCacheFile.save`` is a read-modify-write of
the index without a lock: two processes that compile *different* signatures of one function at the same moment
both read the same index, both pick the free name ``.1.nbc``, and each writes its own index and data file. The
index that survives can then name the data file of the other signature, and every later process that loads that
entry runs machine code compiled for other argument types (wrong results, or a segmentation fault when array
ranks or layouts differ). See :func:`install` for the remedy.

Import ``njit`` from here instead of from numba::

    from sorofem._numba import njit

    @njit(cache=True)
    def kernel(x): ...
"""
import fcntl
import functools
import os

import numba
from numba.core import caching

__all__ = ["njit", "install"]


def _under_lock(method, mode):
    """``method`` of an ``IndexDataCacheFile`` run while holding ``flock(mode)`` on ``<index>.lock``."""
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        try:
            fd = os.open(self._index_path + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:      # no cache folder yet (nothing to load) or a read-only one (numba cannot save either)
            return method(self, *args, **kwargs)
        try:
            fcntl.flock(fd, mode)
            return method(self, *args, **kwargs)
        finally:
            os.close(fd)     # releases the lock
    locked.soro_locked = True
    return locked


def install():
    """Make numba's cache files safe for concurrent processes (idempotent; done when this module is imported).

    ``save`` (read the index, add the signature, write the index and the data file) runs under an exclusive
    ``flock`` of a lock file beside the index, and ``load`` (read the index, then the data file it names) under a
    shared one, so a process never reads an index and a data file that two different writers left behind. The
    lock is advisory and per index file: compiles of different functions never wait for each other.
    """
    cls = caching.IndexDataCacheFile
    if not getattr(cls.save, "soro_locked", False):
        cls.save = _under_lock(cls.save, fcntl.LOCK_EX)
        cls.load = _under_lock(cls.load, fcntl.LOCK_SH)


install()
njit = numba.njit
