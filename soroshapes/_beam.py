r"""Numba kernels of the Cosserat beam model (private; :mod:`soroshapes.shapes` is the public face).

The rod is cut into ``N`` segments of lengths :math:`h_s`; on each segment the strain
:math:`\xi(\sigma) = \Theta(\sigma) q + \xi_\circ(\sigma)` is integrated by a Magnus expansion:

- order 2 (one Gauss point at the midpoint): :math:`\Omega = h\,\xi_1`;
- order 4 (two Gauss points :math:`\tfrac12 \mp \tfrac{\sqrt3}{6}`):
  :math:`\Omega = \tfrac h2(\xi_1 + \xi_2) + \tfrac{\sqrt3 h^2}{12}[\xi_1, \xi_2]`,

and the frames at the segment ends (the *nodes*) follow :math:`g_{s+1} = g_s \exp\hat\Omega_s`. Differentiating
this map exactly gives the body Jacobian and its rate at the nodes,

.. math::

    J_{s+1} = \mathrm{Ad}_{e^{-\Omega}} J_s + T(\Omega)\,\Omega',\qquad
    \dot J_{s+1} = \mathrm{Ad}_{e^{-\Omega}}\dot J_s - \mathrm{ad}_{\psi}\mathrm{Ad}_{e^{-\Omega}} J_s
                   + dT[\dot\Omega]\,\Omega' + T\,\dot\Omega',

with :math:`\Omega' = \partial\Omega/\partial q` (6 x n), :math:`\psi = T(\Omega)\dot\Omega` and :math:`T`, :math:`dT`
from :mod:`soroshapes.lie`. Because :math:`J` is the exact derivative of the discrete map :math:`q \mapsto g_s(q)`,
the dynamics assembled from it is the exact Lagrangian dynamics of the discrete model (energy is conserved by
the continuous-time equations; :math:`\dot M - 2C` is skew-symmetric).

Every 6 x 6 matrix met here (``ad``, ``Ad`` of a pose's inverse, ``T``, ``dT``) has the block form
:math:`\begin{bmatrix} P & 0 \\ Q & P \end{bmatrix}`: products use it (27 instead of 36 multiplications per
column), and ``T``, ``dT`` are built from closed forms of their 3 x 3 blocks (:func:`_tangent_closed`). Column
``k`` of :math:`\Theta` has a single nonzero (in strain ``rows[k]``), which the order-2 updates exploit.
Kernels write into work arrays passed by the caller (a :class:`soroshapes.beam.BeamData` workspace).

The implicit integrator (:func:`integrate_midpoint`) never forms the 6 x n Jacobians in its iterations: its
residual comes from the O(N) forward/backward recursions of :func:`newton_euler` (``T`` and ``dT`` applied to
vectors as polynomials in ``ad``), and its iteration matrix from the mass matrix that
:func:`mass_matrix_pieces` assembles from the per-piece operators of the same pass.
"""
import numpy as np
from sorofem._numba import njit  # numba.njit with a cache that concurrent processes may share

from ._contact import contact_nodal
from .lie import _put_skew, _so3_coeffs, _tse3_coeffs, _tse3_dcoeffs, invSE3, logSE3

MAGNUS4_C = np.sqrt(3.0) / 12.0
GAUSS2 = (0.5 - np.sqrt(3.0) / 6.0, 0.5 + np.sqrt(3.0) / 6.0)

#: The implicit integrator refreshes its iteration matrix after a step that needed more than REFRESH_ITS residual
#: evaluations or whose Newton contraction rate exceeded THETA_REFRESH, and at least every REFRESH_STEPS steps.
#: (0.004: a step with a fresh matrix needs two evaluations, a matrix one step old often three; measured on the
#: 15-DOF rod, 0.004 and 0.01 cost the same time, 0.02 and 0.05 more.)
REFRESH_ITS, REFRESH_STEPS, THETA_REFRESH = 3, 50, 0.004

# indices into the (6, 6, 6) scratch: tangent, its derivative, Ad of the segment's inverse, three temporaries
_T, _DT, _AI, _TMP, _W1, _W2 = range(6)


@njit(cache=True)
def _ad_into(x, A):
    """A = ad_x = [[w^, 0], [v^, w^]] (skew blocks written by :func:`soroshapes.lie._put_skew`)."""
    for i in range(6):
        for j in range(6):
            A[i, j] = 0.0
    _put_skew(A, 0, 0, x, 0)
    _put_skew(A, 3, 3, x, 0)
    _put_skew(A, 3, 0, x, 3)


@njit(cache=True)
def _bapply(A, X, Y, alpha, beta):
    """Y = alpha * A @ X + beta * Y for a block matrix A = [[P, 0], [Q, P]] and X, Y of shape (6, m)."""
    m = X.shape[1]
    for c in range(m):
        x0, x1, x2, x3, x4, x5 = X[0, c], X[1, c], X[2, c], X[3, c], X[4, c], X[5, c]
        for i in range(3):
            top = A[i, 0] * x0 + A[i, 1] * x1 + A[i, 2] * x2
            bot = (A[i + 3, 0] * x0 + A[i + 3, 1] * x1 + A[i + 3, 2] * x2
                   + A[i, 0] * x3 + A[i, 1] * x4 + A[i, 2] * x5)
            if beta == 0.0:              # never read Y: a stale non-finite buffer must not leak (0 * NaN)
                Y[i, c] = alpha * top
                Y[i + 3, c] = alpha * bot
            else:
                Y[i, c] = alpha * top + beta * Y[i, c]
                Y[i + 3, c] = alpha * bot + beta * Y[i + 3, c]


@njit(cache=True)
def _bapply_at(A, X, sx, Y, sy, alpha, beta):
    """:func:`_bapply` on the (6, m) slices ``X[sx]`` and ``Y[sy]`` of 3-D arrays, indexed element by element
    (a view of a slice costs a reference-count pair; a 2-D operand comes as a (1, 6, m) reshape made once)."""
    m = X.shape[2]
    for c in range(m):
        x0, x1, x2, x3, x4, x5 = X[sx, 0, c], X[sx, 1, c], X[sx, 2, c], X[sx, 3, c], X[sx, 4, c], X[sx, 5, c]
        for i in range(3):
            top = A[i, 0] * x0 + A[i, 1] * x1 + A[i, 2] * x2
            bot = (A[i + 3, 0] * x0 + A[i + 3, 1] * x1 + A[i + 3, 2] * x2
                   + A[i, 0] * x3 + A[i, 1] * x4 + A[i, 2] * x5)
            if beta == 0.0:              # never read Y: a stale non-finite buffer must not leak (0 * NaN)
                Y[sy, i, c] = alpha * top
                Y[sy, i + 3, c] = alpha * bot
            else:
                Y[sy, i, c] = alpha * top + beta * Y[sy, i, c]
                Y[sy, i + 3, c] = alpha * bot + beta * Y[sy, i + 3, c]


@njit(cache=True)
def _bvec(A, x, y, alpha, beta):
    """y = alpha * A @ x + beta * y for a block matrix A and vectors of length 6."""
    x0, x1, x2, x3, x4, x5 = x[0], x[1], x[2], x[3], x[4], x[5]
    for i in range(3):
        top = A[i, 0] * x0 + A[i, 1] * x1 + A[i, 2] * x2
        bot = A[i + 3, 0] * x0 + A[i + 3, 1] * x1 + A[i + 3, 2] * x2 + A[i, 0] * x3 + A[i, 1] * x4 + A[i, 2] * x5
        if beta == 0.0:
            y[i] = alpha * top
            y[i + 3] = alpha * bot
        else:
            y[i] = alpha * top + beta * y[i]
            y[i + 3] = alpha * bot + beta * y[i + 3]


@njit(cache=True)
def _adv(x, y, out):
    """out = ad_x y = (w x yw, v x yw + w x yv)."""
    w0, w1, w2, v0, v1, v2 = x[0], x[1], x[2], x[3], x[4], x[5]
    a0, a1, a2, b0, b1, b2 = y[0], y[1], y[2], y[3], y[4], y[5]
    out[0] = w1 * a2 - w2 * a1
    out[1] = w2 * a0 - w0 * a2
    out[2] = w0 * a1 - w1 * a0
    out[3] = v1 * a2 - v2 * a1 + w1 * b2 - w2 * b1
    out[4] = v2 * a0 - v0 * a2 + w2 * b0 - w0 * b2
    out[5] = v0 * a1 - v1 * a0 + w0 * b1 - w1 * b0


@njit(cache=True)
def _exp_into(xi, E):
    """E = exp(xi^) (4 x 4): R = I + a w^ + b w^2, p = (I + b w^ + c w^2) v, coefficients from :mod:`lie`."""
    w0, w1, w2, v0, v1, v2 = xi[0], xi[1], xi[2], xi[3], xi[4], xi[5]
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    a, b, c = _so3_coeffs(np.sqrt(t2))
    # w^2 = w w^T - t2 I
    s00, s11, s22 = w0 * w0 - t2, w1 * w1 - t2, w2 * w2 - t2
    s01, s02, s12 = w0 * w1, w0 * w2, w1 * w2
    E[0, 0] = 1.0 + b * s00
    E[1, 1] = 1.0 + b * s11
    E[2, 2] = 1.0 + b * s22
    E[0, 1] = -a * w2 + b * s01
    E[1, 0] = a * w2 + b * s01
    E[0, 2] = a * w1 + b * s02
    E[2, 0] = -a * w1 + b * s02
    E[1, 2] = -a * w0 + b * s12
    E[2, 1] = a * w0 + b * s12
    E[0, 3] = (1.0 + c * s00) * v0 + (-b * w2 + c * s01) * v1 + (b * w1 + c * s02) * v2
    E[1, 3] = (b * w2 + c * s01) * v0 + (1.0 + c * s11) * v1 + (-b * w0 + c * s12) * v2
    E[2, 3] = (-b * w1 + c * s02) * v0 + (b * w0 + c * s12) * v1 + (1.0 + c * s22) * v2
    E[3, 0] = 0.0
    E[3, 1] = 0.0
    E[3, 2] = 0.0
    E[3, 3] = 1.0


@njit(cache=True)
def _adinv_into(E, A):
    """A = Ad_{E^-1} = [[R^T, 0], [-R^T p^, R^T]]."""
    p0, p1, p2 = E[0, 3], E[1, 3], E[2, 3]
    for i in range(3):
        for j in range(3):
            A[i, j] = E[j, i]
            A[i + 3, j + 3] = E[j, i]
            A[i, j + 3] = 0.0
        # row i of -R^T p^ : -(R^T)_{i,:} p^ ; (p^)_{k,j}
        r0, r1, r2 = E[0, i], E[1, i], E[2, i]
        A[i + 3, 0] = -(r1 * p2 - r2 * p1)
        A[i + 3, 1] = -(r2 * p0 - r0 * p2)
        A[i + 3, 2] = -(r0 * p1 - r1 * p0)


@njit(cache=True)
def _tangent_closed(Om, T):
    r"""T = T(Om) from its 3 x 3 blocks, with :math:`\phi, \rho` the angular and linear parts,
    :math:`s = \phi\cdot\rho`, :math:`\theta = |\phi|` and the coefficients :math:`c_k` of
    :func:`soroshapes.lie.TSE3`: the polynomial in :math:`\mathrm{ad}` reduces (with :math:`\hat\phi^3 =
    -\theta^2\hat\phi`, :math:`\hat\phi\hat\rho\hat\phi = -s\hat\phi`) to

    .. math:: T_\phi = I + \alpha\hat\phi + \gamma(\phi\phi^T - \theta^2 I),\quad
              T_\rho = \alpha\hat\rho + 2sc_3\hat\phi + \gamma(\phi\rho^T + \rho\phi^T) - 2sc_4\phi\phi^T
              - 2s(c_2 - 2\theta^2 c_4) I,

    :math:`\alpha = \theta^2 c_3 - c_1`, :math:`\gamma = c_2 - \theta^2 c_4`; T = [[T_phi, 0], [T_rho, T_phi]]."""
    p0, p1, p2, r0, r1, r2 = Om[0], Om[1], Om[2], Om[3], Om[4], Om[5]
    t2 = p0 * p0 + p1 * p1 + p2 * p2
    c1, c2, c3, c4 = _tse3_coeffs(np.sqrt(t2))
    sd = p0 * r0 + p1 * r1 + p2 * r2
    al = t2 * c3 - c1
    ga = c2 - t2 * c4
    be = 2.0 * sd * c3
    de = -2.0 * sd * c4
    ep = -2.0 * sd * (c2 - 2.0 * t2 * c4)
    ph = (p0, p1, p2)
    rh = (r0, r1, r2)
    for i in range(3):
        for j in range(3):
            tw = ga * ph[i] * ph[j]
            tv = ga * (ph[i] * rh[j] + rh[i] * ph[j]) + de * ph[i] * ph[j]
            if i == j:
                tw += 1.0 - ga * t2
                tv += ep
            T[i, j] = tw
            T[i + 3, j + 3] = tw
            T[i + 3, j] = tv
            T[i, j + 3] = 0.0
    # skew parts: alpha phi^ on the diagonal blocks, alpha rho^ + beta phi^ below
    for (i, j, k, sg) in ((0, 1, 2, -1.0), (0, 2, 1, 1.0), (1, 0, 2, 1.0), (1, 2, 0, -1.0), (2, 0, 1, -1.0),
                          (2, 1, 0, 1.0)):
        T[i, j] += sg * al * ph[k]
        T[i + 3, j + 3] += sg * al * ph[k]
        T[i + 3, j] += sg * (al * rh[k] + be * ph[k])


