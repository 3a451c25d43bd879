r"""Modal strain bases for Cosserat beams ("geometric variable strain", the ``Basis`` of Sorotoki).

A reduced beam of length :math:`L` (m) describes its strain field by a few generalized coordinates :math:`q`:

.. math:: \xi(\sigma) = \Theta(\sigma)\, q + \xi_0(\sigma), \qquad \sigma \in [0, L],

where :math:`\xi = (\kappa, \varepsilon) \in \mathbb{R}^6` is the strain twist (curvatures in 1/m first, then
the stretch/shear strains, dimensionless) and :math:`\xi_0` the strain of the reference configuration. Each
*active* strain component :math:`a` gets its own :class:`Basis` :math:`\{\phi_k\}_{k<n_a}` and fills one row of
the block-diagonal :math:`\Theta`: :math:`\xi_a(\sigma) = \sum_k \phi_k(\sigma / L)\, q_{a,k} + \xi_{0,a}`.

Conventions
-----------
- A basis lives on the **normalized** arc length :math:`s = \sigma / L \in [0, 1]`; it knows nothing of
  :math:`L`. Only :meth:`Basis.orthonormalize` takes a length, to make the functions orthonormal in
  :math:`L^2(0, L)`.
- The functions are **dimensionless**: the coordinates :math:`q` carry the unit of the strain they scale (1/m
  for a curvature, 1 for an elongation). After ``orthonormalize(length=L)`` the functions scale as
  :math:`L^{-1/2}` (their squared integral over :math:`\sigma` is 1), so :math:`q` carries the strain unit
  times :math:`\mathrm{m}^{1/2}`.
- ``basis.breaks`` lists the points where a piecewise basis may be non-smooth (section ends, element nodes,
  data samples); between consecutive breaks every function is :math:`C^\infty`, so a beam model integrates
  piece by piece. At a break, piecewise functions take the value of the piece to the *right*, except at
  :math:`s = 1`, which belongs to the last piece.

Families: :meth:`~Basis.pcc` (piecewise constant curvature), :meth:`~Basis.linear` (hat functions),
:meth:`~Basis.chebyshev`, :meth:`~Basis.legendre`, :meth:`~Basis.bernstein`, :meth:`~Basis.fourier`, their
piecewise versions :meth:`~Basis.piecewise_chebyshev` and :meth:`~Basis.piecewise_bernstein`, data-driven
bases sampled from FEM (:meth:`~Basis.from_data`, DVS) and any vectorized function (:meth:`~Basis.from_callable`).
Bases are immutable and picklable when their functions are (every built-in family is).

Examples
--------
>>> import numpy as np
>>> from soroshapes import Basis
>>> b = Basis.chebyshev(3)                  # T0, T1, T2 of x = 2s - 1
>>> b([0.0, 0.5, 1.0])
array([[ 1., -1.,  1.],
       [ 1.,  0., -1.],
       [ 1.,  1.,  1.]])
>>> Basis.pcc(4).breaks
array([0.  , 0.25, 0.5 , 0.75, 1.  ])
>>> L = 0.08                                # beam length, m
>>> ob = b.orthonormalize(length=L)         # integral_0^L phi_i(sigma/L) phi_j(sigma/L) dsigma = delta_ij
>>> x, w = np.polynomial.legendre.leggauss(10)
>>> V = ob((x + 1) / 2)
>>> bool(np.allclose(V.T @ (w[:, None] * V) * L / 2, np.eye(3)))
True
"""
import math
import operator
from functools import partial

import numpy as np

from sorofem.errors import DataError, ParameterError

__all__ = ["Basis"]

_S_TOL = 1e-12  # s in [-_S_TOL, 1 + _S_TOL] is clipped to [0, 1] (rounding), beyond is an error

_DEPENDENCE_TOL = 1e-10  # relative norm left after Gram-Schmidt below which a function counts as dependent
_MIN_GAUSS = 21  # Gauss-Legendre points per piece: exact for polynomial integrands up to degree 41


