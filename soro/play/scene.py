r"""The scene protocol of ``soro play`` (see :mod:`soro.play`): what a scene callable returns, and how a name
on the command line becomes a :class:`Scene`.

A scene callable takes ``quick`` (bool, optional) and returns either a :class:`Scene` or a bare
:class:`soroshapes.Shapes` / :class:`soroshapes.Model` (then every free input becomes a channel with the default
limits of :func:`default_channel`). Units are SI: pressures in Pa, tensions in N, lengths in m.
"""
from __future__ import annotations

import importlib.util
import inspect
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sorofem.errors import ParameterError, SoroError

from ..demo import demos_dir   # where ``soro play NAME`` looks for a demo's scene

__all__ = ["Channel", "Target", "Scene", "SceneError", "SceneNotFoundError", "default_channel", "as_scene", "load_scene", "DEMO_SCENES",
           "demos_dir"]

#: The beam and network demos that expose ``scene(quick=False)`` (``soro play NAME``).
DEMO_SCENES = ("soft_hand", "jellyfish_gripper", "pcc_arm", "wavy_wall", "manipulator_pick", "suzumori_gripper",
               "board_pick_place")


class SceneError(SoroError):
    """A scene could not be imported or built (its code raised, or it returned something else than a scene);
    the message says which and what to fix."""


class SceneNotFoundError(SceneError):
    """The scene named on the command line does not exist (no such demo, file, module or function)."""


@dataclass(frozen=True)
class Channel:
    """One input channel the page drives with a slider.

    Parameters
    ----------
    name : str
        The input it drives: an input of the :class:`~soroshapes.Shapes` (``"chamber0"``) or a free input of
        the :class:`~soroshapes.Model` (``"p_thumb.pressure_ref"``, :attr:`Model.inputs`).
    low, high : float
        The slider's limits in SI units (Pa for a pressure, N for a tension), ``low < high``.
    unit : str
        ``"Pa"`` (a pressure, shown in kPa), ``"N"`` (a tension or force) or ``"N m"`` (a torque).
    label : str, optional
        Text beside the slider (default ``name``).
    initial : float
        Value at start and after a reset (clipped to the limits).
    """
    name: str
    low: float
    high: float
    unit: str = "Pa"
    label: str | None = None
    initial: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.low < self.high):
            raise ParameterError(f"channel {self.name!r}: limits must be finite with low < high, got "
                                 f"({self.low!r}, {self.high!r})")
        if self.unit not in ("Pa", "N", "N m"):
            raise ParameterError(f"channel {self.name!r}: unit must be 'Pa', 'N' or 'N m', got {self.unit!r}")


@dataclass(frozen=True)
class Target:
    """A draggable inverse-kinematics target: the node at ``at`` [m] of arc length (None: the tip) of the beam
    ``beam`` (a system name of the Model; ``None`` for a Shapes scene) follows ``position`` (3,) [m]."""
    position: tuple
    beam: str | None = None
    at: float | None = None


