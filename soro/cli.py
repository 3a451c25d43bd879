"""The ``soro`` command.

``soro doctor``
    Print the versions of the numerical stack (DOLFINx, PETSc, SLEPc, MPI, numba, gmsh, OpenCV, ...), check
    the JIT cache (writable; no stale lock of a killed compile, :mod:`sorofem.jitcache`), that a UFL form
    JIT-compiles and assembles, and that ``mpirun -n 2`` works. Exit status 0 when all is
    well; otherwise 1, with one line per problem that says how to fix it.
``soro demo [NAME] [--quick] [--out DIR]``
    Run ``demos/NAME.py`` (default: ``chain``, the end-to-end job) and write its report (PNG figures and
    ``report.json``) to ``DIR/NAME/`` (default ``out/NAME/``). ``soro demo --list`` lists the demos.
``soro trade [TRAIN.h5 TEST.h5 --backbone X0,Y0[,Z0]:X1,Y1[,Z1] [--input NAME]] [--tolerance T] [--out DIR]``
    The speed-accuracy trade of beam models (DVS, Chebyshev and PCC bases of 1-6 modes) against FEM
    snapshots (:func:`soroshapes.dvs.trade_files`): a table of tip and shape errors and time per solve, a
    PNG, and the cheapest model within the tolerance (a fraction of the length, default 0.03), chosen by one
    rule (:func:`soroshapes.dvs.cheapest`: the smallest median time per solve among the rows within the
    tolerance on the test and contact tip errors) that also marks the table's selected row. Without files
    it runs the PneuNet of ``demos/dvs_pneunet.py`` (``--quick`` for a short run).
``soro play SCENE [--backend model|sim|board] [--port N] [--open]``
    Serve a live page of a scene (a demo name or ``path/to/file.py:build``) on 127.0.0.1 and print its URL:
    3D view, a slider per input, a draggable IK target, live plots, recording (:mod:`soro.play`).
``soro sweep CONFIG.toml [--out DIR] [--group-size K] [--retry-failed] [--force-rerun] [--dry-run]``
    Run a batch of FEM cases described by a TOML file (format: :mod:`sorofem.sweep`), one snapshot file and
    one status file per case plus ``manifest.json`` in ``DIR`` (default ``out/sweeps/<config name>/``).
    Resumable: run it again after an interruption and only the missing cases run; ``--retry-failed`` runs
    the failed ones again. A resume checks the provenance of the results (builder source, ``[solve]``,
    ``[fixed]``, package version) and each snapshot's digest: other settings are refused unless
    ``--force-rerun`` reruns those cases; a damaged snapshot reruns its case. A second sweep in the same
    directory is refused (lock file). Under ``mpirun -n N`` cases run side by side on groups of ``K`` ranks.
    ``--dry-run`` prints the case table (with each case's status in ``DIR``) and runs nothing. Exit status
    0 when every case is done, 1 when some failed, 2 for an invalid configuration.

This module imports only the standard library at load time; every check imports what it tests.
"""
import argparse
import importlib
import importlib.util
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["main", "doctor", "run_demo", "list_demos", "run_sweep", "run_trade", "DEMOS_DIR"]

#: Where ``soro demo`` looks for demo scripts (the repository's ``demos/``; ``$SORO_DEMOS`` overrides).
DEMOS_DIR = Path(os.environ.get("SORO_DEMOS", Path(__file__).resolve().parents[1] / "demos"))
DEFAULT_DEMO = "chain"

_BOOTSTRAP = "run `bash scripts/bootstrap.sh` from the repository (or `make test`), then use `.venv/bin/soro`"


def _mpi_env():
    """Environment for ``mpirun``: Debian's OpenMPI refuses to run as root without these two variables."""
    env = dict(os.environ)
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    return env


