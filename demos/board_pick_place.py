r"""Open-loop pick-and-place on the simulated pneumatic board (`soro demo board_pick_place`)
=====================================================================================

Purpose
-------
The seed's open-loop pick-and-place (Sorotoki paper, Fig. 16): a soft manipulator with a pneumatic gripper
at its tip is driven through a sequence of pressure set-points, computed beforehand from a model, that take
the gripper above an object, down to it, closes the gripper, carries the object to a place location, opens
the gripper and returns. Here the board is the default simulated one (:meth:`sorocontrol.Board.simulated`:
the board server with its limits, rate limits and watchdog, in its own process), whose plant is a reduced
network plant (:class:`sorocontrol.drivers.NetworkRecipe`, :func:`plant_network`): the reduced Cosserat arm
driven by regulated pneumatic channels, a 5 g cube standing on a table (a rigid body on a contact plane) and
the gripper, a grasp coupling at the arm's tip engaged by the gripper channel's pressure. The host sends the
set-points through the protocol at 100 Hz and reads the tip's and the object's positions back from the
board's sensors. Figures: the object's final position vs the place target (mm), its lift height, how far it
moved, the tip's distance to each waypoint at the end of its hold (mm), the model's own inverse-statics
error, the loop's rate and jitter, the pressures, and a PNG of the tip's and the object's paths.

Equations
---------
*Manipulator.* Two segments of 60 mm, each of piecewise-constant curvature in the vertical plane
(``Basis.pcc(2)``, ``dofs = (0, 2, 0, 0, 0, 0)``: :math:`q_j` = curvature of segment j about body y [1/m]),
clamped horizontally at the origin (pointing along x), gravity along -z. Each segment has two chambers
(area 60 mm^2, centroids at z = +-5 mm from the backbone): chamber pressure p acts as the internal bending
moment :math:`p A_c z` (:meth:`Shapes.add_chamber`). Channel 4 is the gripper (no effect on the arm's bending).

*Object and gripper.* A cube of 16 mm, 5 g (:class:`soroshapes.RigidBody`, light damping 0.05 N s/m,
3e-5 N m s/rad, as air and the pads would give) on a table (:func:`soroshapes.rigid.couple_ground` at its four
base corners: 300 N/m and 1 N s/m each, friction 0.6). The gripper (:func:`soroshapes.rigid.couple_grasp`)
is a spring-damper (100 N/m, 0.5 N s/m) between the tip and the cube's top centre, scaled by
:math:`\min(1, p_4/60\,\mathrm{kPa})`: open at 0 kPa, closed at the gripper's 60 kPa. A reduced gripper: it
transmits force, not moment (the cube hangs from it). The network (18 + 4 states) is continued by the
plant over each board tick with the Model's trapezoidal integrator (steps of at most 5 ms).
Dynamics :math:`M\ddot q + C\dot q + \tau K\dot q + Kq = f_g(q) + G p`, integrated by the board's plant at
its loop rate, behind first-order-like regulator dynamics (:class:`sorocontrol.SimulatedPlant`, 30 ms).

*Plan (open loop).* For each waypoint :math:`x^*` in the x-z plane, inverse statics: find signed segment
activations :math:`a \in [-90, 90]` kPa (:math:`a_j > 0` pressurizes the lower chamber of segment j,
:math:`a_j < 0` the upper one) minimizing :math:`|p_{tip}(q(a)) - x^*|` with :math:`Kq = f_g(q) + G p(a)`
(``Shapes.statics``; ``scipy.optimize.least_squares``), without the object's weight. The pressures are then
played open loop; the tip error on the board measures what the plan leaves (the object's weight sags the
soft arm by up to 7 mm, dynamics not settled, regulator tracking). The arm's workspace is only ~4 mm wide at
the table's height, so the object is carried 3.5 mm sideways but lifted ~20 mm.

Parameters
----------
=================  =====================================================================================
arm                2 x 60 mm, circular section of radius 8 mm, Dragon Skin 30 (Yeoh preset)
chambers           60 mm^2 at +-5 mm, per segment; activations bounded to 90 kPa
board              5 channels, -100..100 kPa, slew limit 1 MPa/s, watchdog 0.5 s, board loop 200 Hz
host loop          100 Hz; each waypoint held 1.5 s of the plant's time (quick: the first 8, 1.2 s each)
object             5 g cube of 16 mm on a table 16 mm under the pick point; pick at x = 95 mm, place at 98.5 mm
gripper            grasp spring 100 N/m, 0.5 N s/m at the tip, engaged by the gripper channel (60 kPa: closed)
=================  =====================================================================================

The network plant runs on the Python path of :meth:`soroshapes.Model.simulate` (the grasp's engagement is a
Python function of the gripper channel), slower than real time: the board caps each of its steps
(``max_advance``) and the plant lags the board's clock. The host therefore sequences the waypoints by the
plant's own time, its last sensor: each hold gets the same plant time on a quiet or a loaded machine.
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

SEGMENT = 60 * mm
P_MAX = 90 * kPa
GRIP = 60 * kPa


#: The full run and the short one (`--quick`, what the tests run): the waypoints played (indices into the
#: sequence of main), each held [s].
#: The holds are in the plant's time (its last sensor): the board's plant simulates at about a third of real time
#: at load 2-3 (its step is capped per board tick, :class:`sorocontrol.SimulatedPlant` ``max_advance``), slower
#: on a busier machine; sequencing by the plant's time gives the same motion at any load.
FULL = dict(waypoints=tuple(range(9)), hold=1.5)
QUICK = dict(waypoints=tuple(range(8)), hold=1.2)
#: Board time [s] allowed per second of plant time before the run gives up with a message (about 3 at load 2-3).
MAX_WALL_PER_PLANT_S = 40.0
#: The gripper coupling in the plant (False: the demo's control experiment, the object must stay).
GRASP = True


def main(out: Path, quick: bool = False) -> dict:
    from sorocontrol import Board
    from sorocontrol.drivers import NetworkRecipe

    shp = arm()
    home = shp.positions(shp.statics(u=pressures([0, 0], 0)))[-1]
    # waypoints: (name, x, z, gripper) of the tip -- above the object, at it (its top centre), grip, lift, above
    # the place, place, release, retreat, home; the arm's workspace is a crescent 89-119 mm out, -69..0 mm high
    # (two segments of fixed length), only 4 mm wide at the table's height: the carry is short, the lift not
    (px, pz), (qx, qz) = PICK, PLACE
    seq = [("above_pick", 0.100, -0.056, 0.0), ("pick", px, pz, 0.0), ("grip", px, pz, GRIP),
           ("lift", 0.110, -0.038, GRIP), ("above_place", 0.1015, -0.055, GRIP), ("place", qx, qz, GRIP),
           ("release", qx, qz, 0.0), ("retreat", 0.110, -0.038, 0.0), ("home", home[0], home[2], 0.0)]
    prm = QUICK if quick else FULL
    seq = [seq[i] for i in prm["waypoints"]]
    hold = prm["hold"]
    t0 = time.perf_counter()
    plans = plan(shp, [(x, z) for _, x, z, _ in seq])
    plan_s = time.perf_counter() - t0

    log_t, log_tip, log_obj, log_p = [], [], [], []
    recipe = NetworkRecipe(str(Path(__file__).resolve()), "plant_network", (("grasp", GRASP),))
    # keepalive: the session survives any pause before brd.loop starts (which then feeds the watchdog itself)
    with Board.simulated(channels=5, network=recipe, network_dt=5e-3, board_rate=200.0, keepalive=True) as brd:
        # the sequence runs on the plant's time (its last sensor), not the loop's: the plant lags the board's
        # clock by however much a loaded machine makes it skip, and each hold still gets `hold` of plant time
        tp, end = 0.0, hold * len(seq)
        for t in brd.loop(duration=MAX_WALL_PER_PLANT_S * end, rate=100.0):
            i = min(int(tp // hold), len(seq) - 1)
            (a, _), grip = plans[i], seq[i][3]
            s = brd.set_pressure(pressures(a, grip))
            tp = float(s.sensors[-1])
            log_t.append(tp)
            log_tip.append(s.sensors[:3].copy())
            log_obj.append(s.sensors[3:6].copy())
            log_p.append(s.measured.copy())
            if tp >= end:
                break
        stats = brd.loop_stats
    if tp < end:
        raise RuntimeError(f"board_pick_place: the simulated plant reached {tp:.2f} s of its {end:.2f} s sequence "
                           f"in {MAX_WALL_PER_PLANT_S:.0f} s of board time per plant second; the machine is too "
                           "busy for this plant (close other programs or run with fewer waypoints)")
    log_t, log_tip, log_obj, log_p = np.array(log_t), np.array(log_tip), np.array(log_obj), np.array(log_p)
    # each waypoint's tip: the last sample of its hold, found by time (a loaded machine skips loop
    # iterations, so an iteration count would land in a later hold)
    reached = [log_tip[np.searchsorted(log_t, (i + 1) * hold, side="left") - 1] for i in range(len(seq))]
    errors = [float(np.hypot(r[0] - x, r[2] - z)) for r, (_, x, z, _) in zip(reached, seq)]
    start, final = log_obj[0], log_obj[-1]
    place_xyz = np.array([PLACE[0], 0.0, start[2]])     # the object's centre when it stands at the place

    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(10, 4))
    (ax, bx) = fig.subplots(1, 2)
    ax.plot(log_tip[:, 0] / mm, log_tip[:, 2] / mm, lw=1, label="tip (board sensors)")
    ax.plot(log_obj[:, 0] / mm, log_obj[:, 2] / mm, lw=1, color="C1", label="object centre (board sensors)")
    ax.plot(PLACE[0] / mm, start[2] / mm, "x", color="C1", label="place target (object centre)")
    ax.axhline(TABLE_TOP / mm, color="0.3", lw=1)
    for (name, x, z, g), r in zip(seq, reached):
        ax.plot(x / mm, z / mm, "o", mfc="none", color="C3" if g else "C2")
        ax.annotate(name, (x / mm, z / mm), fontsize=7, xytext=(3, 3), textcoords="offset points")
    for q in (shp.statics(u=pressures(plans[0][0], 0)), shp.statics(u=pressures(plans[-1][0], 0))):
        P = shp.positions(q)
        ax.plot(P[:, 0] / mm, P[:, 2] / mm, color="0.6", lw=4, alpha=0.5)
    ax.set(xlabel="x [mm]", ylabel="z [mm]", aspect="equal", title="open-loop pick and place")
    ax.legend(fontsize=7)
    for c in range(5):
        bx.plot(log_t, log_p[:, c] / kPa, lw=1, label=["s1 low", "s1 up", "s2 low", "s2 up", "gripper"][c])
    bx.set(xlabel="t [s]", ylabel="measured pressure [kPa]")
    bx.legend(fontsize=7)
    save_figure(fig, out / "pick_place.png")

    return {
        "object_start_mm": [round(v / mm, 3) for v in start],
        "object_final_mm": [round(v / mm, 3) for v in final],
        "object_moved_mm": round(float(np.linalg.norm(final - start)) / mm, 3),
        "place_error_mm": round(float(np.linalg.norm(final - place_xyz)) / mm, 3),
        "lift_mm": round(float(log_obj[:, 2].max() - start[2]) / mm, 3),
        "waypoints": [name for name, *_ in seq],
        "waypoint_error_mm": [round(e / mm, 3) for e in errors],
        "max_waypoint_error_mm": round(max(errors) / mm, 3),
        "plan_error_mm": round(max(e for _, e in plans) / mm, 6),
        "activations_kPa": [[round(v / kPa, 3) for v in a] for a, _ in plans],
        "plan_time_s": round(plan_s, 3),
        "gripper_peak_kPa": round(float(log_p[:, 4].max()) / kPa, 2),
        "gripper_final_kPa": round(float(log_p[-1, 4]) / kPa, 2),
        "loop_rate_hz": round(stats.rate, 2), "loop_jitter_p99_us": round(stats.jitter_p99 * 1e6, 1),
        "loop_missed": stats.missed,
        "png": "pick_place.png",
    }


# ------------------------------------------------------------------------------------------------- the steps
def arm():
    """The manipulator beam: 4 chamber inputs (segment 1 lower/upper, segment 2 lower/upper) + gripper."""
    from soroshapes import Basis, Shapes

    shp = Shapes(Basis.pcc(2), (0, 2, 0, 0, 0, 0), length=2 * SEGMENT, section=sdf.Circle(8 * mm),
                 material=materials.DragonSkin30(), segments=12)
    for j in range(2):
        span = (j * SEGMENT, (j + 1) * SEGMENT)
        shp.add_chamber(60 * mm**2, (0.0, -5 * mm), span, name=f"seg{j}_lower")
        shp.add_chamber(60 * mm**2, (0.0, 5 * mm), span, name=f"seg{j}_upper")
    shp.add_actuator(np.zeros(shp.n), name="gripper")
    shp.add_gravity()
    return shp


def pressures(a, grip):
    """Channel pressures [Pa] of signed segment activations ``a`` (2,) and the gripper's."""
    return np.array([max(a[0], 0), max(-a[0], 0), max(a[1], 0), max(-a[1], 0), grip])


