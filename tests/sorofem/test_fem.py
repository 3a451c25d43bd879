"""Quasi-static hyperelastic FEM against closed-form mechanics, and its failure modes."""
import numpy as np
import pytest

from analytic import elastica_tip
from sorofem import materials
from sorofem.errors import ConvergenceError, MeshError, ParameterError
from sorofem.fem import Fem
from sorofem.mesh import Mesh
from sorofem.units import kPa, MPa

LAWS = {
    "neo-hookean": lambda **kw: materials.NeoHookean(mu=100 * kPa, **kw),
    "mooney-rivlin": lambda **kw: materials.MooneyRivlin(60 * kPa, 15 * kPa, **kw),
    "yeoh": lambda **kw: materials.Yeoh(50 * kPa, -1 * kPa, 0.5 * kPa, **kw),
}


def _uniaxial_box(material, stretch, mixed=False):
    """A unit-ish box pulled along x with sliding supports: a homogeneous uniaxial-stress state."""
    Lx, Ly, Lz = 0.02, 0.01, 0.01
    msh = Mesh.box(Lx, Ly, Lz, size=0.005, center=(Lx / 2, Ly / 2, Lz / 2), cell="tetrahedron")
    fem = Fem(msh, material, degree=2 if mixed else 1, mixed=mixed)
    fem.add_support("left", "x").add_support("front", "y").add_support("bottom", "z")
    fem.add_displacement("right", (stretch - 1) * Lx, "x")
    traj = fem.solve(steps=4 if stretch > 1.5 or stretch < 0.8 else 2)
    force = -traj.reactions["left"][-1][0]  # the support pulls back with -F
    return force / (Ly * Lz), fem, traj


def _lateral_free_stress(material, F):
    """Nominal stress P11 of the numpy law with the lateral stretches chosen so that P22 = P33 = 0."""
    from scipy.optimize import brentq
    lam = F

    def p22(t):
        return material.pk1(np.diag([lam, t, t]))[1, 1]
    t = brentq(p22, 0.2, 2.0, xtol=1e-15)
    return material.pk1(np.diag([lam, t, t]))[0, 0], t


