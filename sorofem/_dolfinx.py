"""The one place that knows which DOLFINx is installed.

The platform runs on the DOLFINx that Debian ships: 0.5.2 (Debian 12, bookworm) and 0.9 (Debian 13, trixie).
Their Python APIs differ in a few dozen calls (legacy UFL elements were removed in 0.8, ``Function.vector``
became ``Function.x.petsc_vec``, dofmaps became 2D arrays, ``scale=`` became ``alpha=``, ...). Every call
whose spelling depends on the version goes through a function of this module; the rest of ``sorofem`` never
tests a version. Each function below names the two spellings it bridges.

The supported range is :data:`SUPPORTED` (oldest and newest ``(major, minor)`` tested); :func:`support_status`
says in words whether the installed version is in it (``soro doctor`` prints that line).

DOLFINx is imported lazily, inside each function: importing this module costs nothing.
"""
import functools

import numpy as np

__all__ = ["SUPPORTED", "version", "support_status", "create_mesh", "gmsh_node_order", "gmsh_facet_node_order",
           "geometry_degree", "geometry_dofs", "cell_dofs", "entity_vertex_nodes", "function_space",
           "mixed_space", "interpolation_points", "petsc_vec", "set_bc", "apply_lifting",
           "create_petsc_vector", "orthonormalize", "colliding_cells", "write_meshtags", "set_jit_timeout"]

#: Oldest and newest DOLFINx ``(major, minor)`` that the test suite runs on (Debian 12 and Debian 13).
SUPPORTED = ((0, 5), (0, 9))


@functools.lru_cache(maxsize=None)
def version():
    """The installed DOLFINx version as ``(major, minor, patch)`` integers (e.g. ``(0, 9, 0)``)."""
    import dolfinx

    parts = []
    for p in dolfinx.__version__.split(".")[:3]:
        digits = "".join(c for c in p if c.isdigit())
        parts.append(int(digits) if digits else 0)
    return tuple(parts + [0] * (3 - len(parts)))


def _at_least(minor):
    return version()[:2] >= (0, minor)


def support_status(found=None):
    """``(supported, sentence)`` for DOLFINx version ``found`` (a string; default: the installed one).

    >>> support_status("0.9.0")[0], support_status("0.5.2")[0], support_status("0.10.0")[0]
    (True, True, False)
    """
    if found is None:
        import dolfinx

        found = dolfinx.__version__
    try:
        key = tuple(int("".join(c for c in p if c.isdigit()) or 0) for p in str(found).split(".")[:2])
    except ValueError:
        key = (-1, -1)
    lo, hi = SUPPORTED
    span = f"{lo[0]}.{lo[1]} (Debian 12) to {hi[0]}.{hi[1]} (Debian 13)"
    if lo <= key <= hi:
        return True, f"DOLFINx {found} is supported (tested: {span})"
    if key > hi:
        return False, (f"DOLFINx {found} is newer than the tested range {span}: it may work, but is untested; "
                       "Debian 12 or 13 packages are the supported installs (README, 'Supported DOLFINx')")
    return False, (f"DOLFINx {found} is older than the supported range {span}; install Debian's python3-dolfinx "
                   "(bash scripts/bootstrap.sh)")


# ------------------------------------------------------------------------------------------------- meshes


def _cell_type(name):
    import dolfinx.mesh

    return getattr(dolfinx.mesh.CellType, name)


