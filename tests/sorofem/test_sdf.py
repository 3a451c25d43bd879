"""sorofem.sdf: distances of every primitive against closed forms or brute force, operators, queries, errors.

Brute force = distance to a dense sampling of the true boundary (a KD-tree query); its error is below
(spacing^2 / 8R) + spacing/2 which the tolerances state explicitly.
"""
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sorofem import sdf
from sorofem.errors import ConvergenceError, GeometryError
from sorofem.units import deg, mm

RNG = np.random.default_rng(20240601)


def _rand(lo, hi, n=400, rng=RNG):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return rng.uniform(lo, hi, (n, len(lo)))


def _segments(vertices, closed=True, n_per_m=2e5):
    """Dense sampling of a polygonal curve [m]; spacing <= 1/n_per_m."""
    v = np.asarray(vertices, float)
    if closed:
        v = np.vstack([v, v[:1]])
    out = []
    for a, b in zip(v[:-1], v[1:]):
        k = max(2, int(np.linalg.norm(b - a) * n_per_m))
        t = np.linspace(0, 1, k)[:, None]
        out.append(a + t * (b - a))
    return np.vstack(out)


def _brute(points, boundary):
    return cKDTree(boundary).query(points)[0]


def _inside_polygon(p, v):
    """Even-odd test via matplotlib-free winding (independent of the library)."""
    v = np.asarray(v)
    x, y = p[:, 0], p[:, 1]
    ins = np.zeros(len(p), bool)
    for (x1, y1), (x2, y2) in zip(v, np.roll(v, -1, axis=0)):
        c = ((y1 > y) != (y2 > y)) & (x < (x2 - x1) * (y - y1) / np.where(y2 != y1, y2 - y1, 1) + x1)
        ins ^= c
    return ins


# ====================================================================== 2D primitives
def test_circle_is_exact():
    c, r = np.array([1.0, -2.0]) * mm, 3 * mm
    p = _rand([-5 * mm, -7 * mm], [7 * mm, 3 * mm])
    assert np.allclose(sdf.Circle(r, c)(p), np.hypot(*(p - c).T) - r, atol=1e-15)


def test_rectangle_is_exact_against_brute_force():
    w, h, c = 20 * mm, 10 * mm, np.array([2 * mm, 1 * mm])
    corners = c + np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
    p = _rand([-20 * mm, -15 * mm], [20 * mm, 15 * mm])
    ref = _brute(p, _segments(corners))
    inside = np.all(np.abs(p - c) < [w / 2, h / 2], axis=1)
    ref = np.where(inside, -ref, ref)
    assert np.allclose(sdf.Rectangle(w, h, center=c)(p), ref, atol=5e-6 * mm * 1e3)


def test_rounded_rectangle_is_exact():
    w, h, r = 20 * mm, 12 * mm, 3 * mm
    # boundary = offset of the inner rectangle by r: distance = dist(inner rect) - r
    inner = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [w / 2 - r, h / 2 - r]
    p = _rand([-20 * mm, -15 * mm], [20 * mm, 15 * mm])
    d_in = _brute(p, _segments(inner, n_per_m=2e6))
    inside_inner = np.all(np.abs(p) < [w / 2 - r, h / 2 - r], axis=1)
    ref = np.where(inside_inner, -d_in, d_in) - r
    assert np.allclose(sdf.RoundedRectangle(w, h, r)(p), ref, atol=3e-7)
    assert sdf.Squircle is sdf.RoundedRectangle


