"""Newton's method on PETSc objects, with the failure modes a load stepper needs to see.

One Newton solve for :math:`R(u) = 0` with Dirichlet conditions: at each iteration assemble the residual
:math:`b = R(u)` lifted so that the correction also enforces the prescribed values, assemble the tangent
:math:`A = \\partial R/\\partial u`, solve :math:`A\\,\\delta = b` and update :math:`u \\leftarrow u - \\delta`.
A step that turns elements inside out (non-finite residual) is halved, up to five times, before the
iteration gives up. Converged when every field :math:`f` of the unknown (the displacement [m], and the pressure
[Pa] of the mixed formulation or the thickness strain [-] of plane stress) has a small correction,
:math:`\\|\\delta_f\\| \\le \\text{rtol}_u \\max(\\|u_f\\|, \\text{scale}_f)`, each measured in its own unit,
or when :math:`\\|b\\| \\le \\max(\\text{rtol}_r \\|b_0\\|, \\text{atol}_r)`. (One norm over all fields would
compare pascals with metres: at rest the pressure's round-off, about :math:`10^{-16}` of the bulk modulus, then
exceeds a displacement tolerance and Newton never stops; under load the pressure's size loosens the test on the
displacement.) It stops early, without raising, on a non-finite
residual, a failed factorization or a residual that grew by ``divergence_factor``; the caller (the load
stepper) restores the last state and cuts the step.

Scalar constraints are solved by bordering: the residual is :math:`R(u) + \\sum_i p_i f_i(u)` with unknown
multipliers :math:`p_i` and constraints :math:`c_i(u, p) = 0`. With :math:`K\\,r = R` and :math:`K a_i = f_i`
(one factorization, one more solve per constraint),
:math:`\\delta p = (G^T A - H)^{-1}(c - G^T r)` and :math:`\\delta u = -r - A\\,\\delta p`, where the columns
of :math:`G` are :math:`\\partial c_i/\\partial u` and :math:`H_{ij} = \\partial c_i/\\partial p_j`. Two kinds:

* volume control of cavities (:class:`VolumeConstraint`): :math:`p_i` a cavity pressure,
  :math:`c_i = V_i(u) - V_i^*`; this passes limit points of pressure, where :math:`K` alone stays regular but
  the pressure-controlled path turns back;
* arc-length continuation (:class:`sorofem.fem.continuation.ArcLength`): :math:`p` the load factor, which
  moves every load, :math:`c` the pseudo-arc-length condition; this passes limit points of any load.
"""
import logging
import math
from dataclasses import dataclass

import numpy as np

from .. import _dolfinx
from ..errors import ParameterError

log = logging.getLogger(__name__)

__all__ = ["NewtonOutcome", "NewtonSolver", "VolumeConstraint"]


@dataclass
class NewtonOutcome:
    """What one Newton solve did: ``converged``, ``iterations``, final ``residual`` and ``correction``
    norms (the correction of the first field: the displacement [m] of a FEM model), and ``reason`` (a short
    text when it failed)."""

    converged: bool
    iterations: int
    residual: float
    correction: float
    reason: str = ""


@dataclass
class VolumeConstraint:
    """One scalar constraint :math:`V(u) = V^*` whose multiplier is a pressure.

    ``pressure`` is the DOLFINx Constant multiplying ``load`` (compiled vector form of the unit-pressure load
    :math:`f`), ``gradient`` the compiled vector form :math:`\\partial V/\\partial u`, ``value`` the compiled
    scalar form :math:`V(u)`, ``target`` the current :math:`V^*` and ``scale`` a volume for the tolerance.

    Every bordered constraint offers ``residual(solver)`` (:math:`c`), ``gradient_vector(solver)``,
    ``load_vector(solver)`` (PETSc vectors, new, destroyed by the caller), ``derivative(other)``
    (:math:`\\partial c/\\partial p_{other}`), ``multiplier`` and ``update(dp)``.
    """

    pressure: object
    load: object
    gradient: object
    value: object
    target: float = 0.0
    scale: float = 1.0
    #: :math:`dV^*/dp` for another constraint's multiplier p (the arc-length's load factor moves the target)
    target_rate: object = None

    def residual(self, solver):
        import dolfinx.fem

        comm = solver.u.function_space.mesh.comm
        return comm.allreduce(dolfinx.fem.assemble_scalar(self.value)) - self.target

    def gradient_vector(self, solver):
        return solver._assemble_border_vector(self.gradient)

    def load_vector(self, solver):
        return solver._assemble_border_vector(self.load)

    def derivative(self, other):
        if other is self or self.target_rate is None:
            return 0.0
        return -self.target_rate(other)

    @property
    def multiplier(self):
        return float(self.pressure.value)

    def update(self, dp):
        self.pressure.value = float(self.pressure.value) + dp


