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
"""
import math
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

THETA, MU = math.radians(30.0), 0.45
BODY_Y, BODY_H, STRUT, SPREAD = 14 * mm, 3 * mm, 2 * mm, 7 * mm
LEGS = (6 * mm, 31 * mm, 56 * mm)
WEIGHTS = (18.5 * mm, 43.5 * mm)


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
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    msh = Mesh.from_sdf(walker(), size=size)
    msh.add_region("weights", lambda x: x[1] > BODY_Y + BODY_H, kind="cells")
    soft = materials.NeoHookean(E=1.2e6, nu=0.45, density=1200.0)
    fem = Fem(msh, soft, degree=2)
    fem.add_material("weights", materials.NeoHookean(E=1.2e6, nu=0.45, density=12000.0))
    g = 9.80665
    fem.add_gravity(np.array([g * math.sin(THETA), -g * math.cos(THETA)]))
    return fem, msh


def main(out: Path, quick: bool = False) -> dict:
    from mpi4py import MPI

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fem, msh = model((1.5 if quick else 1.0) * mm)
    floor = sdf.Line((0.0, 0.0), (0.0, 1.0))
    # 1. stand on the slope: settle under gravity with sticking friction and heavy mass damping
    fem.add_contact(floor, friction=1.0, regularization=0.01 * mm)
    fem.simulate(t_end=0.04, dt=5e-4, rho_inf=0.5, rayleigh=(300.0, 0.0))
    modes = fem.eigen(8)
    freqs = np.array([f for f in modes.frequencies if np.isfinite(f) and f > 1.0])
    # 2. walk: from rest in that state, with the walking friction
    fem.contacts[0].friction = MU
    alpha = fem.rayleigh_coefficients(0.05, 2 * np.pi * freqs[0], 2 * np.pi * freqs[min(4, len(freqs) - 1)])
    T, dt = (0.10, 5e-4) if quick else (0.30, 3.3e-4)
    traj = fem.simulate(t_end=T, dt=dt, rho_inf=0.8, rayleigh=alpha)

    t = traj.times
    force = traj.reactions["contact_0"]            # force of the slope on the walker [N/m], per step
    X, cells, U = traj.vertices, traj.cells, traj.displacement
    a, b = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    area0 = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])   # (np.cross of 2-vectors is deprecated in numpy 2)
    com = (((X + U)[:, cells].mean(axis=2)) * area0[None, :, None]).sum(axis=1) / area0.sum()
    # gait frequency: dominant frequency of the normal contact force after the first 30 % (transient)
    keep = t > 0.3 * T
    fn = force[keep, 1] - force[keep, 1].mean()
    tt = t[keep]
    tu = np.linspace(tt[0], tt[-1], len(tt))
    fu = np.interp(tu, tt, fn) * np.hanning(len(tu))
    spec = np.abs(np.fft.rfft(fu, 8 * len(tu)))          # zero-padded: the peak interpolated between bins
    fr = np.fft.rfftfreq(8 * len(tu), tu[1] - tu[0])
    band = fr > 1.5 / (tt[-1] - tt[0])             # at least 1.5 periods in the window
    f_gait = float(fr[band][np.argmax(spec[band])])
    speed = float((com[-1, 0] - com[keep][0, 0]) / (t[-1] - tt[0]))

    summary = {"gait_frequency_hz": round(f_gait, 3), "gait_period_ms": round(1e3 / f_gait, 2),
               "seed_gait_frequency_hz": 21.1,
               "vibration_frequencies_hz": [round(float(f), 2) for f in freqs],
               "speed_mm_per_s": round(speed / mm, 3), "com_dx_mm": round(float(com[-1, 0] - com[0, 0]) / mm, 3),
               "steps": len(t) - 1, "dt_ms": dt * 1e3, "simulated_s": T, "cells": msh.num_cells,
               "newton_iterations_max": int(traj.newton_iterations.max())}
    if MPI.COMM_WORLD.rank != 0:
        return summary

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax.plot(t * 1e3, -force[:, 1], lw=1, label="normal")
    ax.plot(t * 1e3, -force[:, 0], lw=1, label="tangential")
    ax.set(xlabel="t [ms]", ylabel="contact force on the slope [N/m]")
    ax.legend(fontsize=8)
    bx.plot(fr, spec / spec[band].max())
    bx.axvline(f_gait, color="C3", lw=0.8)
    bx.set(xlim=(0, 100), xlabel="frequency [Hz]", ylabel="spectrum (normalized)",
           title=f"gait {f_gait:.1f} Hz (seed: 21.1 Hz)")
    fig.tight_layout()
    fig.savefig(out / "gait_force.png", dpi=120)
    plt.close(fig)

    traj.filmstrip(out / "gait.png", np.searchsorted(t, t[-1] - np.linspace(1.0 / f_gait, 0.0, 5)), floor=0.0,
                   ylim=(-2, 26), xlabel="x along the slope (downhill) [mm]")
    return summary
