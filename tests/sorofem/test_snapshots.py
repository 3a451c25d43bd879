"""The snapshot format: round trip, deformation gradients, atomicity, refusal of bad data, checksums, every kind
of damaged file (a DataError naming the file and the dataset) and a full disk."""
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from sorofem.errors import DataError
from sorofem.snapshots import (VERSION, SnapshotWriter, Snapshots, cell_deformation_gradients, input_name,
                               parse_input_name)


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


# ---------------------------------------------------------------------------------------------- damaged files
def _valid(path, steps=3):
    """A small valid file: 4x4 square, a facet and a cell region, a cavity, inputs and reactions per step."""
    X, cells = _square()
    regions = {"left": ("facets", [[0, 5]]), "layer": ("cells", [0, 1])}
    with SnapshotWriter(path, X, cells, "triangle", regions=regions, cavities=["left"]) as w:
        for k in range(steps):
            w.append(float(k), 0.01 * k * X, inputs={"pressure/cavity_0": 1e3 * k}, reactions={"left": [k, -k]},
                     cell_fields={"von_mises": np.full(len(cells), float(k))})
    return path


def test_every_dataset_carries_a_fletcher32_checksum(tmp_path):
    path = _valid(tmp_path / "case.h5")
    names = []
    with h5py.File(path, "r") as f:
        f.visititems(lambda k, d: names.append((k, d.fletcher32)) if isinstance(d, h5py.Dataset) else None)
    assert len(names) == 9 and all(ok for _, ok in names), names


def _edit(fn):
    def edit(path):
        with h5py.File(path, "r+") as f:
            fn(f)
    return edit


def _replace(name, data, **attrs):
    def fn(f):
        old = dict(f[name].attrs)
        del f[name]
        d = f.create_dataset(name, data=data)
        d.attrs.update({**old, **attrs})
    return _edit(fn)


# (how the file is damaged, what the message names besides the file)
DAMAGED = {
    "missing cells": (_edit(lambda f: f["mesh"].__delitem__("cells")), "mesh/cells: missing"),
    "missing displacement": (_edit(lambda f: f["steps"].__delitem__("displacement")), "steps/displacement: missing"),
    "time shorter than displacement": (_replace("steps/time", [0.0, 1.0]),
                                       r"steps/displacement: shape \(3, 25, 2\), expected .* = \(2, 25, 2\)"),
    "negative cell index": (_replace("mesh/cells", np.where(np.arange(96).reshape(32, 3) == 7, -1,
                                                            _square()[1])),
                            r"mesh/cells: vertex index -1 out of range \[0, 25\)"),
    "cell index past the vertices": (_replace("mesh/cells", _square()[1] + 1), "mesh/cells: vertex index 25 out"),
    "region cell out of range": (_replace("mesh/regions/layer", [0, 32]), "mesh/regions/layer: cell index 32"),
    "region facet negative": (_replace("mesh/regions/left", [[0, -3]]), "mesh/regions/left: vertex index -3"),
    "unknown cell type": (_edit(lambda f: f["mesh/cells"].attrs.__setitem__("cell_type", "pentagon")),
                          "mesh/cells: unknown cell_type 'pentagon'"),
    "cell type missing": (_edit(lambda f: f["mesh/cells"].attrs.__delitem__("cell_type")),
                          "mesh/cells: attribute 'cell_type' missing"),
    "NaN time": (_replace("steps/time", [0.0, np.nan, 2.0]), "steps/time at step 1: holds NaN"),
    "infinite input": (_replace("steps/inputs/pressure/cavity_0", [0.0, 1e3, np.inf]),
                       "steps/inputs/pressure/cavity_0 at step 2: holds NaN or infinite"),
    "input of another length": (_replace("steps/inputs/pressure/cavity_0", [0.0, 1e3]),
                                r"steps/inputs/pressure/cavity_0: shape \(2,\), expected \(3,\)"),
    "reaction of the wrong width": (_replace("steps/reaction/left", np.zeros((3, 3))),
                                    r"steps/reaction/left: shape \(3, 3\), expected \(3, 2\)"),
    "cell field of the wrong length": (_replace("steps/cell_field/von_mises", np.zeros((3, 5))),
                                       r"steps/cell_field/von_mises: shape \(3, 5\), expected \(3, 32\)"),
    "NaN vertex": (_replace("mesh/vertices", np.where(np.arange(50).reshape(25, 2) == 9, np.nan, _square()[0])),
                   "mesh/vertices: holds NaN"),
    "vertices of 4 coordinates": (_replace("mesh/vertices", np.zeros((25, 4))), r"mesh/vertices: shape \(25, 4\)"),
    "cells as floats": (_replace("mesh/cells", _square()[1].astype(float)), "mesh/cells: has type float64"),
    "a group instead of a dataset": (_edit(lambda f: (f["steps"].__delitem__("time"),
                                                      f["steps"].create_group("time"))),
                                     "steps/time: is a group, not a dataset"),
    "metadata not JSON": (_edit(lambda f: f.attrs.__setitem__("metadata", "{oops")), "metadata: not valid JSON"),
    "version not a number": (_edit(lambda f: f.attrs.__setitem__("version", "one")), "attribute 'version' is 'one'"),
    "cavity not a region": (_edit(lambda f: f["mesh"].attrs.__setitem__("cavities", '["nope"]')),
                            r"cavities \['nope'\] are not among the regions"),
    "time kind unknown": (_edit(lambda f: f["steps/time"].attrs.__setitem__("kind", "hours")),
                          "steps/time: kind 'hours'"),
}


