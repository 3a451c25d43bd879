r"""Back ends of ``soro play``: what moves the scene the page shows.

* :class:`ModelBackend`: the reduced model steps in this process, paced by the wall clock (real time); when a
  step takes longer than the time it simulates, the achieved real-time factor drops below 1, the frames keep
  coming (about 30 per second of wall time) and the page says so.
* :class:`BoardBackend`: a pneumatic board, simulated (:meth:`sorocontrol.Board.simulated`, the scene's beam as
  its plant when the scene is one :class:`~soroshapes.Shapes` with one chamber per channel) or real
  (:meth:`sorocontrol.Board.connect`). The sliders are the board's set-points; the 3D view is the shape the
  board's sensors report (``view_source = "estimate"``) or, when they report none, the model's prediction
  driven by the measured pressures (``"prediction"``). :meth:`Backend.vent` (the page closed) and
  :meth:`Backend.close` (the server stops) vent the board.

Every back end publishes frames (:meth:`Backend.frame`): a dict of plain numbers in SI units (positions in m,
pressures in Pa, energies in J), the page's only input. One stepping thread per back end; commands from the
page (:meth:`Backend.command`) are applied under a lock and answered by the next frame, whose ``input_seq``
is the sequence number of the last command it includes (the page measures its latency with it).
"""
from __future__ import annotations

import csv
import logging
import threading
import time
from pathlib import Path

import numpy as np

from sorofem.errors import ParameterError, SafetyError, SoroError

__all__ = ["Backend", "ModelBackend", "BoardBackend", "MirrorBackend", "section_outline", "scene_geometry"]

log = logging.getLogger(__name__)

FRAME_PERIOD = 1.0 / 30.0     # wall time between frames when the model keeps up [s]
MAX_STEP_WALL = 0.1           # longest wall time of one step before its model time shrinks [s]


# ----------------------------------------------------------------------------------------------------------
# geometry for the page
# ----------------------------------------------------------------------------------------------------------
def section_outline(section, n=24):
    """Boundary of a 2D SDF ``section`` as ``n`` points (y, z) [m] about its centroid, found by bisection
    along rays from the centroid (a star-shaped section: the rounded rectangles and circles of the demos)."""
    from sorofem.sdf.properties import section_properties
    c = np.asarray(section_properties(section).centroid, float)
    a = 2 * np.pi * np.arange(n) / n
    d = np.column_stack([np.cos(a), np.sin(a)])
    lo, hi = np.zeros(n), np.full(n, float(np.max(np.abs(np.asarray(section.bounds) - c))) * 2 + 1e-6)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        inside = np.asarray(section(c + mid[:, None] * d)).reshape(-1) < 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    return 0.5 * (lo + hi)[:, None] * d


def obstacle_points(shape, box, n=2500, seed=0):
    """About ``n`` points [m] on the surface of a 3D SDF within its bounds and the ``box`` (lo (3,), hi (3,))
    [m], projected onto the surface: the page draws obstacles as these points."""
    lo, hi = (np.asarray(b, float) for b in shape.bounds)
    lo = np.maximum(np.where(np.isfinite(lo), lo, -np.inf), box[0])
    hi = np.minimum(np.where(np.isfinite(hi), hi, np.inf), box[1])
    rng = np.random.default_rng(seed)
    p = lo + (hi - lo) * rng.random((8 * n, 3))
    d = np.asarray(shape(p)).reshape(-1)
    h = 0.05 * float(np.max(hi - lo))
    p = p[np.abs(d) < h][:n]
    if len(p) == 0:
        return np.zeros((0, 3))
    p = np.asarray(shape.project(p)[0], float)
    keep = np.all((p >= lo - 1e-9) & (p <= hi + 1e-9), axis=1) & np.all(np.isfinite(p), axis=1)
    return p[keep]


