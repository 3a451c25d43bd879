r"""A tree of bodies (:class:`soroshapes.tree.Tree`) lowered to flat arrays, and its forward dynamics in one
compiled call (private; the public face is :meth:`Tree.system <soroshapes.tree.Tree.system>` and
:meth:`Tree.simulate <soroshapes.tree.Tree.simulate>`).

:func:`lower` packs the tree's description into an integer table (one row per body), one float buffer (each
beam's piece lengths, modal matrix, reference strain and base pose; each body's offset; a link's joint screw and
centre-of-mass frame) and one work buffer (each beam's local kinematics and scratch). :func:`tree_rhs` then
evaluates, with no Python between the bodies,

.. math:: \ddot q_f = M_{ff}^{-1}\big(f_g + Bu + f_{ext} - C\dot q - D\dot q - Kq - M_{fp}\ddot q_p\big)_f

exactly as :func:`soroshapes.tree.accelerations` does: the beams' local kinematics by
:func:`soroshapes._beam.kinematics` (base fixed), every frame hung from its parent by
:func:`soroshapes._tree.attach_upto`, the inertial and gravity forces matrix-free by
:func:`soroshapes._beam.generalized_inertial_force` (with :math:`\dot J\dot q`) and M by
:func:`soroshapes._beam.mass_coriolis_gravity`, then an LU solve over the free coordinates. The prescribed
coordinates' values, rates and accelerations come in ``q``, ``qd``, ``a``.
"""
import math

import numpy as np

from sorofem._numba import njit

from ._beam import _lu, _lu_solve, generalized_inertial_force, kinematics, mass_coriolis_gravity
from ._tree import attach_upto
from .lie import expSE3

__all__ = ["TreeArrays", "lower", "tree_rhs"]

# columns of the body table
_KIND, _PROW, _COL0, _NCOLS, _ROW0, _ROWS, _ORDER, _P, _NG, _FO, _WO, _RO, _COM = range(13)
_BEAM, _LINK = 0, 1


class TreeArrays:
    """The lowered tree (see :func:`lower`): ``args`` is the tuple :func:`tree_rhs` takes before the state."""

    def __init__(self, args, n, free):
        self.args, self.n, self.free = args, n, free


def _beam_work(n, Np):
    """Sizes of one beam's work arrays: local G, J, Jd, eta, then S, E, V, Op, dOp, AJ."""
    return (Np * 16, Np * 6 * n, Np * 6 * n, Np * 6, 216, 16, 48, 6 * n, 6 * n, 6 * n)


def lower(tree):
    """The arrays of :func:`tree_rhs` for ``tree`` (a :class:`~soroshapes.tree.Tree`)."""
    w, Md, K, D, Bu, _, pres, free = tree._arrays()
    bodies = tree._bodies
    n, R = tree.n, len(w)
    tint = np.zeros((len(bodies), 13), np.int64)
    flt, rows_all = [], []
    fo = wo = ro = 0
    for i, b in enumerate(bodies):
        tint[i, _PROW], tint[i, _COL0], tint[i, _NCOLS] = b.parent_row, b.col0, b.ncols
        tint[i, _ROW0], tint[i, _ROWS], tint[i, _FO] = b.row0, b.rows, fo
        flt.append(np.ascontiguousarray(b.offset, dtype=float).reshape(-1))
        fo += 16
        if b.kind == "beam":
            m = b.model
            P, ng = m.h.shape[0], m.B.shape[1]
            tint[i, _KIND], tint[i, _ORDER], tint[i, _P], tint[i, _NG] = _BEAM, m.order, P, ng
            tint[i, _WO], tint[i, _RO] = wo, ro
            for a in (m.h, m.B, m.X0, m.base):
                a = np.ascontiguousarray(a, dtype=float).reshape(-1)
                flt.append(a)
                fo += a.size
            rows_all.append(np.asarray(m.rows, np.int64))
            ro += len(m.rows)
            wo += sum(_beam_work(b.ncols, P + 1))
        else:
            tint[i, _KIND] = _LINK
            tint[i, _COM] = b.com_frame is not None
            flt.append(np.asarray(b.screw, dtype=float))
            flt.append(np.ascontiguousarray(np.eye(4) if b.com_frame is None else b.com_frame, dtype=float)
                       .reshape(-1))
            fo += 22
    tflt = np.concatenate(flt) if flt else np.zeros(0)
    trows = np.concatenate(rows_all) if rows_all else np.zeros(0, np.int64)
    # shared work: world frame (eye, zero J, Jd, eta), the stacked frames, the link's local arrays, M, f, LU
    G, J, Jd, eta, etad = (np.zeros((R, 4, 4)), np.zeros((R, 6, n)), np.zeros((R, 6, n)), np.zeros((R, 6)),
                           np.zeros((R, 6)))
    M, C, fg, S, V, Y = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n), np.zeros((6, 6, 6)), np.zeros((8, 6)), \
        np.zeros((6, n))
    freeidx = np.asarray(free, np.int64)
    nf = len(freeidx)
    LU, piv = np.zeros((nf, nf)), np.zeros(nf, np.int64)
    args = (tint, tflt, np.zeros(wo), trows, np.ascontiguousarray(w), np.ascontiguousarray(Md),
            np.ascontiguousarray(tree.gravity, dtype=float), np.ascontiguousarray(K), np.ascontiguousarray(D),
            np.ascontiguousarray(Bu), freeidx, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv)
    return TreeArrays(args, n, freeidx)


