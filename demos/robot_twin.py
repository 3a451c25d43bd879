"""Digital twins of the soft actuators (a) and (b) from their printed geometry (`soro demo robot_twin`)
=====================================================================================================

Purpose
-------
The seed's robots (a), a bellows bending actuator on an inextensible base layer, and (b), a planar actuator
of two bellows networks in parallel, both in Elastic 80A, are inflated by 3D FEM *of the geometry that is
printed* (:mod:`sorofem.robots`, the same parameters, its ports plugged so that each network is one closed
cavity), and a data-driven (DVS) Cosserat beam is made from the snapshots: the strains recovered along a
backbone, their POD modes, and the actuation identified from the inputs. The beam is made from the even load
steps only and checked on the odd ones: pressures it has not seen (held out).

Model
-----
3D finite strain, the Elastic 80A preset (Neo-Hookean), the mount block's back face (x = 0) clamped,
follower pressures on the chamber networks' surfaces.

(a) One network, a ramp 0 .. ``p_max``. Backbone: the base layer's mid-plane; the beam bends about its y axis
    (curvature modes only). The tip angle is the rotation about y of the backbone's tangent at the tip,
    positive when the actuator curls towards its base layer.
(b) Two networks ``left`` (+y) and ``right`` (-y), each 0 .. ``p_max`` (the top of the seed's -10..50 kPa):
    one load path (pL, pR) = (0, 0) -> (P, 0) -> (P, P) -> (0, P) passes through the left network alone, both
    together and the right one alone. Backbone: the top line of the left chain's crests (mid-wall), sampled
    at the crests (the only material on a straight line along a chain: the chambers are hollow);
    the beam bends in the plane (about body z) and stretches. Pressure in one chain lengthens it: the
    actuator bends away from it (left -> -y); both together lengthen the actuator (+x).

Parameters
----------
out : pathlib.Path
    Output directory: ``a/`` and ``b/`` with ``train.h5`` (snapshots), figures, ``report.json`` at the top.
quick : bool
    Three bellows (50 mm) for (a), four grooves (64 mm) for (b), 3 mm P1 tetrahedra (locking: far too stiff; it
    exercises the pipeline) and few steps (CI); otherwise the default actuators, P2 tetrahedra of 2.5 mm ((a))
    and 3 mm ((b): its round bellows' 1.2 mm walls are meshed to their curvature anyway).
robot : str
    ``"all"`` (default), ``"bending_actuator"`` or ``"planar_actuator"``.

Figures
-------
(a) ``tip_angle_fem_deg`` / ``tip_angle_beam_deg`` (per load step; ``train`` marks the training steps),
``tip_error_top`` (beam vs FEM tip distance at the top pressure, % of the backbone length), ``tip_error_heldout``
(the largest over the held-out pressures); (b) under ``planar``: the same at the three corners of the path
and on the held-out steps, tip displacements, ``fem_cells``, ``fem_s``, and the planar workspace
``workspace_mm`` (x and y extent of the tip plate's centre over -10..50 kPa per network, sampled 7 x 7 on the
DVS beam) against the seed's ``seed_workspace_mm`` (~100 x 100 mm).

Full run of (b) (``main(out, robot="planar_actuator")``; Debian 12, 70,039 P2 tetrahedra, 5306 s of FEM on a
loaded machine): 2 + 2 DVS modes; beam vs FEM tip error 2.56 / 1.31 / 1.97 % of the 144 mm backbone at the
corners (P, 0), (P, P), (0, P) of the path, 2.56 % the largest held out; the left chain's tip moves -39 mm sideways
with the left network alone, +63 mm along x with both. Workspace of the FEM-made beam over -10..50 kPa per
network 89.4 x 84.2 mm (the seed's ~100 x 100 mm; 64.3 x 65.1 mm over the trained 0..50 kPa: the -10 kPa side is
the identified actuation extrapolated). The bellows-modulus beam of :mod:`soro.robots` (calibrated on one chain's
stretch only) gives 89.6 x 121.1 mm: its stretch agrees, its sideways bending is ~1.4x the FEM's.
"""
import time
from pathlib import Path

import numpy as np

from sorofem.errors import ParameterError
from sorofem.snapshots import input_name
from sorofem.units import kPa, mm


#: The full run and the short one (`--quick`, what the tests run), for (a) and (b): the design's parameters
#: (:func:`soro.robots.design`), element size [m], displacement degree, top pressure [Pa] and load steps of (a),
#: load steps per leg of (b)'s path.
FULL = dict(bending=dict(design={}, size=2.5 * mm, degree=2, p_max=100 * kPa, steps=8),
            planar=dict(design={}, size=3.0 * mm, degree=2, per_leg=4))