def scene_geometry(scene):
    """The static part of the page's scene: beam sections, obstacle surface points, channels, view."""
    beams, lo, hi = [], np.full(3, np.inf), np.full(3, -np.inf)
    for name in scene.beam_names:
        shp = scene.beam(name)
        beams.append({"name": name, "outline": _r(section_outline(shp.section)), "radius": shp.contact_radius})
        base = shp.positions(np.zeros(shp.n))[0]
        lo, hi = np.minimum(lo, base - 1.2 * shp.length), np.maximum(hi, base + 1.2 * shp.length)
    box = (lo, hi) if np.all(np.isfinite(lo)) else (np.full(3, -0.2), np.full(3, 0.2))
    return {
        "title": scene.title,
        "beams": beams,
        "obstacles": [_r(obstacle_points(ob, box)) for ob in scene.obstacles],
        "channels": [{"name": c.name, "label": c.label or c.name, "low": c.low, "high": c.high, "unit": c.unit,
                      "initial": c.initial} for c in scene.channels],
        "target": None if scene.target is None else list(map(float, scene.target.position)),
        "impedance": scene.impedance is not None,
        "view": list(map(float, scene.view)),
    }


def _r(a, nd=6):
    return np.round(np.asarray(a, float), nd).tolist()


# ----------------------------------------------------------------------------------------------------------
# plants: the reduced model of a scene, stepped in this process
# ----------------------------------------------------------------------------------------------------------
class _Plant:
    """The scene's system with its state; ``step(h, u)`` advances it by ``h`` [s] with inputs ``u`` (values of
    the scene's channels, SI), holding them constant."""

    def __init__(self, scene):
        self.scene = scene
        self.index = {name: k for k, name in enumerate(scene.inputs)}
        self.reset()

    def _full(self, u):
        v = np.zeros(len(self.index))
        for ch, val in zip(self.scene.channels, u):
            v[self.index[ch.name]] = val
        return v


class _ShapesPlant(_Plant):
    def reset(self):
        shp = self.scene.system
        self.t, self.q, self.qd = 0.0, np.zeros(shp.n), np.zeros(shp.n)

    def step(self, h, u):
        shp = self.scene.system
        tr = shp.simulate(h, min(self.scene.dt, h), q0=self.q, qd0=self.qd, u=self._full(u))
        self.q, self.qd, self.t = tr.q[-1].copy(), tr.qd[-1].copy(), self.t + h

    def beam_states(self):
        return {"beam": (self.scene.system, self.q, self.qd)}

    def set_beam(self, name, q):
        self.q, self.qd = np.asarray(q, float).copy(), np.zeros_like(self.q)

    def bodies(self):
        return []

    def pressures(self):
        return {}


class _ModelPlant(_Plant):
    def __init__(self, scene):
        mdl = scene.system
        self._u = np.zeros(len(mdl.inputs))
        self.impedance_target = None                        # (k,) set-point [m] of the impedance mode, or None
        self._impedance = None
        if scene.impedance is not None:
            from soroshapes.control import impedance
            kw = dict(scene.impedance)
            self._axes = list(kw.get("axes", (0, 1, 2)))
            self._impedance = impedance(scene.target_beam, setpoint=lambda t: self.impedance_target, **kw)
        self._owner = [name.split(".", 1)[0] for name in mdl.inputs]
        mdl.set_controller(self._control, reads=None if scene.impedance else ())
        self.slices, x, k = {}, mdl.initial_state(), 0
        mdl.set_state(0.0, x)
        for name in mdl.systems:
            n = len(mdl[name].x)
            self.slices[name] = slice(k, k + n)
            k += n
        super().__init__(scene)

    def _control(self, model):
        """The sliders' values (the free inputs), plus the impedance controller's in the impedance mode."""
        if self._impedance is None or self.impedance_target is None:
            return self._u
        out = {}
        for k, owner in enumerate(self._owner):
            out.setdefault(owner, []).append(self._u[k])
        out = {name: np.asarray(v) for name, v in out.items()}
        for name, v in self._impedance(model).items():
            out[name] = out.get(name, 0.0) + np.asarray(v, float)
        return out

    def set_impedance_target(self, p):
        """Track ``p`` (3,) [m] (its ``axes``) with the impedance controller; None switches it off."""
        self.impedance_target = None if p is None else np.asarray(p, float)[self._axes].copy()

    def reset(self):
        self.t, self.x = 0.0, self.scene.system.initial_state().copy()
        self.scene.system.set_state(0.0, self.x)

    def step(self, h, u):
        mdl = self.scene.system
        self._u = self._full(u)
        if self._impedance is None or self.impedance_target is None:
            # the sliders as a constant table: a Schedule runs on the compiled network path (a Python controller
            # would force the whole network onto the Python path, Model.evaluation_path)
            from soroshapes.network import Schedule
            mdl.set_controller(Schedule([0.0, 1.0], np.vstack([self._u, self._u])))
        else:
            mdl.set_controller(self._control)
        tr = mdl.simulate(h, min(self.scene.dt, h), method=self.scene.method, x0=self.x, t0=self.t,
                          rtol=self.scene.rtol, atol=self.scene.atol)
        self.x, self.t = tr.x[-1].copy(), self.t + h
        mdl.set_state(self.t, self.x)

    def beam_states(self):
        out = {}
        for name in self.scene.beam_names:
            shp = self.scene.beam(name)
            xs = self.x[self.slices[name]]
            out[name] = (shp, xs[:shp.n], xs[shp.n:2 * shp.n])
        return out

    def set_beam(self, name, q):
        shp, sl = self.scene.beam(name), self.slices[name]
        self.x[sl.start:sl.start + shp.n] = q
        self.x[sl.start + shp.n:sl.start + 2 * shp.n] = 0.0
        self.scene.system.set_state(self.t, self.x)

    def bodies(self):
        mdl, out = self.scene.system, []
        for name in mdl.systems:
            sysm = mdl[name].system
            if hasattr(sysm, "pose") and hasattr(sysm, "twist"):       # RigidBody, SpinningBody
                g = np.asarray(sysm.pose(self.x[self.slices[name]]), float)
                out.append({"name": name, "pose": _r(g[:3, :])})
        return out

    def pressures(self):
        from soroshapes import Fluidic
        mdl = self.scene.system
        return {name: float(mdl[name].pressure) for name in mdl.systems if isinstance(mdl[name].system, Fluidic)}


