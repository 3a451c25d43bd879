"""Descriptions shared by the robot designs: parameters with units and ranges, printed parts, pneumatic
networks, the digital twin's reduced-model data, and the checks a print-ready part must pass.

Everything is SI inside (m, Pa); a parameter's ``unit`` is only the unit the command line reads it in.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import GeometryError
from ..units import kPa, mm

__all__ = ["Param", "Network", "Part", "Chamber", "Twin", "Design", "Robot", "UNITS", "chamber_check"]

#: Units a parameter can be stated in on the command line: name -> SI value of one unit.
UNITS = {"mm": mm, "kPa": kPa, "deg": math.pi / 180, "count": 1.0}


@dataclass(frozen=True)
class Param:
    """A design parameter: SI ``default`` and range [``lo``, ``hi``]; ``unit`` is how a user states it."""

    name: str
    default: float
    lo: float
    hi: float
    unit: str
    doc: str

    def check(self, value):
        """The value in SI (an int for counts), or :class:`GeometryError` naming the parameter and its range."""
        s = UNITS[self.unit]
        shown = f"[{self.lo / s:g}, {self.hi / s:g}] {self.unit}"
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise GeometryError(f"parameter {self.name!r} must be a number in {shown} ({self.doc}), "
                                f"got {value!r}") from None
        if self.unit == "count":
            if v != int(v):
                raise GeometryError(f"parameter {self.name!r} is a count: give an integer in {shown}, got {value!r}")
            v = int(v)
        if not (math.isfinite(v) and self.lo <= v <= self.hi):
            got = f"{v / s:g} {self.unit}" if math.isfinite(v) else repr(value)
            raise GeometryError(f"parameter {self.name!r} = {got} is outside its valid range {shown} "
                                f"({self.doc})")
        return v


@dataclass(frozen=True)
class Network:
    """One pneumatic network of a part: its port bore (a 3D SDF, the hole a tube fitting goes into), points
    [m] inside each of its chambers, and the pressure range [Pa] the board may command on its channel."""

    name: str
    port: object
    chambers: tuple
    pressure_range: tuple


@dataclass(frozen=True)
class Part:
    """A printed part: its solid (3D SDF, assembly coordinates [m]), material preset name, pneumatic
    networks, and the smallest feature [m] an export grid must resolve."""

    name: str
    shape: object
    material: str
    networks: tuple = ()
    feature: float = 1 * mm


@dataclass(frozen=True)
class Chamber:
    """A chamber of the reduced model: cross-section ``area`` [m^2] with centroid at ``offset`` = (y, z) [m]
    from the beam's backbone, on the board channel ``channel``."""

    name: str
    area: float
    offset: tuple
    channel: str


@dataclass(frozen=True)
class Twin:
    """Data of a reduced (Cosserat beam) model of one soft body, built from the same parameters as the print.

    A :class:`soroshapes.Shapes` is made from it as
    ``Shapes(basis, dofs, twin.length, twin.section, materials.PRESETS[twin.material](), base=twin.base)``
    followed by ``add_chamber(c.area, c.offset, name=c.name)`` for each chamber.

    Attributes
    ----------
    name : str
    length : float
        Backbone length [m] from the clamped end.
    section : SDF (2D)
        Solid cross-section in the body (y, z) plane [m], chambers removed, centred on its centroid.
    material : str
        Key of :data:`sorofem.materials.PRESETS`.
    chambers : tuple of Chamber
    base : (4, 4) array
        Pose of the clamped end in the assembly [m]; the beam's body x axis is its first column.
    """

    name: str
    length: float
    section: object
    material: str
    chambers: tuple
    base: np.ndarray = field(default_factory=lambda: np.eye(4))


@dataclass(frozen=True)
class Design:
    """A robot built from one set of parameters: printed parts, the board's channels, reduced-model twins.

    ``channels`` maps a board channel name to its safety limits (lo, hi) [Pa] (the seed's ranges);
    ``size`` is the seed's stated overall size [m] (None when the seed states none); ``workspace`` the seed's
    stated workspace [m] (x, y) planar or (x, y, z), None when it states none."""

    robot: str
    params: dict
    parts: tuple
    channels: dict
    twins: tuple
    size: tuple | None
    workspace: tuple | None = None

    def part(self, name):
        for p in self.parts:
            if p.name == name:
                return p
        raise GeometryError(f"{self.robot} has no part {name!r}; its parts are {[p.name for p in self.parts]}")


