"""The :class:`Mesh` class: a distributed DOLFINx mesh with named regions."""
import logging
import math
import os
import shutil
import tempfile
import time
import contextlib
import contextvars
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .. import _dolfinx
from .._jit import silence_compiler_logs
from ..errors import GeometryError, MeshError
from ..io import on_root
from . import _contour, _gmsh, _regions

__all__ = ["Mesh", "MAX_CELLS", "cell_limit", "estimate_cells"]

log = logging.getLogger(__name__)
silence_compiler_logs()

_SIMPLEX = {"simplex", "triangle", "tetrahedron", "tri", "tet"}
_TENSOR = {"quadrilateral", "hexahedron", "quad", "hex"}
SIDES_2D = ("left", "right", "bottom", "top")
SIDES_3D = ("left", "right", "front", "back", "bottom", "top")


MAX_CELLS = 2_000_000
"""Default largest number of cells :meth:`Mesh.from_sdf` will generate (its ``max_cells``)."""

_cell_limit = contextvars.ContextVar("sorofem_mesh_cell_limit", default=None)

# cells per unit measure at element size h: regular triangle sqrt(3)/4 h^2, regular tetrahedron h^3/(6 sqrt 2),
# square h^2, cube h^3 (gmsh's unstructured cells are close to regular at the requested size)
_CELL_MEASURE = {("simplex", 2): math.sqrt(3) / 4, ("simplex", 3): 1 / (6 * math.sqrt(2)),
                 ("quad", 2): 1.0, ("quad", 3): 1.0}


@contextlib.contextmanager
def cell_limit(max_cells):
    """Within the block, :meth:`Mesh.from_sdf` calls that pass no ``max_cells`` use this limit (a sweep passes
    its ``[sweep] max_cells`` to the builders it runs).

    Parameters
    ----------
    max_cells : int
        Largest estimated number of cells; positive.
    """
    token = _cell_limit.set(_check_max_cells(max_cells))
    try:
        yield
    finally:
        _cell_limit.reset(token)


def _check_max_cells(max_cells):
    if isinstance(max_cells, bool) or not isinstance(max_cells, (int, np.integer, float)) \
            or not math.isfinite(max_cells) or max_cells < 1:
        raise MeshError(f"max_cells must be a positive number of cells, got {max_cells!r}")
    return int(max_cells)


def estimate_cells(shape, size, cell="simplex", samples=2048, measure=None):
    """Estimate how many cells meshing ``shape`` at ``size`` makes, without meshing.

    .. math:: N \\approx |\\Omega|\\,\\big\\langle 1 / (c\\, h(x)^d) \\big\\rangle_{x \\in \\Omega}

    with the domain's measure :math:`|\\Omega|` (``shape.area``/``shape.volume``: exact where the shape knows
    it, otherwise numerical), the cell measure :math:`c\\,h^d` of a regular cell of edge :math:`h`
    (triangle :math:`\\sqrt3/4`, tetrahedron :math:`1/(6\\sqrt2)`, quadrilateral/hexahedron 1) and, for a
    varying size, the mean over ``samples`` points drawn (fixed seed) in the bounding box and kept inside.
    Gmsh's cells are close to regular, so the estimate is within a factor of about 2 of the count.

    Parameters
    ----------
    shape : sorofem.sdf shape
        2D or 3D; lengths in m.
    size : float or callable
        Element size [m], or ``size(x) -> h`` [m] on an (N, dim) array of points [m].
    cell : str
        ``"simplex"`` (triangles/tetrahedra) or ``"quad"`` (quadrilaterals/hexahedra).
    samples : int
        Points sampled for a varying size.
    measure : float, optional
        The domain's area [m^2] or volume [m^3] if known (an upper bound such as the bounding box's gives an
        upper bound of the count); default the shape's.

    Returns
    -------
    float
        The estimated number of cells.
    """
    dim = shape.dim
    if measure is None:
        measure = float(shape.area if dim == 2 else shape.volume)
    c = _CELL_MEASURE[("quad" if cell == "quad" else "simplex", dim)]
    if not callable(size):
        return measure / (c * float(size) ** dim)
    lo, hi = (np.asarray(b, dtype=float) for b in shape.bounds)
    x = lo + (hi - lo) * np.random.default_rng(0).random((int(samples), dim))
    x = x[np.asarray(shape(x)).reshape(-1) < 0]
    if len(x) == 0:
        raise GeometryError("no sample point falls inside the shape; is it empty or are its bounds wrong?")
    h = np.asarray(size(x), dtype=float).reshape(-1)
    if h.size == 1:
        h = np.full(len(x), h[0])
    if not np.all(np.isfinite(h) & (h > 0)):
        raise MeshError("the size function returned a non-positive or non-finite element size inside the shape")
    return measure * float(np.mean(1.0 / (c * h ** dim)))


def _check_size_estimate(shape, h_fn, h_base, kind, max_cells):
    """Refuse (MeshError) a mesh whose estimated cell count exceeds the limit, before gmsh runs. The bounding
    box's measure bounds the estimate from above for free; the shape's own measure is computed only when that
    bound is above the limit."""
    limit = _check_max_cells(max_cells) if max_cells is not None else (_cell_limit.get() or MAX_CELLS)
    size = h_base
    if h_fn is not None:
        pad = [0.0] * (3 - shape.dim)

        def size(x):   # gmsh caps a size callback at h_base (Mesh.MeshSizeMax)
            return np.minimum([h_fn(*p, *pad) for p in x], h_base)
    lo, hi = (np.asarray(b, dtype=float) for b in shape.bounds)
    n = estimate_cells(shape, size, kind, samples=512, measure=float(np.prod(hi - lo)))
    if n > limit:
        n = estimate_cells(shape, size, kind, samples=512)
    if n > limit:
        raise MeshError(f"meshing this shape at size {h_base:.3g} m would make about {n:.3g} cells (its "
                        f"{'area' if shape.dim == 2 else 'volume'} over the cell size), more than max_cells = "
                        f"{limit}: is the size (in metres, e.g. 0.5*mm) meant to be this small? If so, pass "
                        "Mesh.from_sdf(..., max_cells=...) (in a sweep, raise max_cells in [sweep])")


def _world():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def _check_order(order):
    if order not in (1, 2):
        raise MeshError(f"order must be 1 (linear) or 2 (quadratic) cells, got {order!r}")
    return int(order)


def _check_cell(cell, dim):
    c = str(cell).lower()
    if c in _SIMPLEX:
        kind = "simplex"
    elif c in _TENSOR:
        kind = "quad"
    else:
        raise MeshError(f"unknown cell {cell!r}; use 'triangle'/'tetrahedron' or 'quadrilateral'/'hexahedron'")
    if (c in ("triangle", "tri", "quadrilateral", "quad") and dim == 3) or \
            (c in ("tetrahedron", "tet", "hexahedron", "hex") and dim == 2):
        raise MeshError(f"cell {cell!r} does not match a {dim}D domain")
    return kind


