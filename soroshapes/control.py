r"""Model-based controllers for :class:`~soroshapes.shapes.Shapes` beams inside a :class:`~soroshapes.model.Model`.

Every controller here is a closure ``fn(model) -> {system name: inputs}``, the contract of
:meth:`Model.set_controller <soroshapes.model.Model.set_controller>`; :func:`combine` sums several of them. The
model evaluates the controller at every stage and Newton iterate of its implicit integrator, so a controller
keeps no Python memory: the integral of :func:`pid` lives in a :class:`~soroshapes.model.StateSpace` that
:func:`pid` adds to the model. Each closure also carries its parameters as data (``control.compiled``), so a
network runs it inside the compiled kernel (:mod:`soroshapes.network`, the same equations) when its set-points
and profiles are constants or :class:`~soroshapes.network.Schedule` tables (a PID's set-point: a constant);
a Python callable there keeps the network on the Python path, which :attr:`Model.evaluation_path
<soroshapes.model.Model.evaluation_path>` names.

The beam obeys (``soroshapes.shapes``)

.. math:: M(q)\ddot q + C(q,\dot q)\dot q + D\dot q + Kq = f_g(q) + G(q)\,u,

so every controller first designs a generalized force :math:`\tau` [N m per coordinate] and then maps it to
the beam's inputs by :func:`torque_to_inputs`: :math:`u = G(q)^{+}\tau`, the least-squares (minimum-norm)
solution through the input map :math:`G = \partial f_u/\partial u` (``Shapes.input_map``). With one actuator
per coordinate and unit columns (``shp.add_actuator(e_i)``) :math:`G = I` and :math:`u = \tau`, the fully
actuated case; with fewer inputs (chambers, tendons) the part of :math:`\tau` outside the range of :math:`G` is
dropped (under-actuation), which is the only choice that needs no extra model.

Controllers (``e = q_d - q``)
-----------------------------
* compensation (:func:`gravity_compensation`): :math:`\tau = Kq - f_g(q)` (elastic and gravity feed-forward);
* joint PD (:func:`pd`): :math:`\tau = K_p e - K_d\dot q` (+ compensation);
* joint PID (:func:`pid`): :math:`\tau = K_p e + K_i z - K_d\dot q` (+ compensation), :math:`\dot z = e`;
* feed-forward profiles (:func:`feedforward`): inputs :math:`u(t)`, or a generalized force :math:`\tau(t)`,
  or the static inputs that hold a configuration :math:`q_d(t)`: :math:`G u = Kq_d - f_g(q_d)`;
* Cartesian impedance (:func:`impedance`, Della Santina et al. 2020; eq. (32)-(33) of the Sorotoki paper):
  with :math:`p` the tip position [m], :math:`J` its (selected rows of the) spatial linear Jacobian,
  :math:`\Lambda = (JM^{-1}J^\top)^{-1}` the Cartesian inertia (a pseudo-inverse, so that a kinematic
  singularity such as the straight inextensible rod, whose tip cannot move along its axis, gives finite
  torques; the task is then only controlled in the directions the tip can move),
  :math:`\bar J = M^{-1}J^\top\Lambda` the dynamically consistent pseudo-inverse and
  :math:`\eta_C = \Lambda(JM^{-1}C - \dot J)` the Cartesian Coriolis matrix (eq. (33)),

  .. math:: \tau = J^\top\big(K_c(p_d - p) - D_c J\dot q + \eta_C\dot q\big) + Kq - f_g(q)
            + (I - J^\top\bar J^\top)\,\big(K_n(q_n - q) - D_n\dot q\big).

  The last term acts in the null space of the task: :math:`\bar J^\top(I - J^\top\bar J^\top) = 0`, so it
  produces no Cartesian force. At rest the closed loop balances :math:`J^\top K_c(p_d - p)` against the null
  space term only, so the tip reaches :math:`p_d` exactly when the setpoint is reachable.

Example
-------
A one-segment PCC beam (one bending coordinate, one unit actuator) held at a curvature of 5 1/m by PD with
gravity compensation:

>>> import numpy as np
>>> from sorofem import sdf, materials
>>> from soroshapes import Basis, Model, Shapes
>>> from soroshapes.control import pd
>>> shp = Shapes(Basis.pcc(1), dofs=(0, 1, 0, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
...              material=materials.NeoHookean(E=1e5, nu=0.45, density=1000), damping=0.05)
>>> shp = shp.add_gravity().add_actuator(np.ones(1))
>>> mdl = Model().add(shp, "arm").set_controller(pd("arm", kp=1e-3, kd=1e-4, setpoint=[5.0]))
>>> round(float(mdl.simulate(1.0, 0.01)["arm"].q[-1, 0]), 3)
5.0
"""
from __future__ import annotations

import numpy as np

