"""The SDF base class: evaluation, gradients, frames, projection, bounds and the chainable operators.

A shape is an immutable node of a tree. Each node implements four small hooks:

``_eval(p)``
    signed distance of an ``(N, d)`` array of points [m] -> ``(N,)`` [m] (numpy, vectorized);
``_grad(p, h)``
    ``(d, grad)``; analytic where the node allows (chain rule through operators), else central differences
    with the step ``h`` [m] chosen by the root from its size;
``_bounds()``
    a conservative axis-aligned box ``(lo, hi)`` [m] (``±inf`` for half-spaces);
``_emit(g, xs)``
    scalar source code for the fused numba kernel (:mod:`sorofem.sdf._codegen`); optional.

and optionally ``_moments()`` (exact zeroth, first and second area/volume moments about the origin).

The modules built on this base register what the base hands out, so that it imports none of them (no import
cycle): the primitives their ``op`` names (:func:`register_primitives`, for :func:`is_csg`), the 2D -> 3D
operations their classes (:func:`register_operation`, for :meth:`SDF.extrude` and :meth:`SDF.revolve`) and
the fused-kernel generator its compiler (:func:`register_compiler`, for :meth:`SDF.compiled`).
"""
import math

import numpy as np

from ..errors import ConvergenceError, GeometryError

__all__ = ["SDF", "is_csg", "CSG_BOOLEANS", "CSG_TRANSFORMS", "Union", "Intersection", "Difference", "SmoothUnion",
           "SmoothIntersection", "SmoothDifference", "Translate", "Rotate", "Scale", "Mirror", "Shell", "Offset",
           "Repeat", "CircularRepeat"]

#: Boolean operators the gmsh/OpenCASCADE translator supports (see :func:`is_csg`).
CSG_BOOLEANS = frozenset({"union", "intersection", "difference"})
#: Rigid (distance-preserving) transforms, see :func:`is_csg`.
CSG_TRANSFORMS = frozenset({"translate", "rotate", "mirror"})

#: ``op`` names of the registered primitives (:func:`register_primitives`).
_PRIMITIVE_OPS = set()
#: Shape classes of the registered operations, by name (:func:`register_operation`).
_OPERATIONS = {}
#: The registered tree compiler (:func:`register_compiler`), at most one.
_COMPILER = []


def register_primitives(ops):
    """Register the ``op`` names of primitives (each module of primitives calls it once); returns them as a
    frozenset."""
    ops = frozenset(ops)
    _PRIMITIVE_OPS.update(ops)
    return ops


def register_operation(name):
    """Class decorator: the shape class of the operation ``name`` (``"extrude"``, ``"revolve"``) that the base
    class's method of that name builds."""
    def register(cls):
        _OPERATIONS[name] = cls
        return cls
    return register


def register_compiler(compile_tree):
    """Register ``compile_tree(shape) -> kernel or None``, the fused-kernel generator of :meth:`SDF.compiled`."""
    _COMPILER[:] = [compile_tree]
    return compile_tree


def _operation(name):
    try:
        return _OPERATIONS[name]
    except KeyError:   # the package's __init__ imports every module that registers: only a broken install lands here
        raise GeometryError(f"the shape operation {name!r} is not registered: import sorofem.sdf (not one of its "
                            "modules alone)") from None


#: Points per chunk of the numpy evaluation path (keeps temporaries in cache).
_CHUNK = 1 << 15
#: From this many points on, ``shape(points)`` uses the fused numba kernel when the tree supports it.
COMPILE_THRESHOLD = 1 << 17


class NoCodegen(Exception):
    """Raised by ``_emit`` of a node that has no fused-kernel implementation (numpy path is used)."""


def _vec(value, dim, name):
    """Return ``value`` as a finite float vector of length ``dim`` or raise GeometryError."""
    try:
        v = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError) as e:
        raise GeometryError(f"{name} must be {dim} numbers, got {value!r}") from e
    if v.size == 1 and dim > 1 and np.ndim(value) == 0:
        raise GeometryError(f"{name} must be a sequence of {dim} numbers (a {dim}D vector), got {value!r}")
    if v.size != dim:
        raise GeometryError(f"{name} must have {dim} components for a {dim}D shape, got {v.size}: {value!r}")
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{name} must be finite, got {value!r}")
    v.setflags(write=False)
    return v


def _positive(value, name, unit="m"):
    """Return ``value`` as a positive finite float or raise GeometryError naming the parameter."""
    try:
        v = float(value)
    except (TypeError, ValueError) as e:
        raise GeometryError(f"{name} must be a positive number [{unit}], got {value!r}") from e
    if not (math.isfinite(v) and v > 0):
        raise GeometryError(f"{name} must be positive and finite [{unit}], got {value!r}; "
                            f"give a size > 0 (e.g. 5*mm)")
    return v


def _unit(value, dim, name):
    v = np.array(_vec(value, dim, name))
    n = np.linalg.norm(v)
    if n == 0:
        raise GeometryError(f"{name} must be a non-zero vector, got {value!r}")
    v = v / n
    v.setflags(write=False)
    return v


def _rotation_2d(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _rotation_3d(angle, axis):
    """Rodrigues' formula: R = I cos a + sin a [k]x + (1 - cos a) k k^T."""
    k = _unit(axis, 3, "axis")
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) * math.cos(angle) + math.sin(angle) * K + (1 - math.cos(angle)) * np.outer(k, k)


def _perpendicular(n):
    """Unit vectors (N, 3) perpendicular to the unit vectors ``n`` (N, 3), continuous almost everywhere."""
    a = np.zeros_like(n)
    idx = np.argmin(np.abs(n), axis=1)
    a[np.arange(len(n)), idx] = 1.0
    t = np.cross(n, a)
    return t / np.linalg.norm(t, axis=1, keepdims=True)


