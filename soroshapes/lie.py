r"""Lie-group kernels for SO(3) and SE(3): hat/vee maps, adjoints, exponential and logarithm, tangent operators.

Conventions (those of Sorotoki and SoRoSim)
-------------------------------------------
- A **twist** is :math:`\xi = (\omega, v) \in \mathbb{R}^6`, *angular part first*: :math:`\omega` in rad (per
  unit of the parameter, e.g. rad/m for a strain, rad/s for a velocity), :math:`v` in m (or m/m, m/s).
- A **rotation** is a 3x3 orthonormal matrix :math:`R` with :math:`\det R = 1`.
- A **pose** :math:`g \in SE(3)` is the 4x4 homogeneous matrix :math:`g = \begin{bmatrix} R & p \\ 0 & 1
  \end{bmatrix}`, :math:`p` in m. It maps body coordinates to spatial ones: :math:`x_s = R x_b + p`.
- :math:`\hat\xi = \begin{bmatrix} \hat\omega & v \\ 0 & 0 \end{bmatrix}` with :math:`\hat\omega x = \omega
  \times x`; the adjoint of a twist is :math:`\mathrm{ad}_\xi = \begin{bmatrix} \hat\omega & 0 \\ \hat v &
  \hat\omega \end{bmatrix}` (so :math:`\mathrm{ad}_\xi \eta = [\xi, \eta]`), of a pose :math:`\mathrm{Ad}_g =
  \begin{bmatrix} R & 0 \\ \hat p R & R \end{bmatrix}` (so :math:`\widehat{\mathrm{Ad}_g \xi} = g \hat\xi g^{-1}`).
  Wrenches :math:`(m, f)` (moment first) transform with the co-adjoints :math:`\mathrm{ad}^*_\xi =
  -\mathrm{ad}_\xi^T` and :math:`\mathrm{Ad}^*_g = \mathrm{Ad}_g^{-T}`, so that power is invariant.
- The tangent operator :math:`T(\xi)` is the *body-frame* (right) one: :math:`\frac{d}{dt} \exp(\hat\xi) =
  \exp(\hat\xi)\, (T(\xi) \dot\xi)^\wedge` with :math:`T(\xi) = \sum_{k \ge 0} \frac{(-\mathrm{ad}_\xi)^k}{(k+1)!}`.

Numerics
--------
Every function is a numba ``@njit(cache=True)`` kernel: call it from Python with float64 numpy arrays of the
documented shapes, or from other jitted code. Kernels do not check shapes (numba does not bound-check); they
allocate only their result. The trigonometric coefficients (:math:`\sin\theta/\theta`,
:math:`(1-\cos\theta)/\theta^2`, ...) are evaluated by their Taylor series in :math:`\theta^2` (ten terms)
below :data:`SMALL_ANGLE` (1 rad and fourteen terms for :math:`T^{-1}`, whose closed form cancels more) and by
closed forms above it; both branches agree to better than :math:`10^{-13}` relative at the switch. The logarithm of
SO(3) takes the angle from ``atan2`` and, beyond :math:`\pi/2`, the axis from the symmetric part of
:math:`R`, so it stays accurate up to and at :math:`\theta = \pi`.

Examples
--------
>>> import numpy as np
>>> from soroshapes import lie
>>> xi = np.array([0.0, 0.0, np.pi / 2, 1.0, 0.0, 0.0])   # quarter turn about z while moving along x
>>> g = lie.expSE3(xi)
>>> bool(np.allclose(g[:3, 3], [2 / np.pi, 2 / np.pi, 0.0]))   # end of a circular arc of radius 2/pi
True
>>> bool(np.allclose(lie.logSE3(g), xi))
True
"""
import numpy as np
from sorofem._numba import njit  # numba.njit with a cache that concurrent processes may share

__all__ = [
    "SMALL_ANGLE",
    "hat3", "vee3", "hat6", "vee6",
    "ad6", "coad6", "Ad", "Ad_inv", "coAd", "invSE3",
    "expSO3", "logSO3", "expSE3", "logSE3",
    "JlSO3", "JlSO3_inv", "TSE3", "TSE3_inv", "dTSE3",
]

