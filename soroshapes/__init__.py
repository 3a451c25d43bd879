"""soroshapes: reduced-order Cosserat beam models, data-driven strain bases and networks of dynamic systems.

Runs without DOLFINx: it uses :mod:`sorofem.sdf` for sections and contact and reads FEM results only as
snapshot files. Numba kernels compile on first use, not at import: submodules (such as :mod:`soroshapes.lie`,
the SO(3)/SE(3) kernels) are loaded on first attribute access, so ``import soroshapes`` does not import numba.
"""
import importlib

_SUBMODULES = ("lie",)

__all__: list[str] = [*_SUBMODULES]


def __getattr__(name):
    """Import the submodule ``name`` on first access (PEP 562), so numba loads only when a kernel is used."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
