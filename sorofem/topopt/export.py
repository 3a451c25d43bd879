"""Export of a design: density images (PNG), XDMF, thresholded and smooth meshes, extruded STL.

The cell densities :math:`\\bar\\rho_e` are first smoothed to the mesh vertices (volume-weighted average of
the adjacent cells), then interpolated linearly on a raster of square pixels covering the bounding box. The
smooth iso-line :math:`\\bar\\rho = 1/2` of that field is the printable boundary:

* :func:`density_png` writes the raster (solid black on white), the input of
  :meth:`sorofem.mesh.Mesh.from_image`;
* :func:`design_mesh` meshes the solid part bounded by the iso-line (a :class:`~sorofem.mesh.Mesh` that
  :class:`~sorofem.fem.Fem` can simulate; closed chambers become regions ``cavity_k``);
* :func:`write_stl` extrudes it to a thickness (marching cubes on the raster stacked along z, so the caps
  and walls are one watertight surface) and writes a binary STL atomically;
* :func:`threshold_mesh` keeps the cells with :math:`\\bar\\rho_e \\ge` ``threshold`` (staircase boundary);
* :func:`write_xdmf` writes the mesh and the DG0 density for ParaView.
"""
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from .. import _dolfinx
from ..io import atomic_path

__all__ = ["nodal_density", "density_image", "density_png", "write_xdmf", "threshold_mesh", "design_mesh",
           "write_stl"]


def _cells(domain, n):
    return _dolfinx.geometry_dofs(domain, n)


def nodal_density(problem, x):
    """Vertex coordinates (nv, dim) [m] and the volume-weighted vertex average (nv,) of the physical density."""
    dom = problem.mesh.dolfinx
    rho = problem.physical(x)
    cells = _cells(dom, problem.n)
    X = dom.geometry.x[:, : problem.dim]
    w = np.repeat(problem.cell_volumes, cells.shape[1])
    num = np.bincount(cells.ravel(), weights=w * np.repeat(rho, cells.shape[1]), minlength=len(X))
    den = np.bincount(cells.ravel(), weights=w, minlength=len(X))
    return X, num / np.maximum(den, 1e-300)


def _triangles(domain, n):
    cells = _cells(domain, n)
    if cells.shape[1] == 3:
        return cells
    if cells.shape[1] == 4 and domain.geometry.dim == 2:  # DOLFINx quad order: (0,0), (1,0), (0,1), (1,1)
        return np.vstack([cells[:, [0, 1, 3]], cells[:, [0, 3, 2]]])
    raise ParameterError("density images are made from 2D linear meshes (triangles or quadrilaterals)")


def density_image(problem, x, pixel=None):
    """The smoothed physical density on a raster of square pixels (2D designs).

    Parameters
    ----------
    problem : TopOpt
    x : (n,) array
        Design variables.
    pixel : float, optional
        Pixel size [m]; default a quarter of the mean cell size.

    Returns
    -------
    image : (ny, nx) array
        Densities in [0, 1]; row 0 is the top of the domain (image convention).
    lower_left : (2,) array
        Coordinates [m] of the lower-left corner of the raster (the bounding box's).
    pixel : float
        Pixel size [m].
    """
    import matplotlib.tri as mtri
    if problem.dim != 2:
        raise ParameterError("density images are 2D; write_xdmf exports 3D designs")
    dom = problem.mesh.dolfinx
    X, val = nodal_density(problem, x)
    lo, hi = X.min(axis=0), X.max(axis=0)
    h = (problem.mesh.measure() / problem.n) ** 0.5
    px = float(pixel) if pixel is not None else h / 4
    if not px > 0:
        raise ParameterError(f"pixel must be a positive length [m], got {pixel!r}")
    nx, ny = int(round((hi[0] - lo[0]) / px)), int(round((hi[1] - lo[1]) / px))
    if nx * ny > 2e7:
        raise ParameterError(f"pixel {px:g} m gives a {nx} x {ny} raster; use a larger pixel")
    px = (hi[0] - lo[0]) / nx
    tri = mtri.Triangulation(X[:, 0], X[:, 1], _triangles(dom, problem.n))
    gx = lo[0] + (np.arange(nx) + 0.5) * px
    gy = lo[1] + (np.arange(ny) + 0.5) * ((hi[1] - lo[1]) / ny)
    GX, GY = np.meshgrid(gx, gy)
    img = np.ma.filled(mtri.LinearTriInterpolator(tri, val)(GX, GY), 0.0)
    return np.clip(img[::-1], 0.0, 1.0), lo, px


def density_png(problem, x, path, pixel=None, tiles=1):
    """Write the density raster as a grey PNG (solid black, void white), atomically; returns the path.

    ``tiles`` repeats the design along x (a row of identical cells, e.g. the chambers of a PneuNet).
    """
    import matplotlib.image
    img, _, _ = density_image(problem, x, pixel)
    img = np.tile(img, (1, int(tiles)))
    with atomic_path(path, suffix=".png") as tmp:
        matplotlib.image.imsave(tmp, 1.0 - img, cmap="gray", vmin=0.0, vmax=1.0)
    return Path(path)


