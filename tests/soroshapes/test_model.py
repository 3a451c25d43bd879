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
def test_adaptive_steps_are_tolerance_proportional(method):
    """The error-controlled steps (soroshapes.integrate's rule; more in tests/soroshapes/test_integrate.py)."""
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
# valve flow functions (soroshapes.valves): the ISO 6358-like orifice
# --------------------------------------------------------------------------------------------------------
P_AMB, T_GAS = 101325.0, 293.15


def _iso6358(K, b, p1, p2):
    """The reference flow K p1 phi(p2/p1) from p1 to p2 < p1 (choked / subsonic; no laminar branch)."""
    r = p2 / p1
    return K * p1 * (1.0 if r <= b else np.sqrt(1 - ((r - b) / (1 - b)) ** 2))


def test_orifice_flow_is_the_iso6358_law_choked_and_subsonic_and_continuous_at_b():
    from soroshapes.valves import Orifice, orifice_flow
    C, b, supply = 1e-9, 0.4, 500e3
    v = Orifice(C, b, supply)
    K, _, ps, pe, full = v.parameters(P_AMB, T_GAS)
    assert K == pytest.approx(C * 1.185, rel=1e-12) and full == pytest.approx(K * ps, rel=1e-12)
    for p in np.linspace(P_AMB, 0.99 * ps, 41):                         # filling: choked below b ps
        for s in (1.0, 0.3):
            ref = s * _iso6358(K, b, ps, p)
            assert v.flow(s * full, p, P_AMB, T_GAS) == pytest.approx(ref, rel=1e-12)
        assert v.flow(2 * full, p, P_AMB, T_GAS) == v.flow(full, p, P_AMB, T_GAS)   # the opening saturates
    for p in np.linspace(1.02 * P_AMB, ps, 21):                         # venting to the atmosphere
        assert v.flow(-0.5 * full, p, P_AMB, T_GAS) == pytest.approx(-0.5 * _iso6358(K, b, p, pe), rel=1e-12)
    assert v.flow(full, ps, P_AMB, T_GAS) == 0.0 and v.flow(-full, pe, P_AMB, T_GAS) == 0.0
    assert v.flow(full, 1.2 * ps, P_AMB, T_GAS) < 0                     # back-flow into the supply
    # continuity at the critical ratio: both sides within the subsonic law's slope times the gap (it is 0 at b)
    eps = 1e-9 * ps
    lo, hi = (orifice_flow(K, b, ps, pe, full, full, b * ps + d)[0] for d in (-eps, eps))
    assert lo == K * ps and abs(hi - lo) < 1e-12 * K * ps
    # the laminar branch above r = 0.999 joins the subsonic law continuously and is linear down to zero
    r_l = 0.999
    at = [orifice_flow(K, b, ps, pe, full, full, r * ps)[0] for r in (r_l - 1e-12, r_l + 1e-12, 0.9995)]
    assert at[0] == pytest.approx(at[1], rel=1e-6) and at[2] == pytest.approx(0.5 * at[1], rel=1e-6)


def test_orifice_derivatives_equal_central_differences():
    from soroshapes.valves import Orifice, orifice_flow
    v = Orifice(1e-9, 0.5, 600e3, exhaust=-20e3)
    K, b, ps, pe, full = v.parameters(P_AMB, T_GAS)
    rng = np.random.default_rng(7)
    for trial in range(200):                                            # both ports, all branches, reverse flow
        nu = full * rng.uniform(-1.3, 1.3)
        p = ps * rng.uniform(0.1, 1.2)
        if abs(nu) < 1e-3 * full or abs(p / ps - 0.999) < 2e-4 or abs(pe / p - 0.999) < 2e-4:
            continue                                                    # the kinks at nu = 0 and r = 0.999
        m, dnu, dp = orifice_flow(K, b, ps, pe, full, nu, p)
        hn, hp = 1e-6 * full, 1e-6 * p
        fdn = (orifice_flow(K, b, ps, pe, full, nu + hn, p)[0]
               - orifice_flow(K, b, ps, pe, full, nu - hn, p)[0]) / (2 * hn)
        fdp = (orifice_flow(K, b, ps, pe, full, nu, p + hp)[0]
               - orifice_flow(K, b, ps, pe, full, nu, p - hp)[0]) / (2 * hp)
        if abs(abs(nu) - full) > 2e-6 * full:                           # away from the opening's clip
            assert dnu == pytest.approx(fdn, rel=1e-5, abs=1e-12)
        assert dp == pytest.approx(fdp, rel=1e-4, abs=1e-12 * K)


