"""Validation of the Cosserat beam model (soroshapes.shapes) against closed-form mechanics and finite differences.

Tolerances: the basis spans constant strains exactly, so constant-curvature, helix and end-moment cases are
exact up to round-off (1e-9 relative); the elastica and Euler-Bernoulli references converge with the number of
modes (the tolerances are the issue's 0.5 % of length and 1 %); finite-difference checks use central
differences with step 1e-6 (truncation ~1e-12, round-off ~1e-10).
"""
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from sorofem import materials, sdf
from sorofem.errors import ConvergenceError, DataError, ParameterError
from soroshapes import Basis, Shapes, lie

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from analytic import cantilever_frequencies, elastica_tip  # noqa: E402

E, R, L, RHO = 1e6, 0.005, 0.2, 1000.0
EI = E * np.pi * R**4 / 4
MAT = materials.NeoHookean(E=E, nu=0.45, density=RHO)


def elastic(modulus):
    """The test material with another Young's modulus [Pa]."""
    return materials.NeoHookean(E=modulus, nu=0.45, density=RHO)


def rod(basis=None, dofs=(0, 0, 3, 0, 0, 0), **kw):
    kw = {"length": L, "section": sdf.Circle(R), "material": MAT, "damping": 0.0, **kw}
    return Shapes(basis or Basis.chebyshev(3), dofs, **kw)


def hat(xi):
    X = np.zeros((4, 4))
    X[:3, :3] = [[0, -xi[2], xi[1]], [xi[2], 0, -xi[0]], [-xi[1], xi[0], 0]]
    X[:3, 3] = xi[3:]
    return X


# --------------------------------------------------------------------------------------------------------
# kinematics
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("order", [2, 4])
def test_piecewise_constant_curvature_matches_the_closed_form(order):
    k = 3
    shp = rod(Basis.pcc(k), dofs=(0, k, k, 0, 0, 0), order=order, segments=6)
    q = np.array([8.0, -5.0, 12.0, 3.0, 9.0, -14.0])   # (ky_1..3, kz_1..3) [1/m]
    g = np.eye(4)
    for j in range(k):   # one exponential per section: the closed form of a constant-curvature arc
        g = g @ expm(hat(np.array([0, q[j], q[k + j], 1, 0, 0])) * L / k)
    assert np.allclose(shp.forward_kinematics(q)[-1], g, atol=1e-12)


@pytest.mark.parametrize("order", [2, 4])
def test_constant_torsion_and_curvature_trace_a_helix(order):
    kappa, tau = 30.0, 20.0
    shp = rod(Basis.chebyshev(1), dofs=(1, 0, 1, 0, 0, 0), order=order, segments=15)
    P = shp.positions(np.array([tau, kappa]))
    w2 = kappa**2 + tau**2
    axis = np.array([tau, 0.0, kappa]) / np.sqrt(w2)      # the helix axis: the (constant) angular strain
    radius, rise = kappa / w2, tau / np.sqrt(w2)            # radius and advance per unit arc length
    # the axis passes through the point p0 + (w x v)/|w|^2 (the screw's axis)
    c = np.cross(np.array([tau, 0.0, kappa]), [1.0, 0.0, 0.0]) / w2
    d = P - c
    along = d @ axis
    assert np.allclose(along, rise * shp.sigma, atol=1e-12)
    assert np.allclose(np.linalg.norm(d - np.outer(along, axis), axis=1), radius, atol=1e-12)


def test_end_moment_curls_the_rod_into_a_circle_and_beyond():
    for turns in (1.0, 1.25):   # total turning 2 pi and 2.5 pi
        shp = rod()
        Mz = 2 * np.pi * turns * EI / L
        shp.add_point_load(moment=[0, 0, Mz], frame="body")
        q = shp.statics(steps=4)
        kappa = Mz / EI
        tip = shp.positions(q)[-1]
        assert np.allclose(tip, [np.sin(kappa * L) / kappa, (1 - np.cos(kappa * L)) / kappa, 0], atol=1e-10 * L)
        assert np.allclose(q, [kappa, 0, 0], atol=1e-8 * kappa)


