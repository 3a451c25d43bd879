"""Cost of the crawler demo's dynamics (2D hyperelastic FEM, generalized-alpha, pressure signals, floor contact
with friction): wall time per simulated second at the demo's mesh and step, Newton iterations per step, and
where the time goes.

The demo's full settings (its problem with the seed's code parameters, element size 2 mm, P2, dt = 2 ms, rho_inf =
0.8) over 0.2 s of the gait (100 steps). Time is split by wrapping the pieces of the Newton iteration: residual assembly
(``NewtonSolver.assemble_residual``), tangent assembly (``assemble_jacobian``), the contact's own work inside
them (``Contact.subtract`` for the forces, ``Contact.add_tangent`` for the tangent blocks; included in the
assembly figures and also reported alone), and the linear solve (MUMPS LU: time inside
``NewtonSolver.solve`` minus assembly). Asserted: the run converged every step (no cut), the floor carries
weight. Never a time.
"""
import importlib.util
import math
import time
from pathlib import Path

import numpy as np

DEMO = Path(__file__).resolve().parents[2] / "demos" / "crawler.py"


def test_bench_crawler(record):
    from sorofem.fem import contact, newton
    from sorofem.units import mm

    spec = importlib.util.spec_from_file_location("crawler_demo", DEMO)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    fem, msh = demo.crawler_problem(2 * mm)   # the demo's problem at its full mesh
    dofs = fem.num_dofs

    timers = {"residual": 0.0, "tangent": 0.0, "newton": 0.0, "contact_forces": 0.0, "contact_tangent": 0.0,
              "iterations": 0}
    wrapped = [(newton.NewtonSolver, "assemble_residual", "residual"), (newton.NewtonSolver, "assemble_jacobian",
               "tangent"), (newton.NewtonSolver, "solve", "newton"), (contact.Contact, "subtract", "contact_forces"),
               (contact.Contact, "add_tangent", "contact_tangent")]
    orig = {(cls, name): getattr(cls, name) for cls, name, _ in wrapped}

    def timed(cls, name, key):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return orig[(cls, name)](*a, **k)
            finally:
                timers[key] += time.perf_counter() - t
                if key == "tangent":
                    timers["iterations"] += 1
        return wrapper
    for cls, name, key in wrapped:
        setattr(cls, name, timed(cls, name, key))
    try:
        t_end, dt = 0.2, 2e-3
        t0 = time.perf_counter()
        traj = fem.simulate(t_end=t_end, dt=dt, rho_inf=0.8)
        wall = time.perf_counter() - t0
    finally:
        for (cls, name), fn in orig.items():
            setattr(cls, name, fn)
    steps = len(traj) - 1
    its = traj.newton_iterations[1:]
    assert steps == round(t_end / dt), "a step was cut"
    assert np.abs(traj.reactions["contact_0"][:, 1]).max() > 0
    assembly = timers["residual"] + timers["tangent"]
    solve = timers["newton"] - assembly
    record(dofs=int(dofs), cells=int(msh.num_cells), dt_ms=dt * 1e3, steps=steps,
           wall_per_simulated_s=round(wall / t_end, 2), wall_per_step_s=round(wall / steps, 4),
           newton_iterations_per_step_mean=round(float(its.mean()), 2), newton_iterations_per_step_max=int(its.max()),
           share_residual_assembly=round(timers["residual"] / wall, 3),
           share_tangent_assembly=round(timers["tangent"] / wall, 3),
           share_linear_solve=round(solve / wall, 3),
           share_contact=round((timers["contact_forces"] + timers["contact_tangent"]) / wall, 3),
           share_outside_newton=round(1 - timers["newton"] / wall, 3),
           per_iteration_ms=round(1e3 * timers["newton"] / max(timers["iterations"], 1), 2),
           periods_per_wall_hour=round(3600 / (wall / t_end) / (2 * math.pi / demo.OMEGA), 1))


def test_bench_crawler_pressure_maximum(record):
    """Why the earlier section ballooned at the seed's paper amplitude: the static pressure maximum of the back
    segment (Fem.follow through the limit point, feet clamped, the seed's paper materials Ecoflex 00-50 / Dragon
    Skin 30) of the earlier thin-walled section (pockets 6 x 6 mm, 2 mm walls) lies below the paper's A = 45 kPa,
    the demo's section's above it. Element size 3 mm (the quick mesh)."""
    from sorofem.units import kPa, mm

    spec = importlib.util.spec_from_file_location("crawler_demo", DEMO)
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    amplitude = demo.SEEDS["paper"]["amplitude"]
    thin, _ = demo.pressure_maximum(3 * mm, demo.crawler_section((6 * mm, 6 * mm), 2 * mm, 2 * mm), seed="paper")
    ours, _ = demo.pressure_maximum(3 * mm, seed="paper")
    assert thin < amplitude < ours
    record(amplitude_kPa=amplitude / kPa, thin_walled_pressure_maximum_kPa=round(thin / kPa, 2),
           demo_section_pressure_maximum_kPa=round(ours / kPa, 2))
