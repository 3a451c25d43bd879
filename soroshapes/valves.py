r"""Valve flow functions :math:`\dot m = \Psi_v(\nu, p)` of a :class:`~soroshapes.model.Fluidic` reservoir.

The seed (Sorotoki paper, eq. (28)) feeds a reservoir through a valve flow function of the flow command
:math:`\nu` [kg/s] (the input, or the PI regulator's output) and the reservoir's absolute pressure :math:`p`
[Pa]. Three are provided (``Fluidic(valve=...)``):

* the default, saturation: :math:`\dot m = \mathrm{clip}(\nu, \pm\dot m_{max})` (regulated; unregulated
  :math:`\dot m = \nu`), the seed's :math:`\Psi_v = \nu` with the valve's flow limit;
* :class:`Orifice`, an ISO 6358-like pneumatic valve: sonic conductance :math:`C` [m^3/(s Pa)], critical
  pressure ratio :math:`b`, a supply port at :math:`p_s` and an exhaust port at :math:`p_e`. The command opens
  the supply port (:math:`\nu > 0`) or the exhaust port (:math:`\nu < 0`) by the fraction
  :math:`s = \mathrm{clip}(\nu/\dot m_{full}, -1, 1)`, :math:`\dot m_{full} = C\rho_0 p_s\sqrt{T_0/T}` (the
  choked flow of the open supply port), and the flow through a port from :math:`p_1` to :math:`p_2 \le p_1` is

  .. math:: Q(p_1, p_2) = C\rho_0\,p_1\sqrt{T_0/T}\;\varphi(p_2/p_1), \qquad
            \varphi(r) = \begin{cases} 1 & r \le b \ \text{(choked)}\\
            \sqrt{1 - \big(\tfrac{r - b}{1 - b}\big)^2} & b < r \le r_l \ \text{(subsonic)}\\
            \varphi(r_l)\,\tfrac{1 - r}{1 - r_l} & r_l < r \le 1 \end{cases}

  with :math:`\rho_0` = 1.185 kg/m^3 and :math:`T_0` = 293.15 K (ISO 8778's reference atmosphere, the ANR
  reference of ISO 6358), :math:`Q(p_1, p_2) = -Q(p_2, p_1)` for reverse flow, and
  :math:`\dot m = s\,Q(p_s, p)` (filling) or :math:`\dot m = s\,Q(p, p_e)` (venting). The last branch is linear
  in the pressure difference above :math:`r_l` = 0.999 (in the spirit of ISO 6358-3's laminar region): the
  subsonic law has an infinite slope at :math:`r = 1`, which Newton's method cannot use; it changes the flow by
  less than :math:`\varphi(r_l)` of the choked flow (6 % at b = 0.5) and only within 0.1 % of the port's
  pressure;
* a Python callable ``fn(nu, p) -> mdot`` [kg/s] (the stated slower path: the network then runs in Python).

:func:`orifice_flow` gives the flow and its derivatives in closed form; the compiled network's reservoir rows
(:mod:`soroshapes.network`) and :meth:`Fluidic.rhs <soroshapes.model.Fluidic.rhs>` both call it.
"""
from __future__ import annotations

import math

import numpy as np

from sorofem._numba import njit
from sorofem.errors import ParameterError

__all__ = ["Orifice", "orifice_flow", "RHO_ANR", "T_ANR", "LAMINAR_RATIO"]

#: ISO 8778 standard reference atmosphere (ANR): density [kg/m^3] and temperature [K]
RHO_ANR, T_ANR = 1.185, 293.15
#: pressure ratio above which a port's flow is linear in the pressure difference
LAMINAR_RATIO = 0.999


