r"""Compiled beam-SDF contact: the penalty + regularized-Coulomb law of :func:`soroshapes.rigid.beam_contact` and
:meth:`Shapes.add_contact <soroshapes.shapes.Shapes.add_contact>` in one numba kernel, with the obstacle's SDF
evaluated by the program interpreter (:mod:`soroshapes._sdfeval`), so any supported shape runs without a
compile per shape.

Law (the same as the Python path): the beam's tube of radius :math:`r` around its nodes :math:`P_i`; the
obstacle's SDF :math:`\phi` in its own frame :math:`(R, p)` (identity for a fixed obstacle), node in body
coordinates :math:`P^b_i = R^T(P_i - p)`, :math:`d_i = \phi(P^b_i)`, normal :math:`n_i = R\nabla\phi/|\nabla\phi|`;
relative velocity :math:`v^{rel}_i = R_i\eta_{i,v} - R(v + \omega\times P^b_i)` (body twist :math:`(\omega, v)`,
zero for a fixed obstacle); where :math:`d_i < r`,

.. math:: F_i = w_i\left(f_n n_i - \mu f_n \frac{v_t}{\sqrt{|v_t|^2+\epsilon^2}}\right),\quad
          f_n = \max(0, k(r - d_i) - c\,v^{rel}_i\cdot n_i),

on the beam the generalized force :math:`\sum_i J_{i,v}^T R_i^T F_i`, on the body the wrench
:math:`\sum_i (P^b_i\times f^b_i, f^b_i)`, :math:`f^b_i = -R^TF_i`.

Contact of points carried by the frames of a tree of bodies (:func:`soroshapes.rigid.tree_contact`, pads on a
gripper's fingers) follows the same law per point, with the point's own pad radius and no node weight
(:func:`tree_contact_force`; data by :func:`lower_tree_contact`).

Data of one contact (:func:`lower_contact`): floats ``(k, c, mu, eps, r, stride, N+1, w_0 .. w_N)`` and the
obstacle's :class:`~sorofem.sdf.program.Program`.

Nodes far from the obstacle are not evaluated: every SDF of a program is 1-Lipschitz (its primitives are exact
or bounds with unit gradient, its operations min/max, their polynomial smooth forms, whose gradient is a convex
combination, offsets, shells, rigid motions, uniform scaling, extrusion and revolution), so a node whose last
evaluated distance :math:`d^{old}` at :math:`P^{old}` satisfies :math:`d^{old} - |P^b - P^{old}| \ge r` has
:math:`d \ge r` and no force. The pairs :math:`(P^{old}, d^{old})` are kept per node in ``memo`` (any pair
evaluated on the same program is a valid bound; zeros force an evaluation).
"""
import math

import numpy as np

from sorofem._numba import njit
from sorofem.errors import ParameterError
from sorofem.sdf.program import to_program

from ._sdfeval import evaluate

__all__ = ["lower_contact", "lower_contact_of", "contact_force", "contact_nodal", "contact_jacobian",
           "CONTACT_HEAD",
           "lower_tree_contact", "tree_contact_force"]

#: floats before the node weights
CONTACT_HEAD = 7


def lower_contact(beam, shape, stiffness, damping, friction, regularization):
    """(floats, program) of a contact of ``beam`` (a :class:`~soroshapes.shapes.Shapes`, its tube
    ``contact_radius``) with the 3D SDF ``shape``; ``NotImplementedError`` when the SDF has no program form."""
    return lower_contact_of(beam.model, beam.contact_radius, shape, stiffness, damping, friction, regularization)


def lower_contact_of(model, radius, shape, stiffness, damping, friction, regularization):
    """(floats, program) of a contact of the beam ``model`` (a :class:`~soroshapes.beam.BeamModel`) with tube
    radius ``radius`` [m] and the 3D SDF ``shape`` (:func:`lower_contact` for a model without its Shapes)."""
    if getattr(shape, "dim", None) != 3:
        raise ParameterError("a contact obstacle must be a 3D SDF of sorofem.sdf")
    prog = to_program(shape)
    w = np.asarray(model.node_weights, dtype=float)
    head = [stiffness, damping, friction, regularization, radius, model.stride, len(w)]
    return np.concatenate([np.asarray(head, dtype=float), w]), prog


