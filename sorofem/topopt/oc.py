"""Optimality criteria (OC) update for volume-constrained compliance minimization (the 88-line code's).

For :math:`\\min c(x)` s.t. :math:`V(x) \\le f V_0` with :math:`\\partial c/\\partial x_e \\le 0`, the
heuristic fixed-point update of Bendsøe (1995), as in Andreassen et al., Struct. Multidisc. Optim. 43, 1
(2011):

.. math::

    x_e^{new} = \\operatorname{clip}\\left(x_e \\sqrt{\\frac{-\\partial c/\\partial x_e}{\\lambda\\,
    \\partial V/\\partial x_e}},\\; \\max(x_{min}, x_e - m),\\; \\min(1, x_e + m)\\right),

with the Lagrange multiplier :math:`\\lambda` found by bisection so that the volume of the *physical*
(filtered, projected) design meets the target.
"""
import numpy as np

from ..errors import ParameterError

__all__ = ["oc_update"]


def oc_update(x, dc, dv, volume, target, move=0.2, xmin=0.0, tol=1e-3, max_bisections=200):
    """One OC step.

    Parameters
    ----------
    x : (n,) array
        Current design variables in [xmin, 1].
    dc : (n,) array
        Objective sensitivities (non-positive for compliance; positive values are clipped to -0).
    dv : (n,) array
        Volume sensitivities (positive).
    volume : callable
        ``volume(x_new) -> float``, the physical volume fraction of a candidate design (applies the filter).
    target : float
        Volume fraction to meet.
    move : float
        Move limit per iteration.
    tol : float
        Relative bisection tolerance on the multiplier (0.001 in the 88-line code).

    Returns
    -------
    (n,) array
        The updated design.
    """
    if not 0 < target <= 1:
        raise ParameterError(f"the target volume fraction must lie in (0, 1], got {target!r}")
    x = np.asarray(x, float)
    ratio = np.maximum(-np.asarray(dc, float), 0.0) / np.maximum(np.asarray(dv, float), 1e-30)
    l1, l2 = 0.0, 1e9
    lo, hi = np.maximum(xmin, x - move), np.minimum(1.0, x + move)
    xnew = x
    for _ in range(max_bisections):
        if (l2 - l1) / (l1 + l2) <= tol:
            break
        lmid = 0.5 * (l1 + l2)
        xnew = np.clip(x * np.sqrt(ratio / lmid), lo, hi)
        if volume(xnew) > target:
            l1 = lmid
        else:
            l2 = lmid
    return xnew
