r"""The three-bellow soft manipulator with a three-finger soft gripper picks a cylinder and places it
(`soro demo manipulator_pick`)
=====================================================================================================

Purpose
-------
The seed's manipulator case (Sorotoki paper, Sec. V-F, Figs. 16-17): a pressure-driven soft manipulator of three
bellows with a soft three-finger gripper at its end picks a 40 mm cylinder of 45 g from a table, lifts it,
carries it and puts it down elsewhere. Here the robot is the open-hardware manipulator (d) of ``soro.robots``
(three round bellows chains at 120 deg about a hollow axis, -10..30 kPa, and its gripper of three box-bellows
fingers, -30..60 kPa) as its calibrated twin, hung upside down from a frame, as ONE tree of bodies
(:class:`soroshapes.tree.Tree`): the manipulator beam, the top plate and gripper hub as a rigid link on its
end, the three finger beams on the hub. The cylinder is a free rigid body on the table; it is held by the
fingers' contact and friction only (no spring coupling). Figures: lift, place error, grasp normal force per
finger, hold margin, slip, real-time factor; PNGs of 3D scene snapshots and of the cylinder's path.

Model
-----
*Robot* (``soro.robots.twin.twin_shapes`` of the design's twins, bellows modulus
:func:`soro.robots.twin.bellows_modulus`): the manipulator beam (Chebyshev(2) in both bendings plus stretch: 5
coordinates; the twin's default is Chebyshev(3)), its three chambers ``bellows1..3`` (the chains' effective
areas 26 mm off the axis); **chains of 140 mm** (design parameters ``length=140 mm, n_bellows=11``; the
default 120 mm chains stroke only 48.1 mm from 30 to -10 kPa under the gripper's weight, measured with this
model, less than the 50 mm lift the case asks for); the hub link (80 g, an estimate of the printed top plate
and hub); three fingers (constant curvature: Chebyshev(1) in their closing bending, 1 coordinate each) with
one chamber each on the ``gripper`` channel. 8 coordinates, gravity along -z, the base 0.27 m above the table.

*Contact* (:func:`soroshapes.rigid.couple_tree_contact`): points on the inner face of each finger (its
strain-limiting layer, 6.25 mm inside the backbone) at the finger's nodes from 15 mm to its tip, pad radius
1 mm, against the cylinder's surface (``sdf.Cylinder``): penalty k = 1000 N/m and c = 1 N s/m per point,
regularized Coulomb friction mu = 0.6 (elastomer on a printed part), regularization 0.2 mm/s; equal and opposite
on the fingers (generalized forces through the tree block's force inputs) and on the cylinder (its wrench).

*Cylinder* (:class:`soroshapes.RigidBody`, 45 g, R = 20 mm, H = 40 mm) on the table through 12 points of its
bottom rim (:func:`soroshapes.rigid.couple_ground`: 3 kN/m, 6 N s/m per point, friction 0.5).

*Integration*: ``Model.simulate``, BDF2, dt = 2 ms (quick) or 1 ms (full), the network in one compiled kernel
(:mod:`soroshapes.network`: the tree block, the tree contact and the ground contact as compiled terms, the
pressures as a :class:`~soroshapes.network.Schedule` table sampled every 0.5 ms); ``compiled=False`` runs the
same equations on the Python path.

*Control*: open loop, channel pressures [kPa] ramped (cosine) between key frames: close the gripper (-30 ->
60) around the cylinder with the manipulator extended (30 kPa), lift (all chains -> -10), carry sideways
(bellows1 -> 20), lower onto the place (30, 15, 15), open (-> -30), rise. The place target is chosen before
the run: the point between the fingers at the place pressures (statics of the unloaded robot), on the table.

Quick and full run the same sequence; full also approaches from above (the gripper starts open and raised)
and uses dt = 1 ms.

Measured (session 9, Debian 12; quick dt = 2 ms / full dt = 1 ms)
------------------------------------------------------------------
Lift 60.42 / 60.21 mm (53.05 / 52.80 mm at the end of the lift; the carry's bend raises it further); place
error 0.349 / 0.032 mm from the target (0, 45.07) mm, final tilt 0; normal force per finger 0.311 N closed,
0.274 N while lifted; hold margin mu N / W 1.119 at the lift, >= 1.104 while carried (1.9 s off the table);
the fingers' upward force / weight 1.001 (median while carried); slip relative to the grasp centre 1.03 / 1.09
mm; the cylinder is released 15 mm above the table (the bent manipulator at (30, 15, 15) kPa reaches no lower)
and lands upright. Without friction (mu = 0) the fingers press 0.316 N each and slide off: lift 0.0 mm.
Real-time factor 0.064 / 0.041 (Python path; load 4-10 on 2 cores). Compiled network (session 10,
``bench_tree.py -k manipulator_pick``, load 2.2): quick run 0.343x real time (wall and CPU), lift 60.37 mm;
the closing phase (0.6 s) 0.27x compiled vs 0.19x on the Python path; most of the time was the differenced Newton
matrix of the tree and the cylinder (34 columns, each a whole evaluation of the tree's dynamics). Session 11: the
tree's rows of the Newton matrix are its model rows (mass matrix, K, D, and the contact terms' force differenced,
not the tree's dynamics; :func:`soroshapes._treeblock.block_model_rows`), and the tree's kinematics are computed
once per state: quick run 1.93 s CPU (2.17x real time by CPU; 2.97 s wall, 1.41x, load 5.2) against 27.1 s CPU
(0.155x) for the former code run back to back; lift 60.420 mm (60.365 before); per step 4.1 Newton sweeps, 1.2
model-row refreshes and 0.14 differenced Jacobians (2100 steps, 36 split).
"""
import time
from pathlib import Path

