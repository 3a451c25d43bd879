"""The snapshot format: round trip, deformation gradients, atomicity and refusal of bad data."""
import h5py
import numpy as np
import pytest

from sorofem.errors import DataError
from sorofem.snapshots import SnapshotWriter, Snapshots, cell_deformation_gradients


def _square(n=4):
    """A unit square split into 2 n^2 triangles."""
    g = np.linspace(0, 1, n + 1)
    X = np.array([(x, y) for y in g for x in g])
    cells = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            cells += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return X, np.array(cells)


def test_round_trip(tmp_path):
    X, cells = _square()
    path = tmp_path / "case.h5"
    regions = {"left": ("facets", [[0, 5]]), "layer": ("cells", [0, 1])}
    with SnapshotWriter(path, X, cells, "triangle", regions=regions, cavities=["left"],
                        metadata={"material": "Ecoflex 00-30"}, time_kind="load") as w:
        for k in range(3):
            w.append(0.5 * k, 0.01 * k * X, inputs={"pressure/cavity_0": 1e3 * k},
                     cavity_volumes={"cavity_0": 1e-6 * (1 + k)}, reactions={"left": [k, -k]})
    s = Snapshots(path)
    assert s.n_steps == 3 and s.time_kind == "load" and s.cell_type == "triangle"
    np.testing.assert_array_equal(s.times, [0, 0.5, 1.0])
    np.testing.assert_array_equal(s.vertices, X)
    np.testing.assert_array_equal(s.displacement(2), 0.02 * X)
    assert s.displacement().shape == (3, len(X), 2)
    np.testing.assert_array_equal(s.inputs["pressure/cavity_0"], [0, 1e3, 2e3])
    np.testing.assert_array_equal(s.reactions["left"][2], [2, -2])
    assert s.cavities == ["left"] and s.regions["layer"][0] == "cells"
    assert s.metadata == {"material": "Ecoflex 00-30"}
    with pytest.raises(DataError, match="out of range"):
        s.displacement(3)


@pytest.mark.parametrize("dim", [2, 3])
def test_deformation_gradient_of_an_affine_field_is_exact(dim):
    rng = np.random.default_rng(0)
    A = np.eye(dim) + 0.3 * rng.standard_normal((dim, dim))
    if dim == 2:
        X, cells = _square()
        cell_type = "triangle"
    else:
        X = rng.random((20, 3))
        from scipy.spatial import Delaunay
        cells = Delaunay(X).simplices
        cell_type = "tetrahedron"
    u = X @ (A - np.eye(dim)).T + 0.1
    F = cell_deformation_gradients(X, cells, u, cell_type)
    np.testing.assert_allclose(F, np.broadcast_to(A, F.shape), atol=1e-10)


def test_deformation_gradient_on_quads_and_hexes():
    A = np.array([[1.2, 0.1], [-0.2, 0.9]])
    Xq = np.array([[0, 0], [2, 0], [0, 1], [2, 1]], float)  # DOLFINx ordering
    F = cell_deformation_gradients(Xq, [[0, 1, 2, 3]], Xq @ (A - np.eye(2)).T, "quadrilateral")
    np.testing.assert_allclose(F[0], A)
    Xh = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], float)
    B = np.eye(3) + 0.1 * np.arange(9).reshape(3, 3)
    F = cell_deformation_gradients(Xh, [list(range(8))], Xh @ (B - np.eye(3)).T, "hexahedron")
    np.testing.assert_allclose(F[0], B)


def test_failed_case_leaves_nothing(tmp_path):
    X, cells = _square(2)
    path = tmp_path / "case.h5"
    with pytest.raises(RuntimeError):
        with SnapshotWriter(path, X, cells, "triangle") as w:
            w.append(0.0, np.zeros_like(X))
            raise RuntimeError("solver crashed")
    assert list(tmp_path.iterdir()) == []


def test_nan_step_is_refused_and_file_stays_valid(tmp_path):
    X, cells = _square(2)
    path = tmp_path / "case.h5"
    with SnapshotWriter(path, X, cells, "triangle") as w:
        w.append(0.0, np.zeros_like(X), inputs={"p": 0.0})
        bad = np.zeros_like(X)
        bad[3, 1] = np.nan
        with pytest.raises(DataError, match="displacement holds NaN"):
            w.append(1.0, bad, inputs={"p": 1.0})
        with pytest.raises(DataError, match="inputs\\[p\\] holds NaN"):
            w.append(1.0, np.zeros_like(X), inputs={"p": float("nan")})
        with pytest.raises(DataError, match="differ from the first"):
            w.append(1.0, np.zeros_like(X), inputs={"q": 1.0})
        w.append(1.0, np.ones_like(X), inputs={"p": 1.0})
    s = Snapshots(path)
    assert s.n_steps == 2 and np.isfinite(s.displacement()).all()


@pytest.mark.parametrize("kwargs, match", [
    (dict(cell_type="pentagon"), "unknown cell type"),
    (dict(cells=np.array([[0, 1]])), "need 3 vertices"),
    (dict(cells=np.array([[0, 1, 99]])), "do not exist"),
    (dict(cavities=["cavity_0"]), "not among the regions"),
])
def test_bad_writer_input(tmp_path, kwargs, match):
    X, cells = _square(1)
    args = dict(vertices=X, cells=cells, cell_type="triangle")
    args.update(kwargs)
    with pytest.raises(DataError, match=match):
        SnapshotWriter(tmp_path / "c.h5", **args)


def test_reader_refuses_missing_foreign_and_newer_files(tmp_path):
    with pytest.raises(DataError, match="no snapshot file"):
        Snapshots(tmp_path / "none.h5")
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(DataError, match="not a readable HDF5"):
        Snapshots(tmp_path / "junk.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(DataError, match="is not a soro-snapshots file"):
        Snapshots(tmp_path / "other.h5")
    X, cells = _square(1)
    with SnapshotWriter(tmp_path / "new.h5", X, cells, "triangle") as w:
        w.append(0.0, np.zeros_like(X))
    with h5py.File(tmp_path / "new.h5", "a") as f:
        f.attrs["version"] = 99
    with pytest.raises(DataError, match="version 99"):
        Snapshots(tmp_path / "new.h5")
