"""The optimization loop: MMA or OC iterations with progress, continuation, checkpoints and restart.

Each iteration evaluates the problem (state solve, adjoint, filter chain), updates the design and logs one
line (``logging`` at INFO; a progress bar on a terminal, :class:`sorofem.io.Progress`). Convergence is the
88-line code's criterion, :math:`\\max_e |x_e^{k+1} - x_e^k| <` ``tol`` (with a Heaviside projection: and its
sharpness at the largest value). A checkpoint (``.npz``, written atomically) holds the design, the optimizer's
state and the history; ``restart=`` continues from one. Ctrl-C writes the checkpoint and returns the design reached,
flagged ``interrupted``.
"""
import logging
import time
from pathlib import Path

import numpy as np

from ..errors import DataError, ParameterError
from ..io import Progress, atomic_path
from .mma import MMA
from .oc import oc_update

__all__ = ["optimize", "Result", "save_design", "load_design"]

log = logging.getLogger(__name__)


class Result:
    """Outcome of :func:`optimize`.

    Attributes
    ----------
    x : (n,) array
        Design variables.
    density : (n,) array
        Physical densities.
    objective : float
        Final objective value (problem units).
    history : list of dict
        Per iteration: ``iteration``, ``objective``, ``volume``, ``change``, ``beta``, ``newton``, ``time``.
    iterations : int
    converged : bool
    interrupted : bool
    wall_time : float
        [s].
    """

    def __init__(self, x, density, objective, history, converged, interrupted, wall_time):
        self.x, self.density, self.objective = x, density, float(objective)
        self.history, self.converged, self.interrupted = history, converged, interrupted
        self.iterations = len(history)
        self.wall_time = wall_time

    def __repr__(self):
        return (f"Result(objective={self.objective:.6g}, iterations={self.iterations}, converged={self.converged}, "
                f"volume={self.history[-1]['volume'] if self.history else float('nan'):.4f})")


def save_design(path, x, iteration=0, history=(), optimizer_state=None, beta=None):
    """Write a design (and optionally the optimizer state and history) to ``path`` (.npz), atomically."""
    data = {"x": np.asarray(x, float), "iteration": np.array(int(iteration)), "format": np.array("sorofem.topopt/1")}
    keys = ("iteration", "objective", "volume", "change", "beta", "newton", "time")
    if history:
        for k in keys:
            data[f"history_{k}"] = np.array([h.get(k, np.nan) if h.get(k) is not None else np.nan for h in history])
    for k, v in (optimizer_state or {}).items():
        data[f"mma_{k}"] = np.asarray(v)
    if beta is not None:
        data["beta"] = np.array(float(beta))
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **data)
    return Path(path)


