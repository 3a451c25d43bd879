"""Every demo runs in its short mode and reports its key figure (checked here against the reference)."""
import json

import pytest

from sorofem import cli


def _run(name, tmp_path):
    summary = cli.run_demo(name, out=tmp_path, quick=True)
    report = json.loads((tmp_path / name / "report.json").read_text())
    assert report == json.loads(json.dumps(summary)), "report.json must hold what the demo returned"
    return report, tmp_path / name


def test_every_demo_has_a_check():
    assert set(cli.list_demos()) == set(CHECKS), "add a check for each demo to CHECKS below"


def check_chain(report, out):
    from sorofem.snapshots import Snapshots
    assert report["stages"][:3] == ["design", "mesh", "fem_snapshots"]
    assert report["cavities"] == 5  # one per chamber
    assert report["bending_angle_deg"] > 30  # bends toward the strain-limiting layer
    assert report["cavity_volume_change_rel"] > 0
    snap = Snapshots(out / report["snapshot"])
    assert snap.n_steps >= 5 and snap.inputs["pressure/cavity_0"][-1] == pytest.approx(report["max_pressure_kPa"] * 1e3)
    for name in ("design.png", "mesh.png", "deformed.png", "bending.png"):
        assert (out / name).stat().st_size > 0


def check_sdf_gallery(report, out):
    assert report["sphere_volume_error_rel"] < 0.01  # marching cubes at the default resolution
    assert report["seed2d_area_error_rel"] < 1e-3
    assert report["stl_files"] == len(list(out.glob("*.stl"))) >= 4
    assert report["png_files"] == len(list(out.glob("*.png"))) >= 4


def check_mesh_gallery(report, out):
    assert report["pneunet_cavities"] >= 2  # the chambers were found and named
    assert report["pneunet_area_rel_error"] < 1e-3
    assert report["image_area_rel_error"] < 1e-2  # half-pixel bound of the image contour
    assert report["stl_volume_rel_error"] < 2e-2
    assert (out / "pneunet.png").stat().st_size > 0


def check_porous_buckling(report, out):
    assert -0.125 < report["critical_strain"] < -0.02  # the lowest eigenvalue crossed zero under compression
    assert report["lambda1_at_zero"] > 0
    assert report["ellipse_alternation"] >= 0.75  # the mutually orthogonal ellipses of the seed's Fig. 7
    assert (out / "modes.png").stat().st_size > 0 and (out / "stability.png").stat().st_size > 0


def check_pneunet_inflation(report, out):
    assert report["reached_pressure_kPa_2d"] == pytest.approx(report["max_pressure_kPa"])
    assert report["tip_angle_deg_2d"] > 30 and report["tip_angle_deg_3d"] > 5  # curls toward the layer
    assert report["cavities_2d"] == report["chambers"]
    for name in ("angle_vs_pressure.png", "deformed_2d.png", "deformed_3d.png"):
        assert (out / name).stat().st_size > 0
    from sorofem.snapshots import Snapshots
    assert Snapshots(out / "pneunet_2d.h5").n_steps == report["steps_2d"] + 1


def check_crawler(report, out):
    weight = 1070.0 * 9.80665 * (150e-3 * 12e-3)  # upper bound of the section's weight per m of depth [N/m]
    assert report["steps"] == 100  # one 0.4 s period at 4 ms: no step had to be cut
    assert report["max_contact_force_N_per_m"] < 3 * weight  # landings, no violent impacts
    assert abs(report["com_dy_mm"]) < 0.1  # back on the floor after the cycle
    assert (out / "com.png").stat().st_size > 0 and (out / "gait.png").stat().st_size > 0


CHECKS = {
    "chain": check_chain,
    "sdf_gallery": check_sdf_gallery,
    "mesh_gallery": check_mesh_gallery,
    "porous_buckling": check_porous_buckling,
    "pneunet_inflation": check_pneunet_inflation,
    "crawler": check_crawler,
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CHECKS))
def test_demo(name, tmp_path):
    report, out = _run(name, tmp_path)
    CHECKS[name](report, out)
