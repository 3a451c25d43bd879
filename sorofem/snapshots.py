"""The snapshot format: one self-describing HDF5 file per FEM case, readable with numpy and h5py alone.

This is the seam between the FEM layer (:mod:`sorofem.fem` writes) and the reduced-order layer
(:mod:`soroshapes` reads, without DOLFINx). The layout is documented in ``docs/snapshot-format.md``:

``/`` attributes
    ``format = "soro-snapshots"``, ``version = 2``, ``units = "SI"``, ``created`` (ISO time),
    ``metadata`` (a JSON string: material, solver, case inputs).
Every dataset has an attribute ``unit`` (``m``, ``Pa``, ``N``, ``J``, ``1`` for dimensionless numbers,
``index`` for connectivity; see :func:`unit_of`). Version 1 files (no ``unit`` attributes) are still read;
their units are the defaults of :func:`unit_of`.
``/mesh/vertices`` (n_vertices, gdim) float64 [m]
``/mesh/cells`` (n_cells, k) int64, linear connectivity; attribute ``cell_type`` (``triangle``,
    ``quadrilateral``, ``tetrahedron``, ``hexahedron``). Higher-order fields are interpolated to vertices.
``/mesh/regions/<name>`` int64 arrays, attribute ``kind``: ``facets`` (n, k_facet) vertex indices of
    boundary facets, or ``cells`` (n,) cell indices. Attribute ``/mesh.cavities`` lists the cavity names.
``/steps/time`` (n_steps,) float64: time [s] or load level [-] (attribute ``kind``: ``time`` or ``load``)
``/steps/displacement`` (n_steps, n_vertices, gdim) float64 [m], chunked one step per chunk
``/steps/inputs/<name>`` (names made by :func:`input_name`: ``pressure/cavity_0``), ``/steps/cavity_volume/<name>``, ``/steps/energy/<name>`` (n_steps,) float64;
``/steps/reaction/<name>`` (n_steps, gdim) float64 [N]
``/steps/cell_field/<name>`` (n_steps, n_cells) float64, per-cell values (e.g. ``von_mises`` [Pa])

Every dataset carries an HDF5 ``fletcher32`` checksum (per chunk; series are chunked one step per chunk).
Files are written atomically: :class:`SnapshotWriter` fills a temporary file next to the destination, flushes
it to disk and renames it into place when closed without error, so a reader never sees half a case; a full
disk is a :class:`DataError` naming the file and the free space. :class:`Snapshots` validates what it reads
(structure, shapes, index ranges, finiteness, checksums) and names the file, the dataset and the step of
any problem.

Examples
--------
>>> import numpy as np, tempfile, os
>>> X = np.array([[0., 0.], [1., 0.], [0., 1.]]); cells = np.array([[0, 1, 2]])
>>> path = os.path.join(tempfile.mkdtemp(), "case.h5")
>>> with SnapshotWriter(path, X, cells, "triangle") as w:
...     w.append(0.0, np.zeros_like(X), inputs={"pressure": 0.0})
...     w.append(1.0, 0.1 * X, inputs={"pressure": 1e3})
>>> snap = Snapshots(path)
>>> snap.n_steps, snap.deformation_gradient(1)[0].round(3).tolist()
(2, [[1.1, 0.0], [0.0, 1.1]])
"""
import contextlib
import datetime
import errno
import json
import shutil
import sys
from pathlib import Path

import numpy as np

from .errors import DataError
from .io import atomic_path, disk_full_error, is_disk_full

__all__ = ["SnapshotWriter", "Snapshots", "FORMAT", "VERSION", "CELL_TYPES", "INPUT_KINDS", "input_name",
           "parse_input_name", "unit_of", "cell_deformation_gradients"]

FORMAT = "soro-snapshots"
VERSION = 2
#: The kinds of input a FEM case applies and their units (3D; see :func:`unit_of` for 2D).
INPUT_KINDS = {"pressure": "Pa", "tension": "N", "expansion": "1", "added_volume": "m^3"}