# (label, module, version getter, fix hint)
_PACKAGES = [
    ("numpy", "numpy", lambda m: m.__version__, "apt-get install python3-numpy; " + _BOOTSTRAP),
    ("scipy", "scipy", lambda m: m.__version__, "apt-get install python3-scipy; " + _BOOTSTRAP),
    ("numba", "numba", lambda m: m.__version__, "apt-get install python3-numba; " + _BOOTSTRAP),
    ("gmsh", "gmsh", lambda m: m.__version__, "apt-get install python3-gmsh; " + _BOOTSTRAP),
    ("meshio", "meshio", lambda m: m.__version__, "apt-get install python3-meshio; " + _BOOTSTRAP),
    ("h5py", "h5py", lambda m: m.__version__, "apt-get install python3-h5py; " + _BOOTSTRAP),
    ("matplotlib", "matplotlib", lambda m: m.__version__, "apt-get install python3-matplotlib; " + _BOOTSTRAP),
    ("mpi4py", "mpi4py", lambda m: m.__version__, "apt-get install python3-mpi4py; " + _BOOTSTRAP),
    ("MPI library", "mpi4py.MPI", lambda m: m.Get_library_version().splitlines()[0].strip(),
     "apt-get install openmpi-bin python3-mpi4py; " + _BOOTSTRAP),
    ("PETSc", "petsc4py.PETSc", lambda m: ".".join(map(str, m.Sys.getVersion())),
     "apt-get install python3-petsc4py; " + _BOOTSTRAP),
    ("SLEPc", "slepc4py.SLEPc", lambda m: ".".join(map(str, m.Sys.getVersion())),
     "apt-get install python3-slepc4py; " + _BOOTSTRAP),
    ("DOLFINx", "dolfinx", lambda m: m.__version__,
     "apt-get install python3-dolfinx (Debian 12 ships 0.5.2, Debian 13 0.9.0); " + _BOOTSTRAP),
    ("OpenCV", "cv2", lambda m: m.__version__,
     "pip install opencv-python-headless into the project's venv; " + _BOOTSTRAP),
    ("tqdm", "tqdm", lambda m: m.__version__, "pip install tqdm into the project's venv; " + _BOOTSTRAP),
]


def _check_packages():
    rows, problems = [], []
    for label, module, version, fix in _PACKAGES:
        try:
            mod = importlib.import_module(module)
            rows.append((label, str(version(mod)), getattr(mod, "__file__", "") or ""))
        except Exception as e:  # noqa: BLE001 - any import failure is a problem to report, not to raise
            rows.append((label, "MISSING", f"{type(e).__name__}: {e}"))
            problems.append(f"{label} cannot be imported ({type(e).__name__}: {e}). Fix: {fix}")
    return rows, problems


def _check_debian_numpy():
    """numpy must be Debian's build: DOLFINx, SciPy and numba were compiled against it."""
    try:
        import numpy
    except ImportError:
        return []  # already reported
    if not numpy.__file__.startswith("/usr/lib/python3/"):
        return [f"numpy {numpy.__version__} is loaded from {numpy.__file__}, not Debian's /usr/lib/python3: "
                "a pip-installed numpy shadows the one DOLFINx was built against. Fix: "
                "`.venv/bin/pip uninstall numpy`, then " + _BOOTSTRAP + " (it pins numpy with a constraints file)"]
    return []


def _blas():
    """Which BLAS Debian's alternatives give ``libblas.so.3`` (MUMPS, numpy and scipy use it)."""
    import glob

    for link in sorted(glob.glob("/usr/lib/*-linux-gnu/libblas.so.3")):
        real = os.path.realpath(link)
        if "openblas" in real:
            return f"OpenBLAS ({real})"
        if "blis" in real or "mkl" in real or "atlas" in real:
            return real
        return (f"reference BLAS ({real}): direct solves run ~5x slower; "
                "`apt-get install libopenblas0-serial` (scripts/bootstrap.sh does)")
    return "not found in /usr/lib/*-linux-gnu (not a Debian layout)"


