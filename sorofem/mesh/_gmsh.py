"""Everything that talks to gmsh: the session, CSG translation to OpenCASCADE, meshing options, extraction.

gmsh is a process-wide singleton. :func:`session` initialises it once (terminal output off), creates a fresh
model for each build and removes it afterwards, so that several meshes can be built one after the other (or
after an exception) without state leaking between them. gmsh 4.8 installs ``SIG_DFL`` for SIGINT when it is
imported, which would make Ctrl-C kill Python outright; :func:`import_gmsh` restores Python's handler (and
skips the call when imported off the main thread, where ``signal.signal`` is not allowed). A meshing call in
C++ cannot be interrupted mid-way; Ctrl-C takes effect when it returns.

This module is also the seam between gmsh versions (4.8 on Debian 12, 4.13 on Debian 13): every call whose
signature differs between them (the mesh-size callback) goes through a function here.
"""
import contextlib
import itertools
import logging
import math
import signal
import sys
import threading

import numpy as np

from ..errors import GeometryError, MeshError

log = logging.getLogger(__name__)

__all__ = ["import_gmsh", "session", "GMSH_CELLS", "csg_to_occ", "NotTranslatable", "extract", "set_options",
           "set_size_callback", "loops_to_geo", "surface_to_volume", "snap_boundary_nodes"]

#: gmsh element type → (DOLFINx cell name, degree, topological dimension)
GMSH_CELLS = {2: ("triangle", 1, 2), 9: ("triangle", 2, 2), 3: ("quadrilateral", 1, 2), 10: ("quadrilateral", 2, 2),
              4: ("tetrahedron", 1, 3), 11: ("tetrahedron", 2, 3), 5: ("hexahedron", 1, 3),
              12: ("hexahedron", 2, 3)}

_counter = itertools.count()
_lock = threading.RLock()
_initialized = False


def import_gmsh():
    """Import gmsh without letting it take SIGINT away from Python."""
    if "gmsh" in sys.modules:
        gmsh = sys.modules["gmsh"]
    elif threading.current_thread() is threading.main_thread():
        old = signal.getsignal(signal.SIGINT)
        import gmsh
        signal.signal(signal.SIGINT, old)
        gmsh.oldsig = old
    else:
        real = signal.signal
        signal.signal = lambda *a, **k: signal.getsignal(a[0])  # gmsh 4.8 calls signal.signal at import time
        try:
            import gmsh
        finally:
            signal.signal = real
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.SIG_DFL:
        signal.signal(signal.SIGINT, signal.default_int_handler)  # someone imported gmsh before us
    return gmsh


def _initialize_keeping_sigint(gmsh):
    """``gmsh.initialize`` without losing Python's SIGINT handler.

    gmsh 4.8 sets SIGINT to ``SIG_DFL`` when imported (:func:`import_gmsh` undoes it); gmsh 4.11 and later
    (Debian 13: 4.13) do it in ``initialize`` instead (its ``interruptible`` argument, absent in 4.8), so Ctrl-C
    would kill the process outright, without ``KeyboardInterrupt`` and its clean-up. The handler in place before
    the call is put back after it, which serves both versions.
    """
    main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signal.SIGINT) if main else None
    gmsh.initialize([], readConfigFiles=False)
    if main and before is not None and signal.getsignal(signal.SIGINT) is not before:
        signal.signal(signal.SIGINT, before)


@contextlib.contextmanager
def session(name="sorofem"):
    """Yield the gmsh module with a fresh current model; the model is removed on exit (also on error)."""
    gmsh = import_gmsh()
    with _lock:
        global _initialized
        if not _initialized:  # gmsh 4.8 has no isInitialized(); initialising twice is harmless
            _initialize_keeping_sigint(gmsh)
            _initialized = True
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 2)
        model = f"{name}_{next(_counter)}"
        gmsh.model.add(model)
        gmsh.model.setCurrent(model)
        try:
            yield gmsh
        finally:
            with contextlib.suppress(Exception):
                gmsh.model.mesh.removeSizeCallback()
            with contextlib.suppress(Exception):
                gmsh.model.setCurrent(model)
                gmsh.model.remove()


