"""The speed-accuracy trade of beam models of a PneuNet against its FEM parent (`demos/dvs_pneunet.py`, full).

Figures (issue): a 3-mode DVS beam reproduces the FEM tip trajectory within 3 % of the length on the training
ramp and within 5 % at a pressure not in the training data; its static solve is >= 1000x faster than the FEM
solve; the full trade table (DVS, Chebyshev and PCC bases of 1-6 modes: tip and shape errors, time per solve)
and the cheapest model within 3 % (on the test pressure and on the actuator wrapping a cylinder). Asserted: what was computed is consistent (never a time).
"""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_bench_dvs_trade(record, tmp_path):
    spec = importlib.util.spec_from_file_location("dvs_pneunet", ROOT / "demos" / "dvs_pneunet.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    rep = demo.main(tmp_path, quick=False)
    assert rep["dvs_modes"] == 3 and len(rep["trade"]) >= 15
    print("\n" + (tmp_path / "trade.txt").read_text())
    record(chambers=rep["chambers"], p_max_kPa=rep["p_max_kPa"], p_test_kPa=rep["p_test_kPa"],
           tip_error_train_pct=rep["tip_error_train"], tip_error_test_pct=rep["tip_error_test"],
           tip_error_contact_pct=rep["tip_error_contact"], shape_error_contact_pct=rep["shape_error_contact"],
           shape_error_test_pct=rep["shape_error_test"], beam_solve_ms=rep["beam_solve_ms"],
           fem_solve_s=rep["fem_solve_s"], speedup=rep["speedup"], selected=rep["selected"], trade=rep["trade"],
           met=bool(rep["tip_error_train"] < 3 and rep["tip_error_test"] < 5 and rep["speedup"] >= 1000))