def input_name(kind, key):
    """The name of an input series, ``"<kind>/<key>"`` (e.g. ``input_name("pressure", "cavity_0")`` is
    ``"pressure/cavity_0"``): the one function the FEM solver (writer) and readers use to name inputs.

    Parameters
    ----------
    kind : str
        One of :data:`INPUT_KINDS`: ``pressure`` [Pa], ``tension`` [N], ``expansion`` [-],
        ``added_volume`` [m^3].
    key : str or int
        The region (or the tendon's index).
    """
    if kind not in INPUT_KINDS:
        raise DataError(f"unknown input kind {kind!r}; use one of {sorted(INPUT_KINDS)}")
    key = str(key)
    if not key or "/" in key:
        raise DataError(f"an input's region or index must be a non-empty name without '/', got {key!r}")
    return f"{kind}/{key}"


def parse_input_name(name):
    """``(kind, key)`` of a name made by :func:`input_name`; ``(None, name)`` for another name."""
    kind, sep, key = str(name).partition("/")
    return (kind, key) if sep and kind in INPUT_KINDS and key and "/" not in key else (None, str(name))


_PER_DEPTH = {"m^3": "m^2", "N": "N/m", "J": "J/m"}


def unit_of(group, name="", per_depth=False, time_kind="time"):
    """The unit of a dataset: ``group`` is ``vertices``, ``cells``, ``region``, ``time``, ``displacement``,
    ``inputs``, ``cavity_volume``, ``energy``, ``reaction`` or ``cell_field``; ``name`` the series' name.
    ``per_depth``: a plane-strain or plane-stress case, whose volumes, forces and energies are per unit depth
    (``m^2``, ``N/m``, ``J/m``). ``unspecified`` for series whose unit is not known."""
    if group == "inputs":
        unit = INPUT_KINDS.get(str(name).partition("/")[0], "unspecified")
    elif group == "cell_field":
        unit = {"von_mises": "Pa"}.get(str(name), "unspecified")
    elif group == "time":
        unit = "s" if time_kind == "time" else "1"
    else:
        unit = {"vertices": "m", "cells": "index", "region": "index", "displacement": "m", "cavity_volume": "m^3",
                "energy": "J", "reaction": "N"}[group]
    return _PER_DEPTH.get(unit, unit) if per_depth else unit
#: Linear cell types and their (topological dimension, vertices per cell).
CELL_TYPES = {"triangle": (2, 3), "quadrilateral": (2, 4), "tetrahedron": (3, 4), "hexahedron": (3, 8)}


def _h5py():
    try:
        import h5py
    except ImportError as e:  # pragma: no cover - bootstrap installs python3-h5py
        raise DataError("reading or writing snapshots needs h5py: apt-get install python3-h5py") from e
    return h5py


def _finite(name, array):
    array = np.asarray(array, dtype=float)
    if not np.all(np.isfinite(array)):
        raise DataError(f"{name} holds NaN or infinite values; a diverged step must not be stored "
                        "(the solver should have cut the step and reported it)")
    return array


@contextlib.contextmanager
def _unraisable():
    """Collect the exceptions Python would print as "Exception ignored in ..." while the block runs; yields the
    list they are appended to.

    h5py's handle destructors (Cython) report an error twice: first with ``PyErr_PrintEx`` (through
    ``sys.excepthook``, which also sets ``sys.last_*``), then with ``sys.unraisablehook``. Both hooks are
    replaced for the block and ``sys.last_*`` restored after it.
    """
    caught = []
    hooks = sys.unraisablehook, sys.excepthook
    last = [getattr(sys, name, None) for name in _LAST]
    sys.unraisablehook = lambda u: caught.append(u.exc_value)
    sys.excepthook = lambda kind, value, tb: None
    try:
        yield caught
    finally:
        sys.unraisablehook, sys.excepthook = hooks
        for name, value in zip(_LAST, last):
            if value is None:
                with contextlib.suppress(AttributeError):
                    delattr(sys, name)
            else:
                setattr(sys, name, value)