@pytest.mark.parametrize("a,b", [(10 * mm, 4 * mm), (3 * mm, 8 * mm), (5 * mm, 5 * mm)])
def test_ellipse_is_exact_against_dense_boundary(a, b):
    c = np.array([1 * mm, 2 * mm])
    t = np.linspace(0, 2 * np.pi, 200_000)
    bnd = c + np.column_stack([a * np.cos(t), b * np.sin(t)])
    p = np.vstack([_rand(c - 2 * max(a, b), c + 2 * max(a, b)),
                   c + np.array([[0, 0], [a / 2, 0], [0, b / 3], [3 * a, 0], [0, -2 * b]])])  # axes too
    ref = _brute(p, bnd)
    ref = np.where(((p - c) ** 2 / [a * a, b * b]).sum(1) < 1, -ref, ref)
    spacing = 2 * np.pi * max(a, b) / len(t)
    e = sdf.Ellipse(a, b, center=c)
    assert np.allclose(e(p), ref, atol=spacing)
    assert np.allclose(e(p, compiled=True), e(p, compiled=False), atol=1e-12)


POLYS = {
    "triangle": [[0, 0], [10, 0], [3, 8]],
    "L_cw": [[0, 0], [0, 10], [4, 10], [4, 4], [10, 4], [10, 0]],
    "star": [[np.cos(a) * (10 if i % 2 == 0 else 4), np.sin(a) * (10 if i % 2 == 0 else 4)]
             for i, a in enumerate(np.linspace(0, 2 * np.pi, 10, endpoint=False))],
}


@pytest.mark.parametrize("name", sorted(POLYS))
def test_polygon_is_exact(name):
    v = np.array(POLYS[name], float) * mm
    poly = sdf.Polygon(v)
    p = _rand(v.min(0) - 5 * mm, v.max(0) + 5 * mm)
    ref = _brute(p, _segments(v, n_per_m=3e5))
    ref = np.where(_inside_polygon(p, v), -ref, ref)
    assert np.allclose(poly(p), ref, atol=1.5e-6)
    assert np.allclose(poly(p, compiled=True), poly(p, compiled=False), atol=1e-15)


def test_polyline_segment_and_strut_are_exact():
    v = np.array([[0, 0], [10, 0], [10, 10], [20, 15]]) * mm
    t = 2 * mm
    p = _rand([-5 * mm, -5 * mm], [25 * mm, 20 * mm])
    ref = _brute(p, _segments(v, closed=False, n_per_m=1e6)) - t / 2
    pl = sdf.Polyline(v, t)
    assert np.allclose(pl(p), ref, atol=1e-6)
    assert np.allclose(pl(p, compiled=True), pl(p), atol=1e-15)
    ref_seg = _brute(p, _segments(v[:2], closed=False, n_per_m=1e6)) - t / 2
    assert np.allclose(sdf.Segment(v[0], v[1], t)(p), ref_seg, atol=1e-6)
    assert np.allclose(sdf.Strut(v[0], v[1], width=t)(p), ref_seg, atol=1e-6)


def test_line_is_a_half_plane():
    ln = sdf.Line(point=(0, 1 * mm), normal=(0, 2))
    p = _rand([-5 * mm, -5 * mm], [5 * mm, 5 * mm])
    assert np.allclose(ln(p), p[:, 1] - 1 * mm)
    assert np.isinf(ln.bounds[0]).all() and ln.bounds[1][1] == pytest.approx(1 * mm)


# ====================================================================== 3D primitives
def test_sphere_box_capsule_torus_are_exact():
    p = _rand([-20 * mm] * 3, [20 * mm] * 3)
    c = np.array([1, 2, 3]) * mm
    assert np.allclose(sdf.Sphere(5 * mm, c)(p), np.linalg.norm(p - c, axis=1) - 5 * mm)
    # box: outside |p - clamp(p)|, inside -(distance to the nearest face)
    lo, hi = c - [4 * mm, 3 * mm, 2 * mm], c + [4 * mm, 3 * mm, 2 * mm]
    out = np.linalg.norm(p - np.clip(p, lo, hi), axis=1)
    ins = np.all((p > lo) & (p < hi), axis=1)
    ref = np.where(ins, -np.minimum(p - lo, hi - p).min(axis=1), out)
    assert np.allclose(sdf.Box([8 * mm, 6 * mm, 4 * mm], c)(p), ref, atol=1e-15)
    a, b = np.array([0, 0, 0]) * mm, np.array([5, 5, 10]) * mm
    t = np.linspace(0, 1, 300_000)[:, None]
    assert np.allclose(sdf.Capsule(a, b, 2 * mm)(p), _brute(p, a + t * (b - a)) - 2 * mm, atol=1e-7)
    R, r = 8 * mm, 2 * mm
    ref = np.hypot(np.hypot(p[:, 0], p[:, 1]) - R, p[:, 2]) - r
    assert np.allclose(sdf.Torus(R, r)(p), ref)
    # a torus is a revolved circle
    assert np.allclose(sdf.Circle(r).revolve(offset=R)(p), ref)


