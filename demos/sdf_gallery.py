"""Implicit CAD gallery (`soro demo sdf_gallery`)
==============================================

Purpose
-------
Build the example geometries of the Sorotoki paper (Sec. V-A, Fig. 4) and typical soft-robot parts with
signed distance functions, export them (binary STL for 3D printing, PNG previews) and report the numbers a
reader can check: the STL volume of a sphere against 4/3 pi r^3 and the section properties of a PneuNet
cross-section.

Shapes
------
- ``seed2d``: ``Rectangle(20 mm, 10 mm).rotate(45 deg) - Circle(3 mm)`` (the paper's 2D example).
- ``seed3d``: ``(Cube - Sphere_1) & Sphere_2`` (the paper's 3D example, cube edge 10 mm).
- ``pneunet``: the side section of a PneuNet bending actuator, 80 mm x 17 mm, 7 chambers (8.4 x 10 mm) over a
  5 mm strain-limiting base with a 1.5 mm feed channel inside it and a riser into each chamber; the
  ``finger`` STL is the 15 mm thick printable actuator: chambers and channel closed by 2 mm side walls, one
  network open only at its inlet (the channel's mouth on the left end face), one watertight shell.
- ``bellows``: a revolved zig-zag wall (1.5 mm thick, outer radius 12 mm, 6 folds) closed by two end caps.
- ``lattice``: a 20 mm porous block (spherical voids of 1.8 mm radius on a 4 mm pitch, ``repeat``).
- ``sphere``: radius 10 mm, exported at the default resolution for the volume check.

Parameters
----------
out : pathlib.Path
    Output directory (STL files in millimetres, the unit named in their header; PNG previews with axes in mm).
quick : bool
    Coarser grids (STL step 1 mm, sphere 0.5 mm, instead of the default resolution chosen from the
    bounds) so that the demo runs in a few seconds.

Figures
-------
The returned dict holds ``shapes``, ``stl_files``, ``png_files``, ``sphere_volume_error_rel``,
``pneunet_section_area_mm2``, ``pneunet_section_Iy_mm4``, ``pneunet_section_Iz_mm4``, ``seed2d_area_mm2``,
``seed2d_area_error_rel`` (numerical vs closed form 200 - 9 pi mm^2), ``finger_volume_mm3``,
``finger_check`` (the STL's watertightness, shells, volume; :func:`sorofem.sdf.surface_check`),
``finger_network`` (the flood fill of its chambers, :func:`sorofem.robots.chamber_check`),
``lattice_porosity`` and ``bellows_triangles``.
"""
import math
from pathlib import Path

import numpy as np

from sorofem import robots, sdf
from sorofem.units import mm


# ------------------------------------------------------------------------------------------------ parameters
PNEUNET_DEPTH = 15 * mm       # the finger's thickness (z)
PNEUNET_SIDE = 2 * mm         # side walls closing the chambers and the channel (z)
#: Grid steps [m] of the full run and the short one (`--quick`, what the tests run): the STL files (None: the
#: default from the bounds), the sphere's STL, the PneuNet section's properties, the lattice's and the
#: finger's volumes.
FULL = dict(stl_resolution=None, sphere_resolution=None, section_resolution=0.05 * mm,
            lattice_resolution=0.1 * mm, finger_resolution=0.2 * mm)
QUICK = dict(stl_resolution=1.0 * mm, sphere_resolution=0.5 * mm, section_resolution=0.2 * mm,
             lattice_resolution=0.4 * mm, finger_resolution=0.6 * mm)