@njit(cache=True)
def _dtangent_closed(Om, dO, dT):
    r"""dT = dT(Om)[dO], the derivative of :func:`_tangent_closed` along dO (its coefficients differentiated
    with :math:`c_k'/\theta` of :func:`soroshapes.lie._tse3_dcoeffs`)."""
    p0, p1, p2, r0, r1, r2 = Om[0], Om[1], Om[2], Om[3], Om[4], Om[5]
    q0, q1, q2, u0, u1, u2 = dO[0], dO[1], dO[2], dO[3], dO[4], dO[5]
    t2 = p0 * p0 + p1 * p1 + p2 * p2
    th = np.sqrt(t2)
    c1, c2, c3, c4 = _tse3_coeffs(th)
    d1, d2, d3, d4 = _tse3_dcoeffs(th)
    sd = p0 * r0 + p1 * r1 + p2 * r2
    t = p0 * q0 + p1 * q1 + p2 * q2                      # phi . dphi
    ds = q0 * r0 + q1 * r1 + q2 * r2 + p0 * u0 + p1 * u1 + p2 * u2
    al = t2 * c3 - c1
    ga = c2 - t2 * c4
    be = 2.0 * sd * c3
    de = -2.0 * sd * c4
    dal = t * (2.0 * c3 + t2 * d3 - d1)
    dga = t * (d2 - 2.0 * c4 - t2 * d4)
    dbe = 2.0 * (ds * c3 + sd * d3 * t)
    dde = -2.0 * (ds * c4 + sd * d4 * t)
    dep = -2.0 * (ds * (c2 - 2.0 * t2 * c4) + sd * t * (d2 - 4.0 * c4 - 2.0 * t2 * d4))
    ph, rh, dp, dr = (p0, p1, p2), (r0, r1, r2), (q0, q1, q2), (u0, u1, u2)
    for i in range(3):
        for j in range(3):
            pp = ph[i] * ph[j]
            dpp = dp[i] * ph[j] + ph[i] * dp[j]
            tw = dga * pp + ga * dpp
            tv = (dga * (ph[i] * rh[j] + rh[i] * ph[j])
                  + ga * (dp[i] * rh[j] + ph[i] * dr[j] + dr[i] * ph[j] + rh[i] * dp[j]) + dde * pp + de * dpp)
            if i == j:
                tw -= dga * t2 + 2.0 * ga * t
                tv += dep
            dT[i, j] = tw
            dT[i + 3, j + 3] = tw
            dT[i + 3, j] = tv
            dT[i, j + 3] = 0.0
    for (i, j, k, sg) in ((0, 1, 2, -1.0), (0, 2, 1, 1.0), (1, 0, 2, 1.0), (1, 2, 0, -1.0), (2, 0, 1, -1.0),
                          (2, 1, 0, 1.0)):
        w = dal * ph[k] + al * dp[k]
        dT[i, j] += sg * w
        dT[i + 3, j + 3] += sg * w
        dT[i + 3, j] += sg * (dal * rh[k] + al * dr[k] + dbe * ph[k] + be * dp[k])


@njit(cache=True)
def _col_ad(x, r, v, out, k, alpha):
    """out[:, k] += alpha * v * ad_x e_r (column r of ad_x, scaled)."""
    w0, w1, w2, v0, v1, v2 = x[0], x[1], x[2], x[3], x[4], x[5]
    f = alpha * v
    if r == 0:
        out[1, k] += f * w2
        out[2, k] -= f * w1
        out[4, k] += f * v2
        out[5, k] -= f * v1
    elif r == 1:
        out[0, k] -= f * w2
        out[2, k] += f * w0
        out[3, k] -= f * v2
        out[5, k] += f * v0
    elif r == 2:
        out[0, k] += f * w1
        out[1, k] -= f * w0
        out[3, k] += f * v1
        out[4, k] -= f * v0
    elif r == 3:
        out[4, k] += f * w2
        out[5, k] -= f * w1
    elif r == 4:
        out[3, k] -= f * w2
        out[5, k] += f * w0
    else:
        out[3, k] += f * w1
        out[4, k] -= f * w0


@njit(cache=True)
def _strain_at(B, s, j, rows, x0, q, out):
    """out = Theta q + x0 at Gauss point j of segment s, with Theta stored by columns: column k is ``B[s, j, k]``
    in row ``rows[k]`` (indexed element by element: no array-row views, each of which costs a reference-count
    pair)."""
    for r in range(6):
        out[r] = x0[s, j, r]
    for k in range(q.shape[0]):
        out[rows[k]] += B[s, j, k] * q[k]


@njit(cache=True)
def _rate_at(B, s, j, rows, qd, out):
    """out = Theta qd at Gauss point j of segment s (:func:`_strain_at` without the reference strain)."""
    for r in range(6):
        out[r] = 0.0
    for k in range(qd.shape[0]):
        out[rows[k]] += B[s, j, k] * qd[k]


@njit(cache=True)
def _segment(s, q, qd, want_dT, want_dOp, order, h, B, rows, xi0, G, E, Op, dOp, xi1, xi2, xd1, xd2, Om, Omd, tmp,
             Ai, T, dT):
    r"""The Magnus step of segment ``s``: :math:`\Omega`, :math:`\dot\Omega` (``Om``, ``Omd``: rows 4 and 5 of
    the work array ``V``), :math:`\Omega' = \partial\Omega/\partial q` (``Op``) and, if ``want_dOp``, its rate
    (``dOp``, order 4; zeroed otherwise), :math:`E = \exp\hat\Omega`, the next frame ``G[s+1] = G[s] E``,
    ``Ad`` of :math:`E^{-1}` (``Ai``) and the tangent operator ``T`` (and, if ``want_dT``, its derivative
    ``dT`` along :math:`\dot\Omega`). The rows of ``V`` and the blocks of ``S`` come as arguments, made once
    per kinematics pass (a view made per segment costs a reference-count pair)."""
    n = q.shape[0]
    hs = h[s]
    _strain_at(B, s, 0, rows, xi0, q, xi1)
    _rate_at(B, s, 0, rows, qd, xd1)
    for r in range(6):
        for k in range(n):
            Op[r, k] = 0.0
            dOp[r, k] = 0.0
    if order == 2:
        for r in range(6):
            Om[r] = hs * xi1[r]
            Omd[r] = hs * xd1[r]
        for k in range(n):
            Op[rows[k], k] = hs * B[s, 0, k]
    else:
        c = MAGNUS4_C * hs * hs
        _strain_at(B, s, 1, rows, xi0, q, xi2)
        _rate_at(B, s, 1, rows, qd, xd2)
        _adv(xi1, xi2, tmp)
        for r in range(6):
            Om[r] = 0.5 * hs * (xi1[r] + xi2[r]) + c * tmp[r]
        _adv(xd1, xi2, tmp)
        for r in range(6):
            Omd[r] = 0.5 * hs * (xd1[r] + xd2[r]) + c * tmp[r]
        _adv(xi1, xd2, tmp)
        for r in range(6):
            Omd[r] += c * tmp[r]
        # Op = h/2 (B1 + B2) + c (ad_xi1 B2 - ad_xi2 B1);  dOp = c (ad_xd1 B2 - ad_xd2 B1)
        for k in range(n):
            r = rows[k]
            b1, b2 = B[s, 0, k], B[s, 1, k]
            Op[r, k] = 0.5 * hs * (b1 + b2)
            _col_ad(xi1, r, b2, Op, k, c)
            _col_ad(xi2, r, b1, Op, k, -c)
            if want_dOp:
                _col_ad(xd1, r, b2, dOp, k, c)
                _col_ad(xd2, r, b1, dOp, k, -c)
    _exp_into(Om, E)
    for i in range(3):
        for j in range(4):
            v = G[s, i, 0] * E[0, j] + G[s, i, 1] * E[1, j] + G[s, i, 2] * E[2, j]
            if j == 3:
                v += G[s, i, 3]
            G[s + 1, i, j] = v
        G[s + 1, 3, i] = 0.0
    G[s + 1, 3, 3] = 1.0
    _adinv_into(E, Ai)
    _tangent_closed(Om, T)
    if want_dT:
        _dtangent_closed(Om, Omd, dT)


@njit(cache=True)
def _propagate(s, order, rows, Ai, T, Omd, psi, Op, eta, J, AJ, Op3, AJ3):
    r"""Node s+1 from node s: :math:`\psi = T\dot\Omega` (``psi``, row 6 of ``V``), :math:`\eta_{s+1} =
    \mathrm{Ad}_{e^{-\Omega}}\eta_s + \psi`, ``AJ`` = :math:`\mathrm{Ad}_{e^{-\Omega}} J_s` and
    :math:`J_{s+1} = AJ + T\,\Omega'` (sparse columns at order 2), after :func:`_segment` (``Ai``, ``T`` the
    blocks of ``S`` it wrote, ``Omd`` row 5 of ``V``; ``Op3``, ``AJ3`` the (1, 6, n) reshapes of ``Op``, ``AJ``).
    The rows of ``eta`` and ``J`` are indexed element by element (no views)."""
    n = J.shape[2]
    _bvec(T, Omd, psi, 1.0, 0.0)
    x0, x1, x2, x3, x4, x5 = eta[s, 0], eta[s, 1], eta[s, 2], eta[s, 3], eta[s, 4], eta[s, 5]
    for i in range(3):                # eta[s+1] = Ai eta[s] (as _bvec), then + psi
        top = Ai[i, 0] * x0 + Ai[i, 1] * x1 + Ai[i, 2] * x2
        bot = Ai[i + 3, 0] * x0 + Ai[i + 3, 1] * x1 + Ai[i + 3, 2] * x2 + Ai[i, 0] * x3 + Ai[i, 1] * x4 + Ai[i, 2] * x5
        eta[s + 1, i] = 1.0 * top
        eta[s + 1, i + 3] = 1.0 * bot
    for r in range(6):
        eta[s + 1, r] += psi[r]
    _bapply_at(Ai, J, s, AJ3, 0, 1.0, 0.0)
    if order == 2:
        for k in range(n):
            r = rows[k]
            f = Op[r, k]
            for i in range(6):
                J[s + 1, i, k] = AJ[i, k] + T[i, r] * f
    else:
        for r in range(6):
            for k in range(n):
                J[s + 1, r, k] = AJ[r, k]
        _bapply_at(T, Op3, 0, J, s + 1, 1.0, 1.0)


@njit(cache=True)
def kinematics(q, qd, want_rate, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ):
    r"""Frames ``G`` (N+1, 4, 4), body Jacobians ``J`` (N+1, 6, n), body velocities ``eta`` (N+1, 6) and, if
    ``want_rate``, Jacobian rates ``Jd`` (N+1, 6, n) at the nodes, for coordinates ``q`` and rates ``qd``.

    ``h`` (N,) segment lengths [m]; the modal matrix at the Gauss points is stored by columns (it is block
    diagonal: coordinate k drives strain ``rows[k]`` only): ``B`` (N, ng, n) holds
    :math:`\Theta_{rows[k], k}`; ``xi0`` (N, ng, 6) the reference strain there; ``g0`` the base pose;
    ``S, E, V, Op, dOp, AJ`` work arrays of a :class:`soroshapes.beam.BeamData` (separate arguments: numba dispatches tuples slowly).
    """
    n = q.shape[0]
    N = h.shape[0]
    xi1, xi2, xd1, xd2, Om, Omd, psi, tmp = V[0], V[1], V[2], V[3], V[4], V[5], V[6], V[7]
    Ai, T, dT, A = S[_AI], S[_T], S[_DT], S[_TMP]
    Op3, dOp3, AJ3 = Op.reshape((1, 6, n)), dOp.reshape((1, 6, n)), AJ.reshape((1, 6, n))
    G[0, :, :] = g0
    J[0, :, :] = 0.0
    eta[0, :] = 0.0
    if want_rate:
        Jd[0, :, :] = 0.0
    for s in range(N):
        _segment(s, q, qd, want_rate, want_rate, order, h, B, rows, xi0, G, E, Op, dOp, xi1, xi2, xd1, xd2, Om, Omd,
                 tmp, Ai, T, dT)
        _propagate(s, order, rows, Ai, T, Omd, psi, Op, eta, J, AJ, Op3, AJ3)
        if want_rate:
            # Jd[s+1] = Ai Jd[s] - ad_psi AJ + dT Op + T dOp
            _bapply_at(Ai, Jd, s, Jd, s + 1, 1.0, 0.0)
            _ad_into(psi, A)
            _bapply_at(A, AJ3, 0, Jd, s + 1, -1.0, 1.0)
            if order == 2:
                for k in range(n):
                    r = rows[k]
                    f = Op[r, k]
                    for i in range(6):
                        Jd[s + 1, i, k] += dT[i, r] * f
            else:
                _bapply_at(dT, Op3, 0, Jd, s + 1, 1.0, 1.0)
                _bapply_at(T, dOp3, 0, Jd, s + 1, 1.0, 1.0)


