r"""The implicit integrator family of compiled networks: trapezoidal, implicit midpoint and BDF2, one Newton
solver and one step-splitting rule, run many steps per compiled call.

Methods (step :math:`h`, :math:`\dot x = F(t, x)`; all second order)
---------------------------------------------------------------------
* ``TRAPEZOIDAL``: :math:`x_{k+1} = x_k + \tfrac h2 (F_k + F_{k+1})`, predictor :math:`x_k + hF_k`;
* ``MIDPOINT``: :math:`x_{k+1} = x_k + h F(t_k + \tfrac h2, \tfrac12(x_k + x_{k+1}))`, predictor :math:`x_k + hF_k`;
* ``BDF2``: :math:`x_{k+1} - \tfrac43 x_k + \tfrac13 x_{k-1} = \tfrac23 h F_{k+1}` (L-stable), first step and the
  step after a split trapezoidal; predictor: the quadratic through the last three states (linear after a
  restart).

Newton
------
The residual's iteration matrix is :math:`I - cJ` (:math:`c = h/2` or :math:`2h/3`), block diagonal over the
connected components of the network (systems that read each other's states, closed over couplings; see
:func:`soroshapes.network.lower`), factorized per component every step from

* the Jacobian :math:`J` of :func:`soroshapes.network.jacobian` (grouped forward differences), kept across steps
  and refreshed when Newton contracts slowly (a correction above half the previous one from the third
  iteration on) or fails; for beams it is kept as the *force* Jacobian :math:`M\,\partial\ddot q/\partial x`
  and turned into accelerations with the mass matrix of the current iterate (the inertia changes with the
  configuration much faster than the forces do), and
* the rows of the cheap systems (reservoirs) refreshed at the first iterate of every step
  (:func:`soroshapes.network._cheap_rows`).

Each component iterates on its own (one that has converged is no longer evaluated). It has converged when its
correction :math:`\delta` satisfies :math:`\|\delta\| \le \kappa` or, from the second iteration on, the
rate-based estimate of the remaining error :math:`\tfrac{\theta}{1-\theta}\|\delta\| \le \kappa` with
:math:`\theta = \|\delta_k\|/\|\delta_{k-1}\|` (Hairer & Wanner, Solving ODEs II, IV.8), in the norm
:math:`\|\delta\| = \max_j |\delta_j|/(\text{rtol}|x_j| + \text{atol}\,s_j)` and :math:`\kappa` = ``ntol``
(1e-3 from :meth:`Model.simulate <soroshapes.model.Model.simulate>`). A step that fails (no convergence within
``maxit`` iterations after a fresh Jacobian, or an evaluation out of range) is covered by halved steps down to
``min_dt``; below it :func:`integrate` returns -1 with the time in ``st[7]``.

The Python path of :meth:`Model.simulate <soroshapes.model.Model.simulate>` implements the same methods,
predictors (linear for BDF2), refresh rule and splitting in Python over the whole network (any callable, sparse
LU for large networks, adaptive step doubling); it stops on the plain correction test.
"""
import math

import numpy as np

from sorofem._numba import njit

from ._beam import _lu_solve
from .network import _cheap_rows, _iteration_matrix, jacobian, rhs, assemble

__all__ = ["TRAPEZOIDAL", "MIDPOINT", "BDF2", "integrate"]


@njit(cache=True)
def _solve_component(comps, k, LUc, pivc, r, rc, x1, rtol, atol, scale):
    """The Newton correction of component k with the factors of :func:`_iteration_matrix`, applied to x1;
    returns its weighted size max |dx_j|/(rtol |x_j| + atol s_j) (inf if x1 is no longer finite)."""
    s = 0
    while s < comps.shape[1] and comps[k, s] >= 0:
        rc[s] = r[comps[k, s]]
        s += 1
    _lu_solve(LUc[k, :s, :s], pivc[k, :s], rc[:s])
    nrm = 0.0
    for a in range(s):
        j = comps[k, a]
        x1[j] -= rc[a]
        if not math.isfinite(x1[j]):
            return np.inf
        v = abs(rc[a]) / (rtol * abs(x1[j]) + atol * scale[j])
        if v > nrm:
            nrm = v
    return nrm


#: method codes
TRAPEZOIDAL, MIDPOINT, BDF2 = 0, 1, 2


