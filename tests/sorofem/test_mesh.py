"""Tests of sorofem.mesh: SDF/image/file → DOLFINx meshes with named regions, quality and I/O.

Reference values are exact (areas, volumes, perimeters of the primitives). Tolerances:
* exact (OpenCASCADE) boundaries with order-2 cells: the geometry error is O(h^3) on curved edges; 1e-3.
* polygonal (order-1) boundaries: a circle of radius r discretised with chords of length h loses
  about (h/r)^2/6 of its area (relative); tolerances are set from that bound.
* images: the boundary is within half a pixel of the true one, so |dA| <= perimeter * pixel / 2.
"""
import math

import numpy as np
import pytest

from sorofem import sdf
from sorofem.errors import GeometryError, MeshError
from sorofem.units import mm

mesh_mod = pytest.importorskip("sorofem.mesh")
Mesh = mesh_mod.Mesh

W, H, R, XC = 40 * mm, 10 * mm, 2 * mm, 8 * mm


def two_holes():
    return sdf.Rectangle(W, H) - sdf.Circle(R, center=(-XC, 0)) - sdf.Circle(R, center=(XC, 0))


def pneunet():
    """PneuNet-like section: rounded body with two internal chambers of different sizes."""
    body = sdf.RoundedRectangle(W, H, radius=2 * mm)
    c0 = sdf.Rectangle(8 * mm, 4 * mm, center=(-9 * mm, 0.5 * mm))
    c1 = sdf.Rectangle(10 * mm, 5 * mm, center=(9 * mm, 0.5 * mm))
    return body - c0 - c1


EXACT_TWO_HOLES = W * H - 2 * math.pi * R**2


@pytest.fixture(scope="module")
def holes_p2():
    return Mesh.from_sdf(two_holes(), size=1 * mm, order=2)


# ----------------------------------------------------------------------------------------------- 2D areas
@pytest.mark.parametrize("method,order,rtol", [
    # inscribed polygons with chords h=1mm on r=2mm lose theta^2/6 (theta = h/r) of each hole's area:
    # 2 pi r^2 (h/r)^2 / 6 / A = 2.8e-3 of the body's area at most (gmsh's chords are a bit shorter)
    ("csg", 1, 3e-3),
    ("csg", 2, 1e-4),
    ("levelset", 1, 3e-3),  # same bound (vertices are projected onto the exact circles)
    ("levelset", 2, 1e-4),  # order-2 boundary nodes are projected onto the exact circle
])
def test_area_of_rectangle_minus_circles(method, order, rtol):
    msh = Mesh.from_sdf(two_holes(), size=1 * mm, method=method, order=order)
    assert msh.area == pytest.approx(EXACT_TWO_HOLES, rel=rtol)
    assert msh.quality["degree"] == order


def test_cavities_found_ordered_and_measured(holes_p2):
    msh = holes_p2
    assert msh.cavities == ["cavity_0", "cavity_1"]
    for name in ("cavity_0", "cavity_1"):
        assert msh.measure(name) == pytest.approx(2 * math.pi * R, rel=1e-4)
        assert msh.cavity_volume(name) == pytest.approx(math.pi * R**2, rel=5e-4)  # order-2 arcs at h/r = 0.5: enclosed area within ~1e-4
    x0 = msh.dolfinx.geometry.x[:, 0]
    # cavity_0 is the left hole (ordered by centroid x)
    import dolfinx.mesh
    mid0 = dolfinx.mesh.compute_midpoints(msh.dolfinx, 1, msh.facets("cavity_0"))[:, 0]
    mid1 = dolfinx.mesh.compute_midpoints(msh.dolfinx, 1, msh.facets("cavity_1"))[:, 0]
    assert mid0.mean() == pytest.approx(-XC, abs=0.01 * mm) and mid1.mean() == pytest.approx(XC, abs=0.01 * mm)
    assert x0.min() == pytest.approx(-W / 2)