def set_options(gmsh, size, order=1, cell="simplex", algorithm=None, size_callback=None, dim=2):
    """Mesh size and element options common to every builder (sizes in metres)."""
    opt = gmsh.option.setNumber
    opt("Mesh.MeshSizeMax", size)
    opt("Mesh.MeshSizeMin", 0.0 if size_callback is not None else size * 0.5)
    opt("Mesh.MeshSizeFromPoints", 0)
    opt("Mesh.MeshSizeExtendFromBoundary", 0 if size_callback is not None else 1)
    opt("Mesh.MeshSizeFromCurvature", 0)
    opt("Mesh.Algorithm", algorithm or 6)  # 8 (frontal for quads) segfaults in gmsh 4.8 on domains with holes
    opt("Mesh.Algorithm3D", 1)
    opt("Mesh.Optimize", 1)
    # gmsh options are global: set every one we rely on, each time
    opt("Mesh.RecombineAll", 1 if cell == "quad" else 0)
    opt("Mesh.RecombinationAlgorithm", 1)
    opt("Mesh.SubdivisionAlgorithm", 1 if (cell == "quad" and dim == 2) else 0)
    opt("Mesh.SecondOrderIncomplete", 0)
    opt("Mesh.HighOrderOptimize", 2 if order == 2 else 0)  # untangle curved cells near curved boundaries
    opt("Mesh.ElementOrder", 1)
    if size_callback is not None:
        set_size_callback(gmsh, size_callback)


def set_size_callback(gmsh, h):
    """Make ``h(x, y, z) -> size [m]`` gmsh's mesh-size callback.

    gmsh 4.8 calls the callback as ``(dim, tag, x, y, z)``; gmsh 4.11 and later (Debian 13 has 4.13) add the
    size ``lc`` gmsh computed itself as a sixth argument. The adapter takes both, so no version test is needed.
    """
    def callback(dim, tag, x, y, z, *lc):
        return float(h(x, y, z))

    gmsh.model.mesh.setSizeCallback(callback)


def grade_to_corners(gmsh, size, radius, exponent, smallest):
    """A background size field graded towards the model's points (a CSG shape's corners): the size
    ``size * (r / radius)^(1 - exponent)`` at a distance r < ``radius`` [m] of the nearest point, at least
    ``smallest * size``, ``size`` beyond. Call after the geometry is synchronized, before meshing."""
    points = [tag for _, tag in gmsh.model.getEntities(0)]
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "PointsList", points)
    grade = field.add("MathEval")
    field.setString(grade, "F", f"max({smallest * size!r}, {size!r} * min(1, F{dist} / {radius!r})^"
                                f"{1.0 - exponent!r})")
    field.setAsBackgroundMesh(grade)
    opt = gmsh.option.setNumber
    opt("Mesh.MeshSizeMin", smallest * size)
    opt("Mesh.MeshSizeMax", size)
    opt("Mesh.MeshSizeExtendFromBoundary", 0)
    opt("Mesh.MeshSizeFromPoints", 0)


# --------------------------------------------------------------------------------------------------------- CSG


class NotTranslatable(Exception):
    """Internal: a node of the shape tree has no OpenCASCADE equivalent (use the level-set path)."""


def _p(params, *names, default=None):
    for n in names:
        if n in params:
            return params[n]
    if default is not None:
        return default
    raise NotTranslatable(f"missing parameter {names[0]!r}")


def _vec3(v, fill=0.0):
    v = np.atleast_1d(np.asarray(v, dtype=float)).ravel()
    return np.concatenate([v, np.full(3 - len(v), fill)])[:3]


def _affine(gmsh, tags, matrix, offset):
    m = np.eye(3)
    a = np.asarray(matrix, dtype=float)
    m[:a.shape[0], :a.shape[1]] = a
    aff = np.hstack([m, _vec3(offset)[:, None]]).ravel().tolist()
    gmsh.model.occ.affineTransform(tags, aff)
    return tags


