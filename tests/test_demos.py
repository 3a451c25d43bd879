"""Every demo runs in its short mode; its key figures are checked against tests/demo_reference.toml.

The reference table holds each figure's measured value, a relative tolerance with its reason and the physical
bounds; the ``check_*`` functions below hold what a table cannot (files written, relations between figures).
"""
import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from soro import demo

REFERENCE = Path(__file__).with_name("demo_reference.toml")
ROW_KEYS = {"value", "rel", "abs", "min", "max", "why"}


def load_reference(path=REFERENCE):
    """The reference table: ``{demo: {path: row}}`` (see the header of tests/demo_reference.toml)."""
    with open(path, "rb") as f:
        return tomllib.load(f)


def figure(report, path):
    """The figure at ``path`` ("a.b[2]", "c[-1]") of a demo's report."""
    node = report
    for part in path.split("."):
        m = re.fullmatch(r"([^\[\]]+)((?:\[-?\d+\])*)", part)
        if m is None:
            raise KeyError(f"bad figure path {path!r}: keys joined by '.', list elements as [i]")
        node = node[m.group(1)]
        for index in re.findall(r"\[(-?\d+)\]", m.group(2)):
            node = node[int(index)]
    return node


def reference_failures(report, rows):
    """What in ``report`` is off its reference ``rows``: a list of messages, empty when every figure holds."""
    failures = []
    for path, row in rows.items():
        try:
            got = figure(report, path)
        except (KeyError, IndexError, TypeError):
            failures.append(f"{path}: not in the report (the demo no longer reports it? edit the table)")
            continue
        if isinstance(got, bool) or not isinstance(got, (int, float)) or not math.isfinite(got):
            failures.append(f"{path}: {got!r} is not a finite number")
            continue
        value, rel, abs_ = row["value"], row["rel"], row.get("abs", 0.0)
        if abs(got - value) > rel * abs(value) + abs_:
            off = abs(got - value) / abs(value) if value else math.inf
            failures.append(f"{path}: {got:.6g}, reference {value:.6g} +- {rel:g} relative ({off:.2g} off; "
                            f"{row['why']}); if the change is intended, edit tests/demo_reference.toml")
        if "min" in row and got < row["min"]:
            failures.append(f"{path}: {got:.6g} below its physical bound {row['min']:g}")
        if "max" in row and got > row["max"]:
            failures.append(f"{path}: {got:.6g} above its physical bound {row['max']:g}")
    return failures


def _run(name, tmp_path):
    summary = demo.run_demo(name, out=tmp_path, quick=True)
    report = json.loads((tmp_path / name / "report.json").read_text())
    assert report == json.loads(json.dumps(summary)), "report.json must hold what the demo returned"
    return report, tmp_path / name


def test_every_demo_has_a_check():
    assert set(demo.list_demos()) == set(CHECKS), "add a check for each demo to CHECKS below"
    assert set(demo.list_demos()) == set(load_reference()), "add each demo's key figures to demo_reference.toml"


