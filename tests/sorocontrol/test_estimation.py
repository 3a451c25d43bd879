"""Shape estimation (sorocontrol.estimation) on synthetic sequences, against the beam that made the frames.

Tolerances. The frames are rendered from the same model that estimates, so the error comes only from the
image: the detector's centres are within 0.5 px (asserted in test_vision; measured a few hundredths of a pixel),
which at the cameras used here (about 0.35-0.45 m, f = 554 px) is 0.3-0.4 mm on the markers; five markers over
three modes average it down, so the tip must be within 0.1 mm (measured about 0.02 mm), the depth path within
0.3 mm (the depth image adds its interpolation). The null-space prior is checked where it matters: with one
marker (the tip) and three modes, the shape is not determined by the marker; if the beam is in quasi-static
equilibrium under a tip force (and gravity), the prior recovers the whole backbone (to 0.05 mm, the tolerance
of the IK and the Gauss-Newton steps), and an estimate without it (or with the wrong prior) is off by more.
"""
import numpy as np
import pytest

pytest.importorskip("cv2")

from sorofem import materials, sdf  # noqa: E402
from sorofem.errors import DataError, ParameterError  # noqa: E402
from soroshapes import Basis, Shapes  # noqa: E402
from sorocontrol.camera import CameraModel, SyntheticCamera, look_at  # noqa: E402
from sorocontrol.estimation import EstimatorThread, ShapeEstimator, run_sensing  # noqa: E402
from sorocontrol.vision import MarkerDetector  # noqa: E402

L = 0.2


def beam(dofs=(0, 0, 3, 0, 0, 0), E=1e6, gravity=None):
    shp = Shapes(Basis.chebyshev(3), dofs=dofs, length=L, section=sdf.Circle(0.005),
                 material=materials.NeoHookean(E=E, nu=0.45, density=1000.0), damping=0.0, segments=10)
    if gravity is not None:
        shp.add_gravity(gravity)
    return shp


def q_planar(t):
    return np.array([8 * np.sin(2 * np.pi * 0.5 * t), 4 * np.sin(2 * np.pi * 0.8 * t), 1.5 * np.cos(3 * t)])


def test_planar_sequence_tip_within_0_1_mm():
    """A prescribed bending motion seen from above; markers located by rays meeting the bending plane."""
    shp = beam()
    nodes = [2, 4, 6, 8, 10]
    cam = CameraModel.from_fov(60.0, pose=look_at((0.11, -0.01, 0.42), (0.11, -0.01, 0.0), up=(0, 1, 0)))
    syn = SyntheticCamera(cam, lambda t: shp.positions(q_planar(t))[nodes], marker_radius=4e-3, noise=2.0,
                          rate=25.0, seed=2)
    est = ShapeEstimator(shp, shp.sigma[nodes], cam, MarkerDetector(5, radius=(3, 9)),
                         plane=((0, 0, 0), (0, 0, 1)))            # starts straight: the first frame is a full search
    errs = []
    with syn:
        for _ in range(40):
            f = syn.read()
            e = est.update(f)
            assert e.found.all() and e.converged
            errs.append(np.linalg.norm(e.tip - shp.positions(q_planar(f.timestamp))[-1]))
    errs = np.array(errs)
    print(f"\nplanar, 5 markers, rays: tip error max {1e3 * errs.max():.4f} mm, mean {1e3 * errs.mean():.4f} mm")
    assert errs.max() < 1e-4
    assert e.marker_error < 1e-4


def test_depth_sequence_of_a_spatial_motion():
    """Bending in both directions (not planar): run_sensing picks the depth path by itself."""
    shp = beam(dofs=(0, 3, 3, 0, 0, 0))

    def q(t):
        return np.array([5 * np.sin(2 * t), 2 * np.cos(3 * t), 0.5, 6 * np.sin(2.5 * t + 0.3), 2.0, -1.0])
    res = run_sensing(shp, q, duration=1.0, rate=20, noise=2.0)
    print(f"\nspatial, depth: tip error max {1e3 * res['tip_error_max']:.4f} mm, backbone "
          f"{1e3 * res['backbone_error_max']:.4f} mm, {res['rate_hz']:.0f} Hz")
    assert res["depth"] and res["missed_frames"] == 0 and res["frames"] == 20
    assert res["tip_error_max"] < 3e-4


def _equilibria(shp_factory, forces):
    """Backbones (and q) of the beam in static equilibrium under tip forces ``forces`` (k, 3) [N]."""
    out = []
    for f in forces:
        s = shp_factory()
        s.add_point_load(force=f)
        q = s.statics(steps=2)
        out.append((q, s.positions(q)))
    return out


