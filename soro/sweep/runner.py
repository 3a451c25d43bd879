"""The :class:`Sweep` (format and behaviour in :mod:`soro.sweep`): cases from the configuration, status files,
the lock of the output directory, the manifest, and the cases run on groups of MPI ranks."""
import gc
import json
import logging
import math
import os
import time
import tomllib
import traceback
from pathlib import Path

import numpy as np

from sorofem.errors import DataError, ParameterError
from sorofem.io import write_json

from .directory import MANIFEST, clean, take_lock
from .manifest import _fmt, _provenance, format_record, provenance_changes
from .sampling import _grid_values, _lhs_spec, grid, latin_hypercube
from .schema import (MAX_CELLS, MODES, SOLVE_KEYS, _SWEEP_KEYS, _TOP_KEYS, _check_declared, _check_material,
                     _check_solve, _check_value, _describe, _err, _is_material_key, _resolve,
                     rename_solve_keys)

__all__ = ["Sweep"]

log = logging.getLogger(__name__)

FORMAT = "soro-sweep"
VERSION = 1
_TAG = 7301  # MPI tag of the progress records sent to world rank 0 (on a private duplicate of the communicator)
#: What the manifest keeps of a case's status record (besides index, id, params and status).
_RECORD_KEYS = ("wall_time_s", "steps", "ranks", "group", "snapshot", "sha256", "summary", "attempts", "finished",
                "error", "traceback", "load_level")