@pytest.mark.parametrize("name", sorted(DAMAGED))
def test_every_kind_of_damage_is_a_data_error_naming_file_and_dataset(tmp_path, name):
    damage, match = DAMAGED[name]
    path = _valid(tmp_path / "case.h5")
    damage(path)
    with pytest.raises(DataError, match=match) as err:
        Snapshots(path).displacement()
    assert str(path) in str(err.value)


def test_non_finite_displacement_names_the_step(tmp_path):
    path = _valid(tmp_path / "case.h5")
    with h5py.File(path, "r+") as f:
        f["steps/displacement"][2, 4, 1] = np.inf   # rewritten with a valid checksum: only the value is wrong
    snap = Snapshots(path)
    snap.displacement(1)
    for call in (lambda: snap.displacement(2), snap.displacement):
        with pytest.raises(DataError, match=f"{path}: steps/displacement at step 2: holds NaN or infinite"):
            call()


def _flip(path, dataset, chunk=0, byte=17):
    """Flip one bit inside a stored chunk of ``dataset`` (found from HDF5's chunk index)."""
    with h5py.File(path, "r") as f:
        info = f[dataset].id.get_chunk_info(chunk)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + byte)
        b = fh.read(1)[0]
        fh.seek(info.byte_offset + byte)
        fh.write(bytes([b ^ 0x04]))


def test_a_flipped_bit_is_caught_by_the_checksum_and_named(tmp_path):
    path = _valid(tmp_path / "case.h5")
    _flip(path, "steps/displacement", chunk=1)
    snap = Snapshots(path)                       # the mesh and the series are intact
    np.testing.assert_array_equal(snap.displacement(2), 0.02 * _square()[0])
    with pytest.raises(DataError, match=f"{path}: steps/displacement at step 1: checksum mismatch"):
        snap.displacement(1)
    with pytest.raises(DataError, match="steps/displacement at step 1: checksum mismatch"):
        snap.displacement()
    path = _valid(tmp_path / "mesh.h5")
    _flip(path, "mesh/vertices", byte=40)
    with pytest.raises(DataError, match=f"{path}: mesh/vertices: checksum mismatch"):
        Snapshots(path)


