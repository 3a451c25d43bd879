"""The Method of Moving Asymptotes (Svanberg), pure numpy.

Svanberg's MMA (K. Svanberg, Int. J. Numer. Meth. Eng. 24, 359, 1987) in the form of his 2007 notes
"MMA and GCMMA - two methods for nonlinear optimization": the problem

.. math::

    \\min_{x, y, z}\\; f_0(x) + a_0 z + \\sum_{i=1}^m \\left(c_i y_i + \\tfrac12 d_i y_i^2\\right)
    \\quad\\text{s.t.}\\quad f_i(x) - a_i z - y_i \\le 0,\\; x_{min} \\le x \\le x_{max},\\; y, z \\ge 0

is replaced at each outer iteration by a convex separable approximation in which every function is

.. math::

    \\tilde f_i(x) = \\sum_j \\left(\\frac{p_{ij}}{u_j - x_j} + \\frac{q_{ij}}{x_j - l_j}\\right) + r_i,

with moving asymptotes :math:`l < x < u` (pulled in when the iterates oscillate, pushed out when they move
monotonically). The subproblem is solved by a primal-dual interior-point Newton method on its KKT conditions
(the ``subsolv`` of the notes), with the barrier parameter reduced tenfold from 1 to ``1e-7``. With
:math:`a_0 = 1, a_i = 0, c_i = 1000, d_i = 1` (the defaults) the artificial variables :math:`y` vanish at a
feasible optimum and the method solves the original problem.

The implementation is ours, written from the notes; it holds m constraints of n variables, with dense
(m, n) constraint gradients (m is small in topology optimization).
"""
import numpy as np

from ..errors import ConvergenceError, ParameterError

__all__ = ["MMA", "mma_subproblem"]


