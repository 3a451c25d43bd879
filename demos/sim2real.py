r"""Sim2Real replay: a recorded video of the actuator tracked by vision, against the model (`soro demo sim2real`)
==============================================================================================================

Purpose
-------
The seed's Sim2Real comparison (Sorotoki paper, Figs. 25-26): the actuator is driven through a pressure sequence,
filmed, its markers tracked, and the tracked shape compared with the simulated one (the seed reports an average
error of +-2 mm). Here the "real" actuator is a synthetic one built differently from the model on purpose (an
as-built finger: silicone 5 % stiffer, chamber 2.5 % smaller than designed), filmed by a camera with a real lens
(radial distortion rendered, pixel noise, markers dropping out: occluded for single frames and for a 0.3 s burst),
and written as a lossless video file (``video.mkv``, FFV1). The replay knows none of that truth:

1. calibration: the camera's intrinsics and lens distortion from eight views of an ArUco grid
   (:func:`sorocontrol.vision.calibrate_intrinsics`), its pose from an ArUco sheet in the bending plane
   (:func:`sorocontrol.vision.calibrate_world`);
2. tracking: the video is read back (:class:`sorocontrol.OpenCVCamera`), the markers detected, undistorted with
   the calibration and located by rays meeting the bending plane; a marker that dropped out is filled by the
   shape estimate of the markers that were seen (:class:`sorocontrol.ShapeEstimator`: its fitted marker), so no
   frame has a gap, and the fill is reported;
3. comparison: the model (the designed finger, simulated under the same pressures) against the tracked markers,
   error in mm over time.

The rendered ground truth scores the tracking (it is not used by it).

Parameters
----------
=================  =====================================================================================
finger             100 mm, circular section R = 8 mm, Dragon Skin 10, 3 Chebyshev modes of in-plane bending,
                   chamber 40 mm^2 at 5 mm below the backbone, gravity along -z; the as-built one: c1 x 1.05,
                   chamber 39 mm^2
pressures          steps held ``hold`` s each, through a regulator of time constant 0.25 s (slow steps, as in
                   the seed's quasi-static comparison)
markers            5, at 20, 40, ..., 100 mm, radius 4 mm, red
camera             640 x 480, 60 deg field of view, 0.2 m in front of the bending plane (x-z), lens
                   k1 = -0.25, k2 = 0.08, noise 3 grey levels, 30 frames/s
dropouts           each marker hidden in a frame with probability 4 %, and the middle marker for 0.3 s
=================  =====================================================================================
"""
from pathlib import Path

import numpy as np

from sorofem.units import kPa, mm

LENGTH, NODES, FPS = 100 * mm, [2, 4, 6, 8, 10], 30.0
LENS = (-0.25, 0.08, 0.0, 0.0, 0.0)
DROP_P, BURST = 0.04, (2, 0.3)       # single-frame dropout probability; the burst: marker index, length [s]

#: The full run and the short one (`--quick`, what the tests run): pressure steps [Pa], each held [s].
FULL = dict(pressures=(20 * kPa, 45 * kPa, 60 * kPa, 30 * kPa, 0.0), hold=1.2)
QUICK = dict(pressures=(30 * kPa, 60 * kPa, 15 * kPa), hold=0.7)