@njit(cache=True)
def _react(Rb, Pb, i, F, W):
    """Add to the body's wrench W (body frame, moment first) the reaction of the world force F at its point
    Pb[i] (body frame): the force -R^T F and its moment about the body's origin."""
    fb0 = -(Rb[0, 0] * F[0] + Rb[1, 0] * F[1] + Rb[2, 0] * F[2])
    fb1 = -(Rb[0, 1] * F[0] + Rb[1, 1] * F[1] + Rb[2, 1] * F[2])
    fb2 = -(Rb[0, 2] * F[0] + Rb[1, 2] * F[1] + Rb[2, 2] * F[2])
    W[0] += Pb[i, 1] * fb2 - Pb[i, 2] * fb1
    W[1] += Pb[i, 2] * fb0 - Pb[i, 0] * fb2
    W[2] += Pb[i, 0] * fb1 - Pb[i, 1] * fb0
    W[3] += fb0
    W[4] += fb1
    W[5] += fb2


@njit(cache=True)
def contact_nodal(par, ops, consts, depth_values, depth_points, G, eta, Rb, pb, etab, Fc, W, memo, Kc, Cc):
    """The contact's forces at the beam's nodes: add the spatial force on the tube at node i to ``Fc[i * stride]``
    (``Fc`` (P+1, 3), indexed by the beam's chain of points like ``G``) and the wrench on the body (body
    coordinates, about the body origin) to ``W`` (6,), for the beam's frames ``G`` and velocities ``eta`` and the
    body pose (Rb, pb) and twist etab; ``memo`` (N+1, 4) as in :func:`contact_force`. Unless ``Kc`` has no rows,
    add to ``Kc[a]`` and ``Cc[a]`` (P+1, 3, 3) the derivatives of minus the force on the tube at point ``a`` with
    respect to its spatial position and velocity where the node presses: :math:`w k\\,n n^T` and
    :math:`w(c\\,n n^T + \\mu f_n(P_t - v_t v_t^T/s^2)/s)`, :math:`s = \\sqrt{|v_t|^2 + \\epsilon^2}`,
    :math:`P_t = I - n n^T` (the obstacle held still, the normal's turning and the velocity's part of the
    friction's normal force left out: the terms a Newton iteration matrix needs). False if a force is not
    finite."""
    k, c, mu, r = par[0], par[1], par[2], par[4]
    stride = int(par[5])
    Pb, near, ne, d, gr = _near_nodes(par, ops, consts, depth_values, depth_points, G, Rb, pb, memo)
    ns = np.empty(3)
    vt = np.empty(3)
    F = np.empty(3)
    tangents = Kc.shape[0] > 0
    for e in range(ne):
        if not d[e] < r:
            continue
        i = near[e]
        a = i * stride
        fn, slip, _ = _node_force(par, i, d[e], gr[e], G, eta, Rb, Pb, etab, ns, vt, F)
        if not (math.isfinite(F[0]) and math.isfinite(F[1]) and math.isfinite(F[2])):
            return False
        for j in range(3):
            Fc[a, j] += F[j]
        if tangents and fn > 0.0:
            wi = par[CONTACT_HEAD + i]
            ft = wi * mu * fn / slip
            for j in range(3):
                for l in range(3):
                    nnt = ns[j] * ns[l]
                    Kc[a, j, l] += wi * k * nnt
                    Cc[a, j, l] += wi * c * nnt + ft * ((1.0 if j == l else 0.0) - nnt - vt[j] * vt[l] / (slip * slip))
        _react(Rb, Pb, i, F, W)
    return True


