r"""Trees of bodies: Cosserat beams mounted on beams and on rigid links, joints between rigid links.

A :class:`Tree` holds bodies added in order, each hanging from the world or from a body added before it:

* a **beam** (a :class:`~soroshapes.shapes.Shapes` or a :class:`~soroshapes.beam.BeamModel`) whose base frame is
  the parent frame times a constant ``offset`` (then the beam's own ``base`` pose): the world, a node of a
  parent beam (arc length ``at``) or a rigid link's frame;
* a **rigid link** (mass [kg], inertia [kg m^2] about its centre of mass in link axes, centre of mass ``com`` [m]
  in link axes) whose frame is the parent frame times ``offset`` times the joint's motion
  :math:`\exp(\hat\xi\theta)`: ``"revolute"`` (:math:`\xi = (a, 0)`, :math:`\theta` [rad] about the unit
  ``axis`` a of the offset frame), ``"prismatic"`` (:math:`\xi = (0, a)`, :math:`\theta` [m]) or ``"fixed"`` (no
  coordinate). A joint coordinate may be *prescribed* (``motion``: a function of time, e.g. a hub spinning at
  a constant rate, :func:`spin`): it stays in :math:`q` (kinematics and Jacobians see it) and the dynamics
  solve for the other coordinates.

Coordinates :math:`q` (n,) stack the bodies' coordinates in the order they were added (a beam's strain
coordinates, one per revolute or prismatic joint); :meth:`Tree.coordinates` gives each body's slice.

Kinematics. Every frame (the beams' quadrature points, which include their nodes; a link's frame; a link's
principal centre-of-mass frame) is composed with its parent frame by :func:`soroshapes._tree.attach`:
:math:`g_i = g_p X h_i`, :math:`J_i = \mathrm{Ad}_{(Xh_i)^{-1}} J_p + [J^\ell_i]_b` (the child's own columns plus
the parent's columns transported by the adjoint of the offset and the child's local frame), with the Jacobian
rate and twist alike. The beam's local frames, Jacobians and rates come from the compiled beam kernels
(:func:`soroshapes._beam.kinematics`, base fixed), so the child's base twist and acceleration enter its motion
exactly. Jacobians are **body** Jacobians (6 x n, twist in the frame's own axes, angular part first);
``frame="spatial"`` gives :math:`\mathrm{Ad}_g J`.

Dynamics (the exact Lagrangian dynamics of the discrete tree). With every inertial frame :math:`i` (weight
:math:`w_i`, diagonal inertia :math:`\mathcal M_i`: a beam's sectional inertia per length at its quadrature
points, or a link's principal inertia and mass at its centre of mass with :math:`w = 1`):

.. math::

    M(q) = \sum_i w_i J_i^T\mathcal M_i J_i,\qquad
    C(q, \dot q) = \sum_i w_i J_i^T\big(\mathcal M_i\dot J_i + (\mathcal M_i\mathrm{ad}_{\eta_i}
    - \mathrm{ad}_{\eta_i}^T\mathcal M_i)J_i\big),\qquad
    f_g = \sum_i w_i J_i^T \mathcal M_i (0, R_i^T a_g),

summed by the beam's compiled kernel (:func:`soroshapes._beam.mass_coriolis_gravity`) over the stacked frames:
the child's inertia loads the parent's coordinates through the transported columns (:math:`\dot M - 2C` is
skew). The equations of motion are

.. math:: M\ddot q + C\dot q + D\dot q + Kq = f_g + Bu + f_{ext},

with :math:`K`, :math:`D` block diagonal (each beam's stiffness and Kelvin-Voigt damping :math:`\tau K`, each
joint's ``stiffness`` [N m/rad or N/m] and ``damping``), :math:`B` (n, m) the inputs: each beam's chambers and
linear actuators (constant columns), then a torque [N m] or force [N] per ``actuated`` joint.

Simulation uses the integrator family of :class:`~soroshapes.model.Model` (its implicit midpoint, trapezoidal
or BDF2 rule on the first-order state :math:`(q_f, \dot q_f)` of the free coordinates): :meth:`Tree.system`
makes the :class:`~soroshapes.model.StateSpace` block (a network's couplings and controller may drive its
inputs), :meth:`Tree.simulate` runs it alone. The block's accelerations are one compiled call over the whole tree
(:mod:`soroshapes._treeblock`), and a tree without prescribed joints runs inside the compiled network kernel (a
TREE block of :mod:`soroshapes.network`, integrated by :mod:`soroshapes.integrate`); otherwise the network's
Python path. The controllers of :mod:`soroshapes.control` drive the block over the whole tree (the block's
``beam_view``); :meth:`Tree.statics` solves :math:`Kq = f_g + Bu + f_{ext}` by the one Newton with load stepping.
:meth:`Tree.inverse_kinematics` runs the beam's damped least-squares iterations
(:func:`soroshapes.beam.damped_least_squares`) on the tree Jacobians.

Units: SI (m, kg, s, N, rad).

Example
-------
A beam on the tip of another beam:

>>> import numpy as np
>>> from sorofem import sdf, materials
>>> from soroshapes import Basis, Shapes
>>> from soroshapes.tree import Tree
>>> rod = lambda: Shapes(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
...                      material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), damping=0.0)
>>> tree = Tree().add_beam("upper", rod()).add_beam("lower", rod(), parent="upper")
>>> tree.n
8
>>> bool(np.allclose(tree.frame(np.zeros(8), "lower")[:3, 3], [0.2, 0, 0]))
True
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sorofem._lazy import moved_attributes
from sorofem.errors import DataError, ParameterError

from .trajectory import Trajectory

__all__ = ["Tree", "TreeData", "TreeEquilibrium", "spin", "kinematics", "dynamics",
           "inverse_dynamics", "accelerations"]
#: one trajectory type for beams, trees and networks (README.md, "Moved names")
__getattr__ = moved_attributes(__name__, {"TreeTrajectory": "soroshapes.trajectory.Trajectory"})

_JOINTS = ("fixed", "revolute", "prismatic")
_NO_NODES, _NO_WRENCH, _NO_FLAGS = np.zeros(0, dtype=np.int64), np.zeros((0, 6)), np.zeros(0, dtype=np.bool_)


def _pose(g, what):
    g = np.asarray(np.eye(4) if g is None else g, dtype=float)
    if g.shape != (4, 4) or not np.all(np.isfinite(g)):
        raise ParameterError(f"{what} must be a finite (4, 4) homogeneous pose, got shape {g.shape}")
    R = g[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0 or \
            not np.allclose(g[3], [0, 0, 0, 1]):
        raise ParameterError(f"{what} must be a pose [[R, p], [0, 1]] with R orthonormal, det +1 (build R with "
                             "soroshapes.lie.expSO3)")
    return np.ascontiguousarray(g)


def spin(rate, angle=0.0):
    r"""The prescribed motion of a joint turning at a constant ``rate`` [rad/s] from ``angle`` [rad]: a function
    of t [s] giving :math:`(\theta, \dot\theta, \ddot\theta)`."""
    rate, angle = float(rate), float(angle)
    return lambda t: (angle + rate * t, rate, 0.0)


@dataclass(frozen=True, eq=False)
class _Body:
    """One body of a tree (see :class:`Tree`): rows ``row0 .. row0 + rows`` of the stacked frames, columns
    ``col0 .. col0 + ncols`` of q."""

    name: str
    kind: str                 # "beam" or "link"
    parent: int               # body index, -1 for the world
    parent_row: int           # the stacked frame it hangs from, -1 for the world
    offset: np.ndarray
    col0: int
    ncols: int
    row0: int
    rows: int
    model: object = None      # BeamModel of a beam
    tau: float = 0.0          # Kelvin-Voigt damping time of a beam [s]
    inputs: np.ndarray = None  # (ncols, m_b) input columns of a beam
    input_names: tuple = ()
    joint: str = "fixed"
    screw: np.ndarray = field(default_factory=lambda: np.zeros(6))
    com_frame: object = None  # (4, 4) principal centre-of-mass frame of a massive link
    inertia: np.ndarray = field(default_factory=lambda: np.zeros(6))  # (I1, I2, I3, m, m, m)
    stiffness: float = 0.0
    damping: float = 0.0
    actuated: bool = False
    motion: object = None


class Tree:
    r"""A tree of beams and rigid links (see the module docstring). Builders return ``self``.

    Parameters
    ----------
    gravity : (3,) spatial acceleration [m/s^2], optional (default none; :meth:`add_gravity`).
    """

    def __init__(self, gravity=None):
        self._bodies = []
        self._index = {}
        self._n = 0
        self._stacked = 0
        self.gravity = np.zeros(3) if gravity is None else self._vec3(gravity, "gravity")
        self._frozen = None

    # ------------------------------------------------------------------------------------------------
    # building
    # ------------------------------------------------------------------------------------------------
    @staticmethod
    def _vec3(v, what):
        v = np.asarray(v, dtype=float).reshape(-1)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ParameterError(f"{what} must be 3 finite numbers, got {v!r}")
        return v

    def _new_name(self, name):
        name = str(name)
        if name in self._index:
            raise ParameterError(f"a body named {name!r} is already in the tree; give each body its own name")
        return name

    def _parent(self, parent, at):
        """(parent index, stacked row of the parent frame) of a new body."""
        if parent is None:
            if at is not None:
                raise ParameterError("at= places a body on a parent beam; give parent= too")
            return -1, -1
        if parent not in self._index:
            raise ParameterError(f"no body named {parent!r} in the tree (bodies: {', '.join(self._index) or 'none'}); "
                                 "add the parent first")
        p = self._index[parent]
        b = self._bodies[p]
        if b.kind == "beam":
            return p, b.row0 + b.model.node(at) * b.model.stride
        if at is not None:
            raise ParameterError(f"{parent!r} is a rigid link: a child hangs from its frame (use offset=, not at=)")
        return p, b.row0

    def add_beam(self, name, beam, *, parent=None, at=None, offset=None, damping=None):
        r"""Add a beam whose base frame is the parent frame times ``offset`` (4 x 4, default identity) times the
        beam's own ``base``.

        Parameters
        ----------
        name : str
        beam : :class:`~soroshapes.shapes.Shapes` (its model, damping and input terms: chambers and linear
            actuators) or :class:`~soroshapes.beam.BeamModel` (no inputs).
        parent : name of a body added before (None: the world).
        at : arc length [m] of the parent beam's node it hangs from (None: the tip).
        damping : Kelvin-Voigt time constant [s] (default: the Shapes' own, 0 for a BeamModel).
        """
        from . import beam as bm
        name = self._new_name(name)
        pidx, prow = self._parent(parent, at)
        off = _pose(offset, "offset")
        if isinstance(beam, bm.BeamModel):
            model, tau, loads = beam, 0.0, ()
        elif isinstance(getattr(beam, "model", None), bm.BeamModel):
            model, tau, loads = beam.model, beam.damping, beam.loads
        else:
            raise ParameterError(f"beam must be a Shapes or a BeamModel, got {type(beam).__name__}")
        tau = tau if damping is None else float(damping)
        if not (math.isfinite(tau) and tau >= 0):
            raise ParameterError(f"damping must be a time constant >= 0 [s], got {tau!r}")
        terms = bm.input_terms(loads)
        other = [type(ld).__name__ for ld in loads if not ld.inputs]
        if other:
            raise ParameterError(f"beam {name!r} carries load terms a tree does not take over ({', '.join(other)}): "
                                 "gravity is the tree's (Tree(gravity=...) or tree.add_gravity()); mount a beam "
                                 "without them (a tree takes a beam's chambers and linear actuators)")
        for ld in terms:
            if getattr(ld, "configuration_dependent", True):
                raise ParameterError(f"input {ld.name!r} of beam {name!r} depends on the configuration (a tendon): "
                                     "a tree takes chambers and linear actuators only")
        B = bm.input_map(model, model.make_data(), loads, np.zeros(model.n)) if terms else np.zeros((model.n, 0))
        body = _Body(name=name, kind="beam", parent=pidx, parent_row=prow, offset=off, col0=self._n,
                     ncols=model.n, row0=self._stacked, rows=model.points.shape[0], model=model, tau=tau,
                     inputs=np.ascontiguousarray(B), input_names=tuple(f"{name}.{ld.name}" for ld in terms))
        return self._add(body)

    def add_link(self, name, mass=0.0, inertia=0.0, *, com=(0.0, 0.0, 0.0), parent=None, at=None, offset=None,
                 joint="fixed", axis=(0.0, 0.0, 1.0), stiffness=0.0, damping=0.0, actuated=False, motion=None):
        r"""Add a rigid link: frame = parent frame x ``offset`` x :math:`\exp(\hat\xi\theta)`.

        Parameters
        ----------
        name : str
        mass : float [kg] (0: a massless connector).
        inertia : float, (3,) or (3, 3) [kg m^2], about the centre of mass in link axes (a float: a sphere-like
            isotropic inertia; (3,): principal moments along the link axes).
        com : (3,) centre of mass [m] in link axes.
        parent, at, offset : as in :meth:`add_beam`.
        joint : ``"fixed"``, ``"revolute"`` (coordinate [rad]) or ``"prismatic"`` (coordinate [m]).
        axis : (3,) the joint axis in the offset frame (normalized here).
        stiffness, damping : joint spring [N m/rad or N/m] and damper [N m s/rad or N s/m] (about 0).
        actuated : the joint gets an input (torque [N m] or force [N]).
        motion : callable t -> (theta, theta_dot, theta_ddot): a prescribed coordinate (e.g. :func:`spin`).
        """
        name = self._new_name(name)
        pidx, prow = self._parent(parent, at)
        off = _pose(offset, "offset")
        if joint not in _JOINTS:
            raise ParameterError(f"joint must be one of {_JOINTS}, got {joint!r}")
        a = self._vec3(axis, "axis")
        if joint != "fixed":
            if np.linalg.norm(a) == 0:
                raise ParameterError("axis must be a non-zero 3-vector")
            a = a / np.linalg.norm(a)
        screw = np.zeros(6)
        if joint == "revolute":
            screw[:3] = a
        elif joint == "prismatic":
            screw[3:] = a
        if motion is not None and (joint == "fixed" or not callable(motion)):
            raise ParameterError("motion= prescribes a revolute or prismatic joint: give a callable t -> (theta, "
                                 "theta_dot, theta_ddot)")
        stiffness, damping = float(stiffness), float(damping)
        if not (math.isfinite(stiffness) and math.isfinite(damping) and stiffness >= 0 and damping >= 0):
            raise ParameterError(f"a joint's stiffness and damping must be finite and >= 0, got {stiffness!r}, "
                                 f"{damping!r}")
        if (actuated or stiffness or damping) and joint == "fixed":
            raise ParameterError("a fixed joint has no coordinate: actuated, stiffness and damping need a revolute "
                                 "or prismatic joint")
        mass = float(mass)
        I = np.asarray(inertia, dtype=float)
        I = np.eye(3) * I if I.ndim == 0 else (np.diag(I) if I.shape == (3,) else I)
        if I.shape != (3, 3) or not np.all(np.isfinite(I)) or not math.isfinite(mass) or mass < 0:
            raise ParameterError("mass must be >= 0 [kg] and inertia a float, (3,) or (3, 3) [kg m^2]")
        I = 0.5 * (I + I.T)
        lam, R = np.linalg.eigh(I)
        if lam[0] < -1e-12 * max(1.0, abs(lam[-1])):
            raise ParameterError(f"inertia must be positive semi-definite, got eigenvalues {lam}")
        if np.linalg.det(R) < 0:
            R[:, 0] *= -1
        massive = mass > 0 or lam[-1] > 0
        com_frame = None
        if massive:
            com_frame = np.eye(4)
            com_frame[:3, :3], com_frame[:3, 3] = R, self._vec3(com, "com")
        nc = 0 if joint == "fixed" else 1
        body = _Body(name=name, kind="link", parent=pidx, parent_row=prow, offset=off, col0=self._n, ncols=nc,
                     row0=self._stacked, rows=2 if massive else 1, joint=joint, screw=screw, com_frame=com_frame,
                     inertia=np.concatenate([np.maximum(lam, 0.0), [mass] * 3]), stiffness=float(stiffness),
                     damping=float(damping), actuated=bool(actuated), motion=motion)
        return self._add(body)

    def add_gravity(self, g=(0.0, 0.0, -9.81)):
        """Uniform gravity: spatial acceleration ``g`` [m/s^2] (default 9.81 along -z); replaces an earlier one."""
        self.gravity = self._vec3(g, "gravity")
        return self

    def _add(self, body):
        self._index[body.name] = len(self._bodies)
        self._bodies.append(body)
        self._n += body.ncols
        self._stacked += body.rows
        self._frozen = None
        return self

    # ------------------------------------------------------------------------------------------------
    # the frozen arrays
    # ------------------------------------------------------------------------------------------------
    def _arrays(self):
        """Quadrature weights (R,), inertia (R, 6), K, D (n, n), B (n, m), input names, prescribed indices."""
        if self._frozen is None:
            n, R = self._n, self._stacked
            w, Md = np.zeros(R), np.zeros((R, 6))
            K, D = np.zeros((n, n)), np.zeros((n, n))
            cols, names = [], []
            for b in self._bodies:
                s = slice(b.col0, b.col0 + b.ncols)
                if b.kind == "beam":
                    w[b.row0:b.row0 + b.rows] = b.model.weights
                    Md[b.row0:b.row0 + b.rows] = b.model.Md
                    K[s, s], D[s, s] = b.model.K, b.tau * b.model.K
                    for j in range(b.inputs.shape[1]):
                        c = np.zeros(n)
                        c[s] = b.inputs[:, j]
                        cols.append(c)
                    names += list(b.input_names)
                else:
                    if b.com_frame is not None:
                        w[b.row0 + 1], Md[b.row0 + 1] = 1.0, b.inertia
                    if b.ncols:
                        K[b.col0, b.col0], D[b.col0, b.col0] = b.stiffness, b.damping
                    if b.actuated:
                        c = np.zeros(n)
                        c[b.col0] = 1.0
                        cols.append(c)
                        names.append(f"{b.name}.{'torque' if b.joint == 'revolute' else 'force'}")
            Bu = np.column_stack(cols) if cols else np.zeros((n, 0))
            pres = np.array([b.col0 for b in self._bodies if b.motion is not None], dtype=np.int64)
            free = np.setdiff1d(np.arange(n), pres)
            self._frozen = (w, Md, K, D, np.ascontiguousarray(Bu), tuple(names), pres, free)
        return self._frozen

    @property
    def n(self):
        """Number of generalized coordinates."""
        return self._n

    @property
    def bodies(self):
        """Body names in the order they were added."""
        return tuple(self._index)

    @property
    def weights(self):
        """Quadrature weights (R,) of the stacked frames [m for a beam's points, 1 for a link's centre of mass, 0
        for frames without inertia]."""
        return self._arrays()[0]

    @property
    def inertias(self):
        """Diagonal inertia (R, 6) of the stacked frames (per unit length for a beam's points): (I1, I2, I3, m, m,
        m) [kg m^2, kg]."""
        return self._arrays()[1]

    @property
    def K(self):
        """Stiffness matrix (n, n), block diagonal."""
        return self._arrays()[2]

    @property
    def D(self):
        """Damping matrix (n, n), block diagonal."""
        return self._arrays()[3]

    @property
    def input_matrix(self):
        """B (n, m): generalized force per unit input."""
        return self._arrays()[4]

    @property
    def inputs(self):
        """Input names, in the order of u (``"<body>.<chamber or actuator>"``, ``"<link>.torque"``/``".force"``)."""
        return self._arrays()[5]

    @property
    def prescribed(self):
        """Indices of the prescribed coordinates in q."""
        return self._arrays()[6]

    def coordinates(self, body):
        """The slice of ``body``'s coordinates in q."""
        b = self._body(body)
        return slice(b.col0, b.col0 + b.ncols)

    def body_model(self, body):
        """The :class:`~soroshapes.beam.BeamModel` of a beam body."""
        b = self._body(body)
        if b.kind != "beam":
            raise ParameterError(f"{body!r} is a rigid link, not a beam")
        return b.model

    def _body(self, body):
        if body not in self._index:
            raise ParameterError(f"no body named {body!r} (bodies: {', '.join(self._index)})")
        return self._bodies[self._index[body]]

    def row(self, body, at=None):
        """Row of the stacked frames of ``body``'s node at arc length ``at`` [m] (None: the tip), or of a
        link's frame."""
        b = self._body(body)
        if b.kind == "beam":
            return b.row0 + b.model.node(at) * b.model.stride
        if at is not None:
            raise ParameterError(f"{body!r} is a rigid link: it has one frame (no at=)")
        return b.row0

    def make_data(self):
        """A fresh workspace (:class:`TreeData`)."""
        return TreeData(self)

    def _data(self, data):
        if data is None:
            if getattr(self, "_default", None) is None or self._default.n != self._n \
                    or self._default.G.shape[0] != self._stacked:
                self._default = self.make_data()
            return self._default
        return data

    # ------------------------------------------------------------------------------------------------
    # friendly queries (thin wrappers over the functions below)
    # ------------------------------------------------------------------------------------------------
    def frame(self, q, body, at=None, *, data=None):
        """World pose (4, 4) of ``body``'s node at arc length ``at`` [m] (None: the tip) or of a link's frame."""
        data = self._data(data)
        kinematics(self, data, q)
        return data.G[self.row(body, at)].copy()

    def frames(self, q, body, *, data=None):
        """World poses (N+1, 4, 4) of every node of a beam body."""
        data = self._data(data)
        kinematics(self, data, q)
        b = self._body(body)
        if b.kind != "beam":
            return data.G[b.row0:b.row0 + 1].copy()
        return data.G[b.row0:b.row0 + b.rows:b.model.stride].copy()

    def jacobian(self, q, body, at=None, frame="body", *, data=None):
        r"""Tree Jacobian (6, n) of the frame of :meth:`frame`: ``"body"`` (twist in the frame's axes) or
        ``"spatial"`` (:math:`\mathrm{Ad}_g J`, the spatial twist); angular part first."""
        from .lie import Ad
        data = self._data(data)
        kinematics(self, data, q)
        i = self.row(body, at)
        if frame == "body":
            return data.J[i].copy()
        if frame == "spatial":
            return Ad(data.G[i]) @ data.J[i]
        raise ParameterError(f"frame must be 'body' or 'spatial', got {frame!r}")

    def jacobian_rate(self, q, qd, body, at=None, *, data=None):
        r"""Time derivative :math:`\dot J` (6, n) of the body Jacobian of :meth:`jacobian` along the rates ``qd``
        (so that the frame's body acceleration is :math:`J\ddot q + \dot J\dot q`)."""
        data = self._data(data)
        kinematics(self, data, q, qd, rate=True)
        return data.Jd[self.row(body, at)].copy()

    def mass_matrix(self, q, *, data=None):
        """M(q) (n, n) [kg, kg m, kg m^2 per coordinates]."""
        return dynamics(self, self._data(data), q, None, want_c=False)[0].copy()

    def coriolis(self, q, qd, *, data=None):
        r"""The Coriolis matrix C(q, qd) (n, n), :math:`\dot M - 2C` skew."""
        return dynamics(self, self._data(data), q, qd)[1].copy()

    def gravity_force(self, q, *, data=None):
        """Generalized gravity force f_g(q) (n,)."""
        return dynamics(self, self._data(data), q, None, want_c=False)[2].copy()

    def generalized_force(self, q, qd=None, t=0.0, u=None, *, data=None):
        r"""Every generalized force but inertia: :math:`f_g + Bu - C\dot q - D\dot q - Kq` (n,)."""
        data = self._data(data)
        q, qd = _state(self, q), _state(self, qd, "qd")
        M, C, fg = dynamics(self, data, q, qd)
        return fg + self._input_force(u, t) - C @ qd - self.D @ qd - self.K @ q

    def _input_force(self, u, t):
        B = self.input_matrix
        if u is None:
            return np.zeros(self._n)
        v = np.asarray(u(t) if callable(u) else u, dtype=float).reshape(-1)
        if v.shape != (B.shape[1],) or not np.all(np.isfinite(v)):
            raise ParameterError(f"u must give {B.shape[1]} finite inputs ({', '.join(self.inputs)}), got {v.shape}")
        return B @ v

    def inverse_dynamics(self, q, qd, qdd, *, data=None):
        r""":math:`M\ddot q + C\dot q - f_g` (n,): the generalized force the inertia and gravity need."""
        return inverse_dynamics(self, self._data(data), q, qd, _state(self, qdd, "qdd"))

    def forward_dynamics(self, q, qd, t=0.0, u=None, f_ext=None, *, data=None):
        r"""Accelerations (n,) (see :func:`accelerations`)."""
        return accelerations(self, self._data(data), q, qd, t, u, f_ext)

    def base_wrench(self, q, qd, qdd, body, *, data=None):
        r"""The wrench (moment [N m], force [N]) (6,) that the parent exerts on ``body`` and everything hanging
        from it, in the body's frame (a beam's base node, a link's frame after its joint), for the motion
        (q, qd, qdd) under gravity:

        .. math:: W_b = \sum_{i \in \text{subtree}} w_i\,\mathrm{Ad}_{g_i^{-1}g_b}^T \big(\mathcal M_i(J_i\ddot q
                  + \dot J_i\dot q) - \mathrm{ad}_{\eta_i}^T\mathcal M_i\eta_i - \mathcal M_i(0, R_i^Ta_g)\big)

        (the subtree's free-body diagram: inertia and gravity; the beams' elastic forces, chambers and the
        joints inside it are internal). A joint's effort is :math:`\xi^T W` of its link (the row of
        :meth:`inverse_dynamics`); the parent feels :math:`-W_b`."""
        from .lie import Ad, ad6, invSE3
        data = self._data(data)
        q, qd = kinematics(self, data, q, qd, True)
        qdd = _state(self, qdd, "qdd")
        b = self._body(body)
        idx = self._index[b.name]
        sub = {idx}
        for k, c in enumerate(self._bodies):
            if c.parent in sub:
                sub.add(k)
        w, Md = self._arrays()[:2]
        gb = data.G[b.row0]
        W = np.zeros(6)
        for k in sub:
            c = self._bodies[k]
            for i in range(c.row0, c.row0 + c.rows):
                if w[i] == 0.0:
                    continue
                e = data.eta[i]
                F = Md[i] * (data.J[i] @ qdd + data.Jd[i] @ qd) - ad6(e).T @ (Md[i] * e)
                F[3:] -= Md[i, 3:] * (data.G[i, :3, :3].T @ self.gravity)
                W += w[i] * Ad(invSE3(data.G[i]) @ gb).T @ F
        return W

    def energy(self, q, qd=None, *, data=None):
        """Energies [J]: dict with kinetic, elastic (beams and joint springs), gravity, total."""
        data = self._data(data)
        q = _state(self, q)
        qd = _state(self, qd, "qd")
        M = dynamics(self, data, q, qd, want_c=False)[0]
        w, Md = self._arrays()[:2]
        kin = 0.5 * qd @ M @ qd
        el = 0.5 * q @ self.K @ q
        grav = -float(np.sum(w * Md[:, 3] * (data.G[:, :3, 3] @ self.gravity)))
        return {"kinetic": kin, "elastic": el, "gravity": grav, "total": kin + el + grav}

    def inverse_kinematics(self, targets, q0=None, *, tol=1e-8, max_iterations=200, damping=1e-6,
                           rotation_weight=None, subtask=None, subtask_gain=0.1, data=None):
        r"""Damped least-squares inverse kinematics over all the tree's coordinates (the beam's algorithm,
        :func:`soroshapes.beam.damped_least_squares`, on the tree Jacobians).

        Parameters
        ----------
        targets : list of ``(body, at, target)``: ``at`` the arc length [m] of a beam node (None: the tip; None
            for a link), ``target`` a (3,) position [m] or a (4, 4) pose (its error :math:`\log(g^{-1}g^*)`, the
            angular part weighted by ``rotation_weight`` [m], default the longest beam).
        q0 : (n,) start (default zeros).
        subtask : None, ``"elastic"`` (null-space descent of the elastic energy, gradient :math:`Kq`) or a
            callable q -> (n,) gradient; ``subtask_gain`` scales its step to the task step.

        Returns
        -------
        :class:`~soroshapes.beam.IKResult` (``error`` the final error norm [m]).
        """
        from sorofem.errors import ConvergenceError

        from . import _beam
        from .beam import IKResult, damped_least_squares
        data = self._data(data)
        q = _state(self, q0, "q0").copy()
        rows, kinds, goals = [], [], []
        for body, at, v in targets:
            rows.append(self.row(body, at))
            v = np.asarray(v, dtype=float)
            if v.shape == (3,):
                g = np.eye(4)
                g[:3, 3] = v
                kinds.append(0)
            elif v.shape == (4, 4):
                g = _pose(v, "a pose target")
                kinds.append(1)
            else:
                raise ParameterError(f"a target must be a (3,) position or a (4, 4) pose, got shape {v.shape}")
            goals.append(g)
        if not rows:
            raise ParameterError("give at least one target (body, at, position or pose)")
        rows, kinds, goals = np.array(rows, dtype=np.int64), np.array(kinds, dtype=np.int64), np.array(goals)
        lengths = [b.model.length for b in self._bodies if b.kind == "beam"]
        wrot = float(rotation_weight) if rotation_weight is not None else max(lengths, default=1.0)
        if subtask == "elastic":
            grad = lambda x: self.K @ x                                     # noqa: E731
        elif subtask is None or callable(subtask):
            grad = subtask
        else:
            raise ParameterError("subtask must be 'elastic', a callable grad(q) -> (n,), or None")
        m = int(sum(3 if k == 0 else 6 for k in kinds))
        e, A = np.empty(m), np.empty((m, self._n))

        def error(x):
            kinematics(self, data, x)
            return _beam._ik_error(rows, kinds, goals, wrot, data.G, data.J, e, A), e.copy(), A.copy()
        err, it = damped_least_squares(error, q, float(tol), int(max_iterations), float(damping),
                                       1e6 * max(lengths, default=1.0), grad, subtask_gain)
        if not (math.isfinite(err) and np.all(np.isfinite(q))):
            raise ConvergenceError("inverse_kinematics: the iterations left the finite range; give a closer q0 or a "
                                   "reachable target")
        return IKResult(q=q, error=float(err), iterations=int(it), converged=bool(err < tol))

    # ------------------------------------------------------------------------------------------------
    # statics
    # ------------------------------------------------------------------------------------------------
    def statics(self, u=None, q0=None, *, f_ext=None, t=0.0, steps=1, tol=1e-9, max_iterations=40, min_step=1e-4,
                data=None):
        r"""Static equilibrium :math:`Kq = f_g(q) + Bu + f_{ext}(q)` of the free coordinates (the prescribed
        ones held at their motion's value at ``t``) by the Newton solver with load stepping of every static
        problem (:func:`soroshapes.beam.newton_load_stepping`; gravity, inputs and ``f_ext`` ramped together).

        Parameters
        ----------
        u : (m,) inputs (:attr:`inputs`) or a callable of t; None: zeros.
        q0 : (n,) start (default zeros; the prescribed entries are overwritten).
        f_ext : callable (q, t) -> (n,) generalized force [N m per coordinate], or None.
        steps, tol, max_iterations, min_step : as in :func:`~soroshapes.beam.newton_load_stepping`.

        Returns
        -------
        :class:`TreeEquilibrium`
        """
        from .beam import newton_load_stepping
        data = self._data(data)
        q = _state(self, q0, "q0").copy()
        free = self._arrays()[7]
        for b in self._bodies:
            if b.motion is not None:
                q[b.col0] = float(b.motion(t)[0])
        if not len(free):
            raise ParameterError("statics: every coordinate is prescribed; nothing to solve")
        fu = self._input_force(u, t)
        K = self.K
        Kf = K[np.ix_(free, free)]
        kmax = float(np.abs(np.diag(Kf)).max())
        if kmax <= 0.0:
            raise ParameterError("statics: the free coordinates have no stiffness (joints without springs only): "
                                 "give a joint stiffness= or prescribe it")

        def aug(x, scale):
            qq = q.copy()
            qq[free] = x
            try:
                fg = dynamics(self, data, qq, None, want_c=False)[2]
            except DataError:                    # an iterate left the finite range: the line search backs off
                return np.full(len(free), np.nan)
            f = fg + fu
            if f_ext is not None:
                fe = np.asarray(f_ext(qq, t), dtype=float).reshape(-1)
                if fe.shape != (self._n,) or not np.all(np.isfinite(fe)):
                    raise DataError(f"f_ext returned {fe.shape} / non-finite values; expected {self._n} finite")
                f = f + fe
            return (K @ qq - scale * f)[free]
        lengths = [b.model.length for b in self._bodies if b.kind == "beam"]
        x, its, _ = newton_load_stepping(aug, q[free].copy(), len(free), lambda y: Kf @ y, kmax,
                                         max(lengths, default=1.0), steps=steps, tol=tol,
                                         max_iterations=max_iterations, min_step=min_step)
        q[free] = x
        r = aug(x, 1.0)
        return TreeEquilibrium(q=q, iterations=list(its), residual=float(np.linalg.norm(r)))

    # ------------------------------------------------------------------------------------------------
    # simulation with the Model integrators
    # ------------------------------------------------------------------------------------------------
    def _full(self, t, qf, vf):
        """(q, qd, qdd of the prescribed) from the free coordinates and rates at time t."""
        free = self._arrays()[7]
        q, qd, a = np.zeros(self._n), np.zeros(self._n), np.zeros(self._n)
        q[free], qd[free] = qf, vf
        for b in self._bodies:
            if b.motion is not None:
                q[b.col0], qd[b.col0], a[b.col0] = (float(v) for v in b.motion(t))
        return q, qd, a, free

    def system(self, u=None, f_ext=None, name="tree", q0=None, qd0=None, *, data=None, compiled=True,
               controlled=None, force_inputs=False):
        r"""A :class:`~soroshapes.model.StateSpace` block of the free coordinates: state
        :math:`x = (q_f, \dot q_f)`, :math:`\dot x = (\dot q_f, \ddot q_f)` from :func:`accelerations`. ``u``:
        the inputs (:attr:`inputs`) as an array or a callable of t; None makes them the block's inputs, which
        couplings and controllers of a :class:`~soroshapes.model.Model` drive (zeros when unconnected).
        ``f_ext``: callable (q, qd, t) -> (n,) generalized force, or None. The prescribed coordinates follow
        their motions (:meth:`state` rebuilds the full q, qd). ``compiled``: the accelerations by one compiled
        call over the whole tree (:func:`soroshapes._treeblock.tree_rhs`, the same equations); False: by
        :func:`accelerations` (a compiled call per body). A compiled block of a tree without prescribed joints,
        ``f_ext`` and Python ``u`` also runs inside the compiled network kernel (:mod:`soroshapes.network`, one
        tree block per network; :meth:`Model.simulate <soroshapes.model.Model.simulate>` picks it).

        The controllers of :mod:`soroshapes.control` drive the block as they drive a beam, over the whole
        tree: its coordinates q (n,), K, f_g, M, C, the input matrix B, and, for :func:`~soroshapes.control.impedance`,
        the frames of the body ``controlled`` (default the body added last; ``at`` an arc length on it) with
        their tree Jacobians (the block's ``beam_view``; a tree with prescribed joints has none).

        ``force_inputs``: append n inputs, a generalized force (n,) added to the equations (named ``"force<i>"``,
        i the coordinate), which a coupling of the network drives (contact with another block,
        :func:`soroshapes.rigid.couple_tree_contact`): unlike ``f_ext``, the network's Jacobian then sees how it
        depends on the other blocks' states. The compiled tree block runs them too: the network's compiled contact
        terms put their forces on the tree themselves (:func:`soroshapes.rigid.couple_tree_contact` with an SDF
        that has a program form)."""
        from .model import StateSpace
        data = self._data(data)
        free = self._arrays()[7]
        nf = len(free)
        m = 0 if u is not None else len(self.inputs)
        k = self._n if force_inputs else 0
        if compiled:
            from . import _treeblock
            low = _treeblock.lower(self)
            n, nu = self._n, len(self.inputs)
            acc, zero_u, zero_f = np.zeros(n), np.zeros(nu), np.zeros(n)

            def f(x, uu, t):
                q, qd, a, _ = self._full(t, x[:nf], x[nf:])
                v = uu[:m] if m else u
                v = zero_u if v is None else np.asarray(v(t) if callable(v) else v, dtype=float).reshape(-1)
                if v.shape != (nu,) or not np.all(np.isfinite(v)):
                    raise ParameterError(f"u must give {nu} finite inputs ({', '.join(self.inputs)}), got {v.shape}")
                fe = np.asarray(uu[m:m + k], dtype=float) if k else zero_f
                if f_ext is not None:
                    fx = np.asarray(f_ext(q, qd, t), dtype=float).reshape(-1)
                    if fx.shape != (n,) or not np.all(np.isfinite(fx)):
                        raise DataError(f"f_ext returned {fx.shape} / non-finite values; expected {n} finite")
                    fe = fe + fx
                if not _treeblock.tree_rhs(*low.args, q, qd, a, v, fe, acc):
                    raise DataError("the tree's accelerations are not finite, or the mass matrix of the free "
                                    "coordinates is singular (a joint moving a massless chain, or an overflowed "
                                    "state: use a smaller dt)")
                return np.concatenate([x[nf:], acc[free]])
        else:
            def f(x, uu, t):
                q, qd, _, _ = self._full(t, x[:nf], x[nf:])
                fe = f_ext
                if k:
                    fu = np.asarray(uu[m:m + k], dtype=float)
                    fe = (lambda qq, vv, tt: fu) if f_ext is None else (lambda qq, vv, tt: fu + f_ext(qq, vv, tt))
                return np.concatenate([x[nf:], accelerations(self, data, q, qd, t, uu[:m] if m else u, fe)[free]])
        x0 = np.zeros(2 * nf)
        if q0 is not None:
            x0[:nf] = _state(self, q0, "q0")[free]
        if qd0 is not None:
            x0[nf:] = _state(self, qd0, "qd0")[free]
        sysb = StateSpace(f, 2 * nf, m + k, name=name, x0=x0)
        if m + k:
            sysb.input_names = (list(self.inputs) if m else []) + [f"force{i}" for i in range(k)]
        if controlled is not None or not len(self.prescribed):
            if len(self.prescribed):
                raise ParameterError("controlled=: a tree with prescribed joints has no controller face (its state "
                                     "holds the free coordinates only); drop the motion= or control it yourself")
            sysb.beam_view = _ControlledFrame(self, self.bodies[-1] if controlled is None else controlled)
        if compiled and not len(self.prescribed) and f_ext is None and not callable(u):
            from . import _treeblock            # the block runs inside a compiled network (soroshapes.network)
            sysb.tree_block = _treeblock.block_args(self, None if m else u, force_inputs=bool(k))
        return sysb

    def state(self, t, x):
        """(q, qd) (n,) of the tree at time t from a state x of :meth:`system`."""
        nf = self._n - len(self.prescribed)
        q, qd, _, _ = self._full(t, x[:nf], x[nf:])
        return q, qd

    def simulate(self, t_end, dt, q0=None, qd0=None, u=None, *, f_ext=None, method="midpoint", rtol=1e-6,
                 atol=1e-9, record_every=1, data=None, compiled=True):
        r"""Integrate the tree from (``q0``, ``qd0``) (default rest) over ``t_end`` [s] with steps ``dt`` [s] by
        the implicit ``method`` of :meth:`Model.simulate <soroshapes.model.Model.simulate>` ("midpoint",
        "trapezoidal", "bdf2"; Newton to ``rtol``, ``atol``). ``compiled``: as in :meth:`system`. Returns a
        :class:`~soroshapes.trajectory.Trajectory` (``t``, ``q``, ``qd``, ``kinetic``, ``potential``, ``stats``)."""
        from .model import Model
        data = self._data(data)
        sysb = self.system(np.zeros(len(self.inputs)) if u is None else u, f_ext, "tree", q0, qd0, data=data,
                           compiled=compiled)
        traj = Model().add(sysb).simulate(t_end, dt, method=method, rtol=rtol, atol=atol,
                                          record_every=record_every)
        ts, xs = np.asarray(traj.t), np.asarray(traj["tree"].x)
        Q, QD = np.zeros((len(ts), self._n)), np.zeros((len(ts), self._n))
        kin, pot = np.zeros(len(ts)), np.zeros(len(ts))
        for k, (t, x) in enumerate(zip(ts, xs)):
            Q[k], QD[k] = self.state(t, x)
            e = self.energy(Q[k], QD[k], data=data)
            kin[k], pot[k] = e["kinetic"], e["elastic"] + e["gravity"]
        return Trajectory(ts, q=Q, qd=QD, kinetic=kin, potential=pot, stats=traj.stats)


class _ControlledFrame:
    r"""The face of a tree block that :mod:`soroshapes.control` reads from a beam (:meth:`Tree.system`): n, K,
    gravity, the input map (constant B), ``dynamics`` (M, C, f_g copies), and the stacked frames
    (``forward_kinematics``) with ``node(at)`` the row of the ``body``'s frame at ``at`` and its tree Jacobian
    and rate. A workspace of its own (a controller evaluates between the integrator's calls)."""

    def __init__(self, tree, body):
        tree._body(body)
        self.tree, self.body, self.data = tree, body, tree.make_data()
        self.n, self.K, self.gravity = tree.n, tree.K, tree.gravity

    def input_map(self, q):
        return self.tree.input_matrix

    def dynamics(self, q, qd):
        M, C, fg = dynamics(self.tree, self.data, q, qd)
        return M.copy(), C.copy(), fg.copy()

    def forward_kinematics(self, q):
        kinematics(self.tree, self.data, q)
        return self.data.G.copy()

    def node(self, at):
        return self.tree.row(self.body, at)

    def jacobian(self, q, at=None):
        return self.tree.jacobian(q, self.body, at, data=self.data)

    def jacobian_rate(self, q, qd, at=None):
        return self.tree.jacobian_rate(q, qd, self.body, at, data=self.data)


@dataclass
class TreeEquilibrium:
    """Result of :meth:`Tree.statics`: coordinates ``q`` (n,), Newton ``iterations`` per accepted load increment,
    and the norm of the force residual :math:`|Kq - f|_f` at the solution [N m per coordinate]."""

    q: np.ndarray
    iterations: list
    residual: float


class TreeData:
    """The workspace of a :class:`Tree`: after :func:`kinematics`, the stacked frames ``G`` (R, 4, 4), tree body
    Jacobians ``J`` (R, 6, n), twists ``eta`` (R, 6) and rates ``Jd``; after :func:`dynamics`, ``M``, ``C``,
    ``fg``. One :class:`~soroshapes.beam.BeamData` per beam holds its local kinematics. Make a new one after
    adding bodies."""

    def __init__(self, tree):
        n, R = tree.n, tree._stacked
        self.n = n
        self.G, self.J, self.Jd = np.zeros((R, 4, 4)), np.zeros((R, 6, n)), np.zeros((R, 6, n))
        self.eta, self.etad = np.zeros((R, 6)), np.zeros((R, 6))
        self.M, self.C, self.fg = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n)
        self.S, self.V, self.Y = np.zeros((6, 6, 6)), np.zeros((8, 6)), np.zeros((6, n))
        self.beams = {b.name: b.model.make_data() for b in tree._bodies if b.kind == "beam"}
        self.local = {b.name: (np.zeros((1, 4, 4)), np.zeros((1, 6, b.ncols)), np.zeros((1, 6, b.ncols)),
                               np.zeros((1, 6))) for b in tree._bodies if b.kind == "link"}
        self.eye = np.eye(4)[None].copy()
        self.none = (np.zeros((1, 6, 0)), np.zeros((1, 6)))
        self.world = (np.eye(4), np.zeros((6, n)), np.zeros((6, n)), np.zeros(6))
        # per body, in order: the parent frame's views, its own rows' views, its local arrays
        arrays = (self.G, self.J, self.Jd, self.eta)
        self.parents = [self.world if b.parent_row < 0 else tuple(a[b.parent_row] for a in arrays)
                        for b in tree._bodies]
        self.own, self.locals = [], []
        for b in tree._bodies:
            r0 = b.row0
            if b.kind == "beam":
                self.own.append((tuple(a[r0:r0 + b.rows] for a in arrays),))
                self.locals.append(self.beams[b.name])
            else:
                self.own.append((tuple(a[r0:r0 + 1] for a in arrays), tuple(a[r0] for a in arrays),
                                 tuple(a[r0 + 1:r0 + 2] for a in arrays)))
                loc = self.local[b.name]
                if b.ncols:
                    loc[1][0, :, 0] = b.screw
                self.locals.append(loc)


