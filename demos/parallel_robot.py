r"""A parallel continuum robot: three rods welded to a moving platform (`soro demo parallel_robot`)
=============================================================================================

Purpose
-------
A closed-chain soft robot built from the constraints of :mod:`soroshapes.constraints`: three soft rods stand on
a base circle, their tips welded to a rigid platform. The inputs are the rods' base translations along their
axes (the actuation of the classic parallel continuum robot): pushing all three equally lifts the platform,
pushing them differently tilts and shifts it. The demo solves the statics of three poses, checks the symmetric
one against the closed answer, and integrates 10 s of dynamics after a lateral kick of the platform, reporting
the constraint drift (issue 25, must-show 3: below 1e-8 m in statics, 1e-6 m in dynamics).

Equations
---------
Each rod is a Cosserat beam (:class:`soroshapes.Shapes`) on its own base: Chebyshev :math:`T_0..T_3` on both
bendings, a constant torsion and a constant stretch (``dofs = (1, 4, 4, 1, 0, 0)``, 10 coordinates), 20
segments, under gravity, Kelvin-Voigt damping :math:`\tau`. The platform is a :class:`RigidLink` (6
coordinates, rotation vector and translation). The rods' tips are welded to three frames of the platform
(:class:`Weld`, 6 equations each): :math:`Kq - f - J_c^T\lambda = 0,\ c(q) = 0` in statics (bordered Newton,
the welds ramped from the straight rods), and the constrained implicit midpoint step (index 3, velocity
projection) in dynamics, :math:`q` = 36 coordinates, 18 multipliers.

Independent check (symmetric case): pushing the three bases by the same :math:`d` along the vertical is a rigid
translation of the whole robot (base, rods, platform, gravity unchanged relative to each other), so the
platform rises by exactly :math:`d` and keeps its orientation (tolerance: the solver's, 1e-9 of a rod length).
The single rod + platform case (a cantilever with an end mass) is checked in
``tests/soroshapes/test_constraints.py`` (statics to round-off, first frequency within 1e-3).

Parameters
----------
=================  =====================================================================================
rods               3, length 150 mm, circular section radius 3 mm, E = 20 MPa, nu = 0.45, rho = 1200 kg/m^3
                   (a stiff elastomer such as TPU), on a base circle of radius 40 mm at 0, 120, 240 deg;
                   damping tau = 2 ms
platform           mass 50 g, inertia 2e-5 kg m^2 about its axes, its weld frames on a circle of 40 mm
gravity            9.81 m/s^2 along -z
poses (inputs)     base translations d = (0, 0, 0), (10, 10, 10) mm, (15, 0, -15) mm
dynamics           from the tilted pose, the platform kicked at 0.2 m/s along x; h = 5 ms; 10 s (quick: 1 s)
=================  =====================================================================================

Figures
-------
``report.json``: ``platform_mm`` (platform centre per pose), ``platform_tilt_deg`` (per pose),
``symmetric_rise_mm`` and ``symmetric_rise_error_m`` (rise minus the push), ``statics_drift_m`` and
``statics_drift_rad`` (largest over the poses), ``dynamics_drift_m``, ``dynamics_drift_rad`` (largest over the
run), ``sway_frequency_Hz`` (platform x zero crossings), ``max_reaction_N`` (largest weld force in the run),
``t_end_s``, ``dt_s``, ``steps``, ``newton_iterations_mean``, ``simulation_wall_time_s``, ``real_time_factor``
(simulated over wall time). Pictures: ``robot.png`` (the rods and platform in the three poses, side view x-z in mm) and
``dynamics.png`` (platform centre x, y, z [mm] and the drift [m] against time).
"""
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import mm

LENGTH, RADIUS, BASE_RADIUS, MODES = 150 * mm, 3 * mm, 40 * mm, 4
MATERIAL = dict(E=20e6, nu=0.45, density=1200.0)
TAU = 2e-3                                   # Kelvin-Voigt damping of the rods [s]
PLATFORM_MASS, PLATFORM_INERTIA = 0.05, 2e-5
POSES = ((0.0, 0.0, 0.0), (10 * mm, 10 * mm, 10 * mm), (15 * mm, 0.0, -15 * mm))
KICK = 0.2                                   # lateral velocity of the platform at t = 0 [m/s]

#: The full run and the short one (`--quick`, what the tests run): simulated time [s] and step [s].
FULL = dict(t_end=10.0, dt=5e-3)
QUICK = dict(t_end=1.0, dt=5e-3)


def main(out: Path, quick: bool = False) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    run = QUICK if quick else FULL

    # statics of the three poses
    poses = [solve_pose(d) for d in POSES]
    home, sym, tilted = poses
    rise = sym["platform"][2] - home["platform"][2]

    # dynamics from the tilted pose after a lateral kick of the platform
    robot = tilted["robot"]
    qd0 = np.zeros(robot["assembly"].n)
    qd0[-3] = KICK                                            # the platform's x velocity (its last coordinates)
    tr = robot["assembly"].simulate(run["t_end"], run["dt"], tilted["q"], qd0, constraints=robot["welds"])

    plots(out, poses, tr)
    x = tr.tip[:, 0] - tr.tip[:, 0].mean()
    return {
        "platform_mm": [[float(v / mm) for v in p["platform"]] for p in poses],
        "platform_tilt_deg": [p["tilt_deg"] for p in poses],
        "symmetric_rise_mm": float(rise / mm),
        "symmetric_rise_error_m": float(rise - POSES[1][0]),
        "statics_drift_m": max(p["drift_m"] for p in poses),
        "statics_drift_rad": max(p["drift_rad"] for p in poses),
        "dynamics_drift_m": float(tr.drift_position.max()),
        "dynamics_drift_rad": float(tr.drift_rotation.max()),
        "sway_frequency_Hz": sway_frequency(tr.t, x),
        "max_reaction_N": float(np.linalg.norm(tr.reactions[:, :, 3:], axis=2).max()),
        "t_end_s": run["t_end"],
        "dt_s": run["dt"],
        "steps": int(tr.stats["steps"]),
        "newton_iterations_mean": float(tr.stats["newton_iterations_per_step"]),
        "simulation_wall_time_s": float(tr.stats["wall_time"]),
        "real_time_factor": float(run["t_end"] / tr.stats["wall_time"]),
    }