def _check_dolfinx_support():
    """Whether the installed DOLFINx is in the tested range (:data:`sorofem._dolfinx.SUPPORTED`)."""
    from . import _dolfinx

    ok, sentence = _dolfinx.support_status()
    return ("yes: " if ok else "NO: ") + sentence, ([] if ok else [sentence])


def _check_jit():
    """Compile and assemble a small UFL form: integral of 1 over the unit square must be 1."""
    from ._jit import silence_compiler_logs

    silence_compiler_logs()
    t0 = time.perf_counter()
    try:
        from mpi4py import MPI
        import ufl
        import dolfinx.fem
        import dolfinx.mesh
        msh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
        one = dolfinx.fem.Constant(msh, 1.0)
        value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ufl.dx(domain=msh)))
    except Exception as e:  # noqa: BLE001
        return f"failed ({type(e).__name__}: {e})", [
            f"a UFL form does not JIT-compile ({type(e).__name__}: {e}). Fix: check that gcc and "
            "python3-dev are installed (apt-get install build-essential python3-dev) and that "
            "~/.cache/fenics is writable; " + _BOOTSTRAP]
    if abs(value - 1.0) > 1e-12:
        return f"wrong result {value}", [f"a JIT-compiled form gave {value} instead of 1.0: the FEniCSx "
                                         "installation is broken; reinstall python3-dolfinx"]
    return f"ok ({time.perf_counter() - t0:.1f} s)", []


def _check_jit_cache(directory=None):
    """The JIT cache: its directory, module count and locks; a stale lock (killed compile) is a problem."""
    from . import jitcache

    directory = Path(directory) if directory is not None else jitcache.cache_dir()
    if not directory.exists():
        return f"{directory} (empty)", []
    if not os.access(directory, os.W_OK):
        return f"{directory} not writable", [f"the JIT cache {directory} is not writable: forms cannot be "
                                             "compiled. Fix: chown or chmod it, or set XDG_CACHE_HOME"]
    modules = len(list(directory.glob("*.c.cached")))
    locks = jitcache.scan(directory)
    stale = [lock for lock in locks if lock.stale]
    status = f"{directory}: {modules} compiled module(s), {len(locks) - len(stale)} compiling, {len(stale)} stale"
    problems = []
    if stale:
        files = " ".join(str(lock.path) for lock in stale)
        problems.append(f"{len(stale)} stale JIT lock(s) of killed compiles ({stale[0].reason}): every run that "
                        f"needs those forms waits for the JIT timeout and fails. Fix: rm {files} "
                        "(soro sweep removes them at start)")
    return status, problems


