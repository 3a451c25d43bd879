"""Buckling of a porous elastomer block (`soro demo porous_buckling`)
==================================================================

Purpose
-------
The seed paper's case study on nonlinear modal analysis (Sorotoki, IEEE Access 2024, Sec. V-C, Fig. 7),
after Mullin et al. (PRL 99, 084301, 2007), Bertoldi et al. (JMPS 56, 2642, 2008) and Overvelde et al.
(Adv. Mater. 24, 2337, 2012): a square elastomer block perforated by a square array of circular holes is
compressed between two plates. At a critical strain the tangent stiffness loses positive definiteness and
the holes collapse into a pattern of mutually orthogonal ellipses (negative Poisson's ratio).

Equations
---------
Quasi-static plane strain, compressible Neo-Hookean solid (:mod:`sorofem.materials`),

.. math::

    \\psi(F) = \\tfrac{\\mu}{2}(\\bar I_1 - 3) + \\tfrac{\\kappa}{4}(J^2 - 1 - 2\\ln J), \\qquad
    \\int_\\Omega \\frac{\\partial\\psi}{\\partial F} : \\nabla v \\, dX = 0,

with :math:`u_y = \\varepsilon H` on the top (``t`` ramps the nominal strain :math:`\\varepsilon` from 0 to
:math:`\\varepsilon_{end}`), :math:`u_x = 0` on the top, :math:`u = 0` on the bottom (bonded plates, as in the
seed's script). After every converged step the lowest eigenvalue of

.. math::

    K_T(u)\\,\\phi = \\lambda M \\phi

is computed; the critical nominal strain :math:`\\varepsilon_{cr}` is where :math:`\\lambda_1` crosses zero
(linear interpolation between the two steps around the sign change). The path is followed by pseudo-arc-length
continuation (``Fem.follow(monitor_stability=True, branch_switch=True)``, :mod:`sorofem.fem.continuation`):
the problem is perfectly symmetric, so a plain load-stepping Newton iteration stays on the symmetric
(fundamental, now unstable) branch past the bifurcation; here the step after the critical point is taken
along the critical mode (eigenvector injection), and the compression continues to -12.5 % on the
post-critical branch, where the holes have become the alternating ellipses (quick and full run alike).

Parameters
----------
=================  ==========================================  =====================================
block              ``holes`` x ``holes`` cells of pitch a       6 x 6 (quick 4 x 4), a = 10 mm
hole radius        r = a sqrt(psi / pi), porosity psi            psi = 0.50, r = 3.99 mm
material           Neo-Hookean E = 19 kPa, nu = 0.45,            (seed, Sorotoki facts)
                   rho = 1000 kg/m^3
compression        epsilon_end = -12.5 % of the height           (seed; quick alike)
discretization     P2 triangles, h = 0.6 mm (quick 1.25 mm)
=================  ==========================================  =====================================

Reference
---------
Bloch-wave analyses of the infinite periodic solid with circular pores (Bertoldi et al. 2008; Overvelde,
Shan, Bertoldi 2012) put the pattern-transforming instability at a few percent of nominal compressive strain
for porosities near 0.5; ``reference_strain_periodic`` = -0.045 is an approximate value for orientation,
not a tabulated one. A finite specimen bonded to rigid plates buckles later than the periodic solid. The
seed quotes "approximately -12.5 %", the strain at which it shows the modes, not the critical point.
The pattern is checked, not only drawn: ``ellipse_alternation`` is the fraction of neighbouring interior
holes of the compressed (post-critical) block whose ellipses (the cos 2 theta part of the radial displacement
on the hole) have opposite orientations, 1 for the perfect alternating pattern (0 on the symmetric branch,
where every hole flattens the same way).

Figures (in ``out``)
--------------------
``modes.png`` (first four eigenmodes at zero load and at -12.5 % on the post-critical branch, coloured by the
horizontal mode displacement, like the seed's Fig. 7), ``stability.png`` (lowest eigenvalue vs nominal strain
along the path), ``deformed.png`` (the compressed block coloured by the horizontal and the vertical
displacement on the seed's scale, -5 ... 5 mm), ``porous.h5`` (snapshot, full run only). The returned dict
holds ``critical_strain``, ``reference_strain_periodic``, ``holes``, ``porosity``, ``cells``, ``dofs``,
``steps``, ``newton_iterations_max``, ``lambda1_at_zero`` [1/s^2], ``lambda1_at_end`` [1/s^2] (positive: the
post-critical state is stable), ``ellipse_alternation``, ``strain_reached``, ``branch_switch_step``,
``reaction_at_end_N_per_m`` and ``wall_time_s``.

Figures measured (DOLFINx 0.5): full run (6 x 6 holes, 52162 unknowns) eps_cr = -7.84 %, the switch at step 33,
-12.5 % reached in 56 steps (at most 5 Newton iterations), alternation 1.0, lambda_1 = 1089 1/s^2 > 0 at the
end; quick run (4 x 4 holes) eps_cr = -9.08 %, 22 steps, alternation 1.0, lambda_1 = 938 1/s^2 at the end.
"""
import math
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