def _size_function(size, refine, shape, boundary_size, boundary_width, dim):
    """Compose the user's sizing into ``(h_base, h_boundary, callback or None)``; sizes in metres."""
    base_fn = None
    if callable(size):
        base_fn = size
        # the largest size (gmsh's MeshSizeMax caps the callback at it) over the origin and a fixed sample of the
        # bounding box: a size graded towards a point at the origin (a corner) must not cap the whole mesh
        probe = np.zeros((1, dim))
        if shape is not None:
            lo, hi = (np.asarray(b, dtype=float) for b in shape.bounds)
            if np.all(np.isfinite(np.r_[lo, hi])):
                probe = np.vstack([probe, lo + (hi - lo) * np.random.default_rng(0).random((256, dim))])
        h_base = _gmsh.check_size(float(np.max(np.asarray(size(probe), dtype=float).reshape(-1))), "size(x)")
    else:
        h_base = _gmsh.check_size(size)
    regions = []
    for item in refine or ():
        try:
            where, h = item
        except (TypeError, ValueError):
            raise MeshError("`refine` must be a list of (region, size) pairs; a region is a box (lo, hi), "
                            "a shape or a predicate f(x) on (dim, N) coordinates") from None
        regions.append((where, _gmsh.check_size(h, "refine size")))
    hb = None
    if boundary_size is not None:
        hb = _gmsh.check_size(boundary_size, "boundary_size")
        if shape is None:
            raise MeshError("boundary_size needs a shape (signed distance) to measure the distance to the boundary")
        width = _gmsh.check_size(boundary_width, "boundary_width") if boundary_width is not None else 4 * h_base
    if base_fn is None and not regions and hb is None:
        return h_base, h_base, None

    def h_at(x, y, z):
        p = np.array([[x, y, z][:dim]])
        h = float(np.asarray(base_fn(p)).reshape(-1)[0]) if base_fn is not None else h_base
        for where, hr in regions:
            if hr < h and _inside(where, p):
                h = hr
        if hb is not None:
            d = abs(float(shape(p)[0]))
            h = min(h, hb + (h_base - hb) * min(d / width, 1.0))
        return h

    h_min = min([h_base] + [h for _, h in regions] + ([hb] if hb is not None else []))
    return h_base, (hb if hb is not None else h_min), h_at


def _check_grading(grading, size, refine, boundary_size, method):
    """``(radius [m], exponent, smallest)`` of ``Mesh.from_sdf(grading=)``, checked."""
    try:
        radius, exponent, smallest = (float(v) for v in grading)
    except (TypeError, ValueError):
        raise MeshError(f"grading must be (radius [m], exponent, smallest fraction of size), got {grading!r}") \
            from None
    if not (radius > 0 and 0 <= exponent < 1 and 0 < smallest <= 1) or not np.isfinite(radius):
        raise MeshError(f"grading needs radius > 0 [m], 0 <= exponent < 1 and 0 < smallest <= 1, got {grading!r}")
    if callable(size) or refine or boundary_size is not None or method == "levelset":
        raise MeshError("grading= takes a number size on the CSG path, without refine= or boundary_size=: "
                        "give one of them")
    return radius, exponent, smallest


def _inside(where, p):
    if hasattr(where, "bounds") and callable(where):
        return float(where(p)[0]) <= 0.0
    if callable(where):
        return bool(np.asarray(where(p.T.copy())).reshape(-1)[0])
    lo, hi = (np.asarray(b, dtype=float) for b in where)
    return bool(np.all(p[0] >= lo) and np.all(p[0] <= hi))


def _occ_build(gmsh, shape, dim, interfaces=()):
    """Translate ``shape`` into OCC; returns the entities or raises NotTranslatable/GeometryError.

    ``interfaces``: shapes whose boundaries split the domain (OCC ``fragment``): the pieces of the domain are
    kept, glued along the shared curves/surfaces, and the parts of the interface shapes outside it removed."""
    try:
        ents = _gmsh.csg_to_occ(gmsh, shape, dim)
        if interfaces:
            occ = gmsh.model.occ
            tools = [t for s in interfaces for t in _gmsh.csg_to_occ(gmsh, s, dim)]
            out, pieces = occ.fragment(ents, tools)
            keep = {t for m in pieces[:len(ents)] for t in m if t[0] == dim}
            drop = [t for t in out if t[0] == dim and t not in keep]
            if drop:
                occ.remove(drop, recursive=True)
            ents = sorted(keep)
        gmsh.model.occ.synchronize()
    except _gmsh.NotTranslatable:
        raise
    except Exception as e:  # noqa: BLE001 - OCC raises bare Exception
        raise _gmsh.check_geometry_error(e) from e
    if not gmsh.model.getEntities(dim):
        raise GeometryError("the shape is empty: its boolean operations remove everything (no region left to "
                            "mesh)")
    return ents


def _mesh_levelset_2d(gmsh, shape, h_boundary, order, kind, h_base):
    curves = _contour.sdf_contours(shape, h_boundary)
    _gmsh.loops_to_geo(gmsh, _contour.nest_loops(curves), h_base)


