"""Parameter sweeps: one FEM case per point of a parameter space, run in batch (``soro sweep CONFIG.toml``).

A sweep names a *case builder* (a Python function that returns a ready :class:`sorofem.fem.Fem`) and a
parameter space (a full grid or a Latin hypercube sample). Every case is solved with :meth:`Fem.solve` and
saved as a snapshot file (``docs/snapshot-format.md``); a ``manifest.json`` lists every case with its
parameters and status. Sweeps are resumable (a rerun completes only what is missing), a failing case is
recorded and does not stop the others, and under ``mpirun`` cases run side by side on groups of ranks.

Configuration (TOML)
--------------------
A complete example (``demos/sweeps/pneunet.toml``)::

    builder = "pneunet_case.py:build"      # "file.py:function" (relative to this file) or "package.module:function"
    summary = "pneunet_case.py:summary"    # optional: figures of a solved case, kept in the manifest

    [sweep]
    mode = "grid"                          # "grid": every combination; "lhs": Latin hypercube sample
    # samples = 12                         # lhs only: number of cases (required)
    # seed = 1                             # lhs only: random seed (default 0): same seed, same cases
    # max_cells = 1_000_000                # a case whose mesh has more cells fails before its solve

    [parameters]                           # what varies from case to case, SI units
    pressure = [2e3, 4e3, 6e3]             # chamber pressure [Pa]; lhs: a range [lo, hi]
    material = ["Ecoflex0030", "DragonSkin10"]    # categorical: preset names of sorofem.materials.PRESETS

    [fixed]                                # the same in every case (optional)
    chambers = 3
    size = 1.5e-3                          # mesh size [m]

    [solve]                                # keyword arguments of Fem.solve for every case (optional)
    steps = 4

Top-level keys: ``builder`` (required), ``summary``, and the tables ``[sweep]``, ``[parameters]``
(required, at least one), ``[fixed]``, ``[solve]``; an unknown key is an error naming it.

Parameters. In both modes the cases are formed in the order the parameters are written:

==============================  ===============================  ==========================================
value                           ``mode = "grid"``                ``mode = "lhs"``
==============================  ===============================  ==========================================
``[a, b, c]``                   these values                     two numbers ``[lo, hi]``: a range
                                                                 (uniform); names (strings): choices
``{choices = [a, b, c]}``       these values                     choices of any type (numbers, ``true``)
``{linspace = [lo, hi, n]}``    n evenly spaced values, lo..hi   --
``{range = [lo, hi]}``          --                               a range
==============================  ===============================  ==========================================

A grid runs every combination (the last parameter varies fastest). A Latin hypercube with ``samples = n``
splits each range into n equal strata and puts one sample in each, in an independent random order per
parameter (:func:`latin_hypercube`); a categorical parameter is stratified the same way over its choices,
so each choice is drawn uniformly and about n/k times. Numbers are SI and must be finite.
A parameter named ``material`` or ending in ``_material`` (in ``[parameters]`` or ``[fixed]``) must name
presets of :data:`sorofem.materials.PRESETS`; the builder receives the name and makes the material with
``materials.PRESETS[name]()``.

The builder (the contract)::

    def build(params: dict, comm) -> Fem | tuple[Fem, dict]

``params`` holds the ``[fixed]`` values and the case's parameters (plain floats, ints, strings, bools and
lists); ``comm`` is the MPI communicator the case runs on: build the mesh on it
(``Mesh.from_sdf(shape, size=..., comm=comm)``; the Fem follows its mesh). Return the model with its
supports and loads added (numbers are ramped by ``solve`` from 0 to their value at ``t_end = 1``), or
``(fem, solve_kwargs)``, whose keyword arguments override ``[solve]`` for this case. The sweep calls
``fem.solve(**solve)`` and saves the trajectory; ``[solve]`` accepts the arguments of :meth:`Fem.solve`
listed in :data:`SOLVE_KEYS`, of the types in :data:`SOLVE_TYPES` (checked when the configuration is loaded:
``steps = "four"``, ``steps = 2.5`` or ``predictor = 1`` are refused, naming the key).

The builder may declare the types of its parameters, so that a configuration is checked when it is loaded,
not case by case (a bool is not a number, an integer is not a float: ``pressure = [true, false]`` and
``chambers = 2.7`` are refused instead of running as 1 Pa / 0 Pa and 2 chambers; a name the builder does not
declare, e.g. a typo, is refused too)::

    build.parameters = {"pressure": float, "material": str, "chambers": int, "size": float}

(types: ``float`` = any number, ``int``, ``bool``, ``str``, ``list``). Without a declaration the values of
each parameter must at least be of one kind (no ``[1.0, true]``).

The optional summary::

    def summary(traj, params) -> dict | None

is called on every rank of the case after the solve; what it returns on the case's rank 0 (the rank that
holds the gathered ``traj.vertices`` and ``traj.displacement``) must be a JSON dict of finite values and is
kept under ``"summary"`` in the case's status and the manifest (e.g. a tip angle per case).

Output directory
----------------
::

    OUT/manifest.json    every case: index, id, params, status ("done", "failed" or "pending"), wall_time_s,
                         steps (load steps after the initial state), ranks, snapshot, summary, attempts,
                         error and traceback (failures); and the sweep's configuration and counts
    OUT/case_0000.h5     the snapshot file of case 0; its metadata["case"] holds the id and parameters
    OUT/case_0000.json   the status of case 0 (the same record as in the manifest, plus its provenance;
                         "sha256" is the digest of the snapshot file)
    OUT/.sweep.lock      while a run is going on

Every file is written atomically (a temporary file flushed to disk, renamed into place, and the directory
flushed), so a killed run or a power loss leaves either the complete file or none. The status files are the
truth; the manifest is assembled from them by one rank at the start of a run (showing what a resume will do)
and at its end.

Provenance and checksums. Every status record (and the manifest, and each snapshot's metadata) holds the
*provenance* of the results (:func:`provenance_changes` compares two): SHA-256 digests of the builder's (and
summary's) source file and of every file it imports from the configuration's folder (found from its
``import`` statements, recursively, and from the file names its string literals hold: a module loaded with
``spec_from_file_location``, a data file), of ``[solve]`` and ``[fixed]``, and the package version. A done case's
status also holds the SHA-256 digest of its snapshot file, whose datasets carry HDF5 ``fletcher32``
checksums (``docs/snapshot-format.md``).
A disk that fills up while a snapshot is written fails that case with a ``DataError`` naming the file and
the free space (nothing is left under the snapshot's name). A status or claim file that cannot be written
stops the group that writes it (all its ranks together); the run ends on every rank with that ``DataError``
after the other groups' cases and the manifest, and the case without a status runs again in the next run.

Running
-------
* **Resume**: a case is skipped when its status is ``done`` and its snapshot exists and matches the digest
  in its status (a truncated or damaged snapshot runs again); everything else that is missing runs. A case's
  status file records its parameters: a directory holding cases of another configuration is refused (use
  another output directory). Results of another provenance (the builder's source, ``[solve]``, ``[fixed]``
  or the package version changed) are refused with a message naming what changed, before anything is
  written; ``force_rerun=True`` (``--force-rerun``) runs those cases again instead. Failed cases are kept as
  failed unless ``retry_failed=True`` (``--retry-failed``) runs them again.
* **One sweep per directory**: a run holds ``OUT/.sweep.lock`` (process id and host) from start to end; a
  second sweep in the same directory is refused. The lock of a process that no longer runs (killed) is
  taken over.
* **JIT cache**: a form compilation killed or interrupted leaves a lock in the DOLFINx JIT cache that makes
  every later compile of that form time out (:mod:`sorofem.jitcache`). A run records the owner of the locks
  it creates, removes its own unfinished ones on an interrupt and the stale ones (owner gone, or of unknown
  owner and unchanged for 10 min) at start. A case that still meets a JIT timeout is recorded ``pending``,
  not ``failed``: the next run does it.
* **Mesh size**: a case whose builder makes a mesh of more than ``max_cells`` cells (``[sweep]``, default
  :data:`MAX_CELLS`) fails before its solve, naming the count and the limit (a mistyped mesh size would
  otherwise solve for hours). The count is known once the builder has meshed: an estimate before meshing
  needs the mesh module's help (not yet).
* **Failures**: any exception in the builder, the solve or the summary (a ``ConvergenceError``, a
  ``ValueError`` ...) marks the case ``failed`` with its message and the last frames of its traceback;
  the other cases go on. ``KeyboardInterrupt`` stops the run (run it again to resume).
* **MPI**: under ``mpirun -n N`` the ranks are split into groups of ``group_size`` consecutive ranks (the
  last group may be smaller); each group runs one case at a time on its communicator and takes the next
  pending case as soon as it is free (a case is claimed with an exclusively created ``.case_XXXX.claim``
  file in the output directory, which must therefore be on a file system every rank sees). Only a group's
  rank 0 writes its case's files. Without MPI, or on one rank, the cases run one after another. Run one
  sweep per output directory at a time.
* **Progress**: world rank 0 reports one record per finished case (id, status, wall time) to the
  ``progress`` callable (the CLI prints one line); records of other groups arrive when rank 0 is between
  two of its own cases.

Python use::

    from sorofem.sweep import Sweep
    sweep = Sweep.from_toml("demos/sweeps/pneunet.toml")
    sweep.cases                          # [{'chambers': 3, 'size': 0.0015, 'pressure': 2000.0, ...}, ...]
    print(sweep.table())                 # what --dry-run prints
    manifest = sweep.run("out/sweeps/pneunet", group_size=1)      # every rank gets the manifest

Examples
--------
>>> grid({"p": [1.0, 2.0], "m": ["A", "B"]})
[{'p': 1.0, 'm': 'A'}, {'p': 1.0, 'm': 'B'}, {'p': 2.0, 'm': 'A'}, {'p': 2.0, 'm': 'B'}]
>>> cases = latin_hypercube({"p": [0.0, 1.0], "m": ["A", "B"]}, samples=4, seed=1)
>>> sorted(int(c["p"] * 4) for c in cases), sorted(c["m"] for c in cases)
([0, 1, 2, 3], ['A', 'A', 'B', 'B'])
"""
import gc
import hashlib
import importlib
import importlib.util
import inspect
import itertools
import json
import logging
import math
import os
import socket
import sys
import time
import tomllib
import traceback
from pathlib import Path

