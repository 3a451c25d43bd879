"""2D primitives: exact signed distances of planar regions in the (x, y) plane, lengths in metres."""
import math

import numpy as np

from ..errors import GeometryError
from .core import SDF, _positive, _unit, _vec, register_primitives

__all__ = ["Circle", "Rectangle", "RoundedRectangle", "Squircle", "Ellipse", "Polygon", "Polyline",
           "Segment", "Strut", "Line", "PRIMITIVE_OPS_2D"]

#: ``op`` names of the 2D primitives.
PRIMITIVE_OPS_2D = register_primitives({"circle", "rectangle", "rounded_rectangle", "ellipse", "polygon",
                                        "polyline", "segment", "strut", "line"})


def _sgn(x):
    """sign with sign(0) = +1 (so gradients never vanish)."""
    return np.where(x >= 0, 1.0, -1.0)


def _box_eval(p, center, half):
    """Exact distance to an axis-aligned box: q = |p - c| - h, d = |max(q, 0)| + min(max_i q_i, 0)."""
    q = np.abs(p - center) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _box_grad(p, center, half):
    r = p - center
    q = np.abs(r) - half
    m = np.maximum(q, 0.0)
    nm = np.linalg.norm(m, axis=1)
    d = nm + np.minimum(q.max(axis=1), 0.0)
    s = _sgn(r)
    out = nm > 0
    g = np.zeros_like(p)
    g[out] = m[out] / nm[out, None] * s[out]
    inn = ~out
    ax = np.argmax(q[inn], axis=1)
    idx = np.flatnonzero(inn)
    g[idx, ax] = s[idx, ax]
    return d, g


def _emit_box(g, xs, center, half, radius=0.0):
    qs = [g.var(f"abs({x} - {g.const(center[i])}) - {g.const(half[i])}") for i, x in enumerate(xs)]
    ms = [g.var(f"max({q}, 0.0)") for q in qs]
    qmax = qs[0]
    for q in qs[1:]:
        qmax = f"max({qmax}, {q})"
    norm = " + ".join(f"{m} * {m}" for m in ms)
    tail = f" - {g.const(radius)}" if radius else ""
    return g.var(f"math.sqrt({norm}) + min({qmax}, 0.0){tail}")


def _segments_closest(p, A, B):
    """Squared distance from points p (N, d) to the nearest of segments A[k]B[k], and that nearest point."""
    best = np.full(len(p), np.inf)
    cp = np.zeros_like(p)
    for a, b in zip(A, B):
        e = b - a
        w = p - a
        ee = float(e @ e)
        t = np.clip((w @ e) / ee, 0.0, 1.0) if ee > 0 else np.zeros(len(p))
        c = a + t[:, None] * e
        d2 = np.einsum("ij,ij->i", p - c, p - c)
        better = d2 < best
        best = np.where(better, d2, best)
        cp[better] = c[better]
    return best, cp


def _radial_grad(p, c, sign=1.0):
    """Unit vectors (p - c)/|p - c| times sign; (1, 0, ..) where p == c."""
    r = p - c
    n = np.linalg.norm(r, axis=1, keepdims=True)
    e = np.zeros_like(p)
    e[:, 0] = 1.0
    return np.where(n > 0, r / np.where(n > 0, n, 1.0), e) * np.reshape(sign, (-1, 1))


# ====================================================================== primitives
class Circle(SDF):
    """Disc of ``radius`` r [m] centred at ``center`` [m]: d = |p - c| - r.

    ``params``: ``{"radius": r, "center": (x, y)}``.
    """

    op = "circle"

    def __init__(self, radius, center=(0.0, 0.0)):
        super().__init__(2, {"radius": _positive(radius, "radius"), "center": _vec(center, 2, "center")})

    def _eval(self, p):
        return np.linalg.norm(p - self._params["center"], axis=1) - self._params["radius"]

    def _grad(self, p, h):
        return self._eval(p), _radial_grad(p, self._params["center"])

    def _bounds(self):
        c, r = self._params["center"], self._params["radius"]
        return c - r, c + r

    def _emit(self, g, xs):
        c, r = self._params["center"], self._params["radius"]
        dx = g.var(f"{xs[0]} - {g.const(c[0])}")
        dy = g.var(f"{xs[1]} - {g.const(c[1])}")
        return g.var(f"math.sqrt({dx} * {dx} + {dy} * {dy}) - {g.const(r)}")

    def _moments(self):
        c, r = self._params["center"], self._params["radius"]
        A = math.pi * r**2
        return A, A * c, A * np.outer(c, c) + math.pi * r**4 / 4 * np.eye(2)


