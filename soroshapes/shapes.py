r"""Reduced-order Cosserat beams with a modal strain basis (geometric variable strain), the ``Shapes`` of the seed.

The model
---------
A rod of length :math:`L` [m] along its body :math:`x` axis; its cross-section (a 2D SDF) lies in the body
:math:`(y, z)` plane. The strain :math:`\xi = (\kappa_x, \kappa_y, \kappa_z, \epsilon_x, \gamma_y, \gamma_z)`
(torsion [1/m], two bendings [1/m], stretch, two shears [-]; angular part first as in :mod:`soroshapes.lie`)
is

.. math:: \xi(\sigma) = \Theta(\sigma)\, q + \xi_\circ(\sigma), \qquad \xi_\circ = (0, 0, 0, 1, 0, 0)
          \text{ for a straight rod,}

where :math:`\Theta` stacks, for each strain :math:`i` with ``dofs[i] > 0``, the first ``dofs[i]`` functions of
the basis (Sorotoki's ``dof`` mask). The frames :math:`g(\sigma) \in SE(3)` solve :math:`g' = g\hat\xi`,
:math:`g(0) =` ``base``; they are integrated by a Magnus expansion of order 2 or 4 on ``segments`` pieces (see
:mod:`soroshapes._beam`). The equations of motion are

.. math:: M(q)\ddot q + C(q, \dot q)\dot q + D\dot q + K q = f_g(q) + G(q)\, u + f_{ext}(q, \dot q, t),

with :math:`M = \int J^T \mathcal M J\, d\sigma`, :math:`K = \int \Theta^T \mathcal K \Theta\, d\sigma` (constant:
the material is linear in the strain), :math:`\mathcal K = \mathrm{diag}(GJ_p, EI_y, EI_z, EA, GA, GA)` (plus the
product-of-area coupling :math:`-EI_{yz}` of the bendings) and :math:`\mathcal M = \rho\,\mathrm{diag}(J_p, I_y,
I_z, A, A, A)`. Inputs are internal actuation wrenches (pressure chambers and tendons placed off the axis),
point wrenches, contact with SDF environments and user callables.

Units: SI throughout (m, kg, s, N, Pa); :math:`q` carries the unit of its strain times the (dimensionless) basis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sorofem._lazy import moved_attributes
from sorofem.errors import ParameterError

from . import beam as _bm
from .basis import Basis
from .beam import BeamModel, IKResult

__all__ = ["Shapes", "IKResult", "STRAINS", "precompile"]
#: one trajectory type for beams, trees and networks (README.md, "Moved names")
__getattr__ = moved_attributes(__name__, {"BeamTrajectory": "soroshapes.trajectory.Trajectory"})


#: Names of the six strains, in the order of the ``dofs`` mask.
STRAINS = ("torsion", "bending_y", "bending_z", "stretch", "shear_y", "shear_z")



def _as_pose(base):
    g = np.eye(4) if base is None else np.array(base, dtype=float)
    if g.shape == (3,):
        p, g = g, np.eye(4)
        g[:3, 3] = p
    if g.shape != (4, 4) or not np.all(np.isfinite(g)):
        raise ParameterError(f"base must be a 4x4 homogeneous pose (or a 3-vector position) [m], got shape "
                             f"{np.shape(base)}")
    R = g[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ParameterError("base rotation must be orthonormal with det +1; build it with soroshapes.lie."
                             "expSO3 or scipy.spatial.transform.Rotation")
    return g


def _material_moduli(material, E, G):
    """(E, G, density, damping ratio) from a sorofem material (small-strain moduli) or explicit numbers."""
    if material is not None:
        try:
            E = material.E if E is None else E
            G = material.G if G is None else G
            rho = material.density
            zeta = getattr(material, "damping", 0.0)
        except AttributeError as err:
            raise ParameterError(f"material must provide E, G [Pa], density [kg/m^3] (a sorofem.materials "
                                 f"material does): {err}") from None
    else:
        raise ParameterError("give a material, e.g. material=sorofem.materials.NeoHookean(E=1e6, nu=0.45, "
                             "density=1000)")
    for name, v in (("Young's modulus E", E), ("shear modulus G", G), ("density", rho)):
        if not (np.isfinite(v) and v > 0):
            raise ParameterError(f"{name} must be positive and finite, got {v!r}")
    return float(E), float(G), float(rho), float(zeta)


def _gregory_weights(sigma, per):
    """Quadrature weights [m] at the nodes ``sigma`` exact for cubics on every piece of ``per[k]`` equal
    segments: Gregory's end corrections (3/8, 7/6, 23/24, 1, ..., 1, 23/24, 7/6, 3/8) h from 5 segments up,
    Simpson (1, 4, 2, 4, 1) h/3 for 4 and (1, 4, 1) h/3 for 2, Simpson's 3/8 rule for 3, the trapezoid for 1."""
    small = {1: [0.5, 0.5], 2: [1 / 3, 4 / 3, 1 / 3], 3: [3 / 8, 9 / 8, 9 / 8, 3 / 8],
             4: [1 / 3, 4 / 3, 2 / 3, 4 / 3, 1 / 3]}
    w = np.zeros(len(sigma))
    a = 0
    for m in per:
        h = (sigma[a + m] - sigma[a]) / m
        if m in small:
            c = np.array(small[m])
        else:
            c = np.ones(m + 1)
            c[:3] = c[-3:][::-1] = (3 / 8, 7 / 6, 23 / 24)
        w[a:a + m + 1] += h * c
        a += m
    return w


# Small callables stored by a Shapes instead of closures, so that a Shapes pickles (multiprocessing, a
# simulated board's process) whenever the user's own callables do.
@dataclass(frozen=True)
class _Constant:
    value: np.ndarray

    def __call__(self, t):
        return self.value


@dataclass(frozen=True)
class _Vector3:
    fn: object

    def __call__(self, t):
        return np.asarray(self.fn(t), dtype=float).reshape(3)


@dataclass(frozen=True)
class _Linear:
    column: np.ndarray

    def __call__(self, u):
        return self.column * u


@dataclass(frozen=True)
class _Rows:
    row: np.ndarray

    def __call__(self, s):
        return np.tile(self.row, (len(s), 1))