def load_design(path):
    """Read what :func:`save_design` wrote: a dict with ``x``, ``iteration``, ``history``, ``mma``, ``beta``."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no design file at {path}; run optimize(..., checkpoint={str(path)!r}) to write one")
    with np.load(path, allow_pickle=False) as z:
        if "x" not in z or str(z.get("format", "")) != "sorofem.topopt/1":
            raise DataError(f"{path} is not a sorofem.topopt design file (missing 'x' or format tag)")
        out = {"x": z["x"].copy(), "iteration": int(z["iteration"]), "mma": {}, "beta": None, "history": []}
        for k in z.files:
            if k.startswith("mma_"):
                out["mma"][k[4:]] = z[k].copy()
        if "beta" in z.files:
            out["beta"] = float(z["beta"])
        if "history_iteration" in z.files:
            keys = [k[8:] for k in z.files if k.startswith("history_")]
            n = len(z["history_iteration"])
            out["history"] = [{k: float(z[f"history_{k}"][i]) for k in keys} for i in range(n)]
            for h in out["history"]:
                h["iteration"] = int(h["iteration"])
    return out


def optimize(problem, method="mma", max_iterations=200, tol=0.01, x0=None, move=None, callback=None,
             progress=None, checkpoint=None, checkpoint_every=10, restart=None, min_iterations=0):
    """Optimize ``problem`` (a :class:`~sorofem.topopt.TopOpt`) from ``x0`` (default: uniform at the volume
    fraction).

    Parameters
    ----------
    method : {"mma", "oc"}
        MMA (any objective, the default) or optimality criteria (compliance only).
    max_iterations : int
    tol : float
        Stop when the largest design change of an iteration is below ``tol``.
    move : float, optional
        Move limit (default 0.2 for OC, 0.2 for MMA).
    callback : callable, optional
        ``callback(iteration, x, evaluation)`` after each evaluation (frames, custom logging).
    progress : bool or None
        ``None`` (default): a ``tqdm`` bar when standard error is a terminal, nothing otherwise; ``True``: also
        one line per iteration when it is not; ``False``: nothing (:class:`sorofem.io.Progress`, rank 0).
    checkpoint : path, optional
        ``.npz`` file written every ``checkpoint_every`` iterations, at the end and on Ctrl-C.
    restart : path, optional
        Continue from a checkpoint (design, MMA asymptotes, projection sharpness, history).

    Returns
    -------
    Result
    """
    if method not in ("mma", "oc"):
        raise ParameterError(f"method must be 'mma' or 'oc', got {method!r}")
    if method == "oc" and type(problem).__name__ != "Compliance":
        raise ParameterError("optimality criteria only apply to compliance minimization; use method='mma'")
    if int(max_iterations) < 1 or not tol > 0:
        raise ParameterError(f"need max_iterations >= 1 and tol > 0, got {max_iterations!r}, {tol!r}")
    move = 0.2 if move is None else float(move)
    n = problem.n
    opt = MMA(n, 1, 0.0, 1.0, move=move) if method == "mma" else None
    history, start, scale = [], 0, None
    x = problem.initial_design() if x0 is None else np.asarray(x0, float).copy()
    if restart is not None:
        saved = load_design(restart)
        if saved["x"].shape != (n,):
            raise DataError(f"the restart design has {saved['x'].shape[0]} cells, the problem {n}")
        x, start, history = saved["x"], saved["iteration"], saved["history"]
        if opt is not None and saved["mma"]:
            opt.load_state(saved["mma"])
        if "scale" in saved["mma"]:
            scale = float(saved["mma"]["scale"])
        if saved["beta"] is not None and problem.projection is not None:
            problem.projection.beta = saved["beta"]
        log.info("restarting from %s at iteration %d", restart, start)
    x = np.clip(x, 0.0, 1.0)
    x[problem.solid], x[problem.void] = 1.0, 0.0
    bar = Progress(int(max_iterations), "topopt", progress, problem.mesh.comm, unit="it")
    bar.to(start)
    t0 = time.perf_counter()
    converged = interrupted = False
    ev = None

    def save(it):
        if checkpoint is not None:
            state = dict(opt.state()) if opt else {}
            if scale is not None:
                state["scale"] = np.array(scale)
            save_design(checkpoint, x, it, history, state,
                        problem.projection.beta if problem.projection is not None else None)

    it = start
    try:
        while it < max_iterations:
            ti = time.perf_counter()
            ev = problem.evaluate(x)
            if scale is None:
                scale = 1.0 / max(abs(ev.objective), 1e-30)
            if callback is not None:
                callback(it, x, ev)
            if method == "oc":
                xnew = oc_update(x, ev.gradient, ev.constraint_gradients[0], problem.volume, problem.volume_fraction,
                                 move=move)
            else:
                xnew = opt.update(x, ev.objective * scale * 10, ev.gradient * scale * 10, ev.constraints * 10,
                                  ev.constraint_gradients * 10)
            xnew[problem.solid], xnew[problem.void] = 1.0, 0.0
            change = float(np.max(np.abs(xnew - x)))
            x = xnew
            it += 1
            beta = problem.projection.beta if problem.projection is not None else None
            history.append(dict(iteration=it, objective=ev.objective, volume=ev.volume_fraction, change=change,
                                beta=beta, newton=ev.newton_iterations, time=time.perf_counter() - ti))
            log.info("topopt it %4d  J = %.6g  vol = %.4f  change = %.4f%s", it, ev.objective, ev.volume_fraction,
                     change, f"  beta = {beta:g}" if beta else "")
            bar.to(it, J=f"{ev.objective:.4g}", vol=f"{ev.volume_fraction:.3f}", change=f"{change:.3f}")
            if checkpoint is not None and it % int(checkpoint_every) == 0:
                save(it)
            done = change < tol and it >= min_iterations
            if problem.projection is not None:
                if problem.projection.continuation(it, converged=done):
                    scale = None
                    if opt is not None:
                        opt = MMA(n, 1, 0.0, 1.0, move=move)
                    continue
                done = done and problem.projection.beta >= problem.projection.beta_max
            if done:
                converged = True
                break
    except KeyboardInterrupt:
        interrupted = True
        log.warning("topopt interrupted at iteration %d; %s", it,
                    f"checkpoint written to {checkpoint}" if checkpoint else "no checkpoint file was given")
    finally:
        bar.close()
    save(it)
    final = problem.evaluate(x, gradient=False)
    return Result(x, final.density, final.objective, history, converged, interrupted, time.perf_counter() - t0)