class Rectangle(SDF):
    """Axis-aligned rectangle ``width`` x ``height`` [m] centred at ``center`` [m] (exact distance).

    d = |max(q, 0)| + min(max(q_x, q_y), 0), q = |p - c| - (w/2, h/2).
    ``params``: ``{"width": w, "height": h, "center": (x, y)}``.
    """

    op = "rectangle"

    def __init__(self, width, height=None, center=(0.0, 0.0)):
        height = width if height is None else height
        super().__init__(2, {"width": _positive(width, "width"), "height": _positive(height, "height"),
                             "center": _vec(center, 2, "center")})

    def _half(self):
        return np.array([self._params["width"], self._params["height"]]) / 2

    def _eval(self, p):
        return _box_eval(p, self._params["center"], self._half())

    def _grad(self, p, h):
        return _box_grad(p, self._params["center"], self._half())

    def _bounds(self):
        c = self._params["center"]
        return c - self._half(), c + self._half()

    def _emit(self, g, xs):
        return _emit_box(g, xs, self._params["center"], self._half())

    def _moments(self):
        w, hgt, c = self._params["width"], self._params["height"], self._params["center"]
        A = w * hgt
        return A, A * c, A * np.outer(c, c) + np.diag([w**3 * hgt / 12, w * hgt**3 / 12])


class RoundedRectangle(SDF):
    """Rectangle ``width`` x ``height`` [m] with corners rounded by ``radius`` [m] (exact distance).

    d = box(p; w/2 - r, h/2 - r) - r. Default radius: a quarter of the smaller side ("squircle" look).
    ``params``: ``{"width", "height", "radius", "center"}``.
    """

    op = "rounded_rectangle"

    def __init__(self, width, height=None, radius=None, center=(0.0, 0.0)):
        height = width if height is None else height
        w, hgt = _positive(width, "width"), _positive(height, "height")
        r = min(w, hgt) / 4 if radius is None else _positive(radius, "radius")
        if r > min(w, hgt) / 2 * (1 + 1e-12):
            raise GeometryError(f"corner radius {r} m exceeds half the smaller side ({min(w, hgt) / 2} m); "
                                f"use radius <= min(width, height)/2")
        super().__init__(2, {"width": w, "height": hgt, "radius": r, "center": _vec(center, 2, "center")})

    def _inner(self):
        return np.array([self._params["width"], self._params["height"]]) / 2 - self._params["radius"]

    def _eval(self, p):
        return _box_eval(p, self._params["center"], self._inner()) - self._params["radius"]

    def _grad(self, p, h):
        d, g = _box_grad(p, self._params["center"], self._inner())
        return d - self._params["radius"], g

    def _bounds(self):
        c = self._params["center"]
        half = np.array([self._params["width"], self._params["height"]]) / 2
        return c - half, c + half

    def _emit(self, g, xs):
        return _emit_box(g, xs, self._params["center"], self._inner(), self._params["radius"])

    def _moments(self):
        w, hgt, r, c = (self._params[k] for k in ("width", "height", "radius", "center"))
        # rectangle minus four r x r corner squares plus four quarter discs (centroid 4r/(3 pi) from centre)
        a, b = w / 2 - r, hgt / 2 - r
        A = w * hgt - (4 - math.pi) * r**2
        ixx = w**3 * hgt / 12 - 4 * (r**4 / 12 + r**2 * (a + r / 2) ** 2)
        iyy = w * hgt**3 / 12 - 4 * (r**4 / 12 + r**2 * (b + r / 2) ** 2)
        # quarter disc about its own centre: second moment about the corner point is pi r^4/16
        qa = math.pi * r**2 / 4
        e = 4 * r / (3 * math.pi)
        i_c = math.pi * r**4 / 16 - qa * e**2          # about the quarter disc's centroid
        ixx += 4 * (i_c + qa * (a + e) ** 2)
        iyy += 4 * (i_c + qa * (b + e) ** 2)
        return A, A * c, A * np.outer(c, c) + np.diag([ixx, iyy])


