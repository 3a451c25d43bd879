r"""Networks of dynamic systems: ``StateSpace``, ``Fluidic`` reservoirs and ``Shapes`` beams composed in a ``Model``.

The network (Sorotoki's ``Model``, eq. (24) of the paper)
---------------------------------------------------------
Each subsystem :math:`i` is a first-order system :math:`\dot x_i = f_i(x_i, w_i, t)`, where :math:`w_i` holds its
inputs :math:`u_i` (and, for a :class:`Fluidic`, its volume :math:`V`). The model stacks the states,
:math:`x = (x_1, \dots, x_N)`, and assembles every :math:`w_i` at the current :math:`(t, x)` from

* the controller ``fn(model)`` (:meth:`Model.set_controller`), which gives the *free* inputs (those no coupling
  drives) and reads the current state with ``model["finger"].x`` or ``model.state("finger", slice)``;
* the couplings (:meth:`Model.connect`): an output of one system, or any callable of the model, feeds inputs of
  another (chamber pressure -> beam input), or a callable gives a :class:`Fluidic` its volume (beam q -> V).

so that the closed loop is one ODE :math:`\dot x = F(t, x) = (f_i(x_i, W_i(t, x), t))_i`. The controller and the
couplings are part of :math:`F`: they are evaluated at every stage and every Newton iterate of the implicit
integrators, so the closed loop keeps the integrator's order (a controller with internal memory must keep it
in a :class:`StateSpace`, not in Python variables, for the same reason).

A :class:`~soroshapes.shapes.Shapes` beam enters with the state :math:`x = (q, \dot q)` and

.. math:: M(q)\ddot q = -C(q,\dot q)\dot q - D\dot q - Kq + f(q, \dot q, t, u),

evaluated by ``Shapes.forward_dynamics`` (:math:`M, C` and :math:`f`: gravity, inputs, point loads, contact,
user forces, from one kinematic pass).

Integration (``Model.simulate``)
--------------------------------
Two paths, one family of methods. A network whose every part has a compiled form (beams with gravity and
chambers, reservoirs, :meth:`StateSpace.linear` systems, output couplings, :class:`~soroshapes.network.StateMap`
couplings and a :class:`~soroshapes.network.Schedule` controller) runs in one compiled kernel
(:mod:`soroshapes.network`, :mod:`soroshapes.integrate`: Newton per connected component, the beams' iteration
rows re-scaled by the current mass matrix); :attr:`Model.evaluation_path` says which path runs and, for the
Python path, which part forces it. The Python path, described here, runs any network:
implicit, with Newton's method on the global residual, step :math:`h`:

* ``"trapezoidal"`` (Sorotoki's default, like ``ode23t``): :math:`x_{k+1} = x_k + \tfrac h2 (F_k + F_{k+1})`;
* ``"midpoint"``: :math:`x_{k+1} = x_k + h F(t_k + \tfrac h2, \tfrac12(x_k + x_{k+1}))`;
* ``"bdf2"``: :math:`x_{k+1} - \tfrac43 x_k + \tfrac13 x_{k-1} = \tfrac23 h F_{k+1}` (L-stable; the first step is
  trapezoidal).

All three are second order. The Newton matrix is :math:`I - c h J` with :math:`J = \partial F/\partial x` assembled
block by block, :math:`J = \mathrm{blkdiag}(\partial f_i/\partial x_i) + \mathrm{blkdiag}(\partial f_i/\partial
w_i)\, \partial W/\partial x`: the subsystem blocks come from a user Jacobian (:class:`StateSpace`) or finite
differences, the coupling term :math:`\partial W/\partial x` from finite differences of the input assembly (cheap:
no dynamics). When every callable coupling and the controller declare the systems they read (``reads=``), the
coupling term has a known block pattern: only the states read are differenced, and systems that no target
reads together are perturbed in the same evaluation (Curtis-Powell-Reid grouping; a chain of N systems needs
2 evaluations instead of 2N). From 200 states on (``linear_solver="auto"``) the matrix is assembled block-sparse
and factorized by SuperLU, below that dense by LAPACK. It is reused across steps until Newton contracts slowly. Newton stops when every correction is below
:math:`10^{-3}(\text{rtol}|x_j| + \text{atol}\, s_j)` (:math:`s_j` a per-state scale given by the subsystem).
With ``adaptive=True`` both paths run the one step-size controller of :mod:`soroshapes.integrate` (Milne's
estimate of the local error from the step and the quadratic extrapolation of the last three states,
variable-step BDF2, records at the output times by dense output).

Fluidic reservoir (eq. (25)-(29) of the paper)
----------------------------------------------
An enclosed ideal gas of volume :math:`V` [m^3] at temperature :math:`T` [K], gas constant :math:`R` [J/(kg K)].
Pressures: ``p0`` is the ambient (atmospheric) **absolute** pressure [Pa] and the initial absolute pressure; the
output and the regulator's set point are **gauge** pressures :math:`p_g = p - p_0` [Pa]. Net mass flow [kg/s]:
:math:`\dot m = \dot m_{in} - \lambda (p - p_0)` (``leak`` :math:`\lambda` [kg/(s Pa)]).

* Isothermal (``polytropic=1``): state :math:`m` [kg], :math:`p = mRT/V`. This is eq. (25) with :math:`n_k = 1`
  integrated exactly (:math:`\dot p = (RT\dot m - p\dot V)/V` is the derivative of :math:`mRT/V`), so no
  :math:`\dot V` is needed and a closed reservoir keeps :math:`pV = mRT` to round-off.
* Polytropic :math:`n \ne 1`: state :math:`p` [Pa, absolute] with eq. (25),
  :math:`\dot p = \tfrac{n}{V}(RT\dot m - p\dot V)` (:math:`V = J V_0`, so :math:`\tfrac{dV}{dJ}\dot J = \dot V`),
  which for a closed reservoir conserves :math:`pV^n`. If the volume is not constant, :math:`\dot V` is replaced by
  the dirty derivative of eq. (26)-(27) (Loria et al.) with one gain :math:`a` (``filter_gain`` [1/s]):
  :math:`\dot z = -a(z + aV)`, :math:`\tilde{\dot V} = z + aV`, i.e. :math:`\tilde{\dot V} = \tfrac{as}{s+a}V`
  (the paper's :math:`\alpha_1 = \alpha_2 = a`, with the signs that make the filter stable and of unit gain);
  :math:`z` is a state, started at :math:`-aV(0)`.
* Regulated (eq. (28)-(29)): the input is the desired gauge pressure :math:`p_d` [Pa];
  :math:`e = p_d - p_g`, :math:`\nu = k_p e + k_i s`, :math:`\dot m_{in} = \Psi_v(\nu, p)` the valve flow
  function (default the saturation :math:`\mathrm{clip}(\nu, \pm\dot m_{max})`; ``valve=``: the ISO 6358-like
  :class:`~soroshapes.valves.Orifice` or a Python callable, :mod:`soroshapes.valves`), and the integrator state
  :math:`s` [Pa s] follows :math:`\dot s = e + (\mathrm{clip}(\nu, \pm\dot m_{max}) - \nu)/k_p`
  (back-calculation anti-windup on the command's limit, the Orifice's full flow; equal to :math:`e` when the
  command is not saturated). The paper writes :math:`\nu = k_p(p - p_d) + \dots`; we use :math:`e = p_d - p` so that
  positive gains fill the reservoir.

Example
-------
A closed isothermal reservoir squeezed to half its volume doubles its absolute pressure:

>>> from soroshapes import Model, Fluidic
>>> mdl = Model().add(Fluidic(lambda t: 1e-5 * (1 - 0.5 * t), p0=1e5), name="cup")
>>> traj = mdl.simulate(1.0, 0.01)
>>> round(float(traj["cup"].pressure[-1]), 3)      # gauge [Pa]: 2e5 absolute
100000.0
"""
from __future__ import annotations

import logging
import math
import time as _time

import numpy as np

from sorofem._lazy import moved_attributes
from sorofem.errors import ConvergenceError, DataError, ParameterError, SoroError

from .numerics import FD_STEP, fd_columns
from .trajectory import Trajectory

__all__ = ["StateSpace", "Fluidic", "Model", "Stepper"]
#: one trajectory type for beams, trees and networks (README.md, "Moved names")
__getattr__ = moved_attributes(__name__, {name: "soroshapes.trajectory.Trajectory"
                                          for name in ("ModelTrajectory", "SystemTrajectory")})

log = logging.getLogger(__name__)
_NO_POSITIONS = np.zeros(0, dtype=int)


def _finite(v):
    """All entries finite (the sum first: one pass, and finite sums are the rule)."""
    return math.isfinite(np.add.reduce(v, axis=None)) or bool(np.all(np.isfinite(v)))


def _vec(v, what):
    return np.atleast_1d(np.asarray(v, dtype=float)).reshape(-1)


