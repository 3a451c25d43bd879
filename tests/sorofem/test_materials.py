"""Material laws: stresses against closed forms, numpy against UFL, presets against datasheets."""
import numpy as np
import pytest
from scipy.optimize import brentq

from sorofem import materials as mat
from sorofem.errors import ParameterError
from sorofem.units import kPa, MPa

LAWS = {
    "neo-hookean": lambda **kw: mat.NeoHookean(mu=50 * kPa, **kw),
    "neo-hookean-coupled": lambda **kw: mat.NeoHookean(mu=50 * kPa, form="coupled", **kw),
    "mooney-rivlin": lambda **kw: mat.MooneyRivlin(30 * kPa, 10 * kPa, **kw),
    "yeoh": lambda **kw: mat.Yeoh(17 * kPa, -0.2 * kPa, 0.023 * kPa, **kw),
}


def _random_gradients(n, seed=0, scale=0.3):
    rng = np.random.default_rng(seed)
    F = np.eye(3) + scale * rng.standard_normal((n, 3, 3))
    F[np.linalg.det(F) < 0, 0] *= -1  # keep det F > 0
    return F


@pytest.mark.parametrize("law", sorted(LAWS) + ["linear"])
def test_pk1_is_the_derivative_of_the_energy(law):
    m = mat.LinearElastic(1 * MPa, 0.3) if law == "linear" else LAWS[law]()
    F = _random_gradients(20)
    P = m.pk1(F)
    h = 1e-6
    for i in range(3):
        for j in range(3):
            dF = np.zeros((3, 3))
            dF[i, j] = h
            fd = (m.energy(F + dF) - m.energy(F - dF)) / (2 * h)
            np.testing.assert_allclose(P[:, i, j], fd, rtol=1e-5, atol=1e-6 * m.G)


@pytest.mark.parametrize("law", sorted(LAWS))
def test_stress_free_and_objective(law):
    m = LAWS[law]()
    np.testing.assert_allclose(m.pk1(np.eye(3)), 0, atol=1e-9 * m.G)
    assert m.energy(np.eye(3)) == pytest.approx(0, abs=1e-12 * m.G)
    F = _random_gradients(5, seed=1)
    Q = np.linalg.qr(np.random.default_rng(2).standard_normal((3, 3)))[0]
    Q *= np.sign(np.linalg.det(Q))
    np.testing.assert_allclose(m.energy(Q @ F), m.energy(F), rtol=1e-10)
    np.testing.assert_allclose(m.cauchy(Q @ F), Q @ m.cauchy(F) @ Q.T, rtol=1e-8, atol=1e-9 * m.G)


def _incompressible_uniaxial(m, lam):
    """Nominal stress of uniaxial tension of the incompressible limit: P = 2 (lam - lam^-2)(W1 + W2 / lam)."""
    I1b = lam**2 + 2 / lam
    I2b = 2 * lam + 1 / lam**2
    W1, W2 = m._dw(I1b, I2b)
    return 2 * (lam - lam**-2) * (W1 + W2 / lam)


@pytest.mark.parametrize("law", sorted(LAWS))
@pytest.mark.parametrize("lam", [0.7, 1.3, 2.0, 3.0])
def test_uniaxial_nearly_incompressible_matches_closed_form(law, lam):
    """With kappa = 1e5 mu the lateral stretch is lam^-1/2 up to O(mu/kappa): stress within 1e-3."""
    m = LAWS[law](kappa=1e5 * LAWS[law]().mu)

    def lateral_stress(t):
        return m.pk1(np.diag([lam, t, t]))[1, 1]
    t = brentq(lateral_stress, 0.3 * lam**-0.5, 3 * lam**-0.5, xtol=1e-14)
    assert t == pytest.approx(lam**-0.5, rel=1e-3)
    assert m.pk1(np.diag([lam, t, t]))[0, 0] == pytest.approx(_incompressible_uniaxial(m, lam), rel=1e-3)


