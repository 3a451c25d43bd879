"""Speed of trees of bodies (soroshapes.tree), one core.

The manipulator with its three-finger gripper as one tree: a soft arm (Chebyshev(3) in both bendings, 0.2 m), a
rigid palm glued to its tip (20 g), three soft fingers (Chebyshev(2) in both bendings, 50 mm) on the palm at
120 degrees, 18 coordinates, released under gravity; implicit midpoint of the Model integrators at dt = 1 ms for
0.2 s: the tree block inside the compiled network kernel (soroshapes.network's TREE block, one compiled call
over the tree, soroshapes._treeblock) against the Python path with a compiled call per body (compiled=False,
what this benchmark ran before), in the same run; wall and CPU time. Figures, in one run: the real-time factor,
and against the arm alone (a one-body tree on the same path) the ratio of simulation costs; the tree's forward
dynamics and (M, C, f_g) evaluations per second, and (M, C, f_g) of the arm alone as a Shapes (the beam's
compiled kernels) as the baseline ratio. Correctness of what was timed is asserted (finite states, energy kept
to 1e-3 of the exchanged energy), never a time.

The manipulator_pick demo's scene (demos/manipulator_pick.py: the three-bellow manipulator with its hub and three
fingers as one tree, 8 coordinates, a 45 g cylinder on the table held by the fingers' contact; BDF2, dt = 2 ms,
rtol 1e-2 as the demo): the whole quick run (4.2 s) on the compiled network (the tree block with the tree contact
as a compiled term) and its first 0.6 s (closing on the cylinder) on both paths, for the Python path's real-time
factor and the difference of the two trajectories (recorded: at the demo's rtol = 1e-2 the two paths' Newton
stopping rules part the fingers' stick-slip; tests/soroshapes/test_rigid.py holds the compiled tree contact to the
Python path at rtol 1e-8).
"""
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import importlib.util  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from sorofem import materials, sdf  # noqa: E402
from soroshapes import Basis, Shapes, lie  # noqa: E402
from soroshapes.tree import Tree  # noqa: E402

MAT = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)


def arm():
    return Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.008), material=MAT,
                  damping=0.0, segments=6)


def manipulator_with_gripper():
    tree = Tree(gravity=(0.0, 0.0, -9.81)).add_beam("arm", arm())
    tree.add_link("palm", 0.02, [4e-6, 4e-6, 6e-6], com=(0.005, 0, 0), parent="arm")
    for k in range(3):
        off = np.eye(4)
        off[:3, :3] = lie.expSO3(np.array([2 * np.pi * k / 3, 0.0, 0.0])) @ lie.expSO3(np.array([0.0, 0.5, 0.0]))
        off[:3, 3] = lie.expSO3(np.array([2 * np.pi * k / 3, 0.0, 0.0])) @ np.array([0.01, 0.012, 0.0])
        tree.add_beam(f"finger{k}", Shapes(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), length=0.05,
                                           section=sdf.Circle(0.004), material=MAT, damping=0.0, segments=4),
                      parent="palm", offset=off)
    return tree


def _rate(fn, calls, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, time.perf_counter() - t0)
    return calls / best


def _run(tree, t_sim, compiled=True):
    """(best wall time [s] of two runs, its CPU time [s], the trajectory, the energy drift)."""
    tree.simulate(0.003, 1e-3, compiled=compiled)            # warm up
    wall = cpu = np.inf
    for _ in range(2):
        t0, c0 = time.perf_counter(), time.process_time()
        tr = tree.simulate(t_sim, 1e-3, record_every=10, compiled=compiled)
        wall, cpu = min(wall, time.perf_counter() - t0), min(cpu, time.process_time() - c0)
    assert np.all(np.isfinite(tr.q))
    drift = float(np.abs(tr.total - tr.total[0]).max() / tr.kinetic.max())
    assert drift < 1e-3
    return wall, cpu, tr, drift


def test_bench_manipulator_with_gripper(record):
    tree = manipulator_with_gripper()
    assert tree.n == 18
    t_sim = 0.2
    wall, cpu, tr, drift = _run(tree, t_sim)
    wall_py, cpu_py, tr_py, _ = _run(tree, t_sim, compiled=False)       # the per-body path of before
    alone, _, _, _ = _run(Tree(gravity=(0.0, 0.0, -9.81)).add_beam("arm", arm()), t_sim)   # same path, arm only
    rng = np.random.default_rng(0)
    q, qd = rng.normal(size=tree.n), rng.normal(size=tree.n)
    shp = arm().add_gravity()
    qa, qda = q[:6].copy(), qd[:6].copy()
    tree_rate = _rate(lambda: tree.coriolis(q, qd), 300)
    fd_rate = _rate(lambda: tree.forward_dynamics(q, qd), 300)
    beam_rate = _rate(lambda: shp.dynamics(qa, qda), 300)
    record(dofs=tree.n, dt=1e-3, simulated_s=t_sim, wall_s=round(wall, 3), cpu_s=round(cpu, 3),
           realtime_factor=round(t_sim / wall, 3), realtime_factor_cpu=round(t_sim / cpu, 3),
           per_body_path_realtime_factor=round(t_sim / wall_py, 3),
           per_body_path_realtime_factor_cpu=round(t_sim / cpu_py, 3),
           speedup_cpu=round(cpu_py / cpu, 2), speedup_wall=round(wall_py / wall, 2),
           paths_max_q_difference=float(np.abs(tr.q - tr_py.q).max()),
           newton_iterations_per_step=round(tr.stats["newton_iterations"] / tr.stats["steps"], 2),
           jacobians=tr.stats["jacobians"],
           energy_drift=drift, arm_alone_realtime_factor=round(t_sim / alone, 3),
           cost_ratio_simulation_tree_to_arm=round(wall / alone, 2), tree_forward_dynamics_per_s=round(fd_rate),
           tree_m_c_fg_per_s=round(tree_rate), arm_alone_m_c_fg_per_s=round(beam_rate),
           cost_ratio_tree_to_arm=round(beam_rate / tree_rate, 2), path=tr.stats.get("path"),
           per_body_path=tr_py.stats.get("path"))