#: Sorotoki's ``sSquircle``: a rounded rectangle (same class).
Squircle = RoundedRectangle


def _ellipse_distance(px, py, a, b, iters=80):
    """Unsigned distance from points to the ellipse x^2/a^2 + y^2/b^2 = 1 (Eberly's robust bisection).

    In the first quadrant with e0 >= e1, the closest point is x_i = r_i y_i / (s + r_i) (scaled), with s the
    root of F(s) = (r0 z0 / (s + r0))^2 + (z1 / (s + 1))^2 - 1, z = y/e, r0 = (e0/e1)^2, bracketed and
    bisected to machine precision.
    """
    swap = a < b
    e0, e1 = (b, a) if swap else (a, b)
    y0 = np.abs(py if swap else px)
    y1 = np.abs(px if swap else py)
    dist = np.empty_like(y0)
    # y1 == 0 (on the major axis)
    ax = y1 == 0
    num, den = e0 * y0[ax], e0**2 - e1**2
    inner = num < den
    xde = np.where(inner, num / np.where(den > 0, den, 1.0), 1.0)
    x0 = e0 * xde
    x1 = e1 * np.sqrt(np.clip(1 - xde**2, 0, None))
    dist[ax] = np.where(inner, np.hypot(x0 - y0[ax], x1), np.abs(y0[ax] - e0))
    # y0 == 0 (on the minor axis), y1 > 0
    mn = (y0 == 0) & ~ax
    dist[mn] = np.abs(y1[mn] - e1)
    gen = ~(ax | mn)
    yy0, yy1 = y0[gen], y1[gen]
    z0, z1 = yy0 / e0, yy1 / e1
    gval = z0**2 + z1**2 - 1
    r0 = (e0 / e1) ** 2
    n0 = r0 * z0
    s0 = z1 - 1
    s1 = np.where(gval < 0, 0.0, np.hypot(n0, z1) - 1)
    for _ in range(iters):
        s = 0.5 * (s0 + s1)
        f = (n0 / (s + r0)) ** 2 + (z1 / (s + 1)) ** 2 - 1
        pos = f > 0
        s0 = np.where(pos, s, s0)
        s1 = np.where(pos, s1, s)
    s = 0.5 * (s0 + s1)
    x0 = r0 * yy0 / (s + r0)
    x1 = yy1 / (s + 1)
    dist[gen] = np.hypot(x0 - yy0, x1 - yy1)
    return dist


class Ellipse(SDF):
    """Ellipse with semi-axes ``radius_x``, ``radius_y`` [m] centred at ``center`` (exact distance, computed
    by Eberly's robust root bracketing of the closest-point equation; accurate to machine precision).

    ``params``: ``{"radius_x": a, "radius_y": b, "center": (x, y)}``.
    """

    op = "ellipse"

    def __init__(self, radius_x, radius_y, center=(0.0, 0.0)):
        super().__init__(2, {"radius_x": _positive(radius_x, "radius_x"),
                             "radius_y": _positive(radius_y, "radius_y"), "center": _vec(center, 2, "center")})

    def _eval(self, p):
        a, b = self._params["radius_x"], self._params["radius_y"]
        q = p - self._params["center"]
        d = _ellipse_distance(q[:, 0], q[:, 1], a, b)
        inside = (q[:, 0] / a) ** 2 + (q[:, 1] / b) ** 2 < 1
        return np.where(inside, -d, d)

    def _bounds(self):
        c = self._params["center"]
        r = np.array([self._params["radius_x"], self._params["radius_y"]])
        return c - r, c + r

    def _emit(self, g, xs):
        c = self._params["center"]
        return g.var(f"_ellipse({xs[0]} - {g.const(c[0])}, {xs[1]} - {g.const(c[1])}, "
                     f"{g.const(self._params['radius_x'])}, {g.const(self._params['radius_y'])})")

    def _moments(self):
        a, b, c = self._params["radius_x"], self._params["radius_y"], self._params["center"]
        A = math.pi * a * b
        return A, A * c, A * np.outer(c, c) + np.diag([math.pi * a**3 * b / 4, math.pi * a * b**3 / 4])


