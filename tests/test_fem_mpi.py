"""FEM on two MPI ranks gives the serial results."""
import numpy as np
import pytest

pytestmark = pytest.mark.mpi


def _problem(comm):
    from sorofem import materials, sdf
    from sorofem.fem import Fem
    from sorofem.mesh import Mesh
    L, H = 0.1, 0.01
    body = sdf.Rectangle(L, H, center=(L / 2, 0.0)) - sdf.Circle(H / 4, center=(L / 2, 0.0))
    msh = Mesh.from_sdf(body, size=H / 4, comm=comm)
    fem = Fem(msh, materials.NeoHookean(E=100e3, nu=0.45), degree=2).add_support("left")
    fem.add_pressure("cavity_0", 5e3).add_gravity()
    return fem, fem.solve(steps=3)


def test_parallel_solve_equals_serial_solve():
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    assert comm.size == 2
    fem_p, traj_p = _problem(comm)
    fem_s, traj_s = _problem(MPI.COMM_SELF)
    assert fem_p.mesh.dolfinx.topology.index_map(2).size_local < fem_s.mesh.num_cells  # really distributed
    tip = [[0.1, 0.0]]
    np.testing.assert_allclose(fem_p.evaluate(tip), fem_s.evaluate(tip), rtol=1e-7)
    np.testing.assert_allclose(traj_p.cavity_volumes["cavity_0"], traj_s.cavity_volumes["cavity_0"], rtol=1e-9)
    np.testing.assert_allclose(traj_p.reactions["left"], traj_s.reactions["left"], rtol=1e-7, atol=1e-12)
    if comm.rank == 0:  # gathered vertex fields agree too (the same mesh, the same global numbering)
        assert traj_p.displacement.shape == traj_s.displacement.shape
        np.testing.assert_allclose(np.sort(np.abs(traj_p.displacement[-1]).ravel()),
                                   np.sort(np.abs(traj_s.displacement[-1]).ravel()), rtol=1e-6, atol=1e-12)