import numpy as np

from .errors import DataError, ParameterError
from .io import process_alive, write_json

__all__ = ["Sweep", "grid", "latin_hypercube", "SOLVE_KEYS", "SOLVE_TYPES", "PARAMETER_TYPES", "MODES", "MAX_CELLS",
           "format_record", "provenance_changes"]

log = logging.getLogger(__name__)

MODES = ("grid", "lhs")
#: Keyword arguments of :meth:`sorofem.fem.Fem.solve` that ``[solve]`` (or a builder) may set.
SOLVE_KEYS = ("t_end", "steps", "min_step", "max_step", "max_iterations", "predictor", "monitor_stability")
MANIFEST = "manifest.json"
FORMAT = "soro-sweep"
VERSION = 1
_TOP_KEYS = ("builder", "summary", "sweep", "parameters", "fixed", "solve")
_SWEEP_KEYS = ("mode", "samples", "seed", "max_cells")
#: Default largest mesh (global cell count) a case may solve: a mistyped mesh size (1e-5 for 1e-3) fails the
#: case with the count and the limit instead of solving for hours.
MAX_CELLS = 1_000_000
#: What the manifest keeps of a case's status record (besides index, id, params and status).
_RECORD_KEYS = ("wall_time_s", "steps", "ranks", "group", "snapshot", "sha256", "summary", "attempts", "finished",
                "error", "traceback", "load_level")
