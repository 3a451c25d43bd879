r"""Rigid bodies for a :class:`~soroshapes.model.Model`: free 6-DOF bodies, bodies spinning about a fixed axis, and
penalty contact between a Cosserat beam and a body's surface.

Free body (Newton-Euler on SE(3), body coordinates)
---------------------------------------------------
The body frame has its origin at the **centre of mass**; its pose :math:`g = (R, p) \in SE(3)` maps body to
spatial coordinates (:mod:`soroshapes.lie`), its body twist is :math:`\eta = (\omega, v)` (angular first,
rad/s and m/s, both in body axes). With :math:`\mathcal M = \mathrm{diag}(I_b, m I_3)` (``inertia`` [kg m^2]
about the centre of mass, ``mass`` [kg]),

.. math::

    \dot p = R v, \qquad \dot R = R\hat\omega + \tfrac\kappa2 R (I_3 - R^T R), \qquad
    \mathcal M \dot\eta = \mathrm{ad}_\eta^T \mathcal M \eta + W_g + W_d + W_{ext},

with :math:`\mathrm{ad}_\eta` of :func:`soroshapes.lie.ad6`, so that
:math:`\mathrm{ad}_\eta^T\mathcal M\eta = (-\omega\times I_b\omega - v\times m v,\ -\omega\times m v)` (Euler's
equations and the transport term of the linear momentum); the gravity wrench
:math:`W_g = (0, m R^T a_g)` (``gravity`` :math:`a_g` [m/s^2], spatial), the damping wrench
:math:`W_d = -(c_\omega\,\omega, c_v v)` (``damping = (c_v [N s/m], c_omega [N m s/rad])``) and the external
wrench :math:`W_{ext} = (m, f)` [N m, N] in body coordinates (the input, 6 entries).

State (18 entries, what a :class:`Model` integrates): :math:`x = (p, R, \omega, v)` with the rotation matrix
stored row by row (9 entries). The matrix has no singularity (Euler angles do), and the equations stay
polynomial (quadratic) in the state, so the ``"midpoint"`` integrator of :class:`Model` (which conserves every
quadratic invariant) keeps :math:`R^TR = I`, the kinetic energy and the spatial angular momentum
:math:`R I_b\omega` of a free spinning body exactly (to the Newton tolerance); the trapezoidal rule (conjugate to
the midpoint rule) keeps them to a bounded :math:`O(h^2)` error without drift. BDF2 damps the rotation slowly:
give it ``normalization`` :math:`\kappa > 0` [1/s], whose term is zero on :math:`SO(3)` and pulls :math:`R` back
(leave it 0 with the midpoint rule: evaluated at the midpoint of two rotations it biases the norm). The pose
(:meth:`RigidBody.pose`) is the re-orthonormalized (polar) factor of the stored matrix. (A unit quaternion
needs 4 entries instead of 9 but makes the angular momentum a cubic function of the state, which no
Runge-Kutta rule conserves.)

Body spinning about a fixed axis
--------------------------------
:class:`SpinningBody` (``RigidBody.spinning``): a body (a bolt, a valve wheel) that can only turn about a unit
``axis`` through its body origin, fixed in space: state :math:`(\theta, \dot\theta)` [rad, rad/s],

.. math:: I_a \ddot\theta = -c\,\dot\theta + a\cdot m_{ext},

pose :math:`g(\theta) = g_0\,(\exp(\theta\hat a), 0)`, twist :math:`(a\dot\theta, 0)`. The input is the same body
wrench :math:`(m, f)` as a free body's (the bearing takes everything but the axial moment).

Beam-body contact
-----------------
:func:`beam_contact` treats the beam as the tube of radius :math:`r` (``Shapes.contact_radius``) around its
backbone nodes, as ``Shapes.add_contact`` does for a fixed obstacle, with the body's ``shape`` (a 3D SDF of
:mod:`sorofem.sdf` in body coordinates) as the obstacle: node :math:`i` at :math:`P_i` [m] (spatial) has body
coordinates :math:`P^b_i = R^T(P_i - p)`, distance :math:`d_i = \phi(P^b_i)` and normal :math:`n_i = R\,
\nabla\phi/|\nabla\phi|`. The relative velocity of the node with respect to the body material point at the same
place is :math:`v^{rel}_i = R_i \eta_{i,v} - R(v + \omega\times P^b_i)`; with :math:`\delta_i = r - d_i` and
:math:`v_n = n_i\cdot v^{rel}_i`, the force on the beam at node :math:`i` is

.. math:: F_i = w_i\left(f_n n_i - \mu f_n \frac{v_t}{\sqrt{|v_t|^2 + \epsilon^2}}\right), \qquad
          f_n = \max(0, k\delta_i - c v_n),\quad v_t = v^{rel}_i - v_n n_i,

(``stiffness`` :math:`k` [N/m^2] and ``damping`` :math:`c` [N s/m^2] per unit length, ``friction`` :math:`\mu`,
``regularization`` :math:`\epsilon` [m/s], :math:`w_i` [m] the node's share of the rod length). The beam gets
the generalized force :math:`\sum_i J_{i,v}^T R_i^T F_i`; the body gets :math:`-F_i` at the same points, i.e.
the body wrench :math:`W = \sum_i (P^b_i \times f^b_i, f^b_i)`, :math:`f^b_i = -R^T F_i`, so the forces and the
moments about any point cancel (Newton's third law) and the contact power is
:math:`\sum_i F_i\cdot v^{rel}_i` (zero for a frictionless, undamped contact, which is then conservative with
the energy :math:`\sum_i w_i k\delta_i^2/2`). :func:`couple_contact` wires both into a :class:`Model`.

Tree-body contact
-----------------
:func:`tree_contact` does the same for points carried by the bodies of a :class:`~soroshapes.tree.Tree`
(pads on a gripper's fingers: a beam node or a link frame, a constant offset in that frame, a pad radius),
with the tree Jacobians of :func:`soroshapes.tree.kinematics`; the stiffness and damping are per point.
:class:`TreeContact` + :func:`couple_tree_contact` wire it into a :class:`Model`: the tree's block (made with
``Tree.system(..., force_inputs=True)``) gets the generalized force in its force inputs and the body the
opposite wrench, both as couplings of the network, so the network's Jacobian sees each side's dependence on
the other's state (through a tree's ``f_ext`` that reads the body it would not, and Newton stalls at contact).

Ground and grasp
----------------
:func:`ground_contact` / :func:`couple_ground`: a fixed plane (table, floor) pushing on chosen body points
(penalty, damping, regularized Coulomb friction). :func:`grasp_force` / :func:`couple_grasp`: a gripper as a
spring-damper between a beam node and a body point, scaled by an engagement signal in [0, 1] (it closes and
opens), equal and opposite on beam and body. Several contacts and couplings on one body add up.

Example
-------
Free fall: the trapezoidal rule is exact for a constant acceleration, so :math:`z = -g t^2/2`:

>>> import numpy as np
>>> from soroshapes import Model
>>> from soroshapes.rigid import RigidBody
>>> ball = RigidBody(0.1, 4e-6, name="ball")
>>> traj = Model().add(ball).simulate(0.5, 0.01)
>>> round(float(ball.pose(traj["ball"].x[-1])[2, 3]), 6)      # -9.81 * 0.5**2 / 2 [m]
-1.22625
"""
from __future__ import annotations