def _corners(lo, hi):
    """The 2^d corners of a box, (2^d, d)."""
    d = len(lo)
    idx = np.array(np.meshgrid(*[[0, 1]] * d, indexing="ij")).reshape(d, -1).T
    return np.where(idx == 1, hi, lo)


def _finite_corners(lo, hi, what):
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    return _corners(lo, hi)


class SDF:
    """A signed distance function of a 2D region or a 3D solid (base class of every shape).

    ``shape(points)`` returns the signed distance [m] of an ``(N, d)`` array of points [m]: negative inside,
    zero on the surface, positive outside. Shapes are immutable; operators and transforms return new shapes:
    ``a | b`` (union), ``a & b`` (intersection), ``a - b`` (difference), ``a.translate(...)``, ...

    Attributes
    ----------
    dim : int
        2 or 3.
    op : str
        Name of the node in snake_case (``"circle"``, ``"union"``, ``"rotate"``, ...).
    params : dict
        Plain numeric parameters of the node in SI units (a copy; arrays are read-only).
    children : tuple of SDF
        Operand shapes (empty for primitives).
    """

    op = "sdf"

    def __init__(self, dim, params=None, children=()):
        object.__setattr__(self, "dim", int(dim))
        object.__setattr__(self, "_params", dict(params or {}))
        object.__setattr__(self, "_children", tuple(children))
        for c in self._children:
            if not isinstance(c, SDF):
                raise GeometryError(f"operands of {self.op} must be SDF shapes, got {type(c).__name__}")

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} is immutable; transforms and operators return new shapes")

    # ------------------------------------------------------------------ tree contract
    @property
    def params(self):
        """Plain numeric parameters of this node in SI units (a new dict; arrays are read-only)."""
        return dict(self._params)

    @property
    def children(self):
        """Operands of this node (tuple of :class:`SDF`; empty for primitives)."""
        return self._children

    def __repr__(self):
        inner = ", ".join(f"{k}={np.round(v, 6).tolist() if isinstance(v, np.ndarray) else v}"
                          for k, v in self._params.items())
        kids = ", ".join(repr(c) for c in self._children)
        args = ", ".join(s for s in (inner, kids) if s)
        return f"{self.op}({args})"

    # ------------------------------------------------------------------ hooks
    def _eval(self, p):  # pragma: no cover - abstract
        raise NotImplementedError

    def _grad(self, p, h):
        """Central differences of ``_eval`` with step ``h`` [m] (override with the analytic gradient)."""
        d = self._eval(p)
        g = np.empty_like(p)
        q = p.copy()
        for i in range(self.dim):
            q[:, i] = p[:, i] + h
            fp = self._eval(q)
            q[:, i] = p[:, i] - h
            fm = self._eval(q)
            q[:, i] = p[:, i]
            g[:, i] = (fp - fm) / (2 * h)
        return d, g

    def _bounds(self):  # pragma: no cover - abstract
        raise NotImplementedError

    def _emit(self, g, xs):
        raise NoCodegen(self.op)

    def _moments(self):
        """Exact (m0, m1 (d,), m2 (d, d)) moments about the origin, or None (numerical integration)."""
        return None

    # ------------------------------------------------------------------ input checking
    def _points(self, points):
        """Validate ``points`` -> (float (N, d) array, was_single_point)."""
        p = np.asarray(points, dtype=float)
        single = p.ndim == 1
        if single:
            p = p[None, :]
        if p.ndim != 2 or p.shape[1] != self.dim:
            raise GeometryError(
                f"points must be an (N, {self.dim}) array for a {self.dim}D shape, got shape "
                f"{np.shape(points)}; pass one point per row with {self.dim} coordinates [m]"
                + (" (a 2D shape needs (x, y) only; slice points[:, :2] or extrude the shape)"
                   if self.dim == 2 and p.ndim == 2 and p.shape[1] == 3 else ""))
        if not np.all(np.isfinite(p)):
            raise GeometryError("points contain NaN or infinity; pass finite coordinates [m]")
        return np.ascontiguousarray(p), single

    # ------------------------------------------------------------------ queries
    def __call__(self, points, compiled=None):
        """Signed distance [m] of ``points`` ((N, d) array [m]) -> (N,) array; a single (d,) point -> float.

        Parameters
        ----------
        points : array_like, (N, d)
            Query points [m].
        compiled : bool or None
            ``True`` forces the fused numba kernel (GeometryError if the tree has no kernel), ``False`` the
            chunked numpy path; ``None`` (default) uses the kernel from ``COMPILE_THRESHOLD`` points on.
        """
        p, single = self._points(points)
        n = len(p)
        use = compiled
        if use is None:
            use = n >= COMPILE_THRESHOLD and self.compiled() is not None
        if use:
            kernel = self.compiled()
            if kernel is None:
                raise GeometryError(f"this tree ({self.op}) has a node without a fused kernel; "
                                    "call with compiled=False (numpy path)")
            out = kernel(p)
        else:
            out = np.empty(n)
            for s in range(0, n, _CHUNK):
                out[s:s + _CHUNK] = self._eval(p[s:s + _CHUNK])
        return float(out[0]) if single else out

    def evaluate(self, points, compiled=None):
        """Same as ``shape(points)``: the signed distance [m] of (N, d) points [m]."""
        return self(points, compiled=compiled)

    def compiled(self):
        """The fused numba evaluator of this tree (a callable ``(N, d) -> (N,)``), or None if unsupported.

        The kernel is generated from the tree's structure, compiled on first use (about a second) and cached
        per structure for the process, so trees that differ only in their numbers share one kernel.
        """
        try:
            return self.__dict__["_kernel"]
        except KeyError:
            pass
        kernel = _COMPILER[0](self) if _COMPILER else None
        object.__setattr__(self, "_kernel", kernel)
        return kernel

    @property
    def size(self):
        """Characteristic length [m]: the diagonal of the finite part of the bounds (1 m if none)."""
        lo, hi = self.bounds
        ext = np.where(np.isfinite(hi - lo), np.maximum(hi - lo, 0), 0.0)
        s = float(np.linalg.norm(ext))
        return s if s > 0 else 1.0

    def gradient(self, points):
        """Gradient of the signed distance, (N, d) [dimensionless], the outward normal on the surface.

        Analytic where the primitive allows (chain rule through booleans and transforms); other nodes use
        central differences with the step h = 1e-6 * ``size``. |grad| = 1 except on medial axes (kinks) and
        inside smooth blends; it is never NaN (at a circle's centre any unit vector is returned).
        """
        p, single = self._points(points)
        _, g = self._grad(p, 1e-6 * self.size)
        return g[0] if single else g

    def frames(self, points):
        """Local frames (normal, tangent, binormal) at points; the normal is the unit gradient.

        Returns
        -------
        normal, tangent, binormal : ndarray
            3D: three (N, 3) unit vectors, a right-handed frame (``binormal = normal x tangent``); the tangent
            is ``normal x e_k`` normalized, e_k the axis least aligned with the normal.
            2D: normal and tangent are (N, 2) (tangent = normal rotated +90 deg, the counter-clockwise
            direction along the boundary), binormal is the (N, 3) out-of-plane axis (0, 0, 1).
        """
        p, single = self._points(points)
        _, g = self._grad(p, 1e-6 * self.size)
        nrm = np.linalg.norm(g, axis=1, keepdims=True)
        fallback = np.zeros_like(g)
        fallback[:, 0] = 1.0
        n = np.where(nrm > 1e-12, g / np.where(nrm > 1e-12, nrm, 1.0), fallback)
        if self.dim == 2:
            t = np.stack([-n[:, 1], n[:, 0]], axis=1)
            b = np.zeros((len(n), 3))
            b[:, 2] = 1.0
        else:
            t = _perpendicular(n)
            b = np.cross(n, t)
        if single:
            return n[0], t[0], b[0]
        return n, t, b

    def project(self, points, tol=1e-9, max_iter=50):
        """Closest points on the surface and signed distances: Newton-like iteration x <- x - d(x) grad(x).

        Parameters
        ----------
        points : (N, d) array [m]
        tol : float
            Stop when |d(x)| < ``tol * size`` for every point.
        max_iter : int

        Returns
        -------
        closest : (N, d) array [m]
            Points on the zero level set.
        distance : (N,) array [m]
            Signed distance of the input points to their projections (negative inside), |p - closest|.

        Raises
        ------
        ConvergenceError
            If some points do not reach the surface (e.g. a point on a medial axis of a non-exact tree).
        """
        p, single = self._points(points)
        h = 1e-6 * self.size
        x = p.copy()
        atol = tol * self.size
        d0, _ = self._grad(p, h)
        active = np.arange(len(x))
        for _ in range(max_iter):
            d, g = self._grad(x[active], h)
            done = np.abs(d) < atol
            active = active[~done]
            if active.size == 0:
                break
            d, g = d[~done], g[~done]
            gg = np.einsum("ij,ij->i", g, g)
            gg = np.where(gg > 1e-24, gg, 1.0)
            x[active] -= (d / gg)[:, None] * g
        else:
            d = self._eval(x[active]) if active.size else np.zeros(0)
            bad = active[np.abs(d) >= atol]
            if bad.size:
                raise ConvergenceError(
                    f"project: {bad.size} of {len(x)} points did not reach the surface within {max_iter} "
                    f"iterations (first: {p[bad[0]].tolist()} [m], residual {abs(d[0]):.3g} m); raise "
                    f"max_iter or tol, or avoid points on medial axes of smooth/non-exact shapes")
        dist = np.sign(d0) * np.linalg.norm(p - x, axis=1)
        return (x[0], float(dist[0])) if single else (x, dist)

    @property
    def bounds(self):
        """Conservative axis-aligned bounding box ``(lo, hi)``, two (d,) arrays [m] (``±inf`` if unbounded)."""
        lo, hi = self._bounds()
        return np.array(lo, dtype=float), np.array(hi, dtype=float)

    # ------------------------------------------------------------------ operators
    def _check_other(self, other, what):
        if not isinstance(other, SDF):
            return False
        if other.dim != self.dim:
            raise GeometryError(f"cannot {what} a {self.dim}D shape and a {other.dim}D shape; "
                                f"extrude or revolve the 2D one first")
        return True

    def __or__(self, other):
        if not self._check_other(other, "unite"):
            return NotImplemented
        return Union(self, other)

    def __and__(self, other):
        if not self._check_other(other, "intersect"):
            return NotImplemented
        return Intersection(self, other)

    def __sub__(self, other):
        if not self._check_other(other, "subtract"):
            return NotImplemented
        return Difference(self, other)

    def union(self, *others):
        """Union with ``others`` (same as ``|``): d = min(d_i)."""
        return Union(self, *others)

    def intersection(self, *others):
        """Intersection with ``others`` (same as ``&``): d = max(d_i)."""
        return Intersection(self, *others)

    def difference(self, *others):
        """This shape minus ``others`` (same as ``-``): d = max(d_a, -d_b)."""
        return Difference(self, Union(*others) if len(others) > 1 else others[0])

    def smooth_union(self, other, radius):
        """Union blended with a fillet of ``radius`` [m] (polynomial smooth minimum)."""
        self._check_other(other, "unite")
        return SmoothUnion(self, other, radius)

    def smooth_difference(self, other, radius):
        """Difference blended with a fillet of ``radius`` [m] (polynomial smooth maximum of d_a, -d_b)."""
        self._check_other(other, "subtract")
        return SmoothDifference(self, other, radius)

    def smooth_intersection(self, other, radius):
        """Intersection blended with a fillet of ``radius`` [m]."""
        self._check_other(other, "intersect")
        return SmoothIntersection(self, other, radius)

    def translate(self, offset):
        """Move the shape by ``offset`` [m] ((d,) vector): d'(p) = d(p - offset)."""
        return Translate(self, offset)

    def rotate(self, angle=None, axis=None, deg=False, matrix=None, about=None):
        """Rotate the shape about the origin (or the point ``about`` [m]).

        Parameters
        ----------
        angle : float
            Rotation angle [rad], or [deg] with ``deg=True``; counter-clockwise (right-hand rule about axis).
        axis : (3,) array, 3D only
            Rotation axis (normalized internally).
        matrix : (d, d) array, optional
            A proper rotation matrix instead of angle/axis.
        about : (d,) array [m], optional
            Centre of rotation (default: origin).
        """
        if matrix is None:
            if angle is None:
                raise GeometryError("rotate needs an angle (and an axis in 3D) or a matrix")
            a = float(angle) * (math.pi / 180 if deg else 1.0)
            if self.dim == 2:
                if axis is not None:
                    raise GeometryError("a 2D shape rotates about the out-of-plane axis; drop `axis`")
                matrix = _rotation_2d(a)
            else:
                if axis is None:
                    raise GeometryError("rotating a 3D shape needs an axis, e.g. axis=(0, 0, 1)")
                matrix = _rotation_3d(a, axis)
        elif angle is not None or axis is not None:
            raise GeometryError("give either angle (+ axis) or matrix to rotate, not both")
        if about is None:
            return Rotate(self, matrix)
        c = _vec(about, self.dim, "about")
        return Rotate(self.translate(-c), matrix).translate(c)

    def scale(self, factor):
        """Scale uniformly by ``factor`` > 0 about the origin: d'(p) = factor * d(p / factor) (exact)."""
        return Scale(self, factor)

    def mirror(self, normal, point=None):
        """Reflect across the line/plane through ``point`` [m] (default origin) with normal ``normal``."""
        return Mirror(self, normal, point)

    def shell(self, thickness, side="inner"):
        """Hollow the shape into a wall of ``thickness`` [m].

        ``side="inner"`` keeps the outer surface (d' = max(d, -d - t)); ``"outer"`` keeps the inner surface
        (d' = max(d - t, -d)); ``"center"`` centres the wall on the surface (d' = |d| - t/2).
        """
        return Shell(self, thickness, side)

    def offset(self, distance):
        """Grow (``distance`` > 0) or shrink (< 0) the shape by ``distance`` [m]: d' = d - distance."""
        return Offset(self, distance)

    def repeat(self, spacing, count):
        """Linear pattern: copies at ``i * spacing`` for i = 0 .. count-1 along each axis.

        Parameters
        ----------
        spacing : (d,) array [m]
            Pitch along each axis (0 for axes without repetition).
        count : int or (d,) ints
            Number of copies along each axis (>= 1).

        Evaluates the nearest copy and its neighbours (3^d evaluations), exact when each copy lies within
        its own cell and the neighbouring ones.
        """
        return Repeat(self, spacing, count)

    def circular_repeat(self, count, axis=(0.0, 0.0, 1.0)):
        """Circular pattern of ``count`` copies rotated by 2 pi k / count about the origin (2D) or ``axis``
        through the origin (3D); evaluates the nearest sector and its two neighbours."""
        return CircularRepeat(self, count, axis)

    def extrude(self, height):
        """2D -> 3D: prism of ``height`` [m] along z, centred on z = 0 (exact distance)."""
        return _operation("extrude")(self, height)

    def revolve(self, axis=(0.0, 0.0, 1.0), offset=0.0):
        """2D -> 3D: revolve the profile about ``axis`` through the origin.

        The 2D coordinates (u, v) become (radial distance - ``offset``, axial coordinate); the profile part
        with u >= -offset is what the solid contains. Exact for profiles symmetric about u = -offset or lying
        in u >= -offset (a torus is ``Circle(r).revolve(offset=R)``).
        """
        return _operation("revolve")(self, axis, offset)

    # ------------------------------------------------------------------ properties & export
    def section_properties(self, resolution=None):
        """Area, centroid and second moments of a 2D region, see :func:`sorofem.sdf.section_properties`."""
        from .properties import section_properties
        return section_properties(self, resolution=resolution)

    def mass_properties(self, density=1.0, resolution=None):
        """Volume, centre of mass and inertia tensor of a 3D solid, see :func:`sorofem.sdf.mass_properties`."""
        from .properties import mass_properties
        return mass_properties(self, density=density, resolution=resolution)

    @property
    def area(self):
        """Area [m^2] of a 2D region (exact or numerical, see :meth:`section_properties`)."""
        return self.section_properties().area

    @property
    def volume(self):
        """Volume [m^3] of a 3D solid (exact or numerical, see :meth:`mass_properties`)."""
        return self.mass_properties().volume

    def to_stl(self, path, resolution=None, units="mm"):
        """Write a binary STL of a 3D solid (marching cubes) in ``units`` (default mm), see
        :func:`sorofem.sdf.to_stl`."""
        from .export import to_stl
        return to_stl(self, path, resolution=resolution, units=units)

    def to_png(self, path, plane="xy", at=0.0, resolution=None, title=None):
        """Write a PNG preview (2D region or a 3D slice), see :func:`sorofem.sdf.to_png`."""
        from .export import to_png
        return to_png(self, path, plane=plane, at=at, resolution=resolution, title=title)