def plan(shp, targets):
    """Inverse statics for each target (x, z) [m]: activations, model tip and error [m]."""
    from scipy.optimize import least_squares

    out, a0 = [], np.zeros(2)
    for x, z in targets:
        def err(a):
            q = shp.statics(u=pressures(a, 0.0))
            tip = shp.positions(q)[-1]
            return (tip[[0, 2]] - [x, z]) / mm
        sol = least_squares(err, a0, bounds=(-P_MAX, P_MAX), x_scale=10 * kPa, xtol=1e-10)
        a0 = sol.x
        out.append((sol.x, float(np.linalg.norm(sol.fun)) * mm))
    return out


def scene(quick=False):
    """``soro play board_pick_place``: the two-segment arm of the board demo, one slider per board channel (four
    chambers 0-90 kPa, the gripper 0-60 kPa); ``soro play board_pick_place --backend sim`` drives the simulated
    board with this arm as its plant."""
    from soro.play import Channel, Scene, Target

    shp = arm()
    channels = [Channel(n, 0.0, P_MAX, label=n.replace("_", " ")) for n in shp.inputs[:4]]
    channels.append(Channel("gripper", 0.0, GRIP, label="gripper"))
    return Scene(shp, channels, target=Target(tuple(shp.positions(np.zeros(shp.n))[-1])), dt=2e-3,
                 view=(0.0, 0.0), title="board_pick_place")


