"""Our Cosserat beam side by side with its peers, PyElastica and MuJoCo (``make bench``), one core.

The rod of every case is ``peers/elastica_cases.py``'s: ``L = 0.2 m``, ``r = 5 mm``, ``E = 1 MPa``,
``1000 kg/m^3``, clamped, loaded along ``-z`` (its own weight, or a dead tip force with ``P L^2 / EI = 3``).

Statics: for each tolerance on the tip position (5 %, 2 %, 1 %, 0.5 %, 0.1 % of the tip displacement), the
cheapest run of each code that meets it against a converged reference, and the time ratio. Our time is
building the model plus solving (``statics``); a peer's is its stepping to rest (neither has a static solver).

- PyElastica (its own venv, ``peers/elastica_venv.py``): extensible and shearable; reference the Richardson
  extrapolation of its own finest runs; ours the same extensible, shearable rod.
- MuJoCo (``pip install -e '.[peers]'``; ``peers/mujoco_study.py``): a chain of rigid links with elastic hinges,
  inextensible and unshearable; reference the Richardson extrapolation (order 2) of its two finest chains,
  checked against our converged Kirchhoff rod (bending only), which is what ours runs too.

Dynamics at matched accuracy (PyElastica and MuJoCo): the rod released straight under gravity, undamped, 0.5 s;
error the largest tip distance over the run from a reference (our converged rod at a small step: extensible and
shearable against PyElastica, bending only against MuJoCo) over L; for each tolerance the cheapest run of each
code (element count at PositionVerlet's stable step for PyElastica, chain length and step at its stability bound
for MuJoCo; modes and step for ours) and the time ratio. PyElastica's real-time factor at 20 elements is reported
as well.

If MuJoCo is not installed, its test reports that and is skipped; a tolerance a code never reaches is
reported as ``None``. Asserted: that the codes model the same rod (their converged tips agree), never a time.
"""
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from sorofem import materials, sdf  # noqa: E402
from soroshapes import Basis, Shapes  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROD = {"length": 0.2, "radius": 5e-3, "E": 1e6, "density": 1000.0, "g": 9.81}
TOLERANCES = (0.05, 0.02, 0.01, 0.005, 0.001)
#: our discretizations tried in statics: (modes, segments, Magnus order)
CANDIDATES = ((1, 10, 2), (2, 10, 2), (3, 10, 2), (4, 10, 2), (4, 10, 4), (6, 10, 4), (6, 20, 4), (8, 20, 4))
EI = ROD["E"] * np.pi * ROD["radius"] ** 4 / 4


def _rod(k, extensible, segments=10, order=2):
    """Our model of the peers' rod: bending about y (and, for PyElastica's rod, stretch and shear z with the
    shear stiffness (27/28) G A, G = E/3 as PyElastica's)."""
    E = ROD["E"]
    dofs = (0, k, 0, k, 0, k) if extensible else (0, k, 0, 0, 0, 0)
    return Shapes(Basis.chebyshev(k), dofs=dofs, length=ROD["length"], section=sdf.Circle(ROD["radius"]),
                  material=materials.NeoHookean(E=E, nu=0.45, density=ROD["density"]), E=E, G=27 / 28 * E / 3,
                  damping=0.0, segments=segments, order=order)


def _ours_static(case, k, segments=10, order=2, extensible=True):
    t0 = time.perf_counter()
    shp = _rod(k, extensible, segments, order)
    if case == "gravity":
        shp.add_gravity((0.0, 0.0, -ROD["g"]))
    else:
        shp.add_point_load(force=[0.0, 0.0, -3 * EI / ROD["length"] ** 2])
    build = time.perf_counter() - t0
    shp.statics()
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        q = shp.statics()
        best = min(best, time.perf_counter() - t0)
    tip = shp.positions(q)[-1]
    return {"modes": f"{k} modes, {segments} segments of order {order}", "tip_dx": tip[0] - ROD["length"], "tip_dz": tip[2], "solve_s": best, "build_s": build,
            "total_s": best + build}


def _cheapest(runs, err_key, time_key, tol):
    ok = [r for r in runs if r[err_key] <= tol]
    return min(ok, key=lambda r: r[time_key]) if ok else None


def _rel_err(runs, ref):
    for r in runs:
        r["rel_err"] = float(np.hypot(r["tip_dx"] - ref[0], r["tip_dz"] - ref[1]) / np.linalg.norm(ref))


def _table(name, peer, peer_size, peer_time, ours):
    rows = []
    for tol in TOLERANCES:
        p = _cheapest(peer, "rel_err", peer_time, tol)
        o = _cheapest(ours, "rel_err", "total_s", tol)
        rows.append({"tol": tol, f"{name}_size": p and p[peer_size], f"{name}_s": p and p[peer_time],
                     "ours_modes": o and o["modes"], "ours_s": o and o["total_s"],
                     "speedup": (p[peer_time] / o["total_s"]) if p and o else None})
    return rows


