"""A small numpy/scipy port of the classic 88-line topology-optimization code (reference for the tests).

Written from the published algorithm (Andreassen, Clausen, Schevenels, Lazarov & Sigmund, "Efficient
topology optimization in MATLAB using 88 lines of code", Struct. Multidisc. Optim. 43, 1-16, 2011): the MBB
half-beam on ``nelx`` x ``nely`` unit square Q4 elements (plane stress, E0 = 1, Emin = 1e-9, nu = 0.3),
unit load down at the top-left node, symmetry (u_x = 0) on the left edge, roller (u_y = 0) at the
bottom-right node, SIMP with penalty ``penal``, the cone filter of radius ``rmin`` on densities (ft = 2) or
sensitivities (ft = 1), and the optimality-criteria update with bisection (move 0.2) until the largest
change is below 0.01. Nodes are numbered column-wise from the top-left corner, as in the MATLAB code.
"""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def element_stiffness(nu=0.3):
    """The 8x8 Q4 plane-stress stiffness of a unit square with E = 1 (the 88-line code's KE)."""
    A11 = np.array([[12, 3, -6, -3], [3, 12, 3, 0], [-6, 3, 12, -3], [-3, 0, -3, 12]], float)
    A12 = np.array([[-6, -3, 0, 3], [-3, -6, -3, -6], [0, -3, -6, 3], [3, -6, 3, -6]], float)
    B11 = np.array([[-4, 3, -2, 9], [3, -4, -9, 4], [-2, -9, -4, -3], [9, 4, -3, -4]], float)
    B12 = np.array([[2, -3, 4, -9], [-3, 2, 9, -2], [4, 9, 2, 3], [-9, -2, 3, 2]], float)
    return 1 / (1 - nu**2) / 24 * (np.block([[A11, A12], [A12.T, A11]]) + nu * np.block([[B11, B12], [B12.T, B11]]))


def top88(nelx=60, nely=20, volfrac=0.5, penal=3.0, rmin=1.5, ft=2, max_iterations=1000, x0=None):
    """Run the 88-line code; returns dict(c, x (nely, nelx) column-major like MATLAB, iterations, history, c0)."""
    E0, Emin, nu = 1.0, 1e-9, 0.3
    KE = element_stiffness(nu)
    nodenrs = np.arange((1 + nelx) * (1 + nely)).reshape(1 + nelx, 1 + nely).T  # MATLAB reshape (column-major)
    edofVec = (2 * nodenrs[:-1, :-1] + 2).T.reshape(-1)  # 0-based x-dof of each element's lower-left node
    edofMat = edofVec[:, None] + np.array([0, 1, 2 * nely + 2, 2 * nely + 3, 2 * nely, 2 * nely + 1, -2, -1])
    iK = np.kron(edofMat, np.ones((8, 1), dtype=int)).reshape(-1)
    jK = np.kron(edofMat, np.ones((1, 8), dtype=int)).reshape(-1)
    ndof = 2 * (nelx + 1) * (nely + 1)
    F = np.zeros(ndof)
    F[1] = -1.0
    fixed = np.union1d(np.arange(0, 2 * (nely + 1), 2), [ndof - 1])
    free = np.setdiff1d(np.arange(ndof), fixed)
    # filter
    rows, cols, vals = [], [], []
    r = int(np.ceil(rmin)) - 1
    for i1 in range(nelx):
        for j1 in range(nely):
            e1 = i1 * nely + j1
            for i2 in range(max(i1 - r, 0), min(i1 + r + 1, nelx)):
                for j2 in range(max(j1 - r, 0), min(j1 + r + 1, nely)):
                    rows.append(e1)
                    cols.append(i2 * nely + j2)
                    vals.append(max(0.0, rmin - np.hypot(i1 - i2, j1 - j2)))
    H = sp.csr_matrix((vals, (rows, cols)), shape=(nelx * nely, nelx * nely))
    Hs = np.asarray(H.sum(axis=1)).ravel()
    x = np.full(nelx * nely, volfrac) if x0 is None else np.asarray(x0, float).copy()
    xPhys = x.copy() if ft == 1 else H @ x / Hs
    history = []
    change, loop = 1.0, 0
    while change > 0.01 and loop < max_iterations:
        loop += 1
        sK = (KE.reshape(-1)[None, :] * (Emin + xPhys[:, None] ** penal * (E0 - Emin))).reshape(-1)
        K = sp.csc_matrix((sK, (iK, jK)), shape=(ndof, ndof))
        K = (K + K.T) / 2
        U = np.zeros(ndof)
        U[free] = spla.spsolve(K[free][:, free].tocsc(), F[free])
        Ue = U[edofMat]
        ce = np.einsum("ij,jk,ik->i", Ue, KE, Ue)
        c = float(np.sum((Emin + xPhys**penal * (E0 - Emin)) * ce))
        history.append(c)
        dc = -penal * (E0 - Emin) * xPhys ** (penal - 1) * ce
        dv = np.ones(nelx * nely)
        if ft == 1:
            dc = H @ (x * dc) / Hs / np.maximum(1e-3, x)
        else:
            dc = H @ (dc / Hs)
            dv = H @ (dv / Hs)
        l1, l2, move = 0.0, 1e9, 0.2
        while (l2 - l1) / (l1 + l2) > 1e-3:
            lmid = 0.5 * (l2 + l1)
            xnew = np.maximum(0, np.maximum(x - move, np.minimum(1, np.minimum(x + move,
                                                                    x * np.sqrt(-dc / dv / lmid)))))
            xPhys = xnew.copy() if ft == 1 else H @ xnew / Hs
            if xPhys.sum() > volfrac * nelx * nely:
                l1 = lmid
            else:
                l2 = lmid
        change = float(np.max(np.abs(xnew - x)))
        x = xnew
    return {"c": history[-1], "c0": history[0], "iterations": loop, "x": xPhys.reshape(nelx, nely).T,
            "history": history}


if __name__ == "__main__":  # pragma: no cover
    import time
    t0 = time.perf_counter()
    out = top88()
    print(f"c = {out['c']:.4f} (c0 = {out['c0']:.4f}) after {out['iterations']} iterations, "
          f"{time.perf_counter() - t0:.2f} s")
