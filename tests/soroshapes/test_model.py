"""Validation of the network composer (soroshapes.model) against closed forms.

References: the matrix exponential for linear systems (a damped oscillator; a PI-regulated reservoir below
valve saturation is linear too), Boyle's law pV = const for a closed isothermal reservoir and pV^n = const
for a polytropic one, the valve-limited filling rate RT/V * max_flow, and the beam's own static solver.
"""
import numpy as np
import pytest
from scipy.linalg import expm

from sorofem import materials, sdf
from sorofem.errors import ConvergenceError, DataError, ParameterError
from soroshapes import Basis, Fluidic, Model, Shapes, StateSpace

A_OSC = np.array([[0.0, 1.0], [-(2 * np.pi) ** 2, -0.8]])   # omega = 2 pi rad/s, damping 0.8 1/s
X0_OSC = np.array([1.0, 0.0])


def oscillator(jac=True):
    return StateSpace(lambda x, u, t: A_OSC @ x, 2, 0, jacobian=(lambda x, u, t: (A_OSC, np.zeros((2, 0))))
                      if jac else None, x0=X0_OSC)


def vanderpol():
    return StateSpace(lambda x, u, t: [x[1], 2.0 * (1 - x[0] ** 2) * x[1] - x[0] + u[0]], 2, 1, x0=[0.5, 0.0])


# --------------------------------------------------------------------------------------------------------
# the solver
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["trapezoidal", "midpoint", "bdf2"])
def test_uncoupled_systems_match_their_separate_simulations(method):
    ctrl = lambda mdl: {"vdp": [np.sin(3 * mdl.t)]}  # noqa: E731
    both = Model().add(oscillator(), "osc").add(vanderpol(), "vdp").set_controller(ctrl)
    tb = both.simulate(2.0, 0.01, method, rtol=1e-11)
    ta = Model().add(oscillator(), "osc").simulate(2.0, 0.01, method, rtol=1e-11)
    tv = Model().add(vanderpol(), "vdp").set_controller(ctrl).simulate(2.0, 0.01, method, rtol=1e-11)
    assert np.max(np.abs(tb["osc"].x - ta["osc"].x)) < 1e-9
    assert np.max(np.abs(tb["vdp"].x - tv["vdp"].x)) < 1e-9
    assert np.allclose(tb["vdp"].u[:, 0], np.sin(3 * tb.t))
    # and the linear one is close to the exact solution (second order, dt = 0.01)
    bound = 6e-2 if method == "bdf2" else 2e-2          # phase error C (w h)^2 w t, C = 1/12 (2/9 for BDF2)
    assert np.max(np.abs(tb["osc"].x[-1] - expm(2.0 * A_OSC) @ X0_OSC)) < bound


@pytest.mark.parametrize("method", ["trapezoidal", "midpoint", "bdf2"])
@pytest.mark.parametrize("jac", [True, False])
def test_order_of_accuracy_on_a_damped_oscillator(method, jac):
    ref = expm(1.0 * A_OSC) @ X0_OSC
    errs = [np.linalg.norm(Model().add(oscillator(jac), "o").simulate(1.0, dt, method, rtol=1e-12).x[-1] - ref)
            for dt in (0.02, 0.01, 0.005)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.1), orders


@pytest.mark.parametrize("method", ["trapezoidal", "midpoint"])
def test_adaptive_step_doubling_is_tolerance_proportional(method):
    ref = expm(3.0 * A_OSC) @ X0_OSC
    errs, steps = [], []
    for rtol in (1e-6, 1e-8):
        tr = Model().add(oscillator(), "o").simulate(3.0, 1e-3, method, rtol=rtol, atol=rtol, adaptive=True)
        assert tr.t[-1] == pytest.approx(3.0) and np.all(np.diff(tr.t) > 0)
        errs.append(np.linalg.norm(tr.x[-1] - ref))
        steps.append(tr.stats["steps"])
    assert errs[0] < 2e-3
    assert 10 < errs[0] / errs[1] < 100                 # local error ~ h^3 -> global ~ rtol^(2/3): 21.5
    assert steps[1] / steps[0] == pytest.approx(100 ** (1 / 3), rel=0.3)   # h ~ rtol^(1/3)