# ------------------------------------------------------------------------------------------------------------
# subsystems
# ------------------------------------------------------------------------------------------------------------
class StateSpace:
    r"""A first-order system :math:`\dot x = f(x, u, t)`, output :math:`y = h(x, u, t)` (default :math:`y = x`).

    Parameters
    ----------
    f : callable ``(x (n,), u (m,), t) -> (n,)``
    n, m : int
        State and input dimensions.
    jacobian : callable ``(x, u, t) -> (A (n, n), B (n, m))``, optional
        :math:`\partial f/\partial x`, :math:`\partial f/\partial u`; default forward finite differences.
    output : callable ``(x, u, t) -> (p,)``, optional
    feedthrough : bool
        Whether ``output`` depends on ``u`` (default True when an output is given): with False, a coupling
        from this system reads only its state, which keeps the Jacobian of a network sparse.
    name : str, optional
        Default name in a :class:`Model`.
    x0 : (n,), optional
        Default initial state (zeros).
    scale : float or (n,), optional
        Typical magnitude of the states (finite-difference steps and absolute tolerances), default 1.

    Examples
    --------
    >>> import numpy as np
    >>> sys = StateSpace(lambda x, u, t: -x + u, n=1, m=1)
    >>> A, B = sys.jacobian(np.zeros(1), np.ones(1), 0.0)
    >>> bool(np.allclose(A, -1) and np.allclose(B, 1))
    True
    """

    def __init__(self, f, n, m, jacobian=None, output=None, name=None, *, x0=None, scale=1.0, feedthrough=None):
        if not callable(f):
            raise ParameterError("StateSpace needs a callable f(x, u, t) -> xdot")
        self.n, self.m = int(n), int(m)
        if self.n < 1 or self.m < 0:
            raise ParameterError(f"StateSpace needs n >= 1 states and m >= 0 inputs, got n={n}, m={m}")
        for what, fn in (("jacobian", jacobian), ("output", output)):
            if fn is not None and not callable(fn):
                raise ParameterError(f"StateSpace {what} must be callable (x, u, t)")
        self.f, self._jac, self._out, self.name = f, jacobian, output, name
        self.feedthrough = output is not None if feedthrough is None else bool(feedthrough)
        self.x0 = np.zeros(self.n) if x0 is None else _vec(x0, "x0")
        if self.x0.shape != (self.n,):
            raise ParameterError(f"StateSpace x0 must have {self.n} entries, got {self.x0.shape}")
        self.scale = np.broadcast_to(np.asarray(scale, dtype=float), (self.n,)).copy()
        self.input_names = [f"u{k}" for k in range(self.m)]

    def rhs(self, x, u, t):
        """:math:`f(x, u, t)` as an (n,) array."""
        v = _vec(self.f(x, u, t), "f")
        if v.shape != (self.n,):
            raise ParameterError(f"f returned shape {v.shape}, expected ({self.n},)")
        return v

    def jacobian(self, x, u, t):
        """(A, B) = (:math:`\\partial f/\\partial x`, :math:`\\partial f/\\partial u`) at (x, u, t)."""
        x, u = _vec(x, "x"), _vec(u, "u") if self.m else np.zeros(0)
        if self._jac is not None:
            A, B = self._jac(x, u, t)
            A, B = np.asarray(A, dtype=float).reshape(self.n, self.n), np.asarray(B, dtype=float).reshape(self.n,
                                                                                                           self.m)
            return A, B
        f0 = self.rhs(x, u, t)
        A = fd_columns(lambda xx: self.rhs(xx, u, t), x, f0, self.scale)
        B = fd_columns(lambda uu: self.rhs(x, uu, t), u, f0, np.ones(self.m)) if self.m else np.zeros((self.n, 0))
        return A, B

    def output(self, x, u, t):
        """:math:`y = h(x, u, t)` (default the state)."""
        return x.copy() if self._out is None else _vec(self._out(x, u, t), "output")

    #: (A, B, C, D) of a linear system made by :meth:`linear` (None otherwise): what a compiled network runs
    matrices = None

    @classmethod
    def linear(cls, A, B, C=None, D=None, name=None, *, x0=None, scale=1.0):
        r"""The linear system :math:`\dot x = Ax + Bu`, :math:`y = Cx + Du` (C default the identity, D default
        zero), A (n, n), B (n, m), C (p, n), D (p, m), in the units of the states, inputs and outputs. It runs
        compiled inside a network (:mod:`soroshapes.network`).

        Examples
        --------
        >>> lag = StateSpace.linear([[-10.0]], [[10.0]])        # first-order lag, time constant 0.1 s
        >>> float(lag.rhs(np.zeros(1), np.ones(1), 0.0)[0])
        10.0
        """
        A = np.atleast_2d(np.asarray(A, dtype=float))
        n = A.shape[0]
        B = np.asarray(B, dtype=float).reshape(n, -1) if np.size(B) else np.zeros((n, 0))
        m = B.shape[1]
        C = np.eye(n) if C is None else np.atleast_2d(np.asarray(C, dtype=float))
        D = np.zeros((C.shape[0], m)) if D is None else np.asarray(D, dtype=float).reshape(C.shape[0], m)
        if A.shape != (n, n) or C.shape[1] != n:
            raise ParameterError(f"StateSpace.linear needs A (n, n), B (n, m), C (p, n), D (p, m); got A {A.shape}, "
                                 f"B {B.shape}, C {C.shape}, D {D.shape}")
        if not all(np.all(np.isfinite(M)) for M in (A, B, C, D)):
            raise ParameterError("StateSpace.linear: the matrices must be finite")
        sys = cls(lambda x, u, t: A @ x + B @ u, n, m, jacobian=lambda x, u, t: (A, B),
                  output=lambda x, u, t: C @ x + D @ u, name=name, x0=x0, scale=scale,
                  feedthrough=bool(np.any(D != 0)))
        sys.matrices = (A, B, C, D)
        return sys


class Fluidic:
    r"""An enclosed ideal-gas reservoir (eq. (25)-(29) of the Sorotoki paper; see the module docstring).

    Parameters
    ----------
    volume : float [m^3], callable ``t -> V`` [m^3], or None
        None: the volume comes from a :class:`Model` coupling (``model.connect(fn, name, port="volume")``).
    V0 : float [m^3], optional
        Reference volume (scales); default the constant volume or ``volume(0)``.
    p0 : float [Pa]
        Ambient absolute pressure; also the initial absolute pressure (gauge 0).
    T : float [K]
    gas_constant : float [J/(kg K)] (air: 287.05)
    polytropic : float
        Polytropic index :math:`n` (1 isothermal, 1.4 adiabatic air).
    leak : float [kg/(s Pa)]
        Leak :math:`\dot m_{leak} = -\lambda(p - p_0)`.
    regulator : dict, optional
        ``dict(kp=[kg/(s Pa)], ki=[kg/(s^2 Pa)], max_flow=[kg/s])``: the input becomes the desired gauge pressure.
        The PI's output is the valve's flow command :math:`\nu` [kg/s], eq. (29); ``max_flow`` is the saturation
        valve's limit (required with it; with an :class:`~soroshapes.valves.Orifice` the limit is its full flow,
        with a callable valve it is optional). Anti-windup: :math:`\dot s = e + (\mathrm{clip}(\nu, \pm\dot
        m_{max}) - \nu)/k_p`.
    valve : None, :class:`~soroshapes.valves.Orifice` or callable ``fn(nu, p) -> mdot``, optional
        The valve flow function :math:`\dot m = \Psi_v(\nu, p)` of eq. (28) (:mod:`soroshapes.valves`):
        None is the saturation :math:`\mathrm{clip}(\nu, \pm\dot m_{max})` (unregulated: :math:`\dot m = u`);
        an Orifice is the ISO 6358-like choked/subsonic flow from a supply and to an exhaust, compiled in a
        network with its closed-form Newton rows; a Python callable of the command :math:`\nu` [kg/s] and the
        absolute pressure :math:`p` [Pa] giving the mass flow [kg/s] runs on the slower Python path
        (:attr:`Model.evaluation_path` says so). Unregulated, the input is the command :math:`\nu` [kg/s].
    filter_gain : float [1/s]
        Gain :math:`a` of the dirty derivative of :math:`V` (polytropic, varying volume only).
    name : str, optional

    The input is the mass flow [kg/s] into the reservoir (or the desired gauge pressure [Pa] with a
    regulator); the output is the gauge pressure [Pa].

    Examples
    --------
    >>> fl = Fluidic(1e-6, regulator=dict(kp=1e-9, ki=1e-7, max_flow=1e-4))
    >>> fl.n, fl.input_names
    (2, ['pressure_ref'])
    """

    def __init__(self, volume=None, V0=None, p0=101325.0, T=293.15, gas_constant=287.05, polytropic=1.0, leak=0.0,
                 regulator=None, name=None, *, filter_gain=1e3, valve=None):
        self.name = name
        if volume is None or callable(volume):
            self.volume = volume
            self.constant = False
        else:
            self.volume = float(volume)
            if not (np.isfinite(self.volume) and self.volume > 0):
                raise ParameterError(f"Fluidic volume must be > 0 [m^3], got {volume!r}")
            self.constant = True
        if V0 is None:
            V0 = self.volume if self.constant else (float(volume(0.0)) if callable(volume) else None)
        self.V0 = None if V0 is None else float(V0)
        for what, v in (("V0", self.V0), ("p0", p0), ("T", T), ("gas_constant", gas_constant),
                        ("polytropic", polytropic), ("filter_gain", filter_gain)):
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ParameterError(f"Fluidic {what} must be positive and finite, got {v!r}")
        if not (np.isfinite(leak) and leak >= 0):
            raise ParameterError(f"Fluidic leak must be >= 0 [kg/(s Pa)], got {leak!r}")
        self.p0, self.T, self.R, self.polytropic = float(p0), float(T), float(gas_constant), float(polytropic)
        self.leak, self.filter_gain = float(leak), float(filter_gain)
        self.isothermal = self.polytropic == 1.0
        from_valve = None
        if valve is None:
            self.valve_kind = "saturation"
        elif callable(valve):
            self.valve_kind = "python"
        elif hasattr(valve, "full_flow") and hasattr(valve, "parameters"):
            self.valve_kind = "orifice"
            from_valve = valve.full_flow(self.p0, self.T)
        else:
            raise ParameterError(f"valve must be None (saturation), a soroshapes.valves.Orifice or a callable "
                                 f"fn(nu, p) -> mdot [kg/s], got {valve!r}")
        self.valve = valve
        self.regulator = None
        if regulator is not None:
            try:
                kp, ki = float(regulator["kp"]), float(regulator["ki"])
                mx = regulator.get("max_flow")
                mx = from_valve if from_valve is not None else (math.inf if mx is None and self.valve_kind == "python"
                                                                else float(mx))
            except (KeyError, TypeError, ValueError, AttributeError):
                raise ParameterError("regulator must be dict(kp=..., ki=..., max_flow=...) [SI] (max_flow: the "
                                     "saturation valve's limit)") from None
            if not (kp > 0 and ki >= 0 and mx > 0):
                raise ParameterError(f"regulator needs kp > 0, ki >= 0, max_flow > 0, got {regulator!r}")
            self.regulator = (kp, ki, mx)
        self.filtered = not self.isothermal and not self.constant
        self.states = ["mass" if self.isothermal else "pressure"] + (["filter"] if self.filtered else []) \
            + (["integral"] if self.regulator else [])
        self.n, self.m = len(self.states), 1
        self.input_names = ["pressure_ref" if self.regulator else "mass_flow"]

    def volume_at(self, t):
        """Volume [m^3] at time t from the constant or V(t) (None when a model coupling gives it)."""
        if self.constant:
            return self.volume
        return None if self.volume is None else float(self.volume(t))

    def absolute_pressure(self, x, V):
        """Absolute pressure [Pa] at state x and volume V [m^3]."""
        return x[0] * self.R * self.T / V if self.isothermal else x[0]

    def pressure(self, x, V):
        """Gauge pressure [Pa] at state x and volume V [m^3]."""
        return self.absolute_pressure(x, V) - self.p0

    def initial_state(self, V, pressure=0.0):
        """State at gauge ``pressure`` [Pa] in volume ``V`` [m^3] (filter at rest, integrator empty)."""
        p = self.p0 + float(pressure)
        x = [p * V / (self.R * self.T) if self.isothermal else p]
        if self.filtered:
            x.append(-self.filter_gain * V)
        if self.regulator:
            x.append(0.0)
        return np.array(x)

    def scales(self, V):
        """Typical magnitudes of the states (for tolerances and finite-difference steps)."""
        s = [self.p0 * V / (self.R * self.T) if self.isothermal else self.p0]
        if self.filtered:
            s.append(self.filter_gain * V)
        if self.regulator:
            s.append(self.p0 * 1e-3)
        return np.array(s)

    def valve_flow(self, nu, p):
        """Mass flow [kg/s] of the valve for the command ``nu`` [kg/s] at absolute pressure ``p`` [Pa]
        (:mod:`soroshapes.valves`)."""
        if self.valve_kind == "saturation":
            return min(max(nu, -self.regulator[2]), self.regulator[2]) if self.regulator else nu
        if self.valve_kind == "orifice":
            return self.valve.flow(nu, p, self.p0, self.T)
        mdot = float(self.valve(nu, p))
        if not math.isfinite(mdot):
            raise DataError(f"the valve flow function gave {mdot!r} kg/s at nu = {nu!r} kg/s, p = {p!r} Pa: it must "
                            "return a finite mass flow")
        return mdot

    def rhs(self, x, u, V):
        """State derivative at state x, input u (mass flow [kg/s] or set point [Pa]) and volume V [m^3]."""
        if not (V > 0 and np.isfinite(V)):
            raise DataError(f"volume must be positive and finite, got {V!r} m^3")
        p = self.absolute_pressure(x, V)
        out = np.empty(self.n)
        if self.regulator:
            kp, ki, mx = self.regulator
            e = u[0] - (p - self.p0)
            nu = kp * e + ki * x[-1]
            out[-1] = e + (min(max(nu, -mx), mx) - nu) / kp
        else:
            nu = u[0]
        mdot = self.valve_flow(nu, p) - self.leak * (p - self.p0)
        if self.isothermal:
            out[0] = mdot
        else:
            Vdot = 0.0
            if self.filtered:
                a = self.filter_gain
                Vdot = x[1] + a * V                       # eq. (27)
                out[1] = -a * (x[1] + a * V)              # eq. (26)
            out[0] = self.polytropic / V * (self.R * self.T * mdot - p * Vdot)   # eq. (25)
        return out


