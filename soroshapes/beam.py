r"""The Cosserat beam as a frozen description and a workspace (Pinocchio's ``Model``/``Data`` split).

* :class:`BeamModel`: everything that describes the rod and never changes after construction: the DOF mask,
  the Magnus order, the length [m], the base pose, the discretization (node arc lengths ``sigma`` [m]), the
  quadrature (``points``, ``weights``), the modal matrix and the reference strain at the Magnus Gauss points,
  the sectional inertia per unit length ``Md`` and the stiffness matrix ``K``. Its arrays are read-only.
* :class:`BeamData`: every scratch array the kernels of :mod:`soroshapes._beam` write (frames, Jacobians,
  twists and their rates at the quadrature points, the 6 x 6 temporaries, M, C, f_g).

Quadrature. The mass, Coriolis and gravity integrals :math:`\int_0^L (\cdot)\,d\sigma` are weighted sums over
``points``. ``quadrature="gregory"`` (the default) sums at the nodes with Gregory's end corrections of the
trapezoidal rule on every basis piece (weights :math:`(3/8, 7/6, 23/24, 1, \dots, 1, 23/24, 7/6, 3/8)\,h`; Simpson's
rules on pieces of 2-4 segments): exact for cubics, so the error falls as :math:`h^4` like the order-4 Magnus
kinematics, at no extra work. ``"lobatto"`` cuts every segment at its midpoint and uses the three-point
Gauss-Lobatto rule (Simpson, :math:`h/6, 4h/6, h/6`): also :math:`h^4`, a smaller constant, twice the kinematic
work (the kernels integrate the frames through the midpoints: ``stride`` = 2 chain pieces per segment).
``"trapezoid"`` is the plain trapezoidal rule at the nodes (:math:`h^2`; the discretization before issue 18).
Contact acts at the nodes with the trapezoidal weights ``node_weights``. ``model.make_data()`` makes one; two
  workspaces on one model are independent (one per thread, or one per query that must not disturb another).
* Load terms: :class:`Gravity`, :class:`PointLoad`, :class:`Chamber`, :class:`Tendon`, :class:`Actuator`,
  :class:`Contact`, :class:`UserForce`, each giving its generalized force at the kinematics held in a workspace;
  :func:`external_force` sums a list of them.
* Algorithms are functions of ``(model, data, ...)``: :func:`kinematics`, :func:`dynamics`,
  :func:`coriolis_jacobian`, :func:`inverse_dynamics`, :func:`energy`.

:class:`~soroshapes.shapes.Shapes` builds a model, keeps its list of loads and one default workspace, and its
methods are thin wrappers over these functions.

Failure model: a state that is not finite, or so large that the frames overflow (e.g. ``q = 1e200``), raises
:class:`~sorofem.errors.DataError`; the workspace is reset first, so the same objects then compute correct
values at any valid state (nothing stale is left in a buffer).

Units: SI (m, kg, s, N); :math:`q` carries the unit of its strain times the dimensionless basis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sorofem.errors import DataError, ParameterError

__all__ = ["BeamModel", "BeamData", "StateRangeError", "BeamTrajectory", "IKResult", "Gravity", "PointLoad", "Chamber", "Tendon",
           "Actuator", "Contact", "UserForce", "check_state", "kinematics", "dynamics", "coriolis_jacobian",
           "inverse_dynamics", "forward_dynamics", "energy", "external_force", "input_map"]

_NO_NODES, _NO_WRENCH, _NO_FLAGS = np.zeros(0, dtype=np.int64), np.zeros((0, 6)), np.zeros(0, dtype=np.bool_)


class StateRangeError(DataError):
    """A state whose frames overflow floating point (e.g. ``q = 1e200``): solvers treat it as a failed trial
    step; elsewhere it reaches the caller."""


def _frozen(a, dtype=float):
    a = np.ascontiguousarray(a, dtype=dtype)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class BeamModel:
    r"""The frozen description of a discretized Cosserat beam (see the module docstring).

    Attributes
    ----------
    dofs : tuple of 6 ints, the DOF mask (torsion, bending y, bending z, stretch, shear y, shear z).
    order : 2 or 4, the Magnus order.
    length : float [m].
    base : (4, 4) pose of the clamped end.
    sigma : (N+1,) node arc lengths [m].
    points : (P+1,) arc lengths [m] of the chain of frames the kernels integrate (the nodes are every
        ``stride``-th: ``points[::stride] == sigma``); ``h`` (P,) its piece lengths [m].
    B : (P, ng, n) modal matrix at the ``ng`` Magnus Gauss points of each piece, stored by columns
        (coordinate k drives strain ``rows[k]`` only); ``X0`` (P, ng, 6) the reference strain there.
    weights : (P+1,) quadrature weights [m] of the mass, Coriolis and gravity integrals at ``points``.
    node_weights : (N+1,) trapezoidal weights [m] of the contact forces at the nodes.
    Md : (P+1, 6) sectional inertia per unit length :math:`\rho(J_p, I_y, I_z, A, A, A)` at ``points``.
    K : (n, n) stiffness matrix.
    """

    dofs: tuple
    order: int
    length: float
    base: np.ndarray
    sigma: np.ndarray
    points: np.ndarray
    stride: int
    h: np.ndarray
    B: np.ndarray
    rows: np.ndarray
    X0: np.ndarray
    weights: np.ndarray
    node_weights: np.ndarray
    Md: np.ndarray
    K: np.ndarray

    def __post_init__(self):
        for name in ("base", "sigma", "points", "h", "B", "X0", "weights", "node_weights", "Md", "K"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "rows", _frozen(self.rows, np.int64))

    @property
    def n(self):
        """Number of generalized coordinates."""
        return self.B.shape[2]

    @property
    def nodes(self):
        """Number of nodes (segment ends), N+1."""
        return self.sigma.shape[0]

    def at_nodes(self, a):
        """The node rows of an array over ``points`` (a view)."""
        return a[::self.stride]

    def make_data(self):
        """A fresh workspace (:class:`BeamData`) for this model."""
        return BeamData(self)

    def node(self, at):
        """Index of the node at arc length ``at`` [m] (None: the tip); a :class:`ParameterError` if ``at`` is not
        a node."""
        at = self.length if at is None else float(at)
        i = int(np.argmin(np.abs(self.sigma - at)))
        if abs(self.sigma[i] - at) > 1e-9 * self.length:
            raise ParameterError(f"point loads act at nodes; sigma={at:g} m is not one (nearest: "
                                 f"{self.sigma[i]:g} m); pass at=one of shp.sigma or change segments")
        return i


class BeamData:
    """The workspace of a :class:`BeamModel`: after :func:`kinematics`, ``G`` (N+1, 4, 4) frames, ``J``
    (N+1, 6, n) body Jacobians, ``eta`` (N+1, 6) body twists [rad/s, m/s] and, with ``rate=True``, ``Jd`` the
    Jacobian rates; after :func:`dynamics`, ``M``, ``C``, ``fg``; after contact loads, ``contact_forces``
    (N+1, 3) [N]. The remaining arrays are kernel scratch. Read the results, do not keep references across
    calls (the next call overwrites them)."""

    __slots__ = ("G", "J", "Jd", "eta", "etad", "S", "E", "V", "Op", "dOp", "AJ", "W", "M", "C", "Cv", "fg",
                 "R", "piv", "qdd", "contact_forces")

    def __init__(self, model):
        N, n = model.points.shape[0], model.n
        self.G = np.zeros((N, 4, 4))
        self.J = np.zeros((N, 6, n))
        self.Jd = np.zeros((N, 6, n))
        self.eta = np.zeros((N, 6))
        self.etad = np.zeros((N, 6))
        self.S, self.E, self.V = np.zeros((6, 6, 6)), np.zeros((4, 4)), np.zeros((8, 6))
        self.Op, self.dOp, self.AJ = np.zeros((6, n)), np.zeros((6, n)), np.zeros((6, n))
        self.W = np.zeros((8, 6))
        self.M, self.C, self.Cv, self.fg = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)), np.zeros(n)
        self.R, self.piv, self.qdd = np.zeros(n), np.zeros(n, dtype=np.int64), np.zeros(n)
        self.contact_forces = np.zeros((model.nodes, 3))

    def __getstate__(self):
        return {k: getattr(self, k) for k in self.__slots__}

    def __setstate__(self, state):
        for k, v in state.items():
            setattr(self, k, v)

    def reset(self):
        """Zero every array (what a failed evaluation does before it raises)."""
        for k in self.__slots__:
            getattr(self, k)[...] = 0.0


@dataclass
class BeamTrajectory:
    """Result of :meth:`Shapes.simulate`: times ``t`` (m,) [s], coordinates ``q`` and rates ``qd`` (m, n),
    energies (m,) [J] (``kinetic``, ``potential`` = elastic + gravity, ``total``), tip positions (m, 3) [m],
    and the solver statistics (``newton_iterations`` per step, ``steps``, ``wall_time`` [s])."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    tip: np.ndarray
    stats: dict = field(default_factory=dict)

    @property
    def total(self):
        """Total mechanical energy [J] (kinetic + elastic + gravity)."""
        return self.kinetic + self.potential