@dataclass(frozen=True)
class _PerPoint:
    fn: object
    width: int

    def __call__(self, s):
        return np.asarray([self.fn(x) for x in s], dtype=float).reshape(len(s), self.width)


class Shapes:
    r"""A Cosserat beam with a modal strain basis.

    Parameters
    ----------
    basis : Basis or sequence of 6 Basis/None
        One basis for every active strain (strain ``i`` uses its first ``dofs[i]`` functions), or one per strain.
    dofs : 6 ints
        Number of modes per strain (torsion, bending y, bending z, stretch, shear y, shear z); 0 fixes it.
    length : float [m]
    section : 2D SDF (:mod:`sorofem.sdf`), e.g. ``sdf.Circle(5*mm)``; its centroid is on the backbone and its
        2D axes (x, y) are the body axes (y, z).
    material : a :mod:`sorofem.materials` material (its small-strain ``E``, ``G``, ``density``, ``damping``).
    base : (4, 4) pose of the clamped end (default identity: the rod points along the spatial x axis).
    xi0 : (6,) reference strain, or callable ``sigma -> (6,)``; default straight ``(0, 0, 0, 1, 0, 0)``.
    segments : int
        Magnus segments (the nodes are their ends; default 20); pieces of a piecewise basis get whole segments.
    order : 2 or 4
        Magnus order (4: two Gauss points per segment, fourth-order accurate).
    damping : float, optional
        Kelvin-Voigt time constant :math:`\tau` [s]: :math:`D = \tau K` (stiffness-proportional: mode
        :math:`i` gets the damping ratio :math:`\tau\omega_i/2`). Default: from the material's damping ratio
        :math:`\zeta` as :math:`\tau = 2\zeta/\omega_1`, which damps the lowest mode of the *enabled* strains
        at :math:`\zeta` and stiffer modes more (enabling a softer bending direction raises the damping of
        the stiffer one); give ``damping`` explicitly to control it.
    E, G : float [Pa], optional
        Override the material's moduli.
    contact_radius : float [m], optional
        Radius of the tube that touches obstacles (default: the largest distance from the centroid to the
        section's boundary along its axes, i.e. the bounding half-width).
    quadrature : "gregory", "lobatto" or "trapezoid"
        How the mass, Coriolis and gravity integrals are summed (:mod:`soroshapes.beam`): at the nodes with
        Gregory's end-corrected trapezoidal rule, exact for cubics, error :math:`O(h^4)` at no extra work
        (default); three-point Gauss-Lobatto (Simpson) in every segment through its midpoint, :math:`O(h^4)`
        with a smaller constant at twice the kinematic work; or the plain trapezoidal rule, :math:`O(h^2)`
        (the discretization before issue 18).

    Examples
    --------
    >>> import numpy as np
    >>> from sorofem import sdf, materials
    >>> from soroshapes import Basis, Shapes
    >>> shp = Shapes(Basis.chebyshev(3), dofs=(0, 0, 3, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
    ...              material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), damping=0.0)
    >>> shp.n
    3
    >>> tip = shp.forward_kinematics(np.array([np.pi / 0.1, 0, 0]))[-1, :3, 3]   # one constant-curvature half turn
    >>> bool(np.allclose(tip, [0, 2 * 0.1 / np.pi, 0], atol=1e-9))
    True
    """

    def __init__(self, basis, dofs, length, section, material=None, *, base=None, xi0=None, segments=20,
                 order=4, damping=None, E=None, G=None, contact_radius=None, quadrature="gregory"):
        self.length = float(length)
        if not (np.isfinite(self.length) and self.length > 0):
            raise ParameterError(f"length must be a positive number of metres, got {length!r}")
        dofs = tuple(int(d) for d in dofs) if np.ndim(dofs) == 1 else None
        if dofs is None or len(dofs) != 6 or any(d < 0 for d in dofs):
            raise ParameterError("dofs must be 6 non-negative integers (torsion, bending_y, bending_z, stretch, "
                                 "shear_y, shear_z), e.g. (0, 3, 3, 0, 0, 0)")
        if sum(dofs) == 0:
            raise ParameterError("dofs are all zero: the beam would have no degrees of freedom")
        self.dofs = dofs
        self._bases = self._strain_bases(basis, dofs)
        if order not in (2, 4):
            raise ParameterError(f"order must be 2 or 4 (Magnus expansion), got {order!r}")
        self.order = order
        segments = int(segments)
        if segments < 1:
            raise ParameterError(f"segments must be >= 1, got {segments}")
        self._segments = segments
        if quadrature not in ("gregory", "lobatto", "trapezoid"):
            raise ParameterError(f"quadrature must be 'gregory' (at the nodes, error ~h^4), 'lobatto' (Simpson in "
                                 f"every segment through its midpoint, ~h^4 with a smaller constant, twice the "
                                 f"kinematic work) or 'trapezoid' (at the nodes, ~h^2), got {quadrature!r}")
        self.quadrature = quadrature
        self.base = _as_pose(base)
        self.E, self.G, self.density, zeta = _material_moduli(material, E, G)
        self.material = material
        self._section(section, contact_radius)
        self._xi0 = self._reference_strain(xi0)
        #: The frozen description (:class:`soroshapes.beam.BeamModel`) and the default workspace
        #: (:class:`soroshapes.beam.BeamData`) of the methods; ``data=`` selects another (``make_data()``).
        self.model = self._discretize(segments)
        self.data = self.model.make_data()
        self._loads = []         # soroshapes.beam load terms, in the order they were added
        self._plan = None        # their LoadPlan, made on first use
        if damping is None:
            damping = 2.0 * zeta / self.natural_frequencies(1)[0] / (2 * np.pi) if zeta > 0 else 0.0
        if not (np.isfinite(damping) and damping >= 0):
            raise ParameterError(f"damping must be a time constant >= 0 [s], got {damping!r}")
        self.damping = float(damping)

    @property
    def damping(self):
        """Kelvin-Voigt time constant :math:`\tau` [s] of :math:`D = \tau K`."""
        return self._damping

    @damping.setter
    def damping(self, tau):
        tau = float(tau)
        if not (np.isfinite(tau) and tau >= 0):
            raise ParameterError(f"damping must be a time constant >= 0 [s], got {tau!r}")
        self._damping, self._plan = tau, None

    def _add_load(self, term):
        self._loads.append(term)
        self._plan = None

    def _load_plan(self):
        if self._plan is None:
            self._plan = _bm.LoadPlan.of(self.model, self._loads, self.damping)
        return self._plan

    @property
    def evaluation_path(self):
        """How :meth:`forward_dynamics` (and so a :class:`~soroshapes.model.Model` block) evaluates this beam:
        ``"compiled"`` (one numba call: gravity, inputs, point loads) or ``"python: ..."`` naming the load terms
        that need Python (contact, tendons, user forces; several times slower)."""
        slow = sorted({type(ld).__name__ for ld in self._loads if isinstance(ld, (_bm.Contact, _bm.Tendon,
                                                                                    _bm.UserForce))})
        return "compiled" if not slow else "python: " + ", ".join(slow)

    def make_data(self):
        """A new workspace for this beam (queries with ``data=`` leave the default one untouched)."""
        return self.model.make_data()

    @property
    def sigma(self):
        """Arc lengths of the nodes [m], (N+1,)."""
        return self.model.sigma

    @property
    def K(self):
        """Stiffness matrix (n, n) [N m per coordinate^2]."""
        return self.model.K

    @property
    def weights(self):
        """Trapezoidal weights [m] of the nodes, (N+1,): a node's share of a distributed (contact) force."""
        return self.model.node_weights

    @property
    def loads(self):
        """The load terms (:mod:`soroshapes.beam`) in the order they were added."""
        return tuple(self._loads)

    # ------------------------------------------------------------------------------------------------
    # construction
    # ------------------------------------------------------------------------------------------------
    @staticmethod
    def _strain_bases(basis, dofs):
        if isinstance(basis, Basis):
            bases = [basis if d else None for d in dofs]
        else:
            try:
                bases = list(basis)
            except TypeError:
                raise ParameterError(f"basis must be a Basis or 6 of them (None for fixed strains), got "
                                     f"{type(basis).__name__}") from None
            if len(bases) != 6:
                raise ParameterError(f"give one basis per strain (6, None where dofs is 0), got {len(bases)}")
        for i, (b, d) in enumerate(zip(bases, dofs)):
            if d == 0:
                continue
            if not isinstance(b, Basis):
                raise ParameterError(f"strain {STRAINS[i]} has dofs={d} but no Basis")
            if b.n < d:
                raise ParameterError(f"strain {STRAINS[i]} asks for {d} modes but its basis {b.name} has only "
                                     f"{b.n}; lower dofs[{i}] or use a larger basis")
        return bases

    def _section(self, section, contact_radius):
        from sorofem.sdf.properties import section_properties
        if getattr(section, "dim", None) != 2:
            raise ParameterError("section must be a 2D SDF from sorofem.sdf, e.g. sdf.Circle(5e-3)")
        props = section_properties(section)
        self.section = section
        self.section_properties = props
        A, Iy, Iz, Iyz, Jp = props.area, props.Iy, props.Iz, props.Iyz, props.J
        self._Kdiag = np.diag([self.G * Jp, self.E * Iy, self.E * Iz, self.E * A, self.G * A, self.G * A])
        self._Kdiag[1, 2] = self._Kdiag[2, 1] = -self.E * Iyz
        self._Mdiag = self.density * np.array([Jp, Iy, Iz, A, A, A])
        if contact_radius is None:
            lo, hi = section.bounds
            c = props.centroid
            contact_radius = float(np.max(np.abs(np.concatenate([lo - c, hi - c]))))
        if not (np.isfinite(contact_radius) and contact_radius > 0):
            raise ParameterError(f"contact_radius must be positive [m], got {contact_radius!r}")
        self.contact_radius = float(contact_radius)

    def _reference_strain(self, xi0):
        if xi0 is None:
            return _Rows(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]))
        if callable(xi0):
            return _PerPoint(xi0, 6)
        v = np.asarray(xi0, dtype=float)
        if v.shape != (6,) or not np.all(np.isfinite(v)):
            raise ParameterError("xi0 must be 6 finite numbers (kx, ky, kz [1/m], stretch, shear_y, shear_z) or a "
                                 "callable of sigma [m]")
        return _Rows(v)

    @property
    def n(self):
        """Number of generalized coordinates."""
        return int(sum(self.dofs))

    def theta(self, sigma):
        r"""The modal matrix :math:`\Theta(\sigma)` at arc lengths ``sigma`` [m]: array (len(sigma), 6, n)."""
        s = np.clip(np.atleast_1d(np.asarray(sigma, dtype=float)) / self.length, 0.0, 1.0)
        out = np.zeros((len(s), 6, self.n))
        col = 0
        for i, (b, d) in enumerate(zip(self._bases, self.dofs)):
            if d:
                out[:, i, col:col + d] = b(s)[:, :d]
                col += d
        return out

    def _breaks(self):
        """Normalized points where some mode may be non-smooth; segments end on them. A basis with more pieces
        than there are segments (data sampled densely, e.g. a DVS basis: cubic splines, C2 at their knots)
        is integrated across its knots instead."""
        br = {0.0, 1.0}
        for b in self._bases:
            if b is not None and len(b.breaks) - 1 <= self._segments:
                br.update(float(x) for x in b.breaks)
        return np.array(sorted(br))

    def _discretize(self, segments):
        """The :class:`BeamModel`: nodes on the basis breaks (equal segments within every piece); the chain of
        frames through the segment midpoints (``lobatto``) or the nodes only; Magnus Gauss points, quadrature
        weights, stiffness."""
        from . import _beam
        br = self._breaks()
        pieces = np.diff(br)
        per = np.maximum(1, np.round(segments * pieces).astype(int))
        nodes = np.concatenate([[0.0]] + [br[i] + pieces[i] * np.arange(1, per[i] + 1) / per[i]
                                          for i in range(len(pieces))])
        nodes[-1] = 1.0
        sigma = nodes * self.length
        hs = np.diff(sigma)
        node_w = np.zeros(len(sigma))
        node_w[:-1] += hs / 2
        node_w[1:] += hs / 2
        if self.quadrature == "lobatto":           # Simpson: h/6 at the ends, 4h/6 at the midpoint
            stride = 2
            points = np.empty(2 * len(hs) + 1)
            points[0::2] = sigma
            points[1::2] = sigma[:-1] + hs / 2
            w = np.zeros(len(points))
            w[0:-1:2] += hs / 6
            w[2::2] += hs / 6
            w[1::2] = 4 * hs / 6
        elif self.quadrature == "gregory":
            stride, points, w = 1, sigma, _gregory_weights(sigma, per)
        else:
            stride, points, w = 1, sigma, node_w
        h = np.diff(points)
        gp = (0.5,) if self.order == 2 else _beam.GAUSS2
        pts = points[:-1, None] + h[:, None] * np.array(gp)[None, :]
        # a piecewise basis is evaluated inside each piece (Gauss points never sit on a break)
        th = self.theta(pts.ravel()).reshape(len(h), len(gp), 6, self.n)
        rows = np.repeat(np.arange(6), self.dofs).astype(np.int64)
        B = th[:, :, rows, np.arange(self.n)]                     # column k lives in row rows[k]
        X0 = self._xi0(pts.ravel()).reshape(len(h), len(gp), 6)
        Md = np.tile(self._Mdiag, (len(points), 1))
        return BeamModel(dofs=self.dofs, order=self.order, length=self.length, base=self.base, sigma=sigma,
                         points=points, stride=stride, h=h, B=B, rows=rows, X0=X0, weights=w, node_weights=node_w,
                         Md=Md, K=self._stiffness())

    def _quad(self, f, a=0.0, b=None):
        """Integrate ``f(sigma) -> (m, ...)`` over [a, b] by Gauss-Legendre on every basis piece, with
        ``2 max(dofs) + 8`` points (exact for products of two polynomial modes)."""
        b = self.length if b is None else b
        br = self._breaks() * self.length
        cuts = np.unique(np.clip(np.concatenate([[a, b], br]), a, b))
        x, wg = np.polynomial.legendre.leggauss(2 * max(self.dofs) + 8)
        total = 0.0
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            if hi - lo <= 0:
                continue
            s = 0.5 * (lo + hi) + 0.5 * (hi - lo) * x
            vals = f(s)
            total = total + np.tensordot(0.5 * (hi - lo) * wg, vals, axes=(0, 0))
        return total

    def _stiffness(self):
        Kd = self._Kdiag
        K = self._quad(lambda s: np.einsum("mri,rc,mcj->mij", self.theta(s), Kd, self.theta(s)))
        K = 0.5 * (K + K.T)
        if np.linalg.cond(K) > 1e14:
            raise ParameterError("the stiffness matrix is singular: the chosen basis functions are linearly "
                                 "dependent on [0, L]; orthonormalize the basis or use fewer modes")
        return K

    # ------------------------------------------------------------------------------------------------
    # loads (builders return self)
    # ------------------------------------------------------------------------------------------------
    def add_gravity(self, g=(0.0, 0.0, -9.81)):
        """Gravity: spatial acceleration ``g`` [m/s^2] (default 9.81 along -z); replaces an earlier one."""
        g = np.asarray(g, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ParameterError("gravity must be a 3-vector [m/s^2]")
        g = g.copy()
        g.flags.writeable = False
        self._loads = [ld for ld in self._loads if not isinstance(ld, _bm.Gravity)]
        self._add_load(_bm.Gravity(g))
        return self

    @property
    def gravity(self):
        """The gravity acceleration [m/s^2] (3,) (zeros without gravity)."""
        return _bm.gravity_of(self._loads)

    def node(self, at):
        """Index of the node at arc length ``at`` [m] (None: the tip) in :attr:`sigma`; a ParameterError if ``at``
        is not a node."""
        return self.model.node(at)

    def add_point_load(self, force=None, moment=None, *, at=None, frame="spatial"):
        """A point force [N] and/or moment [N m] at arc length ``at`` [m] (a node; default the tip), in the
        ``"spatial"`` or ``"body"`` frame; each may be a 3-vector or a callable of time t [s]."""
        if frame not in ("spatial", "body"):
            raise ParameterError("frame must be 'spatial' or 'body'")

        def signal(v, what):
            if v is None:
                return _Constant(np.zeros(3))
            if callable(v):
                return _Vector3(v)
            v = np.asarray(v, dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ParameterError(f"{what} must be a finite 3-vector or a callable of t")
            return _Constant(v)
        self._add_load(_bm.PointLoad(self.node(at), signal(force, "force"), signal(moment, "moment"), frame))
        return self

    def _input_name(self, name, kind):
        return name or f"{kind}{len(self.inputs)}"

    def add_chamber(self, area, offset, span=None, name=None):
        r"""A pressure chamber of cross-section ``area`` [m^2] whose centroid sits at ``offset`` = (y, z) [m] from
        the backbone, along ``span`` = (sigma_a, sigma_b) [m] (default the whole rod). Adds one input: its
        pressure [Pa]. The pressure acts as an internal wrench :math:`W = p A_c (r \times e_x, e_x)`
        (an axial force off the axis: it stretches the chamber side and bends the rod away from it), so
        :math:`\tau = \int \Theta^T W d\sigma` is constant in :math:`q`."""
        area = float(area)
        off = np.asarray(offset, dtype=float)
        if not (np.isfinite(area) and area > 0) or off.shape != (2,):
            raise ParameterError("a chamber needs area > 0 [m^2] and offset (y, z) [m]")
        a, b = self._span(span)
        W = area * np.array([0.0, off[1], -off[0], 1.0, 0.0, 0.0])
        col = self._quad(lambda s: np.einsum("mri,r->mi", self.theta(s), W), a, b)
        self._add_load(_bm.Chamber(self._input_name(name, "chamber"), col))
        return self

    def add_tendon(self, offset, span=None, name=None):
        r"""A tendon routed parallel to the backbone at ``offset`` = (y, z) [m] along ``span`` (default the whole
        rod), anchored at the span's end. Adds one input: its tension [N] (>= 0). The tension compresses the rod
        along the tendon: internal wrench :math:`W = -T (d \times \hat t, \hat t)` with the tendon direction
        :math:`\hat t = (\nu + \kappa \times d) / |\cdot|`, integrated at the Magnus Gauss points."""
        from . import _beam
        off = np.asarray(offset, dtype=float)
        if off.shape != (2,) or not np.all(np.isfinite(off)):
            raise ParameterError("a tendon needs offset (y, z) [m]")
        a, b = self._span(span)
        gp = (0.5,) if self.order == 2 else _beam.GAUSS2
        h = self.model.h
        pts = self.model.points[:-1, None] + h[:, None] * np.array(gp)[None, :]
        wts = np.repeat(h[:, None] / len(gp), len(gp), axis=1)
        mask = (pts >= a - 1e-12) & (pts <= b + 1e-12)
        self._add_load(_bm.Tendon(self._input_name(name, "tendon"), np.array([0.0, off[0], off[1]]), wts * mask))
        return self


    def _span(self, span):
        a, b = (0.0, self.length) if span is None else map(float, span)
        if not (0.0 <= a < b <= self.length * (1 + 1e-12)):
            raise ParameterError(f"span must satisfy 0 <= a < b <= length ({self.length:g} m), got {span!r}")
        return a, b

    def add_actuator(self, force, name=None):
        """An input whose generalized force is ``force(u) -> (n,)`` for its value ``u`` (any unit), independent
        of the configuration, e.g. an actuation map identified from FEM (:func:`soroshapes.dvs.identify`);
        an (n,) array means the linear map ``column * u``."""
        if callable(force):
            fn = force
            v = np.asarray(fn(0.0), dtype=float)
            if v.shape != (self.n,):
                raise ParameterError(f"an actuator must return {self.n} generalized forces, got shape {v.shape}")
        else:
            col = np.asarray(force, dtype=float).reshape(-1)
            if col.shape != (self.n,) or not np.all(np.isfinite(col)):
                raise ParameterError(f"an actuator column must have {self.n} finite entries")
            fn = _Linear(col)
        self._add_load(_bm.Actuator(self._input_name(name, "actuator"), fn))
        return self

    def add_contact(self, obstacle, stiffness=None, damping=0.0, friction=0.0, regularization=1e-3):
        r"""Contact of the tube (radius :attr:`contact_radius`) with a 3D SDF environment, at the nodes.

        Penetration :math:`\delta = r - d(p)` (:math:`d` the signed distance of the node); normal force per
        unit length :math:`f_n = \max(0, k\delta - c\,\dot d)` along the SDF gradient, with default stiffness
        :math:`k = 10 E` [N/m^2] (a foundation modulus of ten Young's moduli: penetration stays a few percent
        of the radius under loads that bend the rod) and damping ``c`` [N s/m^2]; regularized Coulomb friction
        :math:`f_t = -\mu f_n v_t / \sqrt{|v_t|^2 + \epsilon^2}` with :math:`\epsilon` = ``regularization``
        [m/s]. Forces act on the backbone (no rolling moment)."""
        if getattr(obstacle, "dim", None) != 3:
            raise ParameterError("contact needs a 3D SDF from sorofem.sdf (e.g. sdf.Sphere, sdf.Plane)")
        k = 10.0 * self.E if stiffness is None else float(stiffness)
        for name, v in (("stiffness", k), ("damping", damping), ("friction", friction),
                        ("regularization", regularization)):
            if not (np.isfinite(v) and v >= 0):
                raise ParameterError(f"contact {name} must be >= 0, got {v!r}")
        if k <= 0 or regularization <= 0:
            raise ParameterError("contact stiffness and regularization must be positive")
        self._add_load(_bm.Contact(obstacle, k, float(damping), float(friction), float(regularization),
                                       self.contact_radius))
        return self

    def add_force(self, f):
        """A user generalized force ``f(shapes, q, qd, t) -> (n,)`` [N or N m per coordinate]."""
        if not callable(f):
            raise ParameterError("add_force needs a callable f(shapes, q, qd, t) -> (n,) array")
        self._add_load(_bm.UserForce(f))
        return self

    @property
    def inputs(self):
        """Names of the inputs (chambers [Pa], tendons [N], actuators) in the order of ``u``."""
        return [ld.name for ld in _bm.input_terms(self._loads)]


    # ------------------------------------------------------------------------------------------------
    # kinematics (thin wrappers over soroshapes.beam; ``data``: a workspace of make_data(), default self.data)
    # ------------------------------------------------------------------------------------------------
    def state(self, q, qd=None, *, rate=False, data=None):
        """One kinematic pass at (q, qd) into a workspace, returned (:class:`soroshapes.beam.BeamData`: frames
        ``G``, body Jacobians ``J``, twists ``eta`` at ``model.points``, and ``Jd`` with ``rate``)."""
        data = self.data if data is None else data
        _bm.kinematics(self.model, data, q, qd, rate)
        return data

    def node_kinematics(self, q, qd=None, *, data=None):
        """(G, eta, J) at the nodes :attr:`sigma` for state (q, qd): frames (N+1, 4, 4), body twists (N+1, 6)
        [rad/s, m/s], body Jacobians (N+1, 6, n); views into the workspace (copy them to keep them)."""
        d, at = self.state(q, qd, data=data), self.model.at_nodes
        return at(d.G), at(d.eta), at(d.J)

    def forward_kinematics(self, q, *, data=None):
        """Frames g(sigma_i) at the nodes :attr:`sigma`: array (N+1, 4, 4); positions are ``[:, :3, 3]`` [m]."""
        return self.model.at_nodes(self.state(q, data=data).G).copy()

    def positions(self, q, *, data=None):
        """Backbone positions at the nodes, (N+1, 3) [m]."""
        return self.model.at_nodes(self.state(q, data=data).G)[:, :3, 3].copy()

    def beam(self, q):
        """This rod at coordinates ``q`` as a beam for :mod:`soroshapes.render`: ``{"frames", "radius"}``."""
        return {"frames": self.forward_kinematics(q), "radius": self.contact_radius}

    def render(self, path, q, **kw):
        """Render the rod at ``q`` as a tube to a PNG (keywords of :func:`soroshapes.render.render_png`)."""
        from .render import render_png
        return render_png(path, [self.beam(q)], **kw)

    def jacobian(self, q, at=None, frame="body", *, data=None):
        r"""Geometric Jacobian at node ``at`` [m] (default the tip): body :math:`J` with :math:`\eta = J\dot q`
        (6, n), or ``frame="spatial"``: :math:`\mathrm{Ad}_g J`; ``at="all"`` gives (N+1, 6, n) body Jacobians."""
        if frame not in ("body", "spatial"):
            raise ParameterError("frame must be 'body' or 'spatial'")
        d = self.state(q, data=data)
        if at == "all":
            return self.model.at_nodes(d.J).copy()
        i = self.node(at) * self.model.stride
        if frame == "body":
            return d.J[i].copy()
        from .lie import Ad
        return Ad(d.G[i]) @ d.J[i]

    def jacobian_rate(self, q, qd, at=None, *, data=None):
        r""":math:`\dot J(q, \dot q)` (body) at node ``at`` (default tip), or all nodes with ``at="all"``."""
        d = self.state(q, qd, rate=True, data=data)
        return self.model.at_nodes(d.Jd).copy() if at == "all" else d.Jd[self.node(at) * self.model.stride].copy()

    # ------------------------------------------------------------------------------------------------
    # dynamics terms
    # ------------------------------------------------------------------------------------------------
    def _mcg(self, q, qd, want_c, data=None):
        data = self.data if data is None else data
        M, C, fg = _bm.dynamics(self.model, data, q, qd, self.gravity, want_c)
        return M.copy(), C.copy(), fg.copy()

    def mass_matrix(self, q, *, data=None):
        """Generalized mass matrix M(q), (n, n) (symmetric positive definite)."""
        return self._mcg(q, None, False, data)[0]

    def gravity_force(self, q, *, data=None):
        r"""Generalized gravity force :math:`f_g(q) = \sum_i w_i J_i^T \mathcal M_i (0, R_i^T a_g)` (n,)."""
        return self._mcg(q, None, False, data)[2]

    def coriolis(self, q, qd, *, data=None):
        r"""Coriolis/centrifugal matrix :math:`C(q, \dot q)` with :math:`\dot M - 2C` skew-symmetric."""
        return self._mcg(q, qd, True, data)[1]

    def coriolis_jacobian(self, q, qd, *, data=None):
        r""":math:`\partial (C(q, \dot q)\dot q) / \partial \dot q` (n, n), exact (see
        :func:`soroshapes._beam.coriolis_velocity_jacobian`); Newton matrices of implicit integrators use it."""
        return _bm.coriolis_jacobian(self.model, self.data if data is None else data, q, qd).copy()

    def dynamics(self, q, qd, *, data=None):
        """(M, C, f_g): mass matrix, Coriolis matrix and gravity force for state (q, qd), from one kinematic pass."""
        return self._mcg(q, qd, True, data)

    def inverse_dynamics(self, q, qd, qdd, *, data=None):
        r"""Generalized force that produces the acceleration ``qdd`` at state (q, qd) against inertia, damping,
        elasticity and gravity: :math:`\tau = M\ddot q + C\dot q + D\dot q + Kq - f_g` (n,), computed
        matrix-free (one kinematic pass with :math:`\dot J\dot q` as a vector; no M or C is formed).
        Inputs, point loads, contact and user forces are not included: they are what :math:`\tau` is for."""
        tau = _bm.inverse_dynamics(self.model, self.data if data is None else data, q, qd, qdd, self.gravity)
        q, qd = np.asarray(q, dtype=float).reshape(-1), np.asarray(qd, dtype=float).reshape(-1)
        return tau + self.damping * (self.K @ qd) + self.K @ q

    def forward_dynamics(self, q, qd, t=0.0, u=None, *, data=None):
        r"""Accelerations :math:`\ddot q = M^{-1}(f - C\dot q - D\dot q - Kq)` at state (q, qd), time t [s] and
        inputs ``u`` (all loads included), from one kinematic pass (one compiled call unless contact, tendons or
        user forces are present: :func:`soroshapes.beam.accelerations`)."""
        return _bm.accelerations(self.model, self.data if data is None else data, self._loads, q, qd, t, u,
                                 self.damping, self, self._load_plan())

    def generalized_force(self, q, qd=None, t=0.0, u=None, *, data=None):
        """Generalized force [N or N m per coordinate] (n,) of all loads (gravity, inputs ``u``, point loads,
        contact, user forces) at state (q, qd) and time t [s]."""
        data = self.data if data is None else data
        q, qd = _bm.kinematics(self.model, data, q, qd)
        uv = _bm.inputs_at(self._loads, u, t)
        return _bm.external_force(self.model, data, self._loads, q, qd, t, uv, owner=self)

    @property
    def damping_matrix(self):
        """D = tau K [N m s per coordinate^2] (see ``damping``)."""
        return self.damping * self.K

    def natural_frequencies(self, count=None, q=None):
        """Natural frequencies [Hz] of the undamped linearization about ``q`` (default straight), ascending:
        :math:`K\\phi = \\omega^2 M\\phi` (geometric stiffness of gravity and loads not included)."""
        from scipy.linalg import LinAlgError, eigh
        if not self.density > 0:
            raise ParameterError(f"natural frequencies need a mass: the material's density is {self.density!r}")
        M = self.mass_matrix(q)
        try:
            w2 = eigh(self.K, M, eigvals_only=True)
        except LinAlgError:
            raise ParameterError(
                f"the mass matrix of this beam is singular ({self.n} coordinates on {len(self.model.sigma) - 1} "
                f"segments, order {self.order}): its nodes cannot tell every mode apart; use more segments "
                f"(segments= per unit of the basis) or fewer modes") from None
        f = np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi)
        return f[:count] if count else f

    def input_map(self, q, u=None):
        """G(q): (n, m) derivative of the inputs' generalized force with respect to the inputs (:attr:`inputs`)
        at the values ``u`` (default 0); constant for chambers, configuration-dependent for tendons."""
        q = _bm.check_state(self.model, q)
        return _bm.input_map(self.model, self.data, self._loads, q, u)

    def contact_forces(self, q, qd=None, *, data=None):
        """Contact forces [N] on the nodes at state (q, qd): (N+1, 3) spatial forces (each node's share of the
        distributed force: per-length force times its quadrature weight), zero where there is no contact."""
        data = self.data if data is None else data
        q, qd = _bm.kinematics(self.model, data, q, qd)
        f = np.zeros(self.n)
        data.contact_forces[...] = 0.0
        for ld in self._loads:
            if isinstance(ld, _bm.Contact):
                f += ld.force(self.model, data, q, qd, 0.0)
        return data.contact_forces.copy()

    def energy(self, q, qd=None, *, data=None):
        """Energies [J]: dict with kinetic, elastic, gravity (potential of the uniform gravity field), total."""
        return _bm.energy(self.model, self.data if data is None else data, q, qd, self.gravity)

    # ------------------------------------------------------------------------------------------------
    # solvers
    # ------------------------------------------------------------------------------------------------
    def statics(self, u=None, q0=None, *, steps=1, tol=1e-9, max_iterations=40, min_step=1e-4, t=0.0,
                constraints=None):
        r"""Static equilibrium :math:`K q = f_g(q) + G(q)u + f_{ext}(q)` by Newton's method with load stepping.

        The loads (all but contact) are ramped by a factor :math:`\lambda \in (0, 1]` in ``steps`` equal
        increments; an increment whose Newton iterations fail is halved, down to ``min_step``, then a
        :class:`~sorofem.errors.ConvergenceError` names the load level reached. The tangent is the finite
        difference of the generalized forces (exact elastic part). Converged when the residual norm is below
        ``tol`` times the norm of the elastic + applied forces.

        ``constraints``: a list of :class:`soroshapes.constraints.Weld`, ``Pin`` or ``Align`` (frames of the rod
        held on world frames, or moved to them: their targets ramp with the load factor from where they are at
        ``q0``), enforced with Lagrange multipliers on the bordered system; a constraint the basis cannot
        move at ``q0`` raises a :class:`~sorofem.errors.ParameterError`. See :mod:`soroshapes.constraints`.

        Returns the coordinates q (n,); with ``constraints``, an :class:`soroshapes.constraints.Equilibrium`
        (q, reaction wrenches [N m, N] in the world frame, drift [m, rad], stiffness on the constraint manifold).
        """
        if constraints is None:
            q, self.newton_iterations = _bm.statics(self.model, self.data, self._loads, u, q0, steps=steps,
                                                    tol=tol, max_iterations=max_iterations, min_step=min_step,
                                                    t=t, owner=self)
            return q
        from .constraints import ConstraintSet
        q0 = _bm.check_state(self.model, q0)
        cs = ConstraintSet(self.model, self.data, constraints, q0)
        cs.check(self.data)
        q, lam, self.newton_iterations, Kt, c = _bm.statics(
            self.model, self.data, self._loads, u, q0, steps=steps, tol=tol, max_iterations=max_iterations,
            min_step=min_step, t=t, owner=self, constraints=cs)
        _bm.kinematics(self.model, self.data, q)
        return cs.equilibrium(q, lam, self.newton_iterations, Kt, c, self.data)

    # ------------------------------------------------------------------------------------------------
    # dynamics
    # ------------------------------------------------------------------------------------------------
    def explicit_step_limit(self, q=None):
        """Stability limit [s] of explicit time stepping, :math:`2/\\omega_{max}` (central difference), from
        the largest natural frequency of the linearization about ``q``."""
        return _bm.explicit_step_limit(self.model, self.data, None if q is None else _bm.check_state(self.model, q))

    def simulate(self, t_end, dt, q0=None, qd0=None, u=None, *, method="implicit", tol=1e-8, max_iterations=20,
                 min_dt=None, record_every=1, constraints=None):
        r"""Time integration of the equations of motion from (``q0``, ``qd0``) (default rest, straight).

        ``method="implicit"``: the implicit midpoint rule (second order, A-stable, symplectic for constant
        :math:`M`): with :math:`v_m = (\dot q_n + \dot q_{n+1})/2` and :math:`q_m = q_n + \tfrac h2 v_m`,

        .. math:: M(q_m)\frac{2(v_m - \dot q_n)}{h} + C(q_m, v_m) v_m + D v_m + K q_m = f(q_m, v_m, t_n + h/2),

        solved for :math:`v_m` by Newton iterations with the matrix :math:`2M/h + \partial(C v)/\partial v + D +
        \tfrac h2 K` (:meth:`coriolis_jacobian`; the configuration derivatives of the inertial and external
        forces are left out: they change the rate of convergence, not the solution)
        until :math:`|\Delta v| \le` ``tol`` :math:`|v_m| + 10^{-12}`; then :math:`q_{n+1} = q_n + h v_m`,
        :math:`\dot q_{n+1} = 2v_m - \dot q_n`. Scenes with gravity, chambers, point loads and contact with
        obstacles whose SDF has a program form (:mod:`sorofem.sdf.program`; no tendons or user forces) run in one
        compiled loop (:func:`soroshapes._beam.integrate_midpoint`: residuals by O(N) Newton-Euler recursions
        with the contact forces at the nodes between them, the linearized step as predictor, the matrix
        :math:`2M/h + D + \tfrac h2 K` plus the contacts' normal stiffness, damping and friction slope
        refreshed when convergence slows and the complete, differenced :math:`\partial R/\partial
        v_m` for a step that fails with it; ``stats["matrices"]`` counts the factorizations, ``stats`` has the keys
        of :mod:`soroshapes.trajectory`). A step that does
        not converge in ``max_iterations`` is halved, down to ``min_dt`` (default dt/1024), then a
        :class:`~sorofem.errors.ConvergenceError` reports the time. ``method="explicit"``: classical RK4
        (stable only below about :meth:`explicit_step_limit`; a blow-up is reported, never returned).

        The step is ``t_end / ceil(t_end / dt)`` (at most ``dt``). ``u``: inputs, an array or a callable of
        t [s]. Returns a :class:`~soroshapes.trajectory.Trajectory` (``t``, ``q``, ``qd``, ``kinetic``, ``potential``,
        ``tip``, ``stats``) recorded every ``record_every`` steps (and at the end).

        ``constraints``: a list of :class:`soroshapes.constraints.Weld`, ``Pin`` or ``Align`` (frames held on
        world frames where they are at ``q0``, which must satisfy them: start from a constrained
        :meth:`statics`), enforced in the implicit midpoint step with Lagrange multipliers as unknowns (index 3)
        and the velocity projected on the constraint (see :mod:`soroshapes.constraints`); the trajectory then
        records the drift per step (``drift_position`` [m], ``drift_rotation`` [rad]) and the ``reactions``
        [N m, N]. This path runs in Python.
        """
        if constraints is not None:
            if method != "implicit":
                raise ParameterError("constraints are enforced by the implicit midpoint step only; use "
                                     "method='implicit'")
            from .constraints import Assembly, BeamBody
            body = BeamBody(self.model, self._loads, tau=self.damping, owner=self, data=self.data)
            return Assembly([body]).simulate(t_end, dt, q0, qd0, [u], constraints=constraints, tol=tol,
                                             max_iterations=max_iterations, min_dt=min_dt,
                                             record_every=record_every)
        return _bm.simulate(self.model, self.data, self._loads, t_end, dt, q0, qd0, u, tau=self.damping,
                            method=method, tol=tol, max_iterations=max_iterations, min_dt=min_dt,
                            record_every=record_every, owner=self)

    # ------------------------------------------------------------------------------------------------
    # inverse kinematics
    # ------------------------------------------------------------------------------------------------
    def _targets(self, targets):
        """[(node, kind, value)] from a (3,) / (4, 4) tip target or a list of (at, target) pairs."""
        try:
            v = np.asarray(targets, dtype=float)
        except (TypeError, ValueError):
            v = None
        if v is not None and v.shape in ((3,), (4, 4)):
            targets = [(None, v)]
        out = []
        for item in targets:
            try:
                at, value = item
            except (TypeError, ValueError):
                raise ParameterError("targets: give a (3,) position, a (4, 4) pose, or a list of (at [m], "
                                     "target) pairs") from None
            v = np.asarray(value, dtype=float)
            if v.shape not in ((3,), (4, 4)) or not np.all(np.isfinite(v)):
                raise ParameterError(f"an IK target must be a finite (3,) position [m] or (4, 4) pose, got "
                                     f"shape {v.shape}")
            out.append((self.node(at), "position" if v.shape == (3,) else "pose", v))
        return out

    def inverse_kinematics(self, targets, q0=None, *, tol=1e-8, max_iterations=200, damping=1e-6,
                           rotation_weight=None, subtask=None, subtask_gain=0.1):
        r"""Configuration(s) reaching target positions or poses at nodes of the backbone (damped least squares).

        With the stacked body-frame errors :math:`e` (position: :math:`R_i^T(p_i^* - p_i)` [m]; pose:
        :math:`\log(g_i^{-1} g_i^*)^\vee`, its angular part times ``rotation_weight`` [m], default :math:`L`)
        and Jacobians :math:`J`, each iteration takes the Levenberg-Marquardt step

        .. math:: \Delta q = J^T (J J^T + \lambda^2 I)^{-1} e + (I - J^\dagger J)(-\alpha \nabla\Psi),

        adapting :math:`\lambda` (start ``damping`` [m]; halved after a step that lowers :math:`|e|`, raised
        fourfold and the step retried otherwise). The null-space subtask (the seed's eq. 23) is ``"elastic"``
        (:math:`\nabla\Psi = K q`: among the solutions, the least strained), a callable ``grad(q) -> (n,)``,
        or None; its step is scaled to ``subtask_gain`` times the task step. Stops when :math:`|e| <` ``tol``
        [m], when the task step vanishes, or after 10 steps that lower :math:`|e|` by less than 1e-9 relative (an
        unreachable target gives the least-squares configuration; with as many target equations as
        coordinates there is no null space left for the subtask).

        Parameters
        ----------
        targets : (3,) or (4, 4) array for the tip, or a list of ``(at, target)`` with ``at`` [m] a node.
        q0 : (n,) initial guess (default straight).

        Returns
        -------
        IKResult with ``q``, ``error`` (final |e| [m]), ``iterations``, ``converged``.
        """
        return _bm.inverse_kinematics(self.model, self.data, self._targets(targets), q0, tol=tol,
                                      max_iterations=max_iterations, damping=damping,
                                      rotation_weight=rotation_weight, subtask=subtask, subtask_gain=subtask_gain)

    @property
    def bases(self):
        """The strain bases, a tuple of 6 (:class:`~soroshapes.basis.Basis`, None for a fixed strain)."""
        return tuple(b if d else None for b, d in zip(self._bases, self.dofs))

    @property
    def segments(self):
        """Number of integration segments along the rod (int)."""
        return self._segments


def precompile():
    """Compile the beam kernels a first session needs (or load them from numba's cache) and leave them in the
    cache, so that every later process, from any folder and any user, starts without the JIT (about 40 s with
    an empty cache; ``scripts/bootstrap.sh`` calls this once after installing). Exercises, on a small rod with
    gravity, a point load and a chamber: ``statics``, ``simulate`` (the compiled loop), the kinematics and
    dynamics queries, ``forward_dynamics`` (the path of :class:`soroshapes.Model`) and ``inverse_kinematics``.
    Returns the seconds it took."""
    import time
    from sorofem import materials, sdf
    from .basis import Basis
    t0 = time.perf_counter()
    shp = Shapes(Basis.chebyshev(3), dofs=(1, 3, 3, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)).add_gravity()
    shp.add_point_load((0.0, 0.0, -0.01)).add_chamber(1e-5, (0.0, 0.002), name="chamber")
    q = shp.statics(u=[0.0])
    shp.simulate(0.003, 1e-3, q0=q, u=[0.0])
    qd = np.full(shp.n, 0.1)
    shp.forward_kinematics(q)
    shp.jacobian(q)
    shp.jacobian_rate(q, qd)
    shp.dynamics(q, qd)
    shp.coriolis_jacobian(q, qd)
    shp.inverse_dynamics(q, qd, qd)
    shp.forward_dynamics(q, qd, u=[0.0])
    shp.energy(q, qd)
    shp.inverse_kinematics(shp.forward_kinematics(q)[-1][:3, 3].copy(), q0=np.zeros(shp.n))
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"[soroshapes] beam kernels compiled and cached in {precompile():.1f} s")