import numpy as np

from sorofem import sdf
from sorofem.units import kPa, mm

R_CYL, H_CYL, M_CYL = 20 * mm, 40 * mm, 0.045
MU, EPS = 0.6, 2e-4                    # finger-cylinder friction, regularization [m/s]
K_PAD, C_PAD, PAD = 1000.0, 1.0, 1 * mm
INNER = -6.25 * mm                     # the finger's inner face from its backbone (local z), the design's section
GRAVITY = 9.81
#: the key frames: (time [s], bellows1, bellows2, bellows3, gripper) pressures [kPa]
PICK_PLACE = [(0.0, 30, 30, 30, -30), (0.05, 30, 30, 30, -30), (0.35, 30, 30, 30, 60), (0.5, 30, 30, 30, 60),
              (1.1, -10, -10, -10, 60), (1.3, -10, -10, -10, 60), (2.0, 20, -10, -10, 60), (2.1, 20, -10, -10, 60),
              (2.8, 30, 15, 15, 60), (3.0, 30, 15, 15, 60), (3.3, 30, 15, 15, -30), (3.5, 30, 15, 15, -30),
              (3.9, -10, -10, -10, -30), (4.2, -10, -10, -10, -30)]
APPROACH = [(0.0, -10, -10, -10, -30), (0.6, 30, 30, 30, -30)]

DRIVE_TABLE_DT = 5e-4                  # the pressures' table [s]: linear between samples, within 0.2 Pa of the ramps
#: quick (what the tests run) and full; until [s]: stop early (tests); compiled: the network in one compiled kernel
#: (False: its Python path, the same equations)
QUICK = dict(dt=2e-3, approach=False, friction=MU, until=None, compiled=True)
FULL = dict(dt=1e-3, approach=True, friction=MU, until=None, compiled=True)


