"""Inflation of a PneuNet bending actuator (`soro demo pneunet_inflation`)
========================================================================

Purpose
-------
A PneuNet (Mosadegh et al., Adv. Funct. Mater. 24, 2163, 2014; the seed paper's Sec. V-D3 and VI-B/E): a row
of chambers in a soft body above a stiffer strain-limiting layer, all at the same pressure. Pressurizing the
chambers lengthens the top of the body, the layer does not stretch, so the actuator curls towards the layer.
The demo ramps the pressure, clamps the left end and reports the bending angle of the free (right) end against
pressure, in 2D plane strain (a side section) and in 3D (the section extruded to the actuator's width, with
closed chambers).

Equations
---------
Quasi-static hyperelasticity with a follower pressure on the cavity surface :math:`\\Gamma_c`
(:mod:`sorofem.fem.problem`):

.. math::

    \\int_\\Omega \\frac{\\partial\\psi}{\\partial F} : \\nabla v\\, dX
    + \\int_{\\Gamma_c} p(t)\\, J F^{-T} N \\cdot v\\, dA = 0, \\qquad p(t) = p_{max}\\, t,

with :math:`u = 0` on the clamped end (``left``). Yeoh body (Ecoflex 00-30) and a Dragon Skin 30
strain-limiting layer (the bottom ``layer`` mm of the base, :meth:`Fem.add_material`), both with the presets'
small-strain Poisson ratio 0.49, P2 displacements (no locking at nu = 0.49 in bending).

The bending angle :math:`\\theta` is the rotation of the free end face: the angle turned by the segment from
the bottom corner :math:`(L, 0)` to :math:`(L, h_{base})` of the base's end face (clockwise = curling
down towards the layer, reported positive).

Parameters
----------
=================  ===========================================  ======================================
body               length L = 80 mm, height 17 mm, 7 chambers    quick: 4 chambers (3D: 2), pitch
                                                                 11.4 mm
chambers           wall 2 mm, gap between blocks 1.5 mm,         one cavity per chamber, all at the
                   height 10 mm, base 5 mm                       same pressure
layer              bottom 2 mm of the base, Dragon Skin 30
body material      Ecoflex 00-30 (Yeoh, Sorotoki coefficients)
3D                 width 15 mm, side walls 2 mm
pressure           0 ... p_max, p_max = 6.5 kPa (2D) / 16 kPa (3D; quick 10 kPa), chosen so that
                   the full actuator bends past 90 degrees
mesh               2D h = 0.8 mm (quick 1.2 mm); 3D h = 3.0 mm (quick 4 mm), P2
=================  ===========================================  ======================================

Walls of neighbouring chambers
------------------------------
The FEM model has no self-contact. The inflated chambers' side walls bulge into the 1.5 mm gaps between the
blocks, and past the pressure where they touch the model lets them pass through each other: its results there
are those of an unphysical body (a real PneuNet's walls press on each other). The report gives the 2D ramp's
least gap at its top pressure and the pressure where the walls first touch (:func:`wall_contact`, with
:func:`soro.ladder.wall_gaps`). Measured (quick: 4 chambers, h = 1.2 mm, P2): they touch at 1.76 kPa and
overlap by 1.57 mm at 6.5 kPa, so the 2D ramp's angles beyond 1.76 kPa (and the 90 degrees of the full run) are
past contact. The pressure is kept: the demo's point is the bending towards 90 degrees, which this geometry
reaches only with its walls pressing on each other, i.e. with self-contact, which the FEM does not model yet
(the ladder's scenes, ``soro.ladder.SCENES``, stop below contact instead).

Steps and limits
----------------
2D: a pressure ramp (:meth:`Fem.solve`) whose first step is cut so that its linear response moves no point by
more than 1 % of the body's size (``linear_start=0.01``): the unloaded thin walls are far softer than the
inflated ones, and the Newton correction of a full first step overshot many times (14 and 11 iterations in
the first steps before); at most 6 iterations per step (quick and full).

3D: the equilibrium path is followed by arc length (:meth:`Fem.follow`, the pressure's load factor an
unknown), each step limited to ``MAX_NEWTON`` = 8 Newton iterations (a step that needs more is halved). The
full 3D actuator (7 chambers, 3 mm mesh) has a pressure maximum at 12.638 kPa (load factor 0.78989 of 16 kPa,
step 29), measured on this path with 4-7 Newton iterations per step (5 in the first); in the three steps past
it the load factor falls to 0.78987, 0.78974 and 0.78949 while the chambers keep inflating, and the path
stops there (52 min on a loaded 2-core machine). This is the inflation instability of thin rubber walls, a
limit point, not a solver failure (the ramp under pressure control stopped at 12.635 kPa, with 16 iterations
in its first step and 9-11 near the maximum): near it no equilibrium carries more than 12.64 kPa, so 16 kPa is
not reached. Whether the Yeoh body's stiffening at much larger stretches brings the pressure back up (a
snap-through to a far more inflated state) is not followed: ten steps past the maximum the load factor was
still falling (0.78586). The report gives the limit pressure (``limit_pressure_kPa_3d``) and the figure marks
it. The quick 3D model (2 chambers, 10 kPa) stays below its maximum and reaches 10 kPa.

Figures (in ``out``)
--------------------
``angle_vs_pressure.png`` (2D and 3D tip angle vs pressure), ``deformed_2d.png`` (reference and inflated
sections), ``deformed_3d.png`` (the inflated 3D actuator's surface coloured by von Mises stress),
``pneunet_2d.h5`` (snapshot of the 2D run). The dict returned holds ``max_pressure_kPa`` (2D),
``max_pressure_kPa_3d`` (the target), ``reached_pressure_kPa_3d`` (the last point of the path),
``limit_pressure_kPa_3d`` and ``limit_angle_deg_3d`` (the 3D path's pressure maximum and the tip angle there,
if it passed one, else null), ``tip_angle_deg_2d``, ``tip_angle_deg_3d``, ``newton_iterations_max``,
``steps_2d``/``steps_3d``, ``dofs_2d``/``dofs_3d``, ``cavities_2d``/``cavities_3d``,
``pressure_at_90deg_kPa_2d`` (interpolated; null if 90 degrees is not reached), ``least_wall_gap_mm_2d`` (the
walls of neighbouring chambers at the 2D ramp's top: negative where they overlap) and ``wall_contact_kPa_2d``
(where they first touch; null if they never do), the Newton iterations per step (``newton_iterations_2d``/``_3d``)
and the wall times.
"""
import math
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

