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
horizontal mode displacement over its largest value, like the seed's Fig. 7; axes in mm), ``stability.png``
(lowest eigenvalue vs nominal strain along the path), ``deformed.png`` (the compressed block coloured by the horizontal and the vertical
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

# ------------------------------------------------------------------------------------------------ parameters
PITCH, POROSITY = 10 * mm, 0.5                       # cell pitch [m], hole area fraction [-]
E, NU, RHO = 19 * kPa, 0.45, 1000.0                   # Neo-Hookean rubber [Pa], [-], [kg/m^3]
STRAIN_END = -0.125                                   # nominal strain at the end of the path [-]
MODES = 4                                             # eigenmodes drawn before and after
REFERENCE_STRAIN_PERIODIC = -0.045                    # periodic solid, literature (see Reference above)
#: The full run and the short one (`--quick`, what the tests run): holes per side, element size [m],
#: continuation steps (initial step 1/steps), progress lines per step, snapshot file written.
FULL = dict(holes=6, size=0.6 * mm, steps=50, progress=True, snapshot=True)
QUICK = dict(holes=4, size=1.25 * mm, steps=16, progress=False, snapshot=False)


def main(out: Path, quick: bool = False) -> dict:
    """Compress the block past its critical point into ``out``; returns the report (see Figures above)."""
    from mpi4py import MPI

    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    wall = time.perf_counter()
    prm = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    holes = prm["holes"]
    shape, radius = porous_block(holes, PITCH, POROSITY)
    H = holes * PITCH

    # 1. mesh: P2 displacement on straight triangles
    msh = Mesh.from_sdf(shape, size=prm["size"])

    # 2. model: bonded plates, the top one moved down
    fem = Fem(msh, material=materials.NeoHookean(E=E, nu=NU, density=RHO), degree=2)
    fem.add_support("bottom")
    fem.add_support("top", components="x")
    fem.add_displacement("top", STRAIN_END * H, components="y")

    # 3. eigenmodes of the unloaded block
    before = fem.eigen(MODES)

    # 4. path following: compression past the critical point onto the post-critical branch
    traj = fem.follow(load_level=1.0, steps=prm["steps"], monitor_stability=True, branch_switch=True,
                      progress=prm["progress"])
    strain = traj.times * STRAIN_END
    lam = np.array(traj.lowest_eigenvalue)
    eps_cr = critical_strain(strain, lam)
    switch = traj.metadata.get("branch_switch")   # the first step on the post-critical branch

    # 5. eigenmodes of the compressed block on the post-critical branch
    after = fem.eigen(MODES, shift=-abs(before.eigenvalues[0]))
    if prm["snapshot"]:
        traj.save(out / "porous.h5", regions=None, cavities=())   # every rank calls; rank 0 writes
    if MPI.COMM_WORLD.rank != 0:
        return {}

    summary = {
        "critical_strain": eps_cr,
        "reference_strain_periodic": REFERENCE_STRAIN_PERIODIC,
        "holes": holes * holes,
        "porosity": POROSITY,
        "hole_radius_mm": radius / mm,
        "cells": int(msh.num_cells),
        "dofs": int(fem.num_dofs),
        "steps": len(traj) - 1,
        "newton_iterations_max": int(traj.newton_iterations[1:].max()),
        "lambda1_at_zero": float(before.eigenvalues[0]),
        "lambda1_at_end": float(lam[-1]),
        "ellipse_alternation": ellipse_alternation(traj.vertices, traj.displacement[-1], holes, PITCH, radius),
        "strain_end": STRAIN_END,
        "strain_reached": float(strain[-1]),
        "branch_switch_step": switch["step"] if switch else None,
        "reaction_at_end_N_per_m": float(traj.reactions["top"][-1][1]) if "top" in traj.reactions else float("nan"),
        "wall_time_s": round(time.perf_counter() - wall, 1),
    }

    # 6. figures: the modes before and after, the lowest eigenvalue along the path, the compressed block
    plot_modes(traj, before, after, holes, float(strain[-1]), out / "modes.png")
    plot_stability(strain, lam, eps_cr, out / "stability.png")
    plot_deformed(traj, float(strain[-1]), out / "deformed.png")
    return summary


# ------------------------------------------------------------------------------------------------- the steps
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


# ------------------------------------------------------------------------------------------------ the figures
def _plot_field(ax, X, cells, u, color, title, vmin, vmax):
    """The body displaced by ``u`` [m] drawn in mm, coloured by ``color`` (one value per vertex) on
    [vmin, vmax]; returns the artist for a colour bar."""
    import matplotlib.tri as mtri

    x = (X + u) / mm
    tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
    art = ax.tripcolor(tri, color, shading="gouraud", cmap="coolwarm", vmin=vmin, vmax=vmax)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=8)
    ax.tick_params(labelsize=6)
    return art


