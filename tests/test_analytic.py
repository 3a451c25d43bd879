"""The references themselves are checked against known limits before they check anything else."""
import numpy as np
import pytest

from analytic import (cantilever_frequencies, cylinder_inflation_pressure, elastica_gravity_tip, elastica_tip,
                      sphere_inflation_pressure)


def test_elastica_small_load_is_euler_bernoulli():
    L, EI, P = 1.0, 1.0, 1e-4
    dx, dy = elastica_tip(L, EI, P)
    assert dy == pytest.approx(-P * L**3 / (3 * EI), rel=1e-6)


def test_elastica_large_load_matches_tabulated_value():
    """Bisshopp & Drucker (1945): for P L^2 / EI = 1 the tip deflection is 0.30172 L... and horizontal
    shortening 0.05643 L (their Table 1)."""
    dx, dy = elastica_tip(1.0, 1.0, 1.0)
    assert -dy == pytest.approx(0.30172, abs=2e-5)
    assert -dx == pytest.approx(0.05643, abs=2e-5)



def test_gravity_elastica_small_load_is_euler_bernoulli():
    """dy -> -w L^4 / (8 EI) and, to second order, dx -> -w^2 L^7 / (112 EI^2)."""
    L, EI, w = 1.0, 1.0, 1e-4
    dx, dy = elastica_gravity_tip(L, EI, w)
    assert dy == pytest.approx(-w * L**4 / (8 * EI), rel=1e-6)
    assert dx == pytest.approx(-w**2 * L**7 / (112 * EI**2), rel=1e-4)


def test_gravity_elastica_large_load_self_converges_and_matches_shooting():
    """w L^3 / EI = 12.6 (the soft benchmark rod under its own weight): the result does not depend on the
    initial mesh, and an independent shooting solution (solve_ivp on theta'(0), root by brentq) agrees."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    L, EI, w = 0.2, 4.908738521234052e-4, 0.7704755982928969
    coarse, fine = elastica_gravity_tip(L, EI, w, n=40), elastica_gravity_tip(L, EI, w, n=4000)
    np.testing.assert_allclose(coarse, fine, rtol=0, atol=1e-10 * L)

    def shoot(kappa0, full=False):
        def rhs(s, y):
            return [y[1], w / EI * (L - s) * np.cos(y[0]), np.cos(y[0]), np.sin(y[0])]
        sol = solve_ivp(rhs, (0, L), [0, kappa0, 0, 0], method="DOP853", rtol=1e-12, atol=1e-14)
        return sol.y[:, -1] if full else sol.y[1, -1]
    kappa0 = brentq(shoot, -w * L**2 / (2 * EI), 0.0, xtol=1e-14)
    end = shoot(kappa0, full=True)
    np.testing.assert_allclose(fine, (end[2] - L, end[3]), rtol=0, atol=1e-8 * L)
    assert -fine[1] < w * L**4 / (8 * EI)  # well inside the (wrong, 1.57 L) linear prediction

def test_thick_cylinder_small_strain_is_lame():
    """Small inflation of an incompressible plane-strain cylinder (Lame): u = C/r and
    p = 2 mu C (1/A^2 - 1/B^2), so u(A) = 1e-4 A needs p = 2e-4 mu (B^2 - A^2) / B^2."""
    mu, A, B = 1e5, 1.0, 2.0
    p_lame = 2e-4 * mu * (B**2 - A**2) / B**2
    assert cylinder_inflation_pressure(mu, A, B, A * (1 + 1e-4)) == pytest.approx(p_lame, rel=1e-3)


def test_thick_sphere_thin_limit_has_the_classical_limit_point():
    """Thin incompressible Neo-Hookean sphere: p = 2 mu (H/R)(l^-1 - l^-7); maximum at l = 7^(1/6)."""
    mu, A, H = 1.0, 1.0, 1e-3
    lam = np.linspace(1.05, 2.5, 300)
    p = [sphere_inflation_pressure(mu, A, A + H, A * l) for l in lam]
    thin = 2 * mu * (H / A) * (1 / lam - lam**-7)
    np.testing.assert_allclose(p, thin, rtol=3e-3)
    assert lam[int(np.argmax(p))] == pytest.approx(7 ** (1 / 6), abs=0.01)


def test_cantilever_frequency_ratios():
    f = cantilever_frequencies(1.0, 1.0, 1.0, 1.0, 1.0)
    assert f[1] / f[0] == pytest.approx(6.267, rel=1e-3) and f[2] / f[0] == pytest.approx(17.548, rel=1e-3)