@pytest.mark.parametrize("law", sorted(LAWS))
@pytest.mark.parametrize("stretch", [0.7, 1.6])
def test_uniaxial_tension_3d_compressible(law, stretch):
    """A homogeneous deformation is exact in P1: FEM stress equals the material law's to solver accuracy."""
    mat = LAWS[law](nu=0.45)
    P_fem, fem, _ = _uniaxial_box(mat, stretch)
    P_ref, t = _lateral_free_stress(mat, stretch)
    assert P_fem == pytest.approx(P_ref, rel=1e-6)
    u = fem.evaluate([[0.02, 0.01, 0.01]])[0]
    np.testing.assert_allclose(u, [(stretch - 1) * 0.02, (t - 1) * 0.01, (t - 1) * 0.01], rtol=1e-6, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("law", sorted(LAWS))
def test_uniaxial_tension_nearly_incompressible_mixed_matches_incompressible_closed_form(law):
    """nu = 0.4999 with Taylor-Hood: the stress is the incompressible one, 2 (l - l^-2)(W1 + W2/l), within
    the O(mu/kappa) ~ 1e-3 compressibility of the model."""
    mat = LAWS[law](nu=0.4999)
    lam = 1.8
    P_fem, fem, _ = _uniaxial_box(mat, lam, mixed=True)
    I1b, I2b = lam**2 + 2 / lam, 2 * lam + 1 / lam**2
    W1, W2 = mat._dw(I1b, I2b)
    assert P_fem == pytest.approx(2 * (lam - lam**-2) * (W1 + W2 / lam), rel=2e-3)
    u = fem.evaluate([[0.02, 0.01, 0.01]])[0]
    assert 1 + u[1] / 0.01 == pytest.approx(lam**-0.5, rel=1e-3)  # volume preserved


def test_plane_strain_uniaxial_matches_law():
    mat = materials.NeoHookean(E=1 * MPa, nu=0.3)
    L, H = 0.02, 0.01
    msh = Mesh.rectangle(L, H, size=0.005, center=(L / 2, H / 2))
    fem = Fem(msh, mat).add_support("left", "x").add_support("bottom", "y").add_displacement("right", 0.3 * L, "x")
    traj = fem.solve(steps=2)
    from scipy.optimize import brentq
    t = brentq(lambda t: mat.pk1(np.diag([1.3, t, 1.0]))[1, 1], 0.3, 1.5, xtol=1e-15)
    P11 = mat.pk1(np.diag([1.3, t, 1.0]))[0, 0]
    assert -traj.reactions["left"][-1][0] == pytest.approx(P11 * H, rel=1e-6)  # [N per m of depth]


def _cantilever(L=0.1, H=0.005, size=None, degree=2, E=1 * MPa, nu=0.3):
    msh = Mesh.rectangle(L, H, size=size or H / 2, center=(L / 2, 0.0), cell="quadrilateral")
    mat = materials.NeoHookean(E=E, nu=nu)
    return Fem(msh, mat, degree=degree).add_support("left"), mat


def test_small_load_cantilever_matches_timoshenko_beam():
    """Tip load P (per m of depth): w = P L^3/(3 E' I) + P L/(k G A), E' = E/(1-nu^2) (plane strain),
    k = 5/6. The 2D continuum agrees to within the beam theory's own O((H/L)^2) error, here 1 %."""
    L, H, P = 0.1, 0.005, 1e-3
    fem, mat = _cantilever(L, H)
    fem.add_traction("right", [0.0, -P / H])
    traj = fem.solve(steps=1)
    E_ps = mat.E / (1 - mat.nu**2)
    w = P * L**3 / (3 * E_ps * H**3 / 12) + P * L / (5 / 6 * mat.G * H)
    assert -fem.evaluate([[L, 0.0]])[0][1] == pytest.approx(w, rel=1e-2)
    np.testing.assert_allclose(traj.reactions["left"][-1], [0.0, P], atol=1e-9 * P + 1e-15)


@pytest.mark.slow
@pytest.mark.parametrize("load", [1.0, 3.0])
def test_large_deflection_cantilever_matches_elastica(load):
    """Dead tip load with P L^2 / (E' I) = 1 and 3 (tip rotation ~ 26 deg and ~ 58 deg) against the elastica
    BVP; slender beam L/H = 40, so shear and thickness effects stay below 0.5 %; tolerance 1.5 %."""
    L, H = 0.2, 0.005
    fem, mat = _cantilever(L, H, size=H / 2)
    EI = mat.E / (1 - mat.nu**2) * H**3 / 12
    P = load * EI / L**2
    fem.add_traction("right", [0.0, -P / H])
    fem.solve(steps=6)
    dx, dy = elastica_tip(L, EI, P)
    u = fem.evaluate([[L, 0.0]])[0]
    assert u[1] == pytest.approx(dy, rel=1.5e-2)
    assert u[0] == pytest.approx(dx, rel=3e-2)


def test_mesh_convergence_rate_of_the_cantilever():
    """P1 quadrilaterals: the tip deflection error of a bending-dominated beam falls as O(h^2)."""
    L, H, P = 0.1, 0.01, 1e-3
    tips = []
    for n in (2, 4, 8):
        fem, _ = _cantilever(L, H, size=H / n, degree=1)
        fem.add_traction("right", [0.0, -P / H]).solve(steps=1)
        tips.append(-fem.evaluate([[L, 0.0]])[0][1])
    fem, _ = _cantilever(L, H, size=H / 8, degree=2)
    fem.add_traction("right", [0.0, -P / H]).solve(steps=1)
    ref = -fem.evaluate([[L, 0.0]])[0][1]
    err = np.abs(np.array(tips) - ref)
    rates = np.log2(err[:-1] / err[1:])
    assert np.all(rates > 1.7), rates


def test_very_soft_cantilever_under_gravity_carries_its_weight():
    """E = 10 kPa, 10 cm long, 1 cm thick: it sags by a large fraction of its length, and the support
    carries exactly the weight rho g A (per m of depth)."""
    L, H = 0.1, 0.01
    fem, mat = _cantilever(L, H, size=H / 4, degree=2, E=10 * kPa, nu=0.45)
    fem.add_gravity()
    traj = fem.solve(steps=5)
    weight = mat.density * 9.80665 * L * H
    assert traj.reactions["left"][-1][1] == pytest.approx(weight, rel=1e-6)
    tip = fem.evaluate([[L, 0.0]])[0]
    assert tip[1] < -0.3 * L  # a large deflection, not a linear one
    assert np.all(np.diff(traj.energy) > 0)


def test_diverging_load_is_reported_with_the_load_level():
    """Pull a soft strip far beyond what its material allows in one step budget: the solver must stop with
    ConvergenceError naming the load level, never return NaN."""
    L, H = 0.02, 0.01
    msh = Mesh.rectangle(L, H, size=0.005, center=(L / 2, H / 2))
    fem = Fem(msh, materials.NeoHookean(mu=1 * kPa, nu=0.3)).add_support("left", "x").add_support("bottom", "y")
    fem.add_displacement("right", -1.2 * L, "x")  # compress through zero length: impossible
    with pytest.raises(ConvergenceError, match=r"Reached t = 0\.\d+") as info:
        fem.solve(steps=2)
    traj = info.value.trajectory
    assert len(traj) >= 2 and np.all(np.isfinite(traj.displacement))
    assert 0.5 < info.value.load_level < 1.0 / 1.2


def test_bad_input_is_refused():
    msh = Mesh.rectangle(0.02, 0.01, size=0.005)
    mat = materials.Ecoflex0030()
    fem = Fem(msh, mat)
    with pytest.raises(MeshError, match="no region 'cavity_9'"):
        fem.add_pressure("cavity_9", 10 * kPa)
    with pytest.raises(MeshError, match="no region 'lefty'"):
        fem.add_support("lefty")
    with pytest.raises(ParameterError, match="component 'z' does not exist in 2D"):
        fem.add_support("left", "z")
    with pytest.raises(ParameterError, match="does not fit a 2D mesh"):
        Fem(msh, mat, formulation="3d")
    with pytest.raises(ParameterError, match="Taylor-Hood"):
        Fem(msh, mat, mixed=True, degree=1)
    with pytest.raises(ParameterError, match="must be a sorofem.materials.Material"):
        Fem(msh, "silicone")
    with pytest.raises(ParameterError, match="expected a value of shape \\(2,\\)"):
        fem.add_traction("right", 1.0)
    with pytest.raises(ParameterError, match="spring stiffness must be positive"):
        fem.add_spring("right", -1.0)
    fem.add_support("left").add_pressure("right", lambda t: float("nan"))
    with pytest.raises(ParameterError, match="non-finite value"):
        fem.solve(steps=1)


def test_unsupported_body_is_reported_not_nan():
    """No supports: the tangent is singular (rigid motion); the message says to add supports."""
    msh = Mesh.rectangle(0.02, 0.01, size=0.005)
    fem = Fem(msh, materials.NeoHookean(mu=1 * MPa)).add_traction("right", [1e3, 0.0])
    with pytest.raises(ConvergenceError, match="supports"):
        fem.solve(steps=1)


def test_cantilever_bending_frequencies_match_euler_bernoulli():
    """Slender plane-strain cantilever (L/H = 50): the first three frequencies within 2 % of
    f_k = (b_k L)^2 / (2 pi L^2) sqrt(E' I / (rho A)), E' = E / (1 - nu^2); Timoshenko corrections < 0.5 %."""
    from analytic import cantilever_frequencies
    L, H = 0.25, 0.005
    fem, mat = _cantilever(L, H, size=H / 2, degree=2)
    modes = fem.eigen(3)
    E_ps = mat.E / (1 - mat.nu**2)
    ref = cantilever_frequencies(L, E_ps, H**3 / 12, mat.density, H)
    np.testing.assert_allclose(modes.frequencies, ref, rtol=0.02)
    shape = modes.shapes[0]
    assert np.abs(shape[:, 1]).max() == pytest.approx(1.0)  # first mode: transverse


def _quarter_annulus(A, B, size, order=2):
    """Quarter of a ring A < r < B in x, y >= 0, with its inner arc tagged ``inner``."""
    from sorofem import sdf
    shape = (sdf.Circle(B) - sdf.Circle(A)) & sdf.Rectangle(B, B, center=(B / 2, B / 2))
    msh = Mesh.from_sdf(shape, size=size, order=order)
    return msh.add_region("inner", lambda x: np.hypot(x[0], x[1]) < A * (1 + 1e-3))


def _inner_radius_history(traj, A):
    i = np.argmin(np.hypot(traj.vertices[:, 0] - A, traj.vertices[:, 1]))
    return A + traj.displacement[:, i, 0]


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["plane_strain", "axisymmetric"])
def test_thick_cylinder_and_sphere_inflation_match_closed_form(formulation):
    """Incompressible Neo-Hookean (nu = 0.4999, Taylor-Hood), B = 2A, order-2 geometry: pressure vs inner
    radius along the whole path within 0.2 % (discretization error measured at ~1e-4)."""
    from analytic import cylinder_inflation_pressure, sphere_inflation_pressure
    A, B, mu = 0.01, 0.02, 100 * kPa
    ref = cylinder_inflation_pressure if formulation == "plane_strain" else sphere_inflation_pressure
    p_end = 40 * kPa if formulation == "plane_strain" else 60 * kPa
    fem = Fem(_quarter_annulus(A, B, A / 8), materials.NeoHookean(mu=mu, nu=0.4999), formulation=formulation,
              degree=2, mixed=True)
    fem.add_support("bottom", "y").add_pressure("inner", p_end)
    if formulation == "plane_strain":
        fem.add_support("left", "x")  # symmetry; in the axisymmetric case the axis condition is automatic
    traj = fem.solve(steps=6)
    a = _inner_radius_history(traj, A)
    assert a[-1] > 1.25 * A  # a large inflation
    p_ref = [ref(mu, A, B, ai) for ai in a[1:]]
    np.testing.assert_allclose(traj.inputs["pressure/inner"][1:], p_ref, rtol=2e-3)
    assert traj.newton_iterations[1:].max() <= 6


