"""PyElastica (1.0.0) side of the Cosserat-rod benchmarks: one case per call, JSON in, one JSON line out.

Run by the peer venv's python (see ``elastica_venv.py``); it imports nothing from this repository::

    python elastica_cases.py '{"case": "gravity", "n_elements": 20}'

The rod (all cases): length ``L = 0.2 m``, solid circular section of radius ``r = 5 mm``
(``A = pi r^2``, ``I = pi r^4 / 4``), ``E = 1 MPa``, shear modulus ``G = E / 3`` (Poisson 0.5), density
``1000 kg/m^3``. It starts straight along ``+x`` from the origin with its normal along ``+z``; node 0 and
element 0 are clamped (``OneEndFixedBC``: position of the first node, directors of the first element).
Loads act along ``-z``:

``gravity``
    Own weight, ``g = 9.81 m/s^2`` along ``-z`` on the nodal masses (a distributed load
    ``w = rho A g = 0.7705 N/m``, ``w L^3 / EI = 12.6``: a large deflection).
``tip_load``
    No gravity; a dead force ``P`` along ``-z`` on the last node with ``P L^2 / EI = 3`` (``load_factor``),
    ramped linearly over ``ramp_s = 0.05 s`` (PyElastica's ``EndpointForces`` needs a ramp > 0).
``realtime``
    The gravity rod released from straight and simulated for ``final_time = 1 s`` of dynamics at a fixed
    ``dt``, undamped unless ``damping`` is given; reports the real-time factor ``final_time / wall_s``. With
    ``record_every`` = k > 0 it also returns ``tip_history``, the tip's (x, z) [m] at t = 0 and every k steps
    (the dynamics comparison at matched trajectory accuracy; the copies cost well under 1 % of a step).

The two static cases are solved by damped dynamics to steady state: PyElastica's ``AnalyticalLinearDamper``
with a uniform damping constant ``damping`` [1/s] (``v <- v exp(-damping dt)``, the same on the angular
velocities) and ``PositionVerlet``; the run stops when the largest nodal speed is below ``v_tol``
(default ``1e-6 m/s``, checked every ``check_every`` steps after the load ramp) or at ``t_max``. The damping
changes the path, not the equilibrium.

Time step: the explicit scheme is bounded by the axial wave on fine rods (``dx / sqrt(E / rho)``) and by
the shear/rotation mode of an element on coarse ones, so the default is ``dt = dt_factor * L / n_elements``
with ``dt_factor`` chosen empirically and capped (see ``DT_FACTOR``, ``DT_CAP``). A run that blows up stops
with ``"stable": false`` (a static run also with ``"converged": false``).

Timing: ``wall_s`` is the stepping loop only (including the convergence checks); ``setup_s`` is building the
rod and simulator, plus a warm-up of a few steps on a throw-away simulator of the same size that loads or
compiles numba's kernels (``warmup_s``); ``import_s`` is ``import elastica``.

numpy and elastica are imported by :func:`main` only, so that importing this file (pytest's doctest
collection does, from the project's venv, which has no elastica) costs and requires nothing.
"""
import json
import math
import sys
import time

np = ea = None  # imported by _import_peer()
IMPORT_S = None

#: Defaults of every case; any key may be overridden in the JSON argument.
DEFAULTS = {
    "n_elements": 20,
    "length": 0.2,            # m
    "radius": 5e-3,           # m
    "youngs_modulus": 1e6,    # Pa
    "poisson": 0.5,           # G = E / (2 (1 + nu))
    "density": 1000.0,        # kg/m^3
    "gravity": 9.81,          # m/s^2
    "load_factor": 3.0,       # P L^2 / EI for tip_load
    "ramp_s": 0.05,           # s, tip-load ramp
    "damping": None,          # 1/s, uniform damping constant (case default below)
    "dt": None,               # s (default dt_factor * L / n, capped at DT_CAP)
    "dt_factor": None,        # s/m
    "v_tol": 1e-6,            # m/s
    "t_max": 20.0,            # s, cap on simulated time for the static cases
    "check_every": 50,        # steps between convergence checks
    "final_time": 1.0,        # s, realtime case
    "record_every": 0,        # steps between recorded tip positions in the realtime case (0: none)
    "warmup": True,
}

#: dt = min(DT_FACTOR * dx, DT_CAP), DT_FACTOR_FINE * dx above FINE_N elements. Undamped PositionVerlet
#: blows up for this rod at about min(0.03 dx, 2.5e-4 s) up to n = 160 (the axial wave on fine rods, the
#: element shear/rotation mode on coarse ones; measurements in elastica_study.py): a margin of 1.3 to 1.8.
#: 0.02 dx still settles at n = 320 but blows up at n = 640 (damped gravity, after ~3 s), where 0.015 dx holds.
DT_FACTOR = 0.02
DT_CAP = 1.5e-4
DT_FACTOR_FINE = 0.015
FINE_N = 320
#: Damping constant [1/s] for the static cases: the fastest settling of 5, 10, 15, 20, 25, 30, 40, 80 at n = 20
#: (gravity 20: 1.47 s simulated, tip_load 15: 1.60 s; 10 or 30 take 2 to 3 s).
DAMPING = {"gravity": 20.0, "tip_load": 15.0}


def _import_peer():
    global np, ea, IMPORT_S
    t0 = time.perf_counter()
    import numpy
    import elastica
    import elastica.version
    np, ea = numpy, elastica
    IMPORT_S = time.perf_counter() - t0


def _section(p):
    r = p["radius"]
    area = math.pi * r * r
    inertia = math.pi * r**4 / 4
    return area, inertia


