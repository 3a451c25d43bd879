"""Undulating soft crawler on a floor (`soro demo crawler`)
=======================================================

Purpose
-------
The seed's dynamic FEM case study with contact (Sec. V-D, Fig. 8-9), after the multigait robot of Shepherd et
al. (PNAS 108, 20400, 2011): the side section of a soft body with three pressure chambers above a stiffer
strain-limiting layer stands on four short legs on the floor; the chambers are inflated one after the other,
back to front, and the body bends in a travelling wave against the floor. The legs concentrate the contact
where the segments meet, so that each bending segment pushes its rear leg back and pulls its front leg
forward while the other legs hold: the body crawls forward (toward +x). Figures: the distance travelled and
the mean speed, the centre-of-mass history over the gait cycles.

Equations
---------
Plane-strain hyperelastic dynamics (generalized-alpha, :mod:`sorofem.fem.dynamics`) with gravity, contact
with the floor :math:`y = 0` (penalty and regularized Coulomb friction, :mod:`sorofem.fem.contact`) and the
seed's open-loop pressure signals

.. math::

    p_i(t) = A\\, \\mathrm{sat}\\left[\\sin(\\omega t - \\phi_i)\\right], \\quad \\mathrm{sat}(x) = \\max(x, 0),
    \\quad \\phi_i = \\tfrac{\\pi}{3}(i - 1), \\quad i = 1, 2, 3 \\text{ (back to front)}.

Parameters
----------
=================  =====================================================================================
body               150 mm x 12 mm section, three segments of 5 pockets 4 mm x 5 mm, 1.5 mm above the bottom
                   layer (2 mm): walls 3.5 mm on top, 6 mm between pockets, 3 mm at the ends; four legs 4 mm
                   wide, 3 mm below the body, at x = 3, 50, 100, 147 mm
materials          the seed's: Ecoflex 00-50 body (Yeoh, mu = 47 kPa), Dragon Skin 30 layer and legs (Yeoh,
                   mu = 307 kPa), presets of :mod:`sorofem.materials`
signal             A = 45 kPa, omega = 5 pi rad/s (period 0.4 s), phi_i = pi/3 (i - 1) (the seed's text)
floor              friction mu = 0.6
time               2 periods with dt = 2 ms (quick: 1 period, dt = 4 ms), rho_inf = 0.8
=================  =====================================================================================

Why this section (where it differs from the seed)
--------------------------------------------------
The seed names its materials and signal but not its section's walls (its mesh is an image preset). A
pressurized thin wall of a neo-Hookean-like rubber has a pressure maximum (a limit point, scaling with
mu t / a: shear modulus, wall thickness, span); past it no nearby equilibrium exists and the chamber balloons.
:func:`pressure_maximum` traces the static path of the back segment through that point by arc-length
continuation. The earlier section (pockets 6 mm x 6 mm, 2 mm walls) in Ecoflex 00-50 has its maximum at
28.8 kPa (29.7 kPa with the finer steps the stability monitor takes near it: the end pocket, whose end and top
walls are both 2 mm, snaps into a bubble; a second maximum at 36.1 kPa inflates the whole segment): below the seed's 45 kPa, which is why that section "ballooned until the
step failed" at the seed's amplitude (and ran only with a 200 kPa / 1 MPa body at 30 kPa). Thicker walls around
smaller pockets (this section) move the maximum to 58.6 kPa, above 45 kPa (the full run reports it as
``pressure_maximum_kPa``; ``tests/benchmarks/bench_crawler.py`` measures both). Still different from the seed: a plane-strain section (the seed's 2D model; the real
robot's chambers are closed in depth, which stiffens them), four short legs that concentrate the contact (the
seed's preset is not described), one friction coefficient.

What it does at these parameters: each period the back and middle segments arch the body ~31 mm off the
floor and it lands forward. Full run (2 mm mesh, dt = 2 ms, two periods): +16 mm by 0.4 s, +26.1 mm by 0.8 s
(32.6 mm/s). Quick run (3 mm, dt = 4 ms, one period): +11.3 mm (28.2 mm/s). The gait is mesh-sensitive: the
quick mesh run for two periods gains only +9.7 mm (its second period loses ~2 mm while the body arches on its
front feet).

Convergence (not reached): the distance gained in ONE period (the demo's functions, the quick run's settings
but dt = 2 ms unless stated: ``crawler_problem(size)``, ``Fem.simulate`` over one period,
:func:`centre_of_mass`; Debian 12, gmsh 4.8):

=========  =======  =====  ==========  ===============  ===============
mesh [mm]  dt [ms]  cells  dx [mm]     dx at T/2 [mm]   CoM rise [mm]
=========  =======  =====  ==========  ===============  ===============
3          4        769    +11.29      (quick run)      ~31
3          2        769    +1.77       -1.55            30.6
2          2        1376   +15.46      -1.05            33.1
2          1        1376   +2.04       -2.06            33.2
1.5        2        2319   +0.28       -2.02            32.9
=========  =======  =====  ==========  ===============  ===============

Every run arches the body ~31-33 mm (that figure converges) and slips back 1-2 mm in the first half period;
the net gain is decided by where the arch lands and scatters from 0.3 to 15 mm per period with mesh and step.
The gait is a leap, not the seed's undulation: at 45 kPa and 2.5 Hz the plane-strain body's arching throws it
off the floor, and the landing is sensitive to everything. So the demo checks only that it moves forward; a
converged speed needs a gait that keeps contact (e.g. the seed's code's 15 kPa and 0.75 s period, or the
chambers closed in depth: a 3D body).

Output: ``com.png`` (centre-of-mass history), ``gait.png`` (the body at six instants), ``crawler.xdmf`` (+ .xdmf.h5,
the whole gait for ParaView),
``report.json`` with ``com_dx_mm``, ``com_dy_mm``, ``speed_mm_per_s``, ``periods``, ``steps``,
``newton_iterations_max``, ``max_contact_force_N_per_m``, ``amplitude_kPa``, ``pressure_maximum_kPa``
(full run only).
"""
import math
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

