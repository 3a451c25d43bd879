r"""A Gymnasium environment over any :class:`~soroshapes.model.Model`.

:class:`ModelEnv` holds the action :math:`a_k` constant over one step of length ``dt`` [s] (zero-order hold)
and advances the closed network :math:`\dot x = F(t, x)` (free inputs :math:`u = u_{base}(model) + S a_k`:
the model's own controller, if it had one, plus the action on the ``action_inputs``, a residual policy) with
the model's implicit integrator (``Model.simulate(dt, dt/substeps, x0=x_k, t0=t_k)``), so

.. math:: x_{k+1} = \Phi_{dt}(x_k; a_k), \qquad o_k = \mathrm{observation}(model), \qquad
          r_k = \mathrm{reward}(model, a_k),

with :math:`t_k = k\,dt`. An episode is truncated after ``horizon`` steps and terminated when
``terminate(model)`` is true. Gymnasium is an optional dependency, imported when this module is.

Rendering (``render_mode``): ``"rgb_array"`` returns the model's beams at the current state drawn offscreen as
tubes (:func:`soroshapes.render.render_png`, keywords in ``render_options``: ``obstacles``, ``view``, ``size``,
``dpi``, ``limits``) as an (H, W, 3) uint8 array; ``"human"`` serves the live page of ``soro play`` (the
application layer's :func:`soro.play.serve_mirror`, found by name when first rendered) on 127.0.0.1, its
address in :attr:`ModelEnv.render_url`, and each ``render()`` publishes the current state to it.

Example
-------
>>> import numpy as np
>>> from soroshapes import Model, StateSpace
>>> from soroshapes.gym import ModelEnv
>>> mdl = Model().add(StateSpace(lambda x, u, t: u, 1, 1), "cart")
>>> env = ModelEnv(mdl, observation=lambda m: m["cart"].x, reward=lambda m, a: -abs(m["cart"].x[0]),
...                dt=0.1, horizon=5, action_low=-1.0, action_high=1.0)
>>> obs, info = env.reset(seed=0)
>>> obs, r, terminated, truncated, info = env.step(np.array([1.0]))
>>> round(float(obs[0]), 6), round(r, 6), truncated
(0.1, -0.1, False)
"""
from __future__ import annotations

import numpy as np

from sorofem.errors import DependencyError, ParameterError

try:
    import gymnasium as _gym
    from gymnasium import spaces as _spaces
except ImportError as _err:        # pragma: no cover - exercised only without gymnasium
    raise DependencyError("soroshapes.gym needs gymnasium: install it into the venv with the bootstrap's "
                          "constraints, `.venv/bin/python -m pip install -c .venv/constraints.txt "
                          "'gymnasium>=1.0'` (it is listed in pyproject.toml's dependencies)") from _err

__all__ = ["ModelEnv"]