class _MirrorPlant:
    """A Model that something else steps (and whose controller it keeps): its current state, read through the
    model's public views (``model["name"].x``) after the owner's ``set_state``."""

    def __init__(self, scene):
        self.scene = scene
        self.t = 0.0

    def reset(self):
        pass

    def step(self, h, u):
        raise ParameterError("this view mirrors a model stepped elsewhere")

    def beam_states(self):
        mdl, out = self.scene.system, {}
        for name in self.scene.beam_names:
            shp, x = self.scene.beam(name), np.asarray(mdl[name].x, float)
            out[name] = (shp, x[:shp.n], x[shp.n:2 * shp.n])
        return out

    def bodies(self):
        mdl, out = self.scene.system, []
        for name in mdl.systems:
            sysm = mdl[name].system
            if hasattr(sysm, "pose") and hasattr(sysm, "twist"):
                out.append({"name": name, "pose": _r(np.asarray(sysm.pose(mdl[name].x), float)[:3, :])})
        return out

    def pressures(self):
        from soroshapes import Fluidic
        mdl = self.scene.system
        return {name: float(mdl[name].pressure) for name in mdl.systems if isinstance(mdl[name].system, Fluidic)}


def make_plant(scene):
    """The plant of a scene (its Shapes or Model with a state)."""
    return _ShapesPlant(scene) if scene.kind == "shapes" else _ModelPlant(scene)