@njit(cache=True)
def mass_coriolis_gravity(J, Jd, eta, G, w, Md, ag, M, C, fg, want_c, S, V, Y):
    r"""Generalized mass matrix, Coriolis matrix and gravity force by nodal quadrature (weights ``w``).

    :math:`M = \sum_i w_i J_i^T \mathcal M_i J_i`,
    :math:`C = \sum_i w_i J_i^T (\mathcal M_i \dot J_i + (\mathcal M_i \mathrm{ad}_{\eta_i}
    - \mathrm{ad}_{\eta_i}^T \mathcal M_i) J_i)`,
    :math:`f_g = \sum_i w_i J_i^T \mathcal M_i (0, R_i^T a_g)`, with the sectional inertia per unit length
    :math:`\mathcal M_i = \mathrm{diag}` ``Md[i]`` and the gravity acceleration ``ag`` (spatial, m/s^2).
    ``S``, ``V``, ``Y`` are work arrays of a :class:`soroshapes.beam.BeamData` (``S``, ``V`` and one (6, n) array).
    """
    n = M.shape[0]
    M[:, :] = 0.0
    fg[:] = 0.0
    if want_c:
        C[:, :] = 0.0
    Bm, A, W = S[_W1], S[_W2], V[7]
    for i in range(J.shape[0]):
        wi = w[i]
        if wi == 0.0:
            continue
        for k in range(n):                  # Md indexed element by element (no row view per node)
            for l in range(k, n):
                s = 0.0
                for r in range(6):
                    s += J[i, r, k] * Md[i, r] * J[i, r, l]
                M[k, l] += wi * s
        # gravity: body force density m_lin R^T ag
        for r in range(3):
            W[r] = 0.0
            W[r + 3] = Md[i, r + 3] * (G[i, 0, r] * ag[0] + G[i, 1, r] * ag[1] + G[i, 2, r] * ag[2])
        for k in range(n):
            s = 0.0
            for r in range(3, 6):
                s += J[i, r, k] * W[r]
            fg[k] += wi * s
        if want_c:
            _ad_into(eta[i], A)
            for r in range(6):
                for c in range(6):
                    Bm[r, c] = Md[i, r] * A[r, c] - A[c, r] * Md[i, c]
            for r in range(6):
                for k in range(n):
                    s = Md[i, r] * Jd[i, r, k]
                    for c in range(6):
                        s += Bm[r, c] * J[i, c, k]
                    Y[r, k] = s
            for k in range(n):
                for l in range(n):
                    s = 0.0
                    for r in range(6):
                        s += J[i, r, k] * Y[r, l]
                    C[k, l] += wi * s
    for k in range(n):
        for l in range(k):
            M[k, l] = M[l, k]


@njit(cache=True)
def coriolis_velocity_jacobian(J, Jd, eta, w, Md, C, Cv, S, Y):
    r"""Cv = :math:`\partial (C(q, \dot q)\dot q)/\partial \dot q = C + \sum_i w_i J_i^T(\mathcal M_i \dot J_i -
    \Lambda(\mathcal M_i \eta_i) J_i)` with :math:`\Lambda(y) = \begin{bmatrix} \hat y_\omega & \hat y_v \\
    \hat y_v & 0 \end{bmatrix}` (so that :math:`\mathrm{ad}_x^T y = \Lambda(y) x`). It follows from the
    Maurer-Cartan identity :math:`\dot J(q, w)\dot q = \dot J(q, \dot q) w + \mathrm{ad}_\eta J w` for the body
    Jacobians. The iteration matrix of the implicit integrator uses it (``C`` from :func:`mass_coriolis_gravity`
    at the same state)."""
    n = C.shape[0]
    Cv[:, :] = C
    L, y = S[_W1], S[_W2, 0]
    for i in range(J.shape[0]):
        wi = w[i]
        if wi == 0.0:
            continue
        m = Md[i]
        for r in range(6):
            y[r] = m[r] * eta[i, r]
            for c in range(6):
                L[r, c] = 0.0
        _put_skew(L, 0, 0, y, 0)
        _put_skew(L, 0, 3, y, 3)
        _put_skew(L, 3, 0, y, 3)
        for r in range(6):
            for k in range(n):
                s = m[r] * Jd[i, r, k]
                for c in range(6):
                    s -= L[r, c] * J[i, c, k]
                Y[r, k] = s
        for k in range(n):
            for l in range(n):
                s = 0.0
                for r in range(6):
                    s += J[i, r, k] * Y[r, l]
                Cv[k, l] += wi * s


@njit(cache=True)
def dynamics_terms(q, qd, want_c, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ, w, Md, ag, M,
                   C, fg):
    """:func:`kinematics` then :func:`mass_coriolis_gravity`, in one call."""
    kinematics(q, qd, want_c, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ)
    mass_coriolis_gravity(J, Jd, eta, G, w, Md, ag, M, C, fg, want_c, S, V, AJ)


# ------------------------------------------------------------------------------------------------------------
# vector (matrix-free) dynamics: the fast path of the implicit integrator
# ------------------------------------------------------------------------------------------------------------
@njit(cache=True)
def kinematics_vec(q, qd, order, h, B, rows, xi0, g0, G, J, eta, etad, S, E, V, Op, AJ, W):
    r"""Like :func:`kinematics` but, instead of the Jacobian rates, the vectors :math:`\dot J \dot q` at the
    nodes (``etad``, (N+1, 6)): :math:`\dot\eta_{s+1} = \mathrm{Ad}_{e^{-\Omega}}\dot\eta_s -
    \mathrm{ad}_\psi \eta_{s+1} + dT[\dot\Omega]\dot\Omega + T\,\dot\Omega'\dot q` (no 6 x n rate matrices).
    ``W`` is a (8, 6) work array."""
    N = h.shape[0]
    n = q.shape[0]
    xi1, xi2, xd1, xd2, Om, Omd, psi, tmp = V[0], V[1], V[2], V[3], V[4], V[5], V[6], V[7]
    Ai, T, dT = S[_AI], S[_T], S[_DT]
    Op3, AJ3 = Op.reshape((1, 6, n)), AJ.reshape((1, 6, n))
    G[0, :, :] = g0
    J[0, :, :] = 0.0
    eta[0, :] = 0.0
    etad[0, :] = 0.0
    for s in range(N):
        _segment(s, q, qd, True, False, order, h, B, rows, xi0, G, E, Op, AJ, xi1, xi2, xd1, xd2, Om, Omd, tmp, Ai,
                 T, dT)                                             # AJ: scratch here
        _propagate(s, order, rows, Ai, T, Omd, psi, Op, eta, J, AJ, Op3, AJ3)
        # etad[s+1] = Ai etad[s] - ad_psi eta[s+1] + dT[Omd] Omd (+ T (2c ad_xd1 xd2) at order 4)
        _bvec(Ai, etad[s], etad[s + 1], 1.0, 0.0)
        _adv(psi, eta[s + 1], tmp)
        for r in range(6):
            etad[s + 1, r] -= tmp[r]
        _bvec(dT, Omd, etad[s + 1], 1.0, 1.0)
        if order != 2:
            _adv(xd1, xd2, W[6])
            c = 2.0 * MAGNUS4_C * h[s] * h[s]
            _bvec(T, W[6], etad[s + 1], c, 1.0)


@njit(cache=True)
def generalized_inertial_force(J, eta, etad, G, w, Md, a, ag, pl_nodes, pl_W, pl_spatial, out):
    r"""out = :math:`\sum_i w_i J_i^T [\mathcal M_i (J_i a + \dot J_i \dot q) - \mathrm{ad}_{\eta_i}^T
    \mathcal M_i \eta_i - \mathcal M_i (0, R_i^T a_g)] - \sum_p J_p^T W_p`: inertia and Coriolis minus gravity
    and point wrenches ``pl_W`` (p, 6) at nodes ``pl_nodes`` (spatial if ``pl_spatial``), matrix-free."""
    n = a.shape[0]
    for k in range(n):
        out[k] = 0.0
    F = np.empty(6)
    for i in range(J.shape[0]):
        wi = w[i]
        if wi == 0.0:
            continue
        for r in range(6):                  # Md and eta indexed element by element (no row views)
            s = etad[i, r]
            for k in range(n):
                s += J[i, r, k] * a[k]
            F[r] = Md[i, r] * s
        # - ad_eta^T (M eta) = (w x (m_w * w) + v x (m_v * v), w x (m_v * v))
        e0, e1, e2, e3, e4, e5 = _row6(eta, i)
        mw0, mw1, mw2 = Md[i, 0] * e0, Md[i, 1] * e1, Md[i, 2] * e2
        mv0, mv1, mv2 = Md[i, 3] * e3, Md[i, 4] * e4, Md[i, 5] * e5
        F[0] += e1 * mw2 - e2 * mw1 + e4 * mv2 - e5 * mv1
        F[1] += e2 * mw0 - e0 * mw2 + e5 * mv0 - e3 * mv2
        F[2] += e0 * mw1 - e1 * mw0 + e3 * mv1 - e4 * mv0
        F[3] += e1 * mv2 - e2 * mv1
        F[4] += e2 * mv0 - e0 * mv2
        F[5] += e0 * mv1 - e1 * mv0
        for r in range(3):
            F[r + 3] -= Md[i, r + 3] * (G[i, 0, r] * ag[0] + G[i, 1, r] * ag[1] + G[i, 2, r] * ag[2])
        for k in range(n):
            s = 0.0
            for r in range(6):
                s += J[i, r, k] * F[r]
            out[k] += wi * s
    for p in range(pl_nodes.shape[0]):
        i = pl_nodes[p]
        for r in range(3):
            if pl_spatial[p]:
                F[r] = G[i, 0, r] * pl_W[p, 0] + G[i, 1, r] * pl_W[p, 1] + G[i, 2, r] * pl_W[p, 2]
                F[r + 3] = G[i, 0, r] * pl_W[p, 3] + G[i, 1, r] * pl_W[p, 4] + G[i, 2, r] * pl_W[p, 5]
            else:
                F[r] = pl_W[p, r]
                F[r + 3] = pl_W[p, r + 3]
        for k in range(n):
            s = 0.0
            for r in range(6):
                s += J[i, r, k] * F[r]
            out[k] -= s


# ------------------------------------------------------------------------------------------------------------
# O(N) recursions (Newton-Euler): the residual of the implicit integrator without the 6 x n Jacobians
# ------------------------------------------------------------------------------------------------------------
# The recursions keep their twists and wrenches as 6-tuples of floats (values, not arrays) and index the stored
# arrays element by element: every view of an array row (``eta[s]``, ``SX[s, 0]``, ``X[0]``) costs a call that
# atomically increments the array's reference count and one that decrements it, and the former array form made
# dozens of such calls per piece in each recursion (33 increments in the forward one's own code). The 15-DOF rod
# of ``bench_shapes.py`` (4 pieces): 10.2 -> 6.8 us per step (CPU time, back to back, the same trajectory to the
# last bit; ~3.3 -> ~1.8 us per residual).
@njit(cache=True)
def _ad6(x, y):
    """ad_x y of 6-tuples x = (w, v), y: (w x y_w, v x y_w + w x y_v)."""
    w0, w1, w2, v0, v1, v2 = x
    a0, a1, a2, b0, b1, b2 = y
    return (w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0,
            v1 * a2 - v2 * a1 + w1 * b2 - w2 * b1,
            v2 * a0 - v0 * a2 + w2 * b0 - w0 * b2,
            v0 * a1 - v1 * a0 + w0 * b1 - w1 * b0)


@njit(cache=True)
def _adt6(x, y):
    """ad_x^T y of 6-tuples: (y_w x w + y_v x v, y_v x w)."""
    w0, w1, w2, v0, v1, v2 = x
    a0, a1, a2, b0, b1, b2 = y
    return (a1 * w2 - a2 * w1 + b1 * v2 - b2 * v1,
            a2 * w0 - a0 * w2 + b2 * v0 - b0 * v2,
            a0 * w1 - a1 * w0 + b0 * v1 - b1 * v0,
            b1 * w2 - b2 * w1, b2 * w0 - b0 * w2, b0 * w1 - b1 * w0)


@njit(cache=True)
def _lin6(a, x, b, y):
    """a x + b y of 6-tuples."""
    return (a * x[0] + b * y[0],
            a * x[1] + b * y[1],
            a * x[2] + b * y[2],
            a * x[3] + b * y[3],
            a * x[4] + b * y[4],
            a * x[5] + b * y[5])


@njit(cache=True)
def _series6(u, c1, x1, c2, x2, c3, x3, c4, x4):
    """u - c1 x1 + c2 x2 - c3 x3 + c4 x4 of 6-tuples."""
    return (u[0] - c1 * x1[0] + c2 * x2[0] - c3 * x3[0] + c4 * x4[0],
            u[1] - c1 * x1[1] + c2 * x2[1] - c3 * x3[1] + c4 * x4[1],
            u[2] - c1 * x1[2] + c2 * x2[2] - c3 * x3[2] + c4 * x4[2],
            u[3] - c1 * x1[3] + c2 * x2[3] - c3 * x3[3] + c4 * x4[3],
            u[4] - c1 * x1[4] + c2 * x2[4] - c3 * x3[4] + c4 * x4[4],
            u[5] - c1 * x1[5] + c2 * x2[5] - c3 * x3[5] + c4 * x4[5])


