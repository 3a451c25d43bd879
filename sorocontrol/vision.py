r"""Vision: coloured-marker detection with sub-pixel centres, ArUco calibration of the world frame, and the two
ways from pixels to 3D points (depth back-projection, rays meeting a known plane).

Marker detection
----------------
1. *Candidates*: the image is reduced by ``scale`` (area averaging), converted to HSV and thresholded per colour
   (:class:`HsvRange`, red's hue wraps around 180); circles are found in the blurred mask by
   ``cv2.HoughCircles`` and checked against the mask (blobs Hough misses are taken from connected components).
   When predicted centres are given (tracking), only windows around them are searched, at full resolution.
2. *Sub-pixel centre*: in a window around each candidate, every pixel gets the fraction :math:`\alpha` of it
   covered by the marker, from its colour between the local background :math:`b` (mean of a ring around the
   marker, pixels of the marker's colour left out) and the marker colour :math:`m` (mean of the mask's interior):
   :math:`\alpha = (p - b)\cdot(m - b) / |m - b|^2`, and the centre is the first moment
   :math:`c = \sum_{|x - c| \le r + 1.5} \alpha\, x / \sum \alpha` (iterated until it moves less than 0.01 px).
   Anti-aliased edges carry the sub-pixel position; pixel noise is zero-mean in :math:`\alpha` (no clipping), so
   it does not bias :math:`c`. Where the surround is not uniform (mean :math:`|\alpha|` over the ring above
   0.1), the binary colour mask is used as the weight instead (about a tenth of a pixel, not hundredths). A
   marker whose disc is cut by the image border is dropped (its centroid would be biased).
3. *Order*: a nearest-neighbour chain from a start point (the projected base of the beam), or, when tracking, the
   assignment to the predicted centres (Hungarian, gated). Missing markers are NaN rows, listed in
   :attr:`Detection.missing`.

Examples
--------
>>> import numpy as np
>>> from sorocontrol.camera import CameraModel, SyntheticCamera, look_at
>>> from sorocontrol.vision import MarkerDetector
>>> cam = CameraModel.from_fov(60.0, pose=look_at((0.0, 0.0, 0.4), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0)))
>>> pts = [[0.00, 0.00, 0.0], [0.03, 0.01, 0.0], [0.06, 0.015, 0.0]]
>>> frame = SyntheticCamera(cam, marker_radius=4e-3).render(pts)
>>> det = MarkerDetector(count=3).detect(frame.image, start=cam.project([[-0.03, 0.0, 0.0]])[0][0])
>>> det.missing
[]
>>> bool(np.abs(det.centres - frame.truth.centres).max() < 0.1)
True
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from sorofem.errors import DataError, ParameterError

from .camera import ArucoTarget, CameraModel, Frame, require_cv2

# numpy 2 renamed trapz to trapezoid (trapz is deprecated there); numpy 1.24 has only trapz
_trapezoid = getattr(np, "trapezoid", None) or np.trapz

__all__ = ["HsvRange", "MarkerDetector", "Detection", "order_chain", "calibrate_world", "calibrate_intrinsics",
           "marker_points",
           "depth_at", "RED", "GREEN", "BLUE", "YELLOW"]

log = logging.getLogger(__name__)


# ------------------------------------------------------------------------------------------------------------
# colour thresholds
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HsvRange:
    """An HSV box in OpenCV's units (H in [0, 180), S and V in [0, 255]). ``h_lo > h_hi`` wraps around 180
    (red: ``HsvRange(170, 10, ...)`` covers [170, 180) and [0, 10])."""

    h_lo: int
    h_hi: int
    s_lo: int = 100
    s_hi: int = 255
    v_lo: int = 60
    v_hi: int = 255

    def __post_init__(self):
        for name, lim in (("h_lo", 179), ("h_hi", 179), ("s_lo", 255), ("s_hi", 255), ("v_lo", 255),
                          ("v_hi", 255)):
            v = getattr(self, name)
            if not (0 <= v <= lim):
                raise ParameterError(f"HsvRange.{name} must be in [0, {lim}] (OpenCV HSV), got {v!r}")
        if self.s_lo > self.s_hi or self.v_lo > self.v_hi:
            raise ParameterError("HsvRange: lower saturation/value bounds exceed the upper ones")

    def mask(self, hsv):
        """uint8 mask (255 inside) of an HSV image."""
        cv2 = require_cv2()
        if self.h_lo <= self.h_hi:
            return cv2.inRange(hsv, (self.h_lo, self.s_lo, self.v_lo), (self.h_hi, self.s_hi, self.v_hi))
        a = cv2.inRange(hsv, (self.h_lo, self.s_lo, self.v_lo), (179, self.s_hi, self.v_hi))
        b = cv2.inRange(hsv, (0, self.s_lo, self.v_lo), (self.h_hi, self.s_hi, self.v_hi))
        return cv2.bitwise_or(a, b)


RED = HsvRange(170, 10)
GREEN = HsvRange(40, 80)
BLUE = HsvRange(100, 130)
YELLOW = HsvRange(22, 38)


# ------------------------------------------------------------------------------------------------------------
# detections
# ------------------------------------------------------------------------------------------------------------
@dataclass
class Detection:
    """Markers found in one image, in beam order: ``centres`` (count, 2) [px] (NaN rows where missing), ``radii``
    (count,) [px], ``colors`` (count,) colour names (None where missing), ``found`` (count,) bool, ``extra``
    (k, 2) candidates that were not assigned (clutter or surplus markers), ``tracked`` (found by the tracking
    windows rather than a full search)."""

    centres: np.ndarray
    radii: np.ndarray
    colors: list
    found: np.ndarray
    extra: np.ndarray
    tracked: bool = False

    @property
    def missing(self):
        """Indices of the markers not found."""
        return [int(i) for i in np.flatnonzero(~self.found)]

    @property
    def count(self):
        """Number of markers found."""
        return int(self.found.sum())


def order_chain(points, start):
    """Order 2D points (k, 2) along a chain: start at the point nearest ``start`` (2,), then repeatedly go to the
    nearest unvisited point. Returns the index order (k,)."""
    P = np.asarray(points, dtype=float).reshape(-1, 2)
    cur = np.asarray(start, dtype=float).reshape(2)
    left = list(range(len(P)))
    order = []
    while left:
        d = np.hypot(*(P[left] - cur).T)
        j = left.pop(int(np.argmin(d)))
        order.append(j)
        cur = P[j]
    return np.array(order, dtype=int)


def _refine(img, c, r, mask_fn, iterations=3, passes=2):
    """Sub-pixel centre (2,) and radius [px] of the marker near ``c`` with approximate radius ``r`` (module
    docstring, step 2); None when the window holds no usable marker.

    The coverage :math:`\alpha` is computed once in a window of half-size :math:`r + 6` around ``c``; the disc
    over which the moments are taken then follows the centre until it moves less than 0.01 px (the disc only
    selects which pixels count, and the coverage is zero near its edge, so this is exact once the disc holds
    the whole marker). A second pass
    re-centres the window when the centre moved by more than 3 px."""
    cv2 = require_cv2()
    H, W = img.shape[:2]
    c = np.asarray(c, dtype=float)
    for _ in range(passes):
        h = int(math.ceil(r + 6))
        ic, jc = int(round(c[0])), int(round(c[1]))
        i0, i1, j0, j1 = max(ic - h, 0), min(ic + h + 1, W), max(jc - h, 0), min(jc + h + 1, H)
        if i1 - i0 < 5 or j1 - j0 < 5:
            return None
        sub = img[j0:j1, i0:i1]
        win = sub.astype(np.float32)
        inside = mask_fn(cv2.cvtColor(sub, cv2.COLOR_BGR2HSV)) > 0
        X = np.arange(i0, i1, dtype=np.float64)[None, :]
        Y = np.arange(j0, j1, dtype=np.float64)[:, None]
        d2 = (X - c[0]) ** 2 + (Y - c[1]) ** 2
        core = inside & (d2 <= max(r - 1.0, 0.75) ** 2)
        if not core.any():
            core = inside
        ring = d2 >= (r + 2.5) ** 2
        bg = ring & ~inside                      # the surround, without other markers of this colour
        if core.sum() < 1 or bg.sum() < 8:
            return None
        m = win[core].mean(axis=0)
        b = win[bg].mean(axis=0)
        mb = m - b
        den = float(mb @ mb)
        if den < 25.0:              # marker and background closer than 5 grey levels: no contrast
            return None
        alpha = ((win - b) @ (mb / den)).astype(np.float64)
        if np.mean(np.abs(alpha[bg])) > 0.1:
            # the surround is not uniform (an edge or a pattern behind the marker): the coverage model fails,
            # use the colour mask (pixel accuracy) instead
            alpha = inside.astype(np.float64)
        c0 = c.copy()
        for _ in range(iterations):
            w = np.where((X - c[0]) ** 2 + (Y - c[1]) ** 2 <= (r + 1.5) ** 2, alpha, 0.0)
            sw = float(w.sum())
            if sw <= 0.5:
                return None
            cn = np.array([float((w * X).sum()), float((w * Y).sum())]) / sw
            r = math.sqrt(sw / math.pi)
            moved = cn - c
            c = cn
            if moved @ moved < 1e-4:   # the disc only needs to contain the marker: 0.01 px is converged
                break
        if np.max(np.abs(c - c0)) < 3.0:
            break
    if c[0] - r - 1.0 < -0.5 or c[1] - r - 1.0 < -0.5 or c[0] + r + 1.0 > W - 0.5 or c[1] + r + 1.0 > H - 0.5:
        return None                 # cut by the image border: its centroid would be biased
    return c, r


def _cut(stat, cv2, window, size):
    """Whether a blob (a row of connectedComponentsWithStats) touches an edge of its search ``window`` (i0, i1,
    j0, j1) that is not the image's edge: only part of a marker that moved out of the window is inside, and its
    centroid (hence its refinement) lies a part of a radius or more off the marker's centre, so it is not used
    (the full search finds the marker)."""
    i0, i1, j0, j1 = window
    W, H = size
    x, y = stat[cv2.CC_STAT_LEFT], stat[cv2.CC_STAT_TOP]
    w, h = stat[cv2.CC_STAT_WIDTH], stat[cv2.CC_STAT_HEIGHT]
    return bool((x == 0 and i0 > 0) or (y == 0 and j0 > 0) or (x + w >= i1 - i0 and i1 < W)
                or (y + h >= j1 - j0 and j1 < H))


@dataclass
class _Colour:
    name: str
    rng: HsvRange


class MarkerDetector:
    """Finds ``count`` coloured circular markers and orders them along the beam.

    Parameters
    ----------
    count : int
        Number of markers on the beam.
    colors : dict name -> HsvRange, or a sequence of names of the presets ``red``, ``green``, ``blue``,
        ``yellow``
        Colour classes to look for (default red).
    radius : (min, max) [px]
        Range of marker radii in the image.
    scale : float in (0, 1]
        Resolution of the full search relative to the image (0.5: 320 x 240 for a VGA frame).
    search : float [px]
        Half-size of the tracking windows around predicted centres (default ``2 * radius[1] + 6``).
    gate : float [px]
        Largest distance between a predicted and an assigned centre (default ``1.5 * search``, beyond the
        corners of the windows).
    min_fill : float
        Fraction of a Hough circle that must be inside the colour mask.
    """

    PRESETS = {"red": RED, "green": GREEN, "blue": BLUE, "yellow": YELLOW}

    def __init__(self, count, colors=("red",), *, radius=(3.0, 30.0), scale=0.5, search=None, gate=None,
                 min_fill=0.6, hough_threshold=8):
        self.count = int(count)
        if self.count < 1:
            raise ParameterError(f"count must be >= 1 marker, got {count!r}")
        if isinstance(colors, dict):
            items = list(colors.items())
        else:
            if isinstance(colors, str):
                colors = (colors,)
            items = []
            for c in colors:
                if c not in self.PRESETS:
                    raise ParameterError(f"unknown colour {c!r}: use {sorted(self.PRESETS)} or a dict name -> HsvRange")
                items.append((c, self.PRESETS[c]))
        if not items or not all(isinstance(r, HsvRange) for _, r in items):
            raise ParameterError("colors must map names to HsvRange objects")
        self.colors = [_Colour(n, r) for n, r in items]
        rmin, rmax = (float(x) for x in radius)
        if not (0 < rmin <= rmax):
            raise ParameterError(f"radius must be (min, max) pixels with 0 < min <= max, got {radius!r}")
        self.radius = (rmin, rmax)
        self.scale = float(scale)
        if not (0 < self.scale <= 1):
            raise ParameterError(f"scale must be in (0, 1], got {scale!r}")
        self.search = float(search) if search is not None else 2 * rmax + 6
        self.gate = float(gate) if gate is not None else 1.5 * self.search
        self.min_fill = float(min_fill)
        self.hough_threshold = float(hough_threshold)

    # -- candidates -------------------------------------------------------------------------------
    def _candidates(self, img):
        """[(centre (2,), radius, colour index)] from the full image at reduced resolution."""
        cv2 = require_cv2()
        s = self.scale
        small = img if s == 1 else cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        hsv = cv2.cvtColor(small, cv2.COLOR_BGR2HSV)
        rmin, rmax = self.radius[0] * s, self.radius[1] * s
        out = []
        for ci, col in enumerate(self.colors):
            mask = col.rng.mask(hsv)
            if not mask.any():
                continue
            blur = cv2.GaussianBlur(mask, (5, 5), 1.0)
            circles = cv2.HoughCircles(blur, cv2.HOUGH_GRADIENT, dp=1, minDist=max(2 * rmin, 2.0), param1=100,
                                       param2=self.hough_threshold, minRadius=max(int(rmin * 0.7), 1),
                                       maxRadius=int(math.ceil(rmax * 1.3)) + 1)
            found = []
            if circles is not None:
                for x, y, r in circles[0]:
                    i0, i1 = int(max(x - r - 1, 0)), int(min(x + r + 2, mask.shape[1]))
                    j0, j1 = int(max(y - r - 1, 0)), int(min(y + r + 2, mask.shape[0]))
                    disc = ((np.arange(i0, i1)[None, :] - x) ** 2 + (np.arange(j0, j1)[:, None] - y) ** 2
                            <= r * r)
                    if disc.sum() == 0 or (mask[j0:j1, i0:i1][disc] > 0).mean() < self.min_fill:
                        continue
                    if any(math.hypot(x - fx, y - fy) < max(r, fr) for fx, fy, fr in found):
                        continue
                    found.append((float(x), float(y), float(r)))
            # blobs that Hough missed (very small or partly occluded markers)
            n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
            for k in range(1, n):
                area = stats[k, cv2.CC_STAT_AREA]
                r = math.sqrt(area / math.pi)
                if not (0.5 * rmin <= r <= 1.5 * rmax):
                    continue
                x, y = cents[k]
                if any(math.hypot(x - fx, y - fy) < max(r, fr) for fx, fy, fr in found):
                    continue
                found.append((float(x), float(y), r))
            for x, y, r in found:
                out.append((np.array([(x + 0.5) / s - 0.5, (y + 0.5) / s - 0.5]), r / s, ci))
        return out

    def _refine_all(self, img, cands):
        out = []
        for c, r, ci in cands:
            res = _refine(img, c, max(r, self.radius[0]), self.colors[ci].rng.mask)
            if res is None:
                continue
            c2, r2 = res
            if not (0.5 * self.radius[0] <= r2 <= 1.5 * self.radius[1]):
                continue
            if any(np.hypot(*(c2 - o[0])) < max(r2, o[1]) for o in out):   # duplicate of a refined one
                continue
            out.append((c2, r2, ci))
        return out

    def _track(self, img, predicted):
        """Refined markers found in windows around ``predicted`` (count, 2) [px]; NaN rows are skipped."""
        cv2 = require_cv2()
        H, W = img.shape[:2]
        h = int(math.ceil(self.search))
        out = []
        for k, p in enumerate(predicted):
            if not np.all(np.isfinite(p)):
                continue
            i0, i1 = max(int(round(p[0])) - h, 0), min(int(round(p[0])) + h + 1, W)
            j0, j1 = max(int(round(p[1])) - h, 0), min(int(round(p[1])) + h + 1, H)
            if i1 - i0 < 3 or j1 - j0 < 3:
                continue
            hsv = cv2.cvtColor(img[j0:j1, i0:i1], cv2.COLOR_BGR2HSV)
            best = None
            for ci, col in enumerate(self.colors):
                mask = col.rng.mask(hsv)
                n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
                for b in range(1, n):
                    r = math.sqrt(stats[b, cv2.CC_STAT_AREA] / math.pi)
                    if r < 0.5 * self.radius[0] or _cut(stats[b], cv2, (i0, i1, j0, j1), (W, H)):
                        continue
                    c = cents[b] + (i0, j0)
                    dist = math.hypot(*(c - p))
                    if best is None or dist < best[0]:
                        best = (dist, c, r, ci)
            if best is None or best[0] > self.gate:
                continue
            res = _refine(img, best[1], max(best[2], self.radius[0]), self.colors[best[3]].rng.mask)
            if res is not None and not any(np.hypot(*(res[0] - o[0])) < max(res[1], o[1]) for o in out):
                out.append((res[0], res[1], best[3]))      # (two windows may reach the same marker: keep one)
        return out

    # -- public -------------------------------------------------------------------------------------
    def detect(self, image, start=None, predicted=None):
        """Find the markers in a BGR uint8 ``image`` (or a :class:`~sorocontrol.camera.Frame`).

        Parameters
        ----------
        start : (2,) [px], optional
            Where the chain of markers begins (e.g. the projected base of the beam); default: the candidate
            nearest the image's left edge.
        predicted : (count, 2) [px], optional
            Expected centres (NaN where unknown): search windows around them first, assign by a gated
            Hungarian match, and fall back to the full search for markers not found there (and, when that search
            shows exactly ``count`` markers and ``start`` is given, to the chain order).

        Returns
        -------
        Detection (markers in beam order; missing ones reported, never invented).
        """
        cv2 = require_cv2()
        img = image.image if isinstance(image, Frame) else image
        if not (isinstance(img, np.ndarray) and img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8):
            raise DataError("image must be a BGR uint8 array (H, W, 3)")
        n = self.count
        tracked = False
        if predicted is not None:
            pred = np.asarray(predicted, dtype=float).reshape(-1, 2)
            if len(pred) != n:
                raise ParameterError(f"predicted must have {n} rows (count), got {len(pred)}")
            cands = self._track(img, pred)
            if len(cands) == n:
                det = self._assign(cands, pred, True)
                if det.found.all():
                    return det
            full = self._refine_all(img, self._candidates(img))
            for c in full:
                if not any(np.hypot(*(c[0] - o[0])) < max(c[1], o[1]) for o in cands):
                    cands.append(c)
            det = self._assign(cands, pred, False)
            if det.found.all() or len(full) != n or start is None:
                return det
            # moved beyond the gate, but the full search shows exactly the markers: order them as a chain
            log.debug("markers %s moved beyond the tracking gate; re-ordered from the start point", det.missing)
            cands = full
        else:
            cands = self._refine_all(img, self._candidates(img))
        if start is None:
            start = (0.0, img.shape[0] / 2)
        order = order_chain(np.array([c[0] for c in cands]).reshape(-1, 2), start) if cands else []
        cands = [cands[i] for i in order]
        use, extra = cands[:n], cands[n:]
        centres = np.full((n, 2), np.nan)
        radii = np.full(n, np.nan)
        colors = [None] * n
        for k, (c, r, ci) in enumerate(use):
            centres[k], radii[k], colors[k] = c, r, self.colors[ci].name
        found = np.isfinite(centres[:, 0])
        if extra:
            log.debug("%d candidates beyond the %d markers were left out", len(extra), n)
        if not found.all():
            log.info("markers %s not found", list(np.flatnonzero(~found)))
        return Detection(centres, radii, colors, found, np.array([c[0] for c in extra]).reshape(-1, 2), False)

    def _assign(self, cands, pred, tracked):
        from scipy.optimize import linear_sum_assignment
        n = self.count
        centres = np.full((n, 2), np.nan)
        radii = np.full(n, np.nan)
        colors = [None] * n
        used = set()
        ok = np.isfinite(pred).all(axis=1)
        if cands and ok.any():
            C = np.array([c[0] for c in cands])
            rows = np.flatnonzero(ok)
            D = np.hypot(*(pred[rows][:, None, :] - C[None, :, :]).transpose(2, 0, 1))
            big = 1e6
            Dg = np.where(D <= self.gate, D, big)
            ri, cj = linear_sum_assignment(Dg)
            for a, b in zip(ri, cj):
                if Dg[a, b] < big:
                    k = rows[a]
                    centres[k], radii[k], colors[k] = cands[b][0], cands[b][1], self.colors[cands[b][2]].name
                    used.add(b)
        found = np.isfinite(centres[:, 0])
        extra = np.array([c[0] for j, c in enumerate(cands) if j not in used]).reshape(-1, 2)
        if not found.all():
            log.info("markers %s not found near their predictions", list(np.flatnonzero(~found)))
        return Detection(centres, radii, colors, found, extra, tracked and bool(found.all()))


# ------------------------------------------------------------------------------------------------------------
# pixels -> 3D
# ------------------------------------------------------------------------------------------------------------
def depth_at(depth, pixels, window=1):
    """z-depth [m] at sub-pixel ``pixels`` (m, 2) of a depth image (H, W) [m]: bilinear interpolation of the four
    neighbours when they are all valid (> 0), else the median of the valid depths in a ``(2 window + 1)^2``
    neighbourhood; NaN when none is valid or the pixel is NaN/outside."""
    D = np.asarray(depth, dtype=np.float64)
    if D.ndim != 2:
        raise DataError("depth must be an (H, W) image of z-depths [m]")
    H, W = D.shape
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    out = np.full(len(uv), np.nan)
    for k, (u, v) in enumerate(uv):
        if not (np.isfinite(u) and np.isfinite(v)) or not (0 <= u <= W - 1 and 0 <= v <= H - 1):
            continue
        i, j = min(int(u), W - 2), min(int(v), H - 2)
        a, b = u - i, v - j
        q = D[j:j + 2, i:i + 2]
        if np.all(q > 0):
            out[k] = (q[0, 0] * (1 - a) * (1 - b) + q[0, 1] * a * (1 - b) + q[1, 0] * (1 - a) * b
                      + q[1, 1] * a * b)
            continue
        i, j = int(round(u)), int(round(v))
        nb = D[max(j - window, 0):j + window + 1, max(i - window, 0):i + window + 1]
        nb = nb[nb > 0]
        if nb.size:
            out[k] = float(np.median(nb))
    return out


def marker_points(camera, pixels, *, depth=None, plane=None, offset=0.0):
    r"""World positions (m, 3) [m] of marker centres seen at ``pixels`` (m, 2) [px] (NaN rows stay NaN).

    * ``depth`` (H, W) z-depth image [m]: back-projection :math:`p = T_{wc}\, z (x, y, 1)`, moved ``offset``
      [m] (the marker radius: the camera sees the sphere's surface) along the ray;
    * ``plane = (point, normal)`` [m]: the rays meet the plane the markers' centres lie in (e.g. the bending
      plane of a planar beam).

    Raises ParameterError when neither (or both) is given and DataError when the depth is invalid at a
    detected marker.
    """
    if not isinstance(camera, CameraModel):
        raise ParameterError("camera must be a CameraModel (intrinsics and pose from calibrate_world)")
    if (depth is None) == (plane is None):
        raise ParameterError("give either a depth image (depth=) or the markers' plane (plane=(point, normal))")
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    ok = np.isfinite(uv).all(axis=1)
    out = np.full((len(uv), 3), np.nan)
    if not ok.any():
        return out
    if plane is not None:
        point, normal = plane
        out[ok] = camera.intersect_plane(uv[ok], point, normal)
        return out
    z = depth_at(depth, uv[ok])
    if not np.all(np.isfinite(z)):
        bad = np.flatnonzero(ok)[~np.isfinite(z)]
        raise DataError(f"no valid depth at markers {list(bad)}: the depth camera saw nothing there (too close, "
                        f"too far, or a reflective surface)")
    out[ok] = camera.back_project(uv[ok], z, offset)
    return out


# ------------------------------------------------------------------------------------------------------------
# ArUco calibration of the world frame
# ------------------------------------------------------------------------------------------------------------
def _refine_quad(gray, corners, cells, samples=24):
    r"""Sub-pixel corners (4, 2) of a dark square on a bright surround from coarse ``corners`` (4, 2).

    Along each side, ``samples`` intensity profiles across the edge (bilinear, 0.25 px steps over
    :math:`\pm L`, :math:`L` a third of a marker cell, at most 4 px) locate the edge at
    :math:`t_e = L - \int_{-L}^{L} n(t)\,dt` with :math:`n = (I - I_{dark})/(I_{bright} - I_{dark})` (exact for an
    area-sampled straight step); a line is fitted through the edge points (total least squares) and adjacent
    lines are intersected. Profiles whose dark or bright level is off the side's median by more than 15 % of the
    contrast are left out, and so are edge points more than three median residuals (and 0.1 px) off the fitted
    line (something in front of the target); None when a side keeps fewer than half of its profiles."""
    cv2 = require_cv2()
    c = np.asarray(corners, dtype=np.float64)
    centre = c.mean(axis=0)
    side = float(np.min(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1)))
    L = 0.25 * round(4 * float(np.clip(side / cells / 3, 1.0, 4.0)))
    t = np.arange(-L, L + 1e-9, 0.25)
    s = np.linspace(0.15, 0.85, samples)
    lines = []
    img = gray.astype(np.float32)
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        nrm = np.array([d[1], -d[0]])
        if nrm @ ((a + b) / 2 - centre) < 0:
            nrm = -nrm                               # outward: dark (inside) -> bright (outside)
        base = a[None, :] + s[:, None] * (b - a)[None, :]
        pts = base[:, None, :] + t[None, :, None] * nrm[None, None, :]
        prof = cv2.remap(img, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
        dark, bright = prof[:, :3].mean(axis=1), prof[:, -3:].mean(axis=1)
        md, mb = np.median(dark), np.median(bright)
        ok = (bright - dark > 20.0) & (np.abs(dark - md) < 0.15 * (mb - md)) & (np.abs(bright - mb) < 0.15 * (mb - md))
        if ok.sum() < 0.5 * samples:
            return None                              # this side is hidden or not a clean edge
        nn = (prof[ok] - dark[ok, None]) / (bright - dark)[ok, None]
        te = t[-1] - _trapezoid(nn, t, axis=1)         # edge offset from the coarse side along the normal [px]
        x = s[ok] * np.linalg.norm(b - a)            # position along the side [px]
        keep = np.abs(te - np.median(te)) <= max(3 * np.median(np.abs(te - np.median(te))), 0.3)
        for _ in range(4):                           # trimmed straight-line fit te = alpha + beta x
            if keep.sum() < 0.5 * samples:
                return None
            beta, alpha = np.polyfit(x[keep], te[keep], 1)
            res = np.abs(te - alpha - beta * x)
            new = res <= max(3.0 * np.median(res[keep]), 0.1)
            if np.array_equal(new, keep):
                break
            keep = new
        direction = d + beta * nrm
        lines.append((a + alpha * nrm, direction / np.linalg.norm(direction)))
    out = np.empty((4, 2))
    for k in range(4):
        (p1, d1), (p2, d2) = lines[(k - 1) % 4], lines[k]
        A = np.column_stack([d1, -d2])
        if abs(np.linalg.det(A)) < 1e-9:
            return None
        st = np.linalg.solve(A, p2 - p1)
        out[k] = p1 + st[0] * d1
    return out


def _aruco_points(image, target, refine):
    """The target's markers found in ``image``: sheet-frame corners (4k, 3) [m], their pixels (4k, 2) [px] (refined
    as ``refine`` says, see :func:`calibrate_world`) and the ids used. DataError when none is found."""
    cv2 = require_cv2()
    img = image.image if isinstance(image, Frame) else np.asarray(image)
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    if gray.dtype != np.uint8:
        raise DataError("image must be uint8")
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    det = cv2.aruco.ArucoDetector(target._dict(), params)
    corners, ids, _ = det.detectMarkers(gray)
    if ids is None:
        raise DataError("no ArUco marker found: check the dictionary, the lighting, and that the target is in view")
    obj, pix, used, rejected = [], [], [], []
    for c, i in zip(corners, ids.ravel()):
        if int(i) not in target.ids:
            continue
        c = c.reshape(4, 2).astype(np.float64)
        if refine == "edges":
            r = _refine_quad(gray, c, target._dict().markerSize + 2)
            if r is None:
                rejected.append((int(i), c))
                continue
            c = r
        elif refine == "subpix":
            side = float(np.min(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1)))
            win = int(np.clip(side / 10, 2, 7))
            c = cv2.cornerSubPix(gray, c.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)).reshape(4, 2)
        obj.append(target.local_corners(target.ids.index(int(i))))
        pix.append(c)
        used.append(int(i))
    if rejected:
        log.info("ArUco markers %s have a hidden or unclean edge%s", [i for i, _ in rejected],
                 "; left out" if used else "; using their unrefined corners")
        if not used:
            for i, c in rejected:
                obj.append(target.local_corners(target.ids.index(i)))
                pix.append(c)
                used.append(i)
    if not used:
        raise DataError(f"ArUco markers {sorted(ids.ravel().tolist())} were found but none of the target's ids "
                        f"{list(target.ids)}")
    return np.concatenate(obj).astype(np.float64), np.concatenate(pix).astype(np.float64), used


def calibrate_intrinsics(images, target, *, refine="edges", distortion=5):
    r"""Intrinsics and lens distortion of a camera from views of a flat ArUco ``target`` (Zhang's method).

    In each image the target's markers are found and their corners refined as in :func:`calibrate_world`; the
    sheet-frame corners and their pixels of all views go to ``cv2.calibrateCamera``, which fits
    :math:`K` and the distortion coefficients :math:`(k_1, k_2, p_1, p_2, k_3)` (the last ones held at 0 when
    ``distortion`` < 5) with one pose per view, minimizing the reprojection error. Views must tilt the target
    (at least three, at different angles) for the focal length to be determined.

    Parameters
    ----------
    images : sequence of (H, W, 3) BGR or (H, W) grey uint8 images, or Frames, all of one size.
    target : ArucoTarget
    refine : "edges", "subpix" or None
    distortion : int
        How many of :math:`(k_1, k_2, p_1, p_2, k_3)` are fitted: 2 (radial :math:`k_1, k_2`), 4 or 5.

    Returns
    -------
    CameraModel
        ``K``, image size, ``dist`` (5,) and ``rms``, the reprojection error [px]; pose identity (place it
        with :func:`calibrate_world`).

    Raises DataError when fewer than three views show the target.
    """
    cv2 = require_cv2()
    if not isinstance(target, ArucoTarget):
        raise ParameterError("target must be an ArucoTarget")
    if distortion not in (2, 4, 5):
        raise ParameterError(f"distortion must be 2, 4 or 5 coefficients, got {distortion!r}")
    obj, pix, size = [], [], None
    for image in images:
        img = image.image if isinstance(image, Frame) else np.asarray(image)
        if size is not None and img.shape[:2] != size:
            raise ParameterError(f"all images must have one size: {img.shape[:2]} after {size}")
        size = img.shape[:2]
        try:
            o, p, _ = _aruco_points(img, target, refine)
        except DataError as err:
            log.info("a calibration view was left out: %s", err)
            continue
        obj.append(o.astype(np.float32))
        pix.append(p.astype(np.float32).reshape(-1, 1, 2))
    if len(obj) < 3:
        raise DataError(f"the target was found in {len(obj)} views; calibrating the intrinsics needs at least 3, "
                        "with the target tilted differently in each")
    flags = {2: cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3, 4: cv2.CALIB_FIX_K3, 5: 0}[distortion]
    H, W = size
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, pix, (W, H), None, None, flags=flags)
    log.info("intrinsics calibrated from %d views, reprojection error %.3f px", len(obj), rms)
    return CameraModel(K, W, H, dist=np.asarray(dist, dtype=float).ravel()[:5], rms=float(rms))


def calibrate_world(image, camera, target, *, refine="edges"):
    r"""Pose of the camera in the world, :math:`T_{wc}`, from an ArUco ``target`` seen in ``image``.

    The markers are detected with ``cv2.aruco.ArucoDetector``, their corners refined to sub-pixel accuracy
    (``refine="edges"``: each side's edge is located to sub-pixel precision at points along it, a line is fitted
    through them and the corners are the lines' intersections; ``"subpix"``: ``cv2.cornerSubPix``, which was
    measured biased 0.1-0.2 px towards the inside of the marker's convex corners on anti-aliased renders),
    matched to their world corners by id, and the pose solved by ``cv2.solvePnP``
    (``SOLVEPNP_IPPE_SQUARE`` for one marker, ``SOLVEPNP_IPPE`` for several) then refined by Levenberg-Marquardt
    (``solvePnPRefineLM``). With :math:`T_{ct}` the target's pose in the camera,
    :math:`T_{wc} = T_{wt}\,T_{ct}^{-1}`.

    Parameters
    ----------
    image : (H, W, 3) BGR or (H, W) grey uint8, or a Frame.
    camera : CameraModel
        Intrinsics (and distortion) of the camera; its pose is ignored.
    target : ArucoTarget
    refine : "edges" (default), "subpix" or None

    Returns
    -------
    CameraModel
        ``camera`` with ``pose`` :math:`T_{wc}` and ``rms`` the reprojection error [px].

    Raises DataError when no marker of the target is visible.
    """
    cv2 = require_cv2()
    if not isinstance(camera, CameraModel):
        raise ParameterError("camera must be a CameraModel with the camera's intrinsics")
    if not isinstance(target, ArucoTarget):
        raise ParameterError("target must be an ArucoTarget")
    if refine not in ("edges", "subpix", None):
        raise ParameterError("refine must be 'edges', 'subpix' or None")
    obj, pix, used = _aruco_points(image, target, refine)
    dist = np.zeros(5) if camera.dist is None else camera.dist
    if len(used) == 1:
        h = target.size / 2
        sq = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
        ok, rvec, tvec = cv2.solvePnP(sq, pix, camera.K, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        tvec = tvec - cv2.Rodrigues(rvec)[0] @ (obj[0] - sq[0]).reshape(3, 1)   # square frame -> sheet frame
    else:
        ok, rvec, tvec = cv2.solvePnP(obj, pix, camera.K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise DataError("solvePnP failed on the ArUco corners")
    rvec, tvec = cv2.solvePnPRefineLM(obj, pix, camera.K, dist, rvec, tvec,
                                      (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12))
    proj = cv2.projectPoints(obj, rvec, tvec, camera.K, dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((proj - pix) ** 2, axis=1))))
    T_ct = np.eye(4)
    T_ct[:3, :3] = cv2.Rodrigues(rvec)[0]
    T_ct[:3, 3] = tvec.ravel()
    T_wc = target.pose @ np.linalg.inv(T_ct)
    log.info("world calibrated from ArUco markers %s, reprojection error %.3f px", used, rms)
    return camera.with_pose(T_wc, rms)
