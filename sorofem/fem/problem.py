"""The :class:`Fem` problem builder: hyperelastic statics on DOLFINx with adaptive load stepping.

Weak form (reference configuration, weight :math:`w` = 1, or :math:`2\\pi R` when axisymmetric): find
:math:`u` with :math:`R(u; v) = 0` for all admissible :math:`v`,

.. math::

    R(u; v) = \\int_\\Omega \\frac{\\partial \\psi}{\\partial F} : \\delta F(v)\\, w\\,dX
      + \\sum_{\\text{pressures}} \\int_{\\Gamma_i} p_i(t)\\, (J F^{-T} N)\\cdot v\\, w\\,dA
      + \\sum_{\\text{springs}} \\int_{\\Gamma_k} k\\, u\\cdot v\\, w\\,dA
      - \\sum_{\\text{tractions}} \\int_{\\Gamma_j} t_j(t)\\cdot v\\, w\\,dA
      - \\int_\\Omega \\rho\\, g(t) \\cdot v\\, w\\,dX .

Pressures are follower loads (they act along the current normal on the current area, Nanson's formula);
a positive pressure pushes on the body's surface (inflates a cavity). With ``mixed=True`` the energy is
:math:`\\int \\hat\\psi(F) + p\\, g(F) - p^2/(2k)` (:meth:`sorofem.materials.Material.mixed_energy`: for
the decoupled laws :math:`W_{iso}(F) + p (J - 1) - p^2/(2\\kappa)`, for linear elasticity
:math:`\\mu\\,\\mathrm{dev}\\,\\varepsilon:\\mathrm{dev}\\,\\varepsilon + p \\operatorname{tr}\\varepsilon - p^2/(2K)`) with
Taylor-Hood P2/P1 fields: no volumetric locking as :math:`\\nu \\to 1/2`. Displacement-only P1 elements lock
there (a nearly incompressible body becomes many times too stiff); building such a model warns
(:class:`LockingWarning`) and names the fix.

``formulation="plane_stress"`` adds the thickness strain as a discontinuous unknown field (see
:mod:`sorofem.fem.kinematics`); results are per unit reference thickness.

Loads depend on a parameter ``t`` marched from 0 to ``load_level`` by :meth:`Fem.solve`: a number ``a`` is applied
as :math:`a\\,t` (a ramp reaching ``a`` at ``t = 1``); a callable ``f`` is applied as ``f(t)``. In
:meth:`Fem.simulate` ``t`` is time [s] and a number is applied as the constant ``a``.
"""
import logging
import math
import time as _time
import warnings

import numpy as np

from .. import _dolfinx
from .._jit import silence_compiler_logs
from ..errors import ConvergenceError, MeshError, ParameterError
from ..io import Progress
from ..materials import Material
from ..snapshots import input_name
from ..units import standard_gravity
from .forms import (FemForms, LoadConstant, VolumeControl, gravity_term, pressure_term, spring_term, traction_term,
                    volume_term)
from .kinematics import FORMULATIONS, Kinematics
from .newton import NewtonSolver, VolumeConstraint
from .stepping import march
from .results import Trajectory, VertexGatherer

__all__ = ["Fem", "LockingWarning", "PRESSURE_SPACES"]

#: Poisson ratio from which displacement-only P1 elements warn of volumetric locking (bulk/shear modulus
#: ratio ~100). The silicone presets' default 0.49 (ratio 50) stays below it.
LOCKING_NU = 0.495

#: Pressure spaces of the mixed formulation (``Fem(mixed=...)``): one continuous P1 field (Taylor-Hood), one
#: continuous P1 field per material (the pressure may jump across material interfaces), a constant per cell.
PRESSURE_SPACES = ("taylor_hood", "per_material", "p0")


class LockingWarning(UserWarning):
    """A displacement-only P1 model of a nearly incompressible material: expect it to be far too stiff."""


def _max_op():
    from mpi4py import MPI
    return MPI.MAX

log = logging.getLogger(__name__)
silence_compiler_logs()

_COMPONENTS = {"x": 0, "y": 1, "z": 2, "r": 0}


def _components(components, gdim):
    if components is None:
        return list(range(gdim))
    if isinstance(components, (int, str)):
        components = [components]
    out = []
    for c in components:
        i = _COMPONENTS.get(c, c) if isinstance(c, str) else c
        if not isinstance(i, (int, np.integer)) or not 0 <= i < gdim:
            raise ParameterError(f"component {c!r} does not exist in {gdim}D; use 0..{gdim - 1} or "
                                 f"{'x, y' if gdim == 2 else 'x, y, z'}")
        out.append(int(i))
    return sorted(set(out))


