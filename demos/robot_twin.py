"""Digital twin of the soft bending actuator (a) from its printed geometry (`soro demo robot_twin`)
===============================================================================================

Purpose
-------
The seed's robot (a), a bellows bending actuator on an inextensible base layer in Elastic 80A, is inflated
by 3D FEM *of the geometry that is printed* (:mod:`sorofem.robots`, the same parameters, its port plugged so
the chamber network is one closed cavity), and a data-driven (DVS) Cosserat beam is made from the snapshots:
the bending strain recovered along a backbone in the base layer, its POD modes, and the actuation identified
on the pressure ramp. The tip angle against pressure from FEM and from the beam is the figure.

Model
-----
3D finite strain, the Elastic 80A preset (Neo-Hookean), the mount block's back face (x = 0) clamped, a
follower pressure ramp 0 .. ``p_max`` on the chamber network's surface (``cavity_0``). The tip angle is the
rotation about y of the backbone's tangent at the tip (the recovered FEM frame; the beam's tip frame),
positive when the actuator curls towards its base layer. The beam is identified on the same ramp it is
compared with (no held-out pressure).

Parameters
----------
out : pathlib.Path
    Output directory: ``train.h5`` (snapshots), ``tip_angle.png`` (FEM and beam), ``report.json``.
quick : bool
    Three bellows (50 mm), 3 mm tetrahedra, P1, 40 kPa in 4 steps (CI); otherwise the default actuator's
    eight bellows (100 mm), 2.5 mm P2 tetrahedra, 100 kPa in 8 steps.

Figures
-------
``tip_angle_fem_deg`` and ``tip_angle_beam_deg`` (per load step), ``tip_error_top`` (beam vs FEM tip
distance at the top pressure, % of the backbone length), ``fem_cells``, ``fem_s``, ``dvs_energy``.
"""
import time
from pathlib import Path

import numpy as np

from sorofem.units import kPa, mm


def tip_angle(frames):
    """Tip angle [rad] from tip frames (steps, 4, 4): the rotation of the tangent (first column) about y,
    positive when the actuator curls towards its base layer (-z)."""
    t = np.asarray(frames)[:, :3, 0]
    return np.arctan2(-t[:, 2], t[:, 0])


def main(out: Path, quick: bool = False) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from soroshapes import Shapes
    from soroshapes.dvs import Backbone, compare, dvs_basis, identify, recover_strains
    from sorofem import materials, robots, sdf
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if quick:
        params, size, degree, p_max, steps = dict(n_bellows=3, length=50 * mm), 3.0 * mm, 1, 40 * kPa, 4
    else:
        params, size, degree, p_max, steps = {}, 2.5 * mm, 2, 100 * kPa, 8
    # the printed design with sharp edges (fillet 0: an exact OpenCASCADE rebuild of the tree) and the port
    # bore filled flush with the block's back face: the chamber network becomes one closed cavity
    dsg = robots.design("bending_actuator", fillet=0.0, **params)
    part, twin = dsg.parts[0], dsg.twins[0]
    port = part.networks[0].port
    p = dsg.params
    plug = port & sdf.Box((2 * p["port_depth"], p["width"], p["height"]), (p["port_depth"], 0, p["height"] / 2))
    t0 = time.perf_counter()
    msh = Mesh.from_sdf(part.shape | plug, size=size, method="csg")
    if msh.cavities != ["cavity_0"]:
        raise RuntimeError(f"expected one closed chamber network, the mesh has cavities {msh.cavities}")
    fem = Fem(msh, material=materials.Elastic80A(), degree=degree)
    fem.add_support("left")
    fem.add_pressure("cavity_0", p_max)
    fem.solve(steps=steps, max_step=1.0 / steps).save(out / "train.h5")
    t_fem = time.perf_counter() - t0

    # backbone: the base layer's mid-plane, from the block's front face to the tip
    blk, base, L = p["block"], p["base"], p["length"]
    backbone = Backbone.line([blk, 0.0, base / 2], [L - 0.3 * mm, 0.0, base / 2], normal=[0.0, 1.0, 0.0])
    train = recover_strains(out / "train.h5", backbone, samples=61)
    bases, kept, info = dvs_basis([train], (0, 3, 0, 0, 0, 0))
    shp = Shapes(bases, kept, length=backbone.length, section=twin.section, material=materials.Elastic80A(),
                 base=np.array([blk, 0.0, base / 2]), damping=0.0, segments=30)
    inputs = ["pressure/cavity_0"]
    ident = identify(shp, train, inputs=inputs)
    cmp = compare(shp, train, inputs)
    pressures = np.asarray(train.inputs[inputs[0]])
    a_fem = tip_angle(train.frames[:, -1])
    a_beam = tip_angle(np.array([shp.forward_kinematics(q)[-1] for q in cmp["q"]]))

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(pressures / kPa, np.degrees(a_fem), "ko-", label="3D FEM of the printed geometry")
    ax.plot(pressures / kPa, np.degrees(a_beam), "C1s--", label=f"DVS beam ({kept[1]} bending modes)")
    ax.set_xlabel("pressure [kPa]")
    ax.set_ylabel("tip angle [deg] (towards the base layer)")
    ax.set_title(f"bending actuator (a), {p['n_bellows']} bellows, {L / mm:g} mm")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "tip_angle.png", dpi=120)
    plt.close(fig)
    return {
        "n_bellows": int(p["n_bellows"]), "length_mm": L / mm, "p_max_kPa": p_max / kPa,
        "fem_cells": int(msh.num_cells), "fem_degree": degree, "fem_s": t_fem,
        "pressures_kPa": (pressures / kPa).tolist(),
        "tip_angle_fem_deg": np.degrees(a_fem).tolist(), "tip_angle_beam_deg": np.degrees(a_beam).tolist(),
        "tip_error_top": 100 * float(cmp["tip_error"][-1]), "tip_error_max": 100 * float(cmp["tip_error"].max()),
        "dvs_modes": int(kept[1]), "dvs_energy": info[1]["energy"], "fit_error": ident.fit_error,
    }
