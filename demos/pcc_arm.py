r"""Six-segment PCC soft arm sagging and swinging under gravity (`soro demo pcc_arm`)
===============================================================================

Purpose
-------
The planar soft arm of Della Santina, Katzschmann et al. (IJRR 39, 490, 2020; the seed's ``katzschmann``
preset) as a reduced Cosserat beam with a piecewise-constant-curvature (PCC) basis: six segments of 60 mm,
each weighing 334 g. The arm is clamped horizontally and (a) its static sag under gravity is solved, then
(b) it is released from straight and swings down with the material's damping until it settles; the settled
tip must coincide with the static one. Figures: tip deflection, per-segment curvatures, settling time,
real-time factor, energy decay.

Equations
---------
Strain :math:`\xi(\sigma) = \Theta(\sigma) q + (0, 0, 0, 1, 0, 0)` with the indicator functions of the six
segments in both bendings (``Basis.pcc(6)``, ``dofs = (0, 6, 6, 0, 0, 0)``, :math:`n = 12`):
:math:`q_{y,j}` is the constant curvature [1/m] of segment j about the body y axis. Statics
:math:`Kq = f_g(q)` by Newton with 4 load steps; dynamics

.. math:: M(q)\ddot q + C(q, \dot q)\dot q + \tau K\dot q + Kq = f_g(q),

integrated by the implicit midpoint rule; Kelvin-Voigt damping :math:`D = \tau K` with
:math:`\tau = 2\zeta/\omega_1` from the material's damping ratio :math:`\zeta` (``damping=None``). The decay
predicted by the linearization about the static state, :math:`M\ddot x + D\dot x + K_t x = 0` with the
tangent :math:`K_t = \partial(Kq - f_g)/\partial q` (gravity's geometric stiffness included, finite
differences), restricted to the in-plane coordinates :math:`q_y`, is reported as ``linear_frequency_sag_Hz``
and ``slowest_decay_rate_1_per_s`` :math:`\sigma`; ``settle_envelope_mm`` :math:`= |p_\mathrm{tip}(0) -
p_\mathrm{tip}^\mathrm{static}|\, e^{-\sigma t_\mathrm{end}}` is the distance left at the end by that
envelope (the out-of-plane modes, not excited, are reported too).

Parameters
----------
=================  =====================================================================================
arm                6 segments x 60 mm = 360 mm; rounded rectangle 20 mm x 60 mm (corner radius 5 mm) with
                   the 60 mm side in the vertical bending plane (body z), as the real arm's two chambers sit
                   side by side in its bending plane
mass               334 g per segment: density = 0.334 kg / (A * 60 mm) (reported, ~4.7e3 kg/m^3: the
                   segments carry their valves and fittings)
material           Dragon Skin 30 preset (Yeoh, small-strain E = 0.92 MPa, damping ratio 0.1)
base               at the origin pointing along +x; gravity 9.81 m/s^2 along -z
dynamics           released from straight at rest; implicit midpoint, dt = 1 ms for 4 s
                   (quick: dt = 4 ms for 4 s: 0.5 s would stop mid-swing, 71 mm from the static tip)
=================  =====================================================================================

Figures
-------
``report.json``: ``density_kg_m3``, ``segment_mass_g``, ``youngs_modulus_MPa``, ``damping_ratio``,
``damping_tau_s``, ``t_end_s``, ``dt_s``, ``steps``, ``simulation_wall_time_s``, ``settled``,
``static_tip_mm`` (x, y, z), ``static_tip_deflection_mm`` (drop below the base), ``segment_curvature_1_per_m``
and ``segment_angle_deg`` (bending of each segment, base first), ``static_newton_iterations``,
``final_tip_mm``, ``final_tip_error_mm`` (dynamic vs static), ``settling_time_s`` (last time the tip is more
than 1 mm from the static tip), ``max_tip_speed_m_s``, ``energy_released_J`` (E(0) - E_static),
``energy_dissipated_J``, ``energy_residual_J`` (E(t_end) - E_static), ``energy_max_increase_J`` (largest
rise of the total energy between samples: damping only removes energy), ``real_time_factor``,
``newton_iterations_mean``, ``linear_frequency_sag_Hz``, ``slowest_decay_rate_1_per_s``,
``settle_envelope_mm``, ``linear_frequency_sag_out_of_plane_Hz``, ``slowest_decay_rate_out_of_plane_1_per_s``,
``natural_frequencies_straight_Hz``. Pictures: ``snapshots.png`` (the arm at eight
instants and the static shape, in the bending plane), ``static.png`` (3D view of the static sag), ``tip.png``
(tip path, distance to the static tip with the linearized envelope, energies).
"""
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

SEGMENTS, SEG_LEN, SEG_MASS = 6, 60 * mm, 0.334
WIDTH, HEIGHT = 20 * mm, 60 * mm      # body y (across), body z (in the bending plane)
SETTLE_TOL = 1 * mm


#: The full run and the short one (`--quick`, what the tests run): simulated time and time step [s] (the
#: quick run keeps the 4 s: 0.5 s would stop mid-swing).
FULL = dict(t_end=4.0, dt=1e-3)
QUICK = dict(t_end=4.0, dt=4e-3)


