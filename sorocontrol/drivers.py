r"""What the board server drives: the real I²C hardware, a mock, and a simulated pneumatic plant.

A driver has ``channels`` and one method, ``apply(setpoints, t) -> (measured, sensors, faults)``: it sends
the gauge-pressure set-points [Pa] to the regulators, advances to board time ``t`` [s] and returns the
read-back pressures [Pa] (n,), extra sensor values (k,) and a boolean fault mask (n,) of channels whose
reading failed. ``vent()`` drives every output to 0 Pa at once; ``close()`` vents and releases the hardware.
The server calls ``apply`` at its loop rate and never lets an exception of a driver pass silently: it vents
and reports it.

* :class:`I2CDriver`: the board of the Sorotoki paper: Festo VEAB proportional regulators set by MCP4725
  12-bit DACs and read back through ADS1015 ADCs, on a Raspberry Pi's I²C bus (``smbus2``). Its wiring and
  the calibration of each regulator come from a :class:`BoardProfile` file (``hardware/README.md``), never
  from the safety limits: vent writes the DAC code of 0 kPa gauge of that calibration.
* :class:`MockDriver`: reads back exactly what was set (protocol and safety tests).
* :class:`SimulatedPlant`: each channel is a regulated isothermal air reservoir, a
  :class:`soroshapes.Fluidic` (PI regulator with valve saturation,
  :math:`\dot m = \mathrm{sat}(k_p e + k_i z)`, :math:`\dot z = e`, :math:`p = mRT/V - p_0`) of one
  :class:`soroshapes.Model`, continued by ``Model.simulate`` over each board tick (compiled); optionally the
  chambers drive a :class:`soroshapes.Shapes` beam in the same model, whose tip position and coordinates are
  reported as sensors, or a network plant (a :class:`soroshapes.Model`: an arm, a grasped object on a table,
  ...) built in the plant's process from a :class:`NetworkRecipe`.
"""
import logging
import math
from dataclasses import dataclass

import numpy as np

from sorofem.errors import DependencyError, ParameterError

log = logging.getLogger(__name__)

__all__ = ["Driver", "MockDriver", "SimulatedPlant", "NetworkRecipe", "I2CDriver", "ChannelCalibration",
           "BoardProfile"]


class Driver:
    """Base class: ``channels`` outputs, :meth:`apply` each board tick, :meth:`vent`, :meth:`close`.

    ``p_range`` is the pair of per-channel arrays (lowest, highest) [Pa] of the pressures the outputs can be
    set to (a regulator's calibrated signal range; unbounded for the mock and the simulated plant); the
    server refuses limits outside it. ``safety_limits`` is the pair of per-channel arrays (p_min, p_max) [Pa]
    that the hardware itself requires (the board profile's limits), or None; the server never lets a channel
    go beyond them, whatever limits it is given.
    """

    channels = 0
    sensor_names: tuple = ()

    @property
    def p_range(self):
        return np.full(self.channels, -np.inf), np.full(self.channels, np.inf)

    @property
    def safety_limits(self):
        return None

    def apply(self, setpoints, t):
        raise NotImplementedError

    def vent(self):
        self.apply(np.zeros(self.channels), None)

    def close(self):
        self.vent()


class MockDriver(Driver):
    """Reads back exactly the set-points; keeps the last ``history`` writes as ``(t, setpoints)``."""

    def __init__(self, channels, history=1000):
        self.channels = _channels(channels)
        self.value = np.zeros(self.channels)
        self.writes = []
        self._history = int(history)

    def apply(self, setpoints, t):
        self.value = np.array(setpoints, float)
        self.writes.append((t, self.value.copy()))
        del self.writes[:-self._history]
        return self.value.copy(), np.zeros(0), np.zeros(self.channels, bool)


def _channels(n):
    n = int(n)
    if not 1 <= n <= 64:
        raise ParameterError(f"channels must be between 1 and 64, got {n}")
    return n


