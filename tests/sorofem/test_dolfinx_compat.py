"""sorofem._dolfinx, the one module that knows the DOLFINx version (0.5 on Debian 12, 0.9 on Debian 13), and the
rule that nothing else spells a version-dependent call."""
import re
from pathlib import Path

import numpy as np
import pytest

from sorofem import _dolfinx

PACKAGES = [Path(__file__).resolve().parents[2] / p for p in ("sorofem", "soroshapes", "sorocontrol", "soro", "demos")]
SEAMS = {"sorofem/_dolfinx.py", "sorofem/mesh/_gmsh.py"}

# spellings that exist in only some of the supported versions (0.5 ... 0.9, gmsh 4.8 ... 4.13)
VERSION_DEPENDENT = {
    "legacy UFL elements (gone in 0.8)": r"ufl\.(Cell|FiniteElement|VectorElement|TensorElement|MixedElement)\(",
    "FunctionSpace/VectorFunctionSpace constructors (0.5)": r"\b(Vector)?FunctionSpace\(",
    "fem.functionspace (0.7+)": r"\bfunctionspace\(",
    "basix.ufl elements (0.7+)": r"basix\.ufl",
    "Function.vector / x.petsc_vec": r"\.vector\b(?!\w)|\.petsc_vec\b",
    "AdjacencyList dofmaps (0.5) / 2D arrays (0.8+)": r"dofmap\.(list|array|links)\b|dofmap\.list\.array",
    "set_bc/apply_lifting keywords": r"\b(set_bc|apply_lifting)\(",
    "bounding-box trees": r"BoundingBoxTree|\bbb_tree\(|compute_collisions(_points)?\(",
    "direct C++ bindings": r"dolfinx\.cpp\b|\._cpp_object\b|\._mesh\b",
    "XDMF meshtags output": r"\.write_meshtags\(",
    "entities_to_geometry": r"entities_to_geometry\(",
    "JIT option names": r"JIT_(PARAMETERS|OPTIONS)|jit_(params|options)|form_compiler_(params|options)",
    "gmsh size callback": r"setSizeCallback\(",
    "la.orthonormalize / create_petsc_vector": r"la\.(orthonormalize|create_petsc_vector)\(",
    "version tests": r"dolfinx\.__version__|gmsh\.__version__|GMSH_API_VERSION",
}