# ----------------------------------------------------------------------------------------------------------
# back ends
# ----------------------------------------------------------------------------------------------------------
class Backend:
    """Common part: the channel values, commands, IK target, recording, frame publication.

    Parameters
    ----------
    scene : soro.play.Scene
    clock : callable () -> float [s]
        Monotonic wall clock (injectable for tests).
    out : path
        Where recordings go (``out/play`` by default).
    """

    label = "backend"
    view_source = "model"

    def __init__(self, scene, clock=time.monotonic, out="out/play"):
        self.scene, self.clock, self.out = scene, clock, Path(out)
        self.plant = self._make_plant()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._frame_cv = threading.Condition()
        self.u = np.array([np.clip(c.initial, c.low, c.high) for c in scene.channels], float)
        self.paused = False
        self.mode = "simulate"
        self.target = None if scene.target is None else np.asarray(scene.target.position, float).copy()
        self._ik_dirty = False
        self._want_reset = False
        self.ik_error = None
        self.cmd_seq = 0
        self.seq = 0
        self.rtf = 1.0
        self.message = ""
        self._frame = None
        self._recording = None
        self._replay = None
        self.last_recording = None
        self.thread = None

    # -- commands from the page ------------------------------------------------------------------------
    def command(self, cmd):
        """Apply one command (a dict from the page): ``{"type": "input", "name", "value"}``, ``"target"`` (with
        ``position`` [m]), ``"play"``, ``"pause"``, ``"reset"``, ``"mode"`` (``"simulate"``/``"ik"``),
        ``"record"``, ``"stop_record"``, ``"replay"``, ``"vent"``. ``seq`` (int) numbers the command.
        Returns a short answer dict. Raises :class:`ParameterError` for a malformed command."""
        kind = cmd.get("type")
        seq = int(cmd.get("seq", 0) or 0)
        answer = {"ok": True}
        with self._lock:
            if kind == "input":
                names = [c.name for c in self.scene.channels]
                name = cmd.get("name")
                if name not in names:
                    raise ParameterError(f"no channel {name!r}; channels: {names}")
                k = names.index(name)
                ch = self.scene.channels[k]
                v = float(cmd.get("value"))
                if not np.isfinite(v):
                    raise ParameterError(f"channel {name!r}: value must be finite")
                self.u[k] = float(np.clip(v, ch.low, ch.high))
                if self._replay is not None:                # the person takes over from the recording
                    self._replay, self.message = None, "replay stopped: a slider moved"
                self._on_input()
            elif kind == "target":
                if self.target is None:
                    raise ParameterError("this scene has no IK target")
                p = np.asarray(cmd.get("position"), float).reshape(-1)
                if p.shape != (3,) or not np.all(np.isfinite(p)):
                    raise ParameterError("target position must be 3 finite numbers [m]")
                self.target = p
                if self.mode == "impedance":
                    self.plant.set_impedance_target(p)
                else:
                    self.mode, self._ik_dirty = "ik", True
            elif kind == "play":
                self.paused = False
                if self.mode == "ik":
                    self.mode = "simulate"
            elif kind == "pause":
                self.paused = True
            elif kind == "reset":
                self._reset()
            elif kind == "mode":
                modes = ("simulate", "ik") + (("impedance",) if self.scene.impedance is not None else ())
                if cmd.get("mode") not in modes:
                    raise ParameterError(f"mode must be one of {modes} for this scene, got {cmd.get('mode')!r}")
                self.mode = cmd["mode"]
                self._ik_dirty = self.mode == "ik"
                if self.scene.impedance is not None:
                    self.plant.set_impedance_target(self.target if self.mode == "impedance" else None)
            elif kind == "record":
                self._recording = []
            elif kind == "stop_record":
                answer["path"] = str(self._save_recording())
            elif kind == "replay":
                answer["path"] = str(self._start_replay(cmd.get("path")))
            elif kind == "vent":
                self._vent_locked()
            else:
                raise ParameterError(f"unknown command {kind!r}")
            self.cmd_seq = max(self.cmd_seq, seq)
        self._wake.set()
        return answer

    def _make_plant(self):
        return make_plant(self.scene)

    def _on_input(self):
        """Hook: a channel changed (the board back end leaves its vented state)."""

    def _reset(self):
        """Back to the start; the plant is reset by the stepping thread (:meth:`_apply_pending`)."""
        self._want_reset = True
        self.u[:] = [np.clip(c.initial, c.low, c.high) for c in self.scene.channels]
        if self.scene.target is not None:
            self.target = np.asarray(self.scene.target.position, float).copy()
        if self.scene.impedance is not None:
            self.plant.set_impedance_target(None)
        self.mode, self._replay, self.message = "simulate", None, ""

    def vent(self):
        """All channels to 0 (and the board vented): the page was closed."""
        with self._lock:
            self._vent_locked()
        self._wake.set()

    def _vent_locked(self):
        self.u[:] = 0.0

    # -- recording ---------------------------------------------------------------------------------------
    def _signals(self, tip):
        return [self.plant.t, *self.u.tolist(), *(tip.tolist() if tip is not None else [np.nan] * 3)]

    def _save_recording(self):
        from sorofem.io import atomic_path
        rows = self._recording or []
        self._recording = None
        if not rows:
            raise ParameterError("nothing recorded: press record, let it run, then stop")
        stamp = time.strftime("%Y%m%d-%H%M%S")
        path = self.out / f"{self.scene.title}-{stamp}.csv"
        header = ["t_s", *[f"{c.name}_{c.unit.replace(' ', '')}" for c in self.scene.channels], "tip_x_m", "tip_y_m",
                  "tip_z_m"]
        with atomic_path(path) as tmp:
            with open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(header)
                w.writerows(rows)
        with atomic_path(path.with_suffix(".npz")) as tmp:
            states = {n: np.concatenate([q, qd]) for n, (_, q, qd) in self.plant.beam_states().items()}
            np.savez(tmp, t=self.plant.t, u=self.u, **{f"state_{n}": s for n, s in states.items()})
        self.last_recording = path
        return path

    def _start_replay(self, path=None):
        path = Path(path) if path else self.last_recording
        if path is None or not Path(path).is_file():
            raise ParameterError(f"no recording to replay ({path}); record one first")
        data = np.genfromtxt(path, delimiter=",", skip_header=1, ndmin=2)
        m = len(self.scene.channels)
        if data.shape[1] != m + 4:
            raise ParameterError(f"{path} has {data.shape[1]} columns; this scene's recordings have {m + 4}")
        self._want_reset = True                             # the stepping thread resets, then starts the replay
        self._replay = (None, data[:, 0] - data[0, 0], data[:, 1:1 + m])
        self.paused, self.mode, self.message = False, "simulate", ""
        return path

    def _apply_pending(self):
        """In the stepping thread, under the lock: a reset asked for by a command (the plant is only ever
        touched by this thread). Returns True when it reset."""
        if not self._want_reset:
            return False
        self._want_reset = False
        self.plant.reset()
        if self._replay is not None and self._replay[0] is None:
            self._replay = (self.plant.t, *self._replay[1:])
        return True

    def _replay_inputs(self):
        t0, ts, us = self._replay
        k = int(np.searchsorted(ts, self.plant.t - t0, side="right")) - 1
        if k >= len(ts) - 1:
            self._replay = None
            self.message = "replay finished"
        self.u[:] = us[max(k, 0)]

    # -- the frame ---------------------------------------------------------------------------------------
    def _compose(self, input_seq, extra=None):
        beams, tip, energy = [], None, 0.0
        for name, (shp, q, qd) in self.view_states().items():
            G = shp.forward_kinematics(q)
            item = {"name": name, "p": _r(G[:, :3, 3]), "ey": _r(G[:, :3, 1], 4), "ez": _r(G[:, :3, 2], 4)}
            if self.scene.obstacles:
                f = shp.contact_forces(q, qd)
                hit = np.flatnonzero(np.linalg.norm(f, axis=1) > 0)
                item["contacts"] = [[*_r(G[i, :3, 3]), *_r(f[i])] for i in hit]
            beams.append(item)
            if name == self.scene.focus_beam:
                tip = G[-1, :3, 3].copy()
            energy += float(shp.energy(q, qd)["total"])
        signals = {"tip_x": tip[0], "tip_y": tip[1], "tip_z": tip[2], "energy": energy} if tip is not None else {}
        for c, v in zip(self.scene.channels, self.u):
            signals[f"u:{c.name}"] = float(v)
        for name, p in self.plant.pressures().items():
            signals[f"p:{name}"] = p
        if self.scene.signals is not None:
            signals.update({k: float(v) for k, v in self.scene.signals(self.scene.system, self.plant).items()})
        if self._recording is not None:
            self._recording.append(self._signals(tip))
        self.seq += 1
        frame = {"seq": self.seq, "input_seq": input_seq, "t": self.plant.t, "rtf": self.rtf, "paused": self.paused,
                 "mode": self.mode, "backend": self.label, "view_source": self.view_source, "beams": beams,
                 "bodies": self.plant.bodies(), "target": None if self.target is None else self.target.tolist(),
                 "tip": None if tip is None else tip.tolist(), "ik_error": self.ik_error,
                 "inputs": self.u.tolist(), "signals": signals, "message": self.message,
                 "recording": self._recording is not None, "replaying": self._replay is not None,
                 "last_recording": None if self.last_recording is None else str(self.last_recording)}
        if extra:
            frame.update(extra)
        with self._frame_cv:
            self._frame = frame
            self._frame_cv.notify_all()
        return frame

    def view_states(self):
        """{beam name: (Shapes, q, qd)} shown in the 3D view."""
        return self.plant.beam_states()

    def frame(self):
        """The latest frame (dict), or None before the first."""
        with self._frame_cv:
            return self._frame

    def wait_frame(self, after_seq, timeout):
        """The first frame with ``seq > after_seq``, waiting up to ``timeout`` [s] (None on timeout)."""
        with self._frame_cv:
            self._frame_cv.wait_for(lambda: self._frame is not None and self._frame["seq"] > after_seq, timeout)
            f = self._frame
            return f if f is not None and f["seq"] > after_seq else None

    def _solve_ik(self):
        name = self.scene.target_beam
        shp, q, _ = self.plant.beam_states()[name]
        at = self.scene.target.at
        tgt = self.target if at is None else [(at, self.target)]
        res = shp.inverse_kinematics(tgt, q0=q, tol=1e-7)
        self.plant.set_beam(name, res.q)
        self.ik_error = float(res.error)
        self.message = "" if res.converged else \
            f"target out of reach: the closest pose is {res.error * 1e3:.1f} mm away"

    def _warm_up_ik(self):
        """Compile the IK kernels (numba, several seconds the first time) on a copy of the target's beam in a
        background thread, so that the first drag of the target does not stop the frames."""
        if self.scene.target is None:
            return
        import copy
        shp = copy.deepcopy(self.scene.beam(self.scene.target_beam))

        def warm():
            try:
                tip = shp.positions(np.zeros(shp.n))[-1]
                shp.inverse_kinematics(shp.positions(np.zeros(shp.n))[0] + 0.97 * (tip - shp.positions(
                    np.zeros(shp.n))[0]), q0=np.zeros(shp.n), max_iterations=3)
            except SoroError:
                pass
        threading.Thread(target=warm, daemon=True, name="soro-play-ik-warm-up").start()

    # -- thread ------------------------------------------------------------------------------------------
    def start(self):
        """Start the stepping thread (publishes a first frame before returning)."""
        with self._lock:
            self._compose(self.cmd_seq)
        self.thread = threading.Thread(target=self._run_guarded, daemon=True, name=f"soro-play-{self.label}")
        self.thread.start()
        return self

    def _run_guarded(self):
        try:
            self._run()
        except Exception as e:  # noqa: BLE001 - the page must hear of it, the server must not hang
            log.exception("soro play: the back end stopped")
            with self._lock:
                self.paused = True
                self.message = f"the back end stopped: {type(e).__name__}: {e}"
                try:
                    self._vent_locked()                     # a board goes to 0 Pa, whatever failed
                    self.message += "; vented"
                except Exception as v:  # noqa: BLE001 - say it; the board's watchdog is the last resort
                    self.message += f"; venting failed too ({v}): the board's watchdog vents it"
                try:
                    self._compose(self.cmd_seq)
                except Exception:  # noqa: BLE001 - the frame is a courtesy; the message is logged above
                    log.exception("soro play: could not publish the last frame")

    def close(self):
        """Stop the thread (idempotent)."""
        self._stop.set()
        self._wake.set()
        if self.thread is not None and self.thread is not threading.current_thread():
            self.thread.join(10.0)


