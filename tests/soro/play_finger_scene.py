"""A light scene for the tests of ``soro play``: one pressurized finger (a user scene, ``finger_scene.py:build``).

The finger is a straight rod of length L along +x bending in the x-z plane (``dofs = (0, 3, 0, 0, 0, 0)``,
Chebyshev curvature about the body y axis), with one chamber at z = +d from the backbone: its pressure p is an
internal moment p A d about y, so the static shape is a constant curvature :math:`\\kappa = p A d / (E I_y)`
(bending away from the chamber, toward -z) with the tip at
:math:`(\\sin(\\kappa L)/\\kappa,\\ 0,\\ -(1 - \\cos \\kappa L)/\\kappa)`.
"""
import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

LENGTH, RADIUS = 60 * mm, 5 * mm
AREA, OFFSET = 20 * mm ** 2, 2 * mm
P_MAX = 60 * kPa


def finger():
    from soroshapes import Basis, Shapes
    shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 0, 0, 0, 0), length=LENGTH, section=sdf.Circle(RADIUS),
                 material=materials.DragonSkin30(), segments=8)
    shp.damping = 0.05          # Kelvin-Voigt time constant [s]: settles in a fraction of a second
    return shp.add_chamber(AREA, (0.0, OFFSET), name="chamber")


def static_tip(shp, p):
    """Closed-form tip (3,) [m] of the finger at pressure p [Pa]."""
    kappa = p * AREA * OFFSET / (shp.E * shp.section_properties.Iy)
    if kappa == 0:
        return np.array([LENGTH, 0.0, 0.0])
    return np.array([np.sin(kappa * LENGTH) / kappa, 0.0, -(1 - np.cos(kappa * LENGTH)) / kappa])


def build(quick=False):
    from soro.play import Channel, Scene, Target
    shp = finger()
    return Scene(shp, [Channel("chamber", 0.0, P_MAX, label="chamber pressure")],
                 target=Target((LENGTH, 0.0, 0.0)), dt=2e-3, view=(0.0, 0.0), title="finger")


def raises():
    raise RuntimeError("this scene is broken on purpose")
