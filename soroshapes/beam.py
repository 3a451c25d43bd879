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
  :func:`coriolis_jacobian`, :func:`inverse_dynamics`, :func:`forward_dynamics` (one compiled call),
  :func:`energy`; and of ``(model, data, loads, ...)``: :func:`accelerations`, :func:`statics`,
  :func:`simulate`, :func:`inverse_kinematics`.

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

from sorofem._lazy import moved_attributes
from sorofem.errors import DataError, ParameterError

from .numerics import FD_STEP
from .trajectory import Trajectory, run_stats

__all__ = ["BeamModel", "BeamData", "StateRangeError", "IKResult", "Gravity", "PointLoad",
           "Chamber", "Tendon", "Actuator", "Contact", "UserForce", "check_state", "kinematics", "dynamics",
           "coriolis_jacobian", "inverse_dynamics", "forward_dynamics", "accelerations", "energy", "external_force",
           "input_map", "inputs_at", "motion_terms", "LoadPlan", "statics", "newton_load_stepping", "simulate",
           "explicit_step_limit", "inverse_kinematics", "damped_least_squares", "time_grid", "lower_contacts",
           "integrator_loads"]
#: one trajectory type for beams, trees and networks (README.md, "Moved names")
__getattr__ = moved_attributes(__name__, {"BeamTrajectory": "soroshapes.trajectory.Trajectory"})

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
    #: number of generalized coordinates and of nodes (segment ends, N+1); derived
    n: int = field(init=False)
    nodes: int = field(init=False)

    def __post_init__(self):
        for name in ("base", "sigma", "points", "h", "B", "X0", "weights", "node_weights", "Md", "K"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "rows", _frozen(self.rows, np.int64))
        object.__setattr__(self, "n", int(self.B.shape[2]))
        object.__setattr__(self, "nodes", int(self.sigma.shape[0]))

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
                 "R", "piv", "qdd", "contact_forces", "acc", "SA", "SX", "NE")

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
        # the Newton-Euler recursions (soroshapes._beam.newton_euler): acceleration twists, per-piece Ad of the
        # inverse and tangent, strains at the Gauss points, and their work vectors
        P = N - 1
        self.acc = np.zeros((N, 6))
        self.SA, self.SX, self.NE = np.zeros((P, 6, 6)), np.zeros((P, 4, 6)), np.zeros((32, 6))

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


def _out_of_range(data, q, qd):
    """Reset the workspace and return the error for a state whose frames or mass matrix left floating point."""
    data.reset()
    return StateRangeError(f"the state (max |q| = {np.max(np.abs(q)):.3g}, max |qd| = {np.max(np.abs(qd)):.3g}) "
                           "makes the frames overflow or the mass matrix singular (strain times segment length "
                           "beyond floating point, or a diverged iterate); give a physically meaningful state "
                           "(|strain| of order 1/length) or a smaller step")


def _guard(data, q, qd, rate):
    """Raise (after resetting the workspace) when the pass produced non-finite values. Non-finite values
    propagate along the chain, so the tip's frame, Jacobian and twist tell."""
    s = data.G[-1].sum() + data.J[-1].sum() + data.eta[-1].sum()
    if rate:
        s += data.Jd[-1].sum()
    if not math.isfinite(s):
        raise _out_of_range(data, q, qd)


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


def forward_dynamics(model, data, q, qd, f_in, D, gravity, point_loads=(), t=0.0, plan=None):
    r"""Accelerations :math:`\ddot q = M^{-1}(f_{in} + f_g + \sum_p J_p^T W_p - C\dot q - D\dot q - Kq)` (n,)
    in one compiled call (:func:`soroshapes._beam.forward_dynamics`): ``f_in`` (n,) the inputs' generalized
    force, ``D`` (n, n) the damping matrix, ``gravity`` (3,) [m/s^2], ``point_loads`` :class:`PointLoad` terms
    evaluated at time ``t`` [s] (``plan``: a :class:`LoadPlan` holding their nodes and frames). Configuration-
    dependent loads (contact, tendons, user forces) are not included: :func:`external_force` covers them. Returns
    ``data.qdd``; a non-finite result (a state out of range) resets the workspace and raises."""
    from . import _beam
    q, qd = check_state(model, q), check_state(model, qd, "qd")
    if plan is None:
        plan = LoadPlan.of(model, point_loads)
    W = np.array([ld.wrench(t) for ld in plan.point_loads]) if plan.point_loads else _NO_WRENCH
    nodes, spatial = plan.nodes, plan.spatial
    ok = _beam.forward_dynamics(q, qd, f_in, model.K, D, nodes, W, spatial, model.order, model.h, model.B,
                                model.rows, model.X0, model.base, model.weights, model.Md, gravity, data.G, data.J,
                                data.eta, data.acc, data.SA, data.SX, data.E, data.NE, data.S[0], data.Jd, data.Op,
                                data.M, data.C, data.R, data.piv, data.qdd)
    if not (ok and math.isfinite(data.qdd.sum())):          # a non-finite frame makes M and qdd non-finite
        raise _out_of_range(data, q, qd)
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