class ModelBackend(Backend):
    """The reduced model stepping in this process in real time (see the module docstring).

    Each step simulates ``h`` = one frame period (1/30 s) of model time and is published at once; then the loop
    waits for the wall clock (a command cuts the wait). A model that cannot keep up steps back to back and the
    page shows the achieved real-time factor (``rtf``: model time over wall time, smoothed over about a second);
    ``h`` shrinks only when one step would take longer than ``MAX_STEP_WALL`` of wall time (the frames keep
    coming at 10 Hz or more), never below the scene's ``dt``: each ``Model.simulate`` call has a fixed cost
    (its first Newton matrix), so shorter calls would lower the factor further. The first step after a command
    is a quarter of ``h``, so that the change shows after a short step (the page's latency).

    A model that is behind steps again at once, but gives the GIL away first (``time.sleep(0)``) after each
    published frame: without it, on Python 3.13 the threads that read the frames (the page's server, or
    :meth:`wait_frame`) were starved. Measured in Debian 13's root with a clock that makes every step 4x slower
    than real time: 36 000 steps were published while the reader got 20 frames, and 300 frames took 330 s;
    with the yield, one frame per step and 300 frames in 0.2 s (Debian 12, Python 3.11: 3 s either way).
    """

    label = "model"
    view_source = "model"

    def _run(self):
        h, anchor, last_wall, warm, stepped_seq = FRAME_PERIOD, None, self.clock(), False, 0
        while not self._stop.is_set():
            with self._lock:
                if self._apply_pending():
                    anchor = None                           # real time counts from the new start
                input_seq = self.cmd_seq
                if self.mode == "ik" and self._ik_dirty:
                    self._ik_dirty = False
                    try:
                        self._solve_ik()
                    except SoroError as e:
                        self.message = f"IK failed: {e}"
                    self._compose(input_seq)
                    continue
                running = not self.paused and self.mode in ("simulate", "impedance")
                if running and self._replay is not None:
                    self._replay_inputs()
                u = self.u.copy()
            if not running:
                self.rtf, anchor = 0.0, None
                with self._lock:
                    self._compose(input_seq)
                self._wake.wait(0.25)
                self._wake.clear()
                continue
            t0 = self.clock()
            if anchor is None:                              # (wall, model time) that real time counts from
                anchor, last_wall, t_prev = (t0, self.plant.t), t0, self.plant.t
            hk = h if input_seq == stepped_seq else max(self.scene.dt, 0.25 * h)   # a new command: short step
            stepped_seq = input_seq
            try:
                self.plant.step(hk, u)
            except SoroError as e:
                with self._lock:
                    self.paused = True
                    self.message = f"the model failed at t = {self.plant.t:.3f} s: {e} (press reset)"
                    self._compose(input_seq)
                continue
            compute = max(self.clock() - t0, 1e-6)
            if not warm:                                    # after the first step: its kernels are loaded
                warm = True
                self._warm_up_ik()
            if hk == h:
                h = max(self.scene.dt, min(FRAME_PERIOD, h * MAX_STEP_WALL / compute))
            now = self.clock()
            wall = max(now - last_wall, 1e-6)
            last_wall = now
            a = min(1.0, wall)                              # ~1 s smoothing of the displayed factor
            self.rtf = (1 - a) * self.rtf + a * ((self.plant.t - t_prev) / wall)
            t_prev = self.plant.t
            with self._lock:                                # publish first, then wait for the wall clock:
                self._compose(input_seq)                    # a command wakes the wait and is stepped at once
            while not self._stop.is_set():
                ahead = anchor[0] + (self.plant.t - anchor[1]) - self.clock()
                if ahead < -2 * FRAME_PERIOD:               # behind: count real time from now on
                    anchor = (self.clock(), self.plant.t)
                if ahead <= 0:                              # behind: step again, but first give the GIL away
                    time.sleep(0)                           # (see the class docstring)
                    break
                if not self._wake.wait(ahead):
                    break
                self._wake.clear()                          # a command: step it now unless the model is
                if ahead <= 2 * FRAME_PERIOD:               # already two frames ahead of the wall clock
                    break


