"""Density filters and projection: design variables x → filtered ρ̃ → projected (physical) ρ̄.

All maps act on one value per cell (DG0) and come with their adjoint (the transposed Jacobian), so that
sensitivities with respect to the physical densities are chained back to the design variables:
:math:`\\partial J/\\partial x = (\\partial\\tilde\\rho/\\partial x)^T (\\partial\\bar\\rho/\\partial\\tilde\\rho)
\\,\\partial J/\\partial\\bar\\rho`.

``HelmholtzFilter``
    The PDE filter (Lazarov & Sigmund, IJNME 86, 765, 2011): :math:`-r^2\\Delta\\psi + \\psi = x` in
    :math:`\\Omega`, :math:`\\nabla\\psi\\cdot n = 0` on :math:`\\partial\\Omega`, solved for a continuous
    P1 field :math:`\\psi` and averaged per cell, :math:`\\tilde\\rho_e = |e|^{-1}\\int_e \\psi`. The matrix
    is factorized once. :math:`r = r_{min}/(2\\sqrt3)` matches a cone filter of radius :math:`r_{min}`.
``ConeFilter``
    The classic distance-weighted (cone) density filter of the 88-line code:
    :math:`\\tilde\\rho_e = \\sum_i H_{ei} v_i x_i / \\sum_i H_{ei} v_i`, :math:`H_{ei} = \\max(0, r_{min} -
    \\|c_e - c_i\\|)` on the cell centroids :math:`c` (cell volumes :math:`v` are 1 on a uniform grid).
``LinkedFilter``
    Design variables shared by groups of cells (periodic patterns such as the chambers of a PneuNet): the
    group mean :math:`\\hat x_e = |G(e)|^{-1}\\sum_{i \\in G(e)} x_i` enters the density filter, so every
    cell of a group gets the same design and the same sensitivity (the filter after it sees the whole domain:
    near the ends of a pattern the physical densities of the copies differ by what the filter reaches).
``Heaviside``
    The smoothed projection (Wang, Lazarov & Sigmund, SMO 43, 767, 2011)
    :math:`\\bar\\rho = \\frac{\\tanh(\\beta\\eta) + \\tanh(\\beta(\\tilde\\rho - \\eta))}{\\tanh(\\beta\\eta) +
    \\tanh(\\beta(1-\\eta))}`, with a continuation schedule doubling :math:`\\beta`.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import _dolfinx
from ..errors import ParameterError

__all__ = ["HelmholtzFilter", "ConeFilter", "IdentityFilter", "LinkedFilter", "Heaviside", "cell_centroids",
           "cell_volumes"]


def cell_centroids(domain):
    """Vertex-average centroids (n_cells, gdim) [m] of the local cells of a DOLFINx mesh."""
    tdim = domain.topology.dim
    n = domain.topology.index_map(tdim).size_local
    dofs = _dolfinx.geometry_dofs(domain, n)
    return domain.geometry.x[dofs, : domain.geometry.dim].mean(axis=1)


def cell_volumes(domain):
    """Cell measures (n_cells,) [m^2 or m^3] of the local cells, assembled as the DG0 vector of ∫ w dx."""
    import dolfinx.fem as fem
    import dolfinx.fem.petsc  # noqa: F401
    import ufl
    Q = _dolfinx.function_space(domain, "DG", 0)
    w = ufl.TestFunction(Q)
    vec = dolfinx.fem.petsc.assemble_vector(fem.form(w * ufl.dx(metadata={"quadrature_degree": 2})))
    n = domain.topology.index_map(domain.topology.dim).size_local
    out = vec.array[:n].copy()
    vec.destroy()
    return out


def _check_radius(radius):
    r = float(radius)
    if not np.isfinite(r) or r < 0:
        raise ParameterError(f"the filter radius must be a non-negative length [m], got {radius!r}")
    return r


class IdentityFilter:
    """No filtering: ρ̃ = x."""

    def apply(self, x):
        """Filtered densities."""
        return np.asarray(x, float).copy()

    def adjoint(self, g):
        """Transposed Jacobian times ``g``."""
        return np.asarray(g, float).copy()


class LinkedFilter:
    """Cells grouped by ``labels`` share one design: the group mean :math:`\\hat x = P x` of the design
    variables, then ``inner`` (a density filter or :class:`IdentityFilter`).

    :math:`P` averages over each group; it is symmetric, so the adjoint is :math:`P\\,` ``inner.adjoint``. An
    optimizer that starts from a linked design keeps it linked (every member of a group sees the same gradient
    and the same bounds).

    Parameters
    ----------
    inner : filter
        An object with ``apply``/``adjoint`` (the density filter applied after the averaging).
    labels : (n,) array of int
        Group of each cell; cells with equal labels share their design.
    """

    def __init__(self, inner, labels):
        labels = np.asarray(labels).ravel()
        _, groups, counts = np.unique(labels, return_inverse=True, return_counts=True)
        n = len(labels)
        self.inner, self.groups = inner, groups
        self.matrix = sp.csr_matrix((1.0 / counts[groups], (np.arange(n), groups)), shape=(n, len(counts))) @ \
            sp.csr_matrix((np.ones(n), (groups, np.arange(n))), shape=(len(counts), n))

    def apply(self, x):
        """Filtered densities of the group means."""
        return self.inner.apply(self.matrix @ np.asarray(x, float))

    def adjoint(self, g):
        """Transposed Jacobian times ``g``."""
        return self.matrix.T @ self.inner.adjoint(g)


class ConeFilter:
    """Cone (distance-weighted) density filter of radius ``rmin`` [m] on the cell centroids.

    Parameters
    ----------
    domain : dolfinx.mesh.Mesh or sorofem.mesh.Mesh
    rmin : float
        Radius [m]; cells whose centroids are closer than ``rmin`` are averaged with weight ``rmin - d``.
    weighted : bool
        Weight by cell volume (exact on non-uniform meshes; identical to the 88-line code on a uniform grid).
    """

    def __init__(self, domain, rmin, weighted=True):
        from scipy.spatial import cKDTree
        domain = getattr(domain, "dolfinx", domain)
        self.rmin = _check_radius(rmin)
        c = cell_centroids(domain)
        n = len(c)
        v = cell_volumes(domain) if weighted else np.ones(n)
        if self.rmin > 0:
            D = cKDTree(c).sparse_distance_matrix(cKDTree(c), self.rmin, output_type="coo_matrix")
            rows, cols, dist = D.row, D.col, D.data
            keep = dist < self.rmin
            rows, cols, w = rows[keep], cols[keep], self.rmin - dist[keep]
            rows = np.concatenate([rows, np.arange(n)])  # the diagonal (distance 0 is dropped by the tree)
            cols = np.concatenate([cols, np.arange(n)])
            w = np.concatenate([w, np.full(n, self.rmin)])
            H = sp.csr_matrix((w, (rows, cols)), shape=(n, n))
            H.sum_duplicates()
            H.data[:] = np.where(H.data > self.rmin, self.rmin, H.data)  # a duplicated diagonal stays rmin
        else:
            H = sp.identity(n, format="csr")
        Hv = H @ sp.diags(v)
        self.matrix = sp.csr_matrix(sp.diags(1.0 / np.asarray(Hv.sum(axis=1)).ravel()) @ Hv)
        self._T = self.matrix.T.tocsr()

    def apply(self, x):
        """Filtered densities ρ̃ = W x (rows of W sum to 1)."""
        return self.matrix @ np.asarray(x, float)

    def adjoint(self, g):
        """W^T g."""
        return self._T @ np.asarray(g, float)


class HelmholtzFilter:
    """PDE (Helmholtz) density filter with length ``radius`` [m], P1 field averaged per cell.

    Parameters
    ----------
    domain : dolfinx.mesh.Mesh or sorofem.mesh.Mesh
    radius : float
        The PDE length scale r [m] of :math:`-r^2\\Delta\\psi + \\psi = x`. Use :meth:`from_cone_radius` to
        give the radius of the equivalent cone filter, :math:`r = r_{min}/(2\\sqrt 3)`.

    Notes
    -----
    Three matrices are assembled once: the P1 matrix :math:`A = r^2 K + M`, the coupling :math:`B_{ie} =
    \\int_e \\phi_i` (P1 test, DG0 trial) and the cell volumes :math:`v`; the filter is
    :math:`\\tilde\\rho = V^{-1} B^T A^{-1} B x` and its adjoint :math:`B A^{-1} B^T V^{-1} g` (A symmetric).
    :math:`A` is factorized by SuperLU once.
    """

    def __init__(self, domain, radius):
        import dolfinx.fem as fem
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        domain = getattr(domain, "dolfinx", domain)
        self.radius = _check_radius(radius)
        dx = ufl.dx(metadata={"quadrature_degree": 2})
        V = _dolfinx.function_space(domain, "Lagrange", 1)
        Q = _dolfinx.function_space(domain, "DG", 0)
        p, q = ufl.TrialFunction(V), ufl.TestFunction(V)
        r2 = fem.Constant(domain, self.radius**2)
        A = self._scipy(fem.form((r2 * ufl.inner(ufl.grad(p), ufl.grad(q)) + p * q) * dx))
        B = self._scipy(fem.form(ufl.TrialFunction(Q) * q * dx))
        n = domain.topology.index_map(domain.topology.dim).size_local
        self.vol = np.asarray(B.sum(axis=0)).ravel()[:n]
        self._B = B.tocsr()
        self._BT = B.T.tocsr()
        self._lu = spla.splu(A.tocsc())

    @classmethod
    def from_cone_radius(cls, domain, rmin):
        """The Helmholtz filter equivalent to a cone filter of radius ``rmin`` [m]: r = rmin / (2 sqrt 3)."""
        return cls(domain, _check_radius(rmin) / (2 * np.sqrt(3.0)))

    @staticmethod
    def _scipy(form):
        import dolfinx.fem.petsc
        M = dolfinx.fem.petsc.assemble_matrix(form)
        M.assemble()
        indptr, indices, data = M.getValuesCSR()
        out = sp.csr_matrix((data.copy(), indices.copy(), indptr.copy()), shape=M.getSize())
        M.destroy()
        return out

    def apply(self, x):
        """Filtered densities (cell averages of the P1 solution)."""
        psi = self._lu.solve(self._B @ np.asarray(x, float))
        return (self._BT @ psi) / self.vol

    def adjoint(self, g):
        """Transposed Jacobian times ``g``."""
        return self._BT @ self._lu.solve(self._B @ (np.asarray(g, float) / self.vol))


class Heaviside:
    """Smoothed Heaviside projection with threshold ``eta`` and sharpness ``beta`` (continuation).

    Parameters
    ----------
    beta : float
        Initial sharpness (> 0).
    eta : float
        Threshold in (0, 1).
    beta_max : float
        Largest sharpness reached by :meth:`continuation`.
    every : int
        :meth:`continuation` doubles ``beta`` every ``every`` iterations (and when the design has converged).
    """

    def __init__(self, beta=1.0, eta=0.5, beta_max=32.0, every=40):
        if not beta > 0 or not 0 < eta < 1:
            raise ParameterError(f"Heaviside needs beta > 0 and 0 < eta < 1, got beta={beta!r}, eta={eta!r}")
        self.beta, self.eta, self.beta_max, self.every = float(beta), float(eta), float(beta_max), int(every)

    def apply(self, r):
        """Projected densities."""
        b, e = self.beta, self.eta
        return (np.tanh(b * e) + np.tanh(b * (r - e))) / (np.tanh(b * e) + np.tanh(b * (1 - e)))

    def derivative(self, r):
        """d(projected)/d(filtered), elementwise."""
        b, e = self.beta, self.eta
        return b * (1 - np.tanh(b * (r - e)) ** 2) / (np.tanh(b * e) + np.tanh(b * (1 - e)))

    def continuation(self, iteration, converged=False):
        """Double beta (up to ``beta_max``) every ``every`` iterations or on convergence; True if it changed."""
        if self.beta < self.beta_max and (converged or (iteration > 0 and iteration % self.every == 0)):
            self.beta = min(2 * self.beta, self.beta_max)
            return True
        return False
