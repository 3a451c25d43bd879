"""Inverse design of a PneuNet chamber by topology optimization (`soro demo pneunet_design`)
=========================================================================================

Purpose
-------
The seed paper's Sec. VI-B (Figs. 23-24): find the material layout of a PneuNet chamber that bends the actuator
the most when pressurized, print it, and check it by simulation. The design domain is the actuator itself:
three 15 x 30 mm chambers side by side (x along the actuator, y up) and a 1.5 mm end cap, of Formlabs Elastic
80A, clamped on the left; the fluid enters at the centre of each chamber. The three chambers share one design
(:class:`~sorofem.topopt.filters.LinkedFilter`: a cell and its copies one and two chamber widths away get the
same design variable). SIMP densities, a Helmholtz filter and MMA update the layout; at every design the void
cells connected to an inlet (flood fill) carry the pressure. The optimized actuator is exported (density PNG
and XDMF, an extruded STL of the smooth iso-contour), re-meshed from its iso-contour and inflated to 80 kPa
with the hyperelastic :class:`~sorofem.fem.Fem` (P2, the full material): the validated bending angle. The
initial design (round 5 mm holes, the seed's ``initialTopology``) goes through the same pipeline.

Why the design model is the validated actuator: a single chamber with a spring for its neighbours (the first
version) optimized a different structure from the one validated. Its right wall had pressure on one side only
and could bulge into the spring, while in the actuator the wall between two chambers carries the pressure on
both sides; its objective was the rotation of that face about its centre, while the validation measures the
bending of the base. The design that bent the single chamber most bent the actuator little (100 iterations:
3.5 deg at 80 kPa, 30 iterations: 6.8 deg), and the volume constraint was not active: the optimizer opened
unpressurized holes to soften the face. With the actuator as the design model and the validation's angle
as the objective, the design model and the validation differ only in the discretization (Q1 cells with
nu = 0.45 vs P2 triangles with nu = 0.49), the smoothed iso-contour and the soft void.

Equations
---------
Design problem (:mod:`sorofem.topopt.problems`), geometrically nonlinear, plane strain:

.. math::

    \\min_{x}\\; -\\theta(u) \\quad\\text{s.t.}\\quad R(u, \\bar\\rho) = 0,\\quad
    \\frac{\\sum_e v_e\\bar\\rho_e}{|\\Omega|} \\le f,\\quad 0 \\le x \\le 1,

    R = \\int_\\Omega (\\varepsilon + (1-\\varepsilon)\\bar\\rho^3)\\frac{\\partial\\psi}{\\partial F}:\\nabla v
        - p\\int_{\\Omega_p} (1-\\bar\\rho)^2 J F^{-T}:\\nabla v,

with :math:`\\bar\\rho` the linked (chamber-periodic), filtered (Helmholtz, :math:`-r^2\\Delta\\tilde\\rho +
\\tilde\\rho = x`) and projected (smoothed Heaviside, so that the iso-contour that is printed is the design
that was analysed) densities, :math:`\\Omega_p` the flood-filled chambers (cells with :math:`\\bar\\rho < 0.5`
connected to an inlet) and :math:`\\theta` the clockwise rotation (least squares) of the base's bottom edge
under the last chamber, the angle the validation reports. Sensitivities by the adjoint method; MMA (Svanberg).

Parameters
----------
===================  ==========================================================================
domain               3 chambers of 15 mm (x) x 30 mm (y) and an end cap of 1.5 mm; passive solid
                     base 2 mm, top wall 1 mm, side walls 0.75 mm (1.5 mm between two chambers)
inlet                disk of radius 1.5 mm at each chamber's centre (passive void); initial hole
                     radius 5 mm
material             Elastic 80A (Neo-Hookean, E = 9.35 MPa); design model nu = 0.45 (Q1 cells lock
                     at 0.49), validation nu = 0.49 with P2 triangles
pressure             80 kPa (the seed's validation ramp)
SIMP                 p = 3, epsilon = 1e-3, volume fraction <= 0.5, filter radius 1 mm, Heaviside
                     projection eta = 0.5, beta 1 -> 32 (doubled every 15 iterations; quick: 6)
mesh                 design h = 0.375 mm (quick: 0.5 mm) quadrilaterals; validation h = 0.5 mm
                     (quick: 0.75 mm)
iterations           100 (quick: 30) MMA iterations, move 0.1
===================  ==========================================================================

Measured
--------
Full run (100 iterations, 9920 design cells): the design model bends 15.77 deg at 80 kPa, the validated
actuator 14.46 deg (the initial design 0.04 deg), volume fraction 0.45 (the constraint is not active: less
material bends more); quick run (30 iterations): 15.47 and 13.94 deg. Before, with a single chamber and a
spring as the design model: 3.5 deg (100 iterations) and 6.8 deg (30). The layout: in each chamber a cavity
that fills the upper part under the top wall and narrows toward the base (an upside-down drop, leaning
toward the free end), a solid mound on the base at the chamber's clamped-end side, and two closed,
unpressurized holes: one above the base at the free-end side, where the wall meets the base (a hinge), and a
small one in the upper corner at the clamped-end side (the validated actuator has them too: 9 cavities, 3 of
them pressurized). The teardrop of the seed's Fig. 23 is symmetric and has no such holes.

Figures (in ``out``)
--------------------
``frames/frame_KKK.png`` (the design every few iterations), ``history.png`` (objective and volume),
``density.png`` and ``density.xdmf`` (the final densities), ``design.stl`` (the actuator extruded to 15 mm),
``inflated.png`` (the validated actuator, reference and inflated), ``actuator_optimized.png`` and
``actuator_initial.png`` (each design's iso-contour image, the image that is re-meshed), ``design.npz``
(restartable design).
The dict returned holds ``iterations``, ``design_rotation_deg`` (the design model's base rotation at 80 kPa),
``initial_rotation_deg``, ``volume_fraction``, ``flooded_cells``, ``cavities`` (of the re-meshed actuator),
``pressurized_cavities``, ``bending_angle_deg`` (the validated actuator at 80 kPa: the clockwise rotation,
toward the base, of the bottom chord under the last chamber; the clamp keeps the first chord's rotation near
zero), ``bending_angle_initial_deg`` (the initial design through the same pipeline),
``reached_pressure_kPa``, ``stl_triangles``, ``stl_volume_mm3``, ``frames`` and wall times.
"""
import math
import time
from pathlib import Path