def is_csg(shape):
    """True if the tree holds only primitives, non-smooth booleans and rigid transforms.

    Such trees can be rebuilt exactly by a boundary-representation kernel (gmsh/OpenCASCADE): the node ops
    allowed besides primitives are :data:`CSG_BOOLEANS` and :data:`CSG_TRANSFORMS`.
    """
    allowed = CSG_BOOLEANS | CSG_TRANSFORMS | _PRIMITIVE_OPS
    stack = [shape]
    while stack:
        s = stack.pop()
        if s.op not in allowed:
            return False
        stack.extend(s.children)
    return True


# ====================================================================== booleans
def _pick(ds, gs, idx):
    n = np.arange(len(idx))
    return np.stack(ds)[idx, n], np.stack(gs)[idx, n]


class _NAry(SDF):
    _flatten = True

    def __init__(self, *shapes):
        if len(shapes) == 1 and isinstance(shapes[0], (list, tuple)):
            shapes = tuple(shapes[0])
        if len(shapes) < 1:
            raise GeometryError(f"{self.op} needs at least one shape")
        flat = []
        for s in shapes:
            if not isinstance(s, SDF):
                raise GeometryError(f"{self.op} operands must be SDF shapes, got {type(s).__name__}")
            if type(s) is type(self):
                flat.extend(s.children)
            else:
                flat.append(s)
        dims = {s.dim for s in flat}
        if len(dims) != 1:
            raise GeometryError(f"{self.op} of shapes with different dimensions {sorted(dims)}; "
                                "extrude or revolve the 2D ones first")
        super().__init__(flat[0].dim, {}, flat)


