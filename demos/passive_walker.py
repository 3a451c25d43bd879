r"""Multi-legged soft passive walker on a 30-degree slope (`soro demo passive_walker`)
============================================================================

Purpose
-------
The seed's first case study (Sorotoki paper, Sec. VI-A, Fig. 18-19), after Suzumori and Saito's passive
walker: a soft body on three pairs of legs (each pair a Lambda of two elastic struts), with small weights
on the body between the pairs, placed on an inclined surface. Gravity drives it down the slope; friction at
the feet and the elasticity of the legs turn the descent into a periodic stick-slip gait at a frequency set
by the legs' resonance. Figures: the gait frequency (dominant frequency of the feet's normal contact force
after the first 30 % of the run, Hann window, zero-padded FFT; the seed reports a period of about 47.5 ms,
21 Hz; the quick run is too short for a gait and reports the transient's frequency), the legs' first vibration
frequencies in contact (eigen-analysis about the static state), the mean walking speed, and PNGs of the
walker during one gait cycle and of the contact force and its spectrum.

Equations
---------
Plane-strain hyperelastic dynamics (generalized-alpha, :mod:`sorofem.fem.dynamics`, :math:`\rho_\infty`
= 0.8), Rayleigh damping with damping ratio :math:`\zeta` at the first and fifth vibration frequencies of
the walker standing on the slope, gravity, and contact with the slope (penalty and regularized Coulomb
friction, :mod:`sorofem.fem.contact`). The slope is the floor :math:`y = 0` of a frame rotated by
:math:`\theta` = 30 deg: gravity is :math:`g(\sin\theta, -\cos\theta)` with x pointing downhill. The walker
first settles on the slope under gravity with sticking friction :math:`\mu_0 = 1 > \tan\theta` and heavy
mass-proportional damping (40 ms), its vibration modes in contact are computed about that state, then it is
released from rest with the walking friction :math:`\mu < \tan\theta`.

Parameters
----------
=================  =====================================================================================
geometry           body 62 x 3 mm at 14-17 mm above the slope; three leg pairs 25 mm apart, each two
                   struts 2 mm wide from the body to feet 7 mm before and after (a Lambda, 14 mm high);
                   two weights (8 x 4 mm blocks on the body) between the pairs
materials          Neo-Hookean E = 1.2 MPa, nu = 0.45, density 1200 kg/m^3 (legs and body); weights
                   density 12000 kg/m^3 (the seed lumps 3600 kg/m^3 over the whole walker)
slope, friction    30 deg, mu = 0.45 (< tan 30 deg = 0.577)
damping            zeta = 0.05 (Rayleigh; the seed's "1.5" is a coefficient of its own damping model)
time               0.30 s with dt = 0.33 ms (the seed's step); quick: 0.10 s with dt = 0.5 ms
mesh               P2 triangles, element size 1 mm (quick: 1.5 mm)
=================  =====================================================================================

Output: ``gait.png`` (the walker during the last gait cycle, von Mises colour bar, axes in mm),
``gait_force.png`` (the contact force and its spectrum), ``report.json`` with ``gait_frequency_hz``,
``gait_period_ms``, ``vibration_frequencies_hz``, ``speed_mm_per_s``, ``com_dx_mm``, ``steps``,
``newton_iterations_max``.
"""
import math
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