class _Load:
    """A load value as a function of t. Callables are called. A number ``a`` is ramped, ``a * t``, by the
    quasi-static solver (t is the load parameter) and held constant, ``a``, by the dynamic solver (t is
    time); the solvers set :attr:`ramp`."""

    ramp = True

    def __init__(self, name, value, shape):
        self.name, self.shape = name, shape
        self.constant = None
        if callable(value):
            self.fn = value
        else:
            a = np.asarray(value, dtype=float)
            if a.shape != shape:
                raise ParameterError(f"{name}: expected a value of shape {shape or 'scalar'}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ParameterError(f"{name}: the value must be finite, got {a}")
            self.constant = a
            self.fn = lambda t, a=a: a * t if self.ramp else a

    def __call__(self, t):
        v = np.asarray(self.fn(t), dtype=float)
        if v.shape != self.shape:
            raise ParameterError(f"{self.name}: the function returned shape {v.shape} at t={t}, expected "
                                 f"{self.shape or 'a scalar'}")
        if not np.all(np.isfinite(v)):
            raise ParameterError(f"{self.name}: the function returned a non-finite value {v} at t={t}")
        return v


class Fem:
    """A hyperelastic finite-element model of a soft body on a :class:`sorofem.mesh.Mesh`.

    Parameters
    ----------
    mesh : sorofem.mesh.Mesh
        The body, with named regions (``left``, ``cavity_0``, ...).
    material : sorofem.materials.Material
        Material of every cell not assigned another one by :meth:`add_material`.
    formulation : {"plane_strain", "plane_stress", "axisymmetric", "3d"}, optional
        Default: ``plane_strain`` on 2D meshes, ``3d`` on 3D meshes. Axisymmetric meshes lie in x >= 0
        (x = r, y = z, axis = y axis); the radial displacement is fixed on the axis automatically.
        ``plane_stress``: a thin sheet in the plane, results per unit reference thickness (forces [N/m],
        tractions [Pa], energies [J/m]).
    degree : {1, 2}
        Polynomial degree of the displacement (2 with ``mixed``).
    mixed : bool or {"taylor_hood", "per_material", "p0"}
        Displacement-pressure formulation for nearly incompressible materials (any material; solve and
        eigen; not dynamics, contact or tendons), P2 displacement with the pressure space (see
        :data:`PRESSURE_SPACES`): ``True`` or ``"taylor_hood"``, one continuous P1 pressure (Taylor-Hood);
        ``"per_material"``, one continuous P1 pressure per material, so that the pressure may jump across
        the interfaces between materials (Taylor-Hood in each; with one material the same as
        ``"taylor_hood"``); ``"p0"``, a constant pressure per cell (P2/P0, stable in 2D; first-order
        pressure).
    quadrature_degree : int, optional
        Quadrature degree of all integrals (default ``2 * degree``).
    petsc_options : dict, optional
        Linear solver options (default: direct LU with MUMPS). For large 3D problems e.g.
        ``{"ksp_type": "gmres", "pc_type": "gamg", "ksp_rtol": 1e-10}``.

    Examples
    --------
    >>> from sorofem.mesh import Mesh                               # doctest: +SKIP
    >>> from sorofem import materials
    >>> fem = Fem(Mesh.rectangle(0.1, 0.01, 0.002), material=materials.Ecoflex0030())  # doctest: +SKIP
    >>> traj = fem.add_support("left").add_gravity().solve(steps=4)  # doctest: +SKIP
    """

    def __init__(self, mesh, material, formulation=None, degree=1, mixed=False, quadrature_degree=None,
                 petsc_options=None):
        if not hasattr(mesh, "dolfinx") or not hasattr(mesh, "regions"):
            raise ParameterError("Fem needs a sorofem.mesh.Mesh (e.g. Mesh.from_sdf(shape, size=...)), got "
                                 f"{type(mesh).__name__}")
        self.mesh = mesh
        gdim = mesh.dolfinx.geometry.dim
        if formulation is None:
            formulation = "3d" if gdim == 3 else "plane_strain"
        if formulation not in FORMULATIONS:
            raise ParameterError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
        if (formulation == "3d") != (gdim == 3):
            raise ParameterError(f"formulation {formulation!r} does not fit a {gdim}D mesh")
        if formulation == "axisymmetric" and mesh.bounds[0][0] < -1e-9 * float(np.ptp(mesh.bounds[0] - mesh.bounds[1])):
            raise ParameterError("an axisymmetric mesh must lie in x >= 0 (x is the radius); its x range starts at "
                                 f"{mesh.bounds[0][0]:.3g} m")
        if degree not in (1, 2):
            raise ParameterError(f"degree must be 1 or 2, got {degree!r}")
        if not isinstance(mixed, str):
            mixed = "taylor_hood" if mixed else False
        if mixed and mixed not in PRESSURE_SPACES:
            raise ParameterError(f"mixed must be True, False or a pressure space {PRESSURE_SPACES}, got {mixed!r}")
        if mixed and degree != 2:
            raise ParameterError("the mixed formulation (Taylor-Hood or a pressure per material) uses P2 displacement "
                                 "elements: pass degree=2")
        if mixed and formulation == "plane_stress":
            raise ParameterError("plane stress does not lock (the thickness is free to change): use mixed=False "
                                 "with formulation='plane_stress'")
        self.formulation, self.degree, self.mixed = formulation, degree, bool(mixed)
        #: the pressure space of the mixed formulation (:data:`PRESSURE_SPACES`), None without it
        self.pressure_space = mixed or None
        self.quadrature_degree = int(quadrature_degree or 2 * degree)
        self.petsc_options = dict(petsc_options or {})
        self.gdim = gdim
        self._materials = [(None, self._check_material(material))]
        self._supports, self._displacements = [], []   # (region, components) / (region, components, _Load)
        self._pressures, self._tractions, self._springs = [], [], []  # (region, _Load/value)
        self._volumes = []                                           # (region, _Load of added volume)
        self._expansions = []                                        # (cell region, _Load of strain)
        self._tendons = []                                           # Tendon
        self._contacts = []                                          # Contact
        self._body_forces = []                                       # (_Load of force density [N/m^3])
        self._gravity = None                                         # _Load of acceleration [m/s^2]
        self._forms = None                                           # FemForms, built on first use
        self._load_level = 0.0                                       # t of the loads now applied

    # ------------------------------------------------------------------------------------------ builders
    def _check_material(self, material):
        if not isinstance(material, Material):
            raise ParameterError(f"material must be a sorofem.materials.Material, got {type(material).__name__}")
        if self.degree == 1 and not self.mixed and self.formulation != "plane_stress" and material.nu >= LOCKING_NU:
            warnings.warn(f"{material.name} has nu = {material.nu:.4g} >= {LOCKING_NU}: displacement-only P1 "
                          "elements lock (the model becomes many times too stiff); use degree=2, mixed=True "
                          "(Taylor-Hood) for nearly incompressible materials", LockingWarning, stacklevel=3)
        return material

    def _region(self, name, kind):
        try:
            ents = self.mesh.facets(name) if kind == "facets" else self.mesh.cells(name)
        except MeshError as e:
            raise MeshError(f"{e}. Add it with mesh.add_region({name!r}, ...) or use one of the names above") from e
        if self.mesh.comm.allreduce(len(ents)) == 0:
            raise MeshError(f"region {name!r} is empty")
        return ents

    def _changed(self):
        """A load or region was added: forms are rebuilt on the next solve, starting from the current state."""
        if self._forms is not None:
            self._carry = self._forms.state.x.array.copy()
        self._forms = None
        return self

    def add_material(self, region, material):
        """Use ``material`` on the cells of ``region`` (a cell region, e.g. a strain-limiting layer)."""
        self._region(region, "cells")
        self._materials.append((region, self._check_material(material)))
        return self._changed()

    def add_support(self, region, components=None):
        """Fix the displacement of ``region`` (all components, or some: ``components=("x",)``, ``[1]``)."""
        self._region(region, "facets")
        self._supports.append((region, _components(components, self.gdim)))
        return self._changed()

    def add_displacement(self, region, value, components=None):
        """Prescribe the displacement [m] of ``region``: a number or vector per component (ramped with t),
        or a callable ``value(t)``. One value per listed component (a scalar if one component)."""
        self._region(region, "facets")
        comps = _components(components, self.gdim)
        shape = () if len(comps) == 1 else (len(comps),)
        self._displacements.append((region, comps, _Load(f"displacement on {region!r}", value, shape)))
        return self._changed()

    def add_pressure(self, region, pressure):
        """Follower pressure [Pa] on the surface ``region`` (e.g. ``"cavity_0"``): a number (ramped) or
        ``pressure(t)``. Positive pushes on the body: it inflates a cavity."""
        self._region(region, "facets")
        self._pressures.append((region, _Load(f"pressure on {region!r}", pressure, ())))
        return self._changed()

    def add_volume(self, region, added_volume):
        """Volume control of a cavity: inject ``added_volume`` [m^3; m^2 per m of depth in plane strain] into
        the cavity bounded by ``region``; its pressure becomes an unknown (reported as ``pressure/<region>``).

        A number is ramped (:math:`\\Delta V = a\\,t`), a callable gives :math:`\\Delta V(t)`. Unlike a
        prescribed pressure, this follows a balloon through its pressure maximum (limit point). The region
        may be a closed cavity or the part of it left by symmetry planes through the origin (which add
        nothing to :math:`-\\frac1d\\oint x\\cdot n`).
        """
        self._region(region, "facets")
        if any(r == region for r, _ in self._pressures + self._volumes):
            raise ParameterError(f"{region!r} already has a pressure or volume load")
        self._volumes.append((region, _Load(f"added volume in {region!r}", added_volume, ())))
        return self._changed()

    def add_traction(self, region, traction):
        """Dead traction [Pa = N/m^2 of reference area] on the surface ``region``: a vector (ramped) or
        ``traction(t)``. (A force per area, unlike ``soroshapes.Shapes.add_force``, a generalized force.)"""
        self._region(region, "facets")
        self._tractions.append((region, _Load(f"traction on {region!r}", traction, (self.gdim,))))
        return self._changed()

    def add_force(self, region, traction):
        """Deprecated name of :meth:`add_traction` (the load is a traction [Pa], not a force): warns, then
        adds the traction."""
        warnings.warn("Fem.add_force is deprecated: the load is a traction [Pa]; use Fem.add_traction(region, "
                      "traction)", DeprecationWarning, stacklevel=2)
        return self.add_traction(region, traction)

    def add_body_force(self, force_density):
        """Dead body force [N/m^3] on the whole body: a vector (ramped) or ``force_density(t)``."""
        self._body_forces.append(_Load("body force", force_density, (self.gdim,)))
        return self._changed()

    def add_gravity(self, acceleration=None):
        """Gravity on every material (density from the material): default :math:`g` = 9.80665 m/s^2 along -y
        in 2D (plane strain, axisymmetric) and -z in 3D; or a vector [m/s^2], ramped, or a callable."""
        if acceleration is None:
            acceleration = np.zeros(self.gdim)
            acceleration[-1] = -standard_gravity
        self._gravity = _Load("gravity", acceleration, (self.gdim,))
        return self._changed()

    def add_expansion(self, region, volumetric_strain):
        """Prescribed isotropic expansion of the cells of ``region``: the stress-free volume grows by the factor
        :math:`\\theta = 1 + e` (``volumetric_strain`` e [-], ramped, or ``e(t)``), through the split
        :math:`F = F_e F_g`, :math:`F_g = \\theta^{1/3} I` and energy :math:`\\theta\\,\\psi(F_e)` per reference
        volume. (In plane strain the out-of-plane growth is constrained and produces stress.) Used for
        actuation by swelling or heating, and by topology optimization."""
        self._region(region, "cells")
        self._expansions.append((region, _Load(f"expansion of {region!r}", volumetric_strain, ())))
        return self._changed()

    def add_tendon(self, points, tension, pull_direction=None):
        """A cable through anchor ``points`` (K, dim) [m] (entry first, tied at the last), pulled with
        ``tension`` [N; N per m of depth in plane strain]: a number (ramped) or ``tension(t)``. See
        :mod:`sorofem.fem.tendon` for the forces."""
        from .tendon import Tendon

        tendon = Tendon(points, _Load("tendon tension", tension, ()), pull_direction)
        self._tendons.append(tendon)
        return self._changed()

    def add_contact(self, obstacle, stiffness=None, friction=0.0, regularization=None, motion=None):
        """Contact with a rigid obstacle, a shape from :mod:`sorofem.sdf` of the mesh's dimension (e.g.
        ``sdf.Line(point, normal)`` for a floor, any boolean tree), optionally moving by ``motion(t)`` [m].

        Parameters
        ----------
        stiffness : float, optional
            Penalty stiffness k [Pa/m] (default ``100 E / h``; see :mod:`sorofem.fem.contact`).
        friction : float
            Coulomb coefficient :math:`\\mu` [-].
        regularization : float, optional
            Slip [m] over which friction builds up (default ``1e-3 h``).

        The force the obstacle exerts on the body and the contact area are reported per step in
        ``Trajectory.reactions["contact_k"]`` and ``Trajectory.contact_areas["contact_k"]``.
        """
        from .contact import Contact

        self._contacts.append(Contact(obstacle, stiffness, friction, regularization, motion,
                                      name=f"contact_{len(self._contacts)}"))
        return self._changed()

    def add_spring(self, region, stiffness):
        """Distributed springs to ground on ``region``: traction :math:`-k u`, ``stiffness`` k [N/m^3]."""
        k = float(stiffness)
        if not math.isfinite(k) or k <= 0:
            raise ParameterError(f"spring stiffness must be positive and finite [N/m^3], got {stiffness}")
        self._region(region, "facets")
        self._springs.append((region, k))
        return self._changed()

    # ------------------------------------------------------------------------------------------ assembly
    def _markers(self, names, dim):
        """One MeshTags for possibly overlapping facet regions: each distinct set of regions that some facet
        belongs to gets its own value; returns (meshtags, {region: tuple of the values that contain it})."""
        import dolfinx.mesh

        member = {}
        for k, name in enumerate(names):
            for e in self.mesh.facets(name):
                member.setdefault(int(e), set()).add(k)
        idx = np.array(sorted(member), dtype=np.int32)
        keys = [tuple(sorted(member[e])) for e in idx]
        # number the region sets that occur anywhere, identically on every rank
        sets = sorted(set().union(*self.mesh.comm.allgather(set(keys))))
        number = {key: i + 1 for i, key in enumerate(sets)}
        tags = dolfinx.mesh.meshtags(self.mesh.dolfinx, dim, idx,
                                     np.array([number[key] for key in keys], dtype=np.int32))
        ids = {name: tuple(number[key] for key in sets if k in key) or (-1,) for k, name in enumerate(names)}
        return tags, ids

    def _build(self):
        import ufl
        import dolfinx.fem
        import dolfinx.mesh

        msh = self.mesh.dolfinx
        tdim, fdim = msh.topology.dim, msh.topology.dim - 1
        if self.mixed:
            W = _dolfinx.mixed_space(msh, [("Lagrange", 2, "vector")] + self._pressure_parts())
        elif self.formulation == "plane_stress":  # displacement and thickness strain
            W = _dolfinx.mixed_space(msh, [("Lagrange", self.degree, "vector"), ("DG", self.degree - 1, None)])
        else:
            W = _dolfinx.function_space(msh, "Lagrange", self.degree, "vector")
        w = dolfinx.fem.Function(W, name="state")
        carry = getattr(self, "_carry", None)
        if carry is not None and carry.shape == w.x.array.shape:  # same spaces: keep the current state
            w.x.array[:] = carry
        p = e33 = None
        if self.mixed:
            u, *p = ufl.split(w)          # p: one pressure, or one per material ("per_material")
            v = ufl.TestFunctions(W)[0]
        elif self.formulation == "plane_stress":
            u, e33 = ufl.split(w)
            v, _ = ufl.TestFunctions(W)
        else:
            u, v = w, ufl.TestFunction(W)
        kin = Kinematics(self.formulation, msh, thickness_strain=e33)
        md = {"quadrature_degree": self.quadrature_degree}
        wt = kin.weight

        # cells: material markers (later assignments win)
        n_local = msh.topology.index_map(tdim).size_local + msh.topology.index_map(tdim).num_ghosts
        marker = np.zeros(n_local, dtype=np.int32)
        for k, (region, _) in enumerate(self._materials[1:], start=1):
            marker[self.mesh.cells(region)] = k
        ctags = dolfinx.mesh.meshtags(msh, tdim, np.arange(n_local, dtype=np.int32), marker)
        dx = ufl.Measure("dx", domain=msh, subdomain_data=ctags, metadata=md)

        # growth: theta = det F_g per cell (DG0), 1 where nothing expands
        growth = dolfinx.fem.Function(_dolfinx.function_space(msh, "DG", 0), name="growth")
        growth.x.array[:] = 1.0
        # F enters the residual as a plain expression of u (the dynamics substitute u); the stress
        # P = d(density)/dF is taken with a ufl.variable copy of it
        F = kin.F(u)

        def density(k, mat, F):  # stored energy per reference volume with the growth split F_e = F theta^(-1/3)
            Fe = F * growth ** (-1.0 / 3.0)
            if not self.mixed:
                return growth * mat.strain_energy(Fe)
            return growth * mat.mixed_energy(Fe, p[k if len(p) > 1 else 0])

        energy = sum(density(k, mat, F) * wt * dx(k) for k, (_, mat) in enumerate(self._materials))
        residual = ufl.derivative(energy, w, ufl.TestFunction(W))
        internal = residual
        stress_exprs = []  # von Mises of the Cauchy stress, per material
        Fv = ufl.variable(F)
        for k, (_, mat) in enumerate(self._materials):
            P = ufl.diff(density(k, mat, Fv), Fv)
            sigma = P * Fv.T / ufl.det(Fv)
            dev = sigma - ufl.tr(sigma) / 3 * ufl.Identity(3)
            stress_exprs.append(ufl.sqrt(1.5 * ufl.inner(dev, dev)))

        # facets: one marker for every region that carries a load, support or volume
        load_regions = list(dict.fromkeys(region for region, *_ in self._pressures + self._tractions + self._springs
                                          + self._volumes))
        if load_regions:
            ftags, fids = self._markers(load_regions, fdim)
            ds = ufl.Measure("ds", domain=msh, subdomain_data=ftags, metadata=md)
        v3 = kin.embed(v)
        terms = []   # LoadConstant: the constants that the load values are written into

        def constant(kind, region, load, shape=()):
            c = dolfinx.fem.Constant(msh, np.zeros(shape) if shape else 0.0)
            terms.append(LoadConstant(kind, region, c, load))
            return c

        for region, load in self._pressures:
            residual += pressure_term(kin, u, v3, constant("pressure", region, load), ds(fids[region]))
        d = kin.dimension

        def cavity_volume(name, measure=None):
            """Enclosed volume of the cavity bounded by ``name``; a cavity without load is integrated over
            its own tags, so it adds nothing to the residual's."""
            if measure is None:
                measure = ufl.ds(domain=msh, subdomain_data=self.mesh.meshtags(name),
                                 subdomain_id=self.mesh.regions[name], metadata=md)
            return volume_term(kin, u, measure)

        controls = []
        for region, load in self._volumes:
            pc = dolfinx.fem.Constant(msh, 0.0)
            unit = pressure_term(kin, u, v3, 1.0, ds(fids[region]))
            residual += pc * unit
            vexpr = cavity_volume(region, ds(fids[region]))
            controls.append(VolumeControl(region, load, VolumeConstraint(
                pressure=pc, load=dolfinx.fem.form(unit), value=dolfinx.fem.form(vexpr),
                gradient=dolfinx.fem.form(ufl.derivative(vexpr, w, ufl.TestFunction(W))))))
        for region, load in self._tractions:
            residual -= traction_term(kin, constant("traction", region, load, (self.gdim,)), v, ds(fids[region]))
        for region, k in self._springs:
            residual += spring_term(kin, k, u, v, ds(fids[region]))
        for load in self._body_forces:
            residual -= traction_term(kin, constant("body", None, load, (self.gdim,)), v, dx)
        if self._gravity is not None:
            residual -= gravity_term(kin, constant("gravity", None, self._gravity, (self.gdim,)), v, dx,
                                     [mat for _, mat in self._materials])

        # Dirichlet conditions
        Wu = W.sub(0) if self._split else W
        bcs, prescribed, support_dofs = [], [], {}
        fixed = [(r, comps, None) for r, comps in self._supports] + list(self._displacements)
        axis = None
        if self.formulation == "axisymmetric":
            axis = dolfinx.mesh.locate_entities_boundary(msh, fdim, lambda x: np.abs(x[0]) < 1e-9 * self._size())
            if msh.comm.allreduce(len(axis)):   # collective on every rank (no short-circuit: it hung on 2 ranks)
                fixed.append((None, [0], None))
        for region, comps, load in fixed:
            facets = axis if region is None else self.mesh.facets(region)
            consts_here = []
            for comp in comps:
                sub = Wu.sub(comp)
                dofs = dolfinx.fem.locate_dofs_topological(sub, fdim, facets)
                c = dolfinx.fem.Constant(msh, 0.0)
                bcs.append(dolfinx.fem.dirichletbc(c, dofs, sub))
                consts_here.append(c)
                if region is not None:
                    support_dofs.setdefault(region, {}).setdefault(comp, []).append(dofs)
            if load is not None:
                prescribed.append((tuple(consts_here), load))
        if self.pressure_space == "per_material":   # each material's pressure is zero off its cells
            bcs.extend(self._off_material_pressures(W, marker))

        jacobian = ufl.derivative(residual, w, ufl.TrialFunction(W))
        R_form, J_form = dolfinx.fem.form(residual), dolfinx.fem.form(jacobian)

        # outputs: strain energy, cavity volumes, P1 displacement at the vertices
        Fe = F * growth ** (-1.0 / 3.0)
        energy_form = dolfinx.fem.form(sum(growth * mat.strain_energy(Fe) * wt * dx(k)
                                           for k, (_, mat) in enumerate(self._materials)))
        DG0 = growth.function_space
        pts = _dolfinx.interpolation_points(DG0)
        material_cells = tuple(np.flatnonzero(marker == k).astype(np.int32) for k in range(len(self._materials)))
        von_mises = dolfinx.fem.Function(DG0, name="von_mises")
        stress_exprs = tuple(dolfinx.fem.Expression(e, pts) for e in stress_exprs)
        expansions = tuple((region, self.mesh.cells(region), load) for region, load in self._expansions)
        volume_forms = {name: dolfinx.fem.form(cavity_volume(name))
                        for name in dict.fromkeys(list(self.mesh.cavities) + [r for r, _ in self._volumes])}
        for control in controls:  # reference volume and a tolerance scale
            con = control.constraint
            con.reference = self._scalar(con.value)
            con.scale = max(abs(con.reference), self._size() ** d * 1e-6)
        V1 = _dolfinx.function_space(msh, "Lagrange", 1, "vector")
        u1 = dolfinx.fem.Function(V1, name="displacement")
        gatherer = VertexGatherer(V1)
        owned = W.dofmap.index_map.size_local * W.dofmap.index_map_bs
        for region in support_dofs:
            for comp in support_dofs[region]:
                dofs = np.unique(np.concatenate(support_dofs[region][comp]))
                support_dofs[region][comp] = dofs[dofs < owned]
        if self._split and self._tendons:
            raise ParameterError("tendons act on the displacement formulation: build the Fem with "
                                 "mixed=False and formulation 'plane_strain', 'axisymmetric' or '3d'")
        for tendon in self._tendons:
            tendon.setup(msh, W, owned, bcs)
        for contact in self._contacts:
            contact.setup(self, W, wt, w.x.array)
        self._forms = FemForms(
            space=W, state=w, kinematics=kin, dx=dx, cell_tags=ctags, bcs=tuple(bcs), prescribed=tuple(prescribed),
            load_constants=tuple(terms), volume_controls=tuple(controls), residual=R_form, jacobian=J_form,
            residual_ufl=residual, internal_ufl=internal, energy=energy_form, volumes=volume_forms,
            vertex_space=V1, vertex_displacement=u1, gatherer=gatherer, support_dofs=support_dofs, growth=growth,
            expansions=expansions, von_mises=von_mises, stress_expressions=stress_exprs,
            material_cells=material_cells)
        return self._forms

    def _size(self):
        lo, hi = self.mesh.bounds
        return float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))

    def set_load_level(self, t):
        """Write every load's value at load level (or time) ``t`` into the forms; returns the applied inputs by
        name (:func:`sorofem.snapshots.input_name`: ``pressure/<region>`` [Pa], ``tension/<k>`` [N],
        ``expansion/<region>`` [-], ``added_volume/<region>`` [m^3]). Used by the solvers."""
        b = self.forms
        values = {}
        for term in b.load_constants:
            v = term.load(t)
            term.constant.value = v
            if term.kind == "pressure":
                values[input_name("pressure", term.region)] = float(v)
        self._load_level = t
        for k, tendon in enumerate(self._tendons):
            values[input_name("tension", k)] = float(tendon.tension(t))
        if b.expansions:
            b.growth.x.array[:] = 1.0
            for region, cells, load in b.expansions:
                theta = 1.0 + float(load(t))
                if theta <= 0:
                    raise ParameterError(f"{load.name}: volumetric strain {theta - 1:.3g} at t={t} shrinks the "
                                         "volume to nothing; it must stay > -1")
                b.growth.x.array[cells] = theta
                values[input_name("expansion", region)] = theta - 1.0
        for control in b.volume_controls:
            added = float(control.load(t))
            control.constraint.target = control.constraint.reference + added
            values[input_name("added_volume", control.region)] = added
        self.set_prescribed_displacements(t)
        return values

    def set_prescribed_displacements(self, t):
        """Set the prescribed displacements [m] to their values at ``t``."""
        for consts_here, load in self.forms.prescribed:
            for c, vi in zip(consts_here, np.atleast_1d(load(t))):
                c.value = float(vi)

    @property
    def load_level(self):
        """The load level (or time [s] in dynamics) of the loads now applied."""
        return self._load_level

    # ------------------------------------------------------------------------------------------ outputs
    @property
    def contacts(self):
        """The contacts added by :meth:`add_contact`, in order (``contact_0``, ...). Their ``friction`` may be
        changed between solves (e.g. stand with sticking friction, then walk with the real one): it is read
        at every evaluation, the forms do not depend on it."""
        return tuple(self._contacts)

    @property
    def forms(self):
        """The compiled model (:class:`FemForms`: space, state, forms), built now if a change made it stale."""
        return self._forms or self._build()

    @property
    def function_space(self):
        """The DOLFINx FunctionSpace of the state (mixed in the mixed and plane-stress formulations)."""
        return self.forms.space

    @property
    def num_dofs(self):
        """Number of unknowns of the model (global, every field) [-]."""
        imap = self.forms.space.dofmap
        return imap.index_map.size_global * imap.index_map_bs

    @property
    def materials(self):
        """((region or None, Material), ...): the material of every cell, later entries win on their region."""
        return tuple(self._materials)

    @property
    def pressure_regions(self):
        """Names of the regions under a prescribed follower pressure (:meth:`add_pressure`)."""
        return tuple(r for r, _ in self._pressures)

    @property
    def mixed_state(self):
        """Whether the state is a mixed function (displacement, then pressure or thickness strain): mixed
        or plane-stress formulation."""
        return self._split

    @property
    def size(self):
        """Diagonal of the mesh's bounding box [m]: the length scale of tolerances and penalties."""
        return self._size()

    @property
    def displacement(self):
        """The current displacement as a DOLFINx Function (collapsed copy in the mixed formulation)."""
        b = self.forms
        return b.state.sub(0).collapse() if self._split else b.state

    def _scalar(self, form):
        import dolfinx.fem
        from mpi4py import MPI

        return self.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)

    def _reactions(self, newton):
        vec = newton.assemble_residual(lift=False)
        arr = vec.getArray(readonly=True)
        out = {}
        for region, comps in self.forms.support_dofs.items():
            f = np.zeros(self.gdim)
            for comp, dofs in comps.items():
                f[comp] = self.mesh.comm.allreduce(float(arr[dofs].sum()))
            out[region] = f
        return out

    def record(self, traj, t, iterations, inputs, newton, monitor_stability=False, kinetic=0.0):
        """Append the converged state at ``t`` to ``traj`` (a :meth:`new_trajectory`): vertex displacements,
        ``inputs`` (from :meth:`set_load_level`) with the pressures of volume controls, cavity volumes,
        reactions from ``newton``'s residual, von Mises stress, ``kinetic`` energy [J], and with
        ``monitor_stability`` the lowest eigenvalue. Collective."""
        b = self.forms
        if monitor_stability:
            traj.lowest_eigenvalue.append(self._lowest_eigenvalue(traj.lowest_eigenvalue))
        b.vertex_displacement.interpolate(self.displacement)
        u_vert = b.gatherer.gather_function(b.vertex_displacement)
        volumes = {k: self._scalar(f) for k, f in b.volumes.items()}
        inputs = {**inputs, **{input_name("pressure", c.region): float(c.constraint.pressure.value)
                               for c in b.volume_controls}}
        reactions = self._reactions(newton)
        areas = {}
        for contact in self._contacts:
            reactions[contact.name], areas[contact.name] = contact.totals(b.state.x.array, self._load_level)
        vm = self.von_mises()
        n_owned = self.mesh.dolfinx.topology.index_map(self.mesh.dolfinx.topology.dim).size_local
        vm_cells = self.mesh.comm.gather(vm.x.array[:n_owned].copy(), root=0)
        vm_cells = np.concatenate(vm_cells) if vm_cells is not None else None
        traj.append(t, u_vert, iterations, self._scalar(b.energy), inputs, volumes, reactions,
                    contact_areas=areas,
                    von_mises=vm_cells, kinetic=kinetic, max_von_mises=self.mesh.comm.allreduce(float(vm.x.array[:n_owned].max(initial=0.0)),
                                                                              op=_max_op()))

    def von_mises(self):
        """Von Mises equivalent of the Cauchy stress [Pa] at the current state, one value per cell (DG0
        Function): :math:`\\sqrt{3/2\\, \\mathrm{dev}\\,\\sigma : \\mathrm{dev}\\,\\sigma}`,
        :math:`\\sigma = J^{-1} P F^T` (3D stress, including the out-of-plane component in plane strain)."""
        b = self.forms
        vm = b.von_mises
        for expr, cells in zip(b.stress_expressions, b.material_cells):
            if len(cells):
                vm.interpolate(expr, cells)
        vm.x.scatter_forward()
        return vm

    def _lowest_eigenvalue(self, history):
        """The lowest eigenvalue of K phi = lambda M phi [1/s^2]. Shift-and-invert finds the eigenvalues
        nearest its shift, so the shift is placed below the last lowest value by the scale of the first one
        (the unloaded fundamental); of the three eigenvalues nearest it, the smallest is the lowest."""
        if not history:
            return float(self.eigen(1).eigenvalues[0])
        scale = abs(history[0]) or 1.0
        shift = min(history[-1], 0.0) - scale
        return float(self.eigen(3, shift=shift).eigenvalues.min())

    def evaluate(self, points):
        """Displacement [m] at reference points (N, gdim): (N, gdim) on every rank.

        Raises :class:`ParameterError` if a point lies outside the mesh."""
        from mpi4py import MPI

        msh = self.mesh.dolfinx
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if pts.shape[1] != self.gdim:
            raise ParameterError(f"points must have shape (N, {self.gdim}), got {pts.shape}")
        p3 = np.zeros((len(pts), 3))
        p3[:, : self.gdim] = pts
        cells = _dolfinx.colliding_cells(msh, p3)
        u = self.displacement
        vals = np.full((len(pts), self.gdim), np.nan)
        found = np.zeros(len(pts), dtype=np.int32)
        n_owned = msh.topology.index_map(msh.topology.dim).size_local
        for i in range(len(pts)):
            c = cells.links(i)
            c = c[c < n_owned]
            if len(c):
                vals[i] = u.eval(p3[i], c[:1])
                found[i] = 1
        hits = msh.comm.allreduce(found, op=MPI.SUM)
        if np.any(hits == 0):
            raise ParameterError(f"points {pts[hits == 0].tolist()} lie outside the mesh")
        vals[found == 0] = 0.0
        return msh.comm.allreduce(vals, op=MPI.SUM) / hits[:, None]

    # ------------------------------------------------------------------------------------------ solve
    def solve(self, load_level=1.0, steps=10, min_step=None, max_step=None, max_iterations=25, predictor=True,
              monitor_stability=False, progress=None, linear_start=None, *, t_end=None):
        """March the load level from 0 to ``load_level`` in adaptive steps; return a :class:`Trajectory`.

        A step whose Newton iteration fails (no convergence in ``max_iterations``, a non-finite residual,
        a failed factorization) is undone and halved; an easy step (at most 4 iterations) lets the next one
        grow by 1.5x up to ``max_step``. Reaching ``min_step`` raises :class:`ConvergenceError` naming the
        load level, with the converged part of the trajectory in its ``trajectory`` attribute.

        Parameters
        ----------
        load_level : float
            Final load level t [-]: a load given as a number ``a`` reaches ``a * load_level``; a callable
            load ``f`` reaches ``f(load_level)``.
        steps : int
            Requested number of steps: initial and largest step ``load_level / steps`` unless ``max_step`` is set.
        min_step : float, optional
            Smallest step before giving up (default ``load_level / steps / 1024``).
        predictor : bool
            Start each step from the linear extrapolation of the last two states.
        monitor_stability : bool
            After each converged step compute the lowest eigenvalue of :math:`K\\phi = \\lambda M\\phi`
            (:attr:`Trajectory.lowest_eigenvalue`, [1/s^2]); it crosses zero where the equilibrium
            loses stability (buckling, limit points).
        progress : bool, optional
            Default: a progress bar when attached to a terminal, quiet otherwise; ``True``: also one line per
            step when not on a terminal; ``False``: never (:class:`sorofem.io.Progress`, rank 0).
        t_end : float, optional
            Deprecated name of ``load_level`` (it is not a time): warns, then works as ``load_level``.
        linear_start : float, optional
            A fraction f of the body's size: the first step is cut so that its linear response moves no point by
            more than f times the diagonal of the bounding box (:func:`sorofem.fem.continuation.linear_step`),
            then grows after easy steps. For thin pressurized walls, whose unloaded tangent is far softer than
            the inflated wall (the first Newton correction of a full step overshoots many times), e.g. 0.02.
        """
        from petsc4py import PETSc

        if t_end is not None:
            warnings.warn("Fem.solve(t_end=...) is deprecated: the final load level is now called load_level "
                          "(Fem.solve(load_level=...))", DeprecationWarning, stacklevel=2)
            load_level = t_end
        t_end = load_level
        if not (math.isfinite(t_end) and t_end > 0):
            raise ParameterError(f"load_level must be positive, got {t_end}")
        if int(steps) < 1:
            raise ParameterError(f"steps must be >= 1, got {steps}")
        if linear_start is not None and not (math.isfinite(linear_start) and linear_start > 0):
            raise ParameterError(f"linear_start must be a positive fraction of the body's size, got {linear_start}")
        b = self.forms
        self.use_ramps(True)
        dt0 = t_end / int(steps)
        x = _dolfinx.petsc_vec(b.state)
        controls = [c.constraint for c in b.volume_controls]
        newton = self.newton_solver(b.residual, b.jacobian, max_iterations)
        traj = self.new_trajectory("load")
        inputs = self.set_load_level(0.0)
        out = newton.solve()  # the initial state (loads at t = 0 may be non-zero for callables)
        if not out.converged:
            newton.destroy()
            raise ConvergenceError(f"the initial state (t = 0) did not converge: {out.reason}. Check that the "
                                   "supports prevent rigid motion and that the loads at t = 0 are reasonable")
        self.record(traj, 0.0, out.iterations, inputs, newton, monitor_stability)
        self.commit_contacts()   # after recording: the reported friction is that of the step's slip
        dt_first = dt0
        if linear_start is not None:
            from .continuation import linear_step
            dt_first = min(dt0, linear_step(self, newton, float(linear_start), 1e-6 * t_end))
            self.set_load_level(0.0)
        state = {"x_old": x.copy(), "x_prev": None, "dt_prev": None,
                 "p_old": [float(c.pressure.value) for c in controls]}

        def attempt(t, dt):
            if predictor and state["x_prev"] is not None:  # u_n + dt/dt_prev (u_n - u_{n-1})
                x.axpy(dt / state["dt_prev"], state["x_old"])
                x.axpy(-dt / state["dt_prev"], state["x_prev"])
                x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            state["inputs"] = self.set_load_level(t + dt)
            return newton.solve()

        def accept(t, dt, out):
            self.record(traj, t, out.iterations, state["inputs"], newton, monitor_stability)
            self.commit_contacts()
            state.update(x_prev=state["x_old"], dt_prev=dt, x_old=x.copy(),
                         p_old=[float(c.pressure.value) for c in controls])
            bar.to(t, newton=out.iterations)

        def reject(t, dt, out):
            log.info("step t=%.4g -> %.4g failed (%s); halving", t, t + dt, out.reason)
            state["x_old"].copy(x)
            x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            for c, p in zip(controls, state["p_old"]):
                c.pressure.value = p
            state["x_prev"] = None  # restart the predictor after a failure

        wall = _time.perf_counter()
        t = 0.0
        bar = Progress(t_end, "Fem.solve", progress, self.mesh.comm, unit="load")
        try:
            t = march(0.0, t_end, dt_first, float(min_step or dt0 / 1024), float(max_step or dt0), attempt, accept,
                      reject, "more or smaller steps, degree=2 with mixed=True for nearly incompressible "
                      "materials, a displacement- or volume-controlled load past a limit point, or supports "
                      "that remove rigid-body motion")
        except ConvergenceError as e:
            t = e.load_level
            e.trajectory = traj
            raise
        finally:
            bar.close()
            newton.destroy()
            self.set_load_level(t)
        traj.metadata["wall_time_s"] = _time.perf_counter() - wall
        return traj

    def follow(self, load_level=1.0, steps=10, until=None, max_steps=200, min_step=None, max_step=None,
               max_iterations=15, monitor_stability=False, branch_switch=False, mode_sign=1.0, t_min=0.0,
               progress=False, *, t_end=None):
        """Follow the equilibrium path by pseudo-arc-length continuation, the load factor ``t`` being an
        unknown: through limit points of pressure, force or displacement control (where :meth:`solve` stops),
        with bifurcation detection and branch switching (``monitor_stability=True, branch_switch=True``),
        until the load level ``load_level`` [-] (or ``until``, ``max_steps``).
        Returns a :class:`Trajectory` whose ``times`` are the load factors along the path. See
        :func:`sorofem.fem.continuation.follow` for the method and the parameters (there ``t_end`` is
        ``load_level``); ``t_end=`` here is the deprecated name of ``load_level``."""
        from .continuation import follow

        if t_end is not None:
            warnings.warn("Fem.follow(t_end=...) is deprecated: the final load level is now called load_level "
                          "(Fem.follow(load_level=...))", DeprecationWarning, stacklevel=2)
            load_level = t_end
        t_end = load_level

        return follow(self, t_end=t_end, steps=steps, until=until, max_steps=max_steps, min_step=min_step,
                      max_step=max_step, max_iterations=max_iterations, monitor_stability=monitor_stability,
                      branch_switch=branch_switch, mode_sign=mode_sign, t_min=t_min, progress=progress)

    def newton_solver(self, R, J, max_iterations=25):
        """A :class:`~sorofem.fem.newton.NewtonSolver` for the compiled residual/Jacobian forms ``R``, ``J``
        (e.g. :attr:`FemForms.residual`, or a dynamic residual built from it) with this model's Dirichlet
        conditions, volume controls, tendons, contacts and linear solver options. Destroy it after use."""
        b = self.forms

        point_loads = self._tendons + self._contacts  # forces at nodes, with their derivatives

        def point_forces(b_array, u_array):
            for load in point_loads:
                load.subtract(b_array, u_array, self._load_level)

        def point_tangent(A, u_array):
            for load in point_loads:
                load.add_tangent(A, u_array, self._load_level)

        gamg = self.petsc_options.get("pc_type") == "gamg" and not self._split
        return NewtonSolver(R, J, b.state, list(b.bcs), self.petsc_options, scale=self._size(), fields=self._fields(),
                            near_nullspace=NewtonSolver.rigid_body_modes(b.space) if gamg else None,
                            max_iterations=max_iterations, constraints=[c.constraint for c in b.volume_controls],
                            point_forces=point_forces if point_loads else None,
                            point_tangent=point_tangent if point_loads else None)

    def _fields(self):
        """The fields of the state for Newton's correction test, each with its scale in its own unit: the
        displacement [m] (the bounding box's diagonal), the mixed formulation's pressure [Pa] (the largest
        shear modulus) or plane stress's thickness strain [-] (1); None for a displacement-only state."""
        if not self._split:
            return None
        W = self.forms.space
        second = ("pressure", max(mat.G for _, mat in self._materials)) if self.mixed else ("thickness strain", 1.0)
        n_sub = len(self._pressure_parts()) if self.mixed else 1
        return [("displacement", np.asarray(W.sub(0).collapse()[1]), self._size()),
                (second[0], np.concatenate([np.asarray(W.sub(1 + k).collapse()[1]) for k in range(n_sub)]),
                 second[1])]

    def _off_material_pressures(self, W, marker):
        """Dirichlet conditions p_k = 0 on the unknowns of material k's pressure field that touch none of its
        cells (``marker``: the material of each local cell). A rank sees its own cells only: the touching is
        summed over the ranks that share an unknown."""
        import dolfinx.fem
        from petsc4py import PETSc

        msh = self.mesh.dolfinx
        tdim = msh.topology.dim
        everywhere = np.arange(len(marker), dtype=np.int32)
        touched = dolfinx.fem.Function(W)
        vec = _dolfinx.petsc_vec(touched)
        bcs = []
        for k in range(len(self._materials)):
            sub = W.sub(1 + k)
            touched.x.array[:] = 0.0
            touched.x.array[dolfinx.fem.locate_dofs_topological(sub, tdim, np.flatnonzero(marker == k))] = 1.0
            vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            dofs = dolfinx.fem.locate_dofs_topological(sub, tdim, everywhere)
            off = np.asarray(dofs[touched.x.array[dofs] == 0.0], dtype=np.int32)
            bcs.append(dolfinx.fem.dirichletbc(dolfinx.fem.Constant(msh, 0.0), off, sub))
        return bcs

    def _pressure_parts(self):
        """The pressure field(s) of the mixed state, as parts of :func:`sorofem._dolfinx.mixed_space`."""
        if self.pressure_space == "p0":
            return [("DG", 0, None)]
        n = len(self._materials) if self.pressure_space == "per_material" else 1
        return [("Lagrange", 1, None)] * n

    def _loads(self):
        """Every load of the model (to switch numbers between ramped and constant)."""
        yield from (load for _, load in self._pressures + self._tractions + self._volumes + self._expansions)
        yield from (load for _, _, load in self._displacements)
        yield from self._body_forces
        yield from (t.tension for t in self._tendons)
        if self._gravity is not None:
            yield self._gravity

    def use_ramps(self, ramp):
        """Loads given as numbers are ramped, ``a t`` (``True``: quasi-static, t a load level), or held
        constant, ``a`` (``False``: dynamics, t a time [s])."""
        for load in self._loads():
            load.ramp = bool(ramp)

    def commit_contacts(self):
        """A step converged: the contacts measure the next step's slip from the current state."""
        for contact in self._contacts:
            contact.commit(self.forms.state.x.array)

    def new_trajectory(self, time_kind):
        """An empty :class:`Trajectory` of this model (``time_kind``: ``"load"`` or ``"time"``) that knows the
        mesh's named regions and cavities, which :meth:`Trajectory.save` writes into the snapshot file."""
        b = self.forms
        return Trajectory(b.gatherer.vertices, b.gatherer.cells, self._cell_type(), time_kind=time_kind,
                          metadata=self._metadata(), comm=self.mesh.comm, regions=b.gatherer.regions(self.mesh),
                          cavities=tuple(self.mesh.cavities))

    def simulate(self, t_end, dt, scheme="generalized_alpha", rho_inf=0.8, beta=0.25, gamma=0.5,
                 rayleigh=(0.0, 0.0), velocity=None, max_step=None, min_step=None, max_iterations=25,
                 record_every=1, progress=None):
        """Implicit dynamics from the current state (the reference one, or the result of :meth:`solve`) to
        time ``t_end`` [s]; returns a :class:`Trajectory` (``time_kind="time"``, with kinetic energies).

        Loads given as callables are functions of time [s] here; loads given as numbers are held constant
        (the quasi-static :meth:`solve` ramps them instead). See :mod:`sorofem.fem.dynamics`.

        Parameters
        ----------
        dt : float
            Time step [s]. A step whose Newton iteration fails is halved (down to ``min_step``, default
            ``dt/1024``), and steps grow back by 1.5x after easy ones up to ``max_step`` (default ``dt``:
            a fixed step unless a failure forces a smaller one).
        scheme : {"generalized_alpha", "newmark"}
        rho_inf : float
            Spectral radius at infinite frequency for generalized-alpha (1: no numerical damping).
        beta, gamma : float
            Newmark parameters (``scheme="newmark"``).
        rayleigh : (alpha_M [1/s], alpha_K [s])
            Rayleigh damping :math:`C = \\alpha_M M + \\alpha_K K`; for a damping ratio :math:`\\zeta` at two
            angular frequencies see :meth:`rayleigh_coefficients`.
        velocity : (gdim,) array or callable, optional
            Initial velocity [m/s]: a constant vector, or ``f(x) -> (gdim, N)`` array as DOLFINx interpolates.
        record_every : int
            Keep every n-th step in the trajectory (the last one always).
        progress : bool, optional
            Default: a progress bar when attached to a terminal, quiet otherwise (see :meth:`solve`).
        """
        from .dynamics import simulate

        return simulate(self, t_end, dt, scheme=scheme, rho_inf=rho_inf, beta=beta, gamma=gamma, rayleigh=rayleigh,
                        velocity=velocity, max_step=max_step, min_step=min_step, max_iterations=max_iterations,
                        record_every=record_every, progress=progress)

    @staticmethod
    def rayleigh_coefficients(zeta, omega_1, omega_2):
        """(alpha_M, alpha_K) giving damping ratio ``zeta`` at the angular frequencies ``omega_1`` and
        ``omega_2`` [rad/s]: :math:`\\zeta(\\omega) = \\alpha_M/(2\\omega) + \\alpha_K\\omega/2`."""
        w1, w2 = float(omega_1), float(omega_2)
        if not 0 < w1 < w2:
            raise ParameterError(f"need 0 < omega_1 < omega_2, got {omega_1}, {omega_2}")
        return 2 * zeta * w1 * w2 / (w1 + w2), 2 * zeta / (w1 + w2)

    def eigen(self, n=6, shift=0.0):
        """The ``n`` eigenpairs of :math:`K\\phi = \\omega^2 M\\phi` nearest ``shift`` [1/s^2] about the current
        state: vibration modes, or, along a load path, the buckling indicator (see :mod:`sorofem.fem.eigen`).
        With ``mixed=True`` the pressure is condensed out: the modes of nearly incompressible bodies without
        locking. Returns :class:`sorofem.fem.eigen.Modes`."""
        from .eigen import eigenmodes

        return eigenmodes(self, n=n, shift=shift)

    @property
    def _split(self):
        """The state is a mixed function (displacement, then pressure or thickness strain)."""
        return self.mixed or self.formulation == "plane_stress"

    def _cell_type(self):
        return self.mesh.dolfinx.topology.cell_type.name

    def _metadata(self):
        return {"formulation": self.formulation, "degree": self.degree, "mixed": self.mixed,
                "pressure_space": self.pressure_space,
                "materials": [{"region": r or "all", "name": m.name, "E": m.E, "nu": m.nu, "density": m.density}
                              for r, m in self._materials],
                "loads": {"pressures": [r for r, _ in self._pressures], "supports": [r for r, _ in self._supports]}}
