r"""Cantilever released under gravity: energy, period, implicit vs explicit (`soro demo cantilever_release`)
=====================================================================================================

Purpose
-------
A validation case for the beam dynamics of :class:`soroshapes.Shapes`: a soft horizontal cantilever is
released from straight at rest under gravity with no damping, and swings about its (large) static sag. The
implicit midpoint rule must conserve the energy (up to a bounded O(h^2) oscillation, no drift); the explicit
RK4 at its stable step must give the same motion; the oscillation period is compared with the first natural
frequency of the linearization about the straight rod (``shp.natural_frequencies(1)``) and about the sagged
equilibrium. The sag is large (the tip drops ~75 % of the length), so neither linear frequency need match
the large-amplitude swing: the report gives all three.

Equations
---------
Strain :math:`\xi = \Theta q + (0, 0, 0, 1, 0, 0)`, Chebyshev :math:`T_0..T_3` on the bending about the body
y axis (``dofs = (0, 4, 0, 0, 0, 0)``, planar motion in the vertical x-z plane), 20 Magnus segments of order
4. Dynamics :math:`M(q)\ddot q + C(q, \dot q)\dot q + Kq = f_g(q)` (``damping=0.0``), energy
:math:`E = \tfrac12\dot q^T M\dot q + \tfrac12 q^T K q - \int \rho A\, g\cdot p\, d\sigma`.

- implicit midpoint, :math:`h` = 1 ms: second order, symplectic for constant :math:`M`; the energy error
  stays bounded.
- classical RK4 at :math:`h_e \le 2/\omega_{max}` (``shp.explicit_step_limit()``, rounded down to divide
  :math:`t_{end}`): fourth order, slightly dissipative.

Drift measure: :math:`\max_t |E(t) - E(0)| / \max_t E_{kin}(t)`. The rod swings like a flexible
pendulum: down, under and past its clamp (the tip reaches x < 0), and back up to straight. Period: twice the
mean time between the major turning points of the tip's horizontal coordinate :math:`x_{tip}` (extrema whose
prominence exceeds a quarter of its range, the release at t = 0 included; the tip height is a poor signal: it
has two minima per cycle). Linear reference about the sag: :math:`K_t\phi = \omega^2 M\phi`,
:math:`K_t = \partial(Kq - f_g)/\partial q` at the static state (central differences).

Parameters
----------
=================  =====================================================================================
rod                length 200 mm, circular section radius 5 mm, E = 1 MPa, nu = 0.45, rho = 1000 kg/m^3
load               gravity 9.81 m/s^2 along -z; base at the origin pointing along +x; undamped
time               2 s (quick: 0.5 s); implicit h = 1 ms; explicit h = explicit_step_limit()
=================  =====================================================================================

Figures
-------
``report.json``: ``energy_drift_implicit``, ``energy_drift_explicit``, ``period_s``, ``swing_frequency_Hz``,
``natural_frequency_straight_Hz`` (``shp.natural_frequencies(1)``), ``natural_frequency_sag_Hz``,
``static_tip_mm``, ``lowest_tip_z_mm``, ``min_tip_x_mm``, ``max_kinetic_mJ``, ``max_tip_difference_mm``
(explicit vs implicit, at the explicit times), ``dt_implicit_s``, ``dt_explicit_s``, ``explicit_step_limit_s``,
``wall_time_implicit_s``, ``wall_time_explicit_s``, ``real_time_factor_implicit``, ``real_time_factor_explicit``,
``steps_implicit``, ``steps_explicit``, ``newton_iterations_mean``, ``t_end_s``. Pictures: ``tip.png`` (tip x
and z against time, both methods, with the static tip), ``energy.png`` (energies and the error E(t) - E(0) of
both methods).
"""
import math
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

LENGTH, RADIUS, MODES = 200 * mm, 5 * mm, 4


#: The full run and the short one (`--quick`, what the tests run): simulated time [s].
FULL = dict(t_end=2.0)
QUICK = dict(t_end=0.5)


def main(out: Path, quick: bool = False) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    shp = build()
    t_end = (QUICK if quick else FULL)["t_end"]
    f_straight = float(shp.natural_frequencies(1)[0])
    q_static = shp.statics(steps=4)
    tip_static = shp.positions(q_static)[-1]
    f_sag = sag_frequency(shp, q_static)

    shp.simulate(0.01, 1e-3)                                       # compile the kernels before timing
    shp.simulate(0.01, 1e-3, method="explicit")
    imp = shp.simulate(t_end, 1e-3, method="implicit")
    limit = shp.explicit_step_limit()
    dt_e = t_end / math.ceil(t_end / limit)
    exp = shp.simulate(t_end, dt_e, method="explicit")

    ref = np.column_stack([np.interp(exp.t, imp.t, imp.tip[:, k]) for k in range(3)])
    period = swing_period(imp.t, imp.tip[:, 0])
    plots(out, imp, exp, tip_static)
    return {
        "t_end_s": t_end,
        "energy_drift_implicit": drift(imp),
        "energy_drift_explicit": drift(exp),
        "period_s": period,
        "swing_frequency_Hz": 1.0 / period if period else None,
        "natural_frequency_straight_Hz": f_straight,
        "natural_frequency_sag_Hz": f_sag,
        "static_tip_mm": [float(v) for v in tip_static / mm],
        "lowest_tip_z_mm": float(imp.tip[:, 2].min() / mm),
        "min_tip_x_mm": float(imp.tip[:, 0].min() / mm),
        "max_kinetic_mJ": float(imp.kinetic.max() * 1e3),
        "max_tip_difference_mm": float(np.abs(exp.tip - ref).max() / mm),
        "dt_implicit_s": 1e-3,
        "dt_explicit_s": dt_e,
        "explicit_step_limit_s": limit,
        "wall_time_implicit_s": float(imp.stats["wall_time"]),
        "wall_time_explicit_s": float(exp.stats["wall_time"]),
        "real_time_factor_implicit": float(t_end / imp.stats["wall_time"]),
        "real_time_factor_explicit": float(t_end / exp.stats["wall_time"]),
        "steps_implicit": int(imp.stats["steps"]),
        "steps_explicit": int(exp.stats["steps"]),
        "newton_iterations_mean": float(imp.stats["newton_iterations_per_step"]),
    }