@pytest.mark.slow
def test_thin_balloon_limit_point_needs_volume_control():
    """A thin sphere (H/R = 0.1) has a pressure maximum near a = 1.43 A. Pressure control stops there with a
    ConvergenceError naming the load level; volume control follows the closed-form curve through it."""
    from scipy.optimize import minimize_scalar
    from analytic import sphere_inflation_pressure
    A, B, mu = 0.01, 0.011, 100 * kPa
    msh = _quarter_annulus(A, B, (B - A) / 3)
    mat = materials.NeoHookean(mu=mu, nu=0.4999)
    limit = minimize_scalar(lambda a: -sphere_inflation_pressure(mu, A, B, a), bounds=(1.05 * A, 2 * A),
                            method="bounded")
    p_lim = -limit.fun
    fem = Fem(msh, mat, formulation="axisymmetric", degree=2, mixed=True).add_support("bottom", "y")
    fem.add_pressure("inner", 1.2 * p_lim)
    with pytest.raises(ConvergenceError, match="Reached t = 0.83"):
        fem.solve(steps=12)
    fem = Fem(msh, mat, formulation="axisymmetric", degree=2, mixed=True).add_support("bottom", "y")
    fem.add_volume("inner", 2 / 3 * np.pi * (2**3 - 1) * A**3)  # hemisphere: inflate to a = 2 A
    traj = fem.solve(steps=8)
    a = _inner_radius_history(traj, A)
    p = traj.inputs["pressure/inner"]
    assert a[-1] == pytest.approx(2 * A, rel=2e-3)
    np.testing.assert_allclose(p[1:], [sphere_inflation_pressure(mu, A, B, ai) for ai in a[1:]], rtol=2e-3)
    assert p.max() == pytest.approx(p_lim, rel=5e-3) and p[-1] < 0.9 * p.max()  # through the maximum
    np.testing.assert_allclose(traj.cavity_volumes["inner"], 2 / 3 * np.pi * A**3 * (1 + 7 * traj.times), rtol=1e-8)


