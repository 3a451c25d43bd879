"""Validation of the holonomic end constraints of beam statics (soroshapes.constraints) against the rod literature.

Cases and tolerances:

* Euler load of a strut clamped at both ends, :math:`P_{cr} = 4\\pi^2 EI/L^2`, found where the lowest eigenvalue
  of the stiffness on the constraint manifold changes sign along the straight branch (secant iterations on the
  end shortening). The basis is Chebyshev with 8 bending modes (the clamped-clamped mode's curvature
  :math:`\\cos 2\\pi s/L` and the two end conditions need about 6; measured error 1.4e-4 with 8 modes and 20
  segments, 1.3e-3 with 10 segments). The rod is extensible (one stretch mode: it carries the end shortening of
  the straight state), which moves the load by :math:`P/EA \\approx 4\\times10^{-5}` (the exact extensible
  condition is :math:`P(1 - P/EA) = P_E`). Tolerance 1e-3, ten times below the issue's 1 %.
* The post-buckled shape against the clamped-clamped elastica (:func:`analytic.clamped_elastica`, elliptic
  integrals) at modulus k = 0.3 (shortening 9.1 % of L, midpoint deflection 18.7 % of L), reached by leaving the
  straight branch along the lowest mode at k = 0.1 and continuing in the shortening. Chebyshev(10), 20 segments:
  measured largest position error 3.7e-5 L and axial force error 1.0e-4 (the extension P/EA = 4e-5 of the
  inextensible reference is part of it); tolerances 2e-4 L and 5e-4.
* Twisting instability of a rod clamped at both ends under an end rotation (zero axial force). Linearizing
  :math:`m = EI\\, t \\times t' + M t`, :math:`m' + r' \\times n = 0` about the straight rod with the complex
  deflection :math:`w = y + iz` gives :math:`w''' - i(M/EI) w'' = \\mathrm{const}`, so
  :math:`w \\in \\mathrm{span}\\{1, s, s^2, e^{iMs/EI}\\}`; the four clamped conditions have a non-trivial solution
  when :math:`\\tan(ML/2EI) = ML/2EI`, first at :math:`M_{cr} = 8.9868\\, EI/L = 2.861\\pi\\, EI/L` (Greenhill's
  problem with clamped ends; the value of the rod literature, e.g. van der Heijden & Thompson, Nonlinear Dyn.
  21 (2000) 71-99, who cite Zajac, J. Appl. Mech. 29 (1962) 136-142). Chebyshev(10) per bending, one torsion and
  one stretch mode, 20 segments: measured 6e-6 (40 segments: 2e-5; 8 bending modes: 1.2e-3); tolerance 1e-3.
  The end rotation at the threshold is :math:`M_{cr}L/GJ` = 13.0 rad, two turns: the load stepping keeps each
  increment of a target's turn below pi/4, so the drift (a logarithm) never wraps.
* Reactions (world frame, N and N m) against the small-deflection beam under its own weight: propped
  cantilever :math:`3wL/8` at the pinned end, clamped-clamped :math:`wL/2` and :math:`wL^2/12`; the rod is
  stiff (deflection 1e-5 L), so the tolerance is 1e-4 relative (the Gregory quadrature of the weight is exact
  for the straight rod).
* Centrifugal stiffening of a rotating cantilever (flapwise, hub radius 0): the rod, clamped on the spin axis,
  in the rotating frame under the centrifugal field :math:`\\rho A\\Omega^2 (x, y, 0)` (a user force; the
  centrifugal load of the sections' rotary inertia is left out, :math:`(r/L)^2 = 4\\times10^{-6}`), linearized
  about its steady stretched state (finite-difference tangent, mass matrix there); its first frequency against
  the Euler-Bernoulli eigenproblem of :func:`analytic.rotating_cantilever_frequency` for dimensionless spins
  :math:`\\Omega\\sqrt{\\rho A L^4/EI}` = 0 to 8 (measured within 6e-6 with Chebyshev(6), 20 segments; tolerance
  1e-4), and Southwell's coefficient :math:`K_1 = 1.193` from the slope at small spin (the reference's own
  slope is tested too).
* Constraint drift below 1e-8 m (and 1e-8 rad) at every solution (the Newton loop stops at tol * L = 5e-10 m).

Dynamics (the constrained implicit midpoint step: index 3, velocity projection) and assemblies of bodies:

* Mode 1 of the clamped-clamped rod, :math:`4.730^2\\sqrt{EI/\\rho A L^4}`, from a free vibration (the midpoint
  rule's phase error :math:`(2/h)\\arctan(\\omega h/2)` divided out): 4.4e-5 off, the basis' error; tol 2e-4.
* A pinned arch swinging under gravity (pendulum-like, through its chord): drift ~1e-15 m (bound 1e-6 m), energy
  error 2 % of the kinetic energy at 2.5 ms, falling like h^2; reactions at rest equal the static ones.
* Rod + welded rigid block = cantilever with an end load (statics, round-off); the joint Jacobian between a rod
  and a rigid link's offset frame against central differences; the compound pendulum's period (1e-3) and energy;
  the cantilever with a tip mass, first root 1.2479 of its frequency equation (1e-3).
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ParameterError
from soroshapes import Basis, Shapes
from soroshapes.constraints import Align, ConstraintSet, Pin, Weld

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from analytic import clamped_elastica, rotating_cantilever_frequency  # noqa: E402

L, R = 0.5, 1e-3
MAT = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)
PLANAR = ("x", "y", "rz")       # the components a rod bending in the x-y plane can move


def planar_rod(modes, segments=20):
    """A rod bending in the x-y plane (bending about z) with one stretch mode."""
    return Shapes(Basis.chebyshev(modes), dofs=(0, 0, modes, 1, 0, 0), length=L, section=sdf.Circle(R),
                  material=MAT, segments=segments, damping=0.0)


def stiffnesses(shp):
    I = np.pi * R**4 / 4
    return shp.E * I, shp.E * np.pi * R**2, shp.G * 2 * I


def critical(solve, x0, x1):
    """Secant iterations on the load parameter x for the zero of the lowest constrained eigenvalue; returns the
    equilibrium there."""
    xs = [x0, x1]
    es = [solve(x).lowest_eigenvalue for x in xs]
    for _ in range(12):
        x = xs[1] - es[1] * (xs[1] - xs[0]) / (es[1] - es[0])
        eq = solve(x)
        xs, es = [xs[1], x], [es[1], eq.lowest_eigenvalue]
        if abs(xs[1] - xs[0]) <= 1e-10 * abs(x):
            return eq
    raise AssertionError("the lowest eigenvalue did not cross zero")


def test_the_clamped_elastica_reference_solves_its_equation():
    """The elliptic-function curve against a direct integration of EI theta'' + P sin(theta) = 0 from the clamp
    (theta(0) = 0, theta'(0) = 2 k alpha), and its small-k limit, the linear mode (kL/pi)(1 - cos 2pi s/L)."""
    from scipy.integrate import solve_ivp
    from scipy.special import ellipk
    s = np.linspace(0.0, L, 9)
    for k in (0.3, 0.7):
        ratio, short, x, y = clamped_elastica(k, L, s)
        alpha = 4 * ellipk(k * k) / L
        sol = solve_ivp(lambda _, z: [z[1], -alpha**2 * np.sin(z[0]), np.cos(z[0]), np.sin(z[0])], (0, L),
                        [0.0, 2 * k * alpha, 0.0, 0.0], t_eval=s, rtol=1e-12, atol=1e-15)
        assert np.allclose(sol.y[2], x, atol=1e-10 * L) and np.allclose(sol.y[3], y, atol=1e-10 * L)
        assert x[-1] == pytest.approx(L * (1 - short), rel=1e-12) and abs(y[-1]) < 1e-12 * L
        assert ratio == pytest.approx(alpha**2 * L**2 / (4 * np.pi**2), rel=1e-12)
    k = 1e-4
    _, _, x, y = clamped_elastica(k, L, s)
    assert np.allclose(y, k * L / np.pi * (1 - np.cos(2 * np.pi * s / L)), atol=1e-6 * k * L)


def test_the_rotating_cantilever_reference_at_rest_is_euler_bernoulli():
    EI, rho_a = 2.0, 0.5
    assert rotating_cantilever_frequency(L, EI, rho_a, 0.0) == pytest.approx(
        1.8751040687**2 * np.sqrt(EI / (rho_a * L**4)), rel=1e-9)


def test_euler_load_of_the_clamped_clamped_strut():
    shp = planar_rod(8)
    EI, EA, _ = stiffnesses(shp)
    PE = 4 * np.pi**2 * EI / L**2
    solve = lambda d: shp.statics(constraints=[Weld(at=L, position=(L - d, 0, 0), axes=PLANAR)])   # noqa: E731
    eq = critical(solve, 0.9 * PE / EA * L, 1.1 * PE / EA * L)
    P = -eq.reactions[0, 3]                   # the wall pushes the rod's end back along -x
    assert abs(P / PE - 1) < 1e-3
    assert np.allclose(eq.reactions[0, [0, 1, 2, 4, 5]], 0.0, atol=1e-9 * P * L)   # straight: no moment, no shear
    assert eq.drift_position < 1e-8 and eq.drift_rotation < 1e-8
    # the buckling mode is symmetric: the midpoint moves sideways, the ends do not
    y = shp.positions(1e-3 * eq.lowest_mode / np.max(np.abs(eq.lowest_mode)))[:, 1]
    assert abs(y[len(y) // 2]) == pytest.approx(np.max(np.abs(y)), rel=1e-2) and abs(y[-1]) < 1e-9


def post_buckled(k_final=0.3, modes=10):
    """(largest position error / L, axial force error, equilibrium) of the clamped-clamped strut shortened as the
    elastica of modulus ``k_final``, against :func:`analytic.clamped_elastica`."""
    shp = planar_rod(modes)
    EI, EA, _ = stiffnesses(shp)
    PE = 4 * np.pi**2 * EI / L**2

    def hold(shortening):
        return [Weld(at=L, position=(L - shortening, 0, 0), axes=PLANAR)]

    mode = shp.statics(constraints=hold(1.1 * PE / EA * L)).lowest_mode      # leave the straight branch along it
    short = clamped_elastica(0.1, L, [0.0])[1]
    lo, hi = 0.0, 1.0
    while shp.positions(hi * mode)[-1, 0] > L * (1 - short):
        hi *= 2
    for _ in range(60):                       # amplitude of the mode that shortens the rod as the k = 0.1 elastica
        a = 0.5 * (lo + hi)
        lo, hi = (a, hi) if shp.positions(a * mode)[-1, 0] > L * (1 - short) else (lo, a)
    q = a * mode
    for k in np.arange(0.1, k_final + 0.05, 0.1):
        ratio, short, _, _ = clamped_elastica(k, L, [0.0])
        eq = shp.statics(q0=q, constraints=hold(L * short))
        q = eq.q
    p = shp.positions(q)
    _, _, x, y = clamped_elastica(k, L, shp.sigma)
    y *= np.sign(p[len(p) // 2, 1])
    return np.max(np.hypot(p[:, 0] - x, p[:, 1] - y)) / L, -eq.reactions[0, 3] / PE / ratio - 1, eq


def test_post_buckled_strut_matches_the_clamped_elastica():
    shape_error, force_error, eq = post_buckled(0.3)
    assert shape_error < 2e-4
    assert abs(force_error) < 5e-4
    assert eq.lowest_eigenvalue > 0           # the first buckled branch is stable under end shortening
    assert eq.drift_position < 1e-8 and eq.drift_rotation < 1e-8


def test_twisting_instability_of_the_clamped_clamped_rod():
    shp = Shapes([Basis.chebyshev(1), Basis.chebyshev(10), Basis.chebyshev(10), Basis.chebyshev(1), None, None],
                 dofs=(1, 10, 10, 1, 0, 0), length=L, section=sdf.Circle(R), material=MAT, segments=20, damping=0.0)
    EI, _, GJ = stiffnesses(shp)
    Mcr = 2 * 4.493409457909064 * EI / L        # 2 x the first positive root of tan x = x
    solve = lambda phi: shp.statics(constraints=[Weld(at=L, rotation=(phi, 0, 0))])   # noqa: E731
    eq = critical(solve, 0.95 * Mcr * L / GJ, 1.05 * Mcr * L / GJ)
    M = eq.reactions[0, 0]
    assert abs(M / Mcr - 1) < 1e-3
    assert M == pytest.approx(GJ * eq.q[0], rel=1e-9)       # the straight twisted rod: torque GJ tau
    w = np.linalg.eigvalsh(eq.stiffness)
    assert w[1] == pytest.approx(w[0], abs=1e-6 * w[2])       # the helix: two bending planes at once
    assert eq.drift_position < 1e-8 and eq.drift_rotation < 1e-8


@pytest.mark.parametrize("clamped", [False, True])
def test_reactions_of_a_beam_under_its_own_weight(clamped):
    shp = Shapes(Basis.chebyshev(6), dofs=(0, 6, 6, 1, 0, 0), length=0.2, section=sdf.Circle(0.01),
                 material=materials.NeoHookean(E=1e9, nu=0.3, density=1000.0), damping=0.0).add_gravity()
    w = 1000.0 * np.pi * 0.01**2 * 9.81            # weight per length [N/m]
    Lr = 0.2
    con = Weld(axes=("x", "y", "z", "ry", "rz")) if clamped else Pin()   # no torsion dof: rx is free
    eq = shp.statics(constraints=[con])
    moment, force = eq.reactions[0, :3], eq.reactions[0, 3:]
    expected = w * Lr / 2 if clamped else 3 * w * Lr / 8
    assert force[2] == pytest.approx(expected, rel=1e-4)
    assert np.allclose(force[:2], 0.0, atol=1e-3 * w * Lr)   # x: the membrane tension EA (d/L)^2 of the sag
    if clamped:   # propped, the sagging rod's end tangent would point up (a turn about -y): the clamp turns it back
        assert moment[1] == pytest.approx(w * Lr**2 / 12, rel=1e-4)
    assert eq.drift_position < 1e-8 and eq.drift_rotation < 1e-8


def test_constraint_jacobian_is_the_derivative_of_the_drift():
    shp = Shapes(Basis.chebyshev(3), dofs=(1, 3, 3, 1, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=0.0)
    rng = np.random.default_rng(3)
    q = rng.normal(size=shp.n) * 2.0
    cs = ConstraintSet(shp.model, shp.data, [Weld(at=L, position=(0.3, 0.1, 0.0), rotation=(0.4, -0.2, 0.3)),
                                             Align(at=shp.sigma[5])], np.zeros(shp.n))
    data = shp.make_data()

    def drift(x):
        shp.state(x, data=data)
        return cs.residual(data, 0.7)
    shp.state(q, data=data)
    J = cs.jacobian(data, scale=0.7)
    h = 1e-6
    Jfd = np.column_stack([(drift(q + h * e) - drift(q - h * e)) / (2 * h) for e in np.eye(shp.n)])
    assert np.allclose(J, Jfd, atol=1e-8 * np.abs(J).max())


def test_constraint_errors_name_the_fix():
    shp = planar_rod(4)
    with pytest.raises(ParameterError, match="cannot move .*position z.*axes="):
        shp.statics(constraints=[Weld(at=L)])
    with pytest.raises(ParameterError, match="dependent"):
        shp.statics(constraints=[Pin(at=L, axes=("x", "y")), Pin(at=L, axes=("y",))])
    with pytest.raises(ParameterError, match="axes must be"):
        shp.statics(constraints=[Pin(at=L, axes=("rz",))])
    with pytest.raises(ParameterError, match="not one"):
        shp.statics(constraints=[Pin(at=0.1234, axes=("x", "y"))])
    inextensible = Shapes(Basis.chebyshev(4), dofs=(0, 0, 4, 0, 0, 0), length=L, section=sdf.Circle(R),
                          material=MAT, damping=0.0)
    with pytest.raises(ParameterError, match="stretch dof"):
        inextensible.statics(constraints=[Pin(at=L, axes=("x", "y"))])


class Centrifugal:
    """The centrifugal force per length :math:`\\rho A\\Omega^2 (x, y, 0)` [N/m] of a spin ``spin`` [rad/s] about
    the world z axis, as a generalized force (a user force of the rotating frame)."""

    def __init__(self, spin):
        self.spin = spin

    def __call__(self, shp, q, qd, t):
        G, _, J = shp.node_kinematics(q)
        rho_a = shp.density * shp.section_properties.area
        f = np.zeros(shp.n)
        for g, Ji, w in zip(G, J, shp.model.weights):        # Gregory weights at the nodes (stride 1)
            force = rho_a * self.spin**2 * np.array([g[0, 3], g[1, 3], 0.0])
            f += w * Ji[3:].T @ (g[:3, :3].T @ force)
        return f


def spinning_frequency(spin_bar, modes=6):
    """(first flapwise frequency of the spinning rod [rad/s], the reference, spin [rad/s])."""
    from scipy.linalg import eigh
    shp = Shapes(Basis.chebyshev(modes), dofs=(0, modes, 0, 1, 0, 0), length=L, section=sdf.Circle(R),
                 material=MAT, segments=20, damping=0.0)
    EI, rho_a = stiffnesses(shp)[0], shp.density * np.pi * R**2
    spin = spin_bar * np.sqrt(EI / (rho_a * L**4))
    shp.add_force(Centrifugal(spin))
    q = shp.statics()
    f0, h = shp.generalized_force(q), 1e-7
    Kt = shp.K - np.column_stack([(shp.generalized_force(q + h * e) - f0) / h for e in np.eye(shp.n)])
    w2 = eigh(0.5 * (Kt + Kt.T), shp.mass_matrix(q), eigvals_only=True)
    return np.sqrt(w2[0]), rotating_cantilever_frequency(L, EI, rho_a, spin), spin


@pytest.mark.parametrize("spin_bar", [0.0, 2.0, 8.0])
def test_centrifugal_stiffening_of_a_rotating_cantilever(spin_bar):
    w, ref, _ = spinning_frequency(spin_bar)
    assert w == pytest.approx(ref, rel=1e-4)


def test_southwell_coefficient():
    w0, ref0, _ = spinning_frequency(0.0)
    w, ref, spin = spinning_frequency(0.3)
    assert (ref**2 - ref0**2) / spin**2 == pytest.approx(1.193, abs=1e-3)      # the reference's own slope
    assert (w**2 - w0**2) / spin**2 == pytest.approx(1.193, abs=1e-3)



# ------------------------------------------------------------------------------------------------------------
# dynamics: the constrained implicit midpoint step
# ------------------------------------------------------------------------------------------------------------
def clamped_clamped_vibration(modes=8, periods=3, per_period=100):
    """(simulated first frequency, its reference) [rad/s] of a planar rod clamped at both ends (tip Weld on y and
    rz; x free: the linear theory has no axial force), released from rest in its first constrained mode with a
    small amplitude (largest coordinate 1e-3, midpoint deflection ~1e-4 L)."""
    from scipy.linalg import eigh, null_space
    shp = Shapes(Basis.chebyshev(modes), dofs=(0, 0, modes, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 segments=20, damping=0.0)
    cons = [Weld(axes=("y", "rz"))]
    cs = ConstraintSet(shp.model, shp.data, cons, np.zeros(shp.n))
    Z = null_space(cs.jacobian(shp.data))
    w2, V = eigh(Z.T @ shp.K @ Z, Z.T @ shp.mass_matrix(np.zeros(shp.n)) @ Z)
    mode = Z @ V[:, 0]
    EI, _, _ = stiffnesses(planar_rod(1))
    omega = 4.730040745**2 * np.sqrt(EI / (MAT.density * np.pi * R**2 * L**4))
    h = 2 * np.pi / omega / per_period
    tr = shp.simulate(periods * 2 * np.pi / omega, h, q0=1e-3 * mode / np.abs(mode).max(), constraints=cons)
    y = np.array([shp.positions(q)[10, 1] for q in tr.q])          # the midpoint's deflection
    i = np.nonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)[0]
    crossings = tr.t[i] - y[i] * (tr.t[i + 1] - tr.t[i]) / (y[i + 1] - y[i])
    w = np.pi / np.mean(np.diff(crossings))
    # the midpoint rule's own frequency for an oscillator of frequency omega: (2/h) atan(omega h/2)
    return w, 2 / h * np.arctan(omega * h / 2), tr


def test_clamped_clamped_rod_vibrates_at_the_euler_bernoulli_frequency():
    """Mode 1 of the clamped-clamped Euler-Bernoulli beam, 4.730^2 sqrt(EI/(rho A L^4)), through the midpoint rule
    (its phase error (2/h) atan(omega h/2) divides out: -3.3e-4 at 100 steps a period). Measured 4.4e-5 off,
    the basis' error (the constrained eigenvalue of chebyshev(8), 20 segments, is 4.4e-5 above the closed form);
    tolerance 2e-4 (the zero crossings of three periods interpolated linearly)."""
    w, ref, tr = clamped_clamped_vibration()
    assert abs(w / ref - 1) < 2e-4
    assert tr.drift_position.max() < 1e-9 and tr.drift_rotation.max() < 1e-9
    assert tr.drift_position.shape == tr.t.shape and tr.reactions.shape == (len(tr.t), 1, 6)
    assert np.ptp(tr.total) <= 1e-6 * tr.total[0]               # linear and undamped: the midpoint rule keeps it


def swinging_arch(dt, t_end=1.0):
    """A soft rod clamped at the origin along x and pinned at its tip at x = 0.6 L (x and z held: planar in x-z)
    stands as an arch above the chord; under gravity it swings down through the chord to hang below and back,
    like a pendulum. Undamped."""
    k = 6
    shp = Shapes(Basis.chebyshev(k), dofs=(0, k, 0, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 segments=20, damping=0.0)
    q0 = np.zeros(shp.n)
    q0[0] = 1.0                                                  # bend upwards: the arch stands above the chord
    eq = shp.statics(q0=q0, constraints=[Pin(position=(0.6 * L, 0, 0), axes=("x", "z"))], steps=4)
    shp.add_gravity((0.0, 0.0, -9.81))
    return shp, shp.simulate(t_end, dt, q0=eq.q, constraints=[Pin(axes=("x", "z"))], record_every=4)


def test_pinned_arch_swings_with_no_drift_and_bounded_energy():
    """The swinging arch (mid-span from +0.31 L to about -0.3 L): the tip stays on its pin to round-off (the
    position constraint is solved at every step end; drift bound 1e-6 m, measured ~1e-15 m), and the energy error
    of the undamped swing stays bounded and falls like h^2 (measured max |E - E0| / max E_kin: 12.6 % at 5 ms,
    2.0 % at 2.5 ms: ratio 6.6)."""
    errors = []
    for dt in (0.005, 0.0025):
        shp, tr = swinging_arch(dt)
        assert tr.drift_position.max() < 1e-6
        z = np.array([shp.positions(q)[10, 2] for q in tr.q])
        assert z[0] > 0.3 * L and z.min() < -0.2 * L                      # it swings through the chord
        errors.append(np.abs(tr.total - tr.total[0]).max() / tr.kinetic.max())
        tip = np.array([shp.positions(q)[-1] for q in tr.q])
        assert np.abs(tip[:, [0, 2]] - [0.6 * L, 0.0]).max() < 1e-6
    assert errors[1] < 0.05 and errors[0] / errors[1] > 3.0


def test_reactions_of_a_rod_at_rest_are_the_static_ones():
    """A soft propped cantilever under its own weight (a large sag) started at its constrained equilibrium stays
    there, and the reactions of the steps are the static ones (those are checked against 3 w L / 8 on a stiff rod
    in test_reactions_of_a_beam_under_its_own_weight)."""
    shp = planar_rod(4).add_gravity((0.0, -9.81, 0.0))
    eq = shp.statics(constraints=[Pin(axes=("x", "y"))])
    tr = shp.simulate(0.05, 0.005, q0=eq.q, constraints=[Pin(axes=("x", "y"))])
    w = MAT.density * np.pi * R**2 * 9.81
    assert np.allclose(tr.reactions[:, 0], eq.reactions[0], rtol=0, atol=1e-6 * w * L)
    assert np.abs(tr.q - eq.q).max() < 1e-8 * np.abs(eq.q).max()


def test_constrained_simulate_needs_a_consistent_start():
    shp = planar_rod(3)
    with pytest.raises(ParameterError, match="does not satisfy the constraints"):
        shp.simulate(0.01, 0.005, constraints=[Pin(position=(0.9 * L, 0, 0), axes=("x", "y"))])
    with pytest.raises(ParameterError, match="implicit"):
        shp.simulate(0.01, 0.005, method="explicit", constraints=[Pin(axes=("x", "y"))])



# ------------------------------------------------------------------------------------------------------------
# assemblies: constraints between frames of different bodies
# ------------------------------------------------------------------------------------------------------------
def rod_and_block(mass, gravity=(0.0, -9.81, 0.0), modes=6, length=0.2, offset=0.0):
    """A planar rod (bending about z, one stretch mode) along x with a rigid block whose frame at ``offset`` [m]
    along x (body coordinates) is the rod's tip frame."""
    from soroshapes.constraints import Assembly, RigidLink
    rod = Shapes(Basis.chebyshev(modes), dofs=(0, 0, modes, 1, 0, 0), length=length, section=sdf.Circle(3e-3),
                 material=MAT, segments=20, damping=0.0).add_gravity(gravity)
    g0 = np.eye(4)
    g0[0, 3] = length + offset
    block = RigidLink(mass, 1e-12, pose0=g0, gravity=gravity)
    return rod, block, Assembly([rod, block])


def test_a_rod_welded_to_a_block_is_a_cantilever_with_an_end_load():
    """Statics of rod + block (a Weld between the rod's tip and the block's frame) against the single rod with
    the block's weight as a point load at its tip: the same equations, so the same tip to round-off; the
    reaction on the block carries its weight."""
    mass = 0.002
    rod, block, asm = rod_and_block(mass)
    eq = asm.statics(constraints=[Weld(body=rod, to=block)], steps=2)
    q_rod, q_block = asm.split(eq.q)
    ref = rod_and_block(mass)[0].add_point_load(force=(0.0, -9.81 * mass, 0.0))
    tip = ref.positions(ref.statics(steps=2))[-1]
    assert abs(tip[1]) > 0.1 * 0.2                                    # a large deflection
    assert np.allclose(rod.positions(q_rod)[-1], tip, atol=1e-9 * 0.2)
    assert np.allclose(block.end(q_block), tip, atol=1e-9 * 0.2)
    assert eq.reactions[0, 4] == pytest.approx(-9.81 * mass, rel=1e-9)   # on the rod's tip: the block hangs on it
    assert eq.drift_position < 1e-8 and eq.drift_rotation < 1e-8



def test_rod_with_a_welded_block_vibrates_like_a_cantilever_with_a_tip_mass():
    """Dynamics across bodies: the rod + block (no gravity, block mass = rod mass) set vibrating by a small
    velocity of the block, against the Euler-Bernoulli cantilever with a tip mass, whose first root of
    1 + cos b cosh b + mu b (cos b sinh b - sin b cosh b) = 0 (mu = 1: b = 1.2479) gives
    omega = b^2 sqrt(EI / (rho A L^4)); the midpoint's phase error divided out. The section's rotary inertia,
    (r/L)^2 ~ 2e-4, and the basis are left between them: tolerance 1e-3."""
    from scipy.optimize import brentq
    length, r = 0.2, 3e-3
    rho_a = MAT.density * np.pi * r**2
    rod, block, asm = rod_and_block(rho_a * length, gravity=(0.0, 0.0, 0.0))
    beta = brentq(lambda b: 1 + np.cos(b) * np.cosh(b) + b * (np.cos(b) * np.sinh(b) - np.sin(b) * np.cosh(b)),
                  0.5, 1.8)
    omega = beta**2 * np.sqrt(rod.E * np.pi * r**4 / 4 / (rho_a * length**4))
    h = 2 * np.pi / omega / 100
    qd0 = np.zeros(asm.n)
    qd0[rod.n + 4] = 1e-4                                               # the block's y velocity [m/s]
    tr = asm.simulate(3 * 2 * np.pi / omega, h, None, qd0, constraints=[Weld(body=rod, to=block)])
    y = tr.tip[:, 1]
    i = np.nonzero(np.sign(y[1:-1]) * np.sign(y[2:]) < 0)[0] + 1
    crossings = tr.t[i] - y[i] * (tr.t[i + 1] - tr.t[i]) / (y[i + 1] - y[i])
    w = np.pi / np.mean(np.diff(crossings))
    assert beta == pytest.approx(1.2479, abs=1e-4)
    assert w == pytest.approx(2 / h * np.arctan(omega * h / 2), rel=1e-3)
    assert tr.drift_position.max() < 1e-9 and tr.drift_rotation.max() < 1e-9


def test_joint_jacobian_is_the_derivative_of_the_drift():
    """The Jacobian of Weld and Align rows between a 3D rod's node and an offset frame of a rigid link, against
    central differences at a random state of both (the ramp of the joint at load factor 0.6)."""
    from soroshapes.constraints import Assembly, RigidLink
    rod = Shapes(Basis.chebyshev(3), dofs=(1, 3, 3, 1, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=0.0)
    link = RigidLink(0.01, (1e-6, 2e-6, 3e-6), pose0=np.eye(4))
    offset = np.eye(4)
    offset[:3, 3] = (0.01, -0.02, 0.03)
    offset[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    asm = Assembly([rod, link])
    rng = np.random.default_rng(5)
    q0 = np.concatenate([rng.normal(size=rod.n), 0.3 * rng.normal(size=6)])
    cs = ConstraintSet(asm, None, [Weld(body=rod, to=link, to_at=offset),
                                   Align(body=rod, at=rod.sigma[7], to=link)], q0)
    q = q0 + np.concatenate([0.5 * rng.normal(size=rod.n), 0.2 * rng.normal(size=6)])

    def drift(x):
        asm.kinematics(x)
        return cs.residual(None, 0.6)
    asm.kinematics(q)
    J = cs.jacobian(None, scale=0.6)
    h = 1e-6
    Jfd = np.column_stack([(drift(q + h * e) - drift(q - h * e)) / (2 * h) for e in np.eye(asm.n)])
    assert np.abs(J - Jfd).max() < 1e-7 * np.abs(Jfd).max()


def test_rigid_link_pendulum_conserves_energy_and_swings_at_its_period():
    """A rigid block pinned (Pin, world) at a point d = 0.1 m above its centre of mass, spinning about its own
    axis and swinging: the rotation-vector coordinates' Coriolis terms (differenced M) keep the energy (undamped:
    bounded midpoint error) and a small swing has the compound pendulum's period 2 pi sqrt((I + m d^2)/(m g d))
    (midpoint phase error divided out; tolerance 1e-3 for the zero crossings of two periods)."""
    from soroshapes.constraints import Assembly, RigidLink
    m, I, d, g = 0.1, 2e-4, 0.1, 9.81
    link = RigidLink(m, I, gravity=(0.0, 0.0, -g))
    asm = Assembly([link])
    omega = np.sqrt(m * g * d / (I + m * d * d))
    h = 2 * np.pi / omega / 200
    q0 = np.zeros(6)
    qd0 = np.zeros(6)
    qd0[1] = 0.02 * omega                                              # a small swing about y
    tr = asm.simulate(2 * 2 * np.pi / omega, h, q0, qd0, constraints=[Pin(body=link, at=(0.0, 0.0, d))])
    x = tr.tip[:, 0]
    i = np.nonzero(np.sign(x[1:-1]) * np.sign(x[2:]) < 0)[0] + 1
    crossings = tr.t[i] - x[i] * (tr.t[i + 1] - tr.t[i]) / (x[i + 1] - x[i])
    w = np.pi / np.mean(np.diff(crossings))
    assert w == pytest.approx(2 / h * np.arctan(omega * h / 2), rel=1e-3)
    assert tr.drift_position.max() < 1e-9
    # a large swing with spin about the body's axis (turning 4 rad in all: the coordinates hold below 2 pi)
    qd0 = np.array([0.0, 3.0, 4.0, 0.0, 0.0, 0.0])
    tr = asm.simulate(1.0, 2e-3, q0, qd0, constraints=[Pin(body=link, at=(0.0, 0.0, d))])
    assert tr.drift_position.max() < 1e-6
    assert np.ptp(tr.total) < 1e-2 * tr.kinetic.max()
    from sorofem.errors import ConvergenceError
    with pytest.raises(ConvergenceError, match="singularity"):
        asm.simulate(1.0, 2e-3, q0, np.array([0.0, 0.0, 20.0, 0.0, 0.0, 0.0]),
                     constraints=[Pin(body=link, at=(0.0, 0.0, d))])


if __name__ == "__main__":        # the figures of the report: python tests/soroshapes/test_constraints.py
    shp = planar_rod(8)
    EI, EA, GJ = stiffnesses(shp)
    PE = 4 * np.pi**2 * EI / L**2
    eq = critical(lambda d: shp.statics(constraints=[Weld(at=L, position=(L - d, 0, 0), axes=PLANAR)]),
                  0.9 * PE / EA * L, 1.1 * PE / EA * L)
    print(f"Euler load (chebyshev(8), 20 segments): P/P_E - 1 = {-eq.reactions[0, 3] / PE - 1:.2e}, "
          f"drift {eq.drift_position:.1e} m {eq.drift_rotation:.1e} rad")
    for kf in (0.3, 0.7):
        err, ferr, eq = post_buckled(kf)
        print(f"post-buckled clamped elastica k = {kf} (chebyshev(10), 20 segments): shape error {err:.2e} L, "
              f"axial force error {ferr:.2e}, drift {eq.drift_position:.1e} m {eq.drift_rotation:.1e} rad")
    shp = Shapes([Basis.chebyshev(1), Basis.chebyshev(10), Basis.chebyshev(10), Basis.chebyshev(1), None, None],
                 dofs=(1, 10, 10, 1, 0, 0), length=L, section=sdf.Circle(R), material=MAT, segments=20, damping=0.0)
    Mcr = 2 * 4.493409457909064 * EI / L
    eq = critical(lambda phi: shp.statics(constraints=[Weld(at=L, rotation=(phi, 0, 0))]),
                  0.95 * Mcr * L / GJ, 1.05 * Mcr * L / GJ)
    print(f"twisting instability (chebyshev(10), 20 segments): M/M_cr - 1 = {eq.reactions[0, 0] / Mcr - 1:.2e}, "
          f"drift {eq.drift_position:.1e} m {eq.drift_rotation:.1e} rad")
    for sb in (0.0, 1.0, 2.0, 4.0, 8.0):
        w, ref, _ = spinning_frequency(sb)
        print(f"rotating cantilever, spin {sb:g}: omega/omega_ref - 1 = {w / ref - 1:.2e}")
    w0, _, _ = spinning_frequency(0.0)
    w, _, spin = spinning_frequency(0.3)
    print(f"Southwell coefficient of the beam model: {(w**2 - w0**2) / spin**2:.4f} (published 1.193)")
