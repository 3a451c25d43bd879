"""Path following: pseudo-arc-length continuation of quasi-static equilibria through limit points, with
bifurcation detection and branch switching.

Every load of a :class:`~sorofem.fem.Fem` is a function of the load factor :math:`\\lambda` (the ``t`` of
:meth:`Fem.solve`): pressures, tractions, prescribed displacements, volumes. Instead of prescribing
:math:`\\lambda` step by step, continuation makes it an unknown and adds one scalar condition per step
(Keller's pseudo-arc-length):

.. math::

    R(u, \\lambda) = 0, \\qquad
    c(u, \\lambda) = \\frac{\\tau_u \\cdot W (u - u_n)}{s_u^2} + \\tau_\\lambda (\\lambda - \\lambda_n) - \\Delta s = 0,

where :math:`(\\tau_u, \\tau_\\lambda)` is the unit tangent of the path at the last converged point
:math:`(u_n, \\lambda_n)` (the secant of the last step; at the start the tangent :math:`K u_t = -\\partial R /
\\partial\\lambda`), :math:`W` keeps the displacement unknowns (not the pressure of the mixed formulation),
:math:`s_u = \\|u_t\\|_W` [m per unit load] makes displacement and load commensurate and :math:`\\Delta s` is
the step. The step starts from the predictor :math:`(u_n, \\lambda_n) + \\Delta s\\,\\tau` and is corrected by
the project's Newton iteration (:class:`~sorofem.fem.newton.NewtonSolver`) with :math:`c` as a bordered
constraint (:class:`ArcLength`): per iteration one factorization of :math:`K` and two solves,
:math:`K r = R` and :math:`K a = \\partial R/\\partial\\lambda`, then
:math:`\\delta\\lambda = (c - g\\cdot r)/(g \\cdot a - \\tau_\\lambda)`, :math:`\\delta u = -(r + a\\,\\delta\\lambda)`
(Sherman-Morrison on the bordered matrix). :math:`K` stays regular at a limit point (only the bordered
matrix matters), so the path turns back in :math:`\\lambda` there and goes on. :math:`\\partial R/\\partial
\\lambda` is the difference quotient of the (Dirichlet-lifted) residual in :math:`\\lambda`, exact for the
usual linear ramps; on the Dirichlet rows it is the rate of the prescribed displacement, so displacement
control works the same way. The step size is adapted by the one step controller
(:func:`sorofem.fem.stepping.march`, here on the arc length): halved on failure, grown after easy steps.

Critical points are found with the stability monitor: the lowest eigenvalue :math:`\\mu` of
:math:`K\\phi = \\mu M\\phi` (SLEPc, :meth:`Fem.eigen`) after each step. Where it changes sign the
critical point is placed by linear interpolation of :math:`\\mu(\\lambda)` and classified by its mode: a
**limit point** when the path itself runs along the mode (at a limit point :math:`d\\lambda/ds = 0`, so
:math:`K\\,du/ds = 0`: the path's direction is the critical mode), :math:`|\\cos(\\phi, \\tau_u)|_W > 0.5`; a
**bifurcation** otherwise (the mode is orthogonal to the path: a symmetric structure leaving along an
antisymmetric mode). At a bifurcation, ``branch_switch=True`` takes the next step along the critical mode
(eigenvector injection): the tangent of that step is :math:`(\\hat\\phi_\\perp s_u, 0)`, with
:math:`\\hat\\phi_\\perp` the mode made W-orthogonal to the primary path's tangent, of unit W-norm, so the
constraint puts the solution a distance :math:`\\Delta s` along :math:`\\hat\\phi_\\perp` from the primary
branch (whose points the step's hyperplane then excludes), which places it on the branch that leaves the
critical point along :math:`\\phi` (for a symmetric pitchfork the sign of :math:`\\phi` picks one of the two
mirror branches; ``mode_sign`` chooses). Without it the path continues on the primary (now unstable) branch. No
imperfection is added to the model.

Direction after the switch: the secant from the primary point (past the critical load) to the first point of
the new branch can point back down in :math:`\\lambda` (when the primary step overshot the critical load by
more than the new branch rises in one step), and its predictor then lands near the primary branch again,
which Newton's method happily converges to: the path turns back and runs down the primary branch. So the step
after the switch uses the tangent of the new branch at its first point, :math:`K\\,u_t = -\\partial R/\\partial
\\lambda`, :math:`\\tau \\propto (u_t, 1)`, oriented so that the amplitude along the critical mode grows
(:math:`a = \\langle\\hat\\phi_\\perp, u - u_c\\rangle_W / s_u`, with :math:`\\hat\\phi_\\perp` the mode made
orthogonal to the primary path's tangent and :math:`u_c` the primary state the switch started from); on a
supercritical branch the load factor then keeps rising as it did before the critical point. Two guards refuse
a wrong path instead of returning it: the amplitude falling below half its value at the first point of the new
branch (the path went back onto the primary branch) and the load factor falling below ``t_min`` both raise
:class:`~sorofem.errors.ConvergenceError`, with the path up to there in its ``trajectory`` attribute.
"""
import logging
import math