def test_trajectory_saves_a_snapshot_file_the_reader_understands(tmp_path):
    from sorofem.snapshots import Snapshots
    L, H = 0.02, 0.01
    msh = Mesh.rectangle(L, H, size=0.0025, center=(L / 2, H / 2))
    fem = Fem(msh, materials.NeoHookean(E=1 * MPa, nu=0.3)).add_support("left", "x").add_support("bottom", "y")
    traj = fem.add_displacement("right", 0.2 * L, "x").solve(steps=3)
    snap = Snapshots(traj.save(tmp_path / "case.h5"))
    assert snap.n_steps == 4 and snap.cell_type == "triangle" and snap.time_kind == "load"
    np.testing.assert_allclose(snap.displacement(), traj.displacement)
    F = snap.deformation_gradient(3)
    np.testing.assert_allclose(F[:, 0, 0], 1.2, rtol=1e-8)  # homogeneous stretch recovered from the file
    np.testing.assert_allclose(snap.reactions["left"], traj.reactions["left"])
    assert snap.metadata["formulation"] == "plane_strain"


def test_von_mises_of_uniaxial_tension_is_the_axial_cauchy_stress():
    mat = LAWS["neo-hookean"](nu=0.45)
    P, fem, traj = _uniaxial_box(mat, 1.5)
    _, t = _lateral_free_stress(mat, 1.5)
    sigma11 = mat.cauchy(np.diag([1.5, t, t]))[0, 0]
    np.testing.assert_allclose(traj.von_mises[-1], sigma11, rtol=1e-6)
    assert traj.max_von_mises[-1] == pytest.approx(sigma11, rel=1e-6) and traj.max_von_mises[0] == pytest.approx(0, abs=1e-6)


