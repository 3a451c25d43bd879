"""Path following (sorofem.fem.continuation): a limit point passed under pressure control and a bifurcation
taken onto the buckled branch, both against closed forms along the whole path (tests/analytic.py).

Tolerances:
* thick sphere (incompressible Neo-Hookean, B = 1.5 A, Taylor-Hood P2/P1, order-2 geometry, 3 cells across
  the wall): the pressure along the path differs from the closed form by at most 1.9e-4 of p_max on this mesh
  (2.4e-5 at 6 cells across, tests/benchmarks/bench_continuation.py); tolerance 5e-4 p_max.
* strut (plane strain, L/h = 25, P2, 2 cells across): the elastica is inextensible and unshearable; the
  continuum differs by O((h/L)^2) ~ 0.2-0.3 % in the load (0.25 % at 4 cells across, so not the mesh);
  tolerance 0.6 % of P_cr.
"""
import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ParameterError

mesh_mod = pytest.importorskip("sorofem.mesh")
fem_mod = pytest.importorskip("sorofem.fem")
Mesh, Fem = mesh_mod.Mesh, fem_mod.Fem


# ----------------------------------------------------------------------------------------------- limit point
def _quarter_annulus(A, B, size):
    shape = (sdf.Circle(B) - sdf.Circle(A)) & sdf.Rectangle(B, B, center=(B / 2, B / 2))
    msh = Mesh.from_sdf(shape, size=size, order=2)
    return msh.add_region("inner", lambda x: np.hypot(x[0], x[1]) < A * (1 + 1e-3))


def _inner_radius(traj, A):
    i = np.argmin(np.hypot(traj.vertices[:, 0] - A, traj.vertices[:, 1]))
    return A + traj.displacement[:, i, 0]


def test_thick_sphere_is_followed_through_its_pressure_maximum_under_pressure_control():
    """A thick incompressible Neo-Hookean sphere (B = 1.5 A) has a pressure maximum at a = 1.603 A. Under
    pressure control (the load factor scales a pressure = the maximum) the continuation rises to it, detects
    it as a limit point (the lowest eigenvalue crosses zero along a mode parallel to the path), and follows
    the falling branch to a = 2.2 A; the pressure matches the closed form along the whole path."""
    from analytic import sphere_inflation_pressure, sphere_pressure_maximum

    A, B, mu = 0.01, 0.015, 100e3
    p_max, a_max = sphere_pressure_maximum(mu, A, B)
    assert a_max == pytest.approx(1.6034 * A, rel=1e-4)
    fem = Fem(_quarter_annulus(A, B, (B - A) / 3), materials.NeoHookean(mu=mu, nu=0.4999),
              formulation="axisymmetric", degree=2, mixed=True)
    fem.add_support("bottom", "y").add_pressure("inner", p_max)
    traj = fem.follow(t_end=2.0, steps=8, until=lambda tr: _inner_radius(tr, A)[-1] > 2.2 * A,
                      monitor_stability=True)
    assert traj.metadata["stopped"] == "until"
    a, p = _inner_radius(traj, A), traj.inputs["pressure/inner"]
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


# ----------------------------------------------------------------------------------------------- bifurcation
L, H, E, NU = 0.1, 0.004, 1e6, 0.3
P_CR = np.pi**2 * E / (1 - NU**2) * H**3 / 12 / L**2    # clamped-guided Euler strut, plane strain [N/m]


def _strut(shortening=0.05 * L):
    """Clamped at the left end; the right end is pushed in by ``shortening`` [m] times the load factor
    and is free to slide sideways (its face stays parallel: a guided end)."""
    fem = Fem(Mesh.rectangle(L, H, size=H / 2, center=(L / 2, 0.0)), materials.NeoHookean(E=E, nu=NU), degree=2)
    return fem.add_support("left").add_displacement("right", -shortening, "x")


def _end_offset(traj):
    i = np.argmin(np.hypot(traj.vertices[:, 0] - L, traj.vertices[:, 1]))
    return traj.displacement[:, i, 1]


def test_strut_buckles_onto_the_elastica_by_branch_switching():
    """Euler buckling under displacement control: the straight strut's lowest eigenvalue crosses zero at the
    Euler load (a bifurcation: the mode is sideways, orthogonal to the straight path); the next step is taken
    along that mode (eigenvector injection), and the continuation then follows the buckled branch, which is
    stable and matches the elastica's load against the sideways offset up to w = 0.2 L."""
    from analytic import buckled_strut

    traj = _strut().follow(t_end=1.0, steps=20, until=lambda tr: abs(_end_offset(tr)[-1]) > 0.2 * L,
                           monitor_stability=True, branch_switch=True)
    assert traj.metadata["stopped"] == "until"
    (crit,) = traj.metadata["critical_points"]
    assert crit["kind"] == "bifurcation" and crit["mode_path_cosine"] < 0.05
    k = crit["step"]
    P = -traj.reactions["right"][:, 0]
    w = _end_offset(traj)
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


def test_without_branch_switching_the_perfect_strut_stays_straight():
    """The same continuation without switching stays on the straight (now unstable) branch: the buckled branch
    above is taken deliberately, not by round-off."""
    traj = _strut().follow(t_end=1.0, steps=20, max_steps=3)
    assert traj.metadata["stopped"] == "max_steps" and len(traj) == 4
    assert np.abs(_end_offset(traj)).max() < 1e-5 * L
    assert -traj.reactions["right"][-1, 0] > 2 * P_CR


def test_bad_arguments():
    fem = _strut()
    with pytest.raises(ParameterError, match="monitor_stability=True"):
        fem.follow(branch_switch=True)
    with pytest.raises(ParameterError, match="t_end"):
        fem.follow(t_end=0.0)
    still = Fem(Mesh.rectangle(L, H, size=H, center=(L / 2, 0.0)), materials.NeoHookean(E=E, nu=NU))
    with pytest.raises(ParameterError, match="no load"):
        still.add_support("left").follow()
