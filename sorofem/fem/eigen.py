"""Eigen-analysis about an equilibrium with SLEPc: vibration modes and the buckling indicator.

At the current state :math:`u` the tangent stiffness :math:`K = \\partial R/\\partial u` and the mass
:math:`M = \\int \\rho\\, \\delta u \\cdot v\\, w\\, dX` define :math:`K \\phi = \\lambda M \\phi`, with
:math:`\\lambda = \\omega^2` [1/s^2]. About an unloaded state these are the small-vibration modes (frequencies
:math:`f = \\sqrt{\\lambda}/2\\pi`); along a load path the lowest :math:`\\lambda` crossing zero marks a loss
of stability (buckling or a limit point). Follower pressures make :math:`K` non-symmetric: the problem is then
solved as non-Hermitian and the real parts are reported. Dirichlet rows carry 1 in :math:`K` and 0 in
:math:`M`, so constrained dofs map to infinite eigenvalues, far from the shift-and-invert target.

In the mixed formulation (and in plane stress) the state holds a second field without inertia, the pressure
(the thickness strain): :math:`M` is zero on its rows, so the problem is
:math:`\\begin{bmatrix} K_{uu} & B^T \\\\ B & -C \\end{bmatrix} \\begin{bmatrix}\\phi \\\\ q\\end{bmatrix} =
\\lambda \\begin{bmatrix} M_{uu} & 0 \\\\ 0 & 0\\end{bmatrix} \\begin{bmatrix}\\phi \\\\ q\\end{bmatrix}`: the second
field is condensed out exactly (:math:`q = C^{-1} B \\phi`) and its rows only add infinite eigenvalues. The
stiffness :math:`K_{uu} + B^T C^{-1} B` seen by the displacement is then free of volumetric locking.
"""
import numpy as np

from .. import _dolfinx
from ..errors import ConvergenceError, ParameterError

__all__ = ["Modes", "eigenmodes"]


class Modes:
    """Eigenpairs of :math:`K \\phi = \\lambda M \\phi`, sorted by real part.

    Attributes
    ----------
    eigenvalues : (n,) array [1/s^2] (real parts)
    frequencies : (n,) array [Hz], :math:`\\sqrt{\\lambda}/2\\pi`, NaN where :math:`\\lambda < 0` (unstable)
    shapes : (n, n_vertices, gdim) array, mode shapes at the vertices, max-norm 1 (rank 0 only)
    functions : list of dolfinx Functions (the modes on the FEM space)
    """

    def __init__(self, eigenvalues, shapes, functions):
        self.eigenvalues = np.asarray(eigenvalues)
        with np.errstate(invalid="ignore"):
            self.frequencies = np.where(self.eigenvalues >= 0, np.sqrt(np.abs(self.eigenvalues)) / (2 * np.pi), np.nan)
        self.shapes = shapes
        self.functions = functions

    def __len__(self):
        return len(self.eigenvalues)


def eigenmodes(fem, n=6, shift=0.0, tol=1e-10):
    """The ``n`` eigenpairs of ``fem`` (a :class:`sorofem.fem.Fem`) nearest to ``shift`` [1/s^2] about its
    current state (after :meth:`Fem.solve`, or the reference state)."""
    import ufl
    import dolfinx.fem
    import dolfinx.fem.petsc
    from slepc4py import SLEPc

    if int(n) < 1:
        raise ParameterError(f"n must be >= 1, got {n}")
    b = fem.forms
    W, kin = b.space, b.kinematics
    u, v = ufl.TrialFunction(W), ufl.TestFunction(W)
    if fem.mixed_state:  # the displacement part; the second field carries no inertia
        u, v = ufl.split(u)[0], ufl.split(v)[0]
    md = {"quadrature_degree": fem.quadrature_degree}
    dx = ufl.Measure("dx", domain=fem.mesh.dolfinx, subdomain_data=b.cell_tags, metadata=md)
    mass = sum(mat.density * ufl.dot(u, v) * kin.weight * dx(k) for k, (_, mat) in enumerate(fem.materials))
    K = dolfinx.fem.petsc.assemble_matrix(b.jacobian, bcs=list(b.bcs), diagonal=1.0)
    K.assemble()
    M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(mass), bcs=list(b.bcs), diagonal=0.0)
    M.assemble()
    symmetric = not fem.pressure_regions
    eps = SLEPc.EPS().create(fem.mesh.comm)
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP if symmetric else SLEPc.EPS.ProblemType.GNHEP)
    eps.setDimensions(int(n))
    eps.setTolerances(tol, 1000)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
    eps.setTarget(float(shift))
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    st.setShift(float(shift))
    ksp = st.getKSP()
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    try:
        eps.solve()
    except Exception as e:  # noqa: BLE001 - PETSc errors carry no useful type
        raise ConvergenceError(f"the eigensolver failed ({e}); if the stiffness is singular at the target "
                               f"{shift}, pass a small shift (e.g. shift=-1.0)") from e
    nconv = eps.getConverged()
    if nconv < n:
        raise ConvergenceError(f"only {nconv} of {n} eigenpairs converged; ask for fewer or move the shift")
    vr, vi = K.createVecs()
    pairs = []
    for i in range(nconv):
        lam = eps.getEigenpair(i, vr, vi)
        f = dolfinx.fem.Function(W, name=f"mode_{i}")
        vr.copy(_dolfinx.petsc_vec(f))
        f.x.scatter_forward()
        pairs.append((float(np.real(lam)), f))
    pairs.sort(key=lambda p: p[0])
    pairs = pairs[:n]
    shapes = []
    for _, f in pairs:
        b.vertex_displacement.interpolate(f.sub(0).collapse() if fem.mixed_state else f)
        s = b.gatherer.gather_function(b.vertex_displacement)
        if s is not None:
            s = s / max(np.abs(s).max(), 1e-300)
        shapes.append(s)
    for obj in (eps, K, M, vr, vi):
        obj.destroy()
    return Modes([p[0] for p in pairs], None if shapes[0] is None else np.array(shapes), [p[1] for p in pairs])
