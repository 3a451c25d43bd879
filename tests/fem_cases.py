"""FEM validation cases shared by the tests and the benchmarks (tests/sorofem/test_fem_formulations.py,
tests/benchmarks/bench_cook.py): Cook's membrane and the shear ("vortex") mode of a square on rollers.

Their references are derived in the docstrings; they need DOLFINx (sorofem.fem).
"""
import warnings

import numpy as np

from sorofem import materials
from sorofem.fem import Fem, LockingWarning
from sorofem.mesh import Mesh

__all__ = ["COOK_REFERENCE", "cook_membrane", "cook_displacement", "vortex_eigenvalue"]

#: Converged vertical displacement of the middle of the loaded edge, (48, 52), of Cook's membrane in linear
#: plane stress (E = 1, nu = 1/3, unit total shear on the right edge): the value quoted for this benchmark
#: (R. D. Cook's tapered panel, 1974) in the literature on membrane elements; bench_cook.py reaches it
#: independently (P2 to 64 x 64 and Richardson extrapolation).
COOK_REFERENCE = 23.96


def cook_membrane(n, cell="triangle"):
    """Cook's tapered panel (0, 0), (48, 44), (48, 60), (0, 44) [m] on an n x n structured grid of the bilinear
    map of the unit square; ``left`` (x = 0) and ``right`` (x = 48) are found as the bounding-box sides."""
    xi, eta = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    pts = np.column_stack([48.0 * xi.ravel(), (44.0 * xi + eta * (44.0 - 28.0 * xi)).ravel()])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    if cell == "triangle":
        cells = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    else:
        cells = np.column_stack([a, b, c, d])
    return Mesh.from_arrays(pts, cells)


def cook_displacement(n, degree, cell="triangle", formulation="plane_stress"):
    """Vertical displacement [m] at (48, 52) and the Fem."""
    fem = Fem(cook_membrane(n, cell), materials.LinearElastic(E=1.0, nu=1 / 3), formulation=formulation,
              degree=degree)
    traj = fem.add_support("left").add_force("right", [0.0, 1.0 / 16.0]).solve(steps=1)
    return float(fem.evaluate([[48.0, 52.0]])[0][1]), traj


def vortex_eigenvalue(material, degree, mixed, formulation=None, n=8):
    """Lowest eigenvalue [1/s^2] of a unit square with every side on rollers (normal displacement zero).

    Closed form (separation of variables in Navier's equation): the shear mode u = (sin pi x cos pi y,
    -cos pi x sin pi y) is divergence-free, so omega^2 = 2 pi^2 mu / rho whatever lambda; the dilatational
    modes start at (lambda + 2 mu) pi^2 / rho, above it for every nu >= 0, and go to infinity as nu -> 1/2."""
    msh = Mesh.rectangle(1.0, 1.0, size=1.0 / n, center=(0.5, 0.5))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LockingWarning)
        fem = Fem(msh, material, degree=degree, mixed=mixed, formulation=formulation)
    for region, comp in (("left", "x"), ("right", "x"), ("bottom", "y"), ("top", "y")):
        fem.add_support(region, comp)
    exact = 2 * np.pi**2 * material.G / material.density
    return float(fem.eigen(1, shift=0.5 * exact).eigenvalues[0]) / exact   # the eigenvalue nearest the shift
