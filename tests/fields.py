r"""Synthetic FEM fields of known strain, written as snapshot files: straight bars meshed with simplices and
mapped by constant-strain Cosserat rods (for the strain-recovery tests and the ``soro trade`` CLI test).

The cross-section point (y, z) at arc length X goes to :math:`p(X) + R(X)(0, y, z)` with
:math:`g(X) = \exp(X\hat\xi)`; lengths in m.
"""
import numpy as np
from scipy.linalg import expm

from sorofem.snapshots import SnapshotWriter

L, H = 0.1, 0.01


def hat(xi):
    X = np.zeros((4, 4))
    X[:3, :3] = [[0, -xi[2], xi[1]], [xi[2], 0, -xi[0]], [-xi[1], xi[0], 0]]
    X[:3, 3] = xi[3:]
    return X


def bar_mesh_2d(nx, ny):
    x, y = np.meshgrid(np.linspace(0, L, nx + 1), np.linspace(-H / 2, H / 2, ny + 1), indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel()])
    idx = np.arange(len(V)).reshape(nx + 1, ny + 1)
    cells = []
    for i in range(nx):
        for j in range(ny):
            a, b, c, d = idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]
            cells += [(a, b, c), (a, c, d)]
    return V, np.array(cells)


def bar_mesh_3d(nx, ny):
    g = np.linspace(-H / 2, H / 2, ny + 1)
    x, y, z = np.meshgrid(np.linspace(0, L, nx + 1), g, g, indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    idx = np.arange(len(V)).reshape(nx + 1, ny + 1, ny + 1)
    cells = []
    for i in range(nx):
        for j in range(ny):
            for k in range(ny):
                c = [idx[i + a, j + b, k + e] for a in (0, 1) for b in (0, 1) for e in (0, 1)]
                # six tetrahedra around the diagonal c[0]-c[7] of the hexahedron
                for p in ((1, 3), (3, 2), (2, 6), (6, 4), (4, 5), (5, 1)):
                    cells.append((c[0], c[p[0]], c[p[1]], c[7]))
    return V, np.array(cells)


def rod_field(V, xi):
    """Displacements that map the straight bar to the constant-strain rod exp(X xi^)."""
    X3 = np.column_stack([V, np.zeros(len(V))]) if V.shape[1] == 2 else V
    out = np.zeros_like(X3)
    for k, p in enumerate(X3):
        g = expm(hat(xi) * p[0])
        out[k] = g[:3, 3] + g[:3, :3] @ np.array([0.0, p[1], p[2]]) - p
    return out[:, :V.shape[1]]


def write(path, V, cells, cell_type, fields, inputs=None, volumes=None):
    with SnapshotWriter(path, V, cells, cell_type, time_kind="load") as w:
        for k, U in enumerate(fields):
            w.append(float(k), U, inputs={n: v[k] for n, v in (inputs or {}).items()},
                     cavity_volumes={n: v[k] for n, v in (volumes or {}).items()})
    return path