def inputs_at(loads, u, t):
    """The input values at time ``t`` [s] (``u``: None = zeros, an array, or a callable of t), validated."""
    terms = input_terms(loads)
    m = len(terms)
    if u is None:
        return np.zeros(m)
    v = u(t) if callable(u) else u
    v = np.asarray(v, dtype=float).reshape(-1)
    if v.shape != (m,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"u must give {m} finite inputs ({', '.join(ld.name for ld in terms)}), got {v.shape}")
    return v


def gravity_of(loads):
    """The gravity acceleration [m/s^2] of ``loads`` (zeros without a :class:`Gravity` term)."""
    for ld in loads:
        if isinstance(ld, Gravity):
            return np.asarray(ld.acceleration, dtype=float)
    return np.zeros(3)


def compiled_loads(loads):
    """True when every term runs inside the compiled kernels (gravity, chambers, actuators, point loads)."""
    return not any(isinstance(ld, (Contact, UserForce, Tendon)) for ld in loads)


_NO_CONTACTS = (np.zeros((0, 7), np.int64), np.zeros(0), np.zeros((0, 3), np.int64), np.zeros(0),
                np.zeros((0, 1, 4)))


def lower_contacts(model, loads):
    """The :class:`Contact` terms of ``loads`` in the form the compiled integrator takes
    (:func:`soroshapes._beam.integrate_midpoint`): ``(table, floats, ops, consts, memo)``, per contact a row
    (floats offset, count, SDF ops offset, count, consts offset, value and point stack depths) over the floats
    and SDF programs of :func:`soroshapes._contact.lower_contact_of`, and a zero memo (contacts, N+1, 4); None
    when an obstacle's SDF has no program form (then the Python path runs)."""
    from ._contact import lower_contact_of
    terms = [ld for ld in loads if isinstance(ld, Contact)]
    if not terms:
        return _NO_CONTACTS
    rows, flt, ops, consts = [], [], [], []
    for ld in terms:
        try:
            par, prog = lower_contact_of(model, ld.radius, ld.obstacle, ld.stiffness, ld.damping, ld.friction,
                                         ld.regularization)
        except NotImplementedError:
            return None
        rows.append([sum(len(v) for v in flt), len(par), sum(len(v) for v in ops), len(prog.ops),
                     sum(len(v) for v in consts), prog.values, prog.points])
        flt.append(par)
        ops.append(np.asarray(prog.ops, dtype=np.int64).reshape(-1, 3))
        consts.append(np.asarray(prog.consts, dtype=float))
    return (np.array(rows, dtype=np.int64), np.concatenate(flt), np.ascontiguousarray(np.concatenate(ops)),
            np.concatenate(consts), np.zeros((len(terms), len(model.node_weights), 4)))


def integrator_loads(model, loads):
    """The loads' contacts for the compiled integrator (:func:`lower_contacts`) when every term runs compiled
    there (gravity, chambers, actuators, point loads, contact with obstacles whose SDF has a program form), else
    None (tendons, user forces, or an SDF without a program: the Python step loop)."""
    if any(isinstance(ld, (UserForce, Tendon)) for ld in loads):
        return None
    return lower_contacts(model, loads)


