"""3D primitives and the 2D -> 3D operators (extrude, revolve); lengths in metres."""
import math

import numpy as np

from ..errors import GeometryError
from .core import (SDF, _cylinder_aabb, _perpendicular, _positive, _unit, _vec, register_operation,
                   register_primitives)
from .primitives2d import _box_eval, _box_grad, _emit_box, _emit_capsule, _radial_grad, _segments_closest

__all__ = ["Sphere", "Box", "Cylinder", "Capsule", "Torus", "Cone", "Plane", "Extrude", "Revolve",
           "PRIMITIVE_OPS_3D"]

#: ``op`` names of the 3D primitives.
PRIMITIVE_OPS_3D = register_primitives({"sphere", "box", "cylinder", "capsule", "torus", "cone", "plane"})

_Z = (0.0, 0.0, 1.0)


def _axial(p, center, axis):
    """Axial coordinate z = (p - c) . a and radial distance rho = |(p - c) - z a| of points p (N, 3)."""
    r = p - center
    z = r @ axis
    rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", r, r) - z * z, 0.0))
    return r, z, rho


def _radial_dir(r, z, rho, axis):
    """Unit radial directions (N, 3), an arbitrary perpendicular on the axis itself."""
    e = r - np.outer(z, axis)
    on = rho <= 1e-300
    out = np.empty_like(r)
    out[~on] = e[~on] / rho[~on, None]
    if np.any(on):
        out[on] = _perpendicular(np.broadcast_to(axis, (int(on.sum()), 3)).copy())
    return out


def _emit_axial(g, xs, center, axis):
    rs = [g.var(f"{x} - {g.const(center[i])}") for i, x in enumerate(xs)]
    z = g.var(" + ".join(f"{r} * {g.const(axis[i])}" for i, r in enumerate(rs)))
    rho = g.var(f"math.sqrt(max({' + '.join(f'{r} * {r}' for r in rs)} - {z} * {z}, 0.0))")
    return z, rho


class Sphere(SDF):
    """Ball of ``radius`` r [m] centred at ``center`` [m]: d = |p - c| - r.

    ``params``: ``{"radius": r, "center": (x, y, z)}``.
    """

    op = "sphere"

    def __init__(self, radius, center=(0.0, 0.0, 0.0)):
        super().__init__(3, {"radius": _positive(radius, "radius"), "center": _vec(center, 3, "center")})

    def _eval(self, p):
        return np.linalg.norm(p - self._params["center"], axis=1) - self._params["radius"]

    def _grad(self, p, h):
        return self._eval(p), _radial_grad(p, self._params["center"])

    def _bounds(self):
        c, r = self._params["center"], self._params["radius"]
        return c - r, c + r

    def _emit(self, g, xs):
        c = self._params["center"]
        ds = [g.var(f"{x} - {g.const(c[i])}") for i, x in enumerate(xs)]
        return g.var(f"math.sqrt({' + '.join(f'{d} * {d}' for d in ds)}) - {g.const(self._params['radius'])}")

    def _moments(self):
        c, r = self._params["center"], self._params["radius"]
        V = 4 / 3 * math.pi * r**3
        return V, V * c, V * np.outer(c, c) + 4 * math.pi * r**5 / 15 * np.eye(3)


class Box(SDF):
    """Axis-aligned box of ``size`` (a, b, c) [m] (or a cube of edge ``size``) centred at ``center``.

    Exact distance d = |max(q, 0)| + min(max_i q_i, 0), q = |p - c| - size/2.
    ``params``: ``{"size": (a, b, c), "center": (x, y, z)}``.
    """

    op = "box"

    def __init__(self, size, center=(0.0, 0.0, 0.0)):
        s = np.broadcast_to(np.asarray(size, dtype=float), (3,)).copy() if np.ndim(size) == 0 else \
            np.array(_vec(size, 3, "size"))
        for i, v in enumerate(s):
            _positive(v, f"size[{i}]")
        s.setflags(write=False)
        super().__init__(3, {"size": s, "center": _vec(center, 3, "center")})

    def _eval(self, p):
        return _box_eval(p, self._params["center"], self._params["size"] / 2)

    def _grad(self, p, h):
        return _box_grad(p, self._params["center"], self._params["size"] / 2)

    def _bounds(self):
        c, s = self._params["center"], self._params["size"]
        return c - s / 2, c + s / 2

    def _emit(self, g, xs):
        return _emit_box(g, xs, self._params["center"], self._params["size"] / 2)

    def _moments(self):
        c, (a, b, cc) = self._params["center"], self._params["size"]
        V = a * b * cc
        return V, V * c, V * np.outer(c, c) + V / 12 * np.diag([a * a, b * b, cc * cc])


