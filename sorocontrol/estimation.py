r"""Shape estimation: markers seen by a camera -> the configuration :math:`q` of a Cosserat beam model.

The method (the seed paper, Sec. VI-E)
--------------------------------------
Markers sit on the backbone at known arc lengths :math:`\sigma_1 < \dots < \sigma_m` (nodes of the model).
Each frame, the markers are detected (:mod:`sorocontrol.vision`), lifted to world points :math:`p_i^*` [m]
(depth image, or camera rays meeting the beam's plane), and the configuration is estimated by inverse
kinematics warm-started from the previous estimate:

1. :meth:`soroshapes.Shapes.inverse_kinematics` with the targets :math:`(\sigma_i, p_i^*)` and the null-space
   subtask ``"elastic"`` (:math:`\nabla\Psi = Kq`; other priors pass their gradient as a callable subtask):
   Levenberg-Marquardt steps on the marker error with the subtask projected into the task's null space (the
   seed's eq. 23), started with a damping of :math:`0.05 L` so that it stays on the warm start's branch;
2. ``prior_steps`` Gauss-Newton steps that finish the minimization over the null space, which the IK's subtask
   term only starts (it is scaled to the task step, so it stops when the markers are matched): with the stacked
   marker errors :math:`e = p^* - p(q)`, their Jacobian :math:`A = \partial p / \partial q` and the prior's
   gradient :math:`g(q)`,

   .. math:: (A^T A + \beta K)\,\Delta q = A^T e - \beta\, g, \qquad
             \beta = w\,\mathrm{tr}(A^T A) / \mathrm{tr}(K),

   whose fixed point has :math:`g(q) = A^T \lambda`: the markers are matched (up to :math:`O(\beta)`) and, among
   the configurations that match them, the estimate is the quasi-static equilibrium under forces at the
   markers only. The prior is ``"elastic"`` (:math:`g = Kq`, the least strained shape) or ``"equilibrium"``
   (the seed's :math:`g = Kq - f_g(q) - G(q)u`, with the model's gravity and the actuation :math:`u` passed to
   :meth:`ShapeEstimator.update`), or a callable ``g(q, u)``.

With as many independent marker coordinates as coordinates of :math:`q` (no null space), the prior would have no
effect beyond :math:`O(\beta)` and the steps are skipped; with fewer (e.g. the tip only, as in the seed), the
prior is what picks the shape. If the IK fails (its linear algebra breaks down, or it hits its iteration limit),
up to 10 of these steps take over from the warm start.

Examples
--------
The body of a closed-loop sensing demo with the synthetic camera is :func:`run_sensing`:

>>> import numpy as np
>>> from sorofem import materials, sdf
>>> from soroshapes import Basis, Shapes
>>> from sorocontrol.estimation import run_sensing
>>> shp = Shapes(Basis.chebyshev(3), dofs=(0, 0, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
...              material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), damping=0.0, segments=10)
>>> res = run_sensing(shp, lambda t: np.array([6 * np.sin(2 * t), 3 * np.sin(3 * t), 0.0]), duration=0.5,
...                   rate=30)
>>> res["frames"], res["missed_frames"]
(15, 0)
>>> bool(res["tip_error_max"] < 1e-3)
True
"""
from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from sorofem.errors import DataError, ParameterError

from .camera import CameraModel, Frame, SyntheticCamera, look_at
from .vision import MarkerDetector, marker_points

__all__ = ["Estimate", "ShapeEstimator", "EstimatorThread", "run_sensing"]

log = logging.getLogger(__name__)


@dataclass
class Estimate:
    """One shape estimate.

    Attributes
    ----------
    t : float [s]
        Timestamp of the frame (or of the points given to :meth:`ShapeEstimator.fit`).
    q : (n,) estimated coordinates.
    backbone : (N+1, 3) [m]
        Backbone positions of the estimate at the model's nodes.
    markers : (m, 3) [m]
        Measured marker positions in the world (NaN rows for markers not found).
    fitted : (m, 3) [m]
        Marker positions of the estimate.
    found : (m,) bool
    marker_error : float [m]
        Root mean square distance between measured and fitted markers (over the found ones).
    iterations : int
        IK iterations plus prior steps.
    converged : bool
        The IK converged or stalled at a least-squares fit, or (after it failed) the fallback Gauss-Newton steps
        brought the marker error below :math:`10^{-3} L`; False flags an estimate not to trust.
    detect_time, solve_time : float [s]
        Wall time of detection + lifting to 3D, and of the IK + prior steps.
    """

    t: float
    q: np.ndarray
    backbone: np.ndarray
    markers: np.ndarray
    fitted: np.ndarray
    found: np.ndarray
    marker_error: float
    iterations: int
    converged: bool
    detect_time: float = 0.0
    solve_time: float = 0.0

    @property
    def tip(self):
        """Tip position (3,) [m] of the estimate."""
        return self.backbone[-1]