#: The type of each ``[solve]`` setting: "number" (an int or a float, never a bool), "integer", "bool";
#: all numbers must be positive.
SOLVE_TYPES = {"t_end": "number", "steps": "integer", "min_step": "number", "max_step": "number",
               "max_iterations": "integer", "predictor": "bool", "monitor_stability": "bool"}
#: Parameter types a builder may declare in its ``parameters`` attribute (see the module docstring).
PARAMETER_TYPES = {float: "number", int: "integer", bool: "bool", str: "string", list: "list"}
LOCK = ".sweep.lock"
_TAG = 7301  # MPI tag of the progress records sent to world rank 0 (on a private duplicate of the communicator)


# ---------------------------------------------------------------------------------------------- validation
def _err(source, key, problem):
    return ParameterError(f"{source}: {key}: {problem}" if source else f"{key}: {problem}")


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_value(v, key, source):
    """A case value: a finite number, a string, a bool or a list of those (JSON round-trips it exactly)."""
    if isinstance(v, bool) or isinstance(v, str):
        return v
    if _is_number(v):
        if not math.isfinite(v):
            raise _err(source, key, f"{v} is not a finite number")
        return v
    if isinstance(v, (list, tuple)):
        return [_check_value(x, f"{key}[{i}]", source) for i, x in enumerate(v)]
    raise _err(source, key, f"values must be numbers, strings, booleans or lists of them, got "
                            f"{type(v).__name__} {v!r}")


