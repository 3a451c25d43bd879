"""Scenes timed side by side in two code trees (run by bench_baseline.py as ``python baseline_scenes.py SCENE
OUT.json`` with the tree to measure first on ``sys.path``); only the public API that both trees share is used.

An optional fourth argument sets the beam quadrature of this tree (``trapezoid``: the baseline's discretization,
so that the two trees compute the same model). Each scene prints nothing and writes ``{"wall_s", "simulated_s",
"figures"}`` (``figures``: arrays or numbers to compare between the trees) to OUT.json. Demos are loaded from the
``demos/`` folder of the measured tree (the two changed scenes from the baseline's: ``BASELINE_SCENE``, whose Python
functions of time this tree plays as Schedule tables, ``_time_tables``).
"""
import importlib.util
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _demo(tree, name):
    spec = importlib.util.spec_from_file_location(f"demo_{name}", Path(tree) / "demos" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _per_step(stats):
    """Newton iterations per step from this tree's stats schema (soroshapes.trajectory) or the baseline's, whose
    beam integrator gave them as a per-step array."""
    if "newton_iterations_per_step" in stats:
        return float(stats["newton_iterations_per_step"])
    return float(np.mean(stats["newton_iterations"]))


def rod15(tree):
    """The 15-DOF rod of bench_shapes (torsion + 2 bendings x 5 Chebyshev modes, 4 segments of order 4: the
    discretization chosen by error in bench_shapes, more accurate than the 10 segments of order 2 used before)
    released straight under gravity, dt = 1 ms. Both trees run this same model."""
    from sorofem import materials, sdf
    from soroshapes import Basis, Shapes
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), damping=0.0, segments=4,
                 order=4).add_gravity()
    shp.simulate(0.01, 1e-3)                         # warm up (JIT)
    wall = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        tr = shp.simulate(1.0, 1e-3, record_every=10)
        wall = min(wall, time.perf_counter() - t0)
    return {"wall_s": wall, "simulated_s": 1.0, "figures": {"tip": tr.tip.tolist()},
            "newton_iterations_mean": _per_step(tr.stats)}