@dataclass(frozen=True)
class NetworkRecipe:
    """Where a network plant is built: the function ``function`` of the Python file ``path``, called as
    ``function(pressures, **kwargs)`` in the plant's process, returns a :class:`soroshapes.Model` whose free
    inputs (:attr:`Model.inputs <soroshapes.model.Model.inputs>`, as many as the board's channels, in channel
    order) the plant sets to the channel pressures; ``pressures()`` returns them [Pa] (n,) (held over each
    board tick), for couplings that depend on a channel (a gripper's engagement). A recipe rather than the
    Model itself: a Model with couplings holds closures, which do not pickle to the board's process
    (:meth:`sorocontrol.Board.simulated`)."""
    path: str
    function: str
    kwargs: tuple = ()

    def build(self, pressures):
        import runpy

        try:
            ns = runpy.run_path(str(self.path))
        except FileNotFoundError:
            raise ParameterError(f"NetworkRecipe: no file {self.path}") from None
        fn = ns.get(self.function)
        if not callable(fn):
            raise ParameterError(f"NetworkRecipe: {self.path} has no function {self.function!r}")
        return fn(pressures, **dict(self.kwargs))


class SimulatedPlant(Driver):
    r"""Regulated pneumatic channels (and optionally a beam or a network plant) in real time, as a
    :class:`soroshapes.Model` continued over each board tick.

    Each channel is a :class:`soroshapes.Fluidic` reservoir of the plant's :attr:`model` (systems
    ``channel0``, ``channel1``, ...); with ``beam`` the model also holds the beam (system ``beam``), each
    channel's gauge pressure coupled to the beam's input of the same index. The model runs in a
    :class:`soroshapes.model.Stepper` (:attr:`stepper`, made once: the lowered network, the factored Newton
    matrix and the integrator's memory are kept between ticks). Each call of :meth:`apply` holds the
    set-points over the elapsed board time (``stepper.hold``: a constant :class:`soroshapes.network.Schedule`
    written in place) and advances the stepper by it (trapezoidal steps of at most ``substep``, compiled:
    :attr:`Model.evaluation_path <soroshapes.model.Model.evaluation_path>` is ``"compiled"`` unless the beam
    has a load without a compiled form, which then runs on the Model's slower Python path and says so in the
    log).

    Parameters
    ----------
    channels : int
    volume : float [m^3]
        Volume of each channel's chamber and tubing (default 20 ml).
    time_constant : float [s]
        Time scale :math:`\tau` of the regulator loop: :math:`k_p = V/(R T \tau)`, :math:`k_i = k_p/(4\tau)`.
        Unsaturated, the gauge pressure obeys :math:`\dot p = e/\tau + \int e\,dt/(4\tau^2)`,
        :math:`e = p_{ref} - p`: a double pole at :math:`-a`, :math:`a = 1/(2\tau)`, and a step of the
        reference gives :math:`p/p_{ref} = 1 - e^{-at}(1 - at)` (70 % at :math:`\tau`, overshoot
        :math:`e^{-2}` = 13.5 % at :math:`4\tau`, no steady-state error). Default 30 ms.
    max_flow : float [kg/s]
        Valve saturation; large steps rise at :math:`RT\dot m_{max}/V` [Pa/s] (default 2e-3 kg/s: 8.4 MPa/s
        into 20 ml, a step of 100 kPa in ~12 ms plus the loop's settling).
    beam : soroshapes.Shapes, optional
        A beam with as many inputs (chambers, in that order) as ``channels``, driven by the channels'
        pressures inside the plant's model from its static equilibrium at zero pressure. Its tip position
        [m] (3) and coordinates q (n) are the sensors.
    network : NetworkRecipe or callable, optional
        Instead of ``beam``: a network plant, ``network(pressures)`` (a :class:`NetworkRecipe` or a function
        of the same signature) returning a :class:`soroshapes.Model` whose free inputs are the channels (see
        :class:`NetworkRecipe`). Each call of :meth:`apply` continues it over the elapsed board time with its
        own integrator (``Model.simulate(..., x0=, t0=)``, trapezoidal steps of at most ``network_dt``), the
        channel pressures held at their values at the end of the tick (the reservoirs' model runs first). It
        runs on the Model's Python path when any coupling is a Python function (slower than real time for an
        arm and a grasped body: then ``max_advance`` caps each call and the plant lags the board's clock).
        Sensors: for each beam of the model (in the model's order) its tip position [m] (3), then for each
        rigid body its position [m] (3), last the plant's own time [s] (it lags the board's clock when
        ``max_advance`` caps a call: a host that sequences by the plant's time gets the same motion on a
        loaded machine).
    network_dt : float [s]
        Largest integration step of the network plant (default 2 ms).
    substep : float [s]
        Largest step of the plant's model (trapezoidal, second order; default 1 ms: the regulator loop's
        poles are at :math:`-a = -1/(2\tau)`, and the trapezoidal rule's relative error on them is
        :math:`\approx (ah)^2/12` per unit of :math:`at`, 2e-5 at h = 1 ms, tau = 30 ms).
    max_advance : float [s]
        Most plant time one :meth:`apply` simulates (default 25 ms, ten ticks of a 400 Hz board). When more
        board time has passed since the last call (the host was busy), the plant simulates this much and
        skips the rest, so a slow call never makes the next one longer (without the cap, a beam that
        simulates slower than real time makes each call longer than the last, and the board loop, which
        holds the interpreter during the compiled beam step, stalls for seconds). The plant time then lags
        the board time: :attr:`skipped` [s] in total over :attr:`late` calls, and a warning in the log at
        most once a second.

    A step that does not converge raises :class:`~sorofem.errors.ConvergenceError` out of :meth:`apply`: the
    board server vents every channel and reports the driver error (as for any driver failure) and refuses
    commands until the next login; the plant keeps its state and time from before the failed tick and does
    not simulate that tick's time again. The models are built and their kernels compiled (or loaded from the
    cache) in the constructor, not in the board loop.

    Attributes
    ----------
    model : soroshapes.Model
        The reservoirs (and the beam).
    stepper : soroshapes.model.Stepper
        The model's run, continued tick after tick.
    x : ndarray
        The state of :attr:`model` now, a copy (the channels' (mass [kg], regulator integral [Pa s]) in order,
        then the beam's (q, qd)).
    plant_time : float [s]
        Time of :attr:`model` (behind the board's time by :attr:`skipped`).
    t : float [s]
        Board time of the last call.
    skipped : float [s]
        Board time not simulated (the sum of what the calls past ``max_advance`` left out).
    late : int
        Calls that had more than ``max_advance`` to simulate.
    """

    def __init__(self, channels, volume=20e-6, time_constant=0.03, max_flow=2e-3, beam=None, substep=1e-3,
                 max_advance=0.025, T=293.15, gas_constant=287.05, p0=101325.0, network=None, network_dt=2e-3):
        from soroshapes.model import Fluidic, Model

        self.channels = _channels(channels)
        for what, v in (("volume", volume), ("time_constant", time_constant), ("max_flow", max_flow),
                        ("substep", substep), ("max_advance", max_advance)):
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(f"SimulatedPlant {what} must be positive and finite, got {v!r}")
        if beam is not None and network is not None:
            raise ParameterError("SimulatedPlant takes a beam or a network plant, not both (put the beam into the "
                                 "network's Model)")
        kp = volume / (gas_constant * T * time_constant)
        self.fluidic = Fluidic(volume, p0=p0, T=T, gas_constant=gas_constant,
                               regulator=dict(kp=kp, ki=kp / (4 * time_constant), max_flow=max_flow))
        self.volume, self.substep, self.max_advance = float(volume), float(substep), float(max_advance)
        self.t = 0.0
        self.skipped, self.late = 0.0, 0
        self._warned_at = -math.inf
        self.model = Model()
        for i in range(self.channels):
            self.model.add(self.fluidic, name=f"channel{i}")
        nf = self.fluidic.n
        self._mass = np.arange(self.channels) * nf + self.fluidic.states.index("mass")   # rows of the masses
        self._reservoirs = slice(0, self.channels * nf)
        self.beam = beam
        if beam is not None:
            if len(beam.inputs) != self.channels:
                raise ParameterError(f"the simulated beam has {len(beam.inputs)} inputs, the board "
                                     f"{self.channels} channels: they must match (one chamber per channel)")
            q = beam.statics(u=np.zeros(self.channels), steps=4)     # at rest under its own weight
            self.model.add(beam, name="beam", x0=np.concatenate([q, np.zeros(beam.n)]))
            for i in range(self.channels):
                self.model.connect(f"channel{i}", "beam", index=i)
            self._q = slice(self.channels * nf, self.channels * nf + beam.n)
            self._qd = slice(self._q.stop, self._q.stop + beam.n)
            self.sensor_names = ("tip_x", "tip_y", "tip_z") + tuple(f"q{i}" for i in range(beam.n))
        x0 = self.model.initial_state()
        self._vented = x0[self._reservoirs].copy()          # every channel at 0 Pa gauge, integrators empty
        self.stepper = self.model.stepper(self.substep, x0=x0).hold(np.zeros(self.channels))
        if self.stepper.path != "compiled":
            log.info("simulated plant: its model runs on the Python path (%s), slower than the compiled one",
                     self.stepper.path)
        self.stepper.advance(steps=1)                       # compile now (or load the kernels), not in the loop
        self.stepper.set_state(x0, 0.0)
        self.network = None
        if network is not None:
            self._init_network(network, float(network_dt))

    @property
    def x(self):
        """The state of :attr:`model` now (a copy)."""
        return self.stepper.x

    @property
    def plant_time(self):
        """Time [s] of :attr:`model` (behind the board's time by :attr:`skipped`)."""
        return self.stepper.t

    def _init_network(self, network, dt):
        from soroshapes.model import Model
        from soroshapes.rigid import RigidBody
        from soroshapes.shapes import Shapes

        if not (np.isfinite(dt) and dt > 0):
            raise ParameterError(f"SimulatedPlant network_dt must be positive and finite [s], got {dt!r}")
        build = network.build if isinstance(network, NetworkRecipe) else network
        if not callable(build):
            raise ParameterError("SimulatedPlant network must be a NetworkRecipe or a function(pressures) -> Model")
        self._u = np.zeros(self.channels)
        model = build(lambda: self._u)
        if not isinstance(model, Model):
            raise ParameterError(f"the network recipe returned a {type(model).__name__}, not a soroshapes.Model")
        model.set_controller(lambda m: self._u, reads=())
        if len(model.inputs) != self.channels:
            raise ParameterError(f"the network plant has {len(model.inputs)} free inputs ({model.inputs}), the "
                                 f"board {self.channels} channels: they must match (one input per channel)")
        self.network, self.network_dt = model, dt
        self._beams = [s for s in model.systems if isinstance(model[s].system, Shapes)]
        self._bodies = [s for s in model.systems if isinstance(model[s].system, RigidBody)]
        self.xn = model.initial_state()
        self.tn = 0.0
        names = []
        for s in self._beams:
            names += [f"{s}_tip_{c}" for c in "xyz"]
        for s in self._bodies:
            names += [f"{s}_{c}" for c in "xyz"]
        self.sensor_names = tuple(names) + ("plant_time",)
        self._step_network(1e-4)           # compile/validate now, not in the board loop

    def pressures(self):
        """Gauge pressures [Pa] of the channels now."""
        fl = self.fluidic                   # isothermal: p = m R T / V (Fluidic.pressure, every channel at once)
        return self.stepper.x[self._mass] * (fl.R * fl.T / self.volume) - fl.p0

    @property
    def q(self):
        """The beam's coordinates now (None without a beam)."""
        return None if self.beam is None else self.x[self._q].copy()

    @property
    def qd(self):
        """The beam's coordinate rates now (None without a beam)."""
        return None if self.beam is None else self.x[self._qd].copy()

    def apply(self, setpoints, t):
        u = np.asarray(setpoints, float)
        if t is None:               # vent: the regulators open to atmosphere
            x = self.stepper.x
            x[self._reservoirs] = self._vented
            self.stepper.set_state(x)
            return self.pressures(), self._sensors(), np.zeros(self.channels, bool)
        dt_total = self._advance(float(t))
        self.t = float(t)           # a step that fails is not retried: the board vents on the error
        if dt_total > 0.0:
            self.stepper.hold(u)
            self.stepper.advance(self.stepper.t + dt_total)
            if self.network is not None:
                self._u = self.pressures()
                self._step_network(dt_total)
        return self.pressures(), self._sensors(), np.zeros(self.channels, bool)

    def _advance(self, t):
        """Plant time [s] to simulate to reach board time ``t``: the elapsed time, capped at ``max_advance``
        (the rest is skipped, counted and, at most once a second, logged)."""
        elapsed = max(t - self.t, 0.0)
        if elapsed <= self.max_advance:
            return elapsed
        self.skipped += elapsed - self.max_advance
        self.late += 1
        if t - self._warned_at >= 1.0:
            self._warned_at = t
            log.warning("simulated plant: %.0f ms of board time passed since its last step (more than "
                        "max_advance = %.0f ms): it simulated %.0f ms and skipped the rest (%.3f s skipped in "
                        "%d late steps so far); the host is too busy for this plant at this board rate",
                        1e3 * elapsed, 1e3 * self.max_advance, 1e3 * self.max_advance, self.skipped, self.late)
        return self.max_advance

    def _step_network(self, dt_total):
        """Continue the network plant over ``dt_total`` [s] from its state (ConvergenceError propagates)."""
        traj = self.network.simulate(dt_total, min(dt_total, self.network_dt), x0=self.xn, t0=self.tn)
        self.xn, self.tn = traj.x[-1].copy(), float(traj.t[-1])

    def network_sensors(self, x=None):
        """The network plant's sensors at its state ``x`` (default now): beam tips, then body positions [m],
        last the plant's time [s]."""
        m, x = self.network, self.xn if x is None else x
        m.set_state(self.tn, x)
        out = []
        for s in self._beams:
            shp = m[s].system
            out.append(shp.positions(np.asarray(m.state(s))[:shp.n])[-1])
        for s in self._bodies:
            out.append(np.asarray(m.state(s))[:3])
        out.append(np.array([self.tn]))
        return np.concatenate(out)

    def _sensors(self):
        if self.network is not None:
            return self.network_sensors()
        if self.beam is None:
            return np.zeros(0)
        q = self.stepper.x[self._q]
        return np.concatenate([self.beam.positions(q)[-1], q])