# ------------------------------------------------------------------------------------------------------------
# statics
# ------------------------------------------------------------------------------------------------------------
def statics(model, data, loads, u=None, q0=None, *, steps=1, tol=1e-9, max_iterations=40, min_step=1e-4, t=0.0,
            owner=None, constraints=None):
    r"""Static equilibrium :math:`K q = f_g(q) + G(q)u + f_{ext}(q)` by Newton's method with load stepping
    (see :meth:`soroshapes.shapes.Shapes.statics`). Returns (q, Newton iterations per accepted increment).

    ``constraints``: a :class:`soroshapes.constraints.ConstraintSet` (bound at ``q0``); the unknowns are then
    :math:`(q, \lambda)`, the residual :math:`(Kq - f - J_c^T\lambda,\ c)` and its tangent the bordered matrix
    (:mod:`soroshapes.constraints`); the targets ramp with the load factor; an increment also needs the drift
    :math:`|c|` below ``tol`` times the length, and no increment turns a target by more than pi/4 (the drift is
    a logarithm, defined modulo a turn: a larger increment could land a whole turn short). Returns (q,
    multipliers, iterations, the bordered tangent at the solution (n + m, n + m), the drift c (m,))."""
    q = check_state(model, q0)
    uv = inputs_at(loads, u, t)
    K, n = model.K, model.n
    m = 0 if constraints is None else constraints.m

    def aug(x, scale):
        """(K q - f - J_c^T lambda, c) at x = (q, lambda): forces, then the drift on the same kinematic pass."""
        try:
            qx, qdx = kinematics(model, data, x[:n])
            r = K @ qx - external_force(model, data, loads, qx, qdx, t, uv, scale, owner)
        except StateRangeError:              # an iterate left the finite range: the line search backs off
            return np.full(n + m, np.nan)
        if not m:
            return r
        c, Jc = constraints.residual_and_jacobian(data, scale)
        return np.concatenate([r - Jc.T @ x[n:], c])

    cap = 1.0 if constraints is None else constraints.max_load_step   # a turn of a target stays below pi/4
    x, iterations, Kt = newton_load_stepping(aug, np.concatenate([q, np.zeros(m)]), n, lambda y: K @ y,
                                             float(np.abs(np.diag(K)).max()), model.length, cap=cap, steps=steps,
                                             tol=tol, max_iterations=max_iterations, min_step=min_step,
                                             tangent=bool(m))
    if m:
        return x[:n], x[n:], iterations, Kt, aug(x, 1.0)[n:]
    return x, iterations


def newton_load_stepping(aug, x, n, stiffness_force, kmax, length, *, cap=1.0, steps=1, tol=1e-9,
                         max_iterations=40, min_step=1e-4, tangent=False):
    r"""The Newton solver with load stepping of every static problem (one beam, with or without constraints,
    and an assembly of bodies, :class:`soroshapes.constraints.Assembly`).

    ``aug(x, scale)``: the residual (n + m,) at the unknowns ``x`` = (q (n,), multipliers (m,)) at load factor
    ``scale``: generalized forces [N m per coordinate] then the drift [m, rad] (NaN when an iterate is out of
    range). The tangent is the forward difference (:func:`soroshapes.numerics.fd_columns`) over the n + m
    columns; a backtracking line search on the merit :math:`|r_q| + (k_{max}/L^2)|c|` (``kmax`` the largest
    diagonal stiffness, ``length`` L [m]). An increment converges when :math:`|r_q| \le` ``tol``
    :math:`(|Kq| + |J_c^T\lambda|)` (``stiffness_force(q)`` = :math:`Kq`; the constraint forces from the
    tangent's multiplier columns: a constraint holding q at rest has Kq = 0 while its reaction balances the
    loads), :math:`|c| \le` ``tol`` L and the last correction
    of q is below 1e-8 relative; a failed increment is halved down to ``min_step``, then a
    :class:`~sorofem.errors.ConvergenceError`; increments double (up to ``cap``) after quick convergence.
    Returns (x, Newton iterations per accepted increment, the tangent at the solution (n + m, n + m) when
    ``tangent`` else None)."""
    from .numerics import fd_columns
    m = len(x) - n
    c_weight = kmax / length**2          # drift [m] -> a force of the size of K's [N m per coordinate]
    c_tol = tol * length

    def merit(r):
        return np.linalg.norm(r[:n]) + c_weight * np.linalg.norm(r[n:])

    def newton(x, scale):
        r = aug(x, scale)
        for it in range(1, max_iterations + 1):
            Kt = fd_columns(lambda y: aug(y, scale), x, r, np.ones(n + m))
            try:
                dx = -np.linalg.solve(Kt, r)
            except np.linalg.LinAlgError:
                return None, it
            ref = merit(r)
            step = 1.0
            while True:
                xn = x + step * dx
                rn = aug(xn, scale)
                if np.all(np.isfinite(rn)) and merit(rn) <= (1 - 1e-4 * step) * ref or step < 1e-3:
                    break
                step *= 0.5
            if not np.all(np.isfinite(rn)):
                return None, it
            x, r = xn, rn
            q = x[:n]
            # elastic + applied forces: Kq and the constraints' generalized forces J_c^T lambda (= -Kt[:n, n:]
            # lambda; a constraint that holds q at rest balances the applied forces with Kq = 0)
            scale_ref = (np.linalg.norm(stiffness_force(q)) + np.linalg.norm(Kt[:n, n:] @ x[n:])
                         + 1e-12 * kmax)
            if (np.linalg.norm(r[:n]) <= tol * scale_ref and np.linalg.norm(r[n:]) <= c_tol
                    and np.linalg.norm(step * dx[:n]) <= 1e-8 * (1 + np.linalg.norm(q))):
                return x, it
        return None, max_iterations

    lam, dlam = 0.0, min(cap, 1.0 / max(1, int(steps)))
    iterations = []
    while lam < 1.0 - 1e-14:
        target = min(1.0, lam + dlam)
        xn, its = newton(x.copy(), target)
        if xn is None:
            dlam *= 0.5
            if dlam < min_step:
                from sorofem.errors import ConvergenceError
                extra = ("; with constraints, also check that the targets are reachable by the basis and that "
                         "the path does not cross a bifurcation (perturb q0 or add an imperfection)") if m else ""
                raise ConvergenceError(f"statics: Newton failed at load level {target:.4g} (reached {lam:.4g}) "
                                       "with the minimum increment; use more steps, a better q0, or check "
                                       "that the loads are reachable" + extra)
            continue
        x, lam = xn, target
        iterations.append(its)
        if its <= 4:
            dlam = min(2 * dlam, cap)
    Kt = fd_columns(lambda y: aug(y, 1.0), x, aug(x, 1.0), np.ones(n + m)) if tangent else None
    return x, iterations, Kt