def test_closed_loop_controller_keeps_second_order():
    # xdot = u, u = -x by a controller: the closed loop xdot = -x, x(1) = e^-1
    plant = StateSpace(lambda x, u, t: u, 1, 1, x0=[1.0])
    errs = [abs(Model().add(plant, "p").set_controller(lambda m: -m["p"].x).simulate(1.0, dt, rtol=1e-12).x[-1, 0]
                - np.exp(-1.0)) for dt in (0.05, 0.025)]
    assert np.log2(errs[0] / errs[1]) == pytest.approx(2.0, abs=0.05)


# --------------------------------------------------------------------------------------------------------
# fluidics
# --------------------------------------------------------------------------------------------------------
def test_isothermal_compression_follows_boyles_law():
    V0 = 2e-5
    V = lambda t: V0 * (1 - 0.6 * t + 0.1 * np.sin(5 * t))  # noqa: E731
    tr = Model().add(Fluidic(V), "cup").simulate(1.0, 0.01, rtol=1e-12)
    cup = tr["cup"]
    pabs = cup.pressure + 101325.0
    assert np.allclose(cup.volume, V(tr.t))
    assert np.max(np.abs(pabs * cup.volume / (101325.0 * V0) - 1)) < 1e-8
    assert pabs[-1] / 101325.0 == pytest.approx(V0 / V(1.0), rel=1e-8)


def test_polytropic_compression_follows_p_v_to_the_n_with_the_dirty_derivative():
    V0, n = 2e-5, 1.4
    V = lambda t: V0 * (1 - 0.5 * t)  # noqa: E731
    fl = Fluidic(V, polytropic=n, filter_gain=1e4)
    assert fl.states == ["pressure", "filter"]
    tr = Model().add(fl, "cup").simulate(1.0, 1e-3, rtol=1e-10)
    pabs = tr["cup"].pressure + 101325.0
    invariant = pabs * tr["cup"].volume ** n / (101325.0 * V0 ** n)
    assert np.max(np.abs(invariant - 1)) < 1e-3         # filter lag ~ n Vdot/(a V)
    assert pabs[-1] / 101325.0 == pytest.approx(2.0 ** n, rel=1e-3)


def _regulated(kp=2e-9, ki=2e-7, max_flow=1e-3, V=1e-6):
    return Fluidic(V, regulator=dict(kp=kp, ki=ki, max_flow=max_flow))


def test_regulated_reservoir_below_saturation_matches_the_linear_pi_closed_form():
    V, kp, ki, pd = 1e-6, 2e-9, 2e-7, 2000.0
    fl = _regulated(kp, ki, V=V)
    tr = Model().add(fl, "fl").set_controller(lambda m: [pd]).simulate(0.15, 1e-4, rtol=1e-10)
    g = fl.R * fl.T / V
    A = np.array([[-g * kp, g * ki], [-1.0, 0.0]])    # states (p_gauge, s) with constant input pd
    b = np.array([g * kp * pd, pd])
    z = np.array([np.linalg.solve(A, (expm(A * t) - np.eye(2)) @ b) for t in tr.t])
    assert np.max(np.abs(tr["fl"].pressure - z[:, 0])) < 1e-4 * pd
    assert np.max(np.abs(tr["fl"].pressure)) < 1.3 * pd   # zeta = 0.65 plus the PI zero
    assert tr["fl"].pressure[-1] == pytest.approx(pd, rel=1e-4)


