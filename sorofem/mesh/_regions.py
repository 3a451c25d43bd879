"""Named regions of a distributed DOLFINx mesh: bounding-box sides, cavities, user selections, quality.

All functions here are collective over the mesh communicator and work on each rank's local entities
(owned and ghost), so that integrals over the resulting tags are right in parallel.

Cavities. The boundary of a meshed solid splits into connected components (facets sharing a vertex). For a
component :math:`\\Gamma_k` with the solid's outward normal :math:`n`, the signed enclosed measure is

.. math:: V_k = \\frac{1}{d} \\int_{\\Gamma_k} x \\cdot n \\, ds ,

positive for the outer boundary of a body and equal to minus the enclosed volume (area in 2D) for a closed
inner boundary, i.e. a cavity. On a flat facet :math:`x \\cdot n` is constant, so the integral is exact for
linear facets. Components are found on rank 0 from the gathered boundary facets (global vertex numbers).
"""
import numpy as np

from .. import _dolfinx
from ..errors import MeshError

__all__ = ["exterior_facets", "facet_geometry", "sides", "cavities", "select", "quality"]


def exterior_facets(mesh):
    """Local indices of the exterior (boundary) facets of ``mesh``."""
    import dolfinx.mesh

    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    return np.asarray(dolfinx.mesh.exterior_facet_indices(mesh.topology), dtype=np.int32)


def _entity_vertex_coords(mesh, dim, entities):
    nodes = _dolfinx.entity_vertex_nodes(mesh, dim, entities)
    gdim = mesh.geometry.dim
    return mesh.geometry.x[:, :gdim][nodes]  # (n, nv, gdim)