def _state(tree, q, what="q"):
    q = np.zeros(tree.n) if q is None else np.ascontiguousarray(q, dtype=float).reshape(-1)
    if q.shape != (tree.n,):
        raise ParameterError(f"{what} must have {tree.n} entries (the tree's coordinates), got {q.shape}")
    if not math.isfinite(np.add.reduce(q)) and not np.all(np.isfinite(q)):      # the sum: a cheap first test
        raise DataError(f"{what} contains NaN or inf")
    return q


def kinematics(tree, data, q, qd=None, rate=False):
    r"""Frames, tree body Jacobians, twists (and, with ``rate``, the Jacobian rates :math:`\dot J`) of every
    stacked frame into ``data``, body after body (parents first). Returns the validated (q, qd)."""
    from . import _beam, _tree
    from .lie import expSE3
    q, qd = _state(tree, q), _state(tree, qd, "qd")
    if data.n != tree.n or data.G.shape[0] != tree._stacked:
        raise ParameterError("the workspace was made before bodies were added: make a new one (tree.make_data())")
    for b, parent, own, loc in zip(tree._bodies, data.parents, data.own, data.locals):
        if b.kind == "beam":
            m, d = b.model, loc
            s = slice(b.col0, b.col0 + b.ncols)
            _beam.kinematics(q[s], qd[s], rate, m.order, m.h, m.B, m.rows, m.X0, m.base, d.G, d.J, d.Jd, d.eta, d.S,
                             d.E, d.V, d.Op, d.dOp, d.AJ)
            _tree.attach(*parent, b.offset, d.G, d.J, d.Jd, d.eta, b.col0, rate, *own[0])
        else:
            Gl, Jl, Jdl, etal = loc
            th, thd = (q[b.col0], qd[b.col0]) if b.ncols else (0.0, 0.0)
            Gl[0] = expSE3(b.screw * th)
            etal[0] = b.screw * thd
            _tree.attach(*parent, b.offset, Gl, Jl, Jdl, etal, b.col0, rate, *own[0])
            if b.com_frame is not None:
                zJ, zeta = data.none
                _tree.attach(*own[1], b.com_frame, data.eye, zJ, zJ, zeta, 0, rate, *own[2])
    if not (math.isfinite(data.G[:, :3, 3].sum()) and math.isfinite(data.J.sum())):
        raise DataError(f"the state (max |q| = {np.max(np.abs(q)):.3g}) makes the frames overflow: give a "
                        "physically meaningful state (|strain| of order 1/length)")
    return q, qd