@dataclass
class IKResult:
    """Result of :meth:`Shapes.inverse_kinematics`: coordinates ``q``, final error norm ``error`` [m],
    ``iterations``, ``converged`` (error below the tolerance)."""

    q: np.ndarray
    error: float
    iterations: int
    converged: bool


# ------------------------------------------------------------------------------------------------------------
# kinematics and dynamics terms
# ------------------------------------------------------------------------------------------------------------
def check_state(model, q, what="q"):
    """``q`` as a contiguous float (n,) array (None: zeros); :class:`ParameterError` for a wrong size,
    :class:`DataError` for NaN or inf."""
    q = np.ascontiguousarray(q, dtype=float).reshape(-1) if q is not None else np.zeros(model.n)
    if q.shape != (model.n,):
        raise ParameterError(f"{what} must have {model.n} entries (dofs {model.dofs}), got {q.shape}")
    if not math.isfinite(np.add.reduce(q)) and not np.all(np.isfinite(q)):   # the sum: a cheap first test
        raise DataError(f"{what} contains NaN or inf")
    return q


def _guard(data, q, qd, rate):
    """Raise (after resetting the workspace) when the pass produced non-finite values. Non-finite values
    propagate along the chain, so the tip's frame, Jacobian and twist tell."""
    s = data.G[-1].sum() + data.J[-1].sum() + data.eta[-1].sum()
    if rate:
        s += data.Jd[-1].sum()
    if not math.isfinite(s):
        data.reset()
        raise StateRangeError(f"the state (max |q| = {np.max(np.abs(q)):.3g}, max |qd| = {np.max(np.abs(qd)):.3g}) "
                        "makes the frames overflow (strain times segment length beyond floating point); give "
                        "a physically meaningful state (|strain| of order 1/length)")


