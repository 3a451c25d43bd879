r"""Holonomic end constraints of a Cosserat beam, enforced with Lagrange multipliers.

A constraint holds a material frame :math:`g(s) = (R, p)` of the rod (``at`` = :math:`s` [m], a node; default the
tip) on a frame fixed in the world, in position (:class:`Pin`), orientation (:class:`Align`) or both
(:class:`Weld`). Its residual, the *drift*, is

.. math:: c_p = p(s) - p^* \ \text{[m]}, \qquad c_R = \log\!\left(R(s)\, R^{*T}\right)^\vee \ \text{[rad]},

and its exact Jacobian :math:`J_c = \partial c/\partial q` is :math:`R J_v` for the position and
:math:`J_l^{-1}(c_R)\, R J_\omega` for the orientation (:math:`J = (J_\omega, J_v)` the body Jacobian of the
node, :math:`J_l` the left Jacobian of SO(3)). Statics then solves, with the multipliers :math:`\lambda`,

.. math:: K q - f(q) - J_c(q)^T \lambda = 0, \qquad c(q) = 0,

by Newton's method on the bordered system :math:`\begin{bmatrix} K_t & -J_c^T \\ J_c & 0\end{bmatrix}` (the
tangent :math:`K_t` includes the geometric stiffness :math:`-\partial (J_c^T\lambda)/\partial q` of the reactions)
inside the load stepping of :func:`soroshapes.beam.statics`. At :math:`c = 0` the multipliers are the reaction
wrench that the constraint applies to the rod at the constrained point, in the world frame: a force [N] for the
position rows, a moment [N m] for the orientation rows.

Prescribed motion. The target is ramped with the load factor :math:`\Lambda \in [0, 1]` of the load stepping from
the frame :math:`(R_0, p_0)` the point has at the initial guess ``q0``: :math:`p^*(\Lambda) = p_0 +
\Lambda(p^* - p_0)` and :math:`R^*(\Lambda) = \exp(\Lambda\,\hat\phi)\, R_0`. The orientation target is either a
(3, 3) rotation (then :math:`\phi = \log(R^* R_0^T)`, an angle below :math:`\pi`) or a rotation vector
:math:`\phi` [rad] of any size applied in the world frame to :math:`R_0` (an end twist of several turns:
``Weld(rotation=(2.5 * np.pi, 0, 0))``). A target left at None holds the frame where it is at ``q0``.

Units: SI (m, rad, N, N m).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sorofem.errors import ParameterError

__all__ = ["Constraint", "Weld", "Pin", "Align", "ConstraintSet", "Equilibrium"]


@dataclass(frozen=True)
class Constraint:
    """A frame of the rod at arc length ``at`` [m] (a node; None: the tip) held on a world frame.

    Parameters
    ----------
    at : float [m] or None
    position : (3,) world position [m] of the point, or None (where it is at the initial guess).
    rotation : (3, 3) world orientation, or (3,) rotation vector [rad] applied in the world frame to the
        orientation at the initial guess, or None (hold the initial orientation).
    axes : sequence of "x", "y", "z" (position components) and "rx", "ry", "rz" (rotation components about the
        world axes), optional
        Hold only these world components (default all of the constraint's kind), e.g. ``("x", "y", "rz")``
        for a rod that bends in the x-y plane only.
    """

    at: object = None
    position: object = None
    rotation: object = None
    axes: object = None

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


@dataclass(frozen=True)
class _Bound:
    point: int          # row of the frame in the workspace arrays (node * stride)
    node: int
    sel: tuple          # held components among (x, y, z, rx, ry, rz)
    p0: np.ndarray
    dp: np.ndarray      # position increment at load factor 1 [m]
    R0: np.ndarray
    phi: np.ndarray     # world rotation vector at load factor 1 [rad]
    label: str


class ConstraintSet:
    """Constraints bound to a :class:`~soroshapes.beam.BeamModel`, with the frames held at the initial guess.

    Built by :meth:`soroshapes.shapes.Shapes.statics`; :func:`soroshapes.beam.statics` calls
    :meth:`residual` and :meth:`jacobian` on the kinematics held in a workspace.
    """

    def __init__(self, model, data, constraints, q0):
        from . import beam as _bm
        from .lie import logSO3
        constraints = list(constraints)
        if not constraints:
            raise ParameterError("constraints is empty; pass None for an unconstrained solve")
        _bm.kinematics(model, data, q0)
        bound = []
        for k, con in enumerate(constraints):
            if not isinstance(con, Constraint):
                raise ParameterError(f"constraint {k} is a {type(con).__name__}; use soroshapes.constraints."
                                     "Weld, Pin or Align")
            node = model.node(con.at)
            point = node * model.stride
            G = data.G[point]
            R0, p0 = G[:3, :3].copy(), G[:3, 3].copy()
            dp = np.zeros(3)
            if con.position is not None:
                p = np.asarray(con.position, dtype=float)
                if p.shape != (3,) or not np.all(np.isfinite(p)):
                    raise ParameterError(f"constraint {k}: position must be a finite (3,) world point [m]")
                dp = p - p0
            phi = np.zeros(3)
            if con.rotation is not None:
                r = np.asarray(con.rotation, dtype=float)
                if r.shape == (3, 3):
                    if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
                        raise ParameterError(f"constraint {k}: rotation must be orthonormal with det +1")
                    phi = logSO3(np.ascontiguousarray(r @ R0.T))
                elif r.shape == (3,) and np.all(np.isfinite(r)):
                    phi = r.copy()
                else:
                    raise ParameterError(f"constraint {k}: rotation must be a (3, 3) rotation or a (3,) rotation "
                                         "vector [rad]")
            label = f"{type(con).__name__}(at={model.sigma[node]:g} m)"
            bound.append(_Bound(point, node, con.selected(), p0, dp, R0, phi, label))
        self.model = model
        self.bound = tuple(bound)
        self.m = sum(len(b.sel) for b in bound)

    @property
    def max_load_step(self):
        """Largest load-factor increment that turns every orientation target by at most pi/4 (1 if none turns):
        the rotation drift is a logarithm, defined modulo a full turn."""
        turn = max([float(np.linalg.norm(b.phi)) for b in self.bound if any(i >= 3 for i in b.sel)] + [0.0])
        return 1.0 if turn <= np.pi / 4 else np.pi / 4 / turn

    def targets(self, scale):
        """[(p*, R*)] at load factor ``scale``."""
        from .lie import expSO3
        return [(b.p0 + scale * b.dp, expSO3(scale * b.phi) @ b.R0) for b in self.bound]

    def _full(self, data, scale):
        """[c6] per constraint: the drift of all six components (x, y, z [m], rx, ry, rz [rad]) at load factor
        ``scale``."""
        from .lie import logSO3
        out = []
        for b, (p, R) in zip(self.bound, self.targets(scale)):
            G = data.G[b.point]
            c6 = np.empty(6)
            c6[:3] = G[:3, 3] - p
            c6[3:] = logSO3(np.ascontiguousarray(G[:3, :3] @ R.T))
            out.append(c6)
        return out

    def residual(self, data, scale):
        """The drift c (m,) [m, rad] at the kinematics in ``data`` and the targets at load factor ``scale``."""
        return np.concatenate([c6[list(b.sel)] for b, c6 in zip(self.bound, self._full(data, scale))])

    def jacobian(self, data, scale=None):
        r"""The exact :math:`\partial c/\partial q` (m, n) at the kinematics in ``data``: position rows
        :math:`R J_v`, rotation rows :math:`J_l^{-1}(c_R) R J_\omega` with the full rotation drift :math:`c_R`
        at load factor ``scale`` (None: at :math:`c_R = 0`, the Jacobian on the constraint manifold)."""
        from .lie import JlSO3_inv
        full = self._full(data, scale) if scale is not None else [np.zeros(6)] * len(self.bound)
        rows = []
        for b, c6 in zip(self.bound, full):
            R = data.G[b.point][:3, :3]
            J = data.J[b.point]
            J6 = np.empty((6, self.model.n))
            J6[:3] = R @ J[3:6]
            J6[3:] = JlSO3_inv(np.ascontiguousarray(c6[3:])) @ (R @ J[0:3])
            rows.append(J6[list(b.sel)])
        return np.vstack(rows)

    def _names(self):
        what = ("position x", "position y", "position z", "rotation about x", "rotation about y", "rotation about z")
        return [f"{b.label} {what[i]}" for b in self.bound for i in b.sel]

    def check(self, data):
        """Raise a :class:`ParameterError` if the constraints cannot be enforced from the kinematics in ``data``
        (the initial guess): a row the basis cannot move (a zero row of :math:`J_c`) or rows that repeat each
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
        if self.m > self.model.n or sv[-1] <= 1e-9 * sv[0]:
            raise ParameterError(
                f"the {self.m} constraint equations are dependent at the initial guess (rank "
                f"{int(np.sum(sv > 1e-9 * sv[0]))}, basis of {self.model.n} coordinates): the bordered system "
                "[K_t J_c^T; J_c 0] is singular; remove the repeated constraints or add modes to the basis")

    def reactions(self, lam):
        """Reaction wrenches (k, 6) [N m, N] (moment first, as :mod:`soroshapes.lie`), world frame, at the
        constrained points, from the multipliers ``lam`` (m,); components not held are 0."""
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