SMALL_ANGLE = 0.5
"""Rotation angle (rad) below which trigonometric coefficients use their Taylor series."""

_SMALL_ANGLE_INV = 1.0  # the T^-1 closed forms cancel more (phi ~ t^2 / 12 divided by t^4): switch later


def _coeffs(*fractions):
    return np.array([p / q for p, q in fractions], dtype=np.float64)


# Taylor coefficients in theta^2 (c0 + c1 t^2 + c2 t^4 + ...), exact fractions from a sympy series expansion.
_SINC = _coeffs((1, 1), (-1, 6), (1, 120), (-1, 5040), (1, 362880), (-1, 39916800), (1, 6227020800),
                (-1, 1307674368000), (1, 355687428096000), (-1, 121645100408832000))  # sin t / t
_COS2 = _coeffs((1, 2), (-1, 24), (1, 720), (-1, 40320), (1, 3628800), (-1, 479001600), (1, 87178291200),
                (-1, 20922789888000), (1, 6402373705728000), (-1, 2432902008176640000))  # (1 - cos t) / t^2
_SIN3 = _coeffs((1, 6), (-1, 120), (1, 5040), (-1, 362880), (1, 39916800), (-1, 6227020800),
                (1, 1307674368000), (-1, 355687428096000), (1, 121645100408832000),
                (-1, 51090942171709440000))  # (t - sin t) / t^3
_JINV = _coeffs((1, 12), (1, 720), (1, 30240), (1, 1209600), (1, 47900160), (691, 1307674368000),
                (1, 74724249600), (3617, 10670622842880000), (43867, 5109094217170944000),
                (174611, 802857662698291200000))  # 1/t^2 - (1 + cos t) / (2 t sin t)
_TSIN = _coeffs((1, 1), (1, 6), (7, 360), (31, 15120), (127, 604800), (73, 3421440), (1414477, 653837184000),
                (8191, 37362124800), (16931177, 762187345920000),
                (5749691557, 2554547108585472000))  # t / sin t
_T1 = _coeffs((1, 2), (0, 1), (-1, 720), (1, 20160), (-1, 1209600), (1, 119750400), (-1, 17435658240),
              (1, 3487131648000), (-1, 914624815104000), (1, 304112751022080000))
_T2 = _coeffs((1, 6), (0, 1), (-1, 5040), (1, 181440), (-1, 13305600), (1, 1556755200), (-1, 261534873600),
              (1, 59281238016000), (-1, 17377871486976000), (1, 6386367771463680000))
_T3 = _coeffs((1, 24), (-1, 360), (1, 13440), (-1, 907200), (1, 95800320), (-1, 14529715200),
              (1, 2988969984000), (-1, 800296713216000), (1, 270322445352960000), (-1, 112400072777760768000))
_T4 = _coeffs((1, 120), (-1, 2520), (1, 120960), (-1, 9979200), (1, 1245404160), (-1, 217945728000),
              (1, 50812489728000), (-1, 15205637551104000), (1, 5676771352412160000),
              (-1, 2585201673888497664000))
# Derivatives of the T coefficients divided by theta: c1'/t = t^2 D3, c2'/t = t^2 D4 (sympy).
_D3 = _coeffs((-1, 180), (1, 3360), (-1, 151200), (1, 11975040), (-1, 1452971520), (1, 249080832000),
              (-1, 57164050944000), (1, 16895152834560000), (-1, 6244448487653376000),
              (1, 2820220007878361088000))
_D4 = _coeffs((-1, 1260), (1, 30240), (-1, 1663200), (1, 155675520), (-1, 21794572800), (1, 4234374144000),
              (-1, 1086116967936000), (1, 354798209525760000), (-1, 143622315216027648000),
              (1, 70505500196959027200000))
_SMALL_ANGLE_D = 1.5  # the derivative closed forms cancel as t^6 / 90 against 8: keep the series longer
_TI2 = _coeffs((1, 12), (0, 1), (-1, 30240), (-1, 604800), (-1, 15966720), (-691, 326918592000), (-1, 14944849920),
               (-3617, 1778437140480000), (-43867, 729870602452992000), (-174611, 100357207837286400000),
               (-77683, 1566788893265756160000), (-236364091, 169382413673174366945280000),
               (-657931, 16921320047270166528000000), (-3392780147, 3157772140621322126622720000000))
