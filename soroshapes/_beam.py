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
    \dot J_{s+1} = \mathrm{Ad}_{e^{-\Omega}}(\dot J_s - \ldots) - \mathrm{ad}_{\psi}\mathrm{Ad}_{e^{-\Omega}} J_s
                   + dT[\dot\Omega]\,\Omega' + T\,\dot\Omega',

with :math:`\Omega' = \partial\Omega/\partial q` (6 x n), :math:`\psi = T(\Omega)\dot\Omega` and :math:`T`, :math:`dT`
from :mod:`soroshapes.lie`. Because :math:`J` is the exact derivative of the discrete map :math:`q \mapsto g_s(q)`,
the dynamics assembled from it is the exact Lagrangian dynamics of the discrete model (energy is conserved by
the continuous-time equations; :math:`\dot M - 2C` is skew-symmetric).

Every 6 x 6 matrix met here (``ad``, ``Ad`` of a pose's inverse, ``T``, ``dT``) has the block form
:math:`\begin{bmatrix} P & 0 \\ Q & P \end{bmatrix}`; products use that (81 instead of 216 multiplications).
Kernels write into work arrays passed by the caller and allocate nothing.
"""
import numpy as np
from numba import njit

from .lie import _so3_coeffs, _tse3_coeffs, _tse3_dcoeffs

MAGNUS4_C = np.sqrt(3.0) / 12.0
GAUSS2 = (0.5 - np.sqrt(3.0) / 6.0, 0.5 + np.sqrt(3.0) / 6.0)

# indices into the (12, 6, 6) scratch
_A1, _A2, _A3, _A4, _D, _P2, _P3, _P4, _T, _DT, _AI, _TMP = range(12)


def scratch(n):
    """Work arrays of :func:`kinematics` for ``n`` generalized coordinates."""
    return (np.zeros((12, 6, 6)), np.zeros((4, 4)), np.zeros((8, 6)), np.zeros((6, n)), np.zeros((6, n)),
            np.zeros((6, n)))


@njit(cache=True)
def _ad_into(x, A):
    """A = ad_x = [[w^, 0], [v^, w^]]."""
    w0, w1, w2, v0, v1, v2 = x[0], x[1], x[2], x[3], x[4], x[5]
    for i in range(6):
        for j in range(6):
            A[i, j] = 0.0
    for o in (0, 3):
        A[o + 0, o + 1] = -w2
        A[o + 0, o + 2] = w1
        A[o + 1, o + 0] = w2
        A[o + 1, o + 2] = -w0
        A[o + 2, o + 0] = -w1
        A[o + 2, o + 1] = w0
    A[3, 1] = -v2
    A[3, 2] = v1
    A[4, 0] = v2
    A[4, 2] = -v0
    A[5, 0] = -v1
    A[5, 1] = v0


@njit(cache=True)
def _bmm(A, B, C, alpha, beta):
    """C = alpha * A @ B + beta * C for block matrices [[P, 0], [Q, P]]."""
    for i in range(3):
        for j in range(3):
            p = 0.0
            q = 0.0
            for k in range(3):
                p += A[i, k] * B[k, j]
                q += A[i + 3, k] * B[k, j] + A[i, k] * B[k + 3, j]
            C[i, j] = alpha * p + beta * C[i, j]
            C[i + 3, j + 3] = C[i, j]
            C[i + 3, j] = alpha * q + beta * C[i + 3, j]
            C[i, j + 3] = 0.0


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
            Y[i, c] = alpha * top + beta * Y[i, c]
            Y[i + 3, c] = alpha * bot + beta * Y[i + 3, c]


@njit(cache=True)
def _bvec(A, x, y, alpha, beta):
    """y = alpha * A @ x + beta * y for a block matrix A and vectors of length 6."""
    x0, x1, x2, x3, x4, x5 = x[0], x[1], x[2], x[3], x[4], x[5]
    for i in range(3):
        top = A[i, 0] * x0 + A[i, 1] * x1 + A[i, 2] * x2
        bot = A[i + 3, 0] * x0 + A[i + 3, 1] * x1 + A[i + 3, 2] * x2 + A[i, 0] * x3 + A[i, 1] * x4 + A[i, 2] * x5
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
def _tangent_into(Om, Omd, S, want_d):
    """S[_T] = T(Om); if want_d, S[_DT] = dT[Omd] (see :func:`soroshapes.lie.dTSE3`)."""
    theta = np.sqrt(Om[0] * Om[0] + Om[1] * Om[1] + Om[2] * Om[2])
    c1, c2, c3, c4 = _tse3_coeffs(theta)
    A1, A2, A3, A4, T = S[_A1], S[_A2], S[_A3], S[_A4], S[_T]
    _ad_into(Om, A1)
    _bmm(A1, A1, A2, 1.0, 0.0)
    _bmm(A2, A1, A3, 1.0, 0.0)
    _bmm(A3, A1, A4, 1.0, 0.0)
    for i in range(6):
        for j in range(6):
            T[i, j] = -c1 * A1[i, j] + c2 * A2[i, j] - c3 * A3[i, j] + c4 * A4[i, j]
        T[i, i] += 1.0
    if not want_d:
        return
    d1, d2, d3, d4 = _tse3_dcoeffs(theta)
    sd = Om[0] * Omd[0] + Om[1] * Omd[1] + Om[2] * Omd[2]
    D, P2, P3, P4, dT = S[_D], S[_P2], S[_P3], S[_P4], S[_DT]
    _ad_into(Omd, D)
    _bmm(D, A1, P2, 1.0, 0.0)
    _bmm(A1, D, P2, 1.0, 1.0)
    _bmm(P2, A1, P3, 1.0, 0.0)
    _bmm(A2, D, P3, 1.0, 1.0)
    _bmm(P3, A1, P4, 1.0, 0.0)
    _bmm(A3, D, P4, 1.0, 1.0)
    for i in range(6):
        for j in range(6):
            dT[i, j] = (sd * (-d1 * A1[i, j] + d2 * A2[i, j] - d3 * A3[i, j] + d4 * A4[i, j])
                        - c1 * D[i, j] + c2 * P2[i, j] - c3 * P3[i, j] + c4 * P4[i, j])


@njit(cache=True)
def _strain(Bv, rows, x0, q, out):
    """out = Theta q + x0, with Theta stored by columns: column k is ``Bv[k]`` in row ``rows[k]``."""
    for r in range(6):
        out[r] = x0[r]
    for k in range(q.shape[0]):
        out[rows[k]] += Bv[k] * q[k]


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
def kinematics(q, qd, want_rate, order, h, B, rows, xi0, g0, G, J, Jd, eta, S, E, V, Op, dOp, AJ):
    r"""Frames ``G`` (N+1, 4, 4), body Jacobians ``J`` (N+1, 6, n), body velocities ``eta`` (N+1, 6) and, if
    ``want_rate``, Jacobian rates ``Jd`` (N+1, 6, n) at the nodes, for coordinates ``q`` and rates ``qd``.

    ``h`` (N,) segment lengths [m]; the modal matrix at the Gauss points is stored by columns (it is block
    diagonal: coordinate k drives strain ``rows[k]`` only): ``B`` (N, ng, n) holds
    :math:`\Theta_{rows[k], k}`; ``xi0`` (N, ng, 6) the reference strain there; ``g0`` the base pose;
    ``S, E, V, Op, dOp, AJ`` work arrays from :func:`scratch` (separate arguments: numba dispatches tuples slowly).
    """
    n = q.shape[0]
    N = h.shape[0]
    xi1, xi2, xd1, xd2, Om, Omd, psi, tmp = V[0], V[1], V[2], V[3], V[4], V[5], V[6], V[7]
    Ai, T, dT, A = S[_AI], S[_T], S[_DT], S[_TMP]
    zero = np.zeros(6)
    G[0, :, :] = g0
    J[0, :, :] = 0.0
    eta[0, :] = 0.0
    if want_rate:
        Jd[0, :, :] = 0.0
    for s in range(N):
        hs = h[s]
        _strain(B[s, 0], rows, xi0[s, 0], q, xi1)
        _strain(B[s, 0], rows, zero, qd, xd1)
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
            _strain(B[s, 1], rows, xi0[s, 1], q, xi2)
            _strain(B[s, 1], rows, zero, qd, xd2)
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
                if want_rate:
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
        _tangent_into(Om, Omd, S, want_rate)
        # psi = T Omd ; eta[s+1] = Ai eta[s] + psi
        _bvec(T, Omd, psi, 1.0, 0.0)
        _bvec(Ai, eta[s], eta[s + 1], 1.0, 0.0)
        for r in range(6):
            eta[s + 1, r] += psi[r]
        # AJ = Ai J[s] ; J[s+1] = AJ + T Op
        _bapply(Ai, J[s], AJ, 1.0, 0.0)
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
            _bapply(T, Op, J[s + 1], 1.0, 1.0)
        if want_rate:
            # Jd[s+1] = Ai Jd[s] - ad_psi AJ + dT Op + T dOp
            _bapply(Ai, Jd[s], Jd[s + 1], 1.0, 0.0)
            _ad_into(psi, A)
            _bapply(A, AJ, Jd[s + 1], -1.0, 1.0)
            if order == 2:
                for k in range(n):
                    r = rows[k]
                    f = Op[r, k]
                    for i in range(6):
                        Jd[s + 1, i, k] += dT[i, r] * f
            else:
                _bapply(dT, Op, Jd[s + 1], 1.0, 1.0)
                _bapply(T, dOp, Jd[s + 1], 1.0, 1.0)


@njit(cache=True)
def mass_coriolis_gravity(J, Jd, eta, G, w, Md, ag, M, C, fg, want_c):
    r"""Generalized mass matrix, Coriolis matrix and gravity force by nodal quadrature (weights ``w``).

    :math:`M = \sum_i w_i J_i^T \mathcal M_i J_i`,
    :math:`C = \sum_i w_i J_i^T (\mathcal M_i \dot J_i + (\mathcal M_i \mathrm{ad}_{\eta_i}
    - \mathrm{ad}_{\eta_i}^T \mathcal M_i) J_i)`,
    :math:`f_g = \sum_i w_i J_i^T \mathcal M_i (0, R_i^T a_g)`, with the sectional inertia per unit length
    :math:`\mathcal M_i = \mathrm{diag}` ``Md[i]`` and the gravity acceleration ``ag`` (spatial, m/s^2).
    """
    n = M.shape[0]
    M[:, :] = 0.0
    fg[:] = 0.0
    if want_c:
        C[:, :] = 0.0
    Y = np.empty((6, n))
    Bm = np.empty((6, 6))
    A = np.empty((6, 6))
    W = np.empty(6)
    for i in range(J.shape[0]):
        wi = w[i]
        if wi == 0.0:
            continue
        m = Md[i]
        for k in range(n):
            for l in range(k, n):
                s = 0.0
                for r in range(6):
                    s += J[i, r, k] * m[r] * J[i, r, l]
                M[k, l] += wi * s
        # gravity: body force density m_lin R^T ag
        for r in range(3):
            W[r] = 0.0
            W[r + 3] = m[r + 3] * (G[i, 0, r] * ag[0] + G[i, 1, r] * ag[1] + G[i, 2, r] * ag[2])
        for k in range(n):
            s = 0.0
            for r in range(3, 6):
                s += J[i, r, k] * W[r]
            fg[k] += wi * s
        if want_c:
            _ad_into(eta[i], A)
            for r in range(6):
                for c in range(6):
                    Bm[r, c] = m[r] * A[r, c] - A[c, r] * m[c]
            for r in range(6):
                for k in range(n):
                    s = m[r] * Jd[i, r, k]
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