@pytest.mark.parametrize("nu", [0.3, 0.45])
@pytest.mark.parametrize("lam", [0.8, 1.5, 2.5])
def test_uniaxial_compressible_neo_hookean_from_cauchy_formula(nu, lam):
    """Independent route: sigma = mu J^-5/3 dev(b) + kappa/2 (J - 1/J) I; lateral sigma = 0 fixes t."""
    m = mat.NeoHookean(E=1 * MPa, nu=nu)
    mu, K = m.mu, m.kappa

    def sigma(t, i):
        J = lam * t * t
        b = np.array([lam**2, t**2, t**2])
        return mu * J ** (-5 / 3) * (b[i] - b.sum() / 3) + 0.5 * K * (J - 1 / J)
    t = brentq(lambda t: sigma(t, 1), 0.2, 2.0, xtol=1e-15)
    P11 = lam * t * t * sigma(t, 0) / lam
    F = np.diag([lam, t, t])
    assert m.pk1(F)[0, 0] == pytest.approx(P11, rel=1e-10)
    assert m.pk1(F)[1, 1] == pytest.approx(0, abs=1e-8 * mu)


@pytest.mark.parametrize("a", [0.6, 1.0, 1.7])
def test_coupled_neo_hookean_uniaxial_strain_closed_form(a):
    """F = diag(a, 1, 1): P11 = mu (a - 1/a) + lambda ln(a)/a, P22 = P33 = lambda ln a (the coupled form's
    textbook stresses); the decoupled form with the same constants agrees to second order in ln a only."""
    mu, lmbda = 40 * kPa, 150 * kPa
    m = mat.NeoHookean(mu=mu, lmbda=lmbda, form="coupled")
    P = m.pk1(np.diag([a, 1.0, 1.0]))
    np.testing.assert_allclose(np.diag(P), [mu * (a - 1 / a) + lmbda * np.log(a) / a, lmbda * np.log(a),
                                            lmbda * np.log(a)], rtol=1e-12, atol=1e-9 * mu)
    assert m.energy(np.diag([a, 1.0, 1.0])) == pytest.approx(
        0.5 * mu * (a * a - 1) - mu * np.log(a) + 0.5 * lmbda * np.log(a) ** 2, rel=1e-12, abs=1e-12 * mu)
    d = mat.NeoHookean(mu=mu, lmbda=lmbda)       # the decoupled default, same small-strain constants
    assert d.form == "decoupled" and d.K == pytest.approx(m.K) and m.lmbda == pytest.approx(lmbda)
    eps = 1e-5
    assert d.pk1(np.diag([1 + eps, 1, 1]))[0, 0] == pytest.approx(m.pk1(np.diag([1 + eps, 1, 1]))[0, 0], rel=1e-4)


def test_lame_parameters_are_accepted_and_converted():
    m = mat.NeoHookean(E=1 * MPa, lmbda=2 * MPa, form="coupled")
    assert m.E == pytest.approx(1 * MPa) and m.lmbda == pytest.approx(2 * MPa)
    assert m.nu == pytest.approx(m.lmbda / (2 * (m.lmbda + m.mu)))
    c = m.with_(lmbda=3 * MPa)
    assert c.form == "coupled" and c.lmbda == pytest.approx(3 * MPa) and c.mu == pytest.approx(m.mu)
    assert m.with_(nu=0.3).nu == pytest.approx(0.3)


def test_small_strain_constants_are_consistent():
    m = mat.NeoHookean(E=1 * MPa, nu=0.3)
    assert m.E == pytest.approx(1 * MPa) and m.nu == pytest.approx(0.3) and m.G == pytest.approx(1 * MPa / 2.6)
    # a small uniaxial strain gives sigma = E eps with lateral contraction -nu eps
    eps = 1e-6
    t = brentq(lambda t: m.pk1(np.diag([1 + eps, t, t]))[1, 1], 0.99, 1.01, xtol=1e-16)
    assert (1 - t) / eps == pytest.approx(0.3, rel=1e-4)
    assert m.pk1(np.diag([1 + eps, t, t]))[0, 0] / eps == pytest.approx(1 * MPa, rel=1e-4)
    lin = mat.LinearElastic(E=2 * MPa, nu=0.25)
    assert lin.E == pytest.approx(2 * MPa) and lin.nu == pytest.approx(0.25)
    y = mat.Yeoh(10 * kPa, kappa=1 * MPa)
    assert y.G == pytest.approx(20 * kPa) and y.K == pytest.approx(1 * MPa)