def dynamics(tree, data, q, qd=None, want_c=True):
    r"""(M, C, f_g) of the tree at (q, qd) (see the module docstring; C zero unless ``want_c``), summed by the
    beam's compiled kernel over the stacked frames. The arrays live in ``data``."""
    from . import _beam
    q, qd = kinematics(tree, data, q, qd, want_c)
    w, Md = tree._arrays()[:2]
    _beam.mass_coriolis_gravity(data.J, data.Jd, data.eta, data.G, w, Md, tree.gravity, data.M, data.C, data.fg,
                                want_c, data.S, data.V, data.Y)
    if not want_c:
        data.C[...] = 0.0
    return data.M, data.C, data.fg


def inverse_dynamics(tree, data, q, qd, qdd, mass=False):
    r""":math:`M\ddot q + C\dot q - f_g` (n,) matrix-free: one kinematic pass with the Jacobian rates, then the
    beam's compiled :func:`soroshapes._beam.generalized_inertial_force` over the stacked frames with
    :math:`\dot J_i\dot q`; with ``mass``, also M into ``data.M`` from the same pass (no C is formed)."""
    from . import _beam
    q, qd = kinematics(tree, data, q, qd, True)
    w, Md = tree._arrays()[:2]
    np.matmul(data.Jd, qd, out=data.etad)
    out = np.empty(tree.n)
    _beam.generalized_inertial_force(data.J, data.eta, data.etad, data.G, w, Md, qdd, tree.gravity, _NO_NODES,
                                     _NO_WRENCH, _NO_FLAGS, out)
    if mass:
        _beam.mass_coriolis_gravity(data.J, data.Jd, data.eta, data.G, w, Md, tree.gravity, data.M, data.C,
                                    data.fg, False, data.S, data.V, data.Y)
    return out