def _print(title, name, rows):
    print(f"\n{title}: tolerance | {name} size, s | ours modes, s (build + solve) | speedup")
    for row in rows:
        o = "-" if row["ours_s"] is None else f"{row['ours_modes']}, {row['ours_s']:.2e}"
        p = "not reached" if row[f"{name}_s"] is None else f"{row[f'{name}_size']}, {row[f'{name}_s']:.3g}"
        sp = "-" if row["speedup"] is None else f"{row['speedup']:.2g}x"
        print(f"  {row['tol']:.3f} | {p} | {o} | {sp}")


def test_bench_against_pyelastica(record):
    from peers.elastica_study import elastica_convergence, elastica_realtime

    table = {}
    for case in ("gravity", "tip_load"):
        peer = elastica_convergence(case, n_list=(5, 10, 20, 40, 80, 160))
        assert all(r["converged"] for r in peer)
        ref = np.array([peer[-1]["extrapolated_dx"], peer[-1]["extrapolated_dz"]])   # converged reference
        for r in peer:
            r["rel_err"] = r["rel_err_vs_extrapolated"]
        ours = [_ours_static(case, *c) for c in CANDIDATES]
        _rel_err(ours, ref)
        # the two models converge to the same rod up to PyElastica's dilatation-scaled couples (< 0.1 %)
        assert ours[-1]["rel_err"] < 1e-3
        table[case] = _table("pyelastica", peer, "n_elements", "wall_s", ours)
        _print(f"PyElastica, {case}", "pyelastica", table[case])
    # real time: the same rod released under gravity, undamped
    peer_rt = elastica_realtime(n_elements=20)
    shp = _rod(3, True).add_gravity((0.0, 0.0, -ROD["g"]))
    shp.simulate(0.01, 1e-3)
    t0 = time.perf_counter()
    tr = shp.simulate(1.0, 1e-3, record_every=100)
    ours_rtf = 1.0 / (time.perf_counter() - t0)
    assert np.all(np.isfinite(tr.q))
    record(table=table, pyelastica_rtf_20_elements=peer_rt["rtf"], pyelastica_dt=peer_rt["dt"],
           ours_rtf_9_dof=round(ours_rtf, 1), ours_dt=1e-3,
           met=all(r["speedup"] is None or r["speedup"] >= 10 for rows in table.values() for r in rows))


def _mujoco():
    from peers.mujoco_study import available
    ok, what = available()
    if not ok:
        print(f"\nMuJoCo is not installed or does not load ({what}): pip install -e '.[peers]'; "
              "no MuJoCo comparison in this run")
        pytest.skip(f"MuJoCo unavailable: {what}")
    return what


def test_bench_statics_against_mujoco(record):
    version = _mujoco()
    from peers.mujoco_study import static_tip
    table, checks = {}, {}
    for case in ("gravity", "tip_load"):
        peer = []
        for n in (5, 10, 20, 40, 80):
            runs = [static_tip(case, n, beta=b) for b in (0.1, 0.2)]      # the faster-settling damping
            runs = [r for r in runs if r["converged"]]
            assert runs, f"MuJoCo chain of {n} links did not come to rest ({case})"
            peer.append(min(runs, key=lambda r: r["wall_s"]))
        a, b = peer[-2], peer[-1]                                      # n = 40, 80: order-2 extrapolation
        ref = np.array([b["tip_dx"] + (b["tip_dx"] - a["tip_dx"]) / 3, b["tip_dz"] + (b["tip_dz"] - a["tip_dz"]) / 3])
        _rel_err(peer, ref)
        ours = [_ours_static(case, k, segments, order, extensible=False) for k, segments, order in CANDIDATES]
        _rel_err(ours, ref)
        conv = _ours_static(case, 8, 40, 4, extensible=False)
        _rel_err([conv], ref)
        checks[case] = conv["rel_err"]
        # the chain and our rod converge to the same elastica (the extrapolation's own error is ~1e-5)
        assert conv["rel_err"] < 2e-4, (case, conv)
        table[case] = _table("mujoco", peer, "n_links", "wall_s", ours)
        _print(f"MuJoCo {version}, {case}", "mujoco", table[case])
    record(mujoco=version, table=table, converged_rod_vs_chain_extrapolation=checks,
           met=all(r["speedup"] is None or r["speedup"] >= 10 for rows in table.values() for r in rows))


#: our discretizations tried in dynamics: (modes, segments, Magnus order, dt [s])
DYN_CANDIDATES = ((3, 10, 2, 1e-3), (4, 10, 2, 1e-3), (4, 10, 4, 1e-3), (4, 10, 4, 5e-4), (6, 10, 4, 5e-4),
                  (6, 10, 4, 2.5e-4), (6, 20, 4, 2.5e-4))
#: tolerances on the largest tip distance from the reference over the run, over L
DYN_TOLERANCES = (0.1, 0.05, 0.02, 0.01)


def _release_reference(extensible, t_end, every):
    """Tip (x, z) [m] every ``every`` s of our converged rod (8 modes, 40 segments of order 4, dt 0.1 ms)
    released straight under gravity, undamped."""
    shp = _rod(8, extensible, segments=40, order=4).add_gravity((0.0, 0.0, -ROD["g"]))
    return shp.simulate(t_end, 1e-4, record_every=int(round(every / 1e-4))).tip[:, [0, 2]]