class Cylinder(SDF):
    """Solid cylinder of ``radius`` and ``height`` [m] centred at ``center`` with unit ``axis`` (default z).

    Exact: with z = (p - c).a and rho the distance to the axis, q = (rho - r, |z| - h/2),
    d = |max(q, 0)| + min(max(q), 0). ``params``: ``{"radius", "height", "center", "axis"}``.
    """

    op = "cylinder"

    def __init__(self, radius, height, center=(0.0, 0.0, 0.0), axis=_Z):
        super().__init__(3, {"radius": _positive(radius, "radius"), "height": _positive(height, "height"),
                             "center": _vec(center, 3, "center"), "axis": _unit(axis, 3, "axis")})

    def _q(self, p):
        r, z, rho = _axial(p, self._params["center"], self._params["axis"])
        return r, z, rho, np.stack([rho, z], axis=1)

    def _half(self):
        return np.array([self._params["radius"], self._params["height"] / 2])

    def _eval(self, p):
        return _box_eval(self._q(p)[3], 0.0, self._half())

    def _grad(self, p, h):
        r, z, rho, q = self._q(p)
        d, g2 = _box_grad(q, 0.0, self._half())
        a = self._params["axis"]
        return d, g2[:, :1] * _radial_dir(r, z, rho, a) + g2[:, 1:] * a

    def _bounds(self):
        c, a, hh = self._params["center"], self._params["axis"], self._params["height"] / 2
        lo, hi = _cylinder_aabb(a, -hh, hh, self._params["radius"])
        return lo + c, hi + c

    def _emit(self, g, xs):
        z, rho = _emit_axial(g, xs, self._params["center"], self._params["axis"])
        return _emit_box(g, [rho, z], (0.0, 0.0), self._half())

    def _moments(self):
        r, h, c, a = (self._params[k] for k in ("radius", "height", "center", "axis"))
        V = math.pi * r**2 * h
        aa = np.outer(a, a)
        m2 = math.pi * r**4 * h / 4 * (np.eye(3) - aa) + math.pi * r**2 * h**3 / 12 * aa
        return V, V * c, V * np.outer(c, c) + m2


class Capsule(SDF):
    """Capsule (sphere-swept segment) of ``radius`` [m] between ``start`` and ``end`` [m]:
    d = dist(p, [a, b]) - r. ``params``: ``{"start", "end", "radius"}``."""

    op = "capsule"

    def __init__(self, start, end, radius):
        a, b = _vec(start, 3, "start"), _vec(end, 3, "end")
        if np.allclose(a, b):
            raise GeometryError("capsule start and end coincide; use a Sphere or give two distinct points")
        super().__init__(3, {"start": a, "end": b, "radius": _positive(radius, "radius")})

    def _eval(self, p):
        d2, _ = _segments_closest(p, [self._params["start"]], [self._params["end"]])
        return np.sqrt(d2) - self._params["radius"]

    def _grad(self, p, h):
        d2, cp = _segments_closest(p, [self._params["start"]], [self._params["end"]])
        return np.sqrt(d2) - self._params["radius"], _radial_grad(p, cp)

    def _bounds(self):
        a, b, r = self._params["start"], self._params["end"], self._params["radius"]
        return np.minimum(a, b) - r, np.maximum(a, b) + r

    def _emit(self, g, xs):
        return _emit_capsule(g, xs, self._params["start"], self._params["end"], self._params["radius"])


class Torus(SDF):
    """Torus with ``major_radius`` R (axis to tube centre) and ``minor_radius`` r [m] about ``axis``
    through ``center``: d = |(rho - R, z)| - r. ``params``: ``{"major_radius", "minor_radius", "center",
    "axis"}``."""

    op = "torus"

    def __init__(self, major_radius, minor_radius, center=(0.0, 0.0, 0.0), axis=_Z):
        R, r = _positive(major_radius, "major_radius"), _positive(minor_radius, "minor_radius")
        super().__init__(3, {"major_radius": R, "minor_radius": r, "center": _vec(center, 3, "center"),
                             "axis": _unit(axis, 3, "axis")})

    def _eval(self, p):
        _, z, rho = _axial(p, self._params["center"], self._params["axis"])
        return np.hypot(rho - self._params["major_radius"], z) - self._params["minor_radius"]

    def _grad(self, p, h):
        r, z, rho = _axial(p, self._params["center"], self._params["axis"])
        u = rho - self._params["major_radius"]
        n = np.hypot(u, z)
        a = self._params["axis"]
        safe = np.where(n > 0, n, 1.0)
        gu, gz = np.where(n > 0, u / safe, 1.0), np.where(n > 0, z / safe, 0.0)
        return n - self._params["minor_radius"], gu[:, None] * _radial_dir(r, z, rho, a) + gz[:, None] * a

    def _bounds(self):
        c, a = self._params["center"], self._params["axis"]
        r = self._params["minor_radius"]
        lo, hi = _cylinder_aabb(a, -r, r, self._params["major_radius"] + r)
        return lo + c, hi + c

    def _emit(self, g, xs):
        z, rho = _emit_axial(g, xs, self._params["center"], self._params["axis"])
        u = g.var(f"{rho} - {g.const(self._params['major_radius'])}")
        return g.var(f"math.sqrt({u} * {u} + {z} * {z}) - {g.const(self._params['minor_radius'])}")

    def _moments(self):
        R, r, c, a = (self._params[k] for k in ("major_radius", "minor_radius", "center", "axis"))
        V = 2 * math.pi**2 * R * r**2
        i_axial = V * r**2 / 4                      # int z^2 dV
        i_rad = V * (R**2 + 3 * r**2 / 4) / 2       # int x^2 dV (= int y^2) for axis z
        aa = np.outer(a, a)
        return V, V * c, V * np.outer(c, c) + i_rad * (np.eye(3) - aa) + i_axial * aa