def facet_geometry(mesh, facets):
    """Vertex coordinates (nf, nv, gdim), midpoints, measures and outward unit normals of exterior facets."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    X = _entity_vertex_coords(mesh, tdim - 1, facets)
    mid = X.mean(axis=1)
    if gdim == 2:
        t = X[:, 1] - X[:, 0]
        measure = np.linalg.norm(t, axis=1)
        n = np.column_stack([t[:, 1], -t[:, 0]])
    else:
        if X.shape[1] == 3:
            n = 0.5 * np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
        else:  # quadrilateral facet, vertices in tensor order 0,1,2,3 → diagonals 0-3 and 1-2
            n = 0.5 * np.cross(X[:, 3] - X[:, 0], X[:, 2] - X[:, 1])
        measure = np.linalg.norm(n, axis=1)
        n = n * 2.0 if X.shape[1] == 3 else n
    n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    # orient away from the adjacent cell's centroid
    if len(facets):
        mesh.topology.create_connectivity(tdim - 1, tdim)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        cells = np.array([f2c.links(f)[0] for f in facets], dtype=np.int32)
        cc = _entity_vertex_coords(mesh, tdim, cells).mean(axis=1)
        flip = np.einsum("ij,ij->i", n, mid - cc) < 0
        n[flip] *= -1.0
    return X, mid, measure, n


def global_bbox(mesh):
    """Global (lo, hi) of the mesh nodes."""
    from mpi4py import MPI

    gdim = mesh.geometry.dim
    x = mesh.geometry.x[:, :gdim]
    lo = x.min(axis=0) if len(x) else np.full(gdim, np.inf)
    hi = x.max(axis=0) if len(x) else np.full(gdim, -np.inf)
    comm = mesh.comm
    glo, ghi = np.empty(gdim), np.empty(gdim)
    comm.Allreduce(np.ascontiguousarray(lo, dtype=float), glo, op=MPI.MIN)
    comm.Allreduce(np.ascontiguousarray(hi, dtype=float), ghi, op=MPI.MAX)
    return glo, ghi


def sides(mesh, facets, X, tol):
    """Boundary facets at the extremes of the global bounding box, within ``tol`` [m].

    Returns ``{name: local facet indices}`` for left/right (x), bottom/top (y in 2D, z in 3D) and
    front/back (y in 3D).
    """
    lo, hi = global_bbox(mesh)
    gdim = mesh.geometry.dim
    names = [("left", "right"), ("bottom", "top")] if gdim == 2 else \
        [("left", "right"), ("front", "back"), ("bottom", "top")]
    out = {}
    for axis, (nlo, nhi) in enumerate(names):
        c = X[:, :, axis] if len(facets) else np.zeros((0, 1))
        out[nlo] = facets[np.all(c <= lo[axis] + tol, axis=1)]
        out[nhi] = facets[np.all(c >= hi[axis] - tol, axis=1)]
    return out


def cavities(mesh, facets, X, measure, normal, tol):
    """Closed inner boundaries (cavities) of the mesh, ordered by centroid x, then y, then z.

    Returns a list of local facet index arrays, one per cavity.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    imap = mesh.topology.index_map(tdim - 1)
    owned = facets < imap.size_local
    mesh.topology.create_connectivity(tdim - 1, 0)
    f2v = mesh.topology.connectivity(tdim - 1, 0)
    verts = np.array([f2v.links(f) for f in facets], dtype=np.int32).reshape(len(facets), -1)
    gverts = mesh.topology.index_map(0).local_to_global(verts.ravel()).reshape(verts.shape) if len(facets) else \
        np.zeros((0, tdim), dtype=np.int64)
    mid = X.mean(axis=1) if len(facets) else np.zeros((0, gdim))
    contrib = np.where(owned, np.einsum("ij,ij->i", mid, normal) * measure / gdim, 0.0) if len(facets) else \
        np.zeros(0)
    wmid = np.where(owned[:, None], mid * measure[:, None], 0.0) if len(facets) else np.zeros((0, gdim))
    wm = np.where(owned, measure, 0.0) if len(facets) else np.zeros(0)
    data = comm.gather((gverts, contrib, wmid, wm), root=0)
    labels_per_rank = None
    if comm.rank == 0:
        counts = [len(d[0]) for d in data]
        gv = np.vstack([d[0] for d in data]) if sum(counts) else np.zeros((0, tdim), dtype=np.int64)
        c = np.concatenate([d[1] for d in data])
        w = np.vstack([d[2] for d in data]) if sum(counts) else np.zeros((0, gdim))
        m = np.concatenate([d[3] for d in data])
        nf = len(gv)
        label = np.full(nf, -1)
        if nf:
            uv, inv = np.unique(gv.ravel(), return_inverse=True)
            rows = np.repeat(np.arange(nf), gv.shape[1])
            g = coo_matrix((np.ones(len(rows)), (rows, nf + inv)), shape=(nf + len(uv), nf + len(uv)))
            ncomp, comp = connected_components(g, directed=False)
            comp = comp[:nf]
            V = np.bincount(comp, weights=c, minlength=ncomp)
            A = np.bincount(comp, weights=m, minlength=ncomp)
            C = np.column_stack([np.bincount(comp, weights=w[:, k], minlength=ncomp) for k in range(gdim)])
            C = C / np.maximum(A, 1e-300)[:, None]
            scale = max(float(np.abs(V).max()), 1e-300)
            cav = [k for k in range(ncomp) if V[k] < -1e-9 * scale]
            key = lambda k: tuple(np.round(C[k] / tol).astype(np.int64))  # noqa: E731
            cav.sort(key=key)
            remap = np.full(ncomp, -1)
            remap[cav] = np.arange(len(cav))
            label = remap[comp]
        offsets = np.concatenate([[0], np.cumsum(counts)])
        labels_per_rank = [(label[offsets[r]:offsets[r + 1]], int(label.max(initial=-1)) + 1)
                           for r in range(comm.size)]
    mine, n = comm.scatter(labels_per_rank, root=0)
    return [facets[mine == k] for k in range(n)]