DAC_FULL_SCALE = 4095      # MCP4725: 12-bit codes


@dataclass(frozen=True)
class ChannelCalibration:
    r"""The wiring and calibration of one regulator channel.

    Attributes
    ----------
    dac : int
        I²C address of the channel's MCP4725 DAC.
    adc : (int, int)
        I²C address of the ADS1015 and its single-ended input (0-3) that reads the regulator's sensor output.
    signal_range : (float, float) [Pa]
        Gauge pressure the regulator delivers at DAC code 0 and at full scale (4095): a VEAB with a 0-10 V
        set-point input behind the board's amplifier spans (-100 kPa, 100 kPa). A property of the regulator
        and its wiring, *not* a safety limit.
    sensor_gain : float [Pa/V], sensor_offset : float [V]
        Read-back :math:`p = (V - V_0) G` of the regulator's pressure output (VEAB: 20 kPa/V, 5 V at 0 kPa).
    divider : float
        Voltage divider ratio in front of the ADC (Sorotoki's board: 3).
    name : str
    """
    dac: int
    adc: tuple
    signal_range: tuple = (-100e3, 100e3)
    sensor_gain: float = 20e3
    sensor_offset: float = 5.0
    divider: float = 3.0
    name: str = ""

    def __post_init__(self):
        lo, hi = (float(v) for v in self.signal_range)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= 0.0 <= hi and lo < hi):
            raise ParameterError(f"channel {self.name or hex(self.dac)}: signal_range {self.signal_range} must be "
                                 "finite, increasing and contain 0 Pa (the vent pressure must be writable)")
        if not (self.sensor_gain != 0 and math.isfinite(self.sensor_gain) and self.divider > 0):
            raise ParameterError(f"channel {self.name or hex(self.dac)}: sensor_gain must be finite and non-zero, "
                                 "divider positive")

    def code(self, p):
        r"""The DAC code for gauge pressure ``p`` [Pa]: :math:`x = 4095 (p - p_0)/(p_1 - p_0)` rounded toward
        0 kPa (down for :math:`p > 0`, up for :math:`p < 0`, to the nearest code for :math:`p = 0`), so a
        written code never asks for more pressure or vacuum than ``p``; clipped to 0..4095."""
        lo, hi = self.signal_range
        x = DAC_FULL_SCALE * (float(p) - lo) / (hi - lo)
        c = math.floor(x) if p > 0 else math.ceil(x) if p < 0 else round(x)
        return int(min(max(c, 0), DAC_FULL_SCALE))

    def pressure(self, code):
        """Gauge pressure [Pa] the regulator delivers at DAC ``code``."""
        lo, hi = self.signal_range
        return lo + (hi - lo) * code / DAC_FULL_SCALE

    @property
    def vent_code(self):
        """The DAC code of 0 kPa gauge."""
        return self.code(0.0)