def write_xdmf(problem, x, path):
    """Write the mesh and the physical density (DG0 function ``density``) to ``path`` (.xdmf + .h5).

    Both files are written in a temporary directory and moved into place (the .h5 first)."""
    from dolfinx.io import XDMFFile
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rho = problem.density_function(x)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.stem}.", dir=path.parent))
    try:
        with XDMFFile(problem.mesh.comm, str(tmpdir / path.name), "w") as f:
            f.write_mesh(problem.mesh.dolfinx)
            f.write_function(rho)
        h5 = path.with_suffix(".h5")
        os.replace(tmpdir / h5.name, h5)
        os.replace(tmpdir / path.name, path)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return path


def threshold_mesh(problem, x, threshold=0.5):
    """A :class:`~sorofem.mesh.Mesh` of the cells with physical density >= ``threshold`` (same cells)."""
    from ..mesh import Mesh
    dom = problem.mesh.dolfinx
    keep = problem.physical(x) >= threshold
    if not keep.any():
        raise ParameterError(f"no cell has a density >= {threshold}; lower the threshold")
    cells = _cells(dom, problem.n)[keep]
    if cells.shape[1] == 4 and problem.dim == 2:
        cells = cells[:, [0, 1, 3, 2]]  # DOLFINx tensor-product order -> gmsh counter-clockwise order
    elif cells.shape[1] == 8:
        cells = cells[:, [0, 1, 3, 2, 4, 5, 7, 6]]
    used, inv = np.unique(cells, return_inverse=True)
    return Mesh.from_arrays(dom.geometry.x[used, : problem.dim], inv.reshape(cells.shape))


def design_mesh(problem, x, size=None, pixel=None, tiles=1, threshold=0.5, workdir=None):
    """Mesh the smooth iso-line ``density = threshold`` of a 2D design: a :class:`~sorofem.mesh.Mesh`.

    The origin of the new mesh is the lower-left corner of the design's bounding box; ``tiles`` copies are
    placed side by side along x. ``size`` [m] is the element size (default: the design's mean cell size).
    Closed voids become ``cavity_k`` regions.
    """
    from ..mesh import Mesh
    h = (problem.mesh.measure() / problem.n) ** (1.0 / problem.dim)
    img, _, px = density_image(problem, x, pixel)
    tmpdir = Path(tempfile.mkdtemp(prefix="topopt_design_", dir=workdir))
    try:
        png = density_png(problem, x, tmpdir / "design.png", pixel=pixel, tiles=tiles)
        return Mesh.from_image(png, pixel_size=px, threshold=threshold, size=size if size is not None else h)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def write_stl(problem, x, path, thickness, pixel=None, tiles=1, threshold=0.5, units="mm"):
    """Extrude the smooth iso-line of a 2D design to ``thickness`` [m] and write a binary STL atomically.

    Marching cubes on the density raster stacked along z (zero outside), so the side walls follow the
    iso-line and the surface is closed. Origin at the bounding box's lower-left corner, z centred. The file
    is written by :func:`sorofem.sdf.write_stl` in ``units`` (default ``"mm"``, named in the header).

    Returns
    -------
    dict
        ``path``, ``triangles``, ``volume`` [m^3] (signed volume of the surface, a check of closure).
    """
    from skimage.measure import marching_cubes

    from ..sdf.export import write_stl as write_triangles
    if not thickness > 0:
        raise ParameterError(f"thickness must be a positive length [m], got {thickness!r}")
    img, _, px = density_image(problem, x, pixel)
    img = np.tile(img, (1, int(tiles)))[::-1].T  # (nx, ny), y up
    # the walls are straight; the layer height only sets the chamfer that marching cubes cuts along the cap
    # edges (about px * hz / 2 per unit perimeter and cap), so layers of two pixels keep it small
    nz = max(2, int(math.ceil(thickness / (2 * px))))
    hz = thickness / nz
    vol = np.zeros((img.shape[0] + 2, img.shape[1] + 2, nz + 2))
    vol[1:-1, 1:-1, 1:-1] = img[:, :, None]
    verts, faces, _, _ = marching_cubes(vol, level=threshold, spacing=(px, px, hz), allow_degenerate=False)
    verts = verts - np.array([1.5 * px, 1.5 * px, 1.5 * hz + (thickness - hz) / 2])
    tri = verts[faces]
    signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    if signed < 0:
        faces = faces[:, ::-1]
        signed = -signed
    write_triangles(path, verts, faces, units=units, label="sorofem.topopt extruded design")
    return {"path": Path(path), "triangles": int(len(faces)), "volume": float(signed)}