def main(out: Path, quick: bool = False, **over) -> dict:
    from soroshapes import Model
    from soroshapes.network import Schedule
    from soroshapes.rigid import TreeContact, couple_ground, couple_tree_contact

    prm = dict(QUICK if quick else FULL, **over)
    keys = schedule(prm["approach"])
    if prm["until"] is not None:
        keys = [k for k in keys if k[0] <= prm["until"]]
    T = keys[-1][0]
    tree, z0 = robot()
    q0 = statics(tree, inputs(keys[0][1:]))
    target = grasp_centre(tree, statics(tree, inputs(PLACE)))
    contact = TreeContact(tree, finger_points(tree), K_PAD, C_PAD, prm["friction"], EPS)
    cyl = cylinder()
    mdl = Model().add(tree.system(name="robot", q0=q0, force_inputs=True))
    mdl.add(cyl)
    couple_ground(mdl, "cylinder", rim(), stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    couple_tree_contact(mdl, "robot", "cylinder", contact)
    # the channel pressures as a table (a Schedule runs inside the compiled network, a Python callable would not)
    drive = Schedule.sample(lambda t: inputs(pressures(keys, t)), T, DRIVE_TABLE_DT)
    mdl.set_controller(Schedule(drive.times, {"robot": drive.values}))
    t0 = time.perf_counter()
    tr = mdl.simulate(T, prm["dt"], "bdf2", rtol=1e-2, atol=1e-5, record_every=max(1, round(0.01 / prm["dt"])),
                      compiled=prm["compiled"])
    wall = time.perf_counter() - t0

    # ---- post-processing
    ts, xs, xc = np.asarray(tr.t), np.asarray(tr["robot"].x), np.asarray(tr["cylinder"].x)
    Q = np.array([tree.state(t, x)[0] for t, x in zip(ts, xs)])
    QD = np.array([tree.state(t, x)[1] for t, x in zip(ts, xs)])
    centre = xc[:, :3]
    fingers = [f"gripper{k}" for k in (1, 2, 3)]
    owner = np.array([fingers.index(p[0]) for p in finger_points(tree)])
    normal, vertical, grip = np.zeros((len(ts), 3)), np.zeros(len(ts)), np.zeros((len(ts), 3))
    for i, (q, qd, x) in enumerate(zip(Q, QD, xc)):
        _, W, F, X = contact.evaluate(q, qd, x)
        g = cyl.pose(x)
        for k in range(3):                          # normal force per finger: the radial part of its force
            Fk = F[owner == k]
            if len(Fk):
                r = X[owner == k] - g[:3, 3]
                r -= np.outer(r @ g[:3, 2], g[:3, 2])
                n = r / np.maximum(np.linalg.norm(r, axis=1), 1e-12)[:, None]
                normal[i, k] = float(np.sum(np.einsum("ki,ki->k", Fk, n)))
        vertical[i] = -float(np.sum(F[:, 2]))      # the fingers' upward force on the cylinder [N]
        grip[i] = grasp_centre(tree, q)
    weight = M_CYL * GRAVITY
    lifted = centre[:, 2] - H_CYL / 2
    shift = 0.6 if prm["approach"] else 0.0
    # carried: from the end of the lift (1.1 s) to the opening (3.0 s), and off the table
    held = (lifted > 5 * mm) & (ts >= 1.1 + shift) & (ts <= 3.0 + shift)
    tilt = np.degrees(np.arccos(np.clip([cyl.pose(x)[2, 2] for x in xc], -1, 1)))
    i_lift = min(int(np.searchsorted(ts, 1.3 + shift)), len(ts) - 1)
    i_closed = min(int(np.searchsorted(ts, 0.5 + shift)), len(ts) - 1)
    margin = prm["friction"] * normal.sum(axis=1) / weight
    rel = centre - grip                             # the cylinder's position relative to the grasp centre
    slip = float(np.linalg.norm(rel[held] - rel[held][0], axis=1).max()) if held.any() else 0.0
    final = centre[-1]
    result = {
        "robot": "soro.robots manipulator (d) twin, chains 140 mm; gripper twin; one Tree (8 coordinates)",
        "lift_mm": round(float(lifted.max()) / mm, 3),
        "lift_at_end_of_lift_mm": round(float(lifted[i_lift]) / mm, 3),
        "place_target_mm": [round(v / mm, 3) for v in target[:2]],
        "final_position_mm": [round(v / mm, 3) for v in final],
        "place_error_mm": round(float(np.hypot(*(final[:2] - target[:2]))) / mm, 3),
        "final_height_error_mm": round(float(final[2] - H_CYL / 2) / mm, 3),
        "final_tilt_deg": round(float(tilt[-1]), 3), "tilt_deg_max": round(float(tilt.max()), 3),
        "grasp_normal_force_closed_N": [round(float(v), 4) for v in normal[i_closed]],
        "grasp_normal_force_N": [round(float(v), 4) for v in normal[i_lift]],
        "hold_margin_at_lift": round(float(margin[i_lift]), 3),
        "hold_margin_min_while_carried": round(float(margin[held].min()), 3) if held.any() else 0.0,
        "release_height_mm": round(float(lifted[min(int(np.searchsorted(ts, 3.0 + shift)), len(ts) - 1)]) / mm, 3),
        "finger_lift_force_over_weight_while_carried": (round(float(np.median(vertical[held] / weight)), 3)
                                                     if held.any() else 0.0),
        "carried_s": round(float(held.sum() * (ts[1] - ts[0])), 3),
        "slip_mm": round(slip / mm, 3),
        "cylinder_weight_N": round(weight, 4), "friction": prm["friction"],
        "simulated_s": round(float(T), 3), "dt": prm["dt"], "wall_time_s_sim": round(wall, 2),
        "real_time_factor": round(float(T) / wall, 4),
        "newton_iterations_per_step": round(tr.stats["newton_iterations"] / max(tr.stats["steps"], 1), 2),
        "evaluation_path": tr.stats.get("path"),
        "png": ["manipulator_pick.png", "manipulator_pick_scene.png"],
    }
    if prm["until"] is not None:                    # a shortened run (no place): nothing to compare with the target
        for key in ("place_target_mm", "place_error_mm"):
            result.pop(key)
    _figures(out, tree, ts, Q, xc, cyl, centre, normal, margin, keys, target)
    return result


# ------------------------------------------------------------------------------------------------- the steps
PLACE = (30, 15, 15, 60)


def schedule(approach):
    """Key frames [(t [s], p1, p2, p3, p_gripper [kPa])]: with ``approach``, first lower the open gripper over
    the cylinder (0.6 s)."""
    if not approach:
        return list(PICK_PLACE)
    return APPROACH + [(t + 0.6, *p) for t, *p in PICK_PLACE[1:]]


def pressures(keys, t):
    """Channel pressures (4,) [kPa] at time t: cosine ramps between the key frames."""
    tk = np.array([k[0] for k in keys])
    P = np.array([k[1:] for k in keys], dtype=float)
    i = int(np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(tk) - 2))
    s = float(np.clip((t - tk[i]) / (tk[i + 1] - tk[i]), 0.0, 1.0))
    return P[i] + 0.5 * (1 - np.cos(np.pi * s)) * (P[i + 1] - P[i])