import numpy as np

from sorofem import materials
from sorofem.units import kPa, mm

# ------------------------------------------------------------------------------------------------ parameters
W, H, BASE, TOP, SIDE, END = 15 * mm, 30 * mm, 2 * mm, 1 * mm, 0.75 * mm, 1.5 * mm   # domain and walls [m]
INLET_R, HOLE_R, PRESSURE, CHAMBERS = 1.5 * mm, 5 * mm, 80 * kPa, 3
LENGTH = CHAMBERS * W + END     # the actuator [m]: the chambers and the end cap
STL_THICKNESS = 15 * mm         # the STL's extrusion [m]
FRAME_EVERY = 5                 # a frame of the design every 5 iterations
#: The full run and the short one (`--quick`, what the tests run): design and validation element sizes [m],
#: MMA iterations, iterations between doublings of the projection's sharpness, validation load steps.
FULL = dict(h_design=0.375 * mm, h_fem=0.5 * mm, iterations=100, beta_every=15, steps=16)
QUICK = dict(h_design=0.5 * mm, h_fem=0.75 * mm, iterations=30, beta_every=6, steps=8)


def main(out: Path, quick: bool = False) -> dict:
    """Design, export and validate the chamber into ``out``; returns the report (see Figures above)."""
    from sorofem.topopt import density_png, optimize, write_stl, write_xdmf

    prm = QUICK if quick else FULL
    out = Path(out)
    (out / "frames").mkdir(parents=True, exist_ok=True)

    # 1. the design problem and the seed's initial topology
    t0 = time.perf_counter()
    prob = design_problem(prm["h_design"], every=prm["beta_every"])
    x0 = initial_design(prob)
    ev0 = prob.evaluate(x0, gradient=False)

    # 2. optimize (MMA, a frame every few iterations, a checkpoint every 10)
    frames = []

    def frame(it, x, ev):
        if it % FRAME_EVERY == 0:
            frames.append(draw_frame(prob, it, x, ev, out / "frames").name)

    res = optimize(prob, method="mma", x0=x0, max_iterations=prm["iterations"], move=0.1, callback=frame,
                   checkpoint=out / "design.npz", checkpoint_every=10)
    t_design = time.perf_counter() - t0
    frames.append(draw_frame(prob, res.iterations, res.x, prob.evaluate(res.x, gradient=False),
                             out / "frames").name)
    plot_history(res.history, out / "history.png")

    # 3. exports: densities (PNG, XDMF) and the three chambers as an extruded STL
    density_png(prob, res.x, out / "density.png")
    write_xdmf(prob, res.x, out / "density.xdmf")
    stl = write_stl(prob, res.x, out / "design.stl", thickness=STL_THICKNESS, pixel=prm["h_design"] / 2)

    # 4. validation: re-mesh the smooth iso-contour and inflate with the hyperelastic Fem; the initial design
    #    through the same pipeline
    t1 = time.perf_counter()
    msh = actuator_mesh(prob, res.x, prm["h_fem"], out, "optimized")
    traj, names = inflate(msh, CHAMBERS, prm["steps"])
    ang = base_rotation(traj.vertices, traj.displacement, *GAUGE)
    msh0 = actuator_mesh(prob, x0, prm["h_fem"], out, "initial")
    traj0, names0 = inflate(msh0, CHAMBERS, prm["steps"])
    ang0 = base_rotation(traj0.vertices, traj0.displacement, *GAUGE)
    t_fem = time.perf_counter() - t1
    plot_inflated(traj, ang[-1], ang0[-1], out / "inflated.png")

    return {
        "iterations": res.iterations,
        "design_cells": prob.n,
        "design_rotation_deg": round(math.degrees(-res.objective), 4),
        "initial_rotation_deg": round(math.degrees(-ev0.objective), 4),
        "volume_fraction": round(res.history[-1]["volume"], 4),
        "flooded_cells": int(prob.flooded.sum()),
        "cavities": len(msh.cavities),
        "pressurized_cavities": len(names),
        "bending_angle_deg": round(float(ang[-1]), 3),
        "bending_angle_initial_deg": round(float(ang0[-1]), 3),
        "reached_pressure_kPa": round(float(traj.times[-1] * PRESSURE / kPa), 3),
        "reached_pressure_initial_kPa": round(float(traj0.times[-1] * PRESSURE / kPa), 3),
        "max_pressure_kPa": PRESSURE / kPa,
        "stl_triangles": stl["triangles"],
        "stl_volume_mm3": round(stl["volume"] / mm**3, 1),
        "frames": len(frames),
        "design_time_s": round(t_design, 2),
        "validation_time_s": round(t_fem, 2),
    }


