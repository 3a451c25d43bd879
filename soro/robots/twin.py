"""A robot's digital twin as a scene for ``soro play``: the reduced beams of :attr:`Design.twins` as a
:class:`soroshapes.Shapes` (one soft body) or a :class:`soroshapes.Model` (several), and the board channels
that drive them (names, limits [Pa] from :attr:`Design.channels`, the model inputs each one sets).

This is the application layer (:mod:`soro.robots`): the designs and their twin data come from
:mod:`sorofem.robots`, the beams from ``soroshapes`` (imported inside the functions, so that ``soro robot
export`` does not load it).

The beams are the solid-section twins (the printed cross-section through a bellows, chambers as axial forces
off the axis) with the bellows' effective modulus, calibrated on FEM: the 3D FEM of (a) (a solid section is 28x
too stiff: bellows walls fold) and the axisymmetric FEM of one round bellows chain of (b) and of (d). A
data-driven beam from 3D FEM of the printed geometry is made by ``soro demo robot_twin`` for (a) and (b).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sorofem.errors import ParameterError

__all__ = ["Channel", "Scene", "twin_shapes", "scene", "reach", "chain_stretch", "bellows_modulus",
           "BELLOWS_E_FACTOR", "ROUND_BELLOWS_E_FACTOR", "PARALLEL_BELLOWS_E_FACTOR"]

#: Ratio of the bellows' effective Young's modulus to the material's, for the solid-section beams: the 3D FEM
#: of the printed actuator (a) (``soro demo robot_twin``, full mode: 88.8 deg tip angle at 100 kPa) against its
#: solid-section beam (3.11 deg): 3.11 / 88.8. A stand-in for FEM of each robot, which only (a) and (b) have.
BELLOWS_E_FACTOR = 3.11 / 88.8

#: The same for the round bellows chains side by side of (b) (two) and (d) (three), by the number of chains: the
#: secant stretch of one chain at its robot's top pressure in the axisymmetric FEM of its printed meridian
#: (:func:`chain_stretch`, 0.6 mm P2 elements: (b) 74.70 mm of its 144 mm at 50 kPa, (d) 36.12 mm of its 120 mm at
#: 30 kPa) against the beam of its crest-ring section, whose chamber is the bellows' effective area
#: (:math:`\pi R_m^2`): E_eff = p pi Rm^2 / (strain x ring area). The chains stiffen as their grooves open (the
#: stretch per kPa falls from ~2.9 to ~0.7 mm/kPa over 0..50 kPa in (b)): the linear beam matches the FEM at the
#: top pressure and is stiffer below it.
ROUND_BELLOWS_E_FACTOR = {2: 0.04769, 3: 0.03664}

#: (b)'s factor (compatibility name: chains side by side).
PARALLEL_BELLOWS_E_FACTOR = ROUND_BELLOWS_E_FACTOR[2]


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
    :data:`ROUND_BELLOWS_E_FACTOR` of its number of chains for round chains side by side (several chambers in the
    section: (b), (d)), else :data:`BELLOWS_E_FACTOR` (one box bellows chain on a strain-limiting layer: (a), the
    hand's and the gripper's fingers)."""
    from sorofem import materials
    n = len(twin.chambers)
    if n > 1 and n not in ROUND_BELLOWS_E_FACTOR:
        raise ParameterError(f"no bellows modulus is calibrated for {n} chains side by side (twin {twin.name!r})")
    f = ROUND_BELLOWS_E_FACTOR[n] if n > 1 else BELLOWS_E_FACTOR
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


def chain_stretch(name, pressure, size=0.6e-3, steps=8, **params):
    """Axisymmetric FEM of one round bellows chain of robot ``name`` ((b) or (d), parameters in SI): its
    stretch under internal pressure, the block's bottom clamped, the tip free (Elastic 80A, Taylor-Hood P2/P1).

    Parameters
    ----------
    name : str
    pressure : float
        Top gauge pressure [Pa] (a ramp from 0).
    size : float
        Element size [m] (a wall of 1.2 mm takes two P2 elements at 0.6 mm).
    steps : int
        Load steps requested (adaptive; the first sized from the linear response).

    Returns
    -------
    dict
        ``pressure`` [Pa] and ``stretch`` [m] per converged step, the chain's ``length`` [m] and ``cells``.
    """
    from sorofem import materials
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh
    from sorofem.robots import chain_meridian

    wall, cav, length = chain_meridian(name, **params)
    msh = Mesh.from_sdf(wall, size=size, order=2)
    msh.add_region("inner", cav, tol=0.05e-3)
    fem = Fem(msh, materials.Elastic80A(), formulation="axisymmetric", degree=2, mixed=True)
    fem.add_support("bottom")
    fem.add_pressure("inner", pressure)
    tr = fem.solve(steps=steps, linear_start=0.02, progress=False)
    top = int(np.argmax(tr.vertices[:, 1] - 1e-3 * tr.vertices[:, 0]))     # the tip's point on the axis
    return {"pressure": np.asarray(tr.inputs["pressure/inner"], float), "stretch": tr.displacement[:, top, 1],
            "length": length, "cells": int(msh.num_cells)}
