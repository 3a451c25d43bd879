"""The fidelity ladder of the 2D PneuNet, full scene (`soro trade pneunet2d --tol 1%`; `soro.ladder`).

Figures (issue 24): the table of FEM rungs (P1, P2, P2 mixed on h, h/2, h/4) and beam rungs (DVS, Chebyshev,
PCC) with the Pareto fronts, the reference's Richardson estimate and order, the error budget of the beams'
tip error, and the model selected at 1 % and at 0.1 % of the length with its error on the validation load.
Speed is reported as the ratio FEM reference solve / selected beam solve, measured in the same run. Asserted:
what was computed is consistent (never a time).
"""
import json


def test_bench_ladder_pneunet2d(record, tmp_path):
    from soro.ladder import run_ladder

    out = tmp_path / "pneunet2d"
    status = {tol: run_ladder("pneunet2d", tolerance=tol, measure="tip", out=out) for tol in ("1%", "0.1%")}
    rep = json.loads((out / "ladder.json").read_text())        # the last run (0.1 %)
    print("\n" + (out / "ladder.txt").read_text())
    rows = rep["rows"]
    ref = next(r for r in rows if r.get("estimated"))
    assert status["1%"] in (0, 1) and len(rows) >= 9
    record(status=status, richardson=rep["richardson"], budget=rep["budget"], verdict_0p1=rep["verdict"],
           reference_solve_s=ref["solve_time_s"], rows=rows)
