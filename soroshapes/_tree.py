r"""Numba kernel of the trees of bodies (private; :mod:`soroshapes.tree` is the public face).

One operation composes a body's frames with the frame it hangs from. A body (a beam, or a rigid link after its
joint) has local frames :math:`h_i(q_b)` relative to its attachment frame, with body Jacobians :math:`J^\ell_i`
(6 x n_b, over its own coordinates), their rates and body twists :math:`\eta^\ell_i` relative to that frame
(the beam kernels of :mod:`soroshapes._beam` with a fixed base give exactly these). Hanging the body from a
parent frame :math:`g_p` (tree Jacobian :math:`J_p`, rate :math:`\dot J_p`, twist :math:`\eta_p`) through a
constant offset :math:`X`, with :math:`A_i = \mathrm{Ad}_{(X h_i)^{-1}}`:

.. math::

    g_i = g_p X h_i,\qquad J_i = A_i J_p + [J^\ell_i]_b,\qquad \eta_i = A_i \eta_p + \eta^\ell_i,\qquad
    \dot J_i = A_i \dot J_p - \mathrm{ad}_{\eta^\ell_i} A_i J_p + [\dot J^\ell_i]_b,

where :math:`[\cdot]_b` places the columns at the body's coordinates and :math:`\dot A_i = -\mathrm{ad}_{\eta^\ell_i}
A_i` because :math:`(X h_i)^{-1}\tfrac{d}{dt}(X h_i) = \hat\eta^\ell_i` (X constant). All Jacobians are body
Jacobians (the twist in the frame's own axes, angular part first).
"""
import numpy as np
from sorofem._numba import njit



# Per frame, attach_upto writes Ad of the inverse pose and ad of the local twist into its own 6 x 6 arrays (the
# same arithmetic as lie.Ad(lie.invSE3(h)) and lie.ad6, whose results are new arrays: three allocations per
# frame, about half of attach_upto's time on the manipulator_pick tree's 86 frames)
@njit(cache=True)
def _ad_inverse(h, A):
    r"""A = Ad of the inverse of the pose h, :math:`\mathrm{Ad}_{h^{-1}}` (entries that stay zero untouched)."""
    p0 = p1 = p2 = 0.0
    for j in range(3):
        p0 -= h[j, 0] * h[j, 3]
        p1 -= h[j, 1] * h[j, 3]
        p2 -= h[j, 2] * h[j, 3]
    for i in range(3):
        for j in range(3):
            A[i, j] = h[j, i]
            A[i + 3, j + 3] = h[j, i]
    for j in range(3):
        r0, r1, r2 = h[j, 0], h[j, 1], h[j, 2]
        A[3, j] = p1 * r2 - p2 * r1
        A[4, j] = p2 * r0 - p0 * r2
        A[5, j] = p0 * r1 - p1 * r0


@njit(cache=True)
def _ad_twist(x, i, A):
    """A = ad of the twist x[i] (6,) (entries that stay zero untouched)."""
    w0, w1, w2, v0, v1, v2 = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5]
    for k in (0, 3):
        A[k + 0, k + 1] = -w2
        A[k + 0, k + 2] = w1
        A[k + 1, k + 0] = w2
        A[k + 1, k + 2] = -w0
        A[k + 2, k + 0] = -w1
        A[k + 2, k + 1] = w0
    A[3, 1] = -v2
    A[3, 2] = v1
    A[4, 0] = v2
    A[4, 2] = -v0
    A[5, 0] = -v1
    A[5, 1] = v0


@njit(cache=True)
def attach(gp, Jp, Jdp, etap, X, Gl, Jl, Jdl, etal, col0, rate, G, J, Jd, eta):
    r"""Frames ``G`` (m, 4, 4), tree Jacobians ``J`` (m, 6, n), twists ``eta`` (m, 6) and, if ``rate``, the
    Jacobian rates ``Jd`` of the m local frames ``Gl`` (Jacobians ``Jl`` (m, 6, nb) over the tree coordinates
    ``col0 .. col0 + nb``, rates ``Jdl``, twists ``etal``) hung from the parent frame ``gp`` (``Jp``, ``Jdp``
    (6, n), ``etap`` (6,)) through the offset ``X`` (see the module docstring)."""
    attach_upto(gp, Jp, Jdp, etap, X, Gl, Jl, Jdl, etal, col0, rate, Jp.shape[1], G, J, Jd, eta)


@njit(cache=True)
def attach_upto(gp, Jp, Jdp, etap, X, Gl, Jl, Jdl, etal, col0, rate, ncp, G, J, Jd, eta):
    r""":func:`attach` when the parent's Jacobian and rate are zero beyond column ``ncp`` (a body's parent chain
    owns coordinates added before it: ``ncp = col0``), with explicit loops over those columns only."""
    m = Gl.shape[0]
    nb = Jl.shape[2]
    n = J.shape[2]
    h = np.empty((4, 4))
    A = np.zeros((6, 6))
    ad = np.zeros((6, 6))
    AJ = np.empty((6, ncp))
    for i in range(m):
        for r in range(4):
            for c in range(4):
                h[r, c] = X[r, 0] * Gl[i, 0, c] + X[r, 1] * Gl[i, 1, c] + X[r, 2] * Gl[i, 2, c] + X[r, 3] * Gl[i, 3, c]
        for r in range(4):
            for c in range(4):
                G[i, r, c] = gp[r, 0] * h[0, c] + gp[r, 1] * h[1, c] + gp[r, 2] * h[2, c] + gp[r, 3] * h[3, c]
        _ad_inverse(h, A)
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += A[r, c] * etap[c]
            eta[i, r] = s + etal[i, r]
            for k in range(ncp):
                s = 0.0
                for c in range(6):
                    s += A[r, c] * Jp[c, k]
                AJ[r, k] = s
                J[i, r, k] = s
            for k in range(ncp, n):
                J[i, r, k] = 0.0
            for k in range(nb):
                J[i, r, col0 + k] += Jl[i, r, k]
        if rate:
            _ad_twist(etal, i, ad)
            for r in range(6):
                for k in range(ncp):
                    s = 0.0
                    for c in range(6):
                        s += A[r, c] * Jdp[c, k] - ad[r, c] * AJ[c, k]
                    Jd[i, r, k] = s
                for k in range(ncp, n):
                    Jd[i, r, k] = 0.0
                for k in range(nb):
                    Jd[i, r, col0 + k] += Jdl[i, r, k]