# ----------------------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------------------
def _count(value, what, fix):
    """``value`` as a positive int, or a ParameterError naming ``what`` and how to fix it."""
    if isinstance(value, bool):
        raise ParameterError(f"{what} must be a positive integer, got {value!r}; {fix}")
    try:
        n = operator.index(value)
    except TypeError:
        raise ParameterError(f"{what} must be a positive integer, got {value!r} "
                             f"({type(value).__name__}); {fix}") from None
    if n < 1:
        raise ParameterError(f"{what} must be >= 1, got {n}; {fix}")
    return n


def _as_s(s):
    """Normalized arc length as a 1-D float64 array in [0, 1] (rounding up to 1e-12 is clipped)."""
    arr = np.asarray(s, dtype=np.float64)
    if arr.ndim > 1:
        raise ParameterError(f"s must be a scalar or a 1-D array, got shape {arr.shape}; flatten it first")
    arr = np.atleast_1d(arr)
    if not np.all(np.isfinite(arr)):
        raise ParameterError("s contains NaN or inf; s is the normalized arc length sigma / L in [0, 1]")
    if arr.size and (arr.min() < -_S_TOL or arr.max() > 1.0 + _S_TOL):
        raise ParameterError(f"s must lie in [0, 1] (s = sigma / L, normalized arc length), got values in "
                             f"[{arr.min():.6g}, {arr.max():.6g}]; divide the arc length by the beam length")
    return np.clip(arr, 0.0, 1.0)


def _as_breaks(breaks):
    b = np.array(breaks, dtype=np.float64)   # a copy: the basis freezes it
    if b.ndim != 1 or b.size < 2 or not np.all(np.isfinite(b)):
        raise ParameterError(f"breaks must be a 1-D finite array of at least two points, got {breaks!r}")
    if b[0] != 0.0 or b[-1] != 1.0 or np.any(np.diff(b) <= 0.0):
        raise ParameterError(f"breaks must increase strictly from 0.0 to 1.0 (normalized arc length), "
                             f"got {b.tolist()}")
    return b


# ----------------------------------------------------------------------------------------------------------
# families: each takes validated s (m,) and returns (m, n)
# ----------------------------------------------------------------------------------------------------------
def _sections(s, breaks):
    """Piece index j (right piece at a break, last piece at s = 1) and local coordinate t in [0, 1]."""
    j = np.clip(np.searchsorted(breaks, s, side="right") - 1, 0, breaks.size - 2)
    return j, (s - breaks[j]) / (breaks[j + 1] - breaks[j])   # in [0, 1]: rounding is monotone


def _chebyshev_t(t, n):
    """T_0..T_{n-1} of x = 2t - 1 by T_{k+1} = 2x T_k - T_{k-1}."""
    x = 2.0 * t - 1.0
    V = np.empty((t.size, n))
    V[:, 0] = 1.0
    if n > 1:
        V[:, 1] = x
    for k in range(1, n - 1):
        V[:, k + 1] = 2.0 * x * V[:, k] - V[:, k - 1]
    return V


def _legendre_t(t, n):
    """P_0..P_{n-1} of x = 2t - 1 by (k+1) P_{k+1} = (2k+1) x P_k - k P_{k-1} (Bonnet)."""
    x = 2.0 * t - 1.0
    V = np.empty((t.size, n))
    V[:, 0] = 1.0
    if n > 1:
        V[:, 1] = x
    for k in range(1, n - 1):
        V[:, k + 1] = ((2 * k + 1) * x * V[:, k] - k * V[:, k - 1]) / (k + 1)
    return V


def _bernstein_t(t, n):
    """b_{k,d}(t) = C(d, k) t^k (1 - t)^(d - k), k = 0..d, degree d = n - 1."""
    d = n - 1
    k = np.arange(n)
    binom = np.array([math.comb(d, i) for i in range(n)], dtype=np.float64)
    return binom * t[:, None] ** k * (1.0 - t[:, None]) ** (d - k)  # 0.0 ** 0 == 1.0


