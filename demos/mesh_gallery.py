"""Mesh gallery: a PneuNet cross-section with its chambers, a mesh from an image, a 3D mesh from an STL
=======================================================================================================

Purpose
-------
Show the three ways into :class:`sorofem.mesh.Mesh` and check each against an exact measure:

1. **PneuNet section** (2D, from a signed distance function). A rounded body of ``80 x 16 mm`` with
   four equal rectangular chambers (``8 x 8 mm``, every 16 mm). The shape is a CSG tree, so gmsh rebuilds it
   exactly in OpenCASCADE. The chambers are closed inner boundaries, found automatically and named
   ``cavity_0 .. cavity_3`` from left to right; the exact area is

   .. math:: A = W H - (4 - \\pi) r^2 - 4\\, a b .

2. **Image** (2D). A black disk of radius ``R = 60`` px on white, ``0.1 mm`` per pixel, written as a PNG
   and meshed from its contour; the area error is bounded by half a pixel along the perimeter,
   :math:`|\\Delta A| \\le \\pi R\\, p`.

3. **STL** (3D). A box with a spherical cavity exported to STL by ``sdf``'s marching cubes and filled with
   tetrahedra by gmsh; its volume is compared with :math:`a^3 - \\frac{4}{3}\\pi r^3`.

4. **Voronoi polygons** (2D, the seed's Fig. 5, after PolyMesher). The PneuNet section tiled by ``N_POLY``
   Voronoi cells, seeds spread by Lloyd's iteration to a centroidal tessellation
   (:class:`sorofem.mesh.PolyMesh`): the sides are the tangent lines of the boundary, so the area error is
   second order in the cell size; Lloyd's energy :math:`\\sum_i\\int_{V_i}|x - p_i|^2` is reported before and
   after. For DOLFINx the cells are split into triangles from their centroids (``PolyMesh.to_mesh``).

Outputs in ``out``: ``pneunet.png`` (mesh with named boundaries coloured, axes in mm), ``pneunet.xdmf``,
``image_mesh.png``, ``disk.png``, ``box_cavity.stl``, ``box_cavity.xdmf``, ``voronoi.png`` (the polygons coloured
by area with its colour bar, and Lloyd's energy per iteration).

Run ``python demos/mesh_gallery.py [--quick]``; ``main(out, quick)`` returns the summary figures.
"""
import argparse
import math
import pathlib
import time

import numpy as np

from sorofem import sdf
from sorofem.units import mm

# ------------------------------------------------------------------------------------------------ parameters
W, H, R_CORNER = 80 * mm, 16 * mm, 3 * mm          # PneuNet body
A_CH, B_CH, PITCH = 8 * mm, 8 * mm, 16 * mm         # chamber width, height, spacing
N_CH = 4
PIXEL, R_PX, N_PX = 0.1 * mm, 60, 200               # image: pixel size [m], disk radius and image size [px]
BOX, R_CAV = 20 * mm, 5 * mm                        # 3D part
#: The full run and the short one (`--quick`, what the tests run): element sizes of the section [m], of the
#: image mesh [pixels], of the STL's tetrahedra [m], the STL's marching-cubes resolution [m], Voronoi polygons
#: and Lloyd iterations.
FULL = dict(size_2d=0.4 * mm, image_size_px=2, stl_size=1.5 * mm, stl_resolution=0.5 * mm, polygons=300,
            lloyd=60)
QUICK = dict(size_2d=1.0 * mm, image_size_px=4, stl_size=3 * mm, stl_resolution=1.0 * mm, polygons=80,
             lloyd=15)