def test_regulated_reservoir_tracks_a_step_with_valve_saturation():
    V, mx = 1e-6, 2e-6
    fl = _regulated(max_flow=mx, V=V)
    pd = lambda t: 0.0 if t < 0.01 else 40e3  # noqa: E731
    tr = Model().add(fl, "fl").set_controller(lambda m: [pd(m.t)]).simulate(0.3, 2e-4, "bdf2", rtol=1e-9)
    p, t = tr["fl"].pressure, tr.t
    sat = (t > 0.012) & (t < 0.03)                      # the valve is fully open: p rises at R T / V * max_flow
    slope = np.polyfit(t[sat], p[sat], 1)[0]
    assert slope == pytest.approx(fl.R * fl.T / V * mx, rel=1e-3)
    assert abs(p[-1] - 40e3) < 1e-3 * 40e3               # the PI settles on the set point
    assert np.max(p) < 1.15 * 40e3                       # anti-windup keeps the overshoot small
    assert np.max(np.abs(p[t < 0.0099])) < 1e-6


def test_leak_drains_a_closed_reservoir_exponentially():
    V, lam = 1e-6, 1e-10
    fl = Fluidic(V, leak=lam)
    mdl = Model().add(fl, "fl", x0=fl.initial_state(V, pressure=10e3))
    tr = mdl.simulate(0.1, 1e-4, rtol=1e-12)
    rate = lam * fl.R * fl.T / V
    assert np.allclose(tr["fl"].pressure, 10e3 * np.exp(-rate * tr.t), rtol=1e-6)


# --------------------------------------------------------------------------------------------------------
# a beam driven by a reservoir
# --------------------------------------------------------------------------------------------------------
def finger():
    mat = materials.NeoHookean(E=1e6, nu=0.45, density=1000)
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 0, 2, 0, 0, 0), length=0.1, section=sdf.Circle(0.005), material=mat,
                 damping=0.03, segments=8)
    return shp.add_gravity((0, -9.81, 0)).add_chamber(area=5e-5, offset=(0.003, 0))


def test_beam_driven_by_a_regulated_reservoir_reaches_the_static_bending():
    shp = finger()
    fl = Fluidic(None, V0=1e-6, regulator=dict(kp=2e-9, ki=2e-7, max_flow=1e-5))   # volume from the beam
    mdl = (Model().add(shp, "finger").add(fl, "chamber")
           .connect("chamber", "finger")                                           # pressure -> beam input
           .connect(lambda m: 1e-6 * (1 + 0.2 * np.tanh(0.1 * m["finger"].x[0])), "chamber", port="volume")
           .set_controller(lambda m: {"chamber": [30e3]}))
    tr = mdl.simulate(1.5, 5e-3, "bdf2", rtol=1e-9)
    p_end = tr["chamber"].pressure[-1]
    assert p_end == pytest.approx(30e3, rel=1e-5)
    assert np.allclose(tr["finger"].u[-1], p_end)
    q_static = shp.statics(u=[p_end], steps=2)
    assert np.max(np.abs(tr["finger"].q[-1] - q_static)) < 1e-5 * np.max(np.abs(q_static))
    assert np.max(np.abs(tr["finger"].qd[-1])) < 1e-4
    # the volume followed the beam
    assert tr["chamber"].volume[-1] == pytest.approx(1e-6 * (1 + 0.2 * np.tanh(0.1 * tr["finger"].q[-1, 0])))


# --------------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------------
def test_controller_of_the_wrong_size_names_the_system():
    mdl = Model().add(oscillator(), "osc").add(vanderpol(), "vdp")
    with pytest.raises(ParameterError, match="vdp"):
        mdl.set_controller(lambda m: [1.0, 2.0]).simulate(0.1, 0.01)
    with pytest.raises(ParameterError, match="system 'vdp'.*1 free inputs"):
        mdl.set_controller(lambda m: {"vdp": [1.0, 2.0]}).simulate(0.1, 0.01)
    with pytest.raises(ParameterError, match="unknown system 'nope'"):
        mdl.set_controller(lambda m: {"nope": [1.0]}).simulate(0.1, 0.01)


