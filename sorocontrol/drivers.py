r"""What the board server drives: the real I²C hardware, a mock, and a simulated pneumatic plant.

A driver has ``channels`` and one method, ``apply(setpoints, t) -> (measured, sensors, faults)``: it sends
the gauge-pressure set-points [Pa] to the regulators, advances to board time ``t`` [s] and returns the
read-back pressures [Pa] (n,), extra sensor values (k,) and a boolean fault mask (n,) of channels whose
reading failed. ``vent()`` drives every output to 0 Pa at once; ``close()`` vents and releases the hardware.
The server calls ``apply`` at its loop rate and never lets an exception of a driver pass silently: it vents
and reports it.

* :class:`I2CDriver`: the board of the Sorotoki paper: Festo VEAB proportional regulators set by MCP4725
  12-bit DACs and read back through ADS1015 ADCs, on a Raspberry Pi's I²C bus (``smbus2``).
* :class:`MockDriver`: reads back exactly what was set (protocol and safety tests).
* :class:`SimulatedPlant`: each channel is a regulated isothermal air reservoir, the
  :class:`soroshapes.Fluidic` model (PI regulator with valve saturation,
  :math:`\dot m = \mathrm{sat}(k_p e + k_i z)`, :math:`\dot z = e`, :math:`p = mRT/V - p_0`), integrated
  with RK4 sub-steps; optionally the chambers drive a :class:`soroshapes.Shapes` beam, whose tip position
  and coordinates are reported as sensors.
"""
import logging

import numpy as np

from sorofem.errors import DependencyError, ParameterError

log = logging.getLogger(__name__)

__all__ = ["Driver", "MockDriver", "SimulatedPlant", "I2CDriver"]


class Driver:
    """Base class: ``channels`` outputs, :meth:`apply` each board tick, :meth:`vent`, :meth:`close`."""

    channels = 0
    sensor_names: tuple = ()

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


class SimulatedPlant(Driver):
    r"""Regulated pneumatic channels (and optionally a beam) in real time.

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
        A beam with as many inputs (chambers, in that order) as ``channels``; it is integrated with the
        implicit midpoint rule at the board's tick, driven by the measured pressures, from its static
        equilibrium at zero pressure. Its tip position [m] (3) and coordinates q (n) are the sensors.
    substep : float [s]
        Largest RK4 step of the pneumatics (default 1 ms: the loop's poles are at -1/(2 tau), so the
        truncation error is ~(h/2tau)^4 ~ 1e-7 relative at tau = 30 ms).
    """

    def __init__(self, channels, volume=20e-6, time_constant=0.03, max_flow=2e-3, beam=None, substep=1e-3,
                 T=293.15, gas_constant=287.05, p0=101325.0):
        from soroshapes.model import Fluidic

        self.channels = _channels(channels)
        for what, v in (("volume", volume), ("time_constant", time_constant), ("max_flow", max_flow),
                        ("substep", substep)):
            if not (np.isfinite(v) and v > 0):
                raise ParameterError(f"SimulatedPlant {what} must be positive and finite, got {v!r}")
        kp = volume / (gas_constant * T * time_constant)
        self.fluidic = Fluidic(volume, p0=p0, T=T, gas_constant=gas_constant,
                               regulator=dict(kp=kp, ki=kp / (4 * time_constant), max_flow=max_flow))
        self.volume, self.substep = float(volume), float(substep)
        self.x = np.tile(self.fluidic.initial_state(volume), (self.channels, 1))
        self.t = 0.0
        self.beam = beam
        if beam is not None:
            if len(beam.inputs) != self.channels:
                raise ParameterError(f"the simulated beam has {len(beam.inputs)} inputs, the board "
                                     f"{self.channels} channels: they must match (one chamber per channel)")
            self.q = beam.statics(u=np.zeros(self.channels), steps=4)   # at rest under its own weight
            self.qd = np.zeros(beam.n)
            beam.simulate(1e-4, 1e-4, q0=self.q, u=np.zeros(self.channels))   # compile now, not in the loop
            self.sensor_names = ("tip_x", "tip_y", "tip_z") + tuple(f"q{i}" for i in range(beam.n))

    def pressures(self):
        """Gauge pressures [Pa] of the channels now."""
        return np.array([self.fluidic.pressure(x, self.volume) for x in self.x])

    def _rhs(self, x, u):
        """:meth:`soroshapes.Fluidic.rhs` of every channel at once (isothermal, regulated, constant volume):
        columns (mass [kg], regulator integral [Pa s])."""
        fl = self.fluidic
        kp, ki, mx = fl.regulator
        e = u - (x[:, 0] * (fl.R * fl.T / self.volume) - fl.p0)
        nu = kp * e + ki * x[:, 1]
        mdot = np.clip(nu, -mx, mx)
        return np.column_stack([mdot, e + (mdot - nu) / kp])

    def apply(self, setpoints, t):
        u = np.asarray(setpoints, float)
        if t is None:               # vent: the regulators open to atmosphere
            self.x = np.tile(self.fluidic.initial_state(self.volume), (self.channels, 1))
            return self.pressures(), self._sensors(), np.zeros(self.channels, bool)
        dt_total = max(float(t) - self.t, 0.0)
        steps = int(np.ceil(dt_total / self.substep - 1e-12))
        if steps:
            h = dt_total / steps
            x = self.x
            for _ in range(steps):   # classical RK4 on the reservoirs' (mass, integral) states
                k1 = self._rhs(x, u)
                k2 = self._rhs(x + 0.5 * h * k1, u)
                k3 = self._rhs(x + 0.5 * h * k2, u)
                k4 = self._rhs(x + h * k3, u)
                x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            self.x = x
            if self.beam is not None:
                traj = self.beam.simulate(dt_total, min(dt_total, 5e-3), q0=self.q, qd0=self.qd,
                                          u=self.pressures())
                self.q, self.qd = traj.q[-1].copy(), traj.qd[-1].copy()
            self.t = float(t)
        return self.pressures(), self._sensors(), np.zeros(self.channels, bool)

    def _sensors(self):
        if self.beam is None:
            return np.zeros(0)
        return np.concatenate([self.beam.positions(self.q)[-1], self.q])


