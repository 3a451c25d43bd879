"""Tendons: a cable under tension routed through anchor points of the body.

The cable enters the body at ``points[0]``, runs (frictionless, straight between anchors) through the
guides ``points[1:-1]`` and is tied at ``points[-1]``. With current anchor positions :math:`x_k` and unit
vectors :math:`e_{k,j} = (x_j - x_k)/\\|x_j - x_k\\|`, tension :math:`T` puts the forces

.. math::

    f_0 = T (e_{0,1} + d), \\qquad f_k = T (e_{k,k-1} + e_{k,k+1}) \\; (0 < k < K), \\qquad f_K = T e_{K,K-1}

on the body, where :math:`d` is the direction in which the cable is pulled at the entry (default: straight
back along the first segment in the reference configuration, so :math:`f_0` starts at zero). The forces
follow the deformation, and their derivative enters the tangent: a segment from anchor :math:`k` to
:math:`j` with length :math:`\\ell` contributes :math:`\\partial e_{k,j}/\\partial x_j = (I - e e^T)/\\ell`.
Anchors snap to the nearest mesh vertex.
"""
import numpy as np

from ..errors import ParameterError

__all__ = ["Tendon"]


class Tendon:
    """A tendon on a :class:`sorofem.fem.Fem`; built by :meth:`Fem.add_tendon`."""

    def __init__(self, points, tension, pull_direction=None):
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or len(pts) < 2:
            raise ParameterError(f"a tendon needs at least two anchor points as an (K, dim) array, got shape {pts.shape}")
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if np.any(seg <= 0):
            raise ParameterError("consecutive tendon anchors must be distinct points")
        self.points = pts
        self.tension = tension
        d = -(pts[1] - pts[0]) / seg[0] if pull_direction is None else np.asarray(pull_direction, dtype=float)
        if d.shape != pts[0].shape or not np.isclose(np.linalg.norm(d), 1.0):
            raise ParameterError(f"pull_direction must be a unit vector of dimension {pts.shape[1]}, got {d}")
        self.pull = d

    def setup(self, msh, Wu, owned, bcs=()):
        """Snap anchors to vertices and find their displacement dofs (owned ones on this rank, else -1)."""
        import dolfinx.fem
        from mpi4py import MPI

        gdim = msh.geometry.dim
        if self.points.shape[1] != gdim:
            raise ParameterError(f"tendon points must be {gdim}D, got {self.points.shape[1]}D")
        X = msh.geometry.x[:, :gdim]
        comm = msh.comm
        snapped = []
        for p in self.points:
            dist = np.linalg.norm(X - p, axis=1)
            i = int(np.argmin(dist)) if len(dist) else -1
            best = comm.allreduce((dist[i] if i >= 0 else np.inf, comm.rank), op=MPI.MINLOC)
            q = comm.bcast(X[i] if comm.rank == best[1] else None, root=best[1])
            snapped.append(q)
        self.X = np.array(snapped)
        tol = 1e-10 * max(float(np.ptp(X, axis=0).max()) if len(X) else 0.0, 1e-12)
        self.tol = comm.allreduce(tol, op=MPI.MAX)
        self.dofs = -np.ones((len(self.X), gdim), dtype=np.int64)
        for c in range(gdim):
            sub = Wu.sub(c)
            Vc, _ = sub.collapse()
            for k, q in enumerate(self.X):
                pairs = dolfinx.fem.locate_dofs_geometrical(
                    (sub, Vc), lambda x, q=q: np.linalg.norm(x[:gdim].T - q, axis=1) < self.tol)
                mine = [d for d in pairs[0] if d < owned] if len(pairs[0]) else []
                if mine:
                    self.dofs[k, c] = mine[0]
        found = comm.allreduce((self.dofs >= 0).astype(int), op=MPI.SUM)
        if np.any(found != 1):
            raise ParameterError("a tendon anchor could not be matched to exactly one vertex dof; move it to a "
                                 "vertex of the mesh")
        # global dof numbers, and which of them carry Dirichlet conditions (their rows and columns are skipped)
        constrained = np.unique(np.concatenate([bc.dof_indices()[0] for bc in bcs] or [np.zeros(0, int)]))
        start = Wu.dofmap.index_map.local_range[0] * Wu.dofmap.index_map_bs
        mine = self.dofs >= 0
        self.global_dofs = comm.allreduce(np.where(mine, self.dofs + start, 0), op=MPI.SUM)
        self.fixed = comm.allreduce((mine & np.isin(self.dofs, constrained)).astype(int), op=MPI.SUM).astype(bool)
        self.comm = comm
        return self

    def _positions(self, x_array):
        from mpi4py import MPI

        u = np.zeros(self.X.shape)
        mine = self.dofs >= 0
        u[mine] = x_array[self.dofs[mine]]
        return self.X + self.comm.allreduce(u, op=MPI.SUM)

    def forces(self, x_array, t):
        """Anchor forces (K, gdim) [N] at displacement dof values ``x_array`` and load parameter ``t``."""
        x = self._positions(x_array)
        T = float(self.tension(t))
        seg = np.diff(x, axis=0)
        length = np.linalg.norm(seg, axis=1)
        if np.any(length <= 1e-12 * np.linalg.norm(self.X[-1] - self.X[0])):
            raise ParameterError("two tendon anchors met: the tendon is not defined")
        e = seg / length[:, None]  # e[k] points from anchor k to anchor k+1
        f = np.zeros_like(x)
        f[:-1] += T * e
        f[1:] -= T * e
        f[0] += T * self.pull
        return f

    def add_tangent(self, A, x_array, t):
        """Add :math:`-\\partial f/\\partial x` to the (unassembled) PETSc matrix ``A`` (rank 0 inserts all)."""
        from petsc4py import PETSc

        x = self._positions(x_array)
        if self.comm.rank != 0:
            return
        T = float(self.tension(t))
        d = x.shape[1]
        for k in range(len(x) - 1):
            seg = x[k + 1] - x[k]
            ell = np.linalg.norm(seg)
            e = seg / ell
            G = T * (np.eye(d) - np.outer(e, e)) / ell  # d(T e)/d x_{k+1}; d(T e)/d x_k = -G
            # residual r = -f: r_k = -T e - ..., r_{k+1} = +T e - ...
            for i, si in ((k, -1.0), (k + 1, 1.0)):
                for j, sj in ((k + 1, 1.0), (k, -1.0)):
                    block = si * sj * G
                    for a in range(d):
                        if self.fixed[i, a]:
                            continue
                        for b in range(d):
                            if not self.fixed[j, b]:
                                A.setValue(int(self.global_dofs[i, a]), int(self.global_dofs[j, b]), block[a, b],
                                           addv=PETSc.InsertMode.ADD_VALUES)

    def subtract(self, b_array, x_array, t):
        """Subtract the (external) tendon forces from an owned residual array."""
        f = self.forces(x_array, t)
        mine = self.dofs >= 0
        b_array[self.dofs[mine]] -= f[mine]