def select(mesh, dim, entities, where, tol=0.0):
    """Entities (local indices) whose midpoint satisfies ``where``.

    ``where`` is a box ``(lo, hi)`` [m], a shape with ``.bounds`` (selected where ``shape(x) <= tol``) or a
    predicate ``f(x) -> bool array`` on coordinates ``x`` of shape ``(gdim, N)`` (DOLFINx's convention).
    """
    import dolfinx.mesh

    gdim = mesh.geometry.dim
    entities = np.asarray(entities, dtype=np.int32)
    mid = dolfinx.mesh.compute_midpoints(mesh, dim, entities)[:, :gdim] if len(entities) else np.zeros((0, gdim))
    if hasattr(where, "bounds") and callable(where):
        if getattr(where, "dim", gdim) != gdim:
            raise MeshError(f"a {where.dim}D shape cannot select entities of a {gdim}D mesh")
        keep = np.asarray(where(mid), dtype=float) <= tol if len(mid) else np.zeros(0, dtype=bool)
    elif callable(where):
        keep = np.asarray(where(mid.T.copy()), dtype=bool).reshape(-1) if len(mid) else np.zeros(0, dtype=bool)
        if keep.shape != (len(mid),):
            raise MeshError(f"the region predicate returned shape {keep.shape}; it must return one bool per point "
                            "of its (gdim, N) argument")
    else:
        try:
            lo, hi = (np.asarray(b, dtype=float).reshape(-1) for b in where)
        except (TypeError, ValueError):
            raise MeshError("a region must be a box (lo, hi), a shape (SDF) or a predicate f(x) on (gdim, N) "
                            f"coordinates; got {type(where).__name__}") from None
        if lo.shape != (gdim,) or hi.shape != (gdim,):
            raise MeshError(f"a region box needs two corners of {gdim} coordinates, got {lo.tolist()}, {hi.tolist()}")
        keep = np.all((mid >= lo - tol) & (mid <= hi + tol), axis=1)
    return entities[keep]


def _basix_cell(name):
    import basix

    return {"triangle": basix.CellType.triangle, "quadrilateral": basix.CellType.quadrilateral,
            "tetrahedron": basix.CellType.tetrahedron, "hexahedron": basix.CellType.hexahedron}[name]