_TI4 = _coeffs((-1, 720), (-1, 15120), (-1, 403200), (-1, 11975040), (-691, 261534873600), (-1, 12454041600),
               (-3617, 1524374691840000), (-43867, 638636777146368000), (-174611, 89206406966476800000),
               (-77683, 1410110003939180544000), (-236364091, 153984012430158515404800000),
               (-657931, 15511210043330985984000000), (-3392780147, 2914866591342758886113280000000),
               (-1723168255201, 54270735117574290596988715008000000))


# ----------------------------------------------------------------------------------------------------------
# small helpers
# ----------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _series(c, t2):
    """Horner evaluation of sum_i c[i] t2^i."""
    s = 0.0
    for i in range(c.shape[0] - 1, -1, -1):
        s = s * t2 + c[i]
    return s


@njit(cache=True)
def _norm3(w):
    return np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])


@njit(cache=True)
def _so3_coeffs(theta):
    """(sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3)."""
    if theta < SMALL_ANGLE:
        t2 = theta * theta
        return _series(_SINC, t2), _series(_COS2, t2), _series(_SIN3, t2)
    s = np.sin(theta)
    h = np.sin(0.5 * theta) / theta
    return s / theta, 2.0 * h * h, (theta - s) / (theta * theta * theta)


@njit(cache=True)
def _jinv_coeff(theta):
    """1/t^2 - (1 + cos t) / (2 t sin t) = (1 - (t/2) cot(t/2)) / t^2."""
    if theta < SMALL_ANGLE:
        return _series(_JINV, theta * theta)
    h = 0.5 * theta
    return (1.0 - h * np.cos(h) / np.sin(h)) / (theta * theta)


@njit(cache=True)
def _tse3_coeffs(theta):
    """Coefficients (c1, c2, c3, c4) of T = I - c1 ad + c2 ad^2 - c3 ad^3 + c4 ad^4 (see :func:`TSE3`)."""
    if theta < SMALL_ANGLE:
        t2 = theta * theta
        c1, c2, c3, c4 = _series(_T1, t2), _series(_T2, t2), _series(_T3, t2), _series(_T4, t2)
    else:
        s, c = np.sin(theta), np.cos(theta)
        h = np.sin(0.5 * theta)
        t2 = theta * theta
        c1 = (8.0 * h * h - theta * s) / (2.0 * t2)
        c2 = (4.0 * theta - 5.0 * s + theta * c) / (2.0 * t2 * theta)
        c3 = (4.0 * h * h - theta * s) / (2.0 * t2 * t2)
        c4 = (2.0 * theta - 3.0 * s + theta * c) / (2.0 * t2 * t2 * theta)
    return c1, c2, c3, c4


@njit(cache=True)
def _tse3_dcoeffs(theta):
    """Derivatives of the coefficients of :func:`_tse3_coeffs` divided by theta: (c1'/t, c2'/t, c3'/t, c4'/t)."""
    t2 = theta * theta
    if theta < _SMALL_ANGLE_D:
        d3, d4 = _series(_D3, t2), _series(_D4, t2)
    else:
        s, c = np.sin(theta), np.cos(theta)
        t6 = t2 * t2 * t2
        d3 = (-t2 * c + 5.0 * theta * s + 8.0 * c - 8.0) / (2.0 * t6)
        d4 = (-t2 * s - 7.0 * theta * c - 8.0 * theta + 15.0 * s) / (2.0 * t6 * theta)
    return t2 * d3, t2 * d4, d3, d4


@njit(cache=True)
def _tse3_inv_coeffs(theta):
    """Coefficients (c2, c4) of T^-1 = I + ad/2 + c2 ad^2 + c4 ad^4 (see :func:`TSE3_inv`)."""
    if theta < _SMALL_ANGLE_INV:
        t2 = theta * theta
        c2, c4 = _series(_TI2, t2), _series(_TI4, t2)
    else:
        h = 0.5 * theta
        sh = np.sin(h)
        cot = np.cos(h) / sh
        phi = h * cot - 1.0
        dphi = 0.5 * cot - 0.25 * theta / (sh * sh)
        t2 = theta * theta
        c2 = dphi / (2.0 * theta) - 2.0 * phi / t2
        c4 = (0.5 * theta * dphi - phi) / (t2 * t2)
    return c2, c4