def _check_simple(v):
    """Raise GeometryError if the closed polygon v (n, 2) has repeated vertices, folds or crossing edges."""
    n = len(v)
    e = np.roll(v, -1, axis=0) - v
    scale = float(np.abs(v).max() + np.abs(e).max())
    tol = 1e-12 * scale
    short = np.flatnonzero(np.linalg.norm(e, axis=1) <= tol)
    if short.size:
        raise GeometryError(f"polygon has a zero-length edge at vertex {short[0]} ({v[short[0]].tolist()}): "
                            "remove repeated vertices (do not repeat the first vertex at the end)")
    e_next = np.roll(e, -1, axis=0)
    cross = e[:, 0] * e_next[:, 1] - e[:, 1] * e_next[:, 0]  # z of e x e_next (np.cross of 2-vectors: deprecated)
    dot = np.einsum("ij,ij->i", e, e_next)
    fold = np.flatnonzero((np.abs(cross) <= tol * scale) & (dot < 0))
    if fold.size:
        raise GeometryError(f"polygon folds back on itself at vertex {(fold[0] + 1) % n}: "
                            "the boundary must be a simple closed curve")
    if n < 4:
        return
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # first and last edges are adjacent
    i, j = i[keep], j[keep]
    if i.size == 0:
        return
    a, b, c, d = v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    def on_seg(p, q, r):  # r within the bounding box of pq
        return np.all((np.minimum(p, q) - tol <= r) & (r <= np.maximum(p, q) + tol), axis=1)

    t2 = tol * scale
    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0) & (np.abs(o1) > t2) & (np.abs(o2) > t2) \
        & (np.abs(o3) > t2) & (np.abs(o4) > t2)
    touch = ((np.abs(o1) <= t2) & on_seg(a, b, c)) | ((np.abs(o2) <= t2) & on_seg(a, b, d)) \
        | ((np.abs(o3) <= t2) & on_seg(c, d, a)) | ((np.abs(o4) <= t2) & on_seg(c, d, b))
    bad = np.flatnonzero(proper | touch)
    if bad.size:
        k = bad[0]
        raise GeometryError(f"polygon is self-intersecting: edge {i[k]}->{(i[k] + 1) % n} meets edge "
                            f"{j[k]}->{(j[k] + 1) % n}; reorder the vertices into a simple (non-crossing) "
                            f"loop or split it into several polygons combined with |")


def _vertices(vertices, minimum, what):
    try:
        v = np.array(vertices, dtype=float)
    except (TypeError, ValueError) as e:
        raise GeometryError(f"{what} vertices must be an (n, 2) array of coordinates [m]") from e
    if v.ndim != 2 or v.shape[1] != 2:
        raise GeometryError(f"{what} vertices must be an (n, 2) array of coordinates [m], got shape {v.shape}")
    if len(v) < minimum:
        raise GeometryError(f"a {what} needs at least {minimum} vertices, got {len(v)}")
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{what} vertices must be finite")
    v.setflags(write=False)
    return v