@njit(cache=True)
def _tree_kinematics(tint, tflt, twork, trows, q, qd, G, J, Jd, eta):
    """Frames, tree Jacobians, twists and Jacobian rates of every stacked frame (parents first)."""
    n = q.shape[0]
    eye = np.eye(4)
    zJ = np.zeros((6, n))
    zeta = np.zeros(6)
    Gl = np.zeros((1, 4, 4))
    Jl1 = np.zeros((1, 6, 1))
    Jl0 = np.zeros((1, 6, 0))
    Jdl1 = np.zeros((1, 6, 1))
    etal = np.zeros((1, 6))
    for i in range(tint.shape[0]):
        pr = tint[i, _PROW]
        c0, nb, r0, nr, fo = tint[i, _COL0], tint[i, _NCOLS], tint[i, _ROW0], tint[i, _ROWS], tint[i, _FO]
        X = tflt[fo:fo + 16].reshape((4, 4))
        if pr >= 0:
            gp, Jp, Jdp, etap = G[pr], J[pr], Jd[pr], eta[pr]
        else:
            gp, Jp, Jdp, etap = eye, zJ, zJ, zeta
        if tint[i, _KIND] == _BEAM:
            P, ng, o, wo, ro = tint[i, _P], tint[i, _NG], fo + 16, tint[i, _WO], tint[i, _RO]
            Np = P + 1
            h = tflt[o:o + P]
            o += P
            B = tflt[o:o + P * ng * nb].reshape((P, ng, nb))
            o += P * ng * nb
            X0 = tflt[o:o + P * ng * 6].reshape((P, ng, 6))
            o += P * ng * 6
            base = tflt[o:o + 16].reshape((4, 4))
            w0 = wo
            lG = twork[w0:w0 + Np * 16].reshape((Np, 4, 4))
            w0 += Np * 16
            lJ = twork[w0:w0 + Np * 6 * nb].reshape((Np, 6, nb))
            w0 += Np * 6 * nb
            lJd = twork[w0:w0 + Np * 6 * nb].reshape((Np, 6, nb))
            w0 += Np * 6 * nb
            leta = twork[w0:w0 + Np * 6].reshape((Np, 6))
            w0 += Np * 6
            S = twork[w0:w0 + 216].reshape((6, 6, 6))
            w0 += 216
            E = twork[w0:w0 + 16].reshape((4, 4))
            w0 += 16
            V = twork[w0:w0 + 48].reshape((8, 6))
            w0 += 48
            Op = twork[w0:w0 + 6 * nb].reshape((6, nb))
            w0 += 6 * nb
            dOp = twork[w0:w0 + 6 * nb].reshape((6, nb))
            w0 += 6 * nb
            AJ = twork[w0:w0 + 6 * nb].reshape((6, nb))
            kinematics(q[c0:c0 + nb], qd[c0:c0 + nb], True, tint[i, _ORDER], h, B, trows[ro:ro + nb], X0, base,
                       lG, lJ, lJd, leta, S, E, V, Op, dOp, AJ)
            attach_upto(gp, Jp, Jdp, etap, X, lG, lJ, lJd, leta, c0, True, c0, G[r0:r0 + nr], J[r0:r0 + nr],
                   Jd[r0:r0 + nr], eta[r0:r0 + nr])
        else:
            screw = tflt[fo + 16:fo + 22]
            th, thd = 0.0, 0.0
            if nb:
                th, thd = q[c0], qd[c0]
            Gl[0] = expSE3(screw * th)
            for r in range(6):
                etal[0, r] = screw[r] * thd
                Jl1[0, r, 0] = screw[r]
            if nb:
                attach_upto(gp, Jp, Jdp, etap, X, Gl, Jl1, Jdl1, etal, c0, True, c0, G[r0:r0 + 1], J[r0:r0 + 1],
                       Jd[r0:r0 + 1], eta[r0:r0 + 1])
            else:
                attach_upto(gp, Jp, Jdp, etap, X, Gl, Jl0, Jl0, etal, c0, True, c0, G[r0:r0 + 1], J[r0:r0 + 1],
                       Jd[r0:r0 + 1], eta[r0:r0 + 1])
            if tint[i, _COM]:
                com = tflt[fo + 22:fo + 38].reshape((4, 4))
                Gl[0] = eye
                attach_upto(G[r0], J[r0], Jd[r0], eta[r0], com, Gl, Jl0, Jl0, zeta.reshape((1, 6)), 0, True, c0 + nb,
                       G[r0 + 1:r0 + 2], J[r0 + 1:r0 + 2], Jd[r0 + 1:r0 + 2], eta[r0 + 1:r0 + 2])