# ------------------------------------------------------------------------------------------------------------
# adapters: one interface for the model, w = (u, [V])
# ------------------------------------------------------------------------------------------------------------
class _Block:
    kind = "statespace"

    def __init__(self, name, system):
        self.name, self.system = name, system
        self.n, self.m = system.n, system.m
        self.nw = self.m
        self.input_names = list(system.input_names)

    def default_x0(self):
        return self.system.x0.copy()

    def scale(self, x0):
        return self.system.scale.copy()

    def rhs(self, x, w, t):
        return self.system.rhs(x, w, t)

    def jac(self, x, w, t):
        return self.system.jacobian(x, w, t)

    def output(self, x, w, t):
        return self.system.output(x, w, t)

    @property
    def output_uses_inputs(self):
        """Whether the output may depend on the inputs (:attr:`StateSpace.feedthrough`)."""
        return getattr(self.system, "feedthrough", True)


class _FluidicBlock(_Block):
    kind = "fluidic"
    output_uses_inputs = True            # the pressure depends on the volume input

    def __init__(self, name, system):
        super().__init__(name, system)
        self.nw = 2                                        # (u, V)

    def default_x0(self):
        return None                                       # needs V(0): set by the model

    def scale(self, x0):
        V = self.system.V0 if self.system.V0 is not None else self._V_init
        return self.system.scales(V)

    def rhs(self, x, w, t):
        return self.system.rhs(x, w[:1], w[1])

    def jac(self, x, w, t):
        f0 = self.rhs(x, w, t)
        A = fd_columns(lambda xx: self.rhs(xx, w, t), x, f0, self._scale)
        B = fd_columns(lambda ww: self.rhs(x, ww, t), w, f0, np.array([self._uscale, abs(w[1])]))
        return A, B

    def output(self, x, w, t):
        return np.array([self.system.pressure(x, w[1])])


class _ShapesBlock(_Block):
    kind = "shapes"
    output_uses_inputs = False           # the output is the state

    def __init__(self, name, system):
        self.name, self.system = name, system
        self.nq = system.n
        self.n, self.m = 2 * system.n, len(system.inputs)
        self.nw = self.m
        self.input_names = list(system.inputs)

    def default_x0(self):
        return np.zeros(self.n)

    def scale(self, x0):
        return np.ones(self.n)

    def rhs(self, x, w, t):
        shp, n = self.system, self.nq
        q, qd = x[:n], x[n:]
        qdd = shp.forward_dynamics(q, qd, t, w)
        return np.concatenate([qd, qdd])

    def jac(self, x, w, t):
        f0 = self.rhs(x, w, t)
        A = fd_columns(lambda xx: self.rhs(xx, w, t), x, f0, np.ones(self.n))
        B = (fd_columns(lambda ww: self.rhs(x, ww, t), w, f0, np.maximum(np.abs(w), 1.0)) if self.m
             else np.zeros((self.n, 0)))
        return A, B

    def output(self, x, w, t):
        return x.copy()


def _block(name, system):
    if isinstance(system, Fluidic):
        return _FluidicBlock(name, system)
    if isinstance(system, StateSpace):
        return _Block(name, system)
    from .shapes import Shapes
    if isinstance(system, Shapes):
        return _ShapesBlock(name, system)
    raise ParameterError(f"Model.add takes a StateSpace, Fluidic or Shapes, got {type(system).__name__}")


class _View:
    """``model["name"]``: the current state ``x`` and inputs ``u`` of one system during a simulation."""

    def __init__(self, model, blk):
        self._model, self._blk = model, blk

    @property
    def x(self):
        return self._model._x[self._blk.sl]

    @property
    def u(self):
        return self._model._w[self._blk.wsl][:self._blk.m]

    @property
    def system(self):
        return self._blk.system

    @property
    def pressure(self):
        """Gauge pressure [Pa] of a Fluidic at the current state."""
        if self._blk.kind != "fluidic":
            raise AttributeError(f"system {self._blk.name!r} is not a Fluidic")
        return self._blk.system.pressure(self.x, self._model._w[self._blk.wsl][1])


# ------------------------------------------------------------------------------------------------------------
# the model
# ------------------------------------------------------------------------------------------------------------
def _check_run(method, rtol, atol, t0, newton_tol=1e-3):
    """Check the arguments a run shares (:meth:`Model.simulate`, :class:`Stepper`) and return ``method``'s code
    in :mod:`soroshapes.integrate` and ``t0`` [s] as a float."""
    from . import integrate as itg
    codes = {"trapezoidal": itg.TRAPEZOIDAL, "midpoint": itg.MIDPOINT, "bdf2": itg.BDF2}
    if method not in codes:
        raise ParameterError(f"method must be 'trapezoidal', 'midpoint' or 'bdf2', got {method!r}")
    if not (rtol > 0 and atol > 0):
        raise ParameterError("rtol and atol must be positive")
    if not (0.0 < float(newton_tol) <= 1.0):
        raise ParameterError(f"newton_tol is a fraction of the step tolerance in (0, 1], got {newton_tol!r}")
    t0 = float(t0)
    if not np.isfinite(t0):
        raise ParameterError(f"t0 must be a finite time [s], got {t0!r}")
    return codes[method], t0


