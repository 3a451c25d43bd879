r"""Multi-legged soft passive walker on a 30-degree slope (`soro demo passive_walker`)
============================================================================

Purpose
-------
The seed's first case study (Sorotoki paper, Sec. VI-A, Fig. 18-22), after Suzumori and Saito's passive
walker: a soft body on three pairs of legs (each pair a Lambda of two elastic struts), with small weights
on the body between the pairs, placed on an inclined surface. Gravity drives it down the slope; friction at
the feet and the elasticity of the legs turn the descent into a periodic stick-slip gait at a frequency set
by the legs' resonance. Figures: the gait frequency (dominant frequency of the three leg angles after the
first 30 % of the run, their Hann-windowed, zero-padded amplitude spectra summed; its resolution is one bin of
that window, ``gait_frequency_resolution_hz``; the seed reports a period of about 47.5 ms, 21.1 Hz; the quick
run is too short for a gait), the frequency of the normal contact force, the hop (the normal force on the feet
against the walker's weight: its mean, its peak, the fraction of the time it is zero), the legs' first
vibration frequencies in contact (eigen-analysis about the static state), the mean walking speed, the seed's
Fig. 20 (the front leg's displacement) and Fig. 22 (the leg angles theta_1-theta_3 over the last 200 ms), and
the walker during one gait cycle.

Why it hops: normal to the slope the feet carry the weight on average (``normal_force_mean_over_weight``
~ 1), and the legs' vertical vibration adds an oscillating part; a unilateral contact force cannot pull, so
once the oscillation's amplitude reaches the mean (``normal_force_max_over_weight`` >= 2 for a symmetric
oscillation) the feet leave the slope for part of each cycle. The seed's damping (below) damps the legs'
modes by under 1 % of critical, so nothing keeps that amplitude down.

What it shows at the seed's parameters (full run: 1 mm mesh, dt = 0.33 ms, 0.30 s): the leg angles' dominant
frequency is 22.0 +- 4.8 Hz (seed 21.1 Hz; the +- is one bin of the 0.21 s window: a longer run resolves it
better), but no steady walk. With Coulomb friction mu = 0.5 < tan 30 deg the feet cannot hold the walker, so
it slides and speeds up (72 mm in 0.3 s; 1.6 m/s^2 fitted to the front leg, between 0.66 m/s^2 for sliding in
full contact and 4.9 m/s^2 without friction: it is in the air 33 % of the time); the lightly damped legs
swing by 28-38 deg and the normal force peaks at 6.6 times the weight (mean 1.06). The seed's step-like Fig. 20
needs a contact that can stick on the slope; its contact model (``NormalReaction``/``TangentFriction`` 0.5)
is not Coulomb's.

Equations
---------
Plane-strain hyperelastic dynamics (generalized-alpha, :mod:`sorofem.fem.dynamics`, :math:`\rho_\infty`
= 0.8), the seed's mass-proportional damping :math:`C = \zeta M` (its ``Zeta``, a rate [1/s]: a damping
ratio :math:`\zeta/(2\omega)`, 0.6 % at 21 Hz), gravity, and contact with the slope (penalty and regularized
Coulomb friction, :mod:`sorofem.fem.contact`). The slope is the floor :math:`y = 0` of a frame rotated by
:math:`\theta` = 30 deg: gravity is :math:`g(\sin\theta, -\cos\theta)` with x pointing downhill. The walker
first settles on the slope under gravity with sticking friction :math:`\mu_0 = 1 > \tan\theta` and heavy
mass-proportional damping (40 ms; the seed holds it with two fingers and solves the static state), its
vibration modes in contact are computed about that state, then it is released from rest with the walking
friction :math:`\mu < \tan\theta`.

Parameters
----------
=================  =====================================================================================
geometry           body 62 x 3 mm at 14-17 mm above the slope; three leg pairs 25 mm apart, each two
                   struts 2 mm wide from the body to feet 7 mm before and after (a Lambda, 14 mm high,
                   55 deg between the struts at rest); two weights (8 x 4 mm blocks on the body) between
                   the pairs
materials          the seed's: Neo-Hookean E = 1.2 MPa, nu = 0.49, uniform density 3600 kg/m^3
slope, friction    30 deg, mu = 0.5 (the seed's code; < tan 30 deg = 0.577)
damping            C = zeta M, zeta = 1.5 1/s (the seed's text; its code 1.75, and its element loop adds
                   the mass matrix once per quadrature point, which our one assembly does not repeat)
time               0.30 s with dt = 0.33 ms (the seed's step); quick: 0.10 s with dt = 0.5 ms
mesh               P2 triangles, element size 1 mm (quick: 1.5 mm)
=================  =====================================================================================

Output: ``gait.png`` (the walker during the last gait cycle, von Mises colour bar, axes in mm),
``gait_force.png`` (the contact force and its spectrum), ``front_leg.png`` (Fig. 20: the front leg's
displacement [mm] along and normal to the slope), ``leg_angles.png`` (Fig. 22: theta_1-theta_3 [deg] over the
last 200 ms), ``gait_series.csv`` (their data and the normal force, one row per step), ``report.json`` with
``gait_frequency_hz``, ``gait_period_ms``, ``gait_frequency_resolution_hz``, ``contact_frequency_hz``,
``normal_force_mean_over_weight``, ``normal_force_max_over_weight``, ``airborne_fraction``,
``front_leg_dx_mm``, ``front_leg_dy_mm``, ``leg_angle_mean_deg``, ``leg_angle_range_deg``,
``vibration_frequencies_hz``, ``speed_mm_per_s``, ``com_dx_mm``, ``steps``, ``newton_iterations_max``.
"""
import math
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