def main(out: Path, quick: bool = False) -> dict:
    from sorocontrol import OpenCVCamera, ShapeEstimator
    from sorocontrol.vision import calibrate_intrinsics, calibrate_world

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    prm = QUICK if quick else FULL
    duration = prm["hold"] * len(prm["pressures"])

    # the pressure sequence, simulated on the model and on the as-built actuator
    model, real = finger(), finger(as_built=True)
    t_model, q_model = simulate(model, prm, duration)
    t_real, q_real = simulate(real, prm, duration)

    # the recording (what a lab would have): calibration views and the video
    lens = true_camera()
    views, world_view, target, world_target = calibration_views(lens)
    frames = np.arange(int(round(duration * FPS)))
    hidden = dropouts(len(frames), len(NODES))
    truth = record(out / "video.mkv", lens, real, t_real, q_real, frames, hidden)

    # replay: calibrate, track, compare
    cam = calibrate_intrinsics(views, target, distortion=2)
    cam = calibrate_world(world_view, cam, world_target)
    tracker = ShapeEstimator(finger(), model.sigma[NODES], cam, plane=((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
                             prior="elastic", min_markers=2)
    tracked, found, t_frames = [], [], []
    with OpenCVCamera(str(out / "video.mkv"), model=cam) as video:
        for frame in video:
            e = tracker.update(frame)
            tracked.append(np.where(e.found[:, None], e.markers, e.fitted))   # dropouts: the estimate's marker
            found.append(e.found)
            t_frames.append(frame.timestamp)
    tracked, found, t_frames = np.array(tracked), np.array(found), np.array(t_frames)
    sim = np.array([model.positions(q)[NODES] for q in q_at(t_model, q_model, t_frames)])

    track_err = np.linalg.norm(tracked - truth, axis=2) / mm                 # (frames, markers)
    sim_err = np.linalg.norm(tracked - sim, axis=2) / mm
    shown = len(frames) // 3 + 3                  # a frame inside the burst
    figure(out / "sim2real.png", t_frames, tracked, truth, sim, sim_err, found, prm, video_frame(out, shown),
           shown)
    return {
        "frames": int(len(t_frames)), "markers": len(NODES),
        "calibration_rms_px": round(float(cam.rms), 4),
        "calibrated_k1_k2": [round(float(v), 4) for v in cam.dist[:2]],
        "dropouts": int((~found).sum()), "dropouts_rendered": int(hidden.sum()),
        "frames_with_dropouts": int((~found).any(axis=1).sum()),
        "tracking_error_mm": {"seen_p95": round(float(np.percentile(track_err[found], 95)), 4),
                              "seen_max": round(float(track_err[found].max()), 4),
                              "filled_max": round(float(track_err[~found].max()), 4) if (~found).any() else 0.0},
        "sim2real_error_mm": {"tip_mean": round(float(sim_err[:, -1].mean()), 4),
                              "tip_max": round(float(sim_err[:, -1].max()), 4),
                              "all_mean": round(float(sim_err.mean()), 4)},
        "within_2mm_fraction": round(float((sim_err[:, -1] <= 2.0).mean()), 4),
        "nan_free": bool(np.all(np.isfinite(tracked))),
        "png": "sim2real.png", "video": "video.mkv",
    }


# ------------------------------------------------------------------------------------------------- the steps
def finger(as_built=False):
    """The designed finger, or the as-built one (silicone 5 % stiffer, chamber 2.5 % smaller)."""
    from sorofem import materials, sdf
    from soroshapes import Basis, Shapes

    mat = materials.DragonSkin10(c1=(37.8 if as_built else 36.0) * kPa)
    shp = Shapes(Basis.chebyshev(3), (0, 3, 0, 0, 0, 0), length=LENGTH, section=sdf.Circle(8 * mm), material=mat,
                 segments=10)
    shp.add_chamber((39 if as_built else 40) * mm**2, (0.0, -5 * mm), name="chamber")
    shp.add_gravity((0.0, 0.0, -9.81))
    return shp


def pressure(prm, t):
    """The regulated chamber pressure [Pa] at t [s]: steps through a first-order lag of 0.25 s."""
    p, hold = prm["pressures"], prm["hold"]
    k = min(int(t // hold), len(p) - 1)
    prev = p[k - 1] if k else 0.0
    return prev + (p[k] - prev) * (1.0 - np.exp(-(t - k * hold) / 0.25))


def simulate(shp, prm, duration):
    """Times [s] and coordinates of the beam's dynamics under the pressure sequence, from rest under gravity."""
    q0 = shp.statics(u=[0.0], steps=2)
    traj = shp.simulate(duration, 2e-3, q0=q0, u=lambda t: np.array([pressure(prm, t)]))
    return traj.t, traj.q


def q_at(t, q, times):
    """Coordinates interpolated at ``times`` [s] (linear in time)."""
    return np.column_stack([np.interp(times, t, q[:, i]) for i in range(q.shape[1])])


def true_camera():
    """The lab's camera: 60 deg, 0.2 m in front of the bending plane, with its lens (the replay does not know it)."""
    from sorocontrol import CameraModel
    from sorocontrol.camera import look_at

    ideal = CameraModel.from_fov(60.0, pose=look_at((0.05, -0.2, 0.0), (0.05, 0.0, 0.0), up=(0, 0, 1)))
    return CameraModel(ideal.K, ideal.width, ideal.height, ideal.pose, dist=np.array(LENS))


def calibration_views(lens):
    """Eight views of an ArUco grid held at different tilts (for the intrinsics), one view of a sheet in the
    bending plane behind the finger (for the pose); returns (views, world view, grid, sheet)."""
    from sorocontrol import ArucoTarget, SyntheticCamera
    from sorocontrol.camera import look_at

    grid = ArucoTarget.grid(5, 6, 0.022, 0.006)
    views = []
    for eye in [(0, 0, 0.2), (0.08, 0.02, 0.19), (-0.08, 0.04, 0.19), (0.02, -0.09, 0.18), (-0.04, 0.08, 0.2),
                (0.09, -0.06, 0.17), (-0.09, -0.05, 0.18), (0.05, 0.09, 0.18)]:
        cam = lens.with_pose(look_at(eye, (0, 0, 0), up=(0, 1, 0)))
        views.append(SyntheticCamera(cam, noise=3.0, aruco=grid, seed=len(views), supersample=2)
                     .render(np.zeros((0, 3))).image)
    # the sheet in the plane y = 0.03 (behind the finger), facing the camera: sheet x -> world x, sheet y -> z
    T = np.eye(4)
    T[:3, :3] = np.column_stack([(1, 0, 0), (0, 0, 1), (0, -1, 0)])
    T[:3, 3] = (0.05, 0.03, 0.0)
    sheet = ArucoTarget.grid(2, 3, 0.03, 0.01, pose=T)
    world = SyntheticCamera(lens, noise=3.0, aruco=sheet, seed=99).render(np.zeros((0, 3))).image
    return views, world, grid, sheet


def dropouts(frames, markers, seed=7):
    """(frames, markers) flags of the markers hidden in each frame: random single frames and one burst."""
    hidden = np.random.default_rng(seed).random((frames, markers)) < DROP_P
    k0 = frames // 3
    hidden[k0:k0 + int(round(BURST[1] * FPS)), BURST[0]] = True
    return hidden


def record(path, lens, real, t_real, q_real, frames, hidden):
    """Render the as-built finger's markers through the lens (noise, dropouts) to a lossless video file
    (FFV1); returns the true marker positions (frames, markers, 3) [m]."""
    from sorocontrol import SyntheticCamera
    from sorocontrol.camera import require_cv2

    cv2 = require_cv2()
    cam = SyntheticCamera(lens, marker_radius=4 * mm, noise=3.0, rate=FPS, seed=3)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), FPS, (lens.width, lens.height))
    if not writer.isOpened():
        from sorofem.errors import DependencyError
        raise DependencyError("OpenCV cannot write FFV1 video (lossless) here: install an OpenCV with FFmpeg")
    truth = []
    try:
        for k, q in zip(frames, q_at(t_real, q_real, frames / FPS)):
            P = real.positions(q)[NODES]
            writer.write(cam.render(P, k / FPS, hidden=hidden[k]).image)
            truth.append(P)
    finally:
        writer.release()
    return np.array(truth)


def video_frame(out, k):
    """Frame ``k`` of the recorded video (BGR)."""
    from sorocontrol import OpenCVCamera

    with OpenCVCamera(str(out / "video.mkv")) as video:
        for frame in video:
            if frame.index == k:
                return frame.image
    return None


def figure(path, t, tracked, truth, sim, sim_err, found, prm, image, shown):
    """Tip x and z over time (model, tracked, truth) in mm; the model-vs-tracked error in mm with the seed's +-2 mm
    band and the dropouts marked; a frame of the recording."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(15, 4.5))
    ax, bx, cx = fig.subplots(1, 3)
    for i, name in ((0, "x"), (2, "z")):
        ax.plot(t, sim[:, -1, i] / mm, "-", lw=1.5, label=f"tip {name}, model")
        ax.plot(t, tracked[:, -1, i] / mm, ".", ms=3, label=f"tip {name}, tracked")
        ax.plot(t, truth[:, -1, i] / mm, "k:", lw=1)
    ax.plot([], [], "k:", label="rendered truth")
    ax.set(xlabel="t [s]", ylabel="tip position [mm]", title="pressure steps " + ", ".join(
        f"{p / kPa:g}" for p in prm["pressures"]) + " kPa")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    bx.axhspan(0, 2, color="0.9", label="within the seed's +-2 mm")
    for j in range(sim_err.shape[1]):
        bx.plot(t, sim_err[:, j], lw=1, label=f"marker {j + 1} ({20 * (j + 1)} mm)")
    drop = ~found
    bx.plot(t[drop.any(axis=1)], np.zeros(drop.any(axis=1).sum()), "rx", ms=4, label="frames with a dropout")
    bx.set(xlabel="t [s]", ylabel="|tracked - model| [mm]", title="Sim2Real error per marker")
    bx.legend(fontsize=7)
    bx.grid(alpha=0.3)
    if image is not None:
        cx.imshow(image[..., ::-1])
    cx.set_title(f"frame {shown} of the recording: markers {list(np.flatnonzero(~found[shown]) + 1)} dropped out",
                 fontsize=10)
    cx.axis("off")
    save_figure(fig, path)
