"""soroshapes: reduced-order Cosserat beam models, data-driven strain bases and networks of dynamic systems.

Runs without DOLFINx: it uses :mod:`sorofem.sdf` for sections and contact and reads FEM results only as
snapshot files. Numba kernels compile on first use, not at import.
"""
__all__: list[str] = []