def _check_limits(where, lo, hi, signal_range):
    """Refuse per-channel safety limits ``lo``/``hi`` [Pa] (the profile's ``p_min``/``p_max``) that are not
    finite, do not contain 0 Pa or leave the calibrated ``signal_range``; the message names the key."""
    s_lo, s_hi = signal_range
    for key, v in (("p_min", lo), ("p_max", hi)):
        if not math.isfinite(v):
            raise ParameterError(f"{where}: {key} = {v!r} must be a finite gauge pressure [Pa]")
    if lo > 0.0:
        raise ParameterError(f"{where}: p_min = {lo:g} Pa must be <= 0 Pa (0 Pa, the vent pressure, must be "
                             "allowed)")
    if hi < 0.0:
        raise ParameterError(f"{where}: p_max = {hi:g} Pa must be >= 0 Pa (0 Pa, the vent pressure, must be "
                             "allowed)")
    if lo < s_lo:
        raise ParameterError(f"{where}: p_min = {lo:g} Pa is below the calibrated signal_range [{s_lo:g}, "
                             f"{s_hi:g}] Pa: the regulator cannot deliver it; raise p_min or fix the calibration")
    if hi > s_hi:
        raise ParameterError(f"{where}: p_max = {hi:g} Pa is above the calibrated signal_range [{s_lo:g}, "
                             f"{s_hi:g}] Pa: the regulator cannot deliver it; lower p_max or fix the calibration")