def _check_mpi():
    """Run two ranks that sum their ranks with an allreduce."""
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        return "mpirun not found", ["mpirun is not on PATH. Fix: apt-get install openmpi-bin"]
    # only rank 0 prints: output of two ranks interleaves character by character
    code = ("from mpi4py import MPI; c = MPI.COMM_WORLD; s = c.allreduce(c.rank)\n"
            "if c.rank == 0: print(c.size, s)")
    try:
        res = subprocess.run([mpirun, "-n", "2", sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120, env=_mpi_env(), stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return "timed out", ["`mpirun -n 2` did not finish in 120 s. Fix: check that no firewall or hostname "
                             "lookup blocks OpenMPI (try `mpirun -n 2 hostname`)"]
    lines = res.stdout.split()
    if res.returncode != 0 or lines != ["2", "1"]:
        return f"failed (exit {res.returncode})", [
            f"`mpirun -n 2 python` failed (exit {res.returncode}): {res.stderr.strip()[-300:]} Fix: "
            "apt-get install openmpi-bin python3-mpi4py; as root set OMPI_ALLOW_RUN_AS_ROOT=1 and "
            "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1"]
    return "ok (2 ranks)", []


def doctor(stream=None):
    """Check the installation; print a report to ``stream`` (default stdout). Return the exit status."""
    out = stream or sys.stdout
    print(f"soro doctor — Python {platform.python_version()} at {sys.executable}", file=out)
    rows, problems = _check_packages()
    width = max(len(r[0]) for r in rows)
    for label, version, where in rows:
        print(f"  {label:<{width}}  {version}", file=out)
    problems += _check_debian_numpy()
    print(f"  {'BLAS':<{width}}  {_blas()}", file=out)
    have_dolfinx = all(r[1] != "MISSING" for r in rows if r[0] in ("DOLFINx", "mpi4py"))
    status, p = _check_jit_cache()
    problems += p
    print(f"  {'JIT cache':<{width}}  {status}", file=out)
    if have_dolfinx:
        support, p = _check_dolfinx_support()
        problems += p
        status, p = _check_jit()
        problems += p
    else:
        support = status = "skipped (DOLFINx missing)"
    print(f"  {'supported':<{width}}  {support}", file=out)
    print(f"  {'form JIT':<{width}}  {status}", file=out)
    status, p = _check_mpi()
    problems += p
    print(f"  {'mpirun -n 2':<{width}}  {status}", file=out)
    if problems:
        print(f"\n{len(problems)} problem(s):", file=out)
        for p in problems:
            print(f"  - {p}", file=out)
        return 1
    print("\nall checks passed", file=out)
    return 0


def list_demos():
    """Names of the demos in :data:`DEMOS_DIR` (files ``NAME.py`` not starting with ``_``)."""
    return sorted(p.stem for p in DEMOS_DIR.glob("*.py") if not p.name.startswith("_"))


def run_demo(name=DEFAULT_DEMO, out="out", quick=False, **options):
    """Run ``demos/<name>.py``'s ``main(out_dir, quick, **options)`` and write ``<out>/<name>/report.json``.

    Returns the summary dict the demo returned, completed with its wall time.
    """
    from .io import write_json

    path = DEMOS_DIR / f"{name}.py"
    if not path.is_file():
        raise SystemExit(f"no demo named {name!r}; available: {', '.join(list_demos()) or 'none'} "
                         f"(looked in {DEMOS_DIR})")
    spec = importlib.util.spec_from_file_location(f"soro_demo_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out_dir = Path(out) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    summary = module.main(out_dir, quick=quick, **options)
    summary = dict(summary or {})
    summary.setdefault("demo", name)
    summary["quick"] = bool(quick)
    summary["wall_time_s"] = round(time.perf_counter() - t0, 3)
    write_json(out_dir / "report.json", summary)
    return summary


def _world_rank():
    """This process's rank under mpirun (from the launcher's environment; 0 without MPI), without importing MPI."""
    for var in ("OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"):
        if os.environ.get(var, "").isdigit():
            return int(os.environ[var])
    return 0


def run_sweep(config, out=None, group_size=1, retry_failed=False, dry_run=False, stream=None, force_rerun=False):
    """``soro sweep``: run (or with ``dry_run`` list) the cases of a sweep configuration; return the exit status.

    0 when every case is done, 1 when a case failed (or is still pending), 2 when the configuration is
    invalid. World rank 0 prints one line per finished case and a one-line summary to ``stream``.
    """
    from .errors import SoroError
    from .sweep import Sweep, format_record

    stream = stream or sys.stdout
    rank0 = _world_rank() == 0
    out = Path(out) if out is not None else Path("out") / "sweeps" / Path(config).stem
    try:
        sweep = Sweep.from_toml(config)
        if dry_run:
            table = sweep.table(out)
    except SoroError as e:
        if rank0:
            print(f"soro sweep: {e}", file=sys.stderr)
        return 2
    if dry_run:
        if rank0:
            print(table, file=stream)
            print(f"{len(sweep)} cases; output directory {out}", file=stream)
        return 0

    def progress(rec, done, total):
        print(format_record(rec, done, total), file=stream, flush=True)

    t0 = time.perf_counter()
    try:
        manifest = sweep.run(out, group_size=group_size, retry_failed=retry_failed, progress=progress,
                             force_rerun=force_rerun)
    except SoroError as e:
        if rank0:
            print(f"soro sweep: {e}", file=sys.stderr)
        return 2
    counts = manifest["counts"]
    failed = [c["id"] for c in manifest["cases"] if c["status"] == "failed"]
    if rank0:
        line = (f"sweep: {manifest['n_cases']} cases: {counts['done']} done, {counts['failed']} failed, "
                f"{counts['pending']} pending ({time.perf_counter() - t0:.1f} s); manifest {out / 'manifest.json'}")
        if failed:
            more = " ..." if len(failed) > 10 else ""
            line += f"; failed: {', '.join(failed[:10])}{more} (--retry-failed reruns them)"
        if counts["pending"]:
            line += "; run the same command again for the pending cases"
        print(line, file=stream, flush=True)
    return 0 if counts["failed"] == 0 and counts["pending"] == 0 else 1


def run_trade(train=None, test=None, backbone=None, inputs=None, tolerance=0.03, out=None, quick=False,
              stream=None):
    """``soro trade``: the speed-accuracy table for two snapshot files along a backbone, or for the PneuNet
    demo when no file is given. Prints the table; returns the exit status (1 if no model meets the
    tolerance, 2 for bad arguments)."""
    stream = stream or sys.stdout
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0 < tolerance < 1:
        print(f"soro trade: --tolerance is a fraction of the length in (0, 1), e.g. 0.03; got {tolerance}",
              file=sys.stderr)
        return 2
    if train is None:
        if test is not None or backbone is not None:
            print("soro trade: give both TRAIN and TEST snapshot files with --backbone, or none", file=sys.stderr)
            return 2
        from soroshapes.dvs import trade_text

        out = Path(out or "out")
        report = run_demo("dvs_pneunet", out=out, quick=quick, tolerance=tolerance)
        text, pick = trade_text(report["trade"], tolerance)   # the one selection rule, as in trade.txt
        print(text, file=stream)
    else:
        from sorofem.errors import SoroError
        from soroshapes.dvs import Backbone, trade_files
        if test is None or backbone is None:
            print("soro trade: TRAIN needs a TEST file and --backbone", file=sys.stderr)
            return 2
        try:
            points = [[float(v) for v in p.split(",")] for p in backbone.split(":")]
            rows, pick, text = trade_files(train, test, Backbone(points), inputs=inputs, tolerance=tolerance,
                                           out=Path(out or "out/trade"))
        except (ValueError, SoroError) as e:
            print(f"soro trade: {e}", file=sys.stderr)
            return 2
        print(text, file=stream)
    if pick is None:
        return 1
    print(f"selected: {pick['family']} with {pick['modes']} modes", file=stream)
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog="soro", description="Soft-robot design, simulation and control.")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("doctor", help="check the installation and print versions")
    p = sub.add_parser("demo", help="run a demo and write its report to out/NAME/")
    p.add_argument("name", nargs="?", default=DEFAULT_DEMO, help=f"demo name (default: {DEFAULT_DEMO})")
    p.add_argument("--quick", action="store_true", help="short run (what the tests use)")
    p.add_argument("--out", default="out", help="output directory (default: out)")
    p.add_argument("--list", action="store_true", help="list the demos and exit")
    p = sub.add_parser("trade", help="speed-accuracy trade of beam models against FEM snapshots")
    p.add_argument("train", nargs="?", help="training snapshot file (default: the PneuNet demo's)")
    p.add_argument("test", nargs="?", help="test snapshot file")
    p.add_argument("--backbone", help="backbone polyline in the undeformed body, x0,y0[,z0]:x1,y1[,z1]:... [m]")
    p.add_argument("--input", action="append", dest="inputs", help="input name(s) of the snapshot files")
    p.add_argument("--tolerance", type=float, default=0.03, help="tip error bound, fraction of the length")
    p.add_argument("--out", default=None, help="output directory")
    p.add_argument("--quick", action="store_true", help="short PneuNet run (without files)")
    p = sub.add_parser("sweep", help="run a batch of FEM cases from a TOML configuration (resumable, MPI)")
    p.add_argument("config", help="sweep configuration (TOML; format in sorofem.sweep)")
    p.add_argument("--out", default=None, help="output directory (default: out/sweeps/<config name>)")
    p.add_argument("--group-size", type=int, default=1, metavar="K",
                   help="MPI ranks per case under mpirun (default: 1)")
    p.add_argument("--retry-failed", action="store_true", help="run the cases that failed before again")
    p.add_argument("--force-rerun", action="store_true",
                   help="run again the cases made by another builder source, [solve], [fixed] or package version")
    p.add_argument("--dry-run", action="store_true", help="print the case table and exit")
    p = sub.add_parser("robot", help="the open-hardware robots: list them, export print-ready STL + preview")
    rsub = p.add_subparsers(dest="robot_command", required=True)
    q = rsub.add_parser("list", help="list the robots and their parameters (units, defaults, ranges)")
    q.add_argument("name", nargs="?", help="show only this robot")
    q = rsub.add_parser("export", help="write one STL per printed part, a preview PNG and NAME.json")
    q.add_argument("name", help="robot name (soro robot list)")
    q.add_argument("--out", default="out/robots", help="output directory (default: out/robots)")
    q.add_argument("--units", default="mm", help="length unit of the STL files: mm (default), m, cm, um, in")
    q.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="design parameter in its unit (mm for lengths), e.g. --param wall=2.5; repeatable")
    q.add_argument("--resolution", type=float, default=None,
                   help="marching-cubes grid step [mm] (default: a third of the smallest feature)")
    q.add_argument("--no-preview", action="store_true", help="skip the PNG")
    p = sub.add_parser("play", help="drive a scene live in the browser (model, simulated board or real board)")
    p.add_argument("scene", help="demo name (soft_hand, pcc_arm, ...) or path/to/file.py:build")
    p.add_argument("--backend", choices=("model", "sim", "board"), default="model",
                   help="model: real-time stepping here (default); sim: the simulated board; board: a real board")
    p.add_argument("--board-url", help="tcp://host:port of a real board (--backend board)")
    p.add_argument("--secret-file", help="the board's secret (default $SORO_BOARD_SECRET)")
    p.add_argument("--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine)")
    p.add_argument("--port", type=int, default=8765, help="TCP port (default 8765; 0: any free port)")
    p.add_argument("--open", action="store_true", help="also open the page in the default browser")
    p.add_argument("--quick", action="store_true", help="the scene's quick variant")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: Ctrl-C)")
    p.add_argument("--out", default="out/play", help="where recordings go (default out/play)")
    args = parser.parse_args(argv)
    if args.command == "play":    # soro play SCENE (soro.play)
        from soro.play.cli import run as run_play
        return run_play(args)
    if args.command == "robot":   # soro robot list | export NAME (sorofem.robots)
        from .robots._cli import run as run_robot
        return run_robot(args)

    if args.command == "doctor":
        return doctor()
    if args.command == "demo":
        if args.list:
            print("\n".join(list_demos()))
            return 0
        try:
            summary = run_demo(args.name, out=args.out, quick=args.quick)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return 130
        print(json.dumps(summary, indent=2, default=str))
        print(f"report: {Path(args.out) / args.name / 'report.json'}")
        return 0
    if args.command == "trade":
        return run_trade(args.train, args.test, args.backbone, args.inputs, args.tolerance, args.out, args.quick)
    if args.command == "sweep":
        try:
            return run_sweep(args.config, out=args.out, group_size=args.group_size, retry_failed=args.retry_failed,
                             dry_run=args.dry_run, force_rerun=args.force_rerun)
        except KeyboardInterrupt:
            print("interrupted: run the same command again to resume", file=sys.stderr)
            return 130
    return 2  # pragma: no cover - argparse rejects unknown commands


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