class ShapeEstimator:
    r"""Estimates a beam's configuration from markers at known arc lengths (module docstring for the method).

    Parameters
    ----------
    shapes : soroshapes.Shapes
        The beam model (its base pose in the world frame of ``camera``); gravity and inputs added to it are used
        by ``prior="equilibrium"``.
    arc_lengths : (m,) [m]
        Arc lengths of the markers, base to tip; each must be a node of ``shapes`` (one of ``shapes.sigma``).
    camera : CameraModel, optional
        Intrinsics and calibrated pose :math:`T_{wc}` (:func:`sorocontrol.vision.calibrate_world`); needed by
        :meth:`update`, not by :meth:`fit`.
    detector : MarkerDetector, optional
        Default: red markers, ``count = m``.
    plane : (point (3,), normal (3,)) [m], optional
        Plane of the marker centres (a planar beam): markers are located by camera rays meeting it. Without it,
        the frame's depth image is used.
    marker_radius : float [m]
        Radius of the spherical markers (the depth camera sees their surface, this far in front of the centre).
    prior : "elastic", "equilibrium", None, or callable ``g(q, u) -> (n,)``
    prior_steps : int
        Gauss-Newton steps on the prior after the IK (0: the IK alone).
    prior_weight : float
        :math:`w` in :math:`\beta = w\,\mathrm{tr}(A^TA)/\mathrm{tr}(K)`.
    subtask_gain : float
        Gain of the IK's elastic null-space subtask.
    tol : float [m]
        IK tolerance on the marker error norm.
    max_iterations : int
        IK iteration limit per frame.
    ik_damping : float [m]
        Initial Levenberg-Marquardt damping of the IK (default :math:`0.05 L`). The IK's own default (1e-6 m)
        takes nearly undamped Gauss-Newton first steps, which with few markers can jump to another branch of
        solutions between frames; a damping comparable to the marker motion keeps the warm start's branch.
    min_markers : int
        Fewest markers a frame must show (DataError below).
    q0 : (n,), optional
        Initial estimate (default straight).

    Examples
    --------
    A sensing loop: a beam bending in the world's x-y plane, seen from above by the synthetic camera.

    >>> import numpy as np
    >>> from sorofem import materials, sdf
    >>> from soroshapes import Basis, Shapes
    >>> from sorocontrol.camera import CameraModel, SyntheticCamera, look_at
    >>> shp = Shapes(Basis.chebyshev(3), dofs=(0, 0, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
    ...              material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), segments=10)
    >>> nodes = [2, 4, 6, 8, 10]                                  # a marker every 40 mm
    >>> def q_of_t(t):
    ...     return np.array([6 * np.sin(2 * t), 3 * np.sin(3 * t), 0.0])
    >>> cam = CameraModel.from_fov(60.0, pose=look_at((0.1, 0.0, 0.4), (0.1, 0.0, 0.0), up=(0, 1, 0)))
    >>> video = SyntheticCamera(cam, lambda t: shp.positions(q_of_t(t))[nodes], marker_radius=4e-3, noise=2.0,
    ...                         rate=30.0)
    >>> est = ShapeEstimator(shp, shp.sigma[nodes], cam, plane=((0, 0, 0), (0, 0, 1)))
    >>> with video:
    ...     for _ in range(10):
    ...         frame = video.read()
    ...         e = est.update(frame)                           # e.q, e.backbone, e.tip, e.marker_error
    >>> bool(np.linalg.norm(e.tip - shp.positions(q_of_t(frame.timestamp))[-1]) < 1e-4)
    True
    """

    def __init__(self, shapes, arc_lengths, camera=None, detector=None, *, plane=None, marker_radius=0.0,
                 prior="elastic", prior_steps=2, prior_weight=1e-6, subtask_gain=0.1, tol=1e-7, max_iterations=50,
                 ik_damping=None, min_markers=1, q0=None):
        if not all(hasattr(shapes, a) for a in ("inverse_kinematics", "forward_kinematics", "jacobian", "sigma")):
            raise ParameterError("shapes must be a soroshapes.Shapes")
        self.shapes = shapes
        s = np.asarray(arc_lengths, dtype=float).reshape(-1)
        if s.size < 1 or not np.all(np.isfinite(s)):
            raise ParameterError("arc_lengths must be at least one finite arc length [m]")
        if np.any(np.diff(s) <= 0):
            raise ParameterError("arc_lengths must increase from the base to the tip")
        nodes = []
        for x in s:
            i = int(np.argmin(np.abs(shapes.sigma - x)))
            if abs(shapes.sigma[i] - x) > 1e-9 * shapes.length:
                raise ParameterError(f"marker arc length {x:g} m is not a node of the model (nearest "
                                     f"{shapes.sigma[i]:g} m): put markers at nodes (shapes.sigma) or change the "
                                     f"model's segments")
            nodes.append(i)
        self.arc_lengths = shapes.sigma[nodes].copy()
        self._nodes = np.array(nodes)
        m = len(nodes)
        if camera is not None and not isinstance(camera, CameraModel):
            raise ParameterError("camera must be a CameraModel (from calibrate_world, or a camera's .model)")
        self.camera = camera
        if detector is None:
            detector = MarkerDetector(count=m)
        if not isinstance(detector, MarkerDetector) or detector.count != m:
            raise ParameterError(f"detector must be a MarkerDetector with count={m} (one per arc length)")
        self.detector = detector
        if plane is not None:
            try:
                p0, nrm = (np.asarray(v, dtype=float).reshape(3) for v in plane)
            except (TypeError, ValueError):
                raise ParameterError("plane must be (point (3,), normal (3,)) [m]") from None
            if not (np.all(np.isfinite(p0)) and np.linalg.norm(nrm) > 0):
                raise ParameterError("plane: finite point and non-zero normal needed")
            plane = (p0, nrm / np.linalg.norm(nrm))
        self.plane = plane
        self.marker_radius = float(marker_radius)
        if not (self.marker_radius >= 0):
            raise ParameterError("marker_radius must be >= 0 [m]")
        if not (prior in (None, "elastic", "equilibrium") or callable(prior)):
            raise ParameterError("prior must be 'elastic', 'equilibrium', None, or a callable g(q, u) -> (n,)")
        self.prior = prior
        self.prior_steps = int(prior_steps)
        self.prior_weight = float(prior_weight)
        if self.prior_steps < 0 or not (self.prior_weight > 0):
            raise ParameterError("prior_steps must be >= 0 and prior_weight > 0")
        self.subtask_gain = float(subtask_gain)
        self.ik_damping = 0.05 * shapes.length if ik_damping is None else float(ik_damping)
        if not (self.ik_damping > 0):
            raise ParameterError("ik_damping must be positive [m]")
        self.tol = float(tol)
        self.max_iterations = int(max_iterations)
        self.min_markers = int(min_markers)
        if not (1 <= self.min_markers <= m):
            raise ParameterError(f"min_markers must be in [1, {m}]")
        self._K = np.asarray(shapes.K, dtype=float)
        self._q0 = self._as_q(q0)
        self.reset()

    # -- state -------------------------------------------------------------------------------------
    def _as_q(self, q0):
        if q0 is None:
            return np.zeros(self.shapes.n)
        q = np.asarray(q0, dtype=float).reshape(-1)
        if q.shape != (self.shapes.n,) or not np.all(np.isfinite(q)):
            raise ParameterError(f"q0 must be {self.shapes.n} finite coordinates (dofs {self.shapes.dofs})")
        return q.copy()

    def reset(self, q0=None):
        """Forget the previous estimate: start again from ``q0`` (default: the constructor's) with a full search."""
        self.q = self._q0.copy() if q0 is None else self._as_q(q0)
        self._tracking = False
        self.last = None
        return self

    def predicted_pixels(self):
        """Image positions (m, 2) [px] of the markers of the current estimate (the tracking windows)."""
        self._need_camera()
        P = self.shapes.positions(self.q)[self._nodes]
        return self.camera.project(P)[0]

    def _need_camera(self):
        if self.camera is None:
            raise ParameterError("this estimator has no camera: give camera=CameraModel(...) to read frames")

    # -- prior ---------------------------------------------------------------------------------------
    def _gradient(self, q, u):
        if self.prior in ("elastic", None):     # None: used only to regularize the fallback steps
            return self._K @ q
        if self.prior == "equilibrium":
            g = self._K @ q - self.shapes.gravity_force(q)
            if u is not None and len(self.shapes.inputs):
                g = g - self.shapes.input_map(q, u) @ np.asarray(u, dtype=float).reshape(-1)
            return g
        return np.asarray(self.prior(q, u), dtype=float).reshape(self.shapes.n)

    def _marker_state(self, q, rows):
        """Positions (k, 3) and position Jacobians (3k, n) of the markers ``rows``: :math:`\\partial p_i/\\partial q =
        R_i J_i^{(v)}` (the body Jacobian's linear rows rotated to the world)."""
        J = self.shapes.jacobian(q, at="all")
        G = self.shapes.forward_kinematics(q)
        nodes = self._nodes[rows]
        P = G[nodes, :3, 3]
        A = np.einsum("kij,kjn->kin", G[nodes, :3, :3], J[nodes, 3:, :]).reshape(-1, self.shapes.n)
        return P, A

    def _prior_refine(self, q, targets, rows, u, steps, fallback=False):
        """``steps`` Gauss-Newton steps on the prior (module docstring), each followed by one minimum-norm
        Gauss-Newton correction of the marker error (back onto the set of configurations that match the markers);
        a step is halved until the marker error after the correction is at most 1.5 times the one before it
        (plus 1e-7 L) and, for the elastic prior, the elastic energy does not grow. Skipped when the markers
        determine q well (smallest singular value of A above 1e-3 times the largest). As the ``fallback`` of a
        failed IK: always run, and a step is accepted when it lowers the marker error."""
        its = 0
        P, A = self._marker_state(q, rows)
        e = (targets - P).reshape(-1)
        if not fallback and A.shape[0] >= A.shape[1]:
            sv = np.linalg.svd(A, compute_uv=False)
            if sv[-1] > 1e-3 * sv[0]:
                return q, 0          # the markers determine q: the prior would only add an O(beta) bias
        floor = (1e-7 * self.shapes.length) ** 2
        for _ in range(steps):
            err0 = float(e @ e)
            g = self._gradient(q, u)
            AtA = A.T @ A
            beta = self.prior_weight * np.trace(AtA) / max(np.trace(self._K), 1e-300)
            try:
                dq = np.linalg.solve(AtA + beta * self._K, A.T @ e - beta * g)
            except np.linalg.LinAlgError:
                break
            if np.linalg.norm(dq) < 1e-12 * (1.0 + np.linalg.norm(q)):
                break
            energy0 = 0.5 * q @ self._K @ q
            step, accepted = 1.0, False
            for _ in range(6):
                qn = q + step * dq
                Pn, An = self._marker_state(qn, rows)
                en = (targets - Pn).reshape(-1)
                qn = qn + np.linalg.lstsq(An, en, rcond=1e-8)[0]          # back onto the markers
                Pn, An = self._marker_state(qn, rows)
                en = (targets - Pn).reshape(-1)
                if fallback:
                    ok = float(en @ en) <= err0 + floor
                else:
                    ok = float(en @ en) <= 2.25 * err0 + floor
                if ok and not fallback and self.prior in ("elastic", None):
                    ok = 0.5 * qn @ self._K @ qn <= energy0 * (1 + 1e-12) + 1e-300
                if ok:
                    accepted = True
                    break
                step *= 0.5
            if not accepted:
                break
            q, A, e = qn, An, en
            its += 1
        return q, its

    # -- estimation ----------------------------------------------------------------------------------
    def fit(self, points, t=0.0, u=None):
        """Estimate from measured marker positions ``points`` (m, 3) [m] (NaN rows: not seen), warm-started from
        the previous estimate; the new estimate becomes the warm start of the next call."""
        t0 = time.perf_counter()
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(P) != len(self._nodes):
            raise ParameterError(f"give {len(self._nodes)} marker positions (one per arc length), got {len(P)}")
        found = np.all(np.isfinite(P), axis=1)
        if found.sum() < self.min_markers:
            raise DataError(f"only {int(found.sum())} of {len(P)} markers located (need {self.min_markers}): "
                            f"markers {list(np.flatnonzero(~found))} are missing; check occlusion, lighting and "
                            f"the detector's colour ranges")
        rows = np.flatnonzero(found)
        targets = [(float(self.arc_lengths[i]), P[i]) for i in rows]
        sub = "elastic" if self.prior == "elastic" else (
            None if self.prior is None else (lambda q: self._gradient(q, u)))
        try:
            res = self.shapes.inverse_kinematics(targets, self.q, tol=self.tol, max_iterations=self.max_iterations,
                                                 subtask=sub, subtask_gain=self.subtask_gain,
                                                 damping=self.ik_damping)
            q, its, ik_ok = res.q, res.iterations, res.converged or res.iterations < self.max_iterations
        except np.linalg.LinAlgError:
            # the IK's damped normal matrix J J^T + lambda^2 I can become singular when marker coordinates carry
            # no information (e.g. out-of-plane rows of a planar beam) and lambda has decayed; the Gauss-Newton
            # steps below are regularized by the prior and take over
            log.debug("IK linear algebra failed at t=%.3f s; continuing with the prior-regularized steps", t)
            q, its, ik_ok = self.q.copy(), 0, False
        if not ik_ok:
            q, k = self._prior_refine(q, P[rows], rows, u, max(self.prior_steps, 10), fallback=True)
            its += k
        elif self.prior is not None and self.prior_steps:
            q, k = self._prior_refine(q, P[rows], rows, u, self.prior_steps)
            its += k
        if not np.all(np.isfinite(q)):
            raise DataError("the shape estimate became non-finite; reset() the estimator")
        G = self.shapes.forward_kinematics(q)
        backbone = G[:, :3, 3].copy()
        fitted = backbone[self._nodes]
        err = float(np.sqrt(np.mean(np.sum((fitted[rows] - P[rows]) ** 2, axis=1))))
        converged = bool(ik_ok or err < 10 * self.tol + 1e-3 * self.shapes.length)
        if not converged:
            log.warning("the IK did not converge at t=%.3f s (marker error %.3g m after %d iterations); the "
                        "estimate is flagged converged=False", t, err, its)
        self.q = q
        est = Estimate(float(t), q.copy(), backbone, P.copy(), fitted, found, err, int(its), converged,
                       0.0, time.perf_counter() - t0)
        self.last = est
        return est

    def locate(self, frame, detection):
        """World positions (m, 3) [m] of the detected markers of ``frame`` (NaN rows for missing ones)."""
        self._need_camera()
        if self.plane is not None:
            return marker_points(self.camera, detection.centres, plane=self.plane)
        if frame.depth is None:
            raise DataError("the frame has no depth image and the estimator no marker plane: use a depth camera "
                            "or give plane=(point, normal)")
        return marker_points(self.camera, detection.centres, depth=frame.depth, offset=self.marker_radius)

    def update(self, frame, u=None):
        """Detect the markers in ``frame``, locate them in 3D and estimate the shape (see the module docstring).

        ``u``: the actuation inputs (for ``prior="equilibrium"``). The first frame after construction or
        :meth:`reset` is searched in full, the marker chain starting at the projected base of the beam; later
        frames are searched in windows around the markers predicted by the previous estimate (seen or not), with
        a full search for those not found there. Raises DataError when fewer than ``min_markers`` are found (the
        estimate is then unchanged).
        """
        self._need_camera()
        if not isinstance(frame, Frame):
            raise ParameterError("update needs a Frame (from a camera's read())")
        t0 = time.perf_counter()
        start = self.camera.project(self.shapes.base[:3, 3][None, :])[0][0]
        if self._tracking:
            det = self.detector.detect(frame.image, start=start, predicted=self.predicted_pixels())
        else:
            det = self.detector.detect(frame.image, start=start)
        pts = self.locate(frame, det)
        t1 = time.perf_counter()
        est = self.fit(pts, frame.timestamp, u)
        est.detect_time = t1 - t0
        self._tracking = True          # the estimate predicts every marker, seen or not, for the next frame
        return est