def test_magnus_orders_converge_at_their_rates():
    shp_ref = rod(Basis.chebyshev(4), dofs=(2, 4, 4, 0, 0, 0), segments=400)
    q = np.array([10.0, -6.0, 20.0, -15.0, 8.0, 5.0, -12.0, 9.0, 4.0, -3.0])
    ref = shp_ref.positions(q)[-1]
    for order, rate in ((2, 4.0), (4, 16.0)):
        errs = [np.linalg.norm(rod(Basis.chebyshev(4), dofs=(2, 4, 4, 0, 0, 0), segments=s, order=order)
                               .positions(q)[-1] - ref) for s in (10, 20)]
        assert errs[0] / errs[1] == pytest.approx(rate, rel=0.25)


@pytest.mark.parametrize("order", [2, 4])
def test_jacobians_and_their_rates_match_finite_differences(order):
    shp = rod(Basis.chebyshev(2), dofs=(2, 2, 2, 2, 2, 2), order=order, segments=8)
    rng = np.random.default_rng(1)
    q, qd = 3 * rng.normal(size=12), rng.normal(size=12)
    eps = 1e-6
    G0, J = shp.forward_kinematics(q), shp.jacobian(q, at="all")
    Gp, Gm = shp.forward_kinematics(q + eps * qd), shp.forward_kinematics(q - eps * qd)
    for i in range(len(G0)):
        twist = lie.vee6(np.linalg.solve(G0[i], (Gp[i] - Gm[i]) / (2 * eps)))
        assert np.allclose(J[i] @ qd, twist, atol=1e-9)
    Jd = shp.jacobian_rate(q, qd, at="all")
    fd = (shp.jacobian(q + eps * qd, at="all") - shp.jacobian(q - eps * qd, at="all")) / (2 * eps)
    assert np.allclose(Jd, fd, atol=1e-8)
    Js = shp.jacobian(q, frame="spatial")
    assert np.allclose(Js, lie.Ad(G0[-1]) @ J[-1])


def test_zero_and_tiny_coordinates_are_exact_and_continuous():
    shp = rod(Basis.chebyshev(3), dofs=(3, 3, 3, 3, 3, 3))
    P0 = shp.positions(np.zeros(18))
    assert np.array_equal(P0[:, 1:], np.zeros((len(P0), 2)))
    assert np.allclose(P0[:, 0], shp.sigma, atol=1e-15)
    q = 1e-12 * np.random.default_rng(2).normal(size=18)
    assert np.allclose(shp.jacobian(q, at="all"), shp.jacobian(np.zeros(18), at="all"), atol=1e-11)
    Jd = shp.jacobian_rate(q, np.ones(18), at="all")
    assert np.all(np.isfinite(Jd))


# --------------------------------------------------------------------------------------------------------
# statics
# --------------------------------------------------------------------------------------------------------
def test_tip_load_matches_the_elastica():
    P = 3 * EI / L**2                      # large deflection: the tip drops by about 0.6 L
    dx, dy = elastica_tip(L, EI, P)
    errors = []
    for k in (2, 4):
        shp = rod(Basis.chebyshev(k), dofs=(0, 0, k, 0, 0, 0)).add_point_load(force=[0, -P, 0])
        tip = shp.positions(shp.statics())[-1]
        errors.append(np.hypot(tip[0] - L - dx, tip[1] - dy) / L)
    assert errors[1] < 0.005 and errors[1] < errors[0] / 10


def test_twelve_modes_per_strain_stay_well_posed():
    b = Basis.chebyshev(12).orthonormalize(L)
    shp = rod(b, dofs=(0, 12, 12, 0, 0, 0), segments=40)
    P = 3 * EI / L**2
    shp.add_point_load(force=[0, -P, 0])
    tip = shp.positions(shp.statics())[-1]
    dx, dy = elastica_tip(L, EI, P)
    assert np.hypot(tip[0] - L - dx, tip[1] - dy) / L < 1e-4
    M = shp.mass_matrix(np.random.default_rng(0).normal(size=24))
    assert np.all(np.linalg.eigvalsh(M) > 0)