def demo_layout_problems(source):
    """What keeps a demo's source from reading top to bottom (STYLE.md: the DOLFINx demos): a list of
    messages, empty when ``main`` is its first function, its parameters one ``FULL``/``QUICK`` pair with the same
    keys, and it neither switches matplotlib's backend nor uses pyplot nor reaches for a private name."""
    import ast

    tree = ast.parse(source)
    problems = []
    functions = [n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]
    if not functions or functions[0] != "main":
        problems.append(f"main is not the first function (first: {functions[:1]})")
    sets = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name) \
                and node.targets[0].id in ("FULL", "QUICK"):
            value = node.value
            keys = ([k.arg for k in value.keywords] if isinstance(value, ast.Call)
                    else [k.value for k in value.keys] if isinstance(value, ast.Dict) else None)
            sets[node.targets[0].id] = sorted(keys) if keys is not None else None
    if set(sets) != {"FULL", "QUICK"} or sets["FULL"] is None or sets["FULL"] != sets["QUICK"]:
        problems.append(f"no FULL/QUICK parameter sets with the same keys: {sets}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr == "use" and isinstance(node.value, ast.Name) \
                and node.value.id == "matplotlib":
            problems.append(f"line {node.lineno}: matplotlib.use switches the process's backend")
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            problems.append(f"line {node.lineno}: private attribute .{node.attr}")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
            if any(n and ("pyplot" in n or any(p.startswith("_") for p in n.split("."))) for n in names):
                problems.append(f"line {node.lineno}: imports {names} (pyplot or a private name)")
    return problems


def test_demos_read_top_to_bottom():
    problems = {name: demo_layout_problems(demo.demo_path(name).read_text()) for name in demo.list_demos()}
    assert {k: v for k, v in problems.items() if v} == {}


def test_demo_layout_check_can_fail():
    good = "FULL = dict(a=1)\nQUICK = dict(a=2)\n\ndef main(out, quick=False):\n    pass\n"
    assert demo_layout_problems(good) == []
    bad = ("import matplotlib\nimport matplotlib.pyplot as plt\nFULL = dict(a=1)\nQUICK = dict(b=1)\n\n"
           "def helper():\n    pass\n\ndef main(out, quick=False):\n    matplotlib.use('Agg')\n    model._secret\n")
    got = "\n".join(demo_layout_problems(bad))
    for part in ("main is not the first function", "FULL/QUICK", "matplotlib.use", "private attribute ._secret",
                 "pyplot"):
        assert part in got, part


def test_reference_table_is_well_formed():
    for name, rows in load_reference().items():
        assert rows, f"{name}: no figure"
        for path, row in rows.items():
            where = f"{name}.{path}"
            assert set(row) <= ROW_KEYS and {"value", "rel", "why"} <= set(row), f"{where}: keys {sorted(row)}"
            assert 0 <= row["rel"] <= 0.25 and row["why"].strip(), f"{where}: rel in [0, 0.25] and a reason"
            # the reference sits inside its own physical bounds and tolerance band
            assert reference_failures({"x": row["value"]}, {"x": row}) == [], where


def test_reference_check_fails_on_a_drifted_figure():
    rows = {"a.b[1]": {"value": 10.0, "rel": 0.01, "min": 5.0, "why": "test"},
            "c": {"value": 0.0, "rel": 0, "abs": 1e-6, "why": "test"}}
    assert reference_failures({"a": {"b": [0, 10.09]}, "c": 1e-7}, rows) == []
    drifted = reference_failures({"a": {"b": [0, 10.2]}, "c": 0.0}, rows)
    assert len(drifted) == 1 and drifted[0].startswith("a.b[1]: 10.2, reference 10 +- 0.01 relative")
    assert "below its physical bound 5" in reference_failures({"a": {"b": [0, 4.0]}, "c": 0.0},
                                                               dict(rows, **{"a.b[1]": dict(rows["a.b[1]"], rel=1)}))[0]
    assert "not in the report" in reference_failures({"c": 0.0}, rows)[0]
    assert "not a finite number" in reference_failures({"a": {"b": [0, math.nan]}, "c": 0.0}, rows)[0]


def check_chain(report, out):
    from sorofem.snapshots import Snapshots
    assert report["stages"][:3] == ["design", "mesh", "fem_snapshots"]
    assert report["cavities"] == 5  # one per chamber
    assert report["bending_angle_deg"] > 30  # bends toward the strain-limiting layer
    assert report["cavity_volume_change_rel"] > 0
    snap = Snapshots(out / report["snapshot"])
    assert snap.n_steps >= 5 and snap.inputs["pressure/cavity_0"][-1] == pytest.approx(report["max_pressure_kPa"] * 1e3)
    for name in ("design.png", "mesh.png", "deformed.png", "bending.png", "trade.png", "trade.txt"):
        assert (out / name).stat().st_size > 0
    assert report["stages"][3] == "dvs_beam_model"
    assert report["dvs"]["tip_error_train_pct"] < 3.0 and report["dvs"]["tip_error_test_pct"] < 5.0
    assert report["selected"] is not None and len(report["trade"]) >= 15
    # closed-loop control of the DVS beam on the simulated board: each angle step reached (the model's own
    # static map + integral action; 0.1 deg measured, bound 1 deg). The loop's rate is a benchmark figure
    # (bench_board), not checked here: a loaded machine misses deadlines, and then the real-time loop does not
    # track (at load 11 on 2 cores: 43 Hz, 169 deadlines missed, 7 deg left at the end of a 1.5 s step). So the
    # 1 deg bound holds when the loop kept 90 % of its 100 Hz; otherwise only that the angle stayed in range.
    assert report["stages"][4] == "board_control"
    ctrl = report["control"]
    assert (out / "control.png").stat().st_size
    if ctrl["loop_rate_hz"] >= 90.0:
        assert max(ctrl["end_error_deg"]) < 1.0
    else:
        assert max(ctrl["end_error_deg"]) < ctrl["static_range_deg"][1], ctrl


def check_sdf_gallery(report, out):
    assert report["sphere_volume_error_rel"] < 0.01  # marching cubes at the default resolution
    assert report["seed2d_area_error_rel"] < 1e-3
    assert report["stl_files"] == len(list(out.glob("*.stl"))) >= 4
    assert report["png_files"] == len(list(out.glob("*.png"))) >= 4
    # the PneuNet finger is one printable solid (it was six loose pieces): read back in mm, watertight,
    # consistently oriented, positive volume, one shell; its chambers are one network open only at the inlet
    from sorofem import sdf
    assert sdf.stl_units(out / "finger.stl") == "mm"
    chk = sdf.surface_check(sdf.read_stl(out / "finger.stl")[0])
    assert chk["watertight"] and chk["shells"] == 1 and chk["volume"] > 0, chk
    assert chk["volume"] / 1e-9 == pytest.approx(report["finger_volume_mm3"], rel=0.05)
    size_mm = (chk["hi"] - chk["lo"]) * 1e3
    assert size_mm == pytest.approx([80, 16.5, 15], rel=0.05)
    net = report["finger_network"]
    assert net["connected"] and net["closed"] and net["inlet_open"], net


def check_mesh_gallery(report, out):
    assert report["pneunet_cavities"] >= 2  # the chambers were found and named
    assert report["pneunet_area_rel_error"] < 1e-3
    assert report["image_area_rel_error"] < 1e-2  # half-pixel bound of the image contour
    assert report["stl_volume_rel_error"] < 2e-2
    assert (out / "pneunet.png").stat().st_size > 0
    # Voronoi/Lloyd polygons (quick: 80 polygons, 15 Lloyd steps): area 2.1 % off (measured; 1.0 % with 300):
    # the sides are tangent lines, and at each of the 16 convex chamber corners a triangle of about (h/2)^2/2
    # (h = 3.6 mm, the cell size) is cut off; bound 4 %. Lloyd lowered the energy to 0.53 E_0 (bound 0.7).
    assert report["voronoi_polygons"] == 80
    assert report["voronoi_area_rel_error"] < 0.04
    assert report["voronoi_energy_ratio"] < 0.7
    assert (out / "voronoi.png").stat().st_size > 0


def check_porous_buckling(report, out):
    assert -0.125 < report["critical_strain"] < -0.02  # the lowest eigenvalue crossed zero under compression
    # -9.08 % measured at the quick mesh (4 x 4 holes; -7.84 % for the full 6 x 6 block): the crossing is placed by
    # linear interpolation between steps 0.8 % strain apart, and another step sequence moves it by well under
    # 1 % of its value; 3 %
    assert report["critical_strain"] == pytest.approx(-0.0908, rel=0.03)
    assert report["lambda1_at_zero"] > 0
    assert report["ellipse_alternation"] >= 0.75  # the mutually orthogonal ellipses of the seed's Fig. 7
    # followed onto the post-critical branch (branch switching), to the seed's -12.5 %, where it is stable
    assert report["strain_reached"] == report["strain_end"] == -0.125 and report["branch_switch_step"] is not None
    assert report["lambda1_at_end"] > 0
    assert (out / "modes.png").stat().st_size > 0 and (out / "stability.png").stat().st_size > 0


def check_pneunet_inflation(report, out):
    assert report["reached_pressure_kPa_2d"] == pytest.approx(report["max_pressure_kPa"])
    assert report["tip_angle_deg_2d"] > 30 and report["tip_angle_deg_3d"] > 5  # curls toward the layer
    # the tip angles are rows of tests/demo_reference.toml (2D 1e-3; 3D 5 %: gmsh 4.11 and 4.13 mesh the 3D
    # finger differently, 17.46 vs 17.63 deg measured on Debian 12 and 13)
    # 2D: the first step cut by its linear response (Fem.solve(linear_start=)); 3D: the path followed by arc
    # length with at most 8 Newton iterations per step (Fem.follow(max_iterations=8)). Measured 6 in both
    # (14 and 11 in the first steps before linear_start; 16 in the full 3D ramp's first step before follow)
    assert report["newton_iterations_max"] <= 8
    # the quick 3D actuator has no pressure maximum below 10 kPa: the path lands on the full load (the full
    # one passes its limit point near 12.6 kPa and reports it)
    assert report["limit_pressure_kPa_3d"] is None
    assert report["reached_pressure_kPa_3d"] == pytest.approx(report["max_pressure_kPa_3d"])
    assert report["cavities_2d"] == report["chambers"]
    for name in ("angle_vs_pressure.png", "deformed_2d.png", "deformed_3d.png"):
        assert (out / name).stat().st_size > 0
    from sorofem.snapshots import Snapshots
    assert Snapshots(out / "pneunet_2d.h5").n_steps == report["steps_2d"] + 1


def check_crawler(report, out):
    weight = 1070.0 * 9.80665 * (150e-3 * 15e-3)  # upper bound of the section's weight per m of depth [N/m]
    assert report["amplitude_kPa"] == 15.0 and report["period_s"] == pytest.approx(0.75)   # the seed's code signal
    assert report["steps"] == 188  # one 0.75 s period at 4 ms, no step cut
    # an undulation, not a leap: the legs keep the floor (each rises < 0.5 mm; the paper's 45 kPa lifted the
    # body 31 mm) and the body ends the period on it
    assert max(report["feet_lift_max_mm"]) < 0.5 and report["com_rise_max_mm"] < 1.0
    assert abs(report["com_dy_mm"]) < 0.5
    assert report["max_contact_force_N_per_m"] < 30 * weight  # no impacts
    assert report["com_dx_per_period_mm"] == pytest.approx([report["com_dx_mm"]])
    for name in ("com.png", "gait.png", "crawler.xdmf", "crawler.xdmf.h5"):
        assert (out / name).stat().st_size > 0


def check_jellyfish_gripper(report, out):
    assert len(report["ik_error_m"]) == report["fingers"] == 6
    # 11 targets (33 equations) for 6 coordinates: a least-squares fit; 1 mm bounds the stacked residual
    assert all(c or e < 1e-3 for c, e in zip(report["ik_converged"], report["ik_error_m"]))
    assert report["max_penetration_mm"] < 0.5  # the finger surface stays outside the sphere
    assert min(report["wrap_angle_deg"]) > 90  # each finger wraps the sphere, not just touches it
    # the six fingers are the same problem rotated by 60 degrees: the same answer up to round-off
    assert max(report["penetration_mm"]) - min(report["penetration_mm"]) < 0.02
    assert (out / "jellyfish.png").stat().st_size > 0 and (out / "finger_plane.png").stat().st_size > 0


def check_pcc_arm(report, out):
    x, y, z = report["static_tip_mm"]
    assert z < 0 and 0 < x < 360 and abs(y) < 1e-6  # sags below the clamp, in the vertical plane
    kappa = report["segment_curvature_1_per_m"]
    # the gravity moment decreases from the clamp to the tip, and so does the segment curvature
    assert all(k > 0 for k in kappa) and all(a > b for a, b in zip(kappa, kappa[1:]))
    # settled: the linearized in-plane decay (rate ~2/s) leaves an envelope of ~0.1 mm of the initial 250 mm
    # at t_end = 4 s; 1 mm allows ten times that for the nonlinear first swing
    assert report["settle_envelope_mm"] < 1.0
    assert report["final_tip_error_mm"] < 1.0
    assert report["energy_max_increase_J"] < 1e-9  # damping only removes energy
    assert -1e-9 < report["energy_residual_J"] < 1e-3 * report["energy_released_J"]  # the static state is the minimum
    for name in ("snapshots.png", "static.png", "tip.png"):
        assert (out / name).stat().st_size > 0


def check_cantilever_release(report, out):
    assert report["energy_drift_implicit"] < 1e-2  # undamped: the midpoint rule keeps the energy
    assert report["dt_explicit_s"] <= report["explicit_step_limit_s"]
    # midpoint phase error after 0.5 s, (omega h)^2 / 24 * omega t: ~2e-5 rad for the 1.6 Hz swing (180 mm)
    # and ~0.04 rad for the ~20 Hz third mode (~1 mm): a few hundredths of a mm; 0.5 mm is 0.3 % of the swing
    assert report["max_tip_difference_mm"] < 0.5
    # released from rest above its equilibrium, an undamped rod overshoots the static sag
    assert report["lowest_tip_z_mm"] < report["static_tip_mm"][2]
    assert report["period_s"] is not None and report["period_s"] > 0
    assert (out / "tip.png").stat().st_size > 0 and (out / "energy.png").stat().st_size > 0


def check_dvs_pneunet(report, out):
    # the bars: 3 % of the length on the training ramp, 5 % at a pressure not trained on, 1000x faster
    assert report["dvs_modes"] == 3 and report["dvs_energy"] > 0.999
    assert report["tip_error_train"] < 3.0 and report["tip_error_test"] < 5.0
    assert report["tip_error_contact"] < 5.0          # wrapping the cylinder, with the beam's SDF contact
    assert report["speedup"] > 0  # reported; its size (> 1000 on a quiet machine) is measured by bench_dvs
    one_mode = [r for r in report["trade"] if r["modes"] == 1]
    assert min(r["tip_error_contact"] for r in one_mode) > 0.03   # a constant curvature cannot wrap: the trade bites
    assert report["selected"] is not None and report["selected"]["tip_error_test"] <= 0.03
    assert {r["family"] for r in report["trade"]} == {"dvs", "chebyshev", "pcc"}
    for name in ("modes.png", "shapes.png", "trade.png", "trade.txt", "train.h5", "test.h5", "wrap.h5"):
        assert (out / name).stat().st_size > 0


def check_soft_hand(report, out):
    n = len(report["fingers"])
    assert n == 5 and report["states"] == 5 * (2 * 5) + 5 * 2  # 5 fingers x (q, qd) of 5 modes + 5 (mass, integral)
    # each finger bends both ways; the first swing of a lightly damped finger (zeta 0.1) under a +-80 kPa step
    # overshoots its static angle (~45 deg), so the bound is loose: more than half the static angle
    assert all(a > 0.5 * s for a, s in zip(report["bending_amplitude_deg"], report["static_angle_80kPa_deg"]))
    assert all(hi > 20 and lo < -20 for hi, lo in zip(report["tip_angle_max_deg"], report["tip_angle_min_deg"]))
    # the reservoirs are identical up to the 0.1 % volume coupling: their pressures are the drive shifted by pi/6
    assert all(abs(d - 30) < 0.5 for d in report["pressure_phase_step_deg"])
    # the fingers follow in order; in the quick run (1.1 drive periods, the start-up transient, decay time
    # 1/(zeta omega_1) ~ 0.5 s, not gone) the four identical fingers keep the 30 deg step within 5 deg, the
    # shorter, stiffer thumb within 8 deg (its own lag behind its pressure differs)
    assert all(abs(d - 30) < 5 for d in report["phase_step_fingers_deg"])
    assert abs(report["phase_step_deg"][0] - 30) < 8
    # pressures reach the plateaus: 80 kPa +-3 %. After the valve saturates during a 160 kPa swing the PI loop
    # overshoots by ~2 % (1.5-2 kPa), and that offset decays with the integral time (1 s), not within a 0.45 s
    # plateau; 0.1 s into a plateau (5 regulator time constants of 20 ms) the error is that overshoot: < 3 %
    assert all(78 < p < 82.4 for p in report["max_pressure_kPa"]) and all(-82.4 < p < -78 for p in
                                                                            report["min_pressure_kPa"])
    assert report["plateau_tracking_error_kPa"] < 2.4
    assert report["cut_steps"] == 0 and report["steps"] == round(report["t_end_s"] / report["dt_s"])
    for name in ("trajectories.png", "hand.png"):
        assert (out / name).stat().st_size > 0


def check_board_pick_place(report, out):
    # the simulated board's plant holds the object (a 5 g cube on a table) and the arm: the open-loop plan picks it
    # through the gripper channel (the grasp engages with its pressure), lifts it (21.3 mm measured twice) and
    # puts it down 3.5 mm away (0.66, 1.19 mm from the place target measured); bound 2 mm: the planned carry is
    # 3.5 mm, so a place within 2 mm is a carried object, not one left behind or dropped. The gripper is open at
    # the end (the last hold vents it). Without the grasp the object stays (tests/sorocontrol/
    # test_plant_network.py). Tip errors up to 7.8 mm measured: the plan ignores the object's weight, which
    # sags the soft arm; bound 15 mm. The loop's rate and missed deadlines are reported, not checked.
    assert report["object_moved_mm"] > 1.5 and report["place_error_mm"] < 2.0
    assert report["lift_mm"] > 10.0
    assert abs(report["object_final_mm"][2] - report["object_start_mm"][2]) < 0.5      # standing on the table
    assert report["max_waypoint_error_mm"] < 15.0
    assert report["gripper_peak_kPa"] > 55 and report["gripper_final_kPa"] < 5 and report["loop_rate_hz"] > 0
    assert (out / report["png"]).stat().st_size > 0


def check_wavy_wall(report, out):
    # the start is free of the wall (tip tube 20 mm off the surface: no contact force at all, the bound
    # 0.1 N; before, a start inside the tube gave a 22 N spike), the approach touches the wall (the contact force
    # crosses the 0.3 N threshold at 0.55 s of the 0.8 s ramp, measured), the supervisor switches the set-point
    # (a jump of 9.8 mm measured: the approach set-point was still on its way in), and in the exploration the tip
    # stays on the wall (contact all along, penetration of the tube a few mm: no tunnelling through the penalty
    # wall), presses with about the impedance's K_c (delta + r) (3.8 N mean measured vs 3.3 N nominal; friction
    # and the groove flanks shift it, bound 30 %), and follows the sliding set-point (7.8 mm RMS measured: the
    # friction mu F / K_c = 2.5 mm plus the damping lag of a ramp that starts at the switch; bound 15 mm)
    assert report["contact_force_t0_N"] < 0.1 and report["start_gap_mm"] > 0
    assert 0 < report["contact_detected_s"] < report["simulated_s"] and report["setpoint_switch_mm"] > 0
    assert report["contact_fraction"] > 0.95
    assert -5.0 < report["surface_gap_mm"][0] <= report["surface_gap_mm"][1] < 0.5
    assert report["force_N"]["mean"] == pytest.approx(report["force_N"]["nominal"], rel=0.3)
    assert report["tracking_error_mm"] < 15.0
    for png in report["pngs"]:
        assert (out / png).stat().st_size > 0


def check_pneunet_design(report, out):
    assert report["iterations"] >= 30 and report["frames"] >= 5
    assert report["design_rotation_deg"] > 5.0 > 0.1 > report["initial_rotation_deg"]  # the optimizer made it bend
    assert report["flooded_cells"] > 0 and report["pressurized_cavities"] == 3  # one chamber per copy, all found
    assert report["volume_fraction"] <= 0.5 + 5e-3
    assert report["reached_pressure_kPa"] == pytest.approx(report["max_pressure_kPa"])
    assert report["bending_angle_deg"] > 5.0  # the re-meshed, re-simulated design bends toward its base
    assert report["bending_angle_deg"] > report["bending_angle_initial_deg"] + 5.0  # and beats the initial design
    # the design model is the validated actuator, with the validation's angle as objective: the two agree within
    # what the discretizations leave (Q1 nu = 0.45 and the soft void vs P2 nu = 0.49 on the iso-contour; 10 %
    # measured, bound 30 %). Before, the single-chamber model's objective (its face rotation, 4.2 deg) measured
    # something else than the validation (6.8 deg), and 100 iterations validated worse than 30
    assert report["bending_angle_deg"] == pytest.approx(report["design_rotation_deg"], rel=0.3)
    from sorofem.sdf.export import read_stl
    tri, _ = read_stl(out / "design.stl")
    assert len(tri) == report["stl_triangles"] > 1000
    for name in ("density.png", "density.xdmf", "density.h5", "history.png", "inflated.png", "design.npz",
                 "actuator_optimized.png", "actuator_initial.png"):   # one image per design (not overwritten)
        assert (out / name).stat().st_size > 0
    assert len(list((out / "frames").glob("frame_*.png"))) == report["frames"]


def check_shape_sensing(report, out):
    # offline, the held-out FEM case (the PneuNet pressed by a cylinder near its tip) seen by the camera: the
    # 3-mode DVS and Chebyshev estimates both reach the FEM tip within 1 mm (0.198 / 0.203 mm measured: the
    # bases' fit of a contact shape plus ~0.15 mm per pixel at 0.08 m); their values are pinned in the table
    assert all(v < 1.0 for v in report["offline_tip_error_mm"].values())
    # on the board, the camera-based estimate follows the plant (0.002 mm tip, 0.08 deg at the 95th percentile
    # measured; bounds 0.5 mm / 0.5 deg: sub-pixel markers at ~0.15 mm per pixel); on a loaded machine fewer
    # frames are estimated (skipped ones are counted: the loop sends every period whatever a frame costs), the
    # finger moves further between two estimates: the maximum only says that tracking was never lost
    assert report["markers_found_min"] == 5
    assert report["tip_estimation_error_mm"]["p95"] < 0.5 and report["angle_estimation_error_deg"]["p95"] < 0.5
    assert report["tip_estimation_error_mm"]["max"] < 5.0 and report["angle_estimation_error_deg"]["max"] < 5.0
    assert report["frames_estimated"] + report["frames_skipped"] + report["frames_failed"] == report["frames"]
    assert report["frames_estimated"] > 0 and report["loop_target_hz"] == 60.0
    # the end errors need the feedback and a plant in real time: with estimates at 1 Hz (load 15-18 on 2 cores)
    # the integral action overshoots (20.8 deg left); at 7.7 Hz estimates and a 48 Hz loop 0.9 / 1.4 deg were
    # left. The plant pressed by the cylinder integrates its contact in the beam's compiled loop (0.165 of real
    # time at load 11, the Python step loop before 0.03-0.11); where it is slower than real time the board's plant
    # skips time. The 3 deg bound is checked when the loop kept 90 % of its 60 Hz, the
    # estimator 15 Hz and the plant real time (the estimation bounds above hold at any rate)
    if report["loop_rate_hz"] >= 54.0 and report["estimation_rate_hz"] >= 15.0 \
            and report["plant_realtime_factor"] >= 1.0:
        assert max(report["end_error_deg"]) < 3.0
    assert (out / report["png"]).stat().st_size > 0
    for name in ("free.h5", "wrap.h5", "pressed.h5"):
        assert (out / name).stat().st_size > 0


def check_sim2real(report, out):
    # the replay recovers the rendered truth: the calibration finds the lens (k1, k2 = -0.25, 0.08 rendered;
    # -0.2514, 0.0826 and 0.02 px measured), seen markers within 0.5 mm (0.09 mm p95 measured: centres within
    # ~0.05 px plus the calibration's ~0.1 px, at 0.2 m / 554 px = 0.36 mm per pixel), and a dropped-out marker
    # filled by the shape estimate of the others within 2 mm (0.09 mm measured: the 3-mode model fits the
    # as-built finger's shape); every dropout rendered is reported, none left as NaN
    assert report["calibrated_k1_k2"][0] == pytest.approx(-0.25, abs=0.02)
    assert report["calibrated_k1_k2"][1] == pytest.approx(0.08, abs=0.03)
    assert report["calibration_rms_px"] < 0.5
    assert report["tracking_error_mm"]["seen_p95"] < 0.5 and report["tracking_error_mm"]["seen_max"] < 1.0
    assert report["tracking_error_mm"]["filled_max"] < 2.0
    assert report["dropouts"] == report["dropouts_rendered"] > 0 and report["nan_free"]
    # the as-built finger differs from the model (5 % stiffer, 2.5 % smaller chamber): the Sim2Real error is
    # that difference, larger than the tracking error, of the seed's order (+-2 mm)
    assert report["sim2real_error_mm"]["tip_mean"] > 5 * report["tracking_error_mm"]["seen_p95"]
    for name in (report["png"], report["video"]):
        assert (out / name).stat().st_size > 0


def check_suzumori_gripper(report, out):
    # the static grasps of the seed's Fig. 27 with the FMA's chambers (three 120 deg sectors of a 5 mm bore, 1 mm
    # walls: 21.33 mm^2 each, centroid 3.04 mm, A r = 64.9 mm^3; the hollow section's I = 590 mm^4): a finger
    # touches the object exactly when its free tip travel at the pressures exceeds the gap to close (beaker:
    # 56.9 mm > 11.5 mm; wrench: 57.1 mm > 18.2 mm), and no finger presses harder than its blocked tip, 3 M / (2 L)
    # with M = A r p_max = 0.0195 N m at 300 kPa: 0.365 N; the travel is far beyond a small deflection, so the
    # clamped cantilever's 3 EI / L^3 (travel - gap) is no reference any more. The hold margin is
    # mu F_n / (m g): above 1 for the 30 g beaker by four fingers (the seed's Fig. 27 holds it)
    blocked = 1.5 * 300e3 * 64.9e-9 / 0.08
    for g in (report["pinch_beaker"], report["pair_pinch_wrench"]):
        reach = g["free_tip_travel_mm"] - g["gap_to_close_mm"]
        assert (g["total_normal_N"] > 0) == (reach > 0)
        assert g["total_normal_N"] == pytest.approx(sum(g["normal_force_N"]), rel=1e-5, abs=1e-6)
        assert g["hold_margin"] == pytest.approx(g["friction_available_N"] / g["weight_N"], rel=1e-3, abs=1e-6)
        for f in g["normal_force_N"]:
            assert 0.0 < f < blocked
    assert report["pinch_beaker"]["hold_margin"] >= 1.0
    # the bolt: the fingers pinch its head (contact force during the grasp) and their circular tip motion turns
    # it, in the drive's sense, by friction, with the seed's damping 2.5 N mm s/rad = 2.5e-3 N m s/rad: 0.021 rev/s
    # over the quick run's last 0.5 s (0.037 over the full run's last 2.5 s), below the friction-limited rate
    # mu F_n r / mu_Omega (0.12 rev/s with the FMA fingers on the former tip path) as it must be (they slip; the
    # seed's 0.16 is above that limit: see the docstring; bound 0.01 .. 1)
    assert report["grasp_force_N"] > 0 and report["screw_force_N_max"] > report["grasp_force_N"]
    assert 0.01 < report["revolutions_per_second"] < 1.0 and report["bolt_turns"] > 0.01
    assert report["revolutions_per_second"] < report["friction_limited_rev_per_s"]
    for png in report["pngs"]:
        assert (out / png).stat().st_size > 0


def check_passive_walker(report, out):
    # the walker standing on the slope has leg modes near the seed's gait frequency (third mode 23.5 Hz
    # measured at the quick mesh, the seed's gait 21.1 Hz: bound 15-30 Hz), slides/walks downhill (mu < tan 30)
    # and its implicit dynamics with contact never needed a cut step (a quick run is too short for the gait
    # itself: its frequency resolution, one bin of the 70 ms window, is 14 Hz)
    f = report["vibration_frequencies_hz"]
    assert any(15.0 < v < 30.0 for v in f[:3])
    assert report["com_dx_mm"] > 1.0 and report["newton_iterations_max"] <= 10
    assert report["gait_frequency_resolution_hz"] == pytest.approx(1.0 / (0.7 * report["simulated_s"]), rel=0.02)
    # the hop: a unilateral contact force is never negative, carries the weight on average, and is zero only
    # while the walker is in the air
    assert 0.0 <= report["airborne_fraction"] < 0.5 and report["normal_force_max_over_weight"] > 1.0
    # Fig. 20 and 22: files, and the data (one row per step; the Lambdas open and close about their 55 deg)
    for name in ("gait.png", "gait_force.png", "front_leg.png", "leg_angles.png", "gait_series.csv"):
        assert (out / name).stat().st_size > 0
    series = np.loadtxt(out / "gait_series.csv", delimiter=",")
    assert series.shape == (report["steps"] + 1, 7) and np.all(series[:, 6] >= 0.0)
    assert all(40.0 < a < 70.0 for a in report["leg_angle_mean_deg"])
    assert all(0.5 < r < 30.0 for r in report["leg_angle_range_deg"])
    assert series[-1, 1] == pytest.approx(report["front_leg_dx_mm"], rel=1e-3)


def check_manipulator_pick(report, out):
    # quick: the three-bellow manipulator tree closes its three fingers on the 45 g cylinder, lifts it by more
    # than the case's 50 mm, carries it 45 mm sideways and puts it down on the place target chosen before the
    # run, with nothing but the fingers' contact forces holding it (the cylinder is coupled to the robot by
    # couple_tree_contact only; test_manipulator_pick_slips_out_without_friction shows friction carries it)
    assert report["lift_mm"] >= 50.0 and report["lift_at_end_of_lift_mm"] >= 50.0
    assert report["place_error_mm"] < 5.0 and abs(report["final_height_error_mm"]) < 1.0
    assert report["final_tilt_deg"] < 2.0
    assert np.hypot(*report["place_target_mm"]) > 40.0                     # carried, not put back
    # carried for more than a second off the table, the fingers' upward force carrying its weight (median
    # within 5 %), every finger pressing (0.27 N each, about equal: the three fingers are the same)
    assert report["carried_s"] > 1.0
    assert report["finger_lift_force_over_weight_while_carried"] == pytest.approx(1.0, abs=0.05)
    fn = np.array(report["grasp_normal_force_N"])
    assert report["grasp_normal_force_closed_N"] == pytest.approx(fn, rel=0.2)
    assert np.all(fn > 0.1) and fn.max() - fn.min() < 0.05 * fn.max()
    assert report["hold_margin_at_lift"] > 1.0 and report["hold_margin_min_while_carried"] > 1.0
    assert report["slip_mm"] < 10.0
    assert all((out / p).stat().st_size > 0 for p in report["png"])


def test_manipulator_pick_slips_out_without_friction(tmp_path):
    """The same close and lift with frictionless fingers: the cylinder stays on the table (the grasp holds by
    friction and by nothing else)."""
    r = demo.run_demo("manipulator_pick", out=tmp_path, quick=True, friction=0.0, until=1.3)
    assert r["lift_mm"] < 2.0 and r["carried_s"] == 0.0
    assert all(f > 0.1 for f in r["grasp_normal_force_closed_N"])          # closed, the fingers pressed it
    assert all(f == 0.0 for f in r["grasp_normal_force_N"])                # and slid off it as the arm rose


def check_robot_twin(report, out):
    import numpy as np
    a_fem, a_beam = np.array(report["tip_angle_fem_deg"]), np.array(report["tip_angle_beam_deg"])
    # (a) 3D FEM of the printed actuator: inflation curls it towards its base layer, more with more pressure
    assert a_fem[0] == pytest.approx(0, abs=1e-9) and np.all(np.diff(a_fem) > 0) and a_fem[-1] > 1.0
    # the DVS beam made from the even steps: tip within 5 % of the length (the bound) at the top
    # pressure and at the held-out (odd-step) pressures, angles within 15 %
    assert report["train"] == list(range(0, len(a_fem), 2)) and len(report["heldout_kPa"]) >= 2
    assert report["tip_error_top"] < 5.0 and report["tip_error_heldout"] < 5.0
    assert np.all(np.abs(a_beam - a_fem) <= 0.15 * np.abs(a_fem) + 0.05)
    assert (out / "a" / "tip_angle.png").stat().st_size > 0 and (out / "a" / "train.h5").is_file()
    # (b) the load path (0,0) -> (P,0) -> (P,P) -> (0,P) of (left, right), P = 50 kPa (the seed's top)
    b = report["planar"]
    assert b["p_max_kPa"] == 50.0
    tip = np.array(b["tip_fem_mm"])
    i_l, i_b, i_r = b["corners"]
    assert b["p_left_kPa"][i_l] == b["p_right_kPa"][i_r] == 50.0 and b["p_right_kPa"][i_l] == 0.0
    # left alone bends away from it (-y) and lengthens; right alone mirrors it; both together elongate it
    # (the backbone is the left chain's: its tip moves +x most when the left chain is inflated)
    assert tip[i_l, 1] < -0.2 and tip[i_r, 1] > 0.2 and tip[i_l, 0] > 0.2
    assert abs(tip[i_b, 1]) < 0.1 * abs(tip[i_l, 1]) and tip[i_b, 0] > tip[i_l, 0]
    # the DVS beam: within 5 % of the backbone length at the three top-pressure states and held out
    assert max(b["tip_error_corners"]) < 5.0 and b["tip_error_heldout"] < 5.0
    beam = np.array(b["tip_beam_mm"])
    assert np.all(np.sign(beam[[i_l, i_r], 1]) == np.sign(tip[[i_l, i_r], 1])) and beam[i_b, 0] > 0
    assert (out / "b" / "tip.png").stat().st_size > 0
    # the planar workspace of the DVS beam over -10..50 kPa per network: it holds the FEM's tip-plate centre
    # at the path's corners (within the 5 % bound) and is mirror-symmetric in y (two equal networks)
    lo, hi = np.array(b["workspace_lo_mm"])[:2], np.array(b["workspace_hi_mm"])[:2]
    fem_c = np.array(b["fem_tip_centre_mm"])[b["corners"], :2]
    tol = 0.05 * b["backbone_mm"]
    assert np.all(fem_c >= lo - tol) and np.all(fem_c <= hi + tol)
    assert hi[1] == pytest.approx(-lo[1], rel=0.1) and np.all(np.array(b["workspace_mm"]) > 0)
    assert b["seed_workspace_mm"] == [100.0, 100.0]


def check_parallel_robot(report, out):
    # must-show 3 of issue 25: constraint drift below 1e-8 m in statics and 1e-6 m in the dynamics
    assert report["statics_drift_m"] < 1e-8 and report["dynamics_drift_m"] < 1e-6
    # the closed check: equal pushes translate the whole robot, so the platform rises by the push, level
    assert abs(report["symmetric_rise_error_m"]) < 1e-9 * 0.15
    assert report["platform_tilt_deg"][0] < 1e-6 and report["platform_tilt_deg"][1] < 1e-6
    # unequal pushes tilt the platform and move it towards the pulled rod's side
    assert report["platform_tilt_deg"][2] > 5.0
    assert (out / "robot.png").stat().st_size > 0 and (out / "dynamics.png").stat().st_size > 0


CHECKS = {
    "parallel_robot": check_parallel_robot,
    "robot_twin": check_robot_twin,
    "manipulator_pick": check_manipulator_pick,
    "passive_walker": check_passive_walker,
    "suzumori_gripper": check_suzumori_gripper,
    "shape_sensing": check_shape_sensing,
    "sim2real": check_sim2real,
    "wavy_wall": check_wavy_wall,
    "pneunet_design": check_pneunet_design,
    "board_pick_place": check_board_pick_place,
    "soft_hand": check_soft_hand,
    "chain": check_chain,
    "dvs_pneunet": check_dvs_pneunet,
    "sdf_gallery": check_sdf_gallery,
    "mesh_gallery": check_mesh_gallery,
    "porous_buckling": check_porous_buckling,
    "pneunet_inflation": check_pneunet_inflation,
    "crawler": check_crawler,
    "jellyfish_gripper": check_jellyfish_gripper,
    "pcc_arm": check_pcc_arm,
    "cantilever_release": check_cantilever_release,
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CHECKS))
def test_demo(name, tmp_path):
    report, out = _run(name, tmp_path)
    failures = reference_failures(report, load_reference()[name])
    assert not failures, f"{name}: key figures off tests/demo_reference.toml:\n" + "\n".join(failures)
    CHECKS[name](report, out)
