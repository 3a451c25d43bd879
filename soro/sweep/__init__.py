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
supports and loads added (numbers are ramped by ``solve`` from 0 to their value at ``load_level = 1``), or
``(fem, solve_kwargs)``, whose keyword arguments override ``[solve]`` for this case. The sweep calls
``fem.solve(**solve)`` and saves the trajectory; ``[solve]`` accepts the arguments of :meth:`Fem.solve`
listed in :data:`SOLVE_KEYS`, of the types in :data:`SOLVE_TYPES` (checked when the configuration is loaded:
``steps = "four"``, ``steps = 2.5`` or ``predictor = 1`` are refused, naming the key). The final load level is
``load_level``; the old name ``t_end`` is still read, with a ``FutureWarning`` naming the new one
(:data:`RENAMED_SOLVE_KEYS`).

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

    from soro.sweep import Sweep
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

The package: :mod:`~soro.sweep.schema` (the configuration's keys, types and checks; the builder and summary
references), :mod:`~soro.sweep.sampling` (grid and Latin hypercube), :mod:`~soro.sweep.manifest` (progress
records and the provenance of results), :mod:`~soro.sweep.directory` (the lock of the output directory, the
clean-up of a killed run) and :mod:`~soro.sweep.runner` (the :class:`Sweep`: status files, manifest, MPI
groups).
"""
from .manifest import format_record, provenance_changes
from .runner import Sweep
from .sampling import grid, latin_hypercube
from .schema import MAX_CELLS, MODES, PARAMETER_TYPES, RENAMED_SOLVE_KEYS, SOLVE_KEYS, SOLVE_TYPES

__all__ = ["Sweep", "grid", "latin_hypercube", "SOLVE_KEYS", "SOLVE_TYPES", "RENAMED_SOLVE_KEYS", "PARAMETER_TYPES",
           "MODES", "MAX_CELLS", "format_record", "provenance_changes"]