@dataclass
class Scene:
    """What ``soro play`` shows and drives.

    Parameters
    ----------
    system : soroshapes.Shapes or soroshapes.Model
        The reduced model (a Model's own controller is replaced by the sliders).
    channels : sequence of Channel
        One slider per channel (default: every input, :func:`default_channel`).
    target : Target, optional
        The draggable IK target.
    obstacles : sequence of 3D SDFs (:mod:`sorofem.sdf`)
        Drawn as surface points.
    dt : float [s]
        Integration step of the real-time stepping.
    method : str
        ``Model.simulate`` method for a Model ("trapezoidal", "midpoint", "bdf2").
    rtol, atol : float
        ``Model.simulate`` tolerances for a Model.
    view : (azimuth, elevation) [deg]
        Initial camera; (0, 0) looks along +y (the x-z plane fills the screen).
    title : str
    signals : callable ``(system, plant) -> dict of name: float``, optional
        Extra signals for the live plots (SI units).
    focus : str, optional
        The beam whose tip the plots follow (default the target's beam, else the first).
    impedance : dict, optional
        Keywords of :func:`soroshapes.control.impedance` (``stiffness`` [N/m], ``damping`` [N s/m], ``axes``,
        ``null_damping``, ...) for a Model scene with a target: the page's "impedance" mode adds Cartesian
        impedance control of the target beam's tip toward the dragged target to the sliders' inputs.
    """
    system: object
    channels: tuple = ()
    target: Target | None = None
    obstacles: tuple = ()
    dt: float = 2e-3
    method: str = "trapezoidal"
    rtol: float = 1e-5
    atol: float = 1e-8
    view: tuple = (0.0, 20.0)
    title: str = "scene"
    signals: object = None
    focus: str | None = None
    impedance: dict | None = None
    kind: str = field(init=False, default="shapes")

    def __post_init__(self):
        from soroshapes import Model, Shapes
        if isinstance(self.system, Shapes):
            self.kind = "shapes"
            names = list(self.system.inputs)
        elif isinstance(self.system, Model):
            self.kind = "model"
            names = list(self.system.inputs)
        else:
            raise SceneError(f"a scene must be a soroshapes.Shapes or soroshapes.Model (or a Scene holding one), "
                             f"got {type(self.system).__name__}")
        if not self.channels:
            self.channels = tuple(default_channel(n) for n in names)
        self.channels = tuple(self.channels)
        for ch in self.channels:
            if not isinstance(ch, Channel):
                raise SceneError(f"Scene.channels must hold Channel objects, got {type(ch).__name__}")
            if ch.name not in names:
                raise SceneError(f"channel {ch.name!r} is not an input of the scene's {self.kind}; inputs: {names}")
        if len({c.name for c in self.channels}) != len(self.channels):
            raise SceneError("two channels drive the same input")
        if self.target is not None:
            if not isinstance(self.target, Target):
                self.target = Target(tuple(np.asarray(self.target, float).reshape(3)))
            if self.kind == "model" and self.target.beam not in self.beam_names:
                raise SceneError(f"the target's beam {self.target.beam!r} is not a beam of the model; beams: "
                                 f"{self.beam_names}")
        if self.impedance is not None and (self.kind != "model" or self.target is None):
            raise SceneError("Scene.impedance needs a Model scene with a target (the controller drives the "
                             "target's beam; wrap a Shapes in a Model: Model().add(shp, 'arm'))")
        if self.focus is not None and self.focus not in self.beam_names:
            raise SceneError(f"Scene.focus {self.focus!r} is not a beam; beams: {self.beam_names}")
        for ob in self.obstacles:
            if getattr(ob, "dim", None) != 3:
                raise SceneError("Scene.obstacles must be 3D SDFs of sorofem.sdf")
        if not (self.dt > 0):
            raise SceneError(f"Scene.dt must be positive [s], got {self.dt!r}")

    @property
    def inputs(self):
        """All input names of the system, in the order of its input vector."""
        return list(self.system.inputs)

    @property
    def beam_names(self):
        """Names of the beams drawn as tubes (``["beam"]`` for a Shapes scene)."""
        if self.kind == "shapes":
            return ["beam"]
        from soroshapes import Shapes
        return [n for n in self.system.systems if isinstance(self.system[n].system, Shapes)]

    def beam(self, name):
        """The :class:`~soroshapes.Shapes` of beam ``name``."""
        return self.system if self.kind == "shapes" else self.system[name].system

    @property
    def target_beam(self):
        """The beam the IK target moves (None without a target)."""
        return None if self.target is None else (self.target.beam or self.beam_names[0])

    @property
    def focus_beam(self):
        """The beam whose tip the plots follow."""
        return self.focus or self.target_beam or self.beam_names[0]


def default_channel(name):
    """The channel of an input without stated limits: a tendon (name starting with ``tendon``) 0..5 N, anything
    else a pressure 0..100 kPa."""
    if name.split(".")[-1].startswith("tendon"):
        return Channel(name, 0.0, 5.0, "N")
    return Channel(name, 0.0, 100e3, "Pa")


def as_scene(obj, where="the scene"):
    """A :class:`Scene` from what a scene callable returned (a Scene, a Shapes or a Model)."""
    if isinstance(obj, Scene):
        return obj
    try:
        return Scene(obj)
    except SceneError as e:
        raise SceneError(f"{where} returned {type(obj).__name__}: {e}") from None