_LAST = ("last_type", "last_value", "last_traceback")


class SnapshotWriter:
    """Write one FEM case, step by step, to a snapshot file (atomically, see the module docstring).

    Parameters
    ----------
    path : str or Path
        Destination ``.h5`` file.
    vertices : (n_vertices, gdim) array
        Reference vertex coordinates [m].
    cells : (n_cells, k) int array
        Linear connectivity into ``vertices``.
    cell_type : str
        One of :data:`CELL_TYPES`.
    regions : dict, optional
        ``name -> ("facets", (n, k_facet) vertex indices)`` or ``name -> ("cells", (n,) cell indices)``.
    cavities : sequence of str, optional
        Names (among ``regions``) of the pressure cavities.
    metadata : dict, optional
        JSON-serializable description of the case (material, solver, inputs).
    time_kind : {"time", "load"}
        Whether the step coordinate is a time [s] or a load level [-].
    per_depth : bool
        A plane-strain or plane-stress case: volumes, reactions and energies are per unit depth
        (:func:`unit_of`).
    units : dict, optional
        ``"<group>/<name>" -> unit`` for series whose unit :func:`unit_of` does not know (e.g.
        ``{"inputs/valve": "V"}``).
    """

    def __init__(self, path, vertices, cells, cell_type, regions=None, cavities=(), metadata=None,
                 time_kind="time", per_depth=False, units=None):
        self.path = Path(path)
        vertices = _finite("vertices", vertices)
        cells = np.asarray(cells)
        if vertices.ndim != 2 or vertices.shape[1] not in (2, 3):
            raise DataError(f"vertices must have shape (n, 2) or (n, 3), got {vertices.shape}")
        if cell_type not in CELL_TYPES:
            raise DataError(f"unknown cell type {cell_type!r}; use one of {sorted(CELL_TYPES)}")
        if cells.ndim != 2 or cells.shape[1] != CELL_TYPES[cell_type][1]:
            raise DataError(f"{cell_type} cells need {CELL_TYPES[cell_type][1]} vertices each, got shape {cells.shape}")
        if cells.size and (cells.min() < 0 or cells.max() >= len(vertices)):
            raise DataError("cells refer to vertices that do not exist")
        if time_kind not in ("time", "load"):
            raise DataError(f"time_kind must be 'time' or 'load', got {time_kind!r}")
        regions = dict(regions or {})
        self._per_depth, self._units, self._time_kind = bool(per_depth), dict(units or {}), time_kind
        for name in cavities:
            if name not in regions:
                raise DataError(f"cavity {name!r} is not among the regions {sorted(regions)}")
        self.gdim = vertices.shape[1]
        self.n_vertices = len(vertices)
        self.n_cells = len(cells)
        self.n_steps = 0
        self._series = {}
        for name, (kind, _) in regions.items():
            if kind not in ("facets", "cells"):
                raise DataError(f"region {name!r}: kind must be 'facets' or 'cells', got {kind!r}")
        h5 = _h5py()
        self._f = None
        self._atomic = atomic_path(self.path, suffix=".h5")
        self._tmp = self._atomic.__enter__()
        self._room(vertices.nbytes + cells.size * 8 + sum(np.asarray(i).size * 8 for _, i in regions.values()))
        self._guarded(lambda: self._start(h5, vertices, cells, cell_type, regions, cavities, metadata, time_kind))

    def _start(self, h5, vertices, cells, cell_type, regions, cavities, metadata, time_kind):
        # no chunk cache: every chunk (one step) is written once, and written now, so that a full disk fails
        # this call, not the destructor of a dataset handle later (which loses the error and can leave a
        # dangling handle that crashes HDF5 at exit)
        self._f = f = h5.File(self._tmp, "w", rdcc_nbytes=0)
        f.attrs.update(format=FORMAT, version=VERSION, units="SI",
                       created=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                       metadata=json.dumps(metadata or {}, default=str))
        m = f.create_group("mesh")
        m.create_dataset("vertices", data=vertices, fletcher32=True).attrs["unit"] = self._unit("vertices")
        d = m.create_dataset("cells", data=cells.astype(np.int64), fletcher32=True)
        d.attrs.update(cell_type=cell_type, unit=self._unit("cells"))
        m.attrs["cavities"] = json.dumps(list(cavities))
        g = m.create_group("regions")
        for name, (kind, idx) in regions.items():
            d = g.create_dataset(name, data=np.asarray(idx, dtype=np.int64), fletcher32=True)
            d.attrs.update(kind=kind, unit=self._unit("region"))
        s = f.create_group("steps")
        d = s.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", fletcher32=True)
        d.attrs.update(kind=time_kind, unit=self._unit("time"))
        s.create_dataset("displacement", shape=(0, self.n_vertices, self.gdim),
                         maxshape=(None, self.n_vertices, self.gdim), chunks=(1, self.n_vertices, self.gdim),
                         dtype="f8", fletcher32=True).attrs["unit"] = self._unit("displacement")
        f.flush()

    def _unit(self, group, name=""):
        return self._units.get(f"{group}/{name}") or unit_of(group, name, self._per_depth, self._time_kind)

    def _room(self, nbytes):
        """Refuse to start a write that the disk cannot hold (HDF5 buffers writes and reports a full disk
        only from destructors, as hundreds of ignored exceptions): twice the bytes plus 1 MiB must be free."""
        need = 2 * int(nbytes) + (1 << 20)
        try:
            free = shutil.disk_usage(self._tmp.parent).free
        except OSError:
            return
        if free < need:
            self._discard()
            raise disk_full_error(self.path, OSError(errno.ENOSPC, f"{need / 2**20:.1f} MiB needed for the "
                                                                   "next write"))

    def _guarded(self, fn):
        """Run an HDF5 write; on failure discard the temporary file (a full disk as the DataError that names
        the path and the free space).

        HDF5 often reports a failed write not to the caller but from the destructor of a dataset handle, which
        Python prints as an "Exception ignored" traceback and forgets (the write is then silently lost and
        the file would be committed). During the write those exceptions are caught (:func:`_unraisable`),
        printed nowhere, and the first one is raised here as if the write had failed.
        """
        try:
            with _unraisable() as ignored:
                out = fn()
            if ignored:
                raise ignored[0]
            return out
        except Exception as e:
            self._discard()
            if is_disk_full(e):
                raise disk_full_error(self.path, e) from e
            raise

    def _discard(self):
        """Close (silencing HDF5's errors on a full disk) and remove the temporary file."""
        f, self._f = self._f, None
        if f is not None:
            with _unraisable(), contextlib.suppress(Exception):
                f.close()
        if self._atomic is not None:
            atomic, self._atomic = self._atomic, None
            with contextlib.suppress(DataError):
                atomic.__exit__(DataError, DataError(f"writing {self.path} was aborted"), None)

    def append(self, time, displacement, inputs=None, cavity_volumes=None, reactions=None, energies=None,
               cell_fields=None):
        """Add one step: time or load level, vertex displacements (n_vertices, gdim) [m], and named scalars.

        ``inputs``, ``cavity_volumes`` [m^3 or m^2 per unit depth in 2D] and ``energies`` [J] map names to
        floats; ``reactions`` maps names to (gdim,) forces [N]; ``cell_fields`` maps names to (n_cells,)
        arrays. Every step must carry the same names.
        Non-finite values are refused with :class:`DataError` and nothing of the step is written.
        """
        u = _finite("displacement", displacement)
        if u.shape != (self.n_vertices, self.gdim):
            raise DataError(f"displacement must have shape {(self.n_vertices, self.gdim)}, got {u.shape}")
        t = float(_finite("time", time))
        groups = {"inputs": inputs, "cavity_volume": cavity_volumes, "energy": energies, "reaction": reactions,
                  "cell_field": cell_fields}
        values = {}
        for group, data in groups.items():
            data = {k: _finite(f"{group}[{k}]", v) for k, v in (data or {}).items()}
            known = self._series.setdefault(group, set(data) if self.n_steps == 0 else set())
            if self.n_steps and set(data) != known:
                raise DataError(f"step {self.n_steps}: {group} names {sorted(data)} differ from the first "
                                f"step's {sorted(known)}")
            for k, v in data.items():
                shape = {"reaction": (self.gdim,), "cell_field": (self.n_cells,)}.get(group, ())
                if v.shape != shape:
                    raise DataError(f"{group}[{k}] must have shape {shape}, got {v.shape}")
            values[group] = data
        if self._f is None:
            raise DataError(f"{self.path}: the writer is closed")
        self._room(u.nbytes + sum(np.asarray(v).nbytes for d in values.values() for v in d.values()) + 4096)
        self._guarded(lambda: self._write_step(t, u, values))
        self.n_steps += 1

    def _write_step(self, t, u, values):
        s = self._f["steps"]
        n = self.n_steps
        s["time"].resize((n + 1,))
        s["time"][n] = t
        s["displacement"].resize((n + 1, self.n_vertices, self.gdim))
        s["displacement"][n] = u
        for group, data in values.items():
            for k, v in data.items():
                path = f"{group}/{k}"
                if path not in s:
                    s.create_dataset(path, shape=(0, *v.shape), maxshape=(None, *v.shape), dtype="f8",
                                     chunks=(1, *v.shape), fletcher32=True).attrs["unit"] = self._unit(group, k)
                s[path].resize((n + 1, *v.shape))
                s[path][n] = v
        self._f.flush()  # a full disk shows here, as an exception, not later from a destructor

    def close(self):
        """Finish the file and move it into place."""
        if self._f is not None:
            self._guarded(self._f.close)
            self._f = None
            atomic, self._atomic = self._atomic, None
            try:
                atomic.__exit__(None, None, None)  # fsync, rename, fsync of the directory
            except Exception as e:
                if is_disk_full(e):
                    raise disk_full_error(self.path, e) from e
                raise

    def abort(self):
        """Discard the file (nothing is left at ``path``; a previous file there is kept)."""
        self._discard()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False


