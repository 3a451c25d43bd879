"""Strain bases of :mod:`soroshapes.basis` against independent references.

References: ``numpy.polynomial`` (chebval, legval, Gauss-Legendre rules of other orders than the module's),
``scipy.interpolate.BPoly`` for Bernstein polynomials, ``scipy.integrate.quad`` for Gram matrices, closed forms
(Fourier modes, orthonormal Legendre polynomials sqrt((2k+1)/L) P_k) and identities (partition of unity,
nodal hats, disjoint supports).
"""
import pickle

import numpy as np
import pytest
from numpy.polynomial import chebyshev as npcheb
from numpy.polynomial import legendre as npleg
from scipy.integrate import quad
from scipy.interpolate import BPoly

from sorofem.errors import DataError, ParameterError
from soroshapes import Basis

RNG_SEED = 20240612
LENGTHS = [0.08, 1.0]  # m


def _data_basis():
    """A DVS-like basis: three smooth modes sampled at 33 uneven points."""
    s = np.sort(np.concatenate([[0.0, 1.0], np.random.default_rng(1).uniform(0.01, 0.99, 31)]))
    return Basis.from_data(s, np.column_stack([np.ones_like(s), np.sin(3 * s), np.exp(-2 * s) * s]))


def _kinked(s):
    """Three functions smooth on [0, 0.3] and [0.3, 1]: 1, |s - 0.3|, s^2."""
    return np.column_stack([np.ones_like(s), np.abs(s - 0.3), s * s])


FAMILIES = {
    "pcc": lambda: Basis.pcc(4),
    "linear": lambda: Basis.linear(3),
    "chebyshev": lambda: Basis.chebyshev(5),
    "legendre": lambda: Basis.legendre(5),
    "bernstein": lambda: Basis.bernstein(6),
    "fourier": lambda: Basis.fourier(7),
    "piecewise_chebyshev": lambda: Basis.piecewise_chebyshev(3, 4),
    "piecewise_bernstein": lambda: Basis.piecewise_bernstein(2, 5),
    "data": _data_basis,
    "callable": lambda: Basis.from_callable(_kinked, 3, breaks=(0.0, 0.3, 1.0)),
}


def _dense_rule(breaks, points=64, length=1.0):
    """Gauss-Legendre with `points` nodes per piece: nodes in s, weights in sigma = s * length."""
    x, w = npleg.leggauss(points)
    a, h = np.asarray(breaks)[:-1, None], np.diff(breaks)[:, None]
    return (a + h * (x + 1) / 2).ravel(), (length * h * w / 2).ravel()


def _gram(basis, length, other=None):
    """Independent Gram matrix integral_0^L phi_i(sigma/L) psi_j(sigma/L) dsigma (psi = other or phi)."""
    other = basis if other is None else other
    s, w = _dense_rule(np.union1d(basis.breaks, other.breaks), length=length)
    return basis(s).T @ (w[:, None] * other(s))


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


# ------------------------------------------------------------------------------------------------ structure
@pytest.mark.parametrize("basis, n, breaks", [
    (Basis.pcc(3), 3, [0, 1 / 3, 2 / 3, 1]),
    (Basis.pcc(1), 1, [0, 1]),
    (Basis.linear(4), 5, [0, 0.25, 0.5, 0.75, 1]),
    (Basis.chebyshev(3), 3, [0, 1]),
    (Basis.legendre(1), 1, [0, 1]),
    (Basis.bernstein(4), 4, [0, 1]),
    (Basis.fourier(6), 6, [0, 1]),
    (Basis.piecewise_chebyshev(3, 2), 6, [0, 1 / 3, 2 / 3, 1]),
    (Basis.piecewise_bernstein(2, 3), 6, [0, 0.5, 1]),
    (Basis.from_callable(_kinked, 3, breaks=[0, 0.3, 1]), 3, [0, 0.3, 1]),
])
def test_count_breaks_and_output_shape(basis, n, breaks):
    assert basis.n == n
    np.testing.assert_allclose(basis.breaks, breaks, rtol=0, atol=1e-15)
    assert basis.breaks[0] == 0.0 and basis.breaks[-1] == 1.0
    with pytest.raises(ValueError):
        basis.breaks[0] = 0.5                      # immutable description
    for s, m in [(0.3, 1), ([0.0, 0.5, 1.0], 3), (np.linspace(0, 1, 17)[::2], 9), (np.empty(0), 0)]:
        V = basis(s)
        assert V.shape == (m, n) and V.dtype == np.float64 and V.flags.c_contiguous
    assert basis.name in repr(basis) and f"n={n}" in repr(basis)