class _Extremum(_NAry):
    """n-ary min (union) or max (intersection) of the operands' distances; subclasses set the reducer."""

    _reduce = None     # np.minimum or np.maximum
    _select = None     # np.argmin or np.argmax
    _kernel_fn = None  # "min" or "max" in generated kernels

    def _eval(self, p):
        out = self.children[0]._eval(p)
        for c in self.children[1:]:
            type(self)._reduce(out, c._eval(p), out=out)
        return out

    def _grad(self, p, h):
        ds, gs = zip(*(c._grad(p, h) for c in self.children))
        return _pick(ds, gs, type(self)._select(np.stack(ds), axis=0))

    def _bounds(self):
        lo, hi = zip(*(c._bounds() for c in self.children))
        if self._reduce is np.minimum:  # union: the box around all boxes
            return np.min(lo, axis=0), np.max(hi, axis=0)
        return np.max(lo, axis=0), np.min(hi, axis=0)  # intersection: their common box

    def _emit(self, g, xs):
        names = [c._emit(g, xs) for c in self.children]
        out = names[0]
        for n in names[1:]:
            out = g.var(f"{self._kernel_fn}({out}, {n})")
        return out


class Union(_Extremum):
    """Union of shapes: d = min_i d_i (exact outside, a lower bound of |d| inside where operands overlap)."""

    op = "union"
    _reduce, _select, _kernel_fn = np.minimum, np.argmin, "min"