def _orifice_reservoir(V, valve, regulated=False):
    reg = dict(kp=2e-9, ki=1e-7) if regulated else None
    return Fluidic(V, regulator=reg, valve=valve)


def test_a_reservoir_filled_through_an_orifice_follows_the_choked_then_subsonic_closed_form():
    """Isothermal, open supply port: dp/dt = (RT/V) K p_s phi(p/p_s). Choked (p < b p_s): p rises linearly and
    reaches b p_s at t_c = (b p_s - p0) V / (R T K p_s) (the choked phase's fill time); then x = (p/p_s - b)/(1 - b)
    obeys dx/dt = a sqrt(1 - x^2), a = R T K / (V (1 - b)): x = sin(a (t - t_c)). Compiled and Python paths, the
    trapezoidal rule at dt = 2e-5 s (x'' ~ a^2 = 400 1/s^2: local error ~ dt^3 a^3 / 12, 1e-6 of p_s over the
    run; 1e-5 allowed)."""
    from soroshapes.network import Schedule
    from soroshapes.valves import Orifice
    V, C, b = 1e-6, 1e-10, 0.5
    valve = Orifice(C, b, 600e3)
    fl = _orifice_reservoir(V, valve)
    K, _, ps, _, full = valve.parameters(P_AMB, T_GAS)
    rt = fl.R * fl.T
    t_c = (b * ps - P_AMB) * V / (rt * K * ps)
    a = rt * K / (V * (1 - b))
    t_end = t_c + np.arcsin(0.99) / a
    runs = {}
    for compiled in (None, False):
        mdl = Model().add(fl, "cup").set_controller(Schedule([0.0, 1.0], {"cup": [[full], [full]]}))
        tr = mdl.simulate(t_end, 2e-5, compiled=compiled, rtol=1e-10)
        runs[tr.stats["path"]] = tr
        t, p = tr.t, tr["cup"].pressure + P_AMB
        choked = t <= t_c
        ref = np.where(choked, P_AMB + rt / V * K * ps * t,
                       ps * (b + (1 - b) * np.sin(a * np.clip(t - t_c, 0.0, None))))
        assert np.max(np.abs(p - ref)) < 1e-5 * ps
        assert np.interp(b * ps, p, t) == pytest.approx(t_c, rel=1e-4)    # the choked phase's fill time
    assert set(runs) == {"compiled", "python"}
    assert np.max(np.abs(runs["compiled"].x - runs["python"].x)) < 1e-6 * np.max(np.abs(runs["python"].x))


def test_a_regulated_orifice_reservoir_settles_on_its_set_point():
    from soroshapes.network import Schedule
    from soroshapes.valves import Orifice
    fl = _orifice_reservoir(1e-6, Orifice(1e-10, 0.5, 600e3), regulated=True)
    mdl = Model().add(fl, "cup").set_controller(Schedule([0.0, 1.0], {"cup": [[80e3], [80e3]]}))
    assert mdl.evaluation_path == "compiled"
    tr = mdl.simulate(0.6, 1e-4, "bdf2", rtol=1e-9)
    assert tr["cup"].pressure[-1] == pytest.approx(80e3, rel=1e-4)       # the integral removes the error
    assert np.max(tr["cup"].pressure) < 1.2 * 80e3


def test_a_python_valve_function_runs_on_the_stated_python_path_and_matches_the_orifice():
    from soroshapes.network import Schedule
    from soroshapes.valves import Orifice
    valve = Orifice(1e-10, 0.5, 600e3)

    def my_valve(nu, p):
        return valve.flow(nu, p, P_AMB, T_GAS)

    ref = Model().add(_orifice_reservoir(1e-6, valve, True), "cup")
    # the same command limit for the anti-windup (an Orifice's is its full flow; a callable's is max_flow, if given)
    reg = dict(kp=2e-9, ki=1e-7, max_flow=valve.full_flow(P_AMB, T_GAS))
    mine = Model().add(Fluidic(1e-6, regulator=reg, valve=my_valve), "cup")
    for mdl in (ref, mine):
        mdl.set_controller(Schedule([0.0, 1.0], {"cup": [[50e3], [50e3]]}))
    assert "Python valve flow function 'my_valve'" in mine.evaluation_path
    a, b_ = ref.simulate(0.05, 1e-4, rtol=1e-10), mine.simulate(0.05, 1e-4, rtol=1e-10)
    assert np.max(np.abs(a["cup"].pressure - b_["cup"].pressure)) < 1e-6 * 50e3
    with pytest.raises(ParameterError, match="valve must be"):
        Fluidic(1e-6, valve=42)
    with pytest.raises(DataError, match="finite mass flow"):
        Fluidic(1e-6, valve=lambda nu, p: np.nan).rhs(np.array([1e-6]), np.array([0.0]), 1e-6)


