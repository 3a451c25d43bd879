r"""The implicit integrator family of compiled networks: trapezoidal, implicit midpoint and BDF2, one Newton
solver, one step-splitting rule and one step-size controller, run many steps per compiled call.

Methods (step :math:`h`, :math:`\dot x = F(t, x)`; all second order)
---------------------------------------------------------------------
* ``TRAPEZOIDAL``: :math:`x_{k+1} = x_k + \tfrac h2 (F_k + F_{k+1})`, predictor :math:`x_k + hF_k`;
* ``MIDPOINT``: :math:`x_{k+1} = x_k + h F(t_k + \tfrac h2, \tfrac12(x_k + x_{k+1}))`, predictor :math:`x_k + hF_k`;
* ``BDF2``: :math:`x_{k+1} - \tfrac43 x_k + \tfrac13 x_{k-1} = \tfrac23 h F_{k+1}` (L-stable), first step and the
  step after a split trapezoidal; predictor: the quadratic through the last three states (linear after a
  restart).

Newton
------
Every method solves :math:`x_1 = \hat x + \gamma F(t_e, x_e)` for :math:`x_1`, with the evaluation point
:math:`x_e = x_1` (trapezoidal: :math:`\hat x = x_k + \tfrac h2 F_k`, :math:`\gamma = h/2`; BDF2:
:math:`\hat x = \tfrac43 x_k - \tfrac13 x_{k-1}`, :math:`\gamma = 2h/3`) or the midpoint (:math:`\hat x = x_k`,
:math:`\gamma = h`); :math:`c = \gamma\,\partial x_e/\partial x_1`. The residual (:func:`soroshapes.network.residual`)
is :math:`x_1 - \hat x - \gamma F(t_e, x_e)` for every system but a beam, whose rows are second order: its
coordinate rows as above and its rate rows the equations of motion in force units at the acceleration the step
implies, :math:`M(q_e)(\dot q_1 - \hat{\dot q})/\gamma + C\dot q_e - f_g + D\dot q_e + Kq_e - f_{in}` (one pass of
the O(N) recursions, no mass matrix solved). The iteration matrix is block diagonal over the connected
components of the network (systems that read each other's states, closed over couplings; see
:func:`soroshapes.network.lower`): :math:`I - cJ` in the rows of every system but a beam's rate rows, which are
:math:`M/\gamma` on its rates minus :math:`c/\gamma` times its force Jacobian: the beam's *model* rows
:math:`\partial f_{in}/\partial x - [K\;\;D]` (the input force in closed form through the inputs' Jacobian, or
differenced over the columns it reads where a coupling has no closed form; as in the
beam's own iteration matrix :math:`2M/h + D + \tfrac h2 K`). Where those rows have no differenced column (every
beam's in closed form, no tree), a step in which Newton fails is retried with fresh model rows at the failed
iterate (as the Python path takes its fresh Jacobian there), and when that fails too, with the differenced Jacobian
:math:`M\,\partial\ddot q/\partial x` of :func:`soroshapes.network.jacobian` there (for that step only: a contact's
onset fails Newton from the predictor whatever the matrix, and the model rows, closed form for beam contacts, cost
a fraction of the differenced Jacobian's evaluation per column); otherwise, once a fresh model matrix failed in a
step, the differenced Jacobian serves the rest of the run (kept across steps, refreshed when Newton contracts slowly
or fails). The rows of the other systems are
in closed form where they have one (reservoirs, linear systems) and differenced otherwise
(:func:`soroshapes.network._cheap_rows`), and :math:`M` is formed from the per-piece operators of the
first iterate's pass whenever the matrix is factored. The matrix is block diagonal over the components, and
each component's block is refreshed on its own (its beams' M, its rows, its factor): at a step after one in
which that component's contraction rate exceeded ``THETA_REFRESH`` or it needed more than ``REFRESH_ITS``
iterations, and after ``REFRESH_STEPS`` steps of service (a valve that saturates in one finger of a hand refreshes
that finger's block, not the hand's); the whole matrix when :math:`c` changes and on a retry after a failure (a
kept matrix, then a fresh one, then the differenced Jacobian).

Each component iterates on its own (one that has converged is no longer evaluated). It has converged when its
correction :math:`\delta` satisfies :math:`\|\delta\| \le \kappa` or, from the second iteration on, the
rate-based estimate of the remaining error :math:`\tfrac{\theta}{1-\theta}\|\delta\| \le \kappa` with
:math:`\theta = \|\delta_k\|/\|\delta_{k-1}\|` (Hairer & Wanner, Solving ODEs II, IV.8). With a matrix kept
from earlier steps the ratio of the first two corrections understates the rate (the first also removes the
predictor's error in the coordinates, which that matrix solves exactly), so at the second correction
:math:`\theta` is the larger of that ratio and the largest rate the same matrix showed at a third correction in
the steps it served (none yet: wait for the third); the rule that refreshes a block whose rate exceeds
``THETA_REFRESH`` keeps that bound honest, and it lets a kept matrix stop after two sweeps. Norm:
:math:`\|\delta\| = \max_j |\delta_j|/(\text{rtol}|x_j| + \text{atol}\,s_j)` and :math:`\kappa` = ``ntol``
(1e-3 from :meth:`Model.simulate <soroshapes.model.Model.simulate>`; a tenth of it with a kept matrix, which
converges linearly). A step that fails (no convergence within ``maxit`` iterations after the retries, or an
evaluation out of range) is covered by halved steps down to ``min_dt``; below it :func:`integrate` returns -1
with the time in ``st[7]``.

Step sizes
----------
:func:`integrate` runs fixed steps (a failed step is covered by halved ones). :func:`integrate_adaptive` controls
the local error; it is the one step-size rule of both paths of :meth:`Model.simulate
<soroshapes.model.Model.simulate>` (``adaptive=True``):

* estimate (Milne's device): with :math:`x_p` the quadratic through the last three states extrapolated to
  :math:`t_k + h` (:func:`lagrange3`; error :math:`-E_p y'''`, :math:`E_p = h(h + h_1)(h + h_1 + h_2)/6` for
  the last steps :math:`h_1, h_2`) and the method's own error :math:`E_c y'''` (trapezoidal :math:`h^3/12`, the
  midpoint rule the same for linear F, variable-step BDF2 :math:`h^2H^2/(6(H + h))`, :math:`H = h + h_1`), the
  local error is :math:`e = E_c/(E_c + E_p)(x_{k+1} - x_p)` (:func:`local_error`), measured by the RMS of
  :math:`e_j/(\text{rtol}\max(|x_{kj}|, |x_{k+1,j}|) + \text{atol}\, s_j)`; the first two steps (no three states
  yet) are not estimated and run at the first step size;
* control (:func:`step_factor`): a step with a norm above 1 is repeated from the same state with
  :math:`h \cdot \max(0.2, 0.9\,\text{err}^{-1/3})`; after an accepted one the next step is
  :math:`h\min(2, 0.9\,\text{err}^{-1/3})`, but kept at :math:`h` when that is less than 1.25 h (a new step size
  costs a new factored matrix, twice with BDF2). A growth of at most 2 keeps variable-step BDF2 zero-stable
  (:math:`\omega < 1 + \sqrt 2`);
* Newton failure: the step is halved, down to ``min_dt``, keeping the history (no restart);
* variable-step BDF2 (step ratio :math:`\omega = h/h_1`): :math:`x_{k+1} - \tfrac{(1+\omega)^2}{1+2\omega}x_k
  + \tfrac{\omega^2}{1+2\omega}x_{k-1} = h\tfrac{1+\omega}{1+2\omega}F_{k+1}`, i.e. :math:`\gamma = h(1 +
  \omega)/(1 + 2\omega)`; the first step trapezoidal;
* output: the trajectory is recorded at the requested output times (:math:`t_0 + k\,\Delta t_{out}` and the end),
  not at the steps: :func:`dense_output` evaluates the quadratic through the step's end and the two states
  before it (second order like the methods; the straight line in the first step).

The Python path of :meth:`Model.simulate <soroshapes.model.Model.simulate>` implements the same methods,
predictors (linear for BDF2), refresh rule, splitting and step-size rule (it calls :func:`local_error`,
:func:`step_factor` and :func:`dense_output`) in Python over the whole network (any callable, sparse LU for large
networks); it stops on the plain correction test.
"""
import math

