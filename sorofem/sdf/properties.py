"""Section properties of 2D regions and mass properties of 3D solids.

Both reduce to the moments of the indicator function of the region,

    m0 = int dV,   m1 = int x dV,   m2 = int x x^T dV   (about the origin),

which are *exact* when every node of the tree has a closed form (circle, rectangle, rounded rectangle,
ellipse, polygon, sphere, box, cylinder, torus; through translate / rotate / mirror / scale / extrude) and
otherwise integrated on a uniform cell-centred grid over the bounds with a smoothed Heaviside of the signed
distance, H(-d) ~ clip(1/2 - d/h, 0, 1) (h the cell size), which resolves the boundary inside each cell
(second-order accurate, exact for axis-aligned straight edges).
"""
import math
from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError

__all__ = ["SectionProperties", "MassProperties", "section_properties", "mass_properties", "moments"]

#: Default number of grid cells for numerical integration (2D, 3D).
DEFAULT_CELLS = {2: 1_000_000, 3: 2_000_000}


@dataclass(frozen=True)
class SectionProperties:
    """Beam cross-section properties of a 2D region, about its centroid.

    The 2D coordinates (x, y) of the shape are the section's local axes (y_s, z_s) of a beam along x_beam:
    ``Iz = int (y_s - ybar)^2 dA`` (bending about z_s, i.e. about the 2D y axis), ``Iy = int (z_s - zbar)^2 dA``
    (bending about y_s, i.e. about the 2D x axis), ``Iyz`` the product of area, ``J = Iy + Iz`` the polar
    moment about the centroid (equal to the torsion constant only for circular and annular sections).

    Attributes
    ----------
    area : float [m^2]
    centroid : (2,) array [m]
    Iy, Iz, Iyz, J : float [m^4]
    method : str
        ``"exact"`` (closed forms) or ``"numerical"`` (grid integration).
    """

    area: float
    centroid: np.ndarray
    Iy: float
    Iz: float
    Iyz: float
    J: float
    method: str


@dataclass(frozen=True)
class MassProperties:
    """Mass properties of a 3D solid of uniform density.

    Attributes
    ----------
    volume : float [m^3]
    mass : float [kg]
    center_of_mass : (3,) array [m]
    inertia : (3, 3) array [kg m^2]
        Inertia tensor about the centre of mass, I = rho int (|r|^2 1 - r r^T) dV, r = x - x_com.
    method : str
        ``"exact"`` or ``"numerical"``.
    """

    volume: float
    mass: float
    center_of_mass: np.ndarray
    inertia: np.ndarray
    method: str


def _default_step(lo, hi, dim):
    ext = hi - lo
    return float((np.prod(ext) / DEFAULT_CELLS[dim]) ** (1.0 / dim))


def _check_bounded(shape, what):
    lo, hi = shape.bounds
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GeometryError(f"cannot compute {what} of an unbounded shape ({shape.op}); intersect it with a "
                            "bounded shape (e.g. & Box(...)) first")
    if np.any(hi <= lo):
        raise GeometryError(f"cannot compute {what}: the shape is empty (its bounds do not overlap: lo={lo}, "
                            f"hi={hi}); check that intersected shapes actually overlap")
    return lo, hi