class ModelEnv(_gym.Env):
    """A :class:`gymnasium.Env` stepping a :class:`~soroshapes.model.Model` (see the module docstring).

    Parameters
    ----------
    model : Model
        The network; the env installs its own controller: the model's previous controller, if any, keeps
        running and the action is **added** to the inputs it drives (e.g. gravity compensation + policy).
    observation : callable ``model -> array``
        Read at the current state (``model["name"].x``, ``model.t``, ...).
    reward : callable ``(model, action) -> float``
        Evaluated after the step, at the new state.
    dt : float [s]
        Control period (zero-order hold).
    horizon : int
        Steps per episode (then ``truncated``).
    action_inputs : sequence of str or int, optional
        Free inputs the action drives, as names of :attr:`Model.inputs` (``"arm.actuator0"``) or indices;
        default all free inputs.
    action_low, action_high : float or array
        Bounds of the action Box (actions are clipped to them).
    x0 : array, optional
        Initial state (default the model's initial state). ``reset_fn(rng) -> x0`` draws one instead, with
        the env's ``np_random`` generator.
    terminate : callable ``model -> bool``, optional
    substeps : int
        Integrator steps per control period.
    method : str
        ``Model.simulate`` method.
    dtype : numpy float dtype
        dtype of both spaces and of the observations (float64 default; float32 for most RL libraries).
    seed : int, optional
        Seeds ``np_random`` (``reset(seed=...)`` reseeds).
    render_mode : None, "rgb_array" or "human"
        See the module docstring.
    render_options : dict, optional
        Keywords of :func:`soroshapes.render.render_png` for ``"rgb_array"`` (``limits`` [m] fixes the axes,
        so that frames of an episode line up).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(self, model, observation, reward, dt, horizon, *, action_inputs=None, action_low=-1.0,
                 action_high=1.0, x0=None, reset_fn=None, terminate=None, substeps=1, method="trapezoidal",
                 dtype=np.float64, seed=None, render_mode=None, render_options=None):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ParameterError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.render_mode, self._render_options = render_mode, dict(render_options or {})
        self.render_url, self._viewer = None, None
        for what, fn in (("observation", observation), ("reward", reward)):
            if not callable(fn):
                raise ParameterError(f"ModelEnv {what} must be a callable of the model")
        if terminate is not None and not callable(terminate):
            raise ParameterError("ModelEnv terminate must be a callable model -> bool")
        if reset_fn is not None and not callable(reset_fn):
            raise ParameterError("ModelEnv reset_fn must be a callable rng -> x0")
        self.dt, self.horizon, self.substeps = float(dt), int(horizon), int(substeps)
        if not (self.dt > 0 and self.horizon >= 1 and self.substeps >= 1):
            raise ParameterError(f"dt > 0 [s], horizon >= 1 and substeps >= 1 are needed, got {dt!r}, "
                                 f"{horizon!r}, {substeps!r}")
        self.model, self._obs_fn, self._reward_fn, self._terminate = model, observation, reward, terminate
        self._reset_fn, self.method, self.dtype = reset_fn, method, np.dtype(dtype)
        names = model.inputs
        if action_inputs is None:
            idx = list(range(len(names)))
        else:
            idx = []
            for a in action_inputs:
                if isinstance(a, str):
                    if a not in names:
                        raise ParameterError(f"action input {a!r} is not a free input of the model; free inputs: "
                                             f"{names}")
                    idx.append(names.index(a))
                elif 0 <= int(a) < len(names):
                    idx.append(int(a))
                else:
                    raise ParameterError(f"action input index {a} out of range ({len(names)} free inputs)")
        if not idx:
            raise ParameterError(f"the action drives no input; free inputs of the model: {names}")
        self._idx, self._nfree = np.array(idx), len(names)
        self._free_names = names
        k = len(idx)
        low = np.broadcast_to(np.asarray(action_low, dtype=float), (k,)).astype(self.dtype)
        high = np.broadcast_to(np.asarray(action_high, dtype=float), (k,)).astype(self.dtype)
        if not np.all(low < high):
            raise ParameterError("action_low must be below action_high for every action")
        self.action_space = _spaces.Box(low, high, dtype=self.dtype)
        self._base = model._controller
        self._action = np.zeros(k)
        model.set_controller(self._control)
        self._x0 = None if x0 is None else np.asarray(x0, dtype=float).copy()
        self._x = model.initial_state(self._x0)
        self._set_state(0.0, self._x)
        o = self._observe()
        self.observation_space = _spaces.Box(-np.inf, np.inf, shape=o.shape, dtype=self.dtype)
        self._k, self.t = 0, 0.0
        if seed is not None:
            self.reset(seed=seed)

    # -- the controller the model sees: base values plus the action on the action inputs --------------------------
    def _control(self, model):
        u = np.zeros(self._nfree)
        if self._base is not None:
            v = self._base(model)
            if isinstance(v, dict):
                for name, val in v.items():
                    pos = [p for p, s in enumerate(self._free_names) if s.split(".", 1)[0] == name]
                    u[pos] = np.asarray(val, dtype=float).reshape(-1)
            elif v is not None:
                u[:] = np.asarray(v, dtype=float).reshape(-1)
        u[self._idx] += self._action
        return u

    def _set_state(self, t, x):
        self.model.set_state(t, x)

    def _observe(self):
        o = np.asarray(self._obs_fn(self.model), dtype=float).reshape(-1)
        if not np.all(np.isfinite(o)):
            raise ParameterError(f"observation is not finite at t = {self.model.t:.6g} s: {o}")
        return o.astype(self.dtype)

    # -- gymnasium API ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Start an episode: ``x0`` from ``options["x0"]``, else ``reset_fn(np_random)``, else the default."""
        super().reset(seed=seed)
        x0 = None
        if options and "x0" in options:
            x0 = options["x0"]
        elif self._reset_fn is not None:
            x0 = self._reset_fn(self.np_random)
        elif self._x0 is not None:
            x0 = self._x0
        self._x = self.model.initial_state(x0).copy()
        self._k, self.t = 0, 0.0
        self._action = np.zeros(len(self._idx))
        self._set_state(0.0, self._x)
        return self._observe(), {"t": 0.0}

    def step(self, action):
        """Hold ``action`` (clipped to the Box) for ``dt`` and integrate; returns (obs, reward, terminated,
        truncated, info) with info ``{"t": [s], "newton_iterations": int}``."""
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != self.action_space.shape:
            raise ParameterError(f"action must have shape {self.action_space.shape}, got {a.shape}")
        self._action = np.clip(a, self.action_space.low, self.action_space.high)
        traj = self.model.simulate(self.dt, self.dt / self.substeps, method=self.method, x0=self._x, t0=self.t)
        self._x = traj.x[-1].copy()
        self._k += 1
        self.t = self._k * self.dt
        self._set_state(self.t, self._x)
        obs = self._observe()
        reward = float(self._reward_fn(self.model, self._action))
        terminated = bool(self._terminate(self.model)) if self._terminate is not None else False
        truncated = self._k >= self.horizon
        return obs, reward, terminated, truncated, {"t": self.t,
                                                   "newton_iterations": traj.stats["newton_iterations"]}

    # -- rendering ------------------------------------------------------------------------------------------
    def _beams(self):
        from .shapes import Shapes
        beams = []
        for name in self.model.systems:
            sysm = self.model[name].system
            if isinstance(sysm, Shapes):
                beams.append(sysm.beam(np.asarray(self.model[name].x, dtype=float)[:sysm.n]))
        return beams

    def render(self):
        """``"rgb_array"``: the beams at the current state, (H, W, 3) uint8; ``"human"``: publish the state to the
        page (started on the first call, address in :attr:`render_url`), returns None; no mode: None."""
        if self.render_mode == "rgb_array":
            import os
            import tempfile

            from matplotlib.image import imread

            from .render import render_png
            beams = self._beams()
            if not beams:
                raise ParameterError("render_mode='rgb_array' draws the model's beams (Shapes systems): this model "
                                     "has none")
            with tempfile.TemporaryDirectory() as d:
                img = imread(render_png(os.path.join(d, "frame.png"), beams, **self._render_options))
            return np.round(img[..., :3] * 255).astype(np.uint8)
        if self.render_mode == "human":
            if self._viewer is None:
                import importlib
                try:
                    play = importlib.import_module("soro.play")
                except ImportError as e:
                    raise DependencyError("render_mode='human' serves the page of soro play (the soro package of "
                                          "this project): install the project, `bash scripts/bootstrap.sh`") from e
                self._viewer = play.serve_mirror(self.model, [self._free_names[i] for i in self._idx])
                self.render_url = self._viewer.url
            self._viewer.backend.update(self._action)
        return None

    def close(self):
        """Stop the page of ``render_mode="human"`` (if any)."""
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
        super().close()