QUICK = dict(bending=dict(design=dict(n_bellows=3, length=50 * mm), size=3.0 * mm, degree=1, p_max=40 * kPa,
                          steps=6),
             planar=dict(design=dict(n_bellows=4, length=64 * mm), size=3.0 * mm, degree=1, per_leg=4))


def main(out: Path, quick: bool = False, robot: str = "all") -> dict:
    """Run (a) and/or (b) (``robot``: "all", "bending_actuator" or "planar_actuator") into ``out/a``, ``out/b``."""
    prm = QUICK if quick else FULL
    out = Path(out)
    if robot not in ("all", "bending_actuator", "planar_actuator"):
        raise ParameterError(f"robot must be 'all', 'bending_actuator' or 'planar_actuator', got {robot!r}")
    report = {}
    if robot in ("all", "bending_actuator"):
        report.update(bending(out / "a", prm["bending"]))
    if robot in ("all", "planar_actuator"):
        report["planar"] = planar(out / "b", prm["planar"])
    return report


# ------------------------------------------------------------------------------------------------- the steps
def tip_angle(frames):
    """Tip angle [rad] from tip frames (steps, 4, 4): the rotation of the tangent (first column) about y,
    positive when the actuator curls towards its base layer (-z)."""
    t = np.asarray(frames)[:, :3, 0]
    return np.arctan2(-t[:, 2], t[:, 0])


def plane_angle(frames):
    """In-plane tip angle [rad] of (b): the rotation of the tangent about z (positive towards +y)."""
    t = np.asarray(frames)[:, :3, 0]
    return np.arctan2(t[:, 1], t[:, 0])


def split(n_snapshots):
    """Training (even) and held-out (odd) snapshot indices."""
    k = np.arange(n_snapshots)
    return k[k % 2 == 0], k[k % 2 == 1]


def dvs_twin(train_file, backbone, dofs, section, base, inputs, degree, samples):
    """Recover strains, make the DVS beam from the even steps, identify its actuation there, and compare it
    with every step. Returns (beam, data, comparison, identification, kept modes, info, training indices)."""
    from soroshapes import Shapes
    from soroshapes.dvs import compare, dvs_basis, identify, recover_strains
    from sorofem import materials

    data = recover_strains(train_file, backbone, samples=samples)
    tr, _ = split(len(data.times))
    train = data.select(tr)
    bases, kept, info = dvs_basis([train], dofs)
    shp = Shapes(bases, kept, length=backbone.length, section=section, material=materials.Elastic80A(),
                 base=np.asarray(base, float), damping=0.0, segments=30)
    ident = identify(shp, train, inputs=inputs, degree=degree)
    cmp = compare(shp, data, inputs, repeats=1)
    return shp, data, cmp, ident, kept, info, tr


