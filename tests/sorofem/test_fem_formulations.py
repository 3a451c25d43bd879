"""Plane stress, the mixed (Taylor-Hood) formulation with every material, its pressure spaces that may jump
between materials, and its eigen-analysis, against
published and closed-form references; the locking warning of displacement-only P1 elements.

The refinement study of Cook's membrane to its converged value is ``tests/benchmarks/bench_cook.py``; here the
coarse levels are checked against a reference table.
"""
import warnings

import numpy as np
import pytest

from fem_cases import COOK_REFERENCE, cook_displacement, vortex_eigenvalue
from sorofem import materials
from sorofem.errors import ParameterError
from sorofem.fem import Fem, LockingWarning
from sorofem.mesh import Mesh

# --------------------------------------------------------------------------------------------- Cook's membrane
#: Measured values of this code (P2 triangles, n x n grid; bench_cook.py prints the sequence to 64 x 64). The
#: test checks the coarse levels against them to 1e-4 (the table's rounding; solver round-off is ~1e-12), and
#: against the published converged value with the discretization error they must have: on these coarse grids the
#: error falls by ~5 per halving of h (measured 5.6 and 4.9, asserted > 3; the observed order, 2.5 here, drops
#: to 1.4 on fine grids where the stress singularities at the ends of the clamped edge dominate); at 8 x 8 it
#: is 0.41 %, asserted < 1 %.
COOK_P2 = {2: 21.2514, 4: 23.4761, 8: 23.8607}


def test_cook_membrane_plane_stress_converges_to_the_published_displacement():
    values = {n: cook_displacement(n, 2)[0] for n in COOK_P2}
    for n, v in values.items():
        assert v == pytest.approx(COOK_P2[n], abs=1e-4)
    errors = [COOK_REFERENCE - values[n] for n in sorted(values)]
    assert all(e > 0 for e in errors)                          # from below (a displacement method is too stiff)
    assert errors[0] / errors[1] > 3 and errors[1] / errors[2] > 3   # converging (5.6 and 4.9 measured)
    assert values[8] == pytest.approx(COOK_REFERENCE, rel=0.01)


def test_cook_membrane_reaction_and_plane_strain_differ_as_the_moduli_do():
    """The support carries the unit shear; plane strain is stiffer (E' = E / (1 - nu^2) for bending, 9/8 here)."""
    v_stress, traj = cook_displacement(8, 2)
    np.testing.assert_allclose(traj.reactions["left"][-1], [0.0, -1.0], atol=1e-9)
    v_strain, _ = cook_displacement(8, 2, formulation="plane_strain")
    assert 1.05 < v_stress / v_strain < 1.2


# ------------------------------------------------------------------------------------ homogeneous plane stress
def _strip(L=0.02, H=0.01, size=0.005, degree=1, **kw):
    msh = Mesh.rectangle(L, H, size=size, center=(L / 2, H / 2))
    return Fem(msh, kw.pop("material"), degree=degree, **kw)


def _uniaxial_free(m, lam):
    """3D uniaxial stress of the numpy law (both lateral stresses zero): (P11, lateral stretch)."""
    from scipy.optimize import brentq
    t = brentq(lambda t: m.pk1(np.diag([lam, t, t]))[1, 1], 0.2, 2.0, xtol=1e-15)
    return m.pk1(np.diag([lam, t, t]))[0, 0], t


@pytest.mark.parametrize("make", [
    lambda: materials.LinearElastic(E=1e6, nu=0.3),
    lambda: materials.NeoHookean(E=1e6, nu=0.45),
    lambda: materials.NeoHookean(mu=3e5, lmbda=1e6, form="coupled"),
    lambda: materials.Yeoh(1e5, -1e3, 5e2, nu=0.49),
], ids=["linear", "neo-hookean", "neo-hookean-coupled", "yeoh"])
def test_plane_stress_uniaxial_tension_is_the_3d_uniaxial_state(make):
    """A plane-stress strip pulled along x is in 3D uniaxial stress (sigma_22 = sigma_33 = 0): its force per unit
    thickness is P11 H and its width shrinks by the law's lateral stretch. Homogeneous: exact in P1 with a DG0
    thickness strain, to solver accuracy."""
    m = make()
    L, H = 0.02, 0.01
    lam = 1.001 if isinstance(m, materials.LinearElastic) else 1.5
    fem = _strip(material=m, formulation="plane_stress")
    fem.add_support("left", "x").add_support("bottom", "y").add_displacement("right", (lam - 1) * L, "x")
    traj = fem.solve(steps=2)
    P11, t = _uniaxial_free(m, lam)
    assert -traj.reactions["left"][-1][0] == pytest.approx(P11 * H, rel=1e-6)
    assert 1 + fem.evaluate([[L, H]])[0][1] / H == pytest.approx(t, rel=1e-8)