class Intersection(_Extremum):
    """Intersection of shapes: d = max_i d_i (exact inside, a lower bound of d outside)."""

    op = "intersection"
    _reduce, _select, _kernel_fn = np.maximum, np.argmax, "max"


class Difference(SDF):
    """Difference a - b: d = max(d_a, -d_b)."""

    op = "difference"

    def __init__(self, a, b):
        if a.dim != b.dim:
            raise GeometryError(f"cannot subtract a {b.dim}D shape from a {a.dim}D shape")
        super().__init__(a.dim, {}, (a, b))

    def _eval(self, p):
        return np.maximum(self.children[0]._eval(p), -self.children[1]._eval(p))

    def _grad(self, p, h):
        da, ga = self.children[0]._grad(p, h)
        db, gb = self.children[1]._grad(p, h)
        first = da >= -db
        return np.where(first, da, -db), np.where(first[:, None], ga, -gb)

    def _bounds(self):
        return self.children[0]._bounds()

    def _emit(self, g, xs):
        a = self.children[0]._emit(g, xs)
        b = self.children[1]._emit(g, xs)
        return g.var(f"max({a}, -{b})")


def _smin(a, b, k):
    """Polynomial smooth minimum: h = clip(1/2 + (b - a)/(2k), 0, 1), d = mix(b, a, h) - k h (1 - h).

    Returns (d, h); the gradient is h grad a + (1 - h) grad b (the h-derivative term vanishes).
    """
    hh = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + hh * (a - b) - k * hh * (1.0 - hh), hh


