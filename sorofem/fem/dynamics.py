"""Implicit dynamics: Newmark and generalized-alpha time integration of the hyperelastic model.

Balance at the generalized midpoint (Chung & Hulbert, J. Appl. Mech. 60, 1993):

.. math::

    M a_{n+1-\\alpha_m} + C v_{n+1-\\alpha_f} + R(u_{n+1-\\alpha_f}, t_{n+1-\\alpha_f}) = 0,
    \\qquad x_{n+1-\\alpha} = (1-\\alpha) x_{n+1} + \\alpha x_n,

with the Newmark updates :math:`u_{n+1} = u_n + \\Delta t\\, v_n + \\Delta t^2 ((\\tfrac12 - \\beta) a_n + \\beta a_{n+1})`
and :math:`v_{n+1} = v_n + \\Delta t ((1-\\gamma) a_n + \\gamma a_{n+1})`. :math:`R` is the quasi-static residual
(internal forces minus loads, see :mod:`sorofem.fem.problem`), :math:`M` the consistent mass and
:math:`C = \\alpha_M M + \\alpha_K K(u)` Rayleigh damping with the current tangent :math:`K`.

``scheme="newmark"``: :math:`\\alpha_m = \\alpha_f = 0`, default :math:`\\beta = 1/4, \\gamma = 1/2` (the
trapezoidal rule: unconditionally stable and non-dissipative for linear systems).
``scheme="generalized_alpha"`` with spectral radius at infinite frequency :math:`\\rho_\\infty \\in [0, 1]`:
:math:`\\alpha_m = (2\\rho_\\infty - 1)/(\\rho_\\infty + 1)`, :math:`\\alpha_f = \\rho_\\infty/(\\rho_\\infty + 1)`,
:math:`\\gamma = 1/2 - \\alpha_m + \\alpha_f`, :math:`\\beta = (1 - \\alpha_m + \\alpha_f)^2/4`: second-order
accurate, unconditionally stable, and it damps the unresolved high frequencies down to :math:`\\rho_\\infty`
per step while barely touching the resolved ones.
"""
import numpy as np

from .. import _dolfinx
from ..errors import ParameterError

__all__ = ["TimeIntegrator", "amplification_matrix"]


class TimeIntegrator:
    """Parameters of a Newmark / generalized-alpha scheme (see the module docstring)."""

    def __init__(self, scheme="generalized_alpha", rho_inf=0.8, beta=0.25, gamma=0.5):
        if scheme == "newmark":
            self.alpha_m = self.alpha_f = 0.0
            self.beta, self.gamma = float(beta), float(gamma)
            if not (self.gamma >= 0.5 and self.beta >= self.gamma / 2):
                raise ParameterError(f"Newmark beta={beta}, gamma={gamma} is not unconditionally stable: use "
                                     "gamma >= 1/2 and beta >= gamma/2 (the trapezoidal rule is 1/4, 1/2)")
        elif scheme == "generalized_alpha":
            r = float(rho_inf)
            if not 0.0 <= r <= 1.0:
                raise ParameterError(f"rho_inf must lie in [0, 1], got {rho_inf}")
            self.alpha_m = (2 * r - 1) / (r + 1)
            self.alpha_f = r / (r + 1)
            self.gamma = 0.5 - self.alpha_m + self.alpha_f
            self.beta = 0.25 * (1 - self.alpha_m + self.alpha_f) ** 2
        else:
            raise ParameterError(f"scheme must be 'newmark' or 'generalized_alpha', got {scheme!r}")
        self.scheme, self.rho_inf = scheme, rho_inf

    def acceleration(self, u, u_n, v_n, a_n, dt):
        """:math:`a_{n+1}` from the Newmark displacement update (works on UFL and numpy alike)."""
        return (u - u_n - dt * v_n) / (self.beta * dt**2) - (1 / (2 * self.beta) - 1) * a_n

    def velocity(self, a, v_n, a_n, dt):
        """:math:`v_{n+1}` from the Newmark velocity update."""
        return v_n + dt * ((1 - self.gamma) * a_n + self.gamma * a)