class Robot:
    """A parametric robot: ``name``, ``title``, ``PARAMS`` (tuple of :class:`Param`), ``build(params)``."""

    name = ""
    title = ""
    PARAMS = ()

    def resolve(self, **params):
        """The full parameter dict in SI: defaults updated by ``params``, each checked against its range."""
        known = {p.name: p for p in self.PARAMS}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise GeometryError(f"{self.name} has no parameter(s) {unknown}; its parameters are {sorted(known)}")
        return {n: p.check(params.get(n, p.default)) for n, p in known.items()}

    def design(self, **params):
        """Build the :class:`Design` (parameters in SI, e.g. ``wall=2*mm``)."""
        return self.build(self.resolve(**params))

    def build(self, p):  # pragma: no cover - abstract
        raise NotImplementedError


def _sample(shapes, step, pad=3):
    """Sample SDFs on a voxel grid over the first one's bounds (padded), slab by slab along x."""
    lo, hi = shapes[0].bounds
    n = np.ceil((hi - lo) / step).astype(int) + 2 * pad + 1
    if np.prod(n.astype(float)) > 6e7:
        raise GeometryError(f"a flood-fill grid step of {step:g} m gives {np.prod(n.astype(float)):.3g} "
                            "voxels; use a coarser step")
    origin = lo - pad * step
    axes = [origin[i] + step * np.arange(n[i]) for i in range(3)]
    yz = np.stack(np.meshgrid(axes[1], axes[2], indexing="ij"), axis=-1).reshape(-1, 2)
    out = [np.empty(n) for _ in shapes]
    fused = [s.compiled() is not None for s in shapes]   # the fused numba kernel: ~20x the numpy path
    for i, x in enumerate(axes[0]):
        pts = np.column_stack([np.full(len(yz), x), yz])
        for o, s, c in zip(out, shapes, fused):
            o[i] = s(pts, compiled=c).reshape(n[1], n[2])
    return origin, n, out


def chamber_check(part, step=None):
    """Flood-fill each pneumatic network of a part on a voxel grid.

    The empty voxels (d > 0) are labelled by 6-connected components. For each network: with every port bore
    filled (solid), the chambers' points must lie in one component that does not reach the outside (a closed
    network, separate from the other networks); with the port open, that component must be the outside (the
    inlet connects them).

    Parameters
    ----------
    part : Part
    step : float, optional
        Voxel size [m] (default a quarter of the part's smallest feature: walls and channels span >= 4).

    Returns
    -------
    dict
        Per network name: ``closed`` (sealed when the ports are plugged), ``inlet_open`` (reaches the outside
        through its port), ``connected`` (all its chambers in one component), ``separate`` (no other
        network's chambers in it), ``volume`` [m^3] (the plugged component's voxel volume).
    """
    from scipy import ndimage
    if not part.networks:
        return {}
    h = float(step) if step is not None else part.feature / 4
    ports = part.networks[0].port
    for net in part.networks[1:]:
        ports = ports | net.port
    origin, n, (d, ports) = _sample([part.shape, ports], h)
    struct = ndimage.generate_binary_structure(3, 1)
    plugged, _ = ndimage.label((d > 0) & (ports > 0), structure=struct)
    opened, _ = ndimage.label(d > 0, structure=struct)
    outside_p, outside_o = plugged[0, 0, 0], opened[0, 0, 0]

    def at(lab, x):
        i = np.round((np.asarray(x, float) - origin) / h).astype(int)
        if np.any(i < 0) or np.any(i >= n):
            raise GeometryError(f"chamber point {x} lies outside the part's bounds")
        return lab[tuple(i)]

    labels = {net.name: [at(plugged, c) for c in net.chambers] for net in part.networks}
    out = {}
    for net in part.networks:
        own = labels[net.name]
        others = {lab for k, v in labels.items() if k != net.name for lab in v}
        lab = own[0]
        out[net.name] = {
            "closed": bool(lab != 0 and lab != outside_p and all(x == lab for x in own)),
            "inlet_open": bool(all(at(opened, c) == outside_o for c in net.chambers)),
            "connected": bool(lab != 0 and all(x == lab for x in own)),
            "separate": bool(lab not in others),
            "volume": float(np.count_nonzero(plugged == lab) * h**3) if lab != 0 else 0.0,
        }
    return out
