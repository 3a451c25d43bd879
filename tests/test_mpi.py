"""Tests that run on two MPI ranks (`make test` runs them with `mpirun -n 2`)."""
import pytest

pytestmark = pytest.mark.mpi


def test_two_ranks_communicate():
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    assert comm.size == 2, "run the mpi tests with mpirun -n 2"
    assert comm.allreduce(comm.rank + 1) == 3


def test_dolfinx_distributes_a_mesh_and_assembles_globally():
    from mpi4py import MPI
    import ufl
    import dolfinx.fem
    import dolfinx.mesh
    comm = MPI.COMM_WORLD
    msh = dolfinx.mesh.create_unit_square(comm, 8, 8)
    owned = msh.topology.index_map(2).size_local
    assert comm.allreduce(owned) == 2 * 8 * 8
    assert 0 < owned < 128, "each rank must own part of the mesh"
    area = dolfinx.fem.assemble_scalar(dolfinx.fem.form(dolfinx.fem.Constant(msh, 1.0) * ufl.dx))
    assert comm.allreduce(area) == pytest.approx(1.0, rel=1e-12)