@njit(cache=True)
def _rodrigues(w, c0, c1, c2):
    """c0 I + c1 w^ + c2 w^ w^, using w^ w^ = w w^T - |w|^2 I."""
    t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    M = np.empty((3, 3))
    d = c0 - c2 * t2
    for i in range(3):
        for j in range(3):
            M[i, j] = c2 * w[i] * w[j]
        M[i, i] += d
    M[0, 1] -= c1 * w[2]
    M[1, 0] += c1 * w[2]
    M[0, 2] += c1 * w[1]
    M[2, 0] -= c1 * w[1]
    M[1, 2] -= c1 * w[0]
    M[2, 1] += c1 * w[0]
    return M


@njit(cache=True)
def _mm6(A, B):
    C = np.zeros((6, 6))
    for i in range(6):
        for k in range(6):
            a = A[i, k]
            if a != 0.0:
                for j in range(6):
                    C[i, j] += a * B[k, j]
    return C


@njit(cache=True)
def _poly_ad(xi, c1, c2, c3, c4):
    """I + c1 ad + c2 ad^2 + c3 ad^3 + c4 ad^4 for ad = ad6(xi)."""
    A1 = ad6(xi)
    A2 = _mm6(A1, A1)
    A3 = _mm6(A2, A1)
    A4 = _mm6(A3, A1)
    P = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            P[i, j] = c1 * A1[i, j] + c2 * A2[i, j] + c3 * A3[i, j] + c4 * A4[i, j]
        P[i, i] += 1.0
    return P


# ----------------------------------------------------------------------------------------------------------
# hat / vee and adjoints
# ----------------------------------------------------------------------------------------------------------
@njit(cache=True)
def _put_skew(A, r, c, x, k):
    """Write the skew matrix of ``x[k:k+3]`` into ``A[r:r+3, c:c+3]`` (the other entries are untouched)."""
    A[r + 0, c + 1] = -x[k + 2]
    A[r + 0, c + 2] = x[k + 1]
    A[r + 1, c + 0] = x[k + 2]
    A[r + 1, c + 2] = -x[k + 0]
    A[r + 2, c + 0] = -x[k + 1]
    A[r + 2, c + 1] = x[k + 0]


@njit(cache=True)
def hat3(w):
    r"""so(3) hat map: the skew matrix :math:`\hat w` with :math:`\hat w x = w \times x`.

    Parameters
    ----------
    w : (3,) float64 array

    Returns
    -------
    (3, 3) ndarray :math:`\begin{bmatrix} 0 & -w_3 & w_2 \\ w_3 & 0 & -w_1 \\ -w_2 & w_1 & 0 \end{bmatrix}`.
    """
    W = np.zeros((3, 3))
    _put_skew(W, 0, 0, w, 0)
    return W


@njit(cache=True)
def vee3(W):
    r"""so(3) vee map, the inverse of :func:`hat3`: :math:`w = (W_{32}, W_{13}, W_{21})`.

    Only the lower/upper entries named above are read; ``W`` is assumed skew-symmetric.

    Parameters
    ----------
    W : (3, 3) float64 array

    Returns
    -------
    (3,) ndarray
    """
    w = np.empty(3)
    w[0] = W[2, 1]
    w[1] = W[0, 2]
    w[2] = W[1, 0]
    return w


@njit(cache=True)
def hat6(xi):
    r"""se(3) hat map: :math:`\hat\xi = \begin{bmatrix} \hat\omega & v \\ 0 & 0 \end{bmatrix}` for
    :math:`\xi = (\omega, v)`.

    Parameters
    ----------
    xi : (6,) float64 array, angular part first.

    Returns
    -------
    (4, 4) ndarray
    """
    X = np.zeros((4, 4))
    _put_skew(X, 0, 0, xi, 0)
    X[0, 3] = xi[3]
    X[1, 3] = xi[4]
    X[2, 3] = xi[5]
    return X


