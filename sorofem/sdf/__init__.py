"""Implicit CAD with signed distance functions (layer 1: pure numpy/numba, no DOLFINx, no gmsh).

A shape is a vectorized signed distance function of an ``(N, d)`` array of points [m] (SI units
throughout): negative inside, zero on the surface, positive outside. Shapes are immutable trees built with
operators and chainable transforms::

    from sorofem import sdf
    from sorofem.units import mm
    shape = sdf.Rectangle(20*mm, 10*mm).rotate(45, deg=True) - sdf.Circle(3*mm)   # | union, & inter., - diff.
    shape(points); shape.gradient(points); shape.frames(points); shape.project(points); shape.bounds
    shape.section_properties(); solid.mass_properties(density); solid.to_stl(path); shape.to_png(path)

Modules: :mod:`.core` (base class, booleans, transforms, queries), :mod:`.primitives2d`,
:mod:`.primitives3d` (with extrude/revolve), :mod:`.properties`, :mod:`.export`; fused numba kernels are
generated per tree by ``_codegen`` on first use (``shape.compiled()``), numpy is used otherwise.

Tree contract (read by the gmsh/OpenCASCADE translator)
-------------------------------------------------------
Every shape exposes

``dim``
    2 or 3.
``op``
    snake_case node name. Primitives: ``circle``, ``rectangle``, ``rounded_rectangle``, ``ellipse``,
    ``polygon``, ``polyline``, ``segment``, ``strut``, ``line`` (2D); ``sphere``, ``box``, ``cylinder``,
    ``capsule``, ``torus``, ``cone``, ``plane`` (3D). Operators: ``union``, ``intersection``,
    ``difference``, ``smooth_union``, ``smooth_intersection``, ``smooth_difference``, ``translate``,
    ``rotate``, ``scale``, ``mirror``, ``shell``, ``offset``, ``repeat``, ``circular_repeat``, ``extrude``,
    ``revolve``.
``params``
    dict of plain numbers / read-only numpy arrays in SI units:

    ========================  ===========================================================================
    circle                    radius, center (2,)
    rectangle                 width, height, center (2,)            (axis-aligned, centred)
    rounded_rectangle         width, height, radius, center (2,)
    ellipse                   radius_x, radius_y, center (2,)
    polygon                   vertices (n, 2)                       (simple, either orientation)
    polyline                  vertices (n, 2), thickness
    segment / strut           start (2,), end (2,), thickness / width
    line                      point (2,), normal (2,)               (solid where (p - point).normal < 0)
    sphere                    radius, center (3,)
    box                       size (3,), center (3,)
    cylinder                  radius, height, center (3,) (centroid), axis (3,) (unit)
    capsule                   start (3,), end (3,), radius
    torus                     major_radius, minor_radius, center (3,), axis (3,)
    cone                      radius, height, top_radius, center (3,) (base centre), axis (3,)
    plane                     point (3,), normal (3,)
    union/intersection        {} (n-ary: children are the operands)
    difference                {} (children = (a, b): a minus b)
    smooth_*                  radius
    translate                 offset (d,)
    rotate                    matrix (d, d) (proper rotation about the origin; x' = R x)
    scale                     factor (uniform, about the origin)
    mirror                    normal (d,), point (d,)               (reflection across line/plane)
    shell                     thickness, side ("inner" | "outer" | "center")
    offset                    distance
    repeat                    spacing (d,), count (d ints)          (copies at i * spacing, i = 0..count-1)
    circular_repeat           count [, axis (3,) in 3D]              (about the origin)
    extrude                   height                                (along z, centred on z = 0)
    revolve                   axis (3,), offset                     (profile (u, v) = (rho - offset, z))
    ========================  ===========================================================================
``children``
    tuple of operand shapes (empty for primitives).

:func:`is_csg` tells whether a tree holds only primitives, non-smooth booleans and rigid transforms
(translate, rotate, mirror), i.e. what a B-rep kernel can rebuild exactly.
"""
from . import _codegen, core, export, primitives2d, primitives3d, properties  # noqa: F401 (_codegen registers)
from .core import *  # noqa: F401,F403
from .export import *  # noqa: F401,F403
from .primitives2d import *  # noqa: F401,F403
from .primitives3d import *  # noqa: F401,F403
from .properties import *  # noqa: F401,F403

__all__ = [*core.__all__, *primitives2d.__all__, *primitives3d.__all__, *properties.__all__, *export.__all__]
