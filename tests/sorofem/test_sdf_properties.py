"""sorofem.sdf: section/mass properties against closed forms, STL and PNG export, fused kernels."""
import math

import numpy as np
import pytest

from sorofem import sdf
from sorofem.errors import GeometryError
from sorofem.units import mm

REL = 1e-3


def _circle_ref(r):
    A = math.pi * r**2
    return A, math.pi * r**4 / 4


@pytest.mark.parametrize("exact", [True, False])
def test_circle_section(exact):
    r, c = 6 * mm, np.array([2 * mm, -1 * mm])
    sp = sdf.Circle(r, c).section_properties() if exact else \
        sdf.section_properties(sdf.Circle(r, c), exact=False)
    A, I = _circle_ref(r)
    assert sp.method == ("exact" if exact else "numerical")
    assert sp.area == pytest.approx(A, rel=REL)
    assert sp.centroid == pytest.approx(c, abs=REL * r)
    assert sp.Iy == pytest.approx(I, rel=REL) and sp.Iz == pytest.approx(I, rel=REL)
    assert sp.J == pytest.approx(2 * I, rel=REL) and abs(sp.Iyz) < REL * I


@pytest.mark.parametrize("exact", [True, False])
def test_rotated_translated_rectangle_section(exact):
    b, h, th = 20 * mm, 10 * mm, math.radians(30)
    shape = sdf.Rectangle(b, h).rotate(th).translate((5 * mm, 3 * mm))
    sp = sdf.section_properties(shape, exact=exact)
    Ix, Iy = b * h**3 / 12, h * b**3 / 12           # about the rectangle's own axes (2D x, 2D y)
    c, s = math.cos(th), math.sin(th)
    # rotated second moments: I_xx' = Ix c^2 + Iy s^2 (int y^2), I_yy' = Ix s^2 + Iy c^2 (int x^2)
    assert sp.area == pytest.approx(b * h, rel=REL)
    assert sp.centroid == pytest.approx([5 * mm, 3 * mm], abs=REL * h)
    assert sp.Iy == pytest.approx(Ix * c**2 + Iy * s**2, rel=REL)
    assert sp.Iz == pytest.approx(Ix * s**2 + Iy * c**2, rel=REL)
    assert sp.Iyz == pytest.approx((Iy - Ix) * s * c, rel=REL)
    assert sp.J == pytest.approx(b * h * (b * b + h * h) / 12, rel=REL)


def test_annulus_through_the_numerical_path():
    R, r = 8 * mm, 5 * mm
    sp = (sdf.Circle(R) - sdf.Circle(r)).translate((1 * mm, 2 * mm)).section_properties()
    assert sp.method == "numerical"
    assert sp.area == pytest.approx(math.pi * (R**2 - r**2), rel=REL)
    assert sp.Iy == pytest.approx(math.pi * (R**4 - r**4) / 4, rel=REL)
    assert sp.J == pytest.approx(math.pi * (R**4 - r**4) / 2, rel=REL)
    assert sp.centroid == pytest.approx([1 * mm, 2 * mm], abs=1e-3 * r)


def test_exact_forms_of_polygon_ellipse_rounded_rectangle_agree_with_integration():
    for shape in [sdf.Polygon(np.array([[0, 0], [0, 10], [4, 10], [4, 4], [10, 4], [10, 0]]) * mm),
                  sdf.Ellipse(6 * mm, 3 * mm, (1 * mm, 0)), sdf.RoundedRectangle(12 * mm, 6 * mm, 2 * mm)]:
        ex = sdf.section_properties(shape)
        nu = sdf.section_properties(shape, exact=False)
        assert ex.method == "exact"
        for k in ("area", "Iy", "Iz", "J"):
            assert getattr(ex, k) == pytest.approx(getattr(nu, k), rel=REL), (shape.op, k)
        assert abs(ex.Iyz - nu.Iyz) < REL * ex.J