def _meridian(p, axis, center):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    q = p - center
    z = q @ a
    return np.column_stack([np.linalg.norm(q - np.outer(z, a), axis=1), z])


def test_cylinder_with_any_axis_is_exact():
    r, h, c, axis = 3 * mm, 10 * mm, np.array([1, 0, 2]) * mm, (1, 1, 0.5)
    p = _rand([-15 * mm] * 3, [15 * mm] * 3)
    rz = _meridian(p, axis, c)
    # 2D brute force in the meridian half-plane against the rectangle [0, r] x [-h/2, h/2] minus the axis edge
    edges = _segments([[0, -h / 2], [r, -h / 2], [r, h / 2], [0, h / 2]], closed=False, n_per_m=1e6)
    ref = _brute(rz, edges)
    ins = (rz[:, 0] < r) & (np.abs(rz[:, 1]) < h / 2)
    assert np.allclose(sdf.Cylinder(r, h, c, axis)(p), np.where(ins, -ref, ref), atol=1e-6)


@pytest.mark.parametrize("top", [0.0, 2 * mm])
def test_cone_is_exact(top):
    r, h = 5 * mm, 8 * mm
    p = _rand([-12 * mm] * 3, [12 * mm] * 3)
    rz = _meridian(p, (0, 0, 1), np.zeros(3))
    edges = _segments([[0, 0], [r, 0], [top, h], [0, h]], closed=False, n_per_m=1e6)
    ref = _brute(rz, edges)
    ins = (rz[:, 1] > 0) & (rz[:, 1] < h) & (rz[:, 0] < r + (top - r) * rz[:, 1] / h)
    cone = sdf.Cone(r, h, top_radius=top)
    assert np.allclose(cone(p), np.where(ins, -ref, ref), atol=1e-6)
    assert np.allclose(cone(p, compiled=True), cone(p), atol=1e-14)


def test_plane_and_extrude():
    p = _rand([-10 * mm] * 3, [10 * mm] * 3)
    assert np.allclose(sdf.Plane((0, 0, 1 * mm), (0, 0, -3))(p), 1 * mm - p[:, 2])
    # extruding a rectangle gives the box
    box = sdf.Box([6 * mm, 4 * mm, 8 * mm])
    ext = sdf.Rectangle(6 * mm, 4 * mm).extrude(8 * mm)
    assert np.allclose(ext(p), box(p), atol=1e-15)
    assert np.allclose(ext.gradient(p), box.gradient(p), atol=1e-12)


def test_revolved_rectangle_is_the_cylinder_and_revolve_offset_is_a_tube():
    p = _rand([-10 * mm] * 3, [10 * mm] * 3)
    cyl = sdf.Cylinder(3 * mm, 6 * mm, axis=(0, 1, 0))
    rev = sdf.Rectangle(6 * mm, 6 * mm).revolve(axis=(0, 1, 0))
    assert np.allclose(rev(p), cyl(p), atol=1e-15)
    tube = sdf.Rectangle(2 * mm, 6 * mm).revolve(offset=4 * mm)   # radii 3..5 mm
    ref = (sdf.Cylinder(5 * mm, 6 * mm) - sdf.Cylinder(3 * mm, 8 * mm))(p)
    inside = ref < 0
    assert np.array_equal(tube(p) < 0, inside)


