"""Contact of the body with rigid obstacles given as signed distance functions (:mod:`sorofem.sdf`).

Node-to-obstacle penalty on the boundary nodes. With the current position :math:`x_i = X_i + u_i` of a boundary
node, its gap :math:`g_i = \\phi(x_i - c(t))` (``phi`` the obstacle's signed distance, ``c(t)`` its motion) and
the obstacle's outward normal :math:`n_i = \\nabla\\phi`, a penetrating node (:math:`g_i < 0`) is pushed out by

.. math::

    f_{n,i} = k A_i (-g_i), \\qquad F_i = f_{n,i}\\, n_i + f_{t,i}, \\qquad
    f_{t,i} = -\\mu f_{n,i} \\frac{s_i}{\\sqrt{|s_i|^2 + \\varepsilon^2}},

where :math:`A_i` is the node's share of the boundary area (the integral of its shape function over the
boundary; times :math:`2\\pi R` when axisymmetric; per unit depth in plane strain), :math:`k` [Pa/m] the
penalty stiffness, and :math:`s_i` the tangential slip of the node over the current step (regularized
Coulomb friction: the friction force reaches :math:`\\mu f_n` once the slip exceeds a few
:math:`\\varepsilon`). Penetration at a contact pressure :math:`p` is :math:`p/k`; the default
:math:`k = 100\\,E/h` (``E`` the stiffest material's Young's modulus, ``h`` the smallest boundary edge) keeps
it to 1 % of an element for a contact pressure of :math:`E`, far below it for soft-robot pressures. The
tangent of these forces (normal part, friction's dependence on normal force and slip) enters Newton's
matrix, so convergence stays quadratic; the obstacle's curvature is left out of it.

Use P1 elements (or 2D P2, also mixed: the forces act on the displacement field of the state): in 3D, the
corner functions of quadratic triangles integrate to zero over a face, so corner nodes would carry no contact
area.
"""
import numpy as np

from ..errors import ParameterError

__all__ = ["Contact"]


