"""Inverse design of a PneuNet chamber by topology optimization (`soro demo pneunet_design`)
=========================================================================================

Purpose
-------
The seed paper's Sec. VI-B: find the material layout of one PneuNet chamber that bends the most when
pressurized, print it, and check it by simulation. A 15 x 30 mm design domain (one chamber of the actuator,
x along the actuator, y up) of Formlabs Elastic 80A is clamped on its left face; the fluid enters at the
centre. SIMP densities, a Helmholtz filter and MMA update the layout; at every design the void cells
connected to the inlet (flood fill) carry the pressure. The optimized chamber is exported (density PNG and
XDMF, an extruded STL of the smooth iso-contour), re-meshed from its iso-contour as a three-chamber actuator
(with a 1.5 mm end cap) and inflated with the hyperelastic :class:`~sorofem.fem.Fem` (P2, the full
material), which must bend toward the base. The initial design (a round 5 mm hole, the seed's
``initialTopology``) goes through the same pipeline for comparison.

Equations
---------
Design problem (:mod:`sorofem.topopt.problems`), geometrically nonlinear, plane strain:

.. math::

    \\min_{x}\\; -\\theta(u) \\quad\\text{s.t.}\\quad R(u, \\bar\\rho) = 0,\\quad
    \\frac{\\sum_e v_e\\bar\\rho_e}{|\\Omega|} \\le f,\\quad 0 \\le x \\le 1,

    R = \\int_\\Omega (\\varepsilon + (1-\\varepsilon)\\bar\\rho^3)\\frac{\\partial\\psi}{\\partial F}:\\nabla v
        + \\frac{k}{|\\Gamma_r|}\\int_{\\Gamma_r} u_x v_x
        - p\\int_{\\Omega_p} (1-\\bar\\rho)^2 J F^{-T}:\\nabla v,

with :math:`\\bar\\rho` the filtered (Helmholtz, :math:`-r^2\\Delta\\tilde\\rho + \\tilde\\rho = x`) and
projected (smoothed Heaviside, so that the iso-contour that is printed is the design that was analysed) densities,
:math:`\\Omega_p` the flood-filled chamber (cells with :math:`\\bar\\rho < 0.5` connected to the inlet),
:math:`\\theta` the clockwise rotation of the free (right) face :math:`\\Gamma_r`, which carries a spring
:math:`k` standing for the next chamber. Sensitivities by the adjoint method; MMA (Svanberg).

Parameters
----------
===================  ==========================================================================
domain               15 mm (x) x 30 mm (y); passive solid base 2 mm, top wall 1 mm, side walls 0.75 mm
inlet                disk of radius 1.5 mm at the centre (passive void); initial hole radius 5 mm
material             Elastic 80A (Neo-Hookean, E = 9.35 MPa); design model nu = 0.45 (Q1 cells lock
                     at 0.49), validation nu = 0.49 with P2 triangles
pressure             80 kPa (the seed's validation ramp)
SIMP                 p = 3, epsilon = 1e-3, volume fraction <= 0.5, filter radius 1 mm, Heaviside
                     projection eta = 0.5, beta 1 -> 8 (doubled every 20 iterations; quick: 10)
spring               k = 0.1 E on the right face (x)
mesh                 design h = 0.375 mm (quick: 0.5 mm) quadrilaterals; validation h = 0.5 mm
                     (quick: 0.75 mm), three chambers side by side
iterations           100 (quick: 30) MMA iterations, move 0.1
===================  ==========================================================================

Figures (in ``out``)
--------------------
``frames/frame_KKK.png`` (the design every few iterations), ``history.png`` (objective and volume),
``density.png`` and ``density.xdmf`` (the final densities), ``design.stl`` (three chambers extruded to 15 mm),
``inflated.png`` (the validated actuator, reference and inflated), ``actuator_optimized.png`` and
``actuator_initial.png`` (the three chambers of each design and an end cap of 1.5 mm, the images that are
re-meshed), ``design.npz`` (restartable design).
The dict returned holds ``iterations``, ``design_rotation_deg`` (the design model's face rotation),
``initial_rotation_deg``, ``volume_fraction``, ``flooded_cells``, ``cavities`` (of the re-meshed actuator),
``pressurized_cavities``, ``bending_angle_deg`` (the validated 3-chamber actuator at 80 kPa: the clockwise
rotation, toward the base, of the bottom chord under the last chamber; the clamp keeps the first chord's
rotation near zero), ``bending_angle_initial_deg`` (the initial design through the same pipeline),
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
STL_THICKNESS = 15 * mm         # the STL's extrusion [m]
FRAME_EVERY = 5                 # a frame of the design every 5 iterations
#: The full run and the short one (`--quick`, what the tests run): design and validation element sizes [m],
#: MMA iterations, iterations between doublings of the projection's sharpness, validation load steps.
FULL = dict(h_design=0.375 * mm, h_fem=0.5 * mm, iterations=100, beta_every=20, steps=16)
QUICK = dict(h_design=0.5 * mm, h_fem=0.75 * mm, iterations=30, beta_every=10, steps=8)


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
    stl = write_stl(prob, res.x, out / "design.stl", thickness=STL_THICKNESS, tiles=CHAMBERS,
                    pixel=prm["h_design"] / 2)

    # 4. validation: re-mesh the smooth iso-contour (three chambers) and inflate with the hyperelastic Fem;
    #    the initial design through the same pipeline
    t1 = time.perf_counter()
    length = CHAMBERS * W + END
    msh = actuator_mesh(prob, res.x, prm["h_fem"], CHAMBERS, out, "optimized")
    traj, names = inflate(msh, CHAMBERS, prm["steps"])
    ang = base_rotation(traj.vertices, traj.displacement, length - END - W, length - END)
    msh0 = actuator_mesh(prob, x0, prm["h_fem"], CHAMBERS, out, "initial")
    traj0, names0 = inflate(msh0, CHAMBERS, prm["steps"])
    ang0 = base_rotation(traj0.vertices, traj0.displacement, length - END - W, length - END)
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
def passive_solid(x):
    """Walls kept solid: base, top and side walls (x of shape (2, N) [m])."""
    return (x[1] < BASE) | (x[1] > H - TOP) | (x[0] < SIDE) | (x[0] > W - SIDE)


def inlet(x):
    """The inlet disk at the centre of the domain."""
    return (x[0] - W / 2) ** 2 + (x[1] - H / 2) ** 2 < INLET_R**2


def design_problem(size, every=20):
    """The pressure-driven design problem on a structured quadrilateral mesh of cell size ``size`` [m]; the
    Heaviside projection's sharpness doubles every ``every`` iterations from 1 to 8."""
    from sorofem.mesh import Mesh
    from sorofem.topopt import Heaviside, PressureActuator

    msh = Mesh.rectangle(W, H, size, center=(W / 2, H / 2), cell="quadrilateral")
    mat = materials.Elastic80A().with_(nu=0.45)
    prob = PressureActuator(msh, inlet=inlet, pressure=PRESSURE, material=mat, volume_fraction=0.5, penalty=3.0,
                            e_min=1e-3, radius=1.0 * mm, passive_solid=passive_solid,
                            projection=Heaviside(beta=1.0, eta=0.5, beta_max=8.0, every=every))
    prob.add_support("left").set_rotation_output("right", clockwise=True)
    prob.add_spring("right", 0.1 * mat.E, (1.0, 0.0))
    return prob