def soft_hand(tree):
    """The soft hand of demos/soft_hand.py (five fingers, regulated reservoirs), 1 s. The baseline, and this tree
    with the baseline's discretization (:data:`SAME_MODEL`), run the baseline's demo settings (10 second-order
    pieces, BDF2 at dt = 2 ms, rtol 1e-4); this tree as it is runs its demo's settings (``build()``, ``DT``,
    ``METHOD``, ``RTOL``, ``ATOL``, ``NEWTON_TOL``: as accurate as the baseline's, bench_model.py::
    test_bench_soft_hand_space_time_trade), best of three. Figures: the fingers' q every 50 ms (a multiple of both
    steps)."""
    demo = _demo(tree, "soft_hand")
    if Path(tree).resolve() == BASELINE_TREE.resolve() or SAME_MODEL:
        build = (lambda: demo.build(10, 2)) if hasattr(demo, "SEGMENTS") else demo.build
        kw = dict(dt=2e-3, method="bdf2", rtol=1e-4, atol=1e-6)
    else:
        build = demo.build
        kw = dict(dt=demo.DT, method=demo.METHOD, rtol=demo.RTOL, atol=demo.ATOL, newton_tol=demo.NEWTON_TOL)
    dt = kw.pop("dt")
    mdl, _ = build()
    mdl.simulate(0.02, dt, **kw)          # warm up
    wall = np.inf
    for _ in range(3):                    # best of three, as rod15
        mdl, _ = build()
        t0 = time.perf_counter()
        tr = mdl.simulate(1.0, dt, **kw)
        wall = min(wall, time.perf_counter() - t0)
    every = np.abs(tr.t / 0.05 - np.round(tr.t / 0.05)) < 1e-6
    assert every.sum() == 21, tr.t
    return {"wall_s": wall, "simulated_s": 1.0,
            "figures": {n: tr[n].x[every, :tr[n].x.shape[1] // 2].tolist() for n in demo.NAMES}}


#: Impact scenes: the figures compared between the trees, and the resolution the demo reports each with [their
#: units]. Where a fingertip strikes the bolt, Newton may fail at the integrator's tolerance and the step is
#: split; which steps split depends on the Newton iteration (the compiled network and the Python path of the
#: baseline iterate differently), so the trajectories differ there by more than the tolerance for a few steps.
#: Figures that average over the run (the bolt's rate and turns, the mean grasp force) stay within the
#: integrator tolerance of each other; a peak of the impact force does not (it is the value at one step, which
#: a split moves), so ``screw_force_N_max`` is reported, not compared. A split step changes a figure by about
#: the scene's time-discretization error, which bench_baseline.py estimates by the same scene at half the step
#: (``half_dt``) and allows in the comparison.
IMPACT_FIGURES = {"suzumori_gripper": {"revolutions_per_second": 1e-5, "bolt_turns": 1e-4, "grasp_force_N": 1e-4}}


#: Demos whose scene changed since the baseline (issue 26: the wavy wall's free start, approach and set-point switch;
#: the gripper's static grasps and the seed's bolt damping): both trees run the baseline's demo file, so the two
#: runs time and compare the same scene on the two libraries.
BASELINE_SCENE = {"wavy_wall", "suzumori_gripper"}
BASELINE_TREE = Path(__file__).resolve().parents[2] / "out" / "bench" / "baseline-647fbf9"


#: The baseline's scenes drive their inputs by Python functions of time only (the gripper's chamber pressures, a
#: ``lambda m: {...}`` of ``m.t``; the wall's impedance set-point, a function ``t -> (x, z)``): this tree, whose
#: Schedule runs inside the compiled network, plays the same functions as Schedule tables sampled every
#: ``TABLE_DT`` on [0, ``TABLE_HORIZON``] (linear interpolation: within dt^2/8 max|u''|, 2 Pa of the gripper's
#: 160 kPa at its 2 Hz circle), so the two trees run the same scene, the baseline in Python (it has no compiled
#: form) and this tree compiled; without this a Python callable keeps this tree on its Python path too
#: (issue 18c: suzumori 0.042x, wavy wall 0.27x real time).
TABLE_DT, TABLE_HORIZON = 5e-4, 10.0
#: The path and Newton statistics of every ``Model.simulate`` run under :func:`_time_tables`.
RUNS = []


class _ReadsState(Exception):
    """A controller read more of the model than its time."""


class _OnlyTime:
    """What a time-only controller may read of the model: ``t`` (anything else raises :class:`_ReadsState`)."""

    def __init__(self, t):
        self.t = t

    def __getattr__(self, name):
        raise _ReadsState(name)

    def __getitem__(self, key):
        raise _ReadsState(key)


def _time_tables(put=setattr):
    """Make this process's ``Model.set_controller`` and ``control.impedance`` turn Python functions of time only
    into :class:`~soroshapes.network.Schedule` tables (this tree only: the baseline has no Schedule). A controller
    that reads more than ``t`` (:class:`_OnlyTime`) is left as it is; ``simulate`` past the
    table's horizon raises. ``put``: how to set the patched attributes (a test passes pytest's
    ``monkeypatch.setattr``)."""
    import soroshapes.control as control
    import soroshapes.model as model
    from soroshapes.network import Schedule
    set_controller, impedance, simulate = model.Model.set_controller, control.impedance, model.Model.simulate

    def sampled(fn):
        n = int(round(TABLE_HORIZON / TABLE_DT))
        t = np.linspace(0.0, TABLE_HORIZON, n + 1)
        rows = [fn(ti) for ti in t]
        if isinstance(rows[0], dict):
            return Schedule(t, {k: np.array([np.ravel(r[k]) for r in rows]) for k in rows[0]})
        return Schedule(t, np.array([np.ravel(r) for r in rows]))

    def patched_set_controller(self, controller, *args, **kw):
        if callable(controller) and not isinstance(controller, Schedule) and not hasattr(controller, "reads"):
            try:
                controller(_OnlyTime(0.0))
            except _ReadsState:                # reads the state: stays a Python controller
                pass
            else:
                fn = controller
                controller = sampled(lambda t: fn(_OnlyTime(t)))
        return set_controller(self, controller, *args, **kw)

    def patched_impedance(*args, setpoint=None, **kw):
        if callable(setpoint) and not isinstance(setpoint, Schedule):
            setpoint = sampled(setpoint)
        return impedance(*args, setpoint=setpoint, **kw)

    def patched_simulate(self, t_end, dt, *args, t0=0.0, **kw):
        if t0 + t_end > TABLE_HORIZON + 1e-12:
            raise ValueError(f"baseline_scenes: a time table holds to {TABLE_HORIZON} s, the run goes to "
                             f"{t0 + t_end} s: raise TABLE_HORIZON")
        tr = simulate(self, t_end, dt, *args, t0=t0, **kw)
        RUNS.append({k: v if isinstance(v, str) else int(v) for k, v in tr.stats.items()
                     if k in ("path", "steps", "newton_iterations", "cut_steps", "jacobians")})
        return tr
    put(model.Model, "set_controller", patched_set_controller)
    put(control, "impedance", patched_impedance)
    put(model.Model, "simulate", patched_simulate)


def _quick_demo(name):
    def run(tree):
        if name in BASELINE_SCENE and Path(tree).resolve() != BASELINE_TREE.resolve():
            _time_tables()
        demo = _demo(BASELINE_TREE if name in BASELINE_SCENE else tree, name)
        with tempfile.TemporaryDirectory() as tmp:       # warm up: the first call loads (or compiles) the
            demo.main(Path(tmp), quick=True)              # kernels, 0.15 s of suzumori's 0.82 s (cold start is
        RUNS.clear()                                      # measured by bench_baseline's cold-start test)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            report = demo.main(Path(tmp), quick=True)
            wall = time.perf_counter() - t0
        sim = report.get("simulated_s")
        wall_sim = report.get("wall_time_s_sim", wall)
        figures = {k: v for k, v in report.items()       # the demo's results, not its solver statistics
                   if isinstance(v, (int, float)) and not isinstance(v, bool) and "time" not in k
                   and "real_time" not in k and "wall" not in k and "iterations" not in k}
        result = {"wall_s": wall_sim, "simulated_s": sim, "figures": figures}
        if RUNS:
            result["runs"] = list(RUNS)
        if name in IMPACT_FIGURES:
            compared = IMPACT_FIGURES[name]
            result["figures"] = {k: v for k, v in figures.items() if k in compared}
            result["resolution"] = compared
            result["reported"] = {k: v for k, v in figures.items() if k not in compared}
        return result
    run.__doc__ = (f"demos/{name}.py in its quick mode, the second run of the process (the simulation's wall time "
                   "from its report).")
    return run


def cold_start(tree):
    """The first statics and the first simulate of this process (kernels compiled or loaded from the cache)."""
    t0 = time.perf_counter()
    from sorofem import materials, sdf
    from soroshapes import Basis, Shapes
    shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)).add_gravity()
    t1 = time.perf_counter()
    q = shp.statics()
    t2 = time.perf_counter()
    tr = shp.simulate(0.01, 1e-3, q0=q)
    t3 = time.perf_counter()
    return {"wall_s": t3 - t1, "simulated_s": None, "figures": {"tip": tr.tip[-1].tolist()},
            "import_and_build_s": t1 - t0, "statics_s": t2 - t1, "simulate_s": t3 - t2}


#: True when this tree runs with the baseline's discretization (a quadrature option): scenes whose settings
#: changed since the baseline (soft_hand) then run the baseline's.
SAME_MODEL = False

SCENES = {"rod15": rod15, "soft_hand": soft_hand, "suzumori_gripper": _quick_demo("suzumori_gripper"),
          "wavy_wall": _quick_demo("wavy_wall"), "cold_start": cold_start}

def _quadrature(name):
    """Make ``name`` the default quadrature of every Shapes built in this process (this tree only: the baseline
    has the trapezoidal rule and no such keyword)."""
    import soroshapes.shapes as shapes
    init = shapes.Shapes.__init__

    def patched(self, *args, **kw):
        kw.setdefault("quadrature", name)
        init(self, *args, **kw)
    shapes.Shapes.__init__ = patched


def _half_dt():
    """Run every Model.simulate of this process at half the step it asks for (this tree only: the estimate of a
    scene's time-discretization error)."""
    import soroshapes.model as model
    simulate = model.Model.simulate

    def patched(self, t_end, dt, *args, **kw):
        return simulate(self, t_end, 0.5 * dt, *args, **kw)
    model.Model.simulate = patched


if __name__ == "__main__":
    scene, out, tree = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
    for option in sys.argv[4:]:
        if option == "half_dt":
            _half_dt()
        else:
            _quadrature(option)
            SAME_MODEL = True
    result = SCENES[scene](tree)
    out.write_text(json.dumps(result))