# ------------------------------------------------------------------------------------------ the object plant
#: The object: a 5 g cube of 16 mm, its top centre (the grasp point) at the pick waypoint, on a table.
OBJ_MASS, OBJ_SIDE = 0.005, 16 * mm
PICK, PLACE, TABLE_TOP = (0.095, -0.062), (0.0985, -0.062), -0.062 - 16 * mm


def plant_network(measured, grasp=True):
    """The board's network plant (:class:`sorocontrol.NetworkRecipe`): the arm, the object on the table
    (:func:`soroshapes.rigid.couple_ground` at its four base corners) and the gripper
    (:func:`soroshapes.rigid.couple_grasp` at the arm's tip on the object's top centre), engaged in proportion to
    the gripper channel's pressure ``measured()[4] / GRIP`` (0..1). ``grasp=False``: no gripper coupling."""
    from soroshapes import Model
    from soroshapes.rigid import RigidBody, couple_grasp, couple_ground

    shp = arm()
    q0 = shp.statics(u=pressures([0, 0], 0))
    h = OBJ_SIDE / 2
    pose = np.eye(4)
    pose[:3, 3] = (PICK[0], 0.0, TABLE_TOP + h)
    body = RigidBody(OBJ_MASS, OBJ_MASS * OBJ_SIDE**2 / 6, pose0=pose, damping=(0.05, 3e-5), name="object")
    m = Model().add(shp, "arm", x0=np.concatenate([q0, np.zeros(shp.n)])).add(body, "object")
    corners = [(sx * h, sy * h, -h) for sx in (-1, 1) for sy in (-1, 1)]
    # 4 x 300 N/m: 0.04 mm under the 0.05 N weight; 4 x 1 N s/m: damping ratio 0.8 (critical: 2 sqrt(1200 x
    # 0.005) = 4.9 N s/m in total)
    couple_ground(m, "object", corners, stiffness=300.0, damping=1.0, friction=0.6,
                  plane=((0.0, 0.0, TABLE_TOP), (0.0, 0.0, 1.0)))
    if grasp:
        couple_grasp(m, "arm", "object", (0.0, 0.0, h), stiffness=100.0, damping=0.5,
                     engaged=lambda t: min(max(measured()[4] / GRIP, 0.0), 1.0))
    return m

