"""The ``soro`` command.

The application layer's entry point: it parses the command line, calls the module of each command and
turns their errors (:class:`sorofem.errors.SoroError`) into exit codes; library code never exits.

``soro doctor``
    Print the versions of the numerical stack (DOLFINx, PETSc, SLEPc, MPI, numba, gmsh, OpenCV, ...), check
    the JIT cache (writable; no stale lock of a killed compile, :mod:`sorofem.jitcache`), that a UFL form
    JIT-compiles and assembles, and that ``mpirun -n 2`` works (:mod:`soro.doctor`). Exit status 0 when all is
    well; otherwise 1, with one line per problem that says how to fix it.
``soro demo [NAME] [--quick] [--out DIR]``
    Run the demo ``NAME`` (default: ``chain``, the end-to-end job; the demos are installed with the package,
    :mod:`soro.demo`) and write its report (PNG figures and ``report.json``) to ``DIR/NAME/`` (default
    ``out/NAME/``). ``soro demo --list`` lists the demos; an unknown name exits with status 2.
``soro trade [TRAIN.h5 TEST.h5 --backbone X0,Y0[,Z0]:X1,Y1[,Z1] [--input NAME]] [--tolerance T] [--out DIR]``
    The speed-accuracy trade of beam models (DVS, Chebyshev and PCC bases of 1-6 modes) against FEM
    snapshots (:func:`soro.trade.trade_files`): a table of tip and shape errors and time per solve, a
    PNG, and the cheapest model within the tolerance (a fraction of the length, default 0.03), chosen by one
    rule (:func:`soro.trade.cheapest`: the smallest median time per solve among the rows within the
    tolerance on the test and contact tip errors) that also marks the table's selected row. Without files
    it runs the PneuNet of ``demos/dvs_pneunet.py`` (``--quick`` for a short run).
``soro trade SCENE [--tol T] [--measure tip|shape|volume|blocked|tip_contact|force_contact] [--quick] [--out DIR]``
    The fidelity ladder of a scene (:mod:`soro.ladder`; scenes: ``pneunet2d``, ``cantilever``, ``pneunet3d``):
    FEM rungs (P1, P2, P2 mixed on three meshes, h, h/2, h/4, or h, h/sqrt2, h/2 in 3D; the finest P2 mixed is the
    reference, with one pressure per material in the 2D PneuNet, its own error estimated by Richardson; the 3D
    scene adds the plane-strain section) and
    beam rungs (DVS, Chebyshev, PCC), a table marking the Pareto fronts, one log-log plot per measure and the
    error budget (``DIR``, default ``out/ladder/SCENE``). With ``--tol`` (``1%`` or ``0.01``) it selects the
    cheapest model within the tolerance on the unseen loads, writes it to ``DIR/model.json`` (Python:
    :func:`soro.ladder.load_model`; a beam: :func:`soroshapes.io.load_beam`) and validates it on a load not
    used to choose it. Exit status 1 when no model reaches the tolerance (the message names the best
    reachable error and its model). ``soro play soro.ladder:selected`` then drives the selected beam live.
``soro robot list [NAME]``, ``soro robot export NAME [--out DIR] [--param NAME=VALUE ...]``
    The open-hardware robots: their parameters; print-ready STL, a preview and the board profile
    (:mod:`soro.robots`).
``soro play SCENE [--backend model|sim|board] [--port N] [--open]``
    Serve a live page of a scene (a demo name or ``path/to/file.py:build``) on 127.0.0.1 and print its URL:
    3D view, a slider per input, a draggable IK target, live plots, recording (:mod:`soro.play`).
``soro sweep CONFIG.toml [--out DIR] [--group-size K] [--retry-failed] [--force-rerun] [--dry-run]``
    Run a batch of FEM cases described by a TOML file (format: :mod:`soro.sweep`), one snapshot file and
    one status file per case plus ``manifest.json`` in ``DIR`` (default ``out/sweeps/<config name>/``).
    Resumable: run it again after an interruption and only the missing cases run; ``--retry-failed`` runs
    the failed ones again. A resume checks the provenance of the results (builder source, ``[solve]``,
    ``[fixed]``, package version) and each snapshot's digest: other settings are refused unless
    ``--force-rerun`` reruns those cases; a damaged snapshot reruns its case. A second sweep in the same
    directory is refused (lock file). Under ``mpirun -n N`` cases run side by side on groups of ``K`` ranks.
    ``--dry-run`` prints the case table (with each case's status in ``DIR``) and runs nothing. Exit status
    0 when every case is done, 1 when some failed, 2 for an invalid configuration.

This module imports only the standard library (and :mod:`sorofem.errors`) at load time; each command
imports what it needs.
"""
import argparse
import os
import sys
import time
from pathlib import Path

from .demo import DEFAULT_DEMO

__all__ = ["main", "run_sweep"]


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
    from sorofem.errors import SoroError

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
    p.add_argument("--quick", action="store_true", help="short PneuNet run (without files) or quick ladder")
    p.add_argument("--tol", default=None, help="ladder: select the cheapest model within this error, e.g. 1%% or "
                                               "0.01, and write it to OUT/model.json")
    p.add_argument("--measure", default="tip", help="ladder: the error measure of --tol: tip, shape, volume, blocked "
                   "(the tip held: its reaction; the full 2D PneuNet), tip_contact or force_contact (the cantilever "
                   "pushed onto a floor)")
    p = sub.add_parser("sweep", help="run a batch of FEM cases from a TOML configuration (resumable, MPI)")
    p.add_argument("config", help="sweep configuration (TOML; format in soro.sweep)")
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
        from .play.cli import run as run_play
        return run_play(args)
    if args.command == "robot":   # soro robot list | export NAME (soro.robots)
        from .robots.cli import run as run_robot
        return run_robot(args)

    if args.command == "doctor":
        from .doctor import doctor
        return doctor()
    if args.command == "demo":
        from sorofem.errors import SoroError

        from .demo import key_figures, list_demos, run_demo
        try:
            if args.list:
                print("\n".join(list_demos()))
                return 0
            summary = run_demo(args.name, out=args.out, quick=args.quick)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return 130
        except SoroError as e:
            print(f"soro demo: {e}", file=sys.stderr)
            return 2
        print("\n".join(key_figures(summary)))
        print(f"report: {Path(args.out) / args.name / 'report.json'}")
        return 0
    if args.command == "trade":
        from .ladder import SCENES, run_ladder
        if args.tol is not None or (args.train in SCENES and not Path(args.train).is_file()):
            if args.test is not None or args.backbone is not None:
                print("soro trade: a scene takes no snapshot files or --backbone", file=sys.stderr)
                return 2
            return run_ladder(args.train or "pneunet2d", args.tol, args.measure, args.out, args.quick)
        from .trade import run_trade
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