def kinematics(model, data, q, qd=None, rate=False):
    r"""Frames, body Jacobians and twists at ``model.points`` for ``q`` (and rates ``qd``; with ``rate`` the Jacobian
    rates :math:`\dot J`) into ``data``; returns the validated (q, qd)."""
    from . import _beam
    q = check_state(model, q)
    qd = np.zeros(model.n) if qd is None else check_state(model, qd, "qd")
    _beam.kinematics(q, qd, rate, model.order, model.h, model.B, model.rows, model.X0, model.base, data.G,
                     data.J, data.Jd, data.eta, data.S, data.E, data.V, data.Op, data.dOp, data.AJ)
    _guard(data, q, qd, rate)
    return q, qd


def _mcg(model, data, gravity, want_c):
    """M, C (if want_c), f_g into ``data`` from the kinematics held there."""
    from . import _beam
    _beam.mass_coriolis_gravity(data.J, data.Jd, data.eta, data.G, model.weights, model.Md, gravity, data.M,
                                data.C, data.fg, want_c, data.S, data.V, data.AJ)


def dynamics(model, data, q, qd=None, gravity=None, want_c=True):
    r"""(M, C, f_g) at (q, qd) from one kinematic pass: mass matrix, Coriolis matrix (:math:`\dot M - 2C`
    skew; zeros unless ``want_c``), generalized gravity force for the spatial acceleration ``gravity`` [m/s^2]
    (default none). The arrays live in ``data`` (copy them to keep them)."""
    q, qd = kinematics(model, data, q, qd, want_c)
    _mcg(model, data, np.zeros(3) if gravity is None else gravity, want_c)
    if not want_c:
        data.C[...] = 0.0
    return data.M, data.C, data.fg