@njit(cache=True)
def vee6(X):
    r"""se(3) vee map, the inverse of :func:`hat6`: :math:`\xi = (X_{32}, X_{13}, X_{21}, X_{14}, X_{24}, X_{34})`.

    Parameters
    ----------
    X : (4, 4) float64 array

    Returns
    -------
    (6,) ndarray :math:`(\omega, v)`.
    """
    xi = np.empty(6)
    xi[0] = X[2, 1]
    xi[1] = X[0, 2]
    xi[2] = X[1, 0]
    xi[3] = X[0, 3]
    xi[4] = X[1, 3]
    xi[5] = X[2, 3]
    return xi


@njit(cache=True)
def ad6(xi):
    r"""Adjoint of a twist: :math:`\mathrm{ad}_\xi = \begin{bmatrix} \hat\omega & 0 \\ \hat v & \hat\omega
    \end{bmatrix}`, the matrix of the Lie bracket :math:`\eta \mapsto [\xi, \eta]`.

    Parameters
    ----------
    xi : (6,) float64 array :math:`(\omega, v)`.

    Returns
    -------
    (6, 6) ndarray
    """
    A = np.zeros((6, 6))
    _put_skew(A, 0, 0, xi, 0)
    _put_skew(A, 3, 3, xi, 0)
    _put_skew(A, 3, 0, xi, 3)
    return A


@njit(cache=True)
def coad6(xi):
    r"""Co-adjoint of a twist, acting on wrenches :math:`(m, f)`: :math:`\mathrm{ad}^*_\xi = -\mathrm{ad}_\xi^T
    = \begin{bmatrix} \hat\omega & \hat v \\ 0 & \hat\omega \end{bmatrix}`.

    Parameters
    ----------
    xi : (6,) float64 array :math:`(\omega, v)`.

    Returns
    -------
    (6, 6) ndarray
    """
    A = ad6(xi)
    return -A.T.copy()


@njit(cache=True)
def Ad(g):
    r"""Adjoint of a pose: :math:`\mathrm{Ad}_g = \begin{bmatrix} R & 0 \\ \hat p R & R \end{bmatrix}`, so that
    :math:`\widehat{\mathrm{Ad}_g \xi} = g \hat\xi g^{-1}` and :math:`\mathrm{Ad}_{\exp\hat\xi} =
    \exp(\mathrm{ad}_\xi)`.

    Parameters
    ----------
    g : (4, 4) float64 array, homogeneous pose.

    Returns
    -------
    (6, 6) ndarray
    """
    A = np.zeros((6, 6))
    px, py, pz = g[0, 3], g[1, 3], g[2, 3]
    for i in range(3):
        for j in range(3):
            A[i, j] = g[i, j]
            A[i + 3, j + 3] = g[i, j]
    for j in range(3):
        r0, r1, r2 = g[0, j], g[1, j], g[2, j]
        A[3, j] = py * r2 - pz * r1
        A[4, j] = pz * r0 - px * r2
        A[5, j] = px * r1 - py * r0
    return A


@njit(cache=True)
def Ad_inv(g):
    r"""Adjoint of the inverse pose: :math:`\mathrm{Ad}_g^{-1} = \mathrm{Ad}_{g^{-1}} = \begin{bmatrix} R^T & 0
    \\ -R^T \hat p & R^T \end{bmatrix}`, computed without a matrix inverse.

    Parameters
    ----------
    g : (4, 4) float64 array, homogeneous pose.

    Returns
    -------
    (6, 6) ndarray
    """
    return Ad(invSE3(g))


@njit(cache=True)
def coAd(g):
    r"""Co-adjoint of a pose, acting on wrenches :math:`(m, f)`: :math:`\mathrm{Ad}^*_g = \mathrm{Ad}_g^{-T} =
    \begin{bmatrix} R & \hat p R \\ 0 & R \end{bmatrix}`, so that :math:`(\mathrm{Ad}^*_g \mu)^T
    (\mathrm{Ad}_g \xi) = \mu^T \xi` (power is frame-invariant).

    Parameters
    ----------
    g : (4, 4) float64 array, homogeneous pose.

    Returns
    -------
    (6, 6) ndarray
    """
    A = Ad(g)
    C = np.zeros((6, 6))
    for i in range(3):
        for j in range(3):
            C[i, j] = A[i, j]
            C[i + 3, j + 3] = A[i, j]
            C[i, j + 3] = A[i + 3, j]
    return C