def _symmetric_block(material):
    L = 0.01
    msh = Mesh.box(L, L, L, size=L / 2, center=(L / 2,) * 3, cell="hexahedron")
    msh.add_region("all", lambda x: np.ones(x.shape[1], dtype=bool), kind="cells")
    fem = Fem(msh, material).add_support("left", "x").add_support("front", "y").add_support("bottom", "z")
    return fem, L


def test_free_expansion_is_stress_free_growth():
    fem, L = _symmetric_block(materials.NeoHookean(mu=50 * kPa, nu=0.45))
    traj = fem.add_expansion("all", 0.331).solve(steps=2)  # theta = 1.331 = 1.1^3
    np.testing.assert_allclose(fem.evaluate([[L, L, L]])[0], [0.1 * L] * 3, rtol=1e-8)
    assert traj.max_von_mises[-1] < 1e-6 * 50 * kPa
    assert traj.inputs["expansion/all"][-1] == pytest.approx(0.331)


def test_constrained_expansion_gives_the_hydrostatic_stress_of_the_law():
    """All faces held: F = I, F_e = theta^(-1/3) I, P = theta^(2/3) P_law(F_e); the wall at x = 0 pushes on
    the body with -P11 L^2."""
    mat = materials.NeoHookean(mu=50 * kPa, nu=0.45)
    fem, L = _symmetric_block(mat)
    fem.add_support("right", "x").add_support("back", "y").add_support("top", "z")
    traj = fem.add_expansion("all", 0.2).solve(steps=1)
    theta = 1.2
    P = theta ** (2 / 3) * mat.pk1(theta ** (-1 / 3) * np.eye(3))[0, 0]
    assert P < 0  # compression
    assert traj.reactions["left"][-1][0] == pytest.approx(-P * L**2, rel=1e-8)  # the wall pushes back
    with pytest.raises(ParameterError, match="must stay > -1"):
        _symmetric_block(mat)[0].add_expansion("all", lambda t: -1.5).solve(steps=1)