def test_closed_form_newton_rows_of_orifice_reservoirs_equal_the_differenced_ones():
    """Regulated and unregulated orifice reservoirs (isothermal with a beam's volume; polytropic with the volume
    filter), compiled rows of network._fluidic_jacobian against forward differences of the network (as
    tests/soroshapes/test_network.py does for the saturation valve) at random states."""
    from soroshapes import network
    from soroshapes.network import Schedule, StateMap
    from soroshapes.valves import Orifice
    V0 = 1e-6
    valve = Orifice(1e-10, 0.5, 600e3)
    mdl = Model().add(finger(), "f")
    mdl.add(Fluidic(None, V0=V0, leak=1e-13, regulator=dict(kp=1e-10, ki=1e-8), valve=valve), "p")
    mdl.add(Fluidic(None, V0=V0, polytropic=1.4, filter_gain=200.0, valve=valve), "q")
    mdl.connect("p", "f")
    mdl.connect(StateMap("f", [0.1], index=0, offset=V0, scale=0.2 * V0, function="tanh"), "p", port="volume")
    mdl.connect(StateMap("f", [[1e-8, 2e-8]], index=[0, 1], offset=V0), "q", port="volume")
    mdl.set_controller(Schedule([0.0, 1.0], {"p": [[30e3], [30e3]], "q": [[0.4 * valve.full_flow(P_AMB, T_GAS)],
                                                                          [0.4 * valve.full_flow(P_AMB, T_GAS)]]}))
    mdl._prepare_layout()
    net = mdl._lowered()
    assert not isinstance(net, str)
    table = net.arrays[0]
    assert np.all(table[:, 7] == 1)
    rng = np.random.default_rng(5)
    x0 = mdl.initial_state()
    scale = mdl._scales(x0)
    N = len(x0)
    for trial in range(6):
        x = x0 + 0.3 * scale * rng.standard_normal(N)
        for blk in (mdl._blocks["p"], mdl._blocks["q"]):      # pressures between ambient and the supply
            x[blk.sl.start] = abs(x0[blk.sl.start]) * (1.5 + 2.0 * rng.random())
        ws = [np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N)]
        JA, JD = np.zeros((N, N)), np.zeros((N, N))
        assert network._cheap_rows(0.3, x, net.arrays, scale, *ws, JA, True, True)
        assert network._cheap_rows(0.3, x, net.arrays, scale, *ws, JD, True, False)
        for name in ("p", "q"):
            for i in range(mdl._blocks[name].sl.start, mdl._blocks[name].sl.stop):
                size = max(np.max(np.abs(JD[i])), 1e-300)
                assert np.max(np.abs(JA[i] - JD[i])) <= 1e-5 * size, (trial, name, i, JA[i], JD[i])


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


# --------------------------------------------------------------------------------------------------------
# the stepper: a run continued call after call
# --------------------------------------------------------------------------------------------------------
def regulated_pair():
    """Two regulated reservoirs (one rides its valve's saturation, a kink in F) and a lag that sets the second's
    volume (a StateMap): a compiled network with three components' worth of coupling."""
    from soroshapes.network import Schedule, StateMap
    reg = dict(kp=1e-9, ki=1e-8, max_flow=2e-5)
    return (Model().add(Fluidic(1e-6, regulator=reg), "a").add(Fluidic(None, V0=1e-6, regulator=reg), "b")
            .add(StateSpace.linear([[-20.0]], [[20.0]]), "lag")
            .connect(StateMap("lag", [2e-7], index=0, offset=1e-6), "b", port="volume")
            .set_controller(Schedule([0.0, 0.05, 0.1], {"a": [[0.0], [60e3], [60e3]], "b": [[0.0], [20e3], [-5e3]],
                                                        "lag": [[0.0], [1.0], [1.0]]})))