import numpy as np

from sorofem.errors import ParameterError

from .model import Model, StateSpace

__all__ = ["RigidBody", "SpinningBody", "beam_contact", "couple_contact", "ground_contact", "couple_ground",
           "grasp_force", "couple_grasp", "WrenchSum", "tree_contact", "TreeContact", "couple_tree_contact"]

_WRENCH = ["moment_x", "moment_y", "moment_z", "force_x", "force_y", "force_z"]


# ------------------------------------------------------------------------------------------------------------
# small helpers
# ------------------------------------------------------------------------------------------------------------
def _finite(v, shape, what):
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{what} must be numeric with shape {shape}, got {v!r}") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ParameterError(f"{what} must be finite with shape {shape}, got shape {a.shape}")
    return a.copy()


def _pose(g, what="pose0"):
    g = _finite(g, (4, 4), what)
    R = g[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0 or \
            not np.allclose(g[3], [0, 0, 0, 1]):
        raise ParameterError(f"{what} must be a homogeneous pose [[R, p], [0, 1]] with R orthonormal, det +1 "
                             "(build R with soroshapes.lie.expSO3)")
    return g


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _rotation(axis, angle):
    """Rodrigues: rotation by ``angle`` [rad] about the unit ``axis``."""
    K = _skew(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _polar(R):
    """The rotation nearest to R (polar factor U V^T of its SVD)."""
    U, _, Vt = np.linalg.svd(R)
    Q = U @ Vt
    if np.linalg.det(Q) < 0:
        U[:, -1] *= -1
        Q = U @ Vt
    return Q


def _distance(shape):
    """``P (N, 3) -> d (N,)`` for a body's SDF: its fused numba kernel when the tree has one (contact is
    evaluated on a dozen points many times per step, where numpy's per-call overhead dominates). The normals
    stay analytic (:meth:`sorofem.sdf.SDF.gradient`): finite differences of the distance put a small
    tangential error into frictionless contact forces and round-off noise into the network's FD Jacobians."""
    kernel = shape.compiled()
    if kernel is None:
        return lambda P: np.asarray(shape(P), dtype=float).reshape(-1)
    return lambda P: np.asarray(kernel(np.ascontiguousarray(P, dtype=float)), dtype=float).reshape(-1)


def _shape(shape):
    if shape is not None and getattr(shape, "dim", None) != 3:
        raise ParameterError("shape must be a 3D SDF of sorofem.sdf in body coordinates (e.g. sdf.Cylinder, or "
                             "sdf.Polygon(hexagon).extrude(height) for a bolt head), or None")
    return shape


def _wrench(u):
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.shape != (6,):
        raise ParameterError(f"the external wrench must have 6 entries (m [N m], f [N]) in body coordinates, "
                             f"got {u.size}")
    return u


# ------------------------------------------------------------------------------------------------------------
# free rigid body
# ------------------------------------------------------------------------------------------------------------
class RigidBody(StateSpace):
    r"""A free rigid body: Newton-Euler equations on SE(3) in body coordinates (module docstring).

    A :class:`~soroshapes.model.StateSpace` with 18 states :math:`(p, R, \omega, v)` and 6 inputs (the
    external body wrench :math:`(m, f)` [N m, N]), so ``Model.add`` takes it as it is.

    Parameters
    ----------
    mass : float [kg], > 0
    inertia : float, (3,) or (3, 3) [kg m^2]
        Inertia about the centre of mass in body axes (a number: isotropic; (3,): principal moments);
        symmetric positive definite.
    pose0 : (4, 4), optional
        Initial pose (body -> spatial) [m]; identity by default.
    twist0 : (6,), optional
        Initial body twist :math:`(\omega, v)` [rad/s, m/s].
    gravity : (3,) [m/s^2]
        Spatial gravitational acceleration (``(0, 0, 0)`` for none).
    damping : (2,)
        ``(linear [N s/m], angular [N m s/rad])`` viscous damping on the body twist.
    shape : 3D SDF, optional
        The body's surface in body coordinates, for contact (:func:`beam_contact`).
    name : str, optional
    normalization : float [1/s]
        Gain :math:`\kappa` pulling :math:`R` back to :math:`SO(3)` (default 0; see the module docstring).
    """

    def __init__(self, mass, inertia, pose0=None, twist0=None, gravity=(0.0, 0.0, -9.81), damping=(0.0, 0.0),
                 name=None, *, shape=None, normalization=0.0):
        try:
            mass = float(mass)
        except (TypeError, ValueError):
            raise ParameterError(f"mass must be a positive number of kg, got {mass!r}") from None
        if not (np.isfinite(mass) and mass > 0):
            raise ParameterError(f"mass must be positive and finite [kg], got {mass!r}")
        I = np.asarray(inertia, dtype=float)
        if I.ndim == 0:
            I = float(I) * np.eye(3)
        elif I.shape == (3,):
            I = np.diag(I)
        if I.shape != (3, 3) or not np.all(np.isfinite(I)):
            raise ParameterError(f"inertia must be a number, 3 principal moments or a 3x3 matrix [kg m^2], got "
                                 f"shape {np.shape(inertia)}")
        if not np.allclose(I, I.T, rtol=1e-12, atol=1e-15 * np.abs(I).max()) or np.linalg.eigvalsh(I).min() <= 0:
            raise ParameterError(f"inertia must be symmetric positive definite [kg m^2], got eigenvalues "
                                 f"{np.linalg.eigvals(I)}")
        g0 = _pose(np.eye(4) if pose0 is None else pose0)
        eta0 = np.zeros(6) if twist0 is None else _finite(twist0, (6,), "twist0")
        self.gravity = _finite(gravity, (3,), "gravity")
        dmp = _finite(damping, (2,), "damping (linear [N s/m], angular [N m s/rad])")
        if np.any(dmp < 0):
            raise ParameterError(f"damping (linear, angular) must be >= 0, got {tuple(dmp)}")
        if not (np.isfinite(normalization) and normalization >= 0):
            raise ParameterError(f"normalization must be >= 0 [1/s], got {normalization!r}")
        self.mass, self.inertia = mass, 0.5 * (I + I.T)
        self._Iinv = np.linalg.inv(self.inertia)
        self.damping = (float(dmp[0]), float(dmp[1]))
        self.shape = _shape(shape)
        self.normalization = float(normalization)
        x0 = self.state(g0, eta0)
        super().__init__(self._f, 18, 6, jacobian=None, name=name, x0=x0, scale=1.0)
        self.input_names = list(_WRENCH)
        self.state_names = ["x", "y", "z"] + [f"R{i}{j}" for i in range(3) for j in range(3)] \
            + ["omega_x", "omega_y", "omega_z", "v_x", "v_y", "v_z"]

    @property
    def rigid_parameters(self):
        """The body's parameters as the compiled network reads them (:mod:`soroshapes.network`), (25,): mass [kg],
        inertia (9) [kg m^2] and its inverse (9) row by row, gravity (3) [m/s^2], damping (linear [N s/m],
        angular [N m s/rad]), normalization [1/s]."""
        return np.concatenate([[self.mass], self.inertia.reshape(9), self._Iinv.reshape(9), self.gravity,
                               self.damping, [self.normalization]])

    @classmethod
    def spinning(cls, axis, inertia, damping=0.0, shape=None, **kw):
        """A :class:`SpinningBody`: a body that only turns about ``axis`` (see there for the keywords)."""
        return SpinningBody(axis, inertia, damping, shape, **kw)

    @property
    def mass_matrix(self):
        r""":math:`\mathcal M = \mathrm{diag}(I_b, m I_3)` (6, 6) [kg m^2, kg]."""
        M = np.zeros((6, 6))
        M[:3, :3], M[3:, 3:] = self.inertia, self.mass * np.eye(3)
        return M

    # -- state <-> pose, twist ----------------------------------------------------------------------------
    @staticmethod
    def state(pose, twist=None):
        """The 18-entry state of a pose (4, 4) and a body twist (6,) [rad/s, m/s]."""
        g = _pose(pose, "pose")
        eta = np.zeros(6) if twist is None else _finite(twist, (6,), "twist")
        return np.concatenate([g[:3, 3], g[:3, :3].reshape(9), eta])

    @staticmethod
    def pose(x):
        """Pose (4, 4) of the state ``x`` (the stored rotation re-orthonormalized)."""
        g = np.eye(4)
        g[:3, :3], g[:3, 3] = _polar(np.reshape(x[3:12], (3, 3))), x[:3]
        return g

    @staticmethod
    def twist(x):
        r"""Body twist :math:`\eta = (\omega, v)` (6,) of the state ``x``."""
        return np.asarray(x[12:18], dtype=float).copy()

    def poses(self, X):
        """Poses (K, 4, 4) of a trajectory of states (K, 18), e.g. ``traj["body"].x``."""
        return np.array([self.pose(x) for x in np.atleast_2d(X)])

    def momentum(self, x):
        r"""Spatial momentum :math:`(L, P)`: angular momentum about the spatial origin [kg m^2/s] and linear
        momentum [kg m/s], both in spatial axes (conserved without external wrench, gravity and damping)."""
        g = self.pose(x)
        R, p = g[:3, :3], g[:3, 3]
        P = R @ (self.mass * x[15:18])
        return np.concatenate([R @ (self.inertia @ x[12:15]) + np.cross(p, P), P])

    def energy(self, x):
        """Energies [J]: dict with kinetic (1/2 eta^T M eta), gravity (-m a_g . p) and total."""
        w, v = x[12:15], x[15:18]
        kin = 0.5 * (w @ self.inertia @ w + self.mass * v @ v)
        pot = -self.mass * self.gravity @ x[:3]
        return {"kinetic": float(kin), "gravity": float(pot), "total": float(kin + pot)}

    # -- dynamics -----------------------------------------------------------------------------------------
    def _f(self, x, u, t):
        u = _wrench(u)
        R, w, v = x[3:12].reshape(3, 3), x[12:15], x[15:18]
        out = np.empty(18)
        out[:3] = R @ v
        dR = R @ _skew(w)
        if self.normalization:
            dR += 0.5 * self.normalization * (R - R @ (R.T @ R))
        out[3:12] = dR.reshape(9)
        Iw, mv = self.inertia @ w, self.mass * v
        cv, cw = self.damping
        moment = -np.cross(w, Iw) - np.cross(v, mv) - cw * w + u[:3]
        force = -np.cross(w, mv) + self.mass * (R.T @ self.gravity) - cv * v + u[3:]
        out[12:15] = self._Iinv @ moment
        out[15:18] = force / self.mass
        return out

    def rhs(self, x, u, t):
        """State derivative (18,) at state ``x``, external body wrench ``u`` (6,) [N m, N], time ``t`` [s]."""
        x = np.asarray(x, dtype=float).reshape(-1)
        if x.shape != (18,):
            raise ParameterError(f"a RigidBody state has 18 entries (p, R row by row, omega, v), got {x.size}")
        return self._f(x, u, t)


# ------------------------------------------------------------------------------------------------------------
# body spinning about a fixed axis
# ------------------------------------------------------------------------------------------------------------
class SpinningBody(StateSpace):
    r"""A rigid body that can only turn about a fixed ``axis``: :math:`I_a\ddot\theta = -c\dot\theta + a\cdot m`.

    A :class:`~soroshapes.model.StateSpace` with states :math:`(\theta, \dot\theta)` [rad, rad/s] and the 6
    inputs of the body wrench :math:`(m, f)` [N m, N] (body coordinates; only :math:`a\cdot m` acts).

    Parameters
    ----------
    axis : (3,)
        Axis of rotation in body coordinates (normalized), through the body origin.
    inertia : float [kg m^2], > 0
        Moment of inertia about the axis.
    damping : float [N m s/rad], >= 0
    shape : 3D SDF, optional
        The surface in body coordinates (for contact), e.g. a hexagonal bolt head
        ``sdf.Polygon(hexagon).extrude(h)`` about ``axis = (0, 0, 1)``.
    pose0 : (4, 4), optional
        Pose at :math:`\theta = 0` (where the axis is in space).
    angle0, rate0 : float [rad, rad/s]
        Initial state.
    name : str, optional
    """

    def __init__(self, axis, inertia, damping=0.0, shape=None, *, pose0=None, angle0=0.0, rate0=0.0, name=None):
        a = _finite(axis, (3,), "axis")
        if np.linalg.norm(a) == 0:
            raise ParameterError("axis must be a non-zero 3-vector")
        self.axis = a / np.linalg.norm(a)
        try:
            inertia, damping = float(inertia), float(damping)
        except (TypeError, ValueError):
            raise ParameterError("inertia [kg m^2] and damping [N m s/rad] must be numbers") from None
        if not (np.isfinite(inertia) and inertia > 0):
            raise ParameterError(f"inertia must be positive and finite [kg m^2], got {inertia!r}")
        if not (np.isfinite(damping) and damping >= 0):
            raise ParameterError(f"damping must be >= 0 [N m s/rad], got {damping!r}")
        self.inertia, self.damping = inertia, damping
        self.shape = _shape(shape)
        self.pose0 = _pose(np.eye(4) if pose0 is None else pose0)
        A = np.array([[0.0, 1.0], [0.0, -damping / inertia]])
        B = np.zeros((2, 6))
        B[1, :3] = self.axis / inertia
        super().__init__(self._f, 2, 6, jacobian=lambda x, u, t: (A, B), name=name,
                         x0=[float(angle0), float(rate0)])
        self.input_names = list(_WRENCH)
        self.state_names = ["angle", "rate"]
        self.matrices = (A, B, np.eye(2), np.zeros((2, 6)))     # a linear system: runs compiled in a network

    def _f(self, x, u, t):
        u = _wrench(u)
        return np.array([x[1], (self.axis @ u[:3] - self.damping * x[1]) / self.inertia])

    @property
    def spinning_parameters(self):
        """(15,) the pose data a compiled network needs (:mod:`soroshapes.network`): the initial rotation row by
        row (9), its position [m] (3) and the unit axis (3)."""
        return np.concatenate([self.pose0[:3, :3].reshape(-1), self.pose0[:3, 3], self.axis])

    def pose(self, x):
        r"""Pose :math:`g_0 (\exp(\theta\hat a), 0)` (4, 4) at state ``x = (angle, rate)``."""
        g = self.pose0.copy()
        g[:3, :3] = self.pose0[:3, :3] @ _rotation(self.axis, float(x[0]))
        return g

    def twist(self, x):
        r"""Body twist :math:`(a\dot\theta, 0)` (6,)."""
        return np.concatenate([self.axis * float(x[1]), np.zeros(3)])

    def energy(self, x):
        """Kinetic energy [J] in a dict (``kinetic``, ``total``)."""
        k = 0.5 * self.inertia * float(x[1]) ** 2
        return {"kinetic": k, "total": k}


# ------------------------------------------------------------------------------------------------------------
# contact
# ------------------------------------------------------------------------------------------------------------
def beam_contact(beam, body, stiffness, damping=0.0, friction=0.0, regularization=1e-3, *, q, qd=None, x=None,
                 nodes=False):
    r"""Penalty + regularized-Coulomb contact between a beam's tube and a body's ``shape`` (module docstring).

    Parameters
    ----------
    beam : :class:`~soroshapes.shapes.Shapes` (tube radius ``beam.contact_radius``).
    body : :class:`RigidBody` or :class:`SpinningBody` with a ``shape``.
    stiffness : float [N/m^2] (per unit length of rod), > 0
    damping : float [N s/m^2], >= 0
    friction : float, >= 0 (Coulomb coefficient)
    regularization : float [m/s], > 0 (slip speed below which friction is viscous)
    q, qd : beam coordinates and rates (qd default zeros).
    x : body state (default ``body.x0``).
    nodes : bool
        Also return the (N+1, 3) spatial forces [N] on the beam nodes.

    Returns
    -------
    f_beam : (n,) generalized force on the beam.
    wrench : (6,) wrench :math:`(m, f)` [N m, N] on the body, in body coordinates (moment about the body origin).
    forces : (N+1, 3) [N], only with ``nodes=True``.
    """
    shape = getattr(body, "shape", None)
    if shape is None:
        raise ParameterError("the body has no shape: give RigidBody(..., shape=sdf...) (body coordinates)")
    k, c, mu, eps = (float(v) for v in (stiffness, damping, friction, regularization))
    for what, v, pos in (("stiffness", k, True), ("damping", c, False), ("friction", mu, False),
                         ("regularization", eps, True)):
        if not np.isfinite(v) or v < 0 or (pos and v == 0):
            raise ParameterError(f"contact {what} must be {'> 0' if pos else '>= 0'}, got {v!r}")
    xb = body.x0 if x is None else np.asarray(x, dtype=float).reshape(-1)
    G, eta, J = beam.node_kinematics(q, qd)
    w = beam.weights
    r = beam.contact_radius
    g = body.pose(xb)
    Rb, pb = g[:3, :3], g[:3, 3]
    etab = body.twist(xb)
    Pb = (G[:, :3, 3] - pb) @ Rb                      # rows R^T (P - p)
    distance = _distance(shape)
    d = distance(Pb)
    hit = np.nonzero(d < r)[0]
    f = np.zeros(beam.n)
    W = np.zeros(6)
    F = np.zeros((len(d), 3))
    if len(hit):
        nb = np.asarray(shape.gradient(Pb[hit]), dtype=float).reshape(len(hit), 3)   # exact where analytic
        nb /= np.linalg.norm(nb, axis=1)[:, None]
        ns = nb @ Rb.T
        vnode = np.einsum("kij,kj->ki", G[hit, :3, :3], eta[hit, 3:])
        vbody = (etab[3:] + np.cross(etab[:3], Pb[hit])) @ Rb.T
        vrel = vnode - vbody
        vn = np.einsum("ki,ki->k", vrel, ns)
        fn = np.maximum(0.0, k * (r - d[hit]) - c * vn)
        vt = vrel - vn[:, None] * ns
        slip = np.sqrt(np.einsum("ki,ki->k", vt, vt) + eps * eps)
        Fh = w[hit, None] * (fn[:, None] * ns - mu * (fn / slip)[:, None] * vt)
        F[hit] = Fh
        for j, i in enumerate(hit):
            f += J[i, 3:].T @ (G[i, :3, :3].T @ Fh[j])
        fb = -Fh @ Rb                                 # rows R^T (-F)
        W[:3] = np.cross(Pb[hit], fb).sum(axis=0)
        W[3:] = fb.sum(axis=0)
    return (f, W, F) if nodes else (f, W)


def couple_contact(model, beam, body, stiffness, damping=0.0, friction=0.0, regularization=1e-3):
    """Contact between the beam ``beam`` and the body ``body`` (system names) of ``model``; returns the model.

    The beam gets the contact's generalized force through ``Shapes.add_force`` (reading the body's current
    state from the model), the body gets the equal and opposite wrench through ``model.connect`` into all six
    of its wrench inputs (free, or coupled by earlier calls of this function: several beams touching one body,
    e.g. the fingers of a gripper, add up their wrenches). One contact evaluation serves both at a given
    state. Call it once per pair (each call adds a force to the beam). Parameters as in :func:`beam_contact`.
    """
    if not isinstance(model, Model):
        raise ParameterError("couple_contact needs a soroshapes Model")
    _check_pair(model, beam, body)
    shp, bdy = model[beam].system, model[body].system
    beam_contact(shp, bdy, stiffness, damping, friction, regularization, q=np.zeros(shp.n))   # validate now
    n, cache = shp.n, {}

    def evaluate(q, qd, xb):
        key = (q.tobytes(), qd.tobytes(), xb.tobytes())
        if cache.get("key") != key:
            cache["val"] = beam_contact(shp, bdy, stiffness, damping, friction, regularization, q=q, qd=qd, x=xb)
            cache["key"] = key
        return cache["val"]

    def force(s, q, qd, t):
        return evaluate(np.asarray(q, float), np.asarray(qd, float), np.array(model.state(body)))[0]
    force.network_term = True          # the compiled network evaluates it with the body's contact term below

    shp.add_force(force)

    def wrench(mdl):
        xs = np.array(mdl.state(beam))
        return evaluate(xs[:n], xs[n:], np.array(mdl.state(body)))[1]

    from ._contact import lower_contact
    try:                               # the compiled form (soroshapes.network): the shape as an SDF program
        par, program = lower_contact(shp, bdy.shape, stiffness, damping, friction, regularization)
        wrench.compiled = ("contact", par, beam, program)
    except NotImplementedError as why:
        wrench.compiled = None
        wrench.python_reason = f"contact of beam {beam!r} with body {body!r}: {why}"
    _add_body_wrench(model, body, wrench)
    return model


class WrenchSum:
    """The sum of the wrenches [N m, N] (body coordinates) that contacts and couplings put on one body: a
    callable of the model (the Python path) that the compiled network lowers when every term has a compiled
    form (``compiled_terms``)."""

    def __init__(self, body):
        self.system, self.terms = body, []

    def __call__(self, model):
        return sum(w(model) for w in self.terms)

    @property
    def compiled_terms(self):
        """[(kind, floats, beam name or None)] of the terms (:mod:`soroshapes.network`), or None if one is a
        Python callable."""
        out = [getattr(w, "compiled", None) for w in self.terms]
        return None if any(c is None for c in out) else out

    @property
    def python_reason(self):
        """Why the first term without a compiled form has none (a str), or None."""
        for w in self.terms:
            if getattr(w, "compiled", None) is None:
                return getattr(w, "python_reason", f"a Python wrench on body {self.system!r}")
        return None


class _GroundTerm:
    """:func:`ground_contact` on a body of a model, with its parameters as data for the compiled network."""

    def __init__(self, body, system, points, stiffness, damping, friction, regularization, plane):
        self.body, self.system, self.points = body, system, np.asarray(points, dtype=float).reshape(-1, 3)
        self.args = (stiffness, damping, friction, regularization)
        self.plane = tuple(np.asarray(v, dtype=float) for v in plane)
        c, n = self.plane
        self.compiled = None
        if isinstance(system, RigidBody):
            self.compiled = ("ground", np.concatenate([[float(v) for v in self.args], c, n / np.linalg.norm(n),
                                                       [len(self.points)], self.points.reshape(-1)]), None)

    def __call__(self, model):
        return ground_contact(self.system, np.array(model.state(self.body)), self.points, *self.args,
                              plane=self.plane)


def _add_body_wrench(model, body, wrench):
    """Add ``wrench(model) -> (6,)`` (body coordinates) to the wrench inputs of ``body``: the first call
    connects the sum of all of them (a :class:`WrenchSum`), so that several contacts and couplings act on one
    body."""
    registry = model.__dict__.setdefault("_contact_wrenches", {})
    if body not in registry:
        registry[body] = WrenchSum(body)
        model.connect(registry[body], body)
    registry[body].terms.append(wrench)


def _check_pair(model, beam, body):
    for nm in [n for n in (beam, body) if n is not None]:
        if nm not in model.systems:
            raise ParameterError(f"no system {nm!r} in the model; systems: {', '.join(model.systems)}")
    if beam is not None:
        from .shapes import Shapes
        if not isinstance(model[beam].system, Shapes):
            raise ParameterError(f"system {beam!r} is a {type(model[beam].system).__name__}, not a Shapes beam")
    if not isinstance(model[body].system, (RigidBody, SpinningBody)):
        raise ParameterError(f"system {body!r} is a {type(model[body].system).__name__}, not a RigidBody or "
                             "SpinningBody")


def ground_contact(body, x, points, stiffness, damping=0.0, friction=0.0, regularization=1e-3, *,
                   plane=((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))):
    r"""Wrench [N m, N] (body coordinates) of a fixed plane on the body points ``points`` (k, 3) [m, body
    coordinates], e.g. the rim of a cylinder's base standing on a table.

    Point :math:`r_j` is at :math:`P_j = p + R r_j` with velocity :math:`v_j = R(v + \omega	imes r_j)`; with
    the plane through :math:`c` with unit normal :math:`n`, gap :math:`d_j = (P_j - c)\cdot n`, the force on the
    body is :math:`F_j = f_n n - \mu f_n v_t/\sqrt{|v_t|^2 + \epsilon^2}` with
    :math:`f_n = \max(0, -k d_j - c_d\, v_j\cdot n)` (``stiffness`` k [N/m] and ``damping`` c_d [N s/m] per
    point), :math:`v_t` the tangential velocity; the wrench is :math:`\sum_j (r_j	imes R^TF_j, R^TF_j)`.
    """
    r = np.asarray(points, dtype=float).reshape(-1, 3)
    c, n = (np.asarray(v, dtype=float) for v in plane)
    n = n / np.linalg.norm(n)
    g, eta = body.pose(x), body.twist(x)
    R, p = g[:3, :3], g[:3, 3]
    P = p + r @ R.T
    v = (eta[3:] + np.cross(eta[:3], r)) @ R.T
    d = (P - c) @ n
    vn = v @ n
    fn = np.maximum(0.0, -stiffness * d - damping * vn) * (d < 0)
    vt = v - vn[:, None] * n
    F = fn[:, None] * n - friction * (fn / np.sqrt(np.einsum("ki,ki->k", vt, vt) + regularization**2))[:, None] * vt
    fb = F @ R
    return np.concatenate([np.cross(r, fb).sum(axis=0), fb.sum(axis=0)])


def couple_ground(model, body, points, stiffness, damping=0.0, friction=0.0, regularization=1e-3, *,
                  plane=((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))):
    """A fixed plane (a table, the floor) under the body ``body`` of ``model``, touching it at ``points``
    (body coordinates): :func:`ground_contact` added to the body's wrench inputs. Returns the model."""
    _check_pair(model, None, body)
    bdy = model[body].system
    ground_contact(bdy, bdy.x0, points, stiffness, damping, friction, regularization, plane=plane)   # validate
    _add_body_wrench(model, body, _GroundTerm(body, bdy, points, stiffness, damping, friction, regularization,
                                              plane))
    return model


def grasp_force(beam, body, q, qd, x, anchor, stiffness, damping, at=None):
    r"""Force [N] (spatial) of a grasp: a spring-damper between the beam's node ``at`` (default the tip) and
    the body point ``anchor`` (body coordinates): :math:`F = k(P_b - P_a) + c(\dot P_b - \dot P_a)` acts on
    the body (and :math:`-F` on the beam). Returns (F, generalized force on the beam (n,), body wrench (6,))."""
    i = beam.node(at)
    G, eta, J = beam.node_kinematics(np.asarray(q, float), np.asarray(qd, float))
    Pb, Vb = G[i, :3, 3], G[i, :3, :3] @ eta[i, 3:]
    g, tw = body.pose(x), body.twist(x)
    R = g[:3, :3]
    a = np.asarray(anchor, dtype=float)
    Pa, Va = g[:3, 3] + R @ a, R @ (tw[3:] + np.cross(tw[:3], a))
    F = stiffness * (Pb - Pa) + damping * (Vb - Va)
    fb = R.T @ F
    return F, -(J[i, 3:].T @ (G[i, :3, :3].T @ F)), np.concatenate([np.cross(a, fb), fb])


def couple_grasp(model, beam, body, anchor, stiffness, damping=0.0, engaged=None, at=None):
    """A gripper at the node ``at`` (default the tip) of the beam ``beam`` holding the body ``body`` of
    ``model`` at its point ``anchor`` (body coordinates): :func:`grasp_force` scaled by ``engaged(t)`` in
    [0, 1] (default always 1: a closed gripper; a ramp closes it), equal and opposite on beam and body.
    ``engaged``: None, a callable of t [s], or a one-column :class:`~soroshapes.network.Schedule`; with None or
    a Schedule on a free :class:`RigidBody` the grasp runs compiled in a network (:mod:`soroshapes.network`).
    A reduced model of a gripper (suction cup or fingers closed on the object): it transmits force, not
    moment, so the held body hangs from the grasp point. Returns the model."""
    _check_pair(model, beam, body)
    shp, bdy, n = model[beam].system, model[body].system, model[beam].system.n
    table = hasattr(engaged, "at") and not isinstance(engaged.values, dict)     # a soroshapes.network.Schedule
    if engaged is None:
        on = lambda t: 1.0                                                      # noqa: E731
    elif table:
        if engaged.values.shape[1] != 1:
            raise ParameterError("couple_grasp: an engagement Schedule has one column (0 open .. 1 closed)")
        on = lambda t: float(engaged.at(t)[0])                                  # noqa: E731
    else:
        on = engaged
    grasp_force(shp, bdy, np.zeros(n), np.zeros(n), bdy.x0, anchor, stiffness, damping, at)   # validate now

    def evaluate(q, qd, xb, t):
        return [on(t) * v for v in grasp_force(shp, bdy, q, qd, xb, anchor, stiffness, damping, at)]

    def force(s, q, qd, t):
        return evaluate(q, qd, np.array(model.state(body)), t)[1]
    force.network_term = True          # the compiled network evaluates it with the body's grasp term below

    shp.add_force(force)

    def wrench(mdl):
        xs = np.array(mdl.state(beam))
        return evaluate(xs[:n], xs[n:], np.array(mdl.state(body)), mdl.t)[2]

    wrench.compiled = None
    if isinstance(bdy, RigidBody) and (engaged is None or table):
        times, values, period = ((np.array([0.0, 1.0]), np.ones((2, 1)), 0.0) if engaged is None else
                                 (engaged.times, engaged.values, engaged.period or 0.0))
        wrench.compiled = ("grasp", np.concatenate([[shp.node(at) * shp.model.stride], np.asarray(anchor, float),
                                                    [stiffness, damping, len(times), period], times,
                                                    values[:, 0]]), beam)
    _add_body_wrench(model, body, wrench)
    return model


# ------------------------------------------------------------------------------------------------------------
# contact between the sampled points of a tree's bodies and a rigid body
# ------------------------------------------------------------------------------------------------------------
def tree_contact(tree, body, points, stiffness, damping=0.0, friction=0.0, regularization=1e-3, *, q, qd=None,
                 x=None, data=None, forces=False):
    r"""Penalty + regularized-Coulomb contact between points carried by the bodies of a
    :class:`~soroshapes.tree.Tree` (pads on its fingers) and a rigid body's ``shape``.

    Point :math:`j` rides on the frame :math:`g_i = (R_i, P_i)` of a tree body (a beam node at arc length ``at``
    or a link's frame, :meth:`Tree.row <soroshapes.tree.Tree.row>`) at the constant offset :math:`o_j` (frame
    axes) with the pad radius :math:`r_j`: spatial position :math:`X_j = P_i + R_i o_j`, velocity
    :math:`R_i(v_i + \omega_i\times o_j)` (body twist :math:`(\omega_i, v_i)`), Jacobian
    :math:`R_i(J_{i,v} - \hat o_j J_{i,\omega})`. With the body's distance :math:`d_j = \phi(R^T(X_j - p))`,
    normal :math:`n_j`, penetration :math:`\delta_j = r_j - d_j` and the relative velocity :math:`v^{rel}_j`
    (point minus body material point), the force on the tree at the point is

    .. math:: F_j = f_n n_j - \mu f_n \frac{v_t}{\sqrt{|v_t|^2+\epsilon^2}},\qquad f_n = \max(0, k\delta_j -
              c\,v_n)

    (``stiffness`` k [N/m] and ``damping`` c [N s/m] per point, ``friction`` :math:`\mu`, ``regularization``
    :math:`\epsilon` [m/s]): the tree gets :math:`\sum_j J_{X_j}^T F_j`, the body :math:`-F_j` at the same
    points (the wrench :math:`\sum_j (X^b_j\times f^b_j, f^b_j)` in body coordinates), so forces and moments
    cancel (Newton's third law), as in :func:`beam_contact` (whose stiffness is per unit length instead).

    Parameters
    ----------
    tree : :class:`~soroshapes.tree.Tree`
    body : :class:`RigidBody` or :class:`SpinningBody` with a ``shape``.
    points : list of ``(tree body name, at, offset (3,) [m], radius [m])``; ``at`` the arc length [m] of a beam
        node (None: the tip; None for a link).
    q, qd : tree coordinates and rates (n,).
    x : body state (default ``body.x0``).
    data : a :class:`~soroshapes.tree.TreeData` workspace (default a fresh one).
    forces : also return the (k, 3) spatial forces [N] on the tree's points and their positions (k, 3) [m].

    Returns
    -------
    f_tree (n,), wrench (6,) [N m, N] on the body in body coordinates[, F (k, 3), X (k, 3)].
    """
    shape = getattr(body, "shape", None)
    if shape is None:
        raise ParameterError("the body has no shape: give RigidBody(..., shape=sdf...) (body coordinates)")
    args = _contact_args(stiffness, damping, friction, regularization)
    rows, off, rad = _tree_points(tree, points)
    data = tree.make_data() if data is None else data
    xb = body.x0 if x is None else np.asarray(x, dtype=float).reshape(-1)
    out = _tree_contact(tree, body, _distance(shape), rows, off, rad, args, q, qd, xb, data)
    return out if forces else out[:2]


def _contact_args(stiffness, damping, friction, regularization):
    k, c, mu, eps = (float(v) for v in (stiffness, damping, friction, regularization))
    for what, v, pos in (("stiffness", k, True), ("damping", c, False), ("friction", mu, False),
                         ("regularization", eps, True)):
        if not np.isfinite(v) or v < 0 or (pos and v == 0):
            raise ParameterError(f"contact {what} must be {'> 0' if pos else '>= 0'}, got {v!r}")
    return k, c, mu, eps


def _cross(a, b):
    """Row-wise cross product of (k, 3) arrays (np.cross costs ~10x more on small arrays)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _tree_contact(tree, body, distance, rows, off, rad, args, q, qd, xb, data):
    """:func:`tree_contact` on checked arguments: (f_tree, wrench, F, X)."""
    from .tree import kinematics
    k, c, mu, eps = args
    kinematics(tree, data, q, qd)
    G = data.G[rows]
    R = G[:, :3, :3]
    X = G[:, :3, 3] + np.einsum("kij,kj->ki", R, off)
    g = body.pose(xb)
    Rb, pb = g[:3, :3], g[:3, 3]
    Xb = (X - pb) @ Rb
    d = distance(Xb)
    hit = np.nonzero(d < rad)[0]
    f, W, F = np.zeros(tree.n), np.zeros(6), np.zeros((len(rows), 3))
    if len(hit):
        etab = body.twist(xb)
        shape = body.shape
        nb = np.asarray(shape.gradient(Xb[hit]), dtype=float).reshape(len(hit), 3)
        nb /= np.linalg.norm(nb, axis=1)[:, None]
        ns = nb @ Rb.T
        o, Rh, eta, J = off[hit], R[hit], data.eta[rows[hit]], data.J[rows[hit]]
        vpt = np.einsum("kij,kj->ki", Rh, eta[:, 3:] + _cross(eta[:, :3], o))
        vbody = (etab[3:] + _cross(np.broadcast_to(etab[:3], Xb[hit].shape), Xb[hit])) @ Rb.T
        vrel = vpt - vbody
        vn = np.einsum("ki,ki->k", vrel, ns)
        fn = np.maximum(0.0, k * (rad[hit] - d[hit]) - c * vn)
        vt = vrel - vn[:, None] * ns
        slip = np.sqrt(np.einsum("ki,ki->k", vt, vt) + eps * eps)
        Fh = fn[:, None] * ns - mu * (fn / slip)[:, None] * vt
        F[hit] = Fh
        floc = np.einsum("kji,kj->ki", Rh, Fh)                     # the force in each frame's axes
        f = np.einsum("kji,kj->i", J[:, 3:], floc) + np.einsum("kji,kj->i", J[:, :3], _cross(o, floc))
        fb = -Fh @ Rb
        W[:3] = _cross(Xb[hit], fb).sum(axis=0)
        W[3:] = fb.sum(axis=0)
    return f, W, F, X


def _tree_points(tree, points):
    """(rows (k,), offsets (k, 3), radii (k,)) of the contact points of :func:`tree_contact`, checked."""
    rows, off, rad = [], [], []
    try:
        pts = list(points)
    except TypeError:
        raise ParameterError("points must be a list of (tree body, at, offset (3,), radius)") from None
    if not pts:
        raise ParameterError("give at least one contact point (tree body, at, offset (3,), radius)")
    for p in pts:
        if len(p) != 4:
            raise ParameterError(f"a contact point is (tree body, at, offset (3,) [m], radius [m]), got {p!r}")
        name, at, o, r = p
        try:
            rows.append(tree.row(name, at))
        except ParameterError as err:
            raise ParameterError(f"contact point on {name!r} at {at!r}: contact points sit at a beam's nodes (at = "
                                 f"one of tree.body_model({name!r}).sigma) or on a link (at=None): {err}") from err
        off.append(_finite(o, (3,), f"the offset of a contact point on {name!r}"))
        r = float(r)
        if not (np.isfinite(r) and r >= 0):
            raise ParameterError(f"the radius of a contact point on {name!r} must be >= 0 [m], got {r!r}")
        rad.append(r)
    return np.array(rows, dtype=np.int64), np.array(off), np.array(rad)


class TreeContact:
    r"""Contact of a tree's sampled points with one rigid body of a :class:`~soroshapes.model.Model`
    (:func:`tree_contact`): the description that :func:`couple_tree_contact` wires into a model (the tree's
    block made with ``Tree.system(..., force_inputs=True)``). One evaluation serves both sides at a state
    (cached). Parameters as in :func:`tree_contact`.

    After a call, ``last`` = (f_tree, wrench, F (k, 3), X (k, 3)) of the newest evaluation; :meth:`evaluate`
    gives them at any state of a trajectory (post-processing)."""

    def __init__(self, tree, points, stiffness, damping=0.0, friction=0.0, regularization=1e-3):
        self.tree = tree
        self.points = list(points)
        self.args = _contact_args(stiffness, damping, friction, regularization)
        self._rows, self._off, self._rad = _tree_points(tree, self.points)          # validated now
        self.data = tree.make_data()
        self.model = self.block = self.body = self._distance = None
        self._key = self.last = None

    @property
    def sampled(self):
        """(rows (k,) of the tree's stacked frames, offsets (k, 3) [m], pad radii (k,) [m]) of the points."""
        return self._rows, self._off, self._rad

    def evaluate(self, q, qd, xb):
        """(f_tree (n,), wrench (6,), F (k, 3) [N], X (k, 3) [m]) at tree state (q, qd), body state ``xb``."""
        if self.model is None:
            raise ParameterError("TreeContact: connect it first with couple_tree_contact(model, tree block, body, "
                                 "contact)")
        q, qd, xb = (np.asarray(v, dtype=float) for v in (q, qd, xb))
        key = (q.tobytes(), qd.tobytes(), xb.tobytes())
        if self._key != key:
            body = self.model[self.body].system
            self.last = _tree_contact(self.tree, body, self._distance, self._rows, self._off, self._rad, self.args,
                                      q, qd, xb, self.data)
            self._key = key
        return self.last

    def at(self, model):
        """:meth:`evaluate` at the model's current state."""
        q, qd = self.tree.state(model.t, np.array(model.state(self.block)))
        return self.evaluate(q, qd, np.array(model.state(self.body)))


class _TreeForceSum:
    """The sum of the generalized forces [N, N m per coordinate] that contacts put on one tree block (its
    ``force<i>`` inputs) on the Python path. The compiled network puts each contact's force on the tree itself,
    with the body's wrench term (``network_term``), and leaves these inputs at zero."""

    network_term = True

    def __init__(self, block):
        self.block, self.terms = block, []

    def __call__(self, model):
        return sum(t(model) for t in self.terms)


def couple_tree_contact(model, block, body, contact):
    """Wire a :class:`TreeContact` into ``model``: the tree block ``block`` (made by ``Tree.system(...,
    force_inputs=True)``) gets the contact's generalized force in its ``force<i>`` inputs, the rigid body ``body``
    the equal and opposite wrench in its wrench inputs (added to its other contacts, e.g. :func:`couple_ground`).
    Both are couplings of the network, so its Jacobian sees each side's dependence on the other's state.
    Several contacts on one tree add up. Returns the model."""
    if not isinstance(model, Model):
        raise ParameterError("couple_tree_contact needs a soroshapes Model")
    if not isinstance(contact, TreeContact):
        raise ParameterError("contact must be a TreeContact")
    _check_pair(model, None, body)
    if block not in model.systems:
        raise ParameterError(f"no system {block!r} in the model; systems: {', '.join(model.systems)}")
    names = [f"force{i}" for i in range(contact.tree.n)]
    have = list(getattr(model[block].system, "input_names", None) or [])
    if have[-len(names):] != names:
        raise ParameterError(f"system {block!r} has no generalized-force inputs: make it with "
                             "tree.system(..., force_inputs=True) from the contact's tree")
    if getattr(model[body].system, "shape", None) is None:
        raise ParameterError(f"body {body!r} has no shape: give RigidBody(..., shape=sdf...) (body coordinates)")
    if contact.model is not None:
        raise ParameterError("this TreeContact is already connected; make one per (tree, body) pair")
    contact.model, contact.block, contact.body = model, block, body
    contact._distance = _distance(model[body].system.shape)
    registry = model.__dict__.setdefault("_tree_forces", {})
    if block not in registry:
        registry[block] = _TreeForceSum(block)
        model.connect(registry[block], block, names)
    registry[block].terms.append(lambda mdl: contact.at(mdl)[0])

    def wrench(mdl):
        return contact.at(mdl)[1]
    from ._contact import lower_tree_contact
    try:                               # the compiled form (soroshapes.network): the shape as an SDF program
        par, program = lower_tree_contact(*contact.sampled, model[body].system.shape, *contact.args)
        wrench.compiled = ("tree_contact", par, block, program)
    except NotImplementedError as why:
        wrench.compiled = None
        wrench.python_reason = f"contact of tree {block!r} with body {body!r}: {why}"
    _add_body_wrench(model, body, wrench)
    return model