# ------------------------------------------------------------------------------------------------- the steps
def build(pushes):
    """The robot with its bases pushed by ``pushes`` [m] along their axes: {"rods", "platform", "assembly",
    "welds"}."""
    from soroshapes import Basis, Shapes
    from soroshapes.constraints import Assembly, RigidLink, Weld

    x_to_z = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])        # the rod's axis x up (+z)
    rods, frames = [], []
    for k, push in enumerate(pushes):
        a = 2 * np.pi * k / 3
        turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        base = np.eye(4)
        base[:3, :3] = turn @ x_to_z
        base[:3, 3] = (BASE_RADIUS * np.cos(a), BASE_RADIUS * np.sin(a), push)
        rod = Shapes(Basis.chebyshev(MODES), dofs=(1, MODES, MODES, 1, 0, 0), length=LENGTH,
                     section=sdf.Circle(RADIUS), material=materials.NeoHookean(**MATERIAL), base=base,
                     segments=20, damping=TAU)
        rods.append(rod.add_gravity((0.0, 0.0, -9.81)))
        frame = np.eye(4)                         # the weld frame on the platform: the rod's straight tip frame
        frame[:3, :3] = base[:3, :3]
        frame[:3, 3] = (BASE_RADIUS * np.cos(a), BASE_RADIUS * np.sin(a), 0.0)
        frames.append(frame)
    pose0 = np.eye(4)
    pose0[2, 3] = LENGTH
    platform = RigidLink(PLATFORM_MASS, PLATFORM_INERTIA, pose0=pose0, gravity=(0.0, 0.0, -9.81), name="platform")
    welds = [Weld(body=rod, to=platform, to_at=frame) for rod, frame in zip(rods, frames)]
    return {"rods": rods, "platform": platform, "assembly": Assembly(rods + [platform]), "welds": welds}


def solve_pose(pushes):
    """The constrained equilibrium of the robot with base translations ``pushes`` [m]."""
    robot = build(pushes)
    eq = robot["assembly"].statics(constraints=robot["welds"], steps=4)
    q_platform = robot["assembly"].split(eq.q)[-1]
    centre = robot["platform"].end(q_platform)
    tilt = float(np.degrees(np.linalg.norm(q_platform[:3])))
    return {"robot": robot, "q": eq.q, "platform": centre, "tilt_deg": tilt,
            "drift_m": float(eq.drift_position), "drift_rad": float(eq.drift_rotation),
            "shapes": [rod.positions(q) for rod, q in zip(robot["rods"], robot["assembly"].split(eq.q)[:3])]}


def sway_frequency(t, x):
    """Frequency [Hz] of the platform's sway from the zero crossings of ``x`` (None with fewer than three)."""
    i = np.nonzero(np.sign(x[:-1]) * np.sign(x[1:]) < 0)[0]
    if len(i) < 3:
        return None
    crossings = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    return float(0.5 / np.mean(np.diff(crossings)))


def plots(out, poses, tr):
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(9, 4.5))
    ax = fig.subplots(1, 3, sharey=True)
    for a, pose, d in zip(ax, poses, POSES):
        for shape in pose["shapes"]:
            a.plot(shape[:, 0] / mm, shape[:, 2] / mm, "-", color="tab:blue")
            a.plot(shape[0, 0] / mm, shape[0, 2] / mm, "s", color="k", ms=4)
        tips = np.array([s[-1] for s in pose["shapes"]])
        a.plot(tips[:, 0] / mm, tips[:, 2] / mm, "o", color="tab:red", ms=4)
        a.plot(pose["platform"][0] / mm, pose["platform"][2] / mm, "x", color="tab:red")
        a.set_title(f"d = ({', '.join(f'{v / mm:g}' for v in d)}) mm", fontsize=9)
        a.set_xlabel("x [mm]")
        a.set_aspect("equal")
        a.grid(alpha=0.3)
    ax[0].set_ylabel("z [mm]")
    fig.suptitle("parallel continuum robot: rods (blue), weld points and platform centre (red), side view")
    save_figure(fig, out / "robot.png", dpi=110)

    fig = Figure(figsize=(7, 6))
    ax = fig.subplots(2, 1, sharex=True)
    for k, name in enumerate("xyz"):
        ax[0].plot(tr.t, (tr.tip[:, k] - tr.tip[0, k]) / mm, label=f"{name} - {name}(0)")
    ax[0].set_ylabel("platform centre [mm]")
    ax[0].legend(fontsize=8)
    ax[0].grid(alpha=0.3)
    ax[0].set_title("platform after a lateral kick (constrained implicit midpoint)")
    ax[1].semilogy(tr.t, np.maximum(tr.drift_position, 1e-18), label="position drift [m]")
    ax[1].semilogy(tr.t, np.maximum(tr.drift_rotation, 1e-18), label="rotation drift [rad]")
    ax[1].set_ylabel("largest constraint drift")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    save_figure(fig, out / "dynamics.png", dpi=110)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/parallel_robot"),
                          quick="--quick" in sys.argv), indent=2))
