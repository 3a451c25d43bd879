"""Outputs users open in their tools: XDMF that ParaView/meshio read with 3-component vectors, units and time
stamps; figures that leave the process's matplotlib backend alone; progress shown on terminals only."""
import io
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from sorofem.io import Progress


def _trajectory(n_steps=3):
    """A 2D trajectory without FEM: a unit square of two triangles stretched along x."""
    from mpi4py import MPI

    from sorofem.fem import Trajectory

    X = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    cells = np.array([[0, 1, 2], [0, 2, 3]])
    traj = Trajectory(X, cells, "triangle", time_kind="time", comm=MPI.COMM_SELF,
                      regions={"left": ("facets", np.array([[0, 3]]))}, cavities=())
    for k in range(n_steps):
        u = np.column_stack([0.1 * k * X[:, 0], np.zeros(4)])
        traj.append(0.5 * k, u, 1, 0.0, {"pressure/cavity_0": 1e3 * k}, {}, {}, von_mises=np.full(2, 10.0 * k),
                    max_von_mises=10.0 * k)
    return traj


def test_xdmf_of_a_2d_body_can_be_warped(tmp_path):
    """meshio's XDMF reader sees 3-component displacements; with VTK's XDMF reader (if installed), the
    warp-by-vector filter moves the points by exactly the displacement."""
    import meshio

    traj = _trajectory()
    traj.write_xdmf(tmp_path / "run.xdmf")
    traj.save(tmp_path / "run.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5", "run.xdmf", "run.xdmf.h5"]
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "run.xdmf")) as r:
        points, _ = r.read_points_cells()
        stamps = [r.read_data(k)[0] for k in range(r.num_steps)]
        _, point_data, cell_data = r.read_data(2)
    assert stamps == [0.0, 0.5, 1.0]
    u = point_data["displacement"]
    assert points.shape == (4, 3) and u.shape == (4, 3)
    np.testing.assert_allclose(points[:, :2] + u[:, :2], traj.vertices * [1.2, 1.0])
    np.testing.assert_allclose(cell_data["von_mises"][0], 20.0)
    with pytest.raises(Exception, match="xdmf.h5"):
        traj.save(tmp_path / "run.xdmf.h5")
    vtk = pytest.importorskip("vtk")   # install vtk into the venv to run this part (not a dependency)
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(tmp_path / "run.xdmf"))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    assert list(times) == [0.0, 0.5, 1.0]
    reader.GetOutputInformation(0).Set(vtk.vtkStreamingDemandDrivenPipeline.UPDATE_TIME_STEP(), 1.0)
    reader.Update()
    grid = reader.GetOutputDataObject(0)
    if grid.IsA("vtkMultiBlockDataSet"):
        grid = grid.GetBlock(0)
    grid.GetPointData().SetActiveVectors("displacement")
    warp = vtk.vtkWarpVector()
    warp.SetInputData(grid)
    warp.Update()
    out = warp.GetOutput()
    moved = np.array([out.GetPoint(i) for i in range(out.GetNumberOfPoints())])
    np.testing.assert_allclose(moved[:, :2], traj.vertices * [1.2, 1.0], atol=1e-12)


def test_xdmf_records_units_in_the_xml_and_the_data_file(tmp_path):
    import xml.etree.ElementTree as ET

    import h5py

    _trajectory().write_xdmf(tmp_path / "run.xdmf")
    info = ET.parse(tmp_path / "run.xdmf").getroot().find("Domain/Information")
    assert info.get("Name") == "units"
    assert json.loads(info.get("Value")) == {"time": "s", "displacement": "m", "von_mises": "Pa"}
    with h5py.File(tmp_path / "run.xdmf.h5") as f:
        fields = {f[k].attrs.get("field"): f[k].attrs.get("unit") for k in f if "field" in f[k].attrs}
    assert fields == {"displacement": "m", "von_mises": "Pa"}


def test_figures_leave_the_matplotlib_backend_alone(tmp_path):
    """Trajectory.plot/filmstrip draw on Figure objects: a notebook's inline backend stays in place."""
    script = textwrap.dedent(f"""
        import matplotlib
        matplotlib.use("svg")
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        from test_helper import make
        traj = make()
        traj.plot({str(tmp_path / "a.png")!r})
        traj.filmstrip({str(tmp_path / "b.png")!r}, [0, 2])
        print(matplotlib.get_backend())
    """)
    (tmp_path / "test_helper.py").write_text(
        "import numpy as np\n" + textwrap.dedent(_source_of(_trajectory)).replace("def _trajectory", "def make"))
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().lower() == "svg"
    assert (tmp_path / "a.png").stat().st_size > 5000 and (tmp_path / "b.png").stat().st_size > 5000


def _source_of(fn):
    import inspect
    return inspect.getsource(fn)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize("tty, enabled, shown", [(False, None, False), (True, None, True), (False, True, True),
                                                 (True, False, False)])
def test_progress_shows_on_terminals_and_stays_quiet_otherwise(monkeypatch, tty, enabled, shown):
    stream = _Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    with Progress(1.0, "Fem.solve", enabled, unit="load") as bar:
        for t in (0.25, 0.5, 1.0):
            bar.to(t, newton=3)
    text = stream.getvalue()
    assert bool(text) == shown
    if shown:
        assert "Fem.solve" in text