#: The watchdog [s] of the simulated board behind the page: four times a real board's 0.5 s. This process serves
#: the page, draws frames and talks to the board; on a loaded laptop it can be descheduled for more than half a
#: second (measured in CI beside two CPU burners: 0.501 s), and a simulated board that vents then only
#: interrupts the session. A real board (``--backend board``) keeps the watchdog its server was started with.
SIM_WATCHDOG = 2.0


class BoardBackend(Backend):
    """A simulated or real board behind the page (see the module docstring).

    Parameters
    ----------
    scene : soro.play.Scene
        Its channels (pressures only) are the board's channels, in order.
    board : sorocontrol.Board, optional
        A connected board; default a simulated one (:meth:`sorocontrol.Board.simulated`, its watchdog
        ``SIM_WATCHDOG``) with the scene's beam as plant when the scene is one Shapes whose inputs are all
        channels.
    rate : float [Hz]
        Commands per second to the board.
    """

    def __init__(self, scene, board=None, rate=50.0, **kw):
        super().__init__(scene, **kw)
        for c in scene.channels:
            if c.unit != "Pa":
                raise ParameterError(f"channel {c.name!r} is a {c.unit} input: a board drives pressures only")
        if board is None:
            from sorocontrol import Board
            beam = scene.system if scene.kind == "shapes" and len(scene.inputs) == len(scene.channels) else None
            board = Board.simulated(channels=len(scene.channels), p_min=min(0.0, min(c.low for c in scene.channels)),
                                    p_max=max(c.high for c in scene.channels), beam=beam, watchdog=SIM_WATCHDOG)
            self.label = "simulated board"
        else:
            self.label = "board"
        if board.channels < len(scene.channels):
            board.close()
            raise ParameterError(f"the board has {board.channels} channels, the scene {len(scene.channels)}")
        self.board, self.rate = board, float(rate)
        self.vented = True
        self.board_state = None
        n = scene.system.n if scene.kind == "shapes" else None
        try:
            self._sensor_q = n is not None and board.read().sensors.size == 3 + n
        except BaseException:
            board.close()                                   # vents and releases it
            raise
        self.view_source = "estimate" if self._sensor_q else "prediction"

    def _on_input(self):
        self.vented = False

    def command(self, cmd):
        if cmd.get("type") in ("target", "mode"):
            raise ParameterError("the IK target drives the model back end (soro play --backend model); a board "
                                 "follows its pressure sliders")
        return super().command(cmd)

    def _vent_locked(self):
        self.u[:] = 0.0
        self.vented = True
        self.board_state = self.board.vent()

    def _reset(self):
        super()._reset()
        self._vent_locked()

    def view_states(self):
        if self._sensor_q and self.board_state is not None:
            shp = self.scene.system
            q = np.asarray(self.board_state.sensors[3:3 + shp.n], float)
            return {"beam": (shp, q, np.zeros_like(q))}
        return self.plant.beam_states()

    def _run(self):
        period = 1.0 / self.rate
        m = len(self.scene.channels)
        last = self.clock()
        while not self._stop.is_set():
            t0 = self.clock()
            with self._lock:
                self._apply_pending()
                input_seq = self.cmd_seq
                if self._replay is not None and not self.paused:
                    self._replay_inputs()
                    self.vented = False
                u, vented = self.u.copy(), self.vented
            try:
                values = np.zeros(self.board.channels)
                values[:m] = u
                state = self.board.read() if vented else self.board.set_pressure(values)
            except SoroError as e:
                with self._lock:
                    self.message = f"board: {e}"
                    self.paused = True
                    self._compose(input_seq)
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            measured = np.asarray(state.measured[:m], float)
            with self._lock:
                self.board_state = state
                now = self.clock()
                if not self._sensor_q and not self.paused:     # the model's prediction from the measured pressures
                    try:
                        self.plant.step(max(now - last, 1e-3), measured)
                    except SoroError as e:
                        self.message = f"the prediction failed at t = {self.plant.t:.3f} s: {e} (press reset)"
                        self.paused = True
                self.rtf = 1.0
                last = now
                self._compose(input_seq, {"board": {"requested": state.requested[:m].tolist(),
                                                    "measured": measured.tolist(), "vented": vented,
                                                    "time": state.time}})
            rest = period - (self.clock() - t0)
            if rest > 0:
                self._wake.wait(rest)
                self._wake.clear()
            else:                                           # behind the rate: let the server's threads run
                time.sleep(0)

    def close(self):
        """Stop the thread, vent and close the board (idempotent)."""
        super().close()
        try:
            self.board.close()
        except SoroError as e:     # the board's own watchdog vents it
            raise SafetyError(f"could not vent the board on close ({e}); its watchdog vents it within "
                              f"{self.board.watchdog:g} s") from e


class MirrorBackend(Backend):
    """The page of a Model that its owner steps (the Gymnasium environment's ``render_mode="human"``): nothing
    is stepped here and the owner's controller stays; :meth:`update` publishes the model's current state (set by
    the owner with ``Model.set_state``). The sliders show the owner's inputs; the page cannot command them."""

    label = "gymnasium env"
    view_source = "model"

    def _make_plant(self):
        return _MirrorPlant(self.scene)

    def command(self, cmd):
        raise ParameterError("this page mirrors a model stepped by its owner (a Gymnasium env): it takes no commands")

    def update(self, u=None):
        """Publish a frame of the model's current state (``u``: the values of the scene's channels to show)."""
        with self._lock:
            self.plant.t = float(self.scene.system.t)
            if u is not None:
                self.u[:] = np.asarray(u, float).reshape(-1)[:len(self.u)]
            self._compose(self.cmd_seq)

    def _run(self):
        self._stop.wait()
