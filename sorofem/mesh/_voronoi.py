"""Polygonal (Voronoi) meshes of a 2D signed-distance domain by Lloyd's iteration, after PolyMesher (Talischi,
Paulino, Pereira, Menezes, Struct. Multidisc. Optim. 45, 309, 2012) and the seed paper's Fig. 5.

Algorithm
---------
1. ``n`` seeds :math:`p_i` drawn uniformly inside the domain :math:`\\Omega = \\{x : d(x) < 0\\}` (rejection
   sampling in the bounding box; ``seed`` fixes the random stream).
2. Every seed closer to the boundary than :math:`\\alpha = c\\sqrt{|\\Omega|/n}` is mirrored across the tangent
   line of the boundary at the boundary points near it: the closest point (:meth:`SDF.project`) and the
   closest points of the probes :math:`p_i \\pm \\alpha e_k` that fall outside (so a seed near a convex corner
   is mirrored across both sides). A mirror image is kept when it lies outside, :math:`d(r) > 0`, and the
   tangent line is a side, not a chord: the foot of the seed on it lies on the boundary (a tangent line further
   round a curved boundary would cut into the domain). The
   Voronoi diagram of seeds and images then has, on a straight side, the side itself as the common edge of a
   seed's cell and its image's; on a curved side, its tangent line: the cells tile a polygon whose distance to
   the boundary is :math:`O(h^2 \\kappa)` (:math:`h` the cell size, :math:`\\kappa` the curvature).
3. Lloyd: every seed moves to the centroid :math:`c_i` of its cell (a seed whose centroid falls outside is
   put back on the boundary), and the reflections are redone. This descends the centroidal Voronoi energy

   .. math:: E = \\sum_i \\int_{V_i} |x - p_i|^2\\, dA = \\sum_i \\left(J_i + A_i |c_i - p_i|^2\\right),

   (:math:`A_i`, :math:`J_i` area and polar moment of cell :math:`V_i` about its centroid), which is recorded
   per iteration (``energy``) and reaches a centroidal Voronoi tessellation: cells of nearly equal size and
   regular shape.

How the polygons enter DOLFINx: DOLFINx has no polygonal cells, so :meth:`PolyMesh.to_mesh` sub-triangulates
every (convex) cell as a fan from its centroid, one extra node per cell, and hands the triangles to
:meth:`Mesh.from_arrays`; a linear element on that mesh passes the patch test (``tests/sorofem/
test_voronoi.py``). The polygons themselves are for drawing (:meth:`PolyMesh.plot`) and for codes with
polygonal elements.

Pure numpy + scipy (``scipy.spatial.Voronoi``); DOLFINx only in :meth:`PolyMesh.to_mesh`.
"""
import math

import numpy as np

from ..errors import GeometryError, ParameterError

__all__ = ["PolyMesh"]


def _polygon_moments(xy):
    """Area, centroid and polar moment about the centroid of a polygon (vertices in counter-clockwise order)."""
    x, y = xy[:, 0], xy[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    cx = ((x + xn) * cross).sum() / (6 * area)
    cy = ((y + yn) * cross).sum() / (6 * area)
    ixx = ((y * y + y * yn + yn * yn) * cross).sum() / 12   # about the origin
    iyy = ((x * x + x * xn + xn * xn) * cross).sum() / 12
    return area, np.array([cx, cy]), ixx + iyy - area * (cx * cx + cy * cy)


def _counter_clockwise(xy):
    c = xy.mean(axis=0)
    order = np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]))
    return order