# ====================================================================== booleans and transforms
def _shape_and_boundary():
    """A 2D boolean/transform tree and a dense sampling of its true boundary (from the operands')."""
    rect = sdf.Rectangle(20 * mm, 10 * mm).rotate(30, deg=True).translate((1 * mm, 2 * mm))
    hole = sdf.Circle(3 * mm, (2 * mm, 1 * mm))
    lobe = sdf.Circle(5 * mm, (10 * mm, 4 * mm))
    shape = (rect | lobe) - hole
    R = np.array([[math.cos(30 * deg), -math.sin(30 * deg)], [math.sin(30 * deg), math.cos(30 * deg)]])
    rect_b = _segments(np.array([[-10, -5], [10, -5], [10, 5], [-10, 5]]) * mm, n_per_m=5e5) @ R.T \
        + [1 * mm, 2 * mm]
    t = np.linspace(0, 2 * np.pi, 100_000)[:, None]
    hole_b = [2 * mm, 1 * mm] + 3 * mm * np.hstack([np.cos(t), np.sin(t)])
    lobe_b = [10 * mm, 4 * mm] + 5 * mm * np.hstack([np.cos(t), np.sin(t)])
    cand = np.vstack([rect_b, hole_b, lobe_b])
    keep = np.abs(shape(cand)) < 1e-9
    return shape, cand[keep]


def test_booleans_and_transforms_never_overestimate_the_distance():
    shape, bnd = _shape_and_boundary()
    p = _rand([-20 * mm, -15 * mm], [20 * mm, 15 * mm], n=2000)
    true = _brute(p, bnd)
    d = shape(p)
    assert np.all(np.abs(d) <= true + 1e-8)
    # and exact outside the union where the nearest feature is a single operand: most points agree
    assert np.mean(np.isclose(np.abs(d), true, atol=1e-8)) > 0.8


def test_boolean_signs_follow_set_membership():
    a, b = sdf.Circle(5 * mm), sdf.Rectangle(6 * mm, 12 * mm, center=(4 * mm, 0))
    p = _rand([-10 * mm] * 2, [10 * mm] * 2, n=3000)
    ia, ib = a(p) < 0, b(p) < 0
    assert np.array_equal((a | b)(p) < 0, ia | ib)
    assert np.array_equal((a & b)(p) < 0, ia & ib)
    assert np.array_equal((a - b)(p) < 0, ia & ~ib)


def test_transforms_are_exact_and_immutable():
    p = _rand([-10 * mm] * 2, [10 * mm] * 2)
    base = sdf.Rectangle(8 * mm, 4 * mm)
    moved = base.translate((1 * mm, 2 * mm))
    assert np.allclose(moved(p), sdf.Rectangle(8 * mm, 4 * mm, center=(1 * mm, 2 * mm))(p))
    assert np.allclose(base.rotate(90, deg=True)(p), sdf.Rectangle(4 * mm, 8 * mm)(p), atol=1e-15)
    assert np.allclose(sdf.Circle(1 * mm, (1 * mm, 0)).scale(3)(p), sdf.Circle(3 * mm, (3 * mm, 0))(p))
    m = sdf.Circle(1 * mm, (3 * mm, 0)).mirror((1, 0), point=(1 * mm, 0))
    assert np.allclose(m(p), sdf.Circle(1 * mm, (-1 * mm, 0))(p))
    about = base.rotate(180, deg=True, about=(5 * mm, 0))
    assert np.allclose(about(p), sdf.Rectangle(8 * mm, 4 * mm, center=(10 * mm, 0))(p), atol=1e-15)
    with pytest.raises(AttributeError, match="immutable"):
        base.dim = 3
    assert base.params["width"] == pytest.approx(8 * mm)
    # 3D rotation (axis-angle and matrix agree), chained
    q = _rand([-10 * mm] * 3, [10 * mm] * 3)
    box = sdf.Box([2 * mm, 4 * mm, 6 * mm])
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    assert np.allclose(box.rotate(90, axis=(0, 0, 1), deg=True)(q), box.rotate(matrix=R)(q), atol=1e-15)
    assert np.allclose(box.rotate(matrix=R)(q), sdf.Box([4 * mm, 2 * mm, 6 * mm])(q), atol=1e-15)


