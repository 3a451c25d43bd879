"""The end-to-end job (`make demo` runs `soro demo chain`).

Purpose
-------
Walk a soft actuator through the platform's chain as far as it exists, and write a report a reader can
check at a glance. Stages present now:

1. **design**: the side section of a PneuNet bending actuator as a signed distance function (a base with a
   strain-limiting layer, chamber walls, chambers), previewed as PNG;
2. **mesh**: gmsh triangles with the chambers found and named automatically (``cavity_0`` ...);
3. **FEM snapshots**: plane-strain hyperelastic inflation with a follower pressure ramp on every chamber
   (Dragon Skin 10 body, Elastic 50A bottom layer), written to the snapshot file that reduced models read;
4. **DVS beam model**: a second FEM solve at a pressure between the training steps (test data); the bending
   strain recovered along a backbone in the strain-limiting layer, three DVS modes, the beam's actuation
   identified on the training ramp, and the speed-accuracy trade of DVS, Chebyshev and PCC bases of 1-6 modes
   against FEM (``trade.txt``, ``trade.png``), with the cheapest model within 3 % of the length;
5. **closed-loop control on the simulated board**: the DVS beam (with the material's damping) becomes the
   plant of a simulated pneumatic board (:meth:`sorocontrol.Board.simulated`: board server, regulator
   dynamics, limits set to the training pressure range, watchdog); the host runs a 100 Hz loop through the
   protocol that reads the beam's coordinates from the board's sensors, computes the bending angle and sets
   the pressure by feed-forward (the beam's static angle-pressure map) plus integral feedback, following steps of
   the angle (``control.png``);
6. **report**: PNGs (design, mesh, deformed state, bending angle vs pressure) and ``report.json``.

Parameters
----------
Length 60 mm, height 14 mm, 5 chambers 8 mm x 8 mm, walls 1.5 mm, base 4 mm with a 1 mm strain-limiting
layer; pressure 0 -> 16 kPa (quick: 0 -> 8 kPa); element size 1 mm (quick: 1.6 mm), P2 displacement.

Figure
------
``bending_angle_deg``: the rotation of the free end toward the strain-limiting layer at the final pressure;
``dvs``: tip errors (% of length) of the 3-mode DVS beam on the training ramp and at the test pressure, its
static solve time and the speedup over the FEM test solve; ``trade``: the table; ``selected``: the cheapest
model within 3 % of the length; ``control``: the angle steps, the tracking error at the end of each step
and its RMS over each step's second half [deg], the loop's rate and jitter.
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.snapshots import input_name
from sorofem.units import kPa, mm

# ------------------------------------------------------------------------------------------------ parameters
L, H, N, WALL, BASE, LAYER = 60 * mm, 14 * mm, 5, 1.5 * mm, 4 * mm, 1 * mm   # section (see Parameters above)
P_TEST_FRACTION = 0.55          # the DVS test solve's pressure, as a fraction of p_max [-]
HOLD, LOOP_RATE = 1.5, 100.0    # control: each angle step held [s], the host loop's rate [Hz]
#: The full run and the short one (`--quick`, what the tests run): element size [m], top pressure [Pa], load
#: steps of the training ramp and of the test solve, angle steps as fractions of the static angle range [-].
FULL = dict(size=1.0 * mm, p_max=16 * kPa, steps=8, test_steps=4, angle_steps=(0.35, 0.75, 0.55))
QUICK = dict(size=1.6 * mm, p_max=8 * kPa, steps=4, test_steps=2, angle_steps=(0.4, 0.7))


def main(out: Path, quick: bool = False) -> dict:
    """Run the chain's stages in order into ``out``; returns the report (see Figure above)."""
    from mpi4py import MPI

    from sorofem.io import Progress
    from sorofem.mesh import Mesh

    prm = QUICK if quick else FULL
    rank0 = MPI.COMM_WORLD.rank == 0
    timings = {}
    stages = ["design", "mesh", "fem_snapshots", "dvs_beam_model", "board_control"]
    with Progress(len(stages), "chain", comm=MPI.COMM_WORLD, unit="stage") as bar:
        # 1. design
        t0 = time.perf_counter()
        shape = pneunet_section()
        props = shape.section_properties()
        if rank0:
            shape.to_png(out / "design.png", title="PneuNet section (SDF)")
        timings["design_s"] = time.perf_counter() - t0
        bar.to(1, stage="mesh")

        # 2. mesh: the chambers become the cavities cavity_0 ...; the strain-limiting layer a cell region
        t0 = time.perf_counter()
        msh = Mesh.from_sdf(shape, size=prm["size"])
        msh.add_region("layer", lambda x: x[1] < LAYER, kind="cells")
        if rank0:
            plot_mesh(msh, out / "mesh.png")
        timings["mesh_s"] = time.perf_counter() - t0
        bar.to(2, stage="fem")

        # 3. FEM snapshots: the pressure ramp 0 -> p_max on every chamber
        t0 = time.perf_counter()
        traj = inflation_problem(msh, prm["p_max"]).solve(steps=prm["steps"])
        traj.save(out / "pneunet_inflation.h5", cavities=())
        timings["fem_s"] = time.perf_counter() - t0
        bar.to(3, stage="dvs")

        # 4. DVS beam model from the snapshots, tested at a pressure between the training steps
        t0 = time.perf_counter()
        fem_test = inflation_problem(msh, prm["p_max"])
        t1 = time.perf_counter()
        fem_test.solve(load_level=P_TEST_FRACTION, steps=prm["test_steps"]).save(out / "pneunet_test.h5",
                                                                                   cavities=())
        fem_test_s = time.perf_counter() - t1
        plant, dvs = dvs_stage(out, msh.cavities[0], fem_test_s) if rank0 else (None, {})
        timings["dvs_s"] = time.perf_counter() - t0
        bar.to(4, stage="control")

        # 5. closed-loop control of the DVS beam on the simulated board
        t0 = time.perf_counter()
        control = control_stage(out, plant, prm["p_max"], prm["angle_steps"]) if rank0 else {}
        timings["control_s"] = time.perf_counter() - t0
        bar.to(5)

    # 6. report
    summary = {
        "stages": stages,
        "section_area_mm2": props.area / mm**2,
        "cells": msh.num_cells,
        "cavities": len(msh.cavities),
        "min_angle_deg": msh.quality["min_angle"],
        "max_pressure_kPa": prm["p_max"] / kPa,
        "newton_iterations_max": int(traj.newton_iterations.max()),
        "snapshot": "pneunet_inflation.h5",
        "timings_s": timings,
    }
    if rank0:
        summary.update(dvs)
        summary["control"] = control
        angles = np.degrees(np.unwrap([tip_angle(traj, k) for k in range(len(traj))]))
        summary["bending_angle_deg"] = float(angles[-1])
        volume = sum(traj.cavity_volumes[c] for c in msh.cavities)
        summary["cavity_volume_change_rel"] = float(volume[-1] / volume[0] - 1)
        traj.plot(out / "deformed.png", title=f"p = {prm['p_max'] / kPa:g} kPa, von Mises stress")
        pressure = traj.inputs[input_name("pressure", msh.cavities[0])] / kPa
        plot_bending(pressure, angles, out / "bending.png")
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def inflation_problem(msh, p_max):
    """The plane-strain inflation case: Dragon Skin 10 body, Elastic 50A layer, clamped at x = 0, the pressure
    ``p_max`` [Pa] on every chamber (reached at load level 1)."""
    from sorofem.fem import Fem

    fem = Fem(msh, materials.DragonSkin10(), degree=2)
    fem.add_material("layer", materials.Elastic50A())
    fem.add_support("left")
    for cavity in msh.cavities:
        fem.add_pressure(cavity, p_max)
    return fem