def amplification_matrix(integrator, omega_dt, xi=0.0):
    """The one-step map of (u, v dt, a dt^2) for the linear oscillator :math:`\\ddot u + 2\\xi\\omega\\dot u +
    \\omega^2 u = 0` with :math:`\\Omega = \\omega\\Delta t`; its spectral radius is the per-step amplitude decay
    of a mode of that frequency (used to check the scheme's numerical damping)."""
    am, af, b, g = integrator.alpha_m, integrator.alpha_f, integrator.beta, integrator.gamma
    W = float(omega_dt)
    # unknown a_{n+1} (scaled by dt^2) from the balance at the generalized midpoint, for state (u, v, a)
    # u1 = u + v + (1/2 - b) a + b a1 ; v1 = v + (1 - g) a + g a1 (v, a scaled by dt, dt^2)
    # (1-am) a1 + am a + 2 xi W ((1-af) v1 + af v) + W^2 ((1-af) u1 + af u) = 0
    lhs = (1 - am) + 2 * xi * W * (1 - af) * g + W**2 * (1 - af) * b
    row_u = -(W**2) * np.array([1.0, 0.0, 0.0])
    row_v = -2 * xi * W * np.array([0.0, 1.0, 0.0]) - W**2 * (1 - af) * np.array([0.0, 1.0, 0.0])
    row_a = -am * np.array([0.0, 0.0, 1.0]) - 2 * xi * W * (1 - af) * (1 - g) * np.array([0.0, 0.0, 1.0]) \
        - W**2 * (1 - af) * (0.5 - b) * np.array([0.0, 0.0, 1.0])
    a1 = (row_u + row_v + row_a) / lhs
    u1 = np.array([1.0, 1.0, 0.5 - b]) + b * a1
    v1 = np.array([0.0, 1.0, 1 - g]) + g * a1
    return np.vstack([u1, v1, a1])


def _displacement_part(fem, f):
    import ufl
    return ufl.split(f)[0] if fem.mixed_state else f


