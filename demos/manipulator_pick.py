r"""Soft manipulator with a gripper picks a rigid cylinder and places it (`soro demo manipulator_pick`)
===============================================================================================

Purpose
-------
The seed's manipulator case (Sorotoki paper, Sec. V-F, Fig. 16-17): a soft robot manipulator with a soft
gripper at its tip picks a 40 mm cylinder of 45 g from a table and puts it down at another place; the
cylinder is a Newton-Euler rigid body. Here: the manipulator is a three-segment PCC arm hanging from its
base under Cartesian impedance control (waypoints as set-points), the gripper is a grasp coupling at the tip
that closes and opens on command, and the cylinder stands on the table through frictional contact. Figures:
the cylinder's lift height, its final position against the place target, the largest grasp force, the tip's
tracking error at the waypoints, the real-time factor; PNG of the scene and of the cylinder's path.

Equations
---------
*Arm.* Three PCC segments of 100 mm (``Basis.pcc(3)``, in-plane bending ``dofs = (0, 3, 0, 0, 0, 0)``),
circular section R = 12 mm, Dragon Skin 30 (Yeoh preset, damping ratio 0.1), hanging from (0, 0, 0.32) m
along -z, gravity along -z; each segment driven by a generalized torque (its antagonistic chamber pair;
``add_actuator`` with unit columns). Control: :func:`soroshapes.control.impedance` on the tip's x and z
(:math:`K_c` = 150 N/m, :math:`D_c` = 12 N s/m, gravity/elastic compensation of the arm itself, null-space
damping); the set-point moves between waypoints with smooth (cosine) transitions of 0.8 s.

*Gripper* (:func:`soroshapes.rigid.couple_grasp`): a spring-damper (k = 400 N/m, c = 4 N s/m) between the
tip and the centre of the cylinder's top face, scaled by the engagement (a 0.2 s ramp when it closes/opens):
it transmits force, not moment (a suction cup or fingers closed on the top), so the cylinder hangs from it.

*Cylinder* (:class:`soroshapes.RigidBody`): 45 g, radius 20 mm, height 40 mm, standing on the table z = 0
through 12 points of its bottom rim (:func:`soroshapes.rigid.couple_ground`: 3 kN/m and 6 N s/m per point,
Coulomb friction 0.5).

*Integration.* ``Model.simulate``, BDF2, dt = 2 ms (the rigid body's rotation matrix is pulled back onto
SO(3) with normalization 20 1/s, as BDF2 needs).

Sequence (waypoints of the tip, m): above the cylinder (0.10, 0.06) -> on its top (0.10, 0.042), close ->
lift (0.10, 0.10) -> over the place (-0.06, 0.10) -> down (-0.06, 0.042), open -> up (-0.06, 0.08).
Quick mode: pick, lift and hold (no transfer).
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

SEG, BASE_Z = 100 * mm, 0.32
R_CYL, H_CYL, M_CYL = 20 * mm, 40 * mm, 0.045
PICK, PLACE = (0.10, 0.0), (-0.06, 0.0)
TOP = H_CYL + 2 * mm          # tip height when holding the top (the grasp spring's rest is at the tip)


#: The full run and the short one (`--quick`, what the tests run): pick, lift and place (full), or pick and
#: lift only (quick).
FULL = dict(place=True)
QUICK = dict(place=False)


def main(out: Path, quick: bool = False) -> dict:
    from soroshapes import Model
    from soroshapes.control import impedance
    from soroshapes.network import Schedule
    from soroshapes.rigid import couple_grasp, couple_ground, grasp_force

    shp, cyl = arm(), cylinder()
    prm = QUICK if quick else FULL
    waypoints, T = schedule(prm["place"])
    times = np.array([w[0] for w in waypoints])

    def setpoint(t):
        k = int(np.searchsorted(times, t, side="right")) - 1
        p1 = np.array(waypoints[k][1])
        p0 = np.array(waypoints[k - 1][1]) if k > 0 else p1
        s = min((t - times[k]) / 0.8, 1.0)
        return p0 + (p1 - p0) * 0.5 * (1 - np.cos(np.pi * s))

    def engaged(t):
        k = int(np.searchsorted(times, t, side="right")) - 1
        g1, g0 = waypoints[k][2], waypoints[k - 1][2] if k > 0 else waypoints[k][2]
        return g0 + (g1 - g0) * min((t - times[k]) / 0.2, 1.0)

    start = shp.inverse_kinematics(np.array([PICK[0], 0.0, 0.06]), q0=np.array([-2.0, -1.0, -1.0]))
    mdl = Model().add(shp, "arm", x0=np.concatenate([start.q, np.zeros(3)])).add(cyl)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = np.column_stack([R_CYL * np.cos(ang), R_CYL * np.sin(ang), np.full(12, -H_CYL / 2)])
    couple_ground(mdl, "cylinder", rim, stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    # the set-point and the gripper as tables (10 ms; the kinks fall on samples): the network runs compiled
    couple_grasp(mdl, "arm", "cylinder", anchor=(0.0, 0.0, H_CYL / 2), stiffness=400.0, damping=4.0,
                 engaged=Schedule.sample(engaged, T, 0.01))
    mdl.set_controller(impedance("arm", stiffness=150.0, damping=12.0, setpoint=Schedule.sample(setpoint, T, 0.01),
                                 axes=(0, 2), null_damping=2e-3))
    t0 = time.perf_counter()
    tr = mdl.simulate(T, 2e-3, "bdf2", rtol=1e-5, atol=1e-8)
    wall = time.perf_counter() - t0

    q, qd, xc = tr["arm"].q, tr["arm"].qd, tr["cylinder"].x
    tips = np.array([shp.positions(qi)[-1] for qi in q])
    centre = np.array([cyl.pose(x)[:3, 3] for x in xc])
    force = np.array([np.linalg.norm(grasp_force(shp, cyl, qi, qdi, x, (0, 0, H_CYL / 2), 400.0, 4.0)[0]) * engaged(t)
                      for qi, qdi, x, t in zip(q, qd, xc, tr.t)])
    lift = float(centre[:, 2].max() - H_CYL / 2)
    wp_err = []
    for k, (tk, p, _) in enumerate(waypoints):
        t_end = times[k + 1] if k + 1 < len(times) else T
        i = int(np.searchsorted(tr.t, t_end)) - 1
        wp_err.append(float(np.hypot(tips[i, 0] - p[0], tips[i, 2] - p[1])))
    final = centre[-1]
    target = PLACE if prm["place"] else PICK

    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle
    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4.4))
    (ax, bx) = fig.subplots(1, 2)
    ax.axhline(0, color="0.3", lw=2)
    for k in np.linspace(0, len(q) - 1, 7).astype(int):
        P = shp.positions(q[k]) / mm
        ax.plot(P[:, 0], P[:, 2], lw=5, alpha=0.25 + 0.75 * k / len(q), color="C0")
        c = centre[k] / mm
        ax.add_patch(Rectangle((c[0] - R_CYL / mm, c[2] - H_CYL / 2 / mm), 2 * R_CYL / mm, H_CYL / mm, alpha=0.3,
                               color="C3"))
    ax.plot(centre[:, 0] / mm, centre[:, 2] / mm, "C3", lw=1, label="cylinder centre")
    ax.plot(tips[:, 0] / mm, tips[:, 2] / mm, "C1", lw=1, label="tip")
    ax.set(aspect="equal", xlabel="x [mm]", ylabel="z [mm]", title="pick and place")
    ax.legend(fontsize=7)
    bx.plot(tr.t, 1e3 * (centre[:, 2] - H_CYL / 2), label="cylinder lift [mm]")
    bx.plot(tr.t, 100 * force, label="grasp force [N] x 100")
    bx.plot(tr.t, 100 * np.array([engaged(t) for t in tr.t]), "--", lw=0.8, label="gripper closed [%]")
    bx.set(xlabel="t [s]")
    bx.legend(fontsize=7)
    bx.grid(alpha=0.3)
    save_figure(fig, out / "manipulator_pick.png")

    return {
        "lift_mm": round(lift / mm, 3),
        "final_position_mm": [round(v / mm, 3) for v in final],
        "place_error_mm": round(float(np.hypot(final[0] - target[0], final[1] - target[1])) / mm, 3),
        "final_height_error_mm": round(float(final[2] - H_CYL / 2) / mm, 3),
        "tilt_deg_max": round(float(np.degrees(np.arccos(np.clip([cyl.pose(x)[2, 2] for x in xc], -1, 1)).max())), 3),
        "grasp_force_N_max": round(float(force.max()), 4), "cylinder_weight_N": round(M_CYL * 9.81, 4),
        "waypoint_error_mm": [round(e / mm, 3) for e in wp_err],
        "simulated_s": T, "wall_time_s_sim": round(wall, 2), "real_time_factor": round(T / wall, 3),
        "png": "manipulator_pick.png",
    }


# ------------------------------------------------------------------------------------------------- the steps
def arm():
    from soroshapes import Basis, Shapes

    down = np.eye(4)
    down[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    down[2, 3] = BASE_Z
    shp = Shapes(Basis.pcc(3), (0, 3, 0, 0, 0, 0), length=3 * SEG, section=sdf.Circle(12 * mm),
                 material=materials.DragonSkin30(), base=down, segments=12)
    shp.add_gravity((0.0, 0.0, -9.81))
    for i in range(3):
        shp.add_actuator(np.eye(3)[i], name=f"segment{i}")
    return shp


def cylinder():
    from soroshapes import RigidBody

    Ixx = M_CYL * (3 * R_CYL**2 + H_CYL**2) / 12
    pose = np.eye(4)
    pose[:3, 3] = (PICK[0], PICK[1], H_CYL / 2)
    return RigidBody(M_CYL, [Ixx, Ixx, M_CYL * R_CYL**2 / 2], pose0=pose, damping=(0.05, 1e-4), name="cylinder",
                     normalization=20.0)


def schedule(place):
    """Waypoints [(t_start, (x, z), grip)] and the end time [s]: the set-point moves to (x, z) from t_start on;
    grip in {0, 1}. Pick and lift; with ``place``, also carry, place and release."""
    hold = [(0.0, (PICK[0], 0.06), 0), (0.9, (PICK[0], TOP), 0), (1.8, (PICK[0], TOP), 1), (2.3, (PICK[0], 0.10), 1)]
    if not place:
        return hold, 3.4
    return hold + [(3.3, (PLACE[0], 0.10), 1), (4.3, (PLACE[0], TOP), 1), (5.2, (PLACE[0], TOP), 0),
                   (5.6, (PLACE[0], 0.08), 0)], 6.6


def scene(quick=False):
    """``soro play manipulator_pick``: the three-segment arm (a torque slider [N m] per segment, a target at its
    tip for IK or for the demo's Cartesian impedance controller) above the cylinder standing on the table."""
    from soro.play import Channel, Scene, Target
    from soroshapes import Model
    from soroshapes.rigid import couple_ground

    shp = arm()
    above = np.array([PICK[0], 0.0, 0.06])                 # the demo's start: bent, above the cylinder
    start = shp.inverse_kinematics(above, q0=np.array([-2.0, -1.0, -1.0]))
    mdl = Model().add(shp, "arm", x0=np.concatenate([start.q, np.zeros(3)])).add(cylinder())
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = np.column_stack([R_CYL * np.cos(ang), R_CYL * np.sin(ang), np.full(12, -H_CYL / 2)])
    couple_ground(mdl, "cylinder", rim, stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    channels = [Channel(f"arm.segment{i}", -0.5, 0.5, "N m", label=f"segment {i} torque") for i in range(3)]
    return Scene(mdl, channels, target=Target(tuple(above), beam="arm"), dt=2e-3, method="bdf2",
                 view=(0.0, 10.0), title="manipulator_pick",
                 impedance=dict(stiffness=150.0, damping=12.0, axes=(0, 2), null_damping=2e-3))