import numpy as np

from .. import _dolfinx
from ..errors import ConvergenceError, ParameterError
from .stepping import march

__all__ = ["ArcLength", "follow", "linear_step", "load_rate"]

log = logging.getLogger(__name__)

#: |cos| between the critical mode and the path's direction above which a critical point is a limit point
LIMIT_POINT_COSINE = 0.5


class ArcLength:
    """The pseudo-arc-length condition as a bordered constraint of :class:`NewtonSolver`; its multiplier is the
    load factor :math:`\\lambda`, which :meth:`update` applies to every load of the model.

    Parameters
    ----------
    fem : Fem
        The model (its loads are set with the load factor).
    weight : PETSc Vec
        1 on the displacement unknowns, 0 on the others.
    s_u : float
        Displacement scale [m per unit load factor].
    eps : float
        Step of the difference quotient :math:`\\partial R/\\partial\\lambda`.
    """

    scale = 1.0   # c is dimensionless (a length in the scaled (u, lambda) space)

    def __init__(self, fem, weight, s_u, eps):
        self.fem, self.weight, self.s_u, self.eps = fem, weight, float(s_u), float(eps)
        self.lam = 0.0
        self.g = weight.duplicate()
        self.g.set(0.0)
        self.c0 = 0.0
        self.tau_l = 1.0

    def set_step(self, x0, lam0, tau_u, tau_l, ds):
        """The condition of the next step: tangent (``tau_u``, ``tau_l``) at (``x0``, ``lam0``), length ``ds``."""
        self.g.pointwiseMult(tau_u, self.weight)
        self.g.scale(1.0 / self.s_u**2)
        self.tau_l = float(tau_l)
        self.c0 = self.g.dot(x0) + self.tau_l * float(lam0) + float(ds)

    def residual(self, solver):
        return self.g.dot(_dolfinx.petsc_vec(solver.u)) + self.tau_l * self.lam - self.c0

    def gradient_vector(self, solver):
        return self.g.copy()

    def load_vector(self, solver):
        """:math:`\\partial R/\\partial\\lambda` at the current state (:func:`load_rate`)."""
        return load_rate(self.fem, solver, self.lam, self.eps)

    def rate(self, load):
        """d(load)/d(lambda) of a scalar load at the current load factor."""
        return (float(load(self.lam + self.eps)) - float(load(self.lam))) / self.eps

    def derivative(self, other):
        return self.tau_l if other is self else 0.0

    @property
    def multiplier(self):
        return self.lam

    def set(self, lam):
        """Put the load factor at ``lam`` (every load follows)."""
        self.lam = float(lam)
        return self.fem.set_load_level(self.lam)

    def update(self, dp):
        self.set(self.lam + dp)

    def destroy(self):
        self.g.destroy()


def load_rate(fem, solver, t, eps):
    """:math:`\\partial R/\\partial t` at the current state and load factor ``t``: the difference quotient of the
    lifted residual over ``eps``, Dirichlet rows included (there: the rate of the prescribed displacement). A new
    PETSc vector (the caller destroys it); the loads are left at ``t``."""
    fem.set_load_level(t + eps)
    q = solver.assemble_residual().copy()
    fem.set_load_level(t)
    q.axpy(-1.0, solver.assemble_residual())
    q.scale(1.0 / eps)
    return q