def build(p, case, dt, damping):
    """The simulator, the rod and the stepper of ``case`` (nothing stepped yet)."""
    class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    sim = Simulator()
    E = p["youngs_modulus"]
    rod = ea.CosseratRod.straight_rod(
        int(p["n_elements"]), np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]),
        p["length"], p["radius"], p["density"], youngs_modulus=E, shear_modulus=E / (2 * (1 + p["poisson"])))
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    if case in ("gravity", "realtime"):
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -p["gravity"]]))
    elif case == "tip_load":
        area, inertia = _section(p)
        P = p["load_factor"] * E * inertia / p["length"] ** 2
        sim.add_forcing_to(rod).using(ea.EndpointForces, start_force=np.zeros(3),
                                      end_force=np.array([0.0, 0.0, -P]), ramp_up_time=p["ramp_s"])
    else:
        raise ValueError(f"unknown case {case!r}: expected 'gravity', 'tip_load' or 'realtime'")
    if damping:
        sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping, time_step=dt)
    sim.finalize()
    return sim, rod, ea.PositionVerlet()


def _finite(rod):
    return bool(np.isfinite(rod.position_collection).all() and np.isfinite(rod.velocity_collection).all())


def run(p):
    case = p["case"]
    n = int(p["n_elements"])
    if n < 4:
        raise ValueError("n_elements must be >= 4 (PyElastica's minimum is 3 elements, we ask for 4)")
    dx = p["length"] / n
    dt = p["dt"] or min(DT_CAP, (p["dt_factor"] or (DT_FACTOR if n <= FINE_N else DT_FACTOR_FINE)) * dx)
    damping = p["damping"] if p["damping"] is not None else DAMPING.get(case, 0.0)

    t0 = time.perf_counter()
    warmup_s = 0.0
    if p["warmup"]:
        tw = time.perf_counter()
        wsim, _, wstep = build(p, case, dt, damping)
        tt = 0.0
        for _ in range(3):
            tt = wstep.step(wsim, tt, dt)
        warmup_s = time.perf_counter() - tw
    sim, rod, stepper = build(p, case, dt, damping)
    setup_s = time.perf_counter() - t0

    t = np.float64(0.0)
    steps = 0
    converged = False
    stable = True
    if case == "realtime":
        n_steps = int(round(p["final_time"] / dt))
        every = int(p["record_every"])
        history = [[float(rod.position_collection[0, -1]), float(rod.position_collection[2, -1])]]
        tw = time.perf_counter()
        for k in range(n_steps):
            t = stepper.step(sim, t, dt)
            if every and (k + 1) % every == 0:
                history.append([float(rod.position_collection[0, -1]), float(rod.position_collection[2, -1])])
        wall_s = time.perf_counter() - tw
        steps = n_steps
        stable = _finite(rod) and float(np.abs(rod.position_collection).max()) < 2 * p["length"]
    else:
        check = int(p["check_every"])
        t_min = p["ramp_s"] if case == "tip_load" else 0.0
        max_steps = int(math.ceil(p["t_max"] / dt))
        tw = time.perf_counter()
        while steps < max_steps:
            for _ in range(check):
                t = stepper.step(sim, t, dt)
            steps += check
            vmax = float(np.sqrt((rod.velocity_collection**2).sum(axis=0)).max())
            if not math.isfinite(vmax) or vmax > 1e3:
                stable = False
                break
            if t >= t_min and vmax < p["v_tol"]:
                converged = True
                break
        wall_s = time.perf_counter() - tw
        stable = stable and _finite(rod)

    tip = rod.position_collection[:, -1]
    speed = np.sqrt((rod.velocity_collection**2).sum(axis=0))
    omega = np.sqrt((rod.omega_collection**2).sum(axis=0))
    area, inertia = _section(p)
    out = {
        "case": case, "n_elements": n, "dt": dt, "steps": steps, "sim_time": float(t),
        "damping": damping, "stable": stable,
        "tip": [float(v) for v in tip],
        "tip_x": float(tip[0]), "tip_z": float(tip[2]),
        "tip_dx": float(tip[0] - p["length"]), "tip_dz": float(tip[2]),
        "max_speed": float(speed.max()), "max_omega": float(omega.max()),
        "wall_s": wall_s, "setup_s": setup_s, "warmup_s": warmup_s, "import_s": IMPORT_S,
        "us_per_step": 1e6 * wall_s / max(steps, 1),
        "EI": p["youngs_modulus"] * inertia, "EA": p["youngs_modulus"] * area,
        "w": p["density"] * area * p["gravity"],
        "P": p["load_factor"] * p["youngs_modulus"] * inertia / p["length"] ** 2,
        "pyelastica": ea.version.VERSION, "numpy": np.__version__, "numba": sys.modules["numba"].__version__,
        "python": sys.version.split()[0],
    }
    if case == "realtime":
        out["final_time"] = p["final_time"]
        out["rtf"] = float(t) / wall_s
        if every:
            out["tip_history"] = history
    else:
        out["converged"] = converged
        out["v_tol"] = p["v_tol"]
    return out


def main(argv):
    if len(argv) != 2:
        print(__doc__.split("\n\n")[0] + "\nusage: elastica_cases.py '<json>'", file=sys.stderr)
        return 2
    args = json.loads(argv[1])
    unknown = set(args) - set(DEFAULTS) - {"case"}
    if unknown:
        raise ValueError(f"unknown keys {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    if args.get("case") not in ("gravity", "tip_load", "realtime"):
        raise ValueError(f"the JSON argument needs a 'case': 'gravity', 'tip_load' or 'realtime', "
                         f"got {args.get('case')!r}")
    _import_peer()
    print(json.dumps(run({**DEFAULTS, **args})))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