def csg_to_occ(gmsh, shape, dim):
    """Build ``shape`` (a tree of primitives, booleans and rigid transforms) in gmsh's OCC kernel.

    Returns the list of (dim, tag) of the result. Raises :class:`NotTranslatable` for any other node.
    """
    occ = gmsh.model.occ
    op = getattr(shape, "op", None)
    p = getattr(shape, "params", {}) or {}
    kids = tuple(getattr(shape, "children", ()) or ())
    if op in ("union", "intersection", "difference"):
        if len(kids) < 2:
            raise NotTranslatable(f"{op} with {len(kids)} children")
        if p.get("k", p.get("radius", p.get("smooth", 0))) not in (0, 0.0, None):
            raise NotTranslatable(f"smooth {op}")
        acc = csg_to_occ(gmsh, kids[0], dim)
        for k in kids[1:]:
            other = csg_to_occ(gmsh, k, dim)
            if op == "union":
                acc, _ = occ.fuse(acc, other)
            elif op == "intersection":
                acc, _ = occ.intersect(acc, other)
            else:
                acc, _ = occ.cut(acc, other)
        return [t for t in acc if t[0] == dim]
    if op in ("translate", "rotate", "mirror", "scale", "transform"):
        if len(kids) != 1:
            raise NotTranslatable(f"{op} with {len(kids)} children")
        tags = csg_to_occ(gmsh, kids[0], dim)
        if op == "translate":
            d = _vec3(_p(p, "offset", "vector"))
            occ.translate(tags, *d)
            return tags
        if op == "rotate":
            R = np.asarray(_p(p, "matrix"), dtype=float)
            c = _vec3(p.get("center", np.zeros(dim)))
            R3 = np.eye(3)
            R3[:R.shape[0], :R.shape[1]] = R
            return _affine(gmsh, tags, R3, c - R3 @ c)
        if op == "scale":
            s = np.asarray(_p(p, "factor", "scale"), dtype=float)
            S = np.diag(_vec3(s, 1.0) if s.size > 1 else np.full(3, float(s)))
            if s.size == 1 and dim == 2:
                S[2, 2] = 1.0
            return _affine(gmsh, tags, S, np.zeros(3))
        if op == "mirror":
            n = _vec3(_p(p, "normal", "axis"))
            n = n / np.linalg.norm(n)
            c = _vec3(p.get("point", p.get("center", np.zeros(3))))
            H = np.eye(3) - 2 * np.outer(n, n)
            return _affine(gmsh, tags, H, c - H @ c)
        M = np.asarray(_p(p, "matrix"), dtype=float)
        return _affine(gmsh, tags, M, _vec3(p.get("offset", np.zeros(3))))
    if op == "extrude" and len(kids) == 1 and dim == 3:
        h = float(_p(p, "height"))
        base = csg_to_occ(gmsh, kids[0], 2)
        occ.translate(base, 0.0, 0.0, -h / 2)
        out = occ.extrude(base, 0.0, 0.0, h)
        return [t for t in out if t[0] == 3]
    if kids:
        raise NotTranslatable(f"operation {op!r}")
    c = _vec3(p.get("center", np.zeros(3)))
    if dim == 2:
        if op == "circle":
            r = float(_p(p, "radius"))
            return [(2, occ.addDisk(c[0], c[1], 0.0, r, r))]
        if op == "ellipse":
            a, b = float(_p(p, "radius_x")), float(_p(p, "radius_y"))
            if a >= b:
                return [(2, occ.addDisk(c[0], c[1], 0.0, a, b))]
            t = [(2, occ.addDisk(c[0], c[1], 0.0, b, a))]
            occ.rotate(t, c[0], c[1], 0.0, 0, 0, 1, math.pi / 2)
            return t
        if op in ("rectangle", "rounded_rectangle"):
            if "size" in p:
                w, h = (float(v) for v in np.asarray(p["size"], dtype=float)[:2])
            else:
                w, h = float(_p(p, "width")), float(_p(p, "height"))
            r = float(p.get("radius", p.get("corner_radius", 0.0)) or 0.0)
            if r > 0 and 2 * r >= min(w, h):
                raise NotTranslatable("rounded corner radius too large for OCC")
            return [(2, occ.addRectangle(c[0] - w / 2, c[1] - h / 2, 0.0, w, h, roundedRadius=r))]
        if op == "polygon":
            v = np.asarray(_p(p, "vertices", "points"), dtype=float)
            pts = [occ.addPoint(x, y, 0.0) for x, y in v[:, :2]]
            lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
            return [(2, occ.addPlaneSurface([occ.addCurveLoop(lines)]))]
        raise NotTranslatable(f"2D primitive {op!r}")
    if op == "sphere":
        return [(3, occ.addSphere(c[0], c[1], c[2], float(_p(p, "radius"))))]
    if op == "box":
        if "size" in p or "width" in p:
            s = _vec3(p["size"]) if "size" in p else _vec3([p["width"], p["depth"], p["height"]])
            lo = c - s / 2
        else:
            lo, hi = _vec3(_p(p, "lo", "min")), _vec3(_p(p, "hi", "max"))
            s = hi - lo
        return [(3, occ.addBox(*lo, *s))]
    if op == "cylinder":
        r, h = float(_p(p, "radius")), float(_p(p, "height", "length"))
        axis = _vec3(p.get("axis", (0.0, 0.0, 1.0)))
        axis = axis / np.linalg.norm(axis)
        base = c - axis * h / 2
        return [(3, occ.addCylinder(*base, *(axis * h), r))]
    if op == "cone":
        r1, h = float(_p(p, "radius")), float(_p(p, "height"))
        r2 = float(p.get("top_radius", 0.0))
        axis = _vec3(p.get("axis", (0.0, 0.0, 1.0)))
        axis = axis / np.linalg.norm(axis)
        base = c - axis * h / 2
        return [(3, occ.addCone(*base, *(axis * h), r1, r2))]
    if op == "torus":
        R, r = float(_p(p, "major_radius")), float(_p(p, "minor_radius"))
        axis = _vec3(p.get("axis", (0.0, 0.0, 1.0)))
        axis = axis / np.linalg.norm(axis)
        t = [(3, occ.addTorus(0.0, 0.0, 0.0, R, r))]
        z = np.array([0.0, 0.0, 1.0])
        k = np.cross(z, axis)
        if np.linalg.norm(k) > 1e-12:
            occ.rotate(t, 0, 0, 0, *k, math.atan2(np.linalg.norm(k), float(z @ axis)))
        elif axis[2] < 0:
            occ.rotate(t, 0, 0, 0, 1, 0, 0, math.pi)
        occ.translate(t, *c)
        return t
    raise NotTranslatable(f"3D primitive {op!r}")