def linear_step(fem, solver, fraction, eps, t=0.0):
    """The load-factor step whose linear response from the current (converged) state at load factor ``t`` moves
    no point by more than ``fraction`` of the body's size: :math:`\\Delta t = f\\,D / \\max_i |u_{t,i}|`,
    :math:`K u_t = -\\partial R/\\partial t` (:math:`D` the diagonal of the mesh's bounding box, the maximum over
    the displacement unknowns); ``inf`` when no load moves the body (e.g. a volume control, whose load is not in
    the residual)."""
    from petsc4py import PETSc

    solver.assemble_jacobian()
    q = load_rate(fem, solver, t, eps)
    u_t = q.duplicate()
    solver.ksp.solve(q, u_t)
    weight = _weight(fem, fem.function_space)
    u_t.pointwiseMult(u_t, weight)
    peak = u_t.norm(PETSc.NormType.INFINITY)
    for vec in (q, u_t, weight):
        vec.destroy()
    return fraction * fem.size / peak if peak > 0 and math.isfinite(peak) else math.inf


def _weight(fem, W):
    """1 on the displacement unknowns (the first field of a mixed state), 0 elsewhere."""
    import dolfinx.fem

    f = dolfinx.fem.Function(W)
    if fem.mixed_state:
        f.x.array[np.asarray(W.sub(0).collapse()[1])] = 1.0
    else:
        f.x.array[:] = 1.0
    return _dolfinx.petsc_vec(f).copy()


def _wdot(a, b, weight, tmp):
    tmp.pointwiseMult(a, weight)
    return tmp.dot(b)


#: the amplitude along the critical mode, as a fraction of its value at the first point of the new branch, below
#: which the path is taken to have gone back onto the primary branch
RETURN_FRACTION = 0.5


