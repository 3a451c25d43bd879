"""sorofem.mesh under MPI (2 ranks): a mesh built on rank 0 is distributed, global measures and tags are right."""
import math

import numpy as np
import pytest

pytestmark = pytest.mark.mpi

mm = 1e-3


def test_mesh_from_sdf_is_distributed_with_right_regions(tmp_path_factory):
    from mpi4py import MPI

    from sorofem import sdf
    from sorofem.mesh import Mesh

    comm = MPI.COMM_WORLD
    assert comm.size == 2, "run with mpirun -n 2"
    shape = sdf.Rectangle(40 * mm, 10 * mm) - sdf.Circle(2 * mm, center=(-8 * mm, 0)) \
        - sdf.Circle(2 * mm, center=(8 * mm, 0))
    msh = Mesh.from_sdf(shape, size=1 * mm, order=2)
    owned = msh.dolfinx.topology.index_map(2).size_local
    assert 0 < owned < msh.num_cells, "each rank must own part of the mesh"
    assert comm.allreduce(owned) == msh.num_cells
    assert msh.area == pytest.approx(40 * 10 * mm**2 - 2 * math.pi * (2 * mm) ** 2, rel=1e-4)
    assert msh.cavities == ["cavity_0", "cavity_1"]
    assert msh.measure("left") == pytest.approx(10 * mm, rel=1e-12)
    assert msh.measure("top") == pytest.approx(40 * mm, rel=1e-12)
    for name in msh.cavities:
        assert msh.measure(name) == pytest.approx(2 * math.pi * 2 * mm, rel=1e-4)
    # the left hole is cavity_0 on every rank
    import dolfinx.mesh
    f = msh.facets("cavity_0")
    xs = dolfinx.mesh.compute_midpoints(msh.dolfinx, 1, f)[:, 0] if len(f) else np.zeros(0)
    assert np.all(xs < 0)
    # cell region and quality are global
    msh.add_region("layer", ((-20 * mm, -5 * mm), (20 * mm, -3 * mm)), kind="cells")
    assert msh.measure("layer") > 0
    assert msh.quality["degenerate"] == 0 and msh.quality["min_angle"] > 20
    # XDMF round trip in parallel
    d = comm.bcast(str(tmp_path_factory.mktemp("xdmf")) if comm.rank == 0 else None, root=0)
    path = msh.write_xdmf(f"{d}/body.xdmf")
    back = Mesh.from_file(path)
    assert set(back.regions) == set(msh.regions)
    assert back.area == pytest.approx(msh.area, rel=1e-12)
    for name in msh.regions:  # every region comes back whole (facets on curved cavities included)
        assert back.measure(name) == pytest.approx(msh.measure(name), rel=1e-10), name
    msh.write_msh(f"{d}/body.msh")
    back2 = Mesh.from_file(f"{d}/body.msh")
    assert back2.measure("cavity_1") == pytest.approx(msh.measure("cavity_1"), rel=1e-10)


def test_errors_are_raised_on_every_rank():
    from sorofem import sdf
    from sorofem.errors import GeometryError
    from sorofem.mesh import Mesh

    with pytest.raises(GeometryError, match="empty"):
        Mesh.from_sdf(sdf.Circle(1 * mm) - sdf.Circle(2 * mm), size=0.2 * mm, method="levelset")
