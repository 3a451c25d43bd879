"""Path following (sorofem.fem.continuation): a limit point passed under pressure control and a bifurcation
taken onto the buckled branch, both against closed forms along the whole path (tests/analytic.py).

Tolerances:
* thick sphere (Neo-Hookean, nu = 0.4999, B = 1.5 A, Taylor-Hood P2/P1, order-2 geometry, 3 cells across
  the wall): the pressure along the path differs from the incompressible closed form by at most 1.9e-4 of
  p_max on this mesh, and by 2.3e-4 to 2.6e-4 on 6 and 12 cells (tests/benchmarks/bench_continuation.py): the
  mesh error is gone, what remains is the bulk modulus (kappa/mu = 5000; nu = 0.49999 cuts it); tolerance
  5e-4 p_max.
* strut (plane strain, L/h = 25, P2, 2 cells across): the elastica is inextensible and unshearable; the
  continuum differs by O((h/L)^2) in the load: the largest difference is 0.30 % of P_cr on this mesh, 0.23 %
  and 0.21 % at 4 and 8 cells across (the bench), so not the mesh; tolerance 0.6 % of P_cr.
"""
import numpy as np
import pytest

from sorofem.errors import ParameterError

pytest.importorskip("sorofem.fem")
from fem_cases import STRUT, inner_radius, strut, strut_end_offset, thick_sphere  # noqa: E402

L, P_CR = STRUT["L"], STRUT["P_cr"]


# ----------------------------------------------------------------------------------------------- limit point
def test_thick_sphere_is_followed_through_its_pressure_maximum_under_pressure_control():
    """A thick incompressible Neo-Hookean sphere (B = 1.5 A) has a pressure maximum at a = 1.603 A. Under
    pressure control (the load factor scales a pressure = the maximum) the continuation rises to it, detects
    it as a limit point (the lowest eigenvalue crosses zero along a mode parallel to the path), and follows
    the falling branch to a = 2.2 A; the pressure matches the closed form along the whole path."""
    from analytic import sphere_inflation_pressure, sphere_pressure_maximum

    A, B, mu = 0.01, 0.015, 100e3
    p_max, a_max = sphere_pressure_maximum(mu, A, B)
    assert a_max == pytest.approx(1.6034 * A, rel=1e-4)
    fem = thick_sphere(A, B, mu, p_max, cells_across=3)
    traj = fem.follow(load_level=2.0, steps=8, until=lambda tr: inner_radius(tr, A)[-1] > 2.2 * A,
                      monitor_stability=True)
    assert traj.metadata["stopped"] == "until"
    a, p = inner_radius(traj, A), traj.inputs["pressure/inner"]
    np.testing.assert_allclose(traj.times * p_max, p, rtol=1e-12)          # the load factor is the pressure
    ref = np.array([sphere_inflation_pressure(mu, A, B, ai) for ai in a])
    assert np.abs(p - ref).max() < 5e-4 * p_max
    top = int(np.argmax(p))
    assert 0 < top < len(p) - 1 and p[top] == pytest.approx(p_max, rel=5e-4)   # through the maximum ...
    assert np.all(np.diff(a) > 0) and p[-1] < 0.88 * p_max                     # ... and down the far side
    (crit,) = traj.metadata["critical_points"]
    assert crit["kind"] == "limit" and crit["mode_path_cosine"] > 0.99
    assert crit["load"] == pytest.approx(1.0, abs=2e-3)
    mu_low = np.array(traj.lowest_eigenvalue)
    assert np.all(mu_low[:crit["step"]] > 0) and np.all(mu_low[crit["step"]:] < 0)
    assert max(traj.newton_iterations) <= 6


def test_volume_control_is_followed_too_and_the_last_step_lands_on_t_end():
    """Volume control under continuation: the load factor moves the injected volume (its pressure is the other
    multiplier of the border); the path passes the pressure maximum with the volume exact, and the step that
    would pass t_end lands on it."""
    from analytic import sphere_inflation_pressure, sphere_pressure_maximum

    A, B, mu = 0.01, 0.015, 100e3
    fem = thick_sphere(A, B, mu, 2 / 3 * np.pi * (2**3 - 1) * A**3, cells_across=3, volume=True)  # to a = 2 A
    traj = fem.follow(load_level=1.0, steps=6)
    assert traj.metadata["stopped"] == "t_end" and traj.times[-1] == 1.0
    np.testing.assert_allclose(traj.cavity_volumes["inner"], 2 / 3 * np.pi * A**3 * (1 + 7 * traj.times),
                               rtol=1e-5)
    a, p = inner_radius(traj, A), traj.inputs["pressure/inner"]
    p_max, a_max = sphere_pressure_maximum(mu, A, B)
    assert a[-1] > 1.2 * a_max and p[-1] < 0.95 * p.max()                  # well past the maximum
    ref = np.array([sphere_inflation_pressure(mu, A, B, ai) for ai in a])
    assert np.abs(p - ref).max() < 5e-4 * p_max