# ---------------------------------------------------------------------------------------------- the sweep
class Sweep:
    """A parameter sweep: a case builder and the list of cases (parameter dicts) it is run on.

    Parameters
    ----------
    builder : callable or str
        ``build(params, comm) -> Fem`` or ``(Fem, solve_kwargs)`` (see the module docstring), or its
        ``"file.py:function"`` / ``"package.module:function"`` name.
    parameters : dict
        The parameter space: ``name -> values`` (grid) or ``name -> range or choices`` (lhs).
    mode : {"grid", "lhs"}
    samples : int, optional
        Number of cases of a Latin hypercube (required with ``mode="lhs"``).
    seed : int, optional
        Random seed of the Latin hypercube (default 0).
    fixed : dict, optional
        Values passed to every case.
    solve : dict, optional
        Keyword arguments of :meth:`Fem.solve` (keys in :data:`SOLVE_KEYS`).
    summary : callable or str, optional
        ``summary(traj, params) -> dict`` of figures kept in the manifest.
    base_dir : path, optional
        Folder against which a relative ``file.py`` of ``builder``/``summary`` is resolved.
    source : str, optional
        Where the configuration came from (used in error messages and the manifest).
    max_cells : int, optional
        Largest mesh (global number of cells) a case may solve (default :data:`MAX_CELLS`); a case whose
        builder makes a larger one fails before its solve, with the count and this limit in its error.

    Raises
    ------
    ParameterError
        For any invalid entry, naming its key.
    """

    def __init__(self, builder, parameters, mode="grid", samples=None, seed=None, fixed=None, solve=None,
                 summary=None, base_dir=None, source="", max_cells=None):
        src = source
        self.source = str(source)
        if max_cells is not None and (isinstance(max_cells, bool) or not isinstance(max_cells, (int, np.integer))
                                      or max_cells < 1):
            raise _err(src, "sweep.max_cells", f"must be a positive integer (a number of cells), got {max_cells!r}")
        self.max_cells = MAX_CELLS if max_cells is None else int(max_cells)
        if builder is None or builder == "":
            raise _err(src, "builder", "missing: name the function that builds a case, e.g. "
                                       "builder = \"my_case.py:build\" (def build(params, comm) -> Fem)")
        if mode not in MODES:
            raise _err(src, "sweep.mode", f"unknown mode {mode!r}; use \"grid\" (every combination) or \"lhs\" "
                                          "(Latin hypercube)")
        self.mode = mode
        if not isinstance(parameters, dict) or not parameters:
            raise _err(src, "parameters", "no parameters: list at least one, e.g. pressure = [2e3, 4e3]")
        if fixed is not None and not isinstance(fixed, dict):
            raise _err(src, "fixed", f"must be a table of name = value, got {fixed!r}")
        fixed = dict(fixed or {})
        for k, v in fixed.items():
            _check_value(v, f"fixed.{k}", src)
            if _is_material_key(k):
                _check_material(f"fixed.{k}", v, src)
        both = sorted(set(fixed) & set(parameters))
        if both:
            raise _err(src, "fixed", f"{both} are also in [parameters]; a name is either fixed or varied")
        if mode == "grid":
            for key in ("samples", "seed"):
                if (samples if key == "samples" else seed) is not None:
                    raise _err(src, f"sweep.{key}", "only mode = \"lhs\" draws samples; a grid runs every "
                                                    "combination (remove it, or set mode = \"lhs\")")
            values = {k: _grid_values(f"parameters.{k}", v, src) for k, v in parameters.items()}
            for k, vals in values.items():
                if _is_material_key(k):
                    for i, v in enumerate(vals):
                        _check_material(f"parameters.{k}[{i}]", v, src)
            cases = grid(values)   # the values are checked lists: the grid forms their combinations
        else:
            if samples is None:
                raise _err(src, "sweep.samples", "mode = \"lhs\" needs the number of cases, e.g. samples = 16")
            if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
                raise _err(src, "sweep.samples", f"must be a positive integer, got {samples!r}")
            seed = 0 if seed is None else seed
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise _err(src, "sweep.seed", f"must be a non-negative integer, got {seed!r}")
            specs = {k: _lhs_spec(f"parameters.{k}", v, src) for k, v in parameters.items()}
            for k, spec in specs.items():
                if _is_material_key(k):
                    if spec[0] != "choices":
                        raise _err(src, f"parameters.{k}", "a material is categorical: list preset names")
                    for i, v in enumerate(spec[1]):
                        _check_material(f"parameters.{k}[{i}]", v, src)
            raw = {k: ({"choices": s[1]} if s[0] == "choices" else [s[1], s[2]]) for k, s in specs.items()}
            cases = latin_hypercube(raw, samples, seed)
        self.samples, self.seed = samples, seed
        self.parameters = {k: parameters[k] for k in parameters}
        self.fixed = fixed
        if solve is not None and not isinstance(solve, dict):
            raise _err(src, "solve", f"must be a table of name = value, got {solve!r}")
        solve = dict(solve or {})
        _check_solve(solve, src)
        self.solve = solve
        # params of each case: the fixed values, then the varied ones (normalized through JSON, as stored)
        self.cases = [json.loads(json.dumps({**fixed, **c})) for c in cases]
        self.builder_spec = _describe(builder)
        self.builder = _resolve(builder, base_dir, "builder", src)
        self.summary_spec = _describe(summary) if summary is not None else None
        self.summary = _resolve(summary, base_dir, "summary", src) if summary is not None else None
        _check_declared(self.cases, getattr(self.builder, "parameters", None), self.builder_spec, src, fixed)
        self.base_dir = Path(base_dir) if base_dir is not None else None
        self.provenance = _provenance(self.builder, self.summary, self.base_dir, solve, fixed)
        self._digests = {}  # snapshot digests by (path, size, mtime): each file is read once per change

    # ------------------------------------------------------------------------------------------ loading
    @classmethod
    def from_toml(cls, path):
        """Read a sweep configuration file (see the module docstring for its format)."""
        path = Path(path)
        if not path.is_file():
            raise ParameterError(f"no sweep configuration at {path}")
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as e:
            raise ParameterError(f"{path}: not valid TOML: {e}") from e
        return cls.from_dict(data, base_dir=path.parent, source=str(path))

    @classmethod
    def from_dict(cls, data, base_dir=None, source=""):
        """A sweep from the configuration as a dict (the parsed TOML)."""
        unknown = sorted(set(data) - set(_TOP_KEYS))
        if unknown:
            raise _err(source, unknown[0], f"unknown key; the configuration has {', '.join(_TOP_KEYS)}")
        for key in ("sweep", "parameters", "fixed", "solve"):
            if key in data and not isinstance(data[key], dict):
                raise _err(source, key, f"must be a table [{key}], got {data[key]!r}")
        sweep = data.get("sweep", {})
        unknown = sorted(set(sweep) - set(_SWEEP_KEYS))
        if unknown:
            raise _err(source, f"sweep.{unknown[0]}", f"unknown key; [sweep] has {', '.join(_SWEEP_KEYS)}")
        if "builder" not in data:
            raise _err(source, "builder", "missing: name the function that builds a case, e.g. "
                                          "builder = \"my_case.py:build\" (def build(params, comm) -> Fem)")
        if "parameters" not in data:
            raise _err(source, "parameters", "missing: add a [parameters] table, e.g. pressure = [2e3, 4e3]")
        return cls(data["builder"], data["parameters"], mode=sweep.get("mode", "grid"),
                   samples=sweep.get("samples"), seed=sweep.get("seed"), fixed=data.get("fixed"),
                   solve=data.get("solve"), summary=data.get("summary"), base_dir=base_dir, source=source,
                   max_cells=sweep.get("max_cells"))

    # ------------------------------------------------------------------------------------------ naming
    def __len__(self):
        return len(self.cases)

    @property
    def varied(self):
        """Names of the parameters that vary (the ``[parameters]`` keys, in order)."""
        return list(self.parameters)

    def case_id(self, index):
        """``case_0007``: the stem of case ``index``'s files (4 digits, more for sweeps of 10^4 cases and up)."""
        width = max(4, len(str(len(self.cases) - 1)))
        return f"case_{index:0{width}d}"

    def table(self, out=None):
        """The case table (what ``soro sweep --dry-run`` prints); with ``out``, each case's status there."""
        statuses = self._statuses(Path(out)) if out is not None and Path(out).is_dir() else None
        head = ["case", *self.varied] + (["status"] if statuses is not None else [])
        rows = []
        for i, params in enumerate(self.cases):
            row = [self.case_id(i), *(_fmt(params[k]) for k in self.varied)]
            if statuses is not None:
                row.append(self._state(Path(out), i, statuses[i]))
            rows.append(row)
        width = [max(len(str(r[j])) for r in [head, *rows]) for j in range(len(head))]
        name = f"sweep {self.source}" if self.source else "sweep"
        lines = [f"{name}: {self.mode}, {len(self.cases)} cases, builder {self.builder_spec}"
                 + (f"; fixed {json.dumps(self.fixed)}" if self.fixed else "")
                 + (f"; solve {json.dumps(self.solve)}" if self.solve else "")]
        for r in [head, *rows]:
            lines.append("  ".join(str(c).ljust(w) for c, w in zip(r, width)).rstrip())
        return "\n".join(lines)

    # ------------------------------------------------------------------------------------------ state on disk
    def _statuses(self, out, force_rerun=False):
        """Status records found in ``out`` (None where a case has none or must run again); refuse another
        sweep's cases and, unless ``force_rerun``, cases made by another builder, ``[solve]``, ``[fixed]`` or
        package version."""
        found = [None] * len(self.cases)
        width = len(self.case_id(0)) - len("case_")
        changed = {}
        for f in sorted(out.glob("case_*.json")):
            stem = f.stem[len("case_"):]
            if not stem.isdigit():
                continue
            try:
                rec = json.loads(f.read_text())
                if not isinstance(rec, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as e:
                log.warning("ignoring unreadable status file %s (%s); the case will run again", f, e)
                continue
            i = int(stem)
            changes = provenance_changes(rec.get("provenance"), self.provenance) if i < len(self.cases) else []
            if changes and len(stem) == width:
                changed.setdefault("; ".join(changes), []).append(f.stem)
                continue  # refused below, or (force_rerun) run again
            if i >= len(self.cases) or len(stem) != width or rec.get("params") != self.cases[i]:
                now = self.cases[i] if i < len(self.cases) else "no such case"
                raise ParameterError(
                    f"{out} holds the results of another sweep: {f.name} was run with {rec.get('params')}, "
                    f"the configuration now gives {now}. Use another output directory (--out) or remove {out}")
            found[i] = rec
        if changed and not force_rerun:
            what = " / ".join(f"{why} for {_ids(ids)}" for why, ids in changed.items())
            raise ParameterError(
                f"{out} holds results made with other settings: {what}. Their snapshots would not match the "
                f"configuration {self.source or ''} now; use a new output directory (--out) or run these cases "
                "again with --force-rerun")
        return found

    def _state(self, out, i, rec):
        """``pending``, ``done`` or ``failed``: a ``done`` case whose snapshot is missing or does not match the
        digest in its status is pending (it runs again)."""
        if rec is None:
            return "pending"
        if rec.get("status") == "done":
            snapshot = out / str(rec.get("snapshot") or "")
            if not snapshot.is_file():
                return "pending"  # the snapshot was removed: run it again
            if not self._digest_ok(snapshot, rec.get("sha256")):
                return "pending"
        return rec.get("status", "pending")

    def _digest_ok(self, snapshot, expected):
        """Whether the snapshot's bytes match the digest of its status record (cached per size and mtime)."""
        from sorofem.io import file_digest

        st = snapshot.stat()
        key = (str(snapshot), st.st_size, st.st_mtime_ns)
        if key not in self._digests:
            self._digests[key] = file_digest(snapshot)
        if expected is None or self._digests[key] != expected:
            log.warning("%s does not match the digest in its status file (%s); the case runs again", snapshot,
                        "none recorded" if expected is None else "changed, truncated or damaged")
            return False
        return True

    def _manifest(self, out, statuses, world_size, group_size, started=None):
        cases, counts = [], {"done": 0, "failed": 0, "pending": 0}
        for i, params in enumerate(self.cases):
            rec = statuses[i]
            state = self._state(out, i, rec)
            counts[state] = counts.get(state, 0) + 1
            entry = {"index": i, "id": self.case_id(i), "params": params, "status": state}
            if rec is not None and state != "pending":
                entry.update({k: rec[k] for k in _RECORD_KEYS if k in rec})
            cases.append(entry)
        manifest = {
            "format": FORMAT, "version": VERSION, "config": self.source, "builder": self.builder_spec,
            "summary": self.summary_spec, "mode": self.mode, "samples": self.samples, "seed": self.seed,
            "parameters": self.parameters, "fixed": self.fixed, "solve": self.solve,
            "provenance": self.provenance, "n_cases": len(self.cases), "counts": counts,
            "world_size": world_size, "group_size": group_size,
            "updated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "wall_time_s": None if started is None else round(time.perf_counter() - started, 3),
            "cases": cases,
        }
        write_json(out / MANIFEST, manifest)
        return manifest

    def _claim(self, out, i):
        """Claim case ``i`` for this group (atomic exclusive creation); False if another group has it."""
        try:
            fd = os.open(out / f".{self.case_id(i)}.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            return False
        os.write(fd, f"{os.getpid()}\n".encode())
        os.close(fd)
        return True

    # ------------------------------------------------------------------------------------------ running
    def run(self, out, comm=None, group_size=1, retry_failed=False, progress=None, force_rerun=False):
        """Run every case that is not done yet; return the manifest (a dict, on every rank).

        Collective over ``comm`` (default ``MPI.COMM_WORLD``).

        Parameters
        ----------
        out : path
            Output directory (created; shared by every rank).
        group_size : int
            MPI ranks per case; the ranks of ``comm`` are split into groups of this size.
        retry_failed : bool
            Run the cases recorded as failed again (otherwise they are kept as failed).
        progress : callable, optional
            ``progress(record, n_finished, n_to_run)`` on rank 0 of ``comm`` after each finished case
            (default: a log line at INFO level).
        force_rerun : bool
            Run again the cases whose results were made by another builder source, ``[solve]``, ``[fixed]``
            or package version (otherwise such a directory is refused).

        Raises
        ------
        ParameterError
            Another sweep runs in ``out`` (its lock file), or ``out`` holds another sweep's results.
        """
        from mpi4py import MPI

        from sorofem import jitcache
        from sorofem.io import on_root

        jitcache.track()
        world = (comm or MPI.COMM_WORLD).Dup()
        out = Path(out)
        locked = []
        # on every rank: the first import of DOLFINx initializes PETSc, which is collective
        jit_cache = jitcache.cache_dir()
        try:
            return self._run(out, world, group_size, retry_failed, progress, MPI, on_root, force_rerun, locked,
                             jit_cache)
        except BaseException:
            jitcache.release_owned()  # an interrupted compile leaves no lock behind
            raise
        finally:
            for path in locked:
                path.unlink(missing_ok=True)
            world.Free()

    def _run(self, out, world, group_size, retry_failed, progress, MPI, on_root, force_rerun, locked, jit_cache):
        if isinstance(group_size, bool) or not isinstance(group_size, (int, np.integer)) or group_size < 1:
            raise ParameterError(f"group_size must be a positive integer, got {group_size!r}")
        if group_size > world.size:
            raise ParameterError(f"group_size {group_size} is larger than the {world.size} MPI rank(s); run "
                                 f"with mpirun -n {group_size} (or a multiple) or choose a smaller group size")
        started = time.perf_counter()

        def plan():
            from sorofem import jitcache

            out.mkdir(parents=True, exist_ok=True)
            locked.append(take_lock(out))
            jitcache.remove_stale(jit_cache)   # left by a killed compile: every case needing the form times out
            clean(out)
            statuses = self._statuses(out, force_rerun)
            todo = []
            for i, rec in enumerate(statuses):
                state = self._state(out, i, rec)
                if state == "pending" or (state == "failed" and retry_failed):
                    todo.append(i)
            self._manifest(out, statuses, world.size, group_size)
            return todo

        todo = world.bcast(on_root(world, plan), root=0)
        n_groups = -(-world.size // group_size)
        color = world.rank // group_size
        group = world.Split(color, world.rank)
        if n_groups > 1:
            _patient_jit()
        callback = progress or (lambda rec, k, n: log.info("%s", format_record(rec, k, n)))

        def report(rec, k, n):  # a failing progress callback must not stop rank 0 alone (the others would wait)
            try:
                callback(rec, k, n)
            except Exception:  # noqa: BLE001
                log.warning("the progress callback failed on %s", rec.get("id"), exc_info=True)
        n_reported = 0
        sent = []
        mine = 0  # cases this group finished (counted on its rank 0)
        pointer = 0

        def drain():
            nonlocal n_reported
            while world.iprobe(source=MPI.ANY_SOURCE, tag=_TAG):
                rec = world.recv(source=MPI.ANY_SOURCE, tag=_TAG)
                n_reported += 1
                report(rec, n_reported, len(todo))

        stopped = None  # a claim or status file that could not be written (full disk): this group stops
        while True:
            index = None
            if group.rank == 0:
                try:
                    while pointer < len(todo):
                        candidate = todo[pointer]
                        pointer += 1
                        if self._claim(out, candidate):
                            index = candidate
                            break
                except OSError as e:
                    stopped = _write_error(out / f".{self.case_id(candidate)}.claim", e)
            index, stopped = group.bcast((index, stopped), root=0)
            if index is None or stopped is not None:
                break
            rec, stopped = self._run_case(index, out, group, color, MPI)
            if group.rank == 0:
                mine += 1
                if world.rank == 0:
                    n_reported += 1
                    report(rec, n_reported, len(todo))
                else:
                    sent.append(world.isend(rec, dest=0, tag=_TAG))
            if world.rank == 0:
                drain()
            if stopped is not None:
                break
        total = world.allreduce(mine if group.rank == 0 else 0)
        if world.rank == 0:
            while n_reported < total:
                rec = world.recv(source=MPI.ANY_SOURCE, tag=_TAG)
                n_reported += 1
                report(rec, n_reported, len(todo))
        for req in sent:
            req.wait()
        world.Barrier()

        def finish():
            clean(out)  # the claims of this run (every group is done)
            return self._manifest(out, self._statuses(out, force_rerun), world.size, group_size, started)

        manifest = world.bcast(on_root(world, finish), root=0)
        # every rank raises the same error when some group could not write (no rank stops alone)
        stops = [e for e in world.allgather(stopped if group.rank == 0 else None) if e is not None]
        if stops:
            raise stops[0]
        return manifest

    def _run_case(self, index, out, group, color, MPI):
        """Build, solve, save and summarize case ``index`` on ``group``; write its status (group rank 0).

        Returns ``(record, error)`` on every rank of the group: ``error`` is the :class:`DataError` of a status
        file that could not be written (a full disk), else None; the record then says so and the case, which
        has no status, runs again in the next run."""
        cid = self.case_id(index)
        params = self.cases[index]
        from sorofem import jitcache

        snapshot = out / f"{cid}.h5"
        t0 = time.perf_counter()
        error = steps = summary = digest = None
        try:
            fem, kwargs = self._build(params, group, MPI)
            traj = fem.solve(**{**self.solve, **kwargs})
            traj.metadata["case"] = {"id": cid, "index": index, "params": params, "sweep": self.source}
            if self.summary is not None:
                summary = self.summary(traj, dict(params))
                if group.rank == 0:
                    summary = _check_summary(summary)
            traj.metadata["provenance"] = self.provenance
            traj.save(snapshot)
            steps = len(traj) - 1
            if group.rank == 0:
                from sorofem.io import file_digest
                digest = file_digest(snapshot)
        except Exception as e:  # noqa: BLE001 - a case's failure is recorded; the sweep goes on
            error = e
        errors = group.allgather(None if error is None else _error_record(error))
        failure = next((e for e in errors if e is not None), None)
        jit_timeout = any(e is not None and jitcache.is_jit_timeout(e["error"]) for e in errors)
        wall = group.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        status = "done" if failure is None else "pending" if jit_timeout else "failed"
        rec = {"index": index, "id": cid, "params": params, "status": status,
               "wall_time_s": round(wall, 3), "steps": None if failure else steps, "ranks": group.size,
               "group": color, "snapshot": None if failure else snapshot.name,
               "sha256": None if failure else digest, "summary": None if failure else summary,
               "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "error": None, "traceback": None,
               "provenance": self.provenance}
        if failure:
            rec.update(failure)
        if jit_timeout:  # not the case's fault: a compile elsewhere held the form's lock; the next run retries
            rec["error"] = ("JIT timeout (kept pending, not failed): " + rec["error"] +
                            " -- run the sweep again; it removes stale JIT locks at start")
        write_failed = None
        if group.rank == 0:
            previous = out / f"{cid}.json"
            try:
                rec["attempts"] = int(json.loads(previous.read_text()).get("attempts", 1)) + 1
            except (OSError, ValueError, TypeError, AttributeError):
                rec["attempts"] = 1
            try:
                write_json(previous, rec)  # the claim stays until the run ends: no other group may take the case
            except (OSError, DataError) as e:
                write_failed = e if isinstance(e, DataError) else _write_error(previous, e)
        write_failed = group.bcast(write_failed, root=0)
        if write_failed is not None:
            rec.update(status="failed", error=f"DataError: {write_failed} (the case has no status: the next run "
                                              "does it again)")
        gc.collect()  # destroy this case's PETSc objects now, at the same point on every rank of the group
        return rec, write_failed

    def _build(self, params, group, MPI):
        from sorofem.fem import Fem
        from sorofem.mesh import cell_limit

        with cell_limit(self.max_cells):   # Mesh.from_sdf refuses a larger estimate before gmsh runs
            built = self.builder(dict(params), group)
        kwargs = {}
        if isinstance(built, tuple) and len(built) == 2:
            built, kwargs = built
            if not isinstance(kwargs, dict):
                raise ParameterError(f"the builder {self.builder_spec} returned (fem, {type(kwargs).__name__}); "
                                     "the second item must be a dict of Fem.solve keyword arguments")
        if not isinstance(built, Fem):
            raise ParameterError(f"the builder {self.builder_spec} returned {type(built).__name__}; it must return "
                                 "a Fem, or (fem, solve_kwargs)")
        rename_solve_keys(kwargs, f"the builder {self.builder_spec}")
        bad = sorted(set(kwargs) - set(SOLVE_KEYS))
        if bad:
            raise ParameterError(f"the builder {self.builder_spec} returned solve settings {bad}; use "
                                 f"{', '.join(SOLVE_KEYS)}")
        if MPI.Comm.Compare(built.mesh.comm, group) not in (MPI.IDENT, MPI.CONGRUENT):
            raise ParameterError(f"the builder {self.builder_spec} built its mesh on a communicator of "
                                 f"{built.mesh.comm.size} rank(s), not on the case's ({group.size}): pass the "
                                 "comm it receives to the mesh, Mesh.from_sdf(shape, size=..., comm=comm)")
        cells = built.mesh.num_cells
        if cells > self.max_cells:
            raise ParameterError(f"the builder {self.builder_spec} made a mesh of {cells} cells, more than "
                                 f"max_cells = {self.max_cells}: is its mesh size (params {params}) meant to be "
                                 "this small? If so, raise max_cells in [sweep] (Sweep(..., max_cells=...))")
        return built, kwargs


def _write_error(path, exc):
    """The :class:`DataError` for a file of the sweep that could not be written: a full disk names the free
    space (:func:`sorofem.io.disk_full_error`)."""
    from sorofem.io import disk_full_error, is_disk_full

    if is_disk_full(exc):
        return disk_full_error(path, exc)
    return DataError(f"could not write {path} ({type(exc).__name__}: {exc}); check that the output directory is "
                     "writable on every rank")


def _ids(ids):
    return ", ".join(ids[:5]) + (f" and {len(ids) - 5} more" if len(ids) > 5 else "")


def _check_summary(summary):
    if summary is None:
        return None
    if not isinstance(summary, dict):
        raise ParameterError(f"the summary function must return a dict (or None), got {type(summary).__name__}")
    try:
        data = json.loads(json.dumps(summary, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    except (TypeError, ValueError) as e:
        raise ParameterError(f"the summary {summary!r} cannot be written as JSON: {e}") from e

    def finite(v, key):
        if isinstance(v, float) and not math.isfinite(v):
            raise ParameterError(f"the summary's {key} is {v}: a case summary holds finite numbers only")
        for k, x in (v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else ()):
            finite(x, f"{key}.{k}" if isinstance(v, dict) else f"{key}[{k}]")
    finite(data, "summary")
    return data


def _error_record(e):
    """Message and a short traceback (the last frames) of a failed case."""
    tb = traceback.format_exception(type(e), e, e.__traceback__, limit=-4)
    rec = {"error": f"{type(e).__name__}: {e}", "traceback": "".join(tb).strip()[-4000:]}
    level = getattr(e, "load_level", None)
    if isinstance(level, (int, float)) and math.isfinite(level):
        rec["load_level"] = float(level)
    return rec


def _patient_jit():
    """Groups running side by side compile the same forms at the same moment; FFCx makes the second one wait
    for the first one's module, by default for 10 s only, then fails. Wait up to 10 min instead."""
    try:
        from sorofem import _dolfinx
        _dolfinx.set_jit_timeout(600)
    except ImportError:  # pragma: no cover - no DOLFINx: nothing compiles forms
        log.debug("could not lengthen the JIT timeout", exc_info=True)
