"""Small numerical helpers shared by the beam solvers (:mod:`soroshapes.beam`) and the network integrator
(:mod:`soroshapes.model`): one finite-difference Jacobian, used everywhere a Jacobian is differenced."""
import numpy as np

__all__ = ["fd_columns", "FD_STEP"]

#: Relative step of forward differences, sqrt(machine epsilon): truncation and round-off errors balance.
FD_STEP = float(np.sqrt(np.finfo(float).eps))


def fd_columns(fun, x, f0, scale, cols=None):
    r"""Forward-difference Jacobian :math:`\partial f/\partial x_j \approx (f(x + h_j e_j) - f_0)/h_j` of ``fun`` at
    ``x`` (``fun(x) = f0``) with steps :math:`h_j` = ``FD_STEP`` :math:`\max(|x_j|, \mathrm{scale}_j)` (the
    step actually taken, after rounding, divides), for the columns ``cols`` (default all), in that order:
    array (len(f0), len(cols))."""
    cols = range(len(x)) if cols is None else cols
    J = np.empty((len(f0), len(cols)))
    for k, j in enumerate(cols):
        h = FD_STEP * max(abs(x[j]), scale[j])
        xp = x.copy()
        xp[j] += h
        J[:, k] = (fun(xp) - f0) / (xp[j] - x[j])
    return J