@njit(cache=True)
def invSE3(g):
    r"""Inverse pose :math:`g^{-1} = \begin{bmatrix} R^T & -R^T p \\ 0 & 1 \end{bmatrix}`.

    Parameters
    ----------
    g : (4, 4) float64 array, homogeneous pose.

    Returns
    -------
    (4, 4) ndarray
    """
    h = np.zeros((4, 4))
    for i in range(3):
        s = 0.0
        for j in range(3):
            h[i, j] = g[j, i]
            s -= g[j, i] * g[j, 3]
        h[i, 3] = s
    h[3, 3] = 1.0
    return h


# ----------------------------------------------------------------------------------------------------------
# exponential and logarithm
# ----------------------------------------------------------------------------------------------------------
@njit(cache=True)
def expSO3(w):
    r"""Exponential of so(3) (Rodrigues): :math:`R = I + \frac{\sin\theta}{\theta} \hat w +
    \frac{1-\cos\theta}{\theta^2} \hat w^2`, :math:`\theta = |w|`.

    Parameters
    ----------
    w : (3,) float64 array, rotation vector (rad).

    Returns
    -------
    (3, 3) ndarray, orthonormal with determinant 1.
    """
    a, b, _ = _so3_coeffs(_norm3(w))
    return _rodrigues(w, 1.0, a, b)


@njit(cache=True)
def logSO3(R):
    r"""Logarithm of SO(3): the rotation vector :math:`w = \theta k` with :math:`\theta \in [0, \pi]`.

    With :math:`a = \mathrm{vee}(R - R^T)/2 = \sin\theta\, k` and :math:`c = (\mathrm{tr} R - 1)/2 =
    \cos\theta`, the angle is :math:`\theta = \mathrm{atan2}(|a|, c)`. For :math:`\theta \le \pi/2`,
    :math:`w = \frac{\theta}{\sin\theta} a`. Beyond, :math:`a` loses the axis, which is taken from the
    symmetric part instead: :math:`k k^T = \left(\frac{R + R^T}{2} - c I\right) / (1 - c)` (its largest
    column, normalized), with the sign of :math:`a`. At :math:`\theta = \pi` exactly, either of
    :math:`\pm\pi k` is returned.

    Parameters
    ----------
    R : (3, 3) float64 array, rotation matrix.

    Returns
    -------
    (3,) ndarray, rotation vector with :math:`|w| \le \pi`.
    """
    a = np.empty(3)
    a[0] = 0.5 * (R[2, 1] - R[1, 2])
    a[1] = 0.5 * (R[0, 2] - R[2, 0])
    a[2] = 0.5 * (R[1, 0] - R[0, 1])
    s = _norm3(a)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = np.arctan2(s, c)
    if c >= 0.0:
        if theta < SMALL_ANGLE:
            f = _series(_TSIN, theta * theta)
        else:
            f = theta / s
        return f * a
    # theta > pi/2: axis from the symmetric part (R + R^T)/2 = c I + (1 - c) k k^T
    d = 1.0 - c
    i = 0
    best = R[0, 0]
    for j in range(1, 3):
        if R[j, j] > best:
            best = R[j, j]
            i = j
    col = np.empty(3)
    for j in range(3):
        col[j] = 0.5 * (R[j, i] + R[i, j]) / d
    col[i] = (R[i, i] - c) / d
    k = col / np.sqrt(col[i])
    if k[0] * a[0] + k[1] * a[1] + k[2] * a[2] < 0.0:
        k = -k
    return theta * k