def _type_name(v):
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "integer"
    if isinstance(v, float):
        return "number"
    return {str: "string", list: "list", tuple: "list"}.get(type(v), type(v).__name__)


def _check_type(v, want, key, source):
    """``v`` is of the type ``want`` ("number", "integer", "bool", "string" or "list"): bools are not numbers,
    and an integer setting is an integer (``2.7`` or ``2.0`` is refused, not truncated)."""
    ok = {"number": _is_number(v), "integer": isinstance(v, int) and not isinstance(v, bool),
          "bool": isinstance(v, bool), "string": isinstance(v, str), "list": isinstance(v, (list, tuple))}[want]
    if not ok:
        article = "an" if want[0] in "aeiou" else "a"
        raise _err(source, key, f"must be {article} {want}, got {_type_name(v)} {v!r}")


def _check_solve(solve, source):
    for k, v in solve.items():
        if k not in SOLVE_KEYS:
            raise _err(source, f"solve.{k}", f"not a setting of Fem.solve; use one of {', '.join(SOLVE_KEYS)}")
        _check_type(v, SOLVE_TYPES[k], f"solve.{k}", source)
        _check_value(v, f"solve.{k}", source)
        if SOLVE_TYPES[k] != "bool" and not v > 0:
            raise _err(source, f"solve.{k}", f"must be positive, got {v!r}")


def _check_kinds(key, values, source):
    """The values of one parameter are of one kind: numbers (ints and floats mix), bools, strings or lists."""
    kinds = {("number" if _is_number(v) else _type_name(v)) for v in values}
    if len(kinds) > 1:
        raise _err(source, key, f"mixes {' and '.join(sorted(kinds))} values {values!r}; a parameter's values "
                                "are all of one type (true/false are not 1/0)")


def _check_declared(cases, declared, builder_spec, source, fixed=()):
    """Check every case value against the types the builder declares (``build.parameters``)."""
    if declared is None:
        return
    if not isinstance(declared, dict) or not all(t in PARAMETER_TYPES for t in declared.values()):
        raise _err(source, "builder", f"{builder_spec}.parameters must map names to types among "
                                      f"{', '.join(t.__name__ for t in PARAMETER_TYPES)}, got {declared!r}")
    for params in cases:
        for k, v in params.items():
            key = f"fixed.{k}" if k in fixed else f"parameters.{k}"
            if k not in declared:
                raise _err(source, key, f"the builder {builder_spec} takes no parameter {k!r}; it declares "
                                        f"{', '.join(declared)}")
            _check_type(v, PARAMETER_TYPES[declared[k]], key, source)


