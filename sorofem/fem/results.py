"""Results of a FEM solve: a :class:`Trajectory` of converged states, gathered to rank 0 at the mesh vertices."""
import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .. import _dolfinx
from ..errors import DataError, MeshError
from ..io import on_root
from ..snapshots import SnapshotWriter

__all__ = ["Trajectory", "VertexGatherer"]


class VertexGatherer:
    """Gathers a P1 vector field and its mesh (global vertex numbering) to rank 0.

    The P1 space's dofs are the mesh vertices; owned dofs of every rank are sent to rank 0 with their global
    indices, so serial and parallel runs produce the same arrays.
    """

    def __init__(self, V1):
        self.V1 = V1
        comm = V1.mesh.comm
        self.comm = comm
        imap = V1.dofmap.index_map
        self.n_owned = imap.size_local
        start = imap.local_range[0]
        self.local_to_global = np.concatenate([np.arange(start, start + self.n_owned), imap.ghosts]).astype(np.int64)
        self.n_global = imap.size_global
        tdim = V1.mesh.topology.dim
        n_cells = V1.mesh.topology.index_map(tdim).size_local
        cells = _dolfinx.cell_dofs(self.V1, n_cells)
        X = V1.tabulate_dof_coordinates()[: self.n_owned, : V1.mesh.geometry.dim]
        all_cells = comm.gather(self.local_to_global[cells], root=0)
        self.vertices = self.gather(X)
        self.cells = np.concatenate(all_cells) if comm.rank == 0 else None

    def gather(self, owned_values):
        """Arrays over owned vertices (n_owned, k) → (n_global, k) on rank 0 (None elsewhere)."""
        parts = self.comm.gather((self.local_to_global[: self.n_owned], np.asarray(owned_values)), root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty((self.n_global, parts[0][1].shape[1]))
        for idx, vals in parts:
            out[idx] = vals
        return out

    def gather_function(self, u1):
        """Values of a P1 vector Function at the vertices, (n_global, gdim) on rank 0."""
        bs = self.V1.dofmap.index_map_bs
        return self.gather(u1.x.array[: self.n_owned * bs].reshape(-1, bs))

    def regions(self, mesh):
        """The named regions of ``mesh`` (the :class:`sorofem.mesh.Mesh` of this space) in the gathered
        numbering of :attr:`vertices` and :attr:`cells` (rank 0; None elsewhere): ``name -> ("facets", (n, k)
        vertex indices)`` (owned facets of every rank) or ``("cells", (n,) cell indices)``. Collective."""
        msh = mesh.dolfinx
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim, 0)
        msh.topology.create_connectivity(tdim - 1, 0)
        c2v, f2v = msh.topology.connectivity(tdim, 0), msh.topology.connectivity(tdim - 1, 0)
        n_cells = msh.topology.index_map(tdim).size_local + msh.topology.index_map(tdim).num_ghosts
        vertex_dof = np.full(msh.topology.index_map(0).size_local + msh.topology.index_map(0).num_ghosts, -1,
                             dtype=np.int64)
        # P1: a cell's dofs follow its vertices in reference order
        vertex_dof[c2v.array.reshape(n_cells, -1)] = _dolfinx.cell_dofs(self.V1, n_cells)
        facet_vertices = f2v.array.reshape(-1, len(f2v.links(0))) if len(f2v.array) else np.zeros((0, tdim), int)
        n_owned = msh.topology.index_map(tdim).size_local
        first_cell = msh.comm.exscan(n_owned) or 0
        n_owned_facets = msh.topology.index_map(tdim - 1).size_local
        local = {}
        for name in mesh.regions:
            try:
                facets = mesh.facets(name)
            except MeshError:
                cells = mesh.cells(name)
                local[name] = ("cells", (cells[cells < n_owned] + first_cell).astype(np.int64))
                continue
            facets = facets[facets < n_owned_facets]
            local[name] = ("facets", self.local_to_global[vertex_dof[facet_vertices[facets]]])
        parts = msh.comm.gather(local, root=0)
        if parts is None:
            return None
        out = {}
        for name in mesh.regions:
            kind = parts[0][name][0]
            arrays = [p[name][1] for p in parts if len(p[name][1])]
            out[name] = (kind, np.concatenate(arrays) if arrays else parts[0][name][1])
        return out