# ------------------------------------------------------------------------------------------------------------
# estimation beside a real-time loop
# ------------------------------------------------------------------------------------------------------------
class EstimatorThread:
    r"""Runs a :class:`ShapeEstimator` in a background thread, so that a control loop never waits for a frame.

    A control loop at the board's rate must send a command every period whatever a frame costs (rendering or
    grabbing, detection, IK): the board's watchdog vents a loop that falls silent, and it is right to. Here the
    loop hands each new frame to the thread with :meth:`submit` and reads the newest estimate from
    :attr:`latest`, both without blocking. The thread works on the newest frame only: a frame still waiting when
    the next one is submitted is dropped and counted (``skipped``), so a slow estimator lowers the estimation
    rate, never the loop's. A frame whose markers are not found (DataError) is counted (``failed``) and the
    previous estimate stays; any other error stops the thread and is raised again by :meth:`submit` and
    :meth:`stop`.

    The estimator and its :class:`~soroshapes.Shapes` (whose workspace its kernels write) belong to the thread
    while it runs: the loop computes with another instance of the model.

    Parameters
    ----------
    estimator : ShapeEstimator
        Warm it up (one :meth:`ShapeEstimator.update` compiles the model's kernels) before the loop starts.
    keep : bool
        Keep every ``(tag, Estimate)`` in :attr:`results` (for scoring against a known truth).

    Examples
    --------
    >>> import numpy as np
    >>> from sorofem import materials, sdf
    >>> from soroshapes import Basis, Shapes
    >>> from sorocontrol.camera import CameraModel, SyntheticCamera, look_at
    >>> shp = Shapes(Basis.chebyshev(2), dofs=(0, 0, 2, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
    ...              material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), segments=10)
    >>> nodes = [5, 10]
    >>> cam = CameraModel.from_fov(60.0, pose=look_at((0.1, 0.0, 0.4), (0.1, 0.0, 0.0), up=(0, 1, 0)))
    >>> video = SyntheticCamera(cam, marker_radius=4e-3, noise=2.0)
    >>> est = ShapeEstimator(shp, shp.sigma[nodes], cam, plane=((0, 0, 0), (0, 0, 1)))
    >>> q = np.array([3.0, 1.0])
    >>> with EstimatorThread(est, keep=True) as worker:
    ...     worker.submit(lambda: video.render(shp.positions(q)[nodes]), tag=q)
    ...     e = worker.wait(timeout=60.0)
    >>> bool(np.allclose(e.q, q, atol=0.05)), worker.done
    (True, 1)
    """

    def __init__(self, estimator, *, keep=False):
        if not isinstance(estimator, ShapeEstimator):
            raise ParameterError("estimator must be a ShapeEstimator")
        self.estimator = estimator
        self.keep = bool(keep)
        self.results = []
        self.latest = estimator.last       # the warm-up's estimate until the first frame is done
        self.done = self.skipped = self.failed = 0
        self.busy_time = 0.0
        self._cv = threading.Condition()
        self._pending = None
        self._stop = False
        self._error = None
        self._working = False
        self._thread = None

    def start(self):
        """Start the thread (idempotent); returns self."""
        if self._thread is None:
            self._stop = False
            self._thread = threading.Thread(target=self._run, daemon=True, name="soro-estimator")
            self._thread.start()
        return self

    def submit(self, frame, u=None, tag=None):
        """Hand a frame to the thread without waiting: ``frame`` is a :class:`Frame` or a callable returning one
        (called in the thread: e.g. a synthetic camera's render, so that rendering costs the loop nothing);
        ``u`` the actuation for ``prior="equilibrium"``; ``tag`` is kept with the estimate in :attr:`results`.
        A frame still waiting is replaced (and counted in ``skipped``)."""
        with self._cv:
            self._raise()
            if self._pending is not None:
                self.skipped += 1
            self._pending = (frame, None if u is None else np.array(u, dtype=float), tag)
            self._cv.notify()

    def wait(self, timeout=10.0):
        """Block until the frames submitted so far are estimated (at most ``timeout`` [s]); returns
        :attr:`latest`. For tests and warm-ups, not for a real-time loop."""
        deadline = time.monotonic() + float(timeout)
        with self._cv:
            while (self._pending is not None or self._working) and self._error is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise DataError(f"the estimator thread did not finish within {timeout} s")
                self._cv.wait(left)
            self._raise()
            return self.latest

    def _raise(self):
        if self._error is not None:
            raise DataError(f"the estimator thread stopped: {self._error!r}") from self._error

    def _run(self):
        while True:
            with self._cv:
                while self._pending is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                (frame, u, tag), self._pending = self._pending, None
                self._working = True
            t0 = time.perf_counter()
            try:
                est = self.estimator.update(frame() if callable(frame) else frame, u=u)
            except DataError as err:
                log.debug("estimator thread: frame dropped: %s", err)
                with self._cv:
                    self.failed += 1
                    self._working = False
                    self._cv.notify_all()
                continue
            except BaseException as err:  # noqa: BLE001 - handed to the loop's thread by submit/stop
                with self._cv:
                    self._error = err
                    self._working = False
                    self._cv.notify_all()
                return
            with self._cv:
                self.busy_time += time.perf_counter() - t0
                self.latest = est
                self.done += 1
                if self.keep:
                    self.results.append((tag, est))
                self._working = False
                self._cv.notify_all()

    def stop(self):
        """Stop the thread after the frame it is working on (a waiting one is dropped and counted)."""
        with self._cv:
            self._stop = True
            if self._pending is not None:
                self.skipped += 1
                self._pending = None
            self._cv.notify_all()
        th, self._thread = self._thread, None
        if th is not None:
            th.join()
        self._raise()

    def __enter__(self):
        return self.start()

    def __exit__(self, exc_type, *exc):
        try:
            self.stop()
        except DataError as err:
            if exc_type is None:
                raise
            log.warning("%s (while leaving on another error)", err)   # the error that ended the loop goes on