# ------------------------------------------------------------------------------ mixed formulation, all laws
ALL_LAWS = {
    "linear": lambda nu: materials.LinearElastic(E=3e5, nu=nu),
    "neo-hookean": lambda nu: materials.NeoHookean(mu=1e5, nu=nu),
    "neo-hookean-coupled": lambda nu: materials.NeoHookean(mu=1e5, nu=nu, form="coupled"),
    "mooney-rivlin": lambda nu: materials.MooneyRivlin(4e4, 1e4, nu=nu),
    "yeoh": lambda nu: materials.Yeoh(5e4, -1e3, 5e2, nu=nu),
}


@pytest.mark.parametrize("law", sorted(ALL_LAWS))
def test_mixed_plane_strain_stretch_matches_the_incompressible_closed_form(law):
    """nu = 0.4999, plane strain, pulled along x with the top free: F = diag(l, 1/l, 1) in the incompressible
    limit, P11 = 2 (l - l^-3)(W1 + W2) (hyperelastic; l = 1.5) or 4 mu eps (linear, eps = 1e-3, where
    E' = E/(1 - nu^2) = 4 mu at nu = 1/2). Within the O(mu/kappa) ~ 1e-3 compressibility of the model."""
    m = ALL_LAWS[law](0.4999)
    L, H = 0.02, 0.01
    linear = law == "linear"
    lam = 1.001 if linear else 1.5
    fem = _strip(material=m, degree=2, mixed=True, size=0.01)
    fem.add_support("left", "x").add_support("bottom", "y").add_displacement("right", (lam - 1) * L, "x")
    traj = fem.solve(steps=1 if linear else 3)
    if linear:
        ref = 4 * m.mu * (lam - 1)
    else:
        W1, W2 = m._dw(lam**2 + lam**-2 + 1, lam**2 + lam**-2 + 1)
        ref = 2 * (lam - lam**-3) * (W1 + W2)
    assert -traj.reactions["left"][-1][0] / H == pytest.approx(ref, rel=2e-3)
    assert 1 + fem.evaluate([[L, H]])[0][1] / H == pytest.approx(1 / lam, rel=1e-3)   # area preserved


def test_mixed_linear_elastic_uniaxial_strain_is_exact():
    """Uniaxial strain eps (lateral faces on rollers): P11 = (lambda + 2 mu) eps exactly, even at nu = 0.4999
    where lambda = 1667 mu; the displacement formulation gives the same on this homogeneous state."""
    m = materials.LinearElastic(E=3e5, nu=0.4999)
    L, H, eps = 0.02, 0.01, 1e-3
    for mixed in (True, False):
        fem = _strip(material=m, degree=2, mixed=mixed, size=0.01)
        fem.add_support("left", "x").add_support("bottom", "y").add_support("top", "y")
        traj = fem.add_displacement("right", eps * L, "x").solve(steps=1)
        assert -traj.reactions["left"][-1][0] / H == pytest.approx((m.lmbda + 2 * m.mu) * eps, rel=1e-8)