# ----------------------------------------------------------------------------------------------- bifurcation
def test_strut_buckles_onto_the_elastica_by_branch_switching():
    """Euler buckling under displacement control: the straight strut's lowest eigenvalue crosses zero at the
    Euler load (a bifurcation: the mode is sideways, orthogonal to the straight path); the next step is taken
    along that mode (eigenvector injection), and the continuation then follows the buckled branch, which is
    stable and matches the elastica's load against the sideways offset up to w = 0.2 L."""
    from analytic import buckled_strut

    traj = strut().follow(load_level=1.0, steps=20, until=lambda tr: abs(strut_end_offset(tr)[-1]) > 0.2 * L,
                           monitor_stability=True, branch_switch=True)
    assert traj.metadata["stopped"] == "until"
    (crit,) = traj.metadata["critical_points"]
    assert crit["kind"] == "bifurcation" and crit["mode_path_cosine"] < 0.05
    k = crit["step"]
    P = -traj.reactions["right"][:, 0]
    w = strut_end_offset(traj)
    # before: straight (but for 3e-6 L: the structured triangles' diagonals all lean one way), and the
    # eigenvalue changes sign between the steps that bracket the Euler load
    assert np.all(np.abs(w[:k + 1]) < 1e-5 * L)
    assert P[k - 1] < P_CR < P[k]
    # after: the buckled branch (the largest component of the mode was made positive: a deterministic side)
    post = slice(k + 1, None)
    assert len(w[post]) > 10 and np.all(np.diff(np.abs(w[post])) > 0) and abs(w[-1]) > 0.2 * L
    ratio, _ = buckled_strut(w[post] / L)
    np.testing.assert_allclose(P[post] / P_CR, ratio, atol=6e-3)
    assert np.all(np.array(traj.lowest_eigenvalue)[post] > 0)                # the buckled branch is stable
    assert max(traj.newton_iterations[post][1:]) <= 5


def test_after_an_overshooting_primary_step_the_path_stays_on_the_buckled_branch():
    """Direction control after the switch: the primary step overshoots the Euler load threefold (steps=12) and the
    switch takes a small step (max_step=0.01), so the secant from the primary point to the first buckled point
    points steeply down in load; its predictor landed next to the straight branch and the path turned back down
    it into tension (before the fix: load factor 0.026 -> -0.048 in ten steps, offset 0; the porous block's full
    run ended at +37.9 % strain that way). With the new branch's tangent the load keeps rising, the offset keeps
    growing and the buckled points match the elastica."""
    from analytic import buckled_strut

    traj = strut().follow(load_level=1.0, steps=12, max_step=0.01, max_steps=12, monitor_stability=True,
                          branch_switch=True)
    assert traj.metadata["stopped"] == "max_steps"
    (crit,) = traj.metadata["critical_points"]
    k = crit["step"] + 1   # the first point of the buckled branch
    assert k == 2 and traj.times[1] > 3 * crit["load"]   # the overshoot
    w, lam = strut_end_offset(traj)[k:], traj.times[k:]
    assert np.all(np.diff(lam) > 0) and np.all(np.diff(w) > 0) and w[-1] > 1e-3 * L
    ratio, _ = buckled_strut(w / L)
    np.testing.assert_allclose(-traj.reactions["right"][k:, 0] / P_CR, ratio, atol=6e-3)
    assert traj.metadata["branch_switch"]["step"] == k


def test_a_path_below_t_min_is_refused_with_the_path_so_far():
    """The load-reversal guard: the same switch lands at a load factor of 0.026 (the Euler load) after the
    primary step to 0.083; with t_min = 0.05 that is a reversal past the user's bound, refused with a
    ConvergenceError that carries the path up to there."""
    from sorofem.errors import ConvergenceError

    with pytest.raises(ConvergenceError, match="t_min") as info:
        strut().follow(load_level=1.0, steps=12, max_step=0.01, max_steps=12, monitor_stability=True,
                       branch_switch=True, t_min=0.05)
    traj = info.value.trajectory
    assert len(traj) == 3 and traj.times[-1] < 0.05 < traj.times[-2]


def test_a_return_onto_the_primary_branch_is_refused():
    """The return guard on its own (the direction control above keeps it from firing on the strut): an amplitude
    along the critical mode below half its value at the new branch's first point raises ConvergenceError."""
    from petsc4py import PETSc

    from sorofem.errors import ConvergenceError
    from sorofem.fem.continuation import _check_direction

    class Path(list):
        metadata = {}

    def vec(values):
        return PETSc.Vec().createWithArray(np.array(values, dtype=float), comm=PETSc.COMM_SELF)

    mode, origin, weight, tmp = vec([0, 1, 0]), vec([0, 0, 0]), vec([1, 1, 0]), vec([0, 0, 0])
    state = {"lam": 0.5, "branch": {"mode": mode, "origin": origin, "load": 0.4, "first": None}}
    traj = Path([0, 1, 2])
    _check_direction(traj, state, vec([0.3, 0.2, 0]), weight, tmp, 2.0, 0.0, True)    # first point: amplitude 0.1
    assert state["branch"]["first"] == pytest.approx(0.1)
    _check_direction(traj, state, vec([9.0, 0.12, 5.0]), weight, tmp, 2.0, 0.0, False)   # 0.06: still on it
    with pytest.raises(ConvergenceError, match="back towards the primary branch"):
        _check_direction(traj, state, vec([0.3, 0.08, 0]), weight, tmp, 2.0, 0.0, False)  # 0.04 < 0.05