# ------------------------------------------------------------------------------------------------------------
# dynamics
# ------------------------------------------------------------------------------------------------------------
def motion_terms(model, data, loads, q, qd, t, uv, tau, owner=None):
    r"""(M, :math:`C\dot q + D\dot q + Kq - f`) at (q, qd, t) with the input values ``uv``: the mass matrix
    (a copy) and the left-hand side of the equations of motion without the inertia term [N m per coordinate]."""
    M, C, fg = dynamics(model, data, q, qd, gravity_of(loads), True)
    M, C, fg = M.copy(), C.copy(), fg.copy()           # the gravity force of this pass serves the Gravity term
    q, qd = np.asarray(q, dtype=float).reshape(-1), np.asarray(qd, dtype=float).reshape(-1)
    f = external_force(model, data, [ld for ld in loads if not isinstance(ld, Gravity)], q, qd, t, uv, 1.0, owner)
    return M, C @ qd + tau * (model.K @ qd) + model.K @ q - f - fg


@dataclass(frozen=True, eq=False)
class LoadPlan:
    """What the compiled kernels need from a list of loads, gathered once (rebuild it when the loads or the
    damping change): whether every term runs compiled, the gravity [m/s^2], the damping matrix ``D``, the
    constant input matrix (n, m) when every input is linear and configuration independent (else None), and the
    point loads with their workspace rows and frames."""

    compiled: bool
    gravity: np.ndarray
    D: np.ndarray
    input_matrix: object
    point_loads: tuple
    nodes: np.ndarray
    spatial: np.ndarray

    @classmethod
    def of(cls, model, loads, tau=0.0):
        """The plan of ``loads`` on ``model`` with Kelvin-Voigt damping ``tau`` [s]."""
        points = tuple(ld for ld in loads if isinstance(ld, PointLoad))
        terms = input_terms(loads)
        linear = all(isinstance(ld, Chamber) or (isinstance(ld, Actuator) and isinstance(
            getattr(ld.fn, "column", None), np.ndarray)) for ld in terms)
        G = None
        if linear:
            G = np.zeros((model.n, len(terms)))
            for j, ld in enumerate(terms):
                G[:, j] = ld.column if isinstance(ld, Chamber) else ld.fn.column
        nodes = np.array([ld.node * model.stride for ld in points], dtype=np.int64) if points else _NO_NODES
        spatial = np.array([ld.frame == "spatial" for ld in points], dtype=np.bool_) if points else _NO_FLAGS
        return cls(compiled_loads(loads), gravity_of(loads), tau * model.K, G, points, nodes, spatial)