import numpy as np

from sorofem._numba import njit

from ._beam import REFRESH_ITS, REFRESH_STEPS, _lu_solve
from .network import (BEAM, TREE, _beam_mass_matrix, _beam_mass_of, _cheap_rows_of, _iteration_matrix_of, assemble,
                      jacobian, residual, rhs)

__all__ = ["TRAPEZOIDAL", "MIDPOINT", "BDF2", "integrate", "integrate_adaptive", "workspace", "local_error",
           "step_factor", "lagrange3", "dense_output"]


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


@njit(cache=True)
def _predict(x0, gam, c, net, scale, ws, st, guess):
    r"""The BDF2 predictor of each connected component: the step of the equations linearized about the last
    state :math:`x_k`, :math:`A(x - x_k) = \hat x + \gamma F_k - x_k` (in force units, :math:`\tfrac1\gamma M`
    times it, in a beam's rate rows), with :math:`A` the factored iteration matrix and :math:`F_k = (x_k - \hat
    x_k)/\gamma_k` the derivative the last step's own equations gave (no evaluation: one solve per component;
    exact for a linear network, whatever its stiff modes), or that step plus the error it made in the last step
    (what varies on the resolved time scale: the schedule's drive, the nonlinear part), or the extrapolation
    already in ``guess``; per component the candidate that would have predicted the last step best
    (:func:`_learn`; the linearized step when there is no last one). Needs a valid factor for this ``c`` and
    :math:`F_k` (``st[16]``); ``xq`` keeps the extrapolation, ``xl`` the linearized step (``st[17]`` = 1 when
    it was formed at this step, ``st[19]`` = 1 when the last step's choice and error are known; ``st[18]``
    counts the components predicted by it)."""
    (w, f0, fp, xp, r, g_, Jac, JF, LUc, pivc, rc, fx0, pp, xhat, xe, cst, Fk, xq, xl, elin, pk) = ws
    N = x0.shape[0]
    for i in range(N):
        xq[i] = guess[i]
    if not (st[16] == 1.0 and st[11] == 1.0 and st[12] == c):
        return
    table, comps = net[0], net[18]
    for i in range(N):
        r[i] = -(xhat[i] + gam * Fk[i] - x0[i])        # minus the predicted correction's right-hand side
        xl[i] = x0[i]
    for b in range(table.shape[0]):                   # a beam's rate rows are in force units: M/gam times it
        if table[b, 0] == BEAM:
            n = table[b, 2] // 2
            o = table[b, 1] + n
            M = _beam_mass_of(table[b, 5], net[1], net[3])
            for k in range(n):
                s = 0.0
                for l in range(n):
                    s += M[k, l] * r[o + l]
                fp[k] = s / gam
            for k in range(n):
                r[o + k] = fp[k]
    for k in range(comps.shape[0]):
        if not math.isfinite(_solve_component(comps, k, LUc, pivc, r, rc, xl, 0.0, 1.0, scale)):
            return
    valid = st[19] == 1.0                             # pk and elin are from the last step
    for k in range(comps.shape[0]):
        choice = pk[k] if valid else 1
        s = 0
        while s < comps.shape[1] and comps[k, s] >= 0:
            j = comps[k, s]
            if choice == 1:
                guess[j] = xl[j]
            elif choice == 2:
                guess[j] = xl[j] + elin[j]
            s += 1
        if choice > 0:
            st[18] += 1
    st[17] = 1.0


