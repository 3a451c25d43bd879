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
4. **report**: PNGs (design, mesh, deformed state, bending angle vs pressure) and ``report.json``.

Still to come (their issues extend this file): DVS beam model from the snapshots, closed-loop control on the
simulated board.

Parameters
----------
Length 60 mm, height 14 mm, 5 chambers 8 mm x 8 mm, walls 1.5 mm, base 4 mm with a 1 mm strain-limiting
layer; pressure 0 -> 16 kPa (quick: 0 -> 8 kPa); element size 1 mm (quick: 1.6 mm), P2 displacement.

Figure
------
``bending_angle_deg``: the rotation of the free end toward the strain-limiting layer at the final pressure.
"""
import time
from pathlib import Path

import numpy as np

from sorofem import materials, sdf
from sorofem.units import kPa, mm

L, H, N, WALL, BASE, LAYER = 60 * mm, 14 * mm, 5, 1.5 * mm, 4 * mm, 1 * mm


def pneunet_section():
    """Side section [m]: base + rounded chamber blocks, minus the chambers (separate cavities in 2D: a
    channel joining them would cut the walls off the base in a plane section)."""
    pitch = L / N
    body = sdf.Rectangle(L, BASE, center=(L / 2, BASE / 2))
    blocks = sdf.RoundedRectangle(pitch - 0.6 * mm, H - BASE + 1 * mm, 1.5 * mm, center=(pitch / 2, (H + BASE - 1 * mm) / 2))
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


def main(out: Path, quick: bool = False) -> dict:
    from mpi4py import MPI

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    rank0 = MPI.COMM_WORLD.rank == 0
    timings = {}

    # 1. design
    t0 = time.perf_counter()
    shape = pneunet_section()
    props = shape.section_properties()
    if rank0:
        shape.to_png(out / "design.png", title="PneuNet section (SDF)")
    timings["design_s"] = time.perf_counter() - t0

    # 2. mesh
    t0 = time.perf_counter()
    msh = Mesh.from_sdf(shape, size=1.6 * mm if quick else 1.0 * mm)
    msh.add_region("layer", lambda x: x[1] < LAYER, kind="cells")
    if rank0:
        fig, ax = plt.subplots(figsize=(8, 2.6))
        msh.plot(ax=ax)
        ax.set_title(f"{msh.num_cells} triangles, cavities: {', '.join(msh.cavities)}")
        fig.tight_layout()
        fig.savefig(out / "mesh.png", dpi=120)
        plt.close(fig)
    timings["mesh_s"] = time.perf_counter() - t0

    # 3. FEM snapshots
    t0 = time.perf_counter()
    p_max = (8 if quick else 16) * kPa
    fem = Fem(msh, materials.DragonSkin10(), degree=2)
    fem.add_material("layer", materials.Elastic50A())
    fem.add_support("left")
    for cavity in msh.cavities:
        fem.add_pressure(cavity, p_max)
    traj = fem.solve(steps=4 if quick else 8)
    traj.save(out / "pneunet_inflation.h5", cavities=())
    timings["fem_s"] = time.perf_counter() - t0

    # 4. report
    summary = {
        "stages": ["design", "mesh", "fem_snapshots"],
        "section_area_mm2": props.area / mm**2,
        "cells": msh.num_cells,
        "cavities": len(msh.cavities),
        "min_angle_deg": msh.quality["min_angle"],
        "max_pressure_kPa": p_max / kPa,
        "newton_iterations_max": int(traj.newton_iterations.max()),
        "snapshot": "pneunet_inflation.h5",
        "timings_s": timings,
    }
    if rank0:
        angles = np.degrees(np.unwrap([tip_angle(traj, k) for k in range(len(traj))]))
        pressure = traj.inputs[f"pressure/{msh.cavities[0]}"] / kPa
        summary["bending_angle_deg"] = float(angles[-1])
        volume = sum(traj.cavity_volumes[c] for c in msh.cavities)
        summary["cavity_volume_change_rel"] = float(volume[-1] / volume[0] - 1)
        traj.plot(out / "deformed.png", title=f"p = {p_max / kPa:g} kPa, von Mises stress")
        fig, ax = plt.subplots(figsize=(4.5, 3.2))
        ax.plot(pressure, angles, "o-")
        ax.set_xlabel("pressure [kPa]")
        ax.set_ylabel("bending angle [deg]")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "bending.png", dpi=120)
        plt.close(fig)
    return summary