@njit(cache=True)
def _near_nodes(par, ops, consts, depth_values, depth_points, G, Rb, pb, memo):
    """The nodes in body coordinates ``Pb`` (N+1, 3), the ``ne`` nodes that may touch (``near[:ne]``, by the
    bound of their last evaluation in ``memo``, updated) and their distances ``d`` and SDF gradients ``gr`` (body
    coordinates)."""
    r = par[4]
    stride, nn = int(par[5]), int(par[6])
    Pb = np.empty((nn, 3))
    for i in range(nn):
        a = i * stride
        for j in range(3):
            Pb[i, j] = ((G[a, 0, 3] - pb[0]) * Rb[0, j] + (G[a, 1, 3] - pb[1]) * Rb[1, j]) + (G[a, 2, 3] - pb[2]) * Rb[2, j]
    near = np.empty(nn, np.int64)
    ne = 0
    for i in range(nn):
        e0, e1, e2 = Pb[i, 0] - memo[i, 0], Pb[i, 1] - memo[i, 1], Pb[i, 2] - memo[i, 2]
        if not memo[i, 3] - math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) >= r:
            near[ne] = i
            ne += 1
    d = np.empty(ne)
    gr = np.empty((ne, 3))
    if ne == 0:
        return Pb, near, ne, d, gr
    Pn = np.empty((ne, 3))
    for e in range(ne):
        for j in range(3):
            Pn[e, j] = Pb[near[e], j]
    S, T = max(depth_values, 1), max(depth_points, 1)
    evaluate(ops, consts, Pn, d, gr, np.empty(S), np.empty((S, 3)), np.empty((T, 3)), np.empty((T, 3, 3)),
             np.empty(T))
    for e in range(ne):
        i = near[e]
        if math.isfinite(d[e]):
            memo[i, 0], memo[i, 1], memo[i, 2], memo[i, 3] = Pn[e, 0], Pn[e, 1], Pn[e, 2], d[e]
    return Pb, near, ne, d, gr


@njit(cache=True)
def _node_force(par, i, d, g, G, eta, Rb, Pb, etab, ns, vt, F):
    """The law of the module docstring at node i (distance ``d`` < r, SDF gradient ``g`` (3,) in body
    coordinates): the force on the tube into ``F`` (3,), the spatial unit normal into ``ns`` and the tangential
    relative velocity into ``vt``; returns (f_n, s, v_n), :math:`s = \\sqrt{|v_t|^2 + \\epsilon^2}`, :math:`v_n` the
    normal relative velocity."""
    k, c, mu, eps, r = par[0], par[1], par[2], par[3], par[4]
    a = i * int(par[5])
    g0, g1, g2 = g[0], g[1], g[2]
    gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    g0, g1, g2 = g0 / gn, g1 / gn, g2 / gn
    # body velocity at the node: v + omega x Pb (body), then spatial
    b0 = etab[3] + etab[1] * Pb[i, 2] - etab[2] * Pb[i, 1]
    b1 = etab[4] + etab[2] * Pb[i, 0] - etab[0] * Pb[i, 2]
    b2 = etab[5] + etab[0] * Pb[i, 1] - etab[1] * Pb[i, 0]
    vn = 0.0
    vrel = np.empty(3)
    for j in range(3):
        ns[j] = Rb[j, 0] * g0 + Rb[j, 1] * g1 + Rb[j, 2] * g2
        vrel[j] = (G[a, j, 0] * eta[a, 3] + G[a, j, 1] * eta[a, 4] + G[a, j, 2] * eta[a, 5]) \
            - (Rb[j, 0] * b0 + Rb[j, 1] * b1 + Rb[j, 2] * b2)
    for j in range(3):
        vn += vrel[j] * ns[j]
    fn = max(0.0, k * (r - d) - c * vn)
    vt[0], vt[1], vt[2] = vrel[0] - vn * ns[0], vrel[1] - vn * ns[1], vrel[2] - vn * ns[2]
    slip = math.sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2] + eps * eps)
    wi = par[CONTACT_HEAD + i]
    for j in range(3):
        F[j] = wi * (fn * ns[j] - mu * (fn / slip) * vt[j])
    return fn, slip, vn