def coriolis_jacobian(model, data, q, qd):
    r""":math:`\partial (C(q, \dot q)\dot q) / \partial \dot q` (n, n), exact (see
    :func:`soroshapes._beam.coriolis_velocity_jacobian`); into ``data.Cv``."""
    from . import _beam
    dynamics(model, data, q, qd)
    _beam.coriolis_velocity_jacobian(data.J, data.Jd, data.eta, model.weights, model.Md, data.C, data.Cv, data.S,
                                     data.AJ)
    return data.Cv


def inverse_dynamics(model, data, q, qd, qdd, gravity=None):
    r""":math:`M\ddot q + C\dot q - f_g` (n,), matrix-free (one kinematic pass with :math:`\dot J\dot q` as a
    vector; no M or C is formed)."""
    from . import _beam
    q, qd = check_state(model, q), check_state(model, qd, "qd")
    qdd = check_state(model, qdd, "qdd")
    _beam.kinematics_vec(q, qd, model.order, model.h, model.B, model.rows, model.X0, model.base, data.G, data.J,
                         data.eta, data.etad, data.S, data.E, data.V, data.Op, data.AJ, data.W)
    _guard(data, q, qd, False)
    tau = np.empty(model.n)
    _beam.generalized_inertial_force(data.J, data.eta, data.etad, data.G, model.weights, model.Md, qdd,
                                     np.zeros(3) if gravity is None else gravity, _NO_NODES, _NO_WRENCH,
                                     _NO_FLAGS, tau)
    return tau


def forward_dynamics(model, data, q, qd, f_in, D, gravity, point_loads=(), t=0.0):
    r"""Accelerations :math:`\ddot q = M^{-1}(f_{in} + f_g + \sum_p J_p^T W_p - C\dot q - D\dot q - Kq)` (n,)
    in one compiled call (:func:`soroshapes._beam.forward_dynamics`): ``f_in`` (n,) the inputs' generalized
    force, ``D`` (n, n) the damping matrix, ``gravity`` (3,) [m/s^2], ``point_loads`` :class:`PointLoad` terms
    evaluated at time ``t`` [s]. Configuration-dependent loads (contact, tendons, user forces) are not
    included: :func:`external_force` covers them. Returns ``data.qdd``."""
    from . import _beam
    q, qd = check_state(model, q), check_state(model, qd, "qd")
    npl = len(point_loads)
    nodes = np.array([ld.node * model.stride for ld in point_loads], dtype=np.int64) if npl else _NO_NODES
    W = np.array([ld.wrench(t) for ld in point_loads]) if npl else _NO_WRENCH
    spatial = np.array([ld.frame == "spatial" for ld in point_loads], dtype=np.bool_) if npl else _NO_FLAGS
    ok = _beam.forward_dynamics(q, qd, f_in, model.K, D, nodes, W, spatial, model.order, model.h, model.B,
                                model.rows, model.X0, model.base, model.weights, model.Md, gravity, data.G, data.J,
                                data.Jd, data.eta, data.etad, data.S, data.E, data.V, data.Op, data.AJ, data.W,
                                data.M, data.C, data.fg, data.R, data.piv, data.qdd)
    _guard(data, q, qd, False)
    if not (ok and math.isfinite(data.qdd.sum())):
        data.reset()
        raise StateRangeError(f"the mass matrix is numerically singular at max |q| = {np.max(np.abs(q)):.3g}: the "
                              "state is far outside the beam's range (a diverged iterate); use a smaller step")
    return data.qdd