# ------------------------------------------------------------------------------------------------ parameters
L, H, LAYER, WALL = 150 * mm, 12 * mm, 2 * mm, 1.5 * mm         # body section, bottom layer, wall above it
POCKETS, POCKET_W, POCKET_H, END = 5, 4 * mm, 5 * mm, 3 * mm    # pockets per segment (PneuNet-like walls), end walls
FOOT, FOOT_W, FEET = 3 * mm, 4 * mm, (3 * mm, 50 * mm, 100 * mm, 147 * mm)   # legs: height, width, positions
BODY, LAYER_MATERIAL = materials.Ecoflex0050, materials.DragonSkin30        # the seed's materials (presets)
A, OMEGA, MU = 45 * kPa, 5 * math.pi, 0.6                        # signal amplitude [Pa], [rad/s]; friction [-]
RHO_INF = 0.8                                                    # generalized-alpha spectral radius [-]
#: The full run and the short one (`--quick`, what the tests run): element size [m], gait periods simulated,
#: time step [s].
#: ``static``: whether to trace the back segment's static pressure maximum (:func:`pressure_maximum`, on the
#: quick mesh: ~130 arc-length steps).
FULL = dict(size=2 * mm, periods=2, dt=2e-3, static=True)
QUICK = dict(size=3 * mm, periods=1, dt=4e-3, static=False)


def main(out: Path, quick: bool = False) -> dict:
    """Simulate the gait into ``out`` (``crawler.xdmf``, ``com.png``, ``gait.png``); returns the report."""
    from mpi4py import MPI

    prm = QUICK if quick else FULL
    out = Path(out)

    # 1. mesh and problem: body, stiffer layer and legs, gravity, floor, one pressure signal per segment
    fem, msh = crawler_problem(prm["size"])

    # 2. the gait: generalized-alpha through the given number of periods (a progress bar on a terminal)
    traj = fem.simulate(t_end=prm["periods"] * 2 * math.pi / OMEGA, dt=prm["dt"], rho_inf=RHO_INF)
    traj.write_xdmf(out / "crawler.xdmf")   # the whole gait for ParaView (displacement, von Mises)
    summary = {"amplitude_kPa": A / kPa, "periods": prm["periods"], "steps": len(traj) - 1, "cells": msh.num_cells,
               "newton_iterations_max": int(traj.newton_iterations.max()),
               "max_contact_force_N_per_m": float(np.abs(traj.reactions["contact_0"][:, 1]).max())}
    # 3. the section's static pressure maximum (the amplitude must stay below it, or the pockets balloon)
    if prm["static"]:
        summary["pressure_maximum_kPa"] = pressure_maximum(QUICK["size"])[0] / kPa
    if MPI.COMM_WORLD.rank != 0:
        return summary

    # 4. the distance crawled: the centre of mass over time
    com = centre_of_mass(traj)
    dx, dy = (com[-1] - com[0]) / mm
    summary.update(com_dx_mm=float(dx), com_dy_mm=float(dy), speed_mm_per_s=float(dx / traj.times[-1]))

    # 5. figures: the centre of mass [mm] over time, the body at six instants (von Mises colour bar, mm axes)
    plot_com(traj.times, com, out / "com.png")
    traj.filmstrip(out / "gait.png", np.linspace(0, len(traj) - 1, 6).round(), floor=0.0,
                   xlim=(-10, L / mm + 45))   # room for two periods of travel
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def crawler_section(pocket=None, wall=WALL, end=END):
    """The body [m]: a rounded bar with three segments of small chambers (pockets, ``pocket`` = (width,
    height) [m], default ``(POCKET_W, POCKET_H)``) ``wall`` [m] above the strain-limiting layer, the end pockets
    ``end`` [m] from the body's ends, standing on legs whose feet are on y = 0 (the body's lower-left corner at
    (0, FOOT)). ``crawler_section((6 * mm, 6 * mm), 2 * mm, 2 * mm)`` is the earlier thin-walled section whose
    pockets balloon below the seed's 45 kPa (see :func:`pressure_maximum`)."""
    w, h = pocket if pocket is not None else (POCKET_W, POCKET_H)
    body = sdf.RoundedRectangle(L, H, 2 * mm, center=(L / 2, H / 2))
    hole = sdf.Rectangle(w, h, center=(0.0, LAYER + wall + h / 2))
    for x in np.linspace(end + w / 2, L - end - w / 2, 3 * POCKETS):   # the pitch is L / (3 POCKETS) = 10 mm
        body = body - hole.translate((x, 0.0))
    shape = body.translate((0.0, FOOT))
    for xf in FEET:   # legs overlap the body by 1 mm so that the union is one piece
        shape = shape | sdf.RoundedRectangle(FOOT_W, FOOT + 1 * mm, 0.8 * mm, center=(xf, (FOOT + 1 * mm) / 2))
    return shape


