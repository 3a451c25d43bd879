"""Closed boundary curves of a 2D region: from a signed distance function or from a black-and-white image.

The zero level set is extracted with marching squares on a regular grid (``skimage.measure.find_contours``),
each vertex is snapped onto the true boundary with the shape's closest-point projection, and each closed curve
is resampled to the requested element size while keeping its corners (vertices where the polyline turns by
more than ``corner_angle``). Curves are then nested: a curve inside an even number of others is an outer
boundary, inside an odd number a hole of the smallest curve that contains it.

Only numpy and scikit-image are used here; gmsh is not imported.
"""
import logging
import math

import numpy as np

from ..errors import GeometryError, MeshError

__all__ = ["sdf_contours", "image_contours", "nest_loops", "polygon_area", "points_in_polygon"]

log = logging.getLogger(__name__)

#: Largest number of grid samples used to find the zero contour (memory and time guard).
MAX_GRID_POINTS = 4_000_000


def polygon_area(xy):
    """Signed area [m^2] of a closed polygon given by its (n, 2) vertices (shoelace formula; > 0 if CCW)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def points_in_polygon(points, xy):
    """Even-odd ray-crossing test: which of the (m, 2) ``points`` lie inside the closed polygon ``xy`` (n, 2)."""
    px, py = points[:, 0][:, None], points[:, 1][:, None]
    x0, y0 = xy[:, 0][None, :], xy[:, 1][None, :]
    x1, y1 = np.roll(xy[:, 0], -1)[None, :], np.roll(xy[:, 1], -1)[None, :]
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
    return np.count_nonzero(straddle & (px < xc), axis=1) % 2 == 1


def _snap(shape, pts):
    """Move ``pts`` onto the zero level of ``shape`` (closest-point projection, or Newton steps on the SDF)."""
    project = getattr(shape, "project", None)
    if project is not None:
        out = project(pts)
        out = out[0] if isinstance(out, tuple) else out
        out = np.asarray(out, dtype=float)
        if out.shape == pts.shape and np.all(np.isfinite(out)):
            return out
    x = pts.copy()
    for _ in range(3):
        d = np.asarray(shape(x), dtype=float)
        g = np.asarray(shape.gradient(x), dtype=float)
        g2 = np.maximum(np.einsum("ij,ij->i", g, g), 1e-30)
        x -= (d / g2)[:, None] * g
    return x


def _resample(xy, size, corner_angle, return_corners=False):
    """Resample a closed polyline to segments of length close to ``size``, keeping its corners."""
    n = len(xy)
    seg = np.roll(xy, -1, axis=0) - xy
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-14 * max(1.0, float(np.max(length)))
    xy, seg, length = xy[keep], seg[keep], length[keep]
    n = len(xy)
    total = float(length.sum())
    if n < 3 or total == 0.0:
        return (xy, np.zeros(0, dtype=int)) if return_corners else xy
    # turning angle at each vertex
    t_in = np.roll(seg, 1, axis=0) / np.roll(length, 1)[:, None]
    t_out = seg / length[:, None]
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", t_in, t_out), -1.0, 1.0))
    corners = np.flatnonzero(turn > corner_angle)
    # merge corners closer than size/2 along the curve, keeping the sharpest one
    s = np.concatenate([[0.0], np.cumsum(length)])  # arc length at vertex i is s[i]; s[n] = total
    if len(corners) > 1:
        kept = [corners[0]]
        for c in corners[1:]:
            if s[c] - s[kept[-1]] < 0.5 * size:
                if turn[c] > turn[kept[-1]]:
                    kept[-1] = c
            else:
                kept.append(c)
        if len(kept) > 1 and total - s[kept[-1]] + s[kept[0]] < 0.5 * size:
            if turn[kept[-1]] > turn[kept[0]]:
                kept[0] = kept[-1]
            kept.pop()
        corners = np.sort(np.asarray(kept))
    closed_xy = np.vstack([xy, xy[:1]])
    if len(corners) == 0:
        m = max(8, int(round(total / size)))
        targets = np.linspace(0.0, total, m, endpoint=False)
        out = np.column_stack([np.interp(targets, s, closed_xy[:, 0]), np.interp(targets, s, closed_xy[:, 1])])
        return (out, np.zeros(0, dtype=int)) if return_corners else out
    out, starts = [], []
    for k, c in enumerate(corners):
        a = s[c]
        b = s[corners[(k + 1) % len(corners)]] + (total if k + 1 == len(corners) else 0.0)
        m = max(1, int(round((b - a) / size)))
        targets = np.mod(a + (b - a) * np.arange(m) / m, total)
        starts.append(sum(len(o) for o in out))
        out.append(np.column_stack([np.interp(targets, s, closed_xy[:, 0]), np.interp(targets, s, closed_xy[:, 1])]))
    out = np.vstack(out)
    if len(out) < 3:
        m = max(8, int(round(total / size)))
        targets = np.linspace(0.0, total, m, endpoint=False)
        out = np.column_stack([np.interp(targets, s, closed_xy[:, 0]), np.interp(targets, s, closed_xy[:, 1])])
        starts = []
    if return_corners:
        return out, np.asarray(starts, dtype=int)
    return out


def _sharpen(shape, xy, corners, size):
    """Move each corner vertex to the intersection of the lines through its two neighbours on each side,
    when the signed distance there vanishes (|d| < 1e-3 size): recovers the sharp corners that marching squares
    cuts off."""
    n = len(xy)
    if n < 5 or len(corners) == 0:
        return xy
    xy = xy.copy()
    for i in corners:
        a0, a1 = xy[(i - 2) % n], xy[(i - 1) % n]
        b0, b1 = xy[(i + 2) % n], xy[(i + 1) % n]
        da, db = a1 - a0, b1 - b0
        den = da[0] * db[1] - da[1] * db[0]
        if abs(den) < 1e-12 * (np.dot(da, da) + np.dot(db, db)):
            continue
        t = ((b0[0] - a0[0]) * db[1] - (b0[1] - a0[1]) * db[0]) / den
        c = a0 + t * da
        if np.linalg.norm(c - xy[i]) < size and abs(float(shape(c[None, :])[0])) < 1e-3 * size:
            xy[i] = c
    return xy


def _grid_contours(values, lo, h):
    """Closed zero contours of a sampled field (index space → physical space)."""
    from skimage import measure

    curves = []
    for c in measure.find_contours(values, 0.0):
        if len(c) < 4:
            continue
        if not np.allclose(c[0], c[-1]):
            raise GeometryError("a boundary curve touches the edge of the sampling grid; the shape's bounds are not"
                                " conservative or the image foreground touches the image border (pad it)")
        curves.append(lo + c[:-1] * h)
    return curves


def sdf_contours(shape, size, resolution=None, corner_angle=math.radians(35.0)):
    """Closed boundary curves of a 2D signed distance function, resampled to ``size``.

    Parameters
    ----------
    shape : sdf shape
        2D signed distance function (negative inside) with ``bounds``.
    size : float
        Target segment length [m].
    resolution : float, optional
        Sampling step of the marching-squares grid [m]; default ``size / 4`` (limited to
        :data:`MAX_GRID_POINTS` samples).
    corner_angle : float
        Turning angle [rad] above which a vertex is kept as a corner.

    Returns
    -------
    list of (n, 2) arrays
        Closed curves (first vertex not repeated).
    """
    lo, hi = (np.asarray(b, dtype=float)[:2] for b in shape.bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise GeometryError(f"the shape's bounds {lo.tolist()}..{hi.tolist()} are empty or not finite: "
                            "the shape is empty (e.g. a difference that removes everything)")
    h = float(resolution) if resolution is not None else size / 4.0
    ext = hi - lo
    h = max(h, math.sqrt(float(np.prod(ext + 4 * h)) / MAX_GRID_POINTS))
    lo = lo - 2 * h
    n = np.ceil((ext + 4 * h) / h).astype(int) + 1
    xs = [lo[i] + h * np.arange(n[i]) for i in range(2)]
    X, Y = np.meshgrid(*xs, indexing="ij")
    values = np.asarray(shape(np.column_stack([X.ravel(), Y.ravel()])), dtype=float).reshape(X.shape)
    if not np.all(np.isfinite(values)):
        raise GeometryError("the shape returned non-finite distances inside its bounds")
    if values.min() >= 0.0:
        raise GeometryError(f"the shape has no interior inside its bounds {lo.tolist()}..{(lo + h * (n - 1)).tolist()}"
                            f" (sampled every {h:.3g} m): it is empty, or thinner than the sampling step; "
                            "check the boolean operations or pass a smaller size")
    border = np.concatenate([values[0], values[-1], values[:, 0], values[:, -1]])
    if border.min() < 0.0:
        raise GeometryError("the shape is negative on the edge of its bounding box: its `bounds` are not "
                            "conservative (or the shape is unbounded); intersect it with a finite shape")
    curves = _grid_contours(values, lo, h)
    out = []
    for c in curves:
        c = _snap(shape, c)
        c, corners = _resample(c, size, corner_angle, return_corners=True)
        c = _sharpen(shape, _snap(shape, c), corners, size)
        if abs(polygon_area(c)) > 0.0:
            out.append(c)
    if not out:
        raise GeometryError("no closed boundary curve was found on the zero level of the shape")
    return out


def load_image(path):
    """Read an image file into a 2D float array in [0, 1] (grey levels; alpha composited on white)."""
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"image file {str(path)!r} does not exist")
    try:
        from skimage import io as skio

        img = np.asarray(skio.imread(str(path)), dtype=float)
    except Exception as e:  # noqa: BLE001 - any decoder failure is the same user error
        raise MeshError(f"cannot read image {str(path)!r} ({type(e).__name__}: {e}); give a PNG or JPEG file") from e
    if img.ndim == 3:
        if img.shape[2] == 4:
            a = img[..., 3:4] / (255.0 if img.max() > 1.0 else 1.0)
            img = img[..., :3] * a + (255.0 if img.max() > 1.0 else 1.0) * (1 - a)
        img = img[..., :3].mean(axis=2)
    if img.ndim != 2 or img.size == 0:
        raise MeshError(f"image {str(path)!r} has shape {img.shape}, expected a 2D grey or RGB(A) image")
    return img / (255.0 if img.max() > 1.0 else 1.0)


def image_contours(image, pixel_size, threshold=0.5, invert=False, size=None):
    """Closed boundary curves [m] of the dark (or, with ``invert``, bright) part of a grey image in [0, 1].

    Pixel (row ``i``, column ``j``) has its centre at ``x = (j + 0.5) * pixel_size``,
    ``y = (rows - i - 0.5) * pixel_size`` (image up is +y; the origin is the lower-left corner).
    The contour is the ``threshold`` level of the grey field, which gives sub-pixel boundaries on
    anti-aliased images. Curves are resampled to ``size`` [m] (default: 2 pixels).
    """
    img = np.asarray(image, dtype=float)
    fg = img > threshold if invert else img < threshold
    if not fg.any():
        raise MeshError(f"the image has no foreground: no pixel is {'brighter' if invert else 'darker'} than "
                        f"threshold={threshold}; check the threshold or pass invert=True")
    if fg.all():
        raise MeshError("every pixel of the image is foreground: there is no boundary to mesh; check the threshold"
                        " or pass invert=True")
    # field negative inside, padded with background so every contour closes
    field = (threshold - img) if invert else (img - threshold)
    field = np.pad(field, 1, mode="constant", constant_values=abs(threshold) + 1.0)
    rows = field.shape[0]
    # (row, col) -> (x, y): x = (col - 1 + 0.5) p, y = (rows - 2 - row + 0.5) p in the unpadded frame
    from skimage import measure

    out = []
    for c in measure.find_contours(field, 0.0):
        if len(c) < 4:
            continue
        xy = np.column_stack([(c[:-1, 1] - 0.5) * pixel_size, (rows - 1.5 - c[:-1, 0]) * pixel_size])
        if abs(polygon_area(xy)) < 2.0 * pixel_size**2:
            continue  # single-pixel specks
        out.append(_resample(xy, size if size is not None else 2 * pixel_size, math.radians(60.0)))
    if not out:
        raise MeshError("the image foreground has no region larger than two pixels")
    return out


def nest_loops(curves):
    """Group closed curves into faces: ``[(outer, [holes...]), ...]``.

    A curve inside an even number of other curves is an outer boundary; inside an odd number, a hole of the
    smallest enclosing curve.
    """
    n = len(curves)
    areas = np.array([abs(polygon_area(c)) for c in curves])
    inside = np.zeros((n, n), dtype=bool)  # inside[i, j]: curve i lies inside curve j
    for j in range(n):
        probes = np.array([c[0] for c in curves])
        inside[:, j] = points_in_polygon(probes, curves[j])
        inside[j, j] = False
    depth = inside.sum(axis=1)
    faces = {i: [] for i in range(n) if depth[i] % 2 == 0}
    for i in range(n):
        if depth[i] % 2 == 1:
            parents = [j for j in range(n) if inside[i, j] and depth[j] == depth[i] - 1]
            parent = min(parents, key=lambda j: areas[j])
            faces[parent].append(i)
    return [(curves[i], [curves[k] for k in holes]) for i, holes in faces.items()]