def energy(model, data, q, qd=None, gravity=None):
    """Energies [J]: dict with kinetic, elastic, gravity (potential of the uniform field ``gravity``), total."""
    M = dynamics(model, data, q, qd, None, want_c=False)[0]
    q = check_state(model, q)
    qd = np.zeros(model.n) if qd is None else check_state(model, qd, "qd")
    g = np.zeros(3) if gravity is None else gravity
    kin = 0.5 * qd @ M @ qd
    el = 0.5 * q @ model.K @ q
    grav = -float(np.sum(model.weights * model.Md[:, 3] * (data.G[:, :3, 3] @ g)))
    return {"kinetic": kin, "elastic": el, "gravity": grav, "total": kin + el + grav}


# ------------------------------------------------------------------------------------------------------------
# load terms
# ------------------------------------------------------------------------------------------------------------
# Each term gives its generalized force [N or N m per coordinate] at the kinematics held in ``data`` (computed
# at (q, qd)); input terms (``inputs = 1``) take their input value ``u``. Small frozen dataclasses (no closures),
# so that a beam with its loads pickles whenever the user's own callables do.
@dataclass(frozen=True)
class Gravity:
    """Uniform gravity: spatial acceleration ``acceleration`` [m/s^2]."""

    acceleration: np.ndarray
    inputs = 0

    def force(self, model, data, q, qd, t):
        _mcg(model, data, self.acceleration, False)
        return data.fg.copy()


@dataclass(frozen=True)
class PointLoad:
    """A point force [N] and moment [N m] (callables of t [s] giving 3-vectors) at node ``node``, in the
    ``"spatial"`` or ``"body"`` frame."""

    node: int
    force_at: object
    moment_at: object
    frame: str
    inputs = 0

    def wrench(self, t):
        """(moment, force) (6,) at time t in the load's frame."""
        return np.concatenate([self.moment_at(t), self.force_at(t)])

    def force(self, model, data, q, qd, t):
        i = self.node * model.stride
        W = self.wrench(t)
        if self.frame == "spatial":
            R = data.G[i, :3, :3]
            W = np.concatenate([R.T @ W[:3], R.T @ W[3:]])
        return data.J[i].T @ W


@dataclass(frozen=True)
class Chamber:
    """A pressure chamber: generalized force per unit pressure ``column`` (n,) [m^2 per coordinate], constant."""

    name: str
    column: np.ndarray
    inputs = 1
    configuration_dependent = False

    def input_column(self, model, data, q, u):
        return self.column


@dataclass(frozen=True)
class Tendon:
    r"""A tendon at offset ``d`` = (0, y, z) [m] with quadrature weights ``weights`` (P, ng) [m] at the Gauss points
    (zero outside its span): generalized force per newton of tension at the current configuration."""

    name: str
    d: np.ndarray
    weights: np.ndarray
    inputs = 1
    configuration_dependent = True

    def input_column(self, model, data, q, u):
        col = np.zeros(model.n)
        B, X0, rows, wts, d = model.B, model.X0, model.rows, self.weights, self.d
        for s in range(B.shape[0]):
            for a in range(B.shape[1]):
                if wts[s, a] == 0:
                    continue
                xi = X0[s, a].copy()
                np.add.at(xi, rows, B[s, a] * q)
                t = xi[3:] + np.cross(xi[:3], d)
                t /= np.linalg.norm(t)
                W = -np.concatenate([np.cross(d, t), t])
                col += wts[s, a] * B[s, a] * W[rows]
        return col


@dataclass(frozen=True)
class Actuator:
    """An input whose generalized force is ``fn(u) -> (n,)`` (configuration independent)."""

    name: str
    fn: object
    inputs = 1
    configuration_dependent = False

    def input_column(self, model, data, q, u):
        e = 1e-6 * max(1.0, abs(u))
        return (np.asarray(self.fn(u + e)) - np.asarray(self.fn(u - e))) / (2 * e)

    def input_force(self, u):
        return np.asarray(self.fn(u), dtype=float)


