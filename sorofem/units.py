"""SI unit constants.

Everything in the platform is SI (m, kg, s, Pa, N, rad). These constants convert *into* SI when you
multiply, so a user writes ``length = 80 * mm`` or ``p = 40 * kPa`` and gets metres and pascals; divide to
convert back (``length / mm``).

Examples
--------
>>> from sorofem.units import mm, kPa
>>> 80 * mm
0.08
>>> round(40 * kPa)
40000
"""
import math

__all__ = [
    "m", "cm", "mm", "um",
    "kg", "g",
    "s", "ms",
    "N", "mN",
    "Pa", "kPa", "MPa", "GPa", "bar", "psi",
    "rad", "deg",
    "gravity", "standard_gravity",
]

# length [m]
m = 1.0
cm = 1e-2
mm = 1e-3
um = 1e-6
# mass [kg]
kg = 1.0
g = 1e-3
# time [s]
s = 1.0
ms = 1e-3
# force [N]
N = 1.0
mN = 1e-3
# pressure / stress [Pa]
Pa = 1.0
kPa = 1e3
MPa = 1e6
GPa = 1e9
bar = 1e5
psi = 6894.757293168361
# angle [rad]
rad = 1.0
deg = math.pi / 180.0

#: Standard acceleration of gravity [m/s^2] (CGPM 1901).
standard_gravity = 9.80665
#: Gravity vector [m/s^2] pointing along -z (3D); for 2D models take its first two entries as (0, -g).
gravity = (0.0, 0.0, -standard_gravity)
