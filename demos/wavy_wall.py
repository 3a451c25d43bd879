r"""Impedance-controlled soft arm: approach a wavy wall, detect contact, explore along it (`soro demo wavy_wall`)
=============================================================================================================

Purpose
-------
The seed's interaction experiment (Sorotoki paper, Sec. VI-D and Figs. 30-33, after Della Santina, Katzschmann
et al. 2020): a six-segment soft arm under Cartesian impedance control (eq. (32)-(33) of the seed) starts free
of a wall inclined by 40 degrees with wave indentations, **approaches** it (Phase 1: its set-point moves
towards a point behind the wall), **detects the contact** from its contact force (the seed's controller reads
``shp.system.fContact``), **switches its set-point** (the seed: "upon contact, a new desired equilibrium position
is adopted") and then **explores** the wall (Phase 2: the set-point slides up the slope behind the surface).
The impedance behaves as a spring :math:`K_c` between the tip and its set-point, so with the set-point
:math:`\delta` behind the surface the tip presses with about :math:`K_c(\delta + r)` (:math:`r` the contact
tube's radius) and follows the indentations without a force sensor.

Figures: the contact force at t = 0 (the start is free: no initial penetration), the contact's detection time
and the set-point switch (the jump of the set-point), the tracking error along the wall during the
exploration, the tip's gap to the surface, the contact force, the real-time factor. PNGs, all lengths in mm:
``wavy_wall.png`` (Fig. 30: the arm on the wall with the active and de-activated set-points; the along-wall
error and the surface gap against time), ``wavy_wall_trajectory.png`` (Fig. 31: the tip's x and z against its
set-points; the contact force and the detection threshold), ``wavy_wall_states.png`` (Fig. 32: the six
curvatures), ``wavy_wall_torques.png`` (Fig. 33: the control torques in mN m).

Equations
---------
*Arm.* The planar arm of :mod:`demos.pcc_arm` hanging from its base along -z: six PCC segments of 60 mm
(334 g each, rounded-rectangle section 20 x 60 mm, Dragon Skin 30), one bending coordinate per segment
(``dofs = (0, 6, 0, 0, 0, 0)``), gravity along -z. Each segment is driven by a generalized torque on its
coordinate (``add_actuator`` with unit columns: the antagonistic chamber pair of a real segment, whose
pressure difference sets that torque), so :math:`G = I` and the inputs are the torques :math:`\tau` [N m].

*Wall.* A slope rising at 40 degrees under the arm's tip: the half-space below the line through
:math:`c` = (0.05, 0, -0.33) m with direction :math:`t = (\cos 40^\circ, 0, \sin 40^\circ)` and outward
normal :math:`n = (-\sin 40^\circ, 0, \cos 40^\circ)`, minus smooth cylindrical grooves (radius 15 mm,
centres 6 mm behind the surface, every 50 mm): an SDF of :mod:`sorofem.sdf`, contact by
:meth:`Shapes.add_contact` (penalty :math:`k` = 2e5 N/m^2 per unit length of the rod's contact tube of radius
10 mm, Coulomb friction :math:`\mu` = 0.1 regularized at 1 mm/s).

*Control.* :func:`soroshapes.control.impedance` (eq. (32)-(33)) on the tip's x and z: :math:`K_c` = 150 N/m,
:math:`D_c` = 15 N s/m, gravity and elastic compensation, Cartesian Coriolis term, null-space damping.

*Start.* The static posture (IK, held by the compensation) whose tip is 30 mm off the surface above the arc
length :math:`s_0` = 20 mm of the wall (20 mm of clearance outside the tube), at rest, set-point at the tip.

*Phase 1, approach.* The set-point moves on a cosine ramp over 0.8 s from the start to
:math:`c + s_0 t - \delta n` (:math:`\delta` = 12 mm behind the surface).

*Contact detection and the switch.* A supervisor samples the contact force every 10 ms (the rate of a
host-side loop) and declares contact when the total contact force on the arm exceeds 0.3 N (2 mm of the
impedance's spring, well above the zero force of the free arm). It then switches the set-point to the new
equilibrium :math:`c + s_c t - \delta n`, :math:`s_c` the tip's arc length along the wall at the detection,
and starts the exploration from there: ``Model.simulate`` continues from the state reached (``t0``).

*Phase 2, explore.* :math:`p_d(t) = c + s(t)\,t - \delta n` with :math:`s(t)` a cosine ramp from :math:`s_c`
up the slope by 150 mm (quick: 60 mm) until the end of the run.

*Integration.* ``Model.simulate`` (compiled network), BDF2, dt = 4 ms; the set-points are
:class:`~soroshapes.network.Schedule` tables sampled at 1 ms.

Figures
-------
``contact_force_t0_N``: the total contact force at t = 0; ``contact_detected_s``: the detection time;
``setpoint_switch_mm``: the set-point's jump at the switch; ``tracking_error_mm``: RMS over the exploration (after
0.3 s of settling) of the along-wall distance between tip and set-point; ``surface_gap_mm``: min/max of the tip's
signed distance to the wall surface minus the tube radius (negative: penetration); ``force_N``: contact force
statistics over the exploration; ``contact_fraction``.
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.errors import ConvergenceError
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
S_START, START_GAP = 20 * mm, 30 * mm                   # the start: arc length along the wall, tip off it [m]
T_APPROACH = 0.8                                        # the approach ramp's duration [s]
SUPERVISOR_DT, F_DETECT = 0.01, 0.3                     # contact detection: sampling [s], threshold [N]
#: Wall contact: penalty [N/m^2], damping [N s/m^2], Coulomb friction [-], regularization [m/s].
CONTACT = dict(stiffness=2e5, damping=50.0, friction=0.1, regularization=1e-3)
#: Cartesian impedance on the tip's x and z: stiffness [N/m], damping [N s/m], null-space damping.
IMPEDANCE = dict(stiffness=150.0, damping=15.0, axes=(0, 2), null_damping=2e-3)
DT, SETPOINT_TABLE_DT = 4e-3, 1e-3                      # step [s]; the set-point's table [s]
SETTLE = 0.3                                            # after the switch, not scored [s]
#: The full run and the short one (`--quick`, what the tests run): simulated time [s], sweep up the slope [m].
FULL = dict(t_end=8.0, sweep=0.15)
QUICK = dict(t_end=3.0, sweep=0.06)


def main(out: Path, quick: bool = False) -> dict:
    """Approach the wall, detect the contact, switch and explore, into ``out``; returns the report (see
    Figures above; four PNGs)."""
    from soroshapes import Model
    from soroshapes.control import impedance
    from soroshapes.network import Schedule

    prm = QUICK if quick else FULL
    T = prm["t_end"]

    # 1. the arm and its start: the static posture whose tip is START_GAP off the wall (IK on positions, then
    #    the compensation holds it), at rest; the contact force there is the check of a free start
    shp = arm()
    obstacle = wall()
    start = CORNER + S_START * T_DIR + START_GAP * N_DIR
    q0 = shp.inverse_kinematics(start, q0=np.full(SEGMENTS, 1.0)).q
    x0 = np.concatenate([q0, np.zeros(SEGMENTS)])
    force_t0 = float(np.linalg.norm(shp.contact_forces(q0, np.zeros(SEGMENTS)).sum(axis=0)))
    approach = Ramp(start, CORNER + S_START * T_DIR - DELTA * N_DIR, 0.0, T_APPROACH)

    # 2. phase 1: approach with the set-point table of the ramp; a supervisor samples the contact force every
    #    SUPERVISOR_DT and stops the phase at the first sample above F_DETECT
    def controller(path):
        return impedance("arm", setpoint=Schedule.sample(path.xz, T, SETPOINT_TABLE_DT), **IMPEDANCE)

    mdl = Model().add(shp, "arm", x0=x0).set_controller(controller(approach))
    wall_s, t, parts, t_contact = 0.0, 0.0, [], None
    while t < T - 1e-9 and t_contact is None:
        t0 = time.perf_counter()
        tr = mdl.simulate(min(SUPERVISOR_DT, T - t), DT, "bdf2", x0=x0, t0=t)
        wall_s += time.perf_counter() - t0
        parts.append(tr)
        t, x0 = float(tr.t[-1]), tr.x[-1].copy()
        if contact_force(shp, x0) > F_DETECT:
            t_contact = t

    # 3. the switch: a new equilibrium behind the surface at the tip's arc length, then phase 2: the set-point
    #    slides up the slope until the end
    if t_contact is None:
        raise ConvergenceError(f"wavy_wall: no contact detected in {T} s of approach: the contact force never "
                               f"exceeded {F_DETECT} N (check START_GAP, T_APPROACH and DELTA)")
    tip = shp.positions(x0[:SEGMENTS])[-1]
    s_c = float((tip - CORNER) @ T_DIR)
    explore = Ramp(CORNER + s_c * T_DIR - DELTA * N_DIR, CORNER + (s_c + prm["sweep"]) * T_DIR - DELTA * N_DIR,
                   t_contact, T)
    jump = np.linalg.norm(explore.xz(t_contact) - approach.xz(t_contact))
    mdl.set_controller(controller(explore))
    t0 = time.perf_counter()
    parts.append(mdl.simulate(T - t_contact, DT, "bdf2", x0=x0, t0=t_contact))
    wall_s += time.perf_counter() - t0

    # 4. the whole run: tip, set-points, contact force; tracking along the wall and the gap in phase 2
    tt = np.concatenate([parts[0].t] + [p.t[1:] for p in parts[1:]])
    q = np.vstack([parts[0]["arm"].q] + [p["arm"].q[1:] for p in parts[1:]])
    qd = np.vstack([parts[0]["arm"].qd] + [p["arm"].qd[1:] for p in parts[1:]])
    tau = np.vstack([parts[0]["arm"].u] + [p["arm"].u[1:] for p in parts[1:]])
    tips = np.array([shp.positions(qi)[-1] for qi in q])
    force = np.array([contact_force(shp, np.concatenate([qi, qdi])) for qi, qdi in zip(q, qd)])
    setpoints = np.array([approach.xz(ti) if ti <= t_contact else explore.xz(ti) for ti in tt])
    along = (tips - CORNER) @ T_DIR - np.array([explore.arc(ti, CORNER, T_DIR) for ti in tt])
    gap = obstacle(tips) - RADIUS
    scored = tt > t_contact + SETTLE
    in_contact = force > 1e-3

    # 5. figures [mm]: the arm on the wall (Fig. 30), the tip against its set-points (Fig. 31), the states
    #    (Fig. 32), the torques (Fig. 33)
    plot_wall(shp, obstacle, tt, q, tips, setpoints, along, gap, t_contact, approach, explore, out / "wavy_wall.png")
    plot_trajectory(tt, tips, setpoints, force, t_contact, out / "wavy_wall_trajectory.png")
    plot_states(tt, q, t_contact, out / "wavy_wall_states.png")
    plot_torques(tt, tau, t_contact, out / "wavy_wall_torques.png")
    return {
        "contact_force_t0_N": round(force_t0, 6),
        "start_gap_mm": round(float(obstacle(start[None])[0] - RADIUS) / mm, 3),
        "contact_detected_s": round(t_contact, 4), "detection_threshold_N": F_DETECT,
        "setpoint_switch_mm": round(float(jump) / mm, 3), "contact_arc_mm": round(s_c / mm, 3),
        "tracking_error_mm": round(float(np.sqrt(np.mean(along[scored] ** 2))) / mm, 3),
        "tracking_error_max_mm": round(float(np.abs(along[scored]).max()) / mm, 3),
        "surface_gap_mm": [round(float(gap[scored].min()) / mm, 3), round(float(gap[scored].max()) / mm, 3)],
        "force_N": {"mean": round(float(force[scored].mean()), 5), "min": round(float(force[scored].min()), 5),
                    "max": round(float(force[scored].max()), 5), "max_run": round(float(force.max()), 5),
                    "nominal": IMPEDANCE["stiffness"] * (DELTA + RADIUS)},
        "torque_peak_mNm": round(float(np.abs(tau).max()) * 1e3, 3),
        "contact_fraction": round(float(in_contact[scored].mean()), 4),
        "sweep_mm": round(prm["sweep"] / mm, 1), "simulated_s": T, "wall_time_s_sim": round(wall_s, 2),
        "real_time_factor": round(T / wall_s, 3), "evaluation_path": parts[-1].stats.get("path"),
        "png": "wavy_wall.png",
        "pngs": ["wavy_wall.png", "wavy_wall_trajectory.png", "wavy_wall_states.png", "wavy_wall_torques.png"],
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


def contact_force(shp, x):
    """The total contact force [N] on the arm at state x = (q, qd): what the supervisor compares with F_DETECT."""
    q, qd = x[:SEGMENTS], x[SEGMENTS:]
    return float(np.linalg.norm(shp.contact_forces(q, qd).sum(axis=0)))


class Ramp:
    """A set-point path: a cosine ramp from ``a`` to ``b`` (3D points [m]) over [t0, t1] [s], held before and
    after; ``xz(t)`` its (x, z) [m], ``arc(t, c, t_dir)`` its arc length along the wall from ``c`` [m]."""

    def __init__(self, a, b, t0, t1):
        self.a, self.b, self.t0, self.t1 = np.asarray(a, float), np.asarray(b, float), float(t0), float(t1)

    def point(self, t):
        r = min(max((t - self.t0) / (self.t1 - self.t0), 0.0), 1.0)
        return self.a + (self.b - self.a) * 0.5 * (1 - np.cos(np.pi * r))

    def xz(self, t):
        return self.point(t)[[0, 2]]

    def arc(self, t, c, t_dir):
        return float((self.point(t) - c) @ t_dir)


# ------------------------------------------------------------------------------------------------ the figures
def _phases(ax, t_contact):
    ax.axvspan(0.0, t_contact, color="0.92", lw=0)
    ax.axvline(t_contact, color="C3", lw=0.8, ls=":")
    ax.grid(alpha=0.3)


def plot_wall(shp, obstacle, tt, q, tips, setpoints, along, gap, t_contact, approach, explore, path):
    """``wavy_wall.png`` (Fig. 30): the wall's section (grey), the arm at six instants, the tip's path, the
    approach set-point (de-activated at the switch, open marks) and the exploration's set-points (filled) [mm];
    the along-wall error and the tip's gap to the surface [mm] against time (shaded: the approach)."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4.6))
    ax, bx = fig.subplots(1, 2)
    xs, zs = np.meshgrid(np.linspace(-0.1, 0.3, 300), np.linspace(-0.42, 0.02, 300))
    pts = np.column_stack([xs.ravel(), np.zeros(xs.size), zs.ravel()])
    ax.contourf(xs / mm, zs / mm, obstacle(pts).reshape(xs.shape), levels=[-1, 0], colors=["0.8"])
    for k in np.linspace(0, len(q) - 1, 6).astype(int):
        P = shp.positions(q[k]) / mm
        ax.plot(P[:, 0], P[:, 2], lw=3, alpha=0.4 + 0.6 * k / len(q), color="C0")
    ax.plot(tips[:, 0] / mm, tips[:, 2] / mm, "C1", lw=1, label="tip")
    a = np.array([approach.xz(t) for t in np.linspace(0.0, t_contact, 6)]) / mm
    ax.plot(a[:, 0], a[:, 1], "o", mfc="none", color="k", ms=5, label="approach set-points (de-activated)")
    e = np.array([explore.xz(t) for t in np.linspace(t_contact, tt[-1], 8)]) / mm
    ax.plot(e[:, 0], e[:, 1], "o", color="C3", ms=4, label="exploration set-points")
    ax.set(aspect="equal", xlabel="x [mm]", ylabel="z [mm]", title="impedance control on a wavy wall")
    ax.legend(fontsize=7, loc="lower left")
    explored = tt >= t_contact                        # the along-wall error is that of the exploration's set-point
    bx.plot(tt[explored], along[explored] / mm, label="along-wall error, tip - set-point [mm]")
    bx.plot(tt, gap / mm, label="gap of the tube to the surface [mm]")
    _phases(bx, t_contact)
    bx.set(xlabel="t [s]", ylabel="[mm]", title="approach (shaded), contact detected (dotted), explore")
    bx.legend(fontsize=8)
    save_figure(fig, path)