# ------------------------------------------------------------------------------------------------ parameters
WALL, GAP, BASE, HEIGHT, CHANNEL, LAYER, WIDTH = 2 * mm, 1.5 * mm, 5 * mm, 17 * mm, 1.5 * mm, 2 * mm, 15 * mm
PITCH = 80 * mm / 7             # chamber pitch [m]: 7 chambers make the 80 mm actuator
P_MAX_2D = 6.5 * kPa            # the 2D ramp's top pressure [Pa]
LINEAR_START = 0.01             # first step: linear response <= 1 % of the body's size (Fem.solve(linear_start=))
MAX_NEWTON = 8                  # the 3D path: Newton iterations per step at most (a step that needs more is halved)
PAST_LIMIT = 3                  # the 3D path stops this many steps past a pressure maximum (a limit point)
#: The full run and the short one (`--quick`, what the tests run): chambers (2D, 3D), the 3D ramp's top
#: pressure [Pa], element sizes [m] and load steps of the 2D and 3D ramps.
FULL = dict(chambers=7, chambers_3d=7, p_max_3d=16 * kPa, size_2d=0.8 * mm, size_3d=3.0 * mm, steps_2d=30,
            steps_3d=10)
QUICK = dict(chambers=4, chambers_3d=2, p_max_3d=10 * kPa, size_2d=1.2 * mm, size_3d=4.0 * mm, steps_2d=12,
             steps_3d=4)