def main(out: Path, quick: bool = False) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    """Build, export and measure the gallery's shapes into ``out``; returns the figures (see Figures above)."""
    prm = QUICK if quick else FULL

    # 1. 2D: the paper's example and a PneuNet section, their section properties
    seed2d, seed3d = seed_shapes()
    section = pneunet_section()
    sp_seed = seed2d.section_properties()
    sp_pn = section.section_properties(resolution=prm["section_resolution"])
    pngs = [seed2d.to_png(out / "seed2d.png", title="Rectangle.rotate(45 deg) - Circle"),
            section.to_png(out / "pneunet_section.png", title="PneuNet section")]

    # 2. 3D: solids, STL + slices
    finger, plug, chamber_points = pneunet_finger()
    bel = bellows()
    lat = lattice()
    sphere = sdf.Sphere(10 * mm)
    solids = {"seed3d": seed3d, "finger": finger, "bellows": bel, "lattice": lat}
    stls = {name: s.to_stl(out / f"{name}.stl", resolution=prm["stl_resolution"]) for name, s in solids.items()}
    stls["sphere"] = sphere.to_stl(out / "sphere.stl", resolution=prm["sphere_resolution"])
    pngs += [bel.to_png(out / "bellows_xz.png", plane="xz", title="bellows, slice y = 0"),
             lat.to_png(out / "lattice_xy.png", plane="xy", at=0.0, title="lattice, slice z = 0"),
             finger.to_png(out / "finger_xz.png", plane="xz", at=7 * mm, title="finger, slice y = 7 mm")]

    # 3. checks: the finger is one watertight shell with one chamber network; volumes against closed forms
    chk = sdf.surface_check(sdf.read_stl(stls["finger"])[0])
    net = robots.Network("pneunet", plug, tuple(chamber_points), (0.0, 0.0))
    flood = robots.chamber_check(robots.Part("finger", finger, "Elastic80A", (net,), feature=1.5 * mm))
    v_sphere, _ = _stl_volume(stls["sphere"])
    v_exact = 4 / 3 * math.pi * (10 * mm) ** 3
    _, n_bellows = _stl_volume(stls["bellows"])
    v_lat = lat.mass_properties(resolution=prm["lattice_resolution"]).volume
    v_finger = finger.mass_properties(resolution=prm["finger_resolution"]).volume

    seed_area_exact = (20 * mm) * (10 * mm) - math.pi * (3 * mm) ** 2
    return {
        "shapes": 2 + len(solids) + 1,
        "stl_files": len(stls),
        "png_files": len(pngs),
        "sphere_volume_error_rel": abs(v_sphere - v_exact) / v_exact,
        "pneunet_section_area_mm2": sp_pn.area / mm**2,
        "pneunet_section_Iy_mm4": sp_pn.Iy / mm**4,
        "pneunet_section_Iz_mm4": sp_pn.Iz / mm**4,
        "seed2d_area_mm2": sp_seed.area / mm**2,
        "seed2d_area_error_rel": abs(sp_seed.area - seed_area_exact) / seed_area_exact,
        "finger_volume_mm3": v_finger / mm**3,
        "finger_check": {"watertight": bool(chk["watertight"]), "shells": int(chk["shells"]),
                         "volume_mm3": float(chk["volume"] / mm**3)},
        "finger_network": flood["pneunet"],
        "lattice_porosity": 1.0 - v_lat / (20 * mm) ** 3,
        "bellows_triangles": n_bellows,
    }


# ------------------------------------------------------------------------------------------------ the shapes