# ------------------------------------------------------------------------------------------------ parameters
THETA, MU = math.radians(30.0), 0.5                   # slope [rad], walking friction [-] (the seed's code)
BODY_Y, BODY_H, STRUT, SPREAD = 14 * mm, 3 * mm, 2 * mm, 7 * mm
LEGS = (6 * mm, 31 * mm, 56 * mm)                     # leg pairs' positions along the body [m]
WEIGHTS = (18.5 * mm, 43.5 * mm)                      # weights' positions [m]
E, NU, RHO = 1.2e6, 0.49, 3600.0                      # the seed's: [Pa], [-], uniform density [kg/m^3]
G = 9.80665                                           # [m/s^2]
ALPHA_M = 1.5                                         # the seed's damping C = zeta M, zeta = 1.5 [1/s]
WINDOW = 0.2                                          # the seed's Fig. 22 window [s]
#: Settling on the slope: time [s], step [s], sticking friction [-], mass-proportional damping [1/s] (40 ms).
SETTLE = dict(t_end=0.04, dt=5e-4, friction=1.0, alpha_mass=300.0, rho_inf=0.5)
#: The full run and the short one (`--quick`, what the tests run): element size [m], walking time [s], step [s].
FULL = dict(size=1.0 * mm, t_end=0.30, dt=3.3e-4)
QUICK = dict(size=1.5 * mm, t_end=0.10, dt=5e-4)


