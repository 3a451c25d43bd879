r"""Holonomic constraints of Cosserat beams and rigid links, enforced with Lagrange multipliers in statics and in
the implicit midpoint step of the dynamics.

A constraint holds a material frame :math:`g_a = (R_a, p_a)` of a body (``at``: a node of a beam [m], default its
tip; a frame of a :class:`RigidLink`) on a frame :math:`g_b` that is fixed in the world or belongs to another body
(``to``, ``to_at``), in position (:class:`Pin`), orientation (:class:`Align`) or both (:class:`Weld`). Its
residual, the *drift*, is

.. math:: c_p = p_a - p_b \ \text{[m]}, \qquad c_R = \log\!\left(R_a R_b^T\right)^\vee \ \text{[rad]},

and its exact Jacobian :math:`J_c = \partial c/\partial q` has, in the columns of body a, :math:`R_a J_v` for
the position and :math:`J_l^{-1}(c_R)\, R_a J_\omega` for the orientation (:math:`J = (J_\omega, J_v)` the body
Jacobian of the frame, :math:`J_l` the left Jacobian of SO(3)), and in the columns of body b
:math:`-R_b J_v` and :math:`-J_l^{-1}(c_R)\, R_a J_\omega` (the rate of :math:`E = R_a R_b^T` is
:math:`(\omega_a - E\omega_b)^\wedge E` with the spatial angular velocities :math:`\omega`). Statics then solves,
with the multipliers :math:`\lambda`,

.. math:: K q - f(q) - J_c(q)^T \lambda = 0, \qquad c(q) = 0,

by Newton's method on the bordered system :math:`\begin{bmatrix} K_t & -J_c^T \\ J_c & 0\end{bmatrix}` (the
tangent :math:`K_t` includes the geometric stiffness :math:`-\partial (J_c^T\lambda)/\partial q` of the reactions)
inside the load stepping of :func:`soroshapes.beam.newton_load_stepping`. At :math:`c = 0` the multipliers are
the reaction wrench that the constraint applies to body a at the constrained point, in the world frame: a force
[N] for the position rows, a moment [N m] for the orientation rows (body b takes the opposite wrench at the same
point).

Prescribed motion. A world target is ramped with the load factor :math:`\Lambda \in [0, 1]` of the load stepping
from the frame :math:`(R_0, p_0)` the point has at the initial guess ``q0``: :math:`p^*(\Lambda) = p_0 +
\Lambda(p^* - p_0)` and :math:`R^*(\Lambda) = \exp(\Lambda\,\hat\phi)\, R_0`. The orientation target is either a
(3, 3) rotation (then :math:`\phi = \log(R^* R_0^T)`, an angle below :math:`\pi`) or a rotation vector
:math:`\phi` [rad] of any size applied in the world frame to :math:`R_0` (an end twist of several turns:
``Weld(rotation=(2.5 * np.pi, 0, 0))``). A target left at None holds the frame where it is at ``q0``. Two frames of
bodies are brought together the same way: the offset :math:`(\Delta p_0, \phi_0 = \log E_0)` they have at ``q0``
is ramped to zero, :math:`c_p = p_a - p_b - (1 - \Lambda)\Delta p_0`, :math:`c_R = \log(E\,
\exp(-(1-\Lambda)\hat\phi_0))^\vee`.

Bodies and assemblies
---------------------
:class:`Assembly` stacks bodies (:class:`~soroshapes.shapes.Shapes` beams, each on its own base, and
:class:`RigidLink` bodies): :math:`q = (q_1, \dots, q_B)`, the mass matrix is block diagonal per body, the
constraints couple them. A body is any object with this interface (a tree of bodies can be one):
``n`` (coordinates), ``length`` [m] (a size for the tolerances, or None), ``stiffness`` (n, n),
``handle(at) -> (handle, label)`` (a frame of the body), ``kinematics(q)``, ``frame(handle) -> (g (4, 4),
J (6, n))`` (pose and body Jacobian, angular rows first, at the last kinematics), ``inputs(u, t)``,
``static_residual(q, t, u, scale)`` (:math:`Kq - f`), ``motion_terms(q, qd, t, u) -> (M, C\dot q + D\dot q + Kq -
f)``, ``iteration_matrix(q, qd, h)`` (an approximation of :math:`\partial(\text{residual})/\partial v_m` of the
midpoint step), ``mass_matrix(q)``, ``energy(q, qd) -> (kinetic, potential)`` and ``end(q)`` (a point [m] recorded
as the trajectory's ``tip``).

Dynamics: the implicit midpoint rule with the multipliers as unknowns (index 3)
-------------------------------------------------------------------------------
With :math:`v_m = (\dot q_n + \dot q_{n+1})/2`, :math:`q_m = q_n + \tfrac h2 v_m`, one step solves for
:math:`(v_m, \lambda)`

.. math:: M(q_m)\frac{2(v_m - \dot q_n)}{h} + C\,v_m + D v_m + K q_m - f = J_c(q_m)^T\lambda,
          \qquad c(q_n + h v_m) = 0,

(the rows of :meth:`soroshapes.shapes.Shapes.simulate` plus the reactions) by Newton's method on the bordered
matrix :math:`\begin{bmatrix} S & -J_c(q_m)^T \\ J_c(q_{n+1}) & 0 \end{bmatrix}` (:math:`S` the bodies' iteration
matrices, kept through the step; the whole differenced Jacobian when Newton contracts slowly), then
:math:`q_{n+1} = q_n + h v_m` and :math:`\dot q_{n+1} = 2v_m - \dot q_n` projected on the velocity constraint
:math:`J_c(q_{n+1})\dot q_{n+1} = 0` in the metric of :math:`M(q_{n+1})`. Why this form: the position
constraint is solved at every step end (index 3), so the drift is the Newton tolerance at every step and never
accumulates (an index-2 or Baumgarte form integrates the velocity constraint and lets the positions drift);
the midpoint rule needs no extra unknowns for it (a GGL form adds a second multiplier per row), and its
A-stability copes with the stiff coupling. The midpoint velocity update alone leaves a constraint-normal
velocity that flips sign every step (:math:`J_c\dot q_{n+1} = -J_c\dot q_n` to first order); the projection
removes it (it removes kinetic energy only from motion the constraint forbids). The drift
:math:`|c(q_{n+1})|` [m, rad] and the reactions (the multipliers of the step, the mean constraint wrench over it)
are recorded per step.

Units: SI (m, rad, kg, s, N, N m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sorofem.errors import ParameterError

from . import beam as _bm

__all__ = ["Constraint", "Weld", "Pin", "Align", "ConstraintSet", "Equilibrium", "BeamBody", "RigidLink", "Assembly"]


@dataclass(frozen=True)
class Constraint:
    """A frame of a body held on a world frame or joined to a frame of another body.

    Parameters
    ----------
    at : the frame of ``body``: for a beam the arc length [m] of a node (None: the tip); for a
        :class:`RigidLink` None (its centre of mass), a (3,) point [m] or a (4, 4) pose in its body frame.
    position : (3,) world position [m] of the point, or None (where it is at the initial guess).
    rotation : (3, 3) world orientation, or (3,) rotation vector [rad] applied in the world frame to the
        orientation at the initial guess, or None (hold the initial orientation).
    axes : sequence of "x", "y", "z" (position components) and "rx", "ry", "rz" (rotation components about the
        world axes), optional
        Hold only these world components (default all of the constraint's kind), e.g. ``("x", "y", "rz")``
        for a rod that bends in the x-y plane only.
    body : the body (a :class:`~soroshapes.shapes.Shapes` or :class:`RigidLink` of the :class:`Assembly`)
        whose frame is held; None: the only body (a single beam's statics and simulate).
    to : None (a world frame: ``position``, ``rotation``) or the body whose frame ``to_at`` (same meaning as
        ``at``) the frame is joined to; ``position`` and ``rotation`` must then be None (the two frames are made
        to coincide: put the offset into ``to_at``).
    to_at : the frame of ``to``.
    """

    at: object = None
    position: object = None
    rotation: object = None
    axes: object = None
    body: object = None
    to: object = None
    to_at: object = None

    #: which rows the constraint has: "pose", "position" or "orientation" (set by the subclasses)
    fix = "pose"

    def selected(self):
        """Indices (into position x, y, z, rotation x, y, z) of the held components."""
        kind = {"pose": range(6), "position": range(3), "orientation": range(3, 6)}[self.fix]
        if self.axes is None:
            return tuple(kind)
        names = ("x", "y", "z", "rx", "ry", "rz")
        axes = (self.axes,) if isinstance(self.axes, str) else tuple(self.axes)
        bad = [a for a in axes if a not in names or names.index(a) not in kind]
        if bad or not axes or len(set(axes)) != len(axes):
            allowed = ", ".join(names[i] for i in kind)
            raise ParameterError(f"{type(self).__name__}: axes must be distinct names among {allowed}, got "
                                 f"{self.axes!r}")
        return tuple(sorted(names.index(a) for a in axes))


class Weld(Constraint):
    """Position and orientation of the frame at ``at`` held (a clamp): 6 equations, a force and a moment."""

    fix = "pose"


class Pin(Constraint):
    """Position of the point at ``at`` held (a ball joint): 3 equations, a force."""

    fix = "position"


class Align(Constraint):
    """Orientation of the frame at ``at`` held (a sliding clamp): 3 equations, a moment."""

    fix = "orientation"


# ------------------------------------------------------------------------------------------------------------
# bodies
# ------------------------------------------------------------------------------------------------------------
class BeamBody:
    """A Cosserat beam as a body of an :class:`Assembly` (the interface in the module docstring): its frozen
    :class:`~soroshapes.beam.BeamModel`, its load terms, Kelvin-Voigt damping ``tau`` [s] and a workspace of its
    own (``data``; default a fresh one). ``owner``: the :class:`~soroshapes.shapes.Shapes` passed to user forces.
    :meth:`of` makes one from a :class:`~soroshapes.shapes.Shapes`."""

    def __init__(self, model, loads=(), *, tau=0.0, owner=None, data=None, name=None):
        self.model, self.loads, self.tau, self.owner = model, tuple(loads), float(tau), owner
        self.data = model.make_data() if data is None else data
        self.n, self.length, self.stiffness = model.n, model.length, model.K
        self.name = name or "beam"

    @classmethod
    def of(cls, shapes, name=None):
        """The body of a :class:`~soroshapes.shapes.Shapes` (its model, loads and damping; a new workspace)."""
        return cls(shapes.model, shapes.loads, tau=shapes.damping, owner=shapes, name=name)

    def handle(self, at):
        """(row of the frame in the workspace, label) of the node at arc length ``at`` [m] (None: the tip)."""
        node = self.model.node(at)
        return node * self.model.stride, f"at={self.model.sigma[node]:g} m"

    def kinematics(self, q):
        _bm.kinematics(self.model, self.data, q)

    def frame(self, handle, data=None):
        d = self.data if data is None else data
        return d.G[handle], d.J[handle]

    def inputs(self, u, t):
        return _bm.inputs_at(self.loads, u, t)

    def static_residual(self, q, t, u, scale):
        q, qd = _bm.kinematics(self.model, self.data, q)
        return self.stiffness @ q - _bm.external_force(self.model, self.data, self.loads, q, qd, t, u, scale,
                                                        self.owner)

    def motion_terms(self, q, qd, t, u):
        return _bm.motion_terms(self.model, self.data, self.loads, q, qd, t, u, self.tau, self.owner)

    def iteration_matrix(self, q, qd, h):
        """:math:`2M/h + \\partial(C\\dot q)/\\partial\\dot q + D + \\tfrac h2 K` at (q, qd)."""
        K = self.stiffness
        Cv = _bm.coriolis_jacobian(self.model, self.data, q, qd)
        return 2.0 * self.data.M / h + Cv + (self.tau + 0.5 * h) * K

    def mass_matrix(self, q):
        return _bm.dynamics(self.model, self.data, q, want_c=False)[0].copy()

    def energy(self, q, qd):
        e = _bm.energy(self.model, self.data, q, qd, _bm.gravity_of(self.loads))
        return e["kinetic"], e["elastic"] + e["gravity"]

    def end(self, q):
        _bm.kinematics(self.model, self.data, q)
        return self.data.G[-1, :3, 3].copy()


def _inertia(inertia):
    a = np.asarray(inertia, dtype=float)
    if a.ndim == 0:
        a = a * np.eye(3)
    elif a.shape == (3,):
        a = np.diag(a)
    if a.shape != (3, 3) or not np.all(np.isfinite(a)) or not np.allclose(a, a.T) or np.linalg.eigvalsh(a)[0] <= 0:
        raise ParameterError("inertia must be a positive scalar, (3,) principal moments or a symmetric positive "
                             "definite (3, 3) tensor [kg m^2] about the centre of mass, in body axes")
    return a


class RigidLink:
    r"""A rigid body of an :class:`Assembly`: mass [kg], ``inertia`` [kg m^2] about its centre of mass (scalar,
    principal moments or (3, 3), body axes), initial pose ``pose0`` (4, 4) of the centre-of-mass frame (default
    identity), uniform ``gravity`` [m/s^2].

    Coordinates :math:`q = (\phi, \Delta p)` (6,): :math:`R = \exp(\hat\phi) R_0` [rad], :math:`p = p_0 + \Delta p`
    [m]. The spatial angular velocity is :math:`J_l(\phi)\dot\phi`, so the body Jacobian is
    :math:`\begin{bmatrix} R^T J_l(\phi) & 0 \\ 0 & R^T \end{bmatrix}` and the mass matrix
    :math:`M = \mathrm{diag}(J_l^T R I_b R^T J_l,\ m I_3)`; the Coriolis and centrifugal force of the rotation
    block, :math:`\dot M\dot q - \partial T/\partial q`, comes from the forward difference of :math:`M(\phi)`
    (:func:`soroshapes.numerics.fd_columns`). The coordinates are singular at :math:`|\phi| = 2\pi` (a platform
    turns far less). A frame of the body (``at``): None (the centre of mass), a (3,) point or a (4, 4) pose in
    body coordinates."""

    def __init__(self, mass, inertia, pose0=None, gravity=(0.0, 0.0, -9.81), *, name=None):
        self.mass = float(mass)
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ParameterError(f"mass must be positive [kg], got {mass!r}")
        self.inertia = _inertia(inertia)
        g0 = np.eye(4) if pose0 is None else np.asarray(pose0, dtype=float)
        if g0.shape != (4, 4) or not np.allclose(g0[:3, :3].T @ g0[:3, :3], np.eye(3), atol=1e-9):
            raise ParameterError("pose0 must be a (4, 4) homogeneous pose with an orthonormal rotation")
        self.pose0 = g0.copy()
        self.gravity = np.asarray(gravity, dtype=float).reshape(3)
        self.n, self.length, self.stiffness = 6, None, np.zeros((6, 6))
        self.name = name or "link"
        self._G, self._J = np.eye(4), np.zeros((6, 6))

    def handle(self, at):
        o = np.eye(4)
        if at is not None:
            a = np.asarray(at, dtype=float)
            if a.shape == (3,):
                o[:3, 3] = a
            elif a.shape == (4, 4):
                o = a.copy()
            else:
                raise ParameterError(f"{self.name}: a frame of a rigid link is None, a (3,) point or a (4, 4) pose "
                                     "in body coordinates [m]")
        return o, f"at=({o[0, 3]:g}, {o[1, 3]:g}, {o[2, 3]:g}) m"

    def _rotation(self, phi):
        from .lie import expSO3
        return expSO3(np.ascontiguousarray(phi)) @ self.pose0[:3, :3]

    def kinematics(self, q):
        from .lie import JlSO3
        q = np.asarray(q, dtype=float)
        turn = float(np.linalg.norm(q[:3]))
        if turn > 1.9 * np.pi:
            raise _bm.StateRangeError(f"{self.name}: it has turned {turn:.3g} rad from pose0, near the singularity "
                                      "of its rotation-vector coordinates at 2 pi; a RigidLink serves bodies that "
                                      "turn less than a full turn (a platform, a link): for a spinning body use "
                                      "soroshapes.rigid")
        R = self._rotation(q[:3])
        self._G = np.eye(4)
        self._G[:3, :3], self._G[:3, 3] = R, self.pose0[:3, 3] + q[3:]
        self._J = np.zeros((6, 6))
        self._J[:3, :3] = R.T @ JlSO3(np.ascontiguousarray(q[:3]))
        self._J[3:, 3:] = R.T

    def frame(self, handle, data=None):
        from .lie import Ad_inv
        return self._G @ handle, Ad_inv(handle) @ self._J

    def inputs(self, u, t):
        return np.zeros(0)

    def _rot_block(self, phi):
        from .lie import JlSO3
        Jl = JlSO3(np.ascontiguousarray(phi))
        R = self._rotation(phi)
        return Jl.T @ R @ self.inertia @ R.T @ Jl

    def mass_matrix(self, q):
        self.kinematics(q)
        M = np.zeros((6, 6))
        M[:3, :3] = self._rot_block(np.asarray(q[:3], dtype=float))
        M[3:, 3:] = self.mass * np.eye(3)
        return M

    def static_residual(self, q, t, u, scale):
        self.kinematics(q)
        return np.concatenate([np.zeros(3), -scale * self.mass * self.gravity])

    def motion_terms(self, q, qd, t, u):
        from .numerics import fd_columns
        M = self.mass_matrix(q)
        phi, w = np.asarray(q[:3], dtype=float), np.asarray(qd[:3], dtype=float)
        A0 = M[:3, :3]
        dA = fd_columns(lambda x: self._rot_block(x).ravel(), phi, A0.ravel(), np.ones(3))     # (9, 3)
        Adot = (dA @ w).reshape(3, 3)
        dT = np.array([0.5 * w @ dA[:, k].reshape(3, 3) @ w for k in range(3)])
        lhs = np.concatenate([Adot @ w - dT, -self.mass * self.gravity])
        return M, lhs

    def iteration_matrix(self, q, qd, h):
        return 2.0 * self.mass_matrix(q) / h

    def energy(self, q, qd):
        M = self.mass_matrix(q)
        qd = np.asarray(qd, dtype=float)
        return 0.5 * qd @ M @ qd, -self.mass * float(self.gravity @ self._G[:3, 3])

    def end(self, q):
        self.kinematics(q)
        return self._G[:3, 3].copy()


class _BeamFrames(BeamBody):
    """A single beam's frames read from a workspace passed per call (:class:`ConstraintSet` on one beam)."""


# ------------------------------------------------------------------------------------------------------------
# bound constraints
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Bound:
    a: int              # body of the held frame
    ha: object          # its handle
    b: int              # body of the other frame, -1: the world
    hb: object
    sel: tuple          # held components among (x, y, z, rx, ry, rz)
    p0: np.ndarray      # world: position at q0; joint: the offset p_a - p_b at q0
    dp: np.ndarray      # world: position increment at load factor 1 [m]
    R0: np.ndarray      # world: orientation at q0
    phi: np.ndarray     # world: rotation vector at load factor 1 [rad]; joint: log(R_a R_b^T) at q0
    label: str


class ConstraintSet:
    """Constraints bound to one beam (``model`` a :class:`~soroshapes.beam.BeamModel`, ``data`` the workspace
    whose kinematics the methods read) or to an :class:`Assembly` (``data`` None: each body reads its own
    workspace), with the frames held at the initial guess ``q0`` (stacked for an assembly).

    Built by :meth:`soroshapes.shapes.Shapes.statics` and :class:`Assembly`; the solvers call :meth:`residual`
    and :meth:`jacobian` after the kinematics of every body.
    """

    def __init__(self, model, data, constraints, q0):
        from .lie import logSO3
        constraints = list(constraints)
        if not constraints:
            raise ParameterError("constraints is empty; pass None for an unconstrained solve")
        if isinstance(model, Assembly):
            self.bodies, self.offsets, self._data = model.bodies, model.offsets, None
            index = model.index
        else:
            self.bodies, self.offsets, self._data = [_BeamFrames(model, data=data)], [0, model.n], data
            index = None
        self.n = self.offsets[-1]
        q0 = np.asarray(q0, dtype=float)
        for k, body in enumerate(self.bodies):
            body.kinematics(q0[self.offsets[k]:self.offsets[k + 1]])
        bound = []
        for k, con in enumerate(constraints):
            if not isinstance(con, Constraint):
                raise ParameterError(f"constraint {k} is a {type(con).__name__}; use soroshapes.constraints."
                                     "Weld, Pin or Align")
            a = self._which(index, con.body, k, "body")
            ha, la = self.bodies[a].handle(con.at)
            Ga = self._frame(a, ha, data)[0]
            Ra, pa = Ga[:3, :3].copy(), Ga[:3, 3].copy()
            label = f"{type(con).__name__}({self._name(a)}{la}"
            if con.to is not None:
                if con.position is not None or con.rotation is not None:
                    raise ParameterError(f"constraint {k} joins two bodies: leave position and rotation at None and "
                                         "give the relative placement as the frame to_at of the other body")
                b = self._which(index, con.to, k, "to")
                hb, lb = self.bodies[b].handle(con.to_at)
                Gb = self._frame(b, hb, data)[0]
                E = np.ascontiguousarray(Ra @ Gb[:3, :3].T)
                bound.append(_Bound(a, ha, b, hb, con.selected(), pa - Gb[:3, 3], np.zeros(3), np.eye(3),
                                    logSO3(E), label + f" to {self._name(b)}{lb})"))
                continue
            dp = np.zeros(3)
            if con.position is not None:
                p = np.asarray(con.position, dtype=float)
                if p.shape != (3,) or not np.all(np.isfinite(p)):
                    raise ParameterError(f"constraint {k}: position must be a finite (3,) world point [m]")
                dp = p - pa
            phi = np.zeros(3)
            if con.rotation is not None:
                r = np.asarray(con.rotation, dtype=float)
                if r.shape == (3, 3):
                    if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
                        raise ParameterError(f"constraint {k}: rotation must be orthonormal with det +1")
                    phi = logSO3(np.ascontiguousarray(r @ Ra.T))
                elif r.shape == (3,) and np.all(np.isfinite(r)):
                    phi = r.copy()
                else:
                    raise ParameterError(f"constraint {k}: rotation must be a (3, 3) rotation or a (3,) rotation "
                                         "vector [rad]")
            bound.append(_Bound(a, ha, -1, None, con.selected(), pa, dp, Ra, phi, label + ")"))
        self.bound = tuple(bound)
        self.m = sum(len(b.sel) for b in bound)

    def _which(self, index, body, k, what):
        if index is None:
            if body is not None:
                raise ParameterError(f"constraint {k}: {what}= names a body, but a single beam's statics and "
                                     "simulate have one body; join bodies in a soroshapes.constraints.Assembly")
            return 0
        if body is None:
            if len(self.bodies) == 1 and what == "body":
                return 0
            raise ParameterError(f"constraint {k}: say which body holds the frame (Weld(body=..., ...)); the "
                                 f"assembly has {len(self.bodies)}")
        return index(body)

    def _name(self, k):
        return "" if len(self.bodies) == 1 else f"{self.bodies[k].name} "

    def _frame(self, k, handle, data):
        return self.bodies[k].frame(handle, data if self._data is not None else None)

    @property
    def max_load_step(self):
        """Largest load-factor increment that turns every orientation target by at most pi/4 (1 if none turns):
        the rotation drift is a logarithm, defined modulo a full turn."""
        turn = max([float(np.linalg.norm(b.phi)) for b in self.bound if any(i >= 3 for i in b.sel)] + [0.0])
        return 1.0 if turn <= np.pi / 4 else np.pi / 4 / turn

    def targets(self, scale):
        """[(p*, R*)] of the world constraints at load factor ``scale`` (None for joints between bodies)."""
        from .lie import expSO3
        return [(b.p0 + scale * b.dp, expSO3(scale * b.phi) @ b.R0) if b.b < 0 else None for b in self.bound]

    def _full(self, data, scale):
        """[(c6, E)] per constraint: the drift of all six components (x, y, z [m], rx, ry, rz [rad]) at load
        factor ``scale`` and the relative rotation R_a R_b^T."""
        from .lie import expSO3, logSO3
        out = []
        for b, tgt in zip(self.bound, self.targets(scale)):
            Ga = self._frame(b.a, b.ha, data)[0]
            c6 = np.empty(6)
            if b.b < 0:
                p, R = tgt
                c6[:3] = Ga[:3, 3] - p
                E = Ga[:3, :3] @ R.T
                c6[3:] = logSO3(np.ascontiguousarray(E))
            else:
                Gb = self._frame(b.b, b.hb, data)[0]
                c6[:3] = Ga[:3, 3] - Gb[:3, 3] - (1.0 - scale) * b.p0
                E = Ga[:3, :3] @ Gb[:3, :3].T
                c6[3:] = logSO3(np.ascontiguousarray(E @ expSO3(-(1.0 - scale) * b.phi)))
            out.append(c6)
        return out

    def residual(self, data, scale):
        """The drift c (m,) [m, rad] at the kinematics held (in ``data`` for one beam; None for an assembly)
        and the targets at load factor ``scale``."""
        return np.concatenate([c6[list(b.sel)] for b, c6 in zip(self.bound, self._full(data, scale))])

    def residual_and_jacobian(self, data, scale):
        """(:meth:`residual`, :meth:`jacobian`) at load factor ``scale`` from one evaluation of the drift."""
        full = self._full(data, scale)
        c = np.concatenate([c6[list(b.sel)] for b, c6 in zip(self.bound, full)])
        return c, self._rows(data, full)

    def jacobian(self, data, scale=None):
        r"""The exact :math:`\partial c/\partial q` (m, n) at the kinematics held: position rows
        :math:`R_a J_v` (minus :math:`R_b J_v` of the other body), rotation rows :math:`J_l^{-1}(c_R) R_a
        J_\omega` (minus :math:`J_l^{-1}(c_R) R_a J_\omega` of the other body's frame) with the full rotation
        drift :math:`c_R` at load factor ``scale`` (None: at :math:`c_R = 0`, the Jacobian on the constraint
        manifold)."""
        return self._rows(data, self._full(data, scale) if scale is not None else [np.zeros(6)] * len(self.bound))

    def _rows(self, data, full):
        from .lie import JlSO3_inv
        rows = []
        off = self.offsets
        for b, c6 in zip(self.bound, full):
            Ga, Ja = self._frame(b.a, b.ha, data)
            Ra = Ga[:3, :3]
            Jinv = JlSO3_inv(np.ascontiguousarray(c6[3:]))
            J6 = np.zeros((6, self.n))
            sa = slice(off[b.a], off[b.a + 1])
            J6[:3, sa] += Ra @ Ja[3:6]
            J6[3:, sa] += Jinv @ (Ra @ Ja[0:3])
            if b.b >= 0:
                Gb, Jb = self._frame(b.b, b.hb, data)
                sb = slice(off[b.b], off[b.b + 1])
                J6[:3, sb] -= Gb[:3, :3] @ Jb[3:6]
                J6[3:, sb] -= Jinv @ (Ra @ Jb[0:3])
            rows.append(J6[list(b.sel)])
        return np.vstack(rows)

    def _names(self):
        what = ("position x", "position y", "position z", "rotation about x", "rotation about y", "rotation about z")
        return [f"{b.label} {what[i]}" for b in self.bound for i in b.sel]

    def check(self, data):
        """Raise a :class:`ParameterError` if the constraints cannot be enforced from the kinematics held (the
        initial guess): a row the bodies cannot move (a zero row of :math:`J_c`) or rows that repeat each
        other (rank-deficient :math:`J_c`), naming the constraint and the fix."""
        Jc = self.jacobian(data)
        scale = max(np.abs(Jc).max(), 1e-300)
        names = self._names()
        dead = [names[i] for i in range(self.m) if np.abs(Jc[i]).max() <= 1e-10 * scale]
        if dead:
            raise ParameterError(
                "the beam's basis cannot move " + ", ".join(dead) + " at the initial guess (that row of the "
                "constraint Jacobian is zero, so its multiplier is undefined): hold only the components it moves "
                "(axes=..., e.g. axes=('x', 'y', 'rz') for a rod bending in the x-y plane), enable the strain "
                "that moves it (the stretch dof for an axial position, torsion for a twist), or start from a q0 "
                "where it moves")
        sv = np.linalg.svd(Jc / scale, compute_uv=False)
        if self.m > self.n or sv[-1] <= 1e-9 * sv[0]:
            raise ParameterError(
                f"the {self.m} constraint equations are dependent at the initial guess (rank "
                f"{int(np.sum(sv > 1e-9 * sv[0]))}, {self.n} coordinates): the bordered system "
                "[K_t J_c^T; J_c 0] is singular; remove the repeated constraints or add modes to the basis")

    def reactions(self, lam):
        """Reaction wrenches (k, 6) [N m, N] (moment first, as :mod:`soroshapes.lie`), world frame, on the body
        holding each constrained frame, at that frame's origin, from the multipliers ``lam`` (m,); components
        not held are 0."""
        out = np.zeros((len(self.bound), 6))
        i = 0
        for k, b in enumerate(self.bound):
            for j in b.sel:
                out[k, j + 3 if j < 3 else j - 3] = lam[i]
                i += 1
        return out

    def drift(self, c):
        """(largest position drift [m], largest orientation drift [rad]) of a residual ``c``."""
        dp, dr, i = 0.0, 0.0, 0
        for b in self.bound:
            k = len(b.sel)
            cb, sel = c[i:i + k], np.array(b.sel)
            dp = max(dp, float(np.linalg.norm(cb[sel < 3])))
            dr = max(dr, float(np.linalg.norm(cb[sel >= 3])))
            i += k
        return dp, dr

    def equilibrium(self, q, lam, iterations, Kt, c, data=None):
        """The :class:`Equilibrium` at the solution (q, multipliers ``lam``) of a constrained statics with the
        bordered tangent ``Kt`` and drift ``c``; reads the kinematics held at q."""
        from scipy.linalg import null_space
        Z = null_space(self.jacobian(data, scale=1.0))
        H = 0.5 * (Kt[:self.n, :self.n] + Kt[:self.n, :self.n].T)
        dp, dr = self.drift(c)
        return Equilibrium(q=q, multipliers=lam, reactions=self.reactions(lam), drift_position=dp,
                           drift_rotation=dr, iterations=iterations, stiffness=Z.T @ H @ Z, null_basis=Z)


@dataclass(frozen=True)
class Equilibrium:
    r"""A constrained static equilibrium (:meth:`soroshapes.shapes.Shapes.statics` with ``constraints``).

    Attributes
    ----------
    q : (n,) coordinates.
    multipliers : (m,) Lagrange multipliers [N, N m] in the order of the constraints' held components
        (x, y, z, rx, ry, rz within each).
    reactions : (k, 6) reaction wrench of each constraint on the rod, world frame, at the constrained point:
        moment [N m] then force [N].
    drift_position : float [m], largest :math:`|c_p|` at the solution.
    drift_rotation : float [rad], largest :math:`|c_R|`.
    iterations : list of Newton iterations per accepted load increment.
    stiffness : (n - m, n - m) the tangent stiffness on the constraint manifold, :math:`Z^T H Z` with
        :math:`H = \partial(Kq - f - J_c^T\lambda)/\partial q` (symmetrized; the Hessian of the Lagrangian for
        conservative loads) and :math:`Z` an orthonormal basis of the null space of :math:`J_c`. The
        equilibrium is stable where its lowest eigenvalue (:attr:`lowest_eigenvalue`) is positive; a sign
        change along a path is a bifurcation or limit point (Sylvester's law of inertia: the sign does not
        depend on the choice of Z or on the units of q).
    null_basis : (n, n - m) the orthonormal Z.
    """

    q: np.ndarray
    multipliers: np.ndarray
    reactions: np.ndarray
    drift_position: float
    drift_rotation: float
    iterations: list
    stiffness: np.ndarray
    null_basis: np.ndarray

    @property
    def lowest_eigenvalue(self):
        """Lowest eigenvalue of :attr:`stiffness` [N m per coordinate^2]."""
        return float(np.linalg.eigvalsh(self.stiffness)[0])

    @property
    def lowest_mode(self):
        r"""The coordinate direction (n,) (unit norm) of the lowest eigenvalue, :math:`Z v_{min}`: tangent to the
        constraint manifold; at a bifurcation the buckling mode, a direction to leave the branch along (start a
        constrained solve from ``q + a * lowest_mode``)."""
        w, v = np.linalg.eigh(self.stiffness)
        mode = self.null_basis @ v[:, 0]
        return mode / np.linalg.norm(mode)


# ------------------------------------------------------------------------------------------------------------
# assemblies of bodies
# ------------------------------------------------------------------------------------------------------------
class Assembly:
    r"""Bodies joined by constraints: beams (:class:`~soroshapes.shapes.Shapes`, each on its own base, or
    :class:`BeamBody`), :class:`RigidLink` bodies, or any object with the body interface of the module
    docstring. The coordinates are stacked in the order of ``bodies`` (:attr:`offsets`; :meth:`split`), the
    mass matrix is block diagonal, and the constraints passed to :meth:`statics` and :meth:`simulate` couple the
    bodies (``Weld(body=rod, to=platform, to_at=(0, 0.01, 0))``).

    Inputs ``u``: None or a list with one entry per body (None, an array of its inputs in the order they were
    added, or a callable of t [s] giving them).

    Examples
    --------
    A rod whose tip carries a rigid block: the cantilever with an end mass.

    >>> import numpy as np
    >>> from sorofem import sdf, materials
    >>> from soroshapes import Basis, Shapes
    >>> from soroshapes.constraints import Assembly, RigidLink, Weld
    >>> rod = Shapes(Basis.chebyshev(4), dofs=(0, 0, 4, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
    ...              material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), damping=0.0).add_gravity()
    >>> block = RigidLink(0.001, 1e-9, pose0=np.array([[1., 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    >>> asm = Assembly([rod, block])
    >>> eq = asm.statics(constraints=[Weld(body=rod, to=block)])
    >>> bool(eq.drift_position < 1e-8)
    True
    """

    def __init__(self, bodies):
        self.bodies, self._ids = [], {}
        for k, b in enumerate(bodies):
            self._ids[id(b)] = k
            if hasattr(b, "model") and hasattr(b, "loads") and hasattr(b, "damping"):        # a Shapes
                b = BeamBody.of(b, name=f"body {k}")
            self.bodies.append(b)
        if not self.bodies:
            raise ParameterError("an Assembly needs at least one body")
        self.offsets = [0]
        for b in self.bodies:
            self.offsets.append(self.offsets[-1] + int(b.n))
        #: number of stacked coordinates
        self.n = self.offsets[-1]
        lengths = [b.length for b in self.bodies if b.length is not None]
        #: length scale [m] of the tolerances (the longest beam; 1 m without beams)
        self.length = max(lengths) if lengths else 1.0

    def index(self, body):
        """Position of ``body`` (the object passed to the constructor, or its wrapped body) in :attr:`bodies`."""
        k = self._ids.get(id(body))
        if k is None:
            for j, b in enumerate(self.bodies):
                if b is body:
                    return j
            raise ParameterError(f"{type(body).__name__} is not a body of this assembly; pass one of the objects "
                                 "given to Assembly([...])")
        return k

    def split(self, q):
        """The per-body views of a stacked (n,) array (or (..., n) rows)."""
        q = np.asarray(q)
        return [q[..., self.offsets[k]:self.offsets[k + 1]] for k in range(len(self.bodies))]

    def _state(self, q, what):
        q = np.zeros(self.n) if q is None else np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.n,):
            raise ParameterError(f"{what} must have {self.n} entries (the bodies' coordinates stacked: "
                                 f"{[b.n for b in self.bodies]}), got {q.shape}")
        if not np.all(np.isfinite(q)):
            from sorofem.errors import DataError
            raise DataError(f"{what} contains NaN or inf")
        return q.copy()

    def _inputs(self, u, t):
        if u is None:
            u = [None] * len(self.bodies)
        if len(u) != len(self.bodies):
            raise ParameterError(f"u must have one entry per body ({len(self.bodies)}), got {len(u)}")
        return [b.inputs(ub, t) for b, ub in zip(self.bodies, u)]

    def kinematics(self, q):
        for b, qb in zip(self.bodies, self.split(q)):
            b.kinematics(qb)

    def mass_matrix(self, q):
        """The block-diagonal mass matrix (n, n) at ``q`` (leaves the kinematics at q)."""
        M = np.zeros((self.n, self.n))
        for k, (b, qb) in enumerate(zip(self.bodies, self.split(q))):
            s = slice(self.offsets[k], self.offsets[k + 1])
            M[s, s] = b.mass_matrix(qb)
        return M

    def energy(self, q, qd):
        """(kinetic, potential) [J] summed over the bodies."""
        e = [b.energy(qb, vb) for b, qb, vb in zip(self.bodies, self.split(q), self.split(qd))]
        return sum(x[0] for x in e), sum(x[1] for x in e)

    def bind(self, constraints, q0=None):
        """The :class:`ConstraintSet` of ``constraints`` at ``q0`` (stacked; default zeros), checked."""
        cs = ConstraintSet(self, None, constraints, self._state(q0, "q0"))
        cs.check(None)
        return cs

    def statics(self, u=None, q0=None, *, constraints, steps=1, tol=1e-9, max_iterations=40, min_step=1e-4,
                t=0.0):
        r"""Static equilibrium of the bodies under their loads and the ``constraints`` (targets and joints
        ramped from where they are at ``q0`` with the load factor): :math:`Kq - f - J_c^T\lambda = 0`,
        :math:`c = 0` by :func:`soroshapes.beam.newton_load_stepping`. Returns an :class:`Equilibrium` (q
        stacked; reactions on the body holding each frame; drift; stiffness on the constraint manifold)."""
        q0 = self._state(q0, "q0")
        cs = self.bind(constraints, q0)
        uv = self._inputs(u, t)
        n, m = self.n, cs.m
        from .beam import StateRangeError, newton_load_stepping

        def aug(x, scale):
            try:
                r = np.concatenate([b.static_residual(qb, t, ub, scale)
                                    for b, qb, ub in zip(self.bodies, self.split(x[:n]), uv)])
            except StateRangeError:
                return np.full(n + m, np.nan)
            c, Jc = cs.residual_and_jacobian(None, scale)
            return np.concatenate([r - Jc.T @ x[n:], c])

        def stiffness_force(q):
            return np.concatenate([b.stiffness @ qb for b, qb in zip(self.bodies, self.split(q))])
        kmax = max(float(np.abs(np.diag(b.stiffness)).max()) for b in self.bodies)
        x, its, Kt = newton_load_stepping(aug, np.concatenate([q0, np.zeros(m)]), n, stiffness_force, kmax,
                                          self.length, cap=cs.max_load_step, steps=steps, tol=tol,
                                          max_iterations=max_iterations, min_step=min_step, tangent=True)
        c = aug(x, 1.0)[n:]                               # leaves the kinematics at the solution
        return cs.equilibrium(x[:n].copy(), x[n:].copy(), its, Kt, c)

    def simulate(self, t_end, dt, q0=None, qd0=None, u=None, *, constraints, tol=1e-8, max_iterations=20,
                 min_dt=None, record_every=1, drift_tol=None):
        r"""Time integration with the constraints enforced in the implicit midpoint step (index 3, velocity
        projection; see the module docstring) from (``q0``, ``qd0``) (stacked; ``qd0`` is projected on the
        velocity constraint first). ``q0`` must satisfy the constraints (drift below 1e-6 of :attr:`length`
        and 1e-6 rad: reach it with :meth:`statics`); a step converges when the velocity correction is below
        ``tol`` relative and the drift below ``drift_tol`` [m] (default ``tol`` times :attr:`length`) and ``tol``
        [rad]. A step that fails is halved down to ``min_dt`` (default dt/1024), then a
        :class:`~sorofem.errors.ConvergenceError` names the time.

        Returns a :class:`soroshapes.trajectory.Trajectory` with q, qd stacked, ``tip`` the end point of the last
        body (a beam's tip, a link's centre of mass), the energies summed over the bodies, and per record
        ``drift_position`` [m], ``drift_rotation`` [rad] and ``reactions`` (records, constraints, 6) [N m, N] (the
        multipliers of the step that ended there; at t = 0 those of the first step)."""
        import time
        from sorofem.errors import ConvergenceError
        from .beam import StateRangeError, time_grid
        from .trajectory import Trajectory, run_stats
        t_end, dt, nsteps, min_dt, record_every = time_grid(t_end, dt, min_dt, record_every)
        q, qd = self._state(q0, "q0"), self._state(qd0, "qd0")
        self._inputs(u, 0.0)
        cs = self.bind(constraints, q)
        c0 = cs.residual(None, 1.0)
        dp, dr = cs.drift(c0)
        if dp > 1e-6 * self.length or dr > 1e-6:
            raise ParameterError(f"simulate: q0 does not satisfy the constraints (drift {dp:.3g} m, {dr:.3g} rad): "
                                 "start from a constrained equilibrium (statics(constraints=...).q) or another "
                                 "consistent state")
        ctol = tol * self.length if drift_tol is None else float(drift_tol)
        qd = self._project(cs, q, qd)
        wall0 = time.perf_counter()
        rec = {"t": [], "q": [], "qd": [], "kin": [], "pot": [], "tip": [], "dp": [], "dr": [], "W": []}
        lam = np.zeros(cs.m)

        def record(t, c, lam):
            kin, pot = self.energy(q, qd)
            rec["t"].append(t)
            rec["q"].append(q.copy())
            rec["qd"].append(qd.copy())
            rec["kin"].append(kin)
            rec["pot"].append(pot)
            rec["tip"].append(self.bodies[-1].end(self.split(q)[-1]))
            d = cs.drift(c)
            rec["dp"].append(d[0])
            rec["dr"].append(d[1])
            rec["W"].append(cs.reactions(lam))
        record(0.0, c0, lam)
        its_all = []
        t, last, cuts = 0.0, "", 0
        for k in range(nsteps):
            h, t_next = dt, (k + 1) * dt
            cut = False
            while t < t_next - 1e-12 * dt:
                hh = min(h, t_next - t)
                try:
                    step = self._step(cs, q, qd, lam, t, hh, u, tol, ctol, max_iterations)
                except StateRangeError as e:
                    step, last = None, f" (the last trial: {e})"
                if step is None:
                    cut = True
                    h *= 0.5
                    if h < min_dt:
                        raise ConvergenceError(f"simulate: the constrained step at t = {t:.6g} s did not converge "
                                               f"down to dt = {min_dt:.3g} s; use a smaller dt, check that the "
                                               "constraints are compatible with the loads, or add damping" + last)
                    continue
                q, qd, lam, c, its = step
                if not its_all:
                    rec["W"][0] = cs.reactions(lam)          # the start's row: the first step's reactions
                its_all.append(its)
                t += hh
            cuts += cut
            t = t_next
            if (k + 1) % record_every == 0 or k + 1 == nsteps:
                record(t, c, lam)
        return Trajectory(rec["t"], q=np.array(rec["q"]), qd=np.array(rec["qd"]), kinetic=np.array(rec["kin"]),
                          potential=np.array(rec["pot"]), tip=np.array(rec["tip"]),
                          stats=run_stats(steps=nsteps, newton_iterations=int(np.sum(its_all)),
                                          matrices=len(its_all), jacobians=0, cut_steps=cuts, rejected=0, dt=dt,
                                          method="implicit", path="python", adaptive=False,
                                          wall_time=time.perf_counter() - wall0,
                                          newton_iterations_by_step=np.array(its_all, dtype=int),
                                          compiled_steps=0, constraints=cs._names()),
                          drift_position=np.array(rec["dp"]), drift_rotation=np.array(rec["dr"]),
                          reactions=np.array(rec["W"]))

    def _project(self, cs, q, qd):
        r"""``qd`` projected on :math:`J_c(q)\dot q = 0` in the metric of M(q): the smallest kinetic-energy
        change that makes it consistent."""
        M = self.mass_matrix(q)
        Jc = cs.jacobian(None, scale=1.0)
        m = cs.m
        A = np.block([[M, Jc.T], [Jc, np.zeros((m, m))]])
        rhs = np.concatenate([np.zeros(self.n), -Jc @ qd])
        return qd + np.linalg.solve(A, rhs)[:self.n]

    def _step(self, cs, q, qd, lam0, t, h, u, tol, ctol, max_iterations):
        """One constrained implicit-midpoint step (module docstring); (q1, qd1, multipliers, drift c, its) or
        None when Newton does not converge."""
        from .numerics import fd_columns
        n, m = self.n, cs.m
        tm = t + 0.5 * h
        uv = self._inputs(u, tm)

        ref = [0.0]

        def evaluate(x):
            vm, lam = x[:n], x[n:]
            self.kinematics(q + h * vm)
            c, Jc1 = cs.residual_and_jacobian(None, 1.0)
            qm = q + 0.5 * h * vm
            R = np.empty(n)
            size = 0.0
            for k, (b, qb, vb, ub) in enumerate(zip(self.bodies, self.split(qm), self.split(vm), uv)):
                s = slice(self.offsets[k], self.offsets[k + 1])
                M, lhs = b.motion_terms(qb, vb, tm, ub)
                R[s] = M @ (2.0 * (vb - qd[s]) / h) + lhs
                size += np.linalg.norm(b.stiffness @ qb) + np.linalg.norm(M @ vb) / h + np.linalg.norm(lhs)
            Jm = cs.jacobian(None, None)
            R -= Jm.T @ lam
            ref[0] = size + np.linalg.norm(Jm.T @ lam)
            return np.concatenate([R, c / h]), c, Jc1, Jm
        x = np.concatenate([qd, lam0])
        F, c, Jc1, Jm = evaluate(x)
        S = np.zeros((n, n))
        qm = q + 0.5 * h * qd
        for k, (b, qb, vb) in enumerate(zip(self.bodies, self.split(qm), self.split(qd))):
            s = slice(self.offsets[k], self.offsets[k + 1])
            S[s, s] = b.iteration_matrix(qb, vb, h)
        A = np.block([[S, -Jm.T], [Jc1, np.zeros((m, m))]])
        prev, differenced = np.inf, False
        for it in range(1, max_iterations + 1):
            if not np.all(np.isfinite(F)):
                return None
            nf = np.linalg.norm(F)
            if it > 3 and nf > 0.25 * prev:       # slow: the complete differenced Jacobian, from here on
                A = fd_columns(lambda y: evaluate(y)[0], x, F, np.ones(n + m))
                differenced = True
            prev = nf
            try:
                dx = np.linalg.solve(A, -F)
            except np.linalg.LinAlgError:
                return None
            x = x + dx
            F, c, Jc1, Jm = evaluate(x)
            if not differenced:                   # the border at the new iterate; S kept through the step
                A[n:, :n], A[:n, n:] = Jc1, -Jm.T
            vm = x[:n]
            dp, dr = cs.drift(c)
            if (np.all(np.isfinite(F)) and dp <= ctol and dr <= tol
                    and (np.linalg.norm(dx[:n]) <= tol * np.linalg.norm(vm) + 1e-12
                         or np.linalg.norm(F[:n]) <= 1e-3 * tol * ref[0])):
                q1 = q + h * vm
                qd1 = self._project(cs, q1, 2.0 * vm - qd)
                return q1, qd1, x[n:].copy(), c, it
        return None