@njit(cache=True)
def _learn(method, x1, gam, net, rtol, atol, scale, ws, st):
    """After a successful step: the derivative its equations give at x1 for the next linearized predictor (BDF2
    and trapezoidal, whose evaluation point is x1), and per component the predictor (0 extrapolation, 1
    linearized step, 2 linearized step plus its last error) that would have predicted this step best, in the
    Newton norm (see :func:`_predict`)."""
    (w, f0, fp, xp, r, g_, Jac, JF, LUc, pivc, rc, fx0, pp, xhat, xe, cst, Fk, xq, xl, elin, pk) = ws
    N = x1.shape[0]
    comps = net[18]
    st[19] = st[17]
    if st[17] == 1.0:
        for k in range(comps.shape[0]):
            e = np.zeros(3)
            s = 0
            while s < comps.shape[1] and comps[k, s] >= 0:
                j = comps[k, s]
                wj = rtol * abs(x1[j]) + atol * scale[j]
                e[0] = max(e[0], abs(x1[j] - xq[j]) / wj)
                e[1] = max(e[1], abs(x1[j] - xl[j]) / wj)
                e[2] = max(e[2], abs(x1[j] - xl[j] - elin[j]) / wj)
                s += 1
            pk[k] = np.argmin(e)
        for j in range(N):
            elin[j] = x1[j] - xl[j]
    if method == MIDPOINT:
        st[16] = 0.0
        return
    for j in range(N):
        Fk[j] = (x1[j] - xhat[j]) / gam
    st[16] = 1.0


#: method codes
TRAPEZOIDAL, MIDPOINT, BDF2 = 0, 1, 2
#: The factored iteration matrix is kept for the next step unless the step's Newton contraction rate (of the
#: weighted corrections, largest over the components) exceeded THETA_REFRESH or it needed more than REFRESH_ITS
#: iterations, and at most REFRESH_STEPS steps (the rule of the beam's own loop, soroshapes._beam; the rate here
#: is looser: the network's corrections are measured against the tolerance, not against |v|).
THETA_REFRESH = 0.1