# ------------------------------------------------------------------------------------------------ level sets


def loops_to_geo(gmsh, faces, size):
    """Plane surfaces from nested closed polylines ``[(outer, [holes])]`` in the built-in geo kernel."""
    geo = gmsh.model.geo
    surfaces = []
    for outer, holes in faces:
        loops = []
        for curve in [outer, *holes]:
            pts = [geo.addPoint(float(x), float(y), 0.0, 0.0) for x, y in curve]
            lines = [geo.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
            for ln in lines:  # the polyline is already resampled to the element size: one edge per segment
                geo.mesh.setTransfiniteCurve(ln, 2)
            loops.append(geo.addCurveLoop(lines))
        surfaces.append(geo.addPlaneSurface(loops))
    geo.synchronize()
    return [(2, s) for s in surfaces]


def surface_to_volume(gmsh, nodes, triangles, angle=40.0):
    """Turn a closed triangulated surface (nodes (n, 3) [m], triangles (m, 3) 0-based) into gmsh volumes.

    The surface is split into smooth patches (feature angle ``angle`` in degrees), reparametrised, grouped into
    closed shells; the largest shell of each body bounds a volume and the shells inside it are its cavities.
    """
    s = gmsh.model.addDiscreteEntity(2)
    tags = np.arange(1, len(nodes) + 1)
    gmsh.model.mesh.addNodes(2, s, tags.tolist(), np.asarray(nodes, dtype=float).ravel().tolist())
    gmsh.model.mesh.addElementsByType(s, 2, [], (np.asarray(triangles) + 1).ravel().tolist())
    gmsh.model.mesh.removeDuplicateNodes()
    gmsh.model.mesh.classifySurfaces(math.radians(angle), True, True, math.pi)
    gmsh.model.mesh.createGeometry()
    surfaces = [t for _, t in gmsh.model.getEntities(2)]
    # shells: surfaces connected through shared curves
    parent = {t: t for t in surfaces}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    by_curve = {}
    for t in surfaces:
        for _, c in gmsh.model.getBoundary([(2, t)], oriented=False):
            by_curve.setdefault(abs(c), []).append(t)
    for ts in by_curve.values():
        for a in ts[1:]:
            parent[find(a)] = find(ts[0])
    shells = {}
    for t in surfaces:
        shells.setdefault(find(t), []).append(t)
    boxes = {}
    for root, ts in shells.items():
        bb = np.array([gmsh.model.getBoundingBox(2, t) for t in ts])
        boxes[root] = (bb[:, :3].min(axis=0), bb[:, 3:].max(axis=0))
    order = sorted(shells, key=lambda r: -np.prod(boxes[r][1] - boxes[r][0]))
    geo = gmsh.model.geo
    loops = {r: geo.addSurfaceLoop(shells[r]) for r in order}
    used, volumes = set(), []
    for r in order:
        if r in used:
            continue
        lo, hi = boxes[r]
        holes = [q for q in order if q != r and q not in used
                 and np.all(boxes[q][0] >= lo) and np.all(boxes[q][1] <= hi)]
        used.update([r, *holes])
        volumes.append(geo.addVolume([loops[r]] + [loops[q] for q in holes]))
    geo.synchronize()
    return [(3, v) for v in volumes]


def snap_boundary_nodes(gmsh, shape, tdim, size):
    """Project every mesh node on a boundary entity onto the zero level of ``shape`` (moves of < size/4)."""
    from ._contour import _snap

    for d in range(tdim):
        for _, tag in gmsh.model.getEntities(d):
            ntags, coords, param = gmsh.model.mesh.getNodes(d, tag, includeBoundary=False)
            if len(ntags) == 0:
                continue
            x = np.asarray(coords).reshape(-1, 3)
            y = x.copy()
            y[:, :tdim] = _snap(shape, x[:, :tdim].copy())
            move = np.linalg.norm(y - x, axis=1)
            ok = move < 0.25 * size
            for nt, pt, good in zip(ntags, y, ok):
                if good:
                    gmsh.model.mesh.setNode(int(nt), pt.tolist(), [])


def extract(gmsh, tdim):
    """Nodes (n, 3) and cells of the highest-dimensional elements of the current gmsh model.

    Returns ``(x, cells, gmsh_type)`` with 0-based, compact node numbering. Raises :class:`MeshError` if the
    model has no cells of dimension ``tdim`` or mixes element types.
    """
    types, _, conn = gmsh.model.mesh.getElements(tdim)
    types = [int(t) for t in types]
    if not types or sum(len(c) for c in conn) == 0:
        raise MeshError(f"gmsh produced no {tdim}D cells: the geometry may be empty or too small for the requested"
                        " size; reduce `size`")
    if len(types) > 1:
        names = [gmsh.model.mesh.getElementProperties(t)[0] for t in types]
        raise MeshError(f"gmsh produced mixed cell types {names}; use cell='triangle'/'tetrahedron' or a box-like "
                        "domain for quadrilaterals/hexahedra")
    etype = types[0]
    if etype not in GMSH_CELLS:
        raise MeshError(f"gmsh element type {gmsh.model.mesh.getElementProperties(etype)[0]!r} is not supported")
    nn = gmsh.model.mesh.getElementProperties(etype)[3]
    cells_tags = np.asarray(conn[0], dtype=np.int64).reshape(-1, nn)
    # a cell can be listed twice when a file also stores it in a named region's entity: keep it once
    _, first = np.unique(np.sort(cells_tags, axis=1), axis=0, return_index=True)
    cells_tags = cells_tags[np.sort(first)]
    ntags, coords, _ = gmsh.model.mesh.getNodes()
    ntags = np.asarray(ntags, dtype=np.int64)
    coords = np.asarray(coords, dtype=float).reshape(-1, 3)
    used = np.unique(cells_tags)
    lookup = np.full(ntags.max() + 1, -1, dtype=np.int64)
    lookup[ntags] = np.arange(len(ntags))
    x = coords[lookup[used]]
    renum = np.full(ntags.max() + 1, -1, dtype=np.int64)
    renum[used] = np.arange(len(used))
    return x, renum[cells_tags], etype


def generate(gmsh, tdim, order):
    """Mesh the current model; wrap gmsh's exceptions into :class:`MeshError`."""
    try:
        gmsh.model.mesh.generate(tdim)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
    except Exception as e:  # noqa: BLE001 - gmsh raises bare Exception
        raise MeshError(f"gmsh failed to mesh the geometry ({e}); try a smaller `size`, a simpler shape, or "
                        "method='levelset'") from e


def check_size(size, name="size"):
    """Validate a positive, finite element size [m]."""
    try:
        s = float(size)
    except (TypeError, ValueError):
        raise MeshError(f"`{name}` must be a positive number in metres, got {size!r}") from None
    if not math.isfinite(s) or s <= 0.0:
        raise MeshError(f"`{name}` must be a positive, finite length in metres (e.g. 0.5*mm), got {size!r}")
    return s


def check_geometry_error(e):
    """Turn an OCC boolean exception into a GeometryError."""
    return GeometryError(f"OpenCASCADE could not build the shape ({e}); check the boolean operations")