def main(out: Path, quick: bool = False) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    shp, density = build()

    # (a) statics
    q_static = shp.statics(steps=4)
    static_its = int(sum(shp.newton_iterations))
    tip_s = shp.positions(q_static)[-1]
    kappa = q_static[:SEGMENTS]                       # kappa_y of each segment [1/m]
    f_sag, decay = linear_decay(shp, q_static, np.arange(SEGMENTS))               # in-plane (kappa_y)
    f_out, decay_out = linear_decay(shp, q_static, np.arange(SEGMENTS, 2 * SEGMENTS))  # out of plane
    E_static = shp.energy(q_static)["total"]

    # (b) dynamic release from straight
    prm = QUICK if quick else FULL
    t_end, dt = prm["t_end"], prm["dt"]
    tr = shp.simulate(t_end, dt, method="implicit")
    d = np.linalg.norm(tr.tip - tip_s, axis=1)
    above = np.flatnonzero(d > SETTLE_TOL)
    settle = float(tr.t[above[-1] + 1]) if len(above) and above[-1] + 1 < len(tr.t) else (
        0.0 if not len(above) else float("inf"))
    speed = np.linalg.norm(np.diff(tr.tip, axis=0), axis=1) / np.diff(tr.t)
    plots(out, shp, tr, q_static, decay)

    summary = {
        "density_kg_m3": density,
        "segment_mass_g": SEG_MASS * 1e3,
        "youngs_modulus_MPa": shp.E / 1e6,
        "damping_ratio": shp.material.damping,
        "damping_tau_s": shp.damping,
        "natural_frequencies_straight_Hz": [float(f) for f in shp.natural_frequencies(4)],
        "static_tip_mm": [float(v) for v in tip_s / mm],
        "static_tip_deflection_mm": float(-tip_s[2] / mm),
        "segment_curvature_1_per_m": [float(k) for k in kappa],
        "segment_angle_deg": [float(v) for v in np.degrees(kappa * SEG_LEN)],
        "static_newton_iterations": static_its,
        "linear_frequency_sag_Hz": f_sag,
        "slowest_decay_rate_1_per_s": decay,
        "linear_frequency_sag_out_of_plane_Hz": f_out,
        "slowest_decay_rate_out_of_plane_1_per_s": decay_out,
        "settle_envelope_mm": float(np.linalg.norm(tip_s - shp.positions(np.zeros(shp.n))[-1]) / mm
                                    * np.exp(-decay * t_end)),
        "t_end_s": t_end,
        "dt_s": dt,
        "final_tip_mm": [float(v) for v in tr.tip[-1] / mm],
        "final_tip_error_mm": float(d[-1] / mm),
        "settling_time_s": settle if np.isfinite(settle) else t_end,
        "settled": bool(np.isfinite(settle)),
        "max_tip_speed_m_s": float(speed.max()),
        "energy_released_J": float(tr.total[0] - E_static),
        "energy_dissipated_J": float(tr.total[0] - tr.total[-1]),
        "energy_residual_J": float(tr.total[-1] - E_static),
        "energy_max_increase_J": float(max(0.0, np.diff(tr.total).max())),
        "real_time_factor": float(t_end / tr.stats["wall_time"]),
        "simulation_wall_time_s": float(tr.stats["wall_time"]),
        "newton_iterations_mean": float(tr.stats["newton_iterations_per_step"]),
        "steps": int(tr.stats["steps"]),
    }
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def build():
    """The arm (a :class:`soroshapes.Shapes` with gravity) and its density [kg/m^3]."""
    from sorofem.sdf.properties import section_properties
    from soroshapes import Basis, Shapes

    section = sdf.RoundedRectangle(WIDTH, HEIGHT)
    density = SEG_MASS / (section_properties(section).area * SEG_LEN)
    shp = Shapes(Basis.pcc(SEGMENTS), dofs=(0, SEGMENTS, SEGMENTS, 0, 0, 0), length=SEGMENTS * SEG_LEN,
                 section=section, material=materials.DragonSkin30(density=density), segments=4 * SEGMENTS)
    shp.add_gravity((0.0, 0.0, -9.81))
    return shp, density


def tangent_stiffness(shp, q):
    """K_t = d(K q - f_g(q))/dq by central differences (n, n)."""
    def r(x):
        return shp.K @ x - shp.dynamics(x, np.zeros_like(x))[2]
    Kt = np.empty((shp.n, shp.n))
    for k in range(shp.n):
        e = np.zeros(shp.n)
        e[k] = 1e-6 * max(1.0, abs(q[k]))
        Kt[:, k] = (r(q + e) - r(q - e)) / (2 * e[k])
    return 0.5 * (Kt + Kt.T)