def signal(i):
    """Pressure [Pa] of chamber i (0 = back) as a function of time [s]."""
    phi = math.pi / 3 * i
    return lambda t: A * max(math.sin(OMEGA * t - phi), 0.0)


def crawler_problem(size, section=None):
    """The mesh (element size ``size`` [m]) and the dynamic problem on it: body and layer materials, gravity,
    the floor y = 0 with friction, the signals on the pockets. Returns ``(fem, mesh)``."""
    from sorofem.fem import Fem

    msh = crawler_mesh(size, section)
    fem = Fem(msh, BODY(), degree=2)
    fem.add_material("layer", LAYER_MATERIAL())
    fem.add_gravity()
    fem.add_contact(sdf.Line((0.0, 0.0), (0.0, 1.0)), friction=MU, regularization=0.05 * mm)
    # cavities are named in order of x: pockets 0-4 form the back segment, 5-9 the middle, 10-14 the front
    for k, cavity in enumerate(msh.cavities):
        fem.add_pressure(cavity, signal(k // POCKETS))
    return fem, msh


def crawler_mesh(size, section=None):
    """The section's mesh (element size ``size`` [m]; ``section`` an SDF, default :func:`crawler_section`)
    with its region ``layer`` (legs and bottom layer: the stiffer material)."""
    from sorofem.mesh import Mesh

    msh = Mesh.from_sdf(section if section is not None else crawler_section(), size=size)
    msh.add_region("layer", lambda x: x[1] < FOOT + LAYER, kind="cells")
    return msh


def pressure_maximum(size, section=None, p_top=2 * A):
    """The largest pressure [Pa] the back segment's pockets hold in static equilibrium (feet clamped, no
    gravity): the first limit point of the quasi-static path, followed through it by arc-length continuation
    (:meth:`Fem.follow`) with the pressure ``p_top`` [Pa] as unit load; ``inf`` when the path reaches
    ``p_top`` without one. Above this pressure no nearby equilibrium exists: the pockets' walls balloon (a
    thin-walled chamber's pressure maximum scales with mu t / a, shear modulus times wall thickness over span).
    Returns ``(p_max, path)`` with the path's pressures [Pa]."""
    from sorofem.fem import Fem

    msh = crawler_mesh(size, section).add_region("feet", lambda x: x[1] < 0.4 * mm)
    fem = Fem(msh, BODY(), degree=2)
    fem.add_material("layer", LAYER_MATERIAL())
    fem.add_support("feet")
    for cavity in msh.cavities[:POCKETS]:
        fem.add_pressure(cavity, p_top)
    past_peak = lambda tr: tr.times[-1] < 0.99 * max(tr.times)   # noqa: E731  (1 % below the peak: turned)
    path = fem.follow(load_level=1.0, steps=20, until=past_peak, max_steps=200)
    lam = np.asarray(path.times)
    p_max = float(lam.max()) * p_top if past_peak(path) else math.inf
    return p_max, lam * p_top


def centre_of_mass(traj):
    """Centre of mass [m] of the uniform-density body at each step, (steps, 2): the area-weighted mean of the
    deformed cells' centroids (areas of the reference cells: the body is nearly incompressible)."""
    X, cells, U = traj.vertices, traj.cells, traj.displacement
    x_cells = (X + U)[:, cells].mean(axis=2)
    a, b = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    area0 = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])   # (np.cross of 2-vectors is deprecated in numpy 2)
    return (x_cells * area0[None, :, None]).sum(axis=1) / area0.sum()


def plot_com(times, com, path):
    """``com.png``: the centre of mass's horizontal and vertical displacement [mm] against time [s]."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5.5, 3.5))
    ax = fig.subplots()
    ax.plot(times, (com[:, 0] - com[0, 0]) / mm, label="horizontal")
    ax.plot(times, (com[:, 1] - com[0, 1]) / mm, label="vertical")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("centre of mass displacement [mm]")
    ax.legend()
    ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=120)