class I2CDriver(Driver):
    """Festo VEAB regulators through MCP4725 DACs, read back through ADS1015 ADCs (Sorotoki's board).

    Parameters
    ----------
    dacs : sequence of (bus address) ints
        One MCP4725 per channel (default 0x60, 0x61 on bus 1 and the same on bus 0 for 4 channels; a board
        with a TCA9548A multiplexer passes ``select`` to switch to each channel's branch).
    adcs : sequence of (address, input) pairs
        The ADS1015 and its single-ended input (0-3) reading each channel.
    p_range : (float, float) [Pa]
        Regulator range (VEAB: -100 kPa ... 100 kPa): the DAC's normalized value is
        :math:`(p - p_{min})/(p_{max} - p_{min})`, so 0.5 is 0 kPa.
    adc_gain : float [Pa/V], adc_offset : float [V]
        Read-back calibration :math:`p = (V - V_0) G`; Sorotoki's wiring (x3 divider, 0-10 V sensor output)
        gives :math:`V_0 = 5` V after undoing the divider and :math:`G = 20` kPa/V.
    divider : float
        Voltage divider ratio in front of the ADC.
    bus : int
        I²C bus number (``/dev/i2c-1`` on a Raspberry Pi).
    select : callable(channel), optional
        Called before talking to a channel's devices (multiplexer switching).
    """

    ADS1015_CONFIG = 0x01
    ADS1015_CONVERSION = 0x00

    def __init__(self, dacs, adcs, p_range=(-100e3, 100e3), adc_gain=20e3, adc_offset=5.0, divider=3.0,
                 bus=1, select=None):
        try:
            import smbus2
        except ImportError as e:
            raise DependencyError("the I2C driver needs smbus2 on the board: `pip install smbus2` (or "
                                  "`pip install soro[board]`); use MockDriver/SimulatedPlant elsewhere") from e
        if len(dacs) != len(adcs):
            raise ParameterError(f"{len(dacs)} DACs and {len(adcs)} ADC inputs: one of each per channel")
        self.channels = _channels(len(dacs))
        self.dacs, self.adcs = [int(a) for a in dacs], [(int(a), int(i)) for a, i in adcs]
        self.p_min, self.p_max = map(float, p_range)
        if not self.p_min < self.p_max:
            raise ParameterError(f"p_range must be increasing, got {p_range}")
        self.gain, self.offset, self.divider = float(adc_gain), float(adc_offset), float(divider)
        self.select = select
        self.bus = smbus2.SMBus(bus)
        self.last = np.zeros(self.channels)

    def _write_dac(self, address, value):
        code = int(round(min(max(value, 0.0), 1.0) * 4095))
        # MCP4725 fast write: two bytes, upper 4 bits of the code (power-down bits 00) then the lower 8
        self.bus.write_byte_data(address, (code >> 8) & 0x0F, code & 0xFF)

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
        return raw * 6.144 / 2048 * self.divider   # volts at the sensor

    def apply(self, setpoints, t):
        faults = np.zeros(self.channels, bool)
        for ch in range(self.channels):
            if self.select is not None:
                self.select(ch)
            self._write_dac(self.dacs[ch], (setpoints[ch] - self.p_min) / (self.p_max - self.p_min))
            try:
                self.last[ch] = (self._read_adc(*self.adcs[ch]) - self.offset) * self.gain
            except OSError as e:
                faults[ch] = True
                log.warning("channel %d: ADC read failed (%s); keeping the last reading", ch, e)
        return self.last.copy(), np.zeros(0), faults

    def close(self):
        try:
            self.vent()
        finally:
            self.bus.close()