from sorofem.errors import ParameterError

__all__ = ["torque_to_inputs", "gravity_compensation", "pd", "pid", "feedforward", "impedance", "combine"]


# ------------------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------------------
def _beam(model, system):
    """(shapes, q, qd) of the beam ``system`` at the model's current iterate."""
    view = model[system]
    shp = getattr(view.system, "beam_view", view.system)   # a tree block (Tree.system) shows a beam's face
    if not hasattr(shp, "input_map"):
        raise ParameterError(f"system {system!r} is a {type(shp).__name__}, not a Shapes beam: these "
                             "controllers act on beams")
    x = view.x
    return shp, x[:shp.n], x[shp.n:]


def _gain(k, n, what):
    """A gain as an (n, n) matrix from a scalar, a diagonal (n,) or a matrix."""
    k = np.asarray(k, dtype=float)
    if k.ndim == 0:
        k = k * np.eye(n)
    elif k.shape == (n,):
        k = np.diag(k)
    if k.shape != (n, n) or not np.all(np.isfinite(k)):
        raise ParameterError(f"{what} must be a scalar, {n} diagonal entries or an ({n}, {n}) matrix")
    return k


def _vector(v, n, what):
    if callable(v):
        return v
    v = np.asarray(v, dtype=float).reshape(-1)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ParameterError(f"{what} must have {n} finite entries, got shape {v.shape}")
    return v


def _at(v, t):
    if hasattr(v, "at"):                               # a soroshapes.network.Schedule table
        return np.asarray(v.at(t), dtype=float).reshape(-1)
    return np.asarray(v(t), dtype=float).reshape(-1) if callable(v) else v


def torque_to_inputs(shp, q, tau, rcond=1e-10):
    r"""Inputs :math:`u = G(q)^+\tau` (least squares, minimum norm) that best produce the generalized force
    ``tau`` through the input map :math:`G(q)` (n, m) of the beam ``shp`` (``Shapes.input_map``); the exact
    inverse when :math:`G` is square and invertible (fully actuated)."""
    G = shp.input_map(q)
    if G.shape[1] == 0:
        raise ParameterError("the beam has no inputs: add chambers, tendons or actuators (shp.add_actuator(...)) "
                             "before using a controller")
    if G.shape[0] == G.shape[1]:
        try:
            return np.linalg.solve(G, tau)
        except np.linalg.LinAlgError:
            pass
    return np.linalg.lstsq(G, tau, rcond=rcond)[0]


def _compensation(shp, q, gravity, elastic):
    tau = np.zeros(shp.n)
    if elastic:
        tau += shp.K @ q
    if gravity and np.any(shp.gravity):
        tau -= shp.dynamics(q, np.zeros(shp.n))[2]
    return tau


# ------------------------------------------------------------------------------------------------------------
# controllers
# ------------------------------------------------------------------------------------------------------------
def combine(*controllers):
    """One controller that sums the inputs of ``controllers`` (each ``fn(model) -> {system: inputs}``)."""
    if not controllers or not all(callable(c) for c in controllers):
        raise ParameterError("combine needs one or more controllers fn(model) -> {system: inputs}")

    def control(model):
        out = {}
        for c in controllers:
            for name, u in c(model).items():
                u = np.asarray(u, dtype=float).reshape(-1)
                if name in out and out[name].shape != u.shape:
                    raise ParameterError(f"combine: controllers give {out[name].size} and {u.size} inputs for "
                                         f"system {name!r}")
                out[name] = out[name] + u if name in out else u
        return out

    parts = [getattr(c, "compiled", None) for c in controllers]
    control.compiled = dict(kind="combine", terms=parts)          # a part None keeps the Python path
    return control


def _joint(system, kp, ki, kd, setpoint, gravity, elastic, integral=None):
    """The parameters of a joint-space controller as data, for the compiled network (soroshapes.network)."""
    def gains(n):
        return _gain(kp, n, "kp"), _gain(ki, n, "ki"), _gain(kd, n, "kd")
    return dict(kind="joint", system=system, gains=gains, setpoint=setpoint, gravity=bool(gravity),
                elastic=bool(elastic), integral=integral)


def gravity_compensation(system, *, gravity=True, elastic=True):
    r"""Feed-forward :math:`\tau = Kq - f_g(q)` [N m] (elastic and/or gravity) for the beam ``system``."""

    def control(model):
        shp, q, _ = _beam(model, system)
        return {system: torque_to_inputs(shp, q, _compensation(shp, q, gravity, elastic))}

    control.compiled = _joint(system, 0.0, 0.0, 0.0, None, gravity, elastic)     # no set-point: zeros
    return control