def moments(shape, resolution=None, exact=True):
    """Zeroth, first and second moments of the region about the origin.

    Parameters
    ----------
    shape : SDF
    resolution : float, optional
        Grid cell size [m] of the numerical path (default: about 10^6 cells in 2D, 2 10^6 in 3D).
    exact : bool
        Use closed forms when the whole tree has them.

    Returns
    -------
    m0 : float [m^d]; m1 : (d,) [m^(d+1)]; m2 : (d, d) [m^(d+2)]; method : str
    """
    lo, hi = _check_bounded(shape, "moments")
    m = shape._moments() if exact else None
    if m is not None:
        m0, m1, m2 = m
        if not m0 > 0:
            raise GeometryError(f"the shape ({shape.op}) has zero size")
        return float(m0), np.asarray(m1, dtype=float), np.asarray(m2, dtype=float), "exact"
    d = shape.dim
    h = _default_step(lo, hi, d) if resolution is None else float(resolution)
    if not (math.isfinite(h) and h > 0):
        raise GeometryError(f"resolution must be a positive cell size [m], got {resolution!r}")
    n = np.ceil((hi - lo) / h).astype(int) + 4
    if np.prod(n.astype(float)) > 5e8:
        raise GeometryError(f"resolution {h:g} m gives {np.prod(n.astype(float)):.3g} cells; use a coarser one")
    origin = lo - 2 * h + h / 2
    axes = [origin[i] + h * np.arange(n[i]) for i in range(d)]
    m0, m1, m2 = 0.0, np.zeros(d), np.zeros((d, d))
    rest = np.array(np.meshgrid(*axes[1:], indexing="ij")).reshape(d - 1, -1).T
    step = max(1, (1 << 18) // len(rest))
    for s in range(0, n[0], step):
        x0 = axes[0][s:s + step]
        pts = np.column_stack([np.repeat(x0, len(rest)), np.tile(rest, (len(x0), 1))])
        w = np.clip(0.5 - shape(pts) / h, 0.0, 1.0)
        m0 += w.sum()
        m1 += w @ pts
        m2 += (pts * w[:, None]).T @ pts
    cell = h**d
    if m0 * cell <= 0:
        raise GeometryError(f"the shape ({shape.op}) is empty: no grid cell lies inside it; check that "
                            "intersected shapes overlap and that differences leave material")
    return m0 * cell, m1 * cell, m2 * cell, "numerical"


def section_properties(shape, resolution=None, exact=True):
    """Area, centroid and second moments of a 2D region about its centroid (see :class:`SectionProperties`).

    Parameters
    ----------
    shape : SDF (2D)
    resolution : float, optional
        Grid cell size [m] for the numerical path (default: ~10^6 cells over the bounds).
    exact : bool
        Use closed forms when available (set False to force the numerical path).

    Examples
    --------
    >>> from sorofem import sdf
    >>> round(sdf.Circle(1.0).section_properties().J / (3.141592653589793 / 2), 12)
    1.0
    """
    if shape.dim != 2:
        raise GeometryError(f"section properties need a 2D region, got a {shape.dim}D shape; use "
                            "mass_properties() for solids")
    m0, m1, m2, method = moments(shape, resolution, exact)
    c = m1 / m0
    M = m2 - m0 * np.outer(c, c)
    Iz, Iy, Iyz = float(M[0, 0]), float(M[1, 1]), float(M[0, 1])
    return SectionProperties(area=m0, centroid=c, Iy=Iy, Iz=Iz, Iyz=Iyz, J=Iy + Iz, method=method)


def mass_properties(shape, density=1.0, resolution=None, exact=True):
    """Volume, mass, centre of mass and inertia tensor (about the centre of mass) of a 3D solid.

    Parameters
    ----------
    shape : SDF (3D)
    density : float [kg/m^3]
    resolution : float, optional
        Grid cell size [m] for the numerical path (default: ~2 10^6 cells over the bounds).
    exact : bool
        Use closed forms when available.
    """
    if shape.dim != 3:
        raise GeometryError(f"mass properties need a 3D solid, got a {shape.dim}D shape; use "
                            "section_properties() or extrude()/revolve() it first")
    rho = float(density)
    if not (math.isfinite(rho) and rho > 0):
        raise GeometryError(f"density must be positive [kg/m^3], got {density!r}")
    m0, m1, m2, method = moments(shape, resolution, exact)
    c = m1 / m0
    M = m2 - m0 * np.outer(c, c)
    inertia = rho * (np.trace(M) * np.eye(3) - M)
    return MassProperties(volume=m0, mass=rho * m0, center_of_mass=c, inertia=inertia, method=method)