def _pneunet_2d():
    """The PneuNet's side-view outline and voids in the (x, y) plane [m]: (outline, chambers, channel).

    Base layer 80 x 5 mm, 7 blocks (pitch - 1 mm wide, 13 mm tall) each with a 10 mm chamber; the 1.5 mm feed
    channel runs inside the base layer (y 1.75..3.25 mm) from the left end face (x = 0, the inlet) to under the
    last chamber, with a 1.5 mm riser up into every chamber."""
    length, n = 80 * mm, 7
    pitch = length / n
    base = sdf.Rectangle(length, 5 * mm, center=(length / 2, 2.5 * mm))
    blocks = sdf.RoundedRectangle(pitch - 1 * mm, 13 * mm, 1.5 * mm,
                                  center=(pitch / 2, 10 * mm)).repeat((pitch, 0), (n, 1))
    chambers = sdf.Rectangle(pitch - 3 * mm, 10 * mm, center=(pitch / 2, 10 * mm)).repeat((pitch, 0), (n, 1))
    x_end = length - pitch / 2 + 0.75 * mm
    channel = (sdf.Rectangle(x_end + 1 * mm, 1.5 * mm, center=((x_end - 1 * mm) / 2, 2.5 * mm))
               | sdf.Rectangle(1.5 * mm, 3.5 * mm, center=(pitch / 2, 4.0 * mm)).repeat((pitch, 0), (n, 1)))
    return base | blocks, chambers, channel


def pneunet_section():
    """Side section of a PneuNet actuator in the (x, y) plane [m] (its mid-plane z = 0): base layer +
    chamber walls - chambers - feed channel and risers."""
    outline, chambers, channel = _pneunet_2d()
    return outline - chambers - channel


def pneunet_finger():
    """The PneuNet as one printable solid [m], z centred on 0: the outline extruded to ``PNEUNET_DEPTH``, the
    chambers and the channel extruded less (closed by ``PNEUNET_SIDE`` walls), so that they form one network
    open only at its inlet on the left end face (x = 0).

    Returns (solid, inlet plug (a 3D SDF filling the channel's mouth), a point inside each chamber)."""
    outline, chambers, channel = _pneunet_2d()
    solid = (outline.extrude(PNEUNET_DEPTH) - chambers.extrude(PNEUNET_DEPTH - 2 * PNEUNET_SIDE)
             - channel.extrude(1.5 * mm))
    plug = sdf.Box((2 * mm, 1.5 * mm, 1.5 * mm), (0.0, 2.5 * mm, 0.0))
    pitch = 80 * mm / 7
    points = [(pitch / 2 + k * pitch, 10 * mm, 0.0) for k in range(7)]
    return solid, plug, points


def bellows(folds=6, r_out=12 * mm, r_in=8 * mm, pitch=5 * mm, wall=1.5 * mm):
    """Revolved zig-zag wall about z with end caps [m]."""
    z = np.arange(2 * folds + 1) * pitch / 2
    r = np.where(np.arange(len(z)) % 2 == 0, r_in, r_out)
    wall_profile = sdf.Polyline(np.column_stack([r, z]), wall)
    height = z[-1]
    caps = sdf.Rectangle(2 * r_in, wall, center=(0, 0)) | sdf.Rectangle(2 * r_in, wall, center=(0, height))
    return (wall_profile | caps).revolve(axis=(0, 0, 1))


def lattice(edge=20 * mm, pitch=4 * mm, void=1.8 * mm):
    """Porous block: a cube minus a 3D array of spherical voids [m]."""
    n = int(round(edge / pitch))
    voids = sdf.Sphere(void).repeat((pitch, pitch, pitch), (n, n, n)).translate([-(n - 1) * pitch / 2] * 3)
    return sdf.Box(edge) - voids


def seed_shapes():
    """The paper's Example 1 (Sec. V-A), scaled to millimetres."""
    two = sdf.Rectangle(20 * mm, 10 * mm).rotate(45, deg=True) - sdf.Circle(3 * mm)
    cube = sdf.Box(10 * mm, center=(5 * mm, 5 * mm, 5 * mm))
    s1 = sdf.Sphere(5 * mm, center=(0, 0, 10 * mm))
    s2 = sdf.Sphere(10 * mm, center=(0, 0, 5 * mm))
    return two, (cube - s1) & s2


def _stl_volume(path):
    tri, _ = sdf.read_stl(path)
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6), len(tri)


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(main(Path(sys.argv[1] if len(sys.argv) > 1 else "out/sdf_gallery"),
                          quick="--quick" in sys.argv), indent=2))
