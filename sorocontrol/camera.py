r"""Cameras: a pinhole model with its pose in the world, frame sources (OpenCV devices and files, RealSense,
a synthetic renderer) and the ArUco target that fixes the world frame.

Conventions
-----------
* Camera frame as in OpenCV: :math:`x` right, :math:`y` down, :math:`z` forward (optical axis).
* Pixel coordinates :math:`(u, v)` [px] with integer values at pixel *centres* (OpenCV's convention).
* A pinhole :math:`\tilde u = K\, p_c / z_c` with intrinsics
  :math:`K = \begin{pmatrix} f_x & 0 & c_x\\ 0 & f_y & c_y\\ 0 & 0 & 1\end{pmatrix}` [px].
* The pose of the camera is :math:`T_{wc} \in SE(3)` (``pose``): it maps camera coordinates to world
  coordinates, :math:`p_w = R_{wc} p_c + t_{wc}` [m].
* Depth images hold the :math:`z_c` depth [m] of each pixel (not the range), ``0`` where nothing returned.

Frame sources share one small interface: ``read() -> Frame``, ``close()``, and use as a context manager.
OpenCV is an optional dependency (``pip install opencv-python-headless``); it is imported when first needed.

Examples
--------
>>> import numpy as np
>>> from sorocontrol.camera import CameraModel, look_at
>>> cam = CameraModel.from_fov(60.0, pose=look_at(eye=(0.1, 0.0, 0.5), target=(0.1, 0.0, 0.0)))
>>> uv, z = cam.project([[0.1, 0.0, 0.0]])
>>> bool(np.allclose(uv, [[319.5, 239.5]]) and np.isclose(z[0], 0.5))
True
>>> bool(np.allclose(cam.intersect_plane(uv, (0, 0, 0), (0, 0, 1)), [[0.1, 0.0, 0.0]]))
True
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from sorofem.errors import DataError, DependencyError, ParameterError

__all__ = ["CameraModel", "look_at", "Frame", "GroundTruth", "Camera", "OpenCVCamera", "RealSenseCamera",
           "SyntheticCamera", "ArucoTarget", "require_cv2"]

log = logging.getLogger(__name__)


def require_cv2():
    """Import and return OpenCV (``cv2``) or raise :class:`~sorofem.errors.DependencyError` saying how to
    install it."""
    try:
        import cv2
    except ImportError as err:   # pragma: no cover - cv2 is installed where the tests run
        raise DependencyError("OpenCV is needed for cameras and marker detection: pip install "
                              "opencv-python-headless (the 'extras' of this package)") from err
    return cv2


def _vec(x, n, what):
    v = np.asarray(x, dtype=float).reshape(-1)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"{what} must be {n} finite numbers, got {x!r}")
    return v


def _pose(T, what="pose"):
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ParameterError(f"{what} must be a finite 4x4 homogeneous transform [m], got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ParameterError(f"{what}: the rotation block must be orthonormal with det +1")
    return T.copy()


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    r"""Pose :math:`T_{wc}` (4, 4) of a camera at ``eye`` [m] whose optical axis points at ``target`` [m], with the
    image's "up" (:math:`-y_c`) as close as possible to the world direction ``up``.

    Raises ParameterError when ``eye == target`` or ``up`` is parallel to the viewing direction.
    """
    eye, target, up = _vec(eye, 3, "eye"), _vec(target, 3, "target"), _vec(up, 3, "up")
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise ParameterError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


@dataclass
class CameraModel:
    r"""A calibrated pinhole camera placed in the world.

    Parameters
    ----------
    K : (3, 3) intrinsics [px].
    width, height : int
        Image size [px].
    pose : (4, 4)
        :math:`T_{wc}`, camera-to-world transform [m] (default identity: the camera frame is the world frame).
    dist : (5,) or None
        OpenCV distortion coefficients :math:`(k_1, k_2, p_1, p_2, k_3)`; None or zeros for an ideal pinhole.
    rms : float or None
        Reprojection error [px] of the calibration that produced ``pose`` (set by :func:`calibrate_world`).
    """

    K: np.ndarray
    width: int = 640
    height: int = 480
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    dist: np.ndarray | None = None
    rms: float | None = None

    def __post_init__(self):
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1:
            raise ParameterError("K must be a 3x3 intrinsic matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with "
                                 "positive focal lengths [px]")
        self.K = K
        self.width, self.height = int(self.width), int(self.height)
        if self.width < 1 or self.height < 1:
            raise ParameterError(f"image size must be positive, got {self.width}x{self.height}")
        self.pose = _pose(self.pose)
        if self.dist is not None:
            d = np.asarray(self.dist, dtype=float).reshape(-1)
            if d.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(d)):
                raise ParameterError("dist must be 4, 5, 8, 12 or 14 OpenCV distortion coefficients")
            self.dist = None if not np.any(d) else d

    @classmethod
    def from_fov(cls, fov, width=640, height=480, pose=None):
        """A square-pixel camera with horizontal field of view ``fov`` [deg] and the principal point at the image
        centre ((width - 1)/2, (height - 1)/2)."""
        if not (0 < fov < 179):
            raise ParameterError(f"fov must be in (0, 179) degrees, got {fov!r}")
        f = 0.5 * width / math.tan(math.radians(fov) / 2)
        K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
        return cls(K, width, height, np.eye(4) if pose is None else pose)

    def with_pose(self, pose, rms=None):
        """The same intrinsics with another camera-to-world ``pose`` (4, 4)."""
        return CameraModel(self.K, self.width, self.height, pose, self.dist, rms)

    # -- transforms ---------------------------------------------------------------------------------
    @property
    def position(self):
        """Camera centre in the world (3,) [m]."""
        return self.pose[:3, 3].copy()

    def to_camera(self, points):
        r"""World points (m, 3) [m] -> camera frame: :math:`p_c = R_{wc}^T (p_w - t_{wc})`."""
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        return (P - self.pose[:3, 3]) @ self.pose[:3, :3]

    def to_world(self, points):
        r"""Camera-frame points (m, 3) [m] -> world: :math:`p_w = R_{wc} p_c + t_{wc}`."""
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        return P @ self.pose[:3, :3].T + self.pose[:3, 3]

    def project(self, points):
        """Pixels (m, 2) [px] and depths :math:`z_c` (m,) [m] of world points (m, 3); points behind the camera
        get NaN pixels."""
        Pc = self.to_camera(points)
        z = Pc[:, 2].copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.dist is None:
                uv = (Pc[:, :2] / z[:, None]) * np.diag(self.K)[:2] + self.K[:2, 2]
                uv[:, 0] += self.K[0, 1] * Pc[:, 1] / z
            elif len(Pc) == 0:
                uv = np.zeros((0, 2))
            else:
                cv2 = require_cv2()
                uv = cv2.projectPoints(Pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K,
                                       self.dist)[0].reshape(-1, 2)
        uv[z <= 0] = np.nan
        return uv, z

    def normalized(self, pixels):
        """Normalized image coordinates (m, 2) (:math:`x_c/z_c, y_c/z_c`) of pixels (m, 2), undistorted."""
        uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
        if self.dist is None:
            y = (uv[:, 1] - self.K[1, 2]) / self.K[1, 1]
            x = (uv[:, 0] - self.K[0, 2] - self.K[0, 1] * y) / self.K[0, 0]
            return np.column_stack([x, y])
        cv2 = require_cv2()
        return cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist).reshape(-1, 2)

    def rays(self, pixels):
        """Camera centre (3,) and unit world directions (m, 3) of the rays through ``pixels`` (m, 2) [px]."""
        xy = self.normalized(pixels)
        d = np.column_stack([xy, np.ones(len(xy))])
        d = d @ self.pose[:3, :3].T
        return self.position, d / np.linalg.norm(d, axis=1, keepdims=True)

    def intersect_plane(self, pixels, point, normal):
        r"""World points (m, 3) [m] where the rays through ``pixels`` meet the plane through ``point`` [m] with
        ``normal``: :math:`p = o + s\,d`, :math:`s = n\cdot(p_0 - o) / n\cdot d`.

        Raises DataError for a ray parallel to the plane or meeting it behind the camera; NaN pixels give NaN
        rows (a missing marker stays missing)."""
        p0, n = _vec(point, 3, "plane point"), _vec(normal, 3, "plane normal")
        if np.linalg.norm(n) == 0:
            raise ParameterError("plane normal must be non-zero")
        n = n / np.linalg.norm(n)
        o, d = self.rays(pixels)
        den = d @ n
        ok = np.isfinite(den)
        if np.any(np.abs(den[ok]) < 1e-9):
            raise DataError("a camera ray is parallel to the marker plane: look at the plane, not along it")
        with np.errstate(invalid="ignore"):
            s = ((p0 - o) @ n) / den
        if np.any(s[ok] <= 0):
            raise DataError("the marker plane is behind the camera for some pixels: check the plane and the "
                            "calibration")
        return o + s[:, None] * d

    def back_project(self, pixels, depth, offset=0.0):
        r"""World points (m, 3) [m] of pixels (m, 2) with z-depths (m,) [m]:
        :math:`p_c = z\,(x, y, 1)`, then moved ``offset`` [m] further along the ray (give the marker radius to go
        from the visible surface of a spherical marker to its centre)."""
        xy = self.normalized(pixels)
        z = np.asarray(depth, dtype=float).reshape(-1)
        if z.shape != (len(xy),):
            raise ParameterError(f"give one depth per pixel: {len(xy)} pixels, {z.shape} depths")
        Pc = np.column_stack([xy * z[:, None], z])
        if offset:
            Pc = Pc + offset * Pc / np.linalg.norm(Pc, axis=1, keepdims=True)
        return self.to_world(Pc)


# ------------------------------------------------------------------------------------------------------------
# frames and sources
# ------------------------------------------------------------------------------------------------------------
@dataclass
class GroundTruth:
    """What a synthetic frame shows: marker centres ``points`` (m, 3) world [m], their projections ``centres``
    (m, 2) [px], image radii ``radii`` (m,) [px], depths ``z`` (m,) [m], ``visible`` (m,) (in front of the camera
    and inside the image), and the camera ``pose`` (4, 4)."""

    points: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    z: np.ndarray
    visible: np.ndarray
    pose: np.ndarray


@dataclass
class Frame:
    """One camera frame: ``image`` (H, W, 3) BGR uint8, ``depth`` (H, W) float32 z-depth [m] or None,
    ``timestamp`` [s], ``index`` (frame counter), and ``truth`` (synthetic frames only)."""

    image: np.ndarray
    depth: np.ndarray | None = None
    timestamp: float = 0.0
    index: int = 0
    truth: GroundTruth | None = None


class Camera:
    """Base class of the frame sources: ``read() -> Frame``, ``close()``, context manager, iteration (until the
    source ends). ``model`` is the source's :class:`CameraModel` (None when unknown)."""

    model: CameraModel | None = None

    def read(self):  # pragma: no cover - interface
        raise NotImplementedError

    def close(self):
        """Release the device (idempotent)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __iter__(self):
        while True:
            try:
                yield self.read()
            except EOFError:
                return


class OpenCVCamera(Camera):
    """A camera device (int index) or a video file / stream URL (str) read with ``cv2.VideoCapture``.

    ``read()`` raises ``EOFError`` at the end of a file (iteration stops there) and DataError when a device
    delivers no frame. Timestamps [s]: frame index over the file's frame rate for files, time since opening for
    devices. ``model`` (optional :class:`CameraModel`) gives intrinsics and pose for estimation;
    ``width``/``height`` request a capture size from a device.
    """

    def __init__(self, source=0, *, model=None, width=None, height=None):
        cv2 = require_cv2()
        self._cv2 = cv2
        self.source = source
        self.model = model
        self._cap = cv2.VideoCapture(source)
        if not self._cap.isOpened():
            self._cap.release()
            raise DataError(f"cannot open the video source {source!r}: check the device index or the file path")
        if width:
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(width))
        if height:
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(height))
        self._is_file = isinstance(source, str)
        self._index = 0
        self._t0 = time.perf_counter()

    def read(self):
        if self._cap is None:
            raise DataError("the camera is closed")
        ok, img = self._cap.read()
        if not ok or img is None:
            if self._is_file:
                raise EOFError(f"end of {self.source!r}")
            raise DataError(f"camera {self.source!r} delivered no frame (unplugged or busy?)")
        if img.ndim == 2:
            img = self._cv2.cvtColor(img, self._cv2.COLOR_GRAY2BGR)
        if self._is_file:
            fps = self._cap.get(self._cv2.CAP_PROP_FPS)
            t = self._index / fps if fps > 0 else self._cap.get(self._cv2.CAP_PROP_POS_MSEC) * 1e-3
        else:
            t = time.perf_counter() - self._t0
        frame = Frame(img, None, t, self._index)
        self._index += 1
        return frame

    def close(self):
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class RealSenseCamera(Camera):
    """An Intel RealSense colour + depth camera (``pyrealsense2``); depth is aligned to the colour image and
    converted to metres. ``model`` is built from the colour stream's factory intrinsics (pose identity until
    calibrated with :func:`sorocontrol.vision.calibrate_world`)."""

    def __init__(self, width=640, height=480, fps=30, *, depth=True, serial=None):
        try:
            import pyrealsense2 as rs
        except ImportError as err:
            raise DependencyError("RealSense cameras need pyrealsense2: pip install pyrealsense2 (and the "
                                  "librealsense udev rules on Linux)") from err
        self._rs = rs
        self._pipe = rs.pipeline()
        cfg = rs.config()
        if serial:
            cfg.enable_device(str(serial))
        cfg.enable_stream(rs.stream.color, width, height, rs.format.bgr8, fps)
        if depth:
            cfg.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
        try:
            profile = self._pipe.start(cfg)
        except RuntimeError as err:
            raise DataError(f"cannot start the RealSense pipeline: {err}") from err
        self._align = rs.align(rs.stream.color) if depth else None
        self._scale = profile.get_device().first_depth_sensor().get_depth_scale() if depth else 1.0
        intr = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        K = np.array([[intr.fx, 0, intr.ppx], [0, intr.fy, intr.ppy], [0, 0, 1.0]])
        self.model = CameraModel(K, intr.width, intr.height, np.eye(4), np.array(intr.coeffs[:5], dtype=float))
        self._index = 0

    def read(self):
        if self._pipe is None:
            raise DataError("the camera is closed")
        frames = self._pipe.wait_for_frames()
        if self._align is not None:
            frames = self._align.process(frames)
        color = frames.get_color_frame()
        img = np.asanyarray(color.get_data()).copy()
        depth = None
        if self._align is not None:
            depth = np.asanyarray(frames.get_depth_frame().get_data()).astype(np.float32) * self._scale
        frame = Frame(img, depth, color.get_timestamp() * 1e-3, self._index)
        self._index += 1
        return frame

    def close(self):
        if self._pipe is not None:
            self._pipe.stop()
            self._pipe = None


# ------------------------------------------------------------------------------------------------------------
# ArUco target (defines the world frame)
# ------------------------------------------------------------------------------------------------------------
class ArucoTarget:
    """Square ArUco markers printed on a flat sheet that defines the world frame.

    Parameters
    ----------
    size : float [m]
        Side of each marker's black square (the outer border included).
    ids : sequence of int
        Marker ids of the dictionary (default ``(0,)``).
    centres : (k, 2) [m]
        Marker centres in the sheet's plane coordinates (default: the origin for one marker).
    dictionary : str
        Name of an OpenCV predefined dictionary, e.g. ``"DICT_4X4_50"``.
    pose : (4, 4)
        Pose of the sheet in the world :math:`T_{wt}` (default identity: the sheet is the world's z = 0 plane,
        its x, y axes the world's).
    margin : float [m]
        White paper around the markers (rendering only).

    Marker corners follow OpenCV's order (top-left, top-right, bottom-right, bottom-left of the printed
    marker), at sheet coordinates :math:`c + (\\mp s/2, \\pm s/2)`: the printed marker's top edge points
    along the sheet's +y axis.
    """

    def __init__(self, size, ids=(0,), centres=None, dictionary="DICT_4X4_50", pose=None, margin=None):
        self.size = float(size)
        if not (np.isfinite(self.size) and self.size > 0):
            raise ParameterError(f"marker size must be positive [m], got {size!r}")
        self.ids = tuple(int(i) for i in ids)
        if not self.ids or len(set(self.ids)) != len(self.ids):
            raise ParameterError("ids must be distinct marker ids, at least one")
        c = np.zeros((len(self.ids), 2)) if centres is None else np.asarray(centres, dtype=float)
        if c.shape != (len(self.ids), 2) or not np.all(np.isfinite(c)):
            raise ParameterError(f"centres must be ({len(self.ids)}, 2) sheet coordinates [m]")
        self.centres = c
        self.dictionary = str(dictionary)
        self.pose = _pose(np.eye(4) if pose is None else pose, "target pose")
        self.margin = 0.25 * self.size if margin is None else float(margin)

    @classmethod
    def grid(cls, rows, cols, size, gap, first_id=0, **kw):
        """A ``rows x cols`` grid of markers of side ``size`` [m] separated by ``gap`` [m], centred on the origin,
        ids row by row from ``first_id``."""
        pitch = size + gap
        xs = (np.arange(cols) - (cols - 1) / 2) * pitch
        ys = ((rows - 1) / 2 - np.arange(rows)) * pitch
        centres = [(x, y) for y in ys for x in xs]
        return cls(size, ids=range(first_id, first_id + rows * cols), centres=centres, **kw)

    def _dict(self):
        cv2 = require_cv2()
        try:
            code = getattr(cv2.aruco, self.dictionary)
        except AttributeError:
            raise ParameterError(f"unknown ArUco dictionary {self.dictionary!r}; use e.g. 'DICT_4X4_50'") from None
        return cv2.aruco.getPredefinedDictionary(code)

    def local_corners(self, i):
        """Corners (4, 3) [m] of the ``i``-th marker in the sheet frame (OpenCV corner order)."""
        h = self.size / 2
        cx, cy = self.centres[i]
        return np.array([[cx - h, cy + h, 0.0], [cx + h, cy + h, 0.0], [cx + h, cy - h, 0.0], [cx - h, cy - h, 0.0]])

    def corners(self, marker_id):
        """World corners (4, 3) [m] of marker ``marker_id`` (OpenCV corner order)."""
        P = self.local_corners(self.ids.index(int(marker_id)))
        return P @ self.pose[:3, :3].T + self.pose[:3, 3]

    @property
    def sheet(self):
        """(xmin, xmax, ymin, ymax) [m] of the white sheet in its own frame."""
        h = self.size / 2 + self.margin
        return (self.centres[:, 0].min() - h, self.centres[:, 0].max() + h,
                self.centres[:, 1].min() - h, self.centres[:, 1].max() + h)

    def texture(self, cells_px=40):
        """The printed sheet as a grey uint8 image and its pixel pitch [m/px]: each marker bit is ``cells_px``
        pixels wide. Texture pixel (i, j) (column, row) has its centre at sheet coordinates
        (xmin + (i + 1/2) p, ymax - (j + 1/2) p)."""
        cv2 = require_cv2()
        d = self._dict()
        bits = d.markerSize + 2
        side = bits * int(cells_px)
        pitch = self.size / side
        x0, x1, y0, y1 = self.sheet
        W, H = int(round((x1 - x0) / pitch)), int(round((y1 - y0) / pitch))
        tex = np.full((H, W), 255, np.uint8)
        for k, mid in enumerate(self.ids):
            img = cv2.aruco.generateImageMarker(d, mid, side, borderBits=1)
            cx, cy = self.centres[k]
            i0 = int(round((cx - self.size / 2 - x0) / pitch))
            j0 = int(round((y1 - (cy + self.size / 2)) / pitch))
            tex[j0:j0 + side, i0:i0 + side] = img
        return tex, pitch


# ------------------------------------------------------------------------------------------------------------
# synthetic camera
# ------------------------------------------------------------------------------------------------------------
DEFAULT_COLORS = {"red": (40, 40, 220), "green": (60, 190, 40), "blue": (220, 80, 30), "yellow": (30, 220, 230)}


class SyntheticCamera(Camera):
    r"""Renders coloured spherical markers (and optionally an ArUco sheet) seen by a pinhole camera.

    Each marker, a sphere of radius :math:`R` [m] centred at :math:`p_w`, is drawn as a disc of radius
    :math:`r = f R / z_c` [px] around the projection of its centre, with analytic anti-aliasing: a pixel's
    coverage is :math:`\mathrm{clip}(r - d + 1/2, 0, 1)` with :math:`d` the distance of the pixel centre to the
    disc centre (the area of a pixel inside a straight edge at that distance). The ground-truth centre is the
    projection of :math:`p_w`. (The exact image of a sphere is an ellipse whose centre lies
    :math:`\approx \rho (R/z_c)^2` px further from the principal point, :math:`\rho` the distance to it:
    below 0.05 px for a 5 mm marker at 0.4 m.) Markers are painted far to near, so nearer ones occlude.
    A model with lens distortion (``model.dist``) is rendered as the ideal pinhole image warped by the distortion:
    each output pixel takes the ideal image at the undistorted position of its centre
    (``cv2.undistortPoints``, bilinear), so the markers' ground-truth centres are the distorted projections
    (:meth:`CameraModel.project`) and an undistortion from a calibration is needed to locate them.
    The depth image (``depth=True``) holds the z-depth of the sphere surfaces and of the ArUco sheet, 0
    elsewhere. The ArUco sheet is rendered by a perspective warp at ``supersample`` times the resolution,
    averaged down (area coverage at the edges).

    Parameters
    ----------
    model : CameraModel
        Intrinsics, image size and pose :math:`T_{wc}`.
    scene : callable ``t -> (m, 3)`` [m], optional
        World positions of the marker centres at time ``t`` [s], used by :meth:`read`.
    marker_radius : float or (m,) [m]
    colors : BGR triple, name of :data:`DEFAULT_COLORS`, or one per marker.
    background : BGR triple (uniform) or an (H, W, 3) uint8 image.
    noise : float
        Standard deviation of additive Gaussian pixel noise [grey levels].
    depth : bool
        Also render the depth image.
    aruco : ArucoTarget, optional
    rate : float [Hz]
        Frame rate of :meth:`read`: frame ``k`` is at ``t = k / rate``.
    seed : int
        Noise seed.
    supersample : int
        Supersampling factor of the ArUco sheet's rendering (4: 16 samples per pixel).

    Iterating over a SyntheticCamera with a scene never ends; read a number of frames instead.
    """

    def __init__(self, model, scene=None, *, marker_radius=5e-3, colors="red", background=(90, 90, 90),
                 noise=0.0, depth=False, aruco=None, rate=30.0, seed=0, supersample=4):
        if not isinstance(model, CameraModel):
            raise ParameterError("model must be a CameraModel (e.g. CameraModel.from_fov(60, pose=look_at(...)))")
        self.model = model
        self._ideal = model if model.dist is None else CameraModel(model.K, model.width, model.height, model.pose)
        self._maps = None
        if scene is not None and not callable(scene):
            raise ParameterError("scene must be a callable t [s] -> (m, 3) marker positions [m]")
        self.scene = scene
        self.marker_radius = marker_radius
        self.colors = colors
        self.noise = float(noise)
        if not (np.isfinite(self.noise) and self.noise >= 0):
            raise ParameterError(f"noise must be >= 0 grey levels, got {noise!r}")
        self.depth = bool(depth)
        if aruco is not None and not isinstance(aruco, ArucoTarget):
            raise ParameterError("aruco must be an ArucoTarget")
        self.aruco = aruco
        self.rate = float(rate)
        if not (np.isfinite(self.rate) and self.rate > 0):
            raise ParameterError(f"rate must be positive [Hz], got {rate!r}")
        self.supersample = int(supersample)
        if self.supersample < 1:
            raise ParameterError(f"supersample must be >= 1, got {supersample!r}")
        self._rng = np.random.default_rng(seed)
        H, W = model.height, model.width
        bg = np.asarray(background)
        if bg.shape == (3,):
            self._bg = np.empty((H, W, 3), np.float32)
            self._bg[:] = bg.astype(np.float32)
        elif bg.shape == (H, W, 3):
            self._bg = bg.astype(np.float32)
        else:
            raise ParameterError(f"background must be a BGR triple or an ({H}, {W}, 3) image")
        self._static = None
        self._index = 0
        self._closed = False
        u = np.arange(W, dtype=np.float32)
        v = np.arange(H, dtype=np.float32)
        self._u, self._v = u, v

    # -- static layer -------------------------------------------------------------------------------
    def _static_layer(self):
        if self._static is not None:
            return self._static
        img, dep = self._bg.copy(), np.zeros(self._bg.shape[:2], np.float32)
        if self.aruco is not None:
            img, dep = self._render_aruco(img, dep)
        self._static = (img, dep)
        return self._static

    def _render_aruco(self, img, dep):
        cv2 = require_cv2()
        tg, m = self.aruco, self.model
        tex, p = tg.texture()
        x0, x1, y0, y1 = tg.sheet
        # texture pixel (i, j) -> sheet point -> camera -> pixel
        S = np.array([[p, 0, x0 + 0.5 * p], [0, -p, y1 - 0.5 * p], [0, 0, 1.0]])
        T_ct = np.linalg.inv(m.pose) @ tg.pose
        Hm = m.K @ np.column_stack([T_ct[:3, 0], T_ct[:3, 1], T_ct[:3, 3]]) @ S
        s = self.supersample
        A = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1.0]])   # low-res -> high-res pixels
        Hs = A @ Hm
        H, W = m.height, m.width
        if np.any(T_ct[:3, 3] @ T_ct[:3, 2] >= 0):
            log.warning("the ArUco sheet faces away from the camera; it is not rendered")
            return img, dep
        # sheet corners must be in front of the camera
        cor = np.array([[x0, y0, 0, 1], [x1, y0, 0, 1], [x1, y1, 0, 1], [x0, y1, 0, 1.0]]) @ T_ct.T
        if np.any(cor[:, 2] <= 0):
            raise ParameterError("the ArUco sheet reaches behind the camera; move the camera back")
        hi = cv2.warpPerspective(tex.astype(np.float32), Hs, (W * s, H * s), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        cov = cv2.warpPerspective(np.ones_like(tex, np.float32), Hs, (W * s, H * s), flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        lo = cv2.resize(hi, (W, H), interpolation=cv2.INTER_AREA)
        a = cv2.resize(cov, (W, H), interpolation=cv2.INTER_AREA)
        img = img * (1 - a[..., None]) + lo[..., None] * np.ones(3, np.float32)
        # depth of the sheet plane where covered: ray (x, y, 1) meets n . p = n . t
        n, t = T_ct[:3, 2], T_ct[:3, 3]
        xn = (self._u[None, :] - m.K[0, 2]) / m.K[0, 0]
        yn = (self._v[:, None] - m.K[1, 2]) / m.K[1, 1]
        z = (n @ t) / (n[0] * xn + n[1] * yn + n[2])
        dep = np.where(a > 0.5, z, dep).astype(np.float32)
        return img.astype(np.float32), dep

    # -- markers ------------------------------------------------------------------------------------
    def _marker_colors(self, m):
        c = self.colors
        if isinstance(c, str):
            c = [c] * m
        c = list(c) if not (np.ndim(c) == 1 and len(c) == 3 and not isinstance(c[0], str)) else [c] * m
        if len(c) != m:
            raise ParameterError(f"give one colour per marker ({m}), or one for all")
        out = []
        for x in c:
            if isinstance(x, str):
                if x not in DEFAULT_COLORS:
                    raise ParameterError(f"unknown colour {x!r}; use one of {sorted(DEFAULT_COLORS)} or a BGR triple")
                x = DEFAULT_COLORS[x]
            out.append(np.asarray(x, dtype=np.float32))
        return out

    def render(self, points, t=0.0, hidden=None):
        """A :class:`Frame` showing markers centred at world ``points`` (m, 3) [m] at time ``t`` [s]; markers
        flagged in ``hidden`` (m,) are not drawn (occluded: a dropout), and not ``visible`` in the truth."""
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(P)):
            raise DataError("marker positions contain NaN or inf")
        m = self._ideal
        drawn = np.ones(len(P), bool) if hidden is None else ~np.asarray(hidden, bool).reshape(-1)
        if drawn.shape != (len(P),):
            raise ParameterError(f"hidden must be one flag per marker ({len(P)})")
        img0, dep0 = self._static_layer()
        img = img0.copy()
        dep = dep0.copy() if self.depth else None
        R = np.broadcast_to(np.asarray(self.marker_radius, dtype=float), (len(P),))
        if np.any(R <= 0):
            raise ParameterError("marker_radius must be positive [m]")
        uv, z = m.project(P)
        f = np.sqrt(m.K[0, 0] * m.K[1, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            r = f * R / z
        H, W = m.height, m.width
        visible = (z > 0) & np.all(np.isfinite(uv), axis=1)
        visible &= (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
        colors = self._marker_colors(len(P))
        Pc = m.to_camera(P)
        for k in np.argsort(-z):                      # far to near
            if not (drawn[k] and z[k] > 0 and np.all(np.isfinite(uv[k]))):
                continue
            u0, v0, rk = uv[k, 0], uv[k, 1], r[k]
            i0, i1 = max(int(math.floor(u0 - rk - 1)), 0), min(int(math.ceil(u0 + rk + 1)) + 1, W)
            j0, j1 = max(int(math.floor(v0 - rk - 1)), 0), min(int(math.ceil(v0 + rk + 1)) + 1, H)
            if i0 >= i1 or j0 >= j1:
                continue
            du = self._u[i0:i1][None, :] - np.float32(u0)
            dv = self._v[j0:j1][:, None] - np.float32(v0)
            d = np.sqrt(du * du + dv * dv)
            a = np.clip(rk - d + 0.5, 0.0, 1.0).astype(np.float32)
            win = img[j0:j1, i0:i1]
            win += a[..., None] * (colors[k] - win)
            if dep is not None:
                # sphere surface along each pixel's ray (x, y, 1): |s d - c|^2 = R^2, nearest root
                xn = (np.arange(i0, i1, dtype=float)[None, :] - m.K[0, 2]) / m.K[0, 0]
                yn = (np.arange(j0, j1, dtype=float)[:, None] - m.K[1, 2]) / m.K[1, 1]
                c = Pc[k]
                dd = xn * xn + yn * yn + 1.0
                b = xn * c[0] + yn * c[1] + c[2]
                disc = b * b - dd * (c @ c - R[k] ** 2)
                s = (b - np.sqrt(np.maximum(disc, 0))) / dd
                hit = (disc >= 0) & (a >= 0.5)
                dw = dep[j0:j1, i0:i1]
                dw[hit] = np.where((dw[hit] == 0) | (s[hit] < dw[hit]), s[hit], dw[hit])
        if self.model.dist is not None:
            img, dep, uv = self._distort(img, dep, P)
            visible &= np.all(np.isfinite(uv), axis=1)
            visible &= (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
        visible &= drawn
        if self.noise > 0:
            img += np.float32(self.noise) * self._rng.standard_normal(img.shape, dtype=np.float32)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        truth = GroundTruth(points=P.copy(), centres=uv, radii=r, z=z, visible=visible, pose=m.pose.copy())
        return Frame(out, dep, float(t), self._index, truth)

    def _distort(self, img, dep, P):
        """The ideal image (and depth) warped by the model's lens distortion, and the distorted centres of ``P``."""
        cv2 = require_cv2()
        m = self.model
        if self._maps is None:
            H, W = m.height, m.width
            uv = np.stack(np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64)), -1)
            xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), m.K, m.dist).reshape(H, W, 2)
            self._maps = (np.ascontiguousarray((xy[..., 0] * m.K[0, 0] + xy[..., 1] * m.K[0, 1] + m.K[0, 2])
                                               .astype(np.float32)),
                          np.ascontiguousarray((xy[..., 1] * m.K[1, 1] + m.K[1, 2]).astype(np.float32)))
        mx, my = self._maps
        bg = tuple(float(v) for v in self._bg[0, 0])
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=bg)
        if dep is not None:
            dep = cv2.remap(dep, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return img, dep, m.project(P)[0]

    def read(self):
        """Render the next frame of ``scene`` (frame ``k`` at ``t = k / rate``)."""
        if self._closed:
            raise DataError("the camera is closed")
        if self.scene is None:
            raise ParameterError("this SyntheticCamera has no scene; call render(points) or give scene=")
        t = self._index / self.rate
        frame = self.render(self.scene(t), t)
        self._index += 1
        return frame

    def close(self):
        self._closed = True