def test_chamber_pressure_and_tendon_tension_give_their_constant_curvatures():
    area, off, p, T = 2e-6, 0.002, 20e3, 0.5
    shp = rod().add_chamber(area, (off, 0.0)).add_tendon((off, 0.0))
    q = shp.statics(u=[p, 0.0])
    assert np.allclose(q, [-p * area * off / EI, 0, 0], rtol=1e-9, atol=1e-9)   # bends away from the chamber
    q = shp.statics(u=[0.0, T])
    assert np.allclose(q, [T * off / EI, 0, 0], rtol=1e-9, atol=1e-9)           # bends toward the tendon
    assert shp.inputs == ["chamber0", "tendon1"]


def test_gravity_sag_rests_on_a_floor_without_tunnelling():
    shp = rod(Basis.chebyshev(4), dofs=(0, 4, 0, 0, 0, 0), segments=20, material=elastic(1e5))
    floor = -0.03
    shp.add_gravity().add_contact(sdf.Plane((0, 0, floor), (0, 0, 1)))
    P = shp.positions(shp.statics(steps=4))
    assert P[:, 2].min() - R < floor                      # it touches
    assert floor - (P[:, 2].min() - R) < 0.01 * R          # and penetrates less than 1 % of the radius
    assert shp.contact_forces(shp.statics(steps=4))[:, 2].sum() > 0        # the floor pushes up


# --------------------------------------------------------------------------------------------------------
# dynamics
# --------------------------------------------------------------------------------------------------------
def test_small_deflection_frequencies_match_euler_bernoulli():
    shp = rod(Basis.chebyshev(6), dofs=(0, 0, 6, 0, 0, 0), segments=40)
    f = shp.natural_frequencies(3)
    ref = cantilever_frequencies(L, E, np.pi * R**4 / 4, RHO, np.pi * R**2)
    assert np.allclose(f, ref, rtol=0.01)


def test_mass_matrix_is_spd_and_mdot_minus_2c_is_skew():
    shp = rod(Basis.chebyshev(2), dofs=(2, 2, 2, 2, 2, 2), order=4)
    rng = np.random.default_rng(3)
    q, qd = 3 * rng.normal(size=12), rng.normal(size=12)
    M, C, _ = shp.dynamics(q, qd)
    assert np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() > 0
    eps = 1e-6
    Mdot = (shp.mass_matrix(q + eps * qd) - shp.mass_matrix(q - eps * qd)) / (2 * eps)
    S = Mdot - 2 * C
    assert np.abs(S + S.T).max() < 1e-8 * np.abs(S).max()


def test_undamped_motion_conserves_energy_over_ten_seconds():
    shp = rod(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), segments=8, material=elastic(1e5))
    shp.add_gravity()
    tr = shp.simulate(10.0, 1e-3, qd0=np.array([0.0, 0.0, 5.0, 0.0]), record_every=20)
    scale = tr.kinetic.max()                      # the energy exchanged between kinetic and potential
    assert abs(tr.total[-1] - tr.total[0]) / scale < 1e-3
    assert np.abs(tr.total - tr.total[0]).max() / scale < 5e-3
    assert tr.t[-1] == pytest.approx(10.0)


@pytest.mark.parametrize("modulus, gravity", [(1e3, False), (1e9, True)])
def test_implicit_steps_100x_the_explicit_limit_stay_stable(modulus, gravity):
    """A 1 kPa rod (free vibration: under gravity it would stretch by 200 %) and a 1 GPa rod under gravity, both
    stepped at 100 times the explicit stability limit set by their highest mode."""
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 0, 3, 0, 0), material=elastic(modulus))
    if gravity:
        shp.add_gravity()
    dt = 100 * shp.explicit_step_limit()
    tr = shp.simulate(40 * dt, dt, qd0=np.array([1.0, 0, 0, 0, 0, 0]) * 1e-3 / dt)
    assert np.all(np.isfinite(tr.q))
    assert tr.total.max() <= tr.total[0] + 0.01 * abs(tr.total[0])    # bounded: no growth beyond 1 %


