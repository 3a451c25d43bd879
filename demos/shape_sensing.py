r"""Closed-loop control from camera-based shape sensing (`soro demo shape_sensing`)
===========================================================================

Purpose
-------
The seed's shape sensing (Sorotoki paper, Sec. VI-E): colour markers on a soft finger are tracked by a
camera, and the finger's configuration is estimated in the loop by inverse kinematics of its beam model
with the quasi-static null-space prior. Here the loop is closed on the estimate: the finger is the plant of
the simulated pneumatic board (:meth:`sorocontrol.Board.simulated`), a synthetic camera
(:class:`sorocontrol.SyntheticCamera`) renders its five markers at 20 Hz from the board's true state, the
host detects them (:class:`sorocontrol.MarkerDetector`: HSV threshold, Hough circles, sub-pixel centroids),
lifts them to 3D (camera rays meeting the bending plane), estimates :math:`\hat q`
(:class:`sorocontrol.ShapeEstimator`) and sets the chamber pressure from the *estimated* bending angle
(feed-forward from the model's static map plus integral feedback). The true state is used only to render the
images and to score. Figures: the estimation error of the tip and of the bending angle, the angle tracking
error at the end of each step, the rate and time split of detection and estimation.

Parameters
----------
=================  =====================================================================================
finger             100 mm, circular section R = 8 mm, Dragon Skin 10 (Yeoh preset, damping ratio 0.1),
                   3 Chebyshev modes of in-plane bending (``dofs = (0, 3, 0, 0, 0, 0)``), gravity along -z
chamber            area 40 mm^2 at 5 mm below the backbone (bends the finger up), 0-60 kPa on the board
markers            5, at 20, 40, 60, 80, 100 mm (nodes of the model), radius 4 mm, red
camera             640 x 480, 60 deg field of view, 0.15 m in front of the bending plane (x-z), noise 2 grey
                   levels
loop               20 Hz (the camera), bending angle steps 20, 50, 35 deg held 2 s each (quick: 20, 45 deg,
                   1.5 s), each smoothed by a first-order lag of 0.2 s
=================  =====================================================================================
"""
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

LENGTH, P_MAX = 100 * mm, 60 * kPa
NODES = [2, 4, 6, 8, 10]


#: The full run and the short one (`--quick`, what the tests run): bending angle steps [deg], each held [s].
FULL = dict(refs=(20.0, 50.0, 35.0), hold=2.0)
QUICK = dict(refs=(20.0, 45.0), hold=1.5)


