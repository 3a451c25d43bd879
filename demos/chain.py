"""The end-to-end job (`make demo` → `soro demo chain`).

Runs the chain design → mesh → FEM snapshots → DVS beam model → closed-loop control on the simulated board
as far as the platform has it, and writes a report (PNG figures + report.json) to ``out/chain/``.

Stages present now: environment check (a UFL form compiled and assembled on a DOLFINx mesh of the
actuator's 80 mm x 10 mm bounding rectangle).
"""
from pathlib import Path


def main(out: Path, quick: bool = False) -> dict:
    from mpi4py import MPI
    import numpy as np
    import ufl
    import dolfinx.fem
    import dolfinx.mesh

    from sorofem.units import mm

    L, H = 80 * mm, 10 * mm
    n = (16, 2) if quick else (80, 10)
    msh = dolfinx.mesh.create_rectangle(MPI.COMM_WORLD, [np.zeros(2), np.array([L, H])], list(n))
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(dolfinx.fem.Constant(msh, 1.0) * ufl.dx))
    area = msh.comm.allreduce(area)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    x = msh.geometry.x[:, :2]
    cells = msh.geometry.dofmap.array.reshape(-1, 3)
    fig, ax = plt.subplots(figsize=(8, 1.6))
    ax.add_collection(PolyCollection(x[cells] / mm, facecolor="none", edgecolor="k", linewidth=0.3))
    ax.set_xlim(0, L / mm)
    ax.set_ylim(0, H / mm)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_title(f"DOLFINx mesh, {cells.shape[0]} triangles")
    fig.tight_layout()
    fig.savefig(out / "mesh.png", dpi=120)
    plt.close(fig)
    return {"stages": ["environment"], "cells": int(cells.shape[0]), "area_mm2": area / mm**2,
            "area_error_rel": abs(area - L * H) / (L * H)}