@njit(cache=True)
def _tp6(Om, c, u):
    r"""(T(Om) u, x1, x2, x3, x4): :math:`T u = u - c_1 x_1 + c_2 x_2 - c_3 x_3 + c_4 x_4` with
    :math:`x_k = \mathrm{ad}_\Omega^k u`, the series of :func:`soroshapes.lie.TSE3` applied to a vector
    (``c`` the coefficients c1..c4 of :func:`soroshapes.lie._tse3_coeffs`)."""
    x1 = _ad6(Om, u)
    x2 = _ad6(Om, x1)
    x3 = _ad6(Om, x2)
    x4 = _ad6(Om, x3)
    return _series6(u, c[0], x1, c[1], x2, c[2], x3, c[3], x4), x1, x2, x3, x4


@njit(cache=True)
def _tp6_t(Om, c, y):
    r"""T(Om)^T y (the series of :func:`_tp6` with :math:`\mathrm{ad}^T`, :func:`_adt6`)."""
    x1 = _adt6(Om, y)
    x2 = _adt6(Om, x1)
    x3 = _adt6(Om, x2)
    x4 = _adt6(Om, x3)
    return _series6(y, c[0], x1, c[1], x2, c[2], x3, c[3], x4)


@njit(cache=True)
def _dtp6(Om, u, x1, x2, x3, x4, c, d):
    r"""dT(Om)[u] u, the derivative of T along u applied to u, from the :math:`x_k = \mathrm{ad}^k u` of
    :func:`_tp6`: with :math:`\mathrm{ad}_u u = 0`,

    .. math:: dT[u]u = t(-d_1 x_1 + d_2 x_2 - d_3 x_3 + d_4 x_4) + c_2 y_2 - c_3(y_3 + \mathrm{ad}\,y_2)
              + c_4(y_4 + \mathrm{ad}\,y_3 + \mathrm{ad}^2 y_2),

    :math:`y_k = \mathrm{ad}_u x_{k-1}`, :math:`t = \phi\cdot u_\phi`, ``c`` the coefficients c1..c4 of
    T and ``d`` their derivatives divided by the angle (:func:`soroshapes.lie._tse3_dcoeffs`)."""
    t = Om[0] * u[0] + Om[1] * u[1] + Om[2] * u[2]
    y2 = _ad6(u, x1)
    y3 = _ad6(u, x2)
    y4 = _ad6(u, x3)
    a2 = _ad6(Om, y2)
    a3 = _ad6(Om, y3)
    aa2 = _ad6(Om, a2)
    d1, d2, d3, d4 = d
    c2, c3, c4 = c[1], c[2], c[3]
    return (t * (-d1 * x1[0] + d2 * x2[0] - d3 * x3[0] + d4 * x4[0]) + c2 * y2[0] - c3 * (y3[0] + a2[0])
            + c4 * (y4[0] + a3[0] + aa2[0]),
            t * (-d1 * x1[1] + d2 * x2[1] - d3 * x3[1] + d4 * x4[1]) + c2 * y2[1] - c3 * (y3[1] + a2[1])
            + c4 * (y4[1] + a3[1] + aa2[1]),
            t * (-d1 * x1[2] + d2 * x2[2] - d3 * x3[2] + d4 * x4[2]) + c2 * y2[2] - c3 * (y3[2] + a2[2])
            + c4 * (y4[2] + a3[2] + aa2[2]),
            t * (-d1 * x1[3] + d2 * x2[3] - d3 * x3[3] + d4 * x4[3]) + c2 * y2[3] - c3 * (y3[3] + a2[3])
            + c4 * (y4[3] + a3[3] + aa2[3]),
            t * (-d1 * x1[4] + d2 * x2[4] - d3 * x3[4] + d4 * x4[4]) + c2 * y2[4] - c3 * (y3[4] + a2[4])
            + c4 * (y4[4] + a3[4] + aa2[4]),
            t * (-d1 * x1[5] + d2 * x2[5] - d3 * x3[5] + d4 * x4[5]) + c2 * y2[5] - c3 * (y3[5] + a2[5])
            + c4 * (y4[5] + a3[5] + aa2[5]))


@njit(cache=True)
def _bvec6(A, s, x):
    """A[s] @ x for the block matrix A[s] = [[P, 0], [Q, P]] of a (P, 6, 6) array and a 6-tuple x."""
    x0, x1, x2, x3, x4, x5 = x
    return (A[s, 0, 0] * x0 + A[s, 0, 1] * x1 + A[s, 0, 2] * x2,
            A[s, 1, 0] * x0 + A[s, 1, 1] * x1 + A[s, 1, 2] * x2,
            A[s, 2, 0] * x0 + A[s, 2, 1] * x1 + A[s, 2, 2] * x2,
            A[s, 3, 0] * x0 + A[s, 3, 1] * x1 + A[s, 3, 2] * x2
            + A[s, 0, 0] * x3 + A[s, 0, 1] * x4 + A[s, 0, 2] * x5,
            A[s, 4, 0] * x0 + A[s, 4, 1] * x1 + A[s, 4, 2] * x2
            + A[s, 1, 0] * x3 + A[s, 1, 1] * x4 + A[s, 1, 2] * x5,
            A[s, 5, 0] * x0 + A[s, 5, 1] * x1 + A[s, 5, 2] * x2
            + A[s, 2, 0] * x3 + A[s, 2, 1] * x4 + A[s, 2, 2] * x5)


@njit(cache=True)
def _bvec6_t(A, s, x):
    """A[s]^T @ x for the block matrix A[s] = [[P, 0], [Q, P]] (A^T = [[P^T, Q^T], [0, P^T]]) and a 6-tuple x."""
    x0, x1, x2, x3, x4, x5 = x
    return (A[s, 0, 0] * x0 + A[s, 1, 0] * x1 + A[s, 2, 0] * x2
            + A[s, 3, 0] * x3 + A[s, 4, 0] * x4 + A[s, 5, 0] * x5,
            A[s, 0, 1] * x0 + A[s, 1, 1] * x1 + A[s, 2, 1] * x2
            + A[s, 3, 1] * x3 + A[s, 4, 1] * x4 + A[s, 5, 1] * x5,
            A[s, 0, 2] * x0 + A[s, 1, 2] * x1 + A[s, 2, 2] * x2
            + A[s, 3, 2] * x3 + A[s, 4, 2] * x4 + A[s, 5, 2] * x5,
            A[s, 0, 0] * x3 + A[s, 1, 0] * x4 + A[s, 2, 0] * x5,
            A[s, 0, 1] * x3 + A[s, 1, 1] * x4 + A[s, 2, 1] * x5,
            A[s, 0, 2] * x3 + A[s, 1, 2] * x4 + A[s, 2, 2] * x5)


@njit(cache=True)
def _row6(A, i):
    """Row i of a (m, 6) array as a 6-tuple."""
    return (A[i, 0], A[i, 1], A[i, 2], A[i, 3], A[i, 4], A[i, 5])


@njit(cache=True)
def _put6(A, i, x):
    """Row i of a (m, 6) array = the 6-tuple x."""
    A[i, 0], A[i, 1], A[i, 2], A[i, 3], A[i, 4], A[i, 5] = x


@njit(cache=True)
def _put6_3(A, i, j, x):
    """A[i, j] = the 6-tuple x for a (m, k, 6) array."""
    A[i, j, 0], A[i, j, 1], A[i, j, 2], A[i, j, 3], A[i, j, 4], A[i, j, 5] = x


@njit(cache=True)
def _strains6(B, s, j, rows, xi0, q, qd, a, W):
    r"""The strain, its rate and its acceleration at Gauss point j of piece s as 6-tuples, :math:`\Theta q +
    \xi_\circ`, :math:`\Theta\dot q`, :math:`\Theta a` (summed in rows 27-29 of the work array ``W``)."""
    for r in range(6):
        W[27, r] = xi0[s, j, r]
        W[28, r] = 0.0
        W[29, r] = 0.0
    for k in range(q.shape[0]):
        r = rows[k]
        b = B[s, j, k]
        W[27, r] += b * q[k]
        W[28, r] += b * qd[k]
        W[29, r] += b * a[k]
    return _row6(W, 27), _row6(W, 28), _row6(W, 29)


@njit(cache=True)
def _adinv_at(E, A, s):
    """A[s] = Ad_{E^-1} = [[R^T, 0], [-R^T p^, R^T]] into a (P, 6, 6) array."""
    p0, p1, p2 = E[0, 3], E[1, 3], E[2, 3]
    for i in range(3):
        for j in range(3):
            A[s, i, j] = E[j, i]
            A[s, i + 3, j + 3] = E[j, i]
            A[s, i, j + 3] = 0.0
        r0, r1, r2 = E[0, i], E[1, i], E[2, i]
        A[s, i + 3, 0] = -(r1 * p2 - r2 * p1)
        A[s, i + 3, 1] = -(r2 * p0 - r0 * p2)
        A[s, i + 3, 2] = -(r0 * p1 - r1 * p0)


@njit(cache=True)
def _scale6(a, x):
    """a x of a 6-tuple."""
    return (a * x[0],
            a * x[1],
            a * x[2],
            a * x[3],
            a * x[4],
            a * x[5])


@njit(cache=True)
def _row6_3(A, i, j):
    """A[i, j] of a (m, k, 6) array as a 6-tuple."""
    return (A[i, j, 0], A[i, j, 1], A[i, j, 2], A[i, j, 3], A[i, j, 4], A[i, j, 5])


@njit(cache=True)
def _body6(G, i, w0, w1, w2, w3, w4, w5):
    """The spatial wrench (w0..w5) in the body frame of the pose G[i]: (R^T (w0, w1, w2), R^T (w3, w4, w5))."""
    return (G[i, 0, 0] * w0 + G[i, 1, 0] * w1 + G[i, 2, 0] * w2,
            G[i, 0, 1] * w0 + G[i, 1, 1] * w1 + G[i, 2, 1] * w2,
            G[i, 0, 2] * w0 + G[i, 1, 2] * w1 + G[i, 2, 2] * w2,
            G[i, 0, 0] * w3 + G[i, 1, 0] * w4 + G[i, 2, 0] * w5,
            G[i, 0, 1] * w3 + G[i, 1, 1] * w4 + G[i, 2, 1] * w5,
            G[i, 0, 2] * w3 + G[i, 1, 2] * w4 + G[i, 2, 2] * w5)


@njit(cache=True)
def newton_euler(q, qd, a, order, h, B, rows, xi0, g0, w, Md, ag, pl_nodes, pl_W, pl_spatial, G, eta, acc, SA, SX,
                 E, V, out):
    r"""The generalized inertial force of :func:`generalized_inertial_force`,
    :math:`\sum_i w_i J_i^T F_i - \sum_p J_p^T W_p` with :math:`F_i = \mathcal M_i \alpha_i -
    \mathrm{ad}_{\eta_i}^T\mathcal M_i\eta_i - \mathcal M_i(0, R_i^T a_g)`, by two O(N) recursions instead of the
    6 x n Jacobians (Newton-Euler: the cost grows as N + n, not N n):

    - forward, per piece s: the frame, the twist :math:`\eta_{s+1} = \mathrm{Ad}_{e^{-\Omega}}\eta_s + \psi`,
      :math:`\psi = T\dot\Omega`, and the acceleration twist :math:`\alpha = J a + \dot J\dot q`,
      :math:`\alpha_{s+1} = \mathrm{Ad}_{e^{-\Omega}}\alpha_s - \mathrm{ad}_\psi\eta_{s+1} + dT[\dot\Omega]
      \dot\Omega + T(\Omega' a + 2c\,[\dot\xi_1, \dot\xi_2])` (the bracket at order 4 only);
    - backward, the wrench carried across each piece, :math:`\Lambda_s = w_s F_s + \mathrm{Ad}_{e^{-\Omega_s}}^T
      \Lambda_{s+1}`, and the force :math:`\Omega_s'^T T_s^T \Lambda_{s+1}` it exerts on the coordinates,

    both from :math:`J_{s+1} = \mathrm{Ad}_{e^{-\Omega_s}} J_s + T_s\Omega_s'`. ``T`` and ``dT`` are applied to
    vectors as polynomials in :math:`\mathrm{ad}_\Omega` (:func:`_tp6`, :func:`_dtp6`), never formed.
    ``a`` (n,) the accelerations [unit of q / s^2]; writes ``G``, ``eta``, ``acc`` (P+1, ...), the per-piece
    ``SA`` (P, 6, 6) (Ad of the inverse) and ``SX`` (P, 4, 6) (strains at the two Gauss points,
    :math:`\Omega`, the coefficients c1..c4 of T); ``E`` (4, 4) and ``V`` (32, 6) work arrays; result in ``out``."""
    _ne_forward(q, qd, a, order, h, B, rows, xi0, g0, G, eta, acc, SA, SX, E, V)
    _ne_backward(q.shape[0], order, h, B, rows, w, Md, ag, pl_nodes, pl_W, pl_spatial, _NO_POINT_FORCES, G, eta, acc,
                 SA, SX, V, out)


_NO_POINT_FORCES = np.zeros((0, 3))