def test_without_branch_switching_the_perfect_strut_stays_straight():
    """The same continuation without switching stays on the straight (now unstable) branch: the buckled branch
    above is taken deliberately, not by round-off."""
    traj = strut().follow(load_level=1.0, steps=20, max_steps=3)
    assert traj.metadata["stopped"] == "max_steps" and len(traj) == 4
    assert np.abs(strut_end_offset(traj)).max() < 1e-5 * L
    assert -traj.reactions["right"][-1, 0] > 2 * P_CR


def test_bad_arguments():
    fem = strut()
    with pytest.raises(ParameterError, match="monitor_stability=True"):
        fem.follow(branch_switch=True)
    with pytest.raises(ParameterError, match="t_end"):
        fem.follow(load_level=0.0)
    with pytest.raises(ParameterError, match="t_min"):
        fem.follow(load_level=1.0, t_min=1.0)
    with pytest.raises(ParameterError, match="no load"):
        strut(shortening=0.0).follow()


@pytest.mark.mpi
def test_limit_point_and_branch_switch_on_two_ranks():
    """Under ``mpirun -n 2`` (make test's MPI stage): the sphere's path and limit point and the strut's switch
    onto the buckled branch give the serial figures; ``until`` is asked on rank 0 (where the trajectory's fields
    are) and its answer reaches every rank. (Before, the axisymmetric axis condition hung on two ranks.)"""
    from mpi4py import MPI
    from analytic import buckled_strut, sphere_inflation_pressure, sphere_pressure_maximum

    assert MPI.COMM_WORLD.size == 2
    A, B, mu = 0.01, 0.015, 100e3
    p_max, _ = sphere_pressure_maximum(mu, A, B)
    traj = thick_sphere(A, B, mu, p_max, cells_across=3).follow(
        load_level=2.0, steps=8, until=lambda tr: inner_radius(tr, A)[-1] > 2.2 * A, monitor_stability=True)
    (crit,) = traj.metadata["critical_points"]
    assert crit["kind"] == "limit" and crit["load"] == pytest.approx(1.0, abs=2e-3)
    traj2 = strut().follow(load_level=1.0, steps=20, until=lambda tr: abs(strut_end_offset(tr)[-1]) > 0.2 * L,
                           monitor_stability=True, branch_switch=True)
    assert [c["kind"] for c in traj2.metadata["critical_points"]] == ["bifurcation"]
    if MPI.COMM_WORLD.rank == 0:
        a, p = inner_radius(traj, A), traj.inputs["pressure/inner"]
        assert a[-1] > 2.2 * A
        assert np.abs(p - [sphere_inflation_pressure(mu, A, B, ai) for ai in a]).max() < 5e-4 * p_max
        k = traj2.metadata["critical_points"][0]["step"]
        w = strut_end_offset(traj2)[k + 1:]
        ratio, _ = buckled_strut(w / L)
        np.testing.assert_allclose(-traj2.reactions["right"][k + 1:, 0] / P_CR, ratio, atol=6e-3)


# ----------------------------------------------------------------------------------------------- first step
def test_linear_start_cuts_the_first_step_to_a_fraction_of_the_body_size():
    """``Fem.solve(linear_start=f)``: the first step moves no point of the linear response by more than f times
    the diagonal D of the body's bounding box (for a linear material the response is exactly linear, so the first
    step is f D / max|u(1)|, to round-off), then grows by 1.5x per easy step to the end."""
    from sorofem import materials
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    def cantilever():
        msh = Mesh.rectangle(0.1, 0.01, size=0.0025, center=(0.05, 0.0))
        fem = Fem(msh, materials.LinearElastic(E=1e6, nu=0.3), formulation="plane_stress")
        return fem.add_support("left").add_traction("right", [0.0, -1000.0])

    full = cantilever().solve(steps=1)
    peak = np.abs(full.displacement[-1]).max()
    D = np.hypot(0.1, 0.01)
    assert peak > 0.1 * D   # one step would move the tip by more than a tenth of the body
    traj = cantilever().solve(steps=1, linear_start=0.01)
    assert traj.times[1] == pytest.approx(0.01 * D / peak, rel=1e-6)
    assert traj.times[-1] == 1.0
    np.testing.assert_allclose(traj.displacement[-1], full.displacement[-1], atol=1e-9 * peak)
    with pytest.raises(ParameterError, match="linear_start"):
        cantilever().solve(linear_start=0.0)