class Contact:
    """One obstacle in contact with the body; built by :meth:`sorofem.fem.Fem.add_contact`."""

    def __init__(self, obstacle, stiffness=None, friction=0.0, regularization=None, motion=None, name="contact"):
        if not (callable(obstacle) and hasattr(obstacle, "gradient") and hasattr(obstacle, "dim")):
            raise ParameterError("an obstacle must be a shape from sorofem.sdf (e.g. sdf.Line(...), sdf.Plane(...))")
        if friction < 0 or not np.isfinite(friction):
            raise ParameterError(f"friction must be >= 0, got {friction}")
        if stiffness is not None and not (np.isfinite(stiffness) and stiffness > 0):
            raise ParameterError(f"contact stiffness must be positive [Pa/m], got {stiffness}")
        self.obstacle, self.friction, self.name = obstacle, float(friction), name
        self._stiffness, self._regularization = stiffness, regularization
        self.motion = motion

    # ------------------------------------------------------------------------------------------ setup
    def setup(self, fem, W, wt, u_array, t0=0.0):
        """Find the boundary nodes, their areas and dofs; check that the body starts outside the obstacle."""
        import ufl
        import dolfinx.fem
        import dolfinx.fem.petsc
        import dolfinx.mesh
        from petsc4py import PETSc

        msh = fem.mesh.dolfinx
        gdim, fdim = msh.geometry.dim, msh.topology.dim - 1
        if self.obstacle.dim != gdim:
            raise ParameterError(f"a {self.obstacle.dim}D obstacle cannot touch a {gdim}D body")
        msh.topology.create_connectivity(fdim, msh.topology.dim)
        facets = dolfinx.mesh.exterior_facet_indices(msh.topology)
        Wu = W.sub(0) if fem.mixed_state else W          # the displacement (the first field of a mixed state)
        V0, _ = Wu.sub(0).collapse()
        maps = [np.asarray(Wu.sub(c).collapse()[1]) for c in range(gdim)]
        nodes = dolfinx.fem.locate_dofs_topological(V0, fdim, facets)
        nodes = nodes[nodes < V0.dofmap.index_map.size_local]
        v = ufl.TestFunction(V0)
        area = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(v * wt * ufl.ds(domain=msh)))
        area.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.area = area.getArray()[nodes].copy()
        area.destroy()
        self.X = V0.tabulate_dof_coordinates()[nodes, :gdim]
        self.dofs = np.column_stack([m[nodes] for m in maps])
        start = W.dofmap.index_map.local_range[0] * W.dofmap.index_map_bs
        self.global_dofs = self.dofs + start
        self.comm = msh.comm
        # penalty and regularization scales from the mesh and the materials
        h = msh.comm.allreduce(float(fem.mesh.quality.get("h_min", 0.0)) or np.inf, op=_op("MIN"))
        self.h = h if np.isfinite(h) else fem.size / 100
        E = max(mat.E for _, mat in fem.materials)
        self.k = float(self._stiffness or 100.0 * E / self.h)
        self.eps = float(self._regularization or 1e-3 * self.h)
        x = self.X + u_array[self.dofs]  # the current state (a model may be solved before contact is added)
        gap = self.gap(x, t0)[0]
        worst = msh.comm.allgather((float(gap.min()) if len(gap) else np.inf,
                                    x[np.argmin(gap)].tolist() if len(gap) else None))
        g_min, where = min(worst, key=lambda w: w[0])
        if g_min < -1e-6 * fem.size:
            raise ParameterError(f"the body starts inside obstacle {self.name!r}: a boundary point at "
                                 f"{np.round(where, 6).tolist()} m is {-g_min:.3g} m deep; move the obstacle "
                                 "or the body so that they only touch")
        self.x_prev = x
        return self

    def offset(self, t):
        if self.motion is None:
            return np.zeros(self.X.shape[1])
        c = np.asarray(self.motion(t), dtype=float)
        if c.shape != (self.X.shape[1],) or not np.all(np.isfinite(c)):
            raise ParameterError(f"obstacle motion must return a finite ({self.X.shape[1]},) offset, got {c}")
        return c

    def gap(self, x, t):
        """Gap [m] and obstacle normal at current positions ``x`` (n, gdim)."""
        p = x - self.offset(t)
        if not len(p):
            return np.zeros(0), np.zeros((0, x.shape[1]))
        g = np.asarray(self.obstacle(p), dtype=float)
        n = np.asarray(self.obstacle.gradient(p), dtype=float)
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return g, n / np.where(norm > 0, norm, 1.0)

    # ------------------------------------------------------------------------------------------ forces
    def _state(self, u_array, t):
        x = self.X + u_array[self.dofs]
        g, n = self.gap(x, t)
        active = g < 1e-9 * self.h  # touching nodes count: their normal stiffness holds a body set on the obstacle
        fn = self.k * self.area * np.maximum(-g, 0.0)
        s = x - self.x_prev
        s_t = s - np.einsum("ij,ij->i", s, n)[:, None] * n
        root = np.sqrt(np.einsum("ij,ij->i", s_t, s_t) + self.eps**2)
        h = s_t / root[:, None]
        return x, n, active, fn, h, root

    def forces(self, u_array, t):
        """Contact forces on the owned boundary nodes (n, gdim) [N] and their active mask."""
        _, n, active, fn, h, _ = self._state(u_array, t)
        F = fn[:, None] * n - self.friction * fn[:, None] * h
        return F, active

    def subtract(self, b_array, u_array, t):
        F, _ = self.forces(u_array, t)
        np.subtract.at(b_array, self.dofs, F)

    def add_tangent(self, A, u_array, t):
        """Add the derivative of the residual contribution -F with respect to the node positions."""
        from petsc4py import PETSc

        _, n, active, fn, h, root = self._state(u_array, t)
        d = n.shape[1]
        eye = np.eye(d)
        for i in np.flatnonzero(active):
            kA = self.k * self.area[i]
            block = kA * np.outer(n[i], n[i])
            if self.friction:
                P = eye - np.outer(n[i], n[i])
                Jh = (P - np.outer(h[i], h[i])) / root[i]
                # (a 1e-6 kA tangential term keeps a resting body's sliding mode regular before it is loaded)
                block += -self.friction * kA * np.outer(h[i], n[i]) + self.friction * fn[i] * Jh + 1e-6 * kA * P
            rows = self.global_dofs[i].astype(np.int32)
            A.setValues(rows, rows, block.ravel(), addv=PETSc.InsertMode.ADD_VALUES)

    def commit(self, u_array):
        """The step converged: slips of the next step are measured from here."""
        self.x_prev = self.X + u_array[self.dofs]

    def totals(self, u_array, t):
        """(force the obstacle exerts on the body [N], contact area [m^2]) summed over ranks."""
        F, _ = self.forces(u_array, t)
        loaded = np.linalg.norm(F, axis=1) > 0
        force = self.comm.allreduce(F.sum(axis=0) if len(F) else np.zeros(self.X.shape[1]), op=_op("SUM"))
        area = self.comm.allreduce(float(self.area[loaded].sum()), op=_op("SUM"))
        return force, area


def _op(name):
    from mpi4py import MPI
    return getattr(MPI, name)