class Polygon(SDF):
    """Simple polygon with ``vertices`` (n, 2) [m] in either orientation (exact distance).

    d = ± min_k dist(p, edge_k), negative where the even-odd crossing number is odd. Self-intersecting
    loops, folds, repeated vertices and fewer than 3 vertices raise :class:`GeometryError`.
    ``params``: ``{"vertices": (n, 2) array}``.
    """

    op = "polygon"

    def __init__(self, vertices):
        v = _vertices(vertices, 3, "polygon")
        if np.allclose(v[-1], v[0]) and len(v) > 3:
            v = v[:-1].copy()
            v.setflags(write=False)
        area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        sv = np.linalg.svd(v - v.mean(axis=0), compute_uv=False)
        if abs(area) <= 1e-14 * float(np.ptp(v, axis=0).max()) ** 2 and sv[1] <= 1e-12 * sv[0]:
            raise GeometryError("polygon has zero area (collinear vertices); give a non-degenerate outline")
        _check_simple(v)
        super().__init__(2, {"vertices": v})

    def _inside(self, p):
        v = self._params["vertices"]
        inside = np.zeros(len(p), dtype=bool)
        x, y = p[:, 0], p[:, 1]
        for a, b in zip(v, np.roll(v, -1, axis=0)):
            if a[1] == b[1]:
                continue
            crosses = (a[1] <= y) != (b[1] <= y)
            xint = a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            inside ^= crosses & (x < xint)
        return inside

    def _eval(self, p):
        v = self._params["vertices"]
        d2, _ = _segments_closest(p, v, np.roll(v, -1, axis=0))
        return np.where(self._inside(p), -1.0, 1.0) * np.sqrt(d2)

    def _grad(self, p, h):
        v = self._params["vertices"]
        d2, cp = _segments_closest(p, v, np.roll(v, -1, axis=0))
        s = np.where(self._inside(p), -1.0, 1.0)
        d = s * np.sqrt(d2)
        g = _radial_grad(p, cp, s)
        on = d2 == 0
        if np.any(on):
            g[on] = SDF._grad(self, p[on], h)[1]
        return d, g

    def _bounds(self):
        v = self._params["vertices"]
        return v.min(axis=0), v.max(axis=0)

    def _emit(self, g, xs):
        k = g.array(self._params["vertices"])
        return g.var(f"_polygon({xs[0]}, {xs[1]}, c, {k}, {len(self._params['vertices'])})")

    def _moments(self):
        v = self._params["vertices"]
        x, y = v[:, 0], v[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cr = x * yn - xn * y
        A = cr.sum() / 2
        m1 = np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / 6
        ixx = ((x**2 + x * xn + xn**2) * cr).sum() / 12
        iyy = ((y**2 + y * yn + yn**2) * cr).sum() / 12
        ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / 24
        s = 1.0 if A > 0 else -1.0
        return s * A, s * m1, s * np.array([[ixx, ixy], [ixy, iyy]])


class Polyline(SDF):
    """Open polyline through ``vertices`` (n >= 2, (n, 2) [m]) thickened to ``thickness`` [m] (round caps).

    d = min_k dist(p, segment_k) - thickness / 2. ``params``: ``{"vertices": (n, 2), "thickness": t}``.
    """

    op = "polyline"

    def __init__(self, vertices, thickness):
        v = _vertices(vertices, 2, "polyline")
        if np.any(np.linalg.norm(np.diff(v, axis=0), axis=1) == 0):
            raise GeometryError("polyline has repeated consecutive vertices; remove them")
        super().__init__(2, {"vertices": v, "thickness": _positive(thickness, "thickness")})

    def _ends(self):
        v = self._params["vertices"]
        return v[:-1], v[1:]

    def _eval(self, p):
        d2, _ = _segments_closest(p, *self._ends())
        return np.sqrt(d2) - self._params["thickness"] / 2

    def _grad(self, p, h):
        d2, cp = _segments_closest(p, *self._ends())
        return np.sqrt(d2) - self._params["thickness"] / 2, _radial_grad(p, cp)

    def _bounds(self):
        v, t = self._params["vertices"], self._params["thickness"] / 2
        return v.min(axis=0) - t, v.max(axis=0) + t

    def _emit(self, g, xs):
        k = g.array(self._params["vertices"])
        return g.var(f"_polyline({xs[0]}, {xs[1]}, c, {k}, {len(self._params['vertices'])}) "
                     f"- {g.const(self._params['thickness'] / 2)}")


class _Capsule2(SDF):
    _width_key = "thickness"

    def __init__(self, start, end, width):
        a, b = _vec(start, 2, "start"), _vec(end, 2, "end")
        if np.allclose(a, b):
            raise GeometryError(f"{self.op} start and end coincide ({a.tolist()}); give two distinct points [m]")
        super().__init__(2, {"start": a, "end": b, self._width_key: _positive(width, self._width_key)})

    def _r(self):
        return self._params[self._width_key] / 2

    def _eval(self, p):
        d2, _ = _segments_closest(p, [self._params["start"]], [self._params["end"]])
        return np.sqrt(d2) - self._r()

    def _grad(self, p, h):
        d2, cp = _segments_closest(p, [self._params["start"]], [self._params["end"]])
        return np.sqrt(d2) - self._r(), _radial_grad(p, cp)

    def _bounds(self):
        a, b = self._params["start"], self._params["end"]
        return np.minimum(a, b) - self._r(), np.maximum(a, b) + self._r()

    def _emit(self, g, xs):
        return _emit_capsule(g, xs, self._params["start"], self._params["end"], self._r())


def _emit_capsule(g, xs, a, b, r):
    e = b - a
    ee = float(e @ e)
    ws = [g.var(f"{x} - {g.const(a[i])}") for i, x in enumerate(xs)]
    dot = " + ".join(f"{w} * {g.const(e[i] / ee)}" for i, w in enumerate(ws))
    t = g.var(f"min(max({dot}, 0.0), 1.0)")
    rs = [g.var(f"{w} - {t} * {g.const(e[i])}") for i, w in enumerate(ws)]
    return g.var(f"math.sqrt({' + '.join(f'{q} * {q}' for q in rs)}) - {g.const(r)}")


class Segment(_Capsule2):
    """Straight segment from ``start`` to ``end`` [m] thickened to ``thickness`` [m] (a 2D capsule).

    d = dist(p, [a, b]) - thickness / 2. ``params``: ``{"start", "end", "thickness"}``.
    """

    op = "segment"


class Strut(_Capsule2):
    """Strut (Sorotoki ``sStrut``): a capsule of ``width`` [m] between the points ``start`` and ``end``.

    d = dist(p, [a, b]) - width / 2. ``params``: ``{"start", "end", "width"}``.
    """

    op = "strut"
    _width_key = "width"


class Line(SDF):
    """Half-plane bounded by the line through ``point`` [m] with unit ``normal``; the solid is on the side
    opposite to the normal: d = (p - point) . n. Default: the floor y <= 0. Unbounded (bounds are ±inf).

    ``params``: ``{"point": (x, y), "normal": (nx, ny)}``.
    """

    op = "line"

    def __init__(self, point=(0.0, 0.0), normal=(0.0, 1.0)):
        super().__init__(2, {"point": _vec(point, 2, "point"), "normal": _unit(normal, 2, "normal")})

    def _eval(self, p):
        return (p - self._params["point"]) @ self._params["normal"]

    def _grad(self, p, h):
        return self._eval(p), np.broadcast_to(self._params["normal"], p.shape).copy()

    def _bounds(self):
        inf = np.full(2, np.inf)
        n = self._params["normal"]
        lo, hi = -inf.copy(), inf.copy()
        for i in range(2):  # axis-aligned half-planes have one finite side
            if np.allclose(np.delete(n, i), 0):
                if n[i] > 0:
                    hi[i] = self._params["point"][i]
                else:
                    lo[i] = self._params["point"][i]
        return lo, hi

    def _emit(self, g, xs):
        pt, n = self._params["point"], self._params["normal"]
        return g.var(" + ".join(f"({x} - {g.const(pt[i])}) * {g.const(n[i])}" for i, x in enumerate(xs)))