def test_smooth_operators_blend_within_radius():
    a, b = sdf.Circle(4 * mm, (-3 * mm, 0)), sdf.Circle(4 * mm, (3 * mm, 0))
    k = 2 * mm
    p = _rand([-10 * mm] * 2, [10 * mm] * 2, n=2000)
    su, u = a.smooth_union(b, k)(p), (a | b)(p)
    assert np.all(su <= u + 1e-15) and np.all(su >= u - k / 4 - 1e-15)
    sd, dd = a.smooth_difference(b, k)(p), (a - b)(p)
    assert np.all(sd >= dd - 1e-15) and np.all(sd <= dd + k / 4 + 1e-15)
    si, ii = a.smooth_intersection(b, k)(p), (a & b)(p)
    assert np.all(si >= ii - 1e-15) and np.all(si <= ii + k / 4 + 1e-15)
    far = np.abs(a(p) - b(p)) > k
    assert np.allclose(su[far], u[far])


def test_shell_offset_and_patterns():
    p = _rand([-30 * mm] * 2, [30 * mm] * 2, n=2000)
    ring = sdf.Circle(10 * mm).shell(2 * mm)     # inner wall: radii 8..10 mm
    r = np.hypot(*p.T)
    assert np.allclose(ring(p), np.maximum(r - 10 * mm, 8 * mm - r))
    assert np.allclose(sdf.Circle(10 * mm).shell(2 * mm, side="center")(p), np.abs(r - 10 * mm) - 1 * mm)
    assert np.allclose(sdf.Circle(10 * mm).offset(1 * mm)(p), r - 11 * mm)
    # linear repeat == explicit union of translated copies
    c = sdf.Circle(2 * mm)
    rep = c.repeat((6 * mm, 5 * mm), (4, 3))
    ref = sdf.Union(*[c.translate((i * 6 * mm, j * 5 * mm)) for i in range(4) for j in range(3)])
    assert np.allclose(rep(p), ref(p))
    assert np.allclose(rep.bounds[0], [-2 * mm, -2 * mm]) and np.allclose(rep.bounds[1], [20 * mm, 12 * mm])
    # circular repeat == union of rotated copies
    s = sdf.Rectangle(4 * mm, 2 * mm, center=(8 * mm, 0))
    cr = s.circular_repeat(6)
    ref = sdf.Union(*[s.rotate(60 * k, deg=True) for k in range(6)])
    assert np.allclose(cr(p), ref(p), atol=1e-15)
    q = _rand([-15 * mm] * 3, [15 * mm] * 3, n=1000)
    s3 = sdf.Sphere(2 * mm, (0, 8 * mm, 0))
    cr3 = s3.circular_repeat(5, axis=(1, 0, 0))
    ref3 = sdf.Union(*[s3.rotate(72 * k, axis=(1, 0, 0), deg=True) for k in range(5)])
    assert np.allclose(cr3(q), ref3(q), atol=1e-15)
    assert np.allclose(cr3.gradient(q), ref3.gradient(q), atol=1e-9)


# ====================================================================== queries
def _assert_gradient_ok(shape, p):
    g = shape.gradient(p)
    assert np.all(np.isfinite(g))
    h = 1e-7
    fd = np.column_stack([(shape(p + h * e) - shape(p - h * e)) / (2 * h) for e in np.eye(shape.dim)])
    assert np.allclose(g, fd, atol=1e-5)
    assert np.allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-5)