def _manipulator_scene(until):
    """The manipulator_pick demo's network up to ``until`` [s] of its quick schedule: (model, T, dt)."""
    from soroshapes import Model
    from soroshapes.network import Schedule
    from soroshapes.rigid import TreeContact, couple_ground, couple_tree_contact
    spec = importlib.util.spec_from_file_location(
        "manipulator_pick", Path(__file__).resolve().parents[2] / "demos" / "manipulator_pick.py")
    d = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(d)
    prm = dict(d.QUICK)
    keys = [k for k in d.schedule(prm["approach"]) if k[0] <= until]
    T = keys[-1][0]
    tree, _ = d.robot()
    q0 = d.statics(tree, d.inputs(keys[0][1:]))
    mdl = Model().add(tree.system(name="robot", q0=q0, force_inputs=True))
    mdl.add(d.cylinder())
    couple_ground(mdl, "cylinder", d.rim(), stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    couple_tree_contact(mdl, "robot", "cylinder", TreeContact(tree, d.finger_points(tree), d.K_PAD, d.C_PAD,
                                                              prm["friction"], d.EPS))
    drive = Schedule.sample(lambda t: d.inputs(d.pressures(keys, t)), T, d.DRIVE_TABLE_DT)
    mdl.set_controller(Schedule(drive.times, {"robot": drive.values}))
    return mdl, T, prm["dt"]


def _timed(mdl, T, dt, compiled):
    t0, c0 = time.perf_counter(), time.process_time()
    tr = mdl.simulate(T, dt, "bdf2", rtol=1e-2, atol=1e-5, record_every=5, compiled=compiled)
    return time.perf_counter() - t0, time.process_time() - c0, tr


def test_bench_manipulator_pick_scene(record):
    mdl, T, dt = _manipulator_scene(10.0)
    mdl.simulate(0.01, dt, "bdf2", rtol=1e-2, atol=1e-5, compiled=True)       # warm up (kernels)
    wall, cpu, tr = _timed(mdl, T, dt, True)
    assert tr.stats["path"] == "compiled" and np.all(np.isfinite(tr.x))
    lift = float(tr["cylinder"].x[:, 2].max() - tr["cylinder"].x[0, 2])
    assert lift > 0.04                                  # the cylinder was picked up (the demo's lift, 60 mm)
    short = [_timed(*_manipulator_scene(0.6), c) for c in (True, False)]
    (wc, cc, tc), (wp, cp, tp) = short
    assert tp.stats["path"] == "python"
    # the two paths stop Newton by different rules; at the demo's rtol = 1e-2 the fingers' stick-slip can make their
    # trajectories part (recorded, not asserted: test_rigid's tree-contact test holds them to 1e-9 at rtol 1e-8;
    # session 10: 0.09 in a finger coordinate over 0.6 s; session 11, with the tree's model rows: 2.6e-5)
    n = tc["robot"].x.shape[1] // 2
    diff_q = float(np.abs(tc["robot"].x[:, :n] - tp["robot"].x[:, :n]).max())
    diff_cyl = float(np.abs(tc["cylinder"].x[:, :3] - tp["cylinder"].x[:, :3]).max())
    diff = float(np.abs(tc.x - tp.x).max() / np.abs(tp.x).max())
    st = tr.stats
    # evaluations per step by kind: Newton sweeps (the whole network), model-row refreshes of the tree and the
    # cylinder (each differences the contact and ground terms over the component's 34 columns, not the tree's
    # dynamics: _treeblock.block_model_rows) and differenced Jacobians (each 35 evaluations of the whole network)
    record(simulated_s=T, dt=dt, wall_s=round(wall, 3), cpu_s=round(cpu, 3),
           realtime_factor=round(T / wall, 3), realtime_factor_cpu=round(T / cpu, 3), path=st["path"],
           newton_iterations_per_step=round(st["newton_iterations"] / st["steps"], 2), jacobians=st["jacobians"],
           matrices=st["matrices"], matrices_per_step=round(st["matrices"] / st["steps"], 3),
           jacobians_per_step=round(st["jacobians"] / st["steps"], 3), steps=st["steps"], cut_steps=st["cut_steps"], model_matrix_failures=st["model_matrix_failures"],
           lift_mm=round(lift * 1e3, 2), closing_simulated_s=0.6,
           closing_realtime_factor_compiled=round(0.6 / wc, 3), closing_realtime_factor_cpu_compiled=round(0.6 / cc, 3),
           closing_realtime_factor_python=round(0.6 / wp, 3), closing_realtime_factor_cpu_python=round(0.6 / cp, 3),
           closing_paths_max_difference_relative=diff, closing_paths_max_coordinate_difference=diff_q,
           closing_paths_max_cylinder_position_difference_m=diff_cyl, load_average=round(os.getloadavg()[0], 2))
