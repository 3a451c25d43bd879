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

numba also judges a cached kernel fresh by its own source file only (its modification time and size): a kernel
that calls a kernel of another module keeps the old callee's machine code after that module changed (seen: edits
to ``soroshapes/network.py`` ran with the old code inlined in the cached ``soroshapes/integrate.py`` step). The
stamp of every kernel of the platform therefore also covers the sources of its package and of ``sorofem``
(:func:`source_digest`); after an edit or a ``git pull`` the kernels of that package compile again once.

Import ``njit`` from here instead of from numba::

    from sorofem._numba import njit

    @njit(cache=True)
    def kernel(x): ...
"""
import fcntl
import functools
import hashlib
import os

import numba
from numba.core import caching

__all__ = ["njit", "install", "source_digest", "generated_kernels_in"]

_HERE = os.path.dirname(os.path.abspath(__file__))          # .../sorofem
_ROOT = os.path.dirname(_HERE)                               # the folder that holds the packages


@functools.lru_cache(maxsize=None)
def source_digest(package_dir):
    """SHA-1 over the path, modification time [ns] and size of every ``.py`` file under ``package_dir``
    (``__pycache__`` excluded), computed once per process: the part of a kernel's cache stamp that changes when
    any module it may call changes."""
    h = hashlib.sha1()
    for dirpath, dirnames, filenames in os.walk(package_dir):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for name in sorted(filenames):
            if name.endswith(".py"):
                path = os.path.join(dirpath, name)
                try:
                    st = os.stat(path)
                except OSError:
                    continue
                h.update(f"{os.path.relpath(path, package_dir)}:{st.st_mtime_ns}:{st.st_size};".encode())
    return h.hexdigest()


def _top_package(path):
    """The top-level package folder that holds ``path`` (walking up while ``__init__.py`` exists), or None."""
    folder, top = os.path.dirname(os.path.abspath(path)), None
    while os.path.exists(os.path.join(folder, "__init__.py")):
        top, folder = folder, os.path.dirname(folder)
    return top


_GENERATED = set()


def generated_kernels_in(folder):
    """Declare ``folder`` as holding generated kernel modules that call the platform's kernels (the SDF code
    generator's cache): their stamps then also cover ``sorofem``'s sources."""
    _GENERATED.add(os.path.join(os.path.abspath(str(folder)), ""))


def _stamped(get_source_stamp):
    """numba's stamp (mtime, size of the kernel's own file) extended by :func:`source_digest` of the kernel's
    top-level package and of ``sorofem`` for our packages and generated SDF kernels; other libraries' kernels
    keep numba's stamp."""
    @functools.wraps(get_source_stamp)
    def stamp(self):
        own = get_source_stamp(self)
        path = os.path.abspath(getattr(self, "_py_file", "") or "")
        top = _top_package(path) if path else None
        if top is not None and os.path.dirname(top) == _ROOT:
            return own, source_digest(top), source_digest(_HERE)
        if path and path.startswith(tuple(_GENERATED)):
            return own, source_digest(_HERE)
        return own
    stamp.soro_locked = True
    return stamp


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

    A kernel's cache is fresh only while its own file and every source of its package and of ``sorofem`` are
    unchanged (see the module docstring).
    """
    mixin = caching._SourceFileBackedLocatorMixin
    if not getattr(mixin.get_source_stamp, "soro_locked", False):
        mixin.get_source_stamp = _stamped(mixin.get_source_stamp)
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