# ------------------------------------------------------------------------------------------------------------
# a closed-loop sensing run with the synthetic camera
# ------------------------------------------------------------------------------------------------------------
def _auto_camera(points, fov=60.0, width=640, height=480):
    """A camera that frames the points (k, 3) [m]: along the normal of their best-fit plane, far enough to see all
    of them with a 25 % margin. Returns (model, plane or None)."""
    c = points.mean(axis=0)
    _, sv, vt = np.linalg.svd(points - c, full_matrices=False)
    normal = vt[2]
    planar = sv[2] <= 1e-9 * max(sv[0], 1e-300)
    if normal[2] < 0:
        normal = -normal
    up = vt[1] if abs(vt[1] @ normal) < 0.99 else vt[0]
    d = points - c
    extent_x = np.max(np.abs(d @ np.cross(up, normal))) + 0.01
    extent_y = np.max(np.abs(d @ up)) + 0.01
    f = 0.5 * width / math.tan(math.radians(fov) / 2)
    dist = 1.25 * max(extent_x * f / (0.5 * width), extent_y * f / (0.5 * height))
    dist = max(dist, 0.15)
    model = CameraModel.from_fov(fov, width, height, pose=look_at(c + dist * normal, c, up))
    return model, ((c, normal) if planar else None)


def run_sensing(shapes, q_of_t, duration, rate, camera=None, *, arc_lengths=None, marker_radius=None, noise=2.0,
                depth=None, prior="elastic", seed=0):
    r"""Closed-loop shape sensing of a prescribed motion seen by the synthetic camera; returns the figures.

    The beam moves as ``q_of_t(t)``; markers on its backbone are rendered by a
    :class:`~sorocontrol.camera.SyntheticCamera` at ``rate`` [Hz] for ``duration`` [s]; a
    :class:`ShapeEstimator` detects them and estimates :math:`q` frame by frame; the estimate is compared with the
    truth.

    Parameters
    ----------
    shapes : soroshapes.Shapes
    q_of_t : callable ``t [s] -> (n,)``
    duration : float [s]
    rate : float [Hz]
    camera : CameraModel, optional
        Default: looking along the normal of the plane of the motion (or of its best-fit plane), framing it.
    arc_lengths : (m,) [m], optional
        Marker positions along the beam (nodes); default 5 (or fewer) evenly spaced nodes ending at the tip.
    marker_radius : float [m], optional
        Default: 0.8 times the beam's contact radius.
    noise : float
        Pixel noise [grey levels].
    depth : bool, optional
        Locate markers with the depth image (default: only when the motion is not planar; else rays meet the
        plane of the motion).
    prior : the estimator's prior.
    seed : int

    Returns
    -------
    dict with ``frames``, ``missed_frames`` (frames where a marker was lost), ``markers`` (how many),
    ``depth`` (whether the depth path was used), ``tip_error_mean``,
    ``tip_error_max``, ``backbone_error_max``, ``marker_error_rms`` [m], ``rate_hz`` (frames per second of
    detection + estimation wall time), ``detect_ms``, ``solve_ms`` (mean per frame), and the arrays ``t``,
    ``q_true``, ``q_estimate``, ``tip_true``, ``tip_estimate`` (NaN rows for skipped frames).
    """
    duration, rate = float(duration), float(rate)
    if not (duration > 0 and rate > 0):
        raise ParameterError("duration [s] and rate [Hz] must be positive")
    if not callable(q_of_t):
        raise ParameterError("q_of_t must be a callable t [s] -> (n,) coordinates")
    N = len(shapes.sigma) - 1
    if arc_lengths is None:
        m = min(5, N)
        idx = np.unique(np.round(np.linspace(0, N, m + 1)[1:]).astype(int))
        arc_lengths = shapes.sigma[idx]
    s = np.asarray(arc_lengths, dtype=float)
    nodes = np.array([int(np.argmin(np.abs(shapes.sigma - x))) for x in s])
    frames = max(int(round(duration * rate)), 1)
    ts = np.arange(frames) / rate
    q_true = np.array([np.asarray(q_of_t(t), dtype=float).reshape(shapes.n) for t in ts])
    backbones = np.array([shapes.positions(q) for q in q_true])
    plane = None
    if camera is None:
        camera, plane = _auto_camera(backbones.reshape(-1, 3))
    elif not isinstance(camera, CameraModel):
        raise ParameterError("camera must be a CameraModel")
    use_depth = (plane is None) if depth is None else bool(depth)
    if not use_depth and plane is None:
        raise ParameterError("the motion is not planar: locate markers with depth=True")
    R = 0.8 * shapes.contact_radius if marker_radius is None else float(marker_radius)
    lookup = dict(zip(np.round(ts * rate).astype(int), backbones[:, nodes]))
    cam = SyntheticCamera(camera, lambda t: lookup[int(round(t * rate))], marker_radius=R, noise=noise,
                          depth=use_depth, rate=rate, seed=seed)
    # marker image radii over the run give the detector's radius range
    z = np.array([camera.project(b[nodes])[1] for b in backbones])
    f = math.sqrt(camera.K[0, 0] * camera.K[1, 1])
    r_px = f * R / z
    det = MarkerDetector(count=len(nodes), radius=(0.6 * r_px.min(), 1.5 * r_px.max()))
    est = ShapeEstimator(shapes, s, camera, det, plane=None if use_depth else plane, marker_radius=R, prior=prior,
                         q0=q_true[0])
    q_est = np.full((frames, shapes.n), np.nan)
    tip_est = np.full((frames, 3), np.nan)
    tip_err, bb_err, m_err = [], [], []
    detect, solve, missed = 0.0, 0.0, 0
    with cam:
        for k in range(frames):
            frame = cam.read()
            try:
                e = est.update(frame)
            except DataError as err:
                log.warning("frame %d skipped: %s", k, err)
                missed += 1
                continue
            missed += int(not e.found.all())
            detect += e.detect_time
            solve += e.solve_time
            q_est[k], tip_est[k] = e.q, e.tip
            tip_err.append(np.linalg.norm(e.tip - backbones[k, -1]))
            bb_err.append(np.max(np.linalg.norm(e.backbone - backbones[k], axis=1)))
            m_err.append(e.marker_error)
    done = len(tip_err)
    if done == 0:
        raise DataError("no frame could be estimated: the markers were never found")
    return {"frames": frames, "missed_frames": missed, "markers": len(nodes), "depth": use_depth,
            "tip_error_mean": float(np.mean(tip_err)), "tip_error_max": float(np.max(tip_err)),
            "backbone_error_max": float(np.max(bb_err)), "marker_error_rms": float(np.sqrt(np.mean(np.square(m_err)))),
            "rate_hz": done / max(detect + solve, 1e-12), "detect_ms": 1e3 * detect / done,
            "solve_ms": 1e3 * solve / done, "t": ts, "q_true": q_true, "q_estimate": q_est,
            "tip_true": backbones[:, -1], "tip_estimate": tip_est}