def accelerations(tree, data, q, qd, t=0.0, u=None, f_ext=None):
    r"""Accelerations :math:`\ddot q` (n,) of :math:`M\ddot q = f_g + Bu + f_{ext} - C\dot q - D\dot q - Kq`; the
    prescribed coordinates take their motion's acceleration (their values in q, qd are overwritten by the
    motion at ``t``) and the others solve :math:`M_{ff}\ddot q_f = (\dots)_f - M_{fp}\ddot q_p` (the
    right-hand side from :func:`inverse_dynamics` at the prescribed accelerations, matrix-free; M from the same
    pass). ``f_ext``: callable (q, qd, t) -> (n,) or None."""
    q, qd = _state(tree, q), _state(tree, qd, "qd")
    pres = tree.prescribed
    a = np.zeros(tree.n)
    if len(pres):
        q, qd = q.copy(), qd.copy()
        for b in tree._bodies:
            if b.motion is not None:
                q[b.col0], qd[b.col0], a[b.col0] = (float(v) for v in b.motion(t))
    f = -inverse_dynamics(tree, data, q, qd, a, mass=True) - tree.D @ qd - tree.K @ q
    M = data.M
    if u is not None:
        f += tree._input_force(u, t)
    if f_ext is not None:
        fe = np.asarray(f_ext(q, qd, t), dtype=float).reshape(-1)
        if fe.shape != (tree.n,) or not np.all(np.isfinite(fe)):
            raise DataError(f"f_ext returned {fe.shape} / non-finite values; expected {tree.n} finite")
        f = f + fe
    try:
        if len(pres):
            free = tree._arrays()[7]
            a[free] = np.linalg.solve(M[np.ix_(free, free)], f[free])
        else:
            a = np.linalg.solve(M, f)
    except np.linalg.LinAlgError:
        raise DataError("the mass matrix of the free coordinates is singular: a joint moves a massless chain "
                        "(give the links mass or inertia, or prescribe the joint)") from None
    if not np.all(np.isfinite(a)):
        raise DataError("the accelerations are not finite (the state overflowed)")
    return a


def precompile():
    """Compile the tree kernels (:func:`soroshapes._tree.attach`, :mod:`soroshapes._treeblock`) and the beam kernels
    on the tree's arrays into numba's cache (a beam on a revolute link, one forward-dynamics evaluation, two
    steps in the compiled network). Returns the seconds it took."""
    import time
    from sorofem import materials, sdf
    from .basis import Basis
    from .shapes import Shapes
    t0 = time.perf_counter()
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 0, 0, 0, 0), length=0.05, section=sdf.Circle(0.004),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), segments=2, damping=0.0)
    tree = Tree(gravity=(0.0, 0.0, -9.81)).add_link("hub", 0.01, 1e-6, joint="revolute").add_beam("b", shp,
                                                                                                   parent="hub")
    q = np.full(tree.n, 0.1)
    tree.forward_dynamics(q, q)
    tree.coriolis(q, q)
    tree.simulate(2e-3, 1e-3)                   # the tree block of the compiled network (soroshapes._treeblock)
    return time.perf_counter() - t0
