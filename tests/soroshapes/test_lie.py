"""SO(3)/SE(3) kernels of :mod:`soroshapes.lie` against independent references.

References: ``scipy.linalg.expm`` of the hat/ad matrices, numpy inverses, truncated power series, central
finite differences of the exponential, and identities (group inverse, adjoint equivariance, duality).
"""
import math

import numpy as np
import pytest
from numba import njit
from scipy.linalg import expm

from soroshapes import lie

RNG_SEED = 20240611
# rotation angles (rad): zero, tiny, across the series switch, moderate, large, near and at pi
ANGLES = [0.0, 1e-9, 1e-5, 0.3, 1.0, 2.5, math.pi - 1e-7]
PI_ANGLES = [math.pi - 1e-7, math.pi - 1e-12, math.pi]


def _unit(rng):
    d = rng.normal(size=3)
    return d / np.linalg.norm(d)


def _twist(rng, angle, vscale=1.0):
    """Random twist whose rotation angle is exactly `angle`."""
    return np.concatenate([angle * _unit(rng), vscale * rng.normal(size=3)])


def _pose(rng, angle):
    """Random pose with rotation angle `angle`, built with numpy only (Rodrigues via K^2 = kk^T - I)."""
    k = _unit(rng)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    g = np.eye(4)
    g[:3, :3] = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)
    g[:3, 3] = rng.normal(size=3)
    return g


def _series(A, coeff, n=40):
    """sum_k coeff(k) A^k for k < n."""
    out = np.zeros_like(A)
    P = np.eye(A.shape[0])
    for k in range(n):
        out += coeff(k) * P
        P = P @ A
    return out


# ------------------------------------------------------------------------------------------------ hat, vee, ad
def test_hat_vee_roundtrip_and_cross_product():
    rng = np.random.default_rng(RNG_SEED)
    w, x, xi = rng.normal(size=3), rng.normal(size=3), rng.normal(size=6)
    np.testing.assert_allclose(lie.hat3(w) @ x, np.cross(w, x), atol=1e-15)
    np.testing.assert_array_equal(lie.hat3(w), -lie.hat3(w).T)
    np.testing.assert_array_equal(lie.vee3(lie.hat3(w)), w)
    np.testing.assert_array_equal(lie.vee6(lie.hat6(xi)), xi)
    X = lie.hat6(xi)
    np.testing.assert_array_equal(X[:3, :3], lie.hat3(xi[:3]))
    np.testing.assert_array_equal(X[:3, 3], xi[3:])
    np.testing.assert_array_equal(X[3], np.zeros(4))


def test_ad6_is_the_lie_bracket_and_coad6_its_negative_transpose():
    rng = np.random.default_rng(RNG_SEED + 1)
    a, b = rng.normal(size=6), rng.normal(size=6)
    A, B = lie.hat6(a), lie.hat6(b)
    np.testing.assert_allclose(lie.hat6(lie.ad6(a) @ b), A @ B - B @ A, atol=1e-14)
    np.testing.assert_array_equal(lie.coad6(a), -lie.ad6(a).T)
    np.testing.assert_allclose(lie.ad6(a) @ a, 0.0, atol=1e-15)


# ------------------------------------------------------------------------------------------------ exponentials
@pytest.mark.parametrize("angle", ANGLES + PI_ANGLES)
def test_expSO3_is_a_rotation_and_matches_expm(angle):
    rng = np.random.default_rng(RNG_SEED + 2)
    w = angle * _unit(rng)
    R = lie.expSO3(w)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert abs(np.linalg.det(R) - 1.0) < 1e-14
    np.testing.assert_allclose(R, expm(lie.hat3(w)), atol=1e-13)
    np.testing.assert_allclose(R @ w, w, atol=1e-14)  # the axis is fixed


@pytest.mark.parametrize("angle", ANGLES + PI_ANGLES)
def test_expSE3_matches_expm(angle):
    rng = np.random.default_rng(RNG_SEED + 3)
    xi = _twist(rng, angle)
    np.testing.assert_allclose(lie.expSE3(xi), expm(lie.hat6(xi)), atol=1e-13)


