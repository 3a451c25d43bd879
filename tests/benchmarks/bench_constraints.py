"""Cost of constrained dynamics (soroshapes.constraints): the parallel robot demo's real-time factor and where
the constrained step spends its time.

1. The demo's robot (three rods of 10 coordinates welded to a platform: 36 coordinates, 18 multipliers) from its
   tilted pose after the lateral kick, 2 s at the demo's step (5 ms): real-time factor on the wall clock and on
   the process's CPU clock (the CPU figure is what the code costs; the wall figure includes the machine's
   load), milliseconds and Newton iterations per step, and the shares of the step's time in the bodies' terms
   (``motion_terms``: M, C, forces of each body), the bodies' iteration matrices, the constraint rows
   (``ConstraintSet.residual``/``jacobian``) and the velocity projection.
2. The constrained step against the unconstrained one, in one run: a single rod clamped at its tip
   (Weld, 6 multipliers) against the same rod free on the same Python path (a zero user force selects it)
   and against its compiled path, per step.

Asserted: every step converged at the given step (none cut), drift below 1e-6 m. Never a time.
"""
import importlib.util
import time
from pathlib import Path

import numpy as np

DEMO = Path(__file__).resolve().parents[2] / "demos" / "parallel_robot.py"


def _demo():
    spec = importlib.util.spec_from_file_location("parallel_robot_demo", DEMO)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    return demo


def test_bench_parallel_robot(record):
    from soroshapes import constraints

    demo = _demo()
    pose = demo.solve_pose(demo.POSES[2])
    robot = pose["robot"]
    asm = robot["assembly"]
    qd0 = np.zeros(asm.n)
    qd0[-3] = demo.KICK
    asm.simulate(0.02, 5e-3, pose["q"], qd0, constraints=robot["welds"])        # warm the caches

    timers = {"motion_terms": 0.0, "iteration_matrix": 0.0, "constraint_rows": 0.0, "projection": 0.0}
    wrapped = [(constraints.BeamBody, "motion_terms", "motion_terms"),
               (constraints.RigidLink, "motion_terms", "motion_terms"),
               (constraints.BeamBody, "iteration_matrix", "iteration_matrix"),
               (constraints.RigidLink, "iteration_matrix", "iteration_matrix"),
               (constraints.ConstraintSet, "residual", "constraint_rows"),
               (constraints.ConstraintSet, "jacobian", "constraint_rows"),
               (constraints.Assembly, "_project", "projection")]
    orig = {(cls, name): cls.__dict__[name] for cls, name, _ in wrapped}

    def timed(fn, key):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers[key] += time.perf_counter() - t
        return wrapper
    t_end, dt = 2.0, 5e-3
    for cls, name, key in wrapped:
        setattr(cls, name, timed(orig[(cls, name)], key))
    try:
        c0, w0 = time.process_time(), time.perf_counter()
        tr = asm.simulate(t_end, dt, pose["q"], qd0, constraints=robot["welds"])
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    finally:
        for (cls, name), fn in orig.items():
            setattr(cls, name, fn)
    steps = int(tr.stats["steps"])
    its = tr.stats["newton_iterations_by_step"]
    assert len(its) == steps, "a step was cut"
    assert tr.drift_position.max() < 1e-6 and tr.drift_rotation.max() < 1e-6
    # the projection calls mass_matrix and jacobian inside: its share includes those rows
    record(coordinates=int(asm.n), multipliers=18, dt_ms=dt * 1e3, steps=steps,
           real_time_factor_wall=round(t_end / wall, 4), real_time_factor_cpu=round(t_end / cpu, 4),
           ms_per_step_wall=round(1e3 * wall / steps, 2), ms_per_step_cpu=round(1e3 * cpu / steps, 2),
           newton_iterations_per_step_mean=round(float(np.mean(its)), 2), newton_iterations_max=int(np.max(its)),
           share_motion_terms=round(timers["motion_terms"] / wall, 3),
           share_iteration_matrices=round(timers["iteration_matrix"] / wall, 3),
           share_constraint_rows=round(timers["constraint_rows"] / wall, 3),
           share_velocity_projection=round(timers["projection"] / wall, 3),
           drift_max_m=float(tr.drift_position.max()))


def test_bench_constrained_step_against_free(record):
    from sorofem import materials, sdf
    from soroshapes import Basis, Shapes
    from soroshapes.constraints import Weld

    def rod(python_path):
        shp = Shapes(Basis.chebyshev(4), dofs=(1, 4, 4, 1, 0, 0), length=0.15, section=sdf.Circle(3e-3),
                     material=materials.NeoHookean(E=20e6, nu=0.45, density=1200.0), damping=2e-3, segments=20)
        shp.add_gravity((0.0, 0.0, -9.81))
        if python_path:
            shp.add_force(lambda s, q, qd, t: np.zeros(s.n))
        return shp
    t_end, dt = 0.5, 5e-3
    qd0 = np.zeros(10)
    qd0[2] = 1.0                                 # a bending rate: the rod vibrates
    figures = {}
    for name, shp, kw in (("clamped_python", rod(False), dict(constraints=[Weld()])),
                          ("free_python", rod(True), {}), ("free_compiled", rod(False), {})):
        shp.simulate(0.02, dt, qd0=qd0, **kw)                                   # warm the caches
        c0 = time.process_time()
        tr = shp.simulate(t_end, dt, qd0=qd0, **kw)
        cpu = time.process_time() - c0
        assert len(tr.t) == round(t_end / dt) + 1
        if kw:
            assert tr.drift_position.max() < 1e-6
        figures[name] = cpu / round(t_end / dt)
    record(ms_per_step_cpu={k: round(1e3 * v, 3) for k, v in figures.items()},
           constrained_over_free_python=round(figures["clamped_python"] / figures["free_python"], 2),
           constrained_over_free_compiled=round(figures["clamped_python"] / figures["free_compiled"], 1))