# ------------------------------------------------------------------------------------------------- the steps
def build():
    from soroshapes import Basis, Shapes

    shp = Shapes(Basis.chebyshev(MODES), dofs=(0, MODES, 0, 0, 0, 0), length=LENGTH, section=sdf.Circle(RADIUS),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), damping=0.0, segments=20)
    return shp.add_gravity((0.0, 0.0, -9.81))


def sag_frequency(shp, q):
    """Lowest natural frequency [Hz] about the static state q, gravity's geometric stiffness included."""
    from scipy.linalg import eigh

    def r(x):
        return shp.K @ x - shp.dynamics(x, np.zeros_like(x))[2]
    Kt = np.empty((shp.n, shp.n))
    for k in range(shp.n):
        e = np.zeros(shp.n)
        e[k] = 1e-6 * max(1.0, abs(q[k]))
        Kt[:, k] = (r(q + e) - r(q - e)) / (2 * e[k])
    w2 = eigh(0.5 * (Kt + Kt.T), shp.mass_matrix(q), eigvals_only=True)
    return float(np.sqrt(max(w2[0], 0.0)) / (2 * np.pi))


def swing_period(t, z):
    """Twice the mean spacing [s] of the major turning points of a signal z(t) (t = 0, the release, included);
    None if there is no turning point after the release."""
    from scipy.signal import find_peaks

    prom = 0.25 * (z.max() - z.min())
    ext = np.concatenate([[0], find_peaks(z, prominence=prom)[0], find_peaks(-z, prominence=prom)[0]])
    ext = np.unique(ext)
    if len(ext) < 2:
        return None
    return float(2 * np.mean(np.diff(t[ext])))


def drift(tr):
    return float(np.max(np.abs(tr.total - tr.total[0])) / tr.kinetic.max())


def plots(out, imp, exp, tip_static):
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    fig = Figure(figsize=(7, 6))
    ax = fig.subplots(2, 1, sharex=True)
    for a, k, name in ((ax[0], 0, "x"), (ax[1], 2, "z")):
        a.plot(imp.t, imp.tip[:, k] / mm, "-", color="tab:blue", label="implicit midpoint, h = 1 ms")
        a.plot(exp.t, exp.tip[:, k] / mm, "--", color="tab:orange",
               label=f"explicit RK4, h = {exp.t[1] - exp.t[0]:.2e} s")
        a.axhline(tip_static[k] / mm, color="gray", ls=":", label="static tip")
        a.set_ylabel(f"tip {name} [mm]")
        a.grid(alpha=0.3)
    ax[0].set_ylim(-80, 290)
    ax[0].legend(fontsize=8, loc="upper center", ncol=3)
    ax[0].set_title("undamped cantilever released under gravity: tip position")
    ax[1].set_xlabel("time [s]")
    save_figure(fig, out / "tip.png", dpi=110)

    fig = Figure(figsize=(7, 6))
    ax = fig.subplots(2, 1, sharex=True)
    ax[0].plot(imp.t, imp.kinetic * 1e3, label="kinetic")
    ax[0].plot(imp.t, imp.potential * 1e3, label="potential (elastic + gravity)")
    ax[0].plot(imp.t, imp.total * 1e3, "k", label="total")
    ax[0].set_ylabel("energy [mJ]")
    ax[0].set_title("energy (implicit midpoint)")
    ax[0].legend(fontsize=8)
    ax[1].plot(imp.t, (imp.total - imp.total[0]) * 1e6, label=f"implicit (drift {drift(imp):.1e})")
    ax[1].plot(exp.t, (exp.total - exp.total[0]) * 1e6, "--", label=f"explicit RK4 (drift {drift(exp):.1e})")
    ax[1].set_ylabel(r"$E(t) - E(0)$ [$\mu$J]")
    ax[1].set_xlabel("time [s]")
    ax[1].set_title("energy error; drift = max|E - E(0)| / max kinetic")
    ax[1].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    save_figure(fig, out / "energy.png", dpi=110)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/cantilever_release"),
                          quick="--quick" in sys.argv), indent=2))
