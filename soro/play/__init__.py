r"""``soro play``: drive a reduced model, the simulated board or a real board from a browser page.

``soro play SCENE`` serves a page on ``http://127.0.0.1:8765/`` (prints the URL; ``--open`` also opens it)
that shows the scene in 3D, live: beams as tubes with their cross-sections, rigid bodies, obstacles (points
on their SDF surfaces), contact forces (arrows) and the target. It has a slider per input channel (within
the channel's limits), play/pause/reset, a draggable target (inverse kinematics, or the set-point of a Cartesian
impedance controller where the scene gives its gains), the achieved real-time factor, live plots of
the tip position, the inputs (and reservoir pressures) and the energy, and record (CSV of the signals plus an
NPZ snapshot of the state, under ``out/play/``) and replay.

Back ends (``--backend``, :mod:`soro.play.backends`): ``model`` (default) steps the reduced model in the server
process in real time; ``sim`` runs the simulated board with the model as its plant (the page is a board
client); ``board`` drives a real board (``--board-url tcp://host:port`` and ``--secret-file`` or
``$SORO_BOARD_SECRET``). With a board the page states whether the 3D view is the shape estimated from the
board's sensors or the model's prediction from the measured pressures. Closing the page or the server vents
the board.

The scene protocol
------------------
A scene is a callable (optionally taking ``quick``) that returns a :class:`soroshapes.Shapes`, a
:class:`soroshapes.Model`, or a :class:`Scene` that adds what a bare model cannot say: the input channels
(:class:`Channel`: the input's name, limits in Pa or N, unit, label), a draggable :class:`Target` (a node of a
beam follows it by inverse kinematics), obstacles to draw (3D SDFs), the integration step, the camera.
Without channels every free input gets one (:func:`default_channel`: 0-100 kPa, tendons 0-5 N). ``SCENE`` is

* a demo name: ``soft_hand``, ``jellyfish_gripper``, ``pcc_arm``, ``wavy_wall``, ``manipulator_pick``,
  ``suzumori_gripper``, ``board_pick_place`` (their ``scene(quick=False)`` at the end of ``demos/NAME.py``);
* a user scene, ``path/to/file.py:build`` (the function defaults to ``scene``), or ``package.module:func``.

>>> from soro.play import Scene, Channel
>>> from soroshapes import Basis, Shapes
>>> from sorofem import materials, sdf
>>> shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 0, 0, 0, 0), length=0.06, section=sdf.Circle(0.005),
...              material=materials.DragonSkin30())
>>> shp = shp.add_chamber(2e-5, (0.0, 0.002), name="chamber")
>>> Scene(shp, [Channel("chamber", 0.0, 60e3)]).channels[0].high
60000.0

Exit status of ``soro play``: 0 after a normal stop (Ctrl-C or ``--duration``), 2 when the scene does not
exist or an option is invalid (a board back end on a non-local ``--host`` is refused: the page has no login),
3 when the scene's code raises or returns no model, 4 when the port is in use or cannot be bound, 5 when the
board cannot be reached.

Safety of the board back ends: the board is vented when the last page closes (the page's ``pagehide`` beacon,
or its event stream dropping), when the server stops, when the stepping thread fails (whatever the error), and,
if all of that fails (the process is killed), by the board's own watchdog.
"""
from sorofem._lazy import lazy_attributes

_SUBMODULES = ("scene", "backends", "server", "cli")
_CLASSES = {"Scene": "scene", "Channel": "scene", "Target": "scene", "SceneError": "scene",
            "SceneNotFoundError": "scene", "load_scene": "scene", "default_channel": "scene",
            "ModelBackend": "backends", "BoardBackend": "backends", "PlayServer": "server", "ServeError": "server",
            "serve": "cli", "serve_mirror": "cli"}

__all__: list[str] = [*_SUBMODULES, *_CLASSES]

__getattr__ = lazy_attributes(__name__, _SUBMODULES, _CLASSES)