@njit(cache=True)
def tree_rhs(tint, tflt, twork, trows, w, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv,
             q, qd, a, u, fext, out):
    r"""Accelerations of the tree into ``out`` (n,): the prescribed entries of ``a`` (their accelerations) are
    copied, the free ones solved from :math:`M_{ff}\ddot q_f = (f_g + Bu + f_{ext} - C\dot q - D\dot q - Kq -
    M_{fp}\ddot q_p)_f` (``a`` holds zeros at the free coordinates). Returns False if the state overflowed or
    :math:`M_{ff}` is singular (``out`` is then undefined)."""
    _tree_kinematics(tint, tflt, twork, trows, q, qd, G, J, Jd, eta)
    return _tree_accelerations(w, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, q, qd,
                               a, u, fext, out)


@njit(cache=True)
def _tree_accelerations(w, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, q, qd, a, u,
                        fext, out):
    """:func:`tree_rhs` after the kinematics (the frames, Jacobians, rates and twists already in G, J, Jd, eta)."""
    n = q.shape[0]
    for i in range(G.shape[0]):
        for r in range(6):
            s = 0.0
            for k in range(n):
                s += Jd[i, r, k] * qd[k]
            etad[i, r] = s
    nodes = np.zeros(0, np.int64)
    pW = np.zeros((0, 6))
    flags = np.zeros(0, np.bool_)
    f = np.empty(n)
    generalized_inertial_force(J, eta, etad, G, w, Md, a, ag, nodes, pW, flags, f)
    mass_coriolis_gravity(J, Jd, eta, G, w, Md, ag, M, C, fg, False, S, V, Y)
    for k in range(n):
        s = -f[k] + fext[k]
        for l in range(n):
            s -= D[k, l] * qd[l] + K[k, l] * q[l]
        for j in range(u.shape[0]):
            s += Bu[k, j] * u[j]
        f[k] = s
    nf = free.shape[0]
    for r in range(nf):
        for c in range(nf):
            i, j = free[r], free[c]
            LU[r, c] = M[i, j] if i <= j else M[j, i]       # mass_coriolis_gravity fills the upper triangle
    rhs = np.empty(nf)
    for r in range(nf):
        rhs[r] = f[free[r]]
    for k in range(n):
        out[k] = a[k]
    if not _lu(LU, piv):
        return False
    _lu_solve(LU, piv, rhs)
    s = 0.0
    for r in range(nf):
        out[free[r]] = rhs[r]
        s += rhs[r]
    return math.isfinite(s)