def main(out: Path, quick: bool = False) -> dict:
    """Inflate the 2D section and the 3D actuator into ``out``; returns the report (see Figures above)."""
    from mpi4py import MPI

    prm = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    p2, p3 = P_MAX_2D, prm["p_max_3d"]

    # 1. the 2D section: mesh, materials, clamp, pressure ramp on every chamber (the snapshot file written)
    fem2, length2 = build(2, prm["chambers"], prm["size_2d"], p2)
    traj2, wall2 = ramp(fem2, prm["steps_2d"])
    traj2.save(out / "pneunet_2d.h5")   # the snapshot file the reduced-order layer reads (every rank calls)

    # 2. the 3D actuator: the same section extruded, closed by side walls
    fem3, length3 = build(3, prm["chambers_3d"], prm["size_3d"], p3)
    traj3, wall3 = follow_path(fem3, prm["steps_3d"])
    if MPI.COMM_WORLD.rank != 0:
        return {}

    # 3. the tip angles against pressure
    a2, pa2 = tip_angle(traj2.vertices, traj2.displacement, length2), traj2.times * p2
    a3, pa3 = tip_angle(traj3.vertices, traj3.displacement, length3), traj3.times * p3
    limit3 = limit_point(traj3.times)
    gaps2, contact2 = wall_contact(traj2.vertices, traj2.displacement, prm["chambers"], pa2)
    summary = {
        "max_pressure_kPa": p2 / kPa,
        "max_pressure_kPa_3d": p3 / kPa,
        "reached_pressure_kPa_2d": float(pa2[-1] / kPa),
        "reached_pressure_kPa_3d": float(pa3[-1] / kPa),
        "limit_pressure_kPa_3d": None if limit3 is None else float(pa3[limit3] / kPa),
        "limit_angle_deg_3d": None if limit3 is None else float(a3[limit3]),
        "tip_angle_deg_2d": float(a2[-1]),
        "tip_angle_deg_3d": float(a3[-1]),
        "pressure_at_90deg_kPa_2d": _kpa(_angle_at(pa2, a2, 90.0)),
        "pressure_at_90deg_kPa_3d": _kpa(_angle_at(pa3, a3, 90.0)),
        "least_wall_gap_mm_2d": float(gaps2[-1] / mm),
        "wall_contact_kPa_2d": _kpa(contact2),
        "newton_iterations_max": int(max(t.newton_iterations[1:].max() for t in (traj2, traj3))),
        "newton_iterations_2d": traj2.newton_iterations[1:].tolist(),
        "newton_iterations_3d": traj3.newton_iterations[1:].tolist(),
        "steps_2d": len(traj2) - 1,
        "steps_3d": len(traj3) - 1,
        "dofs_2d": int(fem2.num_dofs),
        "dofs_3d": int(fem3.num_dofs),
        "cavities_2d": len(fem2.mesh.cavities),
        "cavities_3d": len(fem3.mesh.cavities),
        "chambers": prm["chambers"],
        "chambers_3d": prm["chambers_3d"],
        "wall_time_2d_s": round(wall2, 2),
        "wall_time_3d_s": round(wall3, 2),
    }

    # 4. figures: angle vs pressure, the 2D section's states (colour: pressure), the 3D actuator (von Mises)
    plot_angles(pa2, a2, pa3, a3, limit3, prm["chambers"], out / "angle_vs_pressure.png")
    plot_states_2d(traj2, p2, out / "deformed_2d.png")
    traj3.plot(out / "deformed_3d.png", title=f"3D actuator at {pa3[-1] / kPa:.1f} kPa, von Mises stress")
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def pneunet(chambers=7, pitch=PITCH, dim=2, width=WIDTH):
    """PneuNet geometry [m]: x along the length (from 0), y up (the layer at y = 0), z across (3D, centred).

    2D: the side section; 3D: the section extruded to ``width`` with the chambers closed by side walls of
    ``WALL``. The chambers are separate cavities here (no feed channel): quasi-statically a channel only
    equalizes the pressure, which the demo imposes on every cavity anyway, and in a plane-strain section a
    channel along the base would cut the walls off the strain-limiting layer."""
    length = chambers * pitch
    ch_h = HEIGHT - WALL - BASE
    body = sdf.Rectangle(length, BASE, center=(length / 2, BASE / 2))
    voids = None
    for i in range(chambers):
        xc = (i + 0.5) * pitch
        body = body | sdf.Rectangle(pitch - GAP, HEIGHT - BASE + 1 * mm, center=(xc, (HEIGHT + BASE - 1 * mm) / 2))
        c = sdf.Rectangle(pitch - GAP - 2 * WALL, ch_h, center=(xc, BASE + ch_h / 2))
        voids = c if voids is None else voids | c
    if dim == 2:
        return body - voids, length
    return body.extrude(width) - voids.extrude(width - 2 * WALL), length


