"""Adaptive stepping shared by the quasi-static and the dynamic solvers.

A step from ``t`` to ``t + dt`` is attempted; if its Newton iteration converges the step is accepted and,
when it was easy (at most ``easy`` iterations), the next step grows by 1.5x up to ``dt_max``. A failed step
is undone and halved; below ``dt_min`` the march stops with :class:`ConvergenceError`, whose ``load_level``
attribute is the last converged ``t``. ``stop`` ends the march early (after an accepted step): the
arc-length continuation marches the arc length and stops on the load or a user condition.
"""
from ..errors import ConvergenceError

__all__ = ["march"]


def march(t0, t_end, dt, dt_min, dt_max, attempt, accept, reject, advice, easy=4, stop=None):
    """Advance from ``t0`` to ``t_end``.

    Parameters
    ----------
    attempt : callable(t, dt) -> NewtonOutcome
        Try the step (the state is restored by ``reject`` when it fails).
    accept : callable(t_new, dt, outcome)
        Record the converged state.
    reject : callable(t, dt, outcome)
        Restore the state of ``t``.
    advice : str
        What to try, appended to the error message.
    stop : callable() -> bool, optional
        Asked after every accepted step; True ends the march there.

    Returns
    -------
    float
        The final time (``t_end``, or where ``stop`` ended the march).
    """
    t = float(t0)
    while t < t_end - 1e-12 * max(abs(t_end), 1.0):
        dt = min(dt, t_end - t)
        out = attempt(t, dt)
        if out.converged:
            t += dt
            accept(t, dt, out)
            if stop is not None and stop():
                return t
            if out.iterations <= easy:
                dt = min(1.5 * dt, dt_max)
            continue
        reject(t, dt, out)
        dt /= 2
        if dt < dt_min:
            e = ConvergenceError(
                f"the step from t = {t:.6g} failed at step size {2 * dt:.3g} < the minimum {dt_min:.3g} "
                f"({out.reason}; residual {out.residual:.3e}). Reached t = {t:.6g} of {t_end:.6g}. Try: {advice}")
            e.load_level = t
            raise e
    return t