def _track_tip(shp, truth, prior, q0):
    est = ShapeEstimator(shp, [L], prior=prior, q0=q0)
    return np.array([np.abs(est.fit(P[-1][None]).backbone - P).max() for _, P in truth])


def test_elastic_prior_recovers_the_shape_from_the_tip_alone():
    """Without gravity, the least strained shape that reaches a tip position is the equilibrium under a tip
    force (K q = A^T f is the stationarity condition): the prior recovers the backbone, the bare IK does not."""
    truth = _equilibria(beam, [(0.0, fy, 0.0) for fy in np.linspace(0.01, 0.05, 5)])
    with_prior = _track_tip(beam(), truth, "elastic", np.zeros(3))
    without = _track_tip(beam(), truth, None, np.zeros(3))
    print(f"\ntip marker only: backbone error with the elastic prior {1e3 * with_prior.max():.5f} mm, "
          f"without {1e3 * without.max():.4f} mm")
    assert with_prior.max() < 5e-5
    assert without.max() > 5 * with_prior.max() and without.max() > 1e-4


def test_equilibrium_prior_with_gravity_and_a_tip_force():
    """The seed's prior K q - f_g(q) - G u: with gravity in the bending plane it recovers the shape from the tip;
    the purely elastic prior does not (it ignores the beam's weight)."""
    def factory():
        return beam(E=2e6, gravity=(0.0, -9.81, 0.0))
    truth = _equilibria(factory, [(0.0, fy, 0.0) for fy in np.linspace(0.0, 0.04, 9)])
    q0 = truth[0][0]
    eq = _track_tip(factory(), truth, "equilibrium", q0)
    el = _track_tip(factory(), truth, "elastic", q0)
    print(f"\ngravity + tip force, tip marker only: backbone error, equilibrium prior {1e3 * eq.max():.4f} mm, "
          f"elastic prior {1e3 * el.max():.4f} mm")
    assert eq.max() < 5e-5
    assert el.max() > 3 * eq.max()


def test_missing_markers_and_bad_input():
    shp = beam()
    q = np.array([5.0, -2.0, 1.0])
    P = shp.positions(q)[[4, 7, 10]]
    est = ShapeEstimator(shp, shp.sigma[[4, 7, 10]], q0=q * 0.8)
    P_missing = P.copy()
    P_missing[1] = np.nan                                         # a marker not seen
    e = est.fit(P_missing)
    assert e.found.tolist() == [True, False, True]
    assert np.abs(e.backbone[-1] - P[-1]).max() < 1e-6            # two markers still fix three modes here
    with pytest.raises(DataError, match="markers .* are missing"):
        est.fit(np.full((3, 3), np.nan))
    with pytest.raises(ParameterError, match="not a node"):
        ShapeEstimator(shp, [0.05, 0.11])
    with pytest.raises(ParameterError, match="increase"):
        ShapeEstimator(shp, [0.1, 0.04])
    with pytest.raises(ParameterError, match="count=2"):
        ShapeEstimator(shp, [0.1, 0.2], detector=MarkerDetector(3))
    with pytest.raises(ParameterError, match="no camera"):
        est.predicted_pixels()


def test_a_lost_marker_is_reacquired():
    """A marker hidden for some frames is reported missing, the estimate goes on with the others, and the full
    search finds it again when it reappears."""
    shp = beam()
    nodes = [2, 4, 6, 8, 10]
    cam = CameraModel.from_fov(60.0, pose=look_at((0.11, -0.01, 0.42), (0.11, -0.01, 0.0), up=(0, 1, 0)))
    syn = SyntheticCamera(cam, marker_radius=4e-3, noise=2.0)
    est = ShapeEstimator(shp, shp.sigma[nodes], cam, MarkerDetector(5, radius=(3, 9)), plane=((0, 0, 0), (0, 0, 1)))
    seen = []
    for k in range(12):
        t = 0.05 * k
        P = shp.positions(q_planar(t))[nodes]
        shown = [0, 1, 3, 4] if 4 <= k < 8 else [0, 1, 2, 3, 4]
        f = syn.render(P[shown], t)
        e = est.update(f)
        seen.append(e.found.copy())
        assert np.linalg.norm(e.tip - shp.positions(q_planar(t))[-1]) < 2e-4
    seen = np.array(seen)
    assert seen[4:8, 2].sum() == 0 and seen[4:8, [0, 1, 3, 4]].all()
    assert seen[8:].all()


