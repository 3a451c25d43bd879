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

from .lie import Ad, ad6, invSE3


@njit(cache=True)
def attach(gp, Jp, Jdp, etap, X, Gl, Jl, Jdl, etal, col0, rate, G, J, Jd, eta):
    r"""Frames ``G`` (m, 4, 4), tree Jacobians ``J`` (m, 6, n), twists ``eta`` (m, 6) and, if ``rate``, the
    Jacobian rates ``Jd`` of the m local frames ``Gl`` (Jacobians ``Jl`` (m, 6, nb) over the tree coordinates
    ``col0 .. col0 + nb``, rates ``Jdl``, twists ``etal``) hung from the parent frame ``gp`` (``Jp``, ``Jdp``
    (6, n), ``etap`` (6,)) through the offset ``X`` (see the module docstring)."""
    m = Gl.shape[0]
    nb = Jl.shape[2]
    AJ = np.empty((6, Jp.shape[1]))
    for i in range(m):
        h = X @ Gl[i]
        A = Ad(invSE3(h))
        G[i] = gp @ h
        np.dot(A, Jp, AJ)
        J[i] = AJ
        eta[i] = A @ etap
        for r in range(6):
            eta[i, r] += etal[i, r]
            for k in range(nb):
                J[i, r, col0 + k] += Jl[i, r, k]
        if rate:
            Jd[i] = A @ Jdp - ad6(etal[i]) @ AJ
            for r in range(6):
                for k in range(nb):
                    Jd[i, r, col0 + k] += Jdl[i, r, k]