def tip_angle(X, U, length):
    """Clockwise rotation [deg] of the end face segment (L, 0) -> (L, BASE), per step (rank 0 arrays)."""
    a = np.argmin(np.linalg.norm(X[:, :2] - [length, 0.0], axis=1) + (np.abs(X[:, 2]) if X.shape[1] == 3 else 0))
    b = np.argmin(np.linalg.norm(X[:, :2] - [length, BASE], axis=1) + (np.abs(X[:, 2]) if X.shape[1] == 3 else 0))
    d = (X[b, :2] + U[:, b, :2]) - (X[a, :2] + U[:, a, :2])
    ang = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    return np.degrees(math.pi / 2 - ang)


def layer_shape(length, dim=2):
    """The strain-limiting layer [m]: the bottom ``LAYER`` of the base, over (a margin beyond) the length and the
    width. The mesh follows its top (``Mesh.from_sdf(interfaces=)``), so the layer is exactly LAYER thick at
    every element size: selected by cell midpoints on a mesh blind to it, its mean thickness was 1.80, 2.01,
    1.99, 1.98, 2.03 mm at h = 2.4 ... 0.15 mm (4 chambers), and the tip moved with it."""
    rect = sdf.Rectangle(length + 2 * mm, LAYER, center=(length / 2, LAYER / 2))
    return rect if dim == 2 else rect.extrude(WIDTH + 2 * mm)


def build(dim, chambers, size, p_max, petsc_options=None, degree=2, mixed=False, grading=None, refine=0):
    """Mesh and model of the actuator (displacement of ``degree`` 1 or 2; ``mixed``: Taylor-Hood P2 with a
    pressure field, :class:`sorofem.fem.Fem`); its mesh follows the layer's top (:func:`layer_shape`), graded
    towards the corners with ``grading`` (:meth:`sorofem.mesh.Mesh.from_sdf`; None: uniform), then split
    uniformly ``refine`` times (:meth:`sorofem.mesh.Mesh.refined`: cells of size/2^refine, nested in the mesh
    of ``size``); returns (fem, length)."""
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    shape, length = pneunet(chambers, dim=dim)
    layer = layer_shape(length, dim)
    msh = Mesh.from_sdf(shape, size=size, interfaces=[layer],      # cell edges on the layer's top, y = LAYER
                        grading=grading)
    if refine:
        msh = msh.refined(refine)
    msh.add_region("layer", layer, kind="cells")
    fem = Fem(msh, material=materials.Ecoflex0030(), degree=degree, mixed=mixed, petsc_options=petsc_options)
    fem.add_material("layer", materials.DragonSkin30())
    fem.add_support("left")
    for c in msh.cavities:
        fem.add_pressure(c, p_max)
    return fem, length


def _kpa(p):
    return None if p is None else p / kPa


def _angle_at(p, ang, target):
    """Pressure [Pa] where the angle first reaches ``target`` (linear interpolation), or None if it never does."""
    for i in range(1, len(ang)):
        if ang[i - 1] < target <= ang[i]:
            return float(p[i - 1] + (p[i] - p[i - 1]) * (target - ang[i - 1]) / (ang[i] - ang[i - 1]))
    return None


def ramp(fem, steps):
    """The pressure ramp 0 -> p_max in at most ``steps`` load steps, the first one cut to a linear response of
    1 % of the body's size (the unloaded thin walls are far softer than the inflated ones, and a full first
    step's Newton correction overshoots many times: 14 and 11 iterations before). Returns ``(trajectory,
    wall time [s])``; a ramp that stops converging (e.g. a chamber wall inverting on a coarse 3D mesh) keeps
    what converged."""
    from sorofem.errors import ConvergenceError

    t0 = time.perf_counter()
    try:
        traj = fem.solve(steps=steps, max_step=1.0 / steps, linear_start=LINEAR_START)
    except ConvergenceError as e:
        traj = e.trajectory
    return traj, time.perf_counter() - t0