# ------------------------------------------------------------------------------------------------ parameters
THETA, MU = math.radians(30.0), 0.45                  # slope [rad], walking friction [-]
BODY_Y, BODY_H, STRUT, SPREAD = 14 * mm, 3 * mm, 2 * mm, 7 * mm
LEGS = (6 * mm, 31 * mm, 56 * mm)                     # leg pairs' positions along the body [m]
WEIGHTS = (18.5 * mm, 43.5 * mm)                      # weights' positions [m]
E, NU, RHO, RHO_WEIGHTS = 1.2e6, 0.45, 1200.0, 12000.0   # [Pa], [-], [kg/m^3], [kg/m^3]
G = 9.80665                                           # [m/s^2]
ZETA = 0.05                                           # Rayleigh damping ratio [-]
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

    # 3. vibration modes in contact about that state; Rayleigh damping at the first and fifth
    freqs = np.array([f for f in fem.eigen(8).frequencies if np.isfinite(f) and f > 1.0])
    alpha = fem.rayleigh_coefficients(ZETA, 2 * np.pi * freqs[0], 2 * np.pi * freqs[min(4, len(freqs) - 1)])

    # 4. walk: from rest in that state, with the walking friction
    fem.contacts[0].friction = MU
    traj = fem.simulate(t_end=T, dt=dt, rho_inf=0.8, rayleigh=alpha)

    # 5. the gait: frequency of the normal contact force after the first 30 % (the transient), speed
    t = traj.times
    force = traj.reactions["contact_0"]            # force of the slope on the walker [N/m], per step
    com = centre_of_mass(traj)
    keep = t > 0.3 * T
    f_gait, fr, spec, band = dominant_frequency(t[keep], force[keep, 1])
    speed = float((com[-1, 0] - com[keep][0, 0]) / (t[-1] - t[keep][0]))
    summary = {"gait_frequency_hz": round(f_gait, 3), "gait_period_ms": round(1e3 / f_gait, 2),
               "seed_gait_frequency_hz": 21.1,
               "vibration_frequencies_hz": [round(float(f), 2) for f in freqs],
               "speed_mm_per_s": round(speed / mm, 3), "com_dx_mm": round(float(com[-1, 0] - com[0, 0]) / mm, 3),
               "steps": len(t) - 1, "dt_ms": dt * 1e3, "simulated_s": T, "cells": msh.num_cells,
               "newton_iterations_max": int(traj.newton_iterations.max())}
    if MPI.COMM_WORLD.rank != 0:
        return summary

    # 6. figures: contact force and spectrum; the walker over the last gait cycle (mm, von Mises colour bar)
    plot_force(t, force, fr, spec, band, f_gait, out / "gait_force.png")
    traj.filmstrip(out / "gait.png", np.searchsorted(t, t[-1] - np.linspace(1.0 / f_gait, 0.0, 5)), floor=0.0,
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
    msh.add_region("weights", lambda x: x[1] > BODY_Y + BODY_H, kind="cells")
    fem = Fem(msh, materials.NeoHookean(E=E, nu=NU, density=RHO), degree=2)
    fem.add_material("weights", materials.NeoHookean(E=E, nu=NU, density=RHO_WEIGHTS))
    fem.add_gravity(np.array([G * math.sin(THETA), -G * math.cos(THETA)]))
    return fem, msh


def centre_of_mass(traj):
    """Centre of mass [m] at each step, (steps, 2): the mean of the deformed cells' centroids weighted by the
    reference cells' areas."""
    X, cells, U = traj.vertices, traj.cells, traj.displacement
    a, b = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    area0 = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])   # (np.cross of 2-vectors is deprecated in numpy 2)
    return (((X + U)[:, cells].mean(axis=2)) * area0[None, :, None]).sum(axis=1) / area0.sum()


def dominant_frequency(tt, f):
    """The dominant frequency [Hz] of the signal ``f`` sampled at times ``tt`` [s] (mean removed, resampled
    uniformly, Hann window, zero-padded 8x so that the peak is interpolated between bins; at least 1.5 periods
    in the window). Returns ``(frequency, frequencies, spectrum, band)``."""
    fn = f - f.mean()
    tu = np.linspace(tt[0], tt[-1], len(tt))
    fu = np.interp(tu, tt, fn) * np.hanning(len(tu))
    spec = np.abs(np.fft.rfft(fu, 8 * len(tu)))
    fr = np.fft.rfftfreq(8 * len(tu), tu[1] - tu[0])
    band = fr > 1.5 / (tt[-1] - tt[0])
    return float(fr[band][np.argmax(spec[band])]), fr, spec, band


def plot_force(t, force, fr, spec, band, f_gait, path):
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
    bx.axvline(f_gait, color="C3", lw=0.8)
    bx.set(xlim=(0, 100), xlabel="frequency [Hz]", ylabel="spectrum (normalized)",
           title=f"gait {f_gait:.1f} Hz (seed: 21.1 Hz)")
    save_figure(fig, path, dpi=120)