def follow(fem, t_end=1.0, steps=10, until=None, max_steps=200, min_step=None, max_step=None,
           max_iterations=15, monitor_stability=False, branch_switch=False, mode_sign=1.0, t_min=0.0,
           progress=False):
    """Follow the equilibrium path of ``fem`` by pseudo-arc-length continuation (see the module docstring).

    The load factor starts at 0 and the path is followed until it reaches ``t_end`` (the step that would pass it
    lands on it under load control), ``until(traj)`` returns True, or ``max_steps`` steps were taken
    (``traj.metadata["stopped"]`` says which).

    Parameters
    ----------
    t_end : float
        Load factor [-] at which to stop (the path may pass limit points before reaching it).
    steps : int
        The first step advances the load factor by about ``t_end / steps``; the arc length of that step is
        also the largest step unless ``max_step`` is set.
    until : callable(Trajectory) -> bool, optional
        Stop condition asked after every step (e.g. an inflation or deflection reached); called on rank 0, where
        the trajectory's fields are gathered, and its answer sent to every rank.
    max_steps : int
        Largest number of steps.
    min_step, max_step : float, optional
        Smallest and largest arc length (in the scaled space, where the first step is ``sqrt(2) t_end/steps``);
        default first / 1024 and the first.
    monitor_stability : bool
        Lowest eigenvalue after every step (:attr:`Trajectory.lowest_eigenvalue`) and the critical points where
        it changes sign in ``traj.metadata["critical_points"]``: dicts with ``kind`` ("limit" or
        "bifurcation"), ``load`` (interpolated load factor), ``step`` (the first step past it).
    branch_switch : bool
        At the first bifurcation, take the next step along the critical mode onto the branch it starts
        (needs ``monitor_stability``).
    mode_sign : float
        +1 or -1: which of the two directions of the critical mode to take.
    t_min : float
        Smallest load factor [-] the path may reach (default 0: the path came back past the unloaded state,
        which is rarely meant); ``-inf`` lets it run on.

    Returns
    -------
    Trajectory
        ``times`` are the load factors along the path (not monotonic past a limit point).

    Raises
    ------
    ConvergenceError
        A step failed down to ``min_step``, the load factor fell below ``t_min``, or after a branch switch the
        path went back onto the primary branch; the converged part is in its ``trajectory`` attribute.
    """
    from petsc4py import PETSc

    if not (math.isfinite(t_end) and t_end > 0):
        raise ParameterError(f"t_end must be a positive load factor, got {t_end}")
    if not t_min < t_end:
        raise ParameterError(f"t_min must be below t_end (the path starts at 0 and ends at t_end), got {t_min}")
    if int(steps) < 1 or int(max_steps) < 1:
        raise ParameterError(f"steps and max_steps must be >= 1, got {steps} and {max_steps}")
    if branch_switch and not monitor_stability:
        raise ParameterError("branch_switch finds the bifurcation with the stability monitor: pass "
                             "monitor_stability=True too")
    if fem.contacts:
        raise ParameterError("path following with contact is not supported (the contact's friction history is "
                             "committed per load step); use Fem.solve")
    b = fem.forms
    fem.use_ramps(True)
    x = _dolfinx.petsc_vec(b.state)
    controls = [c.constraint for c in b.volume_controls]
    newton = fem.newton_solver(b.residual, b.jacobian, max_iterations)
    traj = fem.new_trajectory("load")
    traj.metadata.update(path="pseudo-arc-length", critical_points=[])
    weight = _weight(fem, b.space)
    tmp = weight.duplicate()
    arc = ArcLength(fem, weight, 1.0, 1e-6 * t_end)
    state = {}
    try:
        inputs = arc.set(0.0)
        out = newton.solve()
        if not out.converged:
            raise ConvergenceError(f"the initial state (t = 0) did not converge: {out.reason}. Check that the "
                                   "supports prevent rigid motion and that the loads at t = 0 are reasonable")
        fem.record(traj, 0.0, out.iterations, inputs, newton, monitor_stability)
        for con, (_, load, _) in zip(controls, b.volume_controls):   # volume targets move with the load factor
            con.target_rate = lambda other, load=load: arc.rate(load) if other is arc else 0.0
        u_t = _tangent(newton, arc, controls)
        s_u = math.sqrt(max(_wdot(u_t, u_t, weight, tmp), 0.0))
        if not (math.isfinite(s_u) and s_u > 0):
            raise ParameterError("no load of the model moves the body (dR/dt = 0 at t = 0): add a pressure, "
                                 "force or prescribed displacement that grows with t")
        arc.s_u = s_u
        tau_u = u_t
        tau_u.scale(1 / math.sqrt(2))
        state.update({"x": x.copy(), "lam": 0.0, "tau_u": tau_u, "tau_l": 1 / math.sqrt(2),
                      "p": [float(c.pressure.value) for c in controls], "inject": None, "switched": False,
                      "branch": None, "stopped": "max_steps"})
        newton.constraints.append(arc)
        ds0 = math.sqrt(2) * t_end / int(steps)

        def attempt(s, ds):
            tau_u, tau_l = (state["inject"], 0.0) if state["inject"] is not None else (state["tau_u"],
                                                                                       state["tau_l"])
            state["x"].copy(x)
            landing = tau_l > 0 and state["lam"] + ds * tau_l >= t_end
            if landing:   # the path reaches t_end within this step: land on it under load control
                ds = (t_end - state["lam"]) / tau_l
            x.axpy(ds, tau_u)
            x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            arc.set(t_end if landing else state["lam"] + ds * tau_l)
            if not landing:
                arc.set_step(state["x"], state["lam"], tau_u, tau_l, ds)
                return newton.solve()
            newton.constraints.remove(arc)
            try:
                return newton.solve()
            finally:
                newton.constraints.append(arc)

        def accept(s, ds, out):
            lam = arc.lam
            inputs = fem.set_load_level(lam)
            fem.record(traj, lam, out.iterations, inputs, newton, monitor_stability)
            injected = state["inject"] is not None
            if injected:   # the first point of the new branch: its tangent, pointing away from the primary branch
                d = _tangent(newton, arc, controls)
                dl = 1.0
                if _wdot(d, state["branch"]["mode"], weight, tmp) < 0:
                    d.scale(-1.0)
                    dl = -1.0
            else:          # the secant of the step
                d = x.copy()
                d.axpy(-1.0, state["x"])
                dl = lam - state["lam"]
            norm = math.sqrt(_wdot(d, d, weight, tmp) / s_u**2 + dl**2)
            if norm > 0:
                d.scale(1.0 / norm)
                state["tau_u"].destroy()
                state.update(tau_u=d, tau_l=dl / norm)
            else:
                d.destroy()
            if injected:   # the step that left the primary branch: its sign change of the lowest eigenvalue is
                state["inject"].destroy()   # the change of branch, not another critical point
                state["inject"] = None
            state["x"].destroy()
            state.update(x=x.copy(), lam=lam, p=[float(c.pressure.value) for c in controls])
            _check_direction(traj, state, x, weight, tmp, s_u, t_min, injected)
            if monitor_stability and not injected:
                _critical(fem, traj, newton, arc, weight, tmp, state, branch_switch, mode_sign)
            if progress and fem.mesh.comm.rank == 0:
                print(f"  step {len(traj) - 1}: load factor {lam:.5g} ({out.iterations} Newton iterations)",
                      flush=True)

        def reject(s, ds, out):
            log.info("arc-length step %.4g from load %.4g failed (%s); halving", ds, state["lam"], out.reason)
            state["x"].copy(x)
            x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            arc.set(state["lam"])
            for c, p in zip(controls, state["p"]):
                c.pressure.value = p

        def stop():
            if state["lam"] >= t_end * (1 - 1e-12):   # (the last step landed on t_end exactly)
                state["stopped"] = "t_end"
            elif until is not None and _on_root(fem.mesh.comm, lambda: bool(until(traj))):
                state["stopped"] = "until"
            elif len(traj) > int(max_steps):
                state["stopped"] = "max_steps"
            else:
                return False
            return True

        ds_max = float(max_step or ds0)
        smax = 2 * max(ds_max, ds0) * (int(max_steps) + 1)   # never reached: stop() ends the march first
        try:
            march(0.0, smax, ds0, float(min_step or ds0 / 1024), ds_max, attempt, accept, reject,
                  "smaller steps (steps=, max_step=), degree=2 with mixed=True for nearly incompressible "
                  "materials, or supports that remove rigid-body motion", stop=stop)
        except ConvergenceError as e:
            e.trajectory = traj
            raise
        traj.metadata["stopped"] = state["stopped"]
    finally:
        for key in ("x", "tau_u", "inject"):
            if state.get(key) is not None:
                state[key].destroy()
        if state.get("branch") is not None:
            for key in ("mode", "origin"):
                state["branch"][key].destroy()
        for con in controls:
            con.target_rate = None
        arc.destroy()
        tmp.destroy()
        weight.destroy()
        newton.destroy()
    return traj


