"""Implicit dynamics: energy conservation, numerical damping as predicted, stability at large steps."""
import numpy as np
import pytest

from sorofem import materials
from sorofem.errors import ParameterError
from sorofem.fem import Fem
from sorofem.fem.dynamics import TimeIntegrator, amplification_matrix
from sorofem.mesh import Mesh
from sorofem.units import MPa

L, H = 0.1, 0.01


def _cantilever():
    msh = Mesh.rectangle(L, H, size=H / 2, center=(L / 2, 0.0), cell="quadrilateral")
    return Fem(msh, materials.NeoHookean(E=1 * MPa, nu=0.3, density=1000.0)).add_support("left")


def test_trapezoidal_newmark_conserves_energy_over_1000_steps():
    fem = _cantilever()
    period = 1 / fem.eigen(1).frequencies[0]
    traj = fem.simulate(t_end=25 * period, dt=period / 40, scheme="newmark",
                        velocity=lambda x: np.vstack([0 * x[0], 0.05 * x[0] / L]))
    assert len(traj) == 1001
    energy = traj.energy + traj.kinetic_energy
    assert np.abs(energy / energy[0] - 1).max() < 1e-3
    assert traj.kinetic_energy.max() > 0.9 * energy[0]  # it really oscillates


@pytest.mark.parametrize("rho_inf, omega_dt", [(0.5, 10.0), (0.0, 3.0), (0.8, 0.5)])
def test_generalized_alpha_damps_a_mode_as_its_amplification_matrix_predicts(rho_inf, omega_dt):
    """Start in the first mode (small amplitude: linear) at Omega = omega dt: the energy step by step equals
    that of the scheme's amplification matrix for the single oscillator, E = (Omega^2 u^2 + (v dt)^2)/2."""
    fem = _cantilever()
    modes = fem.eigen(1)
    omega = 2 * np.pi * modes.frequencies[0]
    phi = modes.functions[0].x.array
    fem.displacement.x.array[:] = 1e-6 / np.abs(phi).max() * phi
    dt = omega_dt / omega
    traj = fem.simulate(t_end=8 * dt, dt=dt, rho_inf=rho_inf)
    A = amplification_matrix(TimeIntegrator("generalized_alpha", rho_inf), omega_dt)
    state, expected = np.array([1.0, 0.0, -omega_dt**2]), []
    for _ in range(9):
        expected.append(0.5 * (omega_dt**2 * state[0] ** 2 + state[1] ** 2) / (0.5 * omega_dt**2))
        state = A @ state
    energy = (traj.energy + traj.kinetic_energy) / traj.energy[0]
    np.testing.assert_allclose(energy, expected, rtol=1e-2, atol=1e-4)
    if omega_dt >= 10:
        radius = max(abs(np.linalg.eigvals(A)))
        assert radius == pytest.approx(rho_inf, abs=0.2)  # unresolved frequencies decay by ~rho_inf a step


def test_steps_100_times_the_explicit_limit_stay_stable():
    """dt = 100 h / c_p (c_p the dilatational wave speed): generalized-alpha stays bounded and dissipates."""
    fem = _cantilever()
    mat = fem.materials[0][1]
    c_p = np.sqrt((mat.K + 4 * mat.G / 3) / mat.density)
    dt = 100 * (H / 2) / c_p
    traj = fem.simulate(t_end=60 * dt, dt=dt, rho_inf=0.8, velocity=lambda x: np.vstack([0 * x[0], 0.05 * x[0] / L]))
    energy = traj.energy + traj.kinetic_energy
    assert np.all(np.isfinite(traj.displacement))
    # bounded (generalized-alpha is not strictly energy-decaying in the nonlinear regime) and dissipative
    assert energy.max() <= 1.2 * energy[0] and energy[-1] < energy[0]
    assert np.all(np.diff(traj.times) == pytest.approx(dt))  # no step had to be cut


def test_rayleigh_damping_decays_the_fundamental_at_the_requested_ratio():
    """zeta = 5 % at the first two frequencies: the free vibration's log decrement is 2 pi zeta / sqrt(1-zeta^2)."""
    fem = _cantilever()
    f = fem.eigen(2).frequencies
    zeta = 0.05
    rayleigh = Fem.rayleigh_coefficients(zeta, 2 * np.pi * f[0], 2 * np.pi * f[1])
    period = 1 / f[0]
    traj = fem.simulate(t_end=6 * period, dt=period / 60, scheme="newmark", rayleigh=rayleigh,
                        velocity=lambda x: np.vstack([0 * x[0], 1e-4 * x[0] / L]))
    energy = traj.energy + traj.kinetic_energy
    # energy ~ exp(-2 zeta omega t): compare the decay over 5 periods
    t = traj.times
    k0, k1 = np.searchsorted(t, period), np.searchsorted(t, 5 * period)
    rate = np.log(energy[k0] / energy[k1]) / (t[k1] - t[k0])
    assert rate == pytest.approx(2 * zeta * 2 * np.pi * f[0], rel=0.1)


def test_bad_dynamic_input():
    fem = _cantilever()
    with pytest.raises(ParameterError, match="rho_inf must lie in"):
        fem.simulate(t_end=1.0, dt=0.1, rho_inf=1.5)
    with pytest.raises(ParameterError, match="not unconditionally stable"):
        fem.simulate(t_end=1.0, dt=0.1, scheme="newmark", beta=0.1, gamma=0.5)
    with pytest.raises(ParameterError, match="must be positive"):
        fem.simulate(t_end=1.0, dt=-0.1)
