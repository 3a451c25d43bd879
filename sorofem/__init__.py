"""sorofem: geometry, meshing, materials and finite elements for soft robots.

Importing ``sorofem`` is cheap: submodules are loaded on first attribute access, and only
``sorofem.mesh``, ``sorofem.fem`` and ``sorofem.topopt`` import DOLFINx/PETSc/gmsh.

Layer 1 (pure numpy/numba): :mod:`sorofem.units`, :mod:`sorofem.errors`, :mod:`sorofem.sdf`.
Layer 2 (DOLFINx, UFL, PETSc, SLEPc, gmsh): :mod:`sorofem.mesh`, :mod:`sorofem.materials`,
:mod:`sorofem.fem`, :mod:`sorofem.topopt`.

``sorofem`` is the ground floor of the platform: it imports nothing from ``soroshapes``, ``sorocontrol`` or the
application layer ``soro`` (``tests/test_layering.py``). The packages above use only its *foundation*:
:mod:`~sorofem.errors`, :mod:`~sorofem.units`, :mod:`~sorofem.io`, :mod:`~sorofem.sdf`,
:mod:`~sorofem.snapshots` (the seam: FEM results as files), :mod:`~sorofem.materials`, and two helpers that
import no DOLFINx: ``sorofem._numba`` (the cache stamp of every numba kernel of the platform) and
``sorofem._lazy`` (the lazy attributes of the packages' ``__init__``).
"""
import importlib

from . import errors, units
from .errors import *  # noqa: F401,F403  (the hierarchy is small and listed in errors.__all__)

__version__ = "0.1.0"

_SUBMODULES = ("sdf", "mesh", "materials", "fem", "topopt", "snapshots")

__all__ = ["units", "errors", *_SUBMODULES, *errors.__all__]


def __getattr__(name):
    """Import the submodule ``name`` on first access (PEP 562), so heavy dependencies load only when used."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