# ------------------------------------------------------------------------------------------------ logarithms
@pytest.mark.parametrize("angle", ANGLES)
def test_log_of_exp_is_identity_below_pi(angle):
    rng = np.random.default_rng(RNG_SEED + 4)
    for _ in range(5):
        xi = _twist(rng, angle)
        np.testing.assert_allclose(lie.logSE3(lie.expSE3(xi)), xi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lie.logSO3(lie.expSO3(xi[:3])), xi[:3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("angle", ANGLES + PI_ANGLES)
def test_exp_of_log_is_identity(angle):
    rng = np.random.default_rng(RNG_SEED + 5)
    for _ in range(5):
        g = _pose(rng, angle)
        xi = lie.logSE3(g)
        assert np.linalg.norm(xi[:3]) <= math.pi + 1e-15
        assert abs(np.linalg.norm(xi[:3]) - angle) < 1e-12
        np.testing.assert_allclose(lie.expSE3(xi), g, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lie.expSO3(lie.logSO3(g[:3, :3])), g[:3, :3], rtol=0, atol=1e-12)


def test_logSO3_at_pi_returns_the_axis_up_to_sign():
    rng = np.random.default_rng(RNG_SEED + 6)
    for _ in range(10):
        k = _unit(rng)
        R = 2.0 * np.outer(k, k) - np.eye(3)  # rotation by pi about k
        w = lie.logSO3(R)
        assert abs(np.linalg.norm(w) - math.pi) < 1e-14
        assert min(np.abs(w - math.pi * k).max(), np.abs(w + math.pi * k).max()) < 1e-13


# ------------------------------------------------------------------------------------------------ adjoints
@pytest.mark.parametrize("angle", [0.0, 1e-9, 1.0, math.pi])
def test_adjoint_conjugates_twists_and_exponentiates_ad(angle):
    rng = np.random.default_rng(RNG_SEED + 7)
    g = _pose(rng, angle)
    xi, mu = rng.normal(size=6), rng.normal(size=6)
    ginv = np.linalg.inv(g)
    np.testing.assert_allclose(lie.hat6(lie.Ad(g) @ xi), g @ lie.hat6(xi) @ ginv, atol=1e-13)
    np.testing.assert_allclose(lie.invSE3(g), ginv, atol=1e-14)
    np.testing.assert_allclose(lie.Ad_inv(g), np.linalg.inv(lie.Ad(g)), atol=1e-13)
    np.testing.assert_allclose(lie.coAd(g), np.linalg.inv(lie.Ad(g)).T, atol=1e-13)
    assert abs((lie.coAd(g) @ mu) @ (lie.Ad(g) @ xi) - mu @ xi) < 1e-13  # power is frame-invariant
    eta = _twist(rng, angle)
    np.testing.assert_allclose(lie.Ad(lie.expSE3(eta)), expm(lie.ad6(eta)), atol=1e-12)
    np.testing.assert_allclose(lie.coAd(lie.expSE3(eta)), expm(lie.coad6(eta)), atol=1e-12)


# ------------------------------------------------------------------------------------------------ tangent operators
@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-3, 0.3, 1.0, 2.5, math.pi - 1e-7])
def test_left_jacobian_SO3(angle):
    rng = np.random.default_rng(RNG_SEED + 8)
    w = angle * _unit(rng)
    J, Ji = lie.JlSO3(w), lie.JlSO3_inv(w)
    np.testing.assert_allclose(J @ Ji, np.eye(3), atol=1e-13)
    np.testing.assert_allclose(J, _series(lie.hat3(w), lambda k: 1.0 / math.factorial(k + 1)), atol=1e-13)
    # d/dh exp(w + h e_k) exp(w)^T = (J e_k)^   (left Jacobian)
    h = 1e-6
    RT = lie.expSO3(w).T
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        dR = (lie.expSO3(w + e) - lie.expSO3(w - e)) / (2 * h)
        np.testing.assert_allclose(lie.vee3(dR @ RT), J[:, k], atol=1e-8)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-3, 0.3, 1.0, 2.5, math.pi - 1e-7])
def test_tangent_operator_against_finite_differences(angle):
    rng = np.random.default_rng(RNG_SEED + 9)
    xi = _twist(rng, angle)
    T = lie.TSE3(xi)
    ginv = lie.invSE3(lie.expSE3(xi))
    h = 1e-5
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        dg = (lie.expSE3(xi + e) - lie.expSE3(xi - e)) / (2 * h)
        np.testing.assert_allclose(ginv @ dg, lie.hat6(T[:, k]), atol=1e-8)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-3, 0.3, 1.0, 2.0])
def test_tangent_operator_against_its_series_and_inverse(angle):
    rng = np.random.default_rng(RNG_SEED + 10)
    xi = _twist(rng, angle, vscale=2.0)
    T, Ti = lie.TSE3(xi), lie.TSE3_inv(xi)
    ref = _series(-lie.ad6(xi), lambda k: 1.0 / math.factorial(k + 1), n=60)
    np.testing.assert_allclose(T, ref, atol=1e-13)
    np.testing.assert_allclose(T @ Ti, np.eye(6), atol=1e-12)
    np.testing.assert_allclose(Ti @ T, np.eye(6), atol=1e-12)
    np.testing.assert_allclose(Ti, np.linalg.inv(ref), atol=1e-12)


def test_tangent_operator_of_pure_translation_and_of_pure_rotation():
    v = np.array([0.0, 0.0, 0.0, 0.3, -1.2, 2.0])
    np.testing.assert_allclose(lie.TSE3(v), np.eye(6) - 0.5 * lie.ad6(v), atol=0)  # ad^2 = 0: T = I - ad/2
    np.testing.assert_allclose(lie.TSE3_inv(v), np.eye(6) + 0.5 * lie.ad6(v), atol=0)
    rng = np.random.default_rng(RNG_SEED + 11)
    w = 1.3 * _unit(rng)
    T = lie.TSE3(np.concatenate([w, np.zeros(3)]))
    Jr = lie.JlSO3(-w)  # right Jacobian of SO(3) on both diagonal blocks
    np.testing.assert_allclose(T[:3, :3], Jr, atol=1e-14)
    np.testing.assert_allclose(T[3:, 3:], Jr, atol=1e-14)
    np.testing.assert_allclose(T[3:, :3], 0.0, atol=0)