def test_data_basis_breaks_are_its_samples():
    s = np.linspace(0, 1, 9) ** 2
    b = Basis.from_data(s, np.column_stack([s, 1 - s]))
    assert b.n == 2
    np.testing.assert_array_equal(b.breaks, s)
    # ends off by rounding (a sum of element lengths) are snapped to exactly 0 and 1
    b = Basis.from_data(s * (1 - 1e-13) + 1e-13, np.column_stack([s, 1 - s]))
    assert b.breaks[0] == 0.0 and b.breaks[-1] == 1.0


def test_lazy_import_and_pickle():
    import soroshapes
    assert soroshapes.Basis is Basis and "Basis" in soroshapes.__all__
    for make in FAMILIES.values():
        b = make()
        for basis in (b, b.orthonormalize(0.08)):
            s = np.linspace(0, 1, 11)
            np.testing.assert_array_equal(pickle.loads(pickle.dumps(basis))(s), basis(s))


# ------------------------------------------------------------------------------------------------ values
@pytest.mark.parametrize("n", [1, 2, 7, 12])
def test_chebyshev_and_legendre_match_numpy(rng, n):
    s = np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 200)])
    x = 2 * s - 1
    I = np.eye(n)
    ref_t = np.column_stack([npcheb.chebval(x, I[k]) for k in range(n)])
    ref_p = np.column_stack([npleg.legval(x, I[k]) for k in range(n)])
    np.testing.assert_allclose(Basis.chebyshev(n)(s), ref_t, rtol=0, atol=1e-13)
    np.testing.assert_allclose(Basis.legendre(n)(s), ref_p, rtol=0, atol=1e-13)


@pytest.mark.parametrize("n", [1, 2, 5, 15])
def test_bernstein_partition_of_unity_nonnegative_and_values(rng, n):
    s = np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 200)])
    V = Basis.bernstein(n)(s)
    assert np.all(V >= 0)
    np.testing.assert_allclose(V.sum(axis=1), 1.0, rtol=0, atol=1e-13)
    # scipy's Bernstein-form polynomial with a unit coefficient vector is one basis function
    I = np.eye(n)
    ref = np.column_stack([BPoly(I[k][:, None], [0.0, 1.0])(s) for k in range(n)])
    np.testing.assert_allclose(V, ref, rtol=0, atol=1e-13)
    # endpoint interpolation: only the first (last) polynomial is non-zero at s = 0 (s = 1)
    np.testing.assert_array_equal(V[:2], np.vstack([I[0], I[-1]]))


@pytest.mark.parametrize("k", [1, 2, 5])
def test_linear_hats_are_nodal_partition_of_unity_and_linear(rng, k):
    b = Basis.linear(k)
    nodes = np.arange(k + 1) / k
    np.testing.assert_allclose(b(nodes), np.eye(k + 1), rtol=0, atol=1e-14)
    s = rng.uniform(0, 1, 300)
    V = b(s)
    assert np.all(V >= 0)
    np.testing.assert_allclose(V.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    # each hat is max(0, 1 - |k s - j|); the nodal values of s itself reproduce s (linear precision)
    ref = np.maximum(0, 1 - np.abs(k * s[:, None] - np.arange(k + 1)))
    np.testing.assert_allclose(V, ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(V @ nodes, s, rtol=0, atol=1e-14)


def test_pcc_indicators_and_break_convention(rng):
    k = 3
    b = Basis.pcc(k)
    s = rng.uniform(0, 1, 300)
    ref = (np.floor(k * s)[:, None] == np.arange(k)).astype(float)
    np.testing.assert_array_equal(b(s), ref)
    # at an interior break the section to the right holds; s = 1 belongs to the last section
    np.testing.assert_array_equal(b([0.0, 1 / 3, 2 / 3, 1.0]), [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]])
    np.testing.assert_array_equal(b(np.nextafter(1 / 3, 0)), [[1, 0, 0]])
    np.testing.assert_array_equal(Basis.pcc(1)([0, 0.5, 1]), np.ones((3, 1)))


def test_fourier_values(rng):
    s = np.concatenate([[0.0, 0.25, 1.0], rng.uniform(0, 1, 100)])
    V = Basis.fourier(6)(s)
    w = 2 * np.pi * s
    ref = np.column_stack([np.ones_like(s), np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w), np.cos(3 * w)])
    np.testing.assert_allclose(V, ref, rtol=0, atol=1e-14)