def _mesh_levelset_3d(gmsh, shape, h_boundary):
    from skimage import measure

    lo, hi = (np.asarray(b, dtype=float) for b in shape.bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise GeometryError("the shape's bounds are empty or not finite; intersect it with a finite shape")
    h = h_boundary / 2.0
    ext = hi - lo
    h = max(h, (float(np.prod(ext + 4 * h)) / 2_000_000) ** (1 / 3))
    lo = lo - 2 * h
    n = np.ceil((ext + 4 * h) / h).astype(int) + 1
    axes = [lo[i] + h * np.arange(n[i]) for i in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    vals = np.asarray(shape(P), dtype=float).reshape(n)
    if vals.min() >= 0:
        raise GeometryError(f"the shape has no interior inside its bounds (sampled every {h:.3g} m): it is empty "
                            "or thinner than the sampling step")
    verts, faces, _, _ = measure.marching_cubes(vals, 0.0, spacing=(h, h, h))
    verts = _contour._snap(shape, verts + lo)
    _gmsh.surface_to_volume(gmsh, verts, faces)


class Mesh:
    """A DOLFINx mesh with named facet and cell regions, built on rank 0 and distributed over MPI.

    Build one with :meth:`from_sdf`, :meth:`from_image`, :meth:`from_file`, :meth:`rectangle`, :meth:`box` or
    :meth:`from_arrays`. Every builder tags the boundary automatically:

    * ``left``/``right`` (x extremes), ``bottom``/``top`` (y in 2D, z in 3D), ``front``/``back`` (y in 3D):
      boundary facets whose vertices all lie within ``side_tol`` of the bounding box;
    * ``cavity_0``, ``cavity_1``, ...: closed inner boundaries (pressure chambers), ordered by centroid
      x, then y, then z.

    Sides that have no facet (e.g. ``left`` of a disk) are not created. More regions are added with
    :meth:`add_region` (facets or cells from a box, a shape or a predicate), which mutates the mesh and returns
    it, so calls chain (the project's builder convention).

    Attributes
    ----------
    dolfinx : dolfinx.mesh.Mesh
        The distributed mesh (coordinates in metres).
    regions : dict[str, int]
        Region name → integer tag used in :attr:`facet_tags`/:attr:`cell_tags` and in UFL measures.
    quality : dict
        The quality report (see :meth:`check_quality`): ``num_cells``, ``min_angle`` [deg],
        ``max_aspect_ratio``, ``h_min``/``h_max`` [m], ``degenerate``, ``inverted``, ...
    build_time : float
        Wall time [s] spent building (rank 0 meshing plus distribution and tagging).

    Examples
    --------
    >>> from sorofem import sdf
    >>> from sorofem.units import mm
    >>> from sorofem.mesh import Mesh
    >>> body = sdf.Rectangle(40*mm, 10*mm) - sdf.Circle(2*mm, center=(-8*mm, 0)) - sdf.Circle(2*mm, center=(8*mm, 0))
    >>> msh = Mesh.from_sdf(body, size=1*mm)           # doctest: +SKIP
    >>> sorted(msh.regions)                            # doctest: +SKIP
    ['bottom', 'cavity_0', 'cavity_1', 'left', 'right', 'top']
    """

    def __init__(self, mesh, side_tol=None, auto_regions=True, source=""):
        t0 = time.perf_counter()
        self.dolfinx = mesh
        self.source = source
        self.regions = {}
        self._entities = {}  # name -> (dim, local indices)
        self.quality = self.check_quality()
        lo, hi = _regions.global_bbox(mesh)
        self.bounds = (lo, hi)
        self._tol = float(side_tol) if side_tol is not None else 1e-6 * float(np.linalg.norm(hi - lo))
        if auto_regions:
            self._auto_regions()
        self.build_time = time.perf_counter() - t0

    # ------------------------------------------------------------------------------------------ properties
    @property
    def comm(self):
        """The MPI communicator of the mesh."""
        return self.dolfinx.comm

    @property
    def dim(self):
        """Geometric dimension (2 or 3)."""
        return self.dolfinx.geometry.dim

    @property
    def num_cells(self):
        """Global number of cells."""
        return self.quality["num_cells"]

    @property
    def area(self):
        """Area [m^2] of a 2D mesh (integral of 1 over the cells, exact for curved order-2 cells too)."""
        if self.dim != 2:
            raise MeshError("`area` is the measure of a 2D mesh; use `volume` for a 3D mesh")
        return self.measure()

    @property
    def volume(self):
        """Volume [m^3] of a 3D mesh."""
        if self.dim != 3:
            raise MeshError("`volume` is the measure of a 3D mesh; use `area` for a 2D mesh")
        return self.measure()

    @property
    def cavities(self):
        """Names of the cavities, in order (``cavity_0``, ``cavity_1``, ...)."""
        return [n for n in self.regions if n.startswith("cavity_")]

    def __repr__(self):
        q = self.quality
        return (f"Mesh({self.dim}D, {q['num_cells']} {q['cell']} cells of degree {q['degree']}, "
                f"regions={list(self.regions)})")

    # ------------------------------------------------------------------------------------------ regions
    def _set(self, name, dim, entities):
        if not isinstance(name, str) or not name:
            raise MeshError(f"a region name must be a non-empty string, got {name!r}")
        self._entities[name] = (dim, np.unique(np.asarray(entities, dtype=np.int32)))
        if name not in self.regions:
            self.regions[name] = max(self.regions.values(), default=0) + 1

    def _global_count(self, local):
        return self.comm.allreduce(int(len(local)))

    def _auto_regions(self):
        m = self.dolfinx
        facets = _regions.exterior_facets(m)
        X, mid, meas, nrm = _regions.facet_geometry(m, facets)
        for name, ents in _regions.sides(m, facets, X, self._tol).items():
            if self._global_count(ents):
                self._set(name, m.topology.dim - 1, ents)
        for k, ents in enumerate(_regions.cavities(m, facets, X, meas, nrm, self._tol)):
            self._set(f"cavity_{k}", m.topology.dim - 1, ents)

    def add_region(self, name, where, kind="facets", tol=0.0):
        """Tag boundary facets or cells selected by ``where`` as region ``name``; returns ``self``.

        Parameters
        ----------
        name : str
            Region name (replaces an existing region of that name).
        where : tuple (lo, hi) or shape or callable
            A box given by two corners [m]; a shape (selects where its signed distance is ``<= tol``); or a
            predicate ``f(x) -> bool array`` on midpoint coordinates ``x`` of shape ``(dim, N)`` [m].
        kind : {"facets", "cells"}
            Select boundary facets (by facet midpoint) or cells (by cell midpoint), e.g. a strain-limiting
            layer for a second material.
        tol : float
            Tolerance [m] added to the box or the shape.

        Returns
        -------
        Mesh
            ``self``, so calls chain.

        Raises
        ------
        MeshError
            If nothing is selected on any rank.
        """
        m = self.dolfinx
        tdim = m.topology.dim
        if kind in ("facets", "facet"):
            dim, ents = tdim - 1, _regions.exterior_facets(m)
        elif kind in ("cells", "cell"):
            dim = tdim
            imap = m.topology.index_map(tdim)
            ents = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        else:
            raise MeshError(f"kind must be 'facets' or 'cells', got {kind!r}")
        sel = _regions.select(m, dim, ents, where, tol)
        if self._global_count(sel) == 0:
            raise MeshError(f"region {name!r} selects no {kind}; check its box/shape/predicate against the mesh "
                            f"bounds {self.bounds[0].tolist()}..{self.bounds[1].tolist()} m")
        self._set(name, dim, sel)
        return self

    def _region(self, name):
        if name not in self._entities:
            raise MeshError(f"no region {name!r}; available regions: {sorted(self.regions)}")
        return self._entities[name]

    def region_dimension(self, name):
        """Topological dimension of region ``name``: the mesh's for cell regions, one less for facet regions."""
        return self._region(name)[0]

    def facets(self, name):
        """Local (this rank's, ghosts included) facet indices of region ``name``."""
        dim, ents = self._region(name)
        if dim != self.dolfinx.topology.dim - 1:
            raise MeshError(f"region {name!r} is a cell region; use cells({name!r})")
        return ents

    def cells(self, name):
        """Local (this rank's, ghosts included) cell indices of region ``name``."""
        dim, ents = self._region(name)
        if dim != self.dolfinx.topology.dim:
            raise MeshError(f"region {name!r} is a facet region; use facets({name!r})")
        return ents

    def meshtags(self, name):
        """A DOLFINx ``MeshTags`` holding only region ``name`` (value ``regions[name]``), exact even where
        regions overlap."""
        import dolfinx.mesh

        dim, ents = self._region(name)
        t = dolfinx.mesh.meshtags(self.dolfinx, dim, ents, np.full(len(ents), self.regions[name], dtype=np.int32))
        t.name = name
        return t

    def _tags(self, dim):
        import dolfinx.mesh

        idx, val = [np.zeros(0, dtype=np.int32)], [np.zeros(0, dtype=np.int32)]
        for name, (d, ents) in self._entities.items():
            if d == dim:
                idx.append(ents)
                val.append(np.full(len(ents), self.regions[name], dtype=np.int32))
        idx, val = np.concatenate(idx), np.concatenate(val)
        # later regions win where regions overlap: keep the last occurrence of each index
        rev_u, rev_i = np.unique(idx[::-1], return_index=True)
        return dolfinx.mesh.meshtags(self.dolfinx, dim, rev_u.astype(np.int32), val[::-1][rev_i])

    @property
    def facet_tags(self):
        """``MeshTags`` of all facet regions (one value per facet: the region added last wins on overlaps;
        use :meth:`meshtags` for one exact region)."""
        return self._tags(self.dolfinx.topology.dim - 1)

    @property
    def cell_tags(self):
        """``MeshTags`` of all cell regions (the region added last wins on overlaps)."""
        return self._tags(self.dolfinx.topology.dim)

    # ------------------------------------------------------------------------------------------ measures
    def _assemble(self, integrand, measure):
        import dolfinx.fem
        from mpi4py import MPI

        val = dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand * measure))
        return float(self.comm.allreduce(val, op=MPI.SUM))

    def measure(self, name=None):
        """Measure of the whole mesh or of a region: area/volume of cells [m^2 or m^3], length/area of facets.

        Parameters
        ----------
        name : str, optional
            Region name; ``None`` for the whole domain.
        """
        import dolfinx.fem
        import ufl

        m = self.dolfinx
        one = dolfinx.fem.Constant(m, 1.0)
        if name is None:
            return self._assemble(one, ufl.dx(domain=m, metadata={"quadrature_degree": 4}))
        dim, _ = self._region(name)
        kind = ufl.ds if dim == m.topology.dim - 1 else ufl.dx
        dm = kind(domain=m, subdomain_data=self.meshtags(name), subdomain_id=self.regions[name],
                  metadata={"quadrature_degree": 4})
        return self._assemble(one, dm)

    def cavity_volume(self, name):
        """Volume [m^3] (area [m^2] in 2D) enclosed by a cavity: :math:`-\\frac{1}{d}\\int_\\Gamma x\\cdot n\\,ds`."""
        import ufl

        if not name.startswith("cavity_"):
            raise MeshError(f"{name!r} is not a cavity; cavities are {self.cavities}")
        m = self.dolfinx
        dim, _ = self._region(name)
        x, n = ufl.SpatialCoordinate(m), ufl.FacetNormal(m)
        dm = ufl.ds(domain=m, subdomain_data=self.meshtags(name), subdomain_id=self.regions[name],
                    metadata={"quadrature_degree": 4})
        return -self._assemble(ufl.dot(x, n) / self.dim, dm)

    # ------------------------------------------------------------------------------------------ quality
    def check_quality(self, min_angle=0.0):
        """Compute the quality report; raise :class:`MeshError` if the mesh is unusable.

        Unusable means: no cells, degenerate cells (Jacobian below 1e-10 h^d), inverted cells (Jacobian
        changing sign inside a cell), or a minimum angle below ``min_angle`` [deg].
        """
        q = _regions.quality(self.dolfinx)
        if q["num_cells"] == 0:
            raise MeshError("the mesh has no cells; the geometry is empty or smaller than the element size")
        if q["degenerate"]:
            raise MeshError(f"the mesh has {q['degenerate']} degenerate cell(s) (zero area/volume); remesh with a "
                            "smaller size or fix the input geometry")
        if q["inverted"]:
            raise MeshError(f"the mesh has {q['inverted']} inverted cell(s) (the Jacobian changes sign inside a "
                            "cell, typically curved order-2 cells on a tight boundary); use order=1 or a smaller "
                            "size")
        if q["min_angle"] < min_angle:
            raise MeshError(f"the smallest angle {q['min_angle']:.3g} deg is below the required {min_angle} deg")
        return q

    # ------------------------------------------------------------------------------------------ building
    @classmethod
    def _from_root_arrays(cls, comm, build, side_tol=None, source=""):
        """Run ``build() -> (x (n, 3), cells, gmsh_type, gdim)`` on rank 0 and distribute the mesh."""
        t0 = time.perf_counter()
        data = on_root(comm, build)
        if comm.rank == 0:
            x, cells, etype, gdim = data
            meta = (etype, cells.shape[1], gdim)
            if len(cells) and (cells.min() < 0 or cells.max() >= len(x)):
                meta = MeshError(f"cells refer to nodes {cells.min()}..{cells.max()} but there are {len(x)}")
        meta = comm.bcast(meta if comm.rank == 0 else None, root=0)
        if isinstance(meta, Exception):
            raise meta
        etype, nn, gdim = meta
        if comm.rank != 0:
            x, cells = np.zeros((0, 3)), np.zeros((0, nn), dtype=np.int64)
        name, degree, tdim = _gmsh.GMSH_CELLS[etype]
        perm = _dolfinx.gmsh_node_order(name, nn)
        mesh = _dolfinx.create_mesh(comm, np.ascontiguousarray(cells[:, perm], dtype=np.int64),
                                    np.ascontiguousarray(x[:, :gdim]), name, degree)
        out = cls(mesh, side_tol=side_tol, source=source)
        out.build_time = time.perf_counter() - t0
        return out

    @classmethod
    def from_arrays(cls, points, cells, cell=None, comm=None, side_tol=None):
        """A mesh from node coordinates [m] (n, dim) and cells (m, k) in gmsh node order (given on rank 0).

        ``cell`` is inferred from ``dim`` and ``k``: 3/6 nodes → triangle, 4 → tetrahedron (3D) or
        quadrilateral (2D), 10 → tetrahedron P2, 8 → hexahedron, 9 → quadrilateral P2, 27 → hexahedron P2.
        """
        comm = comm or _world()

        def build():
            x = np.asarray(points, dtype=float)
            c = np.asarray(cells, dtype=np.int64)
            if x.ndim != 2 or x.shape[1] not in (2, 3) or c.ndim != 2 or len(c) == 0:
                raise MeshError(f"points must be (n, 2|3) and cells (m, k) with m > 0; got {x.shape} and {c.shape}")
            if c.min() < 0 or c.max() >= len(x):
                raise MeshError(f"cells refer to node {c.min()}..{c.max()} but there are {len(x)} nodes")
            gdim, k = x.shape[1], c.shape[1]
            table = {(2, 3): 2, (2, 6): 9, (2, 4): 3, (2, 9): 10, (3, 4): 4, (3, 10): 11, (3, 8): 5, (3, 27): 12}
            if (gdim, k) not in table:
                raise MeshError(f"cannot infer a cell type from {k} nodes per cell in {gdim}D")
            x3 = np.column_stack([x, np.zeros((len(x), 3 - gdim))])
            return x3, c, table[(gdim, k)], gdim

        return cls._from_root_arrays(comm, build, side_tol=side_tol, source="arrays")

    @classmethod
    def from_sdf(cls, shape, size, order=1, cell="simplex", method="auto", refine=None, boundary_size=None,
                 boundary_width=None, comm=None, side_tol=None, max_cells=None, interfaces=None, grading=None):
        """Mesh the inside (negative part) of a signed distance function.

        Parameters
        ----------
        shape : sorofem.sdf shape
            2D or 3D shape; SI units (m).
        size : float or callable
            Target element size [m], or ``size(x) -> h`` on an (N, dim) array of points [m] (the mesh's largest
            size is the largest value of it on the origin and a fixed sample of 256 points in the bounds).
        order : {1, 2}
            Geometric (and natural field) degree of the cells.
        cell : str
            ``"triangle"``/``"tetrahedron"`` (default) or ``"quadrilateral"``/``"hexahedron"`` (a plain
            rectangle/box gets a structured transfinite grid; other shapes are recombined).
        method : {"auto", "csg", "levelset"}
            ``"csg"`` rebuilds the tree exactly in OpenCASCADE (primitives, sharp booleans, rigid transforms
            only); ``"levelset"`` meshes the zero level (marching squares/cubes, snapped onto the surface with
            ``shape.project``); ``"auto"`` uses CSG when the tree allows it.
        refine : list of (region, size), optional
            Finer sizes [m] inside regions: a box ``(lo, hi)``, a shape, or a predicate on ``(dim, N)`` points.
        boundary_size : float, optional
            Element size [m] at the boundary, growing linearly to ``size`` over ``boundary_width`` [m]
            (default ``4 * size``).
        comm : MPI communicator, optional
            Defaults to ``MPI.COMM_WORLD``; the mesh is built on rank 0 and distributed.
        side_tol : float, optional
            Tolerance [m] for the named sides; default ``1e-6`` times the bounding-box diagonal.
        max_cells : int, optional
            Largest number of cells to generate, checked against :func:`estimate_cells` before gmsh runs
            (a mistyped size would otherwise mesh for minutes). Default: the enclosing :func:`cell_limit`
            (a sweep's ``[sweep] max_cells``), else :data:`MAX_CELLS` (2e6).
        interfaces : list of shapes, optional
            Shapes whose boundaries inside the domain the mesh follows: cell edges (3D: faces) lie on them, so
            a second material's region, :meth:`add_region` ``(name, that shape, kind="cells")``, is exactly that
            shape at every size. Without it the region is the cells whose midpoints fall inside, a boundary
            recovered only to ~size (a 2 mm layer's area varied by 2.5 % between sizes 0.3 and 0.15 mm). Needs
            the CSG path (primitives, sharp booleans, rigid transforms) for ``shape`` and each interface.
        grading : (radius, exponent, smallest), optional
            A mesh graded towards the geometry's corners (every point of the CSG model: the corners of the shape
            and the interfaces' ends): size ``size * (r / radius)^(1 - exponent)`` at a distance r [m] below
            ``radius`` [m] from the nearest corner, at least ``smallest * size``. At a re-entrant corner the
            solution goes as r^lambda (a 270 degree traction-free corner: lambda = 0.5445) and a uniform mesh
            converges as h^(2 lambda) there; an exponent below lambda / degree restores the element's order (up to
            ``smallest``). Needs the CSG path and a number ``size`` (no ``refine``, ``boundary_size``); the cell
            estimate that ``max_cells`` checks is the uniform one (a grading with exponent > 0 adds a bounded
            factor).

        Raises
        ------
        GeometryError
            Empty shape, non-conservative bounds.
        MeshError
            Non-positive size, an estimated cell count above ``max_cells``, meshing failure or unusable mesh.
        """
        comm = comm or _world()
        order = _check_order(order)
        dim = getattr(shape, "dim", None)
        if dim not in (2, 3) or not callable(shape):
            raise GeometryError(f"expected a 2D or 3D signed distance shape, got {type(shape).__name__}")
        kind = _check_cell(cell, dim)
        if method not in ("auto", "csg", "levelset"):
            raise MeshError(f"method must be 'auto', 'csg' or 'levelset', got {method!r}")
        interfaces = tuple(interfaces or ())
        if interfaces and method == "levelset":
            raise MeshError("interfaces= needs the CSG path (method='auto' or 'csg'): a level-set mesh cannot "
                            "follow inner boundaries; drop interfaces or build the shape from CSG primitives")
        for s in interfaces:
            if getattr(s, "dim", None) != dim or not callable(s):
                raise GeometryError(f"each interface must be a {dim}D signed distance shape like the domain, got "
                                    f"{type(s).__name__} of dimension {getattr(s, 'dim', None)}")
        if grading is not None:
            grading = _check_grading(grading, size, refine, boundary_size, method)
        h_base, h_bnd, h_fn = _size_function(size, refine, shape, boundary_size, boundary_width, dim)
        if kind == "quad" and dim == 3 and getattr(shape, "op", "") != "box":
            raise MeshError("hexahedra are only generated for a plain box (Mesh.box or sdf.Box); use tetrahedra")
        _check_size_estimate(shape, h_fn, h_base, kind, max_cells)

        def build():
            with _gmsh.session("from_sdf") as gmsh:
                _gmsh.set_options(gmsh, h_base, order, kind, size_callback=h_fn, dim=dim)
                used = None
                p = shape.params if hasattr(shape, "params") else {}
                if kind == "quad" and method != "levelset" and getattr(shape, "op", "") in ("rectangle", "box") \
                        and not p.get("radius") and not interfaces:
                    lo, hi = (np.asarray(b, dtype=float) for b in shape.bounds)
                    _structured(gmsh, lo, hi, h_base, dim)
                    used = "transfinite"
                elif method in ("auto", "csg"):
                    try:
                        _occ_build(gmsh, shape, dim, interfaces)
                        used = "csg"
                        if grading is not None:
                            _gmsh.grade_to_corners(gmsh, h_base, *grading)
                    except _gmsh.NotTranslatable as e:
                        if interfaces or grading is not None:
                            raise GeometryError(f"the shape or an interface cannot be rebuilt exactly in "
                                                f"OpenCASCADE ({e}), which interfaces= and grading= need: build "
                                                "them from "
                                                "CSG primitives, sharp booleans and rigid transforms") from None
                        if method == "csg":
                            raise GeometryError(f"the shape cannot be rebuilt exactly in OpenCASCADE ({e}); use "
                                                "method='levelset'") from None
                        gmsh.model.remove()
                        gmsh.model.add("levelset")
                        _gmsh.set_options(gmsh, h_base, order, kind, size_callback=h_fn, dim=dim)
                if used is None:
                    used = "levelset"
                    if dim == 2:
                        _mesh_levelset_2d(gmsh, shape, h_bnd, order, kind, h_base)
                    else:
                        _mesh_levelset_3d(gmsh, shape, h_bnd)
                log.info("meshing %dD shape %s with the %s path, size %.3g m", dim, getattr(shape, "op", "?"),
                         used, h_base)
                _gmsh.generate(gmsh, dim, order)
                if used == "levelset":
                    _gmsh.snap_boundary_nodes(gmsh, shape, dim, h_bnd)
                x, cells, etype = _gmsh.extract(gmsh, dim)
                return x, cells, etype, dim

        return cls._from_root_arrays(comm, build, side_tol=side_tol, source="sdf")

    def refined(self, times=1):
        """A new mesh, this one's straight simplices split uniformly ``times`` times: every edge halved (a
        triangle into 4, a tetrahedron into 8, the inner octahedron cut along its shortest diagonal, which keeps
        the cells' shapes bounded). The refinements are nested and the geometry is
        the same on each (a polyhedral domain exactly; a curved one stays that of this mesh), so a convergence
        study on ``msh, msh.refined(1), msh.refined(2)`` sees h halve exactly, unlike meshes generated anew at
        h, h/2, h/4, whose cells differ per mesh. The boundary regions found automatically (sides, cavities) are
        found again; regions added with :meth:`add_region` are not carried over: add them again. Serial and
        first-order simplices only (raises :class:`MeshError` otherwise); 8^times (3D) or 4^times (2D) cells."""
        import numbers

        if not isinstance(times, numbers.Integral) or times < 0:
            raise MeshError(f"times must be a whole number >= 0 of uniform refinements, got {times!r}")
        m = self.dolfinx
        q = self.quality
        if self.comm.size > 1:
            raise MeshError("Mesh.refined works on a serial mesh: refine before distributing it, or run in serial")
        if q["degree"] != 1 or q["cell"] not in ("triangle", "tetrahedron"):
            raise MeshError(f"Mesh.refined splits straight triangles and tetrahedra; this mesh has {q['cell']} "
                            f"cells of degree {q['degree']}: build it with order=1 and simplex cells")
        x = np.asarray(m.geometry.x, dtype=float)[:, :self.dim]
        cells = np.asarray(_dolfinx.geometry_dofs(m, m.topology.index_map(m.topology.dim).size_local),
                           dtype=np.int64)
        for _ in range(times):
            x, cells = _split_simplices(x, cells)
        return type(self).from_arrays(x, cells, comm=self.comm, side_tol=self._tol)

    @classmethod
    def rectangle(cls, width, height, size, center=(0.0, 0.0), cell="triangle", order=1, comm=None):
        """A structured (transfinite) mesh of a ``width`` x ``height`` [m] rectangle centred at ``center``."""
        return cls._box_like(np.array([width, height], dtype=float), np.asarray(center, dtype=float), size, cell,
                             order, comm)

    @classmethod
    def box(cls, width, depth, height, size, center=(0.0, 0.0, 0.0), cell="tetrahedron", order=1, comm=None):
        """A structured mesh of a ``width`` (x) x ``depth`` (y) x ``height`` (z) [m] box centred at ``center``."""
        return cls._box_like(np.array([width, depth, height], dtype=float), np.asarray(center, dtype=float), size,
                             cell, order, comm)

    @classmethod
    def _box_like(cls, ext, center, size, cell, order, comm):
        comm = comm or _world()
        dim = len(ext)
        if not np.all(np.isfinite(ext)) or np.any(ext <= 0):
            raise GeometryError(f"box dimensions must be positive lengths in metres, got {ext.tolist()}")
        h = _gmsh.check_size(size)
        kind = _check_cell(cell, dim)
        order = _check_order(order)

        def build():
            with _gmsh.session("box") as gmsh:
                _gmsh.set_options(gmsh, h, order, kind, dim=dim)
                _structured(gmsh, center - ext / 2, center + ext / 2, h, dim, recombine=kind == "quad")
                _gmsh.generate(gmsh, dim, order)
                x, cells, etype = _gmsh.extract(gmsh, dim)
                return x, cells, etype, dim

        return cls._from_root_arrays(comm, build, source="box")

    @classmethod
    def from_image(cls, path, pixel_size, threshold=0.5, invert=False, size=None, order=1, cell="triangle",
                   comm=None, side_tol=None):
        """Mesh the dark part of a black-and-white image (PNG, JPEG).

        Parameters
        ----------
        path : str or Path
            Image file.
        pixel_size : float
            Edge length of one pixel [m].
        threshold : float
            Grey level in [0, 1] separating foreground from background.
        invert : bool
            Mesh the bright part instead of the dark part.
        size : float, optional
            Element size [m]; default 2 pixels.

        The origin is the lower-left corner of the image, +y points up. Boundaries follow the ``threshold``
        iso-line of the grey levels (sub-pixel on anti-aliased images); the area error is of the order of
        (perimeter x pixel_size / 2) for hard-edged images.
        """
        comm = comm or _world()
        px = _gmsh.check_size(pixel_size, "pixel_size")
        h = _gmsh.check_size(size if size is not None else 2 * px)
        order = _check_order(order)
        kind = _check_cell(cell, 2)
        if not 0.0 < float(threshold) < 1.0:
            raise MeshError(f"threshold must lie strictly between 0 and 1 (grey level), got {threshold!r}")

        def build():
            img = _contour.load_image(path)
            curves = _contour.image_contours(img, px, threshold, invert, size=h)
            with _gmsh.session("from_image") as gmsh:
                _gmsh.set_options(gmsh, h, order, kind, dim=2)
                _gmsh.loops_to_geo(gmsh, _contour.nest_loops(curves), h)
                _gmsh.generate(gmsh, 2, order)
                x, cells, etype = _gmsh.extract(gmsh, 2)
                return x, cells, etype, 2

        return cls._from_root_arrays(comm, build, side_tol=side_tol, source=str(path))

    @classmethod
    def from_file(cls, path, size=None, order=1, comm=None, side_tol=None, units=None):
        """Read a mesh or a closed surface.

        * ``.xdmf`` (written by :meth:`write_xdmf`): the mesh and every stored region, read in parallel.
        * ``.msh``: cells of the highest dimension; named physical groups become regions.
        * ``.stl``, ``.obj``, ``.ply``, ``.off``: a closed triangulated surface, remeshed at ``size`` [m] (default
          bounding-box diagonal / 20) and filled with tetrahedra. Its coordinates are in ``units`` (``"mm"``,
          ``"m"``, ...; default: the unit an STL header names, see :func:`sorofem.sdf.write_stl`, else mm).
        * other meshio formats (``.vtu``, ``.mesh``, ...): cells of the highest dimension.

        Planar (z = 0) inputs give 2D meshes. Sides and cavities are tagged as for every builder.
        """
        comm = comm or _world()
        path = Path(path)
        if not path.is_file():
            raise MeshError(f"mesh file {str(path)!r} does not exist")
        suffix = path.suffix.lower()
        if suffix == ".xdmf":
            return _read_xdmf(cls, path, comm, side_tol)
        if size is not None:
            _gmsh.check_size(size)
        order = _check_order(order)

        def build():
            try:
                return _build_from_file()
            except MeshError:
                raise
            except Exception as e:  # noqa: BLE001 - any reader failure is the same user error
                raise MeshError(f"cannot mesh {str(path)!r} ({type(e).__name__}: {e}); give a closed STL/OBJ "
                                "surface, a .msh or an XDMF file") from e

        def _build_from_file():
            if suffix == ".msh":
                return _read_msh(path)
            import meshio

            try:
                m = meshio.read(str(path))
            except Exception as e:  # noqa: BLE001
                raise MeshError(f"cannot read {str(path)!r} ({type(e).__name__}: {e}); give an STL, OBJ, .msh, "
                                "XDMF or another meshio format") from e
            pts = np.asarray(m.points, dtype=float)
            if suffix in (".stl", ".obj", ".ply", ".off"):
                from ..sdf.export import STL_UNITS, stl_units
                unit = units or (stl_units(path) if suffix == ".stl" else None) or "mm"
                if unit not in STL_UNITS:
                    raise MeshError(f"units must be one of {sorted(STL_UNITS)}, got {unit!r}")
                pts = pts * STL_UNITS[unit]
            pts = np.column_stack([pts, np.zeros((len(pts), 3 - pts.shape[1]))]) if pts.shape[1] < 3 else pts
            kinds = {c.type: c.data for c in m.cells}
            planar = np.ptp(pts[:, 2]) <= 1e-12 * max(np.ptp(pts), 1e-300) if len(pts) else False
            for t, dim in (("hexahedron27", 3), ("tetra10", 3), ("hexahedron", 3), ("tetra", 3)):
                if t in kinds:
                    return _arrays_from_meshio(pts, t, kinds[t], 3)
            if planar:
                for t in ("triangle6", "quad9", "triangle", "quad"):
                    if t in kinds:
                        return _arrays_from_meshio(pts, t, kinds[t], 2)
            if "triangle" not in kinds:
                raise MeshError(f"{str(path)!r} holds no triangles or volume cells (found {list(kinds)})")
            tri = kinds["triangle"]
            h = size if size is not None else float(np.linalg.norm(np.ptp(pts, axis=0))) / 20
            with _gmsh.session("from_file") as gmsh:
                _gmsh.set_options(gmsh, h, order, "simplex", dim=3)
                try:
                    _gmsh.surface_to_volume(gmsh, pts, tri)
                except Exception as e:  # noqa: BLE001
                    raise MeshError(f"could not build a volume from the surface in {str(path)!r} ({e}); the "
                                    "surface must be closed and not self-intersecting") from e
                _gmsh.generate(gmsh, 3, order)
                x, cells, etype = _gmsh.extract(gmsh, 3)
                return x, cells, etype, 3

        out = cls._from_root_arrays(comm, build, side_tol=side_tol, source=str(path))
        if suffix == ".msh":
            _attach_msh_regions(out, path)
        return out

    # ------------------------------------------------------------------------------------------ output
    def write_xdmf(self, path):
        """Write the mesh and every region (one ``MeshTags`` grid per region name) to ``path`` (.xdmf + .h5).

        Both files are written in a temporary directory next to ``path`` and moved into place (the ``.h5``
        first), so a reader never sees a half-written pair. Collective.
        """
        from dolfinx.io import XDMFFile

        path = Path(path).with_suffix(".xdmf")
        comm = self.comm
        tmpdir = None
        if comm.rank == 0:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmpdir = tempfile.mkdtemp(prefix=f".{path.stem}.", dir=path.parent)
        tmpdir = Path(comm.bcast(tmpdir, root=0))
        try:
            self.dolfinx.name = "mesh"
            tdim = self.dolfinx.topology.dim
            with XDMFFile(comm, str(tmpdir / path.name), "w") as f:
                f.write_mesh(self.dolfinx)
                if self._entities:
                    self.dolfinx.topology.create_connectivity(tdim - 1, tdim)
                for name in self.regions:
                    _dolfinx.write_meshtags(f, self.meshtags(name), self.dolfinx)
            comm.barrier()
            if comm.rank == 0:
                os.replace(tmpdir / path.with_suffix(".h5").name, path.with_suffix(".h5"))
                os.replace(tmpdir / path.name, path)
        finally:
            comm.barrier()
            if comm.rank == 0:
                shutil.rmtree(tmpdir, ignore_errors=True)
        return path

    def write_msh(self, path):
        """Write the mesh and its regions (as named physical groups) to a gmsh ``.msh`` file, atomically.

        The distributed mesh is gathered on rank 0 (collective).
        """
        from ..io import atomic_path

        path = Path(path)
        data = _gather(self)
        if self.comm.rank == 0:
            with atomic_path(path, suffix=".msh") as tmp:
                _write_msh(tmp, *data)
        self.comm.barrier()
        return path

    def plot(self, ax=None, regions=True, linewidth=0.3, unit="mm"):
        """Draw a 2D mesh (this rank's part) with matplotlib, boundary regions in colour; returns the axes.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw (e.g. from ``matplotlib.figure.Figure().subplots()``); a new pyplot figure if None.
        regions : bool
            Draw the named boundary/cell regions in colour, with a legend.
        linewidth : float
            Line width of the element edges [pt].
        unit : {"mm", "m"}
            Unit of the axes (the mesh is in metres; ``"mm"``, the default, draws it in millimetres and labels
            the axes ``x [mm]``, ``y [mm]``).
        """
        import matplotlib.pyplot as plt
        from matplotlib.collections import LineCollection

        if self.dim != 2:
            raise MeshError("plot() draws 2D meshes; write_xdmf() and open it in ParaView for 3D")
        scales = {"mm": 1e3, "m": 1.0}
        if unit not in scales:
            raise MeshError(f"plot(unit={unit!r}): the unit is 'mm' or 'm'")
        k = scales[unit]
        m = self.dolfinx
        if ax is None:
            _, ax = plt.subplots()
        tdim = m.topology.dim
        m.topology.create_connectivity(1, 0)
        nedge = m.topology.index_map(1).size_local + m.topology.index_map(1).num_ghosts
        X = k * _regions._entity_vertex_coords(m, 1, np.arange(nedge, dtype=np.int32))
        ax.add_collection(LineCollection(X, colors="0.6", linewidths=linewidth))
        if regions:
            cmap = plt.get_cmap("tab10")
            for i, (name, (d, ents)) in enumerate(self._entities.items()):
                if len(ents) == 0:
                    continue
                Xr = k * _regions._entity_vertex_coords(m, d, ents) if d == tdim - 1 else None
                if Xr is not None:
                    ax.add_collection(LineCollection(Xr, colors=[cmap(i % 10)], linewidths=2.0, label=name))
                else:
                    C = k * _regions._entity_vertex_coords(m, d, ents)
                    from matplotlib.collections import PolyCollection
                    ax.add_collection(PolyCollection(C, facecolors=[cmap(i % 10)], alpha=0.4, label=name))
            ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        lo, hi = k * np.asarray(self.bounds[0]), k * np.asarray(self.bounds[1])
        pad = 0.02 * float(np.max(hi - lo))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set(xlabel=f"x [{unit}]", ylabel=f"y [{unit}]")
        ax.set_aspect("equal")
        return ax


