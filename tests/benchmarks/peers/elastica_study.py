"""Convergence and speed of the PyElastica peer on the benchmark rod (cases in ``elastica_cases.py``).

Each run is one subprocess of the peer venv's python (built once by :func:`ensure_elastica_venv`) printing one
JSON line. :func:`elastica_convergence` runs a case at several element counts and adds the tip error against
the finest run and against the inextensible, unshearable elastica (``tests/analytic.py``); the difference
between the finest run and that reference is PyElastica's extension and shear, not a discretisation error.

Stability of PositionVerlet for this rod (undamped gravity release, 1 s; the first unstable dt in brackets):
n = 5: 2.7e-4 s (3e-4), n = 10: 2.4e-4 (2.7e-4), n = 20: 2.0e-4 (2.1e-4), n = 40: 1.25e-4 (1.5e-4),
n = 80: 6.25e-5 (7.5e-5), n = 160: 3.75e-5 (4.4e-5); i.e. about min(0.03 L/n, 2.5e-4 s): the axial wave
(dx / sqrt(E/rho) = 0.032 dx) on fine rods, the shear/rotation mode of an element on coarse ones. The static
cases use dt = min(0.02 L/n, 1.5e-4 s) (``elastica_cases.DT_FACTOR``, ``DT_CAP``; 0.015 L/n above 320
elements, where 0.02 L/n blows up), the real-time case the largest stable dt at n = 20,
``REALTIME_DT = 2e-4 s``.

PyElastica's tip converges at first order in 1/n here (ratio 2.0 per doubling from n = 40 to 640), so the
finest run of a study is not a converged reference: use the Richardson extrapolation
(``err_vs_extrapolated``). Measured limits (n = 320, 640 extrapolated), tip (dx, dz) in m: gravity
(-0.083237, -0.150832), tip load (-0.050959, -0.120850); the inextensible elastica is 4.6e-4 m (0.27 %) and
2.1e-4 m (0.16 %) away from them: PyElastica's extension and shear.

Run ``python tests/benchmarks/peers/elastica_study.py`` (any python with numpy and scipy; the project venv
is fine, the peer runs in its own) for the table.
"""
import importlib.util
import json
import math
import subprocess
import time
from pathlib import Path

try:
    from .elastica_venv import ensure_elastica_venv
except ImportError:  # run as a script
    from elastica_venv import ensure_elastica_venv

__all__ = ["elastica_run", "elastica_convergence", "elastica_realtime", "elastica_stable_dt",
           "inextensible_reference", "ROD", "REALTIME_DT"]

HERE = Path(__file__).resolve().parent
CASES = HERE / "elastica_cases.py"
TESTS = HERE.parents[1]

#: The benchmark rod (SI), the same defaults as ``elastica_cases.DEFAULTS``.
ROD = {"length": 0.2, "radius": 5e-3, "youngs_modulus": 1e6, "poisson": 0.5, "density": 1000.0,
       "gravity": 9.81, "load_factor": 3.0}
#: Largest stable PositionVerlet step at n = 20 (2.1e-4 s blows up within 1 s of undamped dynamics).
REALTIME_DT = 2e-4