@pytest.mark.parametrize("mixed", [False, True])
def test_coupled_neo_hookean_uniaxial_strain_matches_its_closed_form(mixed):
    """F = diag(a, 1, 1) (lateral faces on rollers, plane strain): P11 = mu (a - 1/a) + lambda ln(a)/a and the
    roller on top carries P22 L = lambda ln(a) L. The mixed form of this law is exact (p = lambda ln J), so both
    formulations give it to solver accuracy on the homogeneous state."""
    mu, lmbda, a = 1e5, 4e5, 1.4
    m = materials.NeoHookean(mu=mu, lmbda=lmbda, form="coupled")
    L, H = 0.02, 0.01
    fem = _strip(material=m, degree=2, mixed=mixed, size=0.01)
    fem.add_support("left", "x").add_support("bottom", "y").add_support("top", "y")
    traj = fem.add_displacement("right", (a - 1) * L, "x").solve(steps=3)
    assert -traj.reactions["left"][-1][0] / H == pytest.approx(mu * (a - 1 / a) + lmbda * np.log(a) / a, rel=1e-8)
    assert traj.reactions["top"][-1][1] / L == pytest.approx(lmbda * np.log(a), rel=1e-8)  # reference length


def test_mixed_newton_converges_from_rest_for_stiff_bodies_and_measures_each_field_in_its_unit():
    """A P2 mixed cantilever (L/H = 20, neo-Hookean, nu = 0.49) under a small tip load. Newton's correction test
    takes the displacement [m] and the pressure [Pa] separately: with one norm over both, the pressure's
    round-off at rest (about 1e-16 of the bulk modulus) never fell below the metre tolerance (1e-9 of the
    diagonal) and the state at t = 0 did not converge (25 iterations at |du| ~ 1e-6 at E = 2 GPa). Linear
    response: the tip deflection is the same fraction of Timoshenko's plane-strain value
    PL^3/(3E'I) + PL/(kappa G A) at E = 2 MPa and 2 GPa (to the solver's tolerance, 1e-6), and within 2 % of
    it: 0.9868 with two elements through the thickness, 0.9910 and 0.9921 on meshes 2x and 4x finer (the
    rest is the clamped face's restraint of warping, which beam theory leaves out)."""
    nu, L, H = 0.49, 0.04, 0.002
    ratios = []
    for E in (2e6, 2e9):
        fem = Fem(Mesh.rectangle(L, H, size=H / 2, center=(L / 2, 0.0)), materials.NeoHookean(E=E, nu=nu),
                  degree=2, mixed=True)
        Ep, I, G = E / (1 - nu ** 2), H ** 3 / 12, E / (2 * (1 + nu))
        P = 1e-3 * 3 * Ep * I / L ** 2                      # tip deflection ~1e-3 L: linear
        traj = fem.add_support("left").add_traction("right", [0.0, -P / H]).solve(steps=1)
        assert traj.newton_iterations[0] <= 1               # at rest
        deflection = -fem.evaluate([[L * (1 - 1e-12), 0.0]])[0][1]
        ratios.append(deflection / (P * L ** 3 / (3 * Ep * I) + P * L / (5 / 6 * G * H)))
    assert ratios[0] == pytest.approx(ratios[1], rel=1e-6)
    assert ratios[0] == pytest.approx(1.0, rel=0.02)


# ------------------------------------------------------------------ a pressure that jumps between materials
def _bimaterial_stretch(mixed, a=1.3):
    """Two coupled neo-Hookean layers (bottom half soft and nearly incompressible, top half stiffer and
    compressible), plane strain, pulled to stretch ``a`` along x with the top free. Returns (fem, trajectory)."""
    L, H = 0.02, 0.01
    msh = Mesh.rectangle(L, H, size=0.0025, center=(L / 2, H / 2))     # a grid line at y = H/2
    msh.add_region("bottom_layer", ((0.0, 0.0), (L, H / 2)), kind="cells")
    soft = materials.NeoHookean(mu=1e5, lmbda=5e6, form="coupled")
    stiff = materials.NeoHookean(mu=6e5, lmbda=1.2e6, form="coupled")
    fem = Fem(msh, stiff, degree=2, mixed=mixed).add_material("bottom_layer", soft)
    fem.add_support("left", "x").add_support("bottom", "y").add_displacement("right", (a - 1) * L, "x")
    return fem, fem.solve(steps=3), (soft, stiff)


def _plane_strain_uniaxial(m, a):
    """F = diag(a, t, 1) with P22 = mu (t - 1/t) + lambda ln(a t)/t = 0: (P11, t, pressure lambda ln J)."""
    from scipy.optimize import brentq
    t = brentq(lambda t: m.pk1(np.diag([a, t, 1.0]))[1, 1], 0.3, 1.5, xtol=1e-15)
    return m.pk1(np.diag([a, t, 1.0]))[0, 0], t, m.lmbda * np.log(a * t)