def mma_subproblem(low, upp, alpha, beta, p0, q0, P, Q, b, a0=1.0, a=None, c=None, d=None, epsimin=1e-7,
                   max_newton=200):
    """Solve the MMA subproblem by the primal-dual interior-point method of Svanberg's notes (``subsolv``).

    Parameters
    ----------
    low, upp : (n,) arrays
        Asymptotes, ``low < alpha <= beta < upp``.
    alpha, beta : (n,) arrays
        Bounds of the subproblem's variables.
    p0, q0 : (n,) arrays
        Objective approximation coefficients (non-negative).
    P, Q : (m, n) arrays
        Constraint approximation coefficients (non-negative).
    b : (m,) array
        Right-hand sides: the constraints are :math:`\\sum_j P_{ij}/(u_j - x_j) + Q_{ij}/(x_j - l_j) - a_i z
        - y_i \\le b_i`.
    a0, a, c, d
        The coefficients of the problem statement (module docstring).
    epsimin : float
        Final barrier parameter.

    Returns
    -------
    x : (n,) array
        The subproblem's minimizer.
    lam : (m,) array
        Its Lagrange multipliers.
    """
    n, m = len(low), len(b)
    a = np.zeros(m) if a is None else np.asarray(a, float)
    c = 1000.0 * np.ones(m) if c is None else np.asarray(c, float)
    d = np.ones(m) if d is None else np.asarray(d, float)
    een, eem = np.ones(n), np.ones(m)
    epsi = 1.0
    x = 0.5 * (alpha + beta)
    y = eem.copy()
    z = 1.0
    lam = eem.copy()
    xsi = np.maximum(een / (x - alpha), een)
    eta = np.maximum(een / (beta - x), een)
    mu = np.maximum(eem, 0.5 * c)
    zet = 1.0
    s = eem.copy()

    def residual(x, y, z, lam, xsi, eta, mu, zet, s, epsi):
        ux1, xl1 = upp - x, x - low
        plam = p0 + P.T @ lam
        qlam = q0 + Q.T @ lam
        gvec = P @ (1.0 / ux1) + Q @ (1.0 / xl1)
        dpsidx = plam / ux1**2 - qlam / xl1**2
        return np.concatenate([
            dpsidx - xsi + eta,
            c + d * y - mu - lam,
            [a0 - zet - a @ lam],
            gvec - a * z - y + s - b,
            xsi * (x - alpha) - epsi,
            eta * (beta - x) - epsi,
            mu * y - epsi,
            [zet * z - epsi],
            lam * s - epsi])

    while epsi > epsimin:
        res = residual(x, y, z, lam, xsi, eta, mu, zet, s, epsi)
        resnorm, resmax = np.linalg.norm(res), np.max(np.abs(res))
        it = 0
        while resmax > 0.9 * epsi and it < max_newton:
            it += 1
            ux1, xl1 = upp - x, x - low
            ux2, xl2 = ux1**2, xl1**2
            plam = p0 + P.T @ lam
            qlam = q0 + Q.T @ lam
            gvec = P @ (1.0 / ux1) + Q @ (1.0 / xl1)
            GG = P / ux2 - Q / xl2
            dpsidx = plam / ux2 - qlam / xl2
            delx = dpsidx - epsi / (x - alpha) + epsi / (beta - x)
            dely = c + d * y - lam - epsi / y
            delz = a0 - a @ lam - epsi / z
            dellam = gvec - a * z - y - b + epsi / lam
            diagx = 2.0 * (plam / (ux1 * ux2) + qlam / (xl1 * xl2)) + xsi / (x - alpha) + eta / (beta - x)
            diagy = d + mu / y
            diaglamyi = s / lam + 1.0 / diagy
            if m < n:
                blam = dellam + dely / diagy - GG @ (delx / diagx)
                AA = np.empty((m + 1, m + 1))
                AA[:m, :m] = np.diag(diaglamyi) + (GG / diagx) @ GG.T
                AA[:m, m] = a
                AA[m, :m] = a
                AA[m, m] = -zet / z
                sol = np.linalg.solve(AA, np.concatenate([blam, [delz]]))
                dlam, dz = sol[:m], sol[m]
                dx = -delx / diagx - (GG.T @ dlam) / diagx
            else:
                dellamyi = dellam + dely / diagy
                Axx = np.diag(diagx) + (GG.T / diaglamyi) @ GG
                azz = zet / z + a @ (a / diaglamyi)
                axz = -GG.T @ (a / diaglamyi)
                AA = np.empty((n + 1, n + 1))
                AA[:n, :n] = Axx
                AA[:n, n] = axz
                AA[n, :n] = axz
                AA[n, n] = azz
                bx = delx + GG.T @ (dellamyi / diaglamyi)
                bz = delz - a @ (dellamyi / diaglamyi)
                sol = np.linalg.solve(AA, -np.concatenate([bx, [bz]]))
                dx, dz = sol[:n], sol[n]
                dlam = (GG @ dx) / diaglamyi - dz * (a / diaglamyi) + dellamyi / diaglamyi
            dy = -dely / diagy + dlam / diagy
            dxsi = -xsi + epsi / (x - alpha) - (xsi * dx) / (x - alpha)
            deta = -eta + epsi / (beta - x) + (eta * dx) / (beta - x)
            dmu = -mu + epsi / y - (mu * dy) / y
            dzet = -zet + epsi / z - zet * dz / z
            ds = -s + epsi / lam - (s * dlam) / lam
            xx = np.concatenate([y, [z], lam, xsi, eta, mu, [zet], s])
            dxx = np.concatenate([dy, [dz], dlam, dxsi, deta, dmu, [dzet], ds])
            stm = max(np.max(-1.01 * dxx / xx), np.max(-1.01 * dx / (x - alpha)), np.max(1.01 * dx / (beta - x)), 1.0)
            step = 1.0 / stm
            old = (x, y, z, lam, xsi, eta, mu, zet, s)
            dirs = (dx, dy, dz, dlam, dxsi, deta, dmu, dzet, ds)
            newnorm = 2.0 * resnorm
            for _ in range(50):
                cand = tuple(o + step * dd for o, dd in zip(old, dirs))
                res = residual(*cand, epsi)
                newnorm = np.linalg.norm(res)
                if newnorm <= resnorm:
                    break
                step *= 0.5
            x, y, z, lam, xsi, eta, mu, zet, s = cand
            resnorm, resmax = newnorm, np.max(np.abs(res))
        if not np.all(np.isfinite(x)):
            raise ConvergenceError("the MMA subproblem produced non-finite values; check that the gradients are "
                                   "finite and scaled to order 1-100")
        epsi *= 0.1
    return x, lam