@njit(cache=True)
def _closed(net):
    """True when the model rows of every beam are in closed form and there is no tree (see :func:`_step`'s
    retries): constant per network, so :func:`integrate` and :func:`integrate_adaptive` decide it once per run."""
    table = net[0]
    for b in range(table.shape[0]):
        if (table[b, 0] == BEAM and table[b, 7] != 1) or table[b, 0] == TREE:
            return False
    return True


@njit(cache=True)
def _step(method, t, x0, h, xprev, net, scale, rtol, atol, maxit, ntol, ws, st, x1, hp, closed):
    """One implicit step from (t, x0) into x1; True on success. ``ws``: work arrays; ``st``: statistics and the
    state of the iteration matrix (st[4] = 1 when the differenced Jacobian is valid; st[5] = 1 when the
    quadratic BDF2 predictor may use ``ws[12]``, the state before ``xprev``; st[9] = 1 once the model rows of the
    beams failed in this step, fresh and at the failed iterate, so that the differenced Jacobian serves its last
    attempt; st[11] = 1 while the factored matrix
    is valid, for c = st[12]; st[13] = 1 asks for a fresh one everywhere; st[15] counts the components' matrices
    factored). ``ws[15]`` (components, 3): per connected component, 1 when its last step asks for a fresh matrix,
    the steps its matrix served, and the largest contraction rate that matrix showed at a third correction (-1:
    none yet). ``hp``: the two previous step sizes (h_{k-1}, h_{k-2}) [s] for the variable-step BDF2 and its
    predictor (equal to ``h`` in fixed steps). ``closed``: :func:`_closed` of the network, decided once per run."""
    (w, f0, fp, xp, r, guess, Jac, JF, LUc, pivc, rc, fx0, pp, xhat, xe, cst, Fk, xq, xl, elin, pk) = ws
    N = x0.shape[0]
    table = net[0]
    nb = table.shape[0]
    comps, block_comp = net[18], net[19]
    nc = comps.shape[0]
    alls = np.ones(nb, np.bool_)
    only = np.ones(nb, np.bool_)
    st[17] = 0.0                                        # no linearized prediction formed yet (_predict)
    conv = np.zeros(nc, np.bool_)
    prevc = np.zeros(nc)
    fresh = np.zeros(nc, np.bool_)
    cits = np.zeros(nc, np.int64)
    ctheta = np.zeros(nc)
    ckept = np.zeros(nc)
    # x1 = xhat + gam F(te, xe), xe = x1 or the midpoint; c = d xe/d x1 times gam
    if method == TRAPEZOIDAL:
        if not rhs(t, x0, net, w, fx0, alls):
            return False
        gam, c, te = 0.5 * h, 0.5 * h, t + h
        for i in range(N):
            xhat[i] = x0[i] + gam * fx0[i]
            guess[i] = x0[i] + h * fx0[i]
    elif method == MIDPOINT:
        if not rhs(t, x0, net, w, fx0, alls):
            return False
        gam, c, te = h, 0.5 * h, t + 0.5 * h
        for i in range(N):
            xhat[i] = x0[i]
            guess[i] = x0[i] + h * fx0[i]
    elif hp[0] == h and hp[1] == h:                     # BDF2, equal steps
        gam, c, te = 2.0 * h / 3.0, 2.0 * h / 3.0, t + h
        for i in range(N):
            xhat[i] = (4.0 * x0[i] - xprev[i]) / 3.0
            guess[i] = 2.0 * x0[i] - xprev[i]
        if st[5] == 1.0:                                # quadratic extrapolation through three states
            for i in range(N):
                guess[i] = 3.0 * x0[i] - 3.0 * xprev[i] + pp[i]
        _predict(x0, gam, c, net, scale, ws, st, guess)
    else:                                               # BDF2 after a step of hp[0]: omega = h/hp[0]
        om = h / hp[0]
        d = 1.0 + 2.0 * om
        gam = h * (1.0 + om) / d
        c, te = gam, t + h
        for i in range(N):
            xhat[i] = ((1.0 + om) ** 2 * x0[i] - om * om * xprev[i]) / d
        if st[5] == 1.0:
            lagrange3(x0, xprev, pp, h, hp[0], hp[1], guess)
        else:
            for i in range(N):
                guess[i] = x0[i] + om * (x0[i] - xprev[i])
        _predict(x0, gam, c, net, scale, ws, st, guess)
    for i in range(N):
        x1[i] = guess[i]
    force = False                   # rebuild the iteration matrix whatever the reuse rule says
    sel = np.zeros(nb, np.bool_)    # the blocks of the components whose matrix is rebuilt at this attempt
    # model rows with no differenced column (every beam's closed form, no tree: beams in contact with a spinning
    # body or fixed obstacles) cost about one evaluation: after a failed attempt, fresh ones at the failed
    # iterate, and the differenced Jacobian serves only a step where those failed too; otherwise, once a fresh
    # model matrix failed, the differenced Jacobian serves the rest of the run (st[9] stays 1)
    if closed:
        st[9] = 0.0
    at_iterate = False              # fresh model rows at the failed iterate (after a failed attempt)
    for attempt in range(4):
        # the beams' rows: their model Jacobian (M, K, D and the input force), reused while Newton contracts
        # fast; once Newton failed, fresh model rows at the failed iterate; once those failed too, the
        # differenced Jacobian there (st[9] = 1)
        differenced = st[9] == 1.0
        if at_iterate and not differenced:
            for i in range(N):
                xp[i] = x1[i] if method != MIDPOINT else 0.5 * (x0[i] + x1[i])
            xj = xp.copy()
            if not _cheap_rows_of(te, xj, net, scale, w, f0, fp, xp, JF, True, True, alls):
                st[11] = 0.0
                return False
        if differenced and (st[4] == 0.0 or force):
            for i in range(N):                         # the Jacobian at the guess (first) or at the failed iterate
                xp[i] = x1[i] if method != MIDPOINT else 0.5 * (x0[i] + x1[i])
            xj = xp.copy()
            if not jacobian(te, xj, net, scale, w, f0, fp, xp, Jac, JF):
                st[4] = 0.0
                return False
            st[3] += 1
            st[4] = 1.0
        # the whole matrix is rebuilt when it is not valid for this c, after a failure and in the differenced
        # mode; otherwise only the components that asked for it in the last step (cst[k, 0])
        everything = differenced or force or st[11] == 0.0 or st[12] != c or st[13] == 1.0
        rebuild = False
        for k in range(nc):
            fresh[k] = everything or cst[k, 0] == 1.0
            if fresh[k]:
                rebuild = True
        for b in range(nb):
            sel[b] = fresh[block_comp[b]]
        for i in range(N):
            x1[i] = guess[i]
        # Newton per connected component: a component that has converged is no longer evaluated
        for k in range(nc):
            conv[k] = False
            prevc[k] = np.inf
            cits[k] = 0
            ctheta[k] = 0.0
            ckept[k] = -1.0
        for b in range(nb):
            only[b] = True
        ok = False
        for it in range(maxit):
            for i in range(N):
                xe[i] = x1[i] if method != MIDPOINT else 0.5 * (x0[i] + x1[i])
            good = residual(te, xe, x1, xhat, gam, net, w, r, only)
            for bb in range(nb):
                if only[bb]:
                    st[8] += 1
            if not good:
                break
            if it == 0 and rebuild:     # M at the first iterate, the cheap rows there
                for b in range(nb):
                    if table[b, 0] == BEAM and sel[b]:
                        _beam_mass_matrix(table[b, 5], net)
                xj = xe.copy()
                if not (_cheap_rows_of(te, xj, net, scale, w, f0, fp, xp, JF, not (differenced or at_iterate), True,
                                       sel)
                        and _iteration_matrix_of(c, gam, net, JF, LUc, pivc, fresh)):
                    st[4] = 0.0
                    st[11] = 0.0
                    return False
                st[11], st[12], st[13] = 1.0, c, 0.0
                for k in range(nc):
                    if fresh[k]:
                        cst[k, 0], cst[k, 1], cst[k, 2] = 0.0, 0.0, -1.0
                        st[15] += 1
            st[2] += 1
            finite, slow, done = True, False, True
            for k in range(nc):
                if conv[k]:
                    continue
                nrm = _solve_component(comps, k, LUc, pivc, r, rc, x1, rtol, atol, scale)
                cits[k] += 1
                if it == 0 and math.isfinite(nrm):
                    st[26] += 1.0 if nrm <= 1.0 else 0.0   # first corrections within the tolerance (norm 1)
                    st[27] += 1.0 if fresh[k] else 0.0     # first corrections with a matrix factored at this step
                if not math.isfinite(nrm):
                    finite = False
                    break
                prev = prevc[k]
                # a matrix kept from earlier steps converges linearly (stale M, reservoir rows): stop at a tenth
                # of the tolerance (at ntol the compiled and Python paths drifted apart by ~10 tolerances over
                # 300 steps)
                tol_it = ntol if fresh[k] else 0.1 * ntol
                # the rate-based estimate of the remaining error theta/(1 - theta) |delta|: from the second
                # correction with a matrix factored at this step's first iterate; with one kept from earlier steps
                # from the third (its first two corrections also remove the predictor's error in the coordinates,
                # which it solves exactly, so their ratio understates its contraction rate), or from the second
                # with the largest rate this matrix showed at a third correction in the steps it served (cst[k, 2];
                # a matrix is refreshed once that rate exceeds THETA_REFRESH, so it bounds the rate)
                rate = -1.0
                if it >= 1:
                    ratio = nrm / prev
                    ctheta[k] = max(ctheta[k], ratio)           # the step's contraction rate (refresh rule)
                    if it >= 2 and not fresh[k]:
                        ckept[k] = max(ckept[k], ratio)         # the kept matrix's rate at a third correction
                    if nrm < prev:
                        if fresh[k] or it >= 2:
                            rate = ratio
                        elif cst[k, 2] >= 0.0:
                            rate = max(ratio, cst[k, 2])
                if nrm <= tol_it or (0.0 <= rate < 1.0 and rate / (1.0 - rate) * nrm <= tol_it):
                    conv[k] = True
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
            _learn(method, x1, gam, net, rtol, atol, scale, ws, st)
            for k in range(nc):
                st[19 + min(cits[k], 6)] += 1          # corrections per component: a histogram, 1 ... 6 or more
                cst[k, 1] += 1                         # the matrix served one more step; refresh it next step
                if ckept[k] > cst[k, 2]:
                    cst[k, 2] = ckept[k]               # the largest rate the kept matrix showed
                if ctheta[k] > THETA_REFRESH or cits[k] > REFRESH_ITS or cst[k, 1] >= REFRESH_STEPS:
                    cst[k, 0] = 1.0                    # when it was slow
            return True
        finite = True
        for i in range(N):
            if not math.isfinite(x1[i]):
                finite = False
        if not finite:
            for i in range(N):
                x1[i] = guess[i]
        if differenced:
            if force:
                break                                  # a fresh differenced Jacobian failed
        elif at_iterate:
            st[9] = 1.0                                # nor the model rows at the failed iterate
        elif closed:
            at_iterate = True                          # the kept or a fresh model matrix was not enough here
            if everything:
                st[10] += 1
        elif everything:
            st[9] = 1.0                                # a fresh model matrix was not enough here
            st[10] += 1
        force = True
    st[4] = 0.0
    st[11] = 0.0
    return False


