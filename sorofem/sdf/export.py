"""Export: triangle meshes and binary STL of 3D solids (marching cubes), PNG previews of 2D regions and of
plane slices of 3D solids. scikit-image and matplotlib are imported only when these functions run.

STL files carry no unit, and slicers read millimetres. :func:`write_stl` is the one STL writer of the code
base (every other exporter calls it): it scales the SI coordinates [m] to the requested length unit (default
``"mm"``, what a printer needs) and names that unit in the 80-byte header (``... units: mm``);
:func:`read_stl` reads the unit back and returns metres. Both are plain numpy (no ``meshio``/``numpy-stl``:
the binary format is 50 bytes per triangle and a numpy record type writes it in one call).
"""
import math
import re
from pathlib import Path

import numpy as np

from ..errors import GeometryError
from ..io import atomic_path

__all__ = ["to_mesh", "to_stl", "write_stl", "read_stl", "stl_units", "surface_check", "to_png",
           "DEFAULT_STL_CELLS", "STL_UNITS"]

#: Length units an STL file can be written in: name -> metres per file unit.
STL_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}
_STL_RECORD = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_UNIT_RE = re.compile(rb"units:\s*([A-Za-z]+)")


def _unit_scale(units):
    if units not in STL_UNITS:
        raise GeometryError(f"units must be one of {sorted(STL_UNITS)} (the length unit of the STL "
                            f"coordinates; slicers expect 'mm'), got {units!r}")
    return STL_UNITS[units]

#: Default number of marching-cubes cells over the (padded) bounds.
DEFAULT_STL_CELLS = 1 << 21


def _grid_step(lo, hi, cells, resolution):
    if resolution is None:
        return float((np.prod(hi - lo) / cells) ** (1.0 / len(lo)))
    h = float(resolution)
    if not (math.isfinite(h) and h > 0):
        raise GeometryError(f"resolution must be a positive grid step [m], got {resolution!r}")
    return h


def _bounded(shape, what):
    lo, hi = shape.bounds
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GeometryError(f"cannot {what} an unbounded shape ({shape.op}); intersect it with a Box first")
    if np.any(hi <= lo):
        raise GeometryError(f"cannot {what}: the shape is empty (bounds lo={lo}, hi={hi}); check that "
                            "intersected shapes overlap")
    return lo, hi