# ------------------------------------------------------------------------------------------------ helpers


def _structured(gmsh, lo, hi, h, dim, recombine=True):
    occ = gmsh.model.occ
    ext = hi - lo
    if dim == 2:
        occ.addRectangle(lo[0], lo[1], 0.0, ext[0], ext[1])
    else:
        occ.addBox(*lo, *ext)
    occ.synchronize()
    for _, c in gmsh.model.getEntities(1):
        b = gmsh.model.getBoundingBox(1, c)
        length = max(b[3] - b[0], b[4] - b[1], b[5] - b[2])
        gmsh.model.mesh.setTransfiniteCurve(c, max(2, int(math.ceil(length / h - 1e-3)) + 1))
    for _, s in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(s)
        if recombine:
            gmsh.model.mesh.setRecombine(2, s)
    if dim == 3:
        for _, v in gmsh.model.getEntities(3):
            gmsh.model.mesh.setTransfiniteVolume(v)
    gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 0)
    if not recombine:
        gmsh.option.setNumber("Mesh.RecombineAll", 0)


def _split_simplices(x, cells):
    """One uniform refinement of straight simplices: nodes ``x`` (n, d) plus the edges' midpoints, and the
    children of ``cells`` (m, 3) or (m, 4) (4 or 8 each; a tetrahedron's inner octahedron cut along its shortest diagonal)."""
    k = cells.shape[1]
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
    e = np.sort(np.stack([cells[:, [a, b]] for a, b in pairs], axis=1).reshape(-1, 2), axis=1)
    edges, inv = np.unique(e, axis=0, return_inverse=True)
    mid = len(x) + inv.reshape(len(cells), len(pairs))              # the midpoint node of each cell's edge
    x = np.vstack([x, 0.5 * (x[edges[:, 0]] + x[edges[:, 1]])])
    v = [cells[:, i] for i in range(k)]
    if k == 3:      # edges 01, 02, 12
        m01, m02, m12 = mid.T
        kids = [(v[0], m01, m02), (m01, v[1], m12), (m02, m12, v[2]), (m01, m12, m02)]
    else:           # edges 01, 02, 03, 12, 13, 23; the inner octahedron cut along its shortest diagonal
        m01, m02, m03, m12, m13, m23 = mid.T
        kids = [(v[0], m01, m02, m03), (m01, v[1], m12, m13), (m02, m12, v[2], m23), (m03, m13, m23, v[3])]
        # each diagonal (a, b) with the ring of the other four midpoints around it: 4 tetrahedra (a, b, r_i, r_i+1)
        cuts = [((m02, m13), (m01, m03, m23, m12)), ((m01, m23), (m02, m03, m13, m12)),
                ((m03, m12), (m01, m02, m23, m13))]
        length = np.stack([np.linalg.norm(x[a] - x[b], axis=1) for (a, b), _ in cuts], axis=1)
        pick = np.argmin(length, axis=1)
        for i in range(4):
            kids.append(tuple(np.choose(pick, [c[j] for (a, b), r in cuts for c in [(a, b, r[i], r[(i + 1) % 4])]])
                              for j in range(4)))
    return x, np.concatenate([np.stack(c, axis=1) for c in kids])


