"""SimulatedPlant with a network plant (issue 26): the board's pressures move a real object only through the
gripper channel. The arm, object and table are those of demos/board_pick_place.py (``plant_network``)."""
from pathlib import Path

import numpy as np
import pytest

from sorocontrol.drivers import NetworkRecipe, SimulatedPlant
from sorofem.errors import ConvergenceError, ParameterError

DEMO = Path(__file__).resolve().parents[2] / "demos" / "board_pick_place.py"


def _demo():
    import runpy
    return runpy.run_path(str(DEMO))


def _pick_and_lift(grasp):
    """Down to the object, close the gripper (or not), lift: the object's centre [m] before and at the top."""
    d = _demo()
    plant = SimulatedPlant(5, network=NetworkRecipe(str(DEMO), "plant_network", (("grasp", grasp),)),
                           network_dt=5e-3)
    assert plant.sensor_names == ("arm_tip_x", "arm_tip_y", "arm_tip_z", "object_x", "object_y", "object_z",
                                  "plant_time")
    start = plant.network_sensors()[3:6].copy()
    plans = d["plan"](d["arm"](), [d["PICK"], (0.110, -0.038)])
    t = 0.0
    for (a, _), grip, dur in ((plans[0], 0.0, 0.6), (plans[0], d["GRIP"], 0.4), (plans[1], d["GRIP"], 0.8)):
        for _ in range(int(round(dur / 0.01))):
            t += 0.01
            _, s, faults = plant.apply(d["pressures"](a, grip), t)
            assert not faults.any() and np.all(np.isfinite(s))
    assert s[-1] == pytest.approx(t + 1e-4, abs=1e-9)    # the plant's time: every tick simulated, after its 0.1 ms warm-up step
    return start, s[3:6], s[:3]


@pytest.mark.slow
def test_the_gripper_channel_lifts_the_object_and_without_the_grasp_it_stays():
    # at rest on the table (4 corners x 300 N/m under 0.05 N: 0.04 mm into it) the object's centre is half its
    # 16 mm side above the table top
    d = _demo()
    start, top, tip = _pick_and_lift(True)
    assert start[2] == pytest.approx(d["TABLE_TOP"] + d["OBJ_SIDE"] / 2, abs=1e-4)
    # held by the grasp spring (100 N/m, 0.05 N: 0.5 mm) hanging 8 mm under the tip: lifted (10-15 mm measured)
    assert top[2] - start[2] > 5e-3
    assert top[2] == pytest.approx(tip[2] - d["OBJ_SIDE"] / 2, abs=2e-3)
    start0, top0, tip0 = _pick_and_lift(False)
    np.testing.assert_allclose(start0, start)
    assert np.linalg.norm(top0 - start0) < 0.2e-3          # the arm passes by, the object stays
    assert tip0[2] - top0[2] > 10e-3                       # and the arm did go up


def test_network_plant_needs_one_input_per_channel_and_not_a_beam_too(tmp_path):
    with pytest.raises(ParameterError, match="free inputs"):
        SimulatedPlant(4, network=NetworkRecipe(str(DEMO), "plant_network"))
    with pytest.raises(ParameterError, match="no function"):
        SimulatedPlant(5, network=NetworkRecipe(str(DEMO), "nothing"))
    with pytest.raises(ParameterError, match="not both"):
        SimulatedPlant(5, beam=_demo()["arm"](), network=NetworkRecipe(str(DEMO), "plant_network"))


def test_a_failing_plant_step_raises_out_of_apply_and_the_plant_keeps_its_state(monkeypatch):
    # the board server vents every channel on any exception of apply (test_board covers that path)
    plant = SimulatedPlant(5, network=NetworkRecipe(str(DEMO), "plant_network"), network_dt=5e-3)
    x = plant.xn.copy()

    def fail(*a, **k):
        raise ConvergenceError("Newton did not converge at t = 0.01 s")
    monkeypatch.setattr(plant.network, "simulate", fail)
    with pytest.raises(ConvergenceError):
        plant.apply(np.zeros(5), 0.01)
    np.testing.assert_array_equal(plant.xn, x)
