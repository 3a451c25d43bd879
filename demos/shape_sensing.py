r"""Contact-robust shape sensing of a PneuNet with its FEM-based DVS basis (`soro demo shape_sensing`)
=================================================================================================

Purpose
-------
The seed's Sec. VI-E (Figs. 34-36): a PneuNet's beam model gets its strain basis from FEM (the DVS basis:
three bending modes), colour markers on the actuator are tracked by a camera, and its configuration is estimated
in real time by inverse kinematics in that basis, also while an obstacle presses on it. Here:

1. FEM (2D plane strain, :mod:`sorofem`) inflates the PneuNet of ``dvs_pneunet`` freely and wrapping a cylinder;
   the snapshots are written as files (``free.h5``, ``wrap.h5``) and read back without DOLFINx
   (:func:`soroshapes.dvs.recover_strains`): three DVS bending modes (:func:`soroshapes.dvs.dvs_basis`) and the
   actuation identified on the free ramp (:func:`soroshapes.dvs.identify`). A third FEM case, the actuator
   pressed by another cylinder (``pressed.h5``, not used for the basis), is the held-out test.
2. Offline, the held-out FEM backbones are rendered by the synthetic camera and estimated in the DVS basis and in a
   Chebyshev basis of as many modes: the tip error against FEM says what each basis costs in contact.
3. On the simulated board (:meth:`sorocontrol.Board.simulated`), the plant is the DVS beam pressed by the held-out
   cylinder (beam SDF contact). A camera renders its five markers from the board's true state, the host detects
   them and estimates :math:`\hat q` with no prior (five markers fix the three modes; the quasi-static prior
   would assume free bending, which the obstacle breaks), and the chamber pressure follows the *estimated* tip
   angle (feed-forward from the model's static map with the obstacle, plus integral feedback). The loop runs at
   the seed's 60 Hz and sends to the board every period whatever a frame costs: rendering, detection and IK run
   in a thread (:class:`sorocontrol.EstimatorThread`) on the newest frame; frames it could not take are skipped
   and counted. The board's watchdog (0.5 s) is the default one. The plant with its SDF contact integrates in
   the beam's compiled loop (issue 26; before, on the Python step loop: ``plant_realtime_factor`` 0.03-0.11);
   measured 0.165 of real time at a load average of 11 on 2 cores (the plant's server process gets about a
   sixth of a core there) and 0.58 at a load of 6.7 (loop 59.2 Hz, estimates 16.3 Hz): the board's plant skips the time it cannot simulate, so on a loaded machine the true
   angle moves in steps and slower than the reference asks; the estimation is scored against the state the
   board reports.

Parameters
----------
=================  =====================================================================================
actuator           the 2D PneuNet of ``pneunet_inflation`` (Ecoflex 00-30, Dragon Skin 30 base layer), 4 chambers
                   (quick) or 7, clamped left; 0-5 kPa (quick) or 0-6 kPa; beam: backbone in the base layer,
                   20 segments, damping ratio 0.1
obstacles          basis: the cylinder of ``dvs_pneunet`` (r = 0.26 L at x = 0.55 L); held out: r = 0.2 L at
                   x = 0.75 L, its top 0.5 mm below the base layer
markers            5, at 20, 40, ..., 100 % of the length (model nodes), radius 1.5 mm, red
camera             640 x 480, 60 deg field of view, 0.08 m (quick) / 0.14 m above the bending plane, noise 2
                   grey levels
loop               60 Hz; tip angle steps at 50 % and 90 % of the angle reached at the top pressure with the
                   obstacle, each held 1.5 s (quick) / 2 s and smoothed by a first-order lag of 0.2 s
=================  =====================================================================================
"""
import time
from pathlib import Path

import numpy as np

from sorofem.snapshots import input_name
from sorofem.units import kPa, mm

RATE, SEGMENTS, NODES = 60.0, 20, [4, 8, 12, 16, 20]
#: The held-out obstacle: radius, centre x (fractions of the length) and the gap below the base layer [m].
PRESSED = (0.15, 0.85, 0.3 * mm)

#: The full run and the short one (`--quick`, what the tests run): chambers, FEM element size [m], top
#: pressure [Pa], FEM load steps, camera distance [m], angle steps (fractions of the top angle), hold [s].
FULL = dict(chambers=7, size=0.8 * mm, p_max=6 * kPa, steps=16, distance=0.14, refs=(0.5, 0.9), hold=2.0)
QUICK = dict(chambers=4, size=1.2 * mm, p_max=5 * kPa, steps=10, distance=0.08, refs=(0.5, 0.9), hold=1.5)