def _release_error(ref):
    """The error of a tip history (x, z) against ``ref``: the largest distance over the common records, over L."""
    def err(tip):
        tip = np.asarray(tip, dtype=float)
        m = min(len(tip), len(ref))
        return float(np.max(np.linalg.norm(tip[:m] - ref[:m], axis=1)) / ROD["length"])
    return err


def _ours_release(extensible, t_end, every, err):
    """Each of :data:`DYN_CANDIDATES` released under gravity: its best wall time of 3 (after a warm-up) and error."""
    ours = []
    for k, segments, order, dt in DYN_CANDIDATES:
        shp = _rod(k, extensible, segments, order).add_gravity((0.0, 0.0, -ROD["g"]))
        shp.simulate(0.01, dt)
        rec = int(round(every / dt))
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            tr = shp.simulate(t_end, dt, record_every=rec)
            best = min(best, time.perf_counter() - t0)
        ours.append({"modes": f"{k} modes, {segments}x{order}, dt {dt:g}", "total_s": best,
                     "rel_err": err(tr.tip[:, [0, 2]])})
    return ours


def _dynamics_rows(name, peer, ours):
    rows = []
    for tol in DYN_TOLERANCES:
        p = _cheapest(peer, "rel_err", "wall_s", tol)
        o = _cheapest(ours, "rel_err", "total_s", tol)
        rows.append({"tol": tol, f"{name}_size": p and p["size"], f"{name}_s": p and p["wall_s"],
                     "ours_modes": o and o["modes"], "ours_s": o and o["total_s"],
                     "speedup": (p["wall_s"] / o["total_s"]) if p and o else None})
    return rows


def _dynamics_report(peer_name, title, peer, ours, peer_tol):
    """Print the runs and the matched-accuracy table of a dynamics comparison and return its rows; the codes
    model the same rod, so the finest run of each must follow the reference closely (ours within 5 %, the
    peer within ``peer_tol``)."""
    for r in peer + ours:
        print(r)
    rows = _dynamics_rows(peer_name, peer, ours)
    _print(f"{title} (largest tip error / L)", peer_name, rows)
    assert min(r["rel_err"] for r in ours) < 0.05 and min(r["rel_err"] for r in peer) < peer_tol
    return rows


def test_bench_dynamics_against_pyelastica(record):
    """The extensible, shearable rod released straight under gravity, undamped, 0.5 s: PyElastica (PositionVerlet
    at the largest stable step of each element count, elastica_study.py) against ours at matched accuracy, the
    error against our converged extensible rod; PyElastica's time is its stepping loop, ours the simulate call."""
    from peers.elastica_study import elastica_run
    t_end, every = 0.5, 0.01
    err = _release_error(_release_reference(True, t_end, every))
    peer = []
    # PyElastica's tip converges at first order in 1/n (the error halves per doubling: 2 % needs 160 elements)
    for n, dt in ((5, 2e-4), (10, 2e-4), (20, 2e-4), (40, 1.25e-4), (80, 6.25e-5), (160, 3.125e-5)):
        r = elastica_run("realtime", n, dt=dt, final_time=t_end, record_every=int(round(every / dt)))
        if r["stable"]:
            peer.append({"size": f"{n} elements, dt {dt:.3g}", "wall_s": r["wall_s"],
                         "rel_err": err(r["tip_history"])})
    ours = _ours_release(True, t_end, every, err)
    rows = _dynamics_report("pyelastica", f"PyElastica, dynamics over {t_end} s", peer, ours, 0.05)
    record(simulated_s=t_end, table=rows, pyelastica_runs=peer, ours_runs=ours,
           met=all(r["speedup"] is None or r["speedup"] >= 1 for r in rows))


def test_bench_dynamics_against_mujoco(record):
    version = _mujoco()
    from peers.mujoco_study import _omega_max, release_tip
    t_end, every = 0.5, 0.01
    err = _release_error(_release_reference(False, t_end, every))
    peer = []
    for n in (5, 10, 20, 40):
        for factor in (0.5, 0.25, 0.125):            # of 2 / omega_max: the largest step that stays bounded
            dt = factor * 2.0 / _omega_max(n)
            dt = every / int(np.ceil(every / dt))     # a whole number of steps per record
            r = release_tip(n, dt, t_end, every)
            if r["stable"]:
                peer.append({"size": f"{n} links, dt {dt:.2g}", "wall_s": r["wall_s"], "rel_err": err(r["tip"])})
                break
    ours = _ours_release(False, t_end, every, err)
    rows = _dynamics_report("mujoco", f"MuJoCo {version}, dynamics over {t_end} s", peer, ours, 0.1)
    record(mujoco=version, simulated_s=t_end, table=rows,
           mujoco_runs=[{k: v for k, v in r.items()} for r in peer],
           ours_runs=ours, met=all(r["speedup"] is None or r["speedup"] >= 1 for r in rows))