REFERENCE_STRAIN_PERIODIC = -0.045


def porous_block(holes, pitch=10 * mm, porosity=0.5):
    """A square block of ``holes`` x ``holes`` cells of ``pitch`` [m], each with a circular hole of the given
    area fraction; the lower-left corner at the origin."""
    r = pitch * math.sqrt(porosity / math.pi)
    side = holes * pitch
    block = sdf.Rectangle(side, side, center=(side / 2, side / 2))
    voids = sdf.Circle(r, center=(pitch / 2, pitch / 2)).repeat((pitch, pitch), (holes, holes))
    return block - voids, r


def ellipse_alternation(X, shape, holes, pitch, radius):
    """Fraction of neighbouring interior hole pairs whose mode ellipses alternate (see the docstring).

    For each hole, the radial component of the mode displacement at vertices on its rim is projected on
    cos(2 theta); its sign says whether the hole becomes a horizontal or a vertical ellipse."""
    sign = {}
    for i in range(holes):
        for j in range(holes):
            c = np.array([(i + 0.5) * pitch, (j + 0.5) * pitch])
            d = X - c
            r = np.linalg.norm(d, axis=1)
            rim = np.abs(r - radius) < 0.05 * radius
            if rim.sum() < 8:
                continue
            theta = np.arctan2(d[rim, 1], d[rim, 0])
            radial = np.einsum("ij,ij->i", shape[rim], d[rim] / r[rim, None])
            sign[i, j] = np.sign(np.mean(radial * np.cos(2 * theta)))
    pairs = [((i, j), (i + di, j + dj)) for (i, j) in sign for di, dj in ((1, 0), (0, 1))
             if (i + di, j + dj) in sign and 0 < i < holes - 1 and 0 < j < holes - 1
             and 0 < i + di < holes - 1 and 0 < j + dj < holes - 1]
    if not pairs:
        return float("nan")
    return float(np.mean([sign[a] * sign[b] < 0 for a, b in pairs]))


def critical_strain(strain, lam):
    """First zero crossing of ``lam`` along ``strain`` (linear interpolation); NaN if it never crosses."""
    strain, lam = np.asarray(strain), np.asarray(lam)
    for i in range(1, len(lam)):
        if lam[i - 1] > 0 >= lam[i]:
            return float(strain[i - 1] + (strain[i] - strain[i - 1]) * lam[i - 1] / (lam[i - 1] - lam[i]))
    return float("nan")


def _plot_field(ax, X, cells, u, color, title, vmax=None):
    import matplotlib.tri as mtri

    x = (X + u) / mm
    tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
    vmax = vmax or max(float(np.abs(color).max()), 1e-30)
    art = ax.tripcolor(tri, color, shading="gouraud", cmap="coolwarm", vmin=-vmax, vmax=vmax)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])
    return art