def _arrays_from_meshio(pts, t, data, gdim):
    etype = {"triangle": 2, "triangle6": 9, "quad": 3, "quad9": 10, "tetra": 4, "tetra10": 11, "hexahedron": 5,
             "hexahedron27": 12}[t]
    c = np.asarray(data, dtype=np.int64)
    used = np.unique(c)
    renum = np.full(len(pts), -1, dtype=np.int64)
    renum[used] = np.arange(len(used))
    # meshio uses VTK node order; for the linear and quadratic simplices and linear tensor cells it matches gmsh
    if t in ("quad9", "hexahedron27"):
        raise MeshError(f"{t} cells from meshio formats are not supported; use .msh or XDMF")
    return pts[used], renum[c], etype, gdim


def _read_msh(path):
    with _gmsh.session("read_msh") as gmsh:
        try:
            gmsh.merge(str(path))
        except Exception as e:  # noqa: BLE001
            raise MeshError(f"gmsh cannot read {str(path)!r} ({e})") from e
        tdim = max((d for d, _ in gmsh.model.getEntities()), default=0)
        if tdim < 2:
            raise MeshError(f"{str(path)!r} holds no 2D or 3D cells")
        x, cells, etype = _gmsh.extract(gmsh, tdim)
        gdim = 2 if tdim == 2 and np.ptp(x[:, 2]) <= 1e-12 * max(np.ptp(x), 1e-300) else 3
        return x, cells, etype, gdim