def test_version_dependent_calls_only_in_the_seams():
    """grep: the spellings that differ between the supported versions appear only in sorofem/_dolfinx.py
    (DOLFINx) and sorofem/mesh/_gmsh.py (gmsh)."""
    root = PACKAGES[0].parent
    found = []
    for pkg in PACKAGES:
        for path in sorted(pkg.rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            if rel in SEAMS:
                continue
            for n, line in enumerate(path.read_text().splitlines(), 1):
                code = re.sub(r"\b_dolfinx\.\w+", "_seam", line.split("#", 1)[0])  # calls through the seam are fine
                for what, pattern in VERSION_DEPENDENT.items():
                    if re.search(pattern, code):
                        found.append(f"{rel}:{n}: {what}: {line.strip()}")
    # the doctor prints the installed version: a report, not a version test
    found = [f for f in found if not f.startswith("soro/doctor.py") or "version tests" not in f]
    assert not found, "version-dependent calls outside the compatibility modules:\n" + "\n".join(found)


@pytest.mark.parametrize("found, ok", [("0.5.2", True), ("0.9.0", True), ("0.9.1.post0", True), ("0.4.1", False),
                                       ("0.10.0", False), ("0.10.0.dev0", False)])
def test_support_status_names_the_version_and_the_range(found, ok):
    supported, sentence = _dolfinx.support_status(found)
    assert supported is ok
    assert f"DOLFINx {found}" in sentence and "0.5" in sentence and "0.9" in sentence


def test_installed_version_is_supported():
    """The suite runs on Debian 12 and 13 only; a new DOLFINx needs its row in _dolfinx first."""
    import dolfinx

    assert _dolfinx.support_status()[0], dolfinx.__version__
    assert _dolfinx.version()[:2] in ((0, 5), (0, 9))


@pytest.fixture(scope="module")
def annulus():
    """An order-2 annulus (curved boundary facets) from the project's mesher."""
    from sorofem import sdf
    from sorofem.mesh import Mesh
    from sorofem.units import mm

    return Mesh.from_sdf(sdf.Circle(5 * mm) - sdf.Circle(2 * mm), size=1 * mm, order=2)


def test_entity_vertex_nodes_are_the_vertices(annulus):
    """0.9's entities_to_geometry also returns the edge-midpoint node of a curved facet; the seam keeps the two
    vertices, so the facet's vertex mean is a chord midpoint (inside the annulus material, off the arc by the
    sagitta) on every version."""
    import dolfinx.mesh

    m = annulus.dolfinx
    tdim = m.topology.dim
    facets = dolfinx.mesh.exterior_facet_indices(m.topology)
    nodes = _dolfinx.entity_vertex_nodes(m, tdim - 1, facets)
    assert nodes.shape == (len(facets), 2)
    m.topology.create_connectivity(tdim - 1, 0)
    m.topology.create_connectivity(0, tdim)  # compute_midpoints of vertices needs it on 0.9
    f2v = m.topology.connectivity(tdim - 1, 0)
    # vertex coordinates through the topology (no geometry dofmap involved) must match
    xv = m.geometry.x[nodes][:, :, :2]
    for k, f in enumerate(facets[:20]):
        verts = f2v.links(f)
        topo = dolfinx.mesh.compute_midpoints(m, 0, verts.astype(np.int32))[:, :2]
        assert np.allclose(np.sort(topo, axis=0), np.sort(xv[k], axis=0), rtol=0, atol=1e-15)


def test_geometry_and_cell_dofs_are_2d(annulus):
    m = annulus.dolfinx
    n = m.topology.index_map(2).size_local
    geo = _dolfinx.geometry_dofs(m, n)
    assert geo.shape == (n, 6) and _dolfinx.geometry_degree(m) == 2  # P2 triangles
    V = _dolfinx.function_space(m, "Lagrange", 1, "vector")
    assert _dolfinx.cell_dofs(V, n).shape == (n, 3)
    Q = _dolfinx.function_space(m, "DG", 0)
    assert np.array_equal(np.sort(_dolfinx.cell_dofs(Q, n)[:, 0]), np.arange(n))


def test_orthonormalize_gives_an_orthonormal_basis_of_the_same_span():
    from petsc4py import PETSc

    rng = np.random.default_rng(0)
    A = rng.standard_normal((7, 3))
    vecs = [PETSc.Vec().createWithArray(A[:, j].copy(), comm=PETSc.COMM_SELF) for j in range(3)]
    _dolfinx.orthonormalize(vecs)
    Q = np.column_stack([v.getArray().copy() for v in vecs])
    np.testing.assert_allclose(Q.T @ Q, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(Q @ (Q.T @ A), A, atol=1e-13)  # same span
    dep = [PETSc.Vec().createWithArray(A[:, 0].copy(), comm=PETSc.COMM_SELF) for _ in range(2)]
    with pytest.raises(ValueError, match="linearly dependent"):
        _dolfinx.orthonormalize(dep)


def test_set_bc_and_lifting_keywords(annulus):
    """set_bc with alpha: b = alpha (g - x0) on the constrained rows; the same call on 0.5 (scale=) and 0.9."""
    import dolfinx.fem
    import dolfinx.fem.petsc
    import ufl

    m = annulus.dolfinx
    V = _dolfinx.function_space(m, "Lagrange", 1)
    facets = annulus.facets("cavity_0")
    dofs = dolfinx.fem.locate_dofs_topological(V, 1, facets)
    bc = dolfinx.fem.dirichletbc(dolfinx.fem.Constant(m, 2.0), dofs, V)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = dolfinx.fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx(metadata={"quadrature_degree": 2}))
    L = dolfinx.fem.form(dolfinx.fem.Constant(m, 0.0) * v * ufl.dx(metadata={"quadrature_degree": 2}))
    x0 = dolfinx.fem.Function(V)
    x0.x.array[:] = 0.5
    b = dolfinx.fem.petsc.assemble_vector(L)
    _dolfinx.apply_lifting(b, [a], [[bc]], [_dolfinx.petsc_vec(x0)], alpha=-1.0)
    _dolfinx.set_bc(b, [bc], _dolfinx.petsc_vec(x0), alpha=-1.0)
    owned = dofs[dofs < V.dofmap.index_map.size_local]
    np.testing.assert_allclose(b.getArray()[owned], -1.0 * (2.0 - 0.5), rtol=1e-14)
    b.destroy()


def test_colliding_cells_finds_the_cell_of_a_point(annulus):
    from sorofem.units import mm

    m = annulus.dolfinx
    cells = _dolfinx.colliding_cells(m, np.array([[3.5 * mm, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    assert len(cells.links(0)) >= 1 and len(cells.links(1)) == 0  # in the material / in the hole