@njit(cache=True)
def _split(method, t, x, h, hh, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn, tmp, closed):
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
        if not _step(method, t, tmp, step, tmp, net, scale, rtol, atol, maxit, ntol, ws, st, xn,
                     np.array([step, step]), closed):
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
              st, ws, prev):
    """Fixed-step integration of the network from (t0, x) with ``nsteps`` steps of ``h`` [s] (``method`` a code:
    0 trapezoidal, 1 midpoint, 2 BDF2 with a trapezoidal first step and after a split). Records (t, x, w) every
    ``record_every`` steps and at the end into out_t, out_x, out_w from row 1 (row 0: the caller's start).
    ``st``: steps, rejected, newton_iterations, jacobians, matrix valid, quadratic predictor valid, cut_steps,
    failure time, system evaluations in Newton iterations, the differenced Jacobian in use (this step), steps
    where a fresh model matrix failed, then the matrix reuse state (11-14, see :func:`_step`), matrices factored.
    ``ws``: the work arrays (:func:`workspace`); ``prev``: the state before x, the BDF2 history, valid when
    st[31] = 1 (set on return). A run continued by a later call with the same ``st``, ``ws`` and ``prev`` (and
    the same h) takes the steps one call would have taken (the iteration matrix, the predictors' memory and the
    BDF2 history carry over; :class:`soroshapes.model.Stepper`); fresh ones (st zeros) start a run.
    Returns the number of recorded rows, or -1 when Newton failed down to ``min_dt`` (the time in st[7])."""
    N = x.shape[0]
    hp = np.array([h, h])
    xn, tmp = np.zeros(N), np.zeros(N)
    closed = _closed(net)
    net[34][0] = np.nan                 # the schedule's cached row (network._assemble): the table may have changed
    have_prev = st[31] == 1.0
    rec = 1
    for k in range(nsteps):
        t = t0 + k * h
        if method == BDF2 and have_prev:
            ok = _step(BDF2, t, x, h, prev, net, scale, rtol, atol, maxit, ntol, ws, st, xn, hp, closed)
            if ok:
                for i in range(N):
                    ws[12][i] = prev[i]
                    prev[i] = x[i]
                st[5] = 1.0
            else:
                st[5] = 0.0
                reached = _split(TRAPEZOIDAL, t, x, h, 0.5 * h, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn,
                                 tmp, closed)
                if reached < t + h - 1e-12 * h:
                    st[7] = reached
                    return -1
                have_prev = False
        else:
            base = TRAPEZOIDAL if method == BDF2 else method
            ok = _step(base, t, x, h, prev, net, scale, rtol, atol, maxit, ntol, ws, st, xn, hp, closed)
            if not ok:
                reached = _split(base, t, x, h, 0.5 * h, min_dt, net, scale, rtol, atol, maxit, ntol, ws, st, xn, tmp,
                                 closed)
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
    st[31] = 1.0 if have_prev else 0.0
    return rec