def test_mismatched_coupling_sizes_name_both_systems():
    mdl = Model().add(oscillator(), "osc").add(vanderpol(), "vdp").connect("osc", "vdp")
    with pytest.raises(ParameterError, match="system 'vdp'.*output of system 'osc' has 2 entries"):
        mdl.simulate(0.1, 0.01)
    with pytest.raises(ParameterError, match="out of range for system 'vdp'"):
        Model().add(vanderpol(), "vdp").connect(lambda m: [0.0], "vdp", index=3)
    with pytest.raises(ParameterError, match="not a Fluidic"):
        Model().add(vanderpol(), "vdp").connect(lambda m: 1.0, "vdp", port="volume")
    with pytest.raises(ParameterError, match="'chamber' has volume=None"):
        Model().add(Fluidic(None, V0=1e-6), "chamber").simulate(0.1, 0.01)


def test_nan_state_and_nan_derivative_are_reported():
    with pytest.raises(DataError, match="initial state of system 'osc'"):
        Model().add(oscillator(), "osc", x0=[np.nan, 0.0]).simulate(0.1, 0.01)
    bad = StateSpace(lambda x, u, t: [np.nan], 1, 0)
    with pytest.raises(DataError, match="system 'bad'"):
        Model().add(oscillator(), "osc").add(bad, "bad").simulate(0.1, 0.01)
    with pytest.raises(ParameterError, match="x0 of system 'osc' must have 2"):
        Model().add(oscillator(), "osc", x0=[1.0])


def test_newton_failure_raises_convergence_error_with_the_time():
    late = StateSpace(lambda x, u, t: [np.nan if t > 0.5 else 1.0], 1, 0)
    with pytest.raises(ConvergenceError, match=r"t = 0\.5.*system 'late'"):
        Model().add(late, "late").simulate(1.0, 0.1)


def test_views_and_names():
    fl = Fluidic(1e-6, regulator=dict(kp=1e-9, ki=1e-7, max_flow=1e-4))
    seen = {}

    def ctrl(m):
        seen["p"], seen["x"] = m["fl"].pressure, m.state("osc", 0)
        return {"fl": [1e3]}
    mdl = Model().add(oscillator(), "osc").add(fl, "fl").set_controller(ctrl)
    assert mdl.inputs == ["fl.pressure_ref"] and mdl.systems == ["osc", "fl"] and mdl.n == 4
    tr = mdl.simulate(0.01, 1e-3)
    assert np.isfinite(seen["p"]) and np.isfinite(seen["x"])
    assert tr["fl"].x.shape == (11, 2) and tr.u.shape == (11, 1)
    with pytest.raises(KeyError, match="systems: osc, fl"):
        tr["nope"]


def test_a_simulation_continued_from_t0_equals_one_run():
    """Two runs chained with t0 give the run in one go, also for a time-dependent input."""
    f = lambda x, u, t: np.array([x[1], -4.0 * x[0] + np.sin(3.0 * t)])  # noqa: E731
    model = Model().add(StateSpace(f, 2, 0, name="osc", x0=np.array([1.0, 0.0])))
    whole = model.simulate(2.0, 0.01, method="midpoint")
    first = model.simulate(1.0, 0.01, method="midpoint")
    second = model.simulate(1.0, 0.01, method="midpoint", x0=first.x[-1], t0=1.0)
    assert second.t[0] == pytest.approx(1.0) and second.t[-1] == pytest.approx(2.0)
    assert np.allclose(second.x[-1], whole.x[-1], rtol=1e-8, atol=1e-10)
    model.set_state(0.5, np.array([0.3, -0.2]))
    assert model.t == 0.5 and np.allclose(model["osc"].x, [0.3, -0.2])