def _cone_distance(rho, z, r1, r2, hh):
    """Exact distance to a capped cone (frustum) in the meridian plane: radius r1 at z = -hh, r2 at z = hh."""
    qx, qy = rho, z
    k1x, k1y = r2, hh
    k2x, k2y = r2 - r1, 2 * hh
    cax = qx - np.minimum(qx, np.where(qy < 0, r1, r2))
    cay = np.abs(qy) - hh
    t = np.clip(((k1x - qx) * k2x + (k1y - qy) * k2y) / (k2x * k2x + k2y * k2y), 0.0, 1.0)
    cbx = qx - k1x + k2x * t
    cby = qy - k1y + k2y * t
    s = np.where((cbx < 0) & (cay < 0), -1.0, 1.0)
    return s * np.sqrt(np.minimum(cax * cax + cay * cay, cbx * cbx + cby * cby))


class Cone(SDF):
    """Cone (or frustum) with base ``radius`` at ``center`` [m], ``height`` along ``axis`` and
    ``top_radius`` (default 0, a sharp apex) — exact distance (capped-cone formula in the meridian plane).

    ``params``: ``{"radius", "height", "top_radius", "center", "axis"}`` (``center`` is the base centre).
    """

    op = "cone"

    def __init__(self, radius, height, center=(0.0, 0.0, 0.0), top_radius=0.0, axis=_Z):
        r2 = float(top_radius)
        if not (math.isfinite(r2) and r2 >= 0):
            raise GeometryError(f"top_radius must be >= 0 [m], got {top_radius!r}")
        super().__init__(3, {"radius": _positive(radius, "radius"), "height": _positive(height, "height"),
                             "top_radius": r2, "center": _vec(center, 3, "center"),
                             "axis": _unit(axis, 3, "axis")})

    def _eval(self, p):
        hh = self._params["height"] / 2
        _, z, rho = _axial(p, self._params["center"], self._params["axis"])
        return _cone_distance(rho, z - hh, self._params["radius"], self._params["top_radius"], hh)

    def _bounds(self):
        c, a, h = self._params["center"], self._params["axis"], self._params["height"]
        lo, hi = _cylinder_aabb(a, 0.0, h, max(self._params["radius"], self._params["top_radius"]))
        return lo + c, hi + c

    def _emit(self, g, xs):
        z, rho = _emit_axial(g, xs, self._params["center"], self._params["axis"])
        hh = g.const(self._params["height"] / 2)
        return g.var(f"_cone({rho}, {z} - {hh}, {g.const(self._params['radius'])}, "
                     f"{g.const(self._params['top_radius'])}, {hh})")


class Plane(SDF):
    """Half-space bounded by the plane through ``point`` [m] with unit ``normal``; the solid lies opposite
    the normal: d = (p - point) . n. Default: the floor z <= 0. ``params``: ``{"point", "normal"}``."""

    op = "plane"

    def __init__(self, point=(0.0, 0.0, 0.0), normal=_Z):
        super().__init__(3, {"point": _vec(point, 3, "point"), "normal": _unit(normal, 3, "normal")})

    def _eval(self, p):
        return (p - self._params["point"]) @ self._params["normal"]

    def _grad(self, p, h):
        return self._eval(p), np.broadcast_to(self._params["normal"], p.shape).copy()

    def _bounds(self):
        inf = np.full(3, np.inf)
        lo, hi = -inf.copy(), inf.copy()
        n = self._params["normal"]
        for i in range(3):
            if np.allclose(np.delete(n, i), 0):
                (hi if n[i] > 0 else lo)[i] = self._params["point"][i]
        return lo, hi

    def _emit(self, g, xs):
        pt, n = self._params["point"], self._params["normal"]
        return g.var(" + ".join(f"({x} - {g.const(pt[i])}) * {g.const(n[i])}" for i, x in enumerate(xs)))