class NewtonSolver:
    """Newton iterations for a residual form and its Jacobian (DOLFINx forms) on a Function ``u``.

    Parameters
    ----------
    residual, jacobian : dolfinx.fem.Form
        Compiled forms :math:`R(u; v)` and :math:`\\partial R/\\partial u`.
    u : dolfinx.fem.Function
        The unknown, updated in place.
    bcs : list of DirichletBC
        Dirichlet conditions (their values are the targets for this solve).
    petsc_options : dict
        Options for the linear solver (prefix-free keys, e.g. ``{"ksp_type": "gmres", "pc_type": "gamg"}``);
        default direct LU with MUMPS.
    scale : float
        Displacement scale [m] for the correction test (e.g. the mesh size of the domain); the scale of the
        single field when ``fields`` is not given.
    fields : sequence of (name, indices, scale), optional
        The fields of a mixed unknown for the correction test: their local indices into ``u.x.array`` and a
        scale in the field's unit (e.g. ``("pressure", dofs, G)`` with a shear modulus [Pa]). Every unknown
        should belong to one field. Default: one field of every unknown with scale ``scale``.
    """

    def __init__(self, residual, jacobian, u, bcs, petsc_options=None, scale=1.0, max_iterations=25,
                 rtol_u=1e-9, rtol_r=1e-9, atol_r=1e-12, divergence_factor=1e4, prefix="soro_newton_",
                 constraints=(), point_forces=None, point_tangent=None, near_nullspace=None, fields=None):
        import dolfinx.fem.petsc
        from petsc4py import PETSc

        self.R, self.J, self.u, self.bcs = residual, jacobian, u, bcs
        self.scale, self.max_iterations = float(scale), int(max_iterations)
        self.rtol_u, self.rtol_r, self.atol_r = rtol_u, rtol_r, atol_r
        self.divergence_factor = divergence_factor
        self.constraints = list(constraints)
        self.point_forces = point_forces  # callable(b_local_array, u_array): adds point loads to the residual
        self.point_tangent = point_tangent  # callable(A, u_array): adds their derivative before A.assemble()
        n_owned = u.function_space.dofmap.index_map.size_local * u.function_space.dofmap.index_map_bs
        if fields is None:
            fields = [("state", np.arange(n_owned), self.scale)]
        self.fields = []
        for name, idx, fscale in fields:
            idx = np.asarray(idx, dtype=np.int64)
            if not (np.isfinite(fscale) and fscale > 0):
                raise ParameterError(f"the correction scale of field {name!r} must be positive (in the field's "
                                     f"unit), got {fscale}")
            self.fields.append((name, idx[idx < n_owned], float(fscale)))  # owned entries: each counted once
        self.A = dolfinx.fem.petsc.create_matrix(jacobian)
        if near_nullspace is not None:  # rigid-body modes help algebraic multigrid (GAMG) on elasticity
            self.A.setNearNullSpace(near_nullspace)
        self.b = dolfinx.fem.petsc.create_vector(residual)
        self.dx = self.b.duplicate()
        comm = u.function_space.mesh.comm
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOperators(self.A)
        self.ksp.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        options = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
        options.update(petsc_options or {})
        for k, v in options.items():
            opts[f"{prefix}{k}"] = v
        self.ksp.setFromOptions()
        for k in options:
            del opts[f"{prefix}{k}"]
        self._mumps = options.get("pc_type") == "lu" and options.get("pc_factor_mat_solver_type") == "mumps"
        if self._mumps:
            # MUMPS null-pivot detection (ICNTL 24) so that a singular tangent is reported, not solved
            self.ksp.getPC().setFactorSetUpSolverType()
            F = self.ksp.getPC().getFactorMatrix()
            F.setMumpsIcntl(24, 1)
            F.setMumpsCntl(3, 1e-12)

    def _null_pivots(self):
        """Number of zero pivots MUMPS met in the last factorization (0 for other solvers)."""
        if not self._mumps:
            return 0
        return int(self.ksp.getPC().getFactorMatrix().getMumpsInfog(28))

    def assemble_residual(self, lift=True):
        """Assemble :math:`R(u)` into ``self.b``; with ``lift`` it carries the Dirichlet corrections."""
        import dolfinx.fem.petsc
        from petsc4py import PETSc

        b, x = self.b, _dolfinx.petsc_vec(self.u)
        with b.localForm() as loc:
            loc.set(0.0)
        dolfinx.fem.petsc.assemble_vector(b, self.R)
        if lift:
            _dolfinx.apply_lifting(b, [self.J], [self.bcs], [x], alpha=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.point_forces is not None:
            with b.localForm() as loc:
                self.point_forces(loc.array, self.u.x.array)
        if lift:
            _dolfinx.set_bc(b, self.bcs, x, alpha=-1.0)
        return b

    def field_norms(self, vec):
        """The 2-norm of each field of ``vec`` (a PETSc vector of the unknown's layout), over every rank."""
        a = vec.getArray(readonly=True)
        local = np.array([float(np.dot(a[idx], a[idx])) for _, idx, _ in self.fields])
        return np.sqrt(self.u.function_space.mesh.comm.allreduce(local))

    def _corrections_small(self, step):
        """Whether the last step (``step`` times ``self.dx``) is small in every field, each against its own
        size or scale."""
        dx, x = step * self.field_norms(self.dx), self.field_norms(_dolfinx.petsc_vec(self.u))
        return all(d <= self.rtol_u * max(xf, f[2]) for d, xf, f in zip(dx, x, self.fields))

    def _safeguard(self, halvings=5):
        """After the update u <- u - dx: if the residual there is not finite (elements turned inside out),
        step back along dx by halves until it is (at most ``halvings`` times). Returns the residual norm at
        the accepted point (the next iteration's, so it is not assembled twice) and the fraction of ``dx``
        taken."""
        from petsc4py import PETSc

        x = _dolfinx.petsc_vec(self.u)
        trial = self.assemble_residual().norm()
        alpha = 1.0
        for _ in range(halvings):
            if math.isfinite(trial):
                break
            alpha /= 2
            x.axpy(alpha, self.dx)  # back from u0 - 2 alpha dx to u0 - alpha dx
            x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            trial = self.assemble_residual().norm()
        if alpha < 1:
            log.debug("newton step damped to %.3g to keep every element orientable", alpha)
        return trial, alpha

    def _assemble_border_vector(self, form):
        """Assemble a vector form with zeros on the Dirichlet rows."""
        import dolfinx.fem.petsc
        from petsc4py import PETSc

        vec = dolfinx.fem.petsc.assemble_vector(form)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        _dolfinx.set_bc(vec, self.bcs, alpha=0.0)
        return vec

    def _constraint_values(self):
        return np.array([c.residual(self) for c in self.constraints])

    def _constraint_error(self):
        """max |c_i| / scale_i (0 without constraints)."""
        if not self.constraints:
            return 0.0
        return float(max(abs(v) / k.scale for v, k in zip(self._constraint_values(), self.constraints)))

    def _border(self):
        """Apply the bordering correction to ``self.dx`` (holding :math:`r = K^{-1}R`) and to the multipliers."""
        c = self._constraint_values()
        f = [k.load_vector(self) for k in self.constraints]
        g = [k.gradient_vector(self) for k in self.constraints]
        a = []
        for fi in f:
            ai = fi.duplicate()
            self.ksp.solve(fi, ai)
            a.append(ai)
        n = len(self.constraints)
        M = np.array([[g[i].dot(a[j]) - self.constraints[i].derivative(self.constraints[j]) for j in range(n)]
                      for i in range(n)])
        rhs = c - np.array([g[i].dot(self.dx) for i in range(n)])
        dp = np.linalg.solve(M, rhs)
        for j, k in enumerate(self.constraints):
            self.dx.axpy(dp[j], a[j])  # dx = r + A dp, applied as u -= dx
        for j, k in enumerate(self.constraints):
            k.update(dp[j])
        for vec in f + g + a:
            vec.destroy()

    def assemble_jacobian(self):
        import dolfinx.fem.petsc

        from petsc4py import PETSc

        self.A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.A, self.J, bcs=self.bcs)
        if self.point_tangent is not None:
            self.A.assemble(PETSc.Mat.AssemblyType.FLUSH)
            self.A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
            self.point_tangent(self.A, self.u.x.array)
        self.A.assemble()
        return self.A

    def solve(self):
        """Iterate from the current ``u``. Returns a :class:`NewtonOutcome`; never raises on divergence."""
        from petsc4py import PETSc

        x = _dolfinx.petsc_vec(self.u)
        r0 = trial = None
        rnorm = cnorm = math.nan
        for it in range(1, self.max_iterations + 1):
            rnorm = self.assemble_residual().norm() if trial is None else trial
            trial = None
            if not math.isfinite(rnorm):
                return NewtonOutcome(False, it, rnorm, cnorm, "non-finite residual (inverted elements?)")
            # reference residual: the first one; under volume control the first residual vanishes (only the
            # volume target moved), so the one after the first bordered update is the reference
            if r0 is None or (it == 2 and self.constraints):
                r0 = rnorm
            cons = self._constraint_error()
            if it > 1 and rnorm <= max(self.rtol_r * r0, self.atol_r) and cons <= 1e-9:
                return NewtonOutcome(True, it - 1, rnorm, cnorm)
            if it == 1 and rnorm <= self.atol_r and not self.constraints:
                return NewtonOutcome(True, 0, rnorm, 0.0)   # already in equilibrium (a KSP breaks down on b = 0)
            if it > 2 and rnorm > self.divergence_factor * r0:
                return NewtonOutcome(False, it, rnorm, cnorm, f"residual grew from {r0:.3e} to {rnorm:.3e}")
            self.assemble_jacobian()
            self.ksp.solve(self.b, self.dx)
            reason = self.ksp.getConvergedReason()
            if reason < 0:
                return NewtonOutcome(False, it, rnorm, cnorm, f"linear solver failed (PETSc reason {reason})")
            null_pivots = self._null_pivots()
            if null_pivots:
                return NewtonOutcome(False, it, rnorm, cnorm, f"singular tangent stiffness ({null_pivots} zero "
                                     "pivots): a rigid-body motion or mechanism is not prevented by the supports, "
                                     "or the structure lost stability")
            if self.constraints:
                try:
                    self._border()
                except np.linalg.LinAlgError:
                    return NewtonOutcome(False, it, rnorm, cnorm, "singular border of the volume or arc-length "
                                         "constraints (a cavity volume that does not depend on the displacement?)")
            cnorm = self.dx.norm()
            if not math.isfinite(cnorm):
                return NewtonOutcome(False, it, rnorm, cnorm, "non-finite Newton correction (singular tangent?)")
            x.axpy(-1.0, self.dx)
            x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            step = 1.0
            if not self.constraints:
                trial, step = self._safeguard()
            cnorm = step * float(self.field_norms(self.dx)[0])
            log.debug("newton %d: |R| = %.3e, |du| = %.3e", it, rnorm, cnorm)
            if self._corrections_small(step) and self._constraint_error() <= 1e-9:
                return NewtonOutcome(True, it, rnorm, cnorm)
        return NewtonOutcome(False, self.max_iterations, rnorm, cnorm,
                             f"no convergence in {self.max_iterations} iterations")

    @staticmethod
    def rigid_body_modes(V):
        """Near-nullspace of elasticity on a blocked vector space: translations and infinitesimal rotations
        (3 in 2D, 6 in 3D), orthonormalized, as a PETSc ``NullSpace``."""
        from petsc4py import PETSc

        gdim = V.mesh.geometry.dim
        imap = V.dofmap.index_map
        n = imap.size_local
        x = V.tabulate_dof_coordinates()[:n]
        rot = [(0, 1)] if gdim == 2 else [(0, 1), (1, 2), (2, 0)]
        basis = [_dolfinx.create_petsc_vector(imap, gdim) for _ in range(gdim + len(rot))]
        arrays = [b.array.reshape(-1, gdim) for b in basis]
        for i in range(gdim):
            arrays[i][:n, i] = 1.0
        for k, (i, j) in enumerate(rot):
            a = arrays[gdim + k]
            a[:n, i] = -x[:, j]
            a[:n, j] = x[:, i]
        _dolfinx.orthonormalize(basis)
        return PETSc.NullSpace().create(vectors=basis)

    def destroy(self):
        for obj in (self.ksp, self.A, self.b, self.dx):
            obj.destroy()

