"""Topology-optimization problems on a :class:`sorofem.mesh.Mesh`: SIMP elasticity, adjoint sensitivities.

One density per cell (DG0). The design variables :math:`x \\in [0, 1]^{n_e}` are filtered and projected
(:mod:`sorofem.topopt.filters`) into the physical densities :math:`\\bar\\rho`, which scale the material:

.. math::

    E(\\bar\\rho) = E_{min} + \\bar\\rho^p (E_0 - E_{min})  \\quad\\text{(linear)}, \\qquad
    \\psi_\\rho(F) = \\left(\\varepsilon + (1-\\varepsilon)\\bar\\rho^p\\right)\\psi(F) \\quad\\text{(hyperelastic,
    the seed's Eq. 10)}.

The state :math:`u` solves the residual equation :math:`R(u, \\bar\\rho; v) = 0` for all test functions
:math:`v` (written in UFL), here

.. math::

    R = \\int_\\Omega \\frac{\\partial \\psi_\\rho}{\\partial F} : \\nabla v \\,dX
      + \\sum_s \\frac{k_s}{|\\Gamma_s|}\\int_{\\Gamma_s} (u\\cdot d_s)(v\\cdot d_s)\\,dA
      - \\int_{\\Gamma_t} t\\cdot v\\,dA - \\sum_k F_k\\cdot v(X_k)
      - p \\int_{\\Omega_p} J F^{-T} : \\nabla v \\,dX,

where the last term is the pressure-volume work :math:`p\\,\\Delta|\\Omega_p|` of the pressurized region
:math:`\\Omega_p` (the void cells connected to the inlet, found by flood fill; by the divergence theorem it is
the follower pressure :math:`p\\,J F^{-T}N` on the chamber wall). In the linear analysis
:math:`\\partial\\psi/\\partial F : \\nabla v` becomes :math:`E(\\bar\\rho)\\,\\sigma_1(u):\\varepsilon(v)` and the
pressure term :math:`p\\int_{\\Omega_p}\\nabla\\cdot v`.

Every objective is a linear functional of the state, :math:`J = l^T u` (compliance: :math:`l = f`;
mechanism and actuator: :math:`l` selects an output displacement or rotation). Its gradient follows from
one adjoint solve with the tangent :math:`K = \\partial R/\\partial u`:

.. math::

    K^T\\lambda = l, \\qquad \\frac{dJ}{d\\bar\\rho_e} = -\\lambda^T \\frac{\\partial R}{\\partial\\bar\\rho_e},

where :math:`\\lambda^T\\partial R/\\partial\\bar\\rho` is assembled by UFL (``ufl.derivative`` of the
residual with :math:`v \\to \\lambda` in the DG0 direction). The flood-filled region is held fixed in the
derivative (it changes only when a cell crosses the void threshold, as in the seed). The volume constraint
is :math:`g = \\sum_e v_e\\bar\\rho_e / (f\\,|\\Omega|) - 1 \\le 0`.

The problems run in serial (one MPI rank); the mesh may be 2D (plane stress or plane strain) or 3D.
"""
import logging
import math
import warnings

import numpy as np

from .. import _dolfinx
from ..errors import ConvergenceError, ParameterError
from .filters import ConeFilter, Heaviside, HelmholtzFilter, IdentityFilter, LinkedFilter, cell_centroids

__all__ = ["TopOpt", "Compliance", "Mechanism", "PressureActuator", "Evaluation"]

log = logging.getLogger(__name__)


class Evaluation:
    """Values and gradients (w.r.t. the design variables) at one design; the fields are plain numpy.

    Attributes
    ----------
    objective : float
        :math:`J` in the problem's units (compliance [J] or [J/m]; displacement [m]; rotation [rad]).
    gradient : (n,) array
    constraints : (m,) array
        Constraint values, feasible when <= 0 (the volume constraint first).
    constraint_gradients : (m, n) array
    density : (n,) array
        Physical densities :math:`\\bar\\rho`.
    volume_fraction : float
    newton_iterations : int
    """

    def __init__(self, objective, gradient, constraints, constraint_gradients, density, volume_fraction,
                 newton_iterations=1, extra=None):
        self.objective = float(objective)
        self.gradient = gradient
        self.constraints = np.atleast_1d(constraints)
        self.constraint_gradients = np.atleast_2d(constraint_gradients)
        self.density = density
        self.volume_fraction = float(volume_fraction)
        self.newton_iterations = int(newton_iterations)
        self.extra = extra or {}


def _as_mesh(mesh):
    from ..mesh import Mesh
    if isinstance(mesh, Mesh):
        return mesh
    raise ParameterError(f"expected a sorofem.mesh.Mesh (build one with Mesh.rectangle, Mesh.from_sdf, ...), "
                         f"got {type(mesh).__name__}")