def test_sides_have_the_right_lengths(holes_p2):
    msh = holes_p2
    assert {"left", "right", "top", "bottom"} <= set(msh.regions)
    assert msh.measure("left") == pytest.approx(H, rel=1e-12)
    assert msh.measure("right") == pytest.approx(H, rel=1e-12)
    assert msh.measure("top") == pytest.approx(W, rel=1e-12)
    assert msh.measure("bottom") == pytest.approx(W, rel=1e-12)
    assert "front" not in msh.regions


def test_pneunet_chambers_levelset_and_csg():
    shape = pneunet()
    exact = (W * H - (4 - math.pi) * (2 * mm) ** 2) - 8 * mm * 4 * mm - 10 * mm * 5 * mm
    for method in ("csg", "levelset"):
        msh = Mesh.from_sdf(shape, size=0.5 * mm, method=method)
        assert msh.cavities == ["cavity_0", "cavity_1"], method
        assert msh.measure("cavity_0") == pytest.approx(2 * (8 + 4) * mm, rel=1e-6), method
        assert msh.measure("cavity_1") == pytest.approx(2 * (10 + 5) * mm, rel=1e-6), method
        assert msh.cavity_volume("cavity_1") == pytest.approx(50 * mm**2, rel=1e-6), method
        assert msh.area == pytest.approx(exact, rel=2e-3), method
        # rounded corners: the flat part of the left side is H - 2 r (exact with CSG; the level-set boundary
        # may stop one segment (0.5 mm) short of each tangent point)
        if method == "csg":
            assert msh.measure("left") == pytest.approx(H - 4 * mm, rel=1e-6)
        else:
            assert H - 4 * mm - 1.01 * mm <= msh.measure("left") <= H - 4 * mm + 1e-9


def test_no_cavity_when_hole_is_open():
    notch = sdf.Rectangle(W, H) - sdf.Rectangle(4 * mm, 6 * mm, center=(0, H / 2))
    msh = Mesh.from_sdf(notch, size=1 * mm)
    assert msh.cavities == []


def test_quadrilaterals_and_hexahedra():
    q = Mesh.rectangle(20 * mm, 10 * mm, size=1 * mm, cell="quadrilateral")
    assert q.quality["cell"] == "quadrilateral" and q.num_cells == 20 * 10
    assert q.area == pytest.approx(200 * mm**2, rel=1e-12)
    assert q.quality["min_angle"] == pytest.approx(90.0)
    q2 = Mesh.from_sdf(sdf.Rectangle(20 * mm, 10 * mm), size=2 * mm, cell="quadrilateral", order=2)
    assert q2.quality["cell"] == "quadrilateral" and q2.quality["degree"] == 2 and q2.num_cells == 50
    h = Mesh.box(20 * mm, 10 * mm, 10 * mm, size=2 * mm, cell="hexahedron")
    assert h.quality["cell"] == "hexahedron" and h.num_cells == 10 * 5 * 5
    assert h.volume == pytest.approx(2000 * mm**3, rel=1e-12)
    assert h.measure("front") == pytest.approx(200 * mm**2, rel=1e-12)
    assert set(h.regions) == {"left", "right", "front", "back", "bottom", "top"}
    # recombined quads on a general shape
    g = Mesh.from_sdf(two_holes(), size=1 * mm, cell="quadrilateral", order=2)
    assert g.quality["cell"] == "quadrilateral" and g.area == pytest.approx(EXACT_TWO_HOLES, rel=1e-4)


