"""The digital twin of robot (a) (demos/robot_twin.py, quick mode): 3D FEM of the printed geometry and the
DVS beam made from it bend the same way by about the same amount."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

DEMO = Path(__file__).resolve().parents[1] / "demos" / "robot_twin.py"


@pytest.mark.slow
def test_bending_actuator_twin_quick(tmp_path):
    spec = importlib.util.spec_from_file_location("robot_twin", DEMO)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rep = mod.main(tmp_path, quick=True)
    a_fem, a_beam = np.array(rep["tip_angle_fem_deg"]), np.array(rep["tip_angle_beam_deg"])
    # inflation curls the actuator towards its inextensible base layer, more with more pressure
    assert a_fem[0] == pytest.approx(0, abs=1e-9) and np.all(np.diff(a_fem) > 0)
    assert a_fem[-1] > 1.0
    # the beam identified on these snapshots reproduces them: tip within 5 % of the length (the bound)
    assert rep["tip_error_top"] < 5.0
    assert np.all(np.abs(a_beam - a_fem) <= 0.15 * np.abs(a_fem) + 0.05)
    assert (tmp_path / "tip_angle.png").stat().st_size > 0 and (tmp_path / "train.h5").is_file()