def simulate(fem, t_end, dt, scheme="generalized_alpha", rho_inf=0.8, beta=0.25, gamma=0.5, rayleigh=(0.0, 0.0),
             velocity=None, max_step=None, min_step=None, max_iterations=25, record_every=1, progress=None):
    """Time integration of ``fem`` from its current state; see :meth:`sorofem.fem.Fem.simulate`."""
    import time as _time

    import ufl
    import dolfinx.fem
    import dolfinx.fem.petsc
    from petsc4py import PETSc

    from ..errors import ConvergenceError
    from ..io import Progress
    from .stepping import march

    if not (np.isfinite(t_end) and t_end > 0 and np.isfinite(dt) and dt > 0):
        raise ParameterError(f"t_end and dt must be positive, got t_end={t_end}, dt={dt}")
    if fem.mixed_state:
        raise ParameterError("dynamics uses the displacement formulation: build the Fem with mixed=False (degree=2 "
                             "and nu <= 0.49 keep locking small) and formulation 'plane_strain', 'axisymmetric' or "
                             "'3d'; fem.eigen() gives the vibration modes of the mixed formulation")
    alpha_M, alpha_K = (float(c) for c in rayleigh)
    if alpha_M < 0 or alpha_K < 0:
        raise ParameterError(f"Rayleigh coefficients must be >= 0, got {rayleigh}")
    integ = TimeIntegrator(scheme, rho_inf, beta, gamma)
    b = fem.forms
    fem.use_ramps(False)  # numbers are constant loads in time
    W, w, wt, dx = b.space, b.state, b.kinematics.weight, b.dx
    w_n, v_n, a_n = (dolfinx.fem.Function(W) for _ in range(3))
    w_n.x.array[:] = w.x.array
    if velocity is not None:
        if callable(velocity):
            v_n.interpolate(velocity)
        else:
            v0 = np.asarray(velocity, dtype=float)
            if v0.shape != (fem.gdim,):
                raise ParameterError(f"velocity must be a callable x -> (gdim, N) array or a ({fem.gdim},) vector")
            v_n.x.array[:] = np.tile(v0, len(v_n.x.array) // fem.gdim)
    dtc = dolfinx.fem.Constant(fem.mesh.dolfinx, float(dt))
    am, af = integ.alpha_m, integ.alpha_f
    a_new = integ.acceleration(w, w_n, v_n, a_n, dtc)
    v_new = integ.velocity(a_new, v_n, a_n, dtc)
    a_mid = (1 - am) * a_new + am * a_n
    v_mid = (1 - af) * v_new + af * v_n
    w_mid = (1 - af) * w + af * w_n
    test = ufl.TestFunction(W)
    disp = lambda f: _displacement_part(fem, f)  # noqa: E731
    rho = [mat.density for _, mat in fem.materials]
    inertia = sum(r * ufl.dot(disp(a_mid), disp(test)) * wt * dx(k) for k, r in enumerate(rho))
    residual = ufl.replace(b.residual_ufl, {w: w_mid}) + inertia
    if alpha_M:
        residual += alpha_M * sum(r * ufl.dot(disp(v_mid), disp(test)) * wt * dx(k) for k, r in enumerate(rho))
    if alpha_K:
        direction = dolfinx.fem.Function(W)
        dK = ufl.algorithms.expand_derivatives(ufl.derivative(b.internal_ufl, w, direction))
        residual += alpha_K * ufl.replace(dK, {w: w_mid, direction: v_mid})
    R = dolfinx.fem.form(residual)
    J = dolfinx.fem.form(ufl.derivative(residual, w, ufl.TrialFunction(W)))
    v_now = dolfinx.fem.Function(W)
    kinetic = dolfinx.fem.form(sum(0.5 * r * ufl.dot(disp(v_now), disp(v_now)) * wt * dx(k) for k, r in enumerate(rho)))

    # initial acceleration: M a_0 = -R(u_0, t = 0)
    newton = fem.newton_solver(R, J, max_iterations)
    static = fem.newton_solver(b.residual, b.jacobian, max_iterations)
    fem.set_load_level(0.0)
    rhs = static.assemble_residual(lift=False)
    rhs.scale(-1.0)
    _dolfinx.set_bc(rhs, list(b.bcs), alpha=0.0)
    M = dolfinx.fem.petsc.assemble_matrix(
        dolfinx.fem.form(sum(r * ufl.dot(ufl.TrialFunction(W), test) * wt * dx(k) for k, r in enumerate(rho))),
        bcs=list(b.bcs), diagonal=1.0)
    M.assemble()
    ksp = PETSc.KSP().create(fem.mesh.comm)
    ksp.setOperators(M)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.solve(rhs, _dolfinx.petsc_vec(a_n))
    a_n.x.scatter_forward()
    for obj in (ksp, M):
        obj.destroy()
    static.destroy()
    if not np.all(np.isfinite(a_n.x.array)):
        raise ConvergenceError("the initial acceleration is not finite: check the supports and the initial loads")

    traj = fem.new_trajectory("time")
    v_now.x.array[:] = v_n.x.array

    def energy_now():
        return fem.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(kinetic))

    fem.record(traj, 0.0, 0, fem.set_load_level(0.0), newton, kinetic=energy_now())
    fem.commit_contacts()   # after recording: the reported friction is that of the step's slip
    x = w.x.array
    state = {"count": 0}

    def attempt(t, dt_step):
        dtc.value = dt_step
        state["inputs"] = fem.set_load_level(t + (1 - af) * dt_step)  # loads at the generalized midpoint
        fem.set_prescribed_displacements(t + dt_step)
        # predictor u_{n+1} = u_n (x holds it): robust for steps far beyond the resolved periods, where the
        # constant-acceleration predictor overshoots by (omega dt)^2
        return newton.solve()

    def accept(t, dt_step, out):
        a1 = integ.acceleration(x, w_n.x.array, v_n.x.array, a_n.x.array, dt_step)
        v1 = integ.velocity(a1, v_n.x.array, a_n.x.array, dt_step)
        w_n.x.array[:], v_n.x.array[:], a_n.x.array[:] = x, v1, a1
        state["count"] += 1
        if state["count"] % int(record_every) == 0 or t >= t_end - 1e-12 * t_end:
            v_now.x.array[:] = v1
            fem.record(traj, t, out.iterations, state["inputs"], newton, kinetic=energy_now())
        fem.commit_contacts()   # after recording: the reported friction is that of the step's slip
        bar.to(t, newton=out.iterations)

    def reject(t, dt_step, out):
        x[:] = w_n.x.array

    wall = _time.perf_counter()
    bar = Progress(t_end, "Fem.simulate", progress, fem.mesh.comm, unit="s")
    try:
        march(0.0, t_end, float(dt), float(min_step or dt / 1024), float(max_step or dt), attempt, accept, reject,
              "a smaller time step, generalized-alpha with rho_inf < 1 to damp unresolved frequencies, or Rayleigh "
              "damping", easy=5)
    except ConvergenceError as e:
        e.trajectory = traj
        raise
    finally:
        bar.close()
        newton.destroy()
    traj.metadata.update(wall_time_s=_time.perf_counter() - wall, scheme=scheme, rho_inf=rho_inf,
                         rayleigh=[alpha_M, alpha_K])
    return traj