# ----------------------------------------------------------------------------------------------- 3D
def test_sphere_volume_order2_and_levelset():
    r = 5 * mm
    exact = 4 / 3 * math.pi * r**3
    msh = Mesh.from_sdf(sdf.Sphere(r), size=1.5 * mm, order=2)
    assert msh.volume == pytest.approx(exact, rel=1e-3)
    assert msh.quality["cell"] == "tetrahedron" and msh.quality["degree"] == 2
    # marching-cubes surface → gmsh volume, boundary nodes snapped onto the sphere; the inscribed P1
    # polyhedron loses ~ (h/r)^2 / 4 = 2.3e-2 of the volume at h = 1.5 mm on r = 5 mm
    ls = Mesh.from_sdf(sdf.Sphere(r), size=1.5 * mm, method="levelset")
    assert ls.volume == pytest.approx(exact, rel=3e-2)
    assert ls.volume < exact  # inscribed polyhedron


def test_box_minus_cylinder_and_inner_cavity():
    bx = sdf.Box((20 * mm, 10 * mm, 10 * mm))
    tunnel = Mesh.from_sdf(bx - sdf.Cylinder(2 * mm, 30 * mm, axis=(1, 0, 0)), size=1.5 * mm, order=2)
    assert tunnel.volume == pytest.approx(2000 * mm**3 - math.pi * (2 * mm) ** 2 * 20 * mm, rel=1e-3)
    assert tunnel.cavities == []  # the tunnel is open: its wall touches the outer boundary
    rs = 2.5 * mm
    cav = Mesh.from_sdf(bx - sdf.Sphere(rs, center=(4 * mm, 0, 0)) - sdf.Sphere(rs, center=(-4 * mm, 0, 0)),
                        size=1.0 * mm)
    assert cav.cavities == ["cavity_0", "cavity_1"]
    # inscribed polyhedron with edges up to ~1.3 h, h/r = 0.4: up to (1.3 h/r)^2/4 = 7e-2 of the volume
    # missing (the exact-geometry check is the order-2 sphere above)
    v = 4 / 3 * math.pi * rs**3
    assert 0.92 * v < cav.cavity_volume("cavity_0") < v
    assert cav.cavity_volume("cavity_0") == pytest.approx(cav.cavity_volume("cavity_1"), rel=5e-2)
    assert cav.measure("left") == pytest.approx(100 * mm**2, rel=1e-10)


# ----------------------------------------------------------------------------------------------- regions
def test_user_regions_cells_and_facets(holes_p2):
    msh = Mesh.from_sdf(two_holes(), size=1 * mm)
    layer = sdf.Rectangle(W, 2 * mm, center=(0, -H / 2 + 1 * mm))
    out = msh.add_region("layer", layer, kind="cells")
    assert out is msh
    # cells are picked by their midpoint on a mesh that does not follow the layer's edge: the area is
    # right to within one row of cells along that edge, W * h / 2
    assert msh.measure("layer") == pytest.approx(W * 2 * mm, abs=W * 1 * mm / 2)
    msh.add_region("grip", ((-W / 2 - 1e-9, -H), (-W / 2 + 5 * mm, H)))           # box on boundary facets
    assert msh.measure("grip") == pytest.approx(H + 2 * 5 * mm, rel=1e-10)
    msh.add_region("top_right", lambda x: (x[1] > H / 2 - 1e-9) & (x[0] > 0))     # predicate
    assert msh.measure("top_right") == pytest.approx(W / 2, rel=1e-10)
    assert msh.regions["layer"] != msh.regions["grip"]
    ct = msh.cell_tags
    assert set(np.unique(ct.values)) == {msh.regions["layer"]}
    with pytest.raises(MeshError, match="no region 'nope'"):
        msh.facets("nope")
    with pytest.raises(MeshError, match="selects no"):
        msh.add_region("far", ((1.0, 1.0), (2.0, 2.0)))


def test_refinement_near_boundary_and_region():
    shape = two_holes()
    coarse = Mesh.from_sdf(shape, size=2 * mm)
    fine = Mesh.from_sdf(shape, size=2 * mm, boundary_size=0.5 * mm)
    region = Mesh.from_sdf(shape, size=2 * mm, refine=[(((-20 * mm, -5 * mm), (0, 5 * mm)), 0.5 * mm)])
    assert fine.num_cells > 3 * coarse.num_cells
    assert fine.quality["h_min"] < 0.75 * mm
    import dolfinx.mesh
    m = region.dolfinx
    mid = dolfinx.mesh.compute_midpoints(m, 2, np.arange(m.topology.index_map(2).size_local, dtype=np.int32))
    left = np.count_nonzero(mid[:, 0] < 0)
    assert left > 5 * (len(mid) - left)