@pytest.mark.parametrize("method", ["trapezoidal", "bdf2", "midpoint"])
def test_a_stepper_advanced_tick_by_tick_takes_the_steps_of_one_simulate(method):
    """N calls of advance(steps=k) equal one simulate over the same span with records every k steps: the
    kept iteration matrix, predictors and BDF2 history make the same steps (to round-off in the step times),
    with the same Newton iterations and factorizations."""
    one = regulated_pair().simulate(0.12, 1e-3, method, rtol=1e-6, record_every=4, compiled=True)
    stp = regulated_pair().stepper(1e-3, method, rtol=1e-6, compiled=True)
    assert stp.path == "compiled"
    xs = np.array([stp.advance(steps=4) for _ in range(30)])
    scale = np.abs(one.x).max(axis=0)
    assert np.max(np.abs(xs - one.x[1:]) / scale) < 1e-12
    assert stp.t == pytest.approx(0.12, abs=1e-15)
    for key in ("steps", "newton_iterations", "matrices", "jacobians", "cut_steps"):
        assert stp.stats[key] == one.stats[key], key
    assert one["a"].pressure.max() > 30e3                     # it moved (through the valve's saturation)


def test_a_stepper_holds_inputs_in_place_and_continues_to_a_time():
    """hold(u) makes a constant Schedule the controller once and then writes u in place; advance(t_end) takes
    steps of at most dt. Against simulate chained with t0 under the same constant set-points (each call a fresh
    matrix: the two agree within the Newton tolerance, not to round-off)."""
    from soroshapes.network import Schedule

    def plain():
        reg = dict(kp=1e-9, ki=1e-8, max_flow=2e-5)
        return Model().add(Fluidic(1e-6, regulator=reg), "a").add(Fluidic(2e-6, regulator=reg), "b")
    stp = plain().stepper(1e-3)
    ref, x, t = plain(), None, 0.0
    for t_end, u in ((0.0125, [10e3, -5e3]), (0.03, [40e3, 5e3]), (0.0301, [40e3, 5e3]), (0.05, [0.0, 0.0])):
        stp.hold(u)
        got = stp.advance(t_end)
        tr = ref.set_controller(Schedule([0.0, 1.0], np.array([u, u], float))).simulate(
            t_end - t, 1e-3, x0=x, t0=t, record_every=1 << 20)
        x, t = tr.x[-1], t_end
        assert stp.t == t_end and np.all(np.abs(got - x) <= 1e-7 * np.abs(x) + [1e-12, 1e-3, 1e-12, 1e-3])
    assert stp.path == "compiled" and stp.stats["steps"] == 13 + 18 + 1 + 20
    with pytest.raises(ParameterError, match="2 free inputs"):
        stp.hold([1.0])
    with pytest.raises(ParameterError, match="after t = 0.05"):
        stp.advance(0.05)


def test_a_stepper_on_the_python_path_continues_by_simulate():
    """A network with a Python controller steps on the Python path (said by ``path``) and agrees with one
    simulate within its Newton tolerance."""
    ctrl = lambda mdl: {"vdp": [np.sin(3 * mdl.t)]}  # noqa: E731
    one = Model().add(vanderpol(), "vdp").set_controller(ctrl).simulate(0.5, 0.01, rtol=1e-10)
    stp = Model().add(vanderpol(), "vdp").set_controller(ctrl).stepper(0.01, rtol=1e-10)
    assert stp.path.startswith("python")
    for k in range(1, 11):
        x = stp.advance(0.05 * k)
    assert np.max(np.abs(x - one.x[-1])) < 1e-8 and stp.stats["steps"] == one.stats["steps"] == 50


def test_a_failed_stepper_advance_keeps_the_state_and_time_of_the_call():
    """A volume map that reaches zero fails the step down to min_dt: ConvergenceError, and the stepper is where
    the call found it (a board plant vents and does not simulate that tick again)."""
    from soroshapes.network import Schedule, StateMap
    mdl = (Model().add(Fluidic(None, V0=1e-6), "a").add(StateSpace.linear([[-20.0]], [[20.0]]), "lag")
           .connect(StateMap("lag", [-1e-6], index=0, offset=1e-6), "a", port="volume")
           .set_controller(Schedule([0.0, 1.0], {"a": [[0.0], [0.0]], "lag": [[2.0], [2.0]]})))
    stp = mdl.stepper(1e-3, compiled=True)
    x = stp.advance(0.01)                                    # lag 0.36: the volume is 0.64 of V0
    t = stp.t
    with pytest.raises(ConvergenceError, match=r"stays at t = 0\.03 s"):   # V = 0 at ln 2/20 = 0.0347 s
        for k in range(2, 20):
            x, t = stp.advance(0.01 * k), stp.t
    assert stp.t == t and np.array_equal(stp.x, x)
    with pytest.raises(DataError, match="NaN"):
        stp.set_state([np.nan, 0.0])