def accelerations(model, data, loads, q, qd, t=0.0, u=None, tau=0.0, owner=None, plan=None):
    r"""Accelerations :math:`\ddot q = M^{-1}(f - C\dot q - D\dot q - Kq)` with all ``loads`` at state (q, qd),
    time t [s], inputs ``u``, damping :math:`D = \tau K` (``tau`` [s]); one compiled call when the loads allow
    (:func:`forward_dynamics`), else the assembled matrices. ``plan``: the loads' :class:`LoadPlan` (made here
    when not given)."""
    uv = inputs_at(loads, u, t)
    plan = LoadPlan.of(model, loads, tau) if plan is None else plan
    if plan.compiled:
        if plan.input_matrix is not None:
            f_in = plan.input_matrix @ uv
        else:
            f_in = input_force(model, data, loads, None, uv) if len(uv) else np.zeros(model.n)
        return forward_dynamics(model, data, q, qd, f_in, plan.D, plan.gravity, plan.point_loads, t, plan).copy()
    M, lhs = motion_terms(model, data, loads, q, qd, t, uv, tau, owner)
    try:
        return np.linalg.solve(M, -lhs)
    except np.linalg.LinAlgError:
        raise _out_of_range(data, np.asarray(q, dtype=float), np.asarray(qd, dtype=float)) from None


def time_grid(t_end, dt, min_dt=None, record_every=1):
    """The checked time grid of a simulation: ``(t_end, dt, nsteps, min_dt, record_every)`` with ``dt`` shrunk so
    that ``nsteps`` equal steps end exactly at ``t_end`` [s] and ``min_dt`` [s] (the smallest step a failed step is
    halved to) defaulting to dt/1024. Raises :class:`ParameterError` for a non-positive or non-finite t_end or dt
    and a record_every below 1."""
    t_end, dt = float(t_end), float(dt)
    if not (t_end > 0 and dt > 0 and np.isfinite(t_end) and np.isfinite(dt)):
        raise ParameterError(f"t_end and dt must be positive [s], got {t_end!r}, {dt!r}")
    record_every = int(record_every)
    if record_every < 1:
        raise ParameterError("record_every must be >= 1")
    nsteps = int(np.ceil(t_end / dt - 1e-9))
    dt = t_end / nsteps
    min_dt = dt / 1024 if min_dt is None else float(min_dt)
    return t_end, dt, nsteps, min_dt, record_every


def simulate(model, data, loads, t_end, dt, q0=None, qd0=None, u=None, *, tau=0.0, method="implicit", tol=1e-8,
             max_iterations=20, min_dt=None, record_every=1, owner=None):
    r"""Time integration of the beam's equations of motion (see :meth:`soroshapes.shapes.Shapes.simulate`);
    ``tau`` [s]: Kelvin-Voigt damping :math:`D = \tau K`. Returns a :class:`~soroshapes.trajectory.Trajectory`
    (``t``, ``q``, ``qd``, ``kinetic``, ``potential``, ``tip``, ``stats``). (With constraints,
    :meth:`soroshapes.constraints.Assembly.simulate` integrates the beam as a one-body assembly.)"""
    import time
    if method not in ("implicit", "explicit"):
        raise ParameterError("method must be 'implicit' or 'explicit'")
    t_end, dt, nsteps, min_dt, record_every = time_grid(t_end, dt, min_dt, record_every)
    q = check_state(model, q0).copy()
    qd = check_state(model, qd0, "qd0").copy()
    inputs_at(loads, u, 0.0)                      # validate u before the loop
    t0 = time.perf_counter()
    rec = {"t": [], "q": [], "qd": [], "kin": [], "pot": [], "tip": []}
    its_all = []
    start = 0
    args = (model, data, loads, u, tau, tol, max_iterations, record_every, rec, its_all)
    contacts = integrator_loads(model, loads) if method == "implicit" else None
    if contacts is not None:
        start, q, qd = _simulate_compiled(q, qd, dt, nsteps, contacts, *args)
    if start < nsteps:
        _simulate_python(q, qd, start, dt, nsteps, method, min_dt, owner, *args)
    wall = time.perf_counter() - t0
    path = "compiled" if start == nsteps else "python" if start == 0 else "compiled, then python"
    stats = run_stats(steps=nsteps, newton_iterations=int(np.sum(its_all)), matrices=rec.get("refreshes", 0),
                      jacobians=rec.get("jacobians", 0), cut_steps=rec.get("cut_steps", 0), rejected=0, dt=dt,
                      method=method, path=path, adaptive=False, wall_time=wall,
                      newton_iterations_by_step=np.array(its_all, dtype=int), compiled_steps=start)
    return Trajectory(rec["t"], q=np.array(rec["q"]), qd=np.array(rec["qd"]), kinetic=np.array(rec["kin"]),
                      potential=np.array(rec["pot"]), tip=np.array(rec["tip"]), stats=stats)


