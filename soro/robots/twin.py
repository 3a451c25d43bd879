"""A robot's digital twin as a scene for ``soro play``: the reduced beams of :attr:`Design.twins` as a
:class:`soroshapes.Shapes` (one soft body) or a :class:`soroshapes.Model` (several), and the board channels
that drive them (names, limits [Pa] from :attr:`Design.channels`, the model inputs each one sets).

This is the application layer (:mod:`soro.robots`): the designs and their twin data come from
:mod:`sorofem.robots`, the beams from ``soroshapes`` (imported inside the functions, so that ``soro robot
export`` does not load it).

The beams are the solid-section twins (the printed cross-section through a bellows, chambers as axial forces
off the axis) with the bellows' effective modulus, calibrated on the 3D FEM of (a) and (b) (a solid section is
28x resp. 8x too stiff: bellows walls fold). A data-driven beam from 3D FEM of the printed geometry is made by
``soro demo robot_twin`` for (a) and (b).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sorofem.errors import ParameterError

__all__ = ["Channel", "Scene", "twin_shapes", "scene", "reach", "bellows_modulus", "BELLOWS_E_FACTOR",
           "PARALLEL_BELLOWS_E_FACTOR"]

#: Ratio of the bellows' effective Young's modulus to the material's, for the solid-section beams: the 3D FEM
#: of the printed actuator (a) (``soro demo robot_twin``, full mode: 88.8 deg tip angle at 100 kPa) against its
#: solid-section beam (3.11 deg): 3.11 / 88.8. A stand-in for FEM of each robot, which only (a) and (b) have.
BELLOWS_E_FACTOR = 3.11 / 88.8

#: The same for chains side by side, which resist each other's bending: the 3D FEM of the planar actuator (b)
#: (full mode: 6.12 mm lateral tip at 50 kPa in one network) against its solid-section beam with
#: ``BELLOWS_E_FACTOR`` (21.43 mm); as a ratio it assumes the deflection scales with 1/E (the beam then gives
#: 5.83 mm: within 5 %). Its beam reaches 5.2 x 13.9 mm over -10..50 kPa, the FEM-made DVS beam 4.5 x 13.7 mm.
#: The manipulator's three chains are built the same way.
PARALLEL_BELLOWS_E_FACTOR = BELLOWS_E_FACTOR * 21.43 / 6.12


@dataclass(frozen=True)
class Channel:
    """A board channel of a scene: ``name``, safety ``limits`` (lo, hi) [Pa], ``unit`` ("Pa") and the model
    ``inputs`` it sets (one channel may feed several chambers, e.g. the gripper's three fingers)."""

    name: str
    limits: tuple
    unit: str
    inputs: tuple


@dataclass(frozen=True)
class Scene:
    """A robot's twin for interactive use: ``model`` (a :class:`soroshapes.Shapes` or :class:`soroshapes.Model`)
    and its ``channels`` (tuple of :class:`Channel`) in board order."""

    robot: str
    model: object
    channels: tuple

    def channel(self, name):
        """The :class:`Channel` called ``name``."""
        for c in self.channels:
            if c.name == name:
                return c
        raise ParameterError(f"{self.robot} has no channel {name!r}; its channels are "
                             f"{[c.name for c in self.channels]}")

    def inputs(self, pressures):
        """The model's input vector ``u`` (in the order of ``model.inputs``) for channel pressures [Pa].

        Parameters
        ----------
        pressures : dict
            Channel name -> gauge pressure [Pa]; channels left out are at 0 Pa (vented). A value outside the
            channel's limits is refused (ParameterError naming it), as the board would clamp it.
        """
        names = list(self.model.inputs)
        u = np.zeros(len(names))
        for name, p in pressures.items():
            ch = self.channel(name)
            p = float(p)
            if not (np.isfinite(p) and ch.limits[0] <= p <= ch.limits[1]):
                raise ParameterError(f"channel {name!r}: {p:g} Pa is outside its limits "
                                     f"[{ch.limits[0]:g}, {ch.limits[1]:g}] Pa")
            for inp in ch.inputs:
                u[names.index(inp)] = p
        return u


def twin_shapes(twin, dofs=(0, 3, 3, 1, 0, 0), modes=3, E=None):
    """The solid-section beam of a :class:`Twin` (Chebyshev strain basis, ``modes`` per active strain) with
    one chamber input per twin chamber, named after its board channel.

    Parameters
    ----------
    twin : Twin
    dofs : 6 ints
        Active strains (torsion, bending y, bending z, stretch, shear y, shear z) as for ``Shapes``.
    modes : int
        Order of the Chebyshev basis.
    E : float, optional
        Young's modulus [Pa] in place of the material preset's small-strain modulus.
    """
    from soroshapes import Basis, Shapes

    from sorofem import materials
    shp = Shapes(Basis.chebyshev(modes), dofs, twin.length, twin.section, materials.PRESETS[twin.material](),
                 base=twin.base, E=E)
    for c in twin.chambers:
        shp.add_chamber(c.area, c.offset, name=c.channel)
    return shp


def bellows_modulus(twin):
    """The effective Young's modulus [Pa] of a twin's bellows: the material's times
    :data:`PARALLEL_BELLOWS_E_FACTOR` for chains side by side (several chambers in the section: (b), (d)), else
    :data:`BELLOWS_E_FACTOR` (one chain on a strain-limiting layer: (a), the hand's and the gripper's fingers)."""
    from sorofem import materials
    f = PARALLEL_BELLOWS_E_FACTOR if len(twin.chambers) > 1 else BELLOWS_E_FACTOR
    return materials.PRESETS[twin.material]().E * f


def scene(design, stiffness="bellows"):
    """The :class:`Scene` of a :class:`Design`: one ``Shapes`` for a single soft body ((a), (b)), else a
    ``Model`` with one beam per twin named after it ((c) the five fingers, (d) the manipulator and the
    gripper's three fingers, the gripper on the top plate's rest pose: beams in a Model have fixed bases).

    Parameters
    ----------
    design : Design
    stiffness : "bellows", "section" or float
        The beams' Young's modulus: ``"bellows"`` (default) the bellows' effective modulus calibrated on the 3D
        FEM of (a) and (b) (:func:`bellows_modulus`), ``"section"`` the material's (a solid section: far too
        stiff for bellows), or a number [Pa].
    """
    def modulus(tw):
        if isinstance(stiffness, str):
            if stiffness not in ("bellows", "section"):
                raise ParameterError(f"stiffness must be 'bellows', 'section' or a modulus in Pa, got {stiffness!r}")
            return bellows_modulus(tw) if stiffness == "bellows" else None
        E = float(stiffness)
        if not (np.isfinite(E) and E > 0):
            raise ParameterError(f"stiffness must be a positive modulus [Pa], got {stiffness!r}")
        return E

    if len(design.twins) == 1:
        model = twin_shapes(design.twins[0], E=modulus(design.twins[0]))
        by_channel = {name: tuple(i for i in model.inputs if i == name) for name in design.channels}
    else:
        from soroshapes import Model
        model = Model()
        by_channel = {name: [] for name in design.channels}
        for tw in design.twins:
            model.add(twin_shapes(tw, E=modulus(tw)), name=tw.name)
            for c in tw.chambers:
                by_channel[c.channel].append(f"{tw.name}.{c.channel}")
        by_channel = {k: tuple(v) for k, v in by_channel.items()}
    missing = [k for k, v in by_channel.items() if not v]
    if missing:
        raise ParameterError(f"{design.robot}: channels {missing} drive no chamber of the twin")
    chans = tuple(Channel(name, tuple(float(v) for v in design.channels[name]), "Pa", by_channel[name])
                  for name in design.channels)
    return Scene(design.robot, model, chans)


def reach(shapes, limits, samples=7, point=(0.0, 0.0, 0.0)):
    """The sampled reach of a beam: the position [m] of ``point`` (fixed in the tip frame, [m]) at the static
    equilibrium for every input vector of the grid of ``samples`` values per input over its ``limits``.

    Parameters
    ----------
    shapes : soroshapes.Shapes
        A beam whose inputs are pressures (chambers or identified actuators), in the order of ``limits``.
    limits : sequence of (lo, hi)
        Range [Pa] of each input (the board channel's safety limits).
    samples : int
        Values per input (>= 2; the grid has ``samples ** len(limits)`` points, both ends included).
    point : 3 floats
        The point in the tip frame whose reach is sampled [m] (e.g. the tip plate's centre).

    Returns
    -------
    (N, 3) ndarray [m]
    """
    import itertools

    limits = [tuple(float(v) for v in lim) for lim in limits]
    if len(limits) != len(shapes.inputs):
        raise ParameterError(f"reach: {len(limits)} limits for a beam with inputs {shapes.inputs}")
    samples = int(samples)
    if samples < 2:
        raise ParameterError("reach: samples must be >= 2 (both ends of every range)")
    p = np.append(np.asarray(point, float), 1.0)
    out, q = [], None
    for u in itertools.product(*[np.linspace(lo, hi, samples) for lo, hi in limits]):
        q = shapes.statics(u=list(u), q0=q)
        out.append((shapes.forward_kinematics(q)[-1] @ p)[:3])
    return np.array(out)
