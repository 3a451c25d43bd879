"""FEM validation cases shared by the tests and the benchmarks (tests/sorofem/test_fem_formulations.py,
tests/benchmarks/bench_cook.py, tests/sorofem/test_continuation.py, tests/benchmarks/bench_continuation.py):
Cook's membrane, the shear ("vortex") mode of a square on rollers, the thick sphere through its pressure
maximum and the clamped-guided strut.

Their references are derived in the docstrings; they need DOLFINx (sorofem.fem).
"""
import warnings

import numpy as np

from sorofem import materials
from sorofem.fem import Fem, LockingWarning
from sorofem.mesh import Mesh

__all__ = ["COOK_REFERENCE", "cook_membrane", "cook_displacement", "vortex_eigenvalue", "thick_sphere",
           "inner_radius", "STRUT", "strut", "strut_end_offset"]

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
    traj = fem.add_support("left").add_traction("right", [0.0, 1.0 / 16.0]).solve(steps=1)
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


def thick_sphere(A, B, mu, pressure, cells_across, nu=0.4999, volume=False):
    """Axisymmetric quarter section (A < r < B, x, y >= 0) of a nearly incompressible Neo-Hookean sphere
    (Taylor-Hood P2/P1, order-2 geometry), symmetric about y = 0, with ``pressure`` [Pa] (times the load factor)
    on its inner surface ``inner``; with ``volume`` the load is instead the injected volume ``pressure`` [m^3]
    (times the load factor) under volume control."""
    from sorofem import sdf

    shape = (sdf.Circle(B) - sdf.Circle(A)) & sdf.Rectangle(B, B, center=(B / 2, B / 2))
    msh = Mesh.from_sdf(shape, size=(B - A) / cells_across, order=2)
    msh.add_region("inner", lambda x: np.hypot(x[0], x[1]) < A * (1 + 1e-3))
    fem = Fem(msh, materials.NeoHookean(mu=mu, nu=nu), formulation="axisymmetric", degree=2, mixed=True)
    fem.add_support("bottom", "y")
    return fem.add_volume("inner", pressure) if volume else fem.add_pressure("inner", pressure)


def inner_radius(traj, A):
    """Inner radius [m] per step of a :func:`thick_sphere` trajectory (at its vertex on the equator)."""
    i = np.argmin(np.hypot(traj.vertices[:, 0] - A, traj.vertices[:, 1]))
    return A + traj.displacement[:, i, 0]


#: The strut of :func:`strut`: length, thickness [m], E [Pa], nu, and its Euler load [N/m] clamped-guided in
#: plane strain, pi^2 E/(1 - nu^2) h^3/12 / L^2.
STRUT = dict(L=0.1, h=0.004, E=1e6, nu=0.3)
STRUT["P_cr"] = np.pi**2 * STRUT["E"] / (1 - STRUT["nu"] ** 2) * STRUT["h"] ** 3 / 12 / STRUT["L"] ** 2


def strut(cells_across=2, shortening=0.05):
    """The :data:`STRUT` (plane strain, Neo-Hookean, P2 on a structured grid) clamped at ``left``; its ``right``
    end pushed in by ``shortening`` L times the load factor and free to slide sideways (the face stays
    parallel: a guided end)."""
    L, h = STRUT["L"], STRUT["h"]
    msh = Mesh.rectangle(L, h, size=h / cells_across, center=(L / 2, 0.0))
    fem = Fem(msh, materials.NeoHookean(E=STRUT["E"], nu=STRUT["nu"]), degree=2)
    return fem.add_support("left").add_displacement("right", -shortening * L, "x")


def strut_end_offset(traj):
    """Sideways offset [m] per step of the guided end of a :func:`strut` trajectory (its mid-thickness vertex)."""
    i = np.argmin(np.hypot(traj.vertices[:, 0] - STRUT["L"], traj.vertices[:, 1]))
    return traj.displacement[:, i, 1]