@njit(cache=True)
def contact_force(par, ops, consts, depth_values, depth_points, G, J, eta, Rb, pb, etab, f, W, memo):
    """Add the contact's generalized force on the beam to ``f`` (n,) and its wrench on the body (body
    coordinates, about the body origin) to ``W`` (6,), for the beam's kinematics (frames ``G``, Jacobians ``J``,
    velocities ``eta`` at its chain of points) and the body pose (Rb, pb) and twist etab; ``memo`` (N+1, 4): per
    node the body point and distance of its last evaluation (module docstring), updated. The forces of
    :func:`contact_nodal`, each carried to the coordinates by :math:`J_{i,v}^T R_i^T`. False if a force is not
    finite."""
    stride, nn = int(par[5]), int(par[6])
    n = J.shape[2]
    Fc = np.zeros((G.shape[0], 3))
    if not contact_nodal(par, ops, consts, depth_values, depth_points, G, eta, Rb, pb, etab, Fc, W, memo,
                         np.empty((0, 3, 3)), np.empty((0, 3, 3))):
        return False
    for i in range(nn):
        a = i * stride
        if Fc[a, 0] == 0.0 and Fc[a, 1] == 0.0 and Fc[a, 2] == 0.0:
            continue
        for j in range(3):                                   # J_v^T R_i^T F on the beam
            fl = G[a, 0, j] * Fc[a, 0] + G[a, 1, j] * Fc[a, 1] + G[a, 2, j] * Fc[a, 2]
            for col in range(n):
                f[col] += J[a, 3 + j, col] * fl
    return True