def test_tendon_tip_moment_matches_beam_theory():
    """A tendon tied at the tip at offset d above the neutral axis: for a small tension T the tip force -T e_x
    is a moment T d, so the tip rises by w = T d L^2 / (2 E' I) (plus a negligible axial shortening)."""
    L, H, T = 0.1, 0.01, 1e-2
    fem, mat = _cantilever(L, H, size=H / 4, degree=2)
    d = H / 4
    xs = np.linspace(0, L, 5)
    fem.add_tendon(np.column_stack([xs, np.full_like(xs, d)]), T)
    traj = fem.solve(steps=1)
    E_ps = mat.E / (1 - mat.nu**2)
    w = T * d * L**2 / (2 * E_ps * H**3 / 12)
    assert fem.evaluate([[L, 0.0]])[0][1] == pytest.approx(w, rel=2e-2)
    assert traj.inputs["tension/0"][-1] == pytest.approx(T)
    with pytest.raises(ParameterError, match="at least two anchor points"):
        fem.add_tendon([[0.0, 0.0]], 1.0)


@pytest.mark.slow
def test_tendon_curls_a_soft_finger_past_ninety_degrees():
    """Large tension: the guides follow the bending (forces along the current cable) and Newton converges
    with the modified tangent; the tip turns by more than 90 degrees."""
    L, H = 0.08, 0.008
    fem, mat = _cantilever(L, H, size=H / 4, degree=2, E=200 * kPa, nu=0.45)
    xs = np.linspace(0, L, 9)
    fem.add_tendon(np.column_stack([xs, np.full_like(xs, H / 4)]), 150.0)  # T d L / (E'I) ~ 2.2 rad
    traj = fem.solve(steps=10, max_iterations=40)
    top, bottom = fem.evaluate([[L, H / 2]])[0] + [L, H / 2], fem.evaluate([[L, -H / 2]])[0] + [L, -H / 2]
    angle = np.degrees(np.arctan2(-(top[0] - bottom[0]), top[1] - bottom[1]))  # rotation of the tip face
    assert angle > 90
    assert np.median(traj.newton_iterations[1:]) <= 5  # quadratic: the tendon forces are in the tangent
    assert np.isfinite(traj.displacement).all()


@pytest.mark.parametrize("dim", [2, 3])
def test_xdmf_and_png_outputs(tmp_path, dim):
    import meshio
    if dim == 2:
        msh = Mesh.rectangle(0.02, 0.01, size=0.005, center=(0.01, 0.005), cell="quadrilateral")
        fem = Fem(msh, materials.Ecoflex0030()).add_support("left").add_gravity()
    else:
        msh = Mesh.box(0.02, 0.01, 0.01, size=0.005, center=(0.01, 0.005, 0.005))
        fem = Fem(msh, materials.Ecoflex0030()).add_support("left").add_gravity()
    traj = fem.solve(steps=2)
    traj.write_xdmf(tmp_path / "r.xdmf")
    traj.save(tmp_path / "r.h5")   # the snapshot beside it leaves the XDMF's data file alone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5", "r.xdmf", "r.xdmf.h5"]
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "r.xdmf")) as r:
        points, cells = r.read_points_cells()
        t, point_data, cell_data = r.read_data(2)
    assert t == pytest.approx(1.0)
    u = point_data["displacement"]
    assert u.shape == (len(traj.vertices), 3)   # 3 components in 2D too (ParaView warps 3-vectors only)
    np.testing.assert_allclose(u[:, :dim], traj.displacement[2])
    assert not u[:, dim:].any()
    np.testing.assert_allclose(cell_data["von_mises"][0], traj.von_mises[2])
    import json
    import xml.etree.ElementTree as ET
    info = ET.parse(tmp_path / "r.xdmf").getroot().find("Domain/Information")
    assert json.loads(info.get("Value")) == {"time": "1", "displacement": "m", "von_mises": "Pa"}
    png = traj.plot(tmp_path / "s.png")
    assert png.stat().st_size > 5000


