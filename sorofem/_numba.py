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


def _tolerant(save):
    """``save`` that gives up quietly on a cache folder this process may read but not write."""
    @functools.wraps(save)
    def tolerant(self, *args, **kwargs):
        try:
            return save(self, *args, **kwargs)
        except PermissionError:
            return None          # another user's (read-only) cache: the kernel stays compiled in this process only
    tolerant.soro_locked = True
    return tolerant


class _ReadOnlyInTreeCacheLocator(caching._InTreeCacheLocator):
    """The ``__pycache__`` beside the source when this process may read it but not write it (another user than
    the one who installed and precompiled the platform, e.g. a service account): its kernels are loaded, what it
    lacks is compiled in memory only. numba's own locators skip such a folder, and with no writable home either
    every decorated function raised "no locator available" at import."""

    def ensure_cache_path(self):
        path = self.get_cache_path()
        if not os.access(path, os.R_OK | os.X_OK):
            raise OSError(f"{path} is not readable")


class _NoCacheLocator(caching._InTreeCacheLocator):
    """Last resort: nothing readable or writable anywhere; compiled kernels live in memory only."""

    def ensure_cache_path(self):
        return None


def install():
    """Make numba's cache files safe for concurrent processes and usable by every user (idempotent; done when
    this module is imported).

    ``save`` (read the index, add the signature, write the index and the data file) runs under an exclusive
    ``flock`` of a lock file beside the index, and ``load`` (read the index, then the data file it names) under a
    shared one, so a process never reads an index and a data file that two different writers left behind. The
    lock is advisory and per index file: compiles of different functions never wait for each other.

    A process that may not write the source tree's ``__pycache__`` (another user) still loads the kernels
    compiled there (``scripts/bootstrap.sh`` precompiles the common ones) before trying its own user-wide cache,
    and a save it may not make is skipped instead of failing the compile.
    """
    cls = caching.IndexDataCacheFile
    if not getattr(cls.save, "soro_locked", False):
        cls.save = _tolerant(_under_lock(cls.save, fcntl.LOCK_EX))
        cls.load = _under_lock(cls.load, fcntl.LOCK_SH)
    locators = getattr(getattr(caching, "CacheImpl", None), "_locator_classes", None)
    if locators is not None and caching._InTreeCacheLocator in locators \
            and _ReadOnlyInTreeCacheLocator not in locators:
        locators.insert(locators.index(caching._InTreeCacheLocator) + 1, _ReadOnlyInTreeCacheLocator)
        locators.append(_NoCacheLocator)


install()
njit = numba.njit