def inputs(p):
    """The tree's input vector [Pa] (3 chambers of the manipulator, one per finger) of channel pressures [kPa]."""
    p = np.asarray(p, dtype=float) * kPa
    return np.array([p[0], p[1], p[2], p[3], p[3], p[3]])


def design():
    from sorofem.robots import ROBOTS
    return ROBOTS["manipulator"].design(length=140 * mm, n_bellows=11)


def robot(z_tips=4 * mm):
    """The tree (manipulator beam, hub link, three fingers) hung upside down so that the open fingers' tips are
    ``z_tips`` above the table with the chains at 30 kPa. Returns (tree, base height [m])."""
    from soro.robots.twin import bellows_modulus, twin_shapes
    from soroshapes.lie import invSE3
    from soroshapes.tree import Tree

    des = design()
    arm, fingers = des.twins[0], des.twins[1:]

    def build(z0):
        flip = np.diag([1.0, -1.0, -1.0, 1.0])     # upside down: design z up -> world z down from the frame at z0
        flip[2, 3] = z0
        tree = Tree(gravity=(0.0, 0.0, -GRAVITY))
        tree.add_beam("arm", twin_shapes(arm, dofs=(0, 2, 2, 1, 0, 0), modes=2, E=bellows_modulus(arm)),
                      offset=flip)
        tip = arm.base.copy()
        tip[:3, 3] += arm.base[:3, 0] * arm.length
        # the hub link's frame is the design frame carried by the manipulator's end
        tree.add_link("hub", 0.08, [3e-5, 3e-5, 6e-5], com=(0.0, 0.0, tip[2, 3] + 11 * mm), parent="arm",
                      offset=invSE3(tip))
        for tw in fingers:
            tree.add_beam(tw.name, twin_shapes(tw, dofs=(0, 1, 0, 0, 0, 0), modes=1, E=bellows_modulus(tw)),
                          parent="hub")
        return tree
    trial = build(0.3)
    q = statics(trial, inputs((30, 30, 30, -30)))
    low = min(trial.frame(q, f"gripper{k}")[2, 3] for k in (1, 2, 3))
    z0 = 0.3 - low + z_tips
    return build(z0), z0