class Model:
    r"""A network of dynamic systems solved as one implicit ODE (see the module docstring).

    Build it with :meth:`add`, :meth:`connect` and :meth:`set_controller` (each returns ``self``), then
    :meth:`simulate`. Inside a controller or coupling callable ``fn(model)``: ``model.t`` [s],
    ``model["name"].x``, ``model["name"].u``, ``model["name"].pressure`` (Fluidic) and ``model.state(name, idx)``
    give the current iterate.
    """

    def __init__(self):
        self._blocks = {}
        self._links = []             # (source, target block, input indices or "volume")
        self._reads = []             # per link: names of the systems a callable source reads (None: any)
        self._controller = None
        self._controller_reads = None
        self._prepared = False
        self.t = 0.0

    # -- building --------------------------------------------------------------------------------------
    def add(self, system, name=None, x0=None):
        """Add a :class:`StateSpace`, :class:`Fluidic` or :class:`~soroshapes.shapes.Shapes` as ``name``
        (default its ``name`` or ``kind<k>``), optionally with its initial state ``x0``. Returns self."""
        name = name or getattr(system, "name", None) or f"{type(system).__name__.lower()}{len(self._blocks)}"
        if not isinstance(name, str) or name in self._blocks:
            raise ParameterError(f"system name {name!r} is not a new string; names so far: {list(self._blocks)}")
        blk = _block(name, system)
        blk.x0 = None if x0 is None else _vec(x0, "x0")
        if blk.x0 is not None and blk.x0.shape != (blk.n,):
            raise ParameterError(f"x0 of system {name!r} must have {blk.n} entries, got {blk.x0.shape}")
        self._blocks[name] = blk
        self._prepared = False
        return self

    def _target(self, target):
        if target not in self._blocks:
            raise ParameterError(f"no system {target!r} in the model; systems: {', '.join(self._blocks)}")
        return self._blocks[target]

    def connect(self, source, target, index=None, *, port="input", reads=None):
        """Declare a coupling; returns self.

        Parameters
        ----------
        source : str or callable
            A system name (its output: gauge pressure of a Fluidic, the state of a beam or, by default, of a
            StateSpace), or ``fn(model) -> array`` of the current model state.
        target : str
            The system that receives it.
        index : int, str, slice or sequence, optional
            Which of the target's inputs (indices or input names; default all). Sizes must match.
        port : "input" or "volume"
            ``"volume"``: ``source`` is ``fn(model) -> V`` [m^3] for the Fluidic ``target``.
        reads : sequence of str, optional
            For a callable ``source``: the systems whose states it reads. Declared for every callable (and
            the controller), they give the sparsity of the coupling term of the Jacobian (see
            :meth:`jacobian`); undeclared, the callable may read anything and the term is computed for every
            state. A named ``source`` declares itself.
        """
        blk = self._target(target)
        if reads is None and callable(source):
            reads = getattr(source, "reads", None)          # a StateMap declares what it reads
        reads = self._check_reads(reads, "connect")
        if not (callable(source) or source in self._blocks):
            raise ParameterError(f"connect: source must be a system name or a callable of the model, got {source!r}"
                                 f"; systems: {', '.join(self._blocks)}")
        if port == "volume":
            if blk.kind != "fluidic":
                raise ParameterError(f"connect(port='volume'): target {target!r} is a {blk.kind}, not a Fluidic")
            if not callable(source):
                raise ParameterError("connect(port='volume') takes a callable fn(model) -> V [m^3]")
            if any(t is blk and i == "volume" for _, t, i in self._links):
                raise ParameterError(f"system {target!r} already has a volume coupling")
            self._links.append((source, blk, "volume"))
            self._reads.append(reads)
        elif port == "input":
            idx = self._input_indices(blk, index)
            taken = {i for _, t, ii in self._links if t is blk and ii != "volume" for i in ii}
            if taken & set(idx):
                raise ParameterError(f"inputs {sorted(taken & set(idx))} of system {target!r} are already coupled")
            self._links.append((source, blk, idx))
            self._reads.append((source,) if not callable(source) else reads)
        else:
            raise ParameterError(f"port must be 'input' or 'volume', got {port!r}")
        self._prepared = False
        return self

    @staticmethod
    def _input_indices(blk, index):
        m = blk.m
        if index is None:
            idx = list(range(m))
        elif isinstance(index, slice):
            idx = list(range(m))[index]
        else:
            items = [index] if isinstance(index, (int, np.integer, str)) else list(index)
            idx = []
            for it in items:
                if isinstance(it, str):
                    if it not in blk.input_names:
                        raise ParameterError(f"system {blk.name!r} has no input {it!r}; inputs: {blk.input_names}")
                    idx.append(blk.input_names.index(it))
                elif 0 <= int(it) < m:
                    idx.append(int(it))
                else:
                    raise ParameterError(f"input index {it} out of range for system {blk.name!r} ({m} inputs)")
        if not idx:
            raise ParameterError(f"connect: no inputs of system {blk.name!r} selected ({m} inputs)")
        return idx

    def set_controller(self, fn, reads=None):
        """Set ``fn(model)`` giving the free inputs (those no coupling drives): a flat array in the order of
        :attr:`inputs`, or a dict ``{system name: array of its free inputs}`` (missing systems get 0). It is
        evaluated at every stage and Newton iterate (it is part of F). ``reads``: the systems whose states
        it reads (``()`` for a function of time only), as in :meth:`connect`. Returns self."""
        if fn is not None and not callable(fn):
            raise ParameterError("the controller must be a callable fn(model) -> inputs")
        self._controller = fn
        if reads is None:
            reads = getattr(fn, "reads", None)              # a Schedule reads no state
        self._controller_reads = self._check_reads(reads, "set_controller")
        self._prepared = False
        return self

    def _check_reads(self, reads, where):
        if reads is None:
            return None
        names = (reads,) if isinstance(reads, str) else tuple(reads)
        for nm in names:
            if nm not in self._blocks:
                raise ParameterError(f"{where}(reads=...): no system {nm!r} in the model; systems: "
                                     f"{', '.join(self._blocks)} (add the systems first)")
        return names

    # -- views -----------------------------------------------------------------------------------------
    @property
    def systems(self):
        """Names of the systems, in state order."""
        return list(self._blocks)

    @property
    def evaluation_paths(self):
        """How each system, the couplings and the controller are evaluated at every stage of a step: a dict of
        ``"compiled"`` (numba, no Python in the loop) or ``"python..."``. When the whole network lowers
        (:attr:`evaluation_path` is ``"compiled"``) every entry is ``"compiled"``; otherwise beams with gravity,
        inputs and point loads still evaluate in one compiled call each, and reservoirs, StateSpace and
        rigid-body right-hand sides, beams with contact, tendons or user forces, and every coupling and the
        controller run in Python; a beam that keeps the network on the Python path for a reason of its own
        (a time-varying point load: :func:`soroshapes.network.python_reason`) says so in its entry,
        ``"python: ..."``. Also in a trajectory's ``stats``."""
        return self._paths(self._lowered())

    def _paths(self, net):
        """:attr:`evaluation_paths` for the lowered network ``net`` (or the reason it has none)."""
        from .network import python_reason
        paths = {name: getattr(b.system, "evaluation_path", "python") for name, b in self._blocks.items()}
        compiled = not isinstance(net, str)
        if not compiled:
            for name, b in self._blocks.items():
                why = python_reason(b.system) if paths[name] == "compiled" else None
                if why is not None:
                    paths[name] = f"python: {why}"
        if self._links:
            paths["couplings"] = "compiled" if compiled else "python"
        if self._controller is not None:
            paths["controller"] = "compiled" if compiled else "python"
        if compiled:
            paths.update({name: "compiled" for name in self._blocks})
        return paths

    @property
    def evaluation_path(self):
        """How :meth:`simulate` runs the network (fixed steps): ``"compiled"`` (one numba kernel,
        :mod:`soroshapes.network`) or ``"python: ..."`` naming the first part that has no compiled form (a Python
        callable coupling or controller, a StateSpace with a Python f, a beam with contact, tendons or user
        forces). Also in a trajectory's ``stats``."""
        return self._path(self._lowered())

    @staticmethod
    def _path(net):
        return f"python: {net}" if isinstance(net, str) else "compiled"

    def _lowered(self):
        """The network lowered for the compiled kernel (:func:`soroshapes.network.lower`), or a str saying which
        part keeps it on the Python path."""
        from . import network
        self._prepare_layout()
        blocks = [dict(name=b.name, kind=b.kind, system=b.system, xoff=b.sl.start, n=b.n, woff=b.wsl.start,
                       nw=b.nw, m=b.m) for b in self._blocks.values()]
        links = [(src if callable(src) else src, b.name, idx) for src, b, idx in self._links if idx != "volume"]
        volumes = {b.name: src for src, b, idx in self._links if idx == "volume"}
        free = [(b.name, sum(1 for bb, _ in self._free if bb is b)) for b in self._blocks.values()
                if any(bb is b for bb, _ in self._free)]
        try:
            return network.lower(blocks, links, volumes, self._controller, (free, self._free_rows))
        except NotImplementedError as why:
            return f"{why} runs in Python"

    @property
    def n(self):
        """Total number of states."""
        return sum(b.n for b in self._blocks.values())

    @property
    def inputs(self):
        """Names ``system.input`` of the free inputs (set by the controller), in controller order."""
        self._prepare_layout()
        return [f"{b.name}.{b.input_names[k]}" for b, k in self._free]

    def __getitem__(self, name):
        self._prepare_layout()
        if name not in self._blocks:
            raise KeyError(f"no system {name!r}; systems: {', '.join(self._blocks)}")
        return _View(self, self._blocks[name])

    def state(self, name, index=slice(None)):
        """Current state of system ``name`` (``index``: int, slice or indices)."""
        return self[name].x[index]

    # -- layout and assembly ---------------------------------------------------------------------------
    def _prepare_layout(self):
        if self._prepared:
            return
        if not self._blocks:
            raise ParameterError("the model is empty: add systems with Model.add")
        i = j = 0
        for b in self._blocks.values():
            b.sl, b.wsl = slice(i, i + b.n), slice(j, j + b.nw)
            i, j = i + b.n, j + b.nw
        self._N, self._NW = i, j
        coupled = {(id(t), k) for _, t, ii in self._links if ii != "volume" for k in ii}
        self._free = [(b, k) for b in self._blocks.values() for k in range(b.m) if (id(b), k) not in coupled]
        self._free_at = {}                   # system name -> positions of its free inputs among the free inputs
        for p, (b, _) in enumerate(self._free):
            self._free_at.setdefault(b.name, []).append(p)
        self._free_at = {name: np.array(pos, dtype=int) for name, pos in self._free_at.items()}
        self._free_rows = np.array([b.wsl.start + k for b, k in self._free], dtype=int)
        self._vol_link = {id(t): s for s, t, ii in self._links if ii == "volume"}
        for b in self._blocks.values():
            if b.kind == "fluidic" and b.system.volume is None and id(b) not in self._vol_link:
                raise ParameterError(f"Fluidic {b.name!r} has volume=None and no volume coupling: add "
                                     f"model.connect(lambda mdl: V, {b.name!r}, port='volume')")
        self._x, self._w = np.zeros(self._N), np.zeros(self._NW)
        self._coupling_columns = self._coupling_pattern()
        self._prepared = True

    def _coupling_pattern(self):
        """Which states the inputs W(t, x) may depend on, from the declared reads: ``None`` when a callable or
        the controller did not declare them (every state), else per target system the set of systems it
        reads, closed over named sources whose output uses their own inputs (a Fluidic's pressure depends on
        its volume). Also sets the column groups for the finite differences (see :meth:`jacobian`)."""
        self._fd_groups = None
        if self._controller is not None and self._controller_reads is None:
            return None
        if any(r is None for r in self._reads):
            return None
        feeds = {name: set() for name in self._blocks}        # system -> systems its inputs read
        if self._controller is not None:
            for b, _ in self._free:
                feeds[b.name].update(self._controller_reads)
        for (src, b, _), r in zip(self._links, self._reads):
            feeds[b.name].update(r)
        changed = True
        while changed:                                          # close over sources that pass their inputs on
            changed = False
            for nm in feeds:
                more = set().union(*(feeds[s] for s in feeds[nm] if self._blocks[s].output_uses_inputs)) \
                    if feeds[nm] else set()
                if not more <= feeds[nm]:
                    feeds[nm] |= more
                    changed = True
        read = sorted(set().union(*feeds.values()), key=list(self._blocks).index)
        # Curtis-Powell-Reid grouping: systems that no target reads together are differenced together
        colors = []                                            # [(systems, targets reading them)]
        for sname in read:
            readers = {t for t, f in feeds.items() if sname in f}
            for members, seen in colors:
                if not (readers & seen):
                    members.append(sname)
                    seen |= readers
                    break
            else:
                colors.append(([sname], set(readers)))
        self._fd_groups = []
        for members, _ in colors:
            width = max(self._blocks[m].n for m in members)
            for k in range(width):
                cols = [self._blocks[m].sl.start + k for m in members if k < self._blocks[m].n]
                # rows of W each perturbed column owns: the inputs of the systems that read its system
                owner = {}
                for m in members:
                    if k < self._blocks[m].n:
                        for t, f in feeds.items():
                            if m in f:
                                owner[t] = self._blocks[m].sl.start + k
                self._fd_groups.append((np.array(cols), owner))
        cols = [np.arange(self._blocks[nm].sl.start, self._blocks[nm].sl.stop) for nm in read]
        return np.concatenate(cols) if cols else np.zeros(0, dtype=int)

    def _controller_values(self):
        nfree = len(self._free)
        if self._controller is None:
            return np.zeros(nfree)
        v = self._controller(self)
        if v is None:
            return np.zeros(nfree)
        if isinstance(v, dict):
            out = np.zeros(nfree)
            for name, val in v.items():
                pos = self._free_at.get(name, _NO_POSITIONS)
                if name not in self._blocks:
                    raise ParameterError(f"controller returned inputs for unknown system {name!r}; systems: "
                                         f"{', '.join(self._blocks)}")
                val = _vec(val, "controller")
                if val.shape != (len(pos),):
                    names = [self._blocks[name].input_names[k] for b, k in self._free if b.name == name]
                    raise ParameterError(f"controller returned {val.size} inputs for system {name!r}, which has "
                                         f"{len(pos)} free inputs {names}")
                out[pos] = val
        else:
            out = _vec(v, "controller")
            if out.shape != (nfree,):
                per = {}
                for b, k in self._free:
                    per.setdefault(b.name, []).append(b.input_names[k])
                raise ParameterError(f"controller returned {out.size} inputs, the model has {nfree} free inputs: "
                                     + "; ".join(f"system {n!r}: {v}" for n, v in per.items())
                                     + " (or return a dict {system name: inputs})")
        if not _finite(out):
            bad = {self._free[p][0].name for p in np.nonzero(~np.isfinite(out))[0]}
            raise DataError(f"controller returned non-finite inputs for system(s) {sorted(bad)} at t = {self.t:.6g} s")
        return out

    def set_state(self, t, x):
        """Make (t [s], x) the model's current state: volumes, controller and couplings are evaluated there, so
        that ``model["name"].x``, ``.u`` and callables of the model read it. Returns the assembled inputs."""
        self._prepare_layout()
        x = _vec(x, "x")
        if x.shape != (self._N,):
            raise ParameterError(f"the state must have {self._N} entries, got {x.shape}")
        return self._assemble(float(t), x).copy()

    def _assemble(self, t, x):
        """w = W(t, x): volumes, controller, couplings (in declaration order)."""
        self.t, self._x = t, x
        w = self._w = np.zeros(self._NW)
        for b in self._blocks.values():
            if b.kind == "fluidic":
                src = self._vol_link.get(id(b))
                V = b.system.volume_at(t) if src is None else src(self)
                V = float(np.asarray(V, dtype=float).reshape(-1)[0]) if np.size(V) == 1 else np.nan
                if not (np.isfinite(V) and V > 0):
                    raise DataError(f"the volume of Fluidic {b.name!r} is {V!r} at t = {t:.6g} s; it must be a "
                                    "positive scalar [m^3]")
                w[b.wsl.start + 1] = V
        u = self._controller_values()           # called even without free inputs: it may check and raise
        if len(u):
            w[self._free_rows] = u
        for src, b, idx in self._links:
            if idx == "volume":
                continue
            if callable(src):
                val, what = _vec(src(self), "coupling"), "coupling callable"
            else:
                s = self._blocks[src]
                val, what = _vec(s.output(x[s.sl], w[s.wsl], t), "output"), f"output of system {src!r}"
            if val.shape != (len(idx),):
                raise ParameterError(f"coupling into system {b.name!r}: the {what} has {val.size} entries, but "
                                     f"{len(idx)} inputs {[b.input_names[k] for k in idx]} are connected")
            if not _finite(val):
                raise DataError(f"coupling into system {b.name!r}: the {what} is not finite at t = {t:.6g} s")
            w[b.wsl.start + np.asarray(idx)] = val
        return w

    def _rhs(self, t, x):
        w = self._assemble(t, x)
        out = np.empty(self._N)
        for b in self._blocks.values():
            try:
                v = b.rhs(x[b.sl], w[b.wsl], t)
            except SoroError as err:
                raise type(err)(f"system {b.name!r} at t = {t:.6g} s: {err}") from err
            if v.shape != (b.n,) or not _finite(v):
                raise DataError(f"system {b.name!r} gave a non-finite or mis-sized derivative {v.shape} at "
                                f"t = {t:.6g} s (expected {b.n} finite values)")
            out[b.sl] = v
        return out

    def jacobian(self, t, x, sparse=False):
        r""":math:`\partial F/\partial x` (n, n) at (t, x), assembled block by block (module docstring):
        :math:`J = \mathrm{diag}(A_b) + \mathrm{diag}(B_b)\,\partial W/\partial x`, the coupling term by
        forward differences of the inputs :math:`W(t, x)` over the states they may depend on (all of them,
        unless every callable coupling and the controller declare what they read). ``sparse``: return a
        ``scipy.sparse`` CSC matrix assembled from the blocks (what :meth:`simulate` factorizes for large
        networks)."""
        self._prepare_layout()
        x = np.asarray(x, dtype=float)
        if getattr(self, "_scale", None) is None or len(self._scale) != self._N:
            self._scale = self._scales(x)
        w0 = self._assemble(t, x).copy()
        As, Bs = [], []
        for b in self._blocks.values():
            try:
                A, B = b.jac(x[b.sl], w0[b.wsl], t)
            except SoroError as err:
                raise type(err)(f"system {b.name!r} at t = {t:.6g} s: {err}") from err
            if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
                raise DataError(f"the Jacobian of system {b.name!r} is not finite at t = {t:.6g} s")
            As.append(np.asarray(A, dtype=float).reshape(b.n, b.n))
            Bs.append(np.asarray(B, dtype=float).reshape(b.n, b.nw))
        cols = np.arange(self._N) if self._coupling_columns is None else self._coupling_columns
        dW = None
        if (self._controller is not None or self._links) and len(cols):
            if self._fd_groups is None:          # every column alone
                dW = fd_columns(lambda xx: self._assemble(t, xx).copy(), x, w0, self._scale, cols)
            else:                                # grouped columns: each target's rows belong to one of them
                dW = np.zeros((self._NW, len(cols)))
                position = {j: k for k, j in enumerate(cols)}
                for group, owner in self._fd_groups:
                    xp = x.copy()
                    xp[group] += FD_STEP * np.maximum(np.abs(x[group]), self._scale[group])
                    dw = self._assemble(t, xp) - w0
                    for tname, j in owner.items():
                        rows = self._blocks[tname].wsl
                        dW[rows, position[j]] = dw[rows] / (xp[j] - x[j])
        self._assemble(t, x)
        if sparse:
            import scipy.sparse as sp
            J = sp.block_diag(As, format="csc")
            if dW is not None:   # diag(B_b) dW, its columns scattered to the states they belong to
                P = sp.csr_matrix((np.ones(len(cols)), (np.arange(len(cols)), cols)), shape=(len(cols), self._N))
                J = J + (sp.block_diag(Bs, format="csr") @ sp.csc_matrix(dW)) @ P
            return J.tocsc()
        J = np.zeros((self._N, self._N))
        Bw = np.zeros((self._N, self._NW))
        for b, A, B in zip(self._blocks.values(), As, Bs):
            J[b.sl, b.sl] = A
            Bw[b.sl, b.wsl] = B
        if dW is not None:
            J[:, cols] += Bw @ dW
        return J

    # -- initial state ---------------------------------------------------------------------------------
    def initial_state(self, x0=None, t=0.0):
        """The stacked initial state: ``x0`` if given, else each system's (``add(..., x0=)`` or its default;
        a Fluidic starts at gauge 0 in its initial volume, which a volume coupling evaluates at the others')."""
        self._prepare_layout()
        if x0 is not None:
            x = _vec(x0, "x0")
            if x.shape != (self._N,):
                raise ParameterError(f"x0 must have {self._N} entries ("
                                     + ", ".join(f"{b.name}: {b.n}" for b in self._blocks.values()) + ")")
        else:
            x = np.zeros(self._N)
            for b in self._blocks.values():
                v = b.x0 if b.x0 is not None else b.default_x0()
                if v is not None:
                    x[b.sl] = v
            self.t, self._x, self._w = t, x, np.zeros(self._NW)
            for b in self._blocks.values():
                if b.kind == "fluidic" and b.x0 is None:
                    src = self._vol_link.get(id(b))
                    V = b.system.volume_at(t) if src is None else float(np.asarray(src(self)).reshape(-1)[0])
                    x[b.sl] = b.system.initial_state(V)
        for b in self._blocks.values():
            if not np.all(np.isfinite(x[b.sl])):
                raise DataError(f"the initial state of system {b.name!r} contains NaN or inf: {x[b.sl]}")
        return x

    def _scales(self, x0, t0=0.0):
        s, w = np.ones(self._N), None
        for b in self._blocks.values():
            if b.kind == "fluidic":
                if w is None:                    # the volumes at (t0, x0): one assembly for every reservoir
                    w = self._assemble(t0, x0)
                b._V_init = w[b.wsl][1]
                b._uscale = (b.system.p0 * 0.01 if b.system.regulator else
                             b.system.scales(b._V_init)[0] * 10.0)
            b._scale = b.scale(x0[b.sl])
            s[b.sl] = b._scale
        return s

    # -- integration -----------------------------------------------------------------------------------
    def stepper(self, dt, method="trapezoidal", x0=None, t0=0.0, rtol=1e-6, atol=1e-9, *, max_iterations=12,
                min_dt=None, compiled=None, newton_tol=1e-3):
        """A :class:`Stepper` that continues the network from ``(t0, x0)`` call after call (``advance(t_end)``
        or ``advance(steps=k)``, fixed steps of at most ``dt`` [s], ``hold(u)`` for constant free inputs), keeping
        the lowered network and the integrator's memory between calls: what a real-time loop calls once per
        tick instead of :meth:`simulate`. The arguments mean what they mean in :meth:`simulate`.

        Examples
        --------
        >>> mdl = Model().add(StateSpace.linear([[-10.0]], [[10.0]]), "lag")
        >>> stp = mdl.stepper(1e-3).hold([1.0])
        >>> for k in range(1, 101):
        ...     x = stp.advance(k * 2.5e-3)                 # 100 ticks of 2.5 ms, 3 steps each
        >>> round(float(x[0]), 4), stp.stats["steps"]       # 1 - exp(-2.5)
        (0.9179, 300)
        """
        return Stepper(self, dt, method, x0, t0, rtol, atol, max_iterations, min_dt, compiled, newton_tol)

    def simulate(self, t_end, dt, method="trapezoidal", x0=None, rtol=1e-6, atol=1e-9, adaptive=False, *,
                 max_iterations=12, record_every=1, min_dt=None, max_dt=None, t0=0.0, linear_solver="auto",
                 compiled=None, newton_tol=1e-3):
        """Integrate the network from ``t0`` to ``t0 + t_end`` [s] by the implicit ``method`` ("trapezoidal",
        "midpoint", "bdf2"); ``t0`` lets a simulation continue from a state reached earlier (time-dependent
        volumes, signals and controllers see the absolute time). The trajectory is recorded every
        ``record_every`` multiples of ``h = t_end/ceil(t_end/dt)`` and at the end, in both modes:

        * ``adaptive=False``: fixed steps of ``h``;
        * ``adaptive=True``: error-controlled steps (:func:`soroshapes.integrate.integrate_adaptive`, the same
          rule on both paths), the first of ``h``, at most ``max_dt`` [s] (default: no limit), each step's local
          error estimate kept below ``rtol*|x_j| + atol*s_j`` (RMS); the records at the output times are the
          methods' second-order dense output (the quadratic through the last three states), not steps.

        ``rtol``, ``atol``: also the Newton tolerance: Newton stops when every correction (compiled path: the
        rate-based estimate of the remaining error, :mod:`soroshapes.integrate`) is below ``newton_tol`` (1e-3)
        of ``rtol*|x_j| + atol*s_j``. A step whose Newton iterations fail is split (fixed) or halved (adaptive) down
        to ``min_dt`` (default h/1024, adaptive h*1e-6), then a :class:`~sorofem.errors.ConvergenceError` gives
        the time. ``linear_solver``: the Newton matrix
        :math:`I - cJ` is factorized dense (LAPACK) or sparse (SuperLU on the block-sparse :meth:`jacobian`);
        ``"auto"`` takes sparse from 200 states on. ``compiled``: None runs the network in one compiled kernel
        (:mod:`soroshapes.network`, dense LU) when every part of it has a compiled form and on the
        Python path otherwise (:attr:`evaluation_path` says which and why); True requires the compiled kernel (a
        :class:`~sorofem.errors.ParameterError` names the part that has none); False forces the Python path.
        Returns a :class:`~soroshapes.trajectory.Trajectory`: ``t``, the stacked states ``x``, all inputs ``u``,
        ``stats``; ``traj["name"]`` is one system's (``x``, ``u``, and ``q``, ``qd`` of a beam or ``volume``,
        ``pressure`` of a reservoir).
        """
        _, t0 = _check_run(method, rtol, atol, t0, newton_tol)
        t_end, dt = float(t_end), float(dt)
        if not (t_end > 0 and dt > 0 and np.isfinite(t_end) and np.isfinite(dt)):
            raise ParameterError(f"t_end and dt must be positive [s], got {t_end!r}, {dt!r}")
        if max_dt is not None and not (float(max_dt) > 0 and np.isfinite(float(max_dt))):
            raise ParameterError(f"max_dt must be a positive step [s] or None (no limit), got {max_dt!r}")
        if linear_solver not in ("auto", "dense", "sparse"):
            raise ParameterError(f"linear_solver must be 'auto', 'dense' or 'sparse', got {linear_solver!r}")
        self._prepare_layout()
        x = self.initial_state(x0, t0)
        self._scale = self._scales(x, t0)
        self._rtol, self._atol, self._maxit = float(rtol), float(atol), int(max_iterations)
        self._ntol = float(newton_tol)
        self._sparse = linear_solver == "sparse" or (linear_solver == "auto" and self._N >= 200)
        self._rhs(t0, x)                                         # validates sizes, controller and couplings
        self._last_error = None
        self._J, self._lu_key, self._stats = None, None, {"steps": 0, "rejected": 0, "newton_iterations": 0,
                                                         "jacobians": 0, "cut_steps": 0, "matrices": 0}
        rec_t, rec_x, rec_w = [t0], [x.copy()], [self._assemble(t0, x).copy()]
        if compiled or compiled is None:
            net = self._lowered()
            if compiled and isinstance(net, str):
                raise ParameterError(f"simulate(compiled=True): the network has no compiled form: {net}; use "
                                     "StateMap couplings and a Schedule controller (soroshapes.network), or "
                                     "compiled=None for the Python path")
            if not isinstance(net, str):
                return self._simulate_compiled(net, x, t0, t_end, dt, method, record_every, min_dt, rec_w[0],
                                               adaptive, max_dt)
        else:
            net = None
        wall = _time.perf_counter()
        if adaptive:
            h = t_end / int(np.ceil(t_end / dt - 1e-9))
            self._stats["rejected"] = 0
            self._run_adaptive(x, t0, t0 + t_end, h, h * max(1, int(record_every)),
                               np.inf if max_dt is None else float(max_dt),
                               h * 1e-6 if min_dt is None else float(min_dt), method, rec_t, rec_x, rec_w)
        else:
            nsteps = int(np.ceil(t_end / dt - 1e-9))
            h = t_end / nsteps
            min_dt = h / 1024 if min_dt is None else float(min_dt)
            prev = None
            for k in range(nsteps):
                t = t0 + k * h
                if method == "bdf2" and prev is not None:
                    xn = self._step("bdf2", t, x, h, prev)
                    if xn is None:
                        xn = self._split("trapezoidal", t, x, h, h / 2, min_dt)
                        prev = None
                    else:
                        prev = x
                else:
                    base = "trapezoidal" if method == "bdf2" else method
                    xn = self._step(base, t, x, h)
                    if xn is None:
                        xn = self._split(base, t, x, h, h / 2, min_dt)
                    prev = x if method == "bdf2" else None
                x = xn
                self._stats["steps"] += 1
                if (k + 1) % record_every == 0 or k == nsteps - 1:
                    tt = t0 + (t_end if k == nsteps - 1 else (k + 1) * h)
                    rec_t.append(tt)
                    rec_x.append(x.copy())
                    rec_w.append(self._assemble(tt, x).copy())
        self._finish_stats(method, "python", adaptive, t_end / int(np.ceil(t_end / dt - 1e-9)),
                           _time.perf_counter() - wall)
        return self._trajectory(np.array(rec_t), np.array(rec_x), np.array(rec_w), net)

    def _simulate_compiled(self, net, x, t0, t_end, dt, method, record_every, min_dt, w0, adaptive=False,
                           max_dt=None):
        """Fixed steps by :func:`soroshapes.integrate.integrate` (the methods, refresh rule and splitting of the
        Python path; Newton per connected component with a rate-based stopping estimate), error-controlled ones
        by :func:`soroshapes.integrate.integrate_adaptive`."""
        from . import integrate as itg
        nsteps = int(np.ceil(t_end / dt - 1e-9))
        h = t_end / nsteps
        record_every = max(1, int(record_every))
        rows = 1 + nsteps // record_every + (1 if nsteps % record_every else 0)
        out_t, out_x, out_w = np.zeros(rows), np.zeros((rows, self._N)), np.zeros((rows, self._NW))
        out_t[0], out_x[0], out_w[0] = t0, x, w0
        st = np.zeros(32)
        code = {"trapezoidal": itg.TRAPEZOIDAL, "midpoint": itg.MIDPOINT, "bdf2": itg.BDF2}[method]
        wall = _time.perf_counter()
        if adaptive:
            min_dt = h * 1e-6 if min_dt is None else float(min_dt)
            got = itg.integrate_adaptive(x.copy(), t0, t0 + t_end, h, h * record_every,
                                         np.inf if max_dt is None else float(max_dt), code, min_dt, net.arrays,
                                         self._scale, self._rtol, self._atol, self._maxit, self._ntol, out_t, out_x,
                                         out_w, st)
            self._stats.update(min_step=float(st[28]), max_step=float(st[29]))
        else:
            min_dt = h / 1024 if min_dt is None else float(min_dt)
            got = itg.integrate(x.copy(), t0, h, nsteps, code, record_every, min_dt, net.arrays, self._scale,
                                self._rtol, self._atol, self._maxit, self._ntol, out_t, out_x, out_w, st,
                                itg.workspace(self._N, self._NW, net.arrays), x.copy())
        self._stats.update(steps=int(st[0]), rejected=int(st[1]), newton_iterations=int(st[2]),
                           jacobians=int(st[3]), cut_steps=int(st[6]), matrices=int(st[15]),
                           system_evaluations=int(st[8]), model_matrix_failures=int(st[10]),
                           linearized_predictions=int(st[18]), component_corrections=st[20:26].astype(int).tolist(),
                           first_corrections_within_tolerance=int(st[26]),
                           first_corrections_fresh_matrix=int(st[27]))
        self._finish_stats(method, "compiled", adaptive, h, _time.perf_counter() - wall)
        if got < 0:
            raise ConvergenceError(f"Model.simulate: Newton failed at t = {st[7]:.6g} s down to dt = {min_dt:.3g} s "
                                   f"({method}, compiled network: Newton did not converge, or an evaluation failed "
                                   "because a beam state overflowed or a reservoir volume was not positive); use a "
                                   "smaller dt, check the couplings and schedule for discontinuities and volume maps "
                                   "for their range, or loosen rtol (compiled=False gives the failing system's own "
                                   "message)")
        out_t[-1] = t0 + t_end
        return self._trajectory(out_t[:got], out_x[:got], out_w[:got], net)

    def _finish_stats(self, method, path, adaptive, h, wall):
        """The run's counters in ``self._stats`` as the one ``stats`` schema (:func:`soroshapes.trajectory.run_stats`),
        the path's own counters after it."""
        from .trajectory import STATS_KEYS, run_stats
        c = self._stats
        extra = {k: v for k, v in c.items() if k not in STATS_KEYS}
        self._stats = run_stats(steps=c["steps"], newton_iterations=c["newton_iterations"], matrices=c["matrices"],
                                jacobians=c["jacobians"], cut_steps=c["cut_steps"], rejected=c["rejected"], dt=h,
                                method=method, path=path, adaptive=adaptive, wall_time=wall, **extra)

    def _split(self, method, t, x, h, hh, min_dt):
        """Cover [t, t+h] with steps of hh (halved on failure) after a failed step."""
        self._stats["cut_steps"] += 1
        end = t + h
        while t < end - 1e-12 * h:
            step = min(hh, end - t)
            xn = self._step(method, t, x, step)
            if xn is None:
                hh *= 0.5
                if hh < min_dt:
                    why = getattr(self, "_last_error", None)
                    raise ConvergenceError(f"Model.simulate: Newton failed at t = {t:.6g} s down to dt = "
                                           f"{min_dt:.3g} s ({method}); use a smaller dt, check the couplings and "
                                           "controller for discontinuities, or loosen rtol"
                                           + (f" (last error: {why})" if why else ""))
                continue
            x, t = xn, t + step
        return x

    def _weights(self, x):
        return self._rtol * np.abs(x) + self._atol * self._scale

    def _step(self, method, t, x0, h, xprev=None, omega=1.0):
        """One implicit step; returns x1 or None when Newton fails. BDF2 after a step of h/omega (variable-step
        coefficients, :mod:`soroshapes.integrate`)."""
        N = self._N
        if method == "trapezoidal":
            f0 = self._rhs(t, x0)
            c, t1 = 0.5 * h, t + h
            res = lambda x1: x1 - x0 - 0.5 * h * (f0 + self._rhs(t1, x1))           # noqa: E731
            jac_at = lambda x1: (t1, x1)                                            # noqa: E731
            guess = x0 + h * f0
        elif method == "midpoint":
            c, tm = 0.5 * h, t + 0.5 * h
            res = lambda x1: x1 - x0 - h * self._rhs(tm, 0.5 * (x0 + x1))            # noqa: E731
            jac_at = lambda x1: (tm, 0.5 * (x0 + x1))                              # noqa: E731
            guess = x0 + h * self._rhs(t, x0)
        elif omega == 1.0:
            c, t1 = 2.0 * h / 3.0, t + h
            res = lambda x1: x1 - 4.0 / 3.0 * x0 + xprev / 3.0 - c * self._rhs(t1, x1)   # noqa: E731
            jac_at = lambda x1: (t1, x1)                                            # noqa: E731
            guess = 2.0 * x0 - xprev
        else:
            d = 1.0 + 2.0 * omega
            c, t1 = h * (1.0 + omega) / d, t + h
            xhat = ((1.0 + omega) ** 2 * x0 - omega ** 2 * xprev) / d
            res = lambda x1: x1 - xhat - c * self._rhs(t1, x1)                     # noqa: E731
            jac_at = lambda x1: (t1, x1)                                            # noqa: E731
            guess = x0 + omega * (x0 - xprev)
        from scipy.linalg import lu_factor, lu_solve
        for attempt in range(2):
            fresh = self._J is None or attempt == 1
            if fresh:
                try:
                    self._J = self.jacobian(*jac_at(guess if attempt == 0 else x1), sparse=self._sparse)
                except (DataError, FloatingPointError) as err:
                    self._last_error, self._J = str(err), None
                    return None
                self._stats["jacobians"] += 1
                self._lu_key = None
                if not np.all(np.isfinite(self._J.data if self._sparse else self._J)):
                    self._last_error, self._J = "the Jacobian is not finite", None
                    return None
            if self._lu_key != c:
                if self._sparse:
                    import scipy.sparse as sp
                    from scipy.sparse.linalg import splu
                    self._lu = splu((sp.identity(N, format="csc") - c * self._J).tocsc())
                else:
                    self._lu = lu_factor(np.eye(N) - c * self._J)
                self._lu_key = c
                self._stats["matrices"] += 1
            x1 = guess.copy()
            prev_norm, ok = np.inf, False
            for it in range(self._maxit):
                try:
                    r = res(x1)
                except (DataError, FloatingPointError, np.linalg.LinAlgError) as err:
                    self._last_error = str(err)
                    break
                if not np.all(np.isfinite(r)):
                    break
                dx = self._lu.solve(r) if self._sparse else lu_solve(self._lu, r)
                x1 = x1 - dx
                self._stats["newton_iterations"] += 1
                nrm = np.max(np.abs(dx) / self._weights(x1))
                if not np.all(np.isfinite(x1)):
                    break
                if nrm <= self._ntol:
                    ok = True
                    break
                if it >= 2 and nrm > 0.5 * prev_norm:
                    break                                   # slow contraction: refresh the Jacobian
                prev_norm = nrm
            if ok:
                return x1
            log.debug("Newton at t = %.6g s, h = %.3g s: refreshing the Jacobian", t, h)
            if not np.all(np.isfinite(x1)):
                x1 = guess.copy()
            if fresh and attempt == 1:
                break
        self._J = None
        return None

    def _run_adaptive(self, x, t0, t_end, h, dt_out, max_dt, min_dt, method, rec_t, rec_x, rec_w):
        """Error-controlled steps: the rule of :func:`soroshapes.integrate.integrate_adaptive` (its error
        estimate, step factor and dense output) over the Python step."""
        from . import integrate as itg
        code = {"trapezoidal": itg.TRAPEZOIDAL, "midpoint": itg.MIDPOINT, "bdf2": itg.BDF2}
        n_out = int(np.ceil((t_end - t0) / dt_out - 1e-9))
        outs = [t0 + k * dt_out for k in range(1, n_out)] + [t_end]
        N = self._N
        xm1, pp, xp, xo = x.copy(), x.copy(), np.zeros(N), np.zeros(N)
        h1, h2, nhist, t, k = h, h, 0, t0, 0
        h = min(h, max_dt)
        steps = []
        while k < len(outs):
            if t + h > t_end - 1e-9 * h:
                h = t_end - t
            m = "trapezoidal" if method == "bdf2" and nhist == 0 else method
            xn = self._step(m, t, x, h, xm1, h / h1)
            if xn is None:
                self._stats["cut_steps"] += 1
                h *= 0.5
                if h < min_dt:
                    why = getattr(self, "_last_error", None)
                    raise ConvergenceError(f"Model.simulate (adaptive): Newton failed at t = {t:.6g} s down to dt = "
                                           f"{min_dt:.3g} s ({method}); check the couplings and controller for "
                                           "discontinuities, or loosen rtol" + (f" (last error: {why})" if why else ""))
                continue
            err = -1.0
            if nhist == 2:
                itg.lagrange3(x, xm1, pp, h, h1, h2, xp)
                err = itg.local_error(code[m], x, xn, xp, h, h1, h2, self._rtol, self._atol, self._scale)
            if err > 1.0:
                self._stats["rejected"] += 1
                h *= itg.step_factor(err, False)
                if h < min_dt:
                    raise ConvergenceError(f"Model.simulate (adaptive): the step fell below {min_dt:.3g} s at "
                                           f"t = {t:.6g} s; loosen rtol/atol or check the model for discontinuities")
                continue
            tn = t + h
            while k < len(outs) and outs[k] <= tn + 1e-9 * h:
                itg.dense_output(outs[k] - tn, xn, x, xm1, h, h1, nhist, xo)
                rec_t.append(outs[k])
                rec_x.append(xo.copy())
                rec_w.append(self._assemble(outs[k], xo).copy())
                k += 1
            pp, xm1, x = xm1, x, xn
            h2, h1, nhist, t = h1, h, min(nhist + 1, 2), tn
            steps.append(h)
            self._stats["steps"] += 1
            h = min(h * itg.step_factor(err, True), max_dt)
        self._stats.update(min_step=min(steps), max_step=max(steps))

    def _trajectory(self, t, X, W, net=None):
        net = self._lowered() if net is None else net          # lowered once per simulate
        self._stats["evaluation_paths"] = self._paths(net)
        self._stats["evaluation_path"] = self._path(net)
        systems, U = {}, []
        for b in self._blocks.values():
            x, w = X[:, b.sl], W[:, b.wsl]
            u = w[:, :b.m]
            U.append(u)
            extra = {}
            if b.kind == "shapes":
                extra = {"q": x[:, :b.nq], "qd": x[:, b.nq:]}
            elif b.kind == "fluidic":
                V = w[:, 1]
                fl = b.system             # gauge pressure, vectorized (Fluidic.pressure for each row)
                p = x[:, 0] * fl.R * fl.T / V if fl.isothermal else x[:, 0]
                extra = {"volume": V, "pressure": p - fl.p0}
            systems[b.name] = Trajectory(t, x=x, u=u, name=b.name, **extra)
        return Trajectory(t, x=X, u=np.hstack(U) if U else np.zeros((len(t), 0)), systems=systems,
                          stats=self._stats)


