"""The step-size controller of soroshapes.integrate (``Model.simulate(adaptive=True)``), against closed forms.

References: for :math:`\\dot y = \\lambda y` one step of each method from exact history has a closed form, so the
local error estimate (Milne's device, :func:`soroshapes.integrate.local_error`) is checked against the true local
error, also in variable steps; the damped oscillator's matrix exponential gives the global error, which follows
the tolerance as :math:`\\text{tol}^{2/3}` (local error :math:`\\propto h^3` held at tol: :math:`h \\propto
\\text{tol}^{1/3}`, global error :math:`\\propto h^2`); a stiff relaxation onto :math:`\\sin t` (rate 1e5 1/s)
must be followed with steps set by :math:`\\sin t`, not by the stiff rate. Both paths (compiled, Python) run the
one rule.
"""
import numpy as np
import pytest
from scipy.linalg import expm

from sorofem.errors import ParameterError
from soroshapes import Model, StateSpace
from soroshapes import integrate as itg

A_OSC = np.array([[0.0, 1.0], [-(2 * np.pi) ** 2, -0.8]])   # omega = 2 pi rad/s, damping 0.8 1/s
X0_OSC = np.array([1.0, 0.0])


def linear_oscillator():
    return Model().add(StateSpace.linear(A_OSC, np.zeros((2, 0))), "o", x0=X0_OSC)


def python_oscillator():
    return Model().add(StateSpace(lambda x, u, t: A_OSC @ x, 2, 0, jacobian=lambda x, u, t: (A_OSC, np.zeros((2, 0))),
                                  x0=X0_OSC), "o")


@pytest.mark.parametrize("method", [itg.TRAPEZOIDAL, itg.MIDPOINT, itg.BDF2])
@pytest.mark.parametrize("ratios", [(1.0, 1.0), (1.6, 0.7), (0.5, 1.9)])
@pytest.mark.parametrize("lam", [-1.5, 4.0])
def test_local_error_estimate_equals_the_true_local_error(method, ratios, lam):
    """y' = lam y from exact history at t = -h1-h2, -h1, 0: the step's estimate over its true error -> 1 as h -> 0
    (next-order terms: O(lam h) relative, well below 2 % at |lam| h = 1e-3)."""
    h = 1e-3 / abs(lam)
    h1 = h / ratios[0]
    h2 = h1 / ratios[1]
    y = lambda t: np.array([np.exp(lam * t)])                       # noqa: E731
    z = lam * h
    if method == itg.BDF2:
        om = h / h1
        d = 1 + 2 * om
        x1 = ((1 + om) ** 2 * y(0) - om ** 2 * y(-h1)) / d / (1 - z * (1 + om) / d)
    else:                                                           # both are the trapezoidal rule here
        x1 = y(0) * (1 + z / 2) / (1 - z / 2)
    xp = np.zeros(1)
    itg.lagrange3(y(0), y(-h1), y(-h1 - h2), h, h1, h2, xp)
    est = itg.local_error(method, y(0), x1, xp, h, h1, h2, 1e-300, 1.0, np.ones(1))
    assert est == pytest.approx(abs(x1[0] - y(h)[0]), rel=0.02)


def test_lagrange_and_dense_output_reproduce_a_quadratic():
    p = lambda t: np.array([1.0 - 2.0 * t + 3.0 * t * t, 0.5 * t * t])   # noqa: E731
    h1, h2, out = 0.3, 0.7, np.zeros(2)
    for s in (0.4, -0.1, -0.3, -0.65):
        itg.lagrange3(p(0.0), p(-h1), p(-h1 - h2), s, h1, h2, out)
        assert np.allclose(out, p(s), rtol=0, atol=1e-13)
    itg.dense_output(-0.2, p(0.0), p(-h1), p(-h1 - h2), h1, h2, 2, out)
    assert np.allclose(out, p(-0.2), atol=1e-13)
    itg.dense_output(-0.2, p(0.0), p(-h1), p(-h1 - h2), h1, h2, 0, out)      # first step: the straight line
    assert np.allclose(out, p(0.0) + (p(-h1) - p(0.0)) * 0.2 / h1, atol=1e-13)


def test_step_factor_limits_and_keeps_the_step():
    assert itg.step_factor(-1.0, True) == 1.0                      # not estimated: keep
    assert itg.step_factor(0.0, True) == itg.GROW_MAX
    assert itg.step_factor(1e6, False) == itg.SHRINK_MIN
    assert itg.step_factor(np.inf, False) == itg.SHRINK_MIN
    assert itg.step_factor(2.0, False) == pytest.approx(0.9 * 2.0 ** (-1 / 3))
    assert itg.step_factor(0.3, True) == pytest.approx(0.9 * 0.3 ** (-1 / 3))   # 1.34 >= KEEP_BELOW: grow
    assert itg.step_factor(0.01, True) == itg.GROW_MAX
    assert itg.step_factor(0.5, True) == 1.0                       # 1.13: kept


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("method", ["trapezoidal", "midpoint", "bdf2"])
def test_global_error_follows_the_tolerance_on_a_damped_oscillator(method, compiled):
    make = linear_oscillator if compiled else python_oscillator
    errs, steps = [], []
    for tol in (1e-5, 1e-7):
        tr = make().simulate(3.0, 1e-3, method, rtol=tol, atol=tol, adaptive=True, record_every=10)
        assert tr.stats["path"] == ("compiled" if compiled else "python") and tr.stats["adaptive"]
        assert np.allclose(tr.t, np.linspace(0.0, 3.0, 301), rtol=0, atol=1e-12)     # the output times
        ref = np.array([expm(t * A_OSC) @ X0_OSC for t in tr.t])
        errs.append(np.max(np.abs(tr.x - ref)))
        steps.append(tr.stats["steps"])
    # ~ tol^(2/3): 21.5 for a factor 100 (the two unestimated first steps and dense output add a little)
    assert 8 < errs[0] / errs[1] < 50, errs
    assert errs[0] < 3e-2, errs                          # 3 periods of accumulated phase error (~800 tol)
    assert steps[1] / steps[0] == pytest.approx(100 ** (1 / 3), rel=0.3), steps
    assert steps[0] < 3000 / 4                           # far fewer than fixed steps of the first step (1 ms)