@pytest.mark.parametrize("family, local", [
    (Basis.piecewise_chebyshev, lambda t, i: npcheb.chebval(2 * t - 1, np.eye(i + 1)[i])),
    (Basis.piecewise_bernstein, None),
])
@pytest.mark.parametrize("k, n", [(1, 3), (3, 4), (4, 1)])
def test_piecewise_families_live_on_their_section(rng, family, local, k, n):
    b = family(k, n)
    s = np.concatenate([np.arange(k + 1) / k, rng.uniform(0, 1, 300)])
    V = b(s)
    section = np.minimum(np.floor(k * s + 1e-12), k - 1).astype(int)   # right piece at breaks, last at 1
    t = k * s - section
    for j in range(k):
        cols = slice(j * n, (j + 1) * n)
        outside = section != j
        assert np.all(V[outside, cols] == 0.0), f"section {j} functions leak outside their section"
        for i in range(n):
            if local is None:                       # Bernstein: scipy BPoly of a unit coefficient vector
                ref = BPoly(np.eye(n)[i][:, None], [0.0, 1.0])(t[~outside])
            else:
                ref = local(t[~outside], i)
            np.testing.assert_allclose(V[~outside, j * n + i], ref, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------------ orthonormalize
@pytest.mark.parametrize("length", LENGTHS)
@pytest.mark.parametrize("family", FAMILIES)
def test_orthonormalize_identity_gram_and_same_span(family, length):
    b = FAMILIES[family]()
    ob = b.orthonormalize(length=length)
    assert ob.n == b.n and np.array_equal(ob.breaks, b.breaks)
    np.testing.assert_allclose(_gram(ob, length), np.eye(b.n), rtol=0, atol=1e-12)
    # every original function is its projection on the new ones: phi = sum_j <phi, psi_j> psi_j
    s = np.linspace(0, 1, 257)
    P = _gram(b, length, ob)                        # P[i, j] = <phi_i, psi_j>
    np.testing.assert_allclose(ob(s) @ P.T, b(s), rtol=0, atol=1e-11 * max(1.0, np.abs(b(s)).max()))
    # and each new function is a combination of the originals (residual of a least-squares fit)
    coef, *_ = np.linalg.lstsq(b(s), ob(s), rcond=None)
    np.testing.assert_allclose(b(s) @ coef, ob(s), rtol=0, atol=1e-10)


@pytest.mark.parametrize("basis", [Basis.legendre(4), Basis.fourier(3), Basis.pcc(2)], ids=repr)
def test_orthonormal_gram_against_adaptive_quad(basis):
    L = 0.08
    ob = basis.orthonormalize(L)
    for i in range(ob.n):
        for j in range(i, ob.n):
            val, err = quad(lambda sig: ob(sig / L)[0, i] * ob(sig / L)[0, j], 0.0, L,
                            points=basis.breaks[1:-1] * L, epsabs=1e-13, epsrel=1e-12, limit=200)
            assert abs(val - (i == j)) < 1e-11, (i, j, val)


@pytest.mark.parametrize("length", LENGTHS)
def test_orthonormal_legendre_closed_form(length):
    """Gram-Schmidt of P_0..P_{n-1} in L2(0, L) is sqrt((2k + 1) / L) P_k(2 sigma / L - 1)."""
    n = 12
    s = np.linspace(0, 1, 301)
    ref = npleg.legvander(2 * s - 1, n - 1) * np.sqrt((2 * np.arange(n) + 1) / length)
    np.testing.assert_allclose(Basis.legendre(n).orthonormalize(length)(s), ref, rtol=0,
                               atol=1e-10 * np.abs(ref).max())
    # Chebyshev spans the same polynomials in the same order: same result up to rounding
    np.testing.assert_allclose(Basis.chebyshev(n).orthonormalize(length)(s), ref, rtol=0,
                               atol=1e-10 * np.abs(ref).max())


@pytest.mark.parametrize("family, n", [(Basis.chebyshev, 12), (Basis.legendre, 12), (Basis.fourier, 16)])
def test_many_modes_stay_accurate(family, n):
    L = 0.08
    ob = family(n).orthonormalize(L)
    s, w = _dense_rule([0.0, 1.0], points=97, length=L)
    V = ob(s)
    np.testing.assert_allclose(V.T @ (w[:, None] * V), np.eye(n), rtol=0, atol=1e-10)
    # orthonormalizing again changes nothing
    np.testing.assert_allclose(ob.orthonormalize(L)(s), V, rtol=0, atol=1e-10 * np.abs(V).max())


def test_orthonormalize_keeps_piecewise_support():
    ob = Basis.piecewise_chebyshev(3, 2).orthonormalize(0.08)
    V = ob(np.array([0.1, 0.5, 0.9]))
    assert np.all(V[0, 2:] == 0) and np.all(V[1, [0, 1, 4, 5]] == 0) and np.all(V[2, :4] == 0)


def test_orthonormalize_refuses_dependent_functions_and_bad_length():
    dep = Basis.from_callable(lambda s: np.column_stack([np.ones_like(s), s, 1 + 2 * s]), 3)
    with pytest.raises(ParameterError, match="phi_2 depends linearly on phi_0..phi_1"):
        dep.orthonormalize()
    zero = Basis.from_callable(lambda s: np.column_stack([s, 0 * s]), 2)
    with pytest.raises(ParameterError, match="phi_1 is zero"):
        zero.orthonormalize()
    for bad in (0.0, -0.08, np.inf, np.nan, "80 mm", None):
        with pytest.raises(ParameterError, match="length"):
            Basis.chebyshev(2).orthonormalize(length=bad)


# ---------------------------------------------------------------------------------------------- data, callables
def test_from_data_interpolates_smooth_functions():
    def errors(m):
        s = np.linspace(0, 1, m)
        b = Basis.from_data(s, np.column_stack([np.exp(s), np.sin(np.pi * s)]))
        np.testing.assert_allclose(b(s), np.column_stack([np.exp(s), np.sin(np.pi * s)]), rtol=0, atol=1e-14)
        x = np.linspace(0, 1, 2001)
        return np.abs(b(x) - np.column_stack([np.exp(x), np.sin(np.pi * x)])).max(axis=0)

    e1, e2 = errors(21), errors(41)
    assert e2[0] < 1e-4 and e2[1] < 1e-6
    # natural end conditions: O(h^2) when f'' != 0 at the ends (exp), O(h^4) when f'' = 0 there (sin(pi s))
    assert e1[0] / e2[0] > 3.5
    assert e1[1] / e2[1] > 14.0


def test_from_data_spline_is_natural():
    """Zero second derivative at both ends (checked by second differences), even where f'' = 1."""
    s = np.linspace(0, 1, 11)
    b = Basis.from_data(s, np.exp(s)[:, None])
    h = 1e-4
    for x in (np.array([0.0, h, 2 * h]), np.array([1 - 2 * h, 1 - h, 1.0])):
        second = (b(x)[0, 0] - 2 * b(x)[1, 0] + b(x)[2, 0]) / h ** 2
        assert abs(second) < 0.05, second


def test_from_data_refuses_bad_input():
    s = np.linspace(0, 1, 6)
    v = np.column_stack([s, s ** 2])
    for bad_v in (np.where(s == s[2], np.nan, s)[:, None], np.full((6, 1), np.inf)):
        with pytest.raises(DataError, match="NaN/inf"):
            Basis.from_data(s, bad_v)
    with pytest.raises(DataError, match="NaN/inf"):
        Basis.from_data(np.where(s == s[3], np.nan, s), v)
    with pytest.raises(ParameterError, match="strictly increasing"):
        Basis.from_data(s[[0, 2, 1, 3, 4, 5]], v)
    with pytest.raises(ParameterError, match="strictly increasing"):
        Basis.from_data(s[[0, 1, 1, 3, 4, 5]], v)
    with pytest.raises(ParameterError, match=r"cover \[0, 1\]"):
        Basis.from_data(s * 0.9, v)
    with pytest.raises(ParameterError, match=r"cover \[0, 1\]"):
        Basis.from_data(s * 0.9 + 0.1, v)
    with pytest.raises(ParameterError, match="shape"):
        Basis.from_data(s, s)                       # 1-D values
    with pytest.raises(ParameterError, match="shape"):
        Basis.from_data(s, v[:-1])                  # one sample short
    with pytest.raises(ParameterError, match="shape"):
        Basis.from_data(s, np.empty((6, 0)))
    with pytest.raises(ParameterError, match="1-D"):
        Basis.from_data(s[:, None], v)
    with pytest.raises(ParameterError, match="1-D"):
        Basis.from_data([0.0], [[1.0]])


def test_from_callable_does_not_freeze_the_callers_breaks():
    breaks = np.array([0.0, 0.3, 1.0])
    b = Basis.from_callable(_kinked, 3, breaks=breaks)
    breaks[1] = 0.5                                 # the caller's array stays writable and the basis unchanged
    assert b.breaks[1] == 0.3


def test_from_callable_validates_at_construction_and_on_call():
    with pytest.raises(ParameterError, match=r"shape \(len\(s\), n\)"):
        Basis.from_callable(lambda s: np.ones((s.size, 2)), 3)
    with pytest.raises(ParameterError, match=r"shape \(len\(s\), n\)"):
        Basis.from_callable(lambda s: np.ones(s.size), 1)
    with pytest.raises(ParameterError, match="NaN or inf"):     # blows up at the kink only
        Basis.from_callable(lambda s: np.where(s == 0.5, np.inf, 1.0)[:, None], 1, breaks=(0, 0.5, 1))
    with pytest.raises(ParameterError, match="callable"):
        Basis.from_callable(np.ones((3, 1)), 1)
    for breaks in [(0.0, 0.5), (0.1, 1.0), (0.0, 0.6, 0.4, 1.0), (0.0,), ((0.0, 1.0),)]:
        with pytest.raises(ParameterError, match="breaks"):
            Basis.from_callable(_kinked, 3, breaks=breaks)
    # a function that misbehaves only at other points is caught when evaluated
    b = Basis.from_callable(lambda s: np.where(s == 0.123, np.nan, s)[:, None], 1)
    with pytest.raises(ParameterError, match="NaN or inf"):
        b([0.123])


# ------------------------------------------------------------------------------------------------ input validation
CONSTRUCTORS = {
    "pcc": lambda v: Basis.pcc(v),
    "linear": lambda v: Basis.linear(v),
    "chebyshev": lambda v: Basis.chebyshev(v),
    "legendre": lambda v: Basis.legendre(v),
    "bernstein": lambda v: Basis.bernstein(v),
    "fourier": lambda v: Basis.fourier(v),
    "piecewise_chebyshev k": lambda v: Basis.piecewise_chebyshev(v, 2),
    "piecewise_chebyshev n": lambda v: Basis.piecewise_chebyshev(2, v),
    "piecewise_bernstein k": lambda v: Basis.piecewise_bernstein(v, 2),
    "piecewise_bernstein n": lambda v: Basis.piecewise_bernstein(2, v),
    "from_callable": lambda v: Basis.from_callable(lambda s: np.ones((s.size, 1)), v),
}


@pytest.mark.parametrize("bad, message", [(0, ">= 1"), (-2, ">= 1"), (2.5, "positive integer"),
                                          (3.0, "positive integer"), ("3", "positive integer"),
                                          (True, "positive integer"), (None, "positive integer")])
@pytest.mark.parametrize("constructor", CONSTRUCTORS)
def test_counts_must_be_positive_integers(constructor, bad, message):
    with pytest.raises(ParameterError, match=message):
        CONSTRUCTORS[constructor](bad)


def test_numpy_integers_are_counts():
    assert Basis.chebyshev(np.int64(4)).n == 4 and Basis.piecewise_bernstein(np.int32(2), 3).n == 6


@pytest.mark.parametrize("family", FAMILIES)
def test_s_outside_unit_interval_is_refused(family):
    b = FAMILIES[family]()
    for bad in (-1e-9, 1.0 + 1e-9, [0.5, 2.0], np.nan, [np.inf]):
        with pytest.raises(ParameterError, match="s "):
            b(bad)
    with pytest.raises(ParameterError, match="1-D"):
        b(np.zeros((2, 2)))
    # rounding within 1e-12 of the ends is clipped to the end
    np.testing.assert_array_equal(b([-1e-13, 1 + 1e-13]), b([0.0, 1.0]))