def test_explicit_blow_up_is_reported_not_returned():
    """RK4 past its stability limit raises; the message names the limit (the value of explicit_step_limit, to the
    3 digits it prints) and the two fixes."""
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 0, 3, 0, 0))
    limit = shp.explicit_step_limit()
    dt = 20 * limit
    with pytest.raises(ConvergenceError, match="did not converge") as err:
        shp.simulate(200 * dt, dt, qd0=np.ones(6), method="explicit", min_dt=dt / 2)
    msg = str(err.value)
    assert f"below dt = {limit:.3g} s" in msg and f"use dt < {limit:.3g} s" in msg
    assert "method='implicit'" in msg and "explicit_step_limit" in msg
    assert shp.explicit_step_limit() == limit      # the query did not depend on the state the failure left


def test_contact_forces_follow_the_penalty_and_regularized_coulomb_laws():
    mu, eps, k, depth = 0.6, 1e-3, 2e5, 1e-4
    shp = rod(Basis.chebyshev(2), dofs=(0, 0, 2, 0, 0, 0), segments=10)
    shp.add_contact(sdf.Plane((0, 0, -R + depth), (0, 0, 1)), stiffness=k, friction=mu, regularization=eps)
    qd = np.array([3.0, 0.0])                  # the rod sweeps sideways (+y) over the floor it presses into
    F = shp.contact_forces(np.zeros(2), qd)
    vy = (shp.jacobian(np.zeros(2), at="all")[:, 3:] @ qd)[:, 1]   # node velocities (straight: body = spatial)
    fn = k * depth * shp.weights
    assert np.allclose(F[:, 2], fn, rtol=1e-9)
    assert np.all(vy[1:] > 0)
    assert np.allclose(F[:, 1], -mu * fn * vy / np.sqrt(vy**2 + eps**2), rtol=1e-9, atol=1e-15)
    assert np.all(F[1:, 1] < 0) and np.allclose(F[:, 0], 0, atol=1e-15)   # friction opposes the sliding


def test_contact_at_speed_does_not_tunnel_and_does_not_gain_energy():
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 0, 0, 0, 0), material=elastic(1e5), segments=20)
    shp.add_contact(sdf.Plane((0, 0, -0.02), (0, 0, 1)))
    qd0 = np.linalg.lstsq(shp.jacobian(np.zeros(3))[3:], [0.0, 0.0, -3.0], rcond=None)[0]  # tip at 3 m/s
    tr = shp.simulate(0.06, 1e-4, qd0=qd0, record_every=5)
    lowest = min(shp.positions(q)[:, 2].min() for q in tr.q)
    assert lowest - R < -0.02                       # it hit the floor
    assert -0.02 - (lowest - R) < 0.5 * R           # penetration stays below half the radius
    # The midpoint rule conserves the energy of quadratic potentials exactly; the penalty potential has a kink
    # where contact starts, which costs an O(dt) error per impact of either sign (measured up to 0.36 % over 20-40
    # segments and the three quadratures at this dt, 0.2 % with the trapezoidal rule at 40 segments). A contact force that injected energy (a
    # wrong-signed damping, a force lagging the motion) gains far more than this bound.
    assert tr.total.max() <= tr.total[0] * (1 + 5e-3)


# --------------------------------------------------------------------------------------------------------
# inverse kinematics
# --------------------------------------------------------------------------------------------------------
def test_inverse_kinematics_reaches_positions_and_poses():
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), segments=10)
    q_true = np.array([5.0, 2.0, 1.0, -3.0, 1.0, 0.5])
    G = shp.forward_kinematics(q_true)
    r = shp.inverse_kinematics(G[-1, :3, 3])
    assert r.converged and np.linalg.norm(shp.positions(r.q)[-1] - G[-1, :3, 3]) < 1e-8
    r = shp.inverse_kinematics([(shp.sigma[5], G[5, :3, 3]), (None, G[-1])])
    assert r.converged
    assert np.allclose(shp.forward_kinematics(r.q)[-1], G[-1], atol=1e-8)