def _msh_groups(path):
    """Named physical groups of a .msh file: {name: (dim, node coordinates of each element's vertices)}."""
    out = {}
    with _gmsh.session("msh_groups") as gmsh:
        gmsh.merge(str(path))
        ntags, coords, _ = gmsh.model.mesh.getNodes()
        lookup = np.zeros((int(np.max(ntags)) + 1, 3))
        lookup[np.asarray(ntags, dtype=np.int64)] = np.asarray(coords).reshape(-1, 3)
        for dim, tag in gmsh.model.getPhysicalGroups():
            name = gmsh.model.getPhysicalName(dim, tag)
            if not name or dim == 0:
                continue
            pts = []
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                types, _, conn = gmsh.model.mesh.getElements(dim, ent)
                for t, cn in zip(types, conn):
                    nv = gmsh.model.mesh.getElementProperties(t)[5]  # primary (vertex) nodes
                    nn = gmsh.model.mesh.getElementProperties(t)[3]
                    cn = np.asarray(cn).reshape(-1, nn)[:, :nv]
                    pts.append(lookup[cn.astype(np.int64)])
            if pts:
                out[name] = (dim, np.concatenate(pts))
    return out


def _attach_msh_regions(msh, path):
    """Re-create the named physical groups of a .msh file as regions (matched by vertex coordinates)."""
    from scipy.spatial import cKDTree

    comm = msh.comm
    groups = on_root(comm, lambda: _msh_groups(path))
    groups = comm.bcast(groups, root=0)
    m = msh.dolfinx
    tdim, gdim = m.topology.dim, m.geometry.dim
    tol = msh._tol * 10
    for name, (dim, X) in groups.items():
        if dim == tdim - 1:
            ents = _regions.exterior_facets(m)
        elif dim == tdim:
            imap = m.topology.index_map(tdim)
            ents = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        else:
            continue
        if len(ents) == 0:
            msh._set(name, dim, ents)
            continue
        mine = _regions._entity_vertex_coords(m, dim, ents).mean(axis=1)
        theirs = X[:, :, :gdim].mean(axis=1)
        d, _ = cKDTree(theirs).query(mine, k=1)
        msh._set(name, dim, ents[d <= tol])