@njit(cache=True)
def _ne_forward(q, qd, a, order, h, B, rows, xi0, g0, G, eta, acc, SA, SX, E, V):
    """The forward recursion of :func:`newton_euler`: frames ``G``, twists ``eta``, acceleration twists ``acc``
    and the per-piece operators ``SA``, ``SX`` at (q, qd, a) (rows 27-29 of ``V`` as work space)."""
    P = h.shape[0]
    for i in range(4):
        for j in range(4):
            G[0, i, j] = g0[i, j]
    e = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)           # the twist and the acceleration twist at the piece's start
    al = e
    _put6(eta, 0, e)
    _put6(acc, 0, e)
    for s in range(P):
        hs = h[s]
        xi1, xd1, xa1 = _strains6(B, s, 0, rows, xi0, q, qd, a, V)
        _put6_3(SX, s, 0, xi1)
        if order == 2:
            Om = _scale6(hs, xi1)
            Omd = _scale6(hs, xd1)
            Oa = _scale6(hs, xa1)
        else:
            c = MAGNUS4_C * hs * hs
            hh = 0.5 * hs
            xi2, xd2, xa2 = _strains6(B, s, 1, rows, xi0, q, qd, a, V)
            _put6_3(SX, s, 1, xi2)
            Om = _lin6(hh, _lin6(1.0, xi1, 1.0, xi2), c, _ad6(xi1, xi2))
            Omd = _lin6(hh, _lin6(1.0, xd1, 1.0, xd2), c, _lin6(1.0, _ad6(xd1, xi2), 1.0, _ad6(xi1, xd2)))
            Oa = _lin6(hh, _lin6(1.0, xa1, 1.0, xa2), c, _lin6(1.0, _ad6(xa1, xi2), 1.0, _ad6(xi1, xa2)))
            Oa = _lin6(1.0, Oa, 2.0 * c, _ad6(xd1, xd2))
        _put6_3(SX, s, 2, Om)
        _exp_into(Om, E)
        for i in range(3):
            for j in range(4):
                v = G[s, i, 0] * E[0, j] + G[s, i, 1] * E[1, j] + G[s, i, 2] * E[2, j]
                if j == 3:
                    v += G[s, i, 3]
                G[s + 1, i, j] = v
            G[s + 1, 3, i] = 0.0
        G[s + 1, 3, 3] = 1.0
        _adinv_at(E, SA, s)
        th = np.sqrt(Om[0] * Om[0] + Om[1] * Om[1] + Om[2] * Om[2])
        cc = _tse3_coeffs(th)
        dc = _tse3_dcoeffs(th)
        SX[s, 3, 0], SX[s, 3, 1], SX[s, 3, 2], SX[s, 3, 3] = cc
        psi, x1, x2, x3, x4 = _tp6(Om, cc, Omd)
        dTv = _dtp6(Om, Omd, x1, x2, x3, x4, cc, dc)
        e = _lin6(1.0, _bvec6(SA, s, e), 1.0, psi)
        _put6(eta, s + 1, e)
        y = _tp6(Om, cc, Oa)[0]
        al = _lin6(1.0, _bvec6(SA, s, al), 1.0, _lin6(1.0, _lin6(1.0, dTv, -1.0, _ad6(psi, e)), 1.0, y))
        _put6(acc, s + 1, al)


@njit(cache=True)
def _ne_backward(n, order, h, B, rows, w, Md, ag, pl_nodes, pl_W, pl_spatial, Fp, G, eta, acc, SA, SX, V, out):
    """The backward recursion of :func:`newton_euler` from the state its forward recursion left, into ``out``
    (n,); ``Fp`` (P+1, 3) spatial forces at the points (no moment; e.g. contact), or no rows for none (rows
    27-29 of ``V`` as work space)."""
    P = h.shape[0]
    forces = Fp.shape[0] > 0
    for k in range(n):
        out[k] = 0.0
    l0 = l1 = l2 = l3 = l4 = l5 = 0.0            # the carried wrench
    for i in range(P, 0, -1):
        # the weighted wrench density at point i and the point wrenches there join the carried wrench
        wi = w[i]
        if wi != 0.0:
            m0, m1, m2, m3, m4, m5 = _row6(Md, i)
            e0, e1, e2, e3, e4, e5 = _row6(eta, i)
            mw0, mw1, mw2 = m0 * e0, m1 * e1, m2 * e2
            mv0, mv1, mv2 = m3 * e3, m4 * e4, m5 * e5
            gx = G[i, 0, 0] * ag[0] + G[i, 1, 0] * ag[1] + G[i, 2, 0] * ag[2]
            gy = G[i, 0, 1] * ag[0] + G[i, 1, 1] * ag[1] + G[i, 2, 1] * ag[2]
            gz = G[i, 0, 2] * ag[0] + G[i, 1, 2] * ag[1] + G[i, 2, 2] * ag[2]
            l0 += wi * (m0 * acc[i, 0] + (e1 * mw2 - e2 * mw1 + e4 * mv2 - e5 * mv1))
            l1 += wi * (m1 * acc[i, 1] + (e2 * mw0 - e0 * mw2 + e5 * mv0 - e3 * mv2))
            l2 += wi * (m2 * acc[i, 2] + (e0 * mw1 - e1 * mw0 + e3 * mv1 - e4 * mv0))
            l3 += wi * (m3 * acc[i, 3] + (e1 * mv2 - e2 * mv1) - m3 * gx)
            l4 += wi * (m4 * acc[i, 4] + (e2 * mv0 - e0 * mv2) - m4 * gy)
            l5 += wi * (m5 * acc[i, 5] + (e0 * mv1 - e1 * mv0) - m5 * gz)
        for p in range(pl_nodes.shape[0]):
            if pl_nodes[p] != i:
                continue
            if pl_spatial[p]:
                f0, f1, f2, t0, t1, t2 = _body6(G, i, pl_W[p, 0], pl_W[p, 1], pl_W[p, 2], pl_W[p, 3], pl_W[p, 4],
                                                pl_W[p, 5])
            else:
                f0, f1, f2, t0, t1, t2 = _row6(pl_W, p)
            l0 -= f0
            l1 -= f1
            l2 -= f2
            l3 -= t0
            l4 -= t1
            l5 -= t2
        if forces:
            l3 -= G[i, 0, 0] * Fp[i, 0] + G[i, 1, 0] * Fp[i, 1] + G[i, 2, 0] * Fp[i, 2]
            l4 -= G[i, 0, 1] * Fp[i, 0] + G[i, 1, 1] * Fp[i, 1] + G[i, 2, 1] * Fp[i, 2]
            l5 -= G[i, 0, 2] * Fp[i, 0] + G[i, 1, 2] * Fp[i, 1] + G[i, 2, 2] * Fp[i, 2]
        # piece s = i - 1 carries the wrench (Lambda_i) to the coordinates and to point s
        s = i - 1
        hs = h[s]
        lam = (l0, l1, l2, l3, l4, l5)
        y = _tp6_t(_row6_3(SX, s, 2), (SX[s, 3, 0], SX[s, 3, 1], SX[s, 3, 2], SX[s, 3, 3]), lam)
        _put6(V, 27, y)
        if order == 2:
            for k in range(n):
                out[k] += hs * B[s, 0, k] * V[27, rows[k]]
        else:
            c = MAGNUS4_C * hs * hs
            _put6(V, 28, _adt6(_row6_3(SX, s, 0), y))
            _put6(V, 29, _adt6(_row6_3(SX, s, 1), y))
            for k in range(n):
                r = rows[k]
                b1, b2 = B[s, 0, k], B[s, 1, k]
                out[k] += 0.5 * hs * (b1 + b2) * V[27, r] + c * (b2 * V[28, r] - b1 * V[29, r])
        l0, l1, l2, l3, l4, l5 = _bvec6_t(SA, s, lam)


@njit(cache=True)
def mass_matrix_pieces(order, h, B, rows, w, Md, SA, SX, T, J, Y, Op, M):
    r""":math:`M = \sum_i w_i J_i^T \mathcal M_i J_i` from the per-piece operators that the last
    :func:`newton_euler` pass left in ``SA`` and ``SX`` (no exponentials recomputed; ``T`` a (6, 6) work array):
    :math:`J_{s+1} = \mathrm{Ad}_{e^{-\Omega_s}} J_s + T_s\Omega_s'` into ``J`` (P+1, 6, n), ``Op`` a (6, n)
    work array; the upper triangle is summed, then mirrored."""
    n = M.shape[0]
    P = h.shape[0]
    for k in range(n):
        for l in range(n):
            M[k, l] = 0.0
        for r in range(6):
            J[0, r, k] = 0.0
    for s in range(P):
        hs = h[s]
        _tangent_closed(SX[s, 2], T)
        _bapply(SA[s], J[s], J[s + 1], 1.0, 0.0)
        if order == 2:
            for k in range(n):
                r = rows[k]
                f = hs * B[s, 0, k]
                for i in range(6):
                    J[s + 1, i, k] += T[i, r] * f
        else:
            c = MAGNUS4_C * hs * hs
            for k in range(n):
                for r in range(6):
                    Op[r, k] = 0.0
                r = rows[k]
                b1, b2 = B[s, 0, k], B[s, 1, k]
                Op[r, k] = 0.5 * hs * (b1 + b2)
                _col_ad(SX[s, 0], r, b2, Op, k, c)
                _col_ad(SX[s, 1], r, b1, Op, k, -c)
            _bapply(T, Op, J[s + 1], 1.0, 1.0)
    # M = J^T Y with Y the stacked w_i m_i J_i: one matrix product into M (no allocation, no square roots),
    # then symmetrized (the product's rounding need not be)
    for i in range(P + 1):
        for r in range(6):
            f = w[i] * Md[i, r]
            for k in range(n):
                Y[i, r, k] = f * J[i, r, k]
    Yf = Y.reshape(((P + 1) * 6, n))
    Jf = J.reshape(((P + 1) * 6, n))
    np.dot(Jf.T, Yf, M)
    for k in range(n):
        for l in range(k):
            v = 0.5 * (M[k, l] + M[l, k])
            M[k, l] = v
            M[l, k] = v


# ------------------------------------------------------------------------------------------------------------
# planar beams: bending about the body y axis (+ stretch and shear in the x-z plane) only
# ------------------------------------------------------------------------------------------------------------
#: the strain rows of a planar beam (curvature about y, strains along x and z), in the order of its 3-twists
PLANAR_ROWS = (1, 3, 5)


def is_planar(rows, xi0):
    """Whether a beam moves in its body x-z plane: every coordinate drives a strain row of :data:`PLANAR_ROWS`
    and the reference strain ``xi0`` (..., 6) is zero in the others (then twists, accelerations and the wrench
    that reaches the coordinates stay in the subalgebra se(2) of (omega_y, v_x, v_z), and
    :func:`newton_euler_planar` equals :func:`newton_euler`)."""
    rows = np.asarray(rows).reshape(-1)
    x = np.asarray(xi0).reshape(-1, 6)
    return bool(np.all(np.isin(rows, PLANAR_ROWS)) and not np.any(x[:, [0, 2, 4]]))


@njit(cache=True)
def _adv2(x, y, out):
    """out = ad_x y on 3-twists (omega_y, v_x, v_z): the planar restriction of :func:`_adv`."""
    out[0] = 0.0
    out[1] = x[0] * y[2] - x[2] * y[0]
    out[2] = x[1] * y[0] - x[0] * y[1]


@njit(cache=True)
def _ad3(x, y):
    """ad_x y on 3-twists (omega_y, v_x, v_z) as a 3-tuple: the planar restriction of :func:`_ad6`."""
    return (0.0, x[0] * y[2] - x[2] * y[0], x[1] * y[0] - x[0] * y[1])


@njit(cache=True)
def _adt3(x, y):
    """ad_x^T y on 3-twists and their dual wrenches (m_y, f_x, f_z) as a 3-tuple (:func:`_adt6` restricted)."""
    return (y[2] * x[1] - y[1] * x[2], -y[2] * x[0], y[1] * x[0])


@njit(cache=True)
def _strains3(B, s, j, rows, xi0, q, qd, a, W):
    r"""The strain, its rate and its acceleration at Gauss point j of piece s on 3-twists, as 3-tuples (strain
    row r of coordinate k is planar row (r - 1)/2; summed in rows 27-29 of the work array ``W``)."""
    W[27, 0], W[27, 1], W[27, 2] = xi0[s, j, 1], xi0[s, j, 3], xi0[s, j, 5]
    for r in range(3):
        W[28, r] = 0.0
        W[29, r] = 0.0
    for k in range(q.shape[0]):
        r = (rows[k] - 1) // 2
        b = B[s, j, k]
        W[27, r] += b * q[k]
        W[28, r] += b * qd[k]
        W[29, r] += b * a[k]
    return (W[27, 0], W[27, 1], W[27, 2]), (W[28, 0], W[28, 1], W[28, 2]), (W[29, 0], W[29, 1], W[29, 2])


@njit(cache=True)
def _planar_coeffs(theta):
    r"""The coefficients of T on se(2): :math:`(\beta, \gamma, c_3, c_4)`. On 3-twists
    :math:`\mathrm{ad}_\Omega^3 = -\theta^2\mathrm{ad}_\Omega` (:math:`\theta = \Omega_0`), so the series
    :math:`T = I - c_1\mathrm{ad} + c_2\mathrm{ad}^2 - c_3\mathrm{ad}^3 + c_4\mathrm{ad}^4` of
    :func:`soroshapes.lie._tse3_coeffs` is :math:`T = I - \beta\,\mathrm{ad} + \gamma\,\mathrm{ad}^2` with
    :math:`\beta = c_1 - c_3\theta^2 = (1 - \cos\theta)/\theta^2`, :math:`\gamma = c_2 - c_4\theta^2 =
    (\theta - \sin\theta)/\theta^3`, whose derivatives are :math:`\beta' = -2c_3\theta`, :math:`\gamma' =
    -2c_4\theta` (from :math:`c_1' = \theta^2 c_3'`, :math:`c_2' = \theta^2 c_4'`)."""
    c1, c2, c3, c4 = _tse3_coeffs(abs(theta))
    t2 = theta * theta
    return c1 - c3 * t2, c2 - c4 * t2, c3, c4