def pd(system, kp, kd, setpoint, *, gravity=True, elastic=True):
    r"""Joint-space PD :math:`\tau = K_p(q_d - q) - K_d\dot q + Kq - f_g(q)`.

    Parameters
    ----------
    system : str
        The beam's name in the model.
    kp, kd : scalar, (n,) or (n, n)
        Gains [N m per coordinate unit] and [N m s per coordinate unit].
    setpoint : (n,) or callable ``t -> (n,)``
        :math:`q_d` (coordinates of the beam).
    gravity, elastic : bool
        Add the gravity / elastic compensation (exact regulation to :math:`q_d` with both).
    """

    def control(model):
        shp, q, qd = _beam(model, system)
        n = shp.n
        Kp, Kd, qdes = _gain(kp, n, "kp"), _gain(kd, n, "kd"), _vector(setpoint, n, "setpoint")
        tau = Kp @ (_at(qdes, model.t) - q) - Kd @ qd + _compensation(shp, q, gravity, elastic)
        return {system: torque_to_inputs(shp, q, tau)}

    control.compiled = _joint(system, kp, 0.0, kd, setpoint, gravity, elastic)
    return control


def pid(model, system, kp, ki, kd, setpoint, *, gravity=True, elastic=True, name=None):
    r"""Joint-space PID :math:`\tau = K_p e + K_i z - K_d\dot q + Kq - f_g(q)`, :math:`\dot z = e = q_d - q`.

    The integral :math:`z` [coordinate s] is a :class:`~soroshapes.model.StateSpace` named ``name`` (default
    ``"<system>_pid"``) that this function **adds to** ``model`` together with the coupling that feeds it
    :math:`e`; so it is integrated by the model's implicit solver and its trajectory is recorded
    (``traj[name].x``). Returns the controller; pass it to ``model.set_controller``.
    """
    from .model import StateSpace
    shp = model[system].system
    n = shp.n
    Kp, Ki, Kd = _gain(kp, n, "kp"), _gain(ki, n, "ki"), _gain(kd, n, "kd")
    qdes = _vector(setpoint, n, "setpoint")
    name = name or f"{system}_pid"
    if callable(qdes):                 # the error of a moving set-point: a Python coupling
        integ = StateSpace(lambda z, e, t: e, n, n, jacobian=lambda z, e, t: (np.zeros((n, n)), np.eye(n)))
        model.add(integ, name).connect(lambda mdl: _at(qdes, mdl.t) - mdl[system].x[:n], name)
    else:                              # z' = e = q_d - q: a linear block fed by a StateMap (runs compiled)
        from .network import StateMap
        model.add(StateSpace.linear(np.zeros((n, n)), np.eye(n)), name)
        model.connect(StateMap(system, -np.eye(n), index=np.arange(n), offset=qdes), name)

    def control(mdl):
        shp_, q, qd = _beam(mdl, system)
        z = mdl[name].x
        tau = Kp @ (_at(qdes, mdl.t) - q) + Ki @ z - Kd @ qd + _compensation(shp_, q, gravity, elastic)
        return {system: torque_to_inputs(shp_, q, tau)}

    control.compiled = _joint(system, kp, ki, kd, setpoint, gravity, elastic, integral=name)
    return control


def feedforward(system, profile, *, space="inputs"):
    r"""Open-loop inputs from a profile of time ``t`` [s].

    ``space="inputs"``: ``profile(t)`` gives the inputs (pressures [Pa], tendon forces [N], ...) directly.
    ``space="torque"``: ``profile(t)`` gives a generalized force :math:`\tau(t)` (n,), mapped by least
    squares through the input map, :math:`u = G(q)^+\tau`. ``space="configuration"``: ``profile(t)`` gives a
    configuration :math:`q_d(t)` and the inputs hold it statically, :math:`G(q_d)u = Kq_d - f_g(q_d)` (least
    squares if :math:`G` is not square).
    """
    if not callable(profile):
        raise ParameterError("feedforward needs a callable profile(t)")
    if space not in ("inputs", "torque", "configuration"):
        raise ParameterError(f"space must be 'inputs', 'torque' or 'configuration', got {space!r}")

    def control(model):
        shp, q, _ = _beam(model, system)
        v = _at(profile, model.t)
        if space == "inputs":
            return {system: v}
        if v.shape != (shp.n,):
            raise ParameterError(f"feedforward({space!r}) profile for system {system!r} must give {shp.n} "
                                 f"values, got {v.size}")
        if space == "torque":
            return {system: torque_to_inputs(shp, q, v)}
        return {system: torque_to_inputs(shp, v, _compensation(shp, v, True, True))}

    control.compiled = dict(kind="feedforward", system=system, profile=profile, space=space)
    return control