@dataclass(frozen=True)
class Contact:
    r"""Penalty contact of the tube of radius ``radius`` [m] with a 3D SDF ``obstacle`` at the nodes (see
    :meth:`Shapes.add_contact`): stiffness [N/m^2], damping [N s/m^2], friction coefficient, regularization
    [m/s]. Writes the nodal forces into ``data.contact_forces``."""

    obstacle: object
    stiffness: float
    damping: float
    friction: float
    regularization: float
    radius: float
    inputs = 0

    def force(self, model, data, q, qd, t):
        G, eta, J, r = model.at_nodes(data.G), model.at_nodes(data.eta), model.at_nodes(data.J), self.radius
        P = G[:, :3, 3]
        f = np.zeros(model.n)
        d = self.obstacle(P)
        hit = np.nonzero(d < r)[0]
        if len(hit) == 0:
            return f
        nrm = self.obstacle.gradient(P[hit])
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        k, c, mu, eps = self.stiffness, self.damping, self.friction, self.regularization
        for j, i in enumerate(hit):
            R = G[i, :3, :3]
            v = R @ eta[i, 3:]
            vn = v @ nrm[j]
            fn = max(0.0, k * (r - d[i]) - c * vn)
            vt = v - vn * nrm[j]
            F = fn * nrm[j] - mu * fn * vt / np.sqrt(vt @ vt + eps * eps)
            F *= model.node_weights[i]
            data.contact_forces[i] += F
            f += J[i, 3:].T @ (R.T @ F)
        return f


@dataclass(frozen=True)
class UserForce:
    """A user generalized force ``fn(owner, q, qd, t) -> (n,)`` (``owner``: the :class:`Shapes`)."""

    fn: object
    inputs = 0

    def force(self, model, data, q, qd, t, owner=None):
        v = np.asarray(self.fn(owner, q, qd, t), dtype=float).reshape(-1)
        if v.shape != (model.n,) or not np.all(np.isfinite(v)):
            raise DataError(f"user force returned {v.shape} / non-finite values; expected {model.n} finite")
        return v


def input_terms(loads):
    """The input terms of ``loads`` in the order of ``u``."""
    return [ld for ld in loads if ld.inputs]


def input_force(model, data, loads, q, u):
    """Generalized force of the inputs ``u`` at configuration ``q`` (kinematics not needed)."""
    f = np.zeros(model.n)
    for ui, ld in zip(u, input_terms(loads)):
        f += ld.input_force(ui) if isinstance(ld, Actuator) else ld.input_column(model, data, q, ui) * ui
    return f


def input_map(model, data, loads, q, u=None):
    """(n, m) derivative of the inputs' generalized force with respect to the inputs at the values ``u``
    (default 0); constant for chambers, configuration-dependent for tendons."""
    terms = input_terms(loads)
    u = np.zeros(len(terms)) if u is None else np.asarray(u, dtype=float).reshape(-1)
    cols = [ld.input_column(model, data, q, ui) for ui, ld in zip(u, terms)]
    return np.column_stack(cols) if cols else np.zeros((model.n, 0))


def external_force(model, data, loads, q, qd, t, u, scale=1.0, owner=None):
    """Generalized force of ``loads`` at the kinematics in ``data`` (computed at q, qd): gravity, inputs ``u``,
    point loads and user forces times ``scale``, plus contact (never scaled). Resets ``data.contact_forces``."""
    f = np.zeros(model.n)
    data.contact_forces[...] = 0.0
    contact = np.zeros(model.n)
    has_inputs = False
    for ld in loads:
        if ld.inputs:
            has_inputs = True
        elif isinstance(ld, Contact):
            contact += ld.force(model, data, q, qd, t)
        elif isinstance(ld, UserForce):
            f += ld.force(model, data, q, qd, t, owner)
        else:
            f += ld.force(model, data, q, qd, t)
    if has_inputs and u is not None:
        f += input_force(model, data, loads, q, u)
    return scale * f + contact
