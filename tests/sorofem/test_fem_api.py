"""The public surface of :class:`sorofem.fem.Fem` that other modules and demos use: the typed, frozen forms,
``num_dofs``, the deprecated names, and snapshots that carry the mesh's named regions and cavities."""
import dataclasses
import re

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.fem import Fem, FemForms
from sorofem.mesh import Mesh
from sorofem.units import MPa, kPa, mm


def _bar(degree=1, mixed=False):
    L, H = 0.02, 0.01
    msh = Mesh.rectangle(L, H, size=0.0025, center=(L / 2, H / 2))
    return Fem(msh, materials.NeoHookean(E=1 * MPa, nu=0.3), degree=degree, mixed=mixed), msh


@pytest.mark.parametrize("degree, mixed", [(1, False), (2, True)])
def test_forms_are_typed_and_frozen_and_num_dofs_counts_every_field(degree, mixed):
    fem, msh = _bar(degree, mixed)
    forms = fem.forms
    assert isinstance(forms, FemForms) and forms.space is fem.function_space
    with pytest.raises(dataclasses.FrozenInstanceError):
        forms.residual = None
    n_vertices = msh.dolfinx.topology.index_map(0).size_global
    if not mixed:   # P1 vector: 2 unknowns per vertex
        assert fem.num_dofs == 2 * n_vertices
    else:           # Taylor-Hood: P2 vector (vertices + edges) and P1 pressure
        n_edges = msh.dolfinx.topology.index_map(1).size_global
        assert fem.num_dofs == 2 * (n_vertices + n_edges) + n_vertices
    fem.add_support("left")
    assert fem.forms is not forms, "a change must rebuild the forms"


def test_deprecated_names_warn_naming_the_new_ones_and_still_work():
    fem, _ = _bar()
    fem.add_support("left")
    with pytest.warns(DeprecationWarning, match="add_traction"):
        fem.add_force("right", [0.0, -1 * kPa])
    with pytest.warns(DeprecationWarning, match="load_level"):
        old = fem.solve(t_end=0.5, steps=1)
    assert old.times[-1] == pytest.approx(0.5)
    fem2, _ = _bar()
    new = fem2.add_support("left").add_traction("right", [0.0, -1 * kPa]).solve(load_level=0.5, steps=1)
    np.testing.assert_allclose(new.displacement[-1], old.displacement[-1], rtol=1e-12, atol=1e-15)
    with pytest.warns(DeprecationWarning, match="load_level"):
        fem2.follow(t_end=0.1, steps=1, max_steps=1)


def test_a_solved_case_saves_its_named_regions_cavities_and_units(tmp_path):
    """The snapshot of a FEM solve holds the mesh's regions (facets as vertex indices of the saved mesh) and
    its cavities, and a unit on every dataset; the pressure input is named by input_name."""
    import h5py

    from sorofem.snapshots import Snapshots, input_name

    body = sdf.Rectangle(20 * mm, 10 * mm, center=(10 * mm, 0)) - sdf.Circle(2 * mm, center=(10 * mm, 0))
    msh = Mesh.from_sdf(body, size=1.5 * mm)
    fem = Fem(msh, materials.NeoHookean(E=200 * kPa, nu=0.45)).add_support("left")
    traj = fem.add_pressure("cavity_0", 5 * kPa).solve(steps=2)
    snap = Snapshots(traj.save(tmp_path / "case.h5"))
    assert snap.version == 2 and snap.cavities == ["cavity_0"]
    assert set(snap.regions) == set(msh.regions)
    kind, left = snap.regions["left"]
    assert kind == "facets" and left.shape[1] == 2 and len(left)
    np.testing.assert_allclose(snap.vertices[left.ravel(), 0], 0.0, atol=1e-9)   # the facets of x = 0
    _, cavity = snap.regions["cavity_0"]
    r = np.linalg.norm(snap.vertices[cavity.ravel()] - [10 * mm, 0], axis=1)
    np.testing.assert_allclose(r, 2 * mm, rtol=1e-6)                             # on the hole's circle
    np.testing.assert_allclose(snap.input("pressure", "cavity_0"), [0, 2.5 * kPa, 5 * kPa])
    assert input_name("pressure", "cavity_0") in traj.inputs
    with h5py.File(tmp_path / "case.h5") as f:
        missing = []
        f.visititems(lambda n, d: missing.append(n) if isinstance(d, h5py.Dataset) and "unit" not in d.attrs
                     else None)
    assert not missing
    assert snap.units["steps/cavity_volume/cavity_0"] == "m^2" and snap.units["steps/reaction/left"] == "N/m"


#: The files that build a model and may read their own private state (and this test, which names the patterns).
OWNERS = {"sorofem/fem/problem.py", "sorofem/topopt/problems.py", "tests/sorofem/test_fem_api.py"}


def test_no_module_reaches_into_fem_privately(repo):
    """No ``_built`` outside the file that builds it, and no ``fem._private`` member used outside problem.py."""
    offenders = []
    for root in ("sorofem", "soroshapes", "sorocontrol", "soro", "demos", "hardware", "tests"):
        for path in (repo / root).rglob("*.py"):
            if path.relative_to(repo).as_posix() in OWNERS:
                continue
            text = path.read_text()
            for pattern in (r"\bfem\._[a-z]\w*", r"\bfem_t\._[a-z]\w*", r"\._built\b", r"\._build\(\)\["):
                offenders += [f"{path.relative_to(repo)}: {m}" for m in re.findall(pattern, text)]
    assert not offenders, offenders


@pytest.mark.mpi
def test_regions_saved_from_two_ranks_are_the_serial_ones(tmp_path_factory):
    """The regions of a distributed mesh are gathered into the saved numbering: the same facets (by their
    centroids) and cells (by their centroids) as a serial run."""
    from mpi4py import MPI

    from sorofem.snapshots import Snapshots

    comm = MPI.COMM_WORLD
    assert comm.size == 2
    body = sdf.Rectangle(20 * mm, 10 * mm, center=(10 * mm, 0)) - sdf.Circle(2 * mm, center=(10 * mm, 0))
    folder = comm.bcast(str(tmp_path_factory.mktemp("regions")) if comm.rank == 0 else None, root=0)
    centroids = []
    for c, name in ((comm, "parallel.h5"), (MPI.COMM_SELF, "serial.h5")):
        msh = Mesh.from_sdf(body, size=1.5 * mm, comm=c)
        msh.add_region("core", lambda x: x[0] < 5 * mm, kind="cells")
        fem = Fem(msh, materials.NeoHookean(E=200 * kPa, nu=0.45)).add_support("left")
        traj = fem.add_pressure("cavity_0", 5 * kPa).solve(steps=1)
        path = traj.save(f"{folder}/{name}")
        if comm.rank == 0:
            snap = Snapshots(path)
            out = {}
            for region, (kind, idx) in snap.regions.items():
                cells = snap.cells[idx] if kind == "cells" else idx
                out[region] = np.sort(np.round(snap.vertices[cells].mean(axis=1), 9), axis=0)
            centroids.append((out, snap.cavities))
    if comm.rank == 0:
        (par, cav_p), (ser, cav_s) = centroids
        assert cav_p == cav_s == ["cavity_0"] and sorted(par) == sorted(ser)
        for region in ser:
            np.testing.assert_allclose(par[region][np.lexsort(par[region].T)],
                                       ser[region][np.lexsort(ser[region].T)], atol=1e-12)