def _null_gains(null_stiffness, null_damping, null_posture):
    """``n -> (K_n, D_n, q_n, active)`` of the null-space term (for the compiled network)."""
    def gains(n):
        qn = np.zeros(n) if null_posture is None else _vector(null_posture, n, "null_posture")
        return (_gain(null_stiffness, n, "null_stiffness"), _gain(null_damping, n, "null_damping"), qn,
                bool(np.any(null_stiffness) or np.any(null_damping)))
    return gains


def _tip_task(shp, q, qd, at, axes):
    """Tip position p (3,), position Jacobian Jp and its rate, rows ``axes`` (spatial frame)."""
    g = shp.forward_kinematics(q)
    i = shp.node(at)
    R, p = g[i, :3, :3], g[i, :3, 3]
    Jb = shp.jacobian(q, at=at)                      # body (6, n): rows (omega, v)
    Jbd = shp.jacobian_rate(q, qd, at=at)
    w = Jb[:3] @ qd
    J = R @ Jb[3:]                                    # spatial velocity of the tip point: pdot = R v
    Jd = R @ (np.cross(w[:, None], Jb[3:], axis=0) + Jbd[3:])
    return p[axes], J[axes], Jd[axes]


def impedance(system, stiffness, damping, setpoint, *, axes=(0, 1, 2), at=None, coriolis=True,
              null_stiffness=0.0, null_damping=0.0, null_posture=None, gravity=True, elastic=True):
    r"""Cartesian impedance control of the tip position (Della Santina et al. 2020; module docstring).

    Parameters
    ----------
    system : str
        The beam's name in the model.
    stiffness, damping : scalar, (k,) or (k, k)
        Cartesian stiffness :math:`K_c` [N/m] and damping :math:`D_c` [N s/m], k = len(axes).
    setpoint : (k,), callable ``t -> (k,)`` or :class:`~soroshapes.network.Schedule`
        Desired position :math:`p_d` [m] of the selected axes, spatial frame. A constant or a Schedule (its
        values a (K, k) array) runs compiled inside a network (:mod:`soroshapes.network`, the same equations);
        a Python callable keeps the network on the Python path.
    axes : sequence of int
        Which spatial coordinates (0 x, 1 y, 2 z) form the task: a planar arm uses the two of its plane
        (the third row of its Jacobian is zero and :math:`JM^{-1}J^\top` would be singular).
    at : float [m], optional
        Node of the controlled point (default the tip).
    coriolis : bool
        Add the Cartesian Coriolis compensation :math:`J^\top\eta_C\dot q` of eq. (33).
    null_stiffness, null_damping : scalar, (n,) or (n, n)
        :math:`K_n`, :math:`D_n` of the null-space posture term, projected by :math:`I - J^\top\bar J^\top`.
    null_posture : (n,), optional
        :math:`q_n` (default zero: the straight rod).
    gravity, elastic : bool
        Compensate :math:`f_g(q)` and :math:`Kq`.
    """
    axes = list(axes)
    k = len(axes)
    if k == 0 or any(a not in (0, 1, 2) for a in axes):
        raise ParameterError(f"axes must be a non-empty subset of (0, 1, 2), got {axes!r}")
    pdes = _vector(setpoint, k, "setpoint")
    Kc, Dc = _gain(stiffness, k, "stiffness"), _gain(damping, k, "damping")

    def control(model):
        shp, q, qd = _beam(model, system)
        n = shp.n
        M, C, fg = shp.dynamics(q, qd)
        p, J, Jd = _tip_task(shp, q, qd, at, axes)
        Minv_JT = np.linalg.solve(M, J.T)
        Lam = np.linalg.pinv(J @ Minv_JT, rcond=1e-9, hermitian=True)   # pinv: finite at singularities
        force = Kc @ (_at(pdes, model.t) - p) - Dc @ (J @ qd)
        if coriolis:
            force += Lam @ (J @ np.linalg.solve(M, C @ qd) - Jd @ qd)          # eta_C qd, eq. (33)
        tau = J.T @ force
        if elastic:
            tau += shp.K @ q
        if gravity:
            tau -= fg
        if np.any(null_stiffness) or np.any(null_damping):
            Jbar = Minv_JT @ Lam                                                 # dynamically consistent J^+
            qn = np.zeros(n) if null_posture is None else _vector(null_posture, n, "null_posture")
            tau0 = _gain(null_stiffness, n, "null_stiffness") @ (qn - q) - _gain(null_damping, n,
                                                                                 "null_damping") @ qd
            tau += tau0 - J.T @ (Jbar.T @ tau0)
        return {system: torque_to_inputs(shp, q, tau)}

    # the controller's parameters as data, for the compiled network (soroshapes.network)
    control.compiled = dict(kind="impedance", system=system, axes=axes, stiffness=Kc, damping=Dc, setpoint=pdes,
                            at=at, coriolis=bool(coriolis), gravity=bool(gravity), elastic=bool(elastic),
                            null=_null_gains(null_stiffness, null_damping, null_posture))
    return control