class Trajectory:
    """Converged states of a solve: load levels or times, vertex displacements and per-step scalars.

    Attributes (every rank unless noted)
    ----------
    times : (n_steps,) array
        Load parameter or time of each state (the first is the initial state).
    displacement : (n_steps, n_vertices, gdim) array [m], rank 0 only (None elsewhere)
    vertices, cells : reference vertex coordinates [m] and linear connectivity, rank 0 only
    cell_type : str
    inputs : dict name -> (n_steps,) array of the load values applied (pressures [Pa], ...)
    cavity_volumes : dict name -> (n_steps,) array [m^3]; in plane strain, area per unit depth [m^2]
    reactions : dict support region -> (n_steps, gdim) array: the force [N] the support exerts on the body
        (plane strain: [N/m])
    von_mises : (n_steps, n_cells) array [Pa], rank 0 only; max_von_mises : (n_steps,) array [Pa]
    energy : (n_steps,) strain energy [J] (plane strain: [J/m]); kinetic_energy : (n_steps,) [J]
    newton_iterations : (n_steps,) int
    lowest_eigenvalue : list of float [1/s^2], filled when solved with ``monitor_stability=True``
    metadata : dict
    regions : dict name -> (kind, indices), rank 0 only: the mesh's named regions in the vertex/cell numbering
        of :attr:`vertices`/:attr:`cells` (see :class:`sorofem.snapshots.SnapshotWriter`)
    cavities : tuple of str, the names of the cavities among the regions
    """

    def __init__(self, vertices, cells, cell_type, time_kind="load", metadata=None, comm=None, regions=None,
                 cavities=()):
        from mpi4py import MPI

        self.comm = comm or MPI.COMM_WORLD  # the mesh's communicator: its rank 0 holds the gathered fields
        self.vertices, self.cells, self.cell_type = vertices, cells, cell_type
        self.regions, self.cavities = regions, tuple(cavities)
        self.time_kind = time_kind
        self.metadata = dict(metadata or {})
        self._times, self._u, self._iters, self._energy = [], [], [], []
        self._inputs, self._volumes, self._reactions = {}, {}, {}
        self.lowest_eigenvalue = []
        self._vm, self._vm_max, self._kinetic = [], [], []
        self._areas = {}

    def append(self, t, u_vertices, iterations, energy, inputs, volumes, reactions, von_mises=None,
               max_von_mises=0.0, kinetic=0.0, contact_areas=None):
        self._times.append(float(t))
        for k, v in (contact_areas or {}).items():
            self._areas.setdefault(k, []).append(float(v))
        self._kinetic.append(float(kinetic))
        self._vm.append(von_mises)
        self._vm_max.append(float(max_von_mises))
        self._u.append(u_vertices)
        self._iters.append(int(iterations))
        self._energy.append(float(energy))
        for store, data in ((self._inputs, inputs), (self._volumes, volumes), (self._reactions, reactions)):
            for k, v in data.items():
                store.setdefault(k, []).append(np.asarray(v, dtype=float))

    def __len__(self):
        return len(self._times)

    @property
    def times(self):
        return np.array(self._times)

    @property
    def displacement(self):
        return None if self._u[0] is None else np.array(self._u)

    @property
    def von_mises(self):
        """(n_steps, n_cells) von Mises stress per cell [Pa] (rank 0; cell order of :attr:`cells`)."""
        return None if self._vm[0] is None else np.array(self._vm)

    @property
    def max_von_mises(self):
        """(n_steps,) largest cell von Mises stress [Pa]."""
        return np.array(self._vm_max)

    @property
    def contact_areas(self):
        """dict contact name -> (n_steps,) contact area [m^2] (plane strain: [m] per m of depth)."""
        return {k: np.array(v) for k, v in self._areas.items()}

    @property
    def kinetic_energy(self):
        """(n_steps,) kinetic energy [J] (zero for quasi-static solves)."""
        return np.array(self._kinetic)

    @property
    def newton_iterations(self):
        return np.array(self._iters)

    @property
    def energy(self):
        return np.array(self._energy)

    @property
    def inputs(self):
        return {k: np.array(v) for k, v in self._inputs.items()}

    @property
    def cavity_volumes(self):
        return {k: np.array(v) for k, v in self._volumes.items()}

    @property
    def reactions(self):
        return {k: np.array(v) for k, v in self._reactions.items()}

    _MESHIO = {"triangle": "triangle", "quadrilateral": "quad", "tetrahedron": "tetra", "hexahedron": "hexahedron"}
    # DOLFINx orders quadrilateral/hexahedron vertices lexicographically; VTK/XDMF go around the faces
    _TO_VTK = {"quadrilateral": [0, 1, 3, 2], "hexahedron": [0, 1, 3, 2, 4, 5, 7, 6]}

    def _rank0_cells_vtk(self):
        order = self._TO_VTK.get(self.cell_type)
        return self.cells if order is None else self.cells[:, order]

    #: Units of the fields written by :meth:`write_xdmf`.
    XDMF_UNITS = {"displacement": "m", "von_mises": "Pa"}

    def write_xdmf(self, path):
        """Write every state to an XDMF time series for ParaView (rank 0 writes; call on every rank).

        ``path`` (``run.xdmf``) is the XML file; its arrays go to ``run.xdmf.h5`` beside it, a name that
        :meth:`save` (``run.h5``) never takes. Each step is a time stamp (``times``: the time [s] or the load
        level [-]) with point data ``displacement`` [m] as 3-component vectors (2D bodies get a zero z
        component, so ParaView's Warp By Vector applies) and cell data ``von_mises`` [Pa]; the units are
        recorded in the XML (``<Information Name="units">``, JSON) and on the HDF5 datasets (attribute
        ``unit``). Both files appear together, atomically. Readable by meshio's XDMF reader and ParaView."""
        path = Path(path)
        if path.suffix != ".xdmf":
            raise DataError(f"write_xdmf writes an .xdmf file (with its .xdmf.h5 data file beside it), got {path}")

        def write():
            import json
            import xml.etree.ElementTree as ET

            import meshio

            path.parent.mkdir(parents=True, exist_ok=True)
            tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.stem}.", dir=path.parent))
            try:
                cells = [(self._MESHIO[self.cell_type], self._rank0_cells_vtk())]
                # meshio 5 writes <stem>.h5 into the working directory: a file named run.xdmf.xdmf there
                # writes run.xdmf.h5; the XML is renamed to run.xdmf afterwards (it names its data file)
                with contextlib.chdir(tmpdir), meshio.xdmf.TimeSeriesWriter(path.name + ".xdmf") as w:
                    w.write_points_cells(_pad3(self.vertices), cells)
                    for i, t in enumerate(self._times):
                        cell_data = {} if self._vm[i] is None else {"von_mises": [self._vm[i]]}
                        w.write_data(t, point_data={"displacement": _pad3(self._u[i])}, cell_data=cell_data)
                xml, data = tmpdir / (path.name + ".xdmf"), tmpdir / (path.name + ".h5")
                ET.register_namespace("xi", "http://www.w3.org/2003/XInclude")   # keep meshio's prefix
                tree = ET.parse(xml)
                ET.SubElement(tree.getroot().find("Domain"), "Information", Name="units",
                              Value=json.dumps({"time": "s" if self.time_kind == "time" else "1",
                                                **self.XDMF_UNITS}))
                tree.write(xml)
                _label_xdmf_data(xml, data, self.XDMF_UNITS)
                os.replace(data, path.parent / data.name)   # the data first: the XML then finds it
                os.replace(xml, path)
            finally:
                shutil.rmtree(tmpdir, ignore_errors=True)

        on_root(self.comm, write)
        return path

    def plot(self, path, step=-1, field="von_mises", scale=1.0, title=None):
        """PNG of the deformed body at ``step`` coloured by ``field`` (``"von_mises"`` [kPa] or
        ``"displacement"`` magnitude [mm]); 2D: filled cells, 3D: boundary faces. Rank 0 draws."""
        if self.comm.rank != 0:
            return path
        from matplotlib.collections import PolyCollection
        from matplotlib.figure import Figure   # drawn without pyplot: the process's backend stays as it is

        from ..io import atomic_path

        u = self._u[step]
        x = self.vertices + scale * u
        if field == "von_mises":
            values, label = np.asarray(self._vm[step]) / 1e3, "von Mises stress [kPa]"
        elif field == "displacement":
            values, label = np.linalg.norm(u, axis=1)[self.cells].mean(axis=1) * 1e3, "|u| [mm]"
        else:
            raise ValueError(f"field must be 'von_mises' or 'displacement', got {field!r}")
        cells = self._rank0_cells_vtk()
        if x.shape[1] == 2:
            fig = Figure(figsize=(7, 4))
            ax = fig.subplots()
            pc = PolyCollection(x[cells] * 1e3, array=values, cmap="viridis", edgecolors="k", linewidths=0.1)
            ax.add_collection(pc)
            ax.autoscale()
            ax.set_aspect("equal")
            ax.set_xlabel("x [mm]")
            ax.set_ylabel("y [mm]")
        else:
            from mpl_toolkits.mplot3d.art3d import Poly3DCollection
            faces, owner = _boundary_faces(self.cell_type, cells)
            fig = Figure(figsize=(7, 5))
            ax = fig.add_subplot(projection="3d")
            pc = Poly3DCollection(x[faces] * 1e3, array=values[owner], cmap="viridis", edgecolors="k",
                                  linewidths=0.05)
            ax.add_collection3d(pc)
            lo, hi = x.min(axis=0) * 1e3, x.max(axis=0) * 1e3
            c, r = (lo + hi) / 2, (hi - lo).max() / 2
            ax.set(xlim=(c[0] - r, c[0] + r), ylim=(c[1] - r, c[1] + r), zlim=(c[2] - r, c[2] + r),
                   xlabel="x [mm]", ylabel="y [mm]", zlabel="z [mm]")
        fig.colorbar(pc, ax=ax, label=label, shrink=0.8)
        ax.set_title(title or f"t = {self._times[step]:.3g}")
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=130, format="png")
        return path

    def filmstrip(self, path, steps, floor=None, xlim=None, ylim=None, xlabel="x [mm]"):
        """PNG of a 2D body at several ``steps``, one panel each (deformed cells coloured by von Mises
        stress), stacked with a shared x axis: a gait or a motion at a glance. ``floor``: the height [m] of a
        line to draw (e.g. the ground); ``xlim``/``ylim`` [mm] (default: the body's extent per panel).
        Rank 0 draws."""
        if self.comm.rank != 0:
            return path
        if self.vertices.shape[1] != 2:
            raise ValueError("filmstrip draws 2D bodies; use plot() for 3D")
        from matplotlib.collections import PolyCollection
        from matplotlib.figure import Figure   # drawn without pyplot: the process's backend stays as it is

        from ..io import atomic_path

        steps = [int(k) for k in steps]
        cells = self._rank0_cells_vtk()
        from matplotlib.colors import Normalize

        fig = Figure(figsize=(7.6, 1.4 * len(steps)))
        axes = fig.subplots(len(steps), 1, sharex=True, squeeze=False)
        vm = [np.asarray(self._vm[k]) / 1e3 for k in steps]
        norm = Normalize(0.0, max(float(v.max(initial=0.0)) for v in vm) or 1.0)   # one scale for every panel
        for ax, k, values in zip(axes[:, 0], steps, vm):
            x = (self.vertices + self._u[k]) * 1e3
            pc = PolyCollection(x[cells], array=values, cmap="viridis", norm=norm, edgecolors="none")
            ax.add_collection(pc)
            if floor is not None:
                ax.axhline(floor * 1e3, color="k", lw=0.8)
            ax.set_xlim(xlim or (x[:, 0].min() - 5, x[:, 0].max() + 5))
            ax.set_ylim(ylim or (x[:, 1].min() - 2, x[:, 1].max() + 2))
            ax.set_aspect("equal")
            ax.set_ylabel(f"{self._times[k]:.3g} s", fontsize=8)
        axes[-1, 0].set_xlabel(xlabel)
        fig.tight_layout()
        fig.colorbar(pc, ax=axes[:, 0].tolist(), label="von Mises stress [kPa]", shrink=0.9)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
        return path

    def save(self, path, regions=None, cavities=None):
        """Write the trajectory as a snapshot file (see ``docs/snapshot-format.md``); rank 0 writes, every
        rank must call. Returns the path.

        ``regions``/``cavities``: default (None) the mesh's named regions and cavities that the solver
        recorded (:attr:`regions`, :attr:`cavities`); ``{}``/``()`` writes none."""
        if Path(path).name.endswith(".xdmf.h5"):
            raise DataError(f"{path} is the name of an XDMF data file (write_xdmf); save the snapshot under "
                            "another name, e.g. run.h5")

        def write():
            if not len(self):
                raise DataError("the trajectory is empty: nothing to save")
            regs = self.regions if regions is None else regions
            cavs = self.cavities if cavities is None else cavities
            per_depth = self.metadata.get("formulation") in ("plane_strain", "plane_stress")
            with SnapshotWriter(path, self.vertices, self.cells, self.cell_type, regions=regs,
                                cavities=cavs, metadata=self.metadata, time_kind=self.time_kind,
                                per_depth=per_depth) as w:
                for i in range(len(self)):
                    w.append(self._times[i], self._u[i],
                             inputs={k: v[i] for k, v in self._inputs.items()},
                             cavity_volumes={k: v[i] for k, v in self._volumes.items()},
                             reactions={k: v[i] for k, v in self._reactions.items()},
                             energies={"strain": self._energy[i], "kinetic": self._kinetic[i]},
                             cell_fields={"von_mises": self._vm[i]} if self._vm[i] is not None else None)

        on_root(self.comm, write)
        return path