def test_a_truncated_file_is_a_data_error_naming_it(tmp_path):
    path = _valid(tmp_path / "case.h5")
    data = path.read_bytes()
    for keep in (len(data) // 2, len(data) - 100):
        path.write_bytes(data[:keep])
        with pytest.raises(DataError, match=str(path)):
            Snapshots(path).displacement()


def _version_1_header(f, metadata):
    """The root attributes a version-1 writer put on an open h5py file ``f``."""
    f.attrs.update(format="soro-snapshots", version=1, units="SI", created="2026-01-01T00:00:00+00:00",
                   metadata=metadata)


def test_version_1_files_without_checksums_still_read(tmp_path):
    """Files written before checksums were added (same format version 1) are read as before."""
    X, cells = _square(1)
    path = tmp_path / "old.h5"
    with h5py.File(path, "w") as f:
        _version_1_header(f, "{}")
        f.create_dataset("mesh/vertices", data=X)
        f.create_dataset("mesh/cells", data=cells).attrs["cell_type"] = "triangle"
        f["mesh"].attrs["cavities"] = "[]"
        f.create_group("mesh/regions")
        f.create_dataset("steps/time", data=[0.0, 1.0]).attrs["kind"] = "load"
        f.create_dataset("steps/displacement", data=np.stack([0 * X, 0.1 * X]))
    snap = Snapshots(path)
    assert snap.n_steps == 2 and snap.deformation_gradient(1)[0, 0, 0] == pytest.approx(1.1)


def test_input_names_come_from_one_function():
    assert input_name("pressure", "cavity_0") == "pressure/cavity_0" and input_name("tension", 2) == "tension/2"
    assert parse_input_name("pressure/cavity_0") == ("pressure", "cavity_0")
    assert parse_input_name("valve") == (None, "valve")
    with pytest.raises(DataError, match="unknown input kind"):
        input_name("presure", "cavity_0")
    with pytest.raises(DataError, match="without '/'"):
        input_name("pressure", "a/b")


def test_version_2_files_carry_a_unit_on_every_dataset_and_the_named_regions(tmp_path):
    X, cells = _square()
    path = tmp_path / "v2.h5"
    regions = {"left": ("facets", [[0, 5]]), "cavity_0": ("facets", [[1, 2]]), "layer": ("cells", [0, 1])}
    with SnapshotWriter(path, X, cells, "triangle", regions=regions, cavities=["cavity_0"], time_kind="load",
                        per_depth=True, units={"inputs/valve": "V"}) as w:
        for k in range(2):
            w.append(float(k), 0.01 * k * X, inputs={input_name("pressure", "cavity_0"): 1e3 * k, "valve": 1.0 * k},
                     cavity_volumes={"cavity_0": 1e-6}, reactions={"left": [k, -k]}, energies={"strain": 0.1 * k},
                     cell_fields={"von_mises": np.full(len(cells), float(k))})
    units = {}
    with h5py.File(path, "r") as f:
        assert f.attrs["version"] == VERSION == 2
        f.visititems(lambda name, d: units.__setitem__(name, d.attrs.get("unit")) if isinstance(d, h5py.Dataset)
                     else None)
    assert None not in units.values(), f"datasets without a unit: {[k for k, v in units.items() if v is None]}"
    assert units == {"mesh/vertices": "m", "mesh/cells": "index", "mesh/regions/left": "index",
                     "mesh/regions/cavity_0": "index", "mesh/regions/layer": "index", "steps/time": "1",
                     "steps/displacement": "m", "steps/inputs/pressure/cavity_0": "Pa", "steps/inputs/valve": "V",
                     "steps/cavity_volume/cavity_0": "m^2", "steps/reaction/left": "N/m", "steps/energy/strain": "J/m",
                     "steps/cell_field/von_mises": "Pa"}
    s = Snapshots(path)
    assert s.version == 2 and s.units["steps/inputs/pressure/cavity_0"] == "Pa"
    assert s.cavities == ["cavity_0"] and sorted(s.regions) == ["cavity_0", "layer", "left"]
    np.testing.assert_array_equal(s.input("pressure", "cavity_0"), [0.0, 1e3])
    with pytest.raises(DataError, match="no input 'pressure/cavity_1'.*pressure/cavity_0"):
        s.input("pressure", "cavity_1")
    with h5py.File(path, "a") as f:   # a version 2 file must state its units
        del f["steps/displacement"].attrs["unit"]
    with pytest.raises(DataError, match="steps/displacement: attribute 'unit' missing"):
        Snapshots(path)


def test_a_version_1_file_reads_with_the_default_units(tmp_path):
    """The layout of version 1 (regions, cavities, inputs, no unit attributes), written as that version did."""
    X, cells = _square(1)
    path = tmp_path / "v1.h5"
    with h5py.File(path, "w") as f:
        _version_1_header(f, '{"formulation": "plane_strain"}')
        f.create_dataset("mesh/vertices", data=X, fletcher32=True)
        f.create_dataset("mesh/cells", data=cells, fletcher32=True).attrs["cell_type"] = "triangle"
        f["mesh"].attrs["cavities"] = '["cavity_0"]'
        f.create_dataset("mesh/regions/cavity_0", data=[[0, 1]]).attrs["kind"] = "facets"
        f.create_dataset("steps/time", data=[0.0, 1.0]).attrs["kind"] = "load"
        f.create_dataset("steps/displacement", data=np.stack([0 * X, 0.1 * X]))
        f.create_dataset("steps/inputs/pressure/cavity_0", data=[0.0, 2e3])
        f.create_dataset("steps/reaction/left", data=[[0.0, 0.0], [1.0, 2.0]])
    s = Snapshots(path)
    assert s.version == 1 and s.cavities == ["cavity_0"] and s.regions["cavity_0"][0] == "facets"
    np.testing.assert_array_equal(s.input("pressure", "cavity_0"), [0.0, 2e3])
    assert s.units["steps/inputs/pressure/cavity_0"] == "Pa" and s.units["steps/reaction/left"] == "N/m"
    assert s.units["steps/time"] == "1" and s.units["steps/displacement"] == "m"


# ---------------------------------------------------------------------------------------------- full disk
def test_a_full_disk_is_a_data_error_naming_path_and_free_space(tmp_path, monkeypatch):
    """Fault injection: (1) the free-space check before a step, (2) HDF5 failing to write (ENOSPC) anyway."""
    import errno
    import shutil
    from collections import namedtuple

    import sorofem.snapshots as snapshots

    X, cells = _square()
    path = tmp_path / "case.h5"
    usage = namedtuple("usage", "total used free")
    real = shutil.disk_usage
    with SnapshotWriter(path, X, cells, "triangle") as w:   # a complete file is kept below
        w.append(0.0, 0 * X)
    monkeypatch.setattr(snapshots.shutil, "disk_usage", lambda p: usage(100 << 20, (100 << 20) - 4096, 4096))
    with pytest.raises(DataError, match=rf"no space left writing {path}: 0.0 MiB free of 100.0 MiB on "):
        with SnapshotWriter(path, X, cells, "triangle") as w:
            w.append(0.0, 0 * X)
    monkeypatch.setattr(snapshots.shutil, "disk_usage", real)

    def full(self):
        raise OSError(errno.ENOSPC, "No space left on device")
    w = SnapshotWriter(path, X, cells, "triangle")
    monkeypatch.setattr(h5py.File, "flush", full)
    with pytest.raises(DataError, match=rf"no space left writing {path}: .* MiB free of .* Free some space"):
        w.append(0.0, 0 * X)
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.h5"]   # no temporary file left
    assert Snapshots(path).n_steps == 1                                   # the previous file is intact


def test_a_write_error_met_in_a_destructor_is_the_data_error_without_tracebacks(tmp_path, monkeypatch, capfd):
    """HDF5 may report a failed write from a handle's destructor ("Exception ignored in ...", once through
    ``sys.excepthook`` and once through ``sys.unraisablehook``): the writer raises it as the DataError and
    nothing is printed (fault injection: an object whose ``__del__`` fails with ENOSPC during the flush)."""
    import errno

    X, cells = _square()
    path = tmp_path / "case.h5"

    class Handle:
        def __del__(self):
            raise OSError(errno.ENOSPC, "No space left on device")

    def flush(self):
        Handle()                                  # dropped at once: its error goes to sys.unraisablehook
        sys.excepthook(RuntimeError, RuntimeError("errno = 28"), None)   # Cython's PyErr_PrintEx half
    w = SnapshotWriter(path, X, cells, "triangle")
    capfd.readouterr()
    hooks = sys.unraisablehook, sys.excepthook
    monkeypatch.setattr(h5py.File, "flush", flush)
    with pytest.raises(DataError, match=rf"no space left writing {path}: .* MiB free of "):
        w.append(0.0, 0 * X)
    monkeypatch.undo()
    err = capfd.readouterr().err
    assert "Traceback" not in err and "Exception ignored" not in err and "errno" not in err, err
    assert list(tmp_path.iterdir()) == []                               # nothing committed, no temporary file
    assert (sys.unraisablehook, sys.excepthook) == hooks                 # the hooks are given back


def _tmpfs(where, size):
    where.mkdir()
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True)
    if res.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({res.stderr.decode().strip()}); the fault-injected test covers it")