@pytest.mark.parametrize("law", sorted(LAWS) + ["linear"])
def test_ufl_energy_equals_numpy_energy(law):
    """Assemble the UFL energy of a homogeneous deformation over the unit cube: equals the numpy energy."""
    from mpi4py import MPI
    import ufl
    import dolfinx.fem
    import dolfinx.mesh
    m = mat.LinearElastic(1 * MPa, 0.3) if law == "linear" else LAWS[law]()
    F = _random_gradients(1, seed=3, scale=0.2)[0]
    msh = dolfinx.mesh.create_unit_cube(MPI.COMM_SELF, 1, 1, 1)
    Fc = dolfinx.fem.Constant(msh, F)
    form = dolfinx.fem.form(m.strain_energy(Fc) * ufl.dx(metadata={"quadrature_degree": 1}))
    assert dolfinx.fem.assemble_scalar(form) == pytest.approx(float(m.energy(F)), rel=1e-10)


DATASHEET_100PCT = {  # engineering stress at 100 % elongation [Pa], Smooth-On datasheets
    "Ecoflex0010": 55 * kPa, "Ecoflex0030": 69 * kPa, "Ecoflex0050": 83 * kPa,
    "DragonSkin10": 152 * kPa, "DragonSkin30": 593 * kPa,
}
SHORE_A = {"DragonSkin30": 30, "Elastosil4601": 28, "Elastic50A": 50, "Elastic80A": 80, "NinjaFlex": 85,
           "TPU90A": 90}


@pytest.mark.parametrize("name", sorted(DATASHEET_100PCT))
def test_presets_match_datasheet_100pct_modulus(name):
    m = mat.PRESETS[name]()
    assert _incompressible_uniaxial(m, 2.0) == pytest.approx(DATASHEET_100PCT[name], rel=0.2)


@pytest.mark.parametrize("name", sorted(SHORE_A))
def test_presets_agree_with_hardness_within_gents_scatter(name):
    """Guards against unit slips (a factor 1000): the modulus is within a factor 2 of Gent's estimate."""
    ratio = mat.PRESETS[name]().E / mat.gent_modulus(SHORE_A[name])
    assert 0.5 < ratio < 2.0, ratio


@pytest.mark.parametrize("name", sorted(mat.PRESETS))
def test_every_preset_is_physical(name):
    m = mat.PRESETS[name]()
    assert 500 < m.density < 2000 and 0 <= m.damping < 1 and 0 < m.nu < 0.5 and m.E > 0
    assert m.with_(nu=0.4999).nu == pytest.approx(0.4999)
    assert m.with_(density=2000).density == 2000


@pytest.mark.parametrize("make, match", [
    (lambda: mat.NeoHookean(mu=-1.0), "mu must be a positive"),
    (lambda: mat.NeoHookean(E=1e6, nu=0.5), "outside \\(-1, 0.5\\)"),
    (lambda: mat.NeoHookean(), "exactly one of mu"),
    (lambda: mat.NeoHookean(mu=1e5, kappa=1e6, nu=0.3), "not both"),
    (lambda: mat.MooneyRivlin(-2e4, 1e4), "c10 \\+ c01 > 0"),
    (lambda: mat.Yeoh(0.0), "c1 must be a positive"),
    (lambda: mat.LinearElastic(1e9, nu=0.6), "outside"),
    (lambda: mat.Ecoflex0030(density=0), "density must be a positive"),
    (lambda: mat.Ecoflex0030(damping=-0.1), "damping must be a non-negative"),
    (lambda: mat.NeoHookean(mu=float("nan")), "positive finite"),
    (lambda: mat.NeoHookean(mu=1e5, lmbda=1e6, nu=0.3), "not lmbda and nu"),
    (lambda: mat.NeoHookean(mu=1e5, lmbda=-1e5), "lmbda > -2 mu / 3"),
    (lambda: mat.NeoHookean(mu=1e5, form="lame"), "form must be one of"),
])
def test_non_physical_parameters_are_refused(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def test_inverted_or_misshaped_gradients_are_refused():
    m = mat.NeoHookean(mu=1e5)
    with pytest.raises(ParameterError, match="det F must be positive"):
        m.pk1(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ParameterError, match=r"shape \(\.\.\., 3, 3\)"):
        m.pk1(np.eye(2))