def linear_decay(shp, q, dofs):
    """(lowest damped frequency [Hz], slowest decay rate [1/s]) of the linearization about q restricted to the
    coordinates ``dofs`` (the in-plane and out-of-plane bendings decouple about a planar state)."""
    ix = np.ix_(dofs, dofs)
    M, Kt, D = shp.mass_matrix(q)[ix], tangent_stiffness(shp, q)[ix], shp.damping_matrix[ix]
    n = len(dofs)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, Kt), -np.linalg.solve(M, D)]])
    lam = np.linalg.eigvals(A)
    osc = lam[np.abs(lam.imag) > 1e-9]
    return float(np.abs(osc.imag).min() / (2 * np.pi)), float(-lam.real.max())


def plots(out, shp, tr, q_static, decay):
    from matplotlib import cm
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    from soroshapes.render import render_png

    P_static = shp.positions(q_static)
    tip_s = P_static[-1]
    render_png(out / "static.png", [{"frames": shp.forward_kinematics(q_static), "radius": 10 * mm}],
               view=(20, -70), size=(6, 5), dpi=120, color="tab:red",
               limits=((-20 * mm, 300 * mm), (-60 * mm, 60 * mm), (-250 * mm, 20 * mm)),
               title="static sag under gravity (tube radius 10 mm)")

    # snapshots in the bending plane, drawn with the section's 60 mm height
    picks = np.unique(np.searchsorted(tr.t, [0.0, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.2]).clip(0, len(tr.t) - 1))
    fig = Figure(figsize=(8.5, 5.5))
    ax = fig.subplots()
    for i, k in enumerate(picks):
        G = shp.forward_kinematics(tr.q[k])
        up = G[:, :3, 3] + 0.5 * HEIGHT * G[:, :3, 2]
        lo = G[:, :3, 3] - 0.5 * HEIGHT * G[:, :3, 2]
        poly = np.vstack([up, lo[::-1]])
        c = cm.viridis(i / max(1, len(picks) - 1))
        ax.fill(poly[:, 0] / mm, poly[:, 2] / mm, color=c, alpha=0.25)
        ax.plot(G[:, 0, 3] / mm, G[:, 2, 3] / mm, color=c, lw=1.5, label=f"t = {tr.t[k]:.2f} s")
    G = shp.forward_kinematics(q_static)
    ax.plot(G[:, 0, 3] / mm, G[:, 2, 3] / mm, "--", color="tab:red", lw=2, label="static")
    seg = np.searchsorted(shp.sigma, np.arange(SEGMENTS + 1) * SEG_LEN - 1e-12)
    ax.plot(G[seg, 0, 3] / mm, G[seg, 2, 3] / mm, "o", color="tab:red", ms=4, label="segment ends (static)")
    ax.plot(0, 0, "ks", ms=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_title("release from straight: backbones and 60 mm section outline")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    save_figure(fig, out / "snapshots.png", dpi=120)

    d = np.linalg.norm(tr.tip - tip_s, axis=1)
    fig = Figure(figsize=(13, 4))
    ax = fig.subplots(1, 3)
    ax[0].plot(P_static[:, 0] / mm, P_static[:, 2] / mm, "-", color="tab:red", lw=2, label="static backbone")
    ax[0].plot(tr.tip[:, 0] / mm, tr.tip[:, 2] / mm, "-", color="tab:blue", lw=1, label="tip path (dynamic)")
    ax[0].plot(tip_s[0] / mm, tip_s[2] / mm, "*", color="tab:red", ms=12, label="static tip")
    ax[0].plot(0, 0, "ks", label="clamp")
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("x [mm]")
    ax[0].set_ylabel("z [mm]")
    ax[0].set_title("tip path in the bending plane")
    ax[0].legend(fontsize=8)
    ax[1].semilogy(tr.t, np.maximum(d, 1e-6) / mm)
    ax[1].semilogy(tr.t, d[0] * np.exp(-decay * tr.t) / mm, "--", color="gray",
                   label=f"linearized envelope, decay {decay:.2f} 1/s")
    ax[1].axhline(SETTLE_TOL / mm, color="k", ls=":", lw=1, label="1 mm")
    ax[1].set_xlabel("time [s]")
    ax[1].set_ylabel("|tip - static tip| [mm]")
    ax[1].set_title("settling")
    ax[1].legend(fontsize=8)
    ax[2].plot(tr.t, tr.kinetic, label="kinetic")
    ax[2].plot(tr.t, tr.potential, label="potential (elastic + gravity)")
    ax[2].plot(tr.t, tr.total, "k", label="total")
    ax[2].set_xlabel("time [s]")
    ax[2].set_ylabel("energy [J]")
    ax[2].set_title("energy (damped)")
    ax[2].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    save_figure(fig, out / "tip.png", dpi=110)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/pcc_arm"), quick="--quick" in sys.argv),
                     indent=2))


def scene(quick=False):
    """``soro play pcc_arm``: the arm sagging and swinging under gravity (it has no actuators: no sliders), with
    a draggable IK target at its tip."""
    from soro.play import Scene, Target

    shp, _ = build()
    return Scene(shp, target=Target((SEGMENTS * SEG_LEN, 0.0, 0.0)), dt=2e-3 if quick else 1e-3, view=(0.0, 0.0),
                 title="pcc_arm")