def create_mesh(comm, cells, x, cell_name, degree):
    """A distributed mesh from cells (DOLFINx node order, int64) and coordinates ``x`` (n, gdim) [m].

    The coordinate element is Lagrange of ``degree`` with equispaced nodes (gmsh's). 0.5: a legacy
    ``ufl.VectorElement`` on ``ufl.Cell(name, geometric_dimension=gdim)``; 0.8+: a ``basix.ufl`` element
    with ``shape=(gdim,)`` (the legacy elements are gone).
    """
    import dolfinx.mesh
    import ufl

    gdim = x.shape[1]
    if _at_least(8):
        import basix
        import basix.ufl

        el = basix.ufl.element("Lagrange", cell_name, degree, lagrange_variant=basix.LagrangeVariant.equispaced,
                               shape=(gdim,))
        domain = ufl.Mesh(el)
    else:
        cell = ufl.Cell(cell_name, geometric_dimension=gdim)
        domain = ufl.Mesh(ufl.VectorElement(ufl.FiniteElement("Lagrange", cell, degree, variant="equispaced")))
    return dolfinx.mesh.create_mesh(comm, cells, x, domain)


def gmsh_node_order(cell_name, num_nodes):
    """Permutation ``p`` with ``dolfinx_cells = gmsh_cells[:, p]`` for a cell of ``num_nodes`` nodes.

    0.5: ``dolfinx.cpp.io.perm_gmsh``; 0.6+: ``dolfinx.io.gmshio.cell_perm_array``.
    """
    if _at_least(6):
        from dolfinx.io import gmshio

        return np.asarray(gmshio.cell_perm_array(_cell_type(cell_name), num_nodes))
    import dolfinx.cpp.io

    return np.asarray(dolfinx.cpp.io.perm_gmsh(_cell_type(cell_name), num_nodes))


def gmsh_facet_node_order(cell_name, num_facet_nodes):
    """The same permutation for the facets of a ``cell_name`` cell (the facet type of local facet 0)."""
    import dolfinx.cpp.mesh

    ftype = dolfinx.cpp.mesh.cell_entity_type(_cell_type(cell_name), _TDIM[cell_name] - 1, 0)
    return gmsh_node_order(ftype.name, num_facet_nodes)


_TDIM = {"interval": 1, "triangle": 2, "quadrilateral": 2, "tetrahedron": 3, "hexahedron": 3}


def geometry_degree(mesh):
    """Polynomial degree of the coordinate element (1 for straight cells, 2 for curved)."""
    return int(mesh.geometry.cmap.degree)


def _as_2d(adj, width=None):
    """A dofmap as a 2D array: 0.5 gives an ``AdjacencyList`` (``.array`` flat, fixed ``.offsets``), 0.8+ a
    2D ``ndarray`` already."""
    if isinstance(adj, np.ndarray):
        return adj if adj.ndim == 2 else adj.reshape(-1, width)
    arr = np.asarray(adj.array)
    w = width if width is not None else (int(adj.offsets[1]) if len(adj.offsets) > 1 else 0)
    return arr.reshape(-1, w) if w else arr.reshape(0, 0)


def geometry_dofs(mesh, num_cells=None):
    """Geometry node indices of the cells, ``(num_cells, nodes per cell)`` (ghosts included by default)."""
    g = _as_2d(mesh.geometry.dofmap)
    return g if num_cells is None else g[:num_cells]


def cell_dofs(V, num_cells=None):
    """Dofs (block indices) of the cells of function space ``V``, ``(num_cells, dofs per cell)``."""
    dm = V.dofmap
    a = _as_2d(dm.list, dm.dof_layout.num_dofs)
    return a if num_cells is None else a[:num_cells]


_VERTICES = {"point": 1, "interval": 2, "triangle": 3, "quadrilateral": 4, "tetrahedron": 4, "hexahedron": 8}