GRAD_SHAPES = {
    "circle": sdf.Circle(5 * mm, (1 * mm, 0)),
    "rectangle": sdf.Rectangle(10 * mm, 6 * mm),
    "rounded": sdf.RoundedRectangle(10 * mm, 6 * mm, 2 * mm),
    "ellipse": sdf.Ellipse(6 * mm, 3 * mm),
    "polygon": sdf.Polygon(np.array(POLYS["L_cw"]) * mm),
    "polyline": sdf.Polyline(np.array([[0, 0], [10, 0], [10, 10]]) * mm, 2 * mm),
    "rotated-diff": sdf.Rectangle(20 * mm, 10 * mm).rotate(45, deg=True) - sdf.Circle(3 * mm),
    "sphere": sdf.Sphere(5 * mm),
    "box": sdf.Box([10 * mm, 6 * mm, 4 * mm]).rotate(30, axis=(1, 1, 0), deg=True),
    "cylinder": sdf.Cylinder(3 * mm, 8 * mm, axis=(1, 0, 1)),
    "torus": sdf.Torus(6 * mm, 2 * mm).translate((1 * mm, 0, 0)),
    "cone": sdf.Cone(5 * mm, 8 * mm),
    "capsule": sdf.Capsule((0, 0, 0), (5 * mm, 0, 0), 2 * mm),
    "extrude": sdf.Circle(4 * mm).extrude(6 * mm),
    "revolve": sdf.Rectangle(2 * mm, 6 * mm).revolve(offset=4 * mm),
    "scaled-mirrored": sdf.Sphere(2 * mm, (3 * mm, 0, 0)).scale(2).mirror((1, 0, 0)),
}


@pytest.mark.parametrize("name", sorted(GRAD_SHAPES))
def test_gradient_matches_finite_differences_away_from_medial_axes(name):
    shape = GRAD_SHAPES[name]
    lo, hi = shape.bounds
    p = _rand(lo - 3 * mm, hi + 3 * mm, n=600)
    # drop points near a medial axis/kink: where finite differences of different step sizes disagree
    h1, h2 = 1e-7, 3e-7
    ok = np.ones(len(p), bool)
    for e in np.eye(shape.dim):
        f1 = (shape(p + h1 * e) - shape(p - h1 * e)) / (2 * h1)
        f2 = (shape(p + h2 * e) - shape(p - h2 * e)) / (2 * h2)
        ok &= np.abs(f1 - f2) < 1e-7
    assert ok.sum() > 200
    _assert_gradient_ok(shape, p[ok])


def test_gradient_has_no_nan_at_centres():
    for shape, c in [(sdf.Circle(2 * mm), [0, 0]), (sdf.Sphere(2 * mm), [0, 0, 0]),
                     (sdf.Torus(5 * mm, 1 * mm), [0, 0, 0]), (sdf.Cylinder(1 * mm, 2 * mm), [0, 0, 0]),
                     (sdf.Circle(1 * mm).revolve(offset=3 * mm), [0, 0, 0]),
                     (sdf.Rectangle(2 * mm, 2 * mm), [0, 0]), (sdf.Box(2 * mm), [0, 0, 0])]:
        g = shape.gradient(np.array([c], float))
        assert np.all(np.isfinite(g)) and np.linalg.norm(g) == pytest.approx(1.0), shape.op
        n, t, b = shape.frames(np.array([c], float))
        assert np.all(np.isfinite(n)) and np.all(np.isfinite(t)) and np.all(np.isfinite(b))


@pytest.mark.parametrize("name", ["rotated-diff", "polygon", "ellipse", "box", "torus", "cone", "revolve"])
def test_projection_lands_on_the_surface(name):
    shape = GRAD_SHAPES[name]
    lo, hi = shape.bounds
    p = _rand(lo - 2 * mm, hi + 2 * mm, n=300)
    x, dist = shape.project(p)
    assert np.all(np.abs(shape(x)) < 1e-6 * shape.size)
    # for these exact shapes the projection is the closest point: |p - x| = |d(p)|
    assert np.allclose(np.abs(dist), np.abs(shape(p)), atol=1e-6 * shape.size)
    assert np.array_equal(np.sign(dist), np.sign(shape(p)))