def pneunet_section():
    """Side section [m]: base + rounded chamber blocks, minus the chambers (separate cavities in 2D: a
    channel joining them would cut the walls off the base in a plane section)."""
    pitch = L / N
    body = sdf.Rectangle(L, BASE, center=(L / 2, BASE / 2))
    blocks = sdf.RoundedRectangle(pitch - 0.6 * mm, H - BASE + 1 * mm, 1.5 * mm,
                                  center=(pitch / 2, (H + BASE - 1 * mm) / 2))
    chamber = sdf.Rectangle(pitch - 2 * WALL, H - BASE - WALL, center=(pitch / 2, BASE + (H - BASE - WALL) / 2))
    return (body | blocks.repeat((pitch, 0), (N, 1))) - chamber.repeat((pitch, 0), (N, 1))


def tip_angle(traj, step):
    """Bending angle [rad] of the free end x = L toward the strain-limiting layer (clockwise rotation of the
    segment from its bottom to its top vertex), in (-pi, pi]; unwrap a sequence of them."""
    X = traj.vertices
    end = np.flatnonzero(np.abs(X[:, 0] - L) < 1e-9)
    lo, hi = end[np.argmin(X[end, 1])], end[np.argmax(X[end, 1])]
    x = X + traj.displacement[step]
    d = x[hi] - x[lo]
    return float(np.arctan2(d[0], d[1]))