def initial_design(prob):
    """The seed's initial topology: the volume fraction everywhere, a round hole of radius 5 mm at the centre."""
    x0 = prob.initial_design()
    c = prob.centroids
    x0[((c[:, 0] - W / 2) ** 2 + (c[:, 1] - H / 2) ** 2 < HOLE_R**2) & ~prob.solid] = 0.0
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


def actuator_mesh(prob, x, size, chambers, workdir, name):
    """Mesh of ``chambers`` copies of the design side by side, closed by an end cap of ``END`` on the right
    (the free end wall of a PneuNet is thicker than the walls between chambers), from the smooth iso-contour
    of the densities (:func:`sorofem.topopt.density_image` -> PNG ``actuator_<name>.png`` ->
    :meth:`Mesh.from_image`)."""
    import matplotlib.image

    from sorofem.mesh import Mesh
    from sorofem.topopt import density_image

    img, _, px = density_image(prob, x)
    img = np.tile(img, (1, chambers))
    cap = np.ones((img.shape[0], int(round(END / px))))
    img = np.hstack([img, cap])
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
    fig = Figure(figsize=(2.4, 4.2))
    ax = fig.subplots()
    ax.imshow(1 - img, cmap="gray", vmin=0, vmax=1, extent=[0, W / mm, 0, H / mm])
    flo = prob.centroids[prob.flooded] / mm
    ax.plot(flo[:, 0], flo[:, 1], ",", color="tab:blue", alpha=0.5)
    ax.set_title(f"k = {it}, theta = {math.degrees(-ev.objective):.2f} deg", fontsize=8)
    ax.set_xlabel("x [mm]", fontsize=7)
    ax.set_ylabel("y [mm]", fontsize=7)
    ax.tick_params(labelsize=6)
    return save_figure(fig, Path(folder) / f"frame_{it:03d}.png", dpi=90)


def plot_history(hist, path):
    """``history.png``: the design model's face rotation [deg] and the volume fraction per MMA iteration."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5, 3.2))
    ax = fig.subplots()
    ax.plot([h["iteration"] for h in hist], [math.degrees(-h["objective"]) for h in hist], "o-", ms=2)
    ax.set_xlabel("MMA iteration")
    ax.set_ylabel("face rotation [deg]")
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