@njit(cache=True)
def expSE3(xi):
    r"""Exponential of se(3): :math:`\exp\hat\xi = \begin{bmatrix} \exp\hat\omega & J_l(\omega) v \\ 0 & 1
    \end{bmatrix}` with the left Jacobian :math:`J_l` of SO(3) (:func:`JlSO3`).

    Parameters
    ----------
    xi : (6,) float64 array :math:`(\omega, v)`.

    Returns
    -------
    (4, 4) ndarray, homogeneous pose.
    """
    w = xi[:3]
    a, b, c = _so3_coeffs(_norm3(w))
    R = _rodrigues(w, 1.0, a, b)
    J = _rodrigues(w, 1.0, b, c)
    g = np.zeros((4, 4))
    for i in range(3):
        s = 0.0
        for j in range(3):
            g[i, j] = R[i, j]
            s += J[i, j] * xi[3 + j]
        g[i, 3] = s
    g[3, 3] = 1.0
    return g


@njit(cache=True)
def logSE3(g):
    r"""Logarithm of SE(3): :math:`\omega = \log R` (:func:`logSO3`), :math:`v = J_l(\omega)^{-1} p`.

    Parameters
    ----------
    g : (4, 4) float64 array, homogeneous pose.

    Returns
    -------
    (6,) ndarray :math:`(\omega, v)` with :math:`|\omega| \le \pi`.
    """
    w = logSO3(g[:3, :3])
    Ji = _rodrigues(w, 1.0, -0.5, _jinv_coeff(_norm3(w)))
    xi = np.empty(6)
    for i in range(3):
        xi[i] = w[i]
        xi[3 + i] = Ji[i, 0] * g[0, 3] + Ji[i, 1] * g[1, 3] + Ji[i, 2] * g[2, 3]
    return xi


# ----------------------------------------------------------------------------------------------------------
# tangent operators
# ----------------------------------------------------------------------------------------------------------
@njit(cache=True)
def JlSO3(w):
    r"""Left Jacobian of SO(3): :math:`J_l(w) = \sum_k \frac{\hat w^k}{(k+1)!} = I + \frac{1-\cos\theta}{\theta^2}
    \hat w + \frac{\theta - \sin\theta}{\theta^3} \hat w^2`.

    It gives :math:`\frac{d}{dt} \exp\hat w = (J_l(w) \dot w)^\wedge \exp\hat w` and the translation of
    :math:`\exp\hat\xi`, :math:`p = J_l(\omega) v`. The right Jacobian is :math:`J_l(w)^T = J_l(-w)`.

    Parameters
    ----------
    w : (3,) float64 array, rotation vector (rad).

    Returns
    -------
    (3, 3) ndarray
    """
    _, b, c = _so3_coeffs(_norm3(w))
    return _rodrigues(w, 1.0, b, c)


@njit(cache=True)
def JlSO3_inv(w):
    r"""Inverse left Jacobian of SO(3): :math:`J_l^{-1}(w) = I - \frac12 \hat w + \left(\frac{1}{\theta^2} -
    \frac{1 + \cos\theta}{2\theta\sin\theta}\right) \hat w^2`, defined for :math:`\theta = |w| < 2\pi`.

    Parameters
    ----------
    w : (3,) float64 array, rotation vector (rad).

    Returns
    -------
    (3, 3) ndarray
    """
    return _rodrigues(w, 1.0, -0.5, _jinv_coeff(_norm3(w)))


@njit(cache=True)
def TSE3(xi):
    r"""Body-frame tangent operator of SE(3): :math:`\frac{d}{dt}\exp\hat\xi = \exp\hat\xi\,(T(\xi)\dot\xi)^\wedge`.

    .. math::

        T(\xi) = \sum_{k \ge 0} \frac{(-\mathrm{ad}_\xi)^k}{(k+1)!}
               = I - \frac{4 - 4\cos\theta - \theta\sin\theta}{2\theta^2} \mathrm{ad}_\xi
                 + \frac{4\theta - 5\sin\theta + \theta\cos\theta}{2\theta^3} \mathrm{ad}_\xi^2
                 - \frac{2 - 2\cos\theta - \theta\sin\theta}{2\theta^4} \mathrm{ad}_\xi^3
                 + \frac{2\theta - 3\sin\theta + \theta\cos\theta}{2\theta^5} \mathrm{ad}_\xi^4,

    :math:`\theta = |\omega|` (exact, since :math:`\mathrm{ad}_\xi` is annihilated by :math:`x(x^2 +
    \theta^2)^2`). In a Cosserat rod with :math:`g(X) = \exp(\hat\xi(X))` it maps strain rates to the body
    velocity.

    Parameters
    ----------
    xi : (6,) float64 array :math:`(\omega, v)`.

    Returns
    -------
    (6, 6) ndarray
    """
    c1, c2, c3, c4 = _tse3_coeffs(_norm3(xi[:3]))
    return _poly_ad(xi, -c1, c2, -c3, c4)