def quality(mesh):
    """Collective quality figures of ``mesh`` (angles in degrees, lengths in metres).

    Minimum angle: smallest corner angle of triangles/quadrilaterals, smallest dihedral angle of tetrahedra,
    smallest face-corner angle of hexahedra. Aspect ratio: circumradius / (d * inradius) for simplices (1 for
    the regular simplex), longest / shortest edge otherwise. A cell is *inverted* when the Jacobian determinant
    of its coordinate map changes sign between its vertices and centre, *degenerate* when it is below
    1e-10 h^d.
    """
    import basix
    from mpi4py import MPI

    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    name = mesh.topology.cell_type.name
    ncell = mesh.topology.index_map(tdim).size_local
    nvert = mesh.topology.index_map(0).size_local
    geo = np.asarray(_dolfinx.geometry_dofs(mesh, ncell), dtype=np.int64) if ncell else \
        np.zeros((0, 1), dtype=np.int64)
    ndofs = geo.shape[1] if ncell else 0
    x = mesh.geometry.x[:, :gdim]
    degree = _dolfinx.geometry_degree(mesh)
    bcell = _basix_cell(name)
    nv = {"triangle": 3, "quadrilateral": 4, "tetrahedron": 4, "hexahedron": 8}[name]
    V = x[geo[:, :nv]] if ncell else np.zeros((0, nv, gdim))
    ref = basix.geometry(bcell)
    edges = np.array(basix.topology(bcell)[1])
    E = V[:, edges[:, 1]] - V[:, edges[:, 0]]
    elen = np.linalg.norm(E, axis=2)
    hmin_c = elen.min(axis=1) if ncell else np.zeros(0)
    hmax_c = elen.max(axis=1) if ncell else np.zeros(0)
    # Jacobian determinants at the vertices and the midpoint
    pts = np.vstack([ref, ref.mean(axis=0)])
    el = basix.create_element(basix.ElementFamily.P, bcell, degree, basix.LagrangeVariant.gll_warped)
    dphi = el.tabulate(1, pts)[1:, :, :, 0]  # (tdim, npts, ndofs)
    Xc = x[geo] if ncell else np.zeros((0, ndofs, gdim))
    J = np.einsum("dpn,cng->cpgd", dphi, Xc)  # (cells, pts, gdim, tdim)
    if gdim == tdim:
        detJ = np.linalg.det(J) if ncell else np.zeros((0, len(pts)))
    else:
        detJ = np.sqrt(np.linalg.det(np.einsum("cpgd,cpge->cpde", J, J))) if ncell else np.zeros((0, len(pts)))
    scale = np.maximum(hmax_c, 1e-300) ** tdim
    degenerate = np.abs(detJ).min(axis=1) <= 1e-10 * scale if ncell else np.zeros(0, dtype=bool)
    inverted = np.any(np.sign(detJ) != np.sign(detJ[:, -1:]), axis=1) & ~degenerate if ncell else \
        np.zeros(0, dtype=bool)
    # angles and aspect ratios on the corner (linear) geometry
    def ang(a, b):
        c = np.einsum("...i,...i", a, b) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-300)
        return np.degrees(np.arccos(np.clip(c, -1, 1)))

    if ncell == 0:
        minang, aspect = np.zeros(0), np.zeros(0)
    elif name == "triangle":
        a = [ang(V[:, (i + 1) % 3] - V[:, i], V[:, (i + 2) % 3] - V[:, i]) for i in range(3)]
        minang = np.min(a, axis=0)
        la, lb, lc = (np.linalg.norm(V[:, (i + 1) % 3] - V[:, i], axis=1) for i in range(3))
        s = 0.5 * (la + lb + lc)
        area = np.sqrt(np.maximum(s * (s - la) * (s - lb) * (s - lc), 0.0))
        r_in = area / np.maximum(s, 1e-300)
        with np.errstate(divide="ignore", over="ignore"):  # degenerate cells get an infinite aspect ratio
            R = la * lb * lc / np.maximum(4 * area, 1e-300)
            aspect = R / np.maximum(2 * r_in, 1e-300)
    elif name == "tetrahedron":
        faces = [(1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)]
        normals = [np.cross(V[:, f[1]] - V[:, f[0]], V[:, f[2]] - V[:, f[0]]) for f in faces]
        farea = [0.5 * np.linalg.norm(nrm, axis=1) for nrm in normals]
        dih = []
        for i in range(4):
            for j in range(i + 1, 4):
                dih.append(180.0 - ang(normals[i] * np.sign(np.einsum("ij,ij->i", normals[i], V[:, i] - V[:, faces[i][0]]))[:, None],
                                       normals[j] * np.sign(np.einsum("ij,ij->i", normals[j], V[:, j] - V[:, faces[j][0]]))[:, None]))
        minang = np.min(dih, axis=0)
        vol = np.abs(np.einsum("ij,ij->i", V[:, 1] - V[:, 0], np.cross(V[:, 2] - V[:, 0], V[:, 3] - V[:, 0]))) / 6
        r_in = 3 * vol / np.maximum(np.sum(farea, axis=0), 1e-300)
        a, b, c = (V[:, k] - V[:, 0] for k in (1, 2, 3))
        num = (np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c) + np.einsum("ij,ij->i", b, b)[:, None]
               * np.cross(c, a) + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b))
        R = np.linalg.norm(num, axis=1) / np.maximum(12 * vol, 1e-300)
        aspect = R / np.maximum(3 * r_in, 1e-300)
    else:
        # corner angles between edges meeting at each vertex (tensor-product cells)
        angs = []
        for v in range(nv):
            inc = [e for e in edges if v in e]
            vecs = [V[:, e[1] if e[0] == v else e[0]] - V[:, v] for e in inc]
            for i in range(len(vecs)):
                for j in range(i + 1, len(vecs)):
                    angs.append(ang(vecs[i], vecs[j]))
        minang = np.min(angs, axis=0)
        aspect = hmax_c / np.maximum(hmin_c, 1e-300)
    red = lambda v, op, empty: comm.allreduce(float(op(v)) if len(v) else empty, op=MPI.MIN if op is np.min else MPI.MAX)  # noqa: E731
    return {
        "cell": name,
        "degree": int(degree),
        "num_cells": int(comm.allreduce(ncell)),
        "num_vertices": int(comm.allreduce(nvert)),
        "min_angle": red(minang, np.min, np.inf),
        "max_aspect_ratio": red(aspect, np.max, 0.0),
        "h_min": red(hmin_c, np.min, np.inf),
        "h_max": red(hmax_c, np.max, 0.0),
        "degenerate": int(comm.allreduce(int(np.count_nonzero(degenerate)))),
        "inverted": int(comm.allreduce(int(np.count_nonzero(inverted)))),
    }