class TopOpt:
    """Base of the SIMP problems: design space, filter, projection, supports and loads, adjoint machinery.

    Builders (``add_support``, ``add_traction``, ...) mutate and return ``self``; the forms are compiled on the
    first :meth:`evaluate`.

    Parameters
    ----------
    mesh : sorofem.mesh.Mesh
        The design domain (serial). Quadrilateral/hexahedral or simplex cells, P1/Q1 displacements.
    volume_fraction : float
        Largest admissible fraction of solid, f in (0, 1].
    penalty : float
        SIMP exponent p (>= 1; 3 is usual).
    e_min : float
        Void stiffness ratio :math:`E_{min}/E_0` (linear) or :math:`\\varepsilon` (hyperelastic).
    radius : float, optional
        Filter radius :math:`r_{min}` [m] (cone-filter convention; the Helmholtz filter uses
        :math:`r_{min}/(2\\sqrt3)`). Default: 1.5 times the mean cell size. 0 disables filtering.
    filter : {"helmholtz", "cone", "none"}
        Density filter (see :mod:`sorofem.topopt.filters`).
    projection : Heaviside, optional
        Heaviside projection of the filtered densities (with continuation in :func:`optimize`).
    E, nu : float
        Young's modulus [Pa] and Poisson ratio of the solid (linear analysis).
    formulation : {"plane_stress", "plane_strain", "3d"}, optional
        Default: plane stress in 2D (as the 88-line code), 3d in 3D. Hyperelastic analyses are plane strain
        in 2D.
    material : sorofem.materials.Hyperelastic, optional
        If given, the analysis is geometrically nonlinear with the SIMP-scaled energy of this material
        (``E``/``nu`` are then ignored).
    passive_solid, passive_void : str or callable, optional
        Cells held at density 1 or 0: a cell region name of ``mesh`` or a predicate on cell centroids,
        ``f(x) -> bool`` with ``x`` of shape ``(dim, N)`` [m].
    link : array or callable, optional
        Cells that share one design (a periodic layout): a label per cell, ``(n,)`` ints, or a function of the
        cell centroids ``f(x) -> labels`` with ``x`` of shape ``(dim, N)`` [m]; cells with equal labels get
        the mean of their design variables before the filter (:class:`~sorofem.topopt.filters.LinkedFilter`).
    newton_tol : float
        Relative residual tolerance of the nonlinear state solve.
    load_steps : int
        Number of load increments tried first when a hyperelastic solve must restart from u = 0.
    """

    def __init__(self, mesh, volume_fraction=0.5, penalty=3.0, e_min=1e-9, radius=None, filter="helmholtz",
                 projection=None, E=1.0, nu=0.3, formulation=None, material=None, passive_solid=None,
                 passive_void=None, newton_tol=1e-9, load_steps=4, link=None):
        self.mesh = _as_mesh(mesh)
        if self.mesh.comm.size != 1:
            raise ParameterError("sorofem.topopt runs on one MPI rank; run the optimization in serial")
        if not 0 < volume_fraction <= 1:
            raise ParameterError(f"volume_fraction must lie in (0, 1], got {volume_fraction!r}")
        if not penalty >= 1:
            raise ParameterError(f"the SIMP penalty must be >= 1 (3 is usual), got {penalty!r}")
        if not 0 < e_min < 1:
            raise ParameterError(f"e_min (void stiffness ratio) must lie in (0, 1), e.g. 1e-9 (linear) or 1e-3 "
                                 f"(hyperelastic), got {e_min!r}")
        if material is None and not (E > 0 and -1 < nu < 0.5):
            raise ParameterError(f"need E > 0 and -1 < nu < 0.5, got E={E!r}, nu={nu!r}")
        self.volume_fraction, self.penalty, self.e_min = float(volume_fraction), float(penalty), float(e_min)
        self.E, self.nu, self.material = float(E), float(nu), material
        self.nonlinear = material is not None
        dom = self.mesh.dolfinx
        self.dim = dom.geometry.dim
        if formulation is None:
            formulation = "3d" if self.dim == 3 else ("plane_strain" if self.nonlinear else "plane_stress")
        if formulation not in ("plane_stress", "plane_strain", "3d") or (formulation == "3d") != (self.dim == 3):
            raise ParameterError(f"formulation {formulation!r} does not fit a {self.dim}D mesh; use 'plane_stress' "
                                 "or 'plane_strain' in 2D, '3d' in 3D")
        if self.nonlinear and formulation == "plane_stress":
            raise ParameterError("hyperelastic topology optimization is plane strain in 2D; pass "
                                 "formulation='plane_strain' or leave it unset")
        self.formulation = formulation
        self.n = dom.topology.index_map(dom.topology.dim).size_local
        self.centroids = cell_centroids(dom)
        if radius is None:
            radius = 1.5 * (self.mesh.measure() / self.n) ** (1.0 / self.dim)
        self.radius = float(radius)
        if filter == "helmholtz":
            self.filter = HelmholtzFilter.from_cone_radius(dom, self.radius) if self.radius > 0 else IdentityFilter()
        elif filter == "cone":
            self.filter = ConeFilter(dom, self.radius)
        elif filter in ("none", None):
            self.filter = IdentityFilter()
        elif hasattr(filter, "apply") and hasattr(filter, "adjoint"):
            self.filter = filter
        else:
            raise ParameterError(f"filter must be 'helmholtz', 'cone', 'none' or an object with apply/adjoint, "
                                 f"got {filter!r}")
        if link is not None:
            labels = np.asarray(link(self.centroids.T) if callable(link) else link).ravel()
            if labels.shape != (self.n,):
                raise ParameterError(f"link must give one label per cell ({self.n}), got shape {labels.shape}")
            self.filter = LinkedFilter(self.filter, labels)
        if projection is not None and not isinstance(projection, Heaviside):
            raise ParameterError("projection must be a sorofem.topopt.Heaviside instance or None")
        self.projection = projection
        self.solid = self._cell_mask(passive_solid, "passive_solid")
        self.void = self._cell_mask(passive_void, "passive_void")
        if np.any(self.solid & self.void):
            raise ParameterError("a cell is both passive solid and passive void; make the two regions disjoint")
        self.newton_tol, self.load_steps = float(newton_tol), int(load_steps)
        self._supports, self._forces, self._point_forces, self._springs = [], [], [], []
        self._point_supports = []
        self._built = None
        self._u_prev = None
        self.evaluations = 0

    # ------------------------------------------------------------------------------------------ helpers
    def _cell_mask(self, where, what):
        mask = np.zeros(self.n, dtype=bool)
        if where is None:
            return mask
        if isinstance(where, str):
            mask[self.mesh.cells(where)[self.mesh.cells(where) < self.n]] = True
        elif callable(where):
            mask[:] = np.asarray(where(self.centroids.T), dtype=bool)
        else:
            arr = np.asarray(where)
            if arr.shape != (self.n,):
                raise ParameterError(f"{what} must be a region name, a predicate or a bool array of {self.n} cells")
            mask[:] = arr.astype(bool)
        return mask

    def _components(self, components):
        if components is None:
            return tuple(range(self.dim))
        comps = tuple(int(c) for c in np.atleast_1d(components))
        if any(c < 0 or c >= self.dim for c in comps):
            raise ParameterError(f"components must be in 0..{self.dim - 1}, got {components!r}")
        return comps

    def _vector(self, value, what):
        v = np.asarray(value, dtype=float).ravel()
        if v.shape != (self.dim,) or not np.all(np.isfinite(v)):
            raise ParameterError(f"{what} must be a finite {self.dim}-vector, got {value!r}")
        return v

    def _check_region(self, region):
        self.mesh.facets(region)  # raises MeshError naming the available regions
        return region

    def _changed(self):
        self._built = None
        self._u_prev = None

    # ------------------------------------------------------------------------------------------ builders
    def add_support(self, region, components=None):
        """Fix displacement components (default all) on the facets of ``region``; returns ``self``."""
        self._supports.append((self._check_region(region), self._components(components)))
        self._changed()
        return self

    def add_point_support(self, point, components=None):
        """Fix components (default all) of the mesh node nearest to ``point`` [m]; returns ``self``."""
        self._point_supports.append((self._vector(point, "point"), self._components(components)))
        self._changed()
        return self

    def add_traction(self, region, traction):
        """A dead traction [Pa] (force per area; per length·depth in 2D) on ``region``; returns ``self``.

        Use :meth:`add_total_force` to give the resultant [N] instead. (The name of
        :meth:`sorofem.fem.Fem.add_traction` for the same load.)
        """
        self._forces.append((self._check_region(region), self._vector(traction, "traction"), False))
        self._changed()
        return self

    def add_force(self, region, traction):
        """Deprecated name of :meth:`add_traction` (the load is a traction [Pa], not a force): warns, then
        adds the traction."""
        warnings.warn("TopOpt.add_force is deprecated: the load is a traction [Pa]; use "
                      "TopOpt.add_traction(region, traction) (or add_total_force for a resultant [N])",
                      DeprecationWarning, stacklevel=2)
        return self.add_traction(region, traction)

    def add_total_force(self, region, force):
        """A dead load with resultant ``force`` [N] (2D: [N/m] of depth) spread uniformly over ``region``."""
        self._forces.append((self._check_region(region), self._vector(force, "force"), True))
        self._changed()
        return self

    def add_point_force(self, point, force):
        """A nodal force [N] (2D: [N/m]) at the mesh node nearest to ``point`` [m]; returns ``self``."""
        self._point_forces.append((self._vector(point, "point"), self._vector(force, "force")))
        self._changed()
        return self

    def add_spring(self, region, stiffness, direction):
        """A grounded spring of total ``stiffness`` [N/m] (2D: [N/m per m of depth]) along ``direction``,
        spread over ``region``: energy :math:`\\frac{k}{2|\\Gamma|}\\int_\\Gamma (u\\cdot d)^2`."""
        if not stiffness >= 0:
            raise ParameterError(f"spring stiffness must be non-negative, got {stiffness!r}")
        d = self._vector(direction, "direction")
        self._springs.append((self._check_region(region), float(stiffness), d / np.linalg.norm(d)))
        self._changed()
        return self

    # ------------------------------------------------------------------------------------------ design maps
    def physical(self, x):
        """Physical densities :math:`\\bar\\rho` (n,) of design variables ``x`` (filter, projection, passive)."""
        return self._physical(x)[0]

    def _physical(self, x):
        x = np.asarray(x, float)
        if x.shape != (self.n,):
            raise ParameterError(f"the design has {self.n} cells; got an array of shape {x.shape}")
        rt = self.filter.apply(x)
        if self.projection is not None:
            rb, drb = self.projection.apply(rt), self.projection.derivative(rt)
        else:
            rb, drb = rt, np.ones_like(rt)
        rb = np.where(self.solid, 1.0, np.where(self.void, 0.0, rb))
        drb = np.where(self.solid | self.void, 0.0, drb)
        return np.clip(rb, 0.0, 1.0), drb

    def chain(self, x, g_phys):
        """Chain a gradient w.r.t. the physical densities back to the design variables."""
        _, drb = self._physical(x)
        return self.filter.adjoint(drb * g_phys)

    def volume(self, x):
        """Volume fraction :math:`\\sum_e v_e\\bar\\rho_e/|\\Omega|` of the physical design."""
        b = self._built or self._build()
        return float(b["vol"] @ self.physical(x) / b["vol_total"])

    @property
    def cell_volumes(self):
        """Volume [m^3] (2D: area [m^2]) of each owned cell, in the order of the design variables."""
        return (self._built or self._build())["vol"]

    def density_function(self, x):
        """The physical density of design ``x`` [-] as a DG0 DOLFINx Function named ``density``."""
        import dolfinx.fem

        b = self._built or self._build()
        rho = dolfinx.fem.Function(b["Q"], name="density")
        rho.x.array[b["cell_dofs"]] = self.physical(x)
        return rho

    def initial_design(self):
        """The uniform design at the volume fraction (passive cells set), the usual starting point."""
        x = np.full(self.n, self.volume_fraction)
        x[self.solid] = 1.0
        x[self.void] = 0.0
        return x

    # ------------------------------------------------------------------------------------------ forms
    def _nearest_node(self, V, point):
        X = V.tabulate_dof_coordinates()[:, : self.dim]
        k = int(np.argmin(np.linalg.norm(X - point, axis=1)))
        return k

    def _stress_energy(self, u, v, E_rho):
        """Linear elastic bilinear integrand :math:`E(\\rho)\\,\\sigma_1(u):\\varepsilon(v)` (unit modulus σ₁)."""
        import ufl
        nu = self.nu
        lam = nu / ((1 + nu) * (1 - 2 * nu)) if self.formulation != "plane_stress" else nu / (1 - nu**2)
        mu = 1.0 / (2 * (1 + nu))
        eps_u, eps_v = ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))
        sig = 2 * mu * eps_u + lam * ufl.tr(eps_u) * ufl.Identity(self.dim)
        return E_rho * ufl.inner(sig, eps_v)

    def _F3(self, F):
        import ufl
        if self.dim == 3:
            return F
        return ufl.as_matrix([[F[0, 0], F[0, 1], 0.0], [F[1, 0], F[1, 1], 0.0], [0.0, 0.0, 1.0]])

    def _extra_residual(self, b):
        """Problem-specific residual terms (UFL, linear in the test function); default none."""
        return None

    def _objective_form(self, b):
        """The objective's linear functional l(v) as (UFL form or None, point vector or None)."""
        raise NotImplementedError

    def _build(self):
        import dolfinx
        import dolfinx.fem as fem
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        from petsc4py import PETSc

        from .._jit import silence_compiler_logs
        silence_compiler_logs()
        dom = self.mesh.dolfinx
        tdim = dom.topology.dim
        simplex = dom.topology.cell_type.name in ("triangle", "tetrahedron")
        qd = 1 if (simplex and self.nonlinear) else 2
        dx = ufl.dx(domain=dom, metadata={"quadrature_degree": qd})
        V = _dolfinx.function_space(dom, "Lagrange", 1, "vector")
        Q = _dolfinx.function_space(dom, "DG", 0)
        cell_dofs = _dolfinx.cell_dofs(Q, self.n)[:, 0].astype(np.int64)
        u, v, du = fem.Function(V), ufl.TestFunction(V), ufl.TrialFunction(V)
        rho, lam = fem.Function(Q), fem.Function(V)
        load = fem.Constant(dom, PETSc.ScalarType(1.0))  # load factor (ramps of the hyperelastic solve)
        b = dict(V=V, Q=Q, u=u, v=v, rho=rho, lam=lam, load=load, dx=dx, cell_dofs=cell_dofs)
        bs = V.dofmap.index_map_bs
        ndofs = V.dofmap.index_map.size_local * bs

        # measures of the facet regions used by loads, springs and outputs
        # one MeshTags for every facet region: a facet's tag encodes the set of regions it belongs to (regions
        # overlap, e.g. a load patch on a side), and ds(region) integrates over all tags containing the region
        fdim = tdim - 1
        names = [r for r in self.mesh.regions if self.mesh.region_dimension(r) == fdim]
        nf = dom.topology.index_map(fdim).size_local + dom.topology.index_map(fdim).num_ghosts
        code = np.zeros(nf, dtype=np.int64)
        for k, r in enumerate(names):
            code[self.mesh.facets(r)] |= 1 << k
        facets = np.flatnonzero(code).astype(np.int32)
        combos, tag = np.unique(code[facets], return_inverse=True)
        mt = dolfinx.mesh.meshtags(dom, fdim, facets, (tag + 1).astype(np.int32))
        dsm = ufl.Measure("ds", domain=dom, subdomain_data=mt, metadata={"quadrature_degree": 2})

        def ds(region):
            k = names.index(self._check_region(region))
            ids = tuple(int(i + 1) for i in np.flatnonzero(combos & (1 << k)))
            return dsm(ids)
        b["ds"] = ds

        def region_size(region):
            one = fem.Constant(dom, PETSc.ScalarType(1.0))
            return float(fem.assemble_scalar(fem.form(one * ds(region))))
        b["region_size"] = region_size

        pen, emin = self.penalty, self.e_min
        if self.nonlinear:
            scale = emin + (1 - emin) * rho**pen
            F = ufl.Identity(self.dim) + ufl.grad(u)
            Pi = scale * self.material.strain_energy(self._F3(F)) * dx
            R = ufl.derivative(Pi, u, v)
        else:
            E_rho = self.E * (emin + (1 - emin) * rho**pen)
            R = self._stress_energy(u, v, E_rho) * dx
        for region, k, d in self._springs:
            dd = ufl.as_vector(d.tolist())
            R = R + (k / region_size(region)) * ufl.dot(u, dd) * ufl.dot(v, dd) * ds(region)
        for region, t, total in self._forces:
            t = t / region_size(region) if total else t
            R = R - load * ufl.dot(ufl.as_vector(t.tolist()), v) * ds(region)
        extra = self._extra_residual(b)
        if extra is not None:
            R = R + extra
        b["R"] = fem.form(R)
        b["J"] = fem.form(ufl.derivative(R, u, du))
        R_lam = ufl.replace(R, {v: lam})
        b["dR"] = fem.form(ufl.derivative(R_lam, rho, ufl.TestFunction(Q)))
        # point forces and Dirichlet dofs (unrolled indices)
        fpt = np.zeros(ndofs)
        for p, f in self._point_forces:
            k = self._nearest_node(V, p)
            fpt[k * bs: k * bs + self.dim] += f
        b["f_point"] = fpt
        fixed = []
        dom.topology.create_connectivity(fdim, tdim)
        for region, comps in self._supports:
            nodes = fem.locate_dofs_topological(V, fdim, self.mesh.facets(region))
            fixed += [nodes * bs + c for c in comps]
        for p, comps in self._point_supports:
            k = self._nearest_node(V, p)
            fixed.append(np.array([k * bs + c for c in comps]))
        if not fixed:
            raise ParameterError("the problem has no support: add_support/add_point_support to prevent rigid motion")
        b["fixed"] = np.unique(np.concatenate(fixed)).astype(np.int32)
        # objective functional
        lform, lpt = self._objective_form(b)
        lvec = np.zeros(ndofs) if lpt is None else np.asarray(lpt, float).copy()
        if lform is not None:
            vec = dolfinx.fem.petsc.assemble_vector(fem.form(lform))
            lvec += vec.array[:ndofs]
            vec.destroy()
        lvec[b["fixed"]] = 0.0
        b["l"] = lvec
        # volumes
        vvec = dolfinx.fem.petsc.assemble_vector(fem.form(ufl.TestFunction(Q) * dx))
        b["vol"] = vvec.array[cell_dofs].copy()
        vvec.destroy()
        b["vol_total"] = float(b["vol"].sum())
        # linear algebra
        b["A"] = dolfinx.fem.petsc.create_matrix(b["J"])
        b["b"] = dolfinx.fem.petsc.create_vector(b["R"])
        b["dRvec"] = dolfinx.fem.petsc.create_vector(b["dR"])
        ksp = PETSc.KSP().create(dom.comm)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        b["ksp"] = ksp
        b["du"] = b["b"].duplicate()
        b["ndofs"] = ndofs
        self._built = b
        return b

    # ------------------------------------------------------------------------------------------ state
    def _assemble_A(self, b):
        import dolfinx.fem.petsc
        A = b["A"]
        A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(A, b["J"])
        A.assemble()
        A.zeroRowsColumns(b["fixed"], 1.0)
        return A

    def _assemble_R(self, b):
        import dolfinx.fem.petsc
        vec = b["b"]
        with vec.localForm() as loc:
            loc.set(0.0)
        dolfinx.fem.petsc.assemble_vector(vec, b["R"])
        arr = vec.array
        arr[: b["ndofs"]] -= float(b["load"].value) * b["f_point"]
        arr[b["fixed"]] = 0.0
        return vec

    def _solve(self, A, rhs, out, transpose=False):
        ksp = self._built["ksp"]
        ksp.setOperators(A)
        (ksp.solveTranspose if transpose else ksp.solve)(rhs, out)
        if ksp.getConvergedReason() < 0:
            raise ConvergenceError(f"the LU solve failed (PETSc reason {ksp.getConvergedReason()}); the stiffness "
                                   "matrix is singular: check the supports and that e_min > 0")

    def _solve_linear(self, b):
        u = b["u"]
        u.x.array[:] = 0.0
        A = self._assemble_A(b)
        R = self._assemble_R(b)
        self._solve(A, R, b["du"])
        u.x.array[: b["ndofs"]] = -b["du"].array[: b["ndofs"]]
        u.x.scatter_forward()
        return 1

    def _newton(self, b, max_iterations=30):
        """Newton with backtracking from the current ``u`` at the current load factor; returns iterations."""
        u = b["u"]
        R = self._assemble_R(b)
        r0 = R.norm()
        ref = max(r0, self._ref_norm)
        for it in range(1, max_iterations + 1):
            A = self._assemble_A(b)
            self._solve(A, R, b["du"])
            step = b["du"].array[: b["ndofs"]].copy()
            u0 = u.x.array[: b["ndofs"]].copy()
            alpha = 1.0
            for _ in range(8):
                u.x.array[: b["ndofs"]] = u0 - alpha * step
                R = self._assemble_R(b)
                rn = R.norm()
                if math.isfinite(rn) and rn < max(r0, 1e-300) * (1 - 1e-4 * alpha) + 1e-14 * ref:
                    break
                alpha *= 0.5
            else:
                u.x.array[: b["ndofs"]] = u0
                raise ConvergenceError(f"Newton line search failed at iteration {it} (residual {r0:.3g})")
            r0 = rn
            if rn <= self.newton_tol * ref:
                return it
        raise ConvergenceError(f"Newton did not converge in {max_iterations} iterations (relative residual "
                               f"{r0 / ref:.3g} > {self.newton_tol:g})")

    def _solve_nonlinear(self, b):
        u, load = b["u"], b["load"]
        load.value = 1.0
        u.x.array[:] = 0.0
        self._ref_norm = self._assemble_R(b).norm()  # the load's norm: residual at u = 0
        if self._u_prev is not None:
            u.x.array[:] = self._u_prev
            try:
                return self._newton(b)
            except ConvergenceError:
                log.info("warm-started Newton failed; restarting from u = 0 with load steps")
        for steps in (self.load_steps, 4 * self.load_steps, 16 * self.load_steps):
            u.x.array[:] = 0.0
            total = 0
            try:
                for k in range(1, steps + 1):
                    load.value = k / steps
                    total += self._newton(b)
                load.value = 1.0
                return total
            except ConvergenceError as e:
                last = e
        load.value = 1.0
        raise ConvergenceError(f"the hyperelastic state did not converge with up to {16 * self.load_steps} load "
                               f"steps ({last}); lower the load, raise e_min (void stiffness) or the filter radius")

    def _set_density(self, b, rb):
        b["rho"].x.array[b["cell_dofs"]] = rb
        b["rho"].x.scatter_forward()

    def _before_solve(self, b, rb):
        """Hook: update design-dependent loads (pressurized region) before the state solve."""

    def state(self, x):
        """Solve the state for design ``x``; returns the displacement ``dolfinx.fem.Function`` [m]."""
        b = self._built or self._build()
        rb, _ = self._physical(x)
        self._set_density(b, rb)
        self._before_solve(b, rb)
        self._solve_nonlinear(b) if self.nonlinear else self._solve_linear(b)
        return b["u"]

    # ------------------------------------------------------------------------------------------ evaluate
    def evaluate(self, x, gradient=True):
        """Objective, volume constraint and their gradients w.r.t. the design variables ``x`` (n,).

        Returns
        -------
        Evaluation
        """
        import dolfinx.fem.petsc
        b = self._built or self._build()
        rb, drb = self._physical(x)
        self._set_density(b, rb)
        self._before_solve(b, rb)
        its = self._solve_nonlinear(b) if self.nonlinear else self._solve_linear(b)
        u = b["u"]
        if not np.all(np.isfinite(u.x.array)):
            raise ConvergenceError("the state solve produced non-finite displacements; check supports and loads")
        if self.nonlinear:
            self._u_prev = u.x.array.copy()
        nd = b["ndofs"]
        J = float(b["l"] @ u.x.array[:nd])
        vol = float(b["vol"] @ rb / b["vol_total"])
        g = np.array([vol / self.volume_fraction - 1.0])
        self.evaluations += 1
        if not gradient:
            return Evaluation(J, None, g, None, rb, vol, its)
        # adjoint: K^T lambda = l
        A = self._assemble_A(b) if self.nonlinear else b["A"]
        rhs = b["du"].duplicate()
        rhs.array[:nd] = b["l"]
        lamv = _dolfinx.petsc_vec(b["lam"])
        self._solve(A, rhs, lamv, transpose=True)
        rhs.destroy()
        b["lam"].x.scatter_forward()
        vec = b["dRvec"]
        with vec.localForm() as loc:
            loc.set(0.0)
        dolfinx.fem.petsc.assemble_vector(vec, b["dR"])
        dJ_phys = -vec.array[b["cell_dofs"]]
        dJ = self.filter.adjoint(drb * dJ_phys)
        dg = self.filter.adjoint(drb * b["vol"] / (b["vol_total"] * self.volume_fraction))
        return Evaluation(J, dJ, g, dg[None, :], rb, vol, its)

    def output(self, x=None):
        """Hook for problems with an output (displacement/rotation); returns a dict of figures."""
        return {}