class _Smooth(SDF):
    def __init__(self, a, b, radius):
        if a.dim != b.dim:
            raise GeometryError(f"{self.op} of a {a.dim}D and a {b.dim}D shape")
        super().__init__(a.dim, {"radius": _positive(radius, "radius")}, (a, b))

    def _grad(self, p, h):
        da, ga = self.children[0]._grad(p, h)
        db, gb = self.children[1]._grad(p, h)
        d, w = self._combine(da, db)
        sa, sb = self._signs
        return d, w[:, None] * sa * ga + (1 - w)[:, None] * sb * gb

    def _eval(self, p):
        return self._combine(self.children[0]._eval(p), self.children[1]._eval(p))[0]

    def _emit(self, g, xs):
        a = self.children[0]._emit(g, xs)
        b = self.children[1]._emit(g, xs)
        k = g.const(self._params["radius"])
        outer, sa, sb = self._form  # d = outer * smin(sa * a, sb * b; k)
        a2 = g.var(f"{sa} * {a}")
        b2 = g.var(f"{sb} * {b}")
        hh = g.var(f"min(max(0.5 + 0.5 * ({b2} - {a2}) / {k}, 0.0), 1.0)")
        return g.var(f"{outer} * ({b2} + {hh} * ({a2} - {b2}) - {k} * {hh} * (1.0 - {hh}))")


class SmoothUnion(_Smooth):
    """Union with a fillet of ``radius`` [m]: d = smin(d_a, d_b; k) (the region grows by at most k/4)."""

    op = "smooth_union"
    _signs = (1.0, 1.0)
    _form = (1.0, 1.0, 1.0)

    def _combine(self, a, b):
        return _smin(a, b, self._params["radius"])

    def _bounds(self):
        (la, ha), (lb, hb) = (c._bounds() for c in self.children)
        r = self._params["radius"] / 4
        return np.minimum(la, lb) - r, np.maximum(ha, hb) + r


class SmoothIntersection(_Smooth):
    """Intersection with a fillet: d = smax(d_a, d_b) = -smin(-d_a, -d_b; k)."""

    op = "smooth_intersection"
    _signs = (1.0, 1.0)
    _form = (-1.0, -1.0, -1.0)

    def _combine(self, a, b):
        d, w = _smin(-a, -b, self._params["radius"])
        return -d, w

    def _bounds(self):
        (la, ha), (lb, hb) = (c._bounds() for c in self.children)
        return np.maximum(la, lb), np.minimum(ha, hb)


class SmoothDifference(_Smooth):
    """Difference with a fillet: d = smax(d_a, -d_b) = -smin(-d_a, d_b; k)."""

    op = "smooth_difference"
    _signs = (1.0, -1.0)
    _form = (-1.0, -1.0, 1.0)

    def _combine(self, a, b):
        d, w = _smin(-a, b, self._params["radius"])
        return -d, w

    def _bounds(self):
        return self.children[0]._bounds()


# ====================================================================== transforms
class Translate(SDF):
    """Translation by ``offset`` [m]: d'(p) = d(p - offset)."""

    op = "translate"

    def __init__(self, child, offset):
        super().__init__(child.dim, {"offset": _vec(offset, child.dim, "offset")}, (child,))

    def _eval(self, p):
        return self.children[0]._eval(p - self._params["offset"])

    def _grad(self, p, h):
        return self.children[0]._grad(p - self._params["offset"], h)

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        return lo + self._params["offset"], hi + self._params["offset"]

    def _emit(self, g, xs):
        o = self._params["offset"]
        ys = [g.var(f"{x} - {g.const(o[i])}") for i, x in enumerate(xs)]
        return self.children[0]._emit(g, ys)

    def _moments(self):
        m = self.children[0]._moments()
        if m is None:
            return None
        m0, m1, m2 = m
        o = self._params["offset"]
        return m0, m1 + m0 * o, m2 + np.outer(m1, o) + np.outer(o, m1) + m0 * np.outer(o, o)


class _Linear(SDF):
    """d'(p) = d(A^T p) for an orthogonal A (rotation or reflection through the origin)."""

    def _A(self):
        return self._params["matrix"]

    def _eval(self, p):
        return self.children[0]._eval(p @ self._A())

    def _grad(self, p, h):
        d, g = self.children[0]._grad(p @ self._A(), h)
        return d, g @ self._A().T

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        c = _finite_corners(lo, hi, self.op)
        if c is None:
            inf = np.full(self.dim, np.inf)
            return -inf, inf
        c = c @ self._A().T
        return c.min(axis=0), c.max(axis=0)

    def _emit(self, g, xs):
        A = self._A()
        ys = []
        for j in range(self.dim):  # y_j = sum_i x_i A_ij
            terms = " + ".join(f"{x} * {g.const(A[i, j])}" for i, x in enumerate(xs))
            ys.append(g.var(terms))
        return self.children[0]._emit(g, ys)

    def _moments(self):
        m = self.children[0]._moments()
        if m is None:
            return None
        m0, m1, m2 = m
        A = self._A()
        return m0, A @ m1, A @ m2 @ A.T


class Rotate(_Linear):
    """Rotation by a proper orthogonal ``matrix`` R about the origin: d'(p) = d(R^T p)."""

    op = "rotate"

    def __init__(self, child, matrix):
        R = np.array(matrix, dtype=float)
        d = child.dim
        if R.shape != (d, d) or not np.all(np.isfinite(R)):
            raise GeometryError(f"rotation matrix must be a finite ({d}, {d}) array for a {d}D shape, "
                                f"got shape {R.shape}")
        if not np.allclose(R @ R.T, np.eye(d), atol=1e-9) or np.linalg.det(R) < 0:
            raise GeometryError("rotation matrix must be orthogonal with determinant +1 "
                                "(use mirror() for reflections, scale() for scaling)")
        R.setflags(write=False)
        super().__init__(d, {"matrix": R}, (child,))