def workspace(N, NW, net):
    """The work arrays of :func:`integrate` for N states and NW inputs (the lowered network ``net``): a caller
    that continues a run passes the same ones again."""
    return _workspace(N, NW, net)


@njit(cache=True)
def _workspace(N, NW, net):
    """The work arrays of :func:`_step` (see its unpacking) for N states and NW inputs."""
    comps = net[18]
    nc, mc = comps.shape[0], comps.shape[1]
    return (np.zeros(NW), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((N, N)),
            np.zeros((N, N)), np.zeros((nc, mc, mc)), np.zeros((nc, mc), np.int64), np.zeros(mc), np.zeros(N),
            np.zeros(N), np.zeros(N), np.zeros(N), np.zeros((nc, 3)), np.zeros(N), np.zeros(N),
            np.zeros(N), np.zeros(N), np.zeros(nc, np.int64))


# ------------------------------------------------------------------------------------- the step-size controller
#: Controller constants: the proposed step h (SAFETY err^(-1/3)), limited to [SHRINK_MIN, GROW_MAX] h (GROW_MAX
#: < 1 + sqrt 2 keeps variable-step BDF2 zero-stable); an accepted step keeps h unless the proposal grows it
#: by at least KEEP_BELOW (a new step size costs a new Newton matrix, twice for BDF2).
SAFETY, SHRINK_MIN, GROW_MAX, KEEP_BELOW = 0.9, 0.2, 2.0, 1.25