@njit(cache=True)
def _tpoly2(Om, cf, u, X, out):
    r"""out = T(Om) u on 3-twists, :math:`u - \beta\,\mathrm{ad}u + \gamma\,\mathrm{ad}^2u` (``cf`` of
    :func:`_planar_coeffs`) (arrays; ``X`` (2, 3) scratch)."""
    _adv2(Om, u, X[0])
    _adv2(Om, X[0], X[1])
    for r in range(3):
        out[r] = u[r] - cf[0] * X[0, r] + cf[1] * X[1, r]


@njit(cache=True)
def _segment2(s, Om, G, A):
    r"""The frame G[s+1] = G[s] exp(Om) of a planar piece (rotation by :math:`\theta` = Om[0] about y, offset
    :math:`(I + b\hat\omega + c\hat\omega^2)v` in the x-z plane) and its Ad of the inverse into A[s, :3, :3]:
    rows (1, 0, 0), :math:`(c p_z + s p_x, c, -s)`, :math:`(s p_z - c p_x, s, c)` (:math:`c = \cos\theta`,
    :math:`s = \sin\theta`)."""
    th = Om[0]
    a, b, cc = _so3_coeffs(abs(th))
    sn = a * th
    cs = 1.0 - b * th * th
    f = 1.0 - cc * th * th
    px = f * Om[1] + b * th * Om[2]
    pz = f * Om[2] - b * th * Om[1]
    for i in range(3):
        g0, g1, g2, g3 = G[s, i, 0], G[s, i, 1], G[s, i, 2], G[s, i, 3]
        G[s + 1, i, 0] = g0 * cs - g2 * sn
        G[s + 1, i, 1] = g1
        G[s + 1, i, 2] = g0 * sn + g2 * cs
        G[s + 1, i, 3] = g0 * px + g2 * pz + g3
        G[s + 1, 3, i] = 0.0
    G[s + 1, 3, 3] = 1.0
    A[s, 0, 0], A[s, 0, 1], A[s, 0, 2] = 1.0, 0.0, 0.0
    A[s, 1, 0], A[s, 1, 1], A[s, 1, 2] = cs * pz + sn * px, cs, -sn
    A[s, 2, 0], A[s, 2, 1], A[s, 2, 2] = sn * pz - cs * px, sn, cs


@njit(cache=True)
def newton_euler_planar(q, qd, a, order, h, B, rows, xi0, g0, w, Md, ag, pl_nodes, pl_W, pl_spatial, G, eta, acc,
                        SA, SX, E, V, out):
    r""":func:`newton_euler` for a beam that moves in its body x-z plane (:func:`is_planar`): the same two
    recursions on 3-twists :math:`(\omega_y, v_x, v_z)` (the subalgebra se(2) is closed under ad and Ad, and the
    out-of-plane part of the wrench, gravity's included, never reaches the coordinates), so the result equals
    the general pass to round-off at about a quarter of its cost. Same arguments and outputs: ``G``, ``eta``
    (zero out of the plane) and ``out``; the per-piece operators are planar (``SA[s, :3, :3]`` the Ad of the
    inverse, ``SX[s, 0:3, :3]`` the strains and :math:`\Omega`, ``SX[s, 3, :4]`` the coefficients of T,
    :func:`_planar_coeffs`) for
    :func:`mass_matrix_planar`; ``acc`` holds the 3-twists in its first three columns."""
    n = q.shape[0]
    P = h.shape[0]
    for i in range(4):
        for j in range(4):
            G[0, i, j] = g0[i, j]
    for r in range(3):
        acc[0, r] = 0.0
    for r in range(6):
        eta[0, r] = 0.0
    e = (0.0, 0.0, 0.0)                 # the twist and the acceleration twist at the current node
    al = e
    for s in range(P):
        hs = h[s]
        xi1, xd1, xa1 = _strains3(B, s, 0, rows, xi0, q, qd, a, V)
        SX[s, 0, 0], SX[s, 0, 1], SX[s, 0, 2] = xi1
        if order == 2:
            Om = (hs * xi1[0], hs * xi1[1], hs * xi1[2])
            Omd = (hs * xd1[0], hs * xd1[1], hs * xd1[2])
            Oa = (hs * xa1[0], hs * xa1[1], hs * xa1[2])
        else:
            c = MAGNUS4_C * hs * hs
            xi2, xd2, xa2 = _strains3(B, s, 1, rows, xi0, q, qd, a, V)
            SX[s, 1, 0], SX[s, 1, 1], SX[s, 1, 2] = xi2
            t = _ad3(xi1, xi2)
            Om = (0.5 * hs * (xi1[0] + xi2[0]) + c * t[0], 0.5 * hs * (xi1[1] + xi2[1]) + c * t[1],
                  0.5 * hs * (xi1[2] + xi2[2]) + c * t[2])
            t, y = _ad3(xd1, xi2), _ad3(xi1, xd2)
            Omd = (0.5 * hs * (xd1[0] + xd2[0]) + c * (t[0] + y[0]), 0.5 * hs * (xd1[1] + xd2[1]) + c * (t[1] + y[1]),
                   0.5 * hs * (xd1[2] + xd2[2]) + c * (t[2] + y[2]))
            t, y = _ad3(xa1, xi2), _ad3(xi1, xa2)
            u = _ad3(xd1, xd2)
            Oa = (0.5 * hs * (xa1[0] + xa2[0]) + c * (t[0] + y[0]) + 2.0 * c * u[0],
                  0.5 * hs * (xa1[1] + xa2[1]) + c * (t[1] + y[1]) + 2.0 * c * u[1],
                  0.5 * hs * (xa1[2] + xa2[2]) + c * (t[2] + y[2]) + 2.0 * c * u[2])
        SX[s, 2, 0], SX[s, 2, 1], SX[s, 2, 2] = Om
        _segment2(s, Om, G, SA)
        b1, b2, c3, c4 = _planar_coeffs(Om[0])
        SX[s, 3, 0], SX[s, 3, 1], SX[s, 3, 2], SX[s, 3, 3] = b1, b2, c3, c4
        # psi = T Omd, dT[Omd] Omd = 2 th Omd_0 (c3 ad Omd - c4 ad^2 Omd) + gamma ad_Omd ad Omd
        x0 = _ad3(Om, Omd)
        x1 = _ad3(Om, x0)
        y0 = _ad3(Omd, x0)
        t2 = 2.0 * Om[0] * Omd[0]
        psi = (Omd[0] - b1 * x0[0] + b2 * x1[0], Omd[1] - b1 * x0[1] + b2 * x1[1], Omd[2] - b1 * x0[2] + b2 * x1[2])
        dTv = (t2 * (c3 * x0[0] - c4 * x1[0]) + b2 * y0[0], t2 * (c3 * x0[1] - c4 * x1[1]) + b2 * y0[1],
               t2 * (c3 * x0[2] - c4 * x1[2]) + b2 * y0[2])
        # the Ad of the piece's inverse (first row (1, 0, 0)) carries the twist and the acceleration twist
        e = (e[0] + psi[0], SA[s, 1, 0] * e[0] + SA[s, 1, 1] * e[1] + SA[s, 1, 2] * e[2] + psi[1],
             SA[s, 2, 0] * e[0] + SA[s, 2, 1] * e[1] + SA[s, 2, 2] * e[2] + psi[2])
        eta[s + 1, 0], eta[s + 1, 1], eta[s + 1, 2] = 0.0, e[0], 0.0
        eta[s + 1, 3], eta[s + 1, 4], eta[s + 1, 5] = e[1], 0.0, e[2]
        z = _ad3(psi, e)
        x0 = _ad3(Om, Oa)
        x1 = _ad3(Om, x0)
        al = (al[0] + (dTv[0] - z[0] + (Oa[0] - b1 * x0[0] + b2 * x1[0])),
              SA[s, 1, 0] * al[0] + SA[s, 1, 1] * al[1] + SA[s, 1, 2] * al[2]
              + (dTv[1] - z[1] + (Oa[1] - b1 * x0[1] + b2 * x1[1])),
              SA[s, 2, 0] * al[0] + SA[s, 2, 1] * al[1] + SA[s, 2, 2] * al[2]
              + (dTv[2] - z[2] + (Oa[2] - b1 * x0[2] + b2 * x1[2])))
        acc[s + 1, 0], acc[s + 1, 1], acc[s + 1, 2] = al
    for k in range(n):
        out[k] = 0.0
    l0 = l1 = l2 = 0.0                  # the carried wrench
    for i in range(P, 0, -1):
        wi = w[i]
        if wi != 0.0:
            m0, m1, m2 = Md[i, 1], Md[i, 3], Md[i, 5]
            ew, ex, ez = eta[i, 1], eta[i, 3], eta[i, 5]
            # M alpha - ad_eta^T M eta - M (0, R^T a_g), in the plane
            l0 += wi * (m0 * acc[i, 0] - (m2 * ez * ex - m1 * ex * ez))
            l1 += wi * ((m1 * acc[i, 1] + m2 * ez * ew) - m1 * (G[i, 0, 0] * ag[0] + G[i, 1, 0] * ag[1]
                                                               + G[i, 2, 0] * ag[2]))
            l2 += wi * ((m2 * acc[i, 2] - m1 * ex * ew) - m2 * (G[i, 0, 2] * ag[0] + G[i, 1, 2] * ag[1]
                                                               + G[i, 2, 2] * ag[2]))
        for p in range(pl_nodes.shape[0]):
            if pl_nodes[p] != i:
                continue
            if pl_spatial[p]:
                l0 -= G[i, 0, 1] * pl_W[p, 0] + G[i, 1, 1] * pl_W[p, 1] + G[i, 2, 1] * pl_W[p, 2]
                l1 -= G[i, 0, 0] * pl_W[p, 3] + G[i, 1, 0] * pl_W[p, 4] + G[i, 2, 0] * pl_W[p, 5]
                l2 -= G[i, 0, 2] * pl_W[p, 3] + G[i, 1, 2] * pl_W[p, 4] + G[i, 2, 2] * pl_W[p, 5]
            else:
                l0 -= pl_W[p, 1]
                l1 -= pl_W[p, 3]
                l2 -= pl_W[p, 5]
        s = i - 1
        hs = h[s]
        Om = (SX[s, 2, 0], SX[s, 2, 1], SX[s, 2, 2])
        b1, b2 = SX[s, 3, 0], SX[s, 3, 1]
        lam = (l0, l1, l2)
        x0 = _adt3(Om, lam)
        x1 = _adt3(Om, x0)
        V[27, 0], V[27, 1], V[27, 2] = (l0 - b1 * x0[0] + b2 * x1[0], l1 - b1 * x0[1] + b2 * x1[1],
                                        l2 - b1 * x0[2] + b2 * x1[2])          # T^T lam
        if order == 2:
            for k in range(n):
                out[k] += hs * B[s, 0, k] * V[27, (rows[k] - 1) // 2]
        else:
            c = MAGNUS4_C * hs * hs
            y = (V[27, 0], V[27, 1], V[27, 2])
            V[28, 0], V[28, 1], V[28, 2] = _adt3((SX[s, 0, 0], SX[s, 0, 1], SX[s, 0, 2]), y)
            V[29, 0], V[29, 1], V[29, 2] = _adt3((SX[s, 1, 0], SX[s, 1, 1], SX[s, 1, 2]), y)
            for k in range(n):
                r = (rows[k] - 1) // 2
                b1, b2 = B[s, 0, k], B[s, 1, k]
                out[k] += 0.5 * hs * (b1 + b2) * V[27, r] + c * (b2 * V[28, r] - b1 * V[29, r])
        l0, l1, l2 = (l0 + SA[s, 1, 0] * l1 + SA[s, 2, 0] * l2, SA[s, 1, 1] * l1 + SA[s, 2, 1] * l2,
                      SA[s, 1, 2] * l1 + SA[s, 2, 2] * l2)


@njit(cache=True)
def mass_matrix_planar(order, h, B, rows, w, Md, SA, SX, T, J, Y, Op, M):
    r""":func:`mass_matrix_pieces` from the planar operators of the last :func:`newton_euler_planar` pass: the
    Jacobians :math:`J_{s+1} = \mathrm{Ad}_{e^{-\Omega_s}} J_s + T_s\Omega_s'` on 3-twists in ``J[:, :3]``, the
    columns of :math:`T_s` by its series (into ``T[:3, :3]``), :math:`M = \sum_i w_i J_i^T \mathcal M_i J_i`
    summed over the upper triangle and mirrored. Same arguments (``Y`` unused; ``T`` (6, 6) holds T and the
    series' scratch)."""
    n = M.shape[0]
    P = h.shape[0]
    X = T[2:6, 3:6]
    e = T[0, 3:6]
    col = T[1, 3:6]
    for k in range(n):
        for l in range(n):
            M[k, l] = 0.0
        for r in range(3):
            J[0, r, k] = 0.0
    for s in range(P):
        hs = h[s]
        Om, cf, A = SX[s, 2, :3], SX[s, 3], SA[s]
        for j in range(3):                                  # T's columns
            for r in range(3):
                e[r] = 0.0
            e[j] = 1.0
            _tpoly2(Om, cf, e, X, col)
            for r in range(3):
                T[r, j] = col[r]
        for k in range(n):
            j0, j1, j2 = J[s, 0, k], J[s, 1, k], J[s, 2, k]
            J[s + 1, 0, k] = j0
            J[s + 1, 1, k] = A[1, 0] * j0 + A[1, 1] * j1 + A[1, 2] * j2
            J[s + 1, 2, k] = A[2, 0] * j0 + A[2, 1] * j1 + A[2, 2] * j2
            pr = (rows[k] - 1) // 2
            if order == 2:
                f = hs * B[s, 0, k]
                for r in range(3):
                    J[s + 1, r, k] += T[r, pr] * f
            else:
                c = MAGNUS4_C * hs * hs
                b1, b2 = B[s, 0, k], B[s, 1, k]
                for r in range(3):                          # Op = h/2 (b1 + b2) e_r + c (b2 ad_xi1 - b1 ad_xi2) e_r
                    e[r] = 0.0
                e[pr] = 1.0
                _adv2(SX[s, 0, :3], e, col)
                for r in range(3):
                    Op[r, k] = c * b2 * col[r]
                _adv2(SX[s, 1, :3], e, col)
                for r in range(3):
                    Op[r, k] -= c * b1 * col[r]
                Op[pr, k] += 0.5 * hs * (b1 + b2)
                for r in range(3):
                    J[s + 1, r, k] += T[r, 0] * Op[0, k] + T[r, 1] * Op[1, k] + T[r, 2] * Op[2, k]
    for i in range(P + 1):
        wi = w[i]
        if wi == 0.0:
            continue
        m0, m1, m2 = wi * Md[i, 1], wi * Md[i, 3], wi * Md[i, 5]
        Ji = J[i]
        for k in range(n):
            a0, a1, a2 = m0 * Ji[0, k], m1 * Ji[1, k], m2 * Ji[2, k]
            for l in range(k, n):
                M[k, l] += a0 * Ji[0, l] + a1 * Ji[1, l] + a2 * Ji[2, l]
    for k in range(n):
        for l in range(k):
            M[k, l] = M[l, k]


@njit(cache=True)
def _lu(A, piv):
    """In-place LU factorization with partial pivoting (Doolittle); returns False if singular."""
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        if big == 0.0:
            return False
        piv[k] = p
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        for i in range(k + 1, n):
            A[i, k] /= A[k, k]
            f = A[i, k]
            for j in range(k + 1, n):
                A[i, j] -= f * A[k, j]
    return True


@njit(cache=True)
def _lu_solve(LU, piv, b):
    """Solve in place with the factors of :func:`_lu`."""
    n = LU.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(n):
        s = b[i]
        for j in range(i):
            s -= LU[i, j] * b[j]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, n):
            s -= LU[i, j] * b[j]
        b[i] = s / LU[i, i]