def entity_vertex_nodes(mesh, dim, entities):
    """Geometry node indices of the *vertices* of mesh entities of dimension ``dim``: ``(n, vertices per
    entity)``, in the entity's reference vertex order.

    0.5 (``dolfinx.cpp.mesh.entities_to_geometry`` on the C++ mesh) returns the vertex nodes only; 0.8+
    (``dolfinx.mesh.entities_to_geometry``) returns every node of the entity's closure, vertices first, so
    on curved (order 2) meshes the edge-midpoint nodes follow. Both are cut to the vertices here: a facet's
    vertex mean is then the same number on every version (the .msh region matching relies on it).
    """
    import dolfinx.cpp.mesh

    entities = np.asarray(entities, dtype=np.int32)
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(dim, tdim)  # 0.9 needs it, earlier versions build it
    etype = dolfinx.cpp.mesh.cell_entity_type(mesh.topology.cell_type, dim, 0) if dim < tdim else \
        mesh.topology.cell_type
    nv = _VERTICES[etype.name]
    if _at_least(8):
        import dolfinx.mesh

        nodes = dolfinx.mesh.entities_to_geometry(mesh, dim, entities, False)
    else:
        cpp_mesh = getattr(mesh, "_cpp_object", None) or getattr(mesh, "_mesh", mesh)
        nodes = dolfinx.cpp.mesh.entities_to_geometry(cpp_mesh, dim, entities, False)
    return np.asarray(nodes).reshape(len(entities), -1)[:, :nv]


# ------------------------------------------------------------------------------------------- function spaces


def _element(mesh, family, degree, shape=None):
    """A finite element on the mesh's cell: ``family`` "Lagrange" (continuous) or "DG" (discontinuous)."""
    disc = family in ("DG", "Discontinuous Lagrange")
    if _at_least(8):
        import basix.ufl

        return basix.ufl.element("Lagrange", mesh.topology.cell_type.name, degree, discontinuous=disc,
                                 shape=shape)
    import ufl

    cell = mesh.ufl_cell()
    fam = ("DQ" if cell.cellname() in ("quadrilateral", "hexahedron") else "DG") if disc else "Lagrange"
    if shape is None:
        return ufl.FiniteElement(fam, cell, degree)
    if len(shape) == 1:
        return ufl.VectorElement(fam, cell, degree, dim=shape[0])
    return ufl.TensorElement(fam, cell, degree, shape=shape)


def function_space(mesh, family, degree, shape=None):
    """A Lagrange (``"Lagrange"``) or discontinuous Lagrange (``"DG"``) space of ``degree`` on ``mesh``.

    ``shape`` is ``None`` for scalars, ``"vector"`` for vectors of the geometric dimension, or a tuple.
    0.5: ``fem.FunctionSpace``/``fem.VectorFunctionSpace``; 0.7+: ``fem.functionspace``.
    """
    import dolfinx.fem

    if shape == "vector":
        shape = (mesh.geometry.dim,)
    el = _element(mesh, family, degree, shape)
    if _at_least(7):
        return dolfinx.fem.functionspace(mesh, el)
    return dolfinx.fem.FunctionSpace(mesh, el)


def mixed_space(mesh, parts):
    """A mixed space of ``parts``, each ``(family, degree, shape)`` as for :func:`function_space`
    (e.g. ``[("Lagrange", 2, "vector"), ("Lagrange", 1, None)]``).

    0.5: ``ufl.MixedElement`` of legacy elements; 0.8+: ``basix.ufl.mixed_element``.
    """
    import dolfinx.fem

    els = [_element(mesh, fam, deg, (mesh.geometry.dim,) if shape == "vector" else shape)
           for fam, deg, shape in parts]
    if _at_least(8):
        import basix.ufl

        return dolfinx.fem.functionspace(mesh, basix.ufl.mixed_element(els))
    import ufl

    return dolfinx.fem.FunctionSpace(mesh, ufl.MixedElement(els))


def interpolation_points(V):
    """Reference interpolation points of ``V``'s element (a method in 0.5-0.8, a property in 0.9)."""
    pts = V.element.interpolation_points
    return np.asarray(pts() if callable(pts) else pts)


# ------------------------------------------------------------------------------------------------- PETSc


def petsc_vec(u):
    """The PETSc vector (owned and ghost entries) that wraps ``u.x``: ``u.vector`` in 0.5, ``u.x.petsc_vec``
    from 0.8."""
    if _at_least(8):
        return u.x.petsc_vec
    return u.vector