def bending(out, prm):
    """(a): FEM ramp, DVS beam, held-out check, with the parameter set ``prm["bending"]``; returns the report."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    from soroshapes.dvs import Backbone
    from soro import robots
    from sorofem import materials, sdf
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    out.mkdir(parents=True, exist_ok=True)
    params, size, degree, p_max, steps = (prm[k] for k in ("design", "size", "degree", "p_max", "steps"))
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
    inputs = [input_name("pressure", "cavity_0")]
    shp, data, cmp, ident, kept, info, tr = dvs_twin(out / "train.h5", backbone, (0, 3, 0, 0, 0, 0),
                                                     twin.section, [blk, 0.0, base / 2], inputs, 3, 61)
    ho = np.setdiff1d(np.arange(len(data.times)), tr)
    pressures = np.asarray(data.inputs[inputs[0]])
    a_fem = tip_angle(data.frames[:, -1])
    a_beam = tip_angle(np.array([shp.forward_kinematics(q)[-1] for q in cmp["q"]]))

    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    ax.plot(pressures / kPa, np.degrees(a_fem), "k-", lw=0.8)
    ax.plot(pressures[tr] / kPa, np.degrees(a_fem[tr]), "ko", label="3D FEM, training pressures")
    ax.plot(pressures[ho] / kPa, np.degrees(a_fem[ho]), "kD", mfc="w", label="3D FEM, held-out pressures")
    ax.plot(pressures / kPa, np.degrees(a_beam), "C1s--", label=f"DVS beam ({kept[1]} bending modes)")
    ax.set_xlabel("pressure [kPa]")
    ax.set_ylabel("tip angle [deg] (towards the base layer)")
    ax.set_title(f"bending actuator (a), {p['n_bellows']} bellows, {L / mm:g} mm")
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, out / "tip_angle.png", dpi=120)
    err = 100 * cmp["tip_error"]
    return {
        "n_bellows": int(p["n_bellows"]), "length_mm": L / mm, "p_max_kPa": p_max / kPa,
        "fem_cells": int(msh.num_cells), "fem_degree": degree, "fem_s": t_fem,
        "pressures_kPa": (pressures / kPa).tolist(), "train": tr.tolist(),
        "tip_angle_fem_deg": np.degrees(a_fem).tolist(), "tip_angle_beam_deg": np.degrees(a_beam).tolist(),
        "tip_error_top": float(err[-1]), "tip_error_max": float(err.max()),
        "tip_error_heldout": float(err[ho].max()), "heldout_kPa": (pressures[ho] / kPa).tolist(),
        "dvs_modes": int(kept[1]), "dvs_energy": info[1]["energy"], "fit_error": ident.fit_error,
    }


def _cavity_y(msh, name):
    """The y centroid [m] of a cavity's surface (which network it is)."""
    import dolfinx.fem
    import ufl

    m = msh.dolfinx
    ds = ufl.ds(domain=m, subdomain_data=msh.meshtags(name), subdomain_id=msh.regions[name],
                metadata={"quadrature_degree": 2})
    x = ufl.SpatialCoordinate(m)
    one = dolfinx.fem.Constant(m, 1.0)
    a = dolfinx.fem.assemble_scalar(dolfinx.fem.form(x[1] * ds))
    b = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ds))
    return float(m.comm.allreduce(a) / m.comm.allreduce(b))


def planar_path(p_max, side):
    """Pressure [Pa] of network ``side`` ("left"/"right") at load parameter t in [0, 3] on the path
    (0, 0) -> (P, 0) -> (P, P) -> (0, P) of (left, right)."""
    if side == "left":
        return lambda t: p_max * float(np.clip(min(t, 3.0 - t), 0.0, 1.0))
    return lambda t: p_max * float(np.clip(t - 1.0, 0.0, 1.0))