def test_inverse_kinematics_subtask_prefers_low_strain_and_unreachable_targets_give_least_squares():
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), segments=10)
    target = np.array([0.12, 0.08, 0.05])
    free = shp.inverse_kinematics(target, q0=np.array([0, 0, 30.0, 0, 0, -30.0]))
    soft = shp.inverse_kinematics(target, q0=np.array([0, 0, 30.0, 0, 0, -30.0]), subtask="elastic",
                                  max_iterations=2000)
    assert free.converged and soft.error < 1e-6
    assert soft.q @ shp.K @ soft.q < 0.99 * free.q @ shp.K @ free.q
    far = shp.inverse_kinematics(np.array([2 * L, 0.0, 0.0]))
    assert not far.converged
    assert np.allclose(shp.positions(far.q)[-1], [L, 0, 0], atol=1e-6)


# --------------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, match", [
    ({"dofs": (0, 4, 0, 0, 0, 0)}, "only 3"),
    ({"dofs": (0, 3, 0)}, "6 non-negative"),
    ({"dofs": (0, 0, 0, 0, 0, 0)}, "no degrees of freedom"),
    ({"length": 0.0}, "positive number of metres"),
    ({"E": -1.0}, "Young's modulus"),
    ({"G": 0.0}, "shear modulus"),
    ({"order": 3}, "order must be 2 or 4"),
    ({"section": sdf.Sphere(0.01)}, "2D SDF"),
])
def test_bad_construction_is_refused(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        rod(**kwargs)


def test_bad_calls_are_refused():
    shp = rod()
    with pytest.raises(ParameterError, match="3 entries"):
        shp.positions(np.zeros(4))
    with pytest.raises(DataError, match="NaN"):
        shp.positions(np.array([np.nan, 0, 0]))
    with pytest.raises(ParameterError, match="not one"):
        shp.add_point_load(force=[0, 0, 1], at=0.123456)
    with pytest.raises(ParameterError, match="3D SDF"):
        shp.add_contact(sdf.Circle(0.01))
    shp.add_chamber(1e-6, (0.002, 0.0))
    with pytest.raises(ParameterError, match="1 finite inputs"):
        shp.statics(u=[1.0, 2.0])
    with pytest.raises(ConvergenceError, match="load level"):
        rod().add_point_load(moment=[0, 0, 40 * EI / L]).statics(max_iterations=1, min_step=0.3)


def test_inverse_kinematics_with_a_callable_subtask_matches_the_compiled_elastic_one():
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), segments=10)
    target, q0 = np.array([0.12, 0.08, 0.05]), np.array([0, 0, 30.0, 0, 0, -30.0])
    a = shp.inverse_kinematics(target, q0=q0, subtask="elastic", max_iterations=2000)
    b = shp.inverse_kinematics(target, q0=q0, subtask=lambda q: shp.K @ q, max_iterations=2000)
    assert a.converged and b.converged
    assert np.allclose(a.q, b.q, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("order", [2, 4])
def test_matrix_free_inverse_dynamics_equals_the_assembled_equations(order):
    shp = rod(Basis.chebyshev(2), dofs=(2, 2, 2, 2, 2, 2), order=order, damping=0.01).add_gravity((1.0, -2.0, -9.81))
    rng = np.random.default_rng(5)
    q, qd, qdd = 3 * rng.normal(size=12), rng.normal(size=12), rng.normal(size=12)
    M, C, fg = shp.dynamics(q, qd)
    expected = M @ qdd + C @ qd + shp.damping_matrix @ qd + shp.K @ q - fg
    assert np.allclose(shp.inverse_dynamics(q, qd, qdd), expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


def test_render_writes_the_tube_of_the_current_shape(tmp_path):
    shp = rod()
    q = np.array([20.0, 0.0, 0.0])
    beam = shp.beam(q)
    assert np.allclose(beam["frames"], shp.forward_kinematics(q)) and beam["radius"] == pytest.approx(R)
    path = shp.render(tmp_path / "rod.png", q, title="curl")
    assert path.exists() and path.stat().st_size > 1000


def test_inverse_kinematics_accepts_plain_sequences_and_stops_when_overdetermined():
    shp = rod(Basis.chebyshev(3), dofs=(0, 3, 3, 0, 0, 0), segments=10)
    P = shp.positions(np.array([5.0, 2.0, 1.0, -3.0, 1.0, 0.5]))
    assert shp.inverse_kinematics(list(P[-1])).converged
    targets = [(shp.sigma[i], P[i] * 1.02) for i in (4, 6, 8, 10)]      # 12 equations, 6 unknowns
    plain = shp.inverse_kinematics(targets)
    soft = shp.inverse_kinematics(targets, subtask="elastic")
    assert not plain.converged and soft.iterations < 150
    assert soft.error == pytest.approx(plain.error, rel=1e-4)     # the same least-squares fit


def test_coriolis_jacobian_matches_finite_differences():
    shp = rod(Basis.chebyshev(2), dofs=(2, 2, 2, 2, 2, 2), order=4)
    rng = np.random.default_rng(4)
    q, v = 3 * rng.normal(size=12), rng.normal(size=12)
    eps = 1e-6
    fd = np.column_stack([(shp.coriolis(q, v + eps * e) @ (v + eps * e) - shp.coriolis(q, v - eps * e)
                           @ (v - eps * e)) / (2 * eps) for e in np.eye(12)])
    Cv = shp.coriolis_jacobian(q, v)
    assert np.abs(Cv - fd).max() < 1e-8 * np.abs(Cv).max()
    assert np.abs(Cv - shp.coriolis(q, v)).max() > 0.1 * np.abs(Cv).max()     # not C itself


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.4, 1.49, 1.51, 3.0])
def test_closed_form_tangent_blocks_match_the_lie_kernels(angle):
    from soroshapes import _beam
    rng = np.random.default_rng(6)
    w = rng.normal(size=3)
    xi = np.concatenate([angle * w / np.linalg.norm(w), rng.normal(size=3)])
    d = rng.normal(size=6)
    T, dT = np.zeros((6, 6)), np.zeros((6, 6))
    _beam._tangent_closed(xi, T)
    _beam._dtangent_closed(xi, d, dT)
    assert np.allclose(T, lie.TSE3(xi), atol=1e-14)
    assert np.allclose(dT, lie.dTSE3(xi, d), atol=1e-13)