# ----------------------------------------------------------------------------------------------- quality
def test_quality_report_and_bad_meshes():
    q = Mesh.from_sdf(two_holes(), size=1 * mm).quality
    assert 20.0 < q["min_angle"] <= 60.0
    assert 1.0 <= q["max_aspect_ratio"] < 3.0
    assert q["degenerate"] == 0 and q["inverted"] == 0 and q["num_cells"] > 500
    pts = np.array([[0, 0], [1, 0], [0, 1], [2, 0]], dtype=float) * mm
    ok = Mesh.from_arrays(pts[:3], [[0, 1, 2]])
    assert ok.quality["min_angle"] == pytest.approx(45.0)
    assert ok.quality["max_aspect_ratio"] == pytest.approx((math.sqrt(2) / 2) / (2 * (1 - math.sqrt(2) / 2)))
    with pytest.raises(MeshError, match="degenerate"):
        Mesh.from_arrays(pts, [[0, 1, 2], [0, 1, 3]])  # second triangle is collinear
    with pytest.raises(MeshError):
        Mesh.from_arrays(pts, np.zeros((0, 3), dtype=int))
    # a P2 triangle whose edge node is pulled across the opposite corner is inverted
    p2 = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [-0.2, -0.2], [0, 0.5]]) * mm
    with pytest.raises(MeshError, match="inverted"):
        Mesh.from_arrays(p2, [[0, 1, 2, 3, 4, 5]])


# ----------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("size", [0.0, -1 * mm, float("nan"), "big"])
def test_bad_sizes(size):
    with pytest.raises(MeshError, match="size"):
        Mesh.from_sdf(sdf.Circle(5 * mm), size=size)


def test_empty_shape_and_bad_args():
    empty = sdf.Circle(1 * mm) - sdf.Circle(2 * mm)
    for method in ("csg", "levelset"):
        with pytest.raises(GeometryError, match="empty"):
            Mesh.from_sdf(empty, size=0.2 * mm, method=method)
    with pytest.raises(MeshError, match="order"):
        Mesh.from_sdf(sdf.Circle(5 * mm), size=1 * mm, order=3)
    with pytest.raises(MeshError, match="cell"):
        Mesh.from_sdf(sdf.Circle(5 * mm), size=1 * mm, cell="hexahedron")
    with pytest.raises(GeometryError):
        Mesh.from_sdf(object(), size=1 * mm)


# ----------------------------------------------------------------------------------------------- size estimate
def test_the_cell_estimate_is_close_to_the_count():
    """The estimate (measure over a regular cell's measure) is within a factor 2 of gmsh's count for
    triangles and tetrahedra, for a constant and a varying size: it is meant to catch sizes that are off by
    orders of magnitude (a size in mm typed as m), so a factor 2 is the accuracy it needs."""
    holes = two_holes()
    for shape, size in [(holes, 1 * mm), (sdf.Sphere(5 * mm), 1.5 * mm)]:
        n = mesh_mod.estimate_cells(shape, size)
        assert 0.5 < n / Mesh.from_sdf(shape, size=size).num_cells < 2.0
    varying = lambda x: 1.5 * mm - 0.05 * np.abs(x[:, 0])          # noqa: E731 - 1.5 mm in the middle, 0.5 at the ends
    n = mesh_mod.estimate_cells(holes, varying)
    assert 0.5 < n / Mesh.from_sdf(holes, size=varying).num_cells < 2.0
    assert mesh_mod.estimate_cells(holes, 1 * mm, cell="quad") == pytest.approx(holes.area / mm**2)