def _read_xdmf(cls, path, comm, side_tol):
    from dolfinx.io import XDMFFile

    try:
        names = [g.get("Name") for g in ET.parse(path).getroot().iter("Grid")]
    except ET.ParseError as e:
        raise MeshError(f"{str(path)!r} is not a valid XDMF file ({e})") from e
    mesh_name = names[0] if names else "mesh"
    try:
        with XDMFFile(comm, str(path), "r") as f:
            mesh = f.read_mesh(name=mesh_name)
            tdim = mesh.topology.dim
            mesh.topology.create_connectivity(tdim - 1, tdim)
            tags = {n: f.read_meshtags(mesh, n) for n in names[1:]}
    except RuntimeError as e:
        raise MeshError(f"cannot read {str(path)!r} with DOLFINx ({e})") from e
    out = cls(mesh, side_tol=side_tol, auto_regions=False, source=str(path))
    for n, t in tags.items():
        out._set(n, t.dim, t.indices)
    stored = set(out.regions)
    # add the automatic regions the file did not store
    probe = cls(mesh, side_tol=side_tol, auto_regions=True, source=str(path))
    for n in probe.regions:
        if n not in stored:
            out._set(n, *probe._entities[n])
    return out


def _gather(msh):
    """Gather the mesh and its regions on rank 0 in gmsh node order.

    Returns on rank 0 ``(x (n, 3), cells, gmsh cell type, {name: (dim, gmsh type, nodes)}, tdim)``.
    """
    import basix

    m = msh.dolfinx
    comm = msh.comm
    tdim = m.topology.dim
    imap = m.geometry.index_map()
    nloc = imap.size_local
    nghost = imap.num_ghosts
    glob = imap.local_to_global(np.arange(nloc + nghost, dtype=np.int32))
    ncell = m.topology.index_map(tdim).size_local
    geo = _dolfinx.geometry_dofs(m)
    nn = geo.shape[1]
    name = m.topology.cell_type.name
    degree = 1 if nn == {"triangle": 3, "quadrilateral": 4, "tetrahedron": 4, "hexahedron": 8}[name] else 2
    perm = _dolfinx.gmsh_node_order(name, nn)
    cells_g = np.empty((ncell, nn), dtype=np.int64)
    cells_g[:, perm] = glob[geo[:ncell]]
    # facets: closure dofs of the local facet in the coordinate element
    el = basix.create_element(basix.ElementFamily.P, _regions._basix_cell(name), degree,
                              basix.LagrangeVariant.gll_warped)
    fclos = el.entity_closure_dofs[tdim - 1]
    nfn = len(fclos[0])
    fperm = _dolfinx.gmsh_facet_node_order(name, nfn)
    m.topology.create_connectivity(tdim - 1, tdim)
    m.topology.create_connectivity(tdim, tdim - 1)
    f2c = m.topology.connectivity(tdim - 1, tdim)
    c2f = m.topology.connectivity(tdim, tdim - 1)
    fimap = m.topology.index_map(tdim - 1)
    regions = {}
    for rname, (d, ents) in msh._entities.items():
        if d == tdim:
            own = ents[ents < ncell]
            regions[rname] = (d, cells_g[own])
        else:
            own = ents[ents < fimap.size_local]
            rows = np.empty((len(own), nfn), dtype=np.int64)
            for i, f in enumerate(own):
                c = f2c.links(f)[0]
                lf = int(np.flatnonzero(c2f.links(c) == f)[0])
                rows[i, fperm] = glob[geo[c, fclos[lf]]]
            regions[rname] = (d, rows)
    x = m.geometry.x[:nloc]
    parts = comm.gather((glob[:nloc], x, cells_g, regions), root=0)
    if comm.rank != 0:
        return None
    n = sum(len(p[0]) for p in parts)
    X = np.zeros((n, 3))
    for g, xx, _, _ in parts:
        X[g] = xx
    cells = np.vstack([p[2] for p in parts])
    regs = {}
    for rname in msh.regions:
        d = msh._entities[rname][0]
        rows = [p[3][rname][1] for p in parts if len(p[3][rname][1])]
        nnr = nn if d == tdim else nfn
        rows = np.unique(np.vstack(rows), axis=0) if rows else np.zeros((0, nnr), dtype=np.int64)
        regs[rname] = (d, rows)
    etype = {v[:2]: k for k, v in _gmsh.GMSH_CELLS.items()}[(name, degree)]
    return X, cells, etype, regs, tdim