def _is_material_key(name):
    return name == "material" or name.endswith("_material")


def _check_material(name, value, source):
    from .materials import PRESETS

    if not isinstance(value, str) or value not in PRESETS:
        raise _err(source, name, f"unknown material preset {value!r}; known presets: {', '.join(PRESETS)}")


def _grid_values(key, spec, source=""):
    """The list of values of one grid parameter."""
    if isinstance(spec, dict):
        if set(spec) == {"choices"}:
            spec = spec["choices"]
        elif set(spec) == {"linspace"}:
            ls = spec["linspace"]
            if not (isinstance(ls, list) and len(ls) == 3 and all(_is_number(x) for x in ls)
                    and isinstance(ls[2], int) and ls[2] >= 1):
                raise _err(source, key, f"linspace must be [lo, hi, n] with n a positive integer, got {ls!r}")
            _check_value(ls, key, source)
            return [float(x) for x in np.linspace(ls[0], ls[1], ls[2])]
        elif "range" in spec:
            raise _err(source, key, "a range is sampled by mode = \"lhs\"; a grid needs values: a list, "
                                    "{ choices = [...] } or { linspace = [lo, hi, n] }")
        else:
            raise _err(source, key, f"unknown form {sorted(spec)}; use a list of values, {{ choices = [...] }} "
                                    "or { linspace = [lo, hi, n] }")
    if not isinstance(spec, list):
        raise _err(source, key, f"a grid parameter is a list of values, got {spec!r} (a value that does not "
                                "vary belongs in [fixed])")
    if not spec:
        raise _err(source, key, "the list of values is empty")
    _check_kinds(key, spec, source)
    return [_check_value(v, f"{key}[{i}]", source) for i, v in enumerate(spec)]


def _lhs_spec(key, spec, source=""):
    """("range", lo, hi) or ("choices", values) for one Latin-hypercube parameter."""
    if isinstance(spec, dict):
        if set(spec) == {"choices"}:
            values = spec["choices"]
            if not isinstance(values, list) or not values:
                raise _err(source, key, f"choices must be a non-empty list, got {values!r}")
            _check_kinds(key, values, source)
            return ("choices", [_check_value(v, f"{key}.choices[{i}]", source) for i, v in enumerate(values)])
        if set(spec) == {"range"}:
            spec = spec["range"]
        elif "linspace" in spec:
            raise _err(source, key, "linspace makes grid values; in lhs mode give a range [lo, hi]")
        else:
            raise _err(source, key, f"unknown form {sorted(spec)}; in lhs mode use [lo, hi], a list of names "
                                    "or { choices = [...] }")
    if isinstance(spec, (list, tuple)) and spec and all(isinstance(v, str) for v in spec):
        return ("choices", list(spec))
    if not (isinstance(spec, (list, tuple)) and len(spec) == 2 and all(_is_number(v) for v in spec)):
        raise _err(source, key, f"in lhs mode a parameter is a range [lo, hi] of two numbers, a list of names "
                                f"or {{ choices = [...] }}, got {spec!r}")
    lo, hi = (float(v) for v in spec)
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise _err(source, key, f"the range [lo, hi] needs finite lo < hi, got [{spec[0]}, {spec[1]}]")
    return ("range", lo, hi)


# ---------------------------------------------------------------------------------------------- sampling
def grid(parameters):
    """Every combination of the parameters' values, in order, the last parameter varying fastest.

    Parameters
    ----------
    parameters : dict
        ``name -> list of values`` (or ``{"choices": [...]}``, ``{"linspace": [lo, hi, n]}``).

    Returns
    -------
    list of dict, one per case (``prod(len(values))`` cases).
    """
    names = list(parameters)
    values = [_grid_values(k, parameters[k]) for k in names]
    return [dict(zip(names, combo)) for combo in itertools.product(*values)]


