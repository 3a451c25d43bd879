r"""Compiled networks: a :class:`~soroshapes.model.Model` lowered to flat arrays and integrated by one numba kernel.

What is lowered
---------------
:meth:`Model.simulate <soroshapes.model.Model.simulate>` runs a network here, with no Python in the step loop,
when every part of it has a compiled form:

* systems: :class:`~soroshapes.shapes.Shapes` beams whose loads run compiled (gravity, chambers and linear
  actuators: ``Shapes.evaluation_path == "compiled"``; point loads whose force and moment are constants, in the
  body or the spatial frame, carried in the beam's flat arrays and evaluated by the beam's own recursions, while
  a time-varying one keeps the Python path, :func:`python_reason`; contact with fixed obstacles,
  ``Shapes.add_contact``, whose SDF has a program form, :mod:`sorofem.sdf.program`), every :class:`~soroshapes.model.Fluidic`
  reservoir (isothermal or polytropic, regulated or not, with the saturation or the orifice valve of
  :mod:`soroshapes.valves`; a Python valve function keeps the Python path) whose volume is constant or given by a
  :class:`StateMap`, linear systems (:meth:`StateSpace.linear <soroshapes.model.StateSpace.linear>`, and
  :class:`~soroshapes.rigid.SpinningBody`, which is one) and free rigid bodies (:class:`~soroshapes.rigid.RigidBody`,
  its ``rigid_parameters``);
* couplings: the output of a named system (a beam's state, a reservoir's gauge pressure, a linear system's
  :math:`Cx + Du`) into inputs of another, and :class:`StateMap` (an affine map of one system's state through an optional ``tanh``), as an
  input or as a reservoir's volume; the wrenches on a free rigid body (a :class:`~soroshapes.rigid.WrenchSum`)
  of ground contact (:func:`~soroshapes.rigid.couple_ground`), of beam-body contact
  (:func:`~soroshapes.rigid.couple_contact`, also on a :class:`~soroshapes.rigid.SpinningBody`; the body's
  shape as an SDF program evaluated by one interpreter, :mod:`soroshapes._contact`), of the contact of points on
  a tree's bodies (:func:`~soroshapes.rigid.couple_tree_contact`: its force on the tree is put on the tree block
  by the same term, the tree's ``force<i>`` inputs stay zero) and of a grasp
  (:func:`~soroshapes.rigid.couple_grasp`, engaged always or by a one-column :class:`Schedule`; its force on
  the beam is added to the beam's inputs' force);
* the controller: none, a :class:`Schedule` (a piecewise-linear table of the free inputs against time,
  optionally periodic), or :func:`soroshapes.control.impedance` with a constant or :class:`Schedule`
  set-point (its parameters as data: the same equations, from the beam's kinematics, M, C and f_g in the
  kernel; evaluated only when the beam it drives is), and the joint-space controllers and feed-forwards of
  :mod:`soroshapes.control` (compensation, PD, PID with constant set-point, feed-forward inputs, torques or
  configurations from a Schedule, and :func:`~soroshapes.control.combine` of them).

Anything else (a Python callable coupling or controller, a :class:`~soroshapes.model.StateSpace` with a
Python ``f``, beams with tendons or user forces, contact with an SDF node without program form, adaptive steps)
runs on the Python path of
:mod:`soroshapes.model`; :attr:`Model.evaluation_paths <soroshapes.model.Model.evaluation_paths>` names the
first part that forces it. :class:`StateMap` and :class:`Schedule` are also callables of the model, so the
same network runs on both paths (the tests compare them).

The kernel
----------
The network's right-hand side :math:`F(t, x)` is assembled as on the Python path: reservoir volumes, the
controller's free inputs, then the couplings in declaration order, then every system's derivative (a beam by
:func:`soroshapes._beam.forward_dynamics`, its input force :math:`G u` with the constant input matrix); an
implicit step's residual (:func:`residual`) takes a beam second order, its equations of motion in force units
by one pass of the O(N) recursions. The
rows of the Newton matrix of reservoirs, linear systems and beam input forces are in closed form
(:func:`_analytic_rows`: the inputs' Jacobian through StateMaps and output couplings), and so are the rows of beam
contacts with a spinning body or fixed obstacles, on the beam and on the body (:func:`_contact_rows`, the law's
derivatives through the nodes' Jacobians, :func:`soroshapes._contact.contact_jacobian`); a tree block's are its
model rows (:func:`soroshapes._treeblock.block_model_rows`: its mass matrix and K, D, and the differenced force
of its inputs and contact terms, not its dynamics); the rest, and the full
Jacobian :math:`J = \partial F/\partial x` (:func:`jacobian`) when a beam's model matrix fails, are taken by
forward differences of :math:`F` whose columns are grouped (Curtis-Powell-Reid) over the block dependency pattern
(a column of system :math:`j` changes only the derivatives of the systems that read :math:`j`). The implicit steps, Newton and the step splitting are
:mod:`soroshapes.integrate`; many steps run in one compiled call, recording states and inputs every
``record_every`` steps. The two paths agree to the Newton tolerance (tests/soroshapes/test_network.py).
"""
from __future__ import annotations

import math

import numpy as np

from sorofem._lazy import moved_attributes
from sorofem._numba import njit
from sorofem.errors import ParameterError

from ._beam import _lu, _lu_solve
from ._beam import forward_dynamics as _fd
from ._beam import kinematics as _kinematics
from ._beam import mass_matrix_pieces as _mass_pieces
from ._beam import is_planar as _is_planar
from ._beam import mass_matrix_planar as _mass_planar
from ._beam import newton_euler as _ne
from ._beam import newton_euler_planar as _ne_planar
from ._beam import mass_coriolis_gravity as _mcg
from ._contact import contact_force as _contact_force
from ._contact import contact_jacobian as _contact_jacobian
from ._contact import tree_contact_force as _tree_contact_force
from . import _treeblock        # the tree block kind
from .numerics import FD_STEP
from .valves import orifice_flow

__all__ = ["StateMap", "Schedule", "lower", "python_reason", "assemble", "rhs", "residual", "jacobian"]

_FUNCTIONS = {"identity": 0, "tanh": 1}


# ------------------------------------------------------------------------------------------------------------
# declarative couplings and controllers (callables of the model for the Python path, tables for the kernel)
# ------------------------------------------------------------------------------------------------------------
class StateMap:
    r"""A coupling :math:`y = o + s \odot \phi(A\,x_{[index]})` of one system's state :math:`x`.

    Parameters
    ----------
    system : str
        Name of the system whose state is read.
    matrix : (k, len(index)) or (len(index),) array
        :math:`A` (units: those of :math:`y/s` per state unit).
    index : int, sequence of int or None
        The state entries read (default all).
    offset, scale : float or (k,)
        :math:`o` and :math:`s` (units of :math:`y`).
    function : "identity" or "tanh"
        :math:`\phi`, applied entrywise.

    Use it as ``model.connect(StateMap(...), target, port="volume")`` (a reservoir's volume [m^3]) or as an input
    coupling; it runs compiled (see the module docstring) and, as a callable of the model, on the Python path.

    Examples
    --------
    >>> V = StateMap("finger", [2e-5], index=0, offset=1e-4, scale=1e-4, function="tanh")
    >>> V.reads
    ('finger',)
    """

    def __init__(self, system, matrix, *, index=None, offset=0.0, scale=1.0, function="identity"):
        if not isinstance(system, str):
            raise ParameterError(f"StateMap reads a system by its name (a str), got {system!r}")
        if function not in _FUNCTIONS:
            raise ParameterError(f"StateMap function must be one of {sorted(_FUNCTIONS)}, got {function!r}")
        A = np.atleast_2d(np.asarray(matrix, dtype=float))
        self.index = None if index is None else np.atleast_1d(np.asarray(index, dtype=np.int64)).reshape(-1)
        if self.index is not None and A.shape[1] != len(self.index):
            raise ParameterError(f"StateMap matrix has {A.shape[1]} columns for {len(self.index)} indices")
        self.offset = np.broadcast_to(np.asarray(offset, dtype=float), (A.shape[0],)).copy()
        self.scale = np.broadcast_to(np.asarray(scale, dtype=float), (A.shape[0],)).copy()
        for what, v in (("matrix", A), ("offset", self.offset), ("scale", self.scale)):
            if not np.all(np.isfinite(v)):
                raise ParameterError(f"StateMap {what} must be finite, got {v}")
        self.system, self.matrix, self.function = system, A, function
        self.reads = (system,)

    @property
    def size(self):
        """Number of outputs k."""
        return self.matrix.shape[0]

    def full_matrix(self, n):
        """:math:`A` scattered onto all ``n`` states of the system (k, n)."""
        idx = np.arange(n) if self.index is None else self.index
        if idx.size != self.matrix.shape[1] or (idx.size and (idx.min() < 0 or idx.max() >= n)):
            raise ParameterError(f"StateMap of system {self.system!r}: indices {idx.tolist()} / matrix with "
                                 f"{self.matrix.shape[1]} columns do not fit its {n} states")
        A = np.zeros((self.size, n))
        A[:, idx] = self.matrix
        return A

    def __call__(self, model):
        x = model.state(self.system)
        a = self.full_matrix(len(x)) @ x
        return self.offset + self.scale * (np.tanh(a) if self.function == "tanh" else a)


class Schedule:
    r"""A controller that plays a piecewise-linear table of the free inputs against time.

    Parameters
    ----------
    times : (K,) increasing [s]
    values : (K, m) array in the order of :attr:`Model.inputs <soroshapes.model.Model.inputs>`, or a dict
        ``{system name: (K, m_system)}`` (a system left out gets 0)
    period : float [s], optional
        Repeat the table with this period (then ``times`` must run from 0 to ``period``); otherwise the
        first and last rows hold before and after the table.

    Set it with ``model.set_controller(Schedule(...))``: it runs compiled and, as a callable of the model,
    on the Python path (it reads no state).

    Examples
    --------
    >>> s = Schedule([0.0, 1.0], {"cup": [[0.0], [2.0]]})
    >>> float(s.at(0.25)["cup"][0])
    0.5
    """

    reads = ()

    def __init__(self, times, values, *, period=None):
        t = np.asarray(times, dtype=float).reshape(-1)
        if t.size < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise ParameterError("Schedule times must be at least 2 finite, strictly increasing times [s]")
        if isinstance(values, dict):
            self.values = {k: np.asarray(v, dtype=float).reshape(t.size, -1) for k, v in values.items()}
            arrays = self.values.values()
        else:
            self.values = np.asarray(values, dtype=float).reshape(t.size, -1)
            arrays = (self.values,)
        if not all(np.all(np.isfinite(v)) for v in arrays):
            raise ParameterError("Schedule values must be finite")
        if period is not None:
            period = float(period)
            if not (period > 0 and abs(t[0]) <= 1e-12 * period and abs(t[-1] - period) <= 1e-9 * period):
                raise ParameterError(f"a periodic Schedule needs times from 0 to the period {period!r} s, got "
                                     f"{t[0]:g} .. {t[-1]:g} s")
        self.times, self.period = t, period

    @classmethod
    def sample(cls, fn, t_end, dt, *, period=None):
        """The table of ``fn(t) -> (m,)`` sampled every ``dt`` [s] (or so: a whole number of intervals) on [0,
        ``t_end``] (with ``period``: on one period). Linear interpolation between samples is within
        :math:`\\tfrac{dt^2}{8}\\max|\\ddot u|` of ``fn``."""
        span = float(period if period is not None else t_end)
        k = max(1, int(math.ceil(span / float(dt) - 1e-9)))
        t = np.linspace(0.0, span, k + 1)
        return cls(t, np.array([np.asarray(fn(ti), dtype=float).reshape(-1) for ti in t]), period=period)

    def _phase(self, t):
        return t % self.period if self.period is not None else t

    def at(self, t):
        """The table's values at time ``t`` [s] (an array or a dict, like ``values``)."""
        tt = self._phase(float(t))
        if isinstance(self.values, dict):
            return {k: np.array([np.interp(tt, self.times, v[:, j]) for j in range(v.shape[1])])
                    for k, v in self.values.items()}
        times, v = self.times, self.values      # np.interp of every column at once
        if not tt > times[0]:
            return v[0].copy()
        if not tt < times[-1]:
            return v[-1].copy()
        k = int(np.searchsorted(times, tt, side="right")) - 1
        return (v[k + 1] - v[k]) / (times[k + 1] - times[k]) * (tt - times[k]) + v[k]

    def __call__(self, model):
        return self.at(model.t)

    def table(self, free):
        """The (K, m) table in the order of the free inputs ``free``, a list of (system name, count)."""
        if not isinstance(self.values, dict):
            m = sum(c for _, c in free)
            if self.values.shape[1] != m:
                raise ParameterError(f"Schedule has {self.values.shape[1]} columns, the model has {m} free inputs")
            return self.values
        cols = []
        for name, count in free:
            v = self.values.get(name)
            if v is None:
                v = np.zeros((self.times.size, count))
            if v.shape[1] != count:
                raise ParameterError(f"Schedule gives {v.shape[1]} inputs for system {name!r}, which has {count} "
                                     "free inputs")
            cols.append(v)
        unknown = set(self.values) - {name for name, _ in free}
        if unknown:
            raise ParameterError(f"Schedule gives inputs for systems without free inputs: {sorted(unknown)}")
        return np.hstack(cols) if cols else np.zeros((self.times.size, 0))


# ------------------------------------------------------------------------------------------------------------
# lowering: the network as flat arrays
# ------------------------------------------------------------------------------------------------------------
BEAM, FLUIDIC, LINEAR, RIGID = 0, 1, 2, 3
TREE = 4     # a tree of bodies (soroshapes._treeblock), its arrays the last entry of the tuple
#: floats per reservoir (rows of ``fpar``): isothermal, R, T, p0, n, leak, filter gain, regulated, kp, ki, max flow,
#: filtered, volume kind and value, valve kind (0 saturation, 1 orifice) and the orifice's gain, b, supply, exhaust
#: and full flow (soroshapes.valves)
_FLUIDIC_FLOATS = 20
#: floats per rigid body (rows of ``rflt``): mass, inertia (9), its inverse (9), gravity (3), linear and angular
#: damping, normalization gain
_RIGID_FLOATS = 25
# per-beam integer parameters (rows of ``bint``); _B_PLANAR: 1 for a beam that moves in its body x-z plane, whose
# residual and mass matrix take the planar recursions (soroshapes._beam.newton_euler_planar); _B_DEG, _B_HO: the
# degree of its identified polynomial actuators and the offset of their higher coefficients in bflt; _B_NPL: its
# number of (constant) point loads, their nodes (workspace rows) at bintb[_B_PLN], wrenches (k, 6) at bflt[_B_PLW]
# and frame flags (True: spatial) at the network's point-load flags (net[35]) [_B_PLF]
(_B_N, _B_M, _B_P, _B_NG, _B_ORDER, _B_FO, _B_WO, _B_IO, _B_PO, _B_PLANAR, _B_DEG, _B_HO, _B_NPL, _B_PLN, _B_PLW,
 _B_PLF) = range(16)
_B_COLS = 16


def _beam_floats(n, m, P, ng):
    """Sizes of the model arrays of one beam in the float buffer: K, D, Gin, h, B, X0, base, weights, Md, g."""
    return (n * n, n * n, n * m, P, P * ng * n, P * ng * 6, 16, P + 1, (P + 1) * 6, 3)


def _beam_work(n, P):
    """Sizes of the work arrays of one beam: G, J, Jd, eta, etad, S, E, V, Op, AJ, W, M, C, fg, R, qdd, f_in."""
    Np = P + 1
    return (Np * 16, Np * 6 * n, Np * 6 * n, Np * 6, Np * 6, 216, 16, 48, 6 * n, 6 * n, 48, n * n, n * n, n, n, n,
            n)


def _beam_ne_work(n, P):
    """Sizes of the work arrays of one beam's O(N) recursions (after those of :func:`_beam_work`): acc, SA, SX, V,
    T, Jm, Ym, Opm, Mm, LU, a, v, R, f (see :func:`_beam_ne_views`)."""
    Np = P + 1
    return (Np * 6, P * 36, P * 24, 192, 36, Np * 6 * n, Np * 6 * n, 6 * n, n * n, n * n, n, n, n, n)


