"""Scalar numba helpers called by fused kernels (imported only when a tree is compiled).

Each function mirrors the vectorized numpy implementation of the same primitive (the tests compare them).
"""
import math

from .._numba import njit

__all__ = ["_ellipse", "_polygon", "_polyline", "_cone"]

_jit = njit(cache=True, fastmath=False, error_model="numpy")


@_jit
def _ellipse(x, y, a, b):
    """Signed distance to the ellipse (x/a)^2 + (y/b)^2 = 1 (Eberly's robust bisection)."""
    inside = (x / a) ** 2 + (y / b) ** 2 < 1.0
    if a >= b:
        e0, e1, y0, y1 = a, b, abs(x), abs(y)
    else:
        e0, e1, y0, y1 = b, a, abs(y), abs(x)
    if y1 == 0.0:
        num = e0 * y0
        den = e0 * e0 - e1 * e1
        if num < den:
            xde = num / den
            x0 = e0 * xde
            x1 = e1 * math.sqrt(max(1.0 - xde * xde, 0.0))
            d = math.sqrt((x0 - y0) ** 2 + x1 * x1)
        else:
            d = abs(y0 - e0)
    elif y0 == 0.0:
        d = abs(y1 - e1)
    else:
        z0, z1 = y0 / e0, y1 / e1
        g = z0 * z0 + z1 * z1 - 1.0
        r0 = (e0 / e1) ** 2
        n0 = r0 * z0
        s0 = z1 - 1.0
        s1 = 0.0 if g < 0 else math.sqrt(n0 * n0 + z1 * z1) - 1.0
        s = 0.5 * (s0 + s1)
        for _ in range(200):
            s = 0.5 * (s0 + s1)
            if s == s0 or s == s1:
                break
            f = (n0 / (s + r0)) ** 2 + (z1 / (s + 1.0)) ** 2 - 1.0
            if f > 0:
                s0 = s
            elif f < 0:
                s1 = s
            else:
                break
        x0 = r0 * y0 / (s + r0)
        x1 = y1 / (s + 1.0)
        d = math.sqrt((x0 - y0) ** 2 + (x1 - y1) ** 2)
    return -d if inside else d


@_jit
def _polygon(x, y, c, start, n):
    """Signed distance to the polygon with vertices c[start:start + 2n] (x0, y0, x1, y1, ...)."""
    best = 1e300
    inside = False
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        ax, ay = c[start + 2 * i], c[start + 2 * i + 1]
        bx, by = c[start + 2 * j], c[start + 2 * j + 1]
        ex, ey = bx - ax, by - ay
        wx, wy = x - ax, y - ay
        t = min(max((wx * ex + wy * ey) / (ex * ex + ey * ey), 0.0), 1.0)
        dx, dy = wx - t * ex, wy - t * ey
        best = min(best, dx * dx + dy * dy)
        if ay != by and ((ay <= y) != (by <= y)):
            if x < ax + (y - ay) * ex / ey:
                inside = not inside
    d = math.sqrt(best)
    return -d if inside else d


@_jit
def _polyline(x, y, c, start, n):
    """Unsigned distance to the open polyline with vertices c[start:start + 2n]."""
    best = 1e300
    for i in range(n - 1):
        ax, ay = c[start + 2 * i], c[start + 2 * i + 1]
        bx, by = c[start + 2 * i + 2], c[start + 2 * i + 3]
        ex, ey = bx - ax, by - ay
        wx, wy = x - ax, y - ay
        t = min(max((wx * ex + wy * ey) / (ex * ex + ey * ey), 0.0), 1.0)
        dx, dy = wx - t * ex, wy - t * ey
        best = min(best, dx * dx + dy * dy)
    return math.sqrt(best)


@_jit
def _cone(rho, z, r1, r2, hh):
    """Exact distance to a capped cone in the meridian plane (radius r1 at z = -hh, r2 at z = hh)."""
    k2x, k2y = r2 - r1, 2.0 * hh
    cax = rho - min(rho, r1 if z < 0 else r2)
    cay = abs(z) - hh
    t = min(max(((r2 - rho) * k2x + (hh - z) * k2y) / (k2x * k2x + k2y * k2y), 0.0), 1.0)
    cbx = rho - r2 + k2x * t
    cby = z - hh + k2y * t
    s = -1.0 if (cbx < 0 and cay < 0) else 1.0
    return s * math.sqrt(min(cax * cax + cay * cay, cbx * cbx + cby * cby))