class MMA:
    """Method of Moving Asymptotes for ``min f0(x)`` s.t. ``f_i(x) <= 0`` (i = 1..m), ``xmin <= x <= xmax``.

    A stateful optimizer: each :meth:`update` takes the current point with the values and gradients of the
    objective and the constraints and returns the next point. Asymptotes follow Svanberg's rules
    (initial distance ``asy_init`` (xmax - xmin); factors 0.7 on oscillation, 1.2 on monotone progress).

    Parameters
    ----------
    n, m : int
        Number of variables and of constraints.
    xmin, xmax : float or (n,) arrays
        Variable bounds.
    move : float
        Move limit, a fraction of ``xmax - xmin`` per iteration.
    asy_init, asy_incr, asy_decr : float
        Asymptote rules.
    c : float
        Cost of the artificial variables (large: constraints are enforced).

    Examples
    --------
    >>> import numpy as np
    >>> opt = MMA(2, 1, 0.0, 2.0)
    >>> x = np.array([1.5, 0.5])
    >>> for _ in range(30):   # min (x0-1)^2 + (x1-1)^2  s.t.  x0 + x1 <= 1
    ...     x = opt.update(x, ((x - 1) ** 2).sum(), 2 * (x - 1), np.array([x.sum() - 1]), np.ones((1, 2)))
    >>> np.round(x, 3)
    array([0.5, 0.5])
    """

    def __init__(self, n, m, xmin=0.0, xmax=1.0, move=0.5, asy_init=0.5, asy_incr=1.2, asy_decr=0.7, c=1000.0):
        if int(n) < 1 or int(m) < 1:
            raise ParameterError(f"MMA needs n >= 1 variables and m >= 1 constraints, got n={n}, m={m}")
        if not 0 < move <= 1:
            raise ParameterError(f"move must be a fraction in (0, 1] of the variable range, got {move!r}")
        self.n, self.m = int(n), int(m)
        self.xmin = np.broadcast_to(np.asarray(xmin, float), (self.n,)).copy()
        self.xmax = np.broadcast_to(np.asarray(xmax, float), (self.n,)).copy()
        if np.any(self.xmax <= self.xmin):
            raise ParameterError("MMA bounds must satisfy xmin < xmax for every variable")
        self.move, self.asy_init, self.asy_incr, self.asy_decr = move, asy_init, asy_incr, asy_decr
        self.c = c * np.ones(self.m)
        self.iteration = 0
        self.xold1 = self.xold2 = None
        self.low = self.upp = None
        self.lam = np.zeros(self.m)

    def state(self):
        """The optimizer's state as a dict of arrays (for a restart file)."""
        keys = ("xold1", "xold2", "low", "upp")
        out = {k: getattr(self, k) for k in keys if getattr(self, k) is not None}
        out["iteration"] = np.array(self.iteration)
        return out

    def load_state(self, state):
        """Restore what :meth:`state` returned."""
        for k in ("xold1", "xold2", "low", "upp"):
            if k in state:
                setattr(self, k, np.array(state[k], dtype=float))
        self.iteration = int(state.get("iteration", 0))

    def update(self, x, f0, df0, f, df):
        """One MMA iteration.

        Parameters
        ----------
        x : (n,) array
            Current point.
        f0 : float
            Objective value at ``x`` (unused by the update itself; kept for logging symmetry).
        df0 : (n,) array
            Objective gradient.
        f : (m,) array
            Constraint values (feasible when <= 0).
        df : (m, n) array
            Constraint gradients.

        Returns
        -------
        (n,) array
            The next point.
        """
        x = np.asarray(x, float)
        df0 = np.asarray(df0, float)
        f = np.atleast_1d(np.asarray(f, float))
        df = np.atleast_2d(np.asarray(df, float))
        if x.shape != (self.n,) or df0.shape != (self.n,) or f.shape != (self.m,) or df.shape != (self.m, self.n):
            raise ParameterError(f"MMA.update expects x, df0 of shape ({self.n},), f of shape ({self.m},) and df "
                                 f"of shape ({self.m}, {self.n}); got {x.shape}, {df0.shape}, {f.shape}, {df.shape}")
        if not (np.all(np.isfinite(df0)) and np.all(np.isfinite(df)) and np.all(np.isfinite(f))):
            raise ConvergenceError(f"non-finite objective or constraint gradient at MMA iteration {self.iteration}; "
                                   "the state solve probably failed")
        self.iteration += 1
        span = self.xmax - self.xmin
        if self.iteration <= 2 or self.low is None:
            low = x - self.asy_init * span
            upp = x + self.asy_init * span
        else:
            sgn = (x - self.xold1) * (self.xold1 - self.xold2)
            factor = np.where(sgn > 0, self.asy_incr, np.where(sgn < 0, self.asy_decr, 1.0))
            low = x - factor * (self.xold1 - self.low)
            upp = x + factor * (self.upp - self.xold1)
            low = np.clip(low, x - 10 * span, x - 0.01 * span)
            upp = np.clip(upp, x + 0.01 * span, x + 10 * span)
        alpha = np.maximum.reduce([low + 0.1 * (x - low), x - self.move * span, self.xmin])
        beta = np.minimum.reduce([upp - 0.1 * (upp - x), x + self.move * span, self.xmax])
        xmami = np.maximum(span, 1e-5)
        ux1, xl1 = upp - x, x - low
        p0, q0 = np.maximum(df0, 0), np.maximum(-df0, 0)
        pq0 = 0.001 * (p0 + q0) + 1e-5 / xmami
        p0 = (p0 + pq0) * ux1**2
        q0 = (q0 + pq0) * xl1**2
        P, Q = np.maximum(df, 0), np.maximum(-df, 0)
        PQ = 0.001 * (P + Q) + 1e-5 / xmami
        P = (P + PQ) * ux1**2
        Q = (Q + PQ) * xl1**2
        b = P @ (1 / ux1) + Q @ (1 / xl1) - f
        xnew, self.lam = mma_subproblem(low, upp, alpha, beta, p0, q0, P, Q, b, c=self.c)
        self.xold2 = self.xold1 if self.xold1 is not None else x.copy()
        self.xold1 = x.copy()
        self.low, self.upp = low, upp
        return xnew