def test_sphere_and_box_mass_properties():
    rho, r = 1070.0, 5 * mm
    mp = sdf.Sphere(r, (1 * mm, 0, 0)).mass_properties(density=rho)
    m = rho * 4 / 3 * math.pi * r**3
    assert mp.mass == pytest.approx(m) and mp.center_of_mass == pytest.approx([1 * mm, 0, 0])
    assert mp.inertia == pytest.approx(np.eye(3) * 2 / 5 * m * r**2)
    a, b, c = 10 * mm, 6 * mm, 4 * mm
    box = sdf.Box([a, b, c]).rotate(90, axis=(0, 0, 1), deg=True)
    for exact in (True, False):
        mp = sdf.mass_properties(box, density=rho, exact=exact)
        M = rho * a * b * c
        assert mp.volume == pytest.approx(a * b * c, rel=REL)
        ref = M / 12 * np.diag([a * a + c * c, b * b + c * c, a * a + b * b])   # x and y swapped by the rotation
        assert np.allclose(mp.inertia, ref, rtol=REL, atol=REL * ref.max())
    # a hollow sphere through the numerical path
    R, ri = 6 * mm, 4 * mm
    mp = (sdf.Sphere(R) - sdf.Sphere(ri)).mass_properties(density=rho)
    assert mp.method == "numerical"
    assert mp.volume == pytest.approx(4 / 3 * math.pi * (R**3 - ri**3), rel=REL)
    assert mp.inertia[0, 0] == pytest.approx(8 / 15 * math.pi * rho * (R**5 - ri**5), rel=2 * REL)


def test_cylinder_torus_and_extrusion_exact_forms():
    r, h = 3 * mm, 10 * mm
    cyl = sdf.Cylinder(r, h, axis=(1, 0, 0))
    ex = cyl.mass_properties()
    nu = sdf.mass_properties(cyl, exact=False)
    assert ex.volume == pytest.approx(math.pi * r * r * h)
    assert np.allclose(ex.inertia, nu.inertia, rtol=REL, atol=REL * ex.inertia.max())
    tor = sdf.Torus(8 * mm, 2 * mm)
    assert np.allclose(tor.mass_properties().inertia, sdf.mass_properties(tor, exact=False).inertia,
                       rtol=2 * REL, atol=2 * REL * tor.mass_properties().inertia.max())
    assert sdf.Circle(r).extrude(h).mass_properties().volume == pytest.approx(math.pi * r * r * h)


def test_empty_and_unbounded_shapes_are_refused():
    disjoint = sdf.Circle(1 * mm) & sdf.Circle(1 * mm, (5 * mm, 0))
    with pytest.raises(GeometryError, match="empty.*overlap"):
        disjoint.section_properties()
    with pytest.raises(GeometryError, match="empty"):
        (sdf.Sphere(1 * mm) & sdf.Sphere(1 * mm, (5 * mm, 0, 0))).to_stl("/tmp/never.stl")
    with pytest.raises(GeometryError, match="empty"):   # bounds overlap but nothing inside
        (sdf.Circle(2 * mm) - sdf.Rectangle(5 * mm, 5 * mm)).section_properties()
    with pytest.raises(GeometryError, match="unbounded"):
        sdf.Line().section_properties()
    with pytest.raises(GeometryError, match="2D region"):
        sdf.Sphere(1).section_properties()
    with pytest.raises(GeometryError, match="3D solid"):
        sdf.Circle(1).to_stl("/tmp/never.stl")
    with pytest.raises(GeometryError, match="density"):
        sdf.Sphere(1).mass_properties(density=-1)


def _check_watertight(tri):
    verts, inv = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    faces = inv.reshape(-1, 3)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    und, counts = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2), "every edge must be shared by exactly two triangles"
    # consistent orientation: each directed edge appears once, its reverse once
    directed = np.unique(edges, axis=0)
    assert len(directed) == len(edges)
    return verts, faces


def test_sphere_stl_is_watertight_outward_and_accurate(tmp_path):
    r = 10 * mm
    path = sdf.Sphere(r, (1 * mm, 2 * mm, 3 * mm)).to_stl(tmp_path / "sphere.stl")
    tri, nrm = sdf.read_stl(path)
    verts, faces = _check_watertight(tri)
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert vol > 0
    assert abs(vol - 4 / 3 * math.pi * r**3) / (4 / 3 * math.pi * r**3) < 0.01
    # normals point away from the centre
    cen = tri.mean(axis=1) - np.array([1, 2, 3]) * mm
    assert np.all(np.einsum("ij,ij->i", nrm, cen) > 0)
    assert np.allclose(np.linalg.norm(verts - np.array([1, 2, 3]) * mm, axis=1), r, atol=0.02 * r)