def to_mesh(shape, resolution=None):
    """Triangulate the zero level set of a 3D solid with marching cubes.

    The grid covers the conservative bounds padded by two cells, so the surface is closed (watertight);
    triangles are oriented with outward normals (positive signed volume).

    Parameters
    ----------
    shape : SDF (3D)
    resolution : float, optional
        Grid step [m]; default: about ``DEFAULT_STL_CELLS`` cells over the bounds.

    Returns
    -------
    vertices : (V, 3) float array [m]
    faces : (F, 3) int array (counter-clockwise seen from outside)
    """
    if shape.dim != 3:
        raise GeometryError(f"to_mesh/to_stl need a 3D solid, got a {shape.dim}D shape; extrude() or "
                            "revolve() it first, or use to_png() for a 2D preview")
    lo, hi = _bounded(shape, "mesh")
    h = _grid_step(lo, hi, DEFAULT_STL_CELLS, resolution)
    n = np.ceil((hi - lo) / h).astype(int) + 5
    if np.prod(n.astype(float)) > 3e8:
        raise GeometryError(f"resolution {h:g} m gives {np.prod(n.astype(float)):.3g} grid points; use a "
                            "coarser resolution")
    origin = lo - 2 * h
    axes = [origin[i] + h * np.arange(n[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    vol = shape(pts).reshape(n)
    del pts
    if not np.any(vol < 0):
        raise GeometryError(f"the shape ({shape.op}) is empty at grid step {h:g} m: no grid point is inside; "
                            "check that intersected shapes overlap, or pass a finer resolution")
    # keep the level set off the grid nodes: a node on (or within rounding of) the surface makes vertices
    # that coincide once written in float32, i.e. degenerate triangles and edges shared by four triangles
    # (faces of boxes aligned with the grid do this); moving the surface by 1e-3 h avoids it
    vol[np.abs(vol) < 1e-3 * h] = 1e-3 * h
    from skimage.measure import marching_cubes

    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=(h, h, h), allow_degenerate=False)
    verts = verts + origin
    faces = faces.astype(np.int64)
    tri = verts[faces]
    signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    if signed < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def to_stl(shape, path, resolution=None, units="mm"):
    """Write a binary STL of a 3D solid (marching cubes, watertight, outward normals), atomically.

    Parameters
    ----------
    shape : SDF (3D)
    path : str or Path
    resolution : float, optional
        Grid step [m] (default from the bounds, see :func:`to_mesh`).
    units : str
        Length unit of the file's coordinates (a key of :data:`STL_UNITS`; default ``"mm"``, what slicers
        read), named in the header.

    Returns
    -------
    Path
    """
    _unit_scale(units)
    verts, faces = to_mesh(shape, resolution)
    return write_stl(path, verts, faces, units=units, label="sorofem.sdf")


def write_stl(path, vertices, faces, units="mm", label="sorofem"):
    """Write triangles as a binary STL, atomically: the one STL writer of the code base.

    Parameters
    ----------
    path : str or Path
    vertices : (V, 3) float array [m]
    faces : (F, 3) int array
        Vertex indices, counter-clockwise seen from outside (the facet normals are computed from them).
    units : str
        Length unit of the written coordinates (a key of :data:`STL_UNITS`, default ``"mm"``); the
        coordinates are divided by its size in metres and the header ends with ``units: <units>``.
    label : str
        Start of the 80-byte header (ASCII, must not begin with ``solid``).

    Returns
    -------
    Path
    """
    scale = _unit_scale(units)
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise GeometryError(f"write_stl needs vertices (V, 3) and faces (F, 3), got {vertices.shape} and "
                            f"{faces.shape}")
    if not np.all(np.isfinite(vertices)):
        raise GeometryError("write_stl: the vertices hold NaN or inf; fix the geometry before exporting")
    header = f"{label} binary STL, units: {units}".encode("ascii")
    if len(header) > 80 or header.lower().startswith(b"solid"):
        raise GeometryError(f"STL label {label!r} is too long or starts with 'solid' (ASCII STL marker)")
    tri = vertices[faces] / scale
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    rec = np.zeros(len(faces), dtype=_STL_RECORD)
    rec["n"] = nrm / np.where(ln > 0, ln, 1.0)
    rec["v"] = tri
    with atomic_path(path, suffix=".stl") as tmp:
        with open(tmp, "wb") as f:
            f.write(header.ljust(80, b" "))
            f.write(np.uint32(len(faces)).tobytes())
            f.write(rec.tobytes())
    return Path(path)


def stl_units(path):
    """The length unit named in an STL file's header (``"mm"``, ``"m"``, ...), or None when it names none."""
    with open(path, "rb") as f:
        head = f.read(80)
    m = _UNIT_RE.search(head)
    if m is None:
        return None
    unit = m.group(1).decode("ascii")
    return unit if unit in STL_UNITS else None


def read_stl(path, units=None):
    """Read a binary STL -> (triangles (F, 3, 3) float64 [m], normals (F, 3) float64).

    Parameters
    ----------
    path : str or Path
    units : str, optional
        Length unit of the file's coordinates; default: the unit its header names (see :func:`write_stl`),
        else ``"mm"`` (what slicers and CAD tools assume for an STL without one).
    """
    data = Path(path).read_bytes()
    if len(data) < 84:
        raise GeometryError(f"{path} is not a binary STL (too short)")
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    if len(data) != 84 + 50 * n:
        raise GeometryError(f"{path}: binary STL header says {n} triangles but the file has {len(data)} bytes")
    scale = _unit_scale(units if units is not None else (stl_units(path) or "mm"))
    rec = np.frombuffer(data, _STL_RECORD, n, 84)
    return rec["v"].astype(float) * scale, rec["n"].astype(float)


def surface_check(triangles, tol=None):
    """Topology of a triangle soup, the checks a print-ready STL must pass.

    Vertices are merged when they coincide (within ``tol`` [m], default 1e-9 of the bounding-box
    diagonal); then every undirected edge is counted and the directed edges compared.

    Parameters
    ----------
    triangles : (F, 3, 3) float array [m]

    Returns
    -------
    dict
        ``triangles``, ``vertices``; ``boundary_edges`` (used by one triangle) and ``nonmanifold_edges`` (by
        more than two); ``misoriented_edges`` (a directed edge used twice: two neighbours disagree on the
        orientation); ``watertight`` (all three are zero); ``shells`` (connected components through shared
        edges); ``volume`` [m^3] (signed, positive for outward normals); ``lo``, ``hi`` [m] (bounding box).
    """
    tri = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    pts = tri.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    q = float(tol) if tol is not None else 1e-9 * max(float(np.linalg.norm(hi - lo)), 1e-300)
    keys = np.round((pts - lo) / q).astype(np.int64)
    _, vid = np.unique(keys, axis=0, return_inverse=True)
    f = vid.reshape(-1, 3)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    und = np.sort(directed, axis=1)
    _, eid, counts = np.unique(und, axis=0, return_inverse=True, return_counts=True)
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    # shells: connected components of the graph "triangles sharing an edge"
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    nf = len(f)
    tri_of = np.tile(np.arange(nf), 3)
    order = np.argsort(eid, kind="stable")
    e_sorted, t_sorted = eid[order], tri_of[order]
    same = np.flatnonzero(e_sorted[1:] == e_sorted[:-1])
    adj = coo_matrix((np.ones(len(same)), (t_sorted[same], t_sorted[same + 1])), shape=(nf, nf))
    shells = connected_components(adj, directed=False)[0] if nf else 0
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)
    out = {"triangles": int(nf), "vertices": int(vid.max() + 1) if nf else 0,
           "boundary_edges": int(np.sum(counts == 1)), "nonmanifold_edges": int(np.sum(counts > 2)),
           "misoriented_edges": int(np.sum(dcount > 1)), "shells": int(shells), "volume": volume,
           "lo": lo, "hi": hi}
    out["watertight"] = out["boundary_edges"] == out["nonmanifold_edges"] == out["misoriented_edges"] == 0
    return out


_PLANES = {"xy": (0, 1, 2), "yz": (1, 2, 0), "xz": (0, 2, 1), "zx": (0, 2, 1), "yx": (0, 1, 2),
           "zy": (1, 2, 0)}


def to_png(shape, path, plane="xy", at=0.0, resolution=None, title=None, window=None):
    """Write a PNG preview: the filled region (d < 0) and its zero contour, axes in mm.

    Parameters
    ----------
    shape : SDF
        A 2D region, or a 3D solid sliced by the plane ``plane`` (``"xy"``, ``"yz"`` or ``"xz"``) at the
        coordinate ``at`` [m] along the remaining axis.
    path : str or Path
    resolution : float, optional
        Pixel size [m] (default: 600 pixels along the longer side).
    title : str, optional
    window : ((2,), (2,)) [m], optional
        Plot window (lo, hi) in the plane's coordinates; required for unbounded shapes.
    """
    if plane not in _PLANES:
        raise GeometryError(f"plane must be one of 'xy', 'yz', 'xz', got {plane!r}")
    i, j, k = _PLANES[plane] if shape.dim == 3 else (0, 1, None)
    if window is None:
        lo, hi = _bounded(shape, "preview")
        lo, hi = lo[[i, j]], hi[[i, j]]
        pad = 0.05 * (hi - lo).max()
        lo, hi = lo - pad, hi + pad
    else:
        lo, hi = (np.asarray(w, dtype=float) for w in window)
    h = float(resolution) if resolution is not None else float((hi - lo).max() / 600)
    if not (math.isfinite(h) and h > 0):
        raise GeometryError(f"resolution must be a positive pixel size [m], got {resolution!r}")
    u = lo[0] + h * (np.arange(int(np.ceil((hi[0] - lo[0]) / h)) + 1))
    v = lo[1] + h * (np.arange(int(np.ceil((hi[1] - lo[1]) / h)) + 1))
    U, V = np.meshgrid(u, v, indexing="xy")
    pts = np.zeros((U.size, shape.dim))
    pts[:, i], pts[:, j] = U.ravel(), V.ravel()
    if k is not None:
        pts[:, k] = float(at)
    d = shape(pts).reshape(U.shape)

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    mm = 1e-3
    fig = Figure(figsize=(6, 6 * min(max((v[-1] - v[0]) / (u[-1] - u[0]), 0.25), 2.0) + 0.6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    extent = (u[0] / mm, u[-1] / mm, v[0] / mm, v[-1] / mm)
    ax.imshow((d < 0).astype(float), origin="lower", extent=extent, cmap="Blues", vmin=-0.3, vmax=1.3,
              interpolation="nearest")
    if np.any(d < 0) and np.any(d > 0):
        ax.contour(U / mm, V / mm, d, levels=[0.0], colors="k", linewidths=1.0)
    names = "xyz"
    ax.set_xlabel(f"{names[i]} [mm]")
    ax.set_ylabel(f"{names[j]} [mm]")
    ax.set_aspect("equal")
    label = title or (f"{shape.op}" + (f", slice {plane} at {names[k]} = {float(at) / mm:g} mm" if k is not None
                                       else ""))
    ax.set_title(label)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    return Path(path)