def elastica_run(case, n_elements=20, timeout=900, **params):
    """Run one case of ``elastica_cases.py`` in the peer venv and return its JSON result as a dict.

    ``params`` are passed through (``dt``, ``damping``, ``v_tol``, ``t_max``, ``final_time``, ...). Raises
    ``RuntimeError`` with the tail of stderr if the peer fails.
    """
    python = ensure_elastica_venv()
    arg = json.dumps({"case": case, "n_elements": int(n_elements), **params})
    proc = subprocess.run([str(python), str(CASES), arg], capture_output=True, text=True, timeout=timeout,
                          cwd=str(HERE))
    if proc.returncode != 0:
        tail = "\n".join(proc.stderr.strip().splitlines()[-20:])
        raise RuntimeError(f"PyElastica case {arg} failed (exit {proc.returncode}):\n{tail}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _analytic():
    try:
        import analytic
    except ImportError:
        spec = importlib.util.spec_from_file_location("analytic", TESTS / "analytic.py")
        analytic = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(analytic)
    return analytic


def inextensible_reference(case, rod=ROD):
    """Tip displacement (dx, dz) [m] of the inextensible, unshearable elastica for ``case`` ('gravity' or
    'tip_load'), in the peer's frame (rod along +x, load along -z)."""
    a = _analytic()
    L, r, E = rod["length"], rod["radius"], rod["youngs_modulus"]
    EI = E * math.pi * r**4 / 4
    if case == "gravity":
        return a.elastica_gravity_tip(L, EI, rod["density"] * math.pi * r * r * rod["gravity"])
    if case == "tip_load":
        return a.elastica_tip(L, EI, rod["load_factor"] * EI / L**2)
    raise ValueError(f"no static reference for case {case!r}: expected 'gravity' or 'tip_load'")


def elastica_convergence(case, n_list=(5, 10, 20, 40, 80, 160), repeat=1, **params):
    """Static ``case`` ('gravity' or 'tip_load') at each element count of ``n_list``.

    Returns one dict per run, by increasing n: the peer's result (``tip_dx``, ``tip_dz``, ``wall_s``,
    ``steps``, ``dt``, ``converged``, ...; ``wall_s`` the best of ``repeat`` processes, all in ``all_wall_s``)
    plus the tip errors [m] and the same over the magnitude of the reference tip displacement (``rel_*``)
    against three references:

    ``err_vs_finest``
        the run with the largest n (a lower bound on the error: PyElastica converges at first order);
    ``err_vs_extrapolated``
        the Richardson extrapolation of the three finest runs (they must have one refinement ratio; the
        observed order, ``observed_order``, is used, 1.0 measured); its tip is ``extrapolated_dx/dz``;
    ``err_vs_inextensible``
        the inextensible, unshearable elastica (:func:`inextensible_reference`), ``inextensible_dx/dz``.
    """
    runs = []
    for n in sorted(n_list):
        tries = [elastica_run(case, n, **params) for _ in range(repeat)]
        best = min(tries, key=lambda r: r["wall_s"])
        best["all_wall_s"] = [r["wall_s"] for r in tries]
        runs.append(best)
    refs = {"finest": (runs[-1]["tip_dx"], runs[-1]["tip_dz"]), "inextensible": inextensible_reference(case)}
    order = _observed_order(runs)
    if order is not None:
        ratio = runs[-1]["n_elements"] / runs[-2]["n_elements"]
        refs["extrapolated"] = tuple(runs[-1][k] + (runs[-1][k] - runs[-2][k]) / (ratio**order - 1)
                                     for k in ("tip_dx", "tip_dz"))
    for r in runs:
        r["observed_order"] = order
        for name, (rx, rz) in refs.items():
            err = math.hypot(r["tip_dx"] - rx, r["tip_dz"] - rz)
            r[f"err_vs_{name}"] = err
            r[f"rel_err_vs_{name}"] = err / math.hypot(rx, rz)
            if name != "finest":
                r[f"{name}_dx"], r[f"{name}_dz"] = rx, rz
    return runs


def _observed_order(runs):
    """Convergence order of the tip from the three finest runs, if they share one refinement ratio."""
    if len(runs) < 3:
        return None
    n0, n1, n2 = (r["n_elements"] for r in runs[-3:])
    if not math.isclose(n1 / n0, n2 / n1):
        return None
    d01 = math.hypot(*(runs[-2][k] - runs[-3][k] for k in ("tip_dx", "tip_dz")))
    d12 = math.hypot(*(runs[-1][k] - runs[-2][k] for k in ("tip_dx", "tip_dz")))
    if d01 == 0 or d12 == 0:
        return None
    return math.log(d01 / d12) / math.log(n1 / n0)


def elastica_realtime(n_elements=20, dt=REALTIME_DT, final_time=1.0, repeat=3, **params):
    """The gravity rod simulated for ``final_time`` [s] at ``dt``, best wall time of ``repeat`` runs (each in
    its own process); the result carries ``rtf = final_time / wall_s`` and ``all_wall_s``."""
    runs = [elastica_run("realtime", n_elements, dt=dt, final_time=final_time, **params) for _ in range(repeat)]
    best = min(runs, key=lambda r: r["wall_s"])
    best["all_wall_s"] = [r["wall_s"] for r in runs]
    return best


def elastica_stable_dt(n_elements, dts, final_time=1.0):
    """The largest of ``dts`` [s] for which undamped PositionVerlet stays bounded over ``final_time`` (the
    gravity release), scanning upward and stopping at the first failure; ``None`` if the smallest fails."""
    ok = None
    for dt in sorted(dts):
        if not elastica_run("realtime", n_elements, dt=dt, final_time=final_time)["stable"]:
            break
        ok = dt
    return ok


def _table(case, runs):
    r0 = runs[0]
    lines = [f"{case}: inextensible elastica tip (dx, dz) = "
             f"({r0['inextensible_dx']:.6f}, {r0['inextensible_dz']:.6f}) m"]
    if "extrapolated_dx" in r0:
        lines.append(f"{case}: extrapolated PyElastica tip = ({r0['extrapolated_dx']:.6f}, "
                     f"{r0['extrapolated_dz']:.6f}) m (observed order {r0['observed_order']:.2f})")
    lines.append(f"{'n':>5} {'dt [s]':>9} {'steps':>7} {'t_sim':>6} {'conv':>5} {'tip dx [m]':>11} {'tip dz [m]':>11} "
                 f"{'e/finest':>9} {'e/extrap':>9} {'e/inext':>9} {'wall [s]':>8} {'us/step':>7}")
    for r in runs:
        lines.append(f"{r['n_elements']:>5} {r['dt']:>9.3g} {r['steps']:>7} {r['sim_time']:>6.2f} "
                     f"{str(r['converged']):>5} {r['tip_dx']:>11.6f} {r['tip_dz']:>11.6f} "
                     f"{r['rel_err_vs_finest']:>9.2e} {r.get('rel_err_vs_extrapolated', math.nan):>9.2e} "
                     f"{r['rel_err_vs_inextensible']:>9.2e} {r['wall_s']:>8.3f} {r['us_per_step']:>7.1f}")
    return "\n".join(lines)


if __name__ == "__main__":
    t0 = time.perf_counter()
    print(f"peer python: {ensure_elastica_venv()}  ({time.perf_counter() - t0:.1f} s)")
    for case in ("gravity", "tip_load"):
        print(_table(case, elastica_convergence(case, repeat=2)), flush=True)
    rt = elastica_realtime()
    print(f"realtime: n=20, dt={rt['dt']:g} s, {rt['steps']} steps for {rt['sim_time']:.3f} s: wall "
          f"{rt['wall_s']:.3f} s (runs {', '.join(f'{w:.3f}' for w in rt['all_wall_s'])}), "
          f"real-time factor {rt['sim_time'] / rt['wall_s']:.1f}, stable={rt['stable']}")
    print(f"total {time.perf_counter() - t0:.0f} s")