def latin_hypercube(parameters, samples, seed=0):
    """A Latin hypercube sample of ``samples`` cases.

    For each parameter independently, :math:`u_i = (\\pi_i + r_i)/n`, :math:`i = 0..n-1`, with
    :math:`\\pi` a random permutation of :math:`0..n-1` and :math:`r_i` uniform in [0, 1): exactly one
    sample falls in each of the n strata :math:`[k/n, (k+1)/n)`. A range ``[lo, hi]`` maps it to
    :math:`lo + (hi - lo) u` (so lo <= value < hi); choices :math:`c_0..c_{k-1}` to :math:`c_{\\lfloor k u
    \\rfloor}` (each choice drawn with probability 1/k, n/k times up to one).

    Parameters
    ----------
    parameters : dict
        ``name -> [lo, hi]`` (a range), a list of names, ``{"range": [lo, hi]}`` or ``{"choices": [...]}``.
    samples : int
        Number of cases n >= 1.
    seed : int
        Seed of :func:`numpy.random.default_rng`; the same seed and parameters give the same cases.
    """
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ParameterError(f"samples must be a positive integer, got {samples!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
    n = int(samples)
    rng = np.random.default_rng(int(seed))
    columns = {}
    for name, raw in parameters.items():
        spec = _lhs_spec(name, raw)
        u = (rng.permutation(n) + rng.random(n)) / n
        if spec[0] == "range":
            lo, hi = spec[1], spec[2]
            columns[name] = [min(lo + (hi - lo) * float(x), math.nextafter(hi, lo)) for x in u]
        else:
            choices = spec[1]
            columns[name] = [choices[min(int(x * len(choices)), len(choices) - 1)] for x in u]
    return [{k: columns[k][i] for k in columns} for i in range(n)]


# ---------------------------------------------------------------------------------------------- builders
def _resolve(spec, base_dir, key, source):
    """A function from ``"file.py:function"`` (relative to ``base_dir``) or ``"package.module:function"``."""
    if callable(spec):
        return spec
    if not isinstance(spec, str) or ":" not in spec:
        raise _err(source, key, f"expected \"file.py:function\" or \"package.module:function\", got {spec!r}")
    target, _, name = spec.rpartition(":")
    if not target or not name.isidentifier():
        raise _err(source, key, f"expected \"file.py:function\" or \"package.module:function\", got {spec!r}")
    if target.endswith(".py") or "/" in target or os.sep in target:
        path = Path(target)
        if not path.is_absolute():
            path = Path(base_dir or ".") / path
        if not path.is_file():
            raise _err(source, key, f"no file {path} (a relative path is taken from the config's folder)")
        path = path.resolve()
        # registered in sys.modules under a name unique to the file (dataclasses, pickle look modules up there)
        module_name = f"soro_sweep_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"
        try:
            mod_spec = importlib.util.spec_from_file_location(module_name, path)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[module_name] = module
            mod_spec.loader.exec_module(module)
        except Exception as e:  # noqa: BLE001 - re-raised with the key that named the file
            sys.modules.pop(module_name, None)
            raise _err(source, key, f"importing {path} failed: {type(e).__name__}: {e}") from e
        where = str(path)
    else:
        try:
            module = importlib.import_module(target)
        except ImportError as e:
            raise _err(source, key, f"cannot import module {target!r} ({e})") from e
        where = f"module {target}"
    fn = getattr(module, name, None)
    if not callable(fn):
        raise _err(source, key, f"{where} has no function {name!r}")
    return fn


def _describe(spec):
    """How a builder or summary is named in tables and the manifest."""
    if isinstance(spec, str):
        return spec
    return f"{getattr(spec, '__module__', '?')}:{getattr(spec, '__qualname__', spec)}"


def format_record(rec, done=None, total=None):
    """One progress line for a case record: ``[3/12] case_0002  done     1.4 s  (4 steps, 1 rank)``."""
    count = f"[{done}/{total}] " if done is not None and total is not None else ""
    status = rec["status"]
    line = f"{count}{rec['id']}  {status:<6} {rec.get('wall_time_s') or 0.0:7.1f} s"
    if status == "done":
        ranks = rec.get("ranks", 1)
        line += f"  ({rec.get('steps')} steps, {ranks} rank{'s' if ranks != 1 else ''})"
    elif rec.get("error"):
        line += f"  {rec['error'].splitlines()[0][:200]}"
    return line


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.6g}"
    return json.dumps(v) if not isinstance(v, str) else v