class Mirror(_Linear):
    """Reflection across the line/plane through ``point`` with unit ``normal``: d'(p) = d(H (p - c) + c),
    H = I - 2 n n^T."""

    op = "mirror"

    def __init__(self, child, normal, point=None):
        d = child.dim
        n = _unit(normal, d, "normal")
        c = np.zeros(d) if point is None else np.array(_vec(point, d, "point"))
        c.setflags(write=False)
        H = np.eye(d) - 2 * np.outer(n, n)
        H.setflags(write=False)
        super().__init__(d, {"normal": n, "point": c}, (child,))
        object.__setattr__(self, "_H", H)
        object.__setattr__(self, "_shift", 2 * np.dot(c, n) * n)  # H(p - c) + c = H p + 2 (c.n) n

    def _A(self):
        return self._H

    def _eval(self, p):
        return self.children[0]._eval(p @ self._H + self._shift)

    def _grad(self, p, h):
        d, g = self.children[0]._grad(p @ self._H + self._shift, h)
        return d, g @ self._H

    def _bounds(self):
        lo, hi = super()._bounds()
        return lo + self._shift, hi + self._shift

    def _emit(self, g, xs):
        H, s = self._H, self._shift
        ys = []
        for j in range(self.dim):
            terms = " + ".join(f"{x} * {g.const(H[i, j])}" for i, x in enumerate(xs))
            ys.append(g.var(f"{terms} + {g.const(s[j])}"))
        return self.children[0]._emit(g, ys)

    def _moments(self):
        m = super()._moments()
        if m is None:
            return None
        m0, m1, m2 = m
        o = self._shift
        return m0, m1 + m0 * o, m2 + np.outer(m1, o) + np.outer(o, m1) + m0 * np.outer(o, o)


class Scale(SDF):
    """Uniform scaling by ``factor`` s > 0 about the origin: d'(p) = s d(p / s) (exact)."""

    op = "scale"

    def __init__(self, child, factor):
        if np.ndim(factor) != 0:
            raise GeometryError("scale takes one positive factor (uniform scaling keeps distances exact); "
                                "for different sizes per axis rebuild the primitive with new dimensions")
        super().__init__(child.dim, {"factor": _positive(factor, "scale factor", "-")}, (child,))

    def _eval(self, p):
        s = self._params["factor"]
        return s * self.children[0]._eval(p / s)

    def _grad(self, p, h):
        s = self._params["factor"]
        d, g = self.children[0]._grad(p / s, h / s)
        return s * d, g

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        s = self._params["factor"]
        return lo * s, hi * s

    def _emit(self, g, xs):
        s = g.const(self._params["factor"])
        ys = [g.var(f"{x} / {s}") for x in xs]
        return g.var(f"{s} * {self.children[0]._emit(g, ys)}")

    def _moments(self):
        m = self.children[0]._moments()
        if m is None:
            return None
        s, d = self._params["factor"], self.dim
        return m[0] * s**d, m[1] * s**(d + 1), m[2] * s**(d + 2)


class Shell(SDF):
    """Wall of ``thickness`` t [m] along the surface (side "inner", "outer" or "center", see SDF.shell)."""

    op = "shell"

    def __init__(self, child, thickness, side="inner"):
        if side not in ("inner", "outer", "center"):
            raise GeometryError(f"shell side must be 'inner', 'outer' or 'center', got {side!r}")
        super().__init__(child.dim, {"thickness": _positive(thickness, "shell thickness"), "side": side},
                         (child,))

    def _shift(self):
        t = self._params["thickness"]
        return {"inner": t / 2, "outer": -t / 2, "center": 0.0}[self._params["side"]]

    def _eval(self, p):
        d = self.children[0]._eval(p) + self._shift()
        return np.abs(d) - self._params["thickness"] / 2

    def _grad(self, p, h):
        d, g = self.children[0]._grad(p, h)
        d = d + self._shift()
        s = np.where(d >= 0, 1.0, -1.0)
        return np.abs(d) - self._params["thickness"] / 2, g * s[:, None]

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        e = self._params["thickness"] / 2 - self._shift()
        return lo - e, hi + e

    def _emit(self, g, xs):
        d = self.children[0]._emit(g, xs)
        return g.var(f"abs({d} + {g.const(self._shift())}) - {g.const(self._params['thickness'] / 2)}")


class Offset(SDF):
    """Offset surface: d' = d - distance (grows the shape for distance > 0, rounds its corners)."""

    op = "offset"

    def __init__(self, child, distance):
        r = float(distance)
        if not math.isfinite(r):
            raise GeometryError(f"offset distance must be finite [m], got {distance!r}")
        super().__init__(child.dim, {"distance": r}, (child,))

    def _eval(self, p):
        return self.children[0]._eval(p) - self._params["distance"]

    def _grad(self, p, h):
        d, g = self.children[0]._grad(p, h)
        return d - self._params["distance"], g

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        r = max(self._params["distance"], 0.0)
        return lo - r, hi + r

    def _emit(self, g, xs):
        return g.var(f"{self.children[0]._emit(g, xs)} - {g.const(self._params['distance'])}")