@njit(cache=True)
def lagrange3(x0, x1, x2, s, h1, h2, out):
    """The quadratic through (0, x0), (-h1, x1), (-h1-h2, x2) at s (into out): the predictor at s = h, the
    dense output between the last two states at s in [-h1, 0]."""
    H = h1 + h2
    l0 = (s + h1) * (s + H) / (h1 * H)
    l1 = -s * (s + H) / (h1 * h2)
    l2 = s * (s + h1) / (H * h2)
    for i in range(x0.shape[0]):
        out[i] = l0 * x0[i] + l1 * x1[i] + l2 * x2[i]


@njit(cache=True)
def dense_output(s, x1, x0, xm1, h, h1, nhist, out):
    """The state at s [s] from the end of an accepted step of ``h`` from x0 to x1 (-h <= s <= 0), into out: the
    quadratic through (x1, x0, xm1) (``xm1`` the state ``h1`` before x0) or, in the first step (``nhist`` = 0),
    the straight line; second order like the methods."""
    if s >= -1e-9 * h:
        for i in range(x1.shape[0]):
            out[i] = x1[i]
    elif nhist >= 1:
        lagrange3(x1, x0, xm1, s, h, h1, out)
    else:
        a = 1.0 + s / h
        for i in range(x1.shape[0]):
            out[i] = (1.0 - a) * x0[i] + a * x1[i]


@njit(cache=True)
def local_error(method, x0, x1, xp, h, h1, h2, rtol, atol, scale):
    r"""The weighted RMS norm of the local error estimate of the step of ``h`` from x0 to x1 (Milne's device):
    ``xp`` is the quadratic extrapolation through the three last states (times :math:`t_k, t_k - h_1, t_k - h_1
    - h_2`), whose error is :math:`-E_p y'''` with :math:`E_p = h(h + h_1)(h + h_1 + h_2)/6`; the method's own
    is :math:`E_c y'''`, :math:`E_c = h^3/12` (trapezoidal; midpoint for linear F) and :math:`h^2 H^2/(6(H + h))`,
    :math:`H = h + h_1` (variable-step BDF2; :math:`\tfrac29 h^3` in equal steps), so the error is
    :math:`e = E_c/(E_c + E_p)\,(x_1 - x_p)`, measured by :math:`\sqrt{\tfrac1N\sum_j (e_j/(\text{rtol}
    \max(|x_{0j}|, |x_{1j}|) + \text{atol}\,s_j))^2}`: a step is accepted when it is at most 1."""
    Ep = h * (h + h1) * (h + h1 + h2) / 6.0
    if method == BDF2:
        H = h + h1
        Ec = h * h * H * H / (6.0 * (H + h))
    else:
        Ec = h * h * h / 12.0
    C = Ec / (Ec + Ep)
    s = 0.0
    N = x0.shape[0]
    for j in range(N):
        v = C * (x1[j] - xp[j]) / (rtol * max(abs(x0[j]), abs(x1[j])) + atol * scale[j])
        s += v * v
    return math.sqrt(s / N)


