"""The seed's four open-hardware soft robots: parametric SDF designs, print-ready STL parts, twin data.

>>> from sorofem import robots
>>> sorted(robots.names())
['bending_actuator', 'hand', 'manipulator', 'planar_actuator']
>>> d = robots.design("bending_actuator")          # parameters in SI: robots.design(name, wall=2.5e-3)
>>> [p.name for p in d.parts], d.channels["bend"]
(['actuator'], (-10000.0, 100000.0))

The designs live in this package (not in ``hardware/``) because the ``soro robot`` command must find them in
an installed copy; they use only :mod:`sorofem.sdf`, so they sit on the foundation of the layering.
:func:`export_part` writes one printed part as STL (through :func:`sorofem.sdf.to_stl`). The twins are data
(section SDF, material preset name, chamber areas and offsets, base pose) and so are the board channels with
their limits (``Design.channels``). What is made from them lives in the application layer, :mod:`soro.robots`:
the beams (:class:`soroshapes.Shapes`) and scenes of the twins, the board profile, the full export (STL,
preview, board profile and report) and the ``soro robot`` command; ``sorofem`` never imports ``soroshapes``.
"""
from __future__ import annotations

from .._lazy import moved_attributes
from ..errors import GeometryError
from ._core import UNITS, Chamber, Design, Network, Param, Part, Robot, Twin, chamber_check
from .designs import ROBOTS

__all__ = ["names", "get", "design", "parse_params", "export_part", "chamber_check",
           "Param", "Network", "Part", "Chamber", "Twin", "Design", "Robot", "ROBOTS", "UNITS"]

#: Names that moved to the application layer :mod:`soro.robots` (README.md, "Moved names"): importing one from
#: here is an ImportError that names its new place. (``Design.scene()`` is ``soro.robots.scene(name)``.)
MOVED = {name: f"soro.robots.{name}" for name in (
    "export", "preview_png", "board_profile", "VEAB_SIGNAL_RANGE", "Scene", "Channel", "twin_shapes", "scene",
    "reach", "bellows_modulus", "BELLOWS_E_FACTOR", "PARALLEL_BELLOWS_E_FACTOR")}
__getattr__ = moved_attributes(__name__, MOVED)


def names():
    """Names of the robots."""
    return list(ROBOTS)


def get(name):
    """The :class:`Robot` called ``name``."""
    if name not in ROBOTS:
        raise GeometryError(f"no robot {name!r}; the robots are {names()} (soro robot list)")
    return ROBOTS[name]


def design(name, **params):
    """Build robot ``name`` with ``params`` in SI (m, Pa; counts as integers)."""
    return get(name).design(**params)


def parse_params(name, items):
    """``["wall=2.5", "n_bellows=6"]`` (each in its parameter's unit, mm for lengths) -> SI keyword dict."""
    known = {p.name: p for p in get(name).PARAMS}
    out = {}
    for item in items or ():
        key, sep, value = str(item).partition("=")
        key = key.strip()
        if not sep or key not in known:
            raise GeometryError(f"--param {item!r}: give NAME=VALUE with NAME one of {sorted(known)}")
        try:
            out[key] = float(value) * UNITS[known[key].unit]
        except ValueError:
            raise GeometryError(f"--param {item!r}: {value!r} is not a number ({known[key].unit})") from None
    return out


def export_part(part, path, units="mm", resolution=None):
    """Write one printed part as a binary STL in ``units``; returns its triangles read back from the file,
    (F, 3, 3) [m] (check them with :func:`sorofem.sdf.surface_check`). ``resolution`` [m] defaults to a third
    of the part's smallest feature."""
    from ..sdf import read_stl, to_stl
    h = float(resolution) if resolution is not None else part.feature / 3
    to_stl(part.shape, path, resolution=h, units=units)
    tri, _ = read_stl(path)
    return tri