def test_iterative_solver_option_matches_the_direct_solver():
    """GMRES + GAMG (with the rigid-body near-nullspace) gives the direct solver's answer on a 3D problem."""
    msh = Mesh.box(0.04, 0.01, 0.01, size=0.0025, center=(0.02, 0.0, 0.0))
    tips = []
    for options in (None, {"ksp_type": "gmres", "pc_type": "gamg", "ksp_rtol": 1e-12, "ksp_max_it": 500}):
        fem = Fem(msh, materials.NeoHookean(E=200 * kPa, nu=0.45), petsc_options=options)
        traj = fem.add_support("left").add_gravity().solve(steps=2)
        tips.append(fem.evaluate([[0.04, 0.0, 0.0]])[0])
        assert traj.newton_iterations[1:].max() <= 6
    np.testing.assert_allclose(tips[1], tips[0], rtol=1e-6)


def test_two_materials_in_series_add_their_compliances():
    """A bar of two halves (E1, E2), nu = 0, pulled by a small traction q: u(L) = q (L1/E1 + L2/E2)."""
    L, A = 0.02, 0.005
    msh = Mesh.box(L, A, A, size=A / 2, center=(L / 2, A / 2, A / 2), cell="hexahedron")
    msh.add_region("stiff", lambda x: x[0] > L / 2, kind="cells")
    E1, E2, q = 100 * kPa, 400 * kPa, 10.0
    fem = Fem(msh, materials.NeoHookean(E=E1, nu=0.0))
    fem.add_material("stiff", materials.NeoHookean(E=E2, nu=0.0))
    fem.add_support("left", "x").add_support("front", "y").add_support("bottom", "z")
    fem.add_traction("right", [q, 0.0, 0.0]).solve(steps=1)
    expected = q * (L / 2 / E1 + L / 2 / E2)
    assert fem.evaluate([[L, A, A]])[0][0] == pytest.approx(expected, rel=1e-3)  # O(strain) = 1e-4 nonlinearity
    assert fem.evaluate([[L / 2, A, A]])[0][0] == pytest.approx(q * L / 2 / E1, rel=1e-3)


def test_springs_to_ground_carry_the_load():
    """A block on distributed springs k under a small top traction q (nu = 0): u_top = -q/k - q h/E."""
    h = 0.01
    msh = Mesh.box(h, h, h, size=h / 2, center=(0, 0, h / 2), cell="hexahedron")
    E, k, q = 100 * kPa, 1e7, 10.0
    fem = Fem(msh, materials.NeoHookean(E=E, nu=0.0)).add_spring("bottom", k)
    fem.add_traction("top", [0.0, 0.0, -q]).solve(steps=1)
    assert fem.evaluate([[0.0, 0.0, h]])[0][2] == pytest.approx(-q / k - q * h / E, rel=1e-3)


def test_many_cavities_each_with_its_own_pressure_and_volume():
    """16 holes, every one pressurized: the loaded-region markers scale with the regions that occur (no
    limit on their number), and each cavity reports its own volume."""
    from sorofem import sdf
    pitch, r = 0.01, 0.003
    holes = sdf.Circle(r, center=(pitch / 2, pitch / 2)).repeat((pitch, pitch), (4, 4))
    msh = Mesh.from_sdf(sdf.Rectangle(4 * pitch, 4 * pitch, center=(2 * pitch, 2 * pitch)) - holes, size=0.0015)
    assert len(msh.cavities) == 16
    fem = Fem(msh, materials.NeoHookean(E=100 * kPa, nu=0.45)).add_support("bottom")
    for k, cavity in enumerate(msh.cavities):
        fem.add_pressure(cavity, 100.0 * (1 + k % 2))
    traj = fem.solve(steps=1)
    v0 = np.array([traj.cavity_volumes[c][0] for c in msh.cavities])
    v1 = np.array([traj.cavity_volumes[c][1] for c in msh.cavities])
    np.testing.assert_allclose(v0, [msh.cavity_volume(c) for c in msh.cavities], rtol=1e-10)
    np.testing.assert_allclose(v0, np.pi * r**2, rtol=5e-2)  # polygonal holes of the order-1 mesh
    assert np.all(v1 > v0)
    assert np.mean(v1[1::2] / v0[1::2]) > np.mean(v1[0::2] / v0[0::2])  # double pressure, larger growth


