"""The simulated board's plant is a soroshapes Model (issue 18): its reservoirs against an independent RK4 of
``Fluidic.rhs`` (the plant's former integrator, a few lines here), and its beam against the beam's own
integrator driven by the pressures the plant reported.

Reference for the reservoirs: classical RK4 of :meth:`soroshapes.Fluidic.rhs` per channel at h = 0.25 ms (its
error, ~(h/2 tau)^4 ~ 1e-9 relative between the valve's kinks, is far below what is compared). The plant's
model takes trapezoidal steps (second order): its error falls ~4x when its step halves, which the test checks
together with the bound.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from sorocontrol.drivers import SimulatedPlant

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "soro"))
import play_finger_scene as fs  # noqa: E402  (the light finger of the soro play tests, one chamber)

TICK = 2.5e-3                                          # a 400 Hz board
#: set-points [Pa] of 3 channels, changed at 0.1 s: filling and emptying through the saturated valve
#: (max_flow 1e-4 kg/s into 20 ml: 420 kPa/s) and a small step that never saturates
STEPS = ((0.0, (50e3, -80e3, 1e3)), (0.1, (-20e3, 30e3, 2e3)))
T_END = 0.25


def _setpoints(t):
    return np.array([u for t0, u in STEPS if t >= t0 - 1e-12][-1], float)


def _plant_run(substep):
    plant = SimulatedPlant(3, max_flow=1e-4, substep=substep)
    ticks = np.arange(1, int(round(T_END / TICK)) + 1) * TICK
    # the board applies the set-point it holds during the tick that ends at t
    p = np.array([plant.apply(_setpoints(t - TICK), t)[0] for t in ticks])
    return plant, ticks, p


def _rk4_reference(plant, ticks, h=2.5e-4):
    """RK4 of Fluidic.rhs per channel, the set-points held per tick as the board holds them."""
    fl, V = plant.fluidic, plant.volume
    x = [fl.initial_state(V) for _ in range(3)]
    out = []
    for tk in ticks:
        u = _setpoints(tk - TICK)
        n = int(round(TICK / h))
        for _ in range(n):
            for i in range(3):
                f = lambda xx: fl.rhs(xx, u[i:i + 1], V)      # noqa: E731
                k1 = f(x[i])
                k2 = f(x[i] + 0.5 * h * k1)
                k3 = f(x[i] + 0.5 * h * k2)
                k4 = f(x[i] + h * k3)
                x[i] = x[i] + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append([fl.pressure(xi, V) for xi in x])
    return np.array(out)


def test_reservoir_plant_is_a_compiled_model_and_matches_rk4_of_fluidic_rhs():
    plant, ticks, p = _plant_run(1.25e-3)                   # 2 steps per tick
    assert plant.model.evaluation_path == "compiled"
    assert plant.model.systems == ["channel0", "channel1", "channel2"]
    assert plant.plant_time == pytest.approx(T_END, abs=1e-12) and plant.t == pytest.approx(T_END)
    ref = _rk4_reference(plant, ticks)
    err = np.abs(p - ref).max(axis=0)
    # trapezoidal steps of h = 1.25 ms: ~(a h)^2/12 = 4e-5 of the response per unit of a t (a = 1/(2 tau) = 16.7/s,
    # a t ~ 4), i.e. ~1e-4 of the step; measured 1.9 Pa of 50 kPa, 0.06 Pa of 1 kPa (channel 1 rides the valve's
    # saturation all along, a constant flow that both integrate exactly)
    assert np.all(err < 1e-4 * np.array([80e3, 80e3, 2e3])), err
    _, _, p_half = _plant_run(0.625e-3)                     # 4 steps per tick
    err_half = np.abs(p_half - ref).max(axis=0)
    assert np.all(err_half[[0, 2]] < err[[0, 2]] / 3.0), (err, err_half)   # second order: the error falls ~4x
    # the unsaturated channels reach their set-points (no steady-state error: PI) within the loop's transient
    assert p[-1, [0, 2]] == pytest.approx(_setpoints(T_END)[[0, 2]], rel=0.05, abs=300.0)


def test_vent_empties_every_reservoir_and_keeps_the_plant_time():
    plant = SimulatedPlant(2)
    for k in range(1, 21):
        plant.apply([40e3, -40e3], k * TICK)
    assert np.all(np.abs(plant.pressures()) > 10e3)
    p, sensors, faults = plant.apply(np.zeros(2), None)
    np.testing.assert_array_equal(p, 0.0)            # exactly gauge 0: the state of an open regulator
    assert sensors.size == 0 and not faults.any() and plant.plant_time == pytest.approx(20 * TICK)
    p_next = plant.apply(np.zeros(2), 21 * TICK)[0]
    np.testing.assert_allclose(p_next, 0.0, atol=1e-6)   # and it stays there at a zero set-point


def test_beam_plant_tip_matches_the_beam_driven_by_the_reported_pressures():
    """The beam in the plant's model (coupled to the channel's reservoir) against Shapes.simulate (its implicit
    midpoint integrator) with the pressures the plant reported at each tick, linearly interpolated."""
    shp = fs.finger()
    plant = SimulatedPlant(1, beam=shp, substep=1e-3)
    assert plant.model.evaluation_path == "compiled"
    assert plant.sensor_names == ("tip_x", "tip_y", "tip_z", "q0", "q1", "q2")
    q0 = plant.q.copy()
    ticks = np.arange(1, int(round(0.2 / TICK)) + 1) * TICK
    p, tips = [], []
    for t in ticks:
        m, s, _ = plant.apply([fs.P_MAX], t)
        p.append(m[0])
        tips.append(s[:3])
        np.testing.assert_array_equal(s[3:], plant.q)
    p, tips = np.array(p), np.array(tips)
    tp, pp = np.r_[0.0, ticks], np.r_[0.0, p]
    ref = shp.simulate(0.2, 0.5e-3, q0=q0, u=lambda t: np.array([np.interp(t, tp, pp)]), record_every=5)
    ref_tips = np.array([shp.positions(q)[-1] for q in ref.q[1:]])
    np.testing.assert_allclose(ref.t[1:], ticks, atol=1e-12)
    deflection = np.abs(tips[:, 2] - tips[0, 2]).max()
    assert deflection > 5e-3                               # the finger did bend (60 kPa: ~10 mm at 0.2 s)
    # differences: the pressure's linear interpolation between ticks (dt^2/8 |p''| ~ 2e-4 of p) and two second
    # order integrators at 1 ms and 0.5 ms
    assert np.abs(tips - ref_tips).max() < 2e-3 * deflection, np.abs(tips - ref_tips).max() / deflection


def test_plant_ticks_equal_one_simulate_of_its_model():
    """The plant's ticks (its model's stepper: the lowered network and Newton matrix kept from tick to tick, 3
    trapezoidal steps per 2.5 ms tick) under held set-points equal one Model.simulate of the same model over the
    same span with the same steps. Not to round-off: a tick's step is its elapsed board time / 3, which differs
    from TICK/3 in the last bits at some ticks, and a new step size refactors the Newton matrix; the difference is
    then Newton's tolerance (1e-3 of rtol = 1e-6 relative per step), far below 1e-6 of the pressures (measured:
    3e-10 Pa, with 66 component matrices factored by the ticks against 9 by the one run)."""
    u = np.array([50e3, -80e3, 1e3])
    plant = SimulatedPlant(3, max_flow=1e-4)
    ticks = np.arange(1, 41) * TICK
    p = np.array([plant.apply(u, t)[0] for t in ticks])
    ref = SimulatedPlant(3, max_flow=1e-4)
    ref.stepper.hold(u)                                     # the model's controller: the held set-points
    tr = ref.model.simulate(40 * TICK, TICK / 3, record_every=3, compiled=True)
    P = np.column_stack([tr[f"channel{i}"].pressure[1:] for i in range(3)])
    np.testing.assert_allclose(tr.t[1:], ticks, rtol=0, atol=1e-12)
    assert np.abs(p - P).max() < 1e-6 * 80e3, np.abs(p - P).max()
    assert np.abs(p[-1, 0]) > 10e3                          # it moved
    assert plant.stepper.stats["steps"] == 3 * 40 + 1       # and one step at construction (the warm-up)
