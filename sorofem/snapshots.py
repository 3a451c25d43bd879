"""The snapshot format: one self-describing HDF5 file per FEM case, readable with numpy and h5py alone.

This is the seam between the FEM layer (:mod:`sorofem.fem` writes) and the reduced-order layer
(:mod:`soroshapes` reads, without DOLFINx). The layout is documented in ``docs/snapshot-format.md``:

``/`` attributes
    ``format = "soro-snapshots"``, ``version = 1``, ``units = "SI"``, ``created`` (ISO time),
    ``metadata`` (a JSON string: material, solver, case inputs).
``/mesh/vertices`` (n_vertices, gdim) float64 [m]
``/mesh/cells`` (n_cells, k) int64, linear connectivity; attribute ``cell_type`` (``triangle``,
    ``quadrilateral``, ``tetrahedron``, ``hexahedron``). Higher-order fields are interpolated to vertices.
``/mesh/regions/<name>`` int64 arrays, attribute ``kind``: ``facets`` (n, k_facet) vertex indices of
    boundary facets, or ``cells`` (n,) cell indices. Attribute ``/mesh.cavities`` lists the cavity names.
``/steps/time`` (n_steps,) float64: time [s] or load level [-] (attribute ``kind``: ``time`` or ``load``)
``/steps/displacement`` (n_steps, n_vertices, gdim) float64 [m], chunked one step per chunk
``/steps/inputs/<name>``, ``/steps/cavity_volume/<name>``, ``/steps/energy/<name>`` (n_steps,) float64;
``/steps/reaction/<name>`` (n_steps, gdim) float64 [N]
``/steps/cell_field/<name>`` (n_steps, n_cells) float64, per-cell values (e.g. ``von_mises`` [Pa])

Files are written atomically: :class:`SnapshotWriter` fills a temporary file next to the destination and
renames it into place when closed without error, so a reader never sees half a case.

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
import datetime
import json
from pathlib import Path

import numpy as np

from .errors import DataError
from .io import atomic_path

__all__ = ["SnapshotWriter", "Snapshots", "FORMAT", "VERSION", "CELL_TYPES", "cell_deformation_gradients"]

FORMAT = "soro-snapshots"
VERSION = 1
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
    """

    def __init__(self, path, vertices, cells, cell_type, regions=None, cavities=(), metadata=None,
                 time_kind="time"):
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
        for name in cavities:
            if name not in regions:
                raise DataError(f"cavity {name!r} is not among the regions {sorted(regions)}")
        self.gdim = vertices.shape[1]
        self.n_vertices = len(vertices)
        self.n_cells = len(cells)
        self.n_steps = 0
        self._series = {}
        h5 = _h5py()
        self._atomic = atomic_path(self.path, suffix=".h5")
        self._tmp = self._atomic.__enter__()
        self._f = h5.File(self._tmp, "w")
        f = self._f
        f.attrs.update(format=FORMAT, version=VERSION, units="SI",
                       created=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                       metadata=json.dumps(metadata or {}, default=str))
        m = f.create_group("mesh")
        m.create_dataset("vertices", data=vertices)
        m.create_dataset("cells", data=cells.astype(np.int64)).attrs["cell_type"] = cell_type
        m.attrs["cavities"] = json.dumps(list(cavities))
        g = m.create_group("regions")
        for name, (kind, idx) in regions.items():
            if kind not in ("facets", "cells"):
                raise DataError(f"region {name!r}: kind must be 'facets' or 'cells', got {kind!r}")
            g.create_dataset(name, data=np.asarray(idx, dtype=np.int64)).attrs["kind"] = kind
        s = f.create_group("steps")
        s.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8").attrs["kind"] = time_kind
        s.create_dataset("displacement", shape=(0, self.n_vertices, self.gdim),
                         maxshape=(None, self.n_vertices, self.gdim), chunks=(1, self.n_vertices, self.gdim),
                         dtype="f8")

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
                    s.create_dataset(path, shape=(0, *v.shape), maxshape=(None, *v.shape), dtype="f8")
                s[path].resize((n + 1, *v.shape))
                s[path][n] = v
        self.n_steps += 1

    def close(self):
        """Finish the file and move it into place."""
        if self._f is not None:
            self._f.close()
            self._f = None
            self._atomic.__exit__(None, None, None)

    def abort(self):
        """Discard the file (nothing is left at ``path``; a previous file there is kept)."""
        if self._f is not None:
            self._f.close()
            self._f = None
            aborted = DataError(f"writing {self.path} was aborted")
            self._atomic.__exit__(DataError, aborted, None)  # removes the temporary file

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

    Attributes
    ----------
    vertices, cells, cell_type, gdim, regions (name -> (kind, indices)), cavities, metadata, times,
    time_kind, inputs / cavity_volumes / energies / reactions / cell_fields (name -> array over steps).
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.is_file():
            raise DataError(f"no snapshot file at {self.path}")
        h5 = _h5py()
        try:
            f = h5.File(self.path, "r")
        except OSError as e:
            raise DataError(f"{self.path} is not a readable HDF5 file ({e}); was the case interrupted?") from e
        with f:
            if f.attrs.get("format") != FORMAT:
                raise DataError(f"{self.path} is not a {FORMAT} file (format attribute: {f.attrs.get('format')!r})")
            version = int(f.attrs["version"])
            if version > VERSION:
                raise DataError(f"{self.path} has format version {version}; this reader knows up to {VERSION}: "
                                "update the package")
            self.version = version
            self.metadata = json.loads(f.attrs.get("metadata", "{}"))
            self.vertices = f["mesh/vertices"][...]
            self.cells = f["mesh/cells"][...]
            self.cell_type = str(f["mesh/cells"].attrs["cell_type"])
            self.gdim = self.vertices.shape[1]
            self.cavities = json.loads(f["mesh"].attrs.get("cavities", "[]"))
            self.regions = {k: (str(d.attrs["kind"]), d[...]) for k, d in f["mesh/regions"].items()}
            self.times = f["steps/time"][...]
            self.time_kind = str(f["steps/time"].attrs["kind"])

            def read(group):  # names may contain "/" (e.g. "pressure/cavity_0"): walk the subgroups
                out = {}
                if f"steps/{group}" in f:
                    f[f"steps/{group}"].visititems(
                        lambda k, d: out.__setitem__(k, d[...]) if isinstance(d, h5.Dataset) else None)
                return out
            self.inputs = read("inputs")
            self.cavity_volumes = read("cavity_volume")
            self.energies = read("energy")
            self.reactions = read("reaction")
            self.cell_fields = read("cell_field")

    @property
    def n_steps(self):
        return len(self.times)

    def displacement(self, step=None):
        """Vertex displacements [m]: one step (n_vertices, gdim), or all (n_steps, n_vertices, gdim)."""
        h5 = _h5py()
        with h5.File(self.path, "r") as f:
            d = f["steps/displacement"]
            if step is None:
                return d[...]
            if not -self.n_steps <= step < self.n_steps:
                raise DataError(f"step {step} out of range: the file has {self.n_steps} steps")
            return d[step]

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