def test_a_tiny_size_is_refused_before_meshing(monkeypatch):
    """A size 1000x too small (0.5 um on a 40 mm x 10 mm strip, area 3.75e-4 m^2 over sqrt(3)/4 (0.5 um)^2:
    3.46e9 triangles) is refused from the estimate, naming it,
    the size and the keyword; gmsh never starts (its session is replaced by a failure)."""
    def no_gmsh(*args, **kwargs):
        raise AssertionError("gmsh was started")
    monkeypatch.setattr(mesh_mod._core._gmsh, "session", no_gmsh)
    with pytest.raises(MeshError, match=r"size 5e-07 m would make about 3\.46e\+09 cells .* more than max_cells = "
                                        r"2000000: .* max_cells=\.\.\."):
        Mesh.from_sdf(two_holes(), size=0.5e-3 * mm)
    with pytest.raises(MeshError, match=r"about 8\.66e\+04 cells .* max_cells = 10000"):
        Mesh.from_sdf(two_holes(), size=0.1 * mm, max_cells=10_000)
    with pytest.raises(MeshError, match="max_cells = 100"), mesh_mod.cell_limit(100):   # a sweep's limit
        Mesh.from_sdf(two_holes(), size=1 * mm, refine=[(sdf.Circle(3 * mm), 0.2 * mm)])
    with pytest.raises(MeshError, match="max_cells must be a positive number"):
        Mesh.from_sdf(two_holes(), size=1 * mm, max_cells=True)


# ----------------------------------------------------------------------------------------------- images
def _disk_png(path, n=200, r_px=60):
    from skimage import io as skio
    yy, xx = np.mgrid[0:n, 0:n]
    img = np.where((xx + 0.5 - n / 2) ** 2 + (yy + 0.5 - n / 2) ** 2 <= r_px**2, 0, 255).astype(np.uint8)
    skio.imsave(str(path), img, check_contrast=False)


def test_from_image_disk(tmp_path):
    px = 0.1 * mm
    path = tmp_path / "disk.png"
    _disk_png(path)
    msh = Mesh.from_image(path, pixel_size=px)
    r = 60 * px
    # boundary within half a pixel of the circle: |dA| <= 2 pi r * px / 2
    assert abs(msh.area - math.pi * r**2) <= math.pi * r * px
    assert msh.cavities == []
    lo, hi = msh.bounds
    assert (lo[0] + hi[0]) / 2 == pytest.approx(100 * px, abs=px)