@njit(cache=True)
def forward_dynamics(q, qd, f_in, K, D, pl_nodes, pl_W, pl_spatial, order, h, B, rows, xi0, g0, w, Md, ag, G, J,
                     eta, acc, SA, SX, E, V, T, Y, Op, M, C, R, piv, qdd):
    r"""Accelerations :math:`\ddot q = M^{-1}(f_{in} - (C\dot q - f_g - \sum_p J_p^T W_p) - D\dot q - Kq)` in one
    compiled call on the O(N) recursions: the bias :math:`C\dot q - f_g - \sum_p J_p^T W_p` is
    :func:`newton_euler` at zero acceleration, :math:`M` comes from the operators of the same pass
    (:func:`mass_matrix_pieces`), then an LU solve. ``f_in`` (n,) the generalized force of the inputs; leaves
    the frames ``G``, twists ``eta``, Jacobians ``J`` and ``M`` of (q, qd) behind; ``T`` (6, 6), ``Y``
    (P+1, 6, n), ``Op`` (6, n), ``C`` (n, n), ``R``, ``piv`` work arrays; ``V`` (32, 6) the recursions' work
    array; result in ``qdd``. Returns False if M is singular or not finite."""
    n = q.shape[0]
    for k in range(n):
        qdd[k] = 0.0
    newton_euler(q, qd, qdd, order, h, B, rows, xi0, g0, w, Md, ag, pl_nodes, pl_W, pl_spatial, G, eta, acc, SA, SX,
                 E, V, R)
    mass_matrix_pieces(order, h, B, rows, w, Md, SA, SX, T, J, Y, Op, M)
    for k in range(n):
        s = f_in[k] - R[k]
        for l in range(n):
            s -= D[k, l] * qd[l] + K[k, l] * q[l]
        qdd[k] = s
        for l in range(n):
            C[k, l] = M[k, l]
    if not _lu(C, piv):
        return False
    _lu_solve(C, piv, qdd)
    return True


@njit(cache=True, inline="always")
def _midpoint_residual(vm, q, qd, dt, fext, K, D, points, order, h, B, rows, xi0, g0, w, Md, ag, G, eta, acc, SA, SX,
                       E, V, qm, a, R, contacts, cwork):
    r"""R = the implicit-midpoint residual at the mean velocity ``vm``: :func:`newton_euler` at
    :math:`q_m = q + \tfrac h2 v_m`, :math:`\dot q = v_m`, :math:`a = 2(v_m - \dot q_n)/h`, with the point
    wrenches ``points`` = (nodes, wrenches, spatial) and the forces of the fixed obstacles' ``contacts``
    (:func:`_contact_forces`, into ``cwork`` = (Fp, Kc, Cc)) at the points, plus :math:`D v_m + K q_m - f_{ext}`
    (``D`` with no rows: no damping). Returns :math:`|R|` (not finite when the state overflowed or a contact force
    was not finite). Inlined (numba IR) where it is called: a call of a kernel with some thirty array arguments
    costs a noticeable part of the residual of a 4-piece rod (the 15-DOF rod of ``bench_shapes.py`` in
    :func:`integrate_midpoint`, quiet machine, back to back: 10.7-11.0 -> 9.8-10.0 us per step, the same
    trajectory). At most 30 arguments, or CPython passes them as one tuple, which numba cannot inline. (Inlining
    the recursions it calls too saved another ~1 us per step in a prototype, but their first compilation took
    about a minute more per kernel that inlines them.)"""
    n = q.shape[0]
    pl_nodes, pl_W, pl_spatial = points
    Fp, Kc, Cc = cwork
    for k in range(n):
        qm[k] = q[k] + 0.5 * dt * vm[k]
        a[k] = 2.0 * (vm[k] - qd[k]) / dt
    _ne_forward(qm, vm, a, order, h, B, rows, xi0, g0, G, eta, acc, SA, SX, E, V)
    if contacts[0].shape[0] > 0 and not _contact_forces(contacts, G, eta, Fp, Kc, Cc):
        return np.inf
    _ne_backward(n, order, h, B, rows, w, Md, ag, pl_nodes, pl_W, pl_spatial, Fp, G, eta, acc, SA, SX, V, R)
    damped = D.shape[0] > 0
    nr = 0.0
    for k in range(n):
        s = R[k] - fext[k]
        if damped:
            for l in range(n):
                s += D[k, l] * vm[l]
        for l in range(n):
            s += K[k, l] * qm[l]
        R[k] = s
        nr += s * s
    return np.sqrt(nr)


@njit(cache=True)
def _contact_forces(contacts, G, eta, Fp, Kc, Cc):
    """The spatial forces ``Fp`` (P+1, 3) at the points of the beam's contacts with fixed obstacles, and their
    stiffness and damping matrices ``Kc``, ``Cc`` (P+1, 3, 3) (:func:`soroshapes._contact.contact_nodal`), at the
    frames ``G`` and twists ``eta``. ``contacts``: (table, floats, ops, consts, memo) of
    :func:`soroshapes.beam.lower_contacts`. False if a force is not finite."""
    table, flt, ops, consts, memo = contacts
    for a in range(Fp.shape[0]):
        for j in range(3):
            Fp[a, j] = 0.0
            for l in range(3):
                Kc[a, j, l] = 0.0
                Cc[a, j, l] = 0.0
    Rb = np.eye(3)
    pb = np.zeros(3)
    etab = np.zeros(6)
    W = np.zeros(6)
    for c in range(table.shape[0]):
        o, m, so, sn, co, dv, dp = table[c, 0], table[c, 1], table[c, 2], table[c, 3], table[c, 4], table[c, 5], \
            table[c, 6]
        if not contact_nodal(flt[o:o + m], ops[so:so + sn], consts[co:], dv, dp, G, eta, Rb, pb, etab, Fp, W,
                             memo[c], Kc, Cc):
            return False
    return True


@njit(cache=True)
def _add_contact_matrix(J, G, Kc, Cc, hk, S):
    r"""Add the contacts' part of the iteration matrix, :math:`\sum_a (R_a J_{a,v})^T (h_k K_{c,a} + C_{c,a})
    (R_a J_{a,v})` (``hk`` = h/2: :math:`\partial q_m/\partial v_m`), to ``S`` (n, n); ``J`` the Jacobians of
    the points (P+1, 6, n) of :func:`mass_matrix_pieces`."""
    n = S.shape[0]
    A = np.empty((3, 3))
    RJ = np.empty((3, n))
    for a in range(Kc.shape[0]):
        nz = False
        for j in range(3):
            for l in range(3):
                A[j, l] = hk * Kc[a, j, l] + Cc[a, j, l]
                if A[j, l] != 0.0:
                    nz = True
        if not nz:
            continue
        for j in range(3):
            for k in range(n):
                RJ[j, k] = G[a, j, 0] * J[a, 3, k] + G[a, j, 1] * J[a, 4, k] + G[a, j, 2] * J[a, 5, k]
        for k in range(n):
            for j in range(3):
                t = A[j, 0] * RJ[0, k] + A[j, 1] * RJ[1, k] + A[j, 2] * RJ[2, k]
                if t == 0.0:
                    continue
                for l in range(n):
                    S[l, k] += RJ[j, l] * t