# ------------------------------------------------------------------------------------------------ branch switches
def _all_kernels(xi):
    g = lie.expSE3(xi)
    return [lie.expSO3(xi[:3]), lie.JlSO3(xi[:3]), lie.JlSO3_inv(xi[:3]), g, lie.TSE3(xi), lie.TSE3_inv(xi),
            lie.logSO3(g[:3, :3]), lie.logSE3(g)]


@pytest.mark.parametrize("switch", [lie.SMALL_ANGLE, lie._SMALL_ANGLE_INV, math.pi / 2])
def test_continuity_across_branch_switches(switch):
    rng = np.random.default_rng(RNG_SEED + 12)
    d, v = _unit(rng), rng.normal(size=3)
    below = _all_kernels(np.concatenate([switch * (1 - 1e-14) * d, v]))
    above = _all_kernels(np.concatenate([switch * (1 + 1e-14) * d, v]))
    for lo, hi in zip(below, above):
        np.testing.assert_allclose(lo, hi, rtol=0, atol=1e-12)


def _scalar_coefficients(theta):
    return np.array([*lie._so3_coeffs(theta), lie._jinv_coeff(theta), *lie._tse3_coeffs(theta),
                     *lie._tse3_inv_coeffs(theta)])


@pytest.mark.parametrize("switch", [lie.SMALL_ANGLE, lie._SMALL_ANGLE_INV])
def test_series_and_closed_forms_agree_at_the_switch(switch):
    """Each trigonometric coefficient: Taylor branch (just below) == closed form (at) the switch, relatively."""
    below = _scalar_coefficients(np.nextafter(switch, 0.0))
    at = _scalar_coefficients(switch)
    np.testing.assert_allclose(below, at, rtol=1e-13, atol=0)
    # and the series reproduce the t -> 0 limits of the closed forms
    np.testing.assert_allclose(_scalar_coefficients(0.0),
                               [1, 1 / 2, 1 / 6, 1 / 12, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 12, -1 / 720], rtol=1e-15)


# ------------------------------------------------------------------------------------------------ nopython
@njit
def _chain_in_numba(xi, eta):
    """Uses every kernel from jitted code; returns quantities that are zero if the kernels agree."""
    g = lie.expSE3(xi)
    err = np.abs(lie.logSE3(g) - xi).max()
    err = max(err, np.abs(lie.vee6(lie.hat6(eta)) - eta).max())
    err = max(err, np.abs(lie.vee3(lie.hat3(eta[:3])) - eta[:3]).max())
    err = max(err, np.abs(lie.expSO3(xi[:3]) - g[:3, :3]).max())
    err = max(err, np.abs(lie.logSO3(g[:3, :3]) - xi[:3]).max())
    err = max(err, np.abs(lie.Ad(g) @ lie.Ad_inv(g) - np.eye(6)).max())
    err = max(err, np.abs(lie.coAd(g) - lie.Ad_inv(g).T).max())
    err = max(err, np.abs(lie.coad6(eta) + lie.ad6(eta).T).max())
    err = max(err, np.abs(lie.TSE3(xi) @ lie.TSE3_inv(xi) - np.eye(6)).max())
    err = max(err, np.abs(lie.JlSO3(xi[:3]) @ lie.JlSO3_inv(xi[:3]) - np.eye(3)).max())
    err = max(err, np.abs(lie.invSE3(g) @ g - np.eye(4)).max())
    return err


def test_kernels_compile_in_nopython_mode():
    rng = np.random.default_rng(RNG_SEED + 13)
    for angle in (0.0, 1e-9, 1.0, math.pi - 1e-7):
        xi = _twist(rng, angle)
        assert _chain_in_numba(xi, rng.normal(size=6)) < 1e-12


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.3, 1.49, 1.51, 2.5, np.pi - 1e-3])
def test_tangent_operator_derivative_against_finite_differences(angle):
    rng = np.random.default_rng(7)
    w = rng.normal(size=3)
    xi = np.concatenate([angle * w / np.linalg.norm(w), rng.normal(size=3)])
    delta = rng.normal(size=6)
    eps = 1e-6
    fd = (lie.TSE3(xi + eps * delta) - lie.TSE3(xi - eps * delta)) / (2 * eps)
    assert np.allclose(lie.dTSE3(xi, delta), fd, atol=1e-8, rtol=1e-7)


def test_tangent_operator_derivative_series_and_closed_form_agree_at_the_switch():
    rng = np.random.default_rng(3)
    w = rng.normal(size=3)
    w /= np.linalg.norm(w)
    v, delta = rng.normal(size=3), rng.normal(size=6)
    below = lie.dTSE3(np.concatenate([(lie._SMALL_ANGLE_D - 1e-12) * w, v]), delta)
    above = lie.dTSE3(np.concatenate([(lie._SMALL_ANGLE_D + 1e-12) * w, v]), delta)
    assert np.allclose(below, above, rtol=1e-11, atol=1e-12)