class PolyMesh:
    """A Voronoi polygon mesh of a 2D domain: ``vertices`` (m, 2) [m], ``polygons`` (list of vertex-index arrays,
    counter-clockwise), ``seeds`` (n, 2) [m] and ``energy`` (the centroidal Voronoi energy [m^4] before each Lloyd
    step and at the end). Make one with :meth:`from_sdf`."""

    def __init__(self, vertices, polygons, seeds, energy, domain):
        self.vertices, self.polygons, self.seeds = vertices, polygons, seeds
        self.energy = np.asarray(energy, dtype=float)
        self.domain = domain

    # -------------------------------------------------------------------------------------------- building
    @classmethod
    def from_sdf(cls, shape, n, iterations=50, seed=0, reflect=1.5, tol=1e-4):
        """Lloyd's iteration on ``n`` seeds in the 2D domain ``shape`` (a :class:`sorofem.sdf.SDF`).

        Parameters
        ----------
        shape : SDF
            The domain, negative inside [m].
        n : int
            Number of polygons.
        iterations : int
            Largest number of Lloyd steps.
        seed : int
            Seed of the random initial seeds.
        reflect : float
            c in the reflection band :math:`\\alpha = c \\sqrt{|\\Omega|/n}`.
        tol : float
            Stop when the largest seed move is below ``tol`` times the cell size :math:`\\sqrt{|\\Omega|/n}`.
        """
        if int(n) < 3:
            raise ParameterError(f"a polygon mesh needs n >= 3 seeds, got {n}")
        if int(iterations) < 0 or not reflect > 0:
            raise ParameterError(f"iterations must be >= 0 and reflect > 0, got {iterations} and {reflect}")
        lo, hi = shape.bounds
        if lo.shape != (2,) or not np.all(np.isfinite(np.r_[lo, hi])):
            raise GeometryError("PolyMesh.from_sdf needs a bounded 2D shape")
        rng = np.random.default_rng(seed)
        p = cls._sample(shape, int(n), lo, hi, rng)
        area = float(shape.area)
        h = math.sqrt(area / int(n))
        energy = []
        for _ in range(int(iterations)):
            cells = cls._cells(shape, p, reflect * h, lo, hi)
            e, c = cls._energy(cells, p)
            energy.append(e)
            outside = shape(c) > 0
            if np.any(outside):   # a centroid off a concave boundary: back onto it
                c[outside] = shape.project(c[outside])[0]
            move = float(np.max(np.linalg.norm(c - p, axis=1)))
            p = c
            if move < tol * h:
                break
        cells = cls._cells(shape, p, reflect * h, lo, hi)
        energy.append(cls._energy(cells, p)[0])
        vertices, polygons = cls._merge(cells, 1e-9 * h)
        return cls(vertices, polygons, p, energy, shape)

    @staticmethod
    def _energy(cells, p):
        """The centroidal Voronoi energy of the seeds ``p`` with their ``cells``, and the cells' centroids."""
        e, c = 0.0, np.empty_like(p)
        for i, xy in enumerate(cells):
            a, c[i], j = _polygon_moments(xy)
            e += j + a * float(np.sum((c[i] - p[i]) ** 2))
        return e, c

    @staticmethod
    def _sample(shape, n, lo, hi, rng):
        pts = np.empty((0, 2))
        while len(pts) < n:
            cand = lo + (hi - lo) * rng.random((4 * n, 2))
            pts = np.vstack([pts, cand[shape(cand) < 0]])
        return pts[:n]

    @staticmethod
    def _reflections(shape, p, alpha):
        """Mirror images of the seeds near the boundary across the tangent lines at the boundary points near
        them (see the module docstring)."""
        d = shape(p)
        near = np.flatnonzero(np.abs(d) < alpha)
        q = p[near]
        out = []
        for offset in ((0.0, 0.0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            probe = q + alpha * np.asarray(offset, dtype=float)
            use = np.ones(len(q), bool) if offset == (0.0, 0.0) else shape(probe) > 0
            if not use.any():
                continue
            b, _ = shape.project(probe[use])          # a boundary point near the seed
            nrm = shape.gradient(b)                   # its outward normal
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
            s = q[use]
            h = np.einsum("ij,ij->i", s - b, nrm)[:, None]
            r = s - 2 * h * nrm
            # a side, not a chord: the foot of the seed on the tangent line is on the boundary (true for the
            # closest point and for the straight sides of a corner; a tangent line further round a curved
            # boundary cuts into the domain)
            side = shape(s - h * nrm) > -1e-4 * alpha
            out.append(r[side & (shape(r) > 0)])
        if not out:
            return np.empty((0, 2))
        r = np.vstack(out)
        # the same side found from several probes: one image
        key = np.round(r / (1e-6 * alpha)).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        return r[np.sort(first)]

    @classmethod
    def _cells(cls, shape, p, alpha, lo, hi):
        """The Voronoi cells of the seeds ``p`` (arrays of counter-clockwise vertices), with the mirror images and
        a far box closing the diagram."""
        from scipy.spatial import Voronoi

        r = cls._reflections(shape, p, alpha)
        span = float(np.max(hi - lo))
        mid = 0.5 * (lo + hi)
        far = mid + 10 * span * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
        vor = Voronoi(np.vstack([p, r, far]))
        cells = []
        for i in range(len(p)):
            region = vor.regions[vor.point_region[i]]
            if -1 in region or len(region) < 3:
                raise GeometryError("a Voronoi cell of the polygon mesh is unbounded: the boundary reflections "
                                    "missed a side; use more seeds or a larger reflect=")
            xy = vor.vertices[region]
            cells.append(xy[_counter_clockwise(xy)])
        return cells

    @staticmethod
    def _merge(cells, tol):
        """Shared vertices of the cells (merged within ``tol``) and the cells as index arrays."""
        allv = np.vstack(cells)
        key = np.round(allv / tol).astype(np.int64)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        vertices = allv[first]
        polygons, k = [], 0
        for xy in cells:
            idx = inverse.reshape(-1)[k:k + len(xy)]
            k += len(xy)
            polygons.append(idx[idx != np.roll(idx, 1)])   # vertices closer than tol merged
        return vertices, polygons

    # -------------------------------------------------------------------------------------------- queries
    @property
    def areas(self):
        """Area of every polygon [m^2]."""
        return np.array([_polygon_moments(self.vertices[c])[0] for c in self.polygons])

    @property
    def centroids(self):
        """Centroid of every polygon [m], (n, 2)."""
        return np.array([_polygon_moments(self.vertices[c])[1] for c in self.polygons])

    def triangulate(self):
        """Fan sub-triangulation: every polygon split into triangles from its centroid (one extra node per
        polygon). Returns ``points`` (m + n, 2) [m] and ``triangles`` (k, 3), counter-clockwise."""
        cent = self.centroids
        base = len(self.vertices)
        tris = []
        for i, c in enumerate(self.polygons):
            tris.append(np.column_stack([c, np.roll(c, -1), np.full(len(c), base + i)]))
        return np.vstack([self.vertices, cent]), np.vstack(tris)

    def to_mesh(self, comm=None):
        """The fan sub-triangulation as a :class:`sorofem.mesh.Mesh` (linear triangles, regions found as for
        :meth:`Mesh.from_arrays`)."""
        from ._core import Mesh

        points, triangles = self.triangulate()
        return Mesh.from_arrays(points, triangles, comm=comm)

    def plot(self, ax=None, color=None, linewidth=0.5, seeds=False):
        """Draw the polygons (coloured by ``color``, one value per polygon, if given) on a matplotlib axis [mm]."""
        import matplotlib.pyplot as plt
        from matplotlib.collections import PolyCollection

        if ax is None:
            ax = plt.gca()
        polys = [self.vertices[c] * 1e3 for c in self.polygons]
        coll = PolyCollection(polys, edgecolors="k", linewidths=linewidth,
                              facecolors="none" if color is None else None, cmap="viridis")
        if color is not None:
            coll.set_array(np.asarray(color))
        ax.add_collection(coll)
        if seeds:
            ax.plot(self.seeds[:, 0] * 1e3, self.seeds[:, 1] * 1e3, ".", ms=2, color="C3")
        ax.autoscale_view()
        ax.set_aspect("equal")
        return coll