def _write_msh(path, X, cells, etype, regions, tdim):
    with _gmsh.session("write_msh") as gmsh:
        ftypes = {2: {1: 1, 2: 8}, 3: {("triangle", 1): 2, ("triangle", 2): 9, ("quadrilateral", 1): 3,
                                       ("quadrilateral", 2): 10}}
        name, degree, _ = _gmsh.GMSH_CELLS[etype]
        ftype = ftypes[2][degree] if tdim == 2 else \
            ftypes[3][("triangle" if name == "tetrahedron" else "quadrilateral", degree)]
        vol = gmsh.model.addDiscreteEntity(tdim)
        gmsh.model.mesh.addNodes(tdim, vol, (np.arange(len(X)) + 1).tolist(), X.ravel().tolist())
        gmsh.model.mesh.addElementsByType(vol, etype, [], (cells + 1).ravel().tolist())
        pg = gmsh.model.addPhysicalGroup(tdim, [vol])
        gmsh.model.setPhysicalName(tdim, pg, "domain")
        for rname, (d, rows) in regions.items():
            ent = gmsh.model.addDiscreteEntity(d)
            if len(rows):
                gmsh.model.mesh.addElementsByType(ent, etype if d == tdim else ftype, [], (rows + 1).ravel().tolist())
            pg = gmsh.model.addPhysicalGroup(d, [ent])
            gmsh.model.setPhysicalName(d, pg, rname)
        gmsh.option.setNumber("Mesh.SaveAll", 0)
        gmsh.write(str(path))