# --- point loads: constant ones lowered with the beam ---
def _constant_wrench(ld):
    """The wrench (moment, force) (6,) [N m, N] of a :class:`soroshapes.beam.PointLoad` whose force and moment do
    not change with time, else None: :meth:`Shapes.add_point_load <soroshapes.shapes.Shapes.add_point_load>` keeps
    a 3-vector as a constant signal holding its ``value``, a callable of t as a signal without one."""
    parts = [getattr(sig, "value", None) for sig in (ld.moment_at, ld.force_at)]
    if any(v is None for v in parts):
        return None
    return np.concatenate([np.asarray(v, dtype=float).reshape(3) for v in parts])


def python_reason(system):
    """Why a system that runs compiled on its own keeps a network on the Python path, or None: a beam with a
    time-varying point load (a callable force or moment; the network lowers constant point loads with the beam,
    in its flat arrays, and the beam's own kernels evaluate them). :attr:`Model.evaluation_paths
    <soroshapes.model.Model.evaluation_paths>` gives it as that system's path."""
    from .beam import PointLoad

    for ld in getattr(system, "loads", ()):
        if isinstance(ld, PointLoad) and _constant_wrench(ld) is None:
            return f"a time-varying point load at node {ld.node} (a callable force or moment; constant ones run compiled)"
    return None


# --- identified polynomial actuators (soroshapes.dvs.PolynomialForce), compiled ---
def _polynomial_inputs(loads, n):
    r"""``(D, C)`` with ``C`` (D, n, m) when every input of a beam is a chamber, a linear actuator or an identified
    polynomial actuator (:class:`soroshapes.dvs.PolynomialForce`): :math:`f_{in} = \sum_j \sum_{d=1}^{D}
    C_{d-1,:,j}\,u_j^d`; None otherwise (a Python force keeps the Python path)."""
    from .beam import Actuator, Chamber, input_terms
    from .dvs import PolynomialForce

    cols = []
    for ld in input_terms(loads):
        if isinstance(ld, Chamber):
            cols.append(np.asarray(ld.column, float).reshape(1, n))
        elif isinstance(ld, Actuator) and isinstance(getattr(ld.fn, "column", None), np.ndarray):
            cols.append(np.asarray(ld.fn.column, float).reshape(1, n))
        elif isinstance(ld, Actuator) and isinstance(ld.fn, PolynomialForce):
            cols.append(np.asarray(ld.fn.coefficients, float).reshape(-1, n))
        else:
            return None
    D = max(len(c) for c in cols)
    C = np.zeros((D, n, len(cols)))
    for j, c in enumerate(cols):
        C[:len(c), :, j] = c
    return D, C


def _has_polynomial_actuator(shp):
    """Whether a beam has an identified polynomial actuator (a controller's torque-to-input map :math:`G^+`
    assumes linear inputs: refused on such a beam)."""
    from .dvs import PolynomialForce

    return any(isinstance(getattr(ld, "fn", None), PolynomialForce) for ld in shp.loads)


def _lower_impedance(spec, blocks, index, free_rows, inputs):
    """The set-point table and the integer and float data of a Cartesian impedance controller
    (:func:`soroshapes.control.impedance`), or NotImplementedError; ``inputs``: the beams' input matrices
    {block: G (n, m)}, whose inverse (pseudo-inverse, rcond 1e-10, unless square and regular) maps the
    controller's torque to its inputs."""
    name = spec["system"]
    if name not in index:
        raise ParameterError(f"the impedance controller acts on system {name!r}, which is not in the model")
    b = blocks[index[name]]
    if b["kind"] != "shapes":
        raise NotImplementedError(f"an impedance controller on {name!r}, which is not a beam")
    shp = b["system"]
    n, k = shp.n, len(spec["axes"])
    pdes = spec["setpoint"]
    if isinstance(pdes, Schedule) and not isinstance(pdes.values, dict):
        ctimes, cvals, cper = pdes.times, pdes.values, pdes.period or 0.0
    elif callable(pdes):
        raise NotImplementedError(f"the impedance set-point {getattr(pdes, '__name__', pdes)!r} (a Python callable; "
                                  "a Schedule of the set-point runs compiled)")
    else:
        ctimes, cvals, cper = np.array([0.0, 1.0]), np.vstack([pdes, pdes]), 0.0
    if cvals.shape[1] != k:
        raise ParameterError(f"the impedance set-point gives {cvals.shape[1]} values for {k} axes")
    rows = [r for r in free_rows if b["woff"] <= r < b["woff"] + b["nw"]]
    if len(rows) != b["m"]:
        raise NotImplementedError(f"an impedance controller on beam {name!r} whose inputs are also coupled")
    if _has_polynomial_actuator(shp):                  # G+ maps torques to linear inputs only
        raise NotImplementedError(f"an impedance controller on beam {name!r} with a polynomial actuator")
    Kn, Dn, qn, null = spec["null"](n)
    cint = [index[name], k, shp.node(spec["at"]) * shp.model.stride, int(spec["coriolis"]), int(spec["gravity"]),
            int(spec["elastic"]), int(null), len(rows), *spec["axes"], *rows]
    Gin = np.asarray(inputs[index[name]], dtype=float).reshape(n, -1)
    square = Gin.shape[0] == Gin.shape[1] and abs(np.linalg.det(Gin)) > 0.0
    Gplus = np.linalg.inv(Gin) if square else np.linalg.pinv(Gin, rcond=1e-10)
    cflt = np.concatenate([np.ravel(spec["stiffness"]), np.ravel(spec["damping"]), Kn.ravel(), Dn.ravel(), qn,
                           Gplus.ravel()])
    return ctimes, np.ascontiguousarray(cvals, float), cper, cint, cflt


def _lower_fixed_contact(shp, ld, name):
    """The term of a beam's contact with a fixed obstacle (:class:`soroshapes.beam.Contact`), or
    NotImplementedError naming the SDF node without a program form."""
    from ._contact import lower_contact
    try:
        par, prog = lower_contact(shp, ld.obstacle, ld.stiffness, ld.damping, ld.friction, ld.regularization)
    except NotImplementedError as why:
        raise NotImplementedError(f"beam {name!r} (contact with an obstacle: {why})") from None
    return ("contact", par, prog)


def _add_term(term, bb, wterm, wflt, sops, sconsts):
    """Append one wrench term (kind, floats, SDF program or None) acting with beam block ``bb`` (-1: none)."""
    tk, par, prog = term
    row = [_TERMS[tk], sum(len(v) for v in wflt), len(par), bb, 0, 0, 0, 0, 0]
    if prog is not None:
        row[4:] = [sum(len(v) for v in sops), len(prog.ops), sum(len(v) for v in sconsts), prog.values, prog.points]
        sops.append(prog.ops)
        sconsts.append(prog.consts)
    wterm.append(row)
    wflt.append(np.asarray(par, dtype=float))


_JOINT, _FF_INPUTS, _FF_TORQUE, _FF_CONFIGURATION = 0, 1, 2, 3
#: ints of a controller term before its input rows: kind, beam block, inputs m, gravity, elastic, integral block
#: (-1: none), float offset, table rows K, table columns
_TERM_HEAD = 9


def _table(v, cols, what):
    """(times, values (K, cols), period) of a constant (cols,) or a :class:`Schedule` with an array table."""
    if v is None:
        times, vals, per = np.array([0.0, 1.0]), np.zeros((2, cols)), 0.0
    elif isinstance(v, Schedule) and not isinstance(v.values, dict):
        times, vals, per = v.times, v.values, v.period or 0.0
    elif callable(v):
        raise NotImplementedError(f"the {what} {getattr(v, '__name__', v)!r} (a Python callable; a Schedule runs "
                                  "compiled)")
    else:
        vals = np.asarray(v, dtype=float).reshape(1, -1)
        times, vals, per = np.array([0.0, 1.0]), np.vstack([vals, vals]), 0.0
    if vals.shape[1] != cols:
        raise ParameterError(f"the {what} gives {vals.shape[1]} values per row, expected {cols}")
    return times, np.ascontiguousarray(vals, float), float(per)


def _lower_terms(spec, blocks, index, free_rows):
    """The integer and float records of a joint-space controller, a feed-forward or a combination of them
    (``compiled`` of :mod:`soroshapes.control`), and the (block, block it reads) pairs; NotImplementedError for
    a part without compiled form."""
    specs = spec["terms"] if spec["kind"] == "combine" else [spec]
    cint, cflt, reads = [len(specs)], [], []
    for sp in specs:
        if sp is None or sp["kind"] not in ("joint", "feedforward"):
            raise NotImplementedError(f"a {'Python' if sp is None else sp['kind']} controller inside combine")
        name = sp["system"]
        if name not in index:
            raise ParameterError(f"the controller acts on system {name!r}, which is not in the model")
        b = blocks[index[name]]
        if b["kind"] != "shapes":
            raise NotImplementedError(f"a controller on {name!r}, which is not a beam")
        n = b["system"].n
        rows = [r for r in free_rows if b["woff"] <= r < b["woff"] + b["nw"]]
        if len(rows) != b["m"]:
            raise NotImplementedError(f"a controller on beam {name!r} whose inputs are also coupled")
        if _has_polynomial_actuator(b["system"]):      # G+ maps torques to linear inputs only
            raise NotImplementedError(f"a controller on beam {name!r} with a polynomial actuator")
        integral = -1
        if sp["kind"] == "joint":
            kind = _JOINT
            Kp, Ki, Kd = sp["gains"](n)
            times, vals, per = _table(sp["setpoint"], n, "set-point")
            if sp.get("integral") is not None:
                if sp["integral"] not in index:
                    raise ParameterError(f"the PID integral {sp['integral']!r} is not in the model")
                integral = index[sp["integral"]]
                reads.append((index[name], integral))
            floats = [Kp.ravel(), Ki.ravel(), Kd.ravel()]
            grav, elas = sp["gravity"], sp["elastic"]
        else:
            kind = {"inputs": _FF_INPUTS, "torque": _FF_TORQUE, "configuration": _FF_CONFIGURATION}[sp["space"]]
            times, vals, per = _table(sp["profile"], b["m"] if kind == _FF_INPUTS else n, "feed-forward profile")
            floats, grav, elas = [], True, True
        floats += [[per], times, vals.ravel()]
        cint += [kind, index[name], len(rows), int(grav), int(elas), integral, sum(len(f) for f in cflt),
                 len(times), vals.shape[1], *rows]
        cflt.extend(np.ravel(f) for f in floats)
    return cint, np.concatenate(cflt) if cflt else np.zeros(0), reads


def _mark_analytic(table, blocks, link_tab, link_rows, ckind, free_rows, wsum, wterm):
    """Set ``table[i, 7]`` = 1 for the systems whose rows of the Newton matrix :func:`_analytic_rows` writes in
    closed form: reservoirs, linear systems and beams (their input force) whose every input is a reservoir volume,
    a state-independent controller value (none, a :class:`Schedule`), a coupling from a system's output or a
    :class:`StateMap`, or a wrench sum of beam contacts on a spinning body (:func:`_analytic_sum`; not another
    wrench sum, not a state feedback controller), and beams on which no coupling's force acts but such contacts
    (with a spinning body or fixed obstacles; not a grasp, not a free body's contact). The others are
    differenced (:func:`_fd_rows`)."""
    NW = sum(b["nw"] for b in blocks)
    known = np.ones(NW, np.bool_)
    if ckind in (2, 3):                                 # a feedback controller's inputs read beam states
        known[np.asarray(free_rows, np.int64)] = False
    changed = True
    while changed:                                      # an output with feedthrough inherits its inputs' state
        changed = False
        for lk, src, ro, nr in link_tab:
            rows = link_rows[ro:ro + nr]
            if lk == 2:
                bad = not _analytic_sum(wsum, wterm, src)
            elif lk == 0 and table[src, 0] == LINEAR:
                bad = not known[table[src, 3]:table[src, 3] + table[src, 4]].all()
            else:
                bad = False
            if bad and known[rows].any():
                known[rows] = False
                changed = True
    acted = {int(row[3]) for si in range(len(wsum)) if not _analytic_sum(wsum, wterm, si)
             for row in wterm[wsum[si][0]:wsum[si][0] + wsum[si][1]] if row[3] >= 0}
    for i in range(table.shape[0]):
        ok = table[i, 0] in (BEAM, FLUIDIC, LINEAR) and known[table[i, 3]:table[i, 3] + table[i, 4]].all()
        table[i, 7] = int(ok and i not in acted)


def _analytic_sum(wsum, wterm, si):
    """Whether the rows that wrench sum si adds to the Newton matrix have a closed form
    (:func:`_contact_rows`): every term a beam's contact (:func:`soroshapes._contact.contact_jacobian`) and the
    body a spinning one or fixed obstacles."""
    first, count, _, pose = wsum[si][0], wsum[si][1], wsum[si][2], wsum[si][3]
    return pose in (_SPINNING, _FIXED) and all(wterm[tt][0] == _CONTACT for tt in range(first, first + count))


class Lowered:
    """The network as the kernel's arrays (see :func:`lower`); ``arrays`` is the argument tuple."""

    def __init__(self, arrays, N, NW, groups, dep):
        self.arrays, self.N, self.NW, self.groups, self.dep = arrays, N, NW, groups, dep