@njit(cache=True)
def _step(method, t, x0, h, xprev, net, scale, rtol, atol, maxit, ntol, ws, st, x1):
    """One implicit step from (t, x0) into x1; True on success. ``ws``: work arrays; ``st``: statistics and the
    state of the reused iteration matrix (st[4] = 1 when the Jacobian is valid; st[5] = 1 when the quadratic
    BDF2 predictor may use ``ws[12]``, the state before ``xprev``)."""
    (w, f0, fp, xp, r, guess, Jac, JF, LUc, pivc, rc, fx0, pp) = ws
    N = x0.shape[0]
    nb = net[0].shape[0]
    comps, block_comp = net[18], net[19]
    nc = comps.shape[0]
    alls = np.ones(nb, np.bool_)
    only = np.ones(nb, np.bool_)
    conv = np.zeros(nc, np.bool_)
    prevc = np.zeros(nc)
    if method == TRAPEZOIDAL:
        if not rhs(t, x0, net, w, fx0, alls):
            return False
        c = 0.5 * h
        tj = t + h
        for i in range(N):
            guess[i] = x0[i] + h * fx0[i]
    elif method == MIDPOINT:
        if not rhs(t, x0, net, w, fx0, alls):
            return False
        c = 0.5 * h
        tj = t + 0.5 * h
        for i in range(N):
            guess[i] = x0[i] + h * fx0[i]
    else:
        c = 2.0 * h / 3.0
        tj = t + h
        for i in range(N):
            guess[i] = 2.0 * x0[i] - xprev[i]
        if st[5] == 1.0:                                # quadratic extrapolation through three states
            for i in range(N):
                guess[i] = 3.0 * x0[i] - 3.0 * xprev[i] + pp[i]
    for i in range(N):
        x1[i] = guess[i]
    for attempt in range(2):
        fresh = st[4] == 0.0 or attempt == 1
        if fresh:
            for i in range(N):                         # the Jacobian at the guess (first) or at the failed iterate
                xp[i] = x1[i] if method != MIDPOINT else 0.5 * (x0[i] + x1[i])
            xj = xp.copy()
            if not jacobian(tj, xj, net, scale, w, f0, fp, xp, Jac, JF):
                st[4] = 0.0
                return False
            st[3] += 1
            st[4] = 1.0
        for i in range(N):
            x1[i] = guess[i]
        # Newton per connected component: a component that has converged is no longer evaluated
        for k in range(nc):
            conv[k] = False
            prevc[k] = np.inf
        for b in range(nb):
            only[b] = True
        ok = False
        for it in range(maxit):
            if method == TRAPEZOIDAL:
                good = rhs(t + h, x1, net, w, r, only)
                if good:
                    for i in range(N):
                        r[i] = x1[i] - x0[i] - 0.5 * h * (fx0[i] + r[i])
            elif method == MIDPOINT:
                for i in range(N):
                    xp[i] = 0.5 * (x0[i] + x1[i])
                good = rhs(t + 0.5 * h, xp, net, w, r, only)
                if good:
                    for i in range(N):
                        r[i] = x1[i] - x0[i] - h * r[i]
            else:
                good = rhs(t + h, x1, net, w, r, only)
                if good:
                    for i in range(N):
                        r[i] = x1[i] - 4.0 / 3.0 * x0[i] + xprev[i] / 3.0 - c * r[i]
            for bb in range(nb):
                if only[bb]:
                    st[8] += 1
            if not good:
                break
            if it == 0:                 # M at the first iterate, the reservoirs' rows there
                xj = x1.copy()
                if method == MIDPOINT:
                    for i in range(N):
                        xj[i] = 0.5 * (x0[i] + x1[i])
                if not (_cheap_rows(tj, xj, net, scale, w, f0, fp, xp, JF)
                        and _iteration_matrix(c, net, JF, Jac, LUc, pivc)):
                    st[4] = 0.0
                    return False
            st[2] += 1
            finite, slow, done = True, False, True
            for k in range(nc):
                if conv[k]:
                    continue
                nrm = _solve_component(comps, k, LUc, pivc, r, rc, x1, rtol, atol, scale)
                if not math.isfinite(nrm):
                    finite = False
                    break
                prev = prevc[k]
                if nrm <= ntol or (it >= 1 and nrm < prev and nrm * nrm / (prev - nrm) <= ntol):
                    conv[k] = True                     # the rate-based estimate of the remaining error
                else:
                    done = False
                    if it >= 2 and nrm > 0.5 * prev:
                        slow = True                    # contracts slowly: refresh the Jacobian
                prevc[k] = nrm
            if not finite or slow:
                break
            if done:
                ok = True
                break
            for b in range(nb):
                only[b] = not conv[block_comp[b]]
        if ok:
            return True
        finite = True
        for i in range(N):
            if not math.isfinite(x1[i]):
                finite = False
        if not finite:
            for i in range(N):
                x1[i] = guess[i]
        if fresh and attempt == 1:
            break
    st[4] = 0.0
    return False