# ------------------------------------------------------------------------------------------------- the steps
GAUGE = (LENGTH - END - W, LENGTH - END)   # the base's bottom edge under the last chamber [m]: x from, to


def passive_solid(x):
    """Walls kept solid: each chamber's base, top and side walls, and the end cap (x of shape (2, N) [m])."""
    xc = np.mod(x[0], W)
    return (x[1] < BASE) | (x[1] > H - TOP) | (xc < SIDE) | (xc > W - SIDE) | (x[0] > CHAMBERS * W)


def inlet(x):
    """The inlet disks at the centres of the chambers."""
    return ((np.mod(x[0], W) - W / 2) ** 2 + (x[1] - H / 2) ** 2 < INLET_R**2) & (x[0] < CHAMBERS * W)


def chamber_cells(size):
    """Labels linking the cells of the chambers (x of shape (2, N) [m]): a cell and its copies one and two
    chamber widths away share a label (a cell's position in its chamber, in half cells of ``size`` [m]); the
    end cap's cells get labels of their own."""
    def labels(x):
        key = np.round(np.mod(x[0], W) / size * 2).astype(np.int64) * 1_000_000 + np.round(x[1] / size * 2)
        return np.where(x[0] < CHAMBERS * W, key.astype(np.int64), -1 - np.arange(x.shape[1]))
    return labels


def design_problem(size, every=15):
    """The pressure-driven design problem on a structured quadrilateral mesh of the actuator with cell size
    ``size`` [m]; the Heaviside projection's sharpness doubles every ``every`` iterations from 1 to 32."""
    from sorofem.mesh import Mesh
    from sorofem.topopt import Heaviside, PressureActuator

    msh = Mesh.rectangle(LENGTH, H, size, center=(LENGTH / 2, H / 2), cell="quadrilateral")
    msh.add_region("gauge", ([GAUGE[0] - 1e-9, -1e-9], [GAUGE[1] + 1e-9, 1e-9]))
    mat = materials.Elastic80A().with_(nu=0.45)
    prob = PressureActuator(msh, inlet=inlet, pressure=PRESSURE, material=mat, volume_fraction=0.5, penalty=3.0,
                            e_min=1e-3, radius=1.0 * mm, passive_solid=passive_solid, link=chamber_cells(size),
                            projection=Heaviside(beta=1.0, eta=0.5, beta_max=32.0, every=every))
    return prob.add_support("left").set_rotation_output("gauge", clockwise=True)


def initial_design(prob):
    """The seed's initial topology: the volume fraction everywhere, a round hole of radius 5 mm at the centre
    of each chamber."""
    x0 = prob.initial_design()
    c = prob.centroids
    x0[((np.mod(c[:, 0], W) - W / 2) ** 2 + (c[:, 1] - H / 2) ** 2 < HOLE_R**2) & ~prob.solid] = 0.0
    return x0


def pressurized_cavities(msh, chambers):
    """Cavity regions of the re-meshed actuator that contain an inlet (one per chamber)."""
    import dolfinx.mesh

    dom = msh.dolfinx
    out = []
    for name in msh.cavities:
        mid = dolfinx.mesh.compute_midpoints(dom, dom.topology.dim - 1, msh.facets(name))[:, :2]
        lo, hi = mid.min(axis=0), mid.max(axis=0)
        for k in range(chambers):
            p = np.array([W / 2 + k * W, H / 2])
            if np.all(p > lo) and np.all(p < hi):
                out.append(name)
                break
    return out


