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


def test_bench_ladder_network_by_tolerance(record, tmp_path):
    """Two PneuNet bodies of one network ask for 1 % and 0.3 % of the length on the backbone shape (quick scene;
    its reference tip is known only to 0.6 %, so 0.3 % on the tip cannot be checked): the models they
    get, and the time of the network's simulation (0.3 s at 1 ms) against the all-fine network (both bodies at
    0.3 %), wall (perf_counter) and CPU (process_time) as medians of 5 runs each, on the compiled path (the
    identified polynomial actuators lowered, soroshapes.network) and on the Python path (``compiled=False``,
    the path of every such network before). Asserted: the two paths give the same trajectory (to the Newton
    tolerance), the bodies get different models; never a time."""
    import time

    import numpy as np

    from soro.ladder import beam_within
    from soroshapes import Model
    from soroshapes.network import Schedule

    def body(tol):
        return beam_within("pneunet2d", tol, "shape", out=tmp_path, quick=True)

    def network(a, b):
        mdl = Model().add(a, "left").add(b, "right")
        t = [0.0, 0.05, 0.3]
        return mdl.set_controller(Schedule(t, {"left": [[0.0], [4e3], [4e3]], "right": [[0.0], [4e3], [4e3]]}))

    (loose, fl), (tight, ft) = body("1%"), body("0.3%")
    times, cpu, paths, finals = {}, {}, {}, {}
    for name, (a, b) in {"mixed": (loose, tight), "all_fine": (body("0.3%")[0], body("0.3%")[0])}.items():
        mdl = network(a, b)
        for compiled in (None, False):
            key = f"{name}/{'compiled' if compiled is None else 'python'}"
            tr = mdl.simulate(0.3, 1e-3, compiled=compiled)          # warm-up (compilation)
            finals[key] = np.asarray(tr.x[-1])
            ts, cs = [], []
            for _ in range(5):
                t0, c0 = time.perf_counter(), time.process_time()
                mdl.simulate(0.3, 1e-3, compiled=compiled)
                ts.append(time.perf_counter() - t0)
                cs.append(time.process_time() - c0)
            times[key], cpu[key] = float(np.median(ts)), float(np.median(cs))
        paths[name] = mdl.evaluation_path
    for name in ("mixed", "all_fine"):
        a, b = finals[f"{name}/compiled"], finals[f"{name}/python"]
        assert np.allclose(a, b, rtol=1e-6, atol=1e-8 * max(1.0, np.abs(b).max())), (name, a, b)
    assert (fl.meta["family"], fl.meta["modes"]) != (ft.meta["family"], ft.meta["modes"])
    speed = {"wall_all_fine_python_over_mixed_compiled": times["all_fine/python"] / times["mixed/compiled"],
             "wall_all_fine_compiled_over_mixed_compiled": times["all_fine/compiled"] / times["mixed/compiled"],
             "cpu_all_fine_python_over_mixed_compiled": cpu["all_fine/python"] / cpu["mixed/compiled"],
             "cpu_all_fine_compiled_over_mixed_compiled": cpu["all_fine/compiled"] / cpu["mixed/compiled"]}
    print("\nnetwork by tolerance:", fl.meta["family"], fl.meta["modes"], "/", ft.meta["family"], ft.meta["modes"],
          "\npaths", paths, "\nwall s", times, "\ncpu s", cpu, "\n", speed)
    record(loose=fl.meta, tight=ft.meta, times_s=times, cpu_s=cpu, paths=paths, **speed)


def test_bench_ladder_pneunet3d(record):
    """The 3D PneuNet's ladder (`soro trade pneunet3d --tol 1%` and `--tol 0.1%`): 3D P1/P2/P2 mixed on h = 2.83,
    2, 1.41 mm (ratio sqrt 2), the plane-strain rung, beams on the 3D reference's snapshots; the FEM part is cached
    and resumable in out/ladder/pneunet3d (about 10 min of CPU the first time; the beams are re-measured on each
    run). Recorded: the rows, Richardson, the budget (with the plane-strain model-form error), both verdicts, and
    the ratio of the reference's CPU time per ramp to the selected model's. Asserted: consistency, never a time."""
    from pathlib import Path

    from soro.ladder import run_ladder

    out = Path("out") / "ladder" / "pneunet3d"
    status, verdicts = {}, {}
    for tol in ("1%", "0.1%"):
        status[tol] = run_ladder("pneunet3d", tolerance=tol, measure="tip", out=out)
        verdicts[tol] = json.loads((out / "ladder.json").read_text())
    print("\n" + (out / "ladder.txt").read_text())
    rep = verdicts["1%"]
    rows = rep["rows"]
    ref = next(r for r in rows if r.get("estimated"))
    assert status["1%"] == 0 and rep["validation_error"] <= 0.01 and len(rows) >= 10
    sel = next(r for r in rows if (r["family"], r["modes"]) == (rep["selected"]["family"], rep["selected"]["modes"]))
    record(**_finite(dict(status=status, richardson=rep["richardson"], budget=rep["budget"], verdict_1=rep["verdict"],
                          verdict_0p1=verdicts["0.1%"]["verdict"],
                          reference_over_selected=ref["solve_time_s"] / sel["solve_time_s"], rows=rows)))


def _finite(obj):
    """``obj`` (nested dicts/lists) with NaN and infinities as None: a Richardson order that is not defined (the
    3D reference does not converge monotonically), the spread of a FEM rung timed once."""
    import math

    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return None if isinstance(obj, float) and not math.isfinite(obj) else obj