def _on_root(comm, fn):
    """``fn()`` evaluated on rank 0 (where the trajectory's gathered fields are), its value on every rank; an
    exception there is raised on every rank (:func:`sorofem.io.on_root`)."""
    from ..io import on_root
    return comm.bcast(on_root(comm, fn), root=0)


def _tangent(newton, arc, controls):
    """:math:`du/d\\lambda` at the current converged state: :math:`K\\,du + q + \\sum_j f_j\\,dp_j = 0` with
    :math:`q = \\partial R/\\partial\\lambda`, and for each volume control :math:`g_i\\cdot du + \\partial c_i/
    \\partial\\lambda = 0` (its pressure :math:`p_j` free): :math:`du = -K^{-1}q - \\sum_j a_j\\,dp_j`,
    :math:`K a_j = f_j`, :math:`\\sum_j (g_i\\cdot a_j)\\,dp_j = \\partial c_i/\\partial\\lambda - g_i\\cdot K^{-1}q`."""
    newton.assemble_jacobian()
    q = arc.load_vector(newton)
    u_t = q.duplicate()
    newton.ksp.solve(q, u_t)
    q.destroy()
    if controls:
        f = [c.load_vector(newton) for c in controls]
        g = [c.gradient_vector(newton) for c in controls]
        a = []
        for fi in f:
            ai = fi.duplicate()
            newton.ksp.solve(fi, ai)
            a.append(ai)
        M = np.array([[gi.dot(aj) for aj in a] for gi in g])
        rhs = np.array([c.derivative(arc) - gi.dot(u_t) for c, gi in zip(controls, g)])
        try:
            dp = np.linalg.solve(M, rhs)
        except np.linalg.LinAlgError:
            raise ConvergenceError("the volume-control border is singular at t = 0 (a cavity volume that does "
                                   "not depend on the displacement?)") from None
        for aj, dpj in zip(a, dp):
            u_t.axpy(dpj, aj)
        for vec in f + g + a:
            vec.destroy()
    u_t.scale(-1.0)
    return u_t