def _simulate_compiled(q, qd, dt, nsteps, contacts, model, data, loads, u, tau, tol, max_iterations, record_every,
                       rec, its_all):
    """The compiled loop (:func:`soroshapes._beam.integrate_midpoint`) with the lowered ``contacts``
    (:func:`integrator_loads`); returns (steps done, q, qd) and appends its records."""
    from . import _beam
    n = model.n
    tm = (np.arange(nsteps) + 0.5) * dt
    fext = np.zeros((nsteps, n))
    if input_terms(loads):           # chambers and actuators: forces independent of the configuration
        for k, t in enumerate(tm):
            fext[k] = input_force(model, data, loads, q, inputs_at(loads, u, t))
    point_loads = [ld for ld in loads if isinstance(ld, PointLoad)]
    pl_nodes = np.array([ld.node * model.stride for ld in point_loads], dtype=np.int64)
    pl_spatial = np.array([ld.frame == "spatial" for ld in point_loads], dtype=np.bool_)
    pl_W = np.zeros((nsteps, len(point_loads), 6))
    for j, ld in enumerate(point_loads):
        for k, t in enumerate(tm):
            pl_W[k, j] = ld.wrench(t)
    nrec = nsteps // record_every + 1 + (nsteps % record_every != 0)
    out_t, out_q, out_qd = np.zeros(nrec), np.zeros((nrec, n)), np.zeros((nrec, n))
    out_e, out_tip, its = np.zeros((nrec, 2)), np.zeros((nrec, 3)), np.zeros(nsteps, dtype=np.int64)
    jacs = np.zeros(nsteps, dtype=np.int64)
    done = _beam.integrate_midpoint(
        q, qd, dt, nsteps, record_every, fext, pl_nodes, pl_W, pl_spatial, model.K, tau * model.K,
        model.order, model.h, model.B, model.rows, model.X0, model.base, model.weights, model.Md,
        gravity_of(loads), float(tol), int(max_iterations), FD_STEP, out_t, out_q, out_qd, out_e, out_tip, its,
        jacs, data.G, data.eta, data.acc, data.SA, data.SX, data.E, data.NE, contacts)
    m = done // record_every + 1 + (done == nsteps and nsteps % record_every != 0)
    if done < nsteps:
        m = (done - 1) // record_every + 1 if done > 0 else 1
    rec["t"] += list(out_t[:m])
    rec["q"] += list(out_q[:m])
    rec["qd"] += list(out_qd[:m])
    rec["kin"] += list(out_e[:m, 0])
    rec["pot"] += list(out_e[:m, 1])
    rec["tip"] += list(out_tip[:m])
    its_all += list(its[:done])
    rec["refreshes"] = rec.get("refreshes", 0) + int(np.count_nonzero(jacs[:done]))
    rec["jacobians"] = rec.get("jacobians", 0) + int(np.count_nonzero(jacs[:done] == 2))
    return done, q, qd


def _simulate_python(q, qd, start, dt, nsteps, method, min_dt, owner, model, data, loads, u, tau, tol, max_iterations,
                     record_every, rec, its_all):
    """Step by step in Python (contact, tendons, user forces; or after the compiled loop gave up), halving a step
    that fails down to ``min_dt``."""
    from sorofem.errors import ConvergenceError
    g = gravity_of(loads)

    def record(t):
        e = energy(model, data, q, qd, g)
        rec["t"].append(t)
        rec["q"].append(q.copy())
        rec["qd"].append(qd.copy())
        rec["kin"].append(e["kinetic"])
        rec["pot"].append(e["elastic"] + e["gravity"])
        rec["tip"].append(data.G[-1, :3, 3].copy())
    step_fn = _midpoint_step if method == "implicit" else _rk4_step
    t_end = nsteps * dt
    t, k = start * dt, start
    if start == 0:
        record(t)
    while k < nsteps:
        h, t_next = dt, (k + 1) * dt
        cut = False
        while t < t_next - 1e-12 * dt:          # sub-steps when a step must be cut
            hh = min(h, t_next - t)
            try:
                step = step_fn(model, data, loads, q, qd, t, hh, u, tau, tol, max_iterations, owner)
            except StateRangeError:              # an iterate left the finite range: a failed step, cut it
                step = None
            if step is None:
                cut = True
                h *= 0.5
                if h < min_dt and method == "explicit":
                    limit = explicit_step_limit(model, data)
                    raise ConvergenceError(
                        f"simulate: explicit RK4 did not converge at t = {t:.6g} s down to dt = {min_dt:.3g} s: "
                        f"it is stable only below dt = {limit:.3g} s for this rod (Shapes.explicit_step_limit(), "
                        f"2/omega_max); use dt < {limit:.3g} s or method='implicit' (A-stable, any dt)")
                if h < min_dt:
                    raise ConvergenceError(f"simulate: the step at t = {t:.6g} s did not converge down to dt = "
                                           f"{min_dt:.3g} s ({method}); use a smaller dt, the implicit method, "
                                           "or check the loads")
                continue
            q[:], qd[:], its, nfd = step
            its_all.append(its)
            if method == "implicit":
                rec["refreshes"] = rec.get("refreshes", 0) + 1 + nfd     # S at the start, then FD replacements
                rec["jacobians"] = rec.get("jacobians", 0) + nfd
            t += hh
        rec["cut_steps"] = rec.get("cut_steps", 0) + cut
        t, k = t_next, k + 1
        if k % record_every == 0 or k == nsteps:
            record(min(t, t_end))