def dvs_stage(out, cavity, fem_test_s):
    """Recover strains from the two snapshot files, build the 3-mode DVS beam, compare it with FEM and run
    the trade; returns the report entries."""
    from soroshapes import Shapes
    from soro.trade import trade_report
    from soroshapes.dvs import Backbone, compare, dvs_basis, identify, recover_strains

    backbone = Backbone.line([0.0, LAYER / 2], [L, LAYER / 2])
    train = recover_strains(out / "pneunet_inflation.h5", backbone, samples=61)
    test = recover_strains(out / "pneunet_test.h5", backbone, samples=61)
    test = test.select([len(test.times) - 1])
    inputs = [input_name("pressure", cavity)]

    def make(bases, dofs, damping=0.0):   # the section's stiffness scale is absorbed by the identified actuation
        return Shapes(bases, dofs, length=L, section=sdf.Rectangle(10 * mm, H), material=materials.DragonSkin10(),
                      base=np.array([0.0, LAYER / 2, 0.0]), damping=damping, segments=30)
    bases, kept, info = dvs_basis(train, (0, 0, 3, 0, 0, 0))
    beam = make(bases, kept)
    identify(beam, train, inputs=inputs)
    c_train, c_test = compare(beam, train, inputs), compare(beam, test, inputs)
    rows, pick = trade_report(train, test, make, inputs, out, tolerance=0.03)
    plant = make(bases, kept, damping=None)      # Kelvin-Voigt damping from the material's damping ratio
    identify(plant, train, inputs=inputs)
    return plant, {"dvs": {"modes": int(kept[2]), "energy": info[2]["energy"],
                    "tip_error_train_pct": 100 * float(c_train["tip_error"].max()),
                    "tip_error_test_pct": 100 * float(c_test["tip_error"].max()),
                    "beam_solve_ms": 1e3 * c_test["solve_time"], "fem_test_solve_s": fem_test_s,
                    "speedup": fem_test_s / c_test["solve_time"]},
            "trade": rows, "selected": pick}


def bend_angle(beam, q):
    """Rotation of the beam's tip frame about z relative to its base [deg] (positive toward -y)."""
    R = beam.forward_kinematics(q)[-1, :3, :3]
    return float(np.degrees(np.arctan2(-R[1, 0], R[0, 0])))