def _fourier(s, n):
    """1, cos(2 pi s), sin(2 pi s), cos(4 pi s), sin(4 pi s), ..."""
    j = np.arange(n)
    arg = 2.0 * np.pi * ((j + 1) // 2) * s[:, None]
    return np.where(j % 2 == 1, np.cos(arg), np.sin(arg) + (j == 0))  # column 0: sin(0) + 1 = 1


def _piecewise(s, breaks, local, n):
    """``local`` (n functions of the local coordinate) on each piece, zero elsewhere: column j*n + i."""
    j, t = _sections(s, breaks)
    V = np.zeros((s.size, (breaks.size - 1) * n))
    V[np.arange(s.size)[:, None], j[:, None] * n + np.arange(n)] = local(t, n)
    return V


def _hats(s, breaks):
    """Nodal hat functions: on element j, phi_j = 1 - t and phi_{j+1} = t."""
    j, t = _sections(s, breaks)
    V = np.zeros((s.size, breaks.size))
    rows = np.arange(s.size)
    V[rows, j] = 1.0 - t
    V[rows, j + 1] = t
    return V


def _transformed(s, parent, C):
    """Functions parent(s) @ C (the result of :meth:`Basis.orthonormalize`)."""
    return parent(s) @ C


def _user(s, f, n):
    """Call a user function and check it returns a finite (len(s), n) array."""
    V = np.asarray(f(s), dtype=np.float64)
    if V.shape != (s.size, n):
        raise ParameterError(f"the basis function {getattr(f, '__name__', f)!r} returned shape {V.shape} for "
                             f"{s.size} points; it must return an array of shape (len(s), n) = ({s.size}, {n})")
    if not np.all(np.isfinite(V)):
        raise ParameterError(f"the basis function {getattr(f, '__name__', f)!r} returned NaN or inf on s in "
                             f"[{s.min():.6g}, {s.max():.6g}]; it must be finite on [0, 1]")
    return V


# ----------------------------------------------------------------------------------------------------------
# the basis
# ----------------------------------------------------------------------------------------------------------
class Basis:
    r"""A set of :math:`n` scalar functions :math:`\phi_k(s)` of the normalized arc length :math:`s = \sigma/L`.

    Build one with a constructor (:meth:`chebyshev`, :meth:`pcc`, :meth:`from_data`, ...). The functions are
    dimensionless; see the module docstring for how a beam uses them.

    Parameters
    ----------
    fn : callable
        ``fn(s)`` with ``s`` a validated 1-D float64 array in [0, 1], returning an ``(len(s), n)`` array.
    n : int
        Number of functions.
    breaks : array_like
        Strictly increasing points from 0.0 to 1.0; the functions are smooth between consecutive ones.
    name : str
        Short description, e.g. ``"chebyshev(3)"``.
    points : int or tuple of ndarray, optional
        Quadrature used by :meth:`orthonormalize`: Gauss-Legendre points per piece between breaks (default
        ``max(21, n)``, exact for polynomial integrands up to degree 41), or explicit ``(nodes, weights)`` in
        :math:`s` with weights summing to 1.
    """

    def __init__(self, fn, n, breaks, name, points=None):
        self._fn = fn
        self._n = _count(n, "the number of basis functions n", "a basis needs at least one function")
        self._breaks = _as_breaks(breaks)
        self._breaks.setflags(write=False)
        self._name = str(name)
        self._points = max(_MIN_GAUSS, self._n) if points is None else points  # int or (nodes, weights)

    # ------------------------------------------------------------------ properties
    @property
    def n(self):
        """Number of functions (int)."""
        return self._n

    @property
    def breaks(self):
        """Sorted normalized breakpoints (read-only ndarray), 0.0 first and 1.0 last."""
        return self._breaks

    @property
    def name(self):
        """Short description of the family, e.g. ``"chebyshev(3)"``."""
        return self._name

    def __repr__(self):
        return f"Basis({self._name!r}, n={self._n}, pieces={self._breaks.size - 1})"

    # ------------------------------------------------------------------ evaluation
    def __call__(self, s):
        """Values :math:`\\phi_k(s_i)` as a C-contiguous float64 array of shape ``(len(s), n)``.

        Parameters
        ----------
        s : float or array_like (m,)
            Normalized arc length :math:`\\sigma / L`, dimensionless, in [0, 1] (a scalar gives one row).

        Raises
        ------
        ParameterError
            If ``s`` is not 1-D, not finite or outside [0, 1] by more than 1e-12 (rounding is clipped).
        """
        s = _as_s(s)
        return np.ascontiguousarray(self._fn(s), dtype=np.float64)

    def _quadrature(self):
        """Nodes (m,) in [0, 1] and weights (m,) summing to 1 that integrate products of the functions.

        Gauss-Legendre per piece between breaks (or the explicit rule given at construction).
        """
        if isinstance(self._points, tuple):
            return self._points
        x, w = np.polynomial.legendre.leggauss(self._points)
        a, h = self._breaks[:-1, None], np.diff(self._breaks)[:, None]
        return (a + h * (x + 1.0) / 2.0).ravel(), (h * w / 2.0).ravel()

    def orthonormalize(self, length=1.0):
        r"""A new basis spanning the same space, orthonormal in :math:`L^2(0, L)` with :math:`\sigma = sL`.

        .. math:: \int_0^L \psi_i(\sigma/L)\, \psi_j(\sigma/L)\, d\sigma = \delta_{ij}

        computed by modified Gram-Schmidt, applied twice, on the values at Gauss-Legendre nodes of each piece
        between breaks (``max(21, n)`` per piece unless the family chose its own rule: more for Fourier, 4 per
        sample interval for data). The new functions are :math:`\psi = \phi\, C` with :math:`C` upper
        triangular, so :math:`\psi_k` spans the same space as :math:`\phi_0..\phi_k` and piecewise functions
        keep their support.

        Parameters
        ----------
        length : float
            Beam length :math:`L` in m (> 0). The new functions scale as :math:`L^{-1/2}`.

        Raises
        ------
        ParameterError
            If ``length`` is not positive and finite, or a function depends linearly on the previous ones.
        """
        try:
            L = float(length)
        except (TypeError, ValueError):
            L = np.nan
        if not (np.isfinite(L) and L > 0.0):
            raise ParameterError(f"length must be a positive finite length in m, got {length!r}")
        nodes, weights = self._quadrature()
        A = np.sqrt(L * weights)[:, None] * self(nodes)   # Euclidean inner product of columns = L2(0, L)
        Q = np.empty_like(A)
        C = np.zeros((self._n, self._n))
        for k in range(self._n):
            v, c = A[:, k].copy(), np.zeros(self._n)
            c[k] = 1.0
            norm0 = np.linalg.norm(v)
            for _ in range(2):                             # re-orthogonalize: orthogonality to rounding
                for i in range(k):
                    r = Q[:, i] @ v
                    v -= r * Q[:, i]
                    c -= r * C[:, i]
            norm = np.linalg.norm(v)
            if norm <= _DEPENDENCE_TOL * norm0 or norm == 0.0:
                what = "is zero" if norm0 == 0.0 else f"depends linearly on phi_0..phi_{k - 1}"
                raise ParameterError(f"cannot orthonormalize {self._name}: function phi_{k} {what} (relative "
                                     f"norm left {norm / norm0 if norm0 else 0.0:.1e}); drop it or reduce n")
            Q[:, k], C[:, k] = v / norm, c / norm
        return Basis(partial(_transformed, parent=self, C=C), self._n, self._breaks,
                     f"orthonormal({self._name}, L={L:g})", points=self._points)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def pcc(cls, k):
        """Piecewise constant strain on ``k`` equal sections: :math:`\\phi_j` is the indicator of section j."""
        k = _count(k, "the number of sections k", "use k=1 for a single constant-strain section")
        breaks = np.linspace(0.0, 1.0, k + 1)
        indicators = partial(_piecewise, breaks=breaks, local=_chebyshev_t, n=1)  # T_0 = 1 on each section
        return cls(indicators, k, breaks, f"pcc({k})")

    @classmethod
    def linear(cls, k):
        """Piecewise linear nodal hat functions on ``k`` equal elements: k + 1 functions, phi_j(j/k) = 1."""
        k = _count(k, "the number of elements k", "use k=1 for a strain linear along the beam")
        breaks = np.linspace(0.0, 1.0, k + 1)
        return cls(partial(_hats, breaks=breaks), k + 1, breaks, f"linear({k})")

    @classmethod
    def chebyshev(cls, n):
        """Chebyshev polynomials of the first kind :math:`T_0..T_{n-1}` of :math:`x = 2s - 1`."""
        n = _count(n, "the number of modes n", "n=1 is a constant strain")
        return cls(partial(_chebyshev_t, n=n), n, (0.0, 1.0), f"chebyshev({n})")

    @classmethod
    def legendre(cls, n):
        """Legendre polynomials :math:`P_0..P_{n-1}` of :math:`x = 2s - 1` (orthogonal on [0, 1])."""
        n = _count(n, "the number of modes n", "n=1 is a constant strain")
        return cls(partial(_legendre_t, n=n), n, (0.0, 1.0), f"legendre({n})")

    @classmethod
    def bernstein(cls, n):
        """Bernstein polynomials of degree n - 1 (n functions, non-negative, summing to 1)."""
        n = _count(n, "the number of modes n", "n=1 is a constant strain")
        return cls(partial(_bernstein_t, n=n), n, (0.0, 1.0), f"bernstein({n})")

    @classmethod
    def fourier(cls, n):
        """Fourier modes 1, cos(2 pi s), sin(2 pi s), cos(4 pi s), sin(4 pi s), ... (n functions in that order)."""
        n = _count(n, "the number of modes n", "n=1 is a constant strain")
        # products reach 2 pi n rad per unit s; Gauss-Legendre needs about pi n / 2 + 20 points: take 2 n + 20
        return cls(partial(_fourier, n=n), n, (0.0, 1.0), f"fourier({n})", points=max(_MIN_GAUSS, 2 * n + 20))

    @classmethod
    def piecewise_chebyshev(cls, k, n):
        """Chebyshev :math:`T_0..T_{n-1}` of the local coordinate on each of ``k`` equal sections (k n functions).

        Function ``j * n + i`` is :math:`T_i(2t - 1)` on section j (local :math:`t \\in [0, 1]`), zero elsewhere.
        """
        k = _count(k, "the number of sections k", "use k=1 for a single section")
        n = _count(n, "the number of modes per section n", "n=1 is piecewise constant strain")
        breaks = np.linspace(0.0, 1.0, k + 1)
        return cls(partial(_piecewise, breaks=breaks, local=_chebyshev_t, n=n), k * n, breaks,
                   f"piecewise_chebyshev({k}, {n})", points=max(_MIN_GAUSS, n))

    @classmethod
    def piecewise_bernstein(cls, k, n):
        """Bernstein polynomials of degree n - 1 on each of ``k`` equal sections (k n functions, as above)."""
        k = _count(k, "the number of sections k", "use k=1 for a single section")
        n = _count(n, "the number of modes per section n", "n=1 is piecewise constant strain")
        breaks = np.linspace(0.0, 1.0, k + 1)
        return cls(partial(_piecewise, breaks=breaks, local=_bernstein_t, n=n), k * n, breaks,
                   f"piecewise_bernstein({k}, {n})", points=max(_MIN_GAUSS, n))

    @classmethod
    def from_data(cls, s, values):
        """A data-driven basis (DVS): columns of sampled strain modes, interpolated by natural cubic splines.

        Parameters
        ----------
        s : array_like (m,)
            Normalized arc length of the samples, strictly increasing from exactly 0 to exactly 1 (to 1e-12).
        values : array_like (m, n)
            Column k holds :math:`\\phi_k(s_i)` (dimensionless), e.g. strain modes recovered from FEM snapshots.

        The breaks are the sample points (the splines are cubic between them), and :meth:`orthonormalize`
        integrates each interval with 4 Gauss points, exactly.

        Raises
        ------
        DataError
            If ``s`` or ``values`` hold NaN or inf.
        ParameterError
            If the shapes do not match, ``s`` is not strictly increasing or does not span [0, 1].
        """
        from scipy.interpolate import CubicSpline   # scipy only when a data basis is built

        s = np.asarray(s, dtype=np.float64)
        values = np.asarray(values, dtype=np.float64)
        if s.ndim != 1 or s.size < 2:
            raise ParameterError(f"s must be a 1-D array of at least 2 samples, got shape {s.shape}")
        if values.ndim != 2 or values.shape[0] != s.size or values.shape[1] < 1:
            raise ParameterError(f"values must have shape (len(s), n) = ({s.size}, n), got {values.shape}; "
                                 f"one column per basis function (use values[:, None] for a single one)")
        if not np.all(np.isfinite(s)):
            raise DataError(f"s holds {np.count_nonzero(~np.isfinite(s))} NaN/inf sample(s); clean the data")
        bad = ~np.isfinite(values)
        if bad.any():
            rows, cols = np.nonzero(bad)
            raise DataError(f"values hold {bad.sum()} NaN/inf entries (first at row {rows[0]}, column "
                            f"{cols[0]}); clean or drop those samples")
        if np.any(np.diff(s) <= 0.0):
            i = int(np.argmax(np.diff(s) <= 0.0))
            raise ParameterError(f"s must be strictly increasing, but s[{i}] = {s[i]:.6g} >= s[{i + 1}] = "
                                 f"{s[i + 1]:.6g}; sort the samples and merge duplicates")
        if abs(s[0]) > _S_TOL or abs(s[-1] - 1.0) > _S_TOL:
            raise ParameterError(f"s must cover [0, 1] exactly (s = sigma / L), got [{s[0]:.6g}, {s[-1]:.6g}]; "
                                 f"sample both ends of the beam and divide the arc length by its length")
        s = s.copy()
        s[0], s[-1] = 0.0, 1.0
        spline = CubicSpline(s, values, axis=0, bc_type="natural")
        x, w = np.polynomial.legendre.leggauss(4)               # exact for the degree-6 product of two cubics
        h = np.diff(s)[:, None]
        quad = ((s[:-1, None] + h * (x + 1.0) / 2.0).ravel(), (h * w / 2.0).ravel())
        return cls(spline, values.shape[1], s, f"data(m={s.size}, n={values.shape[1]})", points=quad)

    @classmethod
    def from_callable(cls, f, n, breaks=(0.0, 1.0)):
        """Any vectorized function ``f(s) -> (len(s), n)``, smooth between ``breaks``.

        ``f`` is called on 1-D float64 arrays of normalized arc length in [0, 1] and checked for shape and
        finiteness at the breaks, the piece midpoints and a few more points now, and for shape and finiteness
        on every call. :meth:`orthonormalize` uses ``max(21, n)`` Gauss points per piece: add breaks for
        functions that oscillate faster than a polynomial of degree 20.
        """
        n = _count(n, "the number of functions n", "f must return at least one column")
        if not callable(f):
            raise ParameterError(f"f must be callable as f(s) -> array (len(s), n), got {type(f).__name__}")
        b = _as_breaks(breaks)
        probe = np.unique(np.concatenate([b, (b[:-1] + b[1:]) / 2.0, np.linspace(0.0, 1.0, 7)]))
        basis = cls(partial(_user, f=f, n=n), n, b, f"callable({getattr(f, '__name__', type(f).__name__)})")
        basis(probe)
        return basis