class Compliance(TopOpt):
    """Minimum compliance :math:`c = f^T u` [J] (2D: [J/m]) under dead loads, volume constrained.

    Examples
    --------
    The MBB half-beam of the 88-line code (60 x 20 unit cells, load at the top-left corner, symmetry on the
    left edge, roller at the bottom-right corner)::

        msh = Mesh.rectangle(60.0, 20.0, 1.0, center=(30.0, 10.0), cell="quadrilateral")
        prob = Compliance(msh, volume_fraction=0.5, radius=1.5, filter="cone")
        prob.add_support("left", components=0).add_point_support((60.0, 0.0), components=1)
        prob.add_point_force((0.0, 20.0), (0.0, -1.0))
        result = optimize(prob, method="oc")
    """

    def _objective_form(self, b):
        import ufl
        form = None
        for region, t, total in self._forces:
            t = t / b["region_size"](region) if total else t
            term = ufl.dot(ufl.as_vector(t.tolist()), b["v"]) * b["ds"](region)
            form = term if form is None else form + term
        return form, b["f_point"]


class Mechanism(TopOpt):
    """Compliant mechanism: maximize the output displacement :math:`u_{out} = |\\Gamma_o|^{-1}\\int_{\\Gamma_o}
    u\\cdot d_o` [m] against an output spring (the force inverter when :math:`d_o` opposes the input force).

    The objective minimized is :math:`J = -u_{out}`. Add the input force (:meth:`add_total_force` or
    :meth:`add_point_force`), the input and output springs (:meth:`add_spring`) and set the output with
    :meth:`set_output`.
    """

    def set_output(self, region, direction):
        """Output region (facets) and direction; returns ``self``."""
        d = self._vector(direction, "direction")
        self._output = (self._check_region(region), d / np.linalg.norm(d))
        self._changed()
        return self

    def _objective_form(self, b):
        import ufl
        if not hasattr(self, "_output"):
            raise ParameterError("Mechanism needs an output: call set_output(region, direction)")
        region, d = self._output
        return -ufl.dot(ufl.as_vector(d.tolist()), b["v"]) / b["region_size"](region) * b["ds"](region), None

    def displacement(self, region, direction=None):
        """Mean displacement [m] of the last state over facet ``region`` (a vector, or along ``direction``)."""
        import dolfinx.fem as fem
        b = self._built or self._build()
        size = b["region_size"](region)
        vals = np.array([fem.assemble_scalar(fem.form(b["u"][i] * b["ds"](region))) / size
                         for i in range(self.dim)])
        return vals if direction is None else float(vals @ np.asarray(direction, float))