def main(out: Path, quick: bool = False) -> dict:
    """Settle, analyse and walk the walker into ``out``; returns the report (see Output above)."""
    from mpi4py import MPI

    prm = QUICK if quick else FULL
    out = Path(out)
    T, dt = prm["t_end"], prm["dt"]

    # 1. mesh and problem: body, legs and weights under gravity tilted by the slope
    fem, msh = model(prm["size"])

    # 2. stand on the slope: settle under gravity with sticking friction and heavy mass damping
    fem.add_contact(sdf.Line((0.0, 0.0), (0.0, 1.0)), friction=SETTLE["friction"], regularization=0.01 * mm)
    fem.simulate(t_end=SETTLE["t_end"], dt=SETTLE["dt"], rho_inf=SETTLE["rho_inf"],
                 rayleigh=(SETTLE["alpha_mass"], 0.0))

    # 3. vibration modes in contact about that state
    freqs = np.array([f for f in fem.eigen(8).frequencies if np.isfinite(f) and f > 1.0])

    # 4. walk: from rest in that state, with the walking friction and the seed's damping C = ALPHA_M M
    fem.contacts[0].friction = MU
    traj = fem.simulate(t_end=T, dt=dt, rho_inf=0.8, rayleigh=(ALPHA_M, 0.0))

    # 5. the gait: frequency of the normal contact force after the first 30 % (the transient), speed
    t = traj.times
    force = traj.reactions["contact_0"]            # force of the slope on the walker [N/m], per step
    com = centre_of_mass(traj)
    keep = t > 0.3 * T
    f_contact, fr, spec, band = dominant_frequency(t[keep], force[keep, 1])
    speed = float((com[-1, 0] - com[keep][0, 0]) / (t[-1] - t[keep][0]))
    # the hop: the normal force on the feet against the walker's weight normal to the slope (per m of depth)
    weight = RHO * G * math.cos(THETA) * reference_area(traj)
    normal = force[:, 1]
    # Fig. 20 and 22: the front leg's displacement, the three Lambda angles
    front, theta = front_leg(traj), leg_angles(traj)
    f_gait = dominant_frequency(t[keep], *theta[:, keep])[0]   # the gait: the legs' angles (the seed's Fig. 22)
    summary = {"gait_frequency_hz": round(f_gait, 3), "gait_period_ms": round(1e3 / f_gait, 2),
               "gait_frequency_resolution_hz": round(1.0 / (t[-1] - t[keep][0]), 3),
               "seed_gait_frequency_hz": 21.1, "contact_frequency_hz": round(f_contact, 3),
               "normal_force_mean_over_weight": round(float(normal[keep].mean() / weight), 3),
               "normal_force_max_over_weight": round(float(normal[keep].max() / weight), 3),
               "airborne_fraction": round(float(np.mean(normal[keep] < 0.01 * weight)), 3),
               "front_leg_dx_mm": round(float(front[-1, 0]) / mm, 3),
               "front_leg_dy_mm": round(float(front[-1, 1]) / mm, 3),
               "leg_angle_mean_deg": [round(float(a), 2) for a in theta[:, keep].mean(axis=1)],
               "leg_angle_range_deg": [round(float(a), 2) for a in np.ptp(theta[:, keep], axis=1)],
               "vibration_frequencies_hz": [round(float(f), 2) for f in freqs],
               "speed_mm_per_s": round(speed / mm, 3), "com_dx_mm": round(float(com[-1, 0] - com[0, 0]) / mm, 3),
               "steps": len(t) - 1, "dt_ms": dt * 1e3, "simulated_s": T, "cells": msh.num_cells,
               "newton_iterations_max": int(traj.newton_iterations.max())}
    if MPI.COMM_WORLD.rank != 0:
        return summary

    # 6. figures: contact force and spectrum; the walker over the last gait cycle (mm, von Mises colour bar)
    plot_force(t, force, fr, spec, band, f_contact, out / "gait_force.png")
    plot_front_leg(t, front, out / "front_leg.png")
    last = t >= t[-1] - WINDOW
    plot_leg_angles(t[last], theta[:, last], f_gait, out / "leg_angles.png")
    write_series(out / "gait_series.csv", t, front, theta, normal)
    shown = np.searchsorted(t, t[-1] - np.linspace(1.0 / f_gait, 0.0, 5))
    x_shown = (traj.vertices[None, :, 0] + traj.displacement[shown, :, 0]) / mm   # one x range for every panel
    traj.filmstrip(out / "gait.png", shown, floor=0.0, xlim=(x_shown.min() - 3, x_shown.max() + 3),
                   ylim=(-2, 26), xlabel="x along the slope (downhill) [mm]")
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def walker():
    """The walker's side section [m] (feet on y = 0, x downhill)."""
    shape = sdf.Rectangle(62 * mm, BODY_H, center=(31 * mm, BODY_Y + BODY_H / 2))
    for xc in LEGS:
        top = (xc, BODY_Y + 0.5 * mm)
        for foot in (xc - SPREAD, xc + SPREAD):
            shape = shape | sdf.Strut(top, (foot, STRUT / 2), STRUT)
    for xw in WEIGHTS:
        shape = shape | sdf.Rectangle(8 * mm, 4 * mm, center=(xw, BODY_Y + BODY_H + 2 * mm))
    return shape


def model(size):
    """The mesh (element size ``size`` [m]) and the dynamic problem: soft walker, heavy weights, gravity in
    the slope's frame (x downhill). Returns ``(fem, mesh)``."""
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    msh = Mesh.from_sdf(walker(), size=size)
    fem = Fem(msh, materials.NeoHookean(E=E, nu=NU, density=RHO), degree=2)
    fem.add_gravity(np.array([G * math.sin(THETA), -G * math.cos(THETA)]))
    return fem, msh


def reference_area(traj):
    """The section's reference area [m^2] (sum of the linear cells' areas)."""
    X, cells = traj.vertices, traj.cells
    a, b = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    return float(0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())


def _vertex(traj, point):
    """Index of the mesh vertex nearest to ``point`` [m] in the reference configuration."""
    X = traj.vertices
    return int(np.argmin(np.hypot(X[:, 0] - point[0], X[:, 1] - point[1])))


def front_leg(traj):
    """Displacement [m] of the front (downhill) leg pair's top, where its struts meet the body, at each step,
    (steps, 2): along and normal to the slope (the seed's Fig. 20)."""
    k = _vertex(traj, (LEGS[-1], BODY_Y))
    return traj.displacement[:, k]