@njit(cache=True)
def _split(method, t, x, h, hh, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn, tmp):
    """Cover [t, t+h] with steps of hh, halved on failure (down to min_dt) after a failed step; the result in
    xn. Returns the time reached (t + h on success)."""
    st[6] += 1
    end = t + h
    for i in range(x.shape[0]):
        xn[i] = x[i]
    while t < end - 1e-12 * h:
        step = min(hh, end - t)
        for i in range(x.shape[0]):
            tmp[i] = xn[i]
        if not _step(method, t, tmp, step, tmp, net, scale, rtol, atol, maxit, ntol, ws, st, xn):
            for i in range(x.shape[0]):
                xn[i] = tmp[i]
            hh *= 0.5
            if hh < min_dt:
                return t
            continue
        t += step
    return end


@njit(cache=True)
def integrate(x, t0, h, nsteps, method, record_every, min_dt, net, scale, rtol, atol, maxit, ntol, out_t, out_x, out_w,
              st):
    """Fixed-step integration of the network from (t0, x) with ``nsteps`` steps of ``h`` [s] (``method`` a code:
    0 trapezoidal, 1 midpoint, 2 BDF2 with a trapezoidal first step and after a split). Records (t, x, w) every
    ``record_every`` steps and at the end into out_t, out_x, out_w from row 1 (row 0: the caller's start).
    ``st``: steps, rejected, newton_iterations, jacobians, matrix valid, quadratic predictor valid, cut_steps,
    failure time, system evaluations in Newton iterations.
    Returns the number of recorded rows, or -1 when Newton failed down to ``min_dt`` (the time in st[7])."""
    N = x.shape[0]
    NW = out_w.shape[1]
    comps = net[18]
    nc, mc = comps.shape[0], comps.shape[1]
    ws = (np.zeros(NW), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((N, N)),
          np.zeros((N, N)), np.zeros((nc, mc, mc)), np.zeros((nc, mc), np.int64), np.zeros(mc), np.zeros(N),
          np.zeros(N))
    xn, prev, tmp = np.zeros(N), x.copy(), np.zeros(N)
    have_prev = False
    rec = 1
    for k in range(nsteps):
        t = t0 + k * h
        if method == BDF2 and have_prev:
            ok = _step(BDF2, t, x, h, prev, net, scale, rtol, atol, maxit, ntol, ws, st, xn)
            if ok:
                for i in range(N):
                    ws[12][i] = prev[i]
                    prev[i] = x[i]
                st[5] = 1.0
            else:
                st[5] = 0.0
                reached = _split(TRAPEZOIDAL, t, x, h, 0.5 * h, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn,
                                 tmp)
                if reached < t + h - 1e-12 * h:
                    st[7] = reached
                    return -1
                have_prev = False
        else:
            base = TRAPEZOIDAL if method == BDF2 else method
            ok = _step(base, t, x, h, prev, net, scale, rtol, atol, maxit, ntol, ws, st, xn)
            if not ok:
                reached = _split(base, t, x, h, 0.5 * h, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn, tmp)
                if reached < t + h - 1e-12 * h:
                    st[7] = reached
                    return -1
            if method == BDF2:
                for i in range(N):
                    prev[i] = x[i]
                have_prev = True
        for i in range(N):
            x[i] = xn[i]
        st[0] += 1
        if (k + 1) % record_every == 0 or k == nsteps - 1:
            tt = t0 + (k + 1) * h
            out_t[rec] = tt
            for i in range(N):
                out_x[rec, i] = x[i]
            assemble(tt, x, net, out_w[rec])
            rec += 1
    return rec