def explicit_step_limit(model, data, q=None):
    r"""Stability limit [s] of explicit time stepping, :math:`2/\omega_{max}` (central difference), with
    :math:`\omega_{max}^2` the largest eigenvalue of :math:`K\phi = \omega^2 M(q)\phi` (default ``q``: straight;
    geometric stiffness of gravity and loads not included). Overwrites ``data``."""
    from scipy.linalg import eigh
    M = dynamics(model, data, np.zeros(model.n) if q is None else q, want_c=False)[0]
    w2 = eigh(model.K, M, eigvals_only=True)[-1]
    return 2.0 / math.sqrt(max(w2, 0.0)) if w2 > 0 else math.inf


def _midpoint_step(model, data, loads, q, qd, t, h, u, tau, tol, max_iterations, owner):
    """One implicit-midpoint step: Newton iterations on v_m with the matrix 2M/h + dCv/dv + D + h/2 K; when they
    contract slowly (large steps with large rotations), the matrix is replaced by the finite-difference Jacobian
    of the residual. Returns (q, qd, iterations) or None."""
    from .numerics import fd_columns
    K = model.K
    uv = inputs_at(loads, u, t + 0.5 * h)

    def residual(vm):
        qm = q + 0.5 * h * vm
        M, lhs = motion_terms(model, data, loads, qm, vm, t + 0.5 * h, uv, tau, owner)
        return M @ (2.0 * (vm - qd) / h) + lhs, M, qm
    vm = qd.copy()
    R, M, qm = residual(vm)
    S = 2.0 * M / h + coriolis_jacobian(model, data, qm, vm) + tau * K + 0.5 * h * K
    prev, nfd = np.inf, 0
    for it in range(1, max_iterations + 1):
        if not np.all(np.isfinite(R)):
            return None
        nr = np.linalg.norm(R)
        if it > 3 and nr > 0.25 * prev:
            S = fd_columns(lambda v: residual(v)[0], vm, R, np.ones(model.n))
            nfd += 1
        prev = nr
        dv = np.linalg.solve(S, -R)
        vm = vm + dv
        R, M, qm = residual(vm)
        ref = np.linalg.norm(K @ qm) + np.linalg.norm(M @ vm) / h
        if np.linalg.norm(dv) <= tol * np.linalg.norm(vm) + 1e-12 or np.linalg.norm(R) <= 1e-3 * tol * ref:
            return q + h * vm, 2.0 * vm - qd, it, nfd
    return None


def _rk4_step(model, data, loads, q, qd, t, h, u, tau, tol, max_iterations, owner):
    """One classical RK4 step; None when it blows up."""
    def f(x, v, tt):
        return v, accelerations(model, data, loads, x, v, tt, u, tau, owner)
    k1 = f(q, qd, t)
    k2 = f(q + 0.5 * h * k1[0], qd + 0.5 * h * k1[1], t + 0.5 * h)
    k3 = f(q + 0.5 * h * k2[0], qd + 0.5 * h * k2[1], t + 0.5 * h)
    k4 = f(q + h * k3[0], qd + h * k3[1], t + h)
    qn = q + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    vn = qd + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    if not (np.all(np.isfinite(qn)) and np.all(np.isfinite(vn))) or np.linalg.norm(qn) > 1e6 * (
            1 + np.linalg.norm(q)):
        return None
    return qn, vn, 0, 0