def test_sliding_on_a_floor_dissipates_energy_only_with_friction():
    losses = {}
    for mu in (0.0, 0.6):
        shp = rod(Basis.chebyshev(2), dofs=(0, 0, 2, 0, 0, 0), segments=10, material=elastic(1e5))
        shp.add_contact(sdf.Plane((0, 0, -R + 1e-4), (0, 0, 1)), stiffness=2e5, friction=mu)
        tr = shp.simulate(0.02, 2e-4, qd0=np.array([3.0, 0.0]), record_every=10)
        losses[mu] = (tr.total[0] - tr.total[-1]) / tr.total[0]
        assert np.all(np.diff(tr.total) <= 1e-9 * tr.total[0])          # never gains energy
    assert abs(losses[0.0]) < 1e-4 and losses[0.6] > 0.1


def test_a_beam_too_coarse_for_its_modes_says_so_instead_of_a_linear_algebra_error():
    """Five Chebyshev modes on two fourth-order pieces: the mass matrix is singular (its quadrature nodes cannot
    tell the modes apart); the error names the segments, not scipy's factorization; a finer beam gives frequencies."""
    def beam(segments):
        return Shapes(Basis.chebyshev(5), dofs=(0, 5, 0, 0, 0, 0), length=0.08, section=sdf.Circle(0.005),
                      material=materials.NeoHookean(E=1e5, nu=0.45, density=1000.0), segments=segments, order=4)

    with pytest.raises(ParameterError, match="mass matrix of this beam is singular.*use more segments"):
        beam(2).natural_frequencies(1)
    assert np.all(np.isfinite(beam(8).natural_frequencies(3)))