# ---------------------------------------------------------------------------------------------- provenance
def _sha256(data):
    return hashlib.sha256(data if isinstance(data, bytes) else data.encode()).hexdigest()


def _canonical(obj):
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _local_imports(path, base_dir):
    """Files of ``base_dir`` that the Python file ``path`` imports (``import x``, ``from x import y``,
    ``from x.y import z``, at any depth of the file), found from its syntax tree; and the files that a string
    literal of the file names: a data file of ``base_dir`` the builder reads (relative to ``base_dir`` or to the
    file's folder; not a ``.toml`` file: a sweep configuration's parameters may grow between runs), or a module
    loaded by path (``spec_from_file_location(..., Path(__file__).parents[1] / "case_lib.py")``): a literal
    ending in ``.py`` names the nearest such file in the file's folder or a folder above it."""
    import ast

    try:
        tree = ast.parse(Path(path).read_text(), filename=str(path))
    except (OSError, SyntaxError, ValueError):
        return []
    names, literals = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module)
            names += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and 0 < len(node.value) < 256 \
                and "\n" not in node.value and "\0" not in node.value:
            literals.append(node.value)
    found = []
    base, here = base_dir.resolve(), Path(path).resolve().parent
    for text in literals:
        module = text.endswith(".py")
        for candidate in [base / text, here / text] + ([p / text for p in here.parents] if module else []):
            try:
                real = candidate.resolve()
                ok = real.is_file() and real.suffix != ".toml" and (module or base in real.parents)
            except (OSError, ValueError):
                continue
            if ok:
                if real not in found:
                    found.append(real)
                if module:
                    break
    for name in names:
        parts = name.split(".")
        for n in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__.py and a/b/__init__.py too
            rel = Path(*parts[:n])
            for candidate in (base_dir / rel.with_suffix(".py"), base_dir / rel / "__init__.py"):
                if candidate.is_file() and candidate.resolve() not in found:
                    found.append(candidate.resolve())
    return found


def _source_files(fn, base_dir):
    """The source file of ``fn`` and, recursively, the files of ``base_dir`` it imports."""
    try:
        first = Path(inspect.getsourcefile(fn)).resolve()
    except (TypeError, OSError):
        return []
    files, todo = [], [first]
    while todo:
        f = todo.pop()
        if f in files or not f.is_file():
            continue
        files.append(f)
        if base_dir is not None and f.suffix == ".py":
            todo += _local_imports(f, base_dir)
    return files


def _provenance(builder, summary, base_dir, solve, fixed):
    """What a case's results depend on besides its parameters: digests of the builder's (and summary's) source
    files and of the files they import from the configuration's folder, of ``[solve]`` and ``[fixed]``, and
    the package version."""
    from . import __version__

    base = base_dir.resolve() if base_dir is not None else None
    files = {}
    for fn in (builder, summary):
        if fn is None:
            continue
        sources = _source_files(fn, base)
        if not sources:  # a callable without a source file: its code object stands for it
            code = getattr(fn, "__code__", None)
            files[f"<{_describe(fn)}>"] = _sha256(code.co_code + repr(code.co_consts).encode()) if code \
                else _sha256(_describe(fn))
        for f in sources:  # named relative to the configuration's folder: moving the whole tree changes nothing
            name = os.path.relpath(f, base) if base is not None else str(f)
            files[name] = _sha256(f.read_bytes())
    return {"package_version": __version__, "builder_sha256": _sha256(_canonical(files)), "builder_files": files,
            "solve_sha256": _sha256(_canonical(solve)), "solve": solve,
            "fixed_sha256": _sha256(_canonical(fixed)), "fixed": fixed}