def main(out: pathlib.Path, quick: bool = False) -> dict:
    """Build the four meshes, write PNG/XDMF into ``out`` and return the summary figures."""
    from mpi4py import MPI

    from sorofem.mesh import Mesh, PolyMesh

    prm = QUICK if quick else FULL
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rank0 = MPI.COMM_WORLD.rank == 0
    serial = MPI.COMM_WORLD.size == 1

    # 1. PneuNet section from its SDF; the chambers found as cavities
    t0 = time.perf_counter()
    pn = Mesh.from_sdf(pneunet_section(), size=prm["size_2d"], order=2)
    t_pn = time.perf_counter() - t0
    exact = W * H - (4 - math.pi) * R_CORNER**2 - N_CH * A_CH * B_CH
    pn_err = abs(pn.area - exact) / exact
    cav_err = max(abs(pn.cavity_volume(c) - A_CH * B_CH) / (A_CH * B_CH) for c in pn.cavities)
    pn.write_xdmf(out / "pneunet.xdmf")
    if rank0 and serial:
        plot_mesh(pn, out / "pneunet.png", f"PneuNet section: {pn.num_cells} cells, {len(pn.cavities)} cavities")

    # 2. a mesh from an image: a disk drawn as PNG, meshed from its contour
    img_path = out / "disk.png"
    if rank0:
        write_disk(img_path)
    MPI.COMM_WORLD.barrier()
    t0 = time.perf_counter()
    im = Mesh.from_image(img_path, pixel_size=PIXEL, size=prm["image_size_px"] * PIXEL)
    t_im = time.perf_counter() - t0
    r = R_PX * PIXEL
    im_err = abs(im.area - math.pi * r**2) / (math.pi * r**2)
    if rank0 and serial:
        plot_mesh(im, out / "image_mesh.png", f"from_image: {im.num_cells} cells")

    # 3. STL -> tetrahedra: a box with a spherical cavity, marching cubes, gmsh
    solid = sdf.Box((BOX, BOX, BOX)) - sdf.Sphere(R_CAV)
    stl = out / "box_cavity.stl"
    if rank0:
        solid.to_stl(stl, resolution=prm["stl_resolution"])  # STL facets ~ half the element size
    MPI.COMM_WORLD.barrier()
    t0 = time.perf_counter()
    vol = Mesh.from_file(stl, size=prm["stl_size"])
    t_3d = time.perf_counter() - t0
    v_exact = BOX**3 - 4 / 3 * math.pi * R_CAV**3
    vol_err = abs(vol.volume - v_exact) / v_exact
    vol.write_xdmf(out / "box_cavity.xdmf")

    # 4. Voronoi polygons (PolyMesher-style), seeds spread by Lloyd's iteration
    t0 = time.perf_counter()
    poly = PolyMesh.from_sdf(pneunet_section(), prm["polygons"], iterations=prm["lloyd"])
    t_poly = time.perf_counter() - t0
    poly_err = abs(poly.areas.sum() - exact) / exact
    if rank0:
        plot_voronoi(poly, out / "voronoi.png")

    summary = {
        "voronoi_polygons": len(poly.polygons),
        "voronoi_area_rel_error": poly_err,
        "voronoi_lloyd_iterations": len(poly.energy) - 1,
        "voronoi_energy_ratio": float(poly.energy[-1] / poly.energy[0]),
        "voronoi_area_min_over_max": float(poly.areas.min() / poly.areas.max()),
        "voronoi_time_s": t_poly,
        "pneunet_cells": pn.num_cells,
        "pneunet_cavities": len(pn.cavities),
        "pneunet_area_rel_error": pn_err,
        "pneunet_cavity_area_rel_error": cav_err,
        "pneunet_min_angle_deg": pn.quality["min_angle"],
        "pneunet_mesh_time_s": t_pn,
        "image_cells": im.num_cells,
        "image_area_rel_error": im_err,
        "image_mesh_time_s": t_im,
        "stl_cells": vol.num_cells,
        "stl_cavities": len(vol.cavities),
        "stl_volume_rel_error": vol_err,
        "stl_min_angle_deg": vol.quality["min_angle"],
        "stl_mesh_time_s": t_3d,
    }
    return summary


# ------------------------------------------------------------------------------------------------- the steps
def pneunet_section():
    """Rounded body minus ``N_CH`` rectangular chambers (centred, slightly above mid-height)."""
    body = sdf.RoundedRectangle(W, H, radius=R_CORNER)
    for i in range(N_CH):
        xc = (i - (N_CH - 1) / 2) * PITCH
        body = body - sdf.Rectangle(A_CH, B_CH, center=(xc, 1 * mm))
    return body


def write_disk(path):
    """A black disk of radius ``R_PX`` pixels on a white ``N_PX`` x ``N_PX`` image, as PNG at ``path``."""
    from skimage import io as skio

    yy, xx = np.mgrid[0:N_PX, 0:N_PX]
    disk = (xx + 0.5 - N_PX / 2) ** 2 + (yy + 0.5 - N_PX / 2) ** 2 <= R_PX**2
    skio.imsave(str(path), np.where(disk, 0, 255).astype(np.uint8), check_contrast=False)


# ------------------------------------------------------------------------------------------------ the figures
def plot_mesh(msh, path, title):
    """A 2D mesh with its named boundaries in colour; the axes read in mm (the mesh is in metres)."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(9, 3))
    ax = fig.subplots()
    msh.plot(ax=ax, unit="mm")
    ax.set_title(title)
    save_figure(fig, path, dpi=150)


def plot_voronoi(poly, path):
    """The polygons [mm] coloured by area (colour bar in mm^2) and Lloyd's energy per iteration."""
    from matplotlib.figure import Figure

    from sorofem.io import save_figure

    fig = Figure(figsize=(11, 3))
    ax, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 1]})
    coll = poly.plot(ax=ax, color=poly.areas / mm**2, seeds=True)
    fig.colorbar(coll, ax=ax, shrink=0.8, label="polygon area [mm^2]")
    ax.set_title(f"Voronoi/Lloyd: {len(poly.polygons)} polygons", fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax2.semilogy(poly.energy / poly.energy[0], "o-", ms=2)
    ax2.set_xlabel("Lloyd iteration")
    ax2.set_ylabel("E / E_0")
    ax2.set_title("centroidal Voronoi energy", fontsize=9)
    save_figure(fig, path, dpi=150)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=pathlib.Path, default=pathlib.Path("out/mesh_gallery"))
    ap.add_argument("--quick", action="store_true", help="coarse meshes (a few seconds)")
    args = ap.parse_args()
    for key, value in main(args.out, quick=args.quick).items():
        print(f"{key:32s} {value:.4g}" if isinstance(value, float) else f"{key:32s} {value}")