def _import_file(path, what):
    name = f"_soro_play_scene_{abs(hash(str(path)))}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise SceneError(f"{what}: {path} is not a Python file")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    try:
        spec.loader.exec_module(mod)
    except SoroError as e:
        raise SceneError(f"{what}: importing {path} failed: {e}") from e
    except Exception as e:  # noqa: BLE001 - any error of user code is reported with its type and message
        raise SceneError(f"{what}: importing {path} raised {type(e).__name__}: {e}") from e
    return mod


def robot_scene(name):
    """The scene of the open-hardware robot ``name`` (``soro robot list``): its twin
    (:func:`soro.robots.scene`) with one slider per model input, limited to its board channel's safety limits
    (a channel that feeds several chambers, e.g. the gripper's three fingers, gives one slider per chamber)."""
    from .. import robots
    if name not in robots.names():
        raise SceneNotFoundError(f"no robot {name!r}: the robots are {', '.join(robots.names())} (soro robot list)")
    twin = robots.scene(name)
    channels = []
    for ch in twin.channels:
        lo, hi = (float(v) for v in ch.limits)
        for inp in ch.inputs:
            label = ch.name if len(ch.inputs) == 1 else f"{ch.name}: {inp}"
            channels.append(Channel(inp, lo, hi, ch.unit, label=label))
    return Scene(twin.model, channels=tuple(channels), title=f"robot {name}")


def load_scene(spec, quick=False):
    """Resolve ``spec`` and build the scene.

    ``spec`` is a demo name (:data:`DEMO_SCENES`: calls ``demos/NAME.py:scene``), ``robot:NAME`` (the twin of
    an open-hardware robot, :func:`robot_scene`), ``path/to/file.py:func`` (a user scene; ``func`` defaults to
    ``scene``), or ``package.module:func`` (an importable module).
    ``quick`` is passed to the callable when it accepts it. Raises :class:`SceneError` with what to fix.
    """
    spec = str(spec)
    if spec.startswith("robot:"):
        return robot_scene(spec.split(":", 1)[1])
    if ":" in spec and not os.path.exists(spec):
        target, func = spec.rsplit(":", 1)
    else:
        target, func = spec, "scene"
    if not func.isidentifier():
        raise SceneNotFoundError(f"scene {spec!r}: {func!r} is not a function name; write path/to/file.py:build")
    if target.endswith(".py") or os.sep in target or "/" in target:
        path = Path(target)
        if not path.is_file():
            raise SceneNotFoundError(f"scene file {target!r} does not exist (cwd {os.getcwd()}); give path/to/file.py:func "
                             f"or a demo name: {', '.join(DEMO_SCENES)}")
        mod = _import_file(path, f"scene {spec!r}")
    elif (demos_dir() / f"{target}.py").is_file():
        mod = _import_file(demos_dir() / f"{target}.py", f"demo scene {target!r}")
    else:
        try:
            import importlib
            mod = importlib.import_module(target)
        except ImportError:
            raise SceneNotFoundError(f"no scene {spec!r}: not a demo ({', '.join(DEMO_SCENES)}), not a file and not an "
                             "importable module; a user scene is path/to/file.py:build") from None
    fn = getattr(mod, func, None)
    if not callable(fn):
        raise SceneNotFoundError(f"scene {spec!r}: {getattr(mod, '__file__', target)} has no function {func!r} (a scene is "
                         "a callable returning a soroshapes.Shapes, Model or soro.play.Scene)")
    try:
        takes_quick = "quick" in inspect.signature(fn).parameters
    except (TypeError, ValueError):
        takes_quick = False
    try:
        obj = fn(quick=quick) if takes_quick else fn()
    except SoroError as e:
        raise SceneError(f"scene {spec!r}: {func}() failed: {e}") from e
    except Exception as e:  # noqa: BLE001 - the user's code: report its type and message, exit cleanly
        raise SceneError(f"scene {spec!r}: {func}() raised {type(e).__name__}: {e}") from e
    scn = as_scene(obj, f"scene {spec!r}")
    if scn.title == "scene":
        scn.title = Path(target).stem if target.endswith(".py") else target
    return scn