def test_stability_monitor_tracks_the_lowest_eigenvalue_through_euler_buckling():
    """A slender strut (L/H = 20), clamped at the bottom, its top pushed down by a uniform displacement (so the
    top cannot rotate but may sway): the lowest eigenvalue of K phi = lambda M phi falls and crosses zero at
    the Euler strain of the clamped-sliding column, pi^2 H^2 / (12 L^2), within 5 % (shear and finite-strain
    corrections are O(H/L)^2)."""
    L, H = 0.1, 0.005
    msh = Mesh.rectangle(H, L, size=H / 2, center=(0.0, L / 2), cell="quadrilateral")
    fem = Fem(msh, materials.NeoHookean(E=1 * MPa, nu=0.3), degree=2).add_support("bottom")
    eps_cr = np.pi**2 * H**2 / (12 * L**2)
    fem.add_displacement("top", -1.5 * eps_cr * L, "y")
    traj = fem.solve(steps=16, monitor_stability=True)
    lam = np.array(traj.lowest_eigenvalue)
    assert lam[0] > 0 and lam[-1] < 0 and np.all(np.diff(lam[: len(lam) // 2]) < 0)
    k = np.flatnonzero(lam < 0)[0]
    t_cr = np.interp(0.0, [lam[k], lam[k - 1]], [traj.times[k], traj.times[k - 1]])
    assert 1.5 * eps_cr * t_cr == pytest.approx(eps_cr, rel=5e-2)


@pytest.mark.parametrize("mixed", [False, True])
def test_the_cavity_volume_of_a_p2_field_is_exact_on_a_3d_box_cavity(mixed):
    """The measure behind ``cavity_volumes`` (issue 24: the 3D PneuNet's volume did not converge): on a box cavity
    (straight facets: the rest geometry is exact), the quadratic displacement u = (a x^2, b y z, c x y), which P2
    holds exactly, encloses int_cavity det F dX in closed form, det F = (1 + 2 a x)(1 + b z - b c x y); the
    boundary integral -1/3 oint x . cof(F) N dA is of degree 4 on a facet, which the quadrature degree (4 for
    P2) integrates exactly (degree 2 misses by 1e-4): the measure agrees to round-off, so a volume that does not
    converge with the mesh is the displacement field's error, not the measure's."""
    import dolfinx.fem
    from sorofem import sdf

    lo, hi = np.array([-4e-3, -3e-3, -2e-3]), np.array([5e-3, 2e-3, 3e-3])          # the cavity [m]
    body = sdf.Box((20e-3, 14e-3, 12e-3)) - sdf.Box(tuple(hi - lo), center=tuple((hi + lo) / 2))
    fem = Fem(Mesh.from_sdf(body, size=4e-3), materials.NeoHookean(mu=100 * kPa, nu=0.45), degree=2, mixed=mixed)
    a, b, c = 30.0, 40.0, 50.0                                                        # [1/m]
    u = fem.forms.state.sub(0) if mixed else fem.forms.state
    u.interpolate(lambda x: np.vstack([a * x[0] ** 2, b * x[1] * x[2], c * x[0] * x[1]]))
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    ix0 = (x1 - x0) + a * (x1**2 - x0**2)                                  # int (1 + 2 a x) dx
    ix1 = (x1**2 - x0**2) / 2 + 2 * a * (x1**3 - x0**3) / 3                # int (1 + 2 a x) x dx
    exact = ix0 * (y1 - y0) * ((z1 - z0) + b * (z1**2 - z0**2) / 2) - b * c * ix1 * (y1**2 - y0**2) / 2 * (z1 - z0)
    v0 = np.prod(hi - lo)
    got = dolfinx.fem.assemble_scalar(fem.forms.volumes["cavity_0"])
    assert abs(exact - v0) > 0.05 * v0                                                # a change the test can see
    assert got == pytest.approx(exact, rel=1e-10)