@pytest.mark.parametrize("mixed", ["per_material", "p0"])
def test_mixed_pressure_that_may_jump_is_exact_on_a_stretched_bimaterial_strip(mixed):
    """Closed form: each layer is homogeneous, F_i = diag(a, t_i, 1) with P22 = 0 (coupled neo-Hookean, whose
    mixed form is exact: p = lambda ln J), so the displacement is piecewise linear (P2 holds it exactly) and the
    pressure is constant per layer with a jump at y = H/2 (4.0e4 Pa below, 1.5e5 Pa above at a = 1.3). A
    pressure that may jump there (one P1 field per material, or P0) gives the force and the top's displacement
    to solver accuracy (4e-16 measured); Taylor-Hood's continuous pressure cannot hold the jump and misses both
    (force 1.6 %, top 1.4 % measured on this 8 x 4 grid)."""
    L, H, a = 0.02, 0.01, 1.3
    fem, traj, (soft, stiff) = _bimaterial_stretch(mixed, a)
    (P_soft, t_soft, p_soft), (P_stiff, t_stiff, p_stiff) = (_plane_strain_uniaxial(m, a) for m in (soft, stiff))
    assert abs(p_soft - p_stiff) > 0.5 * abs(p_soft)                    # a real jump
    force = (P_soft + P_stiff) * H / 2
    top = (t_soft - 1) * H / 2 + (t_stiff - 1) * H / 2
    assert -traj.reactions["left"][-1][0] == pytest.approx(force, rel=1e-8)
    assert fem.evaluate([[L, H]])[0][1] == pytest.approx(top, rel=1e-8)
    assert fem.evaluate([[L, H / 4]])[0][1] == pytest.approx((t_soft - 1) * H / 4, rel=1e-8)
    th, th_traj, _ = _bimaterial_stretch("taylor_hood", a)
    assert abs(-th_traj.reactions["left"][-1][0] / force - 1) > 1e-3
    assert abs(th.evaluate([[L, H]])[0][1] / top - 1) > 1e-3


def test_per_material_pressure_on_one_material_is_taylor_hood():
    """With one material the per-material space is the Taylor-Hood space: the same unknowns and solution."""
    msh = Mesh.rectangle(0.04, 0.004, size=0.002, center=(0.02, 0.0))
    tips = []
    for mixed in (True, "per_material"):
        fem = Fem(msh, materials.NeoHookean(E=1e6, nu=0.49), degree=2, mixed=mixed)
        fem.add_support("left").add_traction("right", [0.0, -2e3]).solve(steps=2)
        tips.append((fem.forms.state.x.array.size, fem.evaluate([[0.04 * (1 - 1e-12), 0.0]])[0]))
    assert tips[0][0] == tips[1][0]
    np.testing.assert_allclose(tips[0][1], tips[1][1], rtol=1e-10)


# ------------------------------------------------------------------------- free vibration without locking
@pytest.mark.parametrize("law", ["linear", "neo-hookean"])
def test_mixed_free_vibration_has_the_compressible_frequency_as_nu_goes_to_one_half(law):
    """Taylor-Hood: the shear mode's eigenvalue stays at its closed form (the same as for a compressible body)
    from nu = 0.3 to 0.499999, within the P2 discretization error at 8 x 8 (3e-4 measured, bound 2e-3).
    Displacement-only elements lock: P1 is more than twice too stiff at nu = 0.4999 (3.13 measured), P2's
    error grows with nu (0.05 % at 0.3, 1.6 % at 0.4999)."""
    make = ALL_LAWS[law]
    for nu in (0.3, 0.49, 0.4999, 0.499999):
        assert vortex_eigenvalue(make(nu), 2, True) == pytest.approx(1.0, rel=2e-3)
    if law == "linear":
        assert vortex_eigenvalue(make(0.4999), 1, False) > 2.0
        p2 = [vortex_eigenvalue(make(nu), 2, False) for nu in (0.3, 0.4999)]
        assert p2[1] - 1 > 10 * (p2[0] - 1) > 0