def provenance_changes(old, new):
    """What differs between two provenance records (lists of phrases; empty if they match)."""
    if not isinstance(old, dict) or "builder_sha256" not in old:
        return ["the results were written before provenance was recorded"]
    changes = []
    if old.get("builder_sha256") != new["builder_sha256"]:
        a, b = old.get("builder_files") or {}, new["builder_files"]
        what = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        changes.append(f"the builder's source changed ({', '.join(what) or 'unknown files'})")
    for key, table in (("solve", "[solve]"), ("fixed", "[fixed]")):
        if old.get(f"{key}_sha256") != new[f"{key}_sha256"]:
            a, b = old.get(key) or {}, new[key]
            diff = [f"{k} {json.dumps(a.get(k))} -> {json.dumps(b.get(k))}"
                    for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
            changes.append(f"{table} changed ({'; '.join(diff) or 'values'})")
    if old.get("package_version") != new["package_version"]:
        changes.append(f"the package version changed ({old.get('package_version')} -> {new['package_version']})")
    return changes


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
            cases = [dict(zip(values, combo)) for combo in itertools.product(*values.values())]
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
        from .io import file_digest

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

    @staticmethod
    def _lock(out):
        """Take ``out/.sweep.lock`` (exclusive creation); a lock whose process is gone (same host) is stale
        and taken over. Another live sweep in the same directory is refused."""
        path = out / LOCK
        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        for _ in range(3):
            try:
                fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    other = json.loads(path.read_text())
                    pid, host = int(other["pid"]), str(other["host"])
                except (OSError, ValueError, KeyError, TypeError):
                    pid = host = None
                if pid is not None and host == me["host"] and pid != os.getpid() and not process_alive(pid):
                    log.warning("removing the lock of a sweep that is gone (process %d): %s", pid, path)
                    path.unlink(missing_ok=True)
                    continue
                owner = f"process {pid} on {host}" if pid is not None else "an unknown process"
                raise ParameterError(
                    f"another sweep is running in {out} ({owner}, lock {path}): wait for it to finish or use "
                    f"another output directory (--out); if no sweep runs there any more, remove {path}")
            os.write(fd, json.dumps(me).encode())
            os.close(fd)
            return path
        raise ParameterError(f"could not take the lock {path}: remove it if no sweep runs in {out}")

    @staticmethod
    def _clean(out):
        """Remove what a killed run may have left: claims and temporary files (never a finished file)."""
        for f in out.iterdir():
            n = f.name
            if f.is_file() and (n.startswith(".case_") or n.startswith(f".{MANIFEST}.")):
                f.unlink(missing_ok=True)

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

        from . import jitcache
        from .io import on_root

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
            from . import jitcache

            out.mkdir(parents=True, exist_ok=True)
            locked.append(self._lock(out))
            jitcache.remove_stale(jit_cache)   # left by a killed compile: every case needing the form times out
            self._clean(out)
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
            self._clean(out)  # the claims of this run (every group is done)
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
        from . import jitcache

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
                from .io import file_digest
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
        from .fem import Fem
        from .mesh import cell_limit

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
    from .io import disk_full_error, is_disk_full

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
        from . import _dolfinx
        _dolfinx.set_jit_timeout(600)
    except ImportError:  # pragma: no cover - no DOLFINx: nothing compiles forms
        log.debug("could not lengthen the JIT timeout", exc_info=True)