@njit(cache=True)
def integrate_midpoint(q, qd, dt, nsteps, rec_every, fext, pl_nodes, pl_W, pl_spatial, K, D, order, h, B, rows,
                       xi0, g0, w, Md, ag, tol, max_it, fd_step, out_t, out_q, out_qd, out_e, out_tip, its, jacs,
                       G, eta, acc, SA, SX, E, V, contacts):
    r"""Implicit-midpoint time stepping in one compiled loop (the fast path of :meth:`Shapes.simulate`).

    Per step, Newton iterations on the mean velocity :math:`v_m` for the residual :math:`R(v_m)` of
    :func:`_midpoint_residual` (its inertial part by the O(N) recursions of :func:`newton_euler`), then
    :math:`q_{n+1} = q_n + h v_m`, :math:`\dot q_{n+1} = 2 v_m - \dot q_n`.

    - Predictor: the exact midpoint step of the equations linearized about the last step,
      :math:`S(v - v_n) = 2M a_n - hKv_n + f_{n+1} - f_n` with :math:`a_n = 2(v_n - \dot q_n)/h` the last
      step's acceleration and :math:`2M/h = S - D - \tfrac h2 K` (so the factored matrix gives it at the cost
      of one solve: exact for a linear rod, whatever modes are unresolved), plus the error this prediction made
      in the last step (the nonlinear part, which varies on the resolved time scale); or :math:`v_m`
      extrapolated from the mean velocities of the last three steps by a constant, linear or quadratic
      polynomial. Each step uses the candidate that would have predicted the last step best. On a 15-DOF rod
      swinging under gravity the first error falls from 1-3 % of :math:`|v_m|` (extrapolation: the top
      modes ring at about the step rate) to ~0.03 %.
    - Iteration matrix: :math:`S = 2M/h + D + \tfrac h2 K` with M assembled from the operators of the residual's
      own pass (:func:`mass_matrix_pieces`), factored and reused while Newton contracts fast: refreshed after a
      step whose contraction rate :math:`\theta = |\Delta_k|/|\Delta_{k-1}|` exceeded ``THETA_REFRESH`` or that
      needed more than ``REFRESH_ITS`` residual evaluations, and every ``REFRESH_STEPS`` steps. The Coriolis and
      configuration terms it leaves out are small at the steps where it is used (measured :math:`\theta \approx
      10^{-3}` on a rod swinging under gravity). A step that fails with it is retried from its best iterate
      (the one after the smallest update) with the complete :math:`\partial R/\partial v_m` there, by forward
      differences of ``R`` (steps ``fd_step`` :math:`\max(|v_{m,k}|, 1)`, the rule of
      :func:`soroshapes.numerics.fd_columns`); after a fresh M-based matrix failed, differenced matrices serve
      the rest of the run.
    - Convergence: :math:`|\Delta v| \le` ``tol`` :math:`|v_m| + 10^{-12}`, or, from the second iteration, the
      error estimate :math:`\theta/(1-\theta)\,|\Delta v|` of the new iterate below the same bound.

    Point wrenches ``pl_W`` (nsteps, p, 6) and generalized forces ``fext`` (nsteps, n) act at the step midpoints;
    ``contacts`` (table, floats, ops, consts, memo) of :func:`soroshapes.beam.lower_contacts`: the beam's
    contacts with fixed obstacles, in the residual at the points' current frames and twists
    (:func:`_contact_forces`), their stiffness and damping in the M-based matrix (:func:`_add_contact_matrix`),
    a table without rows for none.
    Records t, q, qd, (kinetic, potential) and the tip position every ``rec_every`` steps (row 0 the start);
    ``its[k]`` the residual evaluations of Newton in step k, ``jacs[k]`` 1 where the matrix was refreshed from
    M, 2 where by finite differences. Work arrays of a :class:`soroshapes.beam.BeamData` (``G`` ... ``V``).
    Returns the number of steps done (< nsteps when a step failed to converge: the state at that step is in
    ``q``, ``qd``)."""
    n = q.shape[0]
    P = h.shape[0]
    vm = np.empty(n)
    v0 = np.empty(n)
    qm = np.empty(n)
    a = np.empty(n)
    R = np.empty(n)
    R0 = np.empty(n)
    dv = np.empty(n)
    Sm = np.empty((n, n))
    piv = np.zeros(n, dtype=np.int64)
    Jw = np.empty((P + 1, 6, n))
    Yw = np.empty((P + 1, 6, n))
    Opw = np.empty((6, n))
    Tw = np.empty((6, 6))
    vlin = np.zeros(n)              # the linearized step's prediction
    elin = np.zeros(n)              # its error in the last step
    xs = np.empty(n)
    us = np.empty(n)
    hist = np.zeros((3, n))         # mean velocities of the last three steps, newest first
    npf = P + 1 if contacts[0].shape[0] > 0 else 0
    Fp = np.zeros((npf, 3))          # the contacts' forces at the points and their stiffness and damping
    Kc = np.zeros((npf, 3, 3))
    Cc = np.zeros((npf, 3, 3))
    cwork = (Fp, Kc, Cc)
    Dres = D if np.any(D != 0.0) else np.zeros((0, 0))   # the residual skips a zero damping
    nhist = 0
    pord = 2                        # the predictor: extrapolation 0 constant, 1 linear, 2 quadratic; 3 the
                                    # linearized step, 4 the linearized step plus its last error
    have = False                    # a factored matrix exists
    exact_mode = False              # the M-based matrix failed once: finite differences from then on
    since = 0
    refresh = True
    rec = 0
    for step in range(nsteps + 1):
        if step % rec_every == 0 or step == nsteps:
            for k in range(n):
                a[k] = 0.0
            newton_euler(q, qd, a, order, h, B, rows, xi0, g0, w, Md, ag, pl_nodes, pl_W[0], pl_spatial, G, eta,
                         acc, SA, SX, E, V, R)
            kin = 0.0
            pot = 0.0
            for i in range(P + 1):
                for r in range(6):
                    kin += 0.5 * w[i] * Md[i, r] * eta[i, r] * eta[i, r]
                pot -= w[i] * Md[i, 3] * (G[i, 0, 3] * ag[0] + G[i, 1, 3] * ag[1] + G[i, 2, 3] * ag[2])
            for k in range(n):
                s = 0.0
                for l in range(n):
                    s += K[k, l] * q[l]
                pot += 0.5 * q[k] * s
            out_t[rec] = step * dt
            out_q[rec, :] = q
            out_qd[rec, :] = qd
            out_e[rec, 0] = kin
            out_e[rec, 1] = pot
            for r in range(3):
                out_tip[rec, r] = G[P, r, 3]
            rec += 1
        if step == nsteps:
            return nsteps
        if have and nhist > 0:
            # the step of the linearized equations: S (v - v_n) = 2 M a_n - h K v_n + f_{n+1} - f_n, with
            # 2M/h = S - D - h/2 K, a_n = 2 x/h, x = qd_{n+1} - v_n
            for k in range(n):
                xs[k] = 2.0 * (qd[k] - hist[0, k])
                us[k] = dt * qd[k]         # h (x + v_n)
            for k in range(n):
                rhs = fext[step, k] - fext[step - 1, k]
                for l in range(n):
                    rhs -= D[k, l] * xs[l] + K[k, l] * us[l]
                vlin[k] = rhs
            _lu_solve(Sm, piv, vlin)
            for k in range(n):
                vlin[k] += 2.0 * qd[k] - hist[0, k]
        for k in range(n):
            if nhist == 0:
                v0[k] = qd[k]
            elif pord == 3 and have:
                v0[k] = vlin[k]
            elif pord == 4 and have:
                v0[k] = vlin[k] + elin[k]
            elif pord == 0 or nhist == 1:
                v0[k] = hist[0, k]
            elif pord == 1 or nhist == 2:
                v0[k] = 2.0 * hist[0, k] - hist[1, k]
            else:
                v0[k] = 3.0 * hist[0, k] - 3.0 * hist[1, k] + hist[2, k]
        ok = False
        spent = 0
        theta = 0.0
        best = np.inf
        points = (pl_nodes, pl_W[step], pl_spatial)
        for attempt in range(2):        # a step that fails is retried with the complete (differenced) matrix
            exact = exact_mode or attempt == 1
            fresh = refresh or not have or since >= REFRESH_STEPS or attempt == 1
            for k in range(n):
                vm[k] = v0[k]           # the predictor, or on the retry the best iterate of the first attempt
            prev = 0.0
            # one evaluation site (the residual is inlined): at the predictor (it = 0), then after each correction
            for it in range(max_it + 1):
                nr = _midpoint_residual(vm, q, qd, dt, fext[step], K, Dres, points, order, h, B, rows, xi0, g0, w,
                                        Md, ag, G, eta, acc, SA, SX, E, V, qm, a, R, contacts, cwork)
                spent += 1
                if not np.isfinite(nr):
                    if it == 0:
                        return step
                    break
                if it == max_it:
                    break
                if it == 0:
                    if fresh and exact:
                        for k in range(n):
                            R0[k] = R[k]
                        for c in range(n):
                            e = fd_step * max(abs(vm[c]), 1.0)
                            old = vm[c]
                            vm[c] = old + e
                            e = vm[c] - old
                            _midpoint_residual(vm, q, qd, dt, fext[step], K, Dres, points, order, h, B, rows, xi0,
                                               g0, w, Md, ag, G, eta, acc, SA, SX, E, V, qm, a, dv, contacts, cwork)
                            vm[c] = old
                            for k in range(n):
                                Sm[k, c] = (dv[k] - R0[k]) / e
                        for k in range(n):
                            R[k] = R0[k]
                        jacs[step] = 2
                    elif fresh:
                        mass_matrix_pieces(order, h, B, rows, w, Md, SA, SX, Tw, Jw, Yw, Opw, Sm)
                        for k in range(n):
                            for l in range(n):
                                Sm[k, l] = 2.0 * Sm[k, l] / dt + D[k, l] + 0.5 * dt * K[k, l]
                        if npf > 0:
                            _add_contact_matrix(Jw, G, Kc, Cc, 0.5 * dt, Sm)
                        jacs[step] = 1
                    if fresh:
                        have = _lu(Sm, piv)
                        if not have:
                            return step
                        since = 0
                for k in range(n):
                    dv[k] = -R[k]
                _lu_solve(Sm, piv, dv)
                ndv = 0.0
                nv = 0.0
                for k in range(n):
                    vm[k] += dv[k]
                    ndv += dv[k] * dv[k]
                    nv += vm[k] * vm[k]
                ndv = np.sqrt(ndv)
                nv = np.sqrt(nv)
                if not np.isfinite(ndv):
                    break
                if ndv < best:
                    best = ndv
                    for k in range(n):
                        v0[k] = vm[k]
                bound = tol * nv + 1e-12
                if it > 0:
                    theta = ndv / prev
                    if theta >= 1.0:          # not contracting
                        break
                    if theta / (1.0 - theta) * ndv <= bound:
                        ok = True
                if ndv <= bound:
                    ok = True
                if ok:
                    break
                prev = ndv
            if ok:
                break
            if fresh and not exact:
                exact_mode = True        # a fresh M-based matrix was not enough here
        if not ok:
            return step
        its[step] = spent
        since += 1
        refresh = theta > THETA_REFRESH or spent > REFRESH_ITS
        if nhist == 3:                  # the predictor that would have predicted this step best
            e0 = 0.0
            e1 = 0.0
            e2 = 0.0
            e3 = 0.0
            e4 = 0.0
            for k in range(n):
                e0 += (vm[k] - hist[0, k]) ** 2
                e1 += (vm[k] - 2.0 * hist[0, k] + hist[1, k]) ** 2
                e2 += (vm[k] - 3.0 * hist[0, k] + 3.0 * hist[1, k] - hist[2, k]) ** 2
                e3 += (vm[k] - vlin[k]) ** 2
                e4 += (vm[k] - vlin[k] - elin[k]) ** 2
            pord = 0 if e0 <= min(e1, e2) else (1 if e1 <= e2 else 2)
            if e3 < min(e0, e1, e2):
                pord = 3
            if e4 < min(e0, e1, e2, e3):
                pord = 4
        for k in range(n):
            elin[k] = vm[k] - vlin[k]
            hist[2, k] = hist[1, k]
            hist[1, k] = hist[0, k]
            hist[0, k] = vm[k]
            qd[k] = 2.0 * vm[k] - qd[k]
            q[k] += dt * vm[k]
        nhist = min(nhist + 1, 3)
    return nsteps


# ------------------------------------------------------------------------------------------------------------
# inverse kinematics
# ------------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _ik_error(nodes, kinds, targets, wrot, G, J, e, A):
    """Stacked body-frame errors ``e`` and their Jacobian rows ``A`` (see :meth:`Shapes.inverse_kinematics`)."""
    row = 0
    for t in range(nodes.shape[0]):
        i = nodes[t]
        if kinds[t] == 0:   # position: R^T (p* - p), rows 3..5 of J
            for r in range(3):
                s = 0.0
                for c in range(3):
                    s += G[i, c, r] * (targets[t, c, 3] - G[i, c, 3])
                e[row + r] = s
                A[row + r, :] = J[i, 3 + r, :]
            row += 3
        else:               # pose: log(g^-1 g*), angular part scaled by wrot
            x = logSE3(invSE3(G[i]) @ targets[t])
            for r in range(6):
                f = wrot if r < 3 else 1.0
                e[row + r] = f * x[r]
                A[row + r, :] = f * J[i, r, :]
            row += 6
    s = 0.0
    for r in range(row):
        s += e[r] * e[r]
    return np.sqrt(s)


@njit(cache=True)
def ik_solve(q, nodes, kinds, targets, wrot, tol, max_it, lam0, lam_max, K, gain, order, h, B, rows, xi0, g0, G, J, Jd,
             eta, S, E, V, Op, dOp, AJ):
    r"""Levenberg-Marquardt inverse kinematics in one compiled loop (:meth:`Shapes.inverse_kinematics`):
    :math:`\Delta q = A^T (A A^T + \lambda^2 I)^{-1} e`, plus, if ``gain`` > 0, the elastic null-space step
    :math:`-(I - A^\dagger A) K q` scaled to ``gain`` times the task step. Stops at :math:`|e| <` ``tol``, when
    the task step vanishes, or after 10 accepted steps that lower :math:`|e|` by less than 1e-9 relative.
    Updates ``q`` in place and returns (error, iterations, converged)."""
    n = q.shape[0]
    m = 0
    for t in range(kinds.shape[0]):
        m += 3 if kinds[t] == 0 else 6
    e, en = np.empty(m), np.empty(m)
    A, An = np.empty((m, n)), np.empty((m, n))
    qn = np.empty(n)
    zero = np.zeros(n)
    kinematics(q, zero, False, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ)
    err = _ik_error(nodes, kinds, targets, wrot, G, J, e, A)
    lam = lam0
    it = 0
    best, since_best = err, 0
    while err >= tol and it < max_it and since_best < 10:
        it += 1
        AAt = A @ A.T
        for r in range(m):
            AAt[r, r] += lam * lam
        y = np.linalg.solve(AAt, e)
        dq = A.T @ y
        stalled = np.sqrt(np.sum(dq * dq)) < 1e-12 * (1.0 + np.sqrt(np.sum(q * q)))   # the task step
        if gain > 0.0:
            Kq = K @ q
            z = np.linalg.solve(AAt, A @ Kq)
            gnull = -(Kq - A.T @ z)
            ng = np.sqrt(np.sum(gnull * gnull))
            nd = max(np.sqrt(np.sum(dq * dq)), tol)
            if ng > 0.0:
                dq += gain * nd * gnull / ng
        for k in range(n):
            qn[k] = q[k] + dq[k]
        kinematics(qn, zero, False, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ)
        errn = _ik_error(nodes, kinds, targets, wrot, G, J, en, An)
        if errn < err or (gain > 0.0 and errn <= err + tol):
            q[:] = qn
            e[:] = en
            A[:, :] = An
            err = errn
            lam = max(0.5 * lam, 1e-12)
            if stalled:
                break
            if err < best * (1.0 - 1e-9):      # the subtask can keep q moving: stop when |e| stops falling
                best, since_best = err, 0
            else:
                since_best += 1
        else:
            lam *= 4.0
            if lam > lam_max:
                break
    kinematics(q, zero, False, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ)
    return err, it, err < tol