# ------------------------------------------------------------------------------------------------------------
# the tree as a block of a compiled network (soroshapes.network: kind TREE, its arrays at the end of the tuple)
# ------------------------------------------------------------------------------------------------------------
def block_args(tree, u, force_inputs=False):
    """The arrays of a tree block in a compiled network: those of :func:`tree_rhs`, then the constant inputs
    ``u`` (used when the block has no network inputs for them), zero prescribed accelerations, a zero external
    force, the block's input layout ``[reads u from the network, has n force inputs]`` and the stamp of its
    kinematics (the state (q, qd) whose frames the work arrays hold, NaN: none; :func:`_kinematics_at`). Only a
    tree without prescribed joints (its state is then (q, qd))."""
    low = lower(tree)
    n = tree.n
    ubar = np.zeros(len(tree.inputs)) if u is None else np.ascontiguousarray(u, dtype=float).reshape(-1)
    layout = np.array([int(u is None), int(bool(force_inputs))], np.int64)
    return low.args + (ubar, np.zeros(n), np.zeros(n), layout, np.full(2 * n, np.nan))


def empty_block_args():
    """Arrays of the same types as :func:`block_args` for a network without a tree (one kernel signature)."""
    z1, z2, z3, i1 = np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0, 0)), np.zeros(0, np.int64)
    return (np.zeros((0, 13), np.int64), z1, z1, i1, z1, z2, np.zeros(3), z2, z2, z2, i1, z3, z3, z3, z2, z2, z2,
            z2, z1, np.zeros((6, 6, 6)), np.zeros((8, 6)), z2, z2, i1, z1, z1, z1, np.zeros(2, np.int64), z1)


@njit(cache=True)
def _kinematics_at(tb, x, xo):
    """Make the block's work arrays hold the kinematics (frames, Jacobians, their rates, twists) of the tree state
    ``x[xo:xo + 2n]``: computed unless the stamp says they already do (the contact term and the tree's own
    derivative read them at the same state; a Newton-matrix column that perturbs only the body in contact
    leaves the tree's state, and so its kinematics, as they were)."""
    (tint, tflt, twork, trows, wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, ubar,
     a0, fext, layout, stamp) = tb
    n = K.shape[0]
    same = True
    for k in range(2 * n):
        if not stamp[k] == x[xo + k]:               # NaN (no kinematics yet) is never equal
            same = False
            break
    if same:
        return
    _tree_kinematics(tint, tflt, twork, trows, x[xo:xo + n], x[xo + n:xo + 2 * n], G, J, Jd, eta)
    for k in range(2 * n):
        stamp[k] = x[xo + k]


@njit(cache=True)
def block_kinematics(tb, x, xo):
    """Frames, tree Jacobians and body twists of every stacked frame of the tree block whose state starts at
    ``x[xo]``, in the block's work arrays (computed once per state, :func:`_kinematics_at`); returns (G, J, eta)
    (the arrays of :func:`soroshapes.tree.kinematics`, row :meth:`Tree.row <soroshapes.tree.Tree.row>`). What a
    coupling that reads the tree's frames (contact) uses."""
    _kinematics_at(tb, x, xo)
    return tb[11], tb[12], tb[14]


@njit(cache=True)
def block_input_force(tb, w, wo, bext, xo, f):
    r"""The generalized force on the tree block whose state starts at ``x[xo]`` from outside the tree, into ``f``
    (n,): its inputs :math:`B u` (``w[wo:wo + nu]`` or the constant ones), the force inputs
    ``w[wo + nu:wo + nu + n]`` and the force of the network's compiled couplings ``bext[xo:xo + n]``: the part
    of its equations that reads other systems (differenced for its Newton rows, :func:`block_model_rows`)."""
    (tint, tflt, twork, trows, wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, ubar,
     a0, fext, layout, stamp) = tb
    n = K.shape[0]
    nu = Bu.shape[1] if layout[0] == 1 else 0
    for k in range(n):
        s = fext[k] + bext[xo + k]
        if layout[1] == 1:
            s += w[wo + nu + k]
        for j in range(Bu.shape[1]):
            s += Bu[k, j] * (w[wo + j] if nu else ubar[j])
        f[k] = s
    return True


