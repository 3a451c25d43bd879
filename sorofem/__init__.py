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

from . import _lazy, errors, units
from .errors import *  # noqa: F401,F403  (the hierarchy is small and listed in errors.__all__)

__version__ = "0.1.0"

_SUBMODULES = ("sdf", "mesh", "materials", "fem", "topopt", "snapshots")

__all__ = ["units", "errors", *_SUBMODULES, *errors.__all__]


#: Modules that moved to the application layer ``soro`` (README.md, "Moved names"): importing one is an
#: ImportError that names its new place.
MOVED_MODULES = {
    "sorofem.cli": "soro.cli (main, run_sweep), soro.demo (run_demo, list_demos, DEFAULT_DEMO; DEMOS_DIR is "
                   "soro.demo.demos_dir()), soro.doctor.doctor and soro.trade.run_trade",
    "sorofem.sweep": "soro.sweep (the same names)",
}
_lazy.moved_modules(MOVED_MODULES)


def __getattr__(name):
    """Import the submodule ``name`` on first access (PEP 562), so heavy dependencies load only when used."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