def _critical(fem, traj, newton, arc, weight, tmp, state, branch_switch, mode_sign):
    """After a step: if the lowest eigenvalue changed sign, locate and classify the critical point; at the first
    bifurcation with ``branch_switch``, set the injection direction for the next step."""
    mu = traj.lowest_eigenvalue
    if len(mu) < 2 or (mu[-2] > 0) == (mu[-1] > 0):
        return
    lam = traj.times
    frac = mu[-2] / (mu[-2] - mu[-1])
    lam_c = float(lam[-2] + frac * (lam[-1] - lam[-2]))
    # the monitor's eigenproblem again (same shift: below the spectrum), keeping the mode of its eigenvalue
    modes = fem.eigen(3, shift=min(mu[-1], 0.0) - (abs(mu[0]) or 1.0))
    mode = modes.functions[int(np.argmin(np.abs(modes.eigenvalues - mu[-1])))]
    phi = _dolfinx.petsc_vec(mode).copy()
    phi.pointwiseMult(phi, weight)
    tau = state["tau_u"]
    pp, tt = _wdot(phi, phi, weight, tmp), _wdot(tau, tau, weight, tmp)
    cosine = abs(_wdot(phi, tau, weight, tmp)) / math.sqrt(pp * tt) if pp > 0 and tt > 0 else 0.0
    kind = "limit" if cosine > LIMIT_POINT_COSINE else "bifurcation"
    traj.metadata["critical_points"].append({"kind": kind, "load": lam_c, "step": len(lam) - 1,
                                             "mode_path_cosine": cosine})
    log.info("%s point near load factor %.5g (lowest eigenvalue %.3g -> %.3g)", kind, lam_c, mu[-2], mu[-1])
    if kind == "bifurcation" and branch_switch and not state["switched"]:
        # the eigensolver's sign is arbitrary: make the largest component of the mode positive, then apply
        # mode_sign (the same branch on every run and every number of ranks)
        vals = phi.getArray(readonly=True)
        big = (float(np.abs(vals).max()), float(vals[np.argmax(np.abs(vals))])) if len(vals) else (0.0, 0.0)
        largest = max(fem.mesh.comm.allgather(big))[1]
        phi.scale(float(np.sign(mode_sign) or 1.0) * (1.0 if largest >= 0 else -1.0))
        # inject the mode made W-orthogonal to the primary path: the step's hyperplane then excludes the primary
        # branch (with the raw mode, a primary step past several critical loads could land back on it)
        if tt > 0:
            phi.axpy(-_wdot(phi, tau, weight, tmp) / tt, tau)
        pn = math.sqrt(max(_wdot(phi, phi, weight, tmp), 0.0))
        if pn == 0:
            phi.destroy()
            return
        phi.scale(1.0 / pn)
        unit = phi.copy()   # the amplitude of the new branch is measured along it (unit W-norm)
        phi.scale(arc.s_u)
        state.update(inject=phi, switched=True,
                     branch={"mode": unit, "origin": state["x"].copy(), "load": lam_c, "first": None})
    else:
        phi.destroy()


def _check_direction(traj, state, x, weight, tmp, s_u, t_min, first):
    """Refuse a path that fell below ``t_min`` or, after a branch switch, went back onto the primary branch (its
    amplitude along the critical mode below :data:`RETURN_FRACTION` of the amplitude at the new branch's first
    point, ``first``)."""
    lam = state["lam"]
    if lam < t_min:
        e = ConvergenceError(
            f"the path turned back to load factor {lam:.4g} < t_min = {t_min:.4g} at step {len(traj) - 1}"
            + (" after the branch switch" if state["branch"] is not None else "")
            + ": the continuation reversed the load. Try smaller steps (steps=, max_step=); pass a lower t_min "
            "if the path really goes there")
        e.trajectory = traj
        raise e
    branch = state["branch"]
    if branch is None:
        return
    d = x.copy()
    d.axpy(-1.0, branch["origin"])
    amp = _wdot(d, branch["mode"], weight, tmp) / s_u
    d.destroy()
    if first:
        branch["first"] = amp
        traj.metadata["branch_switch"] = {"step": len(traj) - 1, "load": branch["load"], "amplitude": amp}
        if not amp > 0:
            e = ConvergenceError(
                f"the branch switch at load factor {branch['load']:.4g} did not leave the primary branch (amplitude "
                f"along the critical mode {amp:.3g} at step {len(traj) - 1}). Try smaller steps near the critical "
                "point (max_step=)")
            e.trajectory = traj
            raise e
        return
    if amp < RETURN_FRACTION * branch["first"]:
        e = ConvergenceError(
            f"after the branch switch at load factor {branch['load']:.4g} the path went back towards the primary "
            f"branch at step {len(traj) - 1} (load factor {lam:.4g}; amplitude along the critical mode "
            f"{amp:.3g}, {branch['first']:.3g} at the switch). Try smaller steps near the critical point "
            "(max_step=) or the other side of the mode (mode_sign=-1)")
        e.trajectory = traj
        raise e
