"""The SDF program interpreter (soroshapes._sdfeval over sorofem.sdf.program) against the SDF's own evaluation.

Every primitive and operation the program supports is evaluated on random points by the interpreter and by the
tree's numpy path (``shape(points, compiled=False)``, ``shape.gradient(points)``, analytic for these nodes): the
distances and gradients agree to 1e-12 (the same formulas; only the order of a few sums differs, round-off of
1e-16 m on distances of 0.1 m, amplified at most ~100x in the gradients of smooth blends). Trees with a node
without a program form raise NotImplementedError naming it.
"""
import numpy as np
import pytest

from sorofem import sdf
from sorofem.sdf.program import to_program
from soroshapes._sdfeval import sdf_eval

HEX = [(0.24 * np.cos(t), 0.24 * np.sin(t)) for t in np.arange(6) * np.pi / 3]
L_SHAPE = [(0.0, 0.0), (0.3, 0.0), (0.3, 0.1), (0.1, 0.1), (0.1, 0.3), (0.0, 0.3)]

SHAPES = {
    # primitives (3D)
    "sphere": sdf.Sphere(0.3, center=(0.1, -0.2, 0.05)),
    "box": sdf.Box((0.3, 0.2, 0.5), center=(0.1, 0.0, 0.0)),
    "cylinder": sdf.Cylinder(0.2, 0.5, center=(0.1, 0.1, 0.0), axis=(0.3, 0.5, 0.8)),
    "plane": sdf.Plane(point=(0.1, 0.0, 0.0), normal=(0.2, 0.3, 1.0)),
    "capsule": sdf.Capsule((0.0, 0.0, 0.0), (0.3, 0.1, 0.2), 0.1),
    # primitives (2D), on their own and extruded or revolved
    "circle": sdf.Circle(0.2, center=(0.05, -0.1)),
    "rectangle": sdf.Rectangle(0.3, 0.2, center=(0.1, 0.05)),
    "polygon": sdf.Polygon(L_SHAPE),
    "line": sdf.Line(point=(0.0, 0.1), normal=(0.3, 1.0)),
    "extrude_polygon": sdf.Polygon(HEX).extrude(0.14),
    "extrude_rectangle": sdf.Rectangle(0.3, 0.2, center=(0.1, 0.05)).extrude(0.2),
    "revolve": sdf.Circle(0.1).revolve(axis=(0.0, 1.0, 1.0), offset=0.3),
    # booleans
    "union": sdf.Sphere(0.3) | sdf.Box(0.4, center=(0.3, 0.0, 0.0)) | sdf.Sphere(0.1, center=(0.0, 0.5, 0.0)),
    "intersection": sdf.Sphere(0.3) & sdf.Box(0.4),
    "difference": sdf.Box(0.5) - sdf.Cylinder(0.1, 1.0),
    "smooth_union": sdf.Sphere(0.3).smooth_union(sdf.Box(0.4, center=(0.3, 0.0, 0.0)), 0.1),
    "smooth_intersection": sdf.Sphere(0.3).smooth_intersection(sdf.Box(0.4), 0.05),
    "smooth_difference": sdf.Box(0.5).smooth_difference(sdf.Sphere(0.2, center=(0.2, 0.0, 0.0)), 0.08),
    # transforms and offsets
    "translate_rotate_scale": sdf.Box(0.3).rotate(30, deg=True, axis=(1, 1, 0)).translate((0.1, 0.2, 0)).scale(1.5),
    "mirror": sdf.Sphere(0.2, center=(0.2, 0.0, 0.0)).mirror((1.0, 0.0, 0.0), point=(0.1, 0.0, 0.0)),
    "shell": sdf.Sphere(0.3).shell(0.05),
    "shell_outer": sdf.Box(0.3).shell(0.04, side="outer"),
    "offset": sdf.Box(0.3).offset(0.02),
    "rotate_2d": sdf.Rectangle(0.3, 0.2).rotate(20, deg=True) - sdf.Circle(0.05),
    "mirror_2d": sdf.Polygon(L_SHAPE).mirror((1.0, 1.0), point=(0.05, 0.0)),
}


def wavy_wall():
    """The grooved wall of demos/wavy_wall.py: a plane minus a union of cylinders with a smooth difference."""
    a = np.radians(40.0)
    t, n, c = np.array([np.cos(a), 0, np.sin(a)]), np.array([-np.sin(a), 0, np.cos(a)]), np.array([0.05, 0, -0.33])
    grooves = sdf.Union([sdf.Cylinder(0.015, 0.3, center=tuple(c + s * t - 0.006 * n), axis=(0, 1, 0))
                         for s in np.arange(-0.075, 0.40, 0.05)])
    return sdf.Plane(point=tuple(c), normal=tuple(n)).smooth_difference(grooves, 0.004), c


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_interpreter_matches_the_sdf_values_and_gradients(name):
    shape = SHAPES[name]
    rng = np.random.default_rng(sorted(SHAPES).index(name))
    P = rng.uniform(-0.6, 0.6, (3000, shape.dim))
    d, g = sdf_eval(shape, P)
    assert np.max(np.abs(d - shape(P, compiled=False))) < 1e-12
    assert np.max(np.abs(g - shape.gradient(P))) < 1e-12
    assert np.ptp(d) > 0.1                          # the points straddle the surface
    assert np.any(d < 0) and np.any(d > 0) or name in ("plane", "line")


def test_interpreter_matches_the_grooved_wall_of_the_demo():
    wall, c = wavy_wall()
    P = c + np.random.default_rng(7).uniform(-0.1, 0.1, (5000, 3))
    d, g = sdf_eval(wall, P)
    assert np.max(np.abs(d - wall(P, compiled=False))) < 1e-12
    assert np.max(np.abs(g - wall.gradient(P))) < 1e-12
    blend = np.abs(np.linalg.norm(g, axis=1) - 1) > 1e-6
    assert blend.any()                              # points inside the smooth blends are covered too


def test_ties_and_degenerate_points_follow_the_sdf():
    """A union of two equal spheres (equal distances: the first operand's gradient), the centre of a sphere and
    a point on a cylinder's axis (the numpy path's fallback directions)."""
    twin = sdf.Sphere(0.2) | sdf.Sphere(0.2)
    cyl = sdf.Cylinder(0.1, 0.4, axis=(0.0, 0.6, 0.8))
    for shape, P in ((twin, np.array([[0.1, 0.2, 0.3]])), (sdf.Sphere(0.2), np.zeros((1, 3))),
                     (cyl, np.array([[0.0, 0.06, 0.08]]))):
        d, g = sdf_eval(shape, P)
        assert np.allclose(d, shape(P, compiled=False), atol=1e-15)
        assert np.allclose(g, shape.gradient(P), atol=1e-15)


@pytest.mark.parametrize("shape, node", [
    (sdf.Torus(0.2, 0.05), "torus"),
    (sdf.Ellipse(0.2, 0.1).extrude(0.1), "ellipse"),
    (sdf.Box(0.1).repeat((0.3, 0.0, 0.0), (3, 1, 1)) | sdf.Sphere(0.1), "repeat"),
])
def test_nodes_without_a_program_form_are_named(shape, node):
    with pytest.raises(NotImplementedError, match=node):
        to_program(shape)