@njit(cache=True)
def block_model_rows(tb, x, xo, JF):
    r"""The tree block's rows of the network Jacobian ``JF`` (N, N) for the Newton matrix, whose force rows
    :math:`\partial f_{in}/\partial x` (:func:`block_input_force`, differenced by the caller over the columns it
    reads) the caller put in the acceleration rows: the *model rows* :math:`[0\;\; I]` (coordinates) and
    :math:`M^{-1}(\partial f_{in}/\partial x - [K\;\; D])` (accelerations), with the mass matrix :math:`M` at the
    state x. As in the beams' model rows (:func:`soroshapes.network._cheap_rows_of`), the configuration and
    velocity derivatives of the inertial and gravity forces are left out: in :math:`I - cJ` they weigh about
    :math:`c^2 g/L` and :math:`c\,|\dot q|` against 1 (1e-4 and 1e-3 at c = 1.3 ms, L = 0.2 m, 1 rad/s), while
    the couplings' stiffness and damping (a contact's penalty and its regularized friction, which dominate the
    matrix at contact) are kept whole. False if M is singular or a row is not finite."""
    (tint, tflt, twork, trows, wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, ubar,
     a0, fext, layout, stamp) = tb
    n = K.shape[0]
    N = JF.shape[1]
    _kinematics_at(tb, x, xo)
    mass_coriolis_gravity(J, Jd, eta, G, wq, Md, ag, M, C, fg, False, S, V, Y)
    for r in range(n):
        for c in range(n):
            LU[r, c] = M[r, c] if r <= c else M[c, r]       # mass_coriolis_gravity fills the upper triangle
    if not _lu(LU, piv):
        return False
    col = np.empty(n)
    total = 0.0
    for j in range(N):
        nz = False
        for r in range(n):
            v = JF[xo + n + r, j]
            if xo <= j < xo + n:
                v -= K[r, j - xo]
            elif xo + n <= j < xo + 2 * n:
                v -= D[r, j - xo - n]
            col[r] = v
            nz = nz or v != 0.0
        if nz:
            _lu_solve(LU, piv, col)
        for r in range(n):
            JF[xo + n + r, j] = col[r]
            JF[xo + r, j] = 1.0 if j == xo + n + r else 0.0
            total += col[r]
    return math.isfinite(total)


@njit(cache=True)
def block_rhs(tb, x, xo, w, wo, bext, out):
    r"""The derivative :math:`(\dot q, \ddot q)` of the tree block whose state starts at ``x[xo]`` into ``out``:
    its inputs ``w[wo:wo + nu]`` (or the constant ones), plus, with force inputs, the generalized force
    ``w[wo + nu:wo + nu + n]`` (``nu`` = 0 with constant inputs), plus the force that the network's compiled
    couplings put on it (``bext[xo:xo + n]``, contact). False if the state overflowed or M is singular."""
    (tint, tflt, twork, trows, wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, ubar,
     a0, fext, layout, stamp) = tb
    n = K.shape[0]
    nu = Bu.shape[1] if layout[0] == 1 else 0
    q = x[xo:xo + n]
    qd = x[xo + n:xo + 2 * n]
    acc = np.empty(n)
    fe = np.empty(n)
    for k in range(n):
        fe[k] = fext[k] + bext[xo + k]
        if layout[1] == 1:
            fe[k] += w[wo + nu + k]
    _kinematics_at(tb, x, xo)
    if nu:
        ok = _tree_accelerations(wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, q, qd,
                                 a0, w[wo:wo + nu], fe, acc)
    else:
        ok = _tree_accelerations(wq, Md, ag, K, D, Bu, free, G, J, Jd, eta, etad, M, C, fg, S, V, Y, LU, piv, q, qd,
                                 a0, ubar, fe, acc)
    for k in range(n):
        out[xo + k] = qd[k]
        out[xo + n + k] = acc[k]
    return ok