# ====================================================================== 2D -> 3D
@register_operation("extrude")
class Extrude(SDF):
    """Prism: the 2D region extruded along z over [-height/2, height/2] (exact for an exact profile).

    With w = (d2(x, y), |z| - h/2): d = min(max(w), 0) + |max(w, 0)|. ``params``: ``{"height": h}``.
    """

    op = "extrude"

    def __init__(self, child, height):
        if child.dim != 2:
            raise GeometryError(f"extrude needs a 2D shape, got a {child.dim}D one")
        super().__init__(3, {"height": _positive(height, "height")}, (child,))

    def _eval(self, p):
        wx = self.children[0]._eval(np.ascontiguousarray(p[:, :2]))
        wy = np.abs(p[:, 2]) - self._params["height"] / 2
        return np.minimum(np.maximum(wx, wy), 0.0) + np.hypot(np.maximum(wx, 0.0), np.maximum(wy, 0.0))

    def _grad(self, p, h):
        wx, g2 = self.children[0]._grad(np.ascontiguousarray(p[:, :2]), h)
        wy = np.abs(p[:, 2]) - self._params["height"] / 2
        sz = np.where(p[:, 2] >= 0, 1.0, -1.0)
        mx, my = np.maximum(wx, 0.0), np.maximum(wy, 0.0)
        n = np.hypot(mx, my)
        d = np.minimum(np.maximum(wx, wy), 0.0) + n
        out = n > 0
        safe = np.where(out, n, 1.0)
        ax = np.where(out, mx / safe, (wx >= wy).astype(float))
        az = np.where(out, my / safe, (wx < wy).astype(float))
        g = np.column_stack([ax[:, None] * g2, az * sz])
        return d, g

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        hh = self._params["height"] / 2
        return np.append(lo, -hh), np.append(hi, hh)

    def _emit(self, g, xs):
        wx = self.children[0]._emit(g, xs[:2])
        wy = g.var(f"abs({xs[2]}) - {g.const(self._params['height'] / 2)}")
        mx, my = g.var(f"max({wx}, 0.0)"), g.var(f"max({wy}, 0.0)")
        return g.var(f"min(max({wx}, {wy}), 0.0) + math.sqrt({mx} * {mx} + {my} * {my})")

    def _moments(self):
        m = self.children[0]._moments()
        if m is None:
            return None
        A, S, M = m
        h = self._params["height"]
        m2 = np.zeros((3, 3))
        m2[:2, :2] = M * h
        m2[2, 2] = A * h**3 / 12
        return A * h, np.append(S * h, 0.0), m2


@register_operation("revolve")
class Revolve(SDF):
    """Solid of revolution of a 2D profile about ``axis`` through the origin.

    The profile's (u, v) are (rho - ``offset``, z) with z = p . a the axial coordinate and rho the distance
    to the axis: d(p) = d2(rho - offset, z). Exact when the profile lies in u >= -offset or is symmetric
    about u = -offset. ``params``: ``{"axis": (3,), "offset": float}``.
    """

    op = "revolve"

    def __init__(self, child, axis=_Z, offset=0.0):
        if child.dim != 2:
            raise GeometryError(f"revolve needs a 2D profile, got a {child.dim}D shape")
        off = float(offset)
        if not math.isfinite(off):
            raise GeometryError(f"revolve offset must be finite [m], got {offset!r}")
        super().__init__(3, {"axis": _unit(axis, 3, "axis"), "offset": off}, (child,))

    def _uv(self, p):
        r, z, rho = _axial(p, 0.0, self._params["axis"])
        return r, z, rho, np.column_stack([rho - self._params["offset"], z])

    def _eval(self, p):
        return self.children[0]._eval(self._uv(p)[3])

    def _grad(self, p, h):
        r, z, rho, uv = self._uv(p)
        d, g2 = self.children[0]._grad(uv, h)
        a = self._params["axis"]
        return d, g2[:, :1] * _radial_dir(r, z, rho, a) + g2[:, 1:] * a

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        R = hi[0] + self._params["offset"]
        if not np.all(np.isfinite([R, lo[1], hi[1]])):
            inf = np.full(3, np.inf)
            return -inf, inf
        return _cylinder_aabb(self._params["axis"], lo[1], hi[1], max(R, 0.0))

    def _emit(self, g, xs):
        z, rho = _emit_axial(g, xs, (0.0, 0.0, 0.0), self._params["axis"])
        u = g.var(f"{rho} - {g.const(self._params['offset'])}")
        return self.children[0]._emit(g, [u, z])
