r"""One compiled interpreter of SDF programs (:mod:`sorofem.sdf.program`): distance and analytic gradient.

:func:`evaluate` runs a lowered tree (``ops``, ``consts``) on a batch of points with a value stack and a point
stack (see the program's docstring); the same compiled code serves every shape, so contact against any
supported SDF runs inside the compiled network (:mod:`soroshapes._contact`) without a compile per shape.
:func:`sdf_eval` is the friendly wrapper (shape in, (distance, gradient) out) the tests compare with
``shape(points)`` and ``shape.gradient(points)``.
"""
import math

import numpy as np

from sorofem._numba import njit
from sorofem.sdf.program import (BOX, CAPSULE, CYLINDER, DIFFERENCE, INTERSECTION, OFFSET, PLANE, POLYGON, POP,
                                 POP_EXTRUDE, PUSH_EXTRUDE, PUSH_LINEAR, PUSH_REVOLVE, PUSH_SCALE, PUSH_TRANSLATE,
                                 SHELL, SMOOTH_DIFFERENCE, SMOOTH_INTERSECTION, SMOOTH_UNION, SPHERE, UNION,
                                 to_program)

__all__ = ["evaluate", "sdf_eval", "workspace"]


def workspace(program):
    """The scratch arrays :func:`evaluate` needs for ``program``: (values (S,), grads (S, 3), points (T, 3),
    mats (T, 3, 3), scales (T,))."""
    S, T = max(program.values, 1), max(program.points, 1)
    return np.zeros(S), np.zeros((S, 3)), np.zeros((T, 3)), np.zeros((T, 3, 3)), np.zeros(T)


@njit(cache=True)
def _radial(x, y, z, cx, cy, cz, g, s):
    """g = s (p - c)/|p - c| ((s, 0, 0) at p = c); returns |p - c|."""
    rx, ry, rz = x - cx, y - cy, z - cz
    n = math.sqrt(rx * rx + ry * ry + rz * rz)
    if n > 0.0:
        g[0], g[1], g[2] = s * rx / n, s * ry / n, s * rz / n
    else:
        g[0], g[1], g[2] = s, 0.0, 0.0
    return n


@njit(cache=True)
def _box(r, half, g):
    """Exact distance to the box |r_i| <= half_i and its gradient into g (the numpy path's tie rules)."""
    q0, q1, q2 = abs(r[0]) - half[0], abs(r[1]) - half[1], abs(r[2]) - half[2]
    m0, m1, m2 = max(q0, 0.0), max(q1, 0.0), max(q2, 0.0)
    nm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    qmax = max(max(q0, q1), q2)
    s0 = 1.0 if r[0] >= 0 else -1.0
    s1 = 1.0 if r[1] >= 0 else -1.0
    s2 = 1.0 if r[2] >= 0 else -1.0
    if nm > 0.0:
        g[0], g[1], g[2] = m0 / nm * s0, m1 / nm * s1, m2 / nm * s2
    else:
        g[0], g[1], g[2] = 0.0, 0.0, 0.0
        if q0 >= q1 and q0 >= q2:                 # argmax: the first of the largest
            g[0] = s0
        elif q1 >= q2:
            g[1] = s1
        else:
            g[2] = s2
    return nm + min(qmax, 0.0)


@njit(cache=True)
def _perpendicular(a, out):
    """A unit vector perpendicular to the unit vector a (as sorofem.sdf.core._perpendicular)."""
    k = 0
    if abs(a[1]) < abs(a[k]):
        k = 1
    if abs(a[2]) < abs(a[k]):
        k = 2
    e = np.zeros(3)
    e[k] = 1.0
    t0, t1, t2 = a[1] * e[2] - a[2] * e[1], a[2] * e[0] - a[0] * e[2], a[0] * e[1] - a[1] * e[0]
    n = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    out[0], out[1], out[2] = t0 / n, t1 / n, t2 / n


@njit(cache=True)
def _axial(x, c, a, rad):
    """(z, rho) of point x about the axis through c along unit a, and the unit radial direction into rad."""
    r0, r1, r2 = x[0] - c[0], x[1] - c[1], x[2] - c[2]
    z = r0 * a[0] + r1 * a[1] + r2 * a[2]
    rho = math.sqrt(max(r0 * r0 + r1 * r1 + r2 * r2 - z * z, 0.0))
    if rho <= 1e-300:
        _perpendicular(a, rad)
    else:
        rad[0], rad[1], rad[2] = (r0 - z * a[0]) / rho, (r1 - z * a[1]) / rho, (r2 - z * a[2]) / rho
    return z, rho