def statics(tree, u, q0=None):
    """Static equilibrium q of the tree under gravity and inputs ``u`` (:meth:`soroshapes.Tree.statics`: the one
    Newton with load stepping)."""
    return tree.statics(u, q0, steps=4).q


def finger_points(tree):
    """Contact points on the fingers' inner faces: (finger, node arc length, offset, pad radius)."""
    pts = []
    for k in (1, 2, 3):
        name = f"gripper{k}"
        for s in tree.body_model(name).sigma:
            if s >= 15 * mm - 1e-9:
                pts.append((name, float(s), (0.0, 0.0, INNER), PAD))
    return pts


def grasp_centre(tree, q):
    """The point between the three fingers' inner faces at 35 mm along them [m] (where they hold the
    cylinder's middle)."""
    P = []
    for k in (1, 2, 3):
        g = tree.frame(q, f"gripper{k}", at=_node(tree, f"gripper{k}", 35 * mm))
        P.append(g[:3, 3] + g[:3, 2] * INNER)
    return np.mean(P, axis=0)


def _node(tree, body, s):
    sig = tree.body_model(body).sigma
    return float(sig[np.argmin(np.abs(sig - s))])


def cylinder(at=(0.0, 0.0)):
    """The 45 g cylinder standing on the table at (x, y) ``at`` [m]."""
    from soroshapes import RigidBody

    Ixx = M_CYL * (3 * R_CYL**2 + H_CYL**2) / 12
    pose = np.eye(4)
    pose[:3, 3] = (at[0], at[1], H_CYL / 2)
    return RigidBody(M_CYL, [Ixx, Ixx, M_CYL * R_CYL**2 / 2], pose0=pose, damping=(0.01, 1e-5), name="cylinder",
                     shape=sdf.Cylinder(R_CYL, H_CYL), normalization=20.0)


def rim():
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    return np.column_stack([R_CYL * np.cos(ang), R_CYL * np.sin(ang), np.full(12, -H_CYL / 2)])


def _figures(out, tree, ts, Q, xc, cyl, centre, normal, margin, keys, target):
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    bodies = ["arm"] + [f"gripper{k}" for k in (1, 2, 3)]
    fig = Figure(figsize=(15, 4.6))
    pick = [0.0] + [k[0] for k in keys if k[0] > 0]
    snaps = [k for k in (0.36, 1.25, 2.05, 2.95, keys[-1][0]) if k <= keys[-1][0]]
    if keys[0][1] < 0:                                   # the approach
        snaps = [0.0] + [s + 0.6 for s in snaps[:-1]] + [keys[-1][0]]
    ang = np.linspace(0, 2 * np.pi, 24)
    for j, ts_ in enumerate(snaps[:5]):
        i = int(np.argmin(np.abs(ts - ts_)))
        ax = fig.add_subplot(1, 5, j + 1, projection="3d")
        for b in bodies:
            P = tree.frames(Q[i], b)[:, :3, 3] / mm
            ax.plot(P[:, 0], P[:, 1], P[:, 2], lw=4 if b == "arm" else 2.5, color="C0" if b == "arm" else "C1")
        hub = np.array([tree.frames(Q[i], f"gripper{k}")[0, :3, 3] for k in (1, 2, 3, 1)]) / mm
        end = tree.frames(Q[i], "arm")[-1, :3, 3] / mm
        ax.plot(hub[:, 0], hub[:, 1], hub[:, 2], color="0.3", lw=2)
        for h in hub[:3]:
            ax.plot([end[0], h[0]], [end[1], h[1]], [end[2], h[2]], color="0.3", lw=1)
        g = cyl.pose(xc[i])
        for zc in (-H_CYL / 2, H_CYL / 2):
            ring = np.column_stack([R_CYL * np.cos(ang), R_CYL * np.sin(ang), np.full_like(ang, zc)])
            W = (ring @ g[:3, :3].T + g[:3, 3]) / mm
            ax.plot(W[:, 0], W[:, 1], W[:, 2], color="C3")
        ax.scatter([target[0] / mm], [target[1] / mm], [0.0], marker="x", color="k")
        ax.set(xlim=(-60, 60), ylim=(-40, 100), zlim=(0, 280), title=f"t = {ts[i]:.2f} s", xlabel="x [mm]",
               ylabel="y [mm]")
        ax.view_init(elev=12, azim=-20)
        ax.tick_params(labelsize=6)
    save_figure(fig, out / "manipulator_pick_scene.png")

    fig = Figure(figsize=(12, 4.2))
    ax, bx, cx = fig.subplots(1, 3)
    ax.plot(centre[:, 1] / mm, centre[:, 2] / mm, "C3")
    ax.plot([target[1] / mm], [H_CYL / 2 / mm], "kx", label="place target")
    ax.plot([centre[0, 1] / mm], [centre[0, 2] / mm], "o", color="C3", label="start")
    ax.plot([centre[-1, 1] / mm], [centre[-1, 2] / mm], "s", color="C3", label="end")
    ax.set(xlabel="y [mm]", ylabel="z [mm]", title="cylinder centre path", aspect="equal")
    ax.legend(fontsize=7)
    bx.plot(ts, (centre[:, 2] - H_CYL / 2) / mm, label="lift [mm]")
    bx.plot(ts, centre[:, 1] / mm, label="y [mm]")
    bx.set(xlabel="t [s]", title="cylinder")
    bx.legend(fontsize=7)
    bx.grid(alpha=0.3)
    for k in range(3):
        cx.plot(ts, normal[:, k], label=f"finger {k + 1} normal [N]")
    cx.plot(ts, margin, "k--", lw=1, label="hold margin mu N / W")
    cx.axhline(1.0, color="0.5", lw=0.8)
    cx.set(xlabel="t [s]", title="grasp")
    cx.legend(fontsize=7)
    cx.grid(alpha=0.3)
    for a in (bx, cx):
        for t in pick:
            a.axvline(t, color="0.85", lw=0.6, zorder=0)
    save_figure(fig, out / "manipulator_pick.png")