class PressureActuator(Mechanism):
    """Pressure-driven actuator: the void cells connected to an inlet carry a pressure [Pa] (flood fill).

    At each design the cells with :math:`\\bar\\rho_e <` ``threshold`` that are connected (through shared
    facets) to the inlet cells form the pressurized region :math:`\\Omega_p`; its pressure-volume work
    :math:`p\\,\\Delta|\\Omega_p|` loads the chamber walls (module docstring). The objective maximizes an
    output: a mean displacement (:meth:`set_output`) or the rotation of a face (:meth:`set_rotation_output`).
    The inlet cells are held void.

    Parameters
    ----------
    mesh : sorofem.mesh.Mesh
    inlet : str or callable
        Cells where the fluid enters (a cell region name or a predicate on centroids ``(dim, N)`` [m]).
    pressure : float
        Chamber pressure [Pa].
    threshold : float
        Density below which a cell is void for the flood fill (the seed uses 0.1).
    pressure_exponent : float
        q of the pressure weight :math:`(1 - \\bar\\rho_e)^q` in the flooded cells: the pressure-volume work
        becomes :math:`p\\sum_{e \\in \\Omega_p}(1-\\bar\\rho_e)^q \\Delta|e|`, so that filling a flooded cell
        loses work and the gradient sees it (q = 0: the seed's plain flood fill, whose gradient ignores it).
    **kwargs
        Passed to :class:`TopOpt` (``material=`` for the hyperelastic analysis).
    """

    def __init__(self, mesh, inlet, pressure, threshold=0.5, pressure_exponent=2.0, **kwargs):
        super().__init__(mesh, **kwargs)
        self.inlet = self._cell_mask(inlet, "inlet")
        if not self.inlet.any():
            raise ParameterError("the inlet selects no cell; enlarge it (a disk of a few cells)")
        if np.any(self.inlet & self.solid):
            raise ParameterError("the inlet overlaps the passive solid region")
        self.void = self.void | self.inlet
        if not pressure > 0 or not 0 < threshold < 1:
            raise ParameterError(f"need pressure > 0 [Pa] and 0 < threshold < 1, got {pressure!r}, {threshold!r}")
        if not pressure_exponent >= 0:
            raise ParameterError(f"pressure_exponent must be >= 0, got {pressure_exponent!r}")
        self.pressure, self.threshold = float(pressure), float(threshold)
        self.pressure_exponent = float(pressure_exponent)
        self._adjacency = None
        self.flooded = self.inlet.copy()

    def set_rotation_output(self, region, clockwise=True):
        """Maximize the rotation [rad] of facet ``region`` about its centroid (2D), clockwise by default:
        :math:`\\theta = \\int_\\Gamma (X - X_c)\\times u \\,dA / \\int_\\Gamma |X - X_c|^2 dA`."""
        if self.dim != 2:
            raise ParameterError("rotation outputs are 2D; use set_output(region, direction) in 3D")
        self._rotation = (self._check_region(region), -1.0 if clockwise else 1.0)
        self._changed()
        return self

    def _objective_form(self, b):
        import ufl
        if not hasattr(self, "_rotation"):
            return super()._objective_form(b)
        import dolfinx.fem as fem
        region, sign = self._rotation
        ds = b["ds"](region)
        size = b["region_size"](region)
        X = ufl.SpatialCoordinate(self.mesh.dolfinx)
        c = [float(fem.assemble_scalar(fem.form(X[i] * ds))) / size for i in range(2)]
        r = ufl.as_vector([X[0] - c[0], X[1] - c[1]])
        I = float(fem.assemble_scalar(fem.form(ufl.dot(r, r) * ds)))
        v = b["v"]
        return -sign * (r[0] * v[1] - r[1] * v[0]) / I * ds, None

    def rotation(self):
        """Rotation [rad] (positive in the direction set by :meth:`set_rotation_output`) of the last state."""
        b = self._built or self._build()
        return -float(b["l"] @ b["u"].x.array[: b["ndofs"]])

    # -------------------------------------------------------------------- flood fill and pressure term
    def adjacency(self):
        """Cell–cell adjacency through shared facets (scipy CSR, n x n)."""
        if self._adjacency is None:
            import scipy.sparse as sp
            dom = self.mesh.dolfinx
            tdim = dom.topology.dim
            dom.topology.create_connectivity(tdim - 1, tdim)
            f2c = dom.topology.connectivity(tdim - 1, tdim)
            off, arr = f2c.offsets, f2c.array
            two = np.flatnonzero(np.diff(off) == 2)
            a, c = arr[off[two]], arr[off[two] + 1]
            keep = (a < self.n) & (c < self.n)
            a, c = a[keep], c[keep]
            self._adjacency = sp.csr_matrix((np.ones(2 * len(a)), (np.r_[a, c], np.r_[c, a])), shape=(self.n, self.n))
        return self._adjacency

    def flood(self, density):
        """Cells (bool, n) of the pressurized region: void cells (``density < threshold``) connected to the
        inlet."""
        from scipy.sparse.csgraph import connected_components
        voidc = (np.asarray(density) < self.threshold) | self.inlet
        idx = np.flatnonzero(voidc)
        sub = self.adjacency()[idx][:, idx]
        _, labels = connected_components(sub, directed=False)
        inlet_labels = np.unique(labels[self.inlet[idx]])
        out = np.zeros(self.n, dtype=bool)
        out[idx[np.isin(labels, inlet_labels)]] = True
        return out

    def _extra_residual(self, b):
        import dolfinx.fem as fem
        import ufl
        chi = fem.Function(b["Q"])
        b["chi"] = chi
        v, u, p = b["v"], b["u"], self.pressure * b["load"]
        chi = chi * (1 - b["rho"]) ** self.pressure_exponent  # smooth in the density: filling a cell costs work
        if self.nonlinear:
            F = ufl.Identity(self.dim) + ufl.grad(u)
            return -p * chi * ufl.det(F) * ufl.inner(ufl.inv(F).T, ufl.grad(v)) * b["dx"]
        return -p * chi * ufl.div(v) * b["dx"]

    def _before_solve(self, b, rb):
        self.flooded = self.flood(rb)
        b["chi"].x.array[b["cell_dofs"]] = self.flooded.astype(float)
        b["chi"].x.scatter_forward()