class Orifice:
    r"""An ISO 6358-like valve (module docstring): ``Fluidic(..., valve=Orifice(C, b, supply))``.

    Parameters
    ----------
    conductance : float [m^3/(s Pa)]
        Sonic conductance :math:`C` of each port (e.g. 1e-9 m^3/(s Pa) = 1 dm^3/(s bar), the size of a small
        proportional valve).
    critical_ratio : float [-]
        Critical pressure ratio :math:`b` in [0, 1) (0.5 is typical; 0.528 is an ideal nozzle).
    supply : float [Pa]
        Gauge pressure of the supply port (> 0).
    exhaust : float [Pa]
        Gauge pressure of the exhaust port (default 0: the atmosphere).

    Examples
    --------
    >>> v = Orifice(1e-9, 0.5, 600e3)
    >>> round(v.full_flow(101325.0, 293.15) * 1e3, 6)      # choked flow of the open supply port [g/s]
    0.83107
    """

    def __init__(self, conductance, critical_ratio=0.5, supply=600e3, *, exhaust=0.0):
        self.conductance, self.critical_ratio = float(conductance), float(critical_ratio)
        self.supply, self.exhaust = float(supply), float(exhaust)
        if not (math.isfinite(self.conductance) and self.conductance > 0):
            raise ParameterError(f"Orifice conductance must be > 0 [m^3/(s Pa)], got {conductance!r}")
        if not (0.0 <= self.critical_ratio < LAMINAR_RATIO):
            raise ParameterError(f"Orifice critical_ratio must be in [0, {LAMINAR_RATIO}), got {critical_ratio!r}")
        if not (math.isfinite(self.supply) and self.supply > 0 and math.isfinite(self.exhaust)
                and self.exhaust < self.supply):
            raise ParameterError(f"Orifice needs a finite gauge supply > 0 and exhaust < supply [Pa], got {supply!r}, "
                                 f"{exhaust!r}")

    def gain(self, T):
        r""":math:`C\rho_0\sqrt{T_0/T}` [kg/(s Pa)] at the gas temperature ``T`` [K]."""
        return self.conductance * RHO_ANR * math.sqrt(T_ANR / T)

    def full_flow(self, p0, T):
        """Choked flow [kg/s] of the open supply port, for the ambient absolute pressure ``p0`` [Pa] and ``T`` [K]."""
        return self.gain(T) * (p0 + self.supply)

    def parameters(self, p0, T):
        """(gain, b, absolute supply, absolute exhaust, full flow) [SI]: the row of the compiled network."""
        return np.array([self.gain(T), self.critical_ratio, p0 + self.supply, p0 + self.exhaust,
                         self.full_flow(p0, T)])

    def flow(self, nu, p, p0, T):
        """Mass flow [kg/s] into a reservoir at absolute pressure ``p`` [Pa] for the command ``nu`` [kg/s]."""
        K, b, ps, pe, full = self.parameters(p0, T)
        return orifice_flow(K, b, ps, pe, full, float(nu), float(p))[0]


@njit(cache=True)
def _fraction(r, b):
    """:math:`\\varphi(r)` and :math:`\\varphi'(r)` for 0 <= r <= 1 (module docstring)."""
    if r <= b:
        return 1.0, 0.0
    if r > LAMINAR_RATIO:
        x = (LAMINAR_RATIO - b) / (1.0 - b)
        fl = math.sqrt(1.0 - x * x)
        return fl * (1.0 - r) / (1.0 - LAMINAR_RATIO), -fl / (1.0 - LAMINAR_RATIO)
    x = (r - b) / (1.0 - b)
    f = math.sqrt(1.0 - x * x)
    return f, -x / (f * (1.0 - b))


@njit(cache=True)
def _port(K, b, pa, pb):
    """Flow from pa to pb [Pa] through one port (negative: from pb to pa) and its derivatives by pa and pb."""
    if pa >= pb:
        r = pb / pa
        f, df = _fraction(r, b)
        return K * pa * f, K * (f - r * df), K * df
    r = pa / pb
    f, df = _fraction(r, b)
    return -K * pb * f, -K * df, -K * (f - r * df)


@njit(cache=True)
def orifice_flow(K, b, ps, pe, full, nu, p):
    r"""Mass flow [kg/s] of the :class:`Orifice` into a reservoir at absolute pressure ``p`` [Pa] for the
    command ``nu`` [kg/s], with ``K`` = :math:`C\rho_0\sqrt{T_0/T}`, ``b``, the absolute supply and exhaust
    pressures ``ps``, ``pe`` [Pa] and the full flow ``full`` [kg/s]. Returns
    :math:`(\dot m, \partial\dot m/\partial\nu, \partial\dot m/\partial p)`."""
    s, ds = nu / full, 1.0 / full
    if s >= 1.0:
        s, ds = 1.0, 0.0
    elif s <= -1.0:
        s, ds = -1.0, 0.0
    if s >= 0.0:
        q, dqa, dqb = _port(K, b, ps, p)
        return s * q, ds * q, s * dqb
    q, dqa, dqb = _port(K, b, p, pe)
    return s * q, ds * q, s * dqa