def test_projection_of_a_smooth_union_converges():
    shape = sdf.Circle(4 * mm, (-3 * mm, 0)).smooth_union(sdf.Circle(4 * mm, (3 * mm, 0)), 2 * mm)
    p = _rand([-12 * mm] * 2, [12 * mm] * 2, n=300)
    x, _ = shape.project(p)
    assert np.all(np.abs(shape(x)) < 1e-6 * shape.size)


def test_frames_are_orthonormal():
    shape = GRAD_SHAPES["torus"]
    p = _rand([-10 * mm] * 3, [10 * mm] * 3, n=200)
    n, t, b = shape.frames(p)
    F = np.stack([n, t, b], axis=2)
    assert np.allclose(np.einsum("nij,nik->njk", F, F), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(F), 1.0)
    assert np.allclose(n, shape.gradient(p) / np.linalg.norm(shape.gradient(p), axis=1, keepdims=True))
    n2, t2, b2 = sdf.Circle(1 * mm).frames(np.array([[2 * mm, 0]]))
    assert np.allclose(n2, [[1, 0]]) and np.allclose(t2, [[0, 1]]) and np.allclose(b2, [[0, 0, 1]])


def test_bounds_are_conservative():
    shapes = [GRAD_SHAPES[k] for k in GRAD_SHAPES] + [
        sdf.Circle(2 * mm).repeat((5 * mm, 0), (3, 1)).rotate(20, deg=True),
        sdf.Circle(1 * mm, (5 * mm, 0)).circular_repeat(7),
        sdf.Box(3 * mm).shell(0.5 * mm, side="outer"),
        sdf.Sphere(3 * mm).smooth_union(sdf.Sphere(2 * mm, (4 * mm, 0, 0)), 2 * mm)]
    for s in shapes:
        lo, hi = s.bounds
        span = hi - lo
        p = _rand(lo - span, hi + span, n=20000)
        inside = s(p) < 0
        assert inside.any(), s.op
        assert np.all(p[inside] >= lo - 1e-12) and np.all(p[inside] <= hi + 1e-12), s.op


# ====================================================================== tree contract
def test_tree_contract_and_is_csg():
    shape = sdf.Rectangle(20 * mm, 10 * mm).rotate(45, deg=True) - sdf.Circle(3 * mm)
    assert shape.dim == 2 and shape.op == "difference" and len(shape.children) == 2
    rot, circ = shape.children
    assert rot.op == "rotate" and rot.params["matrix"].shape == (2, 2)
    assert set(rot.children[0].params) == {"width", "height", "center"}
    assert circ.op == "circle" and circ.params["radius"] == pytest.approx(3e-3)
    assert tuple(circ.params["center"]) == (0.0, 0.0) and circ.children == ()
    assert sdf.Polygon(np.array(POLYS["triangle"]) * mm).params["vertices"].shape == (3, 2)
    assert sdf.Circle(1).translate((1, 2)).params["offset"].tolist() == [1, 2]
    assert sdf.is_csg(shape)
    assert sdf.is_csg((sdf.Box(1) | sdf.Sphere(1).translate((1, 0, 0))).mirror((1, 0, 0)))
    assert not sdf.is_csg(sdf.Circle(1).smooth_union(sdf.Circle(1, (1, 0)), 0.1))
    assert not sdf.is_csg(sdf.Circle(1).extrude(1))
    assert not sdf.is_csg(sdf.Circle(1).shell(0.1))
    u = sdf.Circle(1) | sdf.Circle(1, (1, 0)) | sdf.Circle(1, (2, 0))
    assert u.op == "union" and len(u.children) == 3   # n-ary, flattened
    ops = {type(s).op for s in [sdf.Circle(1), sdf.Rectangle(1), sdf.RoundedRectangle(1), sdf.Ellipse(1, 2),
                               sdf.Line(), sdf.Sphere(1), sdf.Box(1), sdf.Cylinder(1, 1), sdf.Cone(1, 1),
                               sdf.Torus(2, 1), sdf.Plane(), sdf.Capsule((0, 0, 0), (1, 0, 0), 1)]}
    assert ops <= sdf.PRIMITIVE_OPS_2D | sdf.PRIMITIVE_OPS_3D