def main(out: Path, quick: bool = False) -> dict:
    from sorocontrol import Board, CameraModel, EstimatorThread, ShapeEstimator, SyntheticCamera
    from sorocontrol.camera import look_at

    shp, cam_shp = finger(), finger()       # the loop's model, and the estimator thread's (each its workspace)
    grid = np.linspace(0.0, P_MAX, 13)
    static_q = [shp.statics(u=[p], steps=2) for p in grid]
    static = np.array([angle(shp, q) for q in static_q])
    prm = QUICK if quick else FULL
    refs, hold, rate = list(prm["refs"]), prm["hold"], 20.0
    ki = 1.5 * (grid[-1] - grid[0]) / (static[-1] - static[0])        # Pa/(deg s): crossover ~1.5 rad/s

    cam = CameraModel.from_fov(60.0, pose=look_at((0.05, -0.15, 0.02), (0.05, 0.0, 0.02), up=(0, 0, 1)))
    video = SyntheticCamera(cam, marker_radius=4 * mm, noise=2.0, rate=rate, seed=1)
    est = ShapeEstimator(cam_shp, cam_shp.sigma[NODES], cam, plane=((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
                         prior="equilibrium")
    # warm-up before the board starts: compile the estimator's kernels and lock on the markers of the rest shape
    q_rest = static_q[0]
    for _ in range(3):
        est.update(video.render(cam_shp.positions(q_rest)[NODES], 0.0), u=[0.0])
    # the loop sends a command every period whatever a frame costs: rendering, detection and IK run in a
    # background thread on the newest frame (an older one still waiting is dropped and counted), and the
    # control law uses the newest estimate; the board's watchdog (0.5 s) is left as it is
    log, integral, t_prev = [], 0.0, 0.0
    with Board.simulated(channels=1, beam=shp, p_min=0.0, p_max=P_MAX, board_rate=200.0) as brd, \
            EstimatorThread(est, keep=True) as worker:
        state = brd.read()
        for t in brd.loop(duration=hold * len(refs), rate=rate):
            q_true = state.sensors[3:]
            worker.submit(lambda q=q_true, t=t: video.render(cam_shp.positions(q)[NODES], t),
                          u=[state.measured[0]], tag=(t, q_true))
            e = worker.latest
            theta_hat = angle(shp, e.q)
            step = min(int(t // hold), len(refs) - 1)   # steps filtered by a first-order lag of 0.2 s
            prev = refs[step - 1] if step else static[0]
            ref = refs[step] + (prev - refs[step]) * np.exp(-(t - step * hold) / 0.2)
            u = float(np.interp(ref, static, grid)) + ki * integral
            if e.t > t_prev and 0.0 < u < P_MAX:   # each estimate once, over the time since the last one: a
                integral += (ref - theta_hat) * (e.t - t_prev)    # slow estimator does not wind the integral up
            t_prev = max(t_prev, e.t)
            state = brd.set_pressure([u])
            log.append((t, ref, angle(shp, q_true), theta_hat, state.measured[0]))
        stats = brd.loop_stats
    scored = np.array([(t, np.linalg.norm(e.tip - shp.positions(q)[-1]), abs(angle(shp, q) - angle(shp, e.q)),
                        e.detect_time, e.solve_time, e.found.sum()) for (t, q), e in worker.results])
    log = np.array(log)
    t, ref, th, th_hat = log[:, 0], log[:, 1], log[:, 2], log[:, 3]
    end_err = [float(abs(ref[(t < (i + 1) * hold)][-1] - th[(t < (i + 1) * hold)][-1])) for i in range(len(refs))]
    frame = video.render(shp.positions(worker.results[-1][0][1])[NODES], t[-1])

    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 4))
    (ax, bx) = fig.subplots(1, 2)
    ax.plot(t, ref, "k--", lw=1, label="reference")
    ax.plot(t, th, lw=1.5, label="true angle (board)")
    ax.plot(t, th_hat, ".", ms=3, label="estimated from the camera")
    ax.set(xlabel="t [s]", ylabel="bending angle [deg]")
    ax.legend(fontsize=8)
    bx.imshow(frame.image[..., ::-1])
    bx.set_title("last synthetic frame (640 x 480)")
    bx.axis("off")
    save_figure(fig, out / "shape_sensing.png")

    return {
        "reference_deg": refs, "end_error_deg": [round(v, 4) for v in end_err],
        "angle_estimation_error_deg": error_stats(scored[:, 2]),
        "tip_estimation_error_mm": error_stats(scored[:, 1] / mm),
        "markers_found_min": int(scored[:, 5].min()), "frames": int(len(log)),
        "frames_estimated": worker.done, "frames_skipped": worker.skipped, "frames_failed": worker.failed,
        "estimation_rate_hz": round(worker.done / (hold * len(refs)), 2),
        "detect_ms": round(1e3 * float(scored[:, 3].mean()), 3),
        "estimate_ms": round(1e3 * float(scored[:, 4].mean()), 3),
        "loop_rate_hz": round(stats.rate, 2), "loop_missed": stats.missed,
        "png": "shape_sensing.png",
    }


# ------------------------------------------------------------------------------------------------- the steps
def finger():
    from soroshapes import Basis, Shapes

    shp = Shapes(Basis.chebyshev(3), (0, 3, 0, 0, 0, 0), length=LENGTH, section=sdf.Circle(8 * mm),
                 material=materials.DragonSkin10(), segments=10)
    shp.add_chamber(40 * mm**2, (0.0, -5 * mm), name="chamber")
    shp.add_gravity((0.0, 0.0, -9.81))
    return shp


def angle(shp, q):
    """Bending angle of the tip [deg] about -y (positive: the tip turns up, toward +z)."""
    R = shp.forward_kinematics(q)[-1, :3, :3]
    return float(np.degrees(np.arctan2(R[2, 0], R[0, 0])))


def error_stats(err):
    """Mean, 95th percentile and maximum of a series of errors (rounded for the report)."""
    return {"mean": round(float(np.mean(err)), 4), "p95": round(float(np.percentile(err, 95)), 4),
            "max": round(float(np.max(err)), 4)}