def test_from_image_errors(tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        Mesh.from_image(tmp_path / "missing.png", pixel_size=0.1 * mm)
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(MeshError, match="cannot read image"):
        Mesh.from_image(bad, pixel_size=0.1 * mm)
    from skimage import io as skio
    white = tmp_path / "white.png"
    skio.imsave(str(white), np.full((20, 20), 255, dtype=np.uint8), check_contrast=False)
    with pytest.raises(MeshError, match="no foreground"):
        Mesh.from_image(white, pixel_size=0.1 * mm)
    with pytest.raises(MeshError, match="pixel_size"):
        Mesh.from_image(white, pixel_size=0.0)


# ----------------------------------------------------------------------------------------------- files
def test_xdmf_round_trip(tmp_path, holes_p2):
    msh = Mesh.from_sdf(two_holes(), size=1 * mm, order=2).add_region(
        "layer", sdf.Rectangle(W, 2 * mm, center=(0, -4 * mm)), kind="cells")
    path = msh.write_xdmf(tmp_path / "body.xdmf")
    assert path.exists() and path.with_suffix(".h5").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["body.h5", "body.xdmf"]
    back = Mesh.from_file(path)
    assert set(back.regions) == set(msh.regions)
    assert back.area == pytest.approx(msh.area, rel=1e-12)
    assert back.measure("cavity_1") == pytest.approx(2 * math.pi * R, rel=1e-4)
    assert back.measure("layer") == pytest.approx(msh.measure("layer"), rel=1e-12)


def test_msh_round_trip(tmp_path):
    msh = Mesh.from_sdf(two_holes(), size=1 * mm, order=2).add_region(
        "layer", ((-W, -H), (W, -3 * mm)), kind="cells")
    path = msh.write_msh(tmp_path / "body.msh")
    back = Mesh.from_file(path)
    assert back.quality["degree"] == 2 and back.num_cells == msh.num_cells
    assert back.area == pytest.approx(msh.area, rel=1e-12)
    for name in msh.regions:
        assert back.measure(name) == pytest.approx(msh.measure(name), rel=1e-10), name


def test_stl_to_tetrahedra(tmp_path):
    r = 5 * mm
    stl = tmp_path / "ball.stl"
    sdf.Sphere(r).to_stl(stl, resolution=0.4 * mm)   # ~6k triangles (the default's 150k take gmsh ~15x longer)
    msh = Mesh.from_file(stl, size=1.5 * mm)
    assert msh.dim == 3 and msh.quality["cell"] == "tetrahedron"
    # faceted STL + P1 chords: a few percent below the exact volume
    assert msh.volume == pytest.approx(4 / 3 * math.pi * r**3, rel=4e-2)


def test_file_errors(tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        Mesh.from_file(tmp_path / "nope.stl")
    junk = tmp_path / "junk.stl"
    junk.write_text("solid junk\nendsolid\n")
    with pytest.raises(MeshError):
        Mesh.from_file(junk)


def test_ctrl_c_still_raises_keyboard_interrupt_after_meshing(tmp_path, subprocess_env):
    """gmsh 4.13 (Debian 13) sets SIGINT to SIG_DFL in gmsh.initialize, 4.8 (Debian 12) at import: after a mesh
    is built, Ctrl-C must still raise KeyboardInterrupt (clean-up runs), not kill the process."""
    import subprocess
    import sys

    code = ("import os, signal, time\n"
            "from sorofem import sdf\nfrom sorofem.mesh import Mesh\n"
            "Mesh.from_sdf(sdf.Circle(1e-3), size=0.5e-3)\n"
            "try:\n    os.kill(os.getpid(), signal.SIGINT)\n    time.sleep(5)\n"
            "except KeyboardInterrupt:\n    print('KeyboardInterrupt')\n")
    import signal

    # the child starts with Ctrl-C at its default, as from a terminal (a shell's background job inherits SIGINT
    # ignored, and Python then installs no KeyboardInterrupt handler at all)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=subprocess_env,
                         cwd=tmp_path, timeout=300, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert res.returncode == 0 and res.stdout.strip().endswith("KeyboardInterrupt"), (res.returncode, res.stderr)


def test_plot_draws_in_the_unit_asked_for(holes_p2):
    from matplotlib.figure import Figure

    ax_mm = Figure().subplots()
    holes_p2.plot(ax=ax_mm)                                   # default: millimetres
    ax_m = Figure().subplots()
    holes_p2.plot(ax=ax_m, unit="m")
    assert ax_mm.get_xlabel() == "x [mm]" and ax_m.get_ylabel() == "y [m]"
    np.testing.assert_allclose(ax_mm.get_xlim(), 1e3 * np.asarray(ax_m.get_xlim()), rtol=1e-12)
    lo, hi = holes_p2.bounds
    assert ax_m.get_xlim()[0] < lo[0] and ax_m.get_xlim()[1] > hi[0]
    with pytest.raises(MeshError, match="'mm' or 'm'"):
        holes_p2.plot(ax=ax_m, unit="cm")


@pytest.mark.parametrize("size", [1.3 * mm, 0.7 * mm])
def test_a_mesh_with_interfaces_follows_the_second_materials_edge_at_every_size(size):
    """``interfaces=``: the layer's top (y = -H/2 + 1.7 mm, on no row of a uniform mesh) is a line of cell
    edges, so the layer selected by cell midpoints is exactly W x 1.7 mm (round-off) at any size, the body's
    area and its cavities unchanged; without it the layer is right only to a row of cells (the test above)."""
    layer = sdf.Rectangle(W + 2 * mm, 1.7 * mm, center=(0, -H / 2 + 0.85 * mm))
    msh = Mesh.from_sdf(two_holes(), size=size, interfaces=[layer]).add_region("layer", layer, kind="cells")
    assert msh.measure("layer") == pytest.approx(W * 1.7 * mm, rel=1e-10)
    assert msh.area == pytest.approx(W * H - 2 * math.pi * R**2, rel=(size / R) ** 2 / 6)   # chords of the holes
    assert msh.cavities == ["cavity_0", "cavity_1"] and msh.measure("left") == pytest.approx(H, rel=1e-10)


def test_interfaces_need_the_csg_path_and_shapes_of_the_domains_dimension():
    layer = sdf.Rectangle(W, 2 * mm, center=(0, -H / 2 + 1 * mm))
    with pytest.raises(MeshError, match="CSG path"):
        Mesh.from_sdf(two_holes(), size=2 * mm, method="levelset", interfaces=[layer])
    with pytest.raises(GeometryError, match="2D signed distance"):
        Mesh.from_sdf(two_holes(), size=2 * mm, interfaces=[sdf.Sphere(1 * mm)])


def l_shape():
    """A 20 mm square less its top right quarter: one re-entrant (270 degree) corner, at the origin."""
    return sdf.Rectangle(20 * mm, 20 * mm) - sdf.Rectangle(10 * mm, 10 * mm, center=(5 * mm, 5 * mm))


def test_a_mesh_graded_towards_the_corners_is_fine_there_and_coarse_elsewhere():
    """``grading=(radius, exponent, smallest)``: within 0.3 h of the re-entrant corner (the origin) a uniform mesh
    at h has at most a few cell midpoints (a cell's midpoint lies about h/3 from its vertex); the graded one
    (sizes down to h/10 there) has rings of them, while the whole mesh stays within 3x the uniform count (the
    grading reaches only 1.5 h around each of the 6 corners)."""
    h = 1 * mm

    def near_corner(msh):
        try:
            return len(msh.add_region("near", sdf.Circle(0.3 * h), kind="cells").cells("near"))
        except MeshError:       # no midpoint there
            return 0
    uniform = Mesh.from_sdf(l_shape(), size=h)
    graded = Mesh.from_sdf(l_shape(), size=h, grading=(1.5 * h, 0.4, 0.1))
    assert near_corner(uniform) <= 4 < 8 <= near_corner(graded)
    assert uniform.num_cells < graded.num_cells < 3 * uniform.num_cells
    assert graded.area == pytest.approx(l_shape().area, rel=1e-10)


def test_a_size_function_smallest_at_the_origin_does_not_cap_the_mesh():
    """A callable size is the mesh's size everywhere: 0.3 mm at the origin growing to 2.3 mm at 10 mm. gmsh caps
    the callback at the largest size, which is taken over a sample of the bounds (before, the origin's 0.3 mm
    capped the whole mesh: ~4 times the uniform 0.3 mm estimate's cells, here far fewer)."""
    def size(x):
        return 0.3 * mm + 0.2 * np.linalg.norm(np.atleast_2d(x), axis=1)
    n = Mesh.from_sdf(l_shape(), size=size).num_cells
    assert n < 0.25 * mesh_mod.estimate_cells(l_shape(), 0.3 * mm)


@pytest.mark.parametrize("grading, kw, match", [((1 * mm, 1.2, 0.1), {}, "exponent"),
                                                 ((1 * mm, 0.4), {}, "radius"),
                                                 ((1 * mm, 0.4, 0.1), {"boundary_size": 0.5 * mm}, "number size"),
                                                 ((1 * mm, 0.4, 0.1), {"method": "levelset"}, "CSG path")])
def test_a_bad_grading_is_refused_naming_what_to_fix(grading, kw, match):
    with pytest.raises(MeshError, match=match):
        Mesh.from_sdf(l_shape(), size=1 * mm, grading=grading, **kw)


def test_a_refined_mesh_is_nested_with_the_same_geometry_and_regions():
    """Mesh.refined: every cell split into 8 (3D) or 4 (2D), the measure and the cavity's volume exact (a
    polyhedral domain: midpoints of straight edges stay on it), every old node kept and every new one an old
    edge's midpoint (nested), h halved per split, the cells' shapes bounded (longest edge / inradius), regions found
    again."""
    body = sdf.Box((4 * mm, 2 * mm, 2 * mm)) - sdf.Box((1 * mm, 1 * mm, 1 * mm))
    m0 = Mesh.from_sdf(body, size=0.8 * mm)
    m2 = m0.refined(2)
    assert m2.num_cells == 64 * m0.num_cells
    assert m2.volume == pytest.approx(m0.volume, rel=1e-12)
    assert m2.volume == pytest.approx(16e-9 - 1e-9, rel=1e-12)
    assert sorted(m2.regions) == sorted(m0.regions)
    assert m2.cavity_volume("cavity_0") == pytest.approx(1e-9, rel=1e-12)
    # h halved twice: the cells' longest edges a quarter (the inner octahedra's diagonals up to sqrt 2 x half an edge)
    assert m0.quality["h_max"] / 4 <= m2.quality["h_max"] <= 1.2 * m0.quality["h_max"] / 4
    x0 = np.asarray(m0.dolfinx.geometry.x)
    x2 = np.asarray(m2.dolfinx.geometry.x)
    d, _ = __import__("scipy.spatial", fromlist=["cKDTree"]).cKDTree(x2).query(x0)
    assert d.max() < 1e-15                                      # the coarse nodes are nodes of the fine mesh

    def shape(msh):      # longest edge over inradius, the worst cell: bounded under refinement
        from sorofem import _dolfinx
        P = np.asarray(msh.dolfinx.geometry.x)[_dolfinx.geometry_dofs(msh.dolfinx)]
        a, b, c, e = (P[:, i] for i in range(4))
        vol = np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, e - a))) / 6
        area = sum(np.linalg.norm(np.cross(q - p, r - p), axis=1) / 2 for p, q, r in
                   ((a, b, c), (a, b, e), (a, c, e), (b, c, e)))
        edge = np.max([np.linalg.norm(P[:, i] - P[:, j], axis=1) for i in range(4) for j in range(i + 1, 4)], 0)
        return np.max(edge * area / (3 * vol))
    assert shape(m2) <= 1.5 * shape(m0)
    tri = Mesh.from_sdf(sdf.Rectangle(4 * mm, 2 * mm) - sdf.Rectangle(1 * mm, 1 * mm), size=0.5 * mm)
    t1 = tri.refined()
    assert t1.num_cells == 4 * tri.num_cells and t1.area == pytest.approx(7e-6, rel=1e-12)
    assert tri.refined(0).num_cells == tri.num_cells


@pytest.mark.parametrize("times", [-1, 1.5, "2"])
def test_refined_wants_a_whole_number_of_splits(times):
    with pytest.raises(MeshError, match="whole number"):
        Mesh.rectangle(1 * mm, 1 * mm, 0.5 * mm).refined(times)


def test_refined_splits_straight_simplices_only():
    with pytest.raises(MeshError, match="straight triangles and tetrahedra"):
        Mesh.rectangle(1 * mm, 1 * mm, 0.5 * mm, cell="quad").refined()
    with pytest.raises(MeshError, match="order=1"):
        Mesh.from_sdf(sdf.Circle(1 * mm), size=0.5 * mm, order=2).refined()