def plot_trajectory(tt, tips, setpoints, force, t_contact, path):
    """``wavy_wall_trajectory.png`` (Fig. 31): the tip's x and z [mm] against time, the set-points dashed; the
    total contact force [N] and the detection threshold."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4.2))
    ax, bx = fig.subplots(1, 2)
    for i, (k, name) in enumerate(((0, "x"), (2, "z"))):
        ax.plot(tt, tips[:, k] / mm, f"C{i}", label=f"tip {name}")
        ax.plot(tt, setpoints[:, i] / mm, f"C{i}--", lw=1, label=f"set-point {name}")
    _phases(ax, t_contact)
    ax.set(xlabel="t [s]", ylabel="position [mm]", title="end-effector and set-points")
    ax.legend(fontsize=8)
    bx.plot(tt, force, "C2", label="contact force")
    bx.axhline(F_DETECT, color="k", lw=0.8, ls="--", label=f"detection threshold {F_DETECT} N")
    _phases(bx, t_contact)
    bx.set(xlabel="t [s]", ylabel="force [N]", title="contact force")
    bx.legend(fontsize=8)
    save_figure(fig, path)


def plot_states(tt, q, t_contact, path):
    """``wavy_wall_states.png`` (Fig. 32): the curvature of each segment [1/m] against time."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for i in range(q.shape[1]):
        ax.plot(tt, q[:, i], label=f"segment {i + 1}")
    _phases(ax, t_contact)
    ax.set(xlabel="t [s]", ylabel="curvature [1/m]", title="states: planar curvature of each segment")
    ax.legend(fontsize=7, ncol=2)
    save_figure(fig, path)