class Snapshots:
    """Read a snapshot file into numpy arrays (the whole file is small enough except displacements,
    which are read one step at a time on demand).

    The reader trusts nothing: it checks the structure (required groups, datasets and attributes), every
    shape against the mesh and the number of steps, index ranges (cells into vertices, regions into
    vertices or cells), finiteness, and the HDF5 ``fletcher32`` checksums of the datasets (files of
    version 1 written before checksums were added are read without them). Any problem raises
    :class:`DataError` naming the file, the dataset and, for per-step data, the step.

    Attributes
    ----------
    vertices, cells, cell_type, gdim, regions (name -> (kind, indices)), cavities, metadata, times,
    time_kind, inputs / cavity_volumes / energies / reactions / cell_fields (name -> array over steps),
    version (of the file), units (dataset path -> unit; for version 1 files the defaults of :func:`unit_of`).
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(f"no snapshot file at {self.path}")
        h5, f = self._open("is not a readable HDF5 file", "; was the case interrupted?")
        with f:
            self._read(f, h5)

    def _open(self, problem, hint=""):
        """``(h5py, the file open read-only)``; a file HDF5 cannot open is a :class:`DataError`
        ``"<path> <problem> (<HDF5's reason>)<hint>"``."""
        h5 = _h5py()
        try:
            return h5, h5.File(self.path, "r")
        except OSError as e:
            raise DataError(f"{self.path} {problem} ({e}){hint}") from e

    def _fail(self, dataset, problem, step=None):
        where = f"{dataset}" + (f" at step {step}" if step is not None else "")
        return DataError(f"{self.path}: {where}: {problem}; the file is damaged or was not written by "
                         "SnapshotWriter (run its case again)")

    def _dataset(self, f, h5, name, dtype_kind="f"):
        """The dataset ``name`` (present, a dataset, of the right kind of number)."""
        d = f.get(name)
        if d is None:
            raise self._fail(name, "missing")
        if not isinstance(d, h5.Dataset):
            raise self._fail(name, "is a group, not a dataset")
        if d.dtype.kind not in (("i", "u") if dtype_kind == "i" else ("f", "i", "u")):
            raise self._fail(name, f"has type {d.dtype}, expected {'integers' if dtype_kind == 'i' else 'numbers'}")
        return d

    def _values(self, d, name, step=None):
        """Read a dataset (or one step of it): a failed checksum or read is a DataError naming it."""
        try:
            return d[...] if step is None else d[step]
        except (OSError, RuntimeError, ValueError, TypeError, IndexError, SystemError) as e:
            problem = "checksum mismatch (fletcher32)" if "fletcher32" in str(e).lower() or "filter" in \
                str(e).lower() else f"unreadable ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})"
            raise self._fail(name, problem, step) from e

    def _finite(self, array, name, steps=False):
        bad = ~np.isfinite(array)
        if np.any(bad):
            first = np.argwhere(bad)[0]
            raise self._fail(name, "holds NaN or infinite values", int(first[0]) if steps else None)
        return array

    def _attr(self, obj, name, where, kind=str):
        if name not in obj.attrs:
            raise self._fail(where, f"attribute {name!r} missing")
        value = obj.attrs[name]
        if isinstance(value, bytes):
            value = value.decode()
        if kind is str and not isinstance(value, str):
            raise self._fail(where, f"attribute {name!r} is {value!r}, expected a string")
        return value

    def _json(self, text, where):
        try:
            return json.loads(text)
        except (TypeError, ValueError) as e:
            raise self._fail(where, f"not valid JSON ({e})") from e

    def _read(self, f, h5):
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode()
        if fmt != FORMAT:
            raise DataError(f"{self.path} is not a {FORMAT} file (format attribute: {fmt!r})")
        version = self._attr(f, "version", "/ (root)", kind=None)
        if isinstance(version, (bool, np.bool_)) or not isinstance(version, (int, np.integer)) or version < 1:
            raise self._fail("/ (root)", f"attribute 'version' is {version!r}, expected a positive integer")
        version = int(version)
        if version > VERSION:
            raise DataError(f"{self.path} has format version {version}; this reader knows up to {VERSION}: "
                            "update the package")
        self.version = version
        self.units = {}
        self.metadata = self._json(f.attrs.get("metadata", "{}"), "/ attribute metadata")
        if not isinstance(self.metadata, dict):
            raise self._fail("/ attribute metadata", "must be a JSON object")

        # the mesh
        dv = self._dataset(f, h5, "mesh/vertices")
        self.vertices = self._finite(self._values(dv, "mesh/vertices").astype(float), "mesh/vertices")
        self._unit(dv, "mesh/vertices", "vertices")
        if self.vertices.ndim != 2 or self.vertices.shape[1] not in (2, 3) or not len(self.vertices):
            raise self._fail("mesh/vertices", f"shape {self.vertices.shape}, expected (n_vertices > 0, 2 or 3)")
        n_vertices, self.gdim = self.vertices.shape
        dc = self._dataset(f, h5, "mesh/cells", "i")
        self.cell_type = self._attr(dc, "cell_type", "mesh/cells")
        if self.cell_type not in CELL_TYPES:
            raise self._fail("mesh/cells", f"unknown cell_type {self.cell_type!r}; known: {sorted(CELL_TYPES)}")
        self.cells = self._values(dc, "mesh/cells").astype(np.int64)
        self._unit(dc, "mesh/cells", "cells")
        k = CELL_TYPES[self.cell_type][1]
        if self.cells.ndim != 2 or self.cells.shape[1] != k:
            raise self._fail("mesh/cells", f"shape {self.cells.shape}, expected (n_cells, {k}) for {self.cell_type}")
        self._in_range(self.cells, n_vertices, "mesh/cells", "vertex")
        n_cells = len(self.cells)
        self.cavities = self._json(f["mesh"].attrs.get("cavities", "[]"), "mesh attribute cavities")
        if not isinstance(self.cavities, list) or not all(isinstance(c, str) for c in self.cavities):
            raise self._fail("mesh attribute cavities", f"{self.cavities!r} is not a list of names")
        self.regions = {}
        regions = f.get("mesh/regions")
        if regions is not None:
            if not isinstance(regions, h5.Group):
                raise self._fail("mesh/regions", "is not a group")
            for name in regions:
                where = f"mesh/regions/{name}"
                d = self._dataset(f, h5, where, "i")
                kind = self._attr(d, "kind", where)
                idx = self._values(d, where).astype(np.int64)
                self._unit(d, where, "region")
                if kind == "cells":
                    if idx.ndim != 1:
                        raise self._fail(where, f"shape {idx.shape}, expected (n,) cell indices")
                    self._in_range(idx, n_cells, where, "cell")
                elif kind == "facets":
                    if idx.ndim != 2:
                        raise self._fail(where, f"shape {idx.shape}, expected (n, vertices per facet)")
                    self._in_range(idx, n_vertices, where, "vertex")
                else:
                    raise self._fail(where, f"kind {kind!r}, expected 'facets' or 'cells'")
                self.regions[name] = (kind, idx)
        missing = [c for c in self.cavities if c not in self.regions]
        if missing:
            raise self._fail("mesh attribute cavities", f"cavities {missing} are not among the regions "
                                                        f"{sorted(self.regions)}")

        # the steps
        dt = self._dataset(f, h5, "steps/time")
        self.time_kind = self._attr(dt, "kind", "steps/time")
        if self.time_kind not in ("time", "load"):
            raise self._fail("steps/time", f"kind {self.time_kind!r}, expected 'time' or 'load'")
        self.times = self._finite(self._values(dt, "steps/time").astype(float), "steps/time", steps=True)
        self._unit(dt, "steps/time", "time")
        if self.times.ndim != 1:
            raise self._fail("steps/time", f"shape {self.times.shape}, expected (n_steps,)")
        n = len(self.times)
        du = self._dataset(f, h5, "steps/displacement")
        if du.shape != (n, n_vertices, self.gdim):
            raise self._fail("steps/displacement", f"shape {du.shape}, expected (n_steps, n_vertices, gdim) = "
                                                   f"{(n, n_vertices, self.gdim)} (steps/time has {n} steps)")
        self._unit(du, "steps/displacement", "displacement")

        def read(group, tail):  # names may contain "/" (e.g. "pressure/cavity_0"): walk the subgroups
            out = {}
            g = f.get(f"steps/{group}")
            if g is None:
                return out
            if not isinstance(g, h5.Group):
                raise self._fail(f"steps/{group}", "is not a group")
            names = []
            g.visititems(lambda k, d: names.append(k) if isinstance(d, h5.Dataset) else None)
            for k in names:
                where = f"steps/{group}/{k}"
                d = self._dataset(f, h5, where)
                if d.shape != (n, *tail):
                    raise self._fail(where, f"shape {d.shape}, expected {(n, *tail)} (one value per step of "
                                            "steps/time)")
                out[k] = self._finite(self._values(d, where).astype(float), where, steps=True)
                self._unit(d, where, group, k)
            return out
        self.inputs = read("inputs", ())
        self.cavity_volumes = read("cavity_volume", ())
        self.energies = read("energy", ())
        self.reactions = read("reaction", (self.gdim,))
        self.cell_fields = read("cell_field", (n_cells,))

    def _unit(self, d, where, group, name=""):
        """Record the unit of dataset ``where``: its ``unit`` attribute (required from version 2 on), or for a
        version 1 file the default (:func:`unit_of`)."""
        if self.version >= 2:
            unit = self._attr(d, "unit", where)
        else:
            per_depth = self.metadata.get("formulation") in ("plane_strain", "plane_stress")
            unit = unit_of(group, name, per_depth, getattr(self, "time_kind", "time"))
        self.units[where] = unit
        return unit

    def input(self, kind, key):
        """The series of input ``kind`` on ``key`` (:func:`input_name`), e.g. ``snap.input("pressure",
        "cavity_0")`` [Pa]; a missing one is a :class:`DataError` naming the inputs the file has."""
        name = input_name(kind, key)
        if name not in self.inputs:
            raise DataError(f"{self.path} has no input {name!r}; it has {sorted(self.inputs)}")
        return self.inputs[name]

    def _in_range(self, idx, n, where, what):
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            bad = idx[(idx < 0) | (idx >= n)][0]
            raise self._fail(where, f"{what} index {int(bad)} out of range [0, {n})")

    @property
    def n_steps(self):
        return len(self.times)

    def displacement(self, step=None):
        """Vertex displacements [m]: one step (n_vertices, gdim), or all (n_steps, n_vertices, gdim).

        Raises :class:`DataError` naming the file, ``steps/displacement`` and the step for a failed checksum or
        a non-finite value."""
        if step is not None:
            if isinstance(step, bool) or not isinstance(step, (int, np.integer)):
                raise DataError(f"step must be an integer, got {step!r}")
            if not -self.n_steps <= step < self.n_steps:
                raise DataError(f"step {step} out of range: the file has {self.n_steps} steps")
            step = int(step) % self.n_steps
        h5, f = self._open("can no longer be read")
        with f:
            d = self._dataset(f, h5, "steps/displacement")
            if step is not None:
                return self._finite(self._values(d, "steps/displacement", step).astype(float),
                                    f"steps/displacement at step {step}")
            out = np.empty(d.shape)
            for k in range(d.shape[0]):  # step by step: a damaged chunk is named by its step
                out[k] = self._values(d, "steps/displacement", k)
            return self._finite(out, "steps/displacement", steps=True)

    def deformation_gradient(self, step):
        """Deformation gradient per cell (n_cells, gdim, gdim) at ``step`` (exact for linear simplices;
        at the cell centre for quadrilaterals and hexahedra, from the first vertex's corner)."""
        return cell_deformation_gradients(self.vertices, self.cells, self.displacement(step), self.cell_type)


def cell_deformation_gradients(vertices, cells, displacement, cell_type="triangle"):
    """:math:`F = I + \\nabla_X u` per cell for a vertex displacement field.

    For a linear simplex with reference edge matrix :math:`D_X = [X_1 - X_0, \\dots]` and current one
    :math:`D_x = D_X + [u_1 - u_0, \\dots]`, :math:`F = D_x D_X^{-1}` exactly. For quadrilaterals and
    hexahedra the edges from vertex 0 to its neighbours in the reference ordering (DOLFINx/VTK-lagrange
    lexicographic: 1, 2 and 4) give the corner gradient (exact for affine cells).

    Returns
    -------
    (n_cells, gdim, gdim) array.
    """
    X = np.asarray(vertices, dtype=float)
    u = np.asarray(displacement, dtype=float)
    cells = np.asarray(cells)
    tdim, _ = CELL_TYPES[cell_type]
    gdim = X.shape[1]
    if tdim != gdim:
        raise DataError(f"deformation gradients need a {gdim}D solid mesh, got {cell_type} cells")
    corner = {"triangle": [1, 2], "tetrahedron": [1, 2, 3], "quadrilateral": [1, 2], "hexahedron": [1, 2, 4]}
    nb = cells[:, corner[cell_type]]
    DX = np.swapaxes(X[nb] - X[cells[:, :1]], 1, 2)
    du = np.swapaxes(u[nb] - u[cells[:, :1]], 1, 2)
    det = np.linalg.det(DX)
    if np.any(np.abs(det) <= 1e-300):
        raise DataError("degenerate reference cells (zero volume): cannot compute deformation gradients")
    return np.eye(gdim) + du @ np.linalg.inv(DX)