def set_bc(b, bcs, x0=None, alpha=1.0):
    """``b <- alpha (g - x0)`` on the Dirichlet rows (``scale=`` in 0.5, ``alpha=`` from 0.8)."""
    import dolfinx.fem.petsc

    if _at_least(8):
        dolfinx.fem.petsc.set_bc(b, bcs, x0, alpha=alpha)
    else:
        dolfinx.fem.petsc.set_bc(b, bcs, x0, scale=alpha)


def apply_lifting(b, forms, bcs, x0=(), alpha=1.0):
    """``b <- b - alpha A (g - x0)`` for the Dirichlet conditions (``scale=`` in 0.5, ``alpha=`` from 0.8)."""
    import dolfinx.fem.petsc

    kw = {"alpha" if _at_least(8) else "scale": alpha}
    dolfinx.fem.petsc.apply_lifting(b, list(forms), bcs=list(bcs), x0=list(x0), **kw)


def create_petsc_vector(index_map, bs):
    """A ghosted PETSc vector over ``index_map`` with block size ``bs``."""
    import dolfinx.la

    return dolfinx.la.create_petsc_vector(index_map, bs)


def orthonormalize(vectors):
    """Modified Gram-Schmidt on a list of PETSc vectors, in place (the DOLFINx helper changed its argument
    type from PETSc vectors to ``dolfinx.la.Vector`` in 0.8, so the platform keeps its own).

    Raises
    ------
    ValueError
        If a vector is (numerically) in the span of the previous ones.
    """
    for i, v in enumerate(vectors):
        for q in vectors[:i]:
            v.axpy(-v.dot(q), q)
        norm = v.norm()
        if not norm > 1e-12:
            raise ValueError(f"vector {i} is linearly dependent on the previous ones (norm {norm:.3g} after "
                             "projection)")
        v.scale(1.0 / norm)


# ------------------------------------------------------------------------------------------------- geometry


def colliding_cells(mesh, points):
    """For points (N, 3) [m]: an adjacency list whose row ``i`` lists local cells containing point ``i``.

    0.5: ``geometry.BoundingBoxTree`` + ``compute_collisions``; 0.7+: ``geometry.bb_tree`` +
    ``compute_collisions_points``.
    """
    import dolfinx.geometry as geo

    tdim = mesh.topology.dim
    points = np.ascontiguousarray(points, dtype=np.float64)
    if _at_least(7):
        tree = geo.bb_tree(mesh, tdim)
        candidates = geo.compute_collisions_points(tree, points)
    else:
        tree = geo.BoundingBoxTree(mesh, tdim)
        candidates = geo.compute_collisions(tree, points)
    return geo.compute_colliding_cells(mesh, candidates, points)


# ------------------------------------------------------------------------------------------------- I/O, JIT


def write_meshtags(xdmf, tags, mesh):
    """Write ``tags`` to an open ``XDMFFile`` (0.7+ also needs the mesh geometry)."""
    if _at_least(7):
        xdmf.write_meshtags(tags, mesh.geometry)
    else:
        xdmf.write_meshtags(tags)


def set_jit_timeout(seconds):
    """Raise DOLFINx's form-compilation lock timeout to at least ``seconds`` (many MPI ranks compiling the same
    form wait on one lock). The defaults dict is ``DOLFINX_DEFAULT_JIT_PARAMETERS`` in 0.5 and
    ``DOLFINX_DEFAULT_JIT_OPTIONS`` from 0.6."""
    import dolfinx.jit

    defaults = getattr(dolfinx.jit, "DOLFINX_DEFAULT_JIT_OPTIONS" if _at_least(6) else
                       "DOLFINX_DEFAULT_JIT_PARAMETERS")
    value, doc = defaults["timeout"]
    if value < seconds:
        defaults["timeout"] = (seconds, doc)