def main(out: Path, quick: bool = False) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpi4py import MPI

    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    wall = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rank0 = MPI.COMM_WORLD.rank == 0
    holes = 4 if quick else 6
    pitch, porosity = 10 * mm, 0.5
    strain_end = -0.125
    steps = 16 if quick else 50
    shape, radius = porous_block(holes, pitch, porosity)
    H = holes * pitch

    # ---- mesh: P2 displacement on straight triangles
    msh = Mesh.from_sdf(shape, size=(1.25 if quick else 0.6) * mm)

    # ---- model: bonded plates, the top one moved down
    rubber = materials.NeoHookean(E=19 * kPa, nu=0.45, density=1000.0)
    fem = Fem(msh, material=rubber, degree=2)
    fem.add_support("bottom")
    fem.add_support("top", components="x")
    fem.add_displacement("top", strain_end * H, components="y")

    # ---- eigenmodes of the unloaded block
    before = fem.eigen(4)
    dofs = fem.num_dofs

    # ---- path following: compression past the critical point onto the post-critical branch
    traj = fem.follow(load_level=1.0, steps=steps, monitor_stability=True, branch_switch=True, progress=not quick)
    strain = traj.times * strain_end
    strain_reached = float(strain[-1])
    lam = np.array(traj.lowest_eigenvalue)
    eps_cr = critical_strain(strain, lam)
    switch = traj.metadata.get("branch_switch")   # the first step on the post-critical branch

    # ---- eigenmodes of the compressed block on the post-critical branch
    after = fem.eigen(4, shift=-abs(before.eigenvalues[0]))

    summary = {
        "critical_strain": eps_cr,
        "reference_strain_periodic": REFERENCE_STRAIN_PERIODIC,
        "holes": holes * holes,
        "porosity": porosity,
        "hole_radius_mm": radius / mm,
        "cells": int(msh.num_cells),
        "dofs": int(dofs),
        "steps": len(traj) - 1,
        "newton_iterations_max": int(traj.newton_iterations[1:].max()),
        "lambda1_at_zero": float(before.eigenvalues[0]),
        "lambda1_at_end": float(lam[-1]),
        "ellipse_alternation": (ellipse_alternation(traj.vertices, traj.displacement[-1], holes, pitch, radius)
                                if rank0 else float("nan")),
        "strain_end": strain_end,
        "strain_reached": strain_reached,
        "branch_switch_step": switch["step"] if switch else None,
        "reaction_at_end_N_per_m": float(traj.reactions["top"][-1][1]) if "top" in traj.reactions else float("nan"),
        "wall_time_s": round(time.perf_counter() - wall, 1),
    }
    if not rank0:
        return summary

    X, cells, U = traj.vertices, traj.cells, traj.displacement
    amp = 0.08 * H  # drawn mode amplitude [m]
    fig, axes = plt.subplots(2, 4, figsize=(11, 6))
    for row, (modes, u0, label) in enumerate(((before, np.zeros_like(X), "eps = 0"),
                                              (after, U[-1], f"eps = {strain_reached:.3g}"))):
        for k in range(4):
            s = modes.shapes[k]
            _plot_field(axes[row, k], X, cells, u0 + amp * s, s[:, 0],
                        f"{label}: mode {k + 1}, lambda = {modes.eigenvalues[k]:.3g} 1/s^2")
    fig.suptitle(f"Eigenmodes of K phi = lambda M phi ({holes}x{holes} holes, porosity {porosity}); "
                 f"colour: horizontal mode displacement")
    fig.tight_layout()
    fig.savefig(out / "modes.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.plot(-strain * 100, lam, "o-", ms=3, label="lowest eigenvalue along the path")
    ax.axhline(0, color="k", lw=0.6)
    if math.isfinite(eps_cr):
        ax.axvline(-eps_cr * 100, color="r", ls="--", label=f"critical strain {eps_cr:.4f}")
    ax.axvline(-REFERENCE_STRAIN_PERIODIC * 100, color="g", ls=":", label="periodic solid (literature)")
    ax.set_xlabel("nominal compressive strain -eps [%]")
    ax.set_ylabel("lambda_1 [1/s^2]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "stability.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    for ax, comp in zip(axes, (0, 1)):
        art = _plot_field(ax, X, cells, U[-1], U[-1][:, comp] / mm,
                          f"post-critical equilibrium, eps = {strain_reached:.3g}: u_{'xy'[comp]}",
                          vmax=max(5.0, float(np.abs(U[-1][:, comp]).max()) / mm))
        fig.colorbar(art, ax=ax, shrink=0.8, label=f"u_{'xy'[comp]} [mm]")
    fig.tight_layout()
    fig.savefig(out / "deformed.png", dpi=120)
    plt.close(fig)
    if not quick:
        traj.save(out / "porous.h5", regions=None, cavities=())
    return summary


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/porous_buckling"),
                          quick="--quick" in sys.argv), indent=2))