def test_gauss_newton_fallback_when_the_ik_breaks_down(monkeypatch):
    shp = beam()
    q = np.array([5.0, -2.0, 1.0])
    nodes = [4, 7, 10]
    est = ShapeEstimator(shp, shp.sigma[nodes], q0=0.9 * q)

    def broken(*args, **kwargs):
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
    monkeypatch.setattr(shp, "inverse_kinematics", broken)
    P = shp.positions(q)
    e = est.fit(P[nodes])
    assert e.converged and np.abs(e.backbone - P).max() < 1e-7


class _Gated(ShapeEstimator):
    """An estimator whose update waits for a gate (a frame that costs as long as the test wants) and fails on
    request: frames are plain strings here, 'lost' (markers not found) or 'boom' (a bug)."""

    def __init__(self, shp):
        super().__init__(shp, shp.sigma[[5, 10]])
        import threading
        self.entered, self.gate = threading.Event(), threading.Event()

    def update(self, frame, u=None):
        self.entered.set()
        self.gate.wait(60.0)
        if frame == "lost":
            raise DataError("markers not found")
        if frame == "boom":
            raise RuntimeError("a bug in the estimator")
        return self.fit(self.shapes.positions(np.array([1.0, 0.5, 0.0]))[[5, 10]], u=u)


def test_estimator_thread_never_makes_the_loop_wait():
    """While the estimator is stuck on a frame, submit returns at once (the loop keeps sending to the board):
    the frames handed in meanwhile replace each other and only the newest is estimated; the dropped ones are
    counted. A frame without markers is counted as failed and keeps the previous estimate; any other error
    reaches the loop's thread."""
    est = _Gated(beam())
    worker = EstimatorThread(est, keep=True).start()
    worker.submit("first", tag=0)
    assert est.entered.wait(60.0)                  # the thread is inside the first frame, held by the gate
    for k in range(1, 5):
        worker.submit(f"frame {k}", tag=k)         # would hang here (the gate is shut) if submit waited
    assert (worker.done, worker.skipped) == (0, 3) and worker.latest is None
    est.gate.set()
    e = worker.wait(60.0)
    assert worker.done == 2 and [tag for tag, _ in worker.results] == [0, 4] and e is worker.results[-1][1]
    worker.submit("lost", tag=5)
    assert worker.wait(60.0) is e and worker.failed == 1 and worker.done == 2
    worker.submit("boom", tag=6)
    with pytest.raises(DataError, match="estimator thread stopped.*a bug"):
        worker.wait(60.0)
    with pytest.raises(DataError, match="a bug"):
        worker.stop()
    with pytest.raises(ParameterError, match="ShapeEstimator"):
        EstimatorThread(object())


def test_estimator_thread_estimates_synthetic_frames():
    """Frames handed to the thread give the estimates of the estimator called directly on the same frames (the
    thread changes when the work is done, not what it computes), and they track the motion (0.1 mm, as above)."""
    shp, ref = beam(), beam()
    nodes = [2, 4, 6, 8, 10]
    cam = CameraModel.from_fov(60.0, pose=look_at((0.11, -0.01, 0.42), (0.11, -0.01, 0.0), up=(0, 1, 0)))
    video = SyntheticCamera(cam, marker_radius=4e-3, noise=2.0, seed=3)
    make = lambda s: ShapeEstimator(s, s.sigma[nodes], cam, MarkerDetector(5, radius=(3, 9)),  # noqa: E731
                                    plane=((0, 0, 0), (0, 0, 1)))
    direct = make(ref)
    with EstimatorThread(make(shp), keep=True) as worker:
        for k in range(10):
            q = q_planar(k / 25.0)
            frame = video.render(ref.positions(q)[nodes])
            worker.submit(frame, tag=(q, direct.update(frame).q))
            worker.wait(60.0)
    assert worker.done == 10 and worker.skipped == worker.failed == 0
    for (q, q_direct), e in worker.results:
        assert np.array_equal(e.q, q_direct)
        assert np.linalg.norm(e.tip - ref.positions(q)[-1]) < 1e-4


def test_estimator_thread_leaves_the_loops_own_error_in_front():
    """A loop that fails (the board lost, say) while the thread has failed too: the loop's error is raised, the
    thread's is logged."""
    est = _Gated(beam())
    est.gate.set()
    with pytest.raises(KeyError, match="the loop's own"):
        with EstimatorThread(est) as worker:
            worker.submit("boom")
            with pytest.raises(DataError):
                worker.wait(60.0)
            raise KeyError("the loop's own error")