# ------------------------------------------------------------------------------------------------------------
# inverse kinematics
# ------------------------------------------------------------------------------------------------------------
def inverse_kinematics(model, data, targets, q0=None, *, tol=1e-8, max_iterations=200, damping=1e-6,
                       rotation_weight=None, subtask=None, subtask_gain=0.1):
    r"""Damped least-squares inverse kinematics (see :meth:`soroshapes.shapes.Shapes.inverse_kinematics`);
    ``targets``: a list of ``(node index, "position" or "pose", (3,) or (4, 4) target)``. Returns an
    :class:`IKResult`."""
    from sorofem.errors import ConvergenceError

    from . import _beam
    q = check_state(model, q0).copy()
    wrot = model.length if rotation_weight is None else float(rotation_weight)
    if subtask is not None and subtask != "elastic" and not callable(subtask):
        raise ParameterError("subtask must be 'elastic', a callable grad(q) -> (n,), or None")
    nodes = np.array([i * model.stride for i, _, _ in targets], dtype=np.int64)
    kinds = np.array([0 if k == "position" else 1 for _, k, _ in targets], dtype=np.int64)
    goals = np.zeros((len(targets), 4, 4))
    for j, (_, kind, v) in enumerate(targets):
        if kind == "position":
            goals[j] = np.eye(4)
            goals[j, :3, 3] = v
        else:
            goals[j] = v
    args = (nodes, kinds, goals, wrot, float(tol), int(max_iterations), float(damping), 1e6 * model.length)
    d = data
    kin = (model.order, model.h, model.B, model.rows, model.X0, model.base, d.G, d.J, d.Jd, d.eta, d.S, d.E, d.V,
           d.Op, d.dOp, d.AJ)
    if not callable(subtask):
        err, it, converged = _beam.ik_solve(q, *args, model.K, subtask_gain if subtask else 0.0, *kin)
    else:
        err, it, converged = _ik_python(model, data, q, args, subtask, subtask_gain)
    if not (math.isfinite(err) and np.all(np.isfinite(q))):
        d.reset()
        raise ConvergenceError("inverse_kinematics: the iterations left the finite range; give a closer q0 or a "
                               "reachable target")
    return IKResult(q=q, error=float(err), iterations=int(it), converged=bool(converged))


def _ik_python(model, data, q, args, grad, gain):
    """:func:`soroshapes._beam.ik_solve` with a Python subtask gradient ``grad(q)`` (same algorithm)."""
    from . import _beam
    nodes, kinds, goals, wrot, tol, max_it, lam, lam_max = args
    m = int(sum(3 if k == 0 else 6 for k in kinds))
    e, A = np.empty(m), np.empty((m, model.n))

    def error(x):
        kinematics(model, data, x)
        return _beam._ik_error(nodes, kinds, goals, wrot, data.G, data.J, e, A), e.copy(), A.copy()
    err, it = damped_least_squares(error, q, tol, max_it, lam, lam_max, grad, gain)
    kinematics(model, data, q)
    return err, it, err < tol


def damped_least_squares(error, q, tol, max_iterations, damping, damping_max, grad=None, gain=0.0):
    r"""The iterations of the inverse kinematics on ``q`` (in place): ``error(x)`` gives (|e|, e (m,), A (m, n)),
    the stacked task errors and their Jacobian rows; steps :math:`\Delta q = A^T(AA^T + \lambda^2 I)^{-1}e`
    plus, with ``grad`` (a callable q -> (n,)), the null-space step :math:`-(I - A^\dagger A)\nabla` scaled to
    ``gain`` times the task step; :math:`\lambda` halves after an accepted step and grows fourfold after a
    rejected one (up to ``damping_max``). Stops at |e| < ``tol``, after ``max_iterations``, or after 10 accepted
    steps without progress. Returns (|e|, iterations). Any chain of frames uses it (a beam, a tree of bodies)."""
    lam = damping
    err, ek, Ak = error(q)
    m, n = Ak.shape
    it = 0
    best, since_best = err, 0
    while err >= tol and it < max_iterations and since_best < 10:
        it += 1
        AAt = Ak @ Ak.T + lam * lam * np.eye(m)
        dq = Ak.T @ np.linalg.solve(AAt, ek)
        stalled = np.linalg.norm(dq) < 1e-12 * (1 + np.linalg.norm(q))
        if grad is not None:
            g = np.asarray(grad(q), dtype=float).reshape(n)
            gn = -(g - Ak.T @ np.linalg.solve(AAt, Ak @ g))
            if np.linalg.norm(gn) > 0:
                dq += gain * max(np.linalg.norm(dq), tol) * gn / np.linalg.norm(gn)
        errn, en, An = error(q + dq)
        if errn <= err + tol:
            q[:], err, ek, Ak = q + dq, errn, en, An
            lam = max(0.5 * lam, 1e-12)
            if stalled:
                break
            best, since_best = (err, 0) if err < best * (1 - 1e-9) else (best, since_best + 1)
        else:
            lam *= 4.0
            if lam > damping_max:
                break
    return err, it
