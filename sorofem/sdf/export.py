"""Export: triangle meshes and binary STL of 3D solids (marching cubes), PNG previews of 2D regions and of
plane slices of 3D solids. scikit-image and matplotlib are imported only when these functions run."""
import math
from pathlib import Path

import numpy as np

from ..errors import GeometryError
from ..io import atomic_path

__all__ = ["to_mesh", "to_stl", "read_stl", "to_png", "DEFAULT_STL_CELLS"]

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
    vol[vol == 0] = 1e-12 * h  # keep the level set off the grid nodes (no degenerate triangles)
    from skimage.measure import marching_cubes

    verts, faces, _, _ = marching_cubes(vol, level=0.0, spacing=(h, h, h), allow_degenerate=False)
    verts = verts + origin
    faces = faces.astype(np.int64)
    tri = verts[faces]
    signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    if signed < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def to_stl(shape, path, resolution=None):
    """Write a binary STL of a 3D solid (marching cubes, watertight, outward normals), atomically.

    Parameters
    ----------
    shape : SDF (3D)
    path : str or Path
    resolution : float, optional
        Grid step [m] (default from the bounds, see :func:`to_mesh`). Coordinates are written in metres.

    Returns
    -------
    Path
    """
    verts, faces = to_mesh(shape, resolution)
    tri = verts[faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = nrm / np.where(ln > 0, ln, 1.0)
    rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = nrm
    rec["v"] = tri
    header = b"sorofem.sdf binary STL, units: m".ljust(80, b" ")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(header)
            f.write(np.uint32(len(faces)).tobytes())
            f.write(rec.tobytes())
    return Path(path)


def read_stl(path):
    """Read a binary STL -> (triangles (F, 3, 3) float64, normals (F, 3) float64)."""
    data = Path(path).read_bytes()
    if len(data) < 84:
        raise GeometryError(f"{path} is not a binary STL (too short)")
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    if len(data) != 84 + 50 * n:
        raise GeometryError(f"{path}: binary STL header says {n} triangles but the file has {len(data)} bytes")
    rec = np.frombuffer(data, [("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")], n, 84)
    return rec["v"].astype(float), rec["n"].astype(float)


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