class Repeat(SDF):
    """Linear pattern: the union of copies translated by i * spacing, i = 0 .. count - 1 per axis."""

    op = "repeat"

    def __init__(self, child, spacing, count):
        d = child.dim
        s = np.array(_vec(spacing, d, "spacing"))
        cnt = np.broadcast_to(np.asarray(count), (d,))
        if not np.all(np.equal(np.mod(cnt, 1), 0)) or np.any(cnt < 1):
            raise GeometryError(f"count must be integers >= 1 per axis, got {count!r}")
        cnt = tuple(int(c) for c in cnt)
        if any(c > 1 and v == 0 for c, v in zip(cnt, s)):
            raise GeometryError("spacing must be non-zero along every axis with count > 1")
        s.setflags(write=False)
        super().__init__(d, {"spacing": s, "count": cnt}, (child,))

    def _candidates(self, p):
        s, cnt = self._params["spacing"], np.array(self._params["count"])
        safe = np.where(s != 0, s, 1.0)
        k = np.clip(np.rint(p / safe), 0, cnt - 1)
        axes = [i for i in range(self.dim) if cnt[i] > 1]
        deltas = np.array(np.meshgrid(*[[-1, 0, 1]] * len(axes), indexing="ij")).reshape(len(axes), -1).T
        for dl in deltas:
            kk = k.copy()
            kk[:, axes] = np.clip(k[:, axes] + dl, 0, cnt[axes] - 1)
            yield p - kk * s

    def _eval(self, p):
        out = None
        for q in self._candidates(p):
            v = self.children[0]._eval(q)
            out = v if out is None else np.minimum(out, v)
        return out

    def _grad(self, p, h):
        ds, gs = zip(*(self.children[0]._grad(q, h) for q in self._candidates(p)))
        return _pick(ds, gs, np.argmin(np.stack(ds), axis=0))

    def _emit(self, g, xs):
        s, cnt = self._params["spacing"], self._params["count"]
        axes = [i for i in range(self.dim) if cnt[i] > 1]
        ks = {i: g.var(f"min(max(math.floor({xs[i]} / {g.const(s[i])} + 0.5), 0.0), {g.const(cnt[i] - 1)})")
              for i in axes}
        out = None
        for dl in np.array(np.meshgrid(*[[-1, 0, 1]] * len(axes), indexing="ij")).reshape(len(axes), -1).T:
            ys = list(xs)
            for i, di in zip(axes, dl):
                kk = g.var(f"min(max({ks[i]} + {float(di)}, 0.0), {g.const(cnt[i] - 1)})")
                ys[i] = g.var(f"{xs[i]} - {kk} * {g.const(s[i])}")
            d = self.children[0]._emit(g, ys)
            out = d if out is None else g.var(f"min({out}, {d})")
        return out

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        ext = (np.array(self._params["count"]) - 1) * self._params["spacing"]
        return lo + np.minimum(ext, 0), hi + np.maximum(ext, 0)


class CircularRepeat(SDF):
    """Circular pattern: ``count`` copies rotated by 2 pi k / count about the origin (2D) or an axis (3D)."""

    op = "circular_repeat"

    def __init__(self, child, count, axis=(0.0, 0.0, 1.0)):
        if int(count) != count or count < 1:
            raise GeometryError(f"count must be an integer >= 1, got {count!r}")
        params = {"count": int(count)}
        if child.dim == 3:
            params["axis"] = _unit(axis, 3, "axis")
        super().__init__(child.dim, params, (child,))
        # angle of the child's bounds centre: copies sit at theta_c + 2 pi k / count
        lo, hi = child._bounds()
        mid = np.where(np.isfinite(lo + hi), (lo + hi) / 2, 0.0)
        object.__setattr__(self, "_theta_c", float(self._angle(mid[None, :])[0]) if np.any(mid) else 0.0)

    def _rotated(self, p, phi):
        """Rotate each point p_i by -phi_i (about z in 2D, about the axis in 3D, Rodrigues)."""
        c, s = np.cos(phi)[:, None], np.sin(-phi)[:, None]
        if self.dim == 2:
            x, y = p[:, :1], p[:, 1:]
            return np.hstack([c * x - s * y, s * x + c * y])
        a = self._params["axis"]
        return p * c + np.cross(a, p) * s + np.outer(p @ a, a) * (1 - c)

    def _angle(self, p):
        if self.dim == 2:
            return np.arctan2(p[:, 1], p[:, 0])
        a = self._params["axis"]
        u = _perpendicular(a[None, :])[0]
        v = np.cross(a, u)
        return np.arctan2(p @ v, p @ u)

    def _candidates(self, p):
        n = self._params["count"]
        alpha = 2 * np.pi / n
        k = np.rint((self._angle(p) - self._theta_c) / alpha)
        for dl in ((0,) if n == 1 else (-1, 0, 1) if n > 2 else (0, 1)):
            phi = (k + dl) * alpha
            yield phi, self._rotated(p, phi)

    def _eval(self, p):
        out = None
        for _, q in self._candidates(p):
            v = self.children[0]._eval(q)
            out = v if out is None else np.minimum(out, v)
        return out

    def _grad(self, p, h):
        ds, gs = [], []
        for phi, q in self._candidates(p):
            d, g = self.children[0]._grad(q, h)
            ds.append(d)
            gs.append(self._rotated(g, -phi))  # back to world frame: rotate by +phi
        return _pick(ds, gs, np.argmin(np.stack(ds), axis=0))

    def _bounds(self):
        lo, hi = self.children[0]._bounds()
        c = _finite_corners(lo, hi, self.op)
        if c is None:
            inf = np.full(self.dim, np.inf)
            return -inf, inf
        if self.dim == 2:
            r = np.linalg.norm(c, axis=1).max()
            return -np.full(2, r), np.full(2, r)
        a = self._params["axis"]
        z = c @ a
        r = np.linalg.norm(c - np.outer(z, a), axis=1).max()
        return _cylinder_aabb(a, z.min(), z.max(), r)


def _cylinder_aabb(a, z0, z1, r):
    """AABB of a cylinder with unit axis ``a`` through the origin, axial range [z0, z1], radius r."""
    ends = np.stack([z0 * a, z1 * a])
    ext = r * np.sqrt(np.clip(1 - a**2, 0, 1))
    return ends.min(axis=0) - ext, ends.max(axis=0) + ext