@pytest.mark.skipif(not sys.platform.startswith("linux") or os.geteuid() != 0, reason="mounts a tmpfs (root)")
def test_a_really_full_disk_gives_the_message_and_no_crash(tmp_path, subprocess_env):
    """A 512 KiB tmpfs: writing a 2.4 MiB case ends in the DataError (in a child process: no native crash,
    no flood of HDF5 tracebacks)."""
    disk = tmp_path / "disk"
    _tmpfs(disk, "512k")
    try:
        code = ("import numpy as np, sys\n"
                "from sorofem.snapshots import SnapshotWriter\n"
                "from sorofem.errors import DataError\n"
                "X = np.random.default_rng(0).random((10000, 2)); cells = np.array([[0, 1, 2]])\n"
                "try:\n"
                "    with SnapshotWriter(sys.argv[1], X, cells, 'triangle') as w:\n"
                "        for k in range(15):\n"
                "            w.append(float(k), X, inputs={'p': 1.0})\n"
                "except DataError as e:\n"
                "    print('DataError:', e)\n")
        res = subprocess.run([sys.executable, "-c", code, str(disk / "case.h5")], capture_output=True, text=True,
                             env=subprocess_env, timeout=120)
        assert res.returncode == 0, res.stdout + res.stderr
        assert f"DataError: no space left writing {disk / 'case.h5'}: " in res.stdout
        assert "MiB free of 0.5 MiB" in res.stdout
        assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr, res.stderr[:2000]
        assert os.listdir(disk) == []
        # the same with the free-space check fooled (another writer fills the disk after it): HDF5 itself
        # meets the full disk; before the fix its errors went to destructors ("Exception ignored" tracebacks),
        # the truncated file was committed as done and the process crashed at exit (SIGSEGV)
        fooled = ("import shutil, collections\n"
                  "shutil.disk_usage = lambda p: collections.namedtuple('u', 'total used free')(1 << 40, 0, 1 << 40)\n")
        res = subprocess.run([sys.executable, "-c", fooled + code, str(disk / "case.h5")], capture_output=True,
                             text=True, env=subprocess_env, timeout=120)
        assert res.returncode == 0, res.stdout + res.stderr
        assert f"DataError: no space left writing {disk / 'case.h5'}: " in res.stdout
        assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr, res.stderr[:2000]
        assert os.listdir(disk) == []
    finally:
        subprocess.run(["umount", str(disk)], check=False)