def lower(blocks, links, volumes, controller, free):
    """Lower a network description to the kernel's arrays, or raise ``NotImplementedError(reason)``.

    Parameters
    ----------
    blocks : list of dict(name, kind, system, xoff, n, woff, nw, m)
    links : list of (source, target name, input indices); ``source`` a system name or a :class:`StateMap`
    volumes : dict {fluidic name: None (constant) or StateMap}
    controller : None or :class:`Schedule`
    free : list of (system name, count of free inputs) and ``free_rows`` positions in w, as (free, rows)
    """
    free_list, free_rows = free
    index = {b["name"]: i for i, b in enumerate(blocks)}
    # a coupling whose force the network's wrench terms put on its target themselves (a tree's contact forces,
    # soroshapes.rigid.couple_tree_contact): the kernel leaves its inputs at zero
    links = [lk for lk in links if not getattr(lk[0], "network_term", False)]
    kind = np.zeros(len(blocks), np.int64)
    # kind, xoff, n, woff, nw, aux, costly and analytic rows (see _cheap_rows)
    table = np.zeros((len(blocks), 8), np.int64)
    bint, bflt, bintb = [], [], []
    fpar = []
    pflag = []                                      # the frame of each beam's point loads (True: spatial)
    maps, mapint = [], []
    lint, lflt = [], []
    rflt = []
    # wrench sums: [first term, count, body (-1: a fixed obstacle's contacts), pose kind, pose floats]; terms:
    # [kind, float offset, float count, beam, SDF ops offset, ops count, SDF consts offset, value and point stack
    # depths]; floats
    wsum, wterm, wflt = [], [], []
    sops, sconsts = [], []                          # SDF programs of contact terms (soroshapes._contact)
    inputs = {}                                     # input matrices of the beams (the impedance controller's)
    extra_feeds = []                                # (block, block whose state it reads) through contact terms

    def add_map(smap):
        if not isinstance(smap, StateMap):
            raise NotImplementedError(f"the Python callable {getattr(smap, '__name__', smap)!r}")
        if smap.system not in index:
            raise ParameterError(f"StateMap reads system {smap.system!r}, which is not in the model")
        src = blocks[index[smap.system]]
        A = smap.full_matrix(src["n"])
        k = smap.size
        mapint.append([index[smap.system], k, _FUNCTIONS[smap.function], sum(len(v) for v in maps)])
        maps.append(np.concatenate([A.reshape(-1), smap.offset, smap.scale]))
        return len(mapint) - 1

    fo = wo = io = 0
    tree_args = None                                # the tree block's arrays (soroshapes._treeblock)
    for i, b in enumerate(blocks):
        table[i, 1:5] = b["xoff"], b["n"], b["woff"], b["nw"]
        if b["kind"] == "shapes":
            shp = b["system"]
            from .beam import Contact, LoadPlan
            mdl = shp.model
            # forces that a coupling puts on the beam and that the network evaluates itself (a grasp)
            own = [ld for ld in shp.loads if not getattr(getattr(ld, "fn", None), "network_term", False)]
            contacts = [ld for ld in own if isinstance(ld, Contact)]
            if contacts:                            # contact with fixed obstacles: a wrench sum without a body
                terms = [_lower_fixed_contact(shp, ld, b["name"]) for ld in contacts]
                wsum.append([len(wterm), len(terms), -1, _FIXED, 0])
                for term in terms:
                    _add_term(term, i, wterm, wflt, sops, sconsts)
                own = [ld for ld in own if not isinstance(ld, Contact)]
            plan = LoadPlan.of(mdl, own, shp.damping)
            inputs[i] = plan.input_matrix
            if not plan.compiled:
                raise NotImplementedError(f"beam {b['name']!r} ({shp.evaluation_path})")
            why = python_reason(shp)
            if why is not None:
                raise NotImplementedError(f"beam {b['name']!r} ({why})")
            Gin, deg, higher = plan.input_matrix, 1, None
            if Gin is None:                             # an identified polynomial actuator
                poly = _polynomial_inputs(own, mdl.n)
                if poly is None:
                    raise NotImplementedError(f"beam {b['name']!r} (a nonlinear actuator)")
                deg, Gin, higher = poly[0], poly[1][0], poly[1][1:]
            n, m, P, ng = mdl.n, b["m"], mdl.h.shape[0], mdl.B.shape[1]
            arrays = [mdl.K, plan.D, Gin, mdl.h, mdl.B, mdl.X0, mdl.base, mdl.weights, mdl.Md,
                      plan.gravity]
            for a, size in zip(arrays, _beam_floats(n, m, P, ng)):
                a = np.ascontiguousarray(a, dtype=float).reshape(-1)
                if a.size != size:
                    raise ParameterError(f"beam {b['name']!r}: unexpected model array size {a.size} != {size}")
                bflt.append(a)
            bintb.append(np.asarray(mdl.rows, dtype=np.int64))
            fo += sum(_beam_floats(n, m, P, ng))
            bint.append([n, m, P, ng, mdl.order, fo - sum(_beam_floats(n, m, P, ng)), wo, io, io + n,
                         int(_is_planar(mdl.rows, mdl.X0)), deg, fo])      # degree, higher terms at fo
            if higher is not None:                      # the coefficients of u^2..u^D, (D-1, n, m)
                bflt.append(np.ascontiguousarray(higher, dtype=float).reshape(-1))
                fo += higher.size
            wrenches = np.array([_constant_wrench(ld) for ld in plan.point_loads], float).reshape(-1, 6)
            npl = len(plan.point_loads)
            bint[-1] += [npl, io + 2 * n, fo, len(pflag)]       # point loads: nodes after the pivots, wrenches
            bflt.append(wrenches.reshape(-1))
            fo += wrenches.size
            pflag.extend(bool(f) for f in plan.spatial)
            wo += sum(_beam_work(n, P)) + sum(_beam_ne_work(n, P))
            bintb.append(np.zeros(n, np.int64))             # pivots
            bintb.append(np.asarray(plan.nodes, np.int64).reshape(-1))
            io += 2 * n + npl
            kind[i], table[i, 5] = BEAM, len(bint) - 1
        elif b["kind"] == "fluidic":
            fl = b["system"]
            reg = fl.regulator or (1.0, 0.0, 0.0)
            vol = volumes.get(b["name"])
            if vol is None:
                if not fl.constant:
                    raise NotImplementedError(f"reservoir {b['name']!r} (a Python volume V(t))")
                vkind, vval = 0, fl.volume
            else:
                vkind, vval = 1, float(add_map(vol))
            if fl.valve_kind == "python":
                raise NotImplementedError(f"reservoir {b['name']!r} (a Python valve flow function "
                                          f"{getattr(fl.valve, '__name__', fl.valve)!r})")
            valve = ([1.0, *fl.valve.parameters(fl.p0, fl.T)] if fl.valve_kind == "orifice"
                     else [0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            fpar.append([float(fl.isothermal), fl.R, fl.T, fl.p0, fl.polytropic, fl.leak, fl.filter_gain,
                         float(fl.regulator is not None), reg[0], reg[1], reg[2], float(fl.filtered), vkind, vval,
                         *valve])
            kind[i], table[i, 5] = FLUIDIC, len(fpar) - 1
        elif getattr(b["system"], "rigid_parameters", None) is not None:
            par = np.asarray(b["system"].rigid_parameters, dtype=float)
            if par.shape != (_RIGID_FLOATS,):
                raise ParameterError(f"rigid body {b['name']!r}: rigid_parameters must have {_RIGID_FLOATS} entries")
            rflt.append(par)
            kind[i], table[i, 5] = RIGID, len(rflt) - 1
        elif getattr(b["system"], "matrices", None) is not None:
            A, B, C, D = b["system"].matrices
            lint.append([A.shape[0], B.shape[1], C.shape[0], sum(len(v) for v in lflt)])
            lflt.append(np.concatenate([A.reshape(-1), B.reshape(-1), C.reshape(-1), D.reshape(-1)]))
            kind[i], table[i, 5] = LINEAR, len(lint) - 1
        elif getattr(b["system"], "tree_block", None) is not None:     # a Tree.system block
            if tree_args is not None:
                raise NotImplementedError(f"tree {b['name']!r} (one tree block per compiled network)")
            tree_args = b["system"].tree_block
            kind[i], table[i, 5] = TREE, 0
        else:
            raise NotImplementedError(f"system {b['name']!r} (a StateSpace with a Python f; StateSpace.linear "
                                      "runs compiled)")
        table[i, 0] = kind[i]
    link_rows, link_tab = [], []
    for src, tname, idx in links:
        tb = blocks[index[tname]]
        rows = [tb["woff"] + k for k in idx]
        if getattr(src, "compiled_terms", False) is not False:       # a body's WrenchSum (soroshapes.rigid)
            terms = src.compiled_terms
            if terms is None:
                raise NotImplementedError(src.python_reason)
            body = blocks[index[tname]]["system"]
            if kind[index[tname]] == RIGID:
                pose_kind, pose_off = _FREE, 0
            elif getattr(body, "spinning_parameters", None) is not None:
                pose_kind, pose_off = _SPINNING, sum(len(v) for v in wflt)
                wflt.append(np.asarray(body.spinning_parameters, dtype=float))
            else:
                raise NotImplementedError(f"contact on body {tname!r} (compiled for free and spinning rigid bodies)")
            wsum.append([len(wterm), len(terms), index[tname], pose_kind, pose_off])
            for tk, par, beam, *program in terms:
                if tk not in _TERMS:
                    raise NotImplementedError(f"a {tk} wrench on body {tname!r}")
                if tk in ("contact", "tree_contact"):
                    table[index[tname], 6] = 1          # its inputs need the beams' (tree's) kinematics and SDFs
                bb = -1
                if beam is not None:
                    want = TREE if tk == "tree_contact" else BEAM
                    if beam not in index or kind[index[beam]] != want:
                        raise ParameterError(f"a {tk} coupling on body {tname!r} names {beam!r}, which is not a "
                                             f"{'compiled tree' if want == TREE else 'beam'} of the model")
                    bb = index[beam]
                    extra_feeds.append((index[tname], bb))          # the body's wrench reads the beam,
                    extra_feeds.append((bb, index[tname]))          # the beam's force reads the body
                _add_term((tk, par, program[0] if program else None), bb, wterm, wflt, sops, sconsts)
            lk, ls, size = 2, len(wsum) - 1, 6
        elif isinstance(src, str):
            sb = blocks[index[src]]
            size = (1 if sb["kind"] == "fluidic" else sb["system"].matrices[2].shape[0]
                    if getattr(sb["system"], "matrices", None) is not None else sb["n"])
            lk, ls = 0, index[src]
        else:
            ls = add_map(src)
            lk, size = 1, src.size
        if size != len(rows):
            raise ParameterError(f"coupling into system {tname!r}: the source gives {size} values for {len(rows)} "
                                 "connected inputs")
        link_tab.append([lk, ls, len(link_rows), len(rows)])
        link_rows.extend(rows)
    cint, cflt = np.zeros(0, np.int64), np.zeros(0)
    if controller is None:
        ctimes, cvals, cper = np.zeros(2), np.zeros((2, len(free_rows))), 0.0
        ckind = 0
    elif isinstance(controller, Schedule):
        ctimes, cvals = controller.times, np.ascontiguousarray(controller.table(free_list))
        cper, ckind = (controller.period or 0.0), 1
    elif getattr(controller, "compiled", None) is not None and controller.compiled["kind"] == "impedance":
        ckind = 2                                               # soroshapes.control.impedance
        ctimes, cvals, cper, cint, cflt = _lower_impedance(controller.compiled, blocks, index, free_rows, inputs)
    elif getattr(controller, "compiled", None) is not None:     # the other controllers of soroshapes.control
        ckind = 3
        ctimes, cvals, cper = np.zeros(2), np.zeros((2, 0)), 0.0
        cint, cflt, reads = _lower_terms(controller.compiled, blocks, index, free_rows)
        extra_feeds.extend(reads)
    else:
        raise NotImplementedError(f"the Python controller {getattr(controller, '__name__', controller)!r}")

    _mark_analytic(table, blocks, link_tab, link_rows, ckind, free_rows, wsum, wterm)

    # dependency of each block's derivative on the blocks' states (closed over sources fed by their inputs)
    nb = len(blocks)
    reads = [{i} for i in range(nb)]
    feeds = [set() for _ in range(nb)]              # blocks whose state feeds block i's inputs
    for src, tname, _ in links:
        t = index[tname]
        s = index[src] if isinstance(src, str) else index[src.system]       # StateMap or WrenchSum
        feeds[t].add(s)
    for name, vol in volumes.items():
        if vol is not None:
            feeds[index[name]].add(index[vol.system])
    for t, s in extra_feeds:
        feeds[t].add(s)
    changed = True
    while changed:
        changed = False
        for i in range(nb):
            more = set()
            for s in feeds[i]:
                if blocks[s]["kind"] == "fluidic" or (blocks[s]["kind"] == "statespace" and
                                                      blocks[s]["system"].feedthrough):
                    more |= feeds[s]                        # an output that depends on the source's inputs
            if not more <= feeds[i]:
                feeds[i] |= more
                changed = True
    dep = np.zeros((nb, nb), np.bool_)               # dep[i, j]: block i's derivative reads block j's state
    for i in range(nb):
        for j in reads[i] | feeds[i]:
            dep[i, j] = True
    # Curtis-Powell-Reid: blocks that no block reads together share a perturbation
    colors = []
    for j in range(nb):
        readers = set(np.nonzero(dep[:, j])[0])
        for members, seen in colors:
            if not (readers & seen):
                members.append(j)
                seen |= readers
                break
        else:
            colors.append(([j], set(readers)))
    groups = []
    for members, _ in colors:
        width = max(blocks[j]["n"] for j in members)
        for k in range(width):
            groups.append([blocks[j]["xoff"] + k for j in members if k < blocks[j]["n"]])
    N = sum(b["n"] for b in blocks)
    NW = sum(b["nw"] for b in blocks)
    G = np.full((len(groups), max(len(g) for g in groups)), -1, np.int64)
    for gi, g in enumerate(groups):
        G[gi, :len(g)] = g
    col_block = np.zeros(N, np.int64)
    for i, b in enumerate(blocks):
        col_block[b["xoff"]:b["xoff"] + b["n"]] = i
    # connected components of the dependency graph: the iteration matrix is block diagonal over them
    comp = list(range(nb))

    def root(i):
        while comp[i] != i:
            i = comp[i]
        return i
    for i in range(nb):
        for j in range(nb):
            if dep[i, j]:
                comp[root(i)] = root(j)
    members = {}
    for i in range(nb):
        members.setdefault(root(i), []).append(i)
    cols = [np.concatenate([np.arange(blocks[i]["xoff"], blocks[i]["xoff"] + blocks[i]["n"]) for i in mem])
            for mem in members.values()]
    comps = np.full((len(cols), max(len(c) for c in cols)), -1, np.int64)
    for k, c in enumerate(cols):
        comps[k, :len(c)] = c
    block_comp = np.zeros(nb, np.int64)
    for k, mem in enumerate(members.values()):
        block_comp[mem] = k

    def cat(parts, dtype=float):
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)

    arrays = (table, np.array(bint, np.int64).reshape(-1, _B_COLS), cat(bflt), np.zeros(wo), cat(bintb, np.int64),
              np.array(fpar, float).reshape(-1, _FLUIDIC_FLOATS), np.array(mapint, np.int64).reshape(-1, 4), cat(maps),
              np.array(link_tab, np.int64).reshape(-1, 4), np.array(link_rows, np.int64),
              np.int64(ckind), np.ascontiguousarray(ctimes, float), np.ascontiguousarray(cvals, float).reshape(
                  len(ctimes), -1), float(cper), np.asarray(free_rows, np.int64), G, dep, col_block, comps, block_comp,
              np.array(lint, np.int64).reshape(-1, 4), cat(lflt), np.array(rflt, float).reshape(-1, _RIGID_FLOATS),
              np.array(wsum, np.int64).reshape(-1, 5), np.array(wterm, np.int64).reshape(-1, 9), cat(wflt),
              np.asarray(cint, np.int64), np.asarray(cflt, float), np.zeros(N),
              np.concatenate(sops).astype(np.int64) if sops else np.zeros((0, 3), np.int64), cat(sconsts),
              *_term_cache(wterm, table, bint, nb),
              _treeblock.empty_block_args() if tree_args is None else tree_args,          # net[33]: the tree block
              np.full(1 + len(free_rows), np.nan),          # net[34]: the schedule's row cached per time
              np.array(pflag, np.bool_))                    # net[35]: the beams' point-load frames (_B_PLF)
    return Lowered(arrays, N, NW, groups, dep)


def _term_cache(wterm, table, bint, nb):
    """The work arrays of the wrench-term cache (see :func:`_wrench_sum`): per term its wrench (6), its
    generalized force on its beam (the beam's n) and a contact's SDF memo (:func:`soroshapes._contact.contact_force`),
    and the flags: [mode, perturbed blocks (nb), valid
    terms, what each block's beam workspace holds (nb; :func:`_kinematics_level`)]."""
    width = 6
    for row in wterm:
        if row[3] >= 0 and table[row[3], 0] == TREE:         # its force on the tree (n)
            width = max(width, 6 + int(table[row[3], 2]) // 2)
        elif row[3] >= 0:                       # its force on the beam (n), its SDF memo (4 per node, at most P+1)
            n, P = int(bint[table[row[3], 5]][0]), int(bint[table[row[3], 5]][2])
            width = max(width, 6 + n + 4 * (P + 1))
    return np.zeros((len(wterm), width)), np.zeros(1 + nb + len(wterm) + nb, np.int64)


@njit(cache=True)
def _kinematics_level(net, b):
    """What the workspace of beam block b holds for the state of the current :func:`_assemble`: 0 nothing, 1 its
    frames, Jacobians and velocities (:func:`soroshapes._beam.kinematics`), 2 also the Jacobian rates."""
    tflag = net[32]
    return tflag[tflag.shape[0] - net[0].shape[0] + b]


@njit(cache=True)
def _kinematics_done(net, b, level):
    """Record what the workspace of beam block b holds (see :func:`_kinematics_level`)."""
    tflag = net[32]
    tflag[tflag.shape[0] - net[0].shape[0] + b] = level


# ------------------------------------------------------------------------------------------------------------
# the kernel
# ------------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _interp_row(times, vals, period, t, out):
    """Row-wise linear interpolation of the table at t (periodic if period > 0, else held at the ends)."""
    K = times.shape[0]
    tt = t
    if period > 0.0:
        tt = t - period * math.floor(t / period)
    if tt <= times[0]:
        for j in range(out.shape[0]):
            out[j] = vals[0, j]
        return
    if tt >= times[K - 1]:
        for j in range(out.shape[0]):
            out[j] = vals[K - 1, j]
        return
    k = np.searchsorted(times, tt, side="right") - 1
    a = (tt - times[k]) / (times[k + 1] - times[k])
    for j in range(out.shape[0]):
        out[j] = (1.0 - a) * vals[k, j] + a * vals[k + 1, j]


@njit(cache=True)
def _map_eval(mapint, maps, table, x, mi, r):
    """Output r of StateMap mi at the state x."""
    src, k, fn, o = mapint[mi, 0], mapint[mi, 1], mapint[mi, 2], mapint[mi, 3]
    xo, n = table[src, 1], table[src, 2]
    s = 0.0
    for c in range(n):
        s += maps[o + r * n + c] * x[xo + c]
    if fn == 1:
        s = math.tanh(s)
    return maps[o + k * n + r] + maps[o + k * n + k + r] * s


@njit(cache=True)
def _pressure(fpar, fi, x0, V):
    """Absolute pressure [Pa] of reservoir fi at its first state x0 and volume V."""
    if fpar[fi, 0] != 0.0:
        return x0 * fpar[fi, 1] * fpar[fi, 2] / V
    return x0


@njit(cache=True)
def assemble(t, x, net, w):
    """w = W(t, x): reservoir volumes, scheduled free inputs, couplings in declaration order. Returns False when a
    volume is not positive and finite."""
    return _assemble(t, x, net, w, np.ones(net[0].shape[0], np.bool_))


@njit(cache=True)
def _assemble(t, x, net, w, only):
    """:func:`assemble` for an evaluation of the blocks with ``only[i]`` True: a feedback controller that drives
    the inputs of a block left out is not evaluated (its inputs are not read)."""
    table, fpar, mapint, maps, link_tab, link_rows = net[0], net[5], net[6], net[7], net[8], net[9]
    ckind, ctimes, cvals, cper, free_rows = net[10], net[11], net[12], net[13], net[14]
    lint, lflt, wsum, cint, bext = net[20], net[21], net[23], net[26], net[28]
    for j in range(w.shape[0]):
        w[j] = 0.0
    for j in range(bext.shape[0]):
        bext[j] = 0.0
    tflag = net[32]                 # no beam workspace holds kinematics at x yet (_kinematics_done, inline)
    for b in range(tflag.shape[0] - table.shape[0], tflag.shape[0]):
        tflag[b] = 0
    ok = True
    if ckind == 2:                  # first: the contacts of its beam then reuse its kinematics at x
        if only[cint[0]] and not _impedance(t, x, net, w):
            ok = False
    for i in range(table.shape[0]):
        if table[i, 0] == FLUIDIC:
            fi = table[i, 5]
            if fpar[fi, 12] == 0.0:
                V = fpar[fi, 13]
            else:
                V = _map_eval(mapint, maps, table, x, int(fpar[fi, 13]), 0)
            if not (V > 0.0 and math.isfinite(V)):
                ok = False
            w[table[i, 3] + 1] = V
    for si in range(wsum.shape[0]):                   # contact of beams with fixed obstacles: forces into bext
        if wsum[si, 2] < 0 and _wrench_needed(net, si, only):
            if not _wrench_sum(t, net, si, x, np.zeros(6)):
                ok = False
    if ckind == 3:
        if not _controller_terms(t, x, net, w, only):
            ok = False
    elif ckind == 1 and free_rows.shape[0] > 0:
        u = net[34]                                  # [t, the schedule's row at t]: once per time, not per sweep
        if u[0] != t:
            _interp_row(ctimes, cvals, cper, t, u[1:])
            u[0] = t
        for j in range(free_rows.shape[0]):
            w[free_rows[j]] = u[1 + j]
    for li in range(link_tab.shape[0]):
        lk, src, ro, nr = link_tab[li, 0], link_tab[li, 1], link_tab[li, 2], link_tab[li, 3]
        if lk == 2:
            if not _wrench_needed(net, src, only):
                continue
            W = np.zeros(6)
            if not _wrench_sum(t, net, src, x, W):
                ok = False
            for r in range(6):
                w[link_rows[ro + r]] = W[r]
            continue
        if nr > 0 and not _link_needed(table, link_rows[ro], only):
            continue
        for r in range(nr):
            if lk == 1:
                v = _map_eval(mapint, maps, table, x, src, r)
            elif table[src, 0] == FLUIDIC:
                fi = table[src, 5]
                V = w[table[src, 3] + 1]
                v = _pressure(fpar, fi, x[table[src, 1]], V) - fpar[fi, 3]
            elif table[src, 0] == LINEAR:                  # y = C x + D u
                li = table[src, 5]
                n, m, o = lint[li, 0], lint[li, 1], lint[li, 3]
                oc = o + n * n + n * m
                od = oc + lint[li, 2] * n
                v = 0.0
                for c in range(n):
                    v += lflt[oc + r * n + c] * x[table[src, 1] + c]
                for c in range(m):
                    v += lflt[od + r * m + c] * w[table[src, 3] + c]
            else:
                v = x[table[src, 1] + r]
            w[link_rows[ro + r]] = v
    return ok


@njit(cache=True)
def _link_needed(table, row, only):
    """Whether :func:`_assemble` must write the coupling into input row ``row``: its system is evaluated
    (``only``), or it is a linear system, whose inputs a later coupling may read (feed-through :math:`Du`)."""
    for b in range(table.shape[0]):
        if table[b, 3] <= row < table[b, 3] + table[b, 4]:
            return bool(only[b]) or table[b, 0] == LINEAR
    return True


@njit(cache=True)
def _beam_views(bi, net):
    """Views of beam bi's model arrays (in the float buffer) and work arrays (in the beam workspace)."""
    return _beam_arrays(bi, net[1], net[2], net[3], net[4])


@njit(cache=True)
def _beam_arrays(bi, bint, bflt, bwork, bintb):
    """:func:`_beam_views` from the four beam arrays of the network (what the hot loops pass: a call that
    passes the whole network tuple costs the reference counting of its ~30 arrays, about 1 us)."""
    P, wko, po = bint[bi, 2], bint[bi, 6], bint[bi, 8]
    Np = P + 1
    n, m, order, K, D, h, B, X0, base, wts, Md, ag, rows, go = _beam_model(bi, bint, bflt, bintb)
    Gin = bflt[go:go + n * m].reshape((n, m))
    piv = bintb[po:po + n]
    o = wko
    G = bwork[o:o + Np * 16].reshape((Np, 4, 4))
    o += Np * 16
    J = bwork[o:o + Np * 6 * n].reshape((Np, 6, n))
    o += Np * 6 * n
    Jd = bwork[o:o + Np * 6 * n].reshape((Np, 6, n))
    o += Np * 6 * n
    eta = bwork[o:o + Np * 6].reshape((Np, 6))
    o += Np * 6
    etad = bwork[o:o + Np * 6].reshape((Np, 6))
    o += Np * 6
    S = bwork[o:o + 216].reshape((6, 6, 6))
    o += 216
    E = bwork[o:o + 16].reshape((4, 4))
    o += 16
    V = bwork[o:o + 48].reshape((8, 6))
    o += 48
    Op = bwork[o:o + 6 * n].reshape((6, n))
    o += 6 * n
    AJ = bwork[o:o + 6 * n].reshape((6, n))
    o += 6 * n
    W = bwork[o:o + 48].reshape((8, 6))
    o += 48
    M = bwork[o:o + n * n].reshape((n, n))
    o += n * n
    C = bwork[o:o + n * n].reshape((n, n))
    o += n * n
    fg = bwork[o:o + n]
    o += n
    R = bwork[o:o + n]
    o += n
    qdd = bwork[o:o + n]
    o += n
    f_in = bwork[o:o + n]
    end = o + n
    return (n, m, order, K, D, Gin, h, B, X0, base, wts, Md, ag, rows, piv, G, J, Jd, eta, etad, S, E, V, Op, AJ,
            W, M, C, fg, R, qdd, f_in, wko, end)


@njit(cache=True)
def _beam_ne_views(bi, net):
    """Views of the work arrays of beam bi's O(N) recursions (:func:`soroshapes._beam.newton_euler`,
    :func:`soroshapes._beam.mass_matrix_pieces`), stored after those of :func:`_beam_views`: acc, SA, SX, V, T,
    the Jacobians and their weighted copy (Jm, Ym), Opm, the mass matrix Mm of the last pass, an LU scratch, the
    vectors a, v, R, f; the frames G, twists eta and E (of :func:`_beam_views`); and the (start, end) of the
    beam's whole workspace."""
    return _beam_ne_arrays(bi, net[1], net[3])


@njit(cache=True)
def _beam_ne_start(n, P, wko):
    """Offset in the beam workspace of the first array of :func:`_beam_ne_arrays` (after those of
    :func:`_beam_arrays`)."""
    Np = P + 1
    return wko + Np * 16 + 12 * Np * n + 12 * Np + 216 + 16 + 48 + 12 * n + 48 + 2 * n * n + 4 * n


@njit(cache=True)
def _beam_ne_layout(bi, bint):
    """The layout of beam bi's O(N) workspace, written once for :func:`_beam_ne_arrays`,
    :func:`_beam_pass_arrays` and :func:`_beam_mass_of`: (n, P, wko, offsets) with the offsets of acc, SA, SX,
    V, T, Jm, Ym, Opm, Mm, LU, a, v, R, f and the end, in that order."""
    n, P, wko = bint[bi, 0], bint[bi, 2], bint[bi, 6]
    Np = P + 1
    o_acc = _beam_ne_start(n, P, wko)
    o_SA = o_acc + Np * 6
    o_SX = o_SA + P * 36
    o_V = o_SX + P * 24
    o_T = o_V + 192
    o_Jm = o_T + 36
    o_Ym = o_Jm + Np * 6 * n
    o_Opm = o_Ym + Np * 6 * n
    o_Mm = o_Opm + 6 * n
    o_LU = o_Mm + n * n
    o_a = o_LU + n * n
    o_v = o_a + n
    o_R = o_v + n
    o_f = o_R + n
    return n, P, wko, (o_acc, o_SA, o_SX, o_V, o_T, o_Jm, o_Ym, o_Opm, o_Mm, o_LU, o_a, o_v, o_R, o_f, o_f + n)


@njit(cache=True)
def _beam_frames(n, P, wko, bwork):
    """The frames G, twists eta and E of :func:`_beam_views` (shared by the O(N) passes)."""
    Np = P + 1
    G = bwork[wko:wko + Np * 16].reshape((Np, 4, 4))
    oe = wko + Np * 16 + 12 * Np * n
    eta = bwork[oe:oe + Np * 6].reshape((Np, 6))
    oE = oe + 12 * Np + 216
    E = bwork[oE:oE + 16].reshape((4, 4))
    return G, eta, E


@njit(cache=True)
def _beam_ne_arrays(bi, bint, bwork):
    """:func:`_beam_ne_views` from the network's beam arrays."""
    n, P, wko, o = _beam_ne_layout(bi, bint)
    Np = P + 1
    acc = bwork[o[0]:o[1]].reshape((Np, 6))
    SA = bwork[o[1]:o[2]].reshape((P, 6, 6))
    SX = bwork[o[2]:o[3]].reshape((P, 4, 6))
    V = bwork[o[3]:o[4]].reshape((32, 6))
    T = bwork[o[4]:o[5]].reshape((6, 6))
    Jm = bwork[o[5]:o[6]].reshape((Np, 6, n))
    Ym = bwork[o[6]:o[7]].reshape((Np, 6, n))
    Opm = bwork[o[7]:o[8]].reshape((6, n))
    Mm = bwork[o[8]:o[9]].reshape((n, n))
    LU = bwork[o[9]:o[10]].reshape((n, n))
    a = bwork[o[10]:o[11]]
    v = bwork[o[11]:o[12]]
    R = bwork[o[12]:o[13]]
    f = bwork[o[13]:o[14]]
    G, eta, E = _beam_frames(n, P, wko, bwork)
    return acc, SA, SX, V, T, Jm, Ym, Opm, Mm, LU, a, v, R, f, G, eta, E, wko, o[14]


@njit(cache=True)
def _beam_pass_arrays(bi, bint, bwork):
    """The arrays of :func:`_beam_ne_arrays` that one residual pass writes (acc, SA, SX, V, a, R, f, G, eta, E)
    and the (start, end) of the beam's workspace, without the views it does not read (each view costs its
    reference counting: the residual runs every Newton sweep)."""
    n, P, wko, o = _beam_ne_layout(bi, bint)
    Np = P + 1
    acc = bwork[o[0]:o[1]].reshape((Np, 6))
    SA = bwork[o[1]:o[2]].reshape((P, 6, 6))
    SX = bwork[o[2]:o[3]].reshape((P, 4, 6))
    V = bwork[o[3]:o[4]].reshape((32, 6))
    a = bwork[o[10]:o[11]]
    R = bwork[o[12]:o[13]]
    f = bwork[o[13]:o[14]]
    G, eta, E = _beam_frames(n, P, wko, bwork)
    return acc, SA, SX, V, a, R, f, G, eta, E, wko, o[14]


@njit(cache=True)
def _beam_mass_of(bi, bint, bwork):
    """:func:`_beam_mass` from the network's beam arrays (only the view of M)."""
    n, _, _, o = _beam_ne_layout(bi, bint)
    return bwork[o[8]:o[9]].reshape((n, n))


@njit(cache=True)
def _beam_model(bi, bint, bflt, bintb):
    """The model arrays of beam bi that its residual reads (the first part of :func:`_beam_arrays`, without
    the work arrays): n, m, order, K, D, h, B, X0, base, weights, Md, gravity, rows, and the offset of its input
    matrix in bflt."""
    n, m, P, ng, order, fo, io = bint[bi, 0], bint[bi, 1], bint[bi, 2], bint[bi, 3], bint[bi, 4], bint[bi, 5], bint[bi, 7]
    Np = P + 1
    K = bflt[fo:fo + n * n].reshape((n, n))
    D = bflt[fo + n * n:fo + 2 * n * n].reshape((n, n))
    go = fo + 2 * n * n
    o = go + n * m
    h = bflt[o:o + P]
    o += P
    B = bflt[o:o + P * ng * n].reshape((P, ng, n))
    o += P * ng * n
    X0 = bflt[o:o + P * ng * 6].reshape((P, ng, 6))
    o += P * ng * 6
    base = bflt[o:o + 16].reshape((4, 4))
    o += 16
    wts = bflt[o:o + Np]
    o += Np
    Md = bflt[o:o + Np * 6].reshape((Np, 6))
    o += Np * 6
    ag = bflt[o:o + 3]
    return n, m, order, K, D, h, B, X0, base, wts, Md, ag, bintb[io:io + n], go


@njit(cache=True)
def _beam_input_force(xo, n, m, bflt, go, w, wo, bext, f_in, deg=1, ho=0):
    """The generalized force of beam inputs and couplings, :math:`G u` plus a grasp's share, into f_in (G the
    (n, m) input matrix at bflt[go:]); with ``deg`` > 1 (identified polynomial actuators) plus
    :math:`\\sum_{d=2}^{deg} C_d u^d` elementwise in u, the (deg-1, n, m) coefficients at bflt[ho:]."""
    for k in range(n):
        s = bext[xo + k]                            # forces of couplings (a grasp)
        for j in range(m):
            s += bflt[go + k * m + j] * w[wo + j]
            p = w[wo + j]
            for d in range(deg - 1):
                p *= w[wo + j]
                s += bflt[ho + (d * n + k) * m + j] * p
        f_in[k] = s


@njit(cache=True)
def _beam_rhs(bi, x, xo, w, wo, bint, bflt, bwork, bintb, bext, pflag, out):
    """Derivative (qd, qdd) of beam bi into out[xo:xo+2n] (:func:`soroshapes._beam.forward_dynamics`, the O(N)
    recursions, with the beam's point loads; leaves M at x in the workspace); False if the state is out of
    range."""
    (n, m, order, K, D, Gin, h, B, X0, base, wts, Md, ag, rows, piv, G, J, Jd, eta, etad, S, E, V, Op, AJ, W, M, C,
     fg, R, qdd, f_in, wko, end) = _beam_arrays(bi, bint, bflt, bwork, bintb)
    acc, SA, SX, NV, T, Jm, Ym, Opm, Mm, LU, a, v, R, f, G, eta, E, start, stop = _beam_ne_arrays(bi, bint, bwork)
    _beam_input_force(xo, n, m, bflt, bint[bi, 5] + 2 * n * n, w, wo, bext, f_in, bint[bi, _B_DEG], bint[bi, _B_HO])
    q = x[xo:xo + n]
    qd = x[xo + n:xo + 2 * n]
    nodes = np.zeros(0, np.int64)
    pW = np.zeros((0, 6))
    spatial = np.zeros(0, np.bool_)
    if bint[bi, _B_NPL] > 0:
        nodes, pW, spatial = _beam_point_loads(bi, bint, bflt, bintb, pflag)
    ok = _fd(q, qd, f_in, K, D, nodes, pW, spatial, order, h, B, rows, X0, base, wts, Md, ag, G, Jm, eta, acc, SA,
             SX, E, NV, T, Ym, Opm, Mm, LU, R, piv, qdd)
    s = 0.0
    for k in range(n):
        s += qdd[k]
    if not (ok and math.isfinite(s)):
        for j in range(start, stop):                # never keep a poisoned workspace (stale NaN times 0)
            bwork[j] = 0.0
        return False
    for k in range(n):
        out[xo + k] = qd[k]
        out[xo + n + k] = qdd[k]
    return True


#: no point loads in a beam's residual (constants: no allocation per evaluation)
_NO_NODES, _NO_LOADS, _NO_FLAGS = np.zeros(0, np.int64), np.zeros((0, 6)), np.zeros(0, np.bool_)


@njit(cache=True)
def _beam_point_loads(bi, bint, bflt, bintb, pflag):
    """Views of beam bi's constant point loads as the recursions take them (:func:`soroshapes._beam.newton_euler`):
    their nodes (workspace rows), wrenches (k, 6) (moment, force) [N m, N] and frames (True: spatial)."""
    k, on, ow, of = bint[bi, _B_NPL], bint[bi, _B_PLN], bint[bi, _B_PLW], bint[bi, _B_PLF]
    return bintb[on:on + k], bflt[ow:ow + 6 * k].reshape((k, 6)), pflag[of:of + k]


@njit(cache=True)
def _beam_residual(bi, xe, x1, xhat, gam, xo, w, wo, bint, bflt, bwork, bintb, bext, pflag, out):
    r"""The rows of beam bi in the residual of an implicit step (see :func:`residual`), second order: the
    coordinate rows :math:`q_1 - \hat q - \gamma\dot q_e` and, in force units, the equations of motion at the
    evaluation point with the acceleration the step implies, :math:`a = (\dot q_1 - \hat{\dot q})/\gamma`:
    :math:`\rho = M(q_e)a + C\dot q_e - f_g + D\dot q_e + Kq_e - f_{in}` by one pass of the O(N) recursions
    (:func:`soroshapes._beam.newton_euler`, or its planar form :func:`soroshapes._beam.newton_euler_planar` for
    a beam that moves in its body x-z plane, flagged at lowering; no mass matrix is formed or solved), its constant
    point loads (:func:`_beam_point_loads`) in the same pass. Leaves the pass's per-piece operators for
    :func:`_beam_mass_matrix`. False if the state is out of range."""
    n, m, order, K, D, h, B, X0, base, wts, Md, ag, rows, go = _beam_model(bi, bint, bflt, bintb)
    acc, SA, SX, NV, a, R, f_in, G, eta, E, start, stop = _beam_pass_arrays(bi, bint, bwork)
    _beam_input_force(xo, n, m, bflt, go, w, wo, bext, f_in, bint[bi, _B_DEG], bint[bi, _B_HO])
    q = xe[xo:xo + n]
    qd = xe[xo + n:xo + 2 * n]
    for k in range(n):
        a[k] = (x1[xo + n + k] - xhat[xo + n + k]) / gam
    nodes, pW, spatial = _NO_NODES, _NO_LOADS, _NO_FLAGS
    if bint[bi, _B_NPL] > 0:
        nodes, pW, spatial = _beam_point_loads(bi, bint, bflt, bintb, pflag)
    if bint[bi, _B_PLANAR]:
        _ne_planar(q, qd, a, order, h, B, rows, X0, base, wts, Md, ag, nodes, pW, spatial, G, eta, acc, SA, SX, E, NV,
                   R)
    else:
        _ne(q, qd, a, order, h, B, rows, X0, base, wts, Md, ag, nodes, pW, spatial, G, eta, acc, SA, SX, E, NV, R)
    s = 0.0
    for k in range(n):
        r = R[k] - f_in[k]
        for l in range(n):
            r += D[k, l] * qd[l] + K[k, l] * q[l]
        out[xo + k] = x1[xo + k] - xhat[xo + k] - gam * qd[k]
        out[xo + n + k] = r
        s += r
    if not math.isfinite(s):
        for j in range(start, stop):                # never keep a poisoned workspace (stale NaN times 0)
            bwork[j] = 0.0
        return False
    return True


@njit(cache=True)
def _beam_mass_matrix(bi, net):
    """M of beam bi at the configuration of its last :func:`_beam_residual` pass, into its workspace (Mm), from
    that pass's per-piece operators (:func:`soroshapes._beam.mass_matrix_pieces`, or
    :func:`soroshapes._beam.mass_matrix_planar` for a planar beam)."""
    n, m, order, K, D, h, B, X0, base, wts, Md, ag, rows, go = _beam_model(bi, net[1], net[2], net[4])
    acc, SA, SX, NV, T, Jm, Ym, Opm, Mm, LU, a, v, R, f, G, eta, E, start, stop = _beam_ne_views(bi, net)
    if net[1][bi, 9]:
        _mass_planar(order, h, B, rows, wts, Md, SA, SX, T, Jm, Ym, Opm, Mm)
    else:
        _mass_pieces(order, h, B, rows, wts, Md, SA, SX, T, Jm, Ym, Opm, Mm)


@njit(cache=True)
def _impedance(t, x, net, w):
    """The inputs of the Cartesian impedance controller (:func:`soroshapes.control.impedance`, the same
    equations) at (t, x) into w; False if the beam's state is out of range."""
    table, ctimes, cvals, cper, cint, cflt = net[0], net[11], net[12], net[13], net[26], net[27]
    blk, k, node, cor, grav, elas, null, m = cint[0], cint[1], cint[2], cint[3], cint[4], cint[5], cint[6], cint[7]
    bi, xo = table[blk, 5], table[blk, 1]
    (n, _, order, K, D, Gin, h, B, X0, base, wts, Md, ag, brows, piv, G, J, Jd, eta, etad, S, E, V, Op, AJ, W, M, C,
     fg, R, qdd, f_in, wko, end) = _beam_views(bi, net)
    q = np.ascontiguousarray(x[xo:xo + n])
    qd = np.ascontiguousarray(x[xo + n:xo + 2 * n])
    dOp = np.zeros((6, n))
    Mc, Cc, fgc = np.empty((n, n)), np.empty((n, n)), np.empty(n)
    _kinematics(q, qd, True, order, h, B, brows, X0, base, G, J, Jd, eta, S, E, V, Op, dOp, AJ)
    _kinematics_done(net, blk, 2)
    _mcg(J, Jd, eta, G, wts, Md, ag, Mc, Cc, fgc, True, S, V, AJ)
    s = 0.0
    for i in range(n):
        s += fgc[i] + Mc[i, i]
    if not math.isfinite(s):
        return False
    # the task: the spatial velocity of the node's origin, pdot = R v = R J_v qd, and its rate
    Rn = G[node, :3, :3]
    Jb = J[node]
    Jbd = Jd[node]
    om = Jb[:3] @ qd
    Jt, Jdt, p = np.empty((k, n)), np.empty((k, n)), np.empty(k)
    for a in range(k):
        r = cint[8 + a]
        p[a] = G[node, r, 3]
        for c in range(n):
            sj = 0.0
            sd = 0.0
            for l in range(3):
                l1, l2 = (l + 1) % 3, (l + 2) % 3
                sj += Rn[r, l] * Jb[3 + l, c]
                sd += Rn[r, l] * (om[l1] * Jb[3 + l2, c] - om[l2] * Jb[3 + l1, c] + Jbd[3 + l, c])
            Jt[a, c] = sj
            Jdt[a, c] = sd
    Mlu, Mpiv = np.empty((n, n)), np.empty(n, np.int64)
    for a in range(n):
        for c in range(n):
            Mlu[a, c] = Mc[a, c]
    if not _lu(Mlu, Mpiv):
        return False
    MinvJT = np.empty((n, k))
    col = np.empty(n)
    for a in range(k):
        for c in range(n):
            col[c] = Jt[a, c]
        _lu_solve(Mlu, Mpiv, col)
        for c in range(n):
            MinvJT[c, a] = col[c]
    A = Jt @ MinvJT
    ev, U = np.linalg.eigh(A)                         # pinv (hermitian), rcond 1e-9: finite at singularities
    cut = 1e-9 * np.max(np.abs(ev))
    Lam = np.zeros((k, k))
    for e in range(k):
        if abs(ev[e]) > cut:
            for a in range(k):
                for b2 in range(k):
                    Lam[a, b2] += U[a, e] * U[b2, e] / ev[e]
    pd = np.empty(k)
    _interp_row(ctimes, cvals, cper, t, pd)
    Kc = cflt[:k * k].reshape((k, k))
    Dc = cflt[k * k:2 * k * k].reshape((k, k))
    force = Kc @ (pd - p) - Dc @ (Jt @ qd)
    if cor:
        cq = Cc @ qd
        _lu_solve(Mlu, Mpiv, cq)
        force += Lam @ (Jt @ cq - Jdt @ qd)
    tau = Jt.T @ force
    if elas:
        tau += K @ q
    if grav:
        tau -= fgc
    if null:
        o = 2 * k * k
        Kn = cflt[o:o + n * n].reshape((n, n))
        Dn = cflt[o + n * n:o + 2 * n * n].reshape((n, n))
        qn = cflt[o + 2 * n * n:o + 2 * n * n + n]
        tau0 = Kn @ (qn - q) - Dn @ qd
        Jbar = MinvJT @ Lam
        tau += tau0 - Jt.T @ (Jbar.T @ tau0)
    og = 2 * k * k + 2 * n * n + n                  # G^+ (m, n), from the lowering
    for j in range(m):
        u = 0.0
        for c in range(n):
            u += cflt[og + j * n + c] * tau[c]
        w[cint[8 + k + j]] = u
    return True


@njit(cache=True)
def _controller_terms(t, x, net, w, only):
    r"""The inputs of the joint-space controllers and feed-forwards of :mod:`soroshapes.control` (the same
    equations as their Python closures), summed into w: :math:`\tau = K_p(q_d(t) - q) + K_i z - K_d\dot q + Kq
    - f_g(q)` (the compensation terms optional, z a PID's integral block), feed-forward inputs, torques or the
    static inputs of a configuration; :math:`u = G^+\tau`. Terms whose beam is not in ``only`` are skipped.
    False if a beam's state is out of range."""
    table, cint, cflt = net[0], net[26], net[27]
    o = 1
    for _ in range(cint[0]):
        kind, blk, m, grav, elas, integ, fo, K, cols = (cint[o], cint[o + 1], cint[o + 2], cint[o + 3], cint[o + 4],
                                                       cint[o + 5], cint[o + 6], cint[o + 7], cint[o + 8])
        rows = cint[o + _TERM_HEAD:o + _TERM_HEAD + m]
        o += _TERM_HEAD + m
        if not only[blk]:
            continue
        bi, xo = table[blk, 5], table[blk, 1]
        (n, _, order, Kb, D, Gin, h, B, X0, base, wts, Md, ag, brows, piv, G, J, Jd, eta, etad, S, E, V, Op, AJ, W,
         M, C, fg, R, qdd, f_in, wko, end) = _beam_views(bi, net)
        q = np.ascontiguousarray(x[xo:xo + n])
        qd = np.ascontiguousarray(x[xo + n:xo + 2 * n])
        f = fo
        if kind == _JOINT:
            f += 3 * n * n
        per = cflt[f]
        times = cflt[f + 1:f + 1 + K]
        vals = cflt[f + 1 + K:f + 1 + K + K * cols].reshape((K, cols))
        v = np.empty(cols)
        _interp_row(times, vals, per, t, v)
        if kind == _FF_INPUTS:
            for j in range(m):
                w[rows[j]] += v[j]
            continue
        tau = np.zeros(n)
        qc = q
        if kind == _JOINT:
            Kp = cflt[fo:fo + n * n].reshape((n, n))
            Ki = cflt[fo + n * n:fo + 2 * n * n].reshape((n, n))
            Kd = cflt[fo + 2 * n * n:fo + 3 * n * n].reshape((n, n))
            tau += Kp @ (v - q) - Kd @ qd
            if integ >= 0:
                zo = table[integ, 1]
                tau += Ki @ np.ascontiguousarray(x[zo:zo + n])
        elif kind == _FF_TORQUE:
            tau += v
            grav, elas = 0, 0
        else:
            qc = v
        if elas:
            tau += Kb @ qc
        if grav and (ag[0] != 0.0 or ag[1] != 0.0 or ag[2] != 0.0):
            dOp = np.zeros((6, n))
            Mc, Cc, fgc = np.empty((n, n)), np.empty((n, n)), np.empty(n)
            zero = np.zeros(n)
            _kinematics(np.ascontiguousarray(qc), zero, True, order, h, B, brows, X0, base, G, J, Jd, eta, S, E, V,
                        Op, dOp, AJ)
            _kinematics_done(net, blk, 0)              # not those of the state
            _mcg(J, Jd, eta, G, wts, Md, ag, Mc, Cc, fgc, True, S, V, AJ)
            tau -= fgc
        s = 0.0
        for k in range(n):
            s += tau[k]
        if not math.isfinite(s):
            return False
        if Gin.shape[0] == Gin.shape[1] and abs(np.linalg.det(Gin)) > 0.0:
            u = np.linalg.solve(np.ascontiguousarray(Gin), tau)
        else:
            u = np.linalg.lstsq(np.ascontiguousarray(Gin), tau, rcond=1e-10)[0]
        for j in range(m):
            w[rows[j]] += u[j]
    return True


@njit(cache=True)
def _beam_mass(bi, net):
    """The mass matrix that the last :func:`_beam_rhs` or :func:`_beam_mass_matrix` of beam bi left in its
    workspace (a view)."""
    return _beam_mass_of(bi, net[1], net[3])


@njit(cache=True)
def _valve(fpar, fi, nu, p):
    """Valve flow [kg/s] of reservoir fi for the command nu [kg/s] at absolute pressure p [Pa] and its derivatives
    by nu and p (:mod:`soroshapes.valves`): the saturation (regulated: clip to the max flow; else nu) or the
    orifice."""
    if fpar[fi, 14] == 1.0:
        return orifice_flow(fpar[fi, 15], fpar[fi, 16], fpar[fi, 17], fpar[fi, 18], fpar[fi, 19], nu, p)
    if fpar[fi, 7] == 0.0:
        return nu, 1.0, 0.0
    mx = fpar[fi, 10]
    if nu >= mx:
        return mx, 0.0, 0.0
    if nu <= -mx:
        return -mx, 0.0, 0.0
    return nu, 1.0, 0.0


@njit(cache=True)
def _fluidic_rhs(fi, x, xo, nx, w, wo, fpar, out):
    """Derivative of reservoir fi (see :meth:`soroshapes.model.Fluidic.rhs`)."""
    V = w[wo + 1]
    iso, R, T, p0, poly, leak, a = (fpar[fi, 0], fpar[fi, 1], fpar[fi, 2], fpar[fi, 3], fpar[fi, 4], fpar[fi, 5],
                                    fpar[fi, 6])
    reg, kp, ki, mx, filt = fpar[fi, 7], fpar[fi, 8], fpar[fi, 9], fpar[fi, 10], fpar[fi, 11]
    p = _pressure(fpar, fi, x[xo], V)
    if reg != 0.0:
        e = w[wo] - (p - p0)
        nu = kp * e + ki * x[xo + nx - 1]
        out[xo + nx - 1] = e + (min(max(nu, -mx), mx) - nu) / kp
    else:
        nu = w[wo]
    mdot = _valve(fpar, fi, nu, p)[0] - leak * (p - p0)
    if iso != 0.0:
        out[xo] = mdot
    else:
        Vdot = 0.0
        if filt != 0.0:
            Vdot = x[xo + 1] + a * V
            out[xo + 1] = -a * (x[xo + 1] + a * V)
        out[xo] = poly / V * (R * T * mdot - p * Vdot)


@njit(cache=True)
def _linear_rhs(li, x, xo, w, wo, lint, lflt, out):
    """xdot = A x + B u of linear system li."""
    n, m, o = lint[li, 0], lint[li, 1], lint[li, 3]
    ob = o + n * n
    for r in range(n):
        s = 0.0
        for c in range(n):
            s += lflt[o + r * n + c] * x[xo + c]
        for c in range(m):
            s += lflt[ob + r * m + c] * w[wo + c]
        out[xo + r] = s


_GROUND, _GRASP, _CONTACT, _TREE_CONTACT = 0, 1, 2, 3
_TERMS = {"ground": _GROUND, "grasp": _GRASP, "contact": _CONTACT, "tree_contact": _TREE_CONTACT}
#: pose of a wrench sum's body: a free rigid body's state, a spinning body's angle, none (fixed obstacles)
_FREE, _SPINNING, _FIXED = 0, 1, 2


@njit(cache=True)
def _polar3(A):
    """The rotation nearest to A (3, 3): the polar factor U V^T of its SVD, det +1 (as RigidBody.pose). Near a
    rotation (the integrated R is one to the Newton tolerance) by Higham's iteration Q <- (Q + Q^-T)/2, which
    converges quadratically to the same factor in a few 3 x 3 steps (cofactors, no allocation); otherwise by
    the SVD."""
    Q = A.copy()
    C = np.empty((3, 3))
    for _ in range(20):
        for i in range(3):                             # cofactor matrix: Q^-T = C / det Q
            for j in range(3):
                i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
                C[i, j] = Q[i1, j1] * Q[i2, j2] - Q[i1, j2] * Q[i2, j1]
        det = Q[0, 0] * C[0, 0] + Q[0, 1] * C[0, 1] + Q[0, 2] * C[0, 2]
        if not det > 0.0:
            break
        d = 0.0
        for i in range(3):
            for j in range(3):
                v = 0.5 * (Q[i, j] + C[i, j] / det)
                d = max(d, abs(v - Q[i, j]))
                Q[i, j] = v
        if d < 1e-15:
            return Q
    U, _, Vt = np.linalg.svd(A)
    Q = U @ Vt
    if np.linalg.det(Q) < 0.0:
        for i in range(3):
            U[i, 2] = -U[i, 2]
        Q = U @ Vt
    return Q


@njit(cache=True)
def _ground(par, R, p, eta, W):
    """Add the wrench of soroshapes.rigid.ground_contact (a plane pushing on body points; penalty, damping,
    regularized Coulomb friction) on the body at pose (R, p) with twist eta to W (body coordinates)."""
    k, c, mu, eps = par[0], par[1], par[2], par[3]
    n0, n1, n2 = par[7], par[8], par[9]
    npt = int(par[10])
    for j in range(npt):
        r0, r1, r2 = par[11 + 3 * j], par[12 + 3 * j], par[13 + 3 * j]
        b0 = eta[3] + eta[1] * r2 - eta[2] * r1           # v + omega x r (body)
        b1 = eta[4] + eta[2] * r0 - eta[0] * r2
        b2 = eta[5] + eta[0] * r1 - eta[1] * r0
        d = 0.0
        vn = 0.0
        for i in range(3):
            Pi = p[i] + R[i, 0] * r0 + R[i, 1] * r1 + R[i, 2] * r2
            vi = R[i, 0] * b0 + R[i, 1] * b1 + R[i, 2] * b2
            d += (Pi - par[4 + i]) * par[7 + i]
            vn += vi * par[7 + i]
        if d >= 0.0:
            continue
        fn = max(0.0, -k * d - c * vn)
        if fn == 0.0:
            continue
        v0 = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2 - vn * n0
        v1 = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2 - vn * n1
        v2 = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2 - vn * n2
        g = mu * fn / math.sqrt(v0 * v0 + v1 * v1 + v2 * v2 + eps * eps)
        F0, F1, F2 = fn * n0 - g * v0, fn * n1 - g * v1, fn * n2 - g * v2
        f0 = R[0, 0] * F0 + R[1, 0] * F1 + R[2, 0] * F2    # R^T F
        f1 = R[0, 1] * F0 + R[1, 1] * F1 + R[2, 1] * F2
        f2 = R[0, 2] * F0 + R[1, 2] * F1 + R[2, 2] * F2
        W[0] += r1 * f2 - r2 * f1
        W[1] += r2 * f0 - r0 * f2
        W[2] += r0 * f1 - r1 * f0
        W[3] += f0
        W[4] += f1
        W[5] += f2


@njit(cache=True)
def _grasp(t, net, par, bb, R, p, eta, x, W):
    """soroshapes.rigid.grasp_force scaled by the engagement table: a spring-damper between node par[0] of beam
    block bb and the body point par[1:4]; adds the body wrench to W and the beam's generalized force to the
    network's external-force buffer. False if the beam's state is out of range."""
    table, bext = net[0], net[28]
    K = int(par[6])
    e = np.empty(1)
    _interp_row(par[8:8 + K], par[8 + K:8 + 2 * K].reshape((K, 1)), par[7], t, e)
    if e[0] == 0.0:
        return True
    xo = table[bb, 1]
    (n, _, order, Kb, D, Gin, h, B, X0, base, wts, Md, ag, brows, piv, G, J, Jd, eta_b, etad, S, E, V, Op, AJ, Wb,
     M, C, fg, Rr, qdd, f_in, wko, end) = _beam_views(table[bb, 5], net)
    if _kinematics_level(net, bb) == 0:
        q = np.ascontiguousarray(x[xo:xo + n])
        qd = np.ascontiguousarray(x[xo + n:xo + 2 * n])
        dOp = np.zeros((6, n))
        _kinematics(q, qd, False, order, h, B, brows, X0, base, G, J, Jd, eta_b, S, E, V, Op, dOp, AJ)
        _kinematics_done(net, bb, 1)
    i = int(par[0])
    a0, a1, a2 = par[1], par[2], par[3]
    k, c = par[4], par[5]
    b0 = eta[3] + eta[1] * a2 - eta[2] * a1               # v + omega x a (body)
    b1 = eta[4] + eta[2] * a0 - eta[0] * a2
    b2 = eta[5] + eta[0] * a1 - eta[1] * a0
    F = np.empty(3)
    for r in range(3):
        Pa = p[r] + R[r, 0] * a0 + R[r, 1] * a1 + R[r, 2] * a2
        Va = R[r, 0] * b0 + R[r, 1] * b1 + R[r, 2] * b2
        Vb = G[i, r, 0] * eta_b[i, 3] + G[i, r, 1] * eta_b[i, 4] + G[i, r, 2] * eta_b[i, 5]
        F[r] = e[0] * (k * (G[i, r, 3] - Pa) + c * (Vb - Va))
    if not (math.isfinite(F[0]) and math.isfinite(F[1]) and math.isfinite(F[2])):
        return False
    f0 = R[0, 0] * F[0] + R[1, 0] * F[1] + R[2, 0] * F[2]      # R^T F on the body
    f1 = R[0, 1] * F[0] + R[1, 1] * F[1] + R[2, 1] * F[2]
    f2 = R[0, 2] * F[0] + R[1, 2] * F[1] + R[2, 2] * F[2]
    W[0] += a1 * f2 - a2 * f1
    W[1] += a2 * f0 - a0 * f2
    W[2] += a0 * f1 - a1 * f0
    W[3] += f0
    W[4] += f1
    W[5] += f2
    for r in range(3):                                      # -F on the beam: -J_v^T R_i^T F
        fl = G[i, 0, r] * F[0] + G[i, 1, r] * F[1] + G[i, 2, r] * F[2]
        for j in range(n):
            bext[xo + j] -= J[i, 3 + r, j] * fl
    return True


@njit(cache=True)
def _wrench_needed(net, si, only):
    """Whether an evaluation of the blocks marked in ``only`` reads wrench sum si: its body's inputs or the force of
    one of its terms on a beam."""
    wsum, wterm = net[23], net[24]
    if wsum[si, 2] >= 0 and only[wsum[si, 2]]:
        return True
    for tt in range(wsum[si, 0], wsum[si, 0] + wsum[si, 1]):
        if wterm[tt, 3] >= 0 and only[wterm[tt, 3]]:
            return True
    return False


@njit(cache=True)
def _body_pose(net, si, x):
    """Pose (R, p) and body twist of the body of wrench sum si at the state x: a free rigid body's state, a
    spinning body's g0 exp(theta a) and (a theta_dot, 0) (:class:`soroshapes.rigid.SpinningBody`), or the identity
    and zero for fixed obstacles."""
    table, wsum, wflt = net[0], net[23], net[25]
    body, kind, o = wsum[si, 2], wsum[si, 3], wsum[si, 4]
    if kind == _FREE:
        xo = table[body, 1]
        R = _polar3(np.ascontiguousarray(x[xo + 3:xo + 12]).reshape((3, 3)))
        return R, np.ascontiguousarray(x[xo:xo + 3]), np.ascontiguousarray(x[xo + 12:xo + 18])
    R = np.eye(3)
    p = np.zeros(3)
    eta = np.zeros(6)
    if kind == _SPINNING:                             # floats: R0 (9, row by row), p0 (3), axis (3)
        xo = table[body, 1]
        th, rate = x[xo], x[xo + 1]
        a0, a1, a2 = wflt[o + 12], wflt[o + 13], wflt[o + 14]
        s, cth = math.sin(th), 1.0 - math.cos(th)
        K = np.array([[0.0, -a2, a1], [a2, 0.0, -a0], [-a1, a0, 0.0]])
        Q = np.eye(3) + s * K + cth * (K @ K)
        R0 = wflt[o:o + 9].reshape((3, 3))
        R = R0 @ Q
        for i in range(3):
            p[i] = wflt[o + 9 + i]
            eta[i] = wflt[o + 12 + i] * rate
    return R, p, eta


#: modes of the wrench-term cache (net[32][0]): off, fill it at this evaluation, use it for the terms whose
#: blocks were not perturbed (the columns of a differenced Jacobian, :func:`_fd_rows`)
_CACHE_OFF, _CACHE_FILL, _CACHE_USE = 0, 1, 2


@njit(cache=True)
def _wrench_sum(t, net, si, x, W):
    """The summed wrench (body coordinates) of wrench sum si on its body at the state x (and the beams' share of
    its grasp and contact terms into the external-force buffer). False if a beam's state is out of range or a
    force is not finite.

    Each term is evaluated on its own (its wrench and its beam's force from zero, then added): with the cache
    filled at the base point of a differenced Jacobian (:func:`_fd_rows`), a column evaluation takes the terms
    that read no perturbed block (its beam, its body) from the cache, so a column of one beam evaluates that
    beam's contact, not every contact on the body."""
    table, wsum, wterm, wflt, bext, tcache, tflag = net[0], net[23], net[24], net[25], net[28], net[31], net[32]
    nb = table.shape[0]
    mode = tflag[0]
    first, count, body = wsum[si, 0], wsum[si, 1], wsum[si, 2]
    R, p, eta = _body_pose(net, si, x)
    Wt = np.empty(6)
    sv = np.empty(bext.shape[0])
    for tt in range(first, first + count):
        o, m, bb = wterm[tt, 1], wterm[tt, 2], wterm[tt, 3]
        xo, n = 0, 0
        if bb >= 0:
            xo, n = table[bb, 1], table[bb, 2] // 2
        if (mode == _CACHE_USE and tflag[1 + nb + tt] == 1 and not (body >= 0 and tflag[1 + body] == 1)
                and not (bb >= 0 and tflag[1 + bb] == 1)):
            for r in range(6):
                W[r] += tcache[tt, r]
            for k in range(n):
                bext[xo + k] += tcache[tt, 6 + k]
            continue
        for r in range(6):
            Wt[r] = 0.0
        for k in range(n):                               # the term's beam force from zero
            sv[k] = bext[xo + k]
            bext[xo + k] = 0.0
        if wterm[tt, 0] == _GROUND:
            _ground(wflt[o:o + m], R, p, eta, Wt)
            good = True
        elif wterm[tt, 0] == _CONTACT:
            good = _contact_term(net, tt, R, p, eta, x, Wt)
        elif wterm[tt, 0] == _TREE_CONTACT:
            good = _tree_contact_term(net, tt, R, p, eta, x, Wt)
        else:
            good = _grasp(t, net, wflt[o:o + m], bb, R, p, eta, x, Wt)
        fill = mode == _CACHE_FILL and good
        for k in range(n):
            f = bext[xo + k]
            bext[xo + k] = sv[k] + f
            if fill:
                tcache[tt, 6 + k] = f
        for r in range(6):
            W[r] += Wt[r]
            if fill:
                tcache[tt, r] = Wt[r]
        if not good:
            return False
        if fill:
            tflag[1 + nb + tt] = 1
    return True


@njit(cache=True)
def _add_force(f, bext, xo):
    """Add a contact term's generalized force f to the external-force buffer from xo; False (nothing added) if
    any of it is not finite."""
    for k in range(f.shape[0]):
        if not math.isfinite(f[k]):
            return False
    for k in range(f.shape[0]):
        bext[xo + k] += f[k]
    return True


@njit(cache=True)
def _term_kinematics(net, bb, x):
    """(n, G, J, eta) of beam block bb at its state in x: its frames, Jacobians and velocities at its chain of
    points (:func:`soroshapes._beam.kinematics`), computed once per state (:func:`_kinematics_level`)."""
    table = net[0]
    xo = table[bb, 1]
    (n, _, order, Kb, D, Gin, h, B, X0, base, wts, Md, ag, brows, piv, G, J, Jd, eta_b, etad, S, E, V, Op, AJ, Wb,
     M, C, fg, Rr, qdd, f_in, wko, end) = _beam_views(table[bb, 5], net)
    if _kinematics_level(net, bb) == 0:
        q = np.ascontiguousarray(x[xo:xo + n])
        qd = np.ascontiguousarray(x[xo + n:xo + 2 * n])
        dOp = np.zeros((6, n))
        _kinematics(q, qd, False, order, h, B, brows, X0, base, G, J, Jd, eta_b, S, E, V, Op, dOp, AJ)
        _kinematics_done(net, bb, 1)
    return n, G, J, eta_b


@njit(cache=True)
def _contact_rows(net, x, closed, dW, JF):
    r"""The closed-form rows of beam contacts (:func:`_analytic_sum`; :func:`soroshapes._contact.contact_jacobian`)
    at x, after :func:`_assemble` at x: each contact's force derivative added to its beam's rate rows of JF
    (force units, for a beam with ``closed``) and its wrench derivative to the rows of ``dW`` that the body's
    wrench coupling fills (:func:`_input_jacobian`), in the columns of the beam and of the spinning body. False if
    a force is not finite."""
    table, link_tab, link_rows, wsum, wterm, wflt = net[0], net[8], net[9], net[23], net[24], net[25]
    sops, sconsts, tcache = net[29], net[30], net[31]
    for si in range(wsum.shape[0]):
        first, count, body, pose, po = wsum[si, 0], wsum[si, 1], wsum[si, 2], wsum[si, 3], wsum[si, 4]
        if pose == _FREE:
            continue
        use = body >= 0 and closed[body]
        for tt in range(first, first + count):
            if wterm[tt, 0] != _CONTACT:
                use = False
                break
            use = use or closed[wterm[tt, 3]]
        if not use:
            continue
        ro = -1                                         # the body's input rows that its wrench sum fills
        if body >= 0:
            for li in range(link_tab.shape[0]):
                if link_tab[li, 0] == 2 and link_tab[li, 1] == si:
                    ro = link_tab[li, 2]
        R, p, eta = _body_pose(net, si, x)
        axis = np.zeros(3)
        xb = 0
        if pose == _SPINNING:
            xb = table[body, 1]
            for j in range(3):
                axis[j] = wflt[po + 12 + j]
        for tt in range(first, first + count):
            bb, o, m = wterm[tt, 3], wterm[tt, 1], wterm[tt, 2]
            xo = table[bb, 1]
            n, G, J, eta_b = _term_kinematics(net, bb, x)
            Fq, Fb = np.zeros((n, 2 * n)), np.zeros((n, 2))
            Wq, Wb = np.zeros((6, 2 * n)), np.zeros((6, 2))
            so, sn, co = wterm[tt, 4], wterm[tt, 5], wterm[tt, 6]
            nn = int(wflt[o + 6])
            memo = tcache[tt, 6 + n:6 + n + 4 * nn].reshape((nn, 4))
            if not _contact_jacobian(wflt[o:o + m], sops[so:so + sn], sconsts[co:], wterm[tt, 7], wterm[tt, 8], G, J,
                                     eta_b, R, p, eta, axis, memo, Fq, Fb, Wq, Wb):
                return False
            if closed[bb]:
                for k in range(n):
                    row = JF[xo + n + k]
                    for c in range(2 * n):
                        row[xo + c] += Fq[k, c]
                    if pose == _SPINNING:
                        row[xb] += Fb[k, 0]
                        row[xb + 1] += Fb[k, 1]
            if ro >= 0:
                for r in range(6):
                    d = dW[link_rows[ro + r]]
                    for c in range(2 * n):
                        d[xo + c] += Wq[r, c]
                    if pose == _SPINNING:
                        d[xb] += Wb[r, 0]
                        d[xb + 1] += Wb[r, 1]
    return True


@njit(cache=True)
def _contact_term(net, tt, R, p, eta, x, W):
    """Contact term tt (:func:`soroshapes._contact.contact_force`) between its beam, at its state in x, and the
    body at pose (R, p) with twist eta: the beam's force into the external-force buffer, the wrench into W.
    False if the beam's state is out of range or a force is not finite."""
    table, wterm, wflt, bext, sops, sconsts = net[0], net[24], net[25], net[28], net[29], net[30]
    bb, o, m = wterm[tt, 3], wterm[tt, 1], wterm[tt, 2]
    xo = table[bb, 1]
    n, G, J, eta_b = _term_kinematics(net, bb, x)
    f = np.zeros(n)
    so, sn, co = wterm[tt, 4], wterm[tt, 5], wterm[tt, 6]
    nn = int(wflt[o + 6])
    memo = net[31][tt, 6 + n:6 + n + 4 * nn].reshape((nn, 4))       # after the term's cached force
    if not _contact_force(wflt[o:o + m], sops[so:so + sn], sconsts[co:], wterm[tt, 7], wterm[tt, 8], G, J, eta_b,
                          R, p, eta, f, W, memo):
        return False
    return _add_force(f, bext, xo)


@njit(cache=True)
def _tree_contact_term(net, tt, R, p, eta, x, W):
    """Contact term tt (:func:`soroshapes._contact.tree_contact_force`) between the points on the tree block's
    bodies, at its state in x, and the body at pose (R, p) with twist eta: the tree's generalized force into the
    external-force buffer (read by :func:`soroshapes._treeblock.block_rhs`), the wrench into W. False if the
    tree's state is out of range or a force is not finite."""
    table, wterm, wflt, bext, sops, sconsts = net[0], net[24], net[25], net[28], net[29], net[30]
    bb, o, m = wterm[tt, 3], wterm[tt, 1], wterm[tt, 2]
    xo, n = table[bb, 1], table[bb, 2] // 2
    G, J, eta_t = _treeblock.block_kinematics(net[33], x, xo)
    f = np.zeros(n)
    so, sn, co = wterm[tt, 4], wterm[tt, 5], wterm[tt, 6]
    if not _tree_contact_force(wflt[o:o + m], sops[so:so + sn], sconsts[co:], wterm[tt, 7], wterm[tt, 8], G, J,
                               eta_t, R, p, eta, f, W):
        return False
    return _add_force(f, bext, xo)


@njit(cache=True)
def _rigid_rhs(ri, x, xo, w, wo, rflt, out):
    """Newton-Euler derivative of free rigid body ri (:meth:`soroshapes.rigid.RigidBody.rhs`): state
    (p, R row by row, omega, v), input the body wrench (m, f) at w[wo:wo+6]."""
    par = rflt[ri]
    mass, cv, cw, kappa = par[0], par[22], par[23], par[24]
    R = x[xo + 3:xo + 12].reshape((3, 3))
    om, v = x[xo + 12:xo + 15], x[xo + 15:xo + 18]
    for i in range(3):
        out[xo + i] = R[i, 0] * v[0] + R[i, 1] * v[1] + R[i, 2] * v[2]
    # dR = R hat(omega) + kappa/2 (R - R R^T R)
    RtR = R.T @ R
    for i in range(3):
        for j in range(3):
            a = R[i, (j + 1) % 3] * om[(j + 2) % 3] - R[i, (j + 2) % 3] * om[(j + 1) % 3]
            if kappa != 0.0:
                a += 0.5 * kappa * (R[i, j] - (R[i, 0] * RtR[0, j] + R[i, 1] * RtR[1, j] + R[i, 2] * RtR[2, j]))
            out[xo + 3 + 3 * i + j] = a
    Iw = np.empty(3)
    for i in range(3):
        Iw[i] = par[1 + 3 * i] * om[0] + par[2 + 3 * i] * om[1] + par[3 + 3 * i] * om[2]
    mom = np.empty(3)
    force = np.empty(3)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        mom[i] = -(om[i1] * Iw[i2] - om[i2] * Iw[i1]) - cw * om[i] + w[wo + i]      # v x m v = 0
        force[i] = -mass * (om[i1] * v[i2] - om[i2] * v[i1]) \
            + mass * (R[0, i] * par[19] + R[1, i] * par[20] + R[2, i] * par[21]) - cv * v[i] + w[wo + 3 + i]
    for i in range(3):
        out[xo + 12 + i] = par[10 + 3 * i] * mom[0] + par[11 + 3 * i] * mom[1] + par[12 + 3 * i] * mom[2]
        out[xo + 15 + i] = force[i] / mass


@njit(cache=True)
def _system_rhs_a(i, x, w, table, bint, bflt, bwork, bintb, bext, fpar, rflt, lint, lflt, tblk, pflag, out):
    """The derivative of system i (any kind) at x with its inputs in w, into its rows of out, from the network's
    arrays (see :func:`_beam_arrays`; ``tblk`` the tree block's, net[33]; ``pflag`` the beams' point-load frames,
    net[35]); False if a beam's or the tree's state is out of range."""
    xo, nx, wo = table[i, 1], table[i, 2], table[i, 3]
    if table[i, 0] == TREE:                     # a tree of bodies (soroshapes._treeblock)
        return _treeblock.block_rhs(tblk, x, xo, w, wo, bext, out)
    if table[i, 0] == BEAM:
        return _beam_rhs(table[i, 5], x, xo, w, wo, bint, bflt, bwork, bintb, bext, pflag, out)
    if table[i, 0] == FLUIDIC:
        _fluidic_rhs(table[i, 5], x, xo, nx, w, wo, fpar, out)
    elif table[i, 0] == RIGID:
        _rigid_rhs(table[i, 5], x, xo, w, wo, rflt, out)
    else:
        _linear_rhs(table[i, 5], x, xo, w, wo, lint, lflt, out)
    return True


@njit(cache=True)
def _finite_rows(table, mode, out):
    for i in range(table.shape[0]):
        if mode[i]:
            for j in range(table[i, 1], table[i, 1] + table[i, 2]):
                if not math.isfinite(out[j]):
                    return False
    return True


@njit(cache=True)
def rhs(t, x, net, w, out, only):
    """F(t, x) into out (the blocks with ``only[i]`` True; inputs assembled into w). False if a state is out of
    range or a volume is not positive."""
    table, bint, bflt, bwork, bintb, fpar, bext = net[0], net[1], net[2], net[3], net[4], net[5], net[28]
    rflt, lint, lflt = net[22], net[20], net[21]
    if not _assemble(t, x, net, w, only):
        return False
    for i in range(table.shape[0]):
        if only[i] and not _system_rhs_a(i, x, w, table, bint, bflt, bwork, bintb, bext, fpar, rflt, lint, lflt,
                                         net[33], net[35], out):
            return False
    return _finite_rows(table, only, out)


#: what :func:`_evaluate` computes for a system: nothing, its derivative F, or (beams) its inputs' force
_SKIP, _DERIVATIVE, _INPUT_FORCE = 0, 1, 2


@njit(cache=True)
def _evaluate(t, x, net, w, out, mode):
    """Per system, by ``mode[i]``: nothing, its derivative (as :func:`rhs`), or for a beam or a tree the generalized
    force of its inputs and couplings :math:`f_{in}(t, x)` in its rate rows (0 in its coordinate rows): the part
    of its equations that reads other systems, differenced by :func:`_fd_rows`. False as :func:`rhs`."""
    table, bint, bflt, bwork, bintb, fpar, bext = net[0], net[1], net[2], net[3], net[4], net[5], net[28]
    rflt, lint, lflt = net[22], net[20], net[21]
    if not _assemble(t, x, net, w, mode):
        return False
    for i in range(table.shape[0]):
        if mode[i] == _DERIVATIVE:
            if not _system_rhs_a(i, x, w, table, bint, bflt, bwork, bintb, bext, fpar, rflt, lint, lflt, net[33],
                                 net[35], out):
                return False
        elif mode[i] == _INPUT_FORCE and table[i, 0] == TREE:     # the tree's force from outside it
            xo, n = table[i, 1], table[i, 2] // 2
            _treeblock.block_input_force(net[33], w, table[i, 3], bext, xo, out[xo + n:xo + 2 * n])
            for k in range(n):
                out[xo + k] = 0.0
        elif mode[i] == _INPUT_FORCE:
            bi, xo, wo = table[i, 5], table[i, 1], table[i, 3]
            n, m = bint[bi, 0], bint[bi, 1]
            f_in = _beam_ne_arrays(bi, bint, bwork)[13]
            _beam_input_force(xo, n, m, bflt, bint[bi, 5] + 2 * n * n, w, wo, bext, f_in, bint[bi, _B_DEG],
                              bint[bi, _B_HO])
            for k in range(n):
                out[xo + k] = 0.0
                out[xo + n + k] = f_in[k]
    return _finite_rows(table, mode, out)


@njit(cache=True)
def residual(t, xe, x1, xhat, gam, net, w, out, only):
    r"""The residual of an implicit step of the systems with ``only[i]`` True into ``out``, at the evaluation
    point ``xe`` (time t) for the new state ``x1``: :math:`x_1 - \hat x - \gamma F(t, x_e)` for every system but
    a beam, whose rows are second order (:func:`_beam_residual`: the coordinate rows as above, the rate rows
    the equations of motion in force units with the acceleration :math:`(\dot q_1 - \hat{\dot q})/\gamma`, no
    mass matrix solved). The methods of :mod:`soroshapes.integrate` give :math:`\hat x`, :math:`\gamma` and
    :math:`x_e`. False if a state is out of range or a volume is not positive."""
    table, bint, bflt, bwork, bintb, fpar, bext = net[0], net[1], net[2], net[3], net[4], net[5], net[28]
    rflt, lint, lflt = net[22], net[20], net[21]
    if not _assemble(t, xe, net, w, only):
        return False
    for i in range(table.shape[0]):
        if not only[i]:
            continue
        xo, nx = table[i, 1], table[i, 2]
        if table[i, 0] == BEAM:
            if not _beam_residual(table[i, 5], xe, x1, xhat, gam, xo, w, table[i, 3], bint, bflt, bwork, bintb, bext,
                                  net[35], out):
                return False
            continue
        if table[i, 0] == FLUIDIC:
            _fluidic_rhs(table[i, 5], xe, xo, nx, w, table[i, 3], fpar, out)
        else:
            _system_rhs_a(i, xe, w, table, bint, bflt, bwork, bintb, bext, fpar, rflt, lint, lflt, net[33], net[35],
                          out)
        for j in range(xo, xo + nx):
            out[j] = x1[j] - xhat[j] - gam * out[j]
    return _finite_rows(table, only, out)


@njit(cache=True)
def jacobian(t, x, net, scale, w, f0, fp, xp, Jac, JF):
    """:math:`\\partial F/\\partial x` by grouped forward differences (steps ``FD_STEP max(|x_j|, scale_j)``)
    into Jac, and into JF the same with the acceleration rows of every beam multiplied by its mass matrix at x
    (the force Jacobian, which changes slowly with the configuration; see :func:`_iteration_matrix`). A tree's
    rows are its model rows (:func:`soroshapes._treeblock.block_model_rows`, the differenced force of its
    inputs and contact terms): differencing its dynamics costs a whole evaluation of the tree per column, and
    its model rows leave out only the inertial and gravity derivatives, which change the Newton contraction by
    ~1e-4 (tests/soroshapes/test_rigid.py), so they serve this mode as well. False if an evaluation fails."""
    table = net[0]
    nb = table.shape[0]
    N = x.shape[0]
    alls = np.full(nb, _DERIVATIVE, np.int64)
    tree = -1
    for b in range(nb):
        if table[b, 0] == TREE:
            alls[b] = _INPUT_FORCE
            tree = b
    for i in range(N):
        for j in range(N):
            Jac[i, j] = 0.0
    if not _fd_rows(t, x, net, scale, w, f0, fp, xp, alls, Jac):
        return False
    if tree >= 0 and not _treeblock.block_model_rows(net[33], x, table[tree, 1], Jac):
        return False
    if not _evaluate(t, x, net, w, f0, alls):         # the workspaces at x again (their mass matrices)
        return False
    for i in range(N):
        for j in range(N):
            JF[i, j] = Jac[i, j]
    for b in range(nb):
        if table[b, 0] == BEAM:
            n = table[b, 2] // 2
            r0 = table[b, 1] + n
            M = _beam_mass(table[b, 5], net)
            for k in range(n):
                for j in range(N):
                    s = 0.0
                    for l in range(n):
                        s += M[k, l] * Jac[r0 + l, j]
                    JF[r0 + k, j] = s
    return True


@njit(cache=True)
def _fd_rows(t, x, net, scale, w, f0, fp, xp, rows, out):
    """The rows of the systems with ``rows[i]`` not ``_SKIP`` of the Jacobian of :func:`_evaluate` (what it
    computes per system: F, or a beam's input force) by grouped forward differences (steps
    ``FD_STEP max(|x_j|, scale_j)``), evaluating only those systems, into ``out`` (other rows untouched); a
    column evaluates only the wrench terms that read its block (the cache of :func:`_wrench_sum`, filled at x).
    False if an evaluation fails."""
    ok = _fd_rows_cached(t, x, net, scale, w, f0, fp, xp, rows, out)
    net[32][0] = _CACHE_OFF
    return ok


@njit(cache=True)
def _fd_rows_cached(t, x, net, scale, w, f0, fp, xp, rows, out):
    """:func:`_fd_rows` with the wrench-term cache on (its caller turns it off)."""
    table, groups, dep, col_block, tflag = net[0], net[15], net[16], net[17], net[32]
    nb = table.shape[0]
    N = x.shape[0]
    for i in range(tflag.shape[0]):
        tflag[i] = 0
    tflag[0] = _CACHE_FILL
    if not _evaluate(t, x, net, w, f0, rows):
        return False
    tflag[0] = _CACHE_USE
    sel = np.zeros(nb, np.int64)
    for g in range(groups.shape[0]):
        for i in range(N):
            xp[i] = x[i]
        any_row = False
        for b in range(nb):
            sel[b] = _SKIP
            tflag[1 + b] = 0
        for c in range(groups.shape[1]):
            j = groups[g, c]
            if j < 0:
                break
            xp[j] = x[j] + FD_STEP * max(abs(x[j]), scale[j])
            tflag[1 + col_block[j]] = 1
            for b in range(nb):
                if rows[b] != _SKIP and dep[b, col_block[j]]:
                    sel[b] = rows[b]
                    any_row = True
        if not any_row:
            continue
        if not _evaluate(t, xp, net, w, fp, sel):
            return False
        for c in range(groups.shape[1]):
            j = groups[g, c]
            if j < 0:
                break
            d = xp[j] - x[j]
            for b in range(nb):
                if rows[b] != _SKIP and dep[b, col_block[j]]:
                    for i in range(table[b, 1], table[b, 1] + table[b, 2]):
                        out[i, j] = (fp[i] - f0[i]) / d
    return True


@njit(cache=True)
def _cheap_rows(t, x, net, scale, w, f0, fp, xp, JF, beams, analytic):
    """:func:`_cheap_rows_of` for every system of the network."""
    return _cheap_rows_of(t, x, net, scale, w, f0, fp, xp, JF, beams, analytic, np.ones(net[0].shape[0], np.bool_))


@njit(cache=True)
def _cheap_rows_of(t, x, net, scale, w, f0, fp, xp, JF, beams, analytic, sel):
    r"""Refresh the rows of JF that are cheap to form: those of every system other than a beam (reservoirs:
    non-smooth where a valve saturates, so a stale row makes Newton contract slowly), and with ``beams`` the force
    rows of every beam as its model Jacobian :math:`\partial f_{in}/\partial x - [K\;\; D]` (the inputs' force,
    elasticity and damping; the configuration and velocity derivatives of the inertial forces left out, as in the
    beam's own iteration matrix :math:`2M/h + D + \tfrac h2 K`) and their coordinate rows :math:`[0\;\; I]`, and
    the tree's rows as its model rows :math:`M^{-1}(\partial f_{in}/\partial x - [K\;\; D])`
    (:func:`soroshapes._treeblock.block_model_rows`; first-order rows, so :math:`M^{-1}` times a beam's): a column
    evaluates the tree's contact terms and its inputs (:func:`soroshapes._treeblock.block_input_force`), not its
    dynamics, and a column of the body in contact not even the tree's kinematics. Without ``beams`` (the
    differenced mode) the rows of the beams, the tree and the bodies in contact with them are left as the
    differenced Jacobian (:func:`jacobian`) gave them.
    With ``analytic`` the systems marked at lowering (``table[i, 7]``) get their rows in closed form
    (:func:`_analytic_rows`, no evaluation of the network) and only the others are differenced by
    :func:`_fd_rows`; without it all are differenced. Only the systems with ``sel[i]`` True (the others' rows of
    JF are left as they are: the integrator refreshes the components whose Newton contracted slowly). False if
    an evaluation fails."""
    table, bint, bflt = net[0], net[1], net[2]
    N = x.shape[0]
    nb = table.shape[0]
    mode = np.zeros(nb, np.int64)
    closed = np.zeros(nb, np.bool_)
    model = np.zeros(nb, np.bool_)        # the systems that get model rows (beams, the tree) with ``beams``
    any_fd = False
    for b in range(nb):
        if ((table[b, 0] == BEAM or table[b, 0] == TREE) and not beams) or not sel[b]:
            continue
        model[b] = table[b, 0] == BEAM or table[b, 0] == TREE
        if analytic and table[b, 7] == 1:
            closed[b] = True
        elif model[b]:
            mode[b] = _INPUT_FORCE
            any_fd = True
        elif table[b, 6] == 0 or beams:
            # a body whose inputs are contacts with beams or a tree (table[b, 6]): each of its columns evaluates
            # the contacts' kinematics, which the model rows of those beams and that tree (same component, so
            # refreshed here) evaluate anyway (left out, its rows stayed I: Newton solved the body's equations by
            # fixed-point iteration); in the differenced mode its rows come from the differenced Jacobian, as theirs
            mode[b] = _DERIVATIVE
            any_fd = True
        if model[b]:
            for i in range(table[b, 1], table[b, 1] + table[b, 2]):
                for j in range(N):
                    JF[i, j] = 0.0
    if any_fd and not _fd_rows(t, x, net, scale, w, f0, fp, xp, mode, JF):
        return False
    for b in range(nb):
        if model[b] and table[b, 0] == TREE and not _treeblock.block_model_rows(net[33], x, table[b, 1], JF):
            return False
    for b in range(nb):
        if closed[b]:
            if not _analytic_rows(t, x, net, w, closed, JF):
                return False
            break
    if beams:
        for b in range(nb):
            if table[b, 0] != BEAM or not sel[b]:
                continue
            bi, xo = table[b, 5], table[b, 1]
            n, fo = bint[bi, 0], bint[bi, 5]
            for k in range(n):
                JF[xo + k, xo + n + k] = 1.0
                for l in range(n):
                    JF[xo + n + k, xo + l] -= bflt[fo + k * n + l]             # K
                    JF[xo + n + k, xo + n + l] -= bflt[fo + n * n + k * n + l]  # D
    return True


@njit(cache=True)
def _input_jacobian(x, net, w, dW):
    r""":math:`\partial W/\partial x` (NW, N) of the inputs that :func:`assemble` writes, in its order, for the
    rows that :func:`_mark_analytic` knows: reservoir volumes (constant or a :class:`StateMap`), controller values
    that read no state (0), couplings from a system's output (a reservoir's gauge pressure :math:`p(x_0, V) -
    p_0`, a linear system's :math:`Cx + Du`, a state) or a :class:`StateMap` :math:`o + s\,\phi'(a)\,A`. Rows of
    wrench sums and feedback controllers stay 0 (their readers are differenced). ``w`` holds the inputs at x."""
    (table, bint, bflt, bwork, bintb, fpar, mapint, maps, link_tab, link_rows) = net[:10]
    lint, lflt = net[20], net[21]
    N = x.shape[0]
    for j in range(dW.shape[0]):
        for c in range(N):
            dW[j, c] = 0.0
    for i in range(table.shape[0]):
        if table[i, 0] == FLUIDIC:
            fi = table[i, 5]
            if fpar[fi, 12] != 0.0:
                _map_row_jacobian(mapint, maps, table, x, int(fpar[fi, 13]), 0, dW[table[i, 3] + 1])
    for li in range(link_tab.shape[0]):
        lk, src, ro, nr = link_tab[li, 0], link_tab[li, 1], link_tab[li, 2], link_tab[li, 3]
        if lk == 2:
            continue
        for r in range(nr):
            d = dW[link_rows[ro + r]]
            if lk == 1:
                _map_row_jacobian(mapint, maps, table, x, src, r, d)
            elif table[src, 0] == FLUIDIC:                 # p - p0 of the source reservoir
                fi, so = table[src, 5], table[src, 3]
                V = w[so + 1]
                if fpar[fi, 0] != 0.0:
                    p = _pressure(fpar, fi, x[table[src, 1]], V)
                    for c in range(N):
                        d[c] = -p / V * dW[so + 1, c]
                    d[table[src, 1]] += fpar[fi, 1] * fpar[fi, 2] / V
                else:
                    for c in range(N):
                        d[c] = 0.0
                    d[table[src, 1]] = 1.0
            elif table[src, 0] == LINEAR:                  # C x + D u
                lj = table[src, 5]
                n, m, o = lint[lj, 0], lint[lj, 1], lint[lj, 3]
                oc = o + n * n + n * m
                od = oc + lint[lj, 2] * n
                for c in range(N):
                    d[c] = 0.0
                for c in range(n):
                    d[table[src, 1] + c] = lflt[oc + r * n + c]
                for c in range(m):
                    f = lflt[od + r * m + c]
                    if f != 0.0:
                        for cc in range(N):
                            d[cc] += f * dW[table[src, 3] + c, cc]
            else:
                for c in range(N):
                    d[c] = 0.0
                d[table[src, 1] + r] = 1.0


@njit(cache=True)
def _map_row_jacobian(mapint, maps, table, x, mi, r, d):
    """Gradient of output r of StateMap mi with respect to the network state, into d (N,)."""
    src, k, fn, o = mapint[mi, 0], mapint[mi, 1], mapint[mi, 2], mapint[mi, 3]
    xo, n = table[src, 1], table[src, 2]
    s = 0.0
    for c in range(n):
        s += maps[o + r * n + c] * x[xo + c]
    g = maps[o + k * n + k + r]
    if fn == 1:
        th = math.tanh(s)
        g *= 1.0 - th * th
    for c in range(d.shape[0]):
        d[c] = 0.0
    for c in range(n):
        d[xo + c] = g * maps[o + r * n + c]


@njit(cache=True)
def _analytic_rows(t, x, net, w, closed, JF):
    r"""The rows of JF of the systems with ``closed[i]`` in closed form, at (t, x): with :math:`W_x` =
    :func:`_input_jacobian` (and the wrench of beam contacts on a spinning body, :func:`_contact_rows`), a linear
    system's :math:`[A\;\; B W_x]`, a beam's input force :math:`G W_x` plus its contacts' force derivative
    (:func:`_contact_rows`; its rate rows; the caller adds :math:`-[K\;\; D]` and the coordinate rows), a
    reservoir's rows of :func:`_fluidic_jacobian`. False if the inputs are out of range or a contact force is
    not finite."""
    table, bint, bflt = net[0], net[1], net[2]
    lint, lflt, fpar = net[20], net[21], net[5]
    N = x.shape[0]
    if not _assemble(t, x, net, w, closed):
        return False
    dW = np.empty((w.shape[0], N))
    _input_jacobian(x, net, w, dW)
    for i in range(table.shape[0]):
        if closed[i] and table[i, 0] == BEAM:
            n = bint[table[i, 5], 0]
            for k in range(table[i, 1] + n, table[i, 1] + 2 * n):
                for c in range(N):
                    JF[k, c] = 0.0
    if not _contact_rows(net, x, closed, dW, JF):     # contacts: into the beams' rows and the bodies' inputs
        return False
    for i in range(table.shape[0]):
        if not closed[i]:
            continue
        xo, nx, wo = table[i, 1], table[i, 2], table[i, 3]
        if table[i, 0] == BEAM:
            bi = table[i, 5]
            n, m = bint[bi, 0], bint[bi, 1]
            go = bint[bi, 5] + 2 * n * n
            for k in range(n):
                row = JF[xo + n + k]
                for j in range(m):
                    g = bflt[go + k * m + j]
                    if g != 0.0:
                        for c in range(N):
                            row[c] += g * dW[wo + j, c]
        elif table[i, 0] == LINEAR:
            li = table[i, 5]
            n, m, o = lint[li, 0], lint[li, 1], lint[li, 3]
            ob = o + n * n
            for r in range(n):
                row = JF[xo + r]
                for c in range(N):
                    row[c] = 0.0
                for c in range(n):
                    row[xo + c] = lflt[o + r * n + c]
                for j in range(m):
                    g = lflt[ob + r * m + j]
                    if g != 0.0:
                        for c in range(N):
                            row[c] += g * dW[wo + j, c]
        else:
            _fluidic_jacobian(table[i, 5], x, xo, nx, w, wo, fpar, dW, JF)
    return True


@njit(cache=True)
def _fluidic_jacobian(fi, x, xo, nx, w, wo, fpar, dW, JF):
    r"""The rows of reservoir fi in JF, the derivative of :func:`_fluidic_rhs` with respect to the network state
    through its own state and its inputs (set point or flow :math:`u` and volume :math:`V`, rows of ``dW``):
    ideal gas :math:`p = x_0RT/V` (isothermal; else :math:`p = x_0`), PI regulator :math:`\nu = k_p e + k_i s`,
    :math:`e = u - (p - p_0)`, integral :math:`\dot s = e + (\mathrm{clip}(\nu, \pm\dot m_{max}) - \nu)/k_p`
    (slope 1 inside, 0 when saturated), the valve :math:`\dot m = \Psi_v(\nu, p)` with its derivatives by
    :math:`\nu` and :math:`p` (:func:`_valve`: the saturation, or the orifice of :mod:`soroshapes.valves` in
    closed form), leak, the polytropic law and the volume filter."""
    N = x.shape[0]
    V = w[wo + 1]
    iso, R, T, p0, poly, leak, a = (fpar[fi, 0], fpar[fi, 1], fpar[fi, 2], fpar[fi, 3], fpar[fi, 4], fpar[fi, 5],
                                    fpar[fi, 6])
    reg, kp, ki, mx, filt = fpar[fi, 7], fpar[fi, 8], fpar[fi, 9], fpar[fi, 10], fpar[fi, 11]
    p = _pressure(fpar, fi, x[xo], V)
    dV, du = dW[wo + 1], dW[wo]
    dp = np.empty(N)
    for c in range(N):
        dp[c] = -p / V * dV[c] if iso != 0.0 else 0.0
    dp[xo] += R * T / V if iso != 0.0 else 1.0
    dm = np.empty(N)                                 # d mdot (valve flow less the leak)
    if reg != 0.0:
        e = w[wo] - (p - p0)
        si = xo + nx - 1
        nu = kp * e + ki * x[si]
        slope = 1.0 if -mx < nu < mx else 0.0          # of the command's clip (anti-windup)
        mdot, dm_nu, dm_p = _valve(fpar, fi, nu, p)
        row = JF[si]
        for c in range(N):
            de = du[c] - dp[c]
            dnu = kp * de
            if c == si:
                dnu += ki
            row[c] = de + (slope - 1.0) * dnu / kp
            dm[c] = dm_nu * dnu + (dm_p - leak) * dp[c]
    else:
        mdot, dm_nu, dm_p = _valve(fpar, fi, w[wo], p)
        for c in range(N):
            dm[c] = dm_nu * du[c] + (dm_p - leak) * dp[c]
    mdot = mdot - leak * (p - p0)
    row = JF[xo]
    if iso != 0.0:
        for c in range(N):
            row[c] = dm[c]
        return
    Vdot = 0.0
    if filt != 0.0:
        Vdot = x[xo + 1] + a * V
        r1 = JF[xo + 1]
        for c in range(N):
            r1[c] = -a * a * dV[c]
        r1[xo + 1] -= a
    F0 = poly / V * (R * T * mdot - p * Vdot)
    for c in range(N):
        dVdot = a * dV[c] if filt != 0.0 else 0.0
        if filt != 0.0 and c == xo + 1:
            dVdot += 1.0
        row[c] = -F0 / V * dV[c] + poly / V * (R * T * dm[c] - Vdot * dp[c] - p * dVdot)


@njit(cache=True)
def _iteration_matrix(c, gam, net, JF, LUc, pivc):
    """:func:`_iteration_matrix_of` for every connected component."""
    return _iteration_matrix_of(c, gam, net, JF, LUc, pivc, np.ones(net[18].shape[0], np.bool_))


@njit(cache=True)
def _iteration_matrix_of(c, gam, net, JF, LUc, pivc, sel):
    r"""Factor the Newton matrix of :func:`residual` per connected component, :math:`I - cJ` (``c`` =
    :math:`\gamma` times the weight of :math:`x_1` in the evaluation point) in the rows of every system but a
    beam's force rows, which are :math:`\tfrac1\gamma M_{[\cdot, \dot q]} - \tfrac c\gamma J_F` with
    :math:`M` the current mass matrix (:func:`_beam_mass_matrix`) and ``JF`` its force Jacobian (model rows of
    :func:`_cheap_rows`, or the differenced :func:`jacobian`). Each component's block is gathered straight into
    its factor (the matrix is block diagonal); only the components with ``sel[k]`` True. False if singular."""
    table, col_block, comps = net[0], net[17], net[18]
    for k in range(comps.shape[0]):
        if not sel[k]:
            continue
        s = 0
        while s < comps.shape[1] and comps[k, s] >= 0:
            s += 1
        A = LUc[k, :s, :s]
        M = np.zeros((0, 0))
        mb = -1                                         # the beam block whose mass matrix M is
        for a in range(s):
            i = comps[k, a]
            bl = col_block[i]
            f = c
            rate = -1                                   # the row's rate index in its beam, if a force row
            n = 0
            if table[bl, 0] == BEAM:
                n = table[bl, 2] // 2
                if i >= table[bl, 1] + n:
                    rate = i - table[bl, 1] - n
                    f = c / gam
            for b2 in range(s):
                A[a, b2] = -f * JF[i, comps[k, b2]]
            if rate < 0:
                A[a, a] += 1.0
            else:
                if mb != bl:                            # the views once per beam, not once per row
                    M = _beam_mass_of(table[bl, 5], net[1], net[3])
                    mb = bl
                first = a - rate                      # the beam's rate columns are contiguous in the component
                for l in range(n):
                    A[a, first + l] += M[rate, l] / gam
        if not _lu(A, pivc[k, :s]):
            return False
    return True


# the warm-up builds a Model, and model imports this module: it moved out of here to break the import cycle
__getattr__ = moved_attributes(__name__, {"warm_up": "soroshapes.precompile.warm_up"})
