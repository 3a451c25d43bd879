"""Speed of the Cosserat beam model (soroshapes.Shapes), one core.

Targets (issue): FK + Jacobian + M + C evaluations per second for 6 DOF and 50 quadrature points >= 20 000/s
(the matrices M and C assembled; also reported: the matrix-free inverse dynamics M qdd + C qd + K q - f_g
that the integrator evaluates);
real-time factor of a 15-DOF rod at dt = 1 ms >= 100x; IK solves per second for 3 DOF >= 5 000/s. Each
figure is measured in one run, best of a few warm repetitions, and printed; correctness of what was timed is
asserted (never a time). The side by side with PyElastica and MuJoCo is in ``peers/bench_peers.py``.
"""
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

from sorofem import materials, sdf  # noqa: E402
from soroshapes import Basis, Shapes  # noqa: E402

MAT = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)


def _rate(fn, calls, repeat=5):
    """Best calls per second of ``fn`` over ``repeat`` batches of ``calls``."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, time.perf_counter() - t0)
    return calls / best


def test_bench_dynamics_terms_per_second(record):
    """50 quadrature points: 25 Magnus segments of order 4 (two Gauss points each; M and C summed at the 26
    nodes); also the order-2 layout with 49 segments (50 nodes), and the matrix-free inverse dynamics."""
    figures = {}
    for order, segments in ((4, 25), (2, 49)):
        shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                     material=MAT, damping=0.0, segments=segments, order=order)
        rng = np.random.default_rng(0)
        q, qd, qdd = 5 * rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
        M, C, fg = shp.dynamics(q, qd)
        assert np.all(np.linalg.eigvalsh(M) > 0)
        assert np.allclose(shp.inverse_dynamics(q, qd, qdd), M @ qdd + C @ qd + shp.K @ q - fg)
        figures[f"order{order}_segments{segments}"] = {
            "fk_j_m_c_per_s": round(_rate(lambda: shp.dynamics(q, qd), 2000)),
            "fk_per_s": round(_rate(lambda: shp.forward_kinematics(q), 2000)),
            "fk_j_inverse_dynamics_per_s": round(_rate(lambda: shp.inverse_dynamics(q, qd, qdd), 2000))}
    best = figures["order4_segments25"]["fk_j_m_c_per_s"]
    record(dofs=6, quadrature_points=50, **figures, target=20000, met=bool(best >= 20000))


def _rod15(segments, order):
    """The 15-DOF rod: torsion and two bendings, 5 Chebyshev modes each, released straight under gravity."""
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=MAT, damping=0.0, segments=segments, order=order)
    return shp.add_gravity()


#: The rod's discretization, chosen by error (:func:`test_bench_rod15_discretization_error`): 4 segments of
#: Magnus order 4 (1.2 % tip-trajectory error over 1 s against a converged model) instead of the 10 segments of
#: order 2 the bench used before (3.6 %), at about 0.6 of its cost.
ROD15 = (4, 4)


def test_bench_realtime_factor_15_dof(record):
    """The 15-DOF rod, undamped, implicit midpoint at dt = 1 ms and the default Newton tolerance (1e-8), 1 s:
    with its discretization (``ROD15``) and with the former one (10 segments of order 2), in one run."""
    t_sim, figures = 1.0, {}
    for segments, order in (ROD15, (10, 2)):
        shp = _rod15(segments, order)
        assert shp.n == 15
        shp.simulate(0.01, 1e-3)                      # warm up
        wall = cpu = np.inf
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            tr = shp.simulate(t_sim, 1e-3, record_every=100)
            wall, cpu = min(wall, time.perf_counter() - t0), min(cpu, time.process_time() - c0)
        assert np.all(np.isfinite(tr.q)) and tr.tip[-1, 2] < 0
        drift = abs(tr.total[-1] - tr.total[0]) / max(tr.kinetic.max(), 1e-300)
        assert drift < 1e-3
        figures[f"segments{segments}_order{order}"] = {
            "wall_s": round(wall, 4), "realtime_factor": round(t_sim / wall, 1), "us_per_step": round(wall * 1e3, 2),
            "realtime_factor_cpu_time": round(t_sim / cpu, 1),   # this process's CPU time: less load-dependent
            "newton_evaluations_per_step": float(tr.stats["newton_iterations_per_step"]),
            "matrix_refreshes": tr.stats["matrices"], "energy_drift": drift}
    best = figures["segments%d_order%d" % ROD15]["realtime_factor"]
    record(dofs=15, dt=1e-3, simulated_s=t_sim, **figures, target=100, met=bool(best >= 100))


def test_bench_rod15_discretization_error(record):
    """How fine the 15-DOF rod must be cut: the largest tip difference over 1 s (relative to the largest tip
    coordinate) of each discretization at dt = 1 ms against a converged reference (40 segments of order 4,
    dt = 0.1 ms, Newton tolerance 1e-11), split into its spatial part (the same discretization at dt = 0.1 ms
    against the reference) and its time-step part (dt = 1 ms against dt = 0.1 ms). Asserts that ``ROD15`` is no
    less accurate than the former 10 segments of order 2 (with Gregory's rule, or with the trapezoidal rule of
    the baseline) and that the time-step part is below the spatial part everywhere (so the discretization, not
    dt, sets the accuracy). Also reported: the trapezoidal rule at ``ROD15`` (the baseline's model of the
    bench_baseline scene)."""
    def tip(segments, order, dt, tol):
        return _rod15(segments, order).simulate(1.0, dt, tol=tol, record_every=round(1e-2 / dt)).tip

    def diff(a, b):
        return float(np.abs(a - b).max() / np.abs(b).max())
    ref = tip(40, 4, 1e-4, 1e-11)
    figures = {}
    for segments, order in ((10, 2), (10, 4), (5, 4), (4, 4), (3, 4)):
        coarse, fine = tip(segments, order, 1e-3, 1e-8), tip(segments, order, 1e-4, 1e-11)
        figures[f"segments{segments}_order{order}"] = {
            "total": diff(coarse, ref), "spatial": diff(fine, ref), "time_step": diff(coarse, fine)}
    for segments, order in (ROD15, (10, 2)):   # the trapezoidal rule of the pre-issue-18 code (bench_baseline)
        shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                     material=MAT, damping=0.0, segments=segments, order=order, quadrature="trapezoid")
        coarse = shp.add_gravity().simulate(1.0, 1e-3, record_every=10).tip
        figures[f"segments{segments}_order{order}_trapezoid"] = {"total": diff(coarse, ref)}
    chosen, former = figures["segments%d_order%d" % ROD15], figures["segments10_order2"]
    assert chosen["total"] <= min(former["total"], figures["segments10_order2_trapezoid"]["total"]), figures
    assert all(f["time_step"] < f["spatial"] for f in figures.values() if "spatial" in f), figures
    record(reference="40 segments, order 4, dt 1e-4 s, tol 1e-11", chosen="segments%d_order%d" % ROD15,
           **figures)


def test_bench_ik_solves_per_second(record):
    shp = Shapes(Basis.chebyshev(3), dofs=(0, 0, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=MAT, damping=0.0, segments=10)
    rng = np.random.default_rng(1)
    qs = rng.uniform(-8, 8, size=(200, 3))         # tip curls of up to about 1.6 rad
    targets = [shp.positions(q)[-1] for q in qs]
    q0 = np.zeros(3)
    results = [shp.inverse_kinematics(t, q0) for t in targets]
    ok = np.mean([r.converged for r in results])
    assert ok > 0.95
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for t in targets:
            shp.inverse_kinematics(t, q0)
        best = min(best, time.perf_counter() - t0)
    per_s = len(targets) / best
    record(dofs=3, solves_per_s=round(per_s), converged_fraction=float(ok),
           iterations_mean=float(np.mean([r.iterations for r in results])), target=5000, met=bool(per_s >= 5000))


def _finger_on_cylinder(python=False):
    """The finger of the contact test (tests/soroshapes/test_beam.py): 80 mm, R 6 mm, one chamber, gravity,
    pressed by the chamber onto a cylinder across its path (penalty 2e5 N/m^2, damping 20, friction 0.6); with
    ``python`` a zero user force sends it to the Python step loop (the path every contact took before)."""
    shp = Shapes(Basis.chebyshev(3), (0, 3, 3, 0, 0, 0), length=0.08, section=sdf.Circle(0.006),
                 material=materials.NeoHookean(E=1e6, nu=0.3, density=2000.0, damping=0.1), segments=12,
                 contact_radius=0.006)
    shp.add_chamber(np.pi * 0.0015 ** 2, (0.0, 0.003), name="c").add_gravity((0.0, 0.0, -9.81))
    shp.add_contact(sdf.Cylinder(0.01, 0.1, center=(0.06, 0.0, -0.02), axis=(0.0, 1.0, 0.0)), stiffness=2e5,
                    damping=20.0, friction=0.6, regularization=2e-3)
    return shp.add_force(lambda s, q, qd, t: np.zeros(s.n)) if python else shp


def test_bench_plant_with_contact_realtime_factor(record):
    """The simulated board's plant (:class:`sorocontrol.drivers.SimulatedPlant`, one channel) with a beam in
    contact: the finger above pressed onto the cylinder by a 0-200 kPa square wave (0.5 s period), stepped as
    the board steps it (one :meth:`apply` per 5 ms tick of a 200 Hz board, i.e. ``beam.simulate(5 ms, 5 ms)``
    per call), 2 s of plant time, wall and this process's CPU time: the compiled contact (issue 26) against
    the Python step loop that every contact took before, in one run."""
    from sorocontrol.drivers import SimulatedPlant
    t_sim, tick, figures, tips = 2.0, 5e-3, {}, {}
    for label, python in (("compiled", False), ("python_loop", True)):
        plant = SimulatedPlant(1, beam=_finger_on_cylinder(python))
        t0, c0 = time.perf_counter(), time.process_time()
        for k in range(1, int(round(t_sim / tick)) + 1):
            t = k * tick
            plant.apply([200e3 if (t % 0.5) < 0.25 else 0.0], t)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        tips[label] = plant.beam.positions(plant.q)[-1]
        figures[label] = {"wall_s": round(wall, 3), "cpu_s": round(cpu, 3), "realtime_factor": round(t_sim / wall, 3),
                          "realtime_factor_cpu_time": round(t_sim / cpu, 3)}
    assert np.abs(tips["compiled"] - tips["python_loop"]).max() < 1e-6     # the same plant
    record(simulated_s=t_sim, tick_s=tick, **figures,
           speedup_wall=round(figures["python_loop"]["wall_s"] / figures["compiled"]["wall_s"], 1),
           load_average_1min=round(os.getloadavg()[0], 2))