# ------------------------------------------------------------------------------------------ the play scene
# ``soro play`` drives Shapes beams in a Model (a tree scene is not built there yet): its manipulator_pick scene
# stays the planar three-segment PCC arm under torques with its Cartesian impedance mode, above the cylinder.
_PLAY_SEG, _PLAY_BASE_Z, _PLAY_PICK = 100 * mm, 0.32, (0.10, 0.0)


def play_arm():
    """The play scene's arm: three PCC segments of 100 mm hanging from (0, 0, 0.32) m, a torque per segment."""
    from sorofem import materials
    from soroshapes import Basis, Shapes

    down = np.eye(4)
    down[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    down[2, 3] = _PLAY_BASE_Z
    shp = Shapes(Basis.pcc(3), (0, 3, 0, 0, 0, 0), length=3 * _PLAY_SEG, section=sdf.Circle(12 * mm),
                 material=materials.DragonSkin30(), base=down, segments=12)
    shp.add_gravity((0.0, 0.0, -9.81))
    for i in range(3):
        shp.add_actuator(np.eye(3)[i], name=f"segment{i}")
    return shp


def scene(quick=False):
    """``soro play manipulator_pick``: the planar three-segment arm (a torque slider [N m] per segment, a target
    at its tip for IK or for a Cartesian impedance controller) above the cylinder standing on the table (the
    demo itself runs the three-bellow manipulator tree, which play does not take yet)."""
    from soro.play import Channel, Scene, Target
    from soroshapes import Model
    from soroshapes.rigid import couple_ground

    shp = play_arm()
    above = np.array([_PLAY_PICK[0], 0.0, 0.06])
    start = shp.inverse_kinematics(above, q0=np.array([-2.0, -1.0, -1.0]))
    mdl = Model().add(shp, "arm", x0=np.concatenate([start.q, np.zeros(3)])).add(cylinder(_PLAY_PICK))
    couple_ground(mdl, "cylinder", rim(), stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    channels = [Channel(f"arm.segment{i}", -0.5, 0.5, "N m", label=f"segment {i} torque") for i in range(3)]
    return Scene(mdl, channels, target=Target(tuple(above), beam="arm"), dt=2e-3, method="bdf2",
                 view=(0.0, 10.0), title="manipulator_pick",
                 impedance=dict(stiffness=150.0, damping=12.0, axes=(0, 2), null_damping=2e-3))