def base_rotation(X, U, x_a, x_b):
    """Clockwise rotation [deg] of the chord of the base's bottom edge from (x_a, 0) to (x_b, 0), per step
    (the bending of the actuator between the two points, free of the local bulging of the end cap)."""
    a = np.argmin(np.linalg.norm(X[:, :2] - [x_a, 0.0], axis=1))
    b = np.argmin(np.linalg.norm(X[:, :2] - [x_b, 0.0], axis=1))
    d = (X[b, :2] + U[:, b, :2]) - (X[a, :2] + U[:, a, :2])
    return -np.degrees(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))


def actuator_mesh(prob, x, size, workdir, name):
    """Triangle mesh (element size ``size`` [m]) of the actuator of design ``x`` from the smooth iso-contour
    of its densities (:func:`sorofem.topopt.density_image` -> PNG ``actuator_<name>.png`` ->
    :meth:`Mesh.from_image`)."""
    import matplotlib.image

    from sorofem.mesh import Mesh
    from sorofem.topopt import density_image

    img, _, px = density_image(prob, x)
    path = Path(workdir) / f"actuator_{name}.png"
    matplotlib.image.imsave(path, 1.0 - img, cmap="gray", vmin=0.0, vmax=1.0)
    return Mesh.from_image(path, pixel_size=px, threshold=0.5, size=size)


def inflate(msh, chambers, steps):
    """Clamp the left end, pressurize the chambers to 80 kPa with the hyperelastic Fem; returns
    (trajectory, pressurized cavity names)."""
    from sorofem.errors import ConvergenceError
    from sorofem.fem import Fem

    names = pressurized_cavities(msh, chambers)
    fem = Fem(msh, material=materials.Elastic80A(), degree=2)
    fem.add_support("left")
    for c in names:
        fem.add_pressure(c, PRESSURE)
    try:
        traj = fem.solve(steps=steps, max_step=1.0 / steps)
    except ConvergenceError as e:  # keep the converged part (reported through reached_pressure_kPa)
        traj = e.trajectory
    return traj, names


# ------------------------------------------------------------------------------------------------ the figures
def draw_frame(prob, it, x, ev, folder):
    """``frame_KKK.png`` in ``folder``: the design at iteration ``it`` (material black, the flooded chamber's
    cell centres blue, axes in mm); returns its path."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure
    from sorofem.topopt import density_image

    img, lo, px = density_image(prob, x)
    fig = Figure(figsize=(5.2, 3.0))
    ax = fig.subplots()
    ax.imshow(1 - img, cmap="gray", vmin=0, vmax=1, extent=[0, LENGTH / mm, 0, H / mm])
    flo = prob.centroids[prob.flooded] / mm
    ax.plot(flo[:, 0], flo[:, 1], ",", color="tab:blue", alpha=0.5)
    ax.set_title(f"k = {it}, theta = {math.degrees(-ev.objective):.2f} deg", fontsize=8)
    ax.set_xlabel("x [mm]", fontsize=7)
    ax.set_ylabel("y [mm]", fontsize=7)
    ax.tick_params(labelsize=6)
    return save_figure(fig, Path(folder) / f"frame_{it:03d}.png", dpi=90)


def plot_history(hist, path):
    """``history.png``: the design model's bending angle [deg] and the volume fraction per MMA iteration."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5, 3.2))
    ax = fig.subplots()
    ax.plot([h["iteration"] for h in hist], [math.degrees(-h["objective"]) for h in hist], "o-", ms=2)
    ax.set_xlabel("MMA iteration")
    ax.set_ylabel("bending angle at 80 kPa [deg]")
    ax2 = ax.twinx()
    ax2.plot([h["iteration"] for h in hist], [h["volume"] for h in hist], "r--", lw=1)
    ax2.set_ylabel("volume fraction", color="r")
    save_figure(fig, path, dpi=110)


def plot_inflated(traj, angle, angle0, path):
    """``inflated.png``: the validated actuator's mesh [mm], reference (grey) and at the last step (red)."""
    import matplotlib.tri as mtri
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(7, 3.6))
    ax = fig.subplots()
    X, U = traj.vertices, traj.displacement
    for i, color in ((0, "0.7"), (len(traj) - 1, "tab:red")):
        x = (X + U[i]) / mm
        ax.triplot(mtri.Triangulation(x[:, 0], x[:, 1], traj.cells), lw=0.15, color=color)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"optimized chambers at {traj.times[-1] * PRESSURE / kPa:.0f} kPa: bending {angle:.1f} deg "
                 f"(initial design {angle0:.1f} deg)", fontsize=8)
    save_figure(fig, path, dpi=120)