def plot_torques(tt, tau, t_contact, path):
    """``wavy_wall_torques.png`` (Fig. 33): the control torque of each segment [mN m] against time."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for i in range(tau.shape[1]):
        ax.plot(tt, tau[:, i] * 1e3, label=f"segment {i + 1}")
    _phases(ax, t_contact)
    ax.set(xlabel="t [s]", ylabel="torque [mN m]", title="control torques of eq. (32)")
    ax.legend(fontsize=7, ncol=2)
    save_figure(fig, path)


# ------------------------------------------------------------------------------------------- soro play scene
def scene(quick=False):
    """``soro play wavy_wall``: the hanging arm against the grooved wall, one torque slider [N m] per segment,
    the contact forces drawn, a target at the tip for IK or for the demo's Cartesian impedance controller."""
    from soro.play import Channel, Scene, Target
    from soroshapes import Model

    shp = arm()
    start = CORNER + S_START * T_DIR + START_GAP * N_DIR     # the demo's start: the tip free of the wall
    ik = shp.inverse_kinematics(start, q0=np.full(SEGMENTS, 1.0))
    mdl = Model().add(shp, "arm", x0=np.concatenate([ik.q, np.zeros(SEGMENTS)]))
    channels = [Channel(f"arm.segment{i}", -2.0, 2.0, "N m", label=f"segment {i} torque") for i in range(SEGMENTS)]
    return Scene(mdl, channels, target=Target(tuple(start), beam="arm"), obstacles=(wall(),),
                 dt=DT, method="bdf2", view=(0.0, 0.0), title="wavy_wall",
                 impedance=dict(IMPEDANCE))