def _pad3(a):
    """(n, 2) -> (n, 3) with zeros (ParaView warps and glyphs 3-component vectors only); (n, 3) unchanged."""
    a = np.asarray(a, dtype=float)
    return np.column_stack([a, np.zeros((len(a), 3 - a.shape[1]))]) if a.shape[1] < 3 else a


def _label_xdmf_data(xml, data, units):
    """Write the unit of every array of an XDMF data file as its HDF5 attribute ``unit`` (the XML names
    which field each array holds)."""
    import xml.etree.ElementTree as ET

    import h5py

    with h5py.File(data, "r+") as f:
        for att in ET.parse(xml).getroot().iter("Attribute"):
            item = att.find("DataItem")
            key = item.text.strip().split(":/")[-1] if item is not None and item.text else None
            if key in f and att.get("Name") in units:
                f[key].attrs["unit"] = units[att.get("Name")]
                f[key].attrs["field"] = att.get("Name")


_FACES = {"tetrahedron": [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
          "hexahedron": [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]}


def _boundary_faces(cell_type, cells_vtk):
    """Faces (VTK vertex order) that belong to one cell only, and the index of that cell."""
    local = np.array(_FACES[cell_type])
    faces = cells_vtk[:, local].reshape(-1, local.shape[1])
    owner = np.repeat(np.arange(len(cells_vtk)), len(local))
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse] == 1
    return faces[once], owner[once]