# ------------------------------------------------------------------------------------------------------------
# continuing a run call after call
# ------------------------------------------------------------------------------------------------------------
#: the controller's table (K, m) in :func:`soroshapes.network.lower`'s argument tuple, and its kind (1: Schedule)
_NET_CONTROLLER_KIND, _NET_SCHEDULE_VALUES = 10, 12


class Stepper:
    r"""A :class:`Model` run continued call after call (:meth:`Model.stepper`): what a real-time loop calls
    once per tick.

    It lowers the network once and keeps, between calls of :meth:`advance`, the state, the time, the lowered
    network, the integrator's work arrays (the factored iteration matrix, the predictors' memory, the BDF2
    history) and its statistics, so that N calls of ``advance(steps=k)`` take the steps of one
    ``Model.simulate`` over the same span (to round-off in the step times), at the cost of the steps alone.
    The steps are :func:`soroshapes.integrate.integrate`'s, the one fixed-step loop of the compiled path; a
    network without a compiled form (:attr:`Model.evaluation_path`) is continued by :meth:`Model.simulate` on
    the Python path at each call (correct, without the kept matrix).

    Attributes
    ----------
    t : float [s]
        The time of the state.
    dt : float [s]
        The largest step.
    path : str
        ``"compiled"`` or ``"python: ..."`` (why).
    """

    def __init__(self, model, dt, method="trapezoidal", x0=None, t0=0.0, rtol=1e-6, atol=1e-9, max_iterations=12,
                 min_dt=None, compiled=None, newton_tol=1e-3):
        self._code, t0 = _check_run(method, rtol, atol, t0, newton_tol)
        dt = float(dt)
        if not (dt > 0 and math.isfinite(dt)):
            raise ParameterError(f"the stepper's dt must be a positive step [s], got {dt!r}")
        if min_dt is not None and not (float(min_dt) > 0):
            raise ParameterError(f"min_dt must be a positive step [s] or None (dt/1024), got {min_dt!r}")
        self.model, self.dt, self.method, self.t = model, dt, method, t0
        self._rtol, self._atol, self._maxit = float(rtol), float(atol), int(max_iterations)
        self._ntol = float(newton_tol)
        self._min_dt = None if min_dt is None else float(min_dt)
        self._compiled = compiled
        self._held = None
        self._counts = dict(steps=0, newton_iterations=0, matrices=0, jacobians=0, cut_steps=0, wall_time=0.0)
        model._prepare_layout()
        x = model.initial_state(x0, t0)
        self._x = x.copy()
        self._lower()

    def _lower(self):
        """(Re)lower the network and start the integrator's memory afresh (a new network, new work arrays)."""
        from . import integrate as itg
        mdl = self.model
        mdl._prepare_layout()
        self._scale = mdl._scales(self._x, self.t)
        mdl._rhs(self.t, self._x)                         # validates sizes, controller and couplings once
        net = mdl._lowered() if self._compiled or self._compiled is None else "compiled=False"
        if self._compiled and isinstance(net, str):
            raise ParameterError(f"stepper(compiled=True): the network has no compiled form: {net}")
        self._net = None if isinstance(net, str) else net
        self.path = Model._path(net)
        if self._net is not None:
            N, NW = mdl._N, mdl._NW
            self._ws = itg.workspace(N, NW, self._net.arrays)
            self._st = np.zeros(32)
            self._prev = self._x.copy()
            self._out = (np.zeros(2), np.zeros((2, N)), np.zeros((2, NW)))
            self._h = None

    @property
    def x(self):
        """The stacked state now (a copy)."""
        return self._x.copy()

    def set_state(self, x, t=None):
        """Replace the state (and the time ``t`` [s] if given), e.g. to vent reservoirs: the next step starts from
        it without history (BDF2 restarts with a trapezoidal step; the iteration matrix is kept and refreshed by
        the Newton rule if it no longer fits). Returns self."""
        x = _vec(x, "x")
        if x.shape != self._x.shape:
            raise ParameterError(f"the state must have {self._x.size} entries, got {x.shape}")
        if not _finite(x):
            raise DataError("set_state: the state contains NaN or inf")
        self._x[:] = x
        if t is not None:
            if not math.isfinite(float(t)):
                raise ParameterError(f"t must be a finite time [s], got {t!r}")
            self.t = float(t)
        if self._net is not None:
            self._forget_history()
        return self

    def _forget_history(self):
        """The next step starts without history: no BDF2 history (st[31]), no linearized predictor's memory
        (st[16], st[19]: it is of another state), no quadratic predictor (st[5]); the matrix is kept."""
        self._st[31] = self._st[16] = self._st[19] = self._st[5] = 0.0

    def hold(self, u):
        """Hold the free inputs (:attr:`Model.inputs` order) at the constant ``u`` from now on. The first call
        makes a constant :class:`~soroshapes.network.Schedule` the model's controller (and lowers the network
        again); later calls write ``u`` into its table in place, in the lowered network too. Returns self."""
        from .network import Schedule
        mdl = self.model
        u = _vec(u, "u")
        m = len(mdl._free)
        if u.shape != (m,):
            raise ParameterError(f"hold: the model has {m} free inputs {mdl.inputs}, got {u.size} values")
        if not _finite(u):
            raise DataError("hold: the inputs must be finite")
        if self._held is None or mdl._controller is not self._held:
            self._held = Schedule([0.0, 1.0], np.vstack([u, u]))
            mdl.set_controller(self._held)
            self._lower()
            return self
        self._held.values[:] = u                       # the Python path reads the Schedule
        if self._net is not None:
            arrays = self._net.arrays
            if not (arrays[_NET_CONTROLLER_KIND] == 1 and arrays[_NET_SCHEDULE_VALUES].shape == (2, m)):
                raise SoroError("hold: the lowered network's controller is not the held Schedule (report this)")
            arrays[_NET_SCHEDULE_VALUES][:] = u
        return self

    def advance(self, t_end=None, *, steps=None):
        """Continue to the time ``t_end`` [s] (steps of ``(t_end - t)/ceil((t_end - t)/dt)``) or by ``steps``
        steps of ``dt``; returns the state there (a copy). A step that fails down to ``min_dt`` raises
        :class:`~sorofem.errors.ConvergenceError` and leaves the stepper at the state and time of the call."""
        from . import integrate as itg
        if (t_end is None) == (steps is None):
            raise ParameterError("advance takes the time t_end [s] or a number of steps, one of them")
        if steps is not None:
            n = int(steps)
            if n < 1:
                raise ParameterError(f"advance: steps must be >= 1, got {steps!r}")
            h = self.dt
            t_next = self.t + n * h
        else:
            t_next = float(t_end)
            span = t_next - self.t
            if not (span > 0 and math.isfinite(span)):
                raise ParameterError(f"advance: t_end = {t_end!r} s must be a finite time after t = {self.t:.6g} s")
            n = int(math.ceil(span / self.dt - 1e-9))
            h = span / n
        min_dt = h / 1024 if self._min_dt is None else self._min_dt
        wall = _time.perf_counter()
        if self._net is None:
            tr = self.model.simulate(n * h, h, self.method, x0=self._x, t0=self.t, rtol=self._rtol, atol=self._atol,
                                     max_iterations=self._maxit, record_every=n + 1, min_dt=min_dt, compiled=False,
                                     newton_tol=self._ntol)
            st = tr.stats
            for k in ("steps", "newton_iterations", "matrices", "jacobians", "cut_steps"):
                self._counts[k] += int(st[k])
            self._x[:] = tr.x[-1]
        else:
            if h != self._h:
                self._st[31] = 0.0                     # the BDF2 history was at another step
                self._h = h
            x_start, st = self._x.copy(), self._st
            before = st[[0, 2, 3, 6, 15]].copy()
            out_t, out_x, out_w = self._out
            got = itg.integrate(self._x, self.t, h, n, self._code, n, min_dt, self._net.arrays, self._scale,
                                self._rtol, self._atol, self._maxit, self._ntol, out_t, out_x, out_w, st, self._ws,
                                self._prev)
            d = st[[0, 2, 3, 6, 15]] - before
            for k, v in zip(("steps", "newton_iterations", "jacobians", "cut_steps", "matrices"), d):
                self._counts[k] += int(v)
            if got < 0:
                self._x[:] = x_start
                self._forget_history()
                self._counts["wall_time"] += _time.perf_counter() - wall
                raise ConvergenceError(f"Model stepper: Newton failed at t = {st[7]:.6g} s down to dt = {min_dt:.3g} "
                                       f"s ({self.method}, compiled network); the stepper stays at t = {self.t:.6g} "
                                       "s; use a smaller dt, check the couplings and schedule for discontinuities, "
                                       "or loosen rtol")
        self.t = t_next
        self._counts["wall_time"] += _time.perf_counter() - wall
        return self._x.copy()

    @property
    def stats(self):
        """The statistics of every step taken so far, in the schema of :mod:`soroshapes.trajectory`."""
        from .trajectory import run_stats
        c = self._counts
        return run_stats(steps=c["steps"], newton_iterations=c["newton_iterations"], matrices=c["matrices"],
                         jacobians=c["jacobians"], cut_steps=c["cut_steps"], rejected=0, dt=self.dt,
                         method=self.method, path="compiled" if self._net is not None else "python", adaptive=False,
                         wall_time=c["wall_time"])