# ====================================================================== bad input
@pytest.mark.parametrize("make", [
    lambda: sdf.Circle(0), lambda: sdf.Circle(-1 * mm), lambda: sdf.Rectangle(1, -1), lambda: sdf.Box([1, 0, 1]),
    lambda: sdf.Sphere(float("nan")), lambda: sdf.Cylinder(1, 0), lambda: sdf.Torus(1, -1),
    lambda: sdf.Ellipse(1, 0), lambda: sdf.Circle(1).shell(0), lambda: sdf.Circle(1).scale(-2),
    lambda: sdf.Circle(1).scale([1, 2]), lambda: sdf.RoundedRectangle(2, 2, radius=1.5),
    lambda: sdf.Polyline([[0, 0], [1, 0]], 0), lambda: sdf.Circle(1, center=(0, 0, 0)),
    lambda: sdf.Circle(1).extrude(1).extrude(1), lambda: sdf.Circle(1) | sdf.Sphere(1),
    lambda: sdf.Box(1).rotate(30, deg=True), lambda: sdf.Circle(1).rotate(matrix=np.diag([1, -1])),
    lambda: sdf.Circle(1).repeat((1, 1), 0), lambda: sdf.Line(normal=(0, 0)),
])
def test_bad_sizes_and_arguments_raise_geometry_error(make):
    with pytest.raises(GeometryError):
        make()


def test_polygon_validation_messages():
    with pytest.raises(GeometryError, match="at least 3 vertices"):
        sdf.Polygon([[0, 0], [1, 0]])
    with pytest.raises(GeometryError, match="self-intersecting.*reorder"):
        sdf.Polygon([[0, 0], [1, 1], [1, 0], [0, 1]])     # bow tie
    with pytest.raises(GeometryError, match="self-intersecting"):
        sdf.Polygon([[0, 0], [4, 0], [4, 4], [2, 0], [0, 4]])   # vertex touching an edge
    with pytest.raises(GeometryError, match="zero-length edge"):
        sdf.Polygon([[0, 0], [1, 0], [1, 0], [0, 1]])
    with pytest.raises(GeometryError, match="zero area"):
        sdf.Polygon([[0, 0], [1, 0], [2, 0]])
    assert sdf.Polygon([[0, 0], [1, 0], [0, 1], [0, 0]]).params["vertices"].shape == (3, 2)  # closed loop ok


def test_wrong_point_arrays_say_what_to_fix():
    with pytest.raises(GeometryError, match=r"\(N, 2\) array.*points\[:, :2\]"):
        sdf.Circle(1)(np.zeros((4, 3)))
    with pytest.raises(GeometryError, match=r"\(N, 3\)"):
        sdf.Sphere(1).gradient(np.zeros((4, 2)))
    with pytest.raises(GeometryError, match="NaN"):
        sdf.Sphere(1)(np.full((2, 3), np.nan))
    assert isinstance(sdf.Circle(1)([2.0, 0.0]), float)


def test_projection_failure_is_reported():
    with pytest.raises(ConvergenceError, match="did not reach the surface"):
        sdf.Circle(1.0).smooth_union(sdf.Circle(1.0, (1.5, 0)), 1.0).project(np.array([[0.75, 3.0]]), max_iter=1)