def wall_contact(vertices, displacement, chambers, pressure):
    """The walls of neighbouring chambers along a 2D ramp: (the least gap [m] per step, :func:`soro.ladder.wall_gaps`
    over every gap, negative where the walls overlap; the pressure [Pa] at which they first touch, linear between
    the steps, or None if they never do). ``vertices`` (n, 2), ``displacement`` (steps, n, 2) [m], ``pressure``
    (steps,) [Pa]. The FEM model has no self-contact: past that pressure the walls pass through each other."""
    from soro.ladder import wall_gaps

    g = np.array([wall_gaps(vertices, u, chambers).min() for u in np.asarray(displacement)])
    over = np.flatnonzero(g < 0)
    if not len(over):
        return g, None
    k, p = int(over[0]), np.asarray(pressure, dtype=float)
    return g, (float(p[0]) if k == 0 else float(p[k - 1] + (p[k] - p[k - 1]) * g[k - 1] / (g[k - 1] - g[k])))


def limit_point(t):
    """Index of the load factor's maximum along a path ``t`` if the path passed it (a limit point: the steps
    after it have lower load factors), else None."""
    k = int(np.argmax(t))
    return k if k < len(t) - 1 else None


def follow_path(fem, steps):
    """The 3D path by arc length from 0 to the full load (``Fem.follow``), at most ``MAX_NEWTON`` Newton
    iterations per step, about ``steps`` steps to the full load; it stops ``PAST_LIMIT`` steps after a
    pressure maximum. Returns ``(trajectory, wall time [s])``; a path that stops converging keeps what
    converged."""
    from sorofem.errors import ConvergenceError

    def past_limit(traj):
        k = limit_point(traj.times)
        return k is not None and len(traj) - 1 - k >= PAST_LIMIT

    t0 = time.perf_counter()
    try:
        traj = fem.follow(load_level=1.0, steps=steps, max_iterations=MAX_NEWTON, until=past_limit)
    except ConvergenceError as e:
        traj = e.trajectory
    return traj, time.perf_counter() - t0


# ------------------------------------------------------------------------------------------------ the figures
def plot_angles(p2, a2, p3, a3, limit3, chambers, path):
    """``angle_vs_pressure.png``: the tip angles [deg] of the 2D and 3D runs against pressure [kPa], the 3D
    path's limit point (pressure maximum) marked if it passed one."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5.5, 3.8))
    ax = fig.subplots()
    ax.plot(p2 / kPa, a2, "o-", ms=3, label="2D plane strain")
    ax.plot(p3 / kPa, a3, "s-", ms=3, label="3D (arc length)")
    if limit3 is not None:
        ax.plot(p3[limit3] / kPa, a3[limit3], "kv", ms=7, label=f"3D limit point, {p3[limit3] / kPa:.2f} kPa")
    ax.axhline(90, color="k", lw=0.5, ls=":")
    ax.set_xlabel("pressure [kPa]")
    ax.set_ylabel("tip bending angle [deg]")
    ax.set_title(f"PneuNet, {chambers} chambers, Ecoflex 00-30 / Dragon Skin 30 layer", fontsize=9)
    ax.legend()
    save_figure(fig, path, dpi=120)


def plot_states_2d(traj, p_max, path):
    """``deformed_2d.png``: the 2D section's mesh [mm] at five load levels, coloured by pressure [kPa]."""
    import matplotlib.tri as mtri
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    X, U = traj.vertices, traj.displacement
    idx = np.unique(np.linspace(0, len(traj) - 1, 5).round().astype(int))
    colours = ScalarMappable(Normalize(0.0, traj.times[idx[-1]] * p_max / kPa or 1.0), cmap="viridis")
    fig = Figure(figsize=(7, 5))
    ax = fig.subplots()
    for i in idx:
        x = (X + U[i]) / mm
        p = traj.times[i] * p_max / kPa
        ax.triplot(mtri.Triangulation(x[:, 0], x[:, 1], traj.cells), lw=0.2, color=colours.to_rgba(p))
        ax.text(x[:, 0].max(), x[:, 1].min(), f"{p:.1f} kPa", fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title("2D section: reference and inflated states")
    fig.colorbar(colours, ax=ax, label="pressure [kPa]", shrink=0.8)
    save_figure(fig, path, dpi=120)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/pneunet_inflation"),
                          quick="--quick" in sys.argv), indent=2))