def test_plane_stress_eigen_analysis_has_the_shear_mode():
    """Plane stress on rollers: the shear mode is the same divergence-free field (no out-of-plane strain)."""
    assert vortex_eigenvalue(materials.LinearElastic(E=2.6, nu=0.3), 2, False, "plane_stress") == \
        pytest.approx(1.0, rel=2e-3)


# ------------------------------------------------------------------------------ warnings and refusals
def test_p1_near_incompressibility_warns_and_names_the_fix():
    msh = Mesh.rectangle(0.02, 0.01, size=0.005)
    with pytest.warns(LockingWarning, match="mixed=True"):
        Fem(msh, materials.NeoHookean(mu=1e5, nu=0.4999))
    fem = Fem(msh, materials.NeoHookean(mu=1e5, nu=0.45))
    with pytest.warns(LockingWarning, match="degree=2, mixed=True"):
        msh.add_region("half", lambda x: x[0] < 0.01, kind="cells")
        fem.add_material("half", materials.LinearElastic(E=1e6, nu=0.499))
    with warnings.catch_warnings():
        warnings.simplefilter("error", LockingWarning)
        Fem(msh, materials.NeoHookean(mu=1e5, nu=0.4999), degree=2, mixed=True)
        Fem(msh, materials.NeoHookean(mu=1e5, nu=0.4999), formulation="plane_stress")
        Fem(msh, materials.Ecoflex0030())                     # the presets' nu = 0.49 stays below the threshold


def test_unsupported_combinations_are_refused_with_the_alternative():
    msh = Mesh.rectangle(0.02, 0.01, size=0.005)
    m = materials.NeoHookean(mu=1e5)
    with pytest.raises(ParameterError, match="plane stress does not lock"):
        Fem(msh, m, degree=2, mixed=True, formulation="plane_stress")
    with pytest.raises(ParameterError, match="pressure space"):
        Fem(msh, m, degree=2, mixed="P1")
    with pytest.raises(ParameterError, match="does not fit a 3D mesh"):
        Fem(Mesh.box(0.02, 0.01, 0.01, size=0.01), m, formulation="plane_stress")
    fem = Fem(msh, m, formulation="plane_stress").add_support("left")
    with pytest.raises(ParameterError, match="eigen"):
        fem.simulate(0.01, 0.001)
    fem.add_tendon([(-0.009, 0.0), (0.009, 0.0)], 1.0)
    with pytest.raises(ParameterError, match="tendons act on the displacement formulation"):
        fem.solve(steps=1)


@pytest.mark.mpi
def test_plane_stress_and_mixed_eigen_give_the_serial_figures_on_two_ranks():
    """Under ``mpirun -n 2``: the DG thickness strain and the condensed pressure are distributed like the
    displacement; Cook's membrane and the shear-mode eigenvalues equal the serial ones."""
    from mpi4py import MPI
    assert MPI.COMM_WORLD.size == 2
    v, _ = cook_displacement(8, 2)
    assert v == pytest.approx(COOK_P2[8], abs=1e-4)
    assert vortex_eigenvalue(ALL_LAWS["neo-hookean"](0.4999), 2, True) == pytest.approx(1.0, rel=2e-3)
    assert vortex_eigenvalue(ALL_LAWS["linear"](0.3), 2, False, "plane_stress") == pytest.approx(1.0, rel=2e-3)


@pytest.mark.mpi
def test_per_material_pressure_is_exact_on_two_ranks():
    """Under ``mpirun -n 2``: the unknowns of a material's pressure that touch its cells only on the other rank
    stay free, so the stretched bimaterial strip is still exact."""
    from mpi4py import MPI
    assert MPI.COMM_WORLD.size == 2
    L, H, a = 0.02, 0.01, 1.3
    fem, traj, mats = _bimaterial_stretch("per_material", a)
    (P_soft, t_soft, _), (P_stiff, t_stiff, _) = (_plane_strain_uniaxial(m, a) for m in mats)
    assert fem.evaluate([[L, H]])[0][1] == pytest.approx((t_soft - 1) * H / 2 + (t_stiff - 1) * H / 2, rel=1e-8)
    if MPI.COMM_WORLD.rank == 0:
        assert -traj.reactions["left"][-1][0] == pytest.approx((P_soft + P_stiff) * H / 2, rel=1e-8)