@njit(cache=True)
def contact_jacobian(par, ops, consts, depth_values, depth_points, G, J, eta, Rb, pb, etab, axis, memo, Fq, Fb, Wq,
                     Wb):
    r"""The derivatives of the contact's generalized force :math:`f` on the beam and of its wrench :math:`W` on
    the body (:func:`contact_force`, the same arguments to ``memo``) by the beam's coordinates and rates and by the
    angle and rate :math:`(\theta, \dot\theta)` of the body turning about its unit ``axis`` (body coordinates,
    through its origin; zeros for a body that does not move), added to ``Fq`` (n, 2n) :math:`\partial
    f/\partial(q, \dot q)`, ``Fb`` (n, 2) :math:`\partial f/\partial(\theta, \dot\theta)`, ``Wq`` (6, 2n) and
    ``Wb`` (6, 2). At each pressing node, with :math:`A_P = -\partial F/\partial P = w k (n - \mu v_t/s) n^T` and
    :math:`A_v = -\partial F/\partial v = w c (n - \mu v_t/s) n^T + w\mu f_n (P_t - v_t v_t^T/s^2)/s` (the law's
    full derivatives, friction included; :math:`P_t = I - nn^T`), :math:`B = R_i J_{i,v}` (the node's spatial
    displacement per unit of q), :math:`r = P_i - p`, :math:`u = a\times r` (:math:`a = R\,` ``axis``: the
    node's displacement relative to the body per unit of body angle is :math:`-u`):

    .. math:: \partial f/\partial q = -B^T A_P B,\ \partial f/\partial\dot q = -B^T A_v B,\
              \partial f/\partial\theta = B^T F_\theta,\ \partial f/\partial\dot\theta = B^T A_v u,

    :math:`F_\theta = A_P u + \delta F` with :math:`\delta F` the change of the law as the normal turns with the
    body, :math:`\delta n = a\times n` (through :math:`f_n`'s damping part, :math:`v_t` and :math:`n` itself),

    :math:`\partial W/\partial q = R^T[([F]_\times + [r]_\times A_P)B;\ A_P B]`, :math:`\partial W/\partial\dot q
    = R^T[[r]_\times A_v B;\ A_v B]`, :math:`\partial W/\partial\theta = -R^T[r\times F_\theta;\ F_\theta] -
    [\mathrm{axis}]_\times W_i` (both halves: the body frame turns), :math:`\partial W/\partial\dot\theta =
    -R^T[r\times A_v u;\ A_v u]`. Left out, as in the beam's own iteration matrix: the normal's turning along the
    surface (its curvature), and the
    configuration derivatives of the node's velocity and of :math:`R_i J_{i,v}` (geometric stiffness). False if
    a force is not finite."""
    k, c, mu, r = par[0], par[1], par[2], par[4]
    stride = int(par[5])
    n = J.shape[2]
    Pb, near, ne, d, gr = _near_nodes(par, ops, consts, depth_values, depth_points, G, Rb, pb, memo)
    ns = np.empty(3)
    vt = np.empty(3)
    F = np.empty(3)
    AP = np.empty((3, 3))
    Av = np.empty((3, 3))
    B = np.empty((3, n))
    PB = np.empty((3, n))
    VB = np.empty((3, n))
    rr = np.empty(3)
    u = np.empty(3)
    aw = np.empty(3)
    for j in range(3):
        aw[j] = Rb[j, 0] * axis[0] + Rb[j, 1] * axis[1] + Rb[j, 2] * axis[2]
    pu = np.empty(3)
    vu = np.empty(3)
    Wi = np.zeros(6)
    for e in range(ne):
        if not d[e] < r:
            continue
        i = near[e]
        a = i * stride
        fn, slip, vn = _node_force(par, i, d[e], gr[e], G, eta, Rb, Pb, etab, ns, vt, F)
        if not (math.isfinite(F[0]) and math.isfinite(F[1]) and math.isfinite(F[2])):
            return False
        if fn == 0.0:
            continue
        wi = par[CONTACT_HEAD + i]
        ft = wi * mu * fn / slip
        for j in range(3):
            tj = ns[j] - mu * vt[j] / slip
            for l in range(3):
                AP[j, l] = wi * k * tj * ns[l]
                Av[j, l] = wi * c * tj * ns[l] + ft * ((1.0 if j == l else 0.0) - ns[j] * ns[l]
                                                       - vt[j] * vt[l] / (slip * slip))
        for j in range(3):
            rr[j] = G[a, j, 3] - pb[j]
            for col in range(n):
                B[j, col] = G[a, j, 0] * J[a, 3, col] + G[a, j, 1] * J[a, 4, col] + G[a, j, 2] * J[a, 5, col]
        u[0] = aw[1] * rr[2] - aw[2] * rr[1]
        u[1] = aw[2] * rr[0] - aw[0] * rr[2]
        u[2] = aw[0] * rr[1] - aw[1] * rr[0]
        # the normal turns with the body: dn = a x n per unit angle, and with it v_n, f_n and v_t
        dn0, dn1, dn2 = aw[1] * ns[2] - aw[2] * ns[1], aw[2] * ns[0] - aw[0] * ns[2], aw[0] * ns[1] - aw[1] * ns[0]
        dvn = (vt[0] + vn * ns[0]) * dn0 + (vt[1] + vn * ns[1]) * dn1 + (vt[2] + vn * ns[2]) * dn2
        dfn = -c * dvn
        dvt0, dvt1, dvt2 = -dvn * ns[0] - vn * dn0, -dvn * ns[1] - vn * dn1, -dvn * ns[2] - vn * dn2
        vdv = (vt[0] * dvt0 + vt[1] * dvt1 + vt[2] * dvt2) / (slip * slip)
        for j in range(3):
            pu[j] = AP[j, 0] * u[0] + AP[j, 1] * u[1] + AP[j, 2] * u[2]
            vu[j] = Av[j, 0] * u[0] + Av[j, 1] * u[1] + Av[j, 2] * u[2]
        for j, dnj, dvtj in ((0, dn0, dvt0), (1, dn1, dvt1), (2, dn2, dvt2)):
            pu[j] += wi * (dfn * ns[j] + fn * dnj - mu * (dfn * vt[j] + fn * (dvtj - vt[j] * vdv)) / slip)
            for col in range(n):
                PB[j, col] = AP[j, 0] * B[0, col] + AP[j, 1] * B[1, col] + AP[j, 2] * B[2, col]
                VB[j, col] = Av[j, 0] * B[0, col] + Av[j, 1] * B[1, col] + Av[j, 2] * B[2, col]
        for row in range(n):                                 # the beam's force
            b0, b1, b2 = B[0, row], B[1, row], B[2, row]
            for col in range(n):
                Fq[row, col] -= b0 * PB[0, col] + b1 * PB[1, col] + b2 * PB[2, col]
                Fq[row, n + col] -= b0 * VB[0, col] + b1 * VB[1, col] + b2 * VB[2, col]
            Fb[row, 0] += b0 * pu[0] + b1 * pu[1] + b2 * pu[2]
            Fb[row, 1] += b0 * vu[0] + b1 * vu[1] + b2 * vu[2]
        # the body's wrench: spatial moment and force derivatives, then into body coordinates (R^T)
        for col in range(n):
            m0 = F[1] * B[2, col] - F[2] * B[1, col] + rr[1] * PB[2, col] - rr[2] * PB[1, col]
            m1 = F[2] * B[0, col] - F[0] * B[2, col] + rr[2] * PB[0, col] - rr[0] * PB[2, col]
            m2 = F[0] * B[1, col] - F[1] * B[0, col] + rr[0] * PB[1, col] - rr[1] * PB[0, col]
            n0 = rr[1] * VB[2, col] - rr[2] * VB[1, col]
            n1 = rr[2] * VB[0, col] - rr[0] * VB[2, col]
            n2 = rr[0] * VB[1, col] - rr[1] * VB[0, col]
            for j in range(3):
                Wq[j, col] += Rb[0, j] * m0 + Rb[1, j] * m1 + Rb[2, j] * m2
                Wq[3 + j, col] += Rb[0, j] * PB[0, col] + Rb[1, j] * PB[1, col] + Rb[2, j] * PB[2, col]
                Wq[j, n + col] += Rb[0, j] * n0 + Rb[1, j] * n1 + Rb[2, j] * n2
                Wq[3 + j, n + col] += Rb[0, j] * VB[0, col] + Rb[1, j] * VB[1, col] + Rb[2, j] * VB[2, col]
        for s, v in ((0, pu), (1, vu)):
            m0 = rr[1] * v[2] - rr[2] * v[1]
            m1 = rr[2] * v[0] - rr[0] * v[2]
            m2 = rr[0] * v[1] - rr[1] * v[0]
            for j in range(3):
                Wb[j, s] -= Rb[0, j] * m0 + Rb[1, j] * m1 + Rb[2, j] * m2
                Wb[3 + j, s] -= Rb[0, j] * v[0] + Rb[1, j] * v[1] + Rb[2, j] * v[2]
        for j in range(6):
            Wi[j] = 0.0
        _react(Rb, Pb, i, F, Wi)                             # the body frame turns with theta
        for h in (0, 3):
            Wb[h, 0] -= axis[1] * Wi[h + 2] - axis[2] * Wi[h + 1]
            Wb[h + 1, 0] -= axis[2] * Wi[h] - axis[0] * Wi[h + 2]
            Wb[h + 2, 0] -= axis[0] * Wi[h + 1] - axis[1] * Wi[h]
    return True