def planar(out, prm):
    """(b): FEM of both networks along one load path, DVS beam, held-out check, with the parameter set
    ``prm["planar"]``; returns the report dict."""
    from matplotlib.figure import Figure
    from sorofem.io import save_figure

    from soroshapes.dvs import Backbone
    from soro import robots
    from sorofem import materials, sdf
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh

    out.mkdir(parents=True, exist_ok=True)
    params, size, degree, per_leg = (prm[k] for k in ("design", "size", "degree", "per_leg"))
    dsg = robots.design("planar_actuator", **params)
    p_max = dsg.channels["left"][1]
    part, twin = dsg.parts[0], dsg.twins[0]
    p = dsg.params
    H, W = p["diameter"], 2 * p["diameter"] + p["separation"]
    ports = part.networks[0].port | part.networks[1].port
    plug = ports & sdf.Box((2 * p["port_depth"], W, H), (p["port_depth"], 0, H / 2))
    t0 = time.perf_counter()
    msh = Mesh.from_sdf(part.shape | plug, size=size, method="csg")
    if len(msh.cavities) != 2:
        raise RuntimeError(f"expected two closed chamber networks, the mesh has cavities {msh.cavities}")
    side = {("left" if _cavity_y(msh, c) > 0 else "right"): c for c in msh.cavities}
    if sorted(side) != ["left", "right"]:
        raise RuntimeError("the two cavities are not on either side of the mid-plane")
    fem = Fem(msh, material=materials.Elastic80A(), degree=degree)
    fem.add_support("left")
    for s in ("left", "right"):
        fem.add_pressure(side[s], planar_path(p_max, s))
    steps = 3 * per_leg
    # thin round bellows: the first step sized from the linear response (their unloaded tangent is far softer
    # than the inflated walls)
    fem.solve(load_level=3.0, steps=steps, max_step=3.0 / steps, linear_start=0.02).save(out / "train.h5")
    t_fem = time.perf_counter() - t0

    # backbone: the top line of the left chain's crests (mid-wall), sampled at the middle of every crest between
    # two grooves and at both ends (the half crests on the block and under the tip plate): one sample per pitch
    blk, n = p["block"], p["n_bellows"]
    pitch = (p["length"] - blk - p["tip"]) / n
    crest = H / 2 - p["wall"] / 2
    yc, zb = H / 2 + p["separation"] / 2, H / 2 + crest
    x0 = blk
    backbone = Backbone.line([x0, yc, zb], [x0 + n * pitch, yc, zb], normal=[0.0, 1.0, 0.0])
    inputs = [input_name("pressure", side["left"]), input_name("pressure", side["right"])]
    shp, data, cmp, ident, kept, info, tr = dvs_twin(out / "train.h5", backbone, (0, 0, 2, 2, 0, 0),
                                                     twin.section, [x0, yc, zb], inputs, 2, n + 1)
    ho = np.setdiff1d(np.arange(len(data.times)), tr)
    pl, pr = (np.asarray(data.inputs[k]) for k in inputs)
    tip_fem = data.frames[:, -1, :3, 3] - data.frames[0, -1, :3, 3]
    beam_frames = np.array([shp.forward_kinematics(q)[-1] for q in cmp["q"]])
    tip_beam = beam_frames[:, :3, 3] - data.frames[0, -1, :3, 3]
    a_fem, a_beam = plane_angle(data.frames[:, -1]), plane_angle(beam_frames)
    err = 100 * cmp["tip_error"]
    corners = [int(np.argmin(np.abs(data.times - t))) for t in (1.0, 2.0, 3.0)]
    # the planar workspace: the tip plate's centre (the backbone's tip frame, -yc along body y) over the
    # board's pressure box, -10..50 kPa per network (below 0 Pa the identified actuation is extrapolated: the
    # FEM path has no vacuum) and over the trained box 0..50 kPa
    centre = (0.0, -yc, -crest)
    lims = [dsg.channels["left"], dsg.channels["right"]]
    pts = robots.reach(shp, lims, samples=7, point=centre)
    pts_trained = robots.reach(shp, [(0.0, hi) for _, hi in lims], samples=7, point=centre)
    fem_centre = np.array([(data.frames[k, -1] @ np.append(centre, 1.0))[:3] for k in range(len(data.times))])
    seed = dsg.workspace

    fig = Figure(figsize=(10, 4))
    axs = fig.subplots(1, 2)
    s = np.asarray(data.times)
    for ax, k, lab in ((axs[0], 1, "left chain's tip: y [mm]"), (axs[1], 0, "left chain's tip: x displacement [mm]")):
        ax.plot(s, tip_fem[:, k] / mm, "k-", lw=0.8)
        ax.plot(s[tr], tip_fem[tr, k] / mm, "ko", label="3D FEM, training")
        ax.plot(s[ho], tip_fem[ho, k] / mm, "kD", mfc="w", label="3D FEM, held out")
        ax.plot(s, tip_beam[:, k] / mm, "C1s--", label=f"DVS beam ({kept[2]}+{kept[3]} modes)")
        ax.set_xlabel("load path: (0,0) -> (P,0) -> (P,P) -> (0,P), P = %g kPa" % (p_max / kPa))
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    axs[0].legend()
    fig.suptitle(f"planar actuator (b), {n} bellows per network, {p['length'] / mm:g} mm")
    save_figure(fig, out / "tip.png", dpi=120)
    return {
        "n_bellows": int(n), "length_mm": p["length"] / mm, "backbone_mm": backbone.length / mm,
        "p_max_kPa": p_max / kPa, "fem_cells": int(msh.num_cells), "fem_degree": degree, "fem_s": t_fem,
        "p_left_kPa": (pl / kPa).tolist(), "p_right_kPa": (pr / kPa).tolist(), "train": tr.tolist(),
        "corners": corners, "tip_fem_mm": (tip_fem / mm).tolist(), "tip_beam_mm": (tip_beam / mm).tolist(),
        "angle_fem_deg": np.degrees(a_fem).tolist(), "angle_beam_deg": np.degrees(a_beam).tolist(),
        "tip_error": err.tolist(), "tip_error_corners": [float(err[c]) for c in corners],
        "tip_error_heldout": float(err[ho].max()), "dvs_modes": [int(kept[2]), int(kept[3])],
        "fit_error": ident.fit_error,
        "workspace_mm": (np.ptp(pts, axis=0)[:2] / mm).tolist(),
        "workspace_trained_mm": (np.ptp(pts_trained, axis=0)[:2] / mm).tolist(),
        "workspace_lo_mm": (pts.min(axis=0) / mm).tolist(), "workspace_hi_mm": (pts.max(axis=0) / mm).tolist(),
        "fem_tip_centre_mm": (fem_centre / mm).tolist(),
        "seed_workspace_mm": [v / mm for v in seed],
    }