@dataclass(frozen=True)
class BoardProfile:
    """A board's wiring and calibration: one :class:`ChannelCalibration` per channel and the I²C ``bus``, and
    optionally the safety limits of every channel.

    Read from a TOML file with :meth:`load` (format in ``hardware/README.md``, example
    ``hardware/profiles/veab-2ch.toml``).

    Attributes
    ----------
    channels : tuple of ChannelCalibration
    bus : int
    name : str
    limits : tuple of (float, float) [Pa], or None
        Per channel, the safety limits ``(p_min, p_max)`` (gauge; the ``p_min``/``p_max`` keys of its
        ``[[channels]]`` table): inside the channel's ``signal_range``, containing 0 Pa; given for every
        channel or for none. A :class:`BoardServer` driving this board never lets a channel beyond them.
    """
    channels: tuple
    bus: int = 1
    name: str = ""
    limits: tuple = None

    FORMAT = "soro-board-profile"
    VERSION = 1
    _TOP_KEYS = {"format", "version", "name", "i2c_bus", "channels"}
    _KEYS = {"dac", "adc", "signal_range", "sensor_gain", "sensor_offset", "divider", "name", "p_min", "p_max"}

    def __post_init__(self):
        if self.limits is None:
            return
        limits = tuple((float(lo), float(hi)) for lo, hi in self.limits)
        if len(limits) != len(self.channels):
            raise ParameterError(f"board profile {self.name!r}: {len(limits)} pairs of safety limits for "
                                 f"{len(self.channels)} channels: give p_min/p_max for every channel or none")
        for i, ((lo, hi), cal) in enumerate(zip(limits, self.channels)):
            _check_limits(f"board profile {self.name!r}: channel {i} ({cal.name or hex(cal.dac)})", lo, hi,
                          cal.signal_range)
        object.__setattr__(self, "limits", limits)

    @property
    def p_min(self):
        """Per-channel lower safety limits [Pa] (array), or None without limits."""
        return None if self.limits is None else np.array([lo for lo, _ in self.limits])

    @property
    def p_max(self):
        """Per-channel upper safety limits [Pa] (array), or None without limits."""
        return None if self.limits is None else np.array([hi for _, hi in self.limits])

    @classmethod
    def load(cls, path):
        """Read the profile file ``path``; ParameterError naming the file and the key at fault."""
        import tomllib

        try:
            with open(path, "rb") as f:
                doc = tomllib.load(f)
        except FileNotFoundError:
            raise ParameterError(f"board profile {path} does not exist (example: hardware/profiles/veab-2ch.toml)") \
                from None
        except tomllib.TOMLDecodeError as e:
            raise ParameterError(f"board profile {path} is not valid TOML: {e}") from None
        return cls.from_dict(doc, source=str(path))

    @classmethod
    def from_dict(cls, doc, source="board profile"):
        """The profile of a parsed TOML document ``doc`` (dict)."""
        if doc.get("format") != cls.FORMAT or doc.get("version") != cls.VERSION:
            raise ParameterError(f"{source}: expected format = \"{cls.FORMAT}\" and version = {cls.VERSION} at the top")
        unknown = sorted(set(doc) - cls._TOP_KEYS)
        if unknown:
            hint = (" (safety limits go into each [[channels]] table as p_min/p_max [Pa])"
                    if any("limit" in k for k in unknown) else "")
            raise ParameterError(f"{source}: unknown top-level keys {unknown}{hint} (known: {sorted(cls._TOP_KEYS)})")
        chans = doc.get("channels")
        if not isinstance(chans, list) or not chans:
            raise ParameterError(f"{source}: no [[channels]] tables (one per regulator channel)")
        out, limits = [], []
        for i, ch in enumerate(chans):
            if not isinstance(ch, dict):
                raise ParameterError(f"{source}: channels must be [[channels]] tables")
            unknown = set(ch) - cls._KEYS
            missing = {"dac", "adc", "signal_range"} - set(ch)
            if unknown or missing:
                raise ParameterError(f"{source}: channel {i}: unknown keys {sorted(unknown)}, missing keys "
                                     f"{sorted(missing)} (known: {sorted(cls._KEYS)})")
            try:
                adc = (int(ch["adc"][0]), int(ch["adc"][1]))
                sr = (float(ch["signal_range"][0]), float(ch["signal_range"][1]))
            except (TypeError, IndexError, ValueError):
                raise ParameterError(f"{source}: channel {i}: adc = [address, input] and signal_range = "
                                     "[p_at_code_0, p_at_full_scale] (Pa)") from None
            if len(ch["adc"]) != 2 or len(ch["signal_range"]) != 2 or not 0 <= adc[1] <= 3:
                raise ParameterError(f"{source}: channel {i}: adc = [address, input 0-3], signal_range = [lo, hi]")
            kw = {k: float(ch[k]) for k in ("sensor_gain", "sensor_offset", "divider") if k in ch}
            out.append(ChannelCalibration(int(ch["dac"]), adc, sr, name=str(ch.get("name", f"channel {i}")), **kw))
            limits.append(cls._channel_limits(ch, f"{source}: channel {i} ({out[-1].name})", sr))
        _channels(len(out))
        given = [i for i, lim in enumerate(limits) if lim is not None]
        if given and len(given) != len(limits):
            bare = [i for i, lim in enumerate(limits) if lim is None]
            raise ParameterError(f"{source}: channels {given} have safety limits (p_min/p_max) and channels {bare} "
                                 "do not: give p_min and p_max in every [[channels]] table, or in none")
        return cls(tuple(out), bus=int(doc.get("i2c_bus", 1)), name=str(doc.get("name", source)),
                   limits=tuple(limits) if given else None)

    @staticmethod
    def _channel_limits(ch, where, signal_range):
        """``(p_min, p_max)`` [Pa] of the channel table ``ch``, None without; refused with the key named."""
        present = [k for k in ("p_min", "p_max") if k in ch]
        if not present:
            return None
        if len(present) == 1:
            other = "p_max" if present[0] == "p_min" else "p_min"
            raise ParameterError(f"{where}: {present[0]} given without {other}: a channel's safety limits are the "
                                 "pair p_min <= 0 <= p_max [Pa]")
        vals = []
        for key in ("p_min", "p_max"):
            v = ch[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ParameterError(f"{where}: {key} = {v!r} must be a number, a gauge pressure in Pa")
            vals.append(float(v))
        _check_limits(where, vals[0], vals[1], signal_range)
        return tuple(vals)


class I2CDriver(Driver):
    """Festo VEAB regulators through MCP4725 DACs, read back through ADS1015 ADCs (Sorotoki's board).

    Parameters
    ----------
    profile : BoardProfile or path
        The wiring, calibration and optional per-channel safety limits (:class:`BoardProfile`, or the path of
        its TOML file); the limits are :attr:`safety_limits`, which a :class:`BoardServer` always enforces.
    select : callable(channel), optional
        Called before talking to a channel's devices (multiplexer switching, e.g. a TCA9548A).
    """

    ADS1015_CONFIG = 0x01
    ADS1015_CONVERSION = 0x00
    MCP4725_WRITE_DAC_AND_EEPROM = 0x60

    def __init__(self, profile, select=None):
        if not isinstance(profile, BoardProfile):
            profile = BoardProfile.load(profile)
        try:
            import smbus2
        except ImportError as e:
            raise DependencyError("the I2C driver needs smbus2 on the board: `pip install smbus2` (or "
                                  "`pip install soro[board]`); use MockDriver/SimulatedPlant elsewhere") from e
        self.profile = profile
        self.calibration = profile.channels
        self.channels = _channels(len(profile.channels))
        self.select = select
        self.bus = smbus2.SMBus(profile.bus)
        self.last = np.zeros(self.channels)

    @property
    def p_range(self):
        return (np.array([c.signal_range[0] for c in self.calibration], float),
                np.array([c.signal_range[1] for c in self.calibration], float))

    @property
    def safety_limits(self):
        """The profile's per-channel (p_min, p_max) arrays [Pa], or None when it sets none."""
        return None if self.profile.limits is None else (self.profile.p_min, self.profile.p_max)

    def _write_dac(self, ch, code):
        # MCP4725 fast write: two bytes, upper 4 bits of the code (power-down bits 00) then the lower 8
        self.bus.write_byte_data(self.calibration[ch].dac, (code >> 8) & 0x0F, code & 0xFF)

    def _read_adc(self, address, channel):
        # single-shot, single-ended input `channel`, +-6.144 V range, 1600 SPS
        config = 0x8000 | ((0x4 + channel) << 12) | (0x0 << 9) | 0x0100 | (0x4 << 5) | 0x0003
        self.bus.write_i2c_block_data(address, self.ADS1015_CONFIG, [config >> 8, config & 0xFF])
        for _ in range(20):
            hi, lo = self.bus.read_i2c_block_data(address, self.ADS1015_CONFIG, 2)
            if hi & 0x80:
                break
        hi, lo = self.bus.read_i2c_block_data(address, self.ADS1015_CONVERSION, 2)
        raw = ((hi << 8) | lo) >> 4
        if raw & 0x800:
            raw -= 1 << 12
        return raw * 6.144 / 2048      # volts at the ADC input

    def apply(self, setpoints, t):
        faults = np.zeros(self.channels, bool)
        for ch, cal in enumerate(self.calibration):
            if self.select is not None:
                self.select(ch)
            self._write_dac(ch, cal.code(setpoints[ch]))
            try:
                volts = self._read_adc(*cal.adc) * cal.divider
                self.last[ch] = (volts - cal.sensor_offset) * cal.sensor_gain
            except OSError as e:
                faults[ch] = True
                log.warning("channel %d: ADC read failed (%s); keeping the last reading", ch, e)
        return self.last.copy(), np.zeros(0), faults

    def vent(self):
        """Write every channel's 0 kPa code (no read-back: the fastest path, used by the vent command)."""
        errors = []
        for ch, cal in enumerate(self.calibration):
            try:
                if self.select is not None:
                    self.select(ch)
                self._write_dac(ch, cal.vent_code)
            except OSError as e:         # go on with the other channels, then say which failed
                errors.append(f"channel {ch} (DAC {cal.dac:#x}): {e}")
        if errors:
            raise OSError("vent failed on " + "; ".join(errors))

    def store_power_on_vent(self):
        """Write each channel's 0 kPa code into its MCP4725's EEPROM, which the DAC outputs at power-up (so a
        board that boots, or a Pi that resets, starts vented). Once at installation: the EEPROM wears."""
        for ch, cal in enumerate(self.calibration):
            if self.select is not None:
                self.select(ch)
            c = cal.vent_code
            self.bus.write_i2c_block_data(cal.dac, self.MCP4725_WRITE_DAC_AND_EEPROM, [c >> 4, (c & 0x0F) << 4])

    def close(self):
        try:
            self.vent()
        finally:
            self.bus.close()