def main(out: Path, quick: bool = False) -> dict:
    from sorocontrol import Board, EstimatorThread
    from soroshapes import Basis
    from soroshapes.dvs import Backbone, dvs_basis, identify, recover_strains

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    prm = QUICK if quick else FULL
    pn = pneunet_module()
    length = prm["chambers"] * pn.PITCH

    # 1. FEM snapshots (files) -> strains -> DVS basis and identified actuation
    files = fem_snapshots(out, pn, prm)
    backbone = Backbone.line([0.0, pn.LAYER / 2], [length, pn.LAYER / 2])
    free, wrap, pressed = (recover_strains(files[k], backbone, samples=81) for k in ("free", "wrap", "pressed"))
    bases, dofs, info = dvs_basis([free, wrap], (0, 0, 3, 0, 0, 0))
    pressure = input_name("pressure", "cavity_0")        # every chamber at the same pressure
    models = {"dvs": lambda: beam(pn, length, bases, dofs), "chebyshev": lambda: beam(pn, length, Basis.chebyshev(3),
                                                                                       dofs)}
    plant = models["dvs"]()
    identify(plant, free, inputs=[pressure])
    add_obstacle(plant, pn, length)

    # 2. offline: the held-out FEM case seen by the camera, estimated in each basis
    cam, video = camera(length, prm["distance"])
    offline = {name: offline_errors(make(), pressed, cam, video) for name, make in models.items()}

    # 3. closed loop on the simulated board at 60 Hz
    grid = np.linspace(0.0, prm["p_max"], 11)
    static = np.array([angle(plant, plant.statics(u=[p], steps=4)) for p in grid])
    refs = [float(f * static[-1]) for f in prm["refs"]]
    hold = prm["hold"]
    ki = 1.5 * (grid[-1] - grid[0]) / (static[-1] - static[0])        # Pa/(deg s): crossover ~1.5 rad/s
    # the plant's real-time factor (simulated / wall time): the beam with SDF contact integrates on the Python
    # path, slower than real time, and the board's plant then skips time (its max_advance): reported
    t0 = time.perf_counter()
    plant.simulate(0.1, 5e-3, q0=plant.statics(u=[0.0]), u=[0.5 * prm["p_max"]])
    plant_rtf = 0.1 / (time.perf_counter() - t0)
    est_shp = models["dvs"]()                # the estimator thread's own model (its workspace)
    est = estimator(est_shp, cam, video, plant.statics(u=[0.0]))
    log, integral, t_prev = [], 0.0, 0.0
    with Board.simulated(channels=1, beam=plant, p_min=0.0, p_max=prm["p_max"], board_rate=200.0) as brd, \
            EstimatorThread(est, keep=True) as worker:
        state = brd.read()
        for t in brd.loop(duration=hold * len(refs), rate=RATE):
            q_true = state.sensors[3:]
            worker.submit(lambda q=q_true, t=t: video.render(est_shp.positions(q)[NODES], t), tag=(t, q_true))
            e = worker.latest
            theta_hat = angle(plant, e.q)
            step = min(int(t // hold), len(refs) - 1)   # steps filtered by a first-order lag of 0.2 s
            prev = refs[step - 1] if step else static[0]
            ref = refs[step] + (prev - refs[step]) * np.exp(-(t - step * hold) / 0.2)
            u = float(np.interp(ref, static, grid)) + ki * integral
            if e.t > t_prev and 0.0 < u < prm["p_max"]:   # each estimate once, over the time since the last:
                integral += (ref - theta_hat) * (e.t - t_prev)    # a slow estimator does not wind it up
            t_prev = max(t_prev, e.t)
            state = brd.set_pressure([min(max(u, 0.0), prm["p_max"])])     # within the board's limits
            log.append((t, ref, angle(plant, q_true), theta_hat, state.measured[0]))
        stats = brd.loop_stats
    scored = np.array([(t, np.linalg.norm(e.tip - plant.positions(q)[-1]), abs(angle(plant, q) - angle(plant, e.q)),
                        e.detect_time, e.solve_time, e.found.sum()) for (t, q), e in worker.results])
    log = np.array(log)
    t, ref, th, th_hat = log[:, 0], log[:, 1], log[:, 2], log[:, 3]
    end_err = [float(abs(ref[(t < (i + 1) * hold)][-1] - th[(t < (i + 1) * hold)][-1])) for i in range(len(refs))]
    q_last = worker.results[-1][0][1]

    figure(out / "shape_sensing.png", t, ref, th, th_hat, plant, q_last, worker.results[-1][1], pressed, offline,
           video.render(plant.positions(q_last)[NODES], t[-1]), pn, length)
    return {
        "dvs_energy": info[2]["energy"], "length_mm": round(length / mm, 3),
        "offline_tip_error_mm": {name: round(v["tip_max_mm"], 4) for name, v in offline.items()},
        "offline_shape_error_mm": {name: round(v["shape_max_mm"], 4) for name, v in offline.items()},
        "reference_deg": [round(r, 3) for r in refs], "end_error_deg": [round(v, 4) for v in end_err],
        "angle_estimation_error_deg": error_stats(scored[:, 2]),
        "tip_estimation_error_mm": error_stats(scored[:, 1] / mm),
        "markers_found_min": int(scored[:, 5].min()), "frames": int(len(log)),
        "frames_estimated": worker.done, "frames_skipped": worker.skipped, "frames_failed": worker.failed,
        "estimation_rate_hz": round(worker.done / (hold * len(refs)), 2),
        "detect_ms": round(1e3 * float(scored[:, 3].mean()), 3),
        "estimate_ms": round(1e3 * float(scored[:, 4].mean()), 3),
        "loop_rate_hz": round(stats.rate, 2), "loop_target_hz": RATE, "loop_missed": stats.missed,
        "plant_realtime_factor": round(plant_rtf, 3),
        "png": "shape_sensing.png",
    }


# ------------------------------------------------------------------------------------------------- the steps
def pneunet_module():
    """The ``pneunet_inflation`` demo as a module (its actuator geometry and FEM builder)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("pneunet_inflation",
                                                  Path(__file__).resolve().parent / "pneunet_inflation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def obstacle(length, which):
    """(radius, (x, y)) [m] of the basis's cylinder (``"wrap"``, that of ``dvs_pneunet``) or the held-out one."""
    if which == "wrap":
        r = 0.26 * length
        return r, (0.55 * length, -r - 1 * mm)
    r = PRESSED[0] * length
    return r, (PRESSED[1] * length, -r - PRESSED[2])


def fem_snapshots(out, pn, prm):
    """FEM pressure ramps of the actuator: free, wrapping the basis's cylinder, pressed by the held-out one; each
    written as a snapshot file. Returns {case: path}."""
    from sorofem import sdf

    files = {}
    for case in ("free", "wrap", "pressed"):
        fem, _ = pn.build(2, prm["chambers"], prm["size"], prm["p_max"])
        if case != "free":
            r, c = obstacle(prm["chambers"] * pn.PITCH, case)
            fem.add_contact(sdf.Circle(r, center=c))
        files[case] = out / f"{case}.h5"
        # the first step cut to a linear response of 1 % of the body (pneunet_inflation's ramp): with the mesh
        # following the layer's top, the pressed case's full first step no longer converged
        fem.solve(steps=prm["steps"], max_step=1.0 / prm["steps"], linear_start=pn.LINEAR_START).save(files[case])
    return files


def beam(pn, length, bases, dofs):
    """The beam of the actuator: backbone in the base layer from the clamped end, the actuator's section."""
    from sorofem import materials, sdf
    from soroshapes import Shapes

    return Shapes(bases, dofs, length=length, section=sdf.Rectangle(pn.WIDTH, pn.HEIGHT),
                  material=materials.Ecoflex0030(), base=np.array([0.0, pn.LAYER / 2, 0.0]), damping=0.1,
                  segments=SEGMENTS)


def add_obstacle(shp, pn, length):
    """The held-out cylinder as an SDF contact of the beam (the backbone lies LAYER/2 above the bottom face)."""
    from sorofem import sdf

    r, c = obstacle(length, "pressed")
    shp.contact_radius = pn.LAYER / 2
    return shp.add_contact(sdf.Cylinder(r, 1.0, center=(c[0], c[1], 0.0)))


def camera(length, distance):
    """The camera above the bending plane (z = 0) and its synthetic renderer (markers of radius 1.5 mm)."""
    from sorocontrol import CameraModel, SyntheticCamera
    from sorocontrol.camera import look_at

    c = (0.5 * length, -0.2 * length, 0.0)
    cam = CameraModel.from_fov(60.0, pose=look_at((c[0], c[1], distance), c, up=(0, 1, 0)))
    return cam, SyntheticCamera(cam, marker_radius=1.5 * mm, noise=2.0, rate=RATE, seed=1)


def estimator(shp, cam, video, q0):
    """A ShapeEstimator of the five markers with no prior (they fix the three modes), warmed up on the rest
    shape (compiles its kernels before the board starts)."""
    from sorocontrol import ShapeEstimator

    est = ShapeEstimator(shp, shp.sigma[NODES], cam, plane=((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), prior=None)
    for _ in range(2):
        est.update(video.render(shp.positions(q0)[NODES], 0.0))
    return est


def offline_errors(shp, data, cam, video):
    """Estimate each FEM backbone of ``data`` from its rendered markers in the basis of ``shp``: the largest tip
    error and root-mean-square backbone error [mm] against FEM, and the estimates."""
    P = data.positions()
    est = estimator(shp, cam, video, np.zeros(shp.n))
    tips, shapes, qs = [], [], []
    for k in range(len(data.times)):
        markers = np.column_stack([np.interp(shp.sigma[NODES], data.sigma, P[k, :, i]) for i in range(3)])
        e = est.update(video.render(markers, float(k)))
        B = np.column_stack([np.interp(data.sigma, shp.sigma, e.backbone[:, i]) for i in range(3)])
        tips.append(np.linalg.norm(e.tip - P[k, -1]) / mm)
        shapes.append(np.sqrt(np.mean(np.sum((B - P[k]) ** 2, axis=1))) / mm)
        qs.append(e.q)
    return {"tip_max_mm": float(max(tips)), "shape_max_mm": float(max(shapes)), "tip_mm": tips, "q": qs,
            "shp": shp}


def angle(shp, q):
    """Bending angle of the tip [deg] about -z (positive: the tip turns down, toward the obstacles)."""
    R = shp.forward_kinematics(q)[-1, :3, :3]
    return float(-np.degrees(np.arctan2(R[1, 0], R[0, 0])))


def error_stats(err):
    """Mean, 95th percentile and maximum of a series of errors (rounded for the report)."""
    return {"mean": round(float(np.mean(err)), 4), "p95": round(float(np.percentile(err, 95)), 4),
            "max": round(float(np.max(err)), 4)}


def figure(path, t, ref, th, th_hat, plant, q_last, e_last, pressed, offline, frame, pn, length):
    """Three panels: the loop's tip angle (reference, true, estimated), the backbones in mm (FEM pressed by the
    held-out cylinder vs its DVS and Chebyshev estimates; the board's plant and its estimate), the last frame."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from sorofem.io import save_figure

    fig = Figure(figsize=(15, 4.5))
    ax, bx, cx = fig.subplots(1, 3, gridspec_kw=dict(width_ratios=[1.1, 1.0, 1.0]))
    ax.plot(t, ref, "k--", lw=1, label="reference")
    ax.plot(t, th, lw=1.5, label="true tip angle (board's plant)")
    ax.plot(t, th_hat, ".", ms=2, label="estimated from the camera (DVS basis)")
    ax.set(xlabel="t [s]", ylabel="tip bending angle [deg]", title=f"closed loop at {RATE:g} Hz, pressed by a cylinder")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    r, c = obstacle(length, "pressed")
    bx.add_patch(Circle((c[0] / mm, c[1] / mm), r / mm, color="0.85", zorder=0))
    P = pressed.positions()[-1] / mm
    bx.plot(P[:, 0], P[:, 1], "k-", lw=3, alpha=0.4, label="FEM, top pressure (held out)")
    for name, style in (("dvs", "C0--"), ("chebyshev", "C3:")):
        B = offline[name]["shp"].positions(offline[name]["q"][-1]) / mm
        bx.plot(B[:, 0], B[:, 1], style, lw=1.5,
                label=f"{name} estimate (tip {offline[name]['tip_mm'][-1]:.2f} mm off)")
    B = plant.positions(q_last) / mm
    bx.plot(B[:, 0], B[:, 1], "C2-", lw=1, label="board's plant, last frame")
    bx.plot(e_last.backbone[:, 0] / mm, e_last.backbone[:, 1] / mm, "C1.", ms=4, label="its estimate")
    bx.set(xlabel="x [mm]", ylabel="y [mm]", aspect="equal", title="backbones [mm]")
    bx.legend(fontsize=7, loc="lower left")
    bx.grid(alpha=0.3)
    cx.imshow(frame.image[..., ::-1])
    cx.set_title("last synthetic frame (640 x 480)")
    cx.axis("off")
    save_figure(fig, path)
