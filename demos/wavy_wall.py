r"""Impedance-controlled soft arm sliding along a wavy wall (`soro demo wavy_wall`)
===========================================================================

Purpose
-------
The seed's interaction experiment (Sorotoki paper, Sec. VI, after Della Santina, Katzschmann et al. 2020):
a six-segment soft arm under Cartesian impedance control keeps its tip on a wall inclined by 40 degrees
with wave indentations, while its set-point slides along the wall. The impedance controller is what makes
this possible without a force sensor: it behaves as a spring :math:`K_c` between the tip and a set-point
placed :math:`\delta` behind the wall's surface, so the tip presses with about :math:`K_c(\delta + r)`
(:math:`r` the radius of the contact tube around the backbone) and
follows the indentations by itself. Figures: tracking error along the wall, the tip's distance to the
wall's surface (penetration of the contact tube), the contact force (mean, min, max over the sweep, and
the fraction of time in contact), the real-time factor; PNG of the arm on the wall and the force history.

Equations
---------
*Arm.* The planar arm of :mod:`demos.pcc_arm` hanging from its base along -z: six PCC segments of 60 mm
(334 g each, rounded-rectangle section 20 x 60 mm, Dragon Skin 30), one bending coordinate per segment
(``dofs = (0, 6, 0, 0, 0, 0)``), gravity along -z. Each segment is driven by a generalized torque on its
coordinate (``add_actuator`` with unit columns: the antagonistic chamber pair of a real segment, whose
pressure difference sets that torque), so :math:`G = I`.

*Wall.* A slope rising at 40 degrees under the arm's tip: the half-space below the line through
:math:`c` = (0.05, 0, -0.33) m with direction :math:`t = (\cos 40^\circ, 0, \sin 40^\circ)` and outward
normal :math:`n = (-\sin 40^\circ, 0, \cos 40^\circ)`, minus smooth cylindrical grooves (radius 15 mm,
centres 6 mm behind the surface, every 50 mm, the first at 25 mm): an SDF of :mod:`sorofem.sdf`, contact by :meth:`Shapes.add_contact` (penalty
:math:`k` = 2e5 N/m^2 per unit length of the rod's contact tube, radius 10 mm at the tip region, Coulomb
friction :math:`\mu` = 0.1 regularized at 1 mm/s).

*Control.* :func:`soroshapes.control.impedance` (eq. (32)-(33) of the seed) on the tip's x and z:
:math:`K_c` = 150 N/m, :math:`D_c` = 15 N s/m, gravity and elastic compensation, Cartesian Coriolis term,
null-space damping. Set-point :math:`p_d(t) = c + s(t)\,t - \delta n` with :math:`\delta` = 12 mm and
:math:`s(t)` a smooth (cosine) ramp from 0 to 150 mm up the slope over the sweep (quick: to 60 mm).

*Integration.* ``Model.simulate`` with BDF2, dt = 4 ms.

Figures
-------
``tracking_error_mm``: RMS over the sweep of the along-wall distance between tip and set-point;
``surface_gap_mm``: min/max of the tip's signed distance to the wall surface minus the tube radius (negative:
penetration); ``force_N``: contact force statistics; ``contact_fraction``.
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

# ------------------------------------------------------------------------------------------------ parameters
SEGMENTS, SEG_LEN, SEG_MASS = 6, 60 * mm, 0.334        # PCC segments, length [m], mass [kg]
WIDTH, HEIGHT = 20 * mm, 60 * mm                        # section [m]
ANGLE = np.radians(40.0)                                # the wall's slope [rad]
T_DIR = np.array([np.cos(ANGLE), 0.0, np.sin(ANGLE)])   # along the wall, up the slope
N_DIR = np.array([-np.sin(ANGLE), 0.0, np.cos(ANGLE)])  # the wall's outward normal
CORNER = np.array([0.05, 0.0, -0.33])                   # a point of the wall's surface [m]
DELTA = 12 * mm                                         # the set-point behind the surface [m]
RADIUS = 10 * mm                                        # contact tube [m]
#: Wall contact: penalty [N/m^2], damping [N s/m^2], Coulomb friction [-], regularization [m/s].
CONTACT = dict(stiffness=2e5, damping=50.0, friction=0.1, regularization=1e-3)
#: Cartesian impedance on the tip's x and z: stiffness [N/m], damping [N s/m], null-space damping.
IMPEDANCE = dict(stiffness=150.0, damping=15.0, axes=(0, 2), null_damping=2e-3)
DT, SETPOINT_TABLE_DT = 4e-3, 1e-3                      # step [s]; the set-point's table [s]
SETTLE = 0.3                                            # the tip settling into contact [s], not scored
#: The full run and the short one (`--quick`, what the tests run): simulated time [s], sweep up the slope [m].
FULL = dict(t_end=8.0, sweep=0.15)
QUICK = dict(t_end=3.0, sweep=0.06)


def main(out: Path, quick: bool = False) -> dict:
    """Slide the tip along the wall into ``out``; returns the report (see Figures above; ``wavy_wall.png``)."""
    from soroshapes import Model
    from soroshapes.control import impedance
    from soroshapes.network import Schedule

    prm = QUICK if quick else FULL
    T = prm["t_end"]
    sweep = Sweep(T, 0.0, prm["sweep"])

    # 1. the arm and its start: the static posture whose tip is just off the wall (IK on positions, then the
    #    compensation holds it), at rest
    shp = arm()
    obstacle = wall()
    start = CORNER + sweep.s0 * T_DIR + 2 * mm * N_DIR
    ik = shp.inverse_kinematics(start, q0=np.full(SEGMENTS, 1.0))

    # 2. the impedance controller following the set-point, as a table sampled at a quarter of the step (linear
    #    interpolation within 1e-7 m of the cosine ramp): a Schedule runs compiled inside the network, a Python
    #    callable would not
    ctrl = impedance("arm", setpoint=Schedule.sample(sweep.setpoint, T, SETPOINT_TABLE_DT), **IMPEDANCE)
    mdl = Model().add(shp, "arm", x0=np.concatenate([ik.q, np.zeros(SEGMENTS)])).set_controller(ctrl)

    # 3. simulate
    t0 = time.perf_counter()
    tr = mdl.simulate(T, DT, "bdf2")
    wall_s = time.perf_counter() - t0

    # 4. tracking along the wall, the gap to its surface, the contact force
    q, qd = tr["arm"].q, tr["arm"].qd
    tips = np.array([shp.positions(qi)[-1] for qi in q])
    force = np.array([np.linalg.norm(shp.contact_forces(qi, qdi).sum(axis=0)) for qi, qdi in zip(q, qd)])
    along = (tips - CORNER) @ T_DIR - np.array([sweep.arc(t) for t in tr.t])
    gap = obstacle(tips) - RADIUS
    scored = tr.t > SETTLE
    in_contact = force > 1e-3

    # 5. figure: the arm on the wall [mm], force and error against time
    plot(shp, obstacle, tr, tips, force, along, sweep, out / "wavy_wall.png")
    return {
        "tracking_error_mm": round(float(np.sqrt(np.mean(along[scored] ** 2))) / mm, 3),
        "tracking_error_max_mm": round(float(np.abs(along[scored]).max()) / mm, 3),
        "surface_gap_mm": [round(float(gap[scored].min()) / mm, 3), round(float(gap[scored].max()) / mm, 3)],
        "force_N": {"mean": round(float(force[scored].mean()), 4), "min": round(float(force[scored].min()), 4),
                    "max": round(float(force[scored].max()), 4),
                    "nominal": IMPEDANCE["stiffness"] * (DELTA + RADIUS)},
        "contact_fraction": round(float(in_contact[scored].mean()), 4),
        "sweep_mm": round((sweep.s1 - sweep.s0) / mm, 1), "simulated_s": T, "wall_time_s_sim": round(wall_s, 2),
        "real_time_factor": round(T / wall_s, 3), "evaluation_path": tr.stats.get("path"),
        "png": "wavy_wall.png",
    }


# ------------------------------------------------------------------------------------------------- the steps
def wall():
    """The inclined wall with grooves (3D SDF, solid behind the surface)."""
    plane = sdf.Plane(point=tuple(CORNER), normal=tuple(N_DIR))
    grooves = None
    for s in np.arange(-0.075, 0.40, 0.05):
        c = CORNER + s * T_DIR - 6 * mm * N_DIR
        g = sdf.Cylinder(15 * mm, 0.3, center=tuple(c), axis=(0.0, 1.0, 0.0))
        grooves = g if grooves is None else grooves | g
    return plane.smooth_difference(grooves, 4 * mm)


def arm():
    """The hanging arm with one torque actuator per segment and contact with the wall."""
    from sorofem.sdf.properties import section_properties
    from soroshapes import Basis, Shapes

    section = sdf.RoundedRectangle(WIDTH, HEIGHT)
    density = SEG_MASS / (section_properties(section).area * SEG_LEN)
    down = np.eye(4)
    down[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]      # body x (the rod axis) along spatial -z
    shp = Shapes(Basis.pcc(SEGMENTS), dofs=(0, SEGMENTS, 0, 0, 0, 0), length=SEGMENTS * SEG_LEN,
                 section=section, material=materials.DragonSkin30(density=density), segments=4 * SEGMENTS,
                 base=down, contact_radius=RADIUS)
    shp.add_gravity((0.0, 0.0, -9.81))
    for i in range(SEGMENTS):
        shp.add_actuator(np.eye(SEGMENTS)[i], name=f"segment{i}")
    shp.add_contact(wall(), **CONTACT)
    return shp


class Sweep:
    """The set-point's path: arc length ``s(t)`` [m] up the slope, a cosine ramp from ``s0`` to ``s1`` over
    ``t_end`` [s]; the set-point ``c + s(t) t - delta n`` in the (x, z) plane."""

    def __init__(self, t_end, s0, s1):
        self.t_end, self.s0, self.s1 = t_end, s0, s1

    def arc(self, t):
        return self.s0 + (self.s1 - self.s0) * 0.5 * (1 - np.cos(np.pi * min(max(t / self.t_end, 0.0), 1.0)))

    def setpoint(self, t):
        p = CORNER + self.arc(t) * T_DIR - DELTA * N_DIR
        return p[[0, 2]]


# ------------------------------------------------------------------------------------------------ the figures
def plot(shp, obstacle, tr, tips, force, along, sweep, path):
    """``wavy_wall.png``: the wall's section (grey), the arm at six instants, the tip's path and the set-point
    [mm]; the contact force [N] and the along-wall error [mm] against time."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    q = tr["arm"].q
    fig = Figure(figsize=(11, 4.6))
    ax, bx = fig.subplots(1, 2)
    xs, zs = np.meshgrid(np.linspace(-0.1, 0.3, 300), np.linspace(-0.42, 0.02, 300))
    pts = np.column_stack([xs.ravel(), np.zeros(xs.size), zs.ravel()])
    ax.contourf(xs / mm, zs / mm, obstacle(pts).reshape(xs.shape), levels=[-1, 0], colors=["0.8"])
    for k in np.linspace(0, len(q) - 1, 6).astype(int):
        P = shp.positions(q[k]) / mm
        ax.plot(P[:, 0], P[:, 2], lw=3, alpha=0.4 + 0.6 * k / len(q), color="C0")
    ax.plot(tips[:, 0] / mm, tips[:, 2] / mm, "C1", lw=1, label="tip")
    sp = np.array([sweep.setpoint(t) for t in tr.t]) / mm
    ax.plot(sp[:, 0], sp[:, 1], "k--", lw=0.8, label="set-point (behind the wall)")
    ax.set(aspect="equal", xlabel="x [mm]", ylabel="z [mm]", title="impedance control on a wavy wall")
    ax.legend(fontsize=7, loc="lower left")
    bx.plot(tr.t, force, label="contact force [N]")
    bx.plot(tr.t, 1e3 * along, label="along-wall error [mm]")
    bx.set(xlabel="t [s]")
    bx.legend(fontsize=8)
    bx.grid(alpha=0.3)
    save_figure(fig, path)


# ------------------------------------------------------------------------------------------- soro play scene
def scene(quick=False):
    """``soro play wavy_wall``: the hanging arm against the grooved wall, one torque slider [N m] per segment,
    the contact forces drawn, a target at the tip for IK or for the demo's Cartesian impedance controller."""
    from soro.play import Channel, Scene, Target
    from soroshapes import Model

    shp = arm()
    start = CORNER + 2 * mm * N_DIR                         # the demo's start: the tip just off the wall
    ik = shp.inverse_kinematics(start, q0=np.full(SEGMENTS, 1.0))
    mdl = Model().add(shp, "arm", x0=np.concatenate([ik.q, np.zeros(SEGMENTS)]))
    channels = [Channel(f"arm.segment{i}", -2.0, 2.0, "N m", label=f"segment {i} torque") for i in range(SEGMENTS)]
    return Scene(mdl, channels, target=Target(tuple(start), beam="arm"), obstacles=(wall(),),
                 dt=DT, method="bdf2", view=(0.0, 0.0), title="wavy_wall",
                 impedance=dict(IMPEDANCE))
