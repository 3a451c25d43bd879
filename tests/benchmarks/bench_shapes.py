"""Speed of the Cosserat beam model (soroshapes.Shapes), one core.

Targets (issue): FK + Jacobian + M + C evaluations per second for 6 DOF and 50 quadrature points >= 20 000/s
(the matrices M and C assembled; also reported: the matrix-free inverse dynamics M qdd + C qd + K q - f_g
that the integrator evaluates);
real-time factor of a 15-DOF rod at dt = 1 ms >= 100x; IK solves per second for 3 DOF >= 5 000/s. Each
figure is measured in one run, best of a few warm repetitions, and printed; correctness of what was timed is
asserted (never a time).
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
    shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=MAT, damping=0.0, segments=49, order=2)
    assert len(shp.sigma) == 50
    rng = np.random.default_rng(0)
    q, qd = 5 * rng.normal(size=6), rng.normal(size=6)
    M, C, fg = shp.dynamics(q, qd)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    per_s = _rate(lambda: shp.dynamics(q, qd), 2000)
    fk = _rate(lambda: shp.forward_kinematics(q), 2000)
    qdd = rng.normal(size=6)
    assert np.allclose(shp.inverse_dynamics(q, qd, qdd), M @ qdd + C @ qd + shp.K @ q - fg)
    inv = _rate(lambda: shp.inverse_dynamics(q, qd, qdd), 2000)
    record(dofs=6, nodes=50, fk_j_m_c_per_s=round(per_s), fk_per_s=round(fk),
           fk_j_inverse_dynamics_per_s=round(inv), target=20000, met=bool(per_s >= 20000))


def test_bench_realtime_factor_15_dof(record):
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=0.2, section=sdf.Circle(0.005),
                 material=MAT, damping=0.0, segments=10, order=2)
    shp.add_gravity()
    assert shp.n == 15
    shp.simulate(0.01, 1e-3)                      # warm up
    t_sim = 1.0
    t0 = time.perf_counter()
    tr = shp.simulate(t_sim, 1e-3, record_every=100)
    wall = time.perf_counter() - t0
    assert np.all(np.isfinite(tr.q)) and tr.tip[-1, 2] < 0
    drift = abs(tr.total[-1] - tr.total[0]) / max(tr.kinetic.max(), 1e-300)
    rtf = t_sim / wall
    record(dofs=15, dt=1e-3, simulated_s=t_sim, wall_s=round(wall, 4), realtime_factor=round(rtf, 1),
           newton_iterations_mean=float(np.mean(tr.stats["newton_iterations"])), energy_drift=drift,
           target=100, met=bool(rtf >= 100))


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