@njit(cache=True)
def TSE3_inv(xi):
    r"""Inverse of the tangent operator :func:`TSE3`:
    :math:`T(\xi)^{-1} = \frac{\mathrm{ad}_\xi}{I - e^{-\mathrm{ad}_\xi}} = \sum_k \frac{B_k^+}{k!}
    \mathrm{ad}_\xi^k` (Bernoulli numbers with :math:`B_1^+ = +\frac12`).

    The odd part of :math:`x / (1 - e^{-x})` is exactly :math:`x/2`, the even part is :math:`\frac{x}{2}
    \coth\frac{x}{2}`, so with :math:`\varphi(\theta) = \frac{\theta}{2}\cot\frac{\theta}{2} - 1`,

    .. math::

        T^{-1} = I + \tfrac12 \mathrm{ad}_\xi + \left(\frac{\varphi'}{2\theta} - \frac{2\varphi}{\theta^2}\right)
                 \mathrm{ad}_\xi^2 + \frac{\theta\varphi'/2 - \varphi}{\theta^4} \mathrm{ad}_\xi^4,

    defined for :math:`\theta = |\omega| < 2\pi`.

    Parameters
    ----------
    xi : (6,) float64 array :math:`(\omega, v)`.

    Returns
    -------
    (6, 6) ndarray
    """
    c2, c4 = _tse3_inv_coeffs(_norm3(xi[:3]))
    return _poly_ad(xi, 0.5, c2, 0.0, c4)


@njit(cache=True)
def dTSE3(xi, delta):
    r"""Directional derivative of the tangent operator :func:`TSE3`:
    :math:`dT = \frac{d}{d\epsilon} T(\xi + \epsilon\delta)\big|_{\epsilon=0}`.

    With :math:`A = \mathrm{ad}_\xi`, :math:`D = \mathrm{ad}_\delta`, :math:`T = I - c_1 A + c_2 A^2 - c_3 A^3 +
    c_4 A^4` and :math:`\theta' = \omega\cdot\delta_\omega / \theta`,

    .. math::

        dT = \sum_{k=1}^4 (-1)^k \left(\frac{c_k'}{\theta}(\omega\cdot\delta_\omega) A^k
             + c_k \sum_{j=0}^{k-1} A^j D A^{k-1-j}\right).

    The coefficient derivatives :math:`c_k'/\theta` use their Taylor series below 1.5 rad. A Cosserat rod's
    Jacobian rate :math:`\dot J` needs it: :math:`\frac{d}{dt}(T(\Omega)\Omega') = dT[\dot\Omega]\,\Omega' +
    T\,\dot\Omega'`.

    Parameters
    ----------
    xi, delta : (6,) float64 arrays :math:`(\omega, v)`.

    Returns
    -------
    (6, 6) ndarray
    """
    theta = _norm3(xi[:3])
    c1, c2, c3, c4 = _tse3_coeffs(theta)
    d1, d2, d3, d4 = _tse3_dcoeffs(theta)
    sd = xi[0] * delta[0] + xi[1] * delta[1] + xi[2] * delta[2]
    A1 = ad6(xi)
    D = ad6(delta)
    A2 = _mm6(A1, A1)
    A3 = _mm6(A2, A1)
    A4 = _mm6(A3, A1)
    P2 = _mm6(D, A1) + _mm6(A1, D)
    P3 = _mm6(P2, A1) + _mm6(A2, D)
    P4 = _mm6(P3, A1) + _mm6(A3, D)
    return (sd * (-d1 * A1 + d2 * A2 - d3 * A3 + d4 * A4)
            - c1 * D + c2 * P2 - c3 * P3 + c4 * P4)