@njit(cache=True)
def step_factor(err, accepted):
    """The next step over this one from the error norm ``err`` of this one (:func:`local_error`; < 0: unknown,
    keep the step): SAFETY err^(-1/3) within [SHRINK_MIN, GROW_MAX]; an accepted step below KEEP_BELOW keeps
    its size."""
    if err < 0.0:
        return 1.0
    if not math.isfinite(err):
        return SHRINK_MIN
    fac = SAFETY * err ** (-1.0 / 3.0) if err > 0.0 else GROW_MAX
    fac = min(GROW_MAX, max(SHRINK_MIN, fac))
    if accepted and fac < KEEP_BELOW:
        return 1.0
    return fac


@njit(cache=True)
def integrate_adaptive(x, t0, t_end, h, dt_out, max_dt, method, min_dt, net, scale, rtol, atol, maxit, ntol, out_t,
                       out_x, out_w, st):
    """Error-controlled integration of the network from (t0, x) to ``t_end`` [s], first step ``h``, steps at most
    ``max_dt``: each step's local error (:func:`local_error`, from the third step on) is kept below the
    tolerance, a step above it is repeated with the step :func:`step_factor` proposes, and a step whose Newton
    iteration fails is halved (down to ``min_dt``). BDF2 runs in variable steps (its first step trapezoidal).
    Records (t, x, w) at t0 + k ``dt_out`` and at ``t_end`` into out_t, out_x, out_w from row 1, by the quadratic
    through the last three states (the straight line in the first step). ``st`` as :func:`integrate`, and: 1
    steps rejected by the error test, 28 the smallest and 29 the largest step accepted [s], 30 steps whose error
    was estimated. Returns the number of rows recorded, or -1 (the time in st[7])."""
    N = x.shape[0]
    ws = _workspace(N, out_w.shape[1], net)
    closed = _closed(net)
    xn, xm1, xp, xo = np.zeros(N), x.copy(), np.zeros(N), np.zeros(N)
    pp = ws[12]                                   # the state before xm1 (the quadratic predictor's third point)
    hp = np.array([h, h])                         # the last two step sizes
    net[34][0] = np.nan                           # the schedule's cached row (see integrate)
    nhist = 0                                     # past states known before x: 0, 1 (xm1) or 2 (and pp)
    rows = out_t.shape[0]
    rec = 1
    t = t0
    h = min(h, max_dt)
    st[28], st[29] = np.inf, 0.0
    while rec < rows:
        if t + h > t_end - 1e-9 * h:
            h = t_end - t
        m = method
        if method == BDF2 and nhist == 0:
            m = TRAPEZOIDAL
        st[5] = 1.0 if nhist == 2 else 0.0
        if not _step(m, t, x, h, xm1, net, scale, rtol, atol, maxit, ntol, ws, st, xn, hp, closed):
            st[6] += 1                            # Newton failed: halve the step
            st[16], st[19] = 0.0, 0.0             # the linearized predictor's memory is of the failed step
            h *= 0.5
            if h < min_dt:
                st[7] = t
                return -1
            continue
        err = -1.0
        if nhist == 2:
            lagrange3(x, xm1, pp, h, hp[0], hp[1], xp)
            err = local_error(m, x, xn, xp, h, hp[0], hp[1], rtol, atol, scale)
            st[30] += 1
        if err > 1.0:
            st[1] += 1
            st[16], st[19] = 0.0, 0.0
            h *= step_factor(err, False)
            if h < min_dt:
                st[7] = t
                return -1
            continue
        # accepted: record the output times in (t, t + h]
        tn = t + h
        while rec < rows:
            to = t0 + rec * dt_out if rec < rows - 1 else t_end
            if to > tn + 1e-9 * h:
                break
            dense_output(to - tn, xn, x, xm1, h, hp[0], nhist, xo)
            out_t[rec] = to
            for i in range(N):
                out_x[rec, i] = xo[i]
            assemble(to, xo, net, out_w[rec])
            rec += 1
        for i in range(N):
            pp[i] = xm1[i]
            xm1[i] = x[i]
            x[i] = xn[i]
        hp[1], hp[0] = hp[0], h
        nhist = min(nhist + 1, 2)
        st[0] += 1
        st[28] = min(st[28], h)
        st[29] = max(st[29], h)
        t = tn
        h = min(h * step_factor(err, True), max_dt)
    return rec