def test_stl_of_a_boolean_solid_is_watertight(tmp_path):
    solid = sdf.Box(10 * mm) - sdf.Cylinder(3 * mm, 20 * mm) | sdf.Sphere(3 * mm, (5 * mm, 5 * mm, 5 * mm))
    tri, _ = sdf.read_stl(sdf.to_stl(solid, tmp_path / "b.stl", resolution=0.4 * mm))
    _check_watertight(tri)
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    ref = sdf.mass_properties(solid).volume
    assert vol == pytest.approx(ref, rel=0.02)


def test_png_previews(tmp_path):
    shape = sdf.Rectangle(20 * mm, 10 * mm).rotate(45, deg=True) - sdf.Circle(3 * mm)
    p2 = shape.to_png(tmp_path / "a.png")
    p3 = (sdf.Sphere(5 * mm) - sdf.Box(4 * mm)).to_png(tmp_path / "b.png", plane="xz", at=1 * mm)
    for p in (p2, p3):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(GeometryError, match="plane"):
        sdf.Sphere(1).to_png(tmp_path / "c.png", plane="ab")


def test_fused_kernel_agrees_with_numpy_for_every_node_type():
    rng = np.random.default_rng(3)
    poly = sdf.Polygon(np.array([[0, 0], [6, 0], [6, 2], [2, 2], [2, 6], [0, 6]]) * mm)
    two = ((sdf.Circle(3 * mm) | sdf.RoundedRectangle(6 * mm, 3 * mm, 1 * mm, (4 * mm, 0)))
           .smooth_union(sdf.Ellipse(4 * mm, 2 * mm, (0, 3 * mm)), 1 * mm)
           .smooth_difference(sdf.Strut((0, 0), (5 * mm, 5 * mm), 1 * mm), 0.5 * mm)
           .smooth_intersection(sdf.Line((0, 4 * mm), (0.2, 1)), 0.5 * mm)
           - sdf.Segment((-3 * mm, 0), (0, -3 * mm), 0.5 * mm) | poly.mirror((1, 1)).scale(0.8)
           | sdf.Polyline(np.array([[0, 0], [3, 1], [4, 4]]) * mm, 0.4 * mm).rotate(20, deg=True)
           ).shell(0.5 * mm).offset(0.1 * mm) & sdf.Rectangle(30 * mm, 30 * mm)
    three = ((two.extrude(4 * mm) | sdf.Box([4 * mm, 5 * mm, 6 * mm]).rotate(30, axis=(1, 2, 3), deg=True))
             - sdf.Sphere(2 * mm) | sdf.Cylinder(1 * mm, 8 * mm, axis=(1, 0, 0)) | sdf.Torus(6 * mm, 1 * mm)
             | sdf.Cone(2 * mm, 5 * mm, (0, 0, 2 * mm)) | sdf.Capsule((0, 0, 0), (0, 5 * mm, 5 * mm), 1 * mm)
             | sdf.Circle(1 * mm).revolve(axis=(0, 1, 0), offset=4 * mm)) & sdf.Plane((0, 0, 5 * mm))
    for shape in (two, three):
        p = rng.uniform(-12 * mm, 12 * mm, (20000, shape.dim))
        assert shape.compiled() is not None
        assert np.allclose(shape(p, compiled=True), shape(p, compiled=False), atol=1e-14)
    rep = sdf.Sphere(1 * mm).repeat((3 * mm, 0, 2 * mm), (4, 1, 3))
    p = rng.uniform(-5 * mm, 12 * mm, (20000, 3))
    assert np.allclose(rep(p, compiled=True), rep(p, compiled=False), atol=1e-15)
    # circular patterns have no kernel: the numpy path is used transparently
    cr = sdf.Circle(1 * mm, (3 * mm, 0)).circular_repeat(5)
    assert cr.compiled() is None
    assert cr(np.zeros((300_000, 2))).shape == (300_000,)
    with pytest.raises(GeometryError, match="compiled=False"):
        cr(np.zeros((3, 2)), compiled=True)