def test_compiled_and_python_paths_take_the_same_steps():
    a = linear_oscillator().simulate(2.0, 1e-3, "bdf2", rtol=1e-6, atol=1e-6, adaptive=True)
    b = python_oscillator().simulate(2.0, 1e-3, "bdf2", rtol=1e-6, atol=1e-6, adaptive=True, compiled=False)
    assert abs(a.stats["steps"] - b.stats["steps"]) <= 2
    assert np.max(np.abs(a.x - b.x)) < 1e-6             # well inside the tolerance's global error (~1e-4)


def test_stiff_relaxation_takes_steps_of_the_slow_solution():
    """x' = -k (x - sin t), k = 1e5 1/s, x(0) = 1: after the 10 us transient, x = sin t - cos t / k + ...; BDF2
    (L-stable) with the controller must take steps set by sin t (tol 1e-6: ~ms), not by 1/k."""
    k = 1e5
    mdl = Model().add(StateSpace.linear([[-k]], [[k]]), "s", x0=[1.0])
    from soroshapes.network import Schedule
    t = np.linspace(0.0, 2.0, 20001)
    mdl.set_controller(Schedule(t, {"s": np.sin(t)[:, None]}))
    tr = mdl.simulate(2.0, 1e-6, "bdf2", rtol=1e-6, atol=1e-6, adaptive=True, record_every=10000)
    assert tr.stats["path"] == "compiled"
    late = tr.t > 1e-3
    exact = np.sin(tr.t) - np.cos(tr.t) / k
    assert np.max(np.abs(tr.x[late, 0] - exact[late])) < 1e-4
    assert tr.stats["steps"] < 2000 and tr.stats["max_step"] > 1e-3


def test_max_dt_caps_the_step_and_bad_values_are_refused():
    tr = linear_oscillator().simulate(1.0, 1e-3, "bdf2", rtol=1e-3, atol=1e-3, adaptive=True, max_dt=5e-3)
    assert tr.stats["max_step"] <= 5e-3 * (1 + 1e-12)
    with pytest.raises(ParameterError, match="max_dt"):
        linear_oscillator().simulate(1.0, 1e-3, adaptive=True, max_dt=-1.0)


def falling_beam():
    """A planar cantilever released straight under its own weight (2 Chebyshev modes of bending, a large swing:
    w L^3 / (8 EI) ~ 2): a nonlinear network on the compiled path."""
    from sorofem import materials, sdf
    from soroshapes import Basis, Shapes
    mat = materials.NeoHookean(E=1e5, nu=0.45, density=1000)
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 0, 0, 0, 0), length=0.1, section=sdf.Circle(0.005), material=mat,
                 damping=0.01, segments=4).add_gravity((0, 0, -9.81))
    return Model().add(shp, "beam")


def test_newton_tolerance_trades_sweeps_within_the_step_tolerance():
    """``newton_tol`` (the fraction of the step tolerance Newton's remaining error is held below): a looser one takes
    fewer sweeps; each step's Newton error is at most newton_tol tolerances, so over the run's steps (a damped,
    stable swing) the states stay within steps x newton_tol x (rtol |x| + atol s) of a run with a tight Newton.
    The Stepper runs the same steps as simulate."""
    rtol, atol, T, dt = 1e-4, 1e-6, 0.3, 2e-3
    runs = {ntol: falling_beam().simulate(T, dt, "bdf2", rtol=rtol, atol=atol, newton_tol=ntol)
            for ntol in (1e-6, 1e-3, 1e-1)}
    assert all(tr.stats["path"] == "compiled" for tr in runs.values())
    its = [runs[k].stats["newton_iterations"] for k in (1e-6, 1e-3, 1e-1)]
    assert its[0] > its[1] >= its[2], its
    ref = runs[1e-6].x
    size = np.abs(ref).max(axis=0)
    for ntol in (1e-3, 1e-1):
        bound = runs[ntol].stats["steps"] * ntol * (rtol * size + atol * np.maximum(size, 1.0))
        assert np.all(np.abs(runs[ntol].x - ref).max(axis=0) <= bound), ntol
    stp = falling_beam().stepper(dt, "bdf2", rtol=rtol, atol=atol, newton_tol=1e-1)
    x = stp.advance(T)
    assert np.allclose(x, runs[1e-1].x[-1], rtol=0, atol=1e-12)
    assert stp.stats["newton_iterations"] == its[2]
    py = falling_beam().simulate(T, dt, "bdf2", rtol=rtol, atol=atol, newton_tol=1e-1, compiled=False)
    assert np.max(np.abs(py.x[-1] - ref[-1]) / (rtol * size + atol)) < 150 * 0.1
    for bad in (0.0, 2.0, np.nan):
        with pytest.raises(ParameterError, match="newton_tol"):
            falling_beam().simulate(T, dt, "bdf2", newton_tol=bad)