@njit(cache=True)
def _segment(x, y, z, ax, ay, az, bx, by, bz):
    """(squared distance, closest point) of the point to the segment [a, b]."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    wx, wy, wz = x - ax, y - ay, z - az
    ee = ex * ex + ey * ey + ez * ez
    t = 0.0
    if ee > 0.0:
        t = min(max((wx * ex + wy * ey + wz * ez) / ee, 0.0), 1.0)
    cx, cy, cz = ax + t * ex, ay + t * ey, az + t * ez
    dx, dy, dz = x - cx, y - cy, z - cz
    return dx * dx + dy * dy + dz * dz, cx, cy, cz


@njit(cache=True)
def _smin(a, b, k):
    """Polynomial smooth minimum (value, weight h of a)."""
    hh = min(max(0.5 + 0.5 * (b - a) / k, 0.0), 1.0)
    return b + hh * (a - b) - k * hh * (1.0 - hh), hh


@njit(cache=True)
def evaluate(ops, c, P, d, grad, vals, gs, pts, mats, scl):
    """Signed distance d (N,) [m] and gradient grad (N, 3) of the program (ops, c) at the points P (N, 3) [m]
    (a 2D program: z = 0); the last five arguments are the scratch arrays of :func:`workspace`."""
    rad = np.empty(3)
    tmp = np.empty(3)
    gb = np.empty(3)
    for i in range(P.shape[0]):
        pts[0, 0], pts[0, 1], pts[0, 2] = P[i, 0], P[i, 1], P[i, 2]
        lv = 0                                            # top of the point stack
        sv = -1                                           # top of the value stack
        for k in range(ops.shape[0]):
            code, o, cnt = ops[k, 0], ops[k, 1], ops[k, 2]
            x = pts[lv]
            if code == SPHERE:
                sv += 1
                vals[sv] = _radial(x[0], x[1], x[2], c[o], c[o + 1], c[o + 2], gs[sv], 1.0) - c[o + 3]
            elif code == BOX:
                sv += 1
                for j in range(3):
                    tmp[j] = x[j] - c[o + j]
                vals[sv] = _box(tmp, c[o + 3:o + 6], gs[sv])
            elif code == CYLINDER:
                sv += 1
                z, rho = _axial(x, c[o:o + 3], c[o + 3:o + 6], rad)
                tmp[0], tmp[1], tmp[2] = rho, z, 0.0
                gb[0], gb[1], gb[2] = c[o + 6], c[o + 7], 1e300
                vals[sv] = _box(tmp, gb, tmp)
                for j in range(3):
                    gs[sv, j] = tmp[0] * rad[j] + tmp[1] * c[o + 3 + j]
            elif code == PLANE:
                sv += 1
                vals[sv] = ((x[0] - c[o]) * c[o + 3] + (x[1] - c[o + 1]) * c[o + 4]) + (x[2] - c[o + 2]) * c[o + 5]
                for j in range(3):
                    gs[sv, j] = c[o + 3 + j]
            elif code == CAPSULE:
                sv += 1
                d2, cx, cy, cz = _segment(x[0], x[1], x[2], c[o], c[o + 1], c[o + 2], c[o + 3], c[o + 4], c[o + 5])
                _radial(x[0], x[1], x[2], cx, cy, cz, gs[sv], 1.0)
                vals[sv] = math.sqrt(d2) - c[o + 6]
            elif code == POLYGON:
                sv += 1
                best = np.inf
                bx = by = 0.0
                inside = False
                for e in range(cnt):
                    f = e + 1 if e + 1 < cnt else 0
                    ax, ay = c[o + 2 * e], c[o + 2 * e + 1]
                    qx, qy = c[o + 2 * f], c[o + 2 * f + 1]
                    d2, cx, cy, _ = _segment(x[0], x[1], 0.0, ax, ay, 0.0, qx, qy, 0.0)
                    if d2 < best:
                        best, bx, by = d2, cx, cy
                    if ay != qy and ((ay <= x[1]) != (qy <= x[1])):
                        if x[0] < ax + (x[1] - ay) * (qx - ax) / (qy - ay):
                            inside = not inside
                s = -1.0 if inside else 1.0
                _radial(x[0], x[1], 0.0, bx, by, 0.0, gs[sv], s)
                vals[sv] = s * math.sqrt(best)
            elif code == UNION or code == INTERSECTION or code == DIFFERENCE:
                a, b = vals[sv - 1], vals[sv]
                sv -= 1
                if code == UNION:
                    take = b < a
                elif code == INTERSECTION:
                    take = b > a
                else:
                    take = not (a >= -b)
                if take:
                    sb = -1.0 if code == DIFFERENCE else 1.0
                    vals[sv] = sb * b
                    for j in range(3):
                        gs[sv, j] = sb * gs[sv + 1, j]
            elif code == SMOOTH_UNION or code == SMOOTH_INTERSECTION or code == SMOOTH_DIFFERENCE:
                a, b = vals[sv - 1], vals[sv]
                sv -= 1
                kk = c[o]
                sb = -1.0 if code == SMOOTH_DIFFERENCE else 1.0
                if code == SMOOTH_UNION:
                    v, w = _smin(a, b, kk)
                elif code == SMOOTH_INTERSECTION:
                    v, w = _smin(-a, -b, kk)
                    v = -v
                else:
                    v, w = _smin(-a, b, kk)
                    v = -v
                vals[sv] = v
                for j in range(3):
                    gs[sv, j] = w * gs[sv, j] + (1.0 - w) * sb * gs[sv + 1, j]
            elif code == OFFSET:
                vals[sv] -= c[o]
            elif code == SHELL:
                v = vals[sv] + c[o]
                if v < 0.0:
                    for j in range(3):
                        gs[sv, j] = -gs[sv, j]
                vals[sv] = abs(v) - c[o + 1]
            elif code == POP:
                for j in range(3):
                    tmp[j] = mats[lv, j, 0] * gs[sv, 0] + mats[lv, j, 1] * gs[sv, 1] + mats[lv, j, 2] * gs[sv, 2]
                for j in range(3):
                    gs[sv, j] = tmp[j]
                vals[sv] *= scl[lv]
                lv -= 1
            elif code == POP_EXTRUDE:
                lv -= 1
                wx = vals[sv]
                zz = pts[lv, 2]
                wy = abs(zz) - c[o]
                sz = 1.0 if zz >= 0 else -1.0
                mx, my = max(wx, 0.0), max(wy, 0.0)
                nn = math.hypot(mx, my)
                vals[sv] = min(max(wx, wy), 0.0) + nn
                if nn > 0.0:
                    ax, az = mx / nn, my / nn
                else:
                    ax = 1.0 if wx >= wy else 0.0
                    az = 1.0 if wx < wy else 0.0
                gs[sv, 0], gs[sv, 1], gs[sv, 2] = ax * gs[sv, 0], ax * gs[sv, 1], az * sz
            else:                                          # PUSH_*: the child's point, A and s
                y = pts[lv + 1]
                A = mats[lv + 1]
                for a1 in range(3):
                    for a2 in range(3):
                        A[a1, a2] = 1.0 if a1 == a2 else 0.0
                scl[lv + 1] = 1.0
                if code == PUSH_TRANSLATE:
                    for j in range(3):
                        y[j] = x[j] - c[o + j]
                elif code == PUSH_LINEAR:                  # y_j = sum_i x_i A_ij + shift_j; grad_x = A grad_y
                    for j in range(3):
                        y[j] = (x[0] * c[o + j] + x[1] * c[o + 3 + j]) + x[2] * c[o + 6 + j] + c[o + 9 + j]
                    for a1 in range(3):
                        for a2 in range(3):
                            A[a1, a2] = c[o + 3 * a1 + a2]
                elif code == PUSH_SCALE:
                    s = c[o]
                    for j in range(3):
                        y[j] = x[j] / s
                    scl[lv + 1] = s
                elif code == PUSH_EXTRUDE:
                    y[0], y[1], y[2] = x[0], x[1], 0.0
                else:                                      # PUSH_REVOLVE: (rho - offset, z)
                    tmp[0], tmp[1], tmp[2] = 0.0, 0.0, 0.0
                    z, rho = _axial(x, tmp, c[o:o + 3], rad)
                    y[0], y[1], y[2] = rho - c[o + 3], z, 0.0
                    for j in range(3):
                        A[j, 0], A[j, 1], A[j, 2] = rad[j], c[o + j], 0.0
                lv += 1
        d[i] = vals[0]
        for j in range(3):
            grad[i, j] = gs[0, j]


def sdf_eval(shape, points):
    """(distance (N,) [m], gradient (N, dim)) of ``shape`` at ``points`` (N, dim) [m] by the interpreter
    (``NotImplementedError`` for a tree without a program form)."""
    prog = to_program(shape)
    p = np.asarray(points, dtype=float).reshape(-1, shape.dim)
    P = np.zeros((len(p), 3))
    P[:, :shape.dim] = p
    d, g = np.empty(len(p)), np.empty((len(p), 3))
    evaluate(prog.ops, prog.consts, P, d, g, *workspace(prog))
    return d, g[:, :shape.dim]