#: floats of a tree contact before its points, and per point (frame row, offset (3), radius)
TREE_CONTACT_HEAD, TREE_CONTACT_POINT = 5, 5


def lower_tree_contact(rows, offsets, radii, shape, stiffness, damping, friction, regularization):
    """(floats, program) of a contact of points on a tree's frames (rows of the stacked frames, offsets (k, 3)
    [m] in the frames' axes, pad radii (k,) [m]) with the 3D SDF ``shape``: ``(k, c, mu, eps, npoints)`` then
    per point ``(row, offset, radius)``; ``NotImplementedError`` when the SDF has no program form."""
    if getattr(shape, "dim", None) != 3:
        raise ParameterError("a contact obstacle must be a 3D SDF of sorofem.sdf")
    prog = to_program(shape)
    rows = np.asarray(rows, dtype=float).reshape(-1)
    pts = np.column_stack([rows, np.asarray(offsets, dtype=float).reshape(-1, 3),
                           np.asarray(radii, dtype=float).reshape(-1)])
    head = [stiffness, damping, friction, regularization, len(rows)]
    return np.concatenate([np.asarray(head, dtype=float), pts.reshape(-1)]), prog


@njit(cache=True)
def tree_contact_force(par, ops, consts, depth_values, depth_points, G, J, eta, Rb, pb, etab, f, W):
    r"""Add the contact's generalized force on the tree to ``f`` (n,) and its wrench on the body (body
    coordinates, about the body origin) to ``W`` (6,), for the tree's stacked frames ``G``, body Jacobians ``J``
    and body twists ``eta`` and the body's pose (Rb, pb) and twist etab. Point j on frame :math:`(R_a, P_a)` at
    offset :math:`o_j`: :math:`X_j = P_a + R_a o_j`, velocity :math:`R_a(v_a + \omega_a\times o_j)`; where its
    distance :math:`d_j < r_j`, the force of the module's law (no node weight) :math:`F_j` acts on the tree as
    :math:`J_{a,v}^T f + J_{a,\omega}^T (o_j\times f)`, :math:`f = R_a^T F_j`, and :math:`-R_b^T F_j` on the body at
    :math:`X^b_j`. False if a force is not finite."""
    k, c, mu, eps = par[0], par[1], par[2], par[3]
    npt = int(par[4])
    n = f.shape[0]
    Pb = np.empty((npt, 3))
    for e in range(npt):
        o = TREE_CONTACT_HEAD + TREE_CONTACT_POINT * e
        a = int(par[o])
        for j in range(3):
            X = G[a, j, 3] + G[a, j, 0] * par[o + 1] + G[a, j, 1] * par[o + 2] + G[a, j, 2] * par[o + 3]
            Pb[e, j] = X - pb[j]
    for e in range(npt):                      # body coordinates: R^T (X - p)
        x0, x1, x2 = Pb[e, 0], Pb[e, 1], Pb[e, 2]
        for j in range(3):
            Pb[e, j] = Rb[0, j] * x0 + Rb[1, j] * x1 + Rb[2, j] * x2
    d = np.empty(npt)
    gr = np.empty((npt, 3))
    S, T = max(depth_values, 1), max(depth_points, 1)
    evaluate(ops, consts, Pb, d, gr, np.empty(S), np.empty((S, 3)), np.empty((T, 3)), np.empty((T, 3, 3)),
             np.empty(T))
    ns = np.empty(3)
    vrel = np.empty(3)
    vt = np.empty(3)
    F = np.empty(3)
    fl = np.empty(3)
    for e in range(npt):
        o = TREE_CONTACT_HEAD + TREE_CONTACT_POINT * e
        r = par[o + 4]
        if not d[e] < r:
            continue
        a = int(par[o])
        o0, o1, o2 = par[o + 1], par[o + 2], par[o + 3]
        g0, g1, g2 = gr[e, 0], gr[e, 1], gr[e, 2]
        gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        g0, g1, g2 = g0 / gn, g1 / gn, g2 / gn
        # the point's velocity in its frame's axes: v + omega x o; the body's at the point: v + omega x Pb
        l0 = eta[a, 3] + eta[a, 1] * o2 - eta[a, 2] * o1
        l1 = eta[a, 4] + eta[a, 2] * o0 - eta[a, 0] * o2
        l2 = eta[a, 5] + eta[a, 0] * o1 - eta[a, 1] * o0
        b0 = etab[3] + etab[1] * Pb[e, 2] - etab[2] * Pb[e, 1]
        b1 = etab[4] + etab[2] * Pb[e, 0] - etab[0] * Pb[e, 2]
        b2 = etab[5] + etab[0] * Pb[e, 1] - etab[1] * Pb[e, 0]
        vn = 0.0
        for j in range(3):
            ns[j] = Rb[j, 0] * g0 + Rb[j, 1] * g1 + Rb[j, 2] * g2
            vrel[j] = (G[a, j, 0] * l0 + G[a, j, 1] * l1 + G[a, j, 2] * l2) \
                - (Rb[j, 0] * b0 + Rb[j, 1] * b1 + Rb[j, 2] * b2)
        for j in range(3):
            vn += vrel[j] * ns[j]
        fn = max(0.0, k * (r - d[e]) - c * vn)
        if fn == 0.0:
            continue
        for j in range(3):
            vt[j] = vrel[j] - vn * ns[j]
        slip = math.sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2] + eps * eps)
        for j in range(3):
            F[j] = fn * ns[j] - mu * (fn / slip) * vt[j]
        if not (math.isfinite(F[0]) and math.isfinite(F[1]) and math.isfinite(F[2])):
            return False
        for j in range(3):                                   # the force in the frame's axes
            fl[j] = G[a, 0, j] * F[0] + G[a, 1, j] * F[1] + G[a, 2, j] * F[2]
        m0 = o1 * fl[2] - o2 * fl[1]                         # its moment about the frame's origin
        m1 = o2 * fl[0] - o0 * fl[2]
        m2 = o0 * fl[1] - o1 * fl[0]
        for col in range(n):
            f[col] += (J[a, 3, col] * fl[0] + J[a, 4, col] * fl[1] + J[a, 5, col] * fl[2]
                       + J[a, 0, col] * m0 + J[a, 1, col] * m1 + J[a, 2, col] * m2)
        _react(Rb, Pb, e, F, W)
    return True