def plot_modes(traj, before, after, holes, strain_reached, path):
    """``modes.png``: the first eigenmodes at zero load (top row) and on the post-critical branch (bottom),
    drawn with an amplitude of 8 % of the height, coloured by the horizontal mode displacement over its
    largest value."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    X, cells, U = traj.vertices, traj.cells, traj.displacement
    amp = 0.08 * holes * PITCH  # drawn mode amplitude [m]
    fig = Figure(figsize=(11.5, 6))
    axes = fig.subplots(2, MODES + 1, gridspec_kw={"width_ratios": [1.0] * MODES + [0.06]})  # last: colour bars
    for row, (modes, u0, label) in enumerate(((before, np.zeros_like(X), "eps = 0"),
                                              (after, U[-1], f"eps = {strain_reached:.3g}"))):
        for k in range(MODES):
            s = modes.shapes[k]
            art = _plot_field(axes[row, k], X, cells, u0 + amp * s, s[:, 0] / max(np.abs(s[:, 0]).max(), 1e-30),
                              f"{label}: mode {k + 1}, lambda = {modes.eigenvalues[k]:.3g} 1/s^2", -1.0, 1.0)
        fig.colorbar(art, cax=axes[row, -1], label="u_x / max |u_x| [-]")
    for ax in axes[-1, :MODES]:
        ax.set_xlabel("x [mm]", fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel("y [mm]", fontsize=7)
    fig.suptitle(f"Eigenmodes of K phi = lambda M phi ({holes}x{holes} holes, porosity {POROSITY}); "
                 "colour: horizontal mode displacement")
    save_figure(fig, path, dpi=110)


def plot_stability(strain, lam, eps_cr, path):
    """``stability.png``: the lowest eigenvalue [1/s^2] against the nominal compressive strain [%]."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5.5, 3.8))
    ax = fig.subplots()
    ax.plot(-strain * 100, lam, "o-", ms=3, label="lowest eigenvalue along the path")
    ax.axhline(0, color="k", lw=0.6)
    if math.isfinite(eps_cr):
        ax.axvline(-eps_cr * 100, color="r", ls="--", label=f"critical strain {eps_cr:.4f}")
    ax.axvline(-REFERENCE_STRAIN_PERIODIC * 100, color="g", ls=":", label="periodic solid (literature)")
    ax.set_xlabel("nominal compressive strain -eps [%]")
    ax.set_ylabel("lambda_1 [1/s^2]")
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=120)


def plot_deformed(traj, strain_reached, path):
    """``deformed.png``: the compressed block [mm] coloured by u_x and u_y [mm] on the seed's scale
    (-5 ... 5 mm, wider if the displacement is larger)."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    X, cells, u = traj.vertices, traj.cells, traj.displacement[-1]
    fig = Figure(figsize=(10, 4.4))
    axes = fig.subplots(1, 2)
    for ax, comp in zip(axes, (0, 1)):
        vmax = max(5.0, float(np.abs(u[:, comp]).max()) / mm)
        art = _plot_field(ax, X, cells, u, u[:, comp] / mm,
                          f"post-critical equilibrium, eps = {strain_reached:.3g}: u_{'xy'[comp]}", -vmax, vmax)
        ax.set(xlabel="x [mm]", ylabel="y [mm]")
        fig.colorbar(art, ax=ax, shrink=0.8, label=f"u_{'xy'[comp]} [mm]")
    save_figure(fig, path, dpi=120)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/porous_buckling"),
                          quick="--quick" in sys.argv), indent=2))