def control_stage(out, beam, p_max, angle_steps):
    """Closed-loop control of the bending angle of ``beam`` on a simulated board: steps to the fractions
    ``angle_steps`` of the static angle range, each held ``HOLD`` s; returns the figures."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    from sorocontrol import Board

    # the static angle-pressure map of the model: feed-forward, and the reachable range
    grid = np.linspace(0.0, p_max, 9)
    angles = np.array([bend_angle(beam, beam.statics(u=[p], steps=2)) for p in grid])
    refs = [float(angles[0] + f * (angles[-1] - angles[0])) for f in angle_steps]
    hold, rate = HOLD, LOOP_RATE
    # integral feedback only, crossing over at ~1 rad/s: well below the beam's lightly damped first mode and
    # the regulator's lag (a proportional term made the loop ring at the first mode)
    ki = 1.0 * (grid[-1] - grid[0]) / (angles[-1] - angles[0])      # Pa/(deg s)
    log, integral, t_prev = [], 0.0, 0.0
    with Board.simulated(channels=1, beam=beam, p_min=0.0, p_max=p_max, board_rate=200.0) as brd:
        state = brd.read()
        for t in brd.loop(duration=hold * len(refs), rate=rate):
            ref = refs[min(int(t // hold), len(refs) - 1)]
            theta = bend_angle(beam, state.sensors[3:])
            e = ref - theta
            ff = float(np.interp(ref, angles, grid))
            u = ff + ki * integral
            if 0.0 < u < p_max:          # integrate only when not saturated (anti-windup)
                integral += e * (t - t_prev)     # the elapsed time: a loaded machine skips iterations
            t_prev = t
            state = brd.set_pressure([u])
            log.append((t, ref, theta, state.requested[0], state.measured[0]))
        stats = brd.loop_stats
    log = np.array(log)
    end_err, rms = [], []
    for i in range(len(refs)):
        sel = (log[:, 0] >= i * hold + hold / 2) & (log[:, 0] < (i + 1) * hold)
        rms.append(float(np.sqrt(np.mean((log[sel, 1] - log[sel, 2]) ** 2))))
        end_err.append(float(abs(log[sel, 1][-1] - log[sel, 2][-1])))
    fig = Figure(figsize=(6, 4.5))
    ax, bx = fig.subplots(2, 1, sharex=True)
    ax.plot(log[:, 0], log[:, 1], "k--", lw=1, label="reference")
    ax.plot(log[:, 0], log[:, 2], lw=1.2, label="DVS beam on the board")
    ax.set_ylabel("bending angle [deg]")
    ax.legend(fontsize=8)
    bx.plot(log[:, 0], log[:, 3] / kPa, lw=1, label="set-point")
    bx.plot(log[:, 0], log[:, 4] / kPa, lw=1, label="measured")
    bx.set(xlabel="t [s]", ylabel="pressure [kPa]")
    bx.legend(fontsize=8)
    save_figure(fig, out / "control.png", dpi=120)
    return {"reference_deg": [round(r, 3) for r in refs], "end_error_deg": [round(e, 4) for e in end_err],
            "rms_error_second_half_deg": [round(r, 4) for r in rms],
            "static_range_deg": [round(float(angles[0]), 3), round(float(angles[-1]), 3)],
            "loop_rate_hz": round(stats.rate, 2), "loop_jitter_p99_us": round(stats.jitter_p99 * 1e6, 1),
            "loop_missed": stats.missed}


def plot_mesh(msh, path):
    """The mesh with its regions, axes in mm."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    fig = Figure(figsize=(8, 2.8))
    ax = fig.subplots()
    msh.plot(ax=ax, unit="mm")
    ax.set_title(f"{msh.num_cells} triangles, cavities: {', '.join(msh.cavities)}")
    save_figure(fig, path, dpi=120)


def plot_bending(pressure, angles, path):
    """Bending angle [deg] against the chamber pressure [kPa]."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    fig = Figure(figsize=(4.5, 3.2))
    ax = fig.subplots()
    ax.plot(pressure, angles, "o-")
    ax.set(xlabel="pressure [kPa]", ylabel="bending angle [deg]")
    ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=120)