def leg_angles(traj):
    """The angle [deg] between the two struts of each leg pair (theta_1 back to theta_3 front, the seed's
    Fig. 21-22) at each step, (3, steps): each strut's direction from a point 15 % down from its top to its
    foot's centre (both taken at the nearest mesh vertex)."""
    x = traj.vertices[None] + traj.displacement
    angles = []
    for xc in LEGS:
        top = np.array([xc, BODY_Y + 0.5 * mm])
        d = []
        for foot in (np.array([xc - SPREAD, STRUT / 2]), np.array([xc + SPREAD, STRUT / 2])):
            upper, lower = _vertex(traj, top + 0.15 * (foot - top)), _vertex(traj, foot)
            d.append(x[:, lower] - x[:, upper])
        cos = (d[0] * d[1]).sum(axis=1) / (np.linalg.norm(d[0], axis=1) * np.linalg.norm(d[1], axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.array(angles)


def centre_of_mass(traj):
    """Centre of mass [m] at each step, (steps, 2): the mean of the deformed cells' centroids weighted by the
    reference cells' areas."""
    X, cells, U = traj.vertices, traj.cells, traj.displacement
    a, b = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    area0 = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])   # (np.cross of 2-vectors is deprecated in numpy 2)
    return (((X + U)[:, cells].mean(axis=2)) * area0[None, :, None]).sum(axis=1) / area0.sum()


def dominant_frequency(tt, *signals):
    """The dominant frequency [Hz] of the signals sampled at times ``tt`` [s] (each: mean removed, resampled
    uniformly, Hann window, zero-padded 8x so that the peak is interpolated between bins; their amplitude
    spectra summed; at least 1.5 periods in the window). The resolution is still about one bin of the window,
    1 / (tt[-1] - tt[0]). Returns ``(frequency, frequencies, spectrum, band)``."""
    tu = np.linspace(tt[0], tt[-1], len(tt))
    spec = sum(np.abs(np.fft.rfft(np.interp(tu, tt, f - f.mean()) * np.hanning(len(tu)), 8 * len(tu)))
               for f in signals)
    fr = np.fft.rfftfreq(8 * len(tu), tu[1] - tu[0])
    band = fr > 1.5 / (tt[-1] - tt[0])
    return float(fr[band][np.argmax(spec[band])]), fr, spec, band


def plot_force(t, force, fr, spec, band, f_contact, path):
    """``gait_force.png``: the contact force [N/m] against time [ms], and its normalized spectrum."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(10, 3.6))
    ax, bx = fig.subplots(1, 2)
    ax.plot(t * 1e3, -force[:, 1], lw=1, label="normal")
    ax.plot(t * 1e3, -force[:, 0], lw=1, label="tangential")
    ax.set(xlabel="t [ms]", ylabel="contact force on the slope [N/m]")
    ax.legend(fontsize=8)
    bx.plot(fr, spec / spec[band].max())
    bx.axvline(f_contact, color="C3", lw=0.8)
    bx.set(xlim=(0, max(100.0, 1.2 * f_contact)), xlabel="frequency [Hz]", ylabel="spectrum (normalized)",
           title=f"normal contact force: {f_contact:.1f} Hz")
    save_figure(fig, path, dpi=120)


def plot_front_leg(t, front, path):
    """``front_leg.png`` (the seed's Fig. 20): the front leg's displacement [mm] along the slope (downhill)
    and normal to it against time [ms]."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5.5, 3.5))
    ax = fig.subplots()
    ax.plot(t * 1e3, front[:, 0] / mm, label="along the slope (downhill)")
    ax.plot(t * 1e3, front[:, 1] / mm, label="normal to the slope")
    ax.set(xlabel="t [ms]", ylabel="front leg displacement [mm]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=120)


def plot_leg_angles(t, theta, f_gait, path):
    """``leg_angles.png`` (the seed's Fig. 22): the three leg pairs' angles [deg] over the last ``WINDOW``."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(5.5, 3.5))
    ax = fig.subplots()
    for i, th in enumerate(theta):
        ax.plot(t * 1e3, th, label=f"theta_{i + 1}")
    ax.set(xlabel="t [ms]", ylabel="leg angle [deg]", title=f"gait {f_gait:.1f} Hz (seed: 21.1 Hz)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=120)


def write_series(path, t, front, theta, normal):
    """``gait_series.csv``: the data of Fig. 20 and 22 and the normal force, one row per step (atomic)."""
    from sorofem.io import atomic_path

    data = np.column_stack([t * 1e3, front / mm, theta.T, normal])
    with atomic_path(path) as tmp:
        np.savetxt(tmp, data, delimiter=",", fmt="%.6g",
                   header="t_ms,front_dx_mm,front_dy_mm,theta1_deg,theta2_deg,theta3_deg,normal_force_N_per_m")