# --------------------------------------------------------------------------------------------------------
# block-sparse Jacobian
# --------------------------------------------------------------------------------------------------------
def oscillator_chain(K, c=0.2, declare=True, feedthrough=False):
    """K damped unit oscillators, each driven by the previous one's position (named couplings) and the
    first by a sine of time (a callable declared to read nothing)."""
    A, B = np.array([[0.0, 1.0], [-1.0, -c]]), np.array([[0.0], [1.0]])
    mdl = Model()
    for i in range(K):
        mdl.add(StateSpace(lambda x, u, t: A @ x + B @ u, 2, 1, jacobian=lambda x, u, t: (A, B),
                           output=lambda x, u, t: x[:1], feedthrough=feedthrough), f"osc{i}",
                x0=[0.1 * (i % 3), 0.0])
    for i in range(1, K):
        mdl.connect(f"osc{i - 1}", f"osc{i}")
    mdl.connect(lambda m: [np.sin(m.t)], "osc0", reads=() if declare else None)
    return mdl, A, B


def test_block_sparse_jacobian_equals_the_dense_one_and_the_exact_one():
    K = 30
    mdl, A, B = oscillator_chain(K)
    x = np.random.default_rng(0).normal(size=2 * K)
    J = mdl.jacobian(0.3, x)
    S = mdl.jacobian(0.3, x, sparse=True)
    exact = np.kron(np.eye(K), A) + np.kron(np.eye(K, k=-1), B @ np.array([[1.0, 0.0]]))
    assert np.allclose(J, exact, atol=1e-7) and np.allclose(S.toarray(), J, rtol=0, atol=1e-14)
    assert S.nnz == np.count_nonzero(exact)
    # the couplings read osc0..osc{K-2}: the last oscillator's columns are not differenced, and as no system
    # reads two others, all of them are differenced together: 2 evaluations of W instead of 2 K - 2
    assert len(mdl._coupling_columns) == 2 * (K - 1) and len(mdl._fd_groups) == 2
    # an output that may use its inputs passes on what they read: a lower-triangular pattern, no grouping
    passing, *_ = oscillator_chain(K, feedthrough=True)
    assert passing.jacobian(0.3, x) == pytest.approx(J, abs=1e-7) and len(passing._fd_groups) == 2 * (K - 1)
    undeclared, *_ = oscillator_chain(K, declare=False)
    assert undeclared.jacobian(0.3, x) == pytest.approx(J, abs=1e-7) and undeclared._coupling_columns is None


def test_sparse_newton_gives_the_dense_trajectory():
    mdl, *_ = oscillator_chain(120)            # 240 states: "auto" factorizes sparse
    sparse = mdl.simulate(2.0, 0.01, "bdf2")
    dense = mdl.simulate(2.0, 0.01, "bdf2", linear_solver="dense")
    assert np.allclose(sparse.x, dense.x, rtol=1e-9, atol=1e-11)
    assert np.abs(sparse.x[:, 2 * 60]).max() > 1e-3      # the drive travelled down the chain


def test_reads_must_name_systems():
    mdl, *_ = oscillator_chain(3)
    with pytest.raises(ParameterError, match="no system 'oscX'"):
        mdl.connect(lambda m: [0.0], "osc1", reads=["oscX"])
    with pytest.raises(ParameterError, match="linear_solver"):
        mdl.simulate(0.1, 0.01, linear_solver="lu")


def test_a_controller_may_name_a_system_without_free_inputs():
    """{"b": []} for a system with no inputs assigns nothing (and leaves the other system's input in place):
    x' = -x + 1 from 0 gives 1 - exp(-t)."""
    a = StateSpace(lambda x, u, t: -x + u, 1, 1, name="a")
    b = StateSpace(lambda x, u, t: -x, 1, 0, name="b")
    tr = Model().add(a).add(b).set_controller(lambda mdl: {"a": [1.0], "b": []}).simulate(0.1, 0.001)
    assert tr["a"].x[-1, 0] == pytest.approx(1 - np.exp(-0.1), rel=1e-5)   # trapezoidal, h = 1 ms: ~1e-7
    assert tr["b"].x[-1, 0] == 0.0
