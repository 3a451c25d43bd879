"""The beam's model/data split (soroshapes.beam): a frozen description, independent workspaces, and states out of
the floating-point range that raise without poisoning anything.

References: a second, independently built beam with the same parameters (bitwise-equal arithmetic, so equality
is exact up to 0 ulp; compared with 1e-14 relative to leave room for a different summation order nowhere used).
"""
import re
from pathlib import Path

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import DataError
from soroshapes import Basis, Shapes
from soroshapes import beam as bm

L, R = 0.2, 0.005
MAT = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)
ROOT = Path(__file__).resolve().parents[2]


def rod(**kw):
    return Shapes(Basis.chebyshev(3), (1, 3, 3, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                  damping=0.0, **kw).add_gravity()


def state(seed):
    rng = np.random.default_rng(seed)
    return rng.normal(scale=5.0, size=7), rng.normal(scale=2.0, size=7)


def test_the_description_is_frozen():
    shp = rod()
    with pytest.raises(AttributeError):
        shp.model.length = 1.0
    with pytest.raises(ValueError):
        shp.model.K[0, 0] = 1.0                    # read-only arrays
    with pytest.raises(ValueError):
        shp.model.B[0, 0, 0] = 1.0


@pytest.mark.parametrize("bad", [1e200, -1e300, np.nan, np.inf])
def test_a_huge_or_non_finite_state_raises_and_leaves_the_object_usable(bad):
    shp, ref = rod(), rod()
    q0 = np.zeros(shp.n)
    M0, P0 = ref.mass_matrix(q0), ref.positions(q0)
    q = np.zeros(shp.n)
    q[2] = bad
    for query in (shp.positions, shp.mass_matrix, lambda x: shp.dynamics(x, x), shp.energy,
                  lambda x: shp.inverse_dynamics(x, x, x), shp.generalized_force):
        with pytest.raises(DataError, match="NaN or inf|overflow"):
            query(q)
        # the same object, at q = 0, gives the values of a fresh one (nothing stale left in a buffer)
        assert np.allclose(shp.mass_matrix(q0), M0, rtol=1e-14, atol=0)
        assert np.allclose(shp.positions(q0), P0, rtol=1e-14, atol=1e-16)
        assert np.all(np.isfinite(shp.dynamics(q0, q0)[1]))


def test_a_huge_state_in_the_functional_api_resets_the_workspace():
    shp = rod()
    data = shp.make_data()
    q = np.full(shp.n, 1e200)
    with pytest.raises(bm.StateRangeError, match="overflow"):
        bm.kinematics(shp.model, data, q, q, rate=True)
    for name in data.__slots__:
        assert np.all(np.isfinite(getattr(data, name))), name
    bm.kinematics(shp.model, data, np.zeros(shp.n))
    assert np.allclose(data.G[-1, :3, 3], [L, 0, 0], atol=1e-15)


def test_two_workspaces_used_alternately_give_the_results_of_two_independent_models():
    shp = rod()
    one, two = rod(), rod()
    d1, d2 = shp.make_data(), shp.make_data()
    (q1, v1), (q2, v2) = state(1), state(2)
    for _ in range(2):          # alternate: each pass must not disturb the other workspace
        M1, C1, f1 = (a.copy() for a in bm.dynamics(shp.model, d1, q1, v1, shp.gravity))
        M2, C2, f2 = (a.copy() for a in bm.dynamics(shp.model, d2, q2, v2, shp.gravity))
        G1, G2 = d1.G.copy(), d2.G.copy()
        # d1 still holds state 1 after d2 was used
        assert np.array_equal(d1.G, G1) and np.array_equal(d1.M, M1)
        for (M, C, f, G), other, (q, v) in (((M1, C1, f1, G1), one, (q1, v1)), ((M2, C2, f2, G2), two, (q2, v2))):
            Mr, Cr, fr = other.dynamics(q, v)
            assert np.allclose(M, Mr, rtol=1e-14, atol=0)
            assert np.allclose(C, Cr, rtol=1e-14, atol=1e-300)
            assert np.allclose(f, fr, rtol=1e-14, atol=1e-300)
            assert np.allclose(shp.model.at_nodes(G), other.forward_kinematics(q), rtol=1e-14, atol=1e-16)
    # the wrappers with data= leave the default workspace alone
    shp.positions(q1)
    G = shp.data.G.copy()
    shp.positions(q2, data=d2)
    assert np.array_equal(shp.data.G, G)


def test_the_wrappers_equal_the_functions():
    shp = rod()
    q, v = state(3)
    data = shp.make_data()
    assert np.array_equal(shp.mass_matrix(q), bm.dynamics(shp.model, data, q, None, None, False)[0])
    assert np.allclose(shp.coriolis_jacobian(q, v), bm.coriolis_jacobian(shp.model, data, q, v), rtol=1e-14)
    tau = shp.inverse_dynamics(q, v, np.zeros(shp.n))
    M, C, fg = shp.dynamics(q, v)
    assert np.allclose(tau, C @ v - fg + shp.K @ q, rtol=1e-10, atol=1e-12 * np.abs(shp.K @ q).max())
    qdd = shp.forward_dynamics(q, v)
    assert np.allclose(M @ qdd + C @ v + shp.K @ q - fg, 0.0, atol=1e-9 * np.abs(shp.K @ q).max())


def test_no_module_reads_the_beam_cores_private_arrays():
    """Outside the beam core (shapes.py, beam.py, _beam.py), nothing reads a beam's workspace or load lists
    through private names (a module's own objects, ``self`` and a view's ``self._model``, excepted)."""
    private = re.compile(r"\.(_kin|_G|_J|_Jd|_eta|_w|_node|_gravity|_external|_work|_Md|_h|_B|_rows|_X0|_loads|"
                         r"_mcg|_contact_force|_inputs_at|_accel_terms)\b")
    core = {"shapes.py", "beam.py", "_beam.py"}
    hits = []
    for folder in ("soroshapes", "sorocontrol", "demos", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            if path.parent.name == "soroshapes" and path.name in core:
                continue
            for k, line in enumerate(path.read_text().splitlines(), 1):
                for m in private.finditer(line):
                    owner = line[:m.start()].rstrip()
                    if not (owner.endswith("self") or owner.endswith("self._model")):   # own/same-module objects
                        hits.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not hits, "\n".join(hits)


# --------------------------------------------------------------------------------------------------------
# accuracy of the default discretization (20 segments, Magnus order 4, Gregory quadrature; and Gauss-Lobatto)
# --------------------------------------------------------------------------------------------------------
def slender(quadrature="gregory", modes=8, **kw):
    """A slender rod (L/R = 200): rotary inertia shifts mode 3 from Euler-Bernoulli by about
    (beta_3 r_g)^2 / 2 = 1.9e-4 (r_g = R/2), well inside the 1e-3 tolerance."""
    return Shapes(Basis.chebyshev(modes), (0, 0, modes, 0, 0, 0), length=L, section=sdf.Circle(0.001),
                  material=MAT, damping=0.0, quadrature=quadrature, **kw)


def test_default_discretization_gives_euler_bernoulli_frequencies_within_0p1_percent():
    import sys
    sys.path.insert(0, str(ROOT / "tests"))
    from analytic import cantilever_frequencies
    ref = np.array(cantilever_frequencies(L, MAT.E, np.pi * 0.001**4 / 4, MAT.density, np.pi * 0.001**2))
    err = np.abs(slender().natural_frequencies(3) / ref - 1)
    assert err.max() < 1e-3, err                     # measured 1.4e-5, 7.4e-5, 1.1e-4
    err = np.abs(slender("lobatto").natural_frequencies(3) / ref - 1)
    assert err.max() < 1e-3, err                     # measured 1.5e-5, 1.0e-4, 2.4e-4
    # the trapezoidal rule at the nodes (the previous default) misses by O(h^2): the test tells them apart
    assert np.abs(slender("trapezoid").natural_frequencies(3) / ref - 1).max() > 2e-3


@pytest.mark.parametrize("quadrature", ["gregory", "lobatto"])
def test_default_discretization_gives_the_self_weight_elastica_tip_within_1e_4_length(quadrature):
    """A soft rod (E = 0.1 MPa, R = 5 mm, L = 0.2 m) drooping under its own weight to dx = -0.86 L,
    dy = -0.94 L; reference: the inextensible elastica BVP (tests/analytic.py). Shear and stretch are not in the
    model (dofs: one bending), as in the reference; 8 modes make the modal truncation ~1e-5 L (measured
    1.2e-5 L, 1.1e-5 L with Gregory's rule; 1.1e-5 L, 3.5e-6 L with Gauss-Lobatto)."""
    import sys
    sys.path.insert(0, str(ROOT / "tests"))
    from analytic import elastica_gravity_tip
    Rr, E = 0.005, 1e5
    mat = materials.NeoHookean(E=E, nu=0.45, density=1000.0)
    shp = Shapes(Basis.chebyshev(8), (0, 8, 0, 0, 0, 0), length=L, section=sdf.Circle(Rr), material=mat,
                 damping=0.0, quadrature=quadrature).add_gravity((0, 0, -9.81))
    dx, dy = elastica_gravity_tip(L, E * np.pi * Rr**4 / 4, 1000.0 * np.pi * Rr**2 * 9.81)
    tip = shp.positions(shp.statics(steps=4))[-1]
    assert abs(tip[0] - L - dx) < 1e-4 * L and abs(tip[2] - dy) < 1e-4 * L, (tip[0] - L - dx, tip[2] - dy)


def test_compiled_forward_dynamics_equals_the_assembled_one():
    """The one-call kernel (gravity, chambers, actuators, point loads) against M^-1 (f - C qd - D qd - K q) from
    the assembled matrices and the load terms."""
    shp = Shapes(Basis.chebyshev(3), (1, 3, 3, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=0.01).add_gravity((1.0, 2.0, -9.81))
    shp.add_chamber(2e-5, (0.002, 0.001)).add_actuator(np.arange(7.0), name="a")
    shp.add_point_load(force=lambda t: [0.1 * t, 0, -0.2], moment=[0, 0.01, 0], at=L / 2, frame="body")
    shp.add_point_load(force=[0, 0.3, 0])
    q, v = state(4)
    u = np.array([3e3, 0.2])
    fast = shp.forward_dynamics(q, v, 0.7, u)
    M, C, _ = shp.dynamics(q, v)
    f = shp.generalized_force(q, v, 0.7, u)
    ref = np.linalg.solve(M, f - C @ v - shp.damping_matrix @ v - shp.K @ q)
    assert np.allclose(fast, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    q[0] = 1e200
    with pytest.raises(DataError, match="overflow"):
        shp.forward_dynamics(q, v, 0.7, u)
    q[0] = 0.0
    assert np.all(np.isfinite(shp.forward_dynamics(q, v, 0.7, u)))


def test_the_model_says_which_path_each_block_takes():
    from soroshapes import Fluidic, Model
    fast = rod().add_chamber(1e-5, (0.0, 0.002), name="chamber")
    slow = rod().add_contact(sdf.Plane((0, 0, -0.05), (0, 0, 1))).add_force(lambda s, q, qd, t: np.zeros(7))
    assert fast.evaluation_path == "compiled"
    assert slow.evaluation_path == "python: Contact, UserForce"
    mdl = Model().add(fast, "fast").add(slow, "slow").add(Fluidic(None, V0=1e-6), "p")
    mdl.connect(lambda m: 1e-6, "p", port="volume").connect("p", "fast")
    tr = mdl.simulate(2e-3, 1e-3)
    assert tr.stats["evaluation_paths"] == {"fast": "compiled", "slow": "python: Contact, UserForce",
                                            "p": "python", "couplings": "python"}


def test_the_compiled_loop_retries_a_hard_step_with_a_fresh_matrix_instead_of_leaving_it():
    """A twisted, bent rod released under gravity: with the iteration matrix kept for up to 50 steps, Newton once
    failed within 30 steps and the rest of the run went to the Python integrator (~50x slower); a failing step
    is now retried with a fresh matrix inside the compiled loop. Checked against a run at a tight tolerance."""
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=0.0, segments=10, order=2).add_gravity()
    q0 = np.zeros(15)
    q0[0], q0[5] = 2.0, 3.0
    tr = shp.simulate(0.3, 1e-3, q0=q0, record_every=50)
    assert tr.stats["compiled_steps"] == 300
    ref = shp.simulate(0.3, 1e-3, q0=q0, record_every=50, tol=1e-12)
    assert np.abs(tr.tip - ref.tip).max() < 1e-6 * L


@pytest.mark.parametrize("order, quadrature", [(2, "gregory"), (4, "gregory"), (4, "lobatto"), (2, "trapezoid")])
@pytest.mark.parametrize("scale", [2.0, 1e-3, 0.0])
def test_the_newton_euler_recursions_equal_the_jacobian_sums(order, quadrature, scale):
    """``_beam.newton_euler`` (O(N) forward/backward recursions, T and dT applied as polynomials in ad) against
    ``generalized_inertial_force`` (the explicit sums over the 6 x n Jacobians), and ``mass_matrix_pieces``
    (from the recursion's per-piece operators) against ``dynamics``' M: the same discrete model in another
    order of operations, so they agree to rounding (1e-12 relative; measured 1e-16 to 6e-16). Large, small
    (series branch of the coefficients) and zero strains; every strain kind; two point wrenches, one spatial."""
    from soroshapes import _beam
    shp = Shapes(Basis.chebyshev(3), (3, 3, 3, 2, 1, 1), length=L, section=sdf.Circle(R), material=MAT,
                 segments=6, order=order, quadrature=quadrature)
    m, d = shp.model, shp.model.make_data()
    n, P = m.n, m.h.shape[0]
    rng = np.random.default_rng(3)
    q, qd, a = scale * rng.normal(size=n), 3.0 * rng.normal(size=n), 10.0 * rng.normal(size=n)
    ag = np.array([0.3, 0.1, -9.81])
    nodes, W, spatial = np.array([P, P // 2], dtype=np.int64), rng.normal(size=(2, 6)), np.array([True, False])
    ref, new = np.zeros(n), np.zeros(n)
    _beam.kinematics_vec(q, qd, m.order, m.h, m.B, m.rows, m.X0, m.base, d.G, d.J, d.eta, d.etad, d.S, d.E, d.V,
                         d.Op, d.AJ, d.W)
    _beam.generalized_inertial_force(d.J, d.eta, d.etad, d.G, m.weights, m.Md, a, ag, nodes, W, spatial, ref)
    G_ref = d.G.copy()
    _beam.newton_euler(q, qd, a, m.order, m.h, m.B, m.rows, m.X0, m.base, m.weights, m.Md, ag, nodes, W, spatial,
                       d.G, d.eta, d.acc, d.SA, d.SX, d.E, d.NE, new)
    assert np.abs(new - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.abs(d.G - G_ref).max() <= 1e-14
    M = np.zeros((n, n))
    _beam.mass_matrix_pieces(m.order, m.h, m.B, m.rows, m.weights, m.Md, d.SA, d.SX, np.zeros((6, 6)),
                             np.zeros((P + 1, 6, n)), np.zeros((P + 1, 6, n)), np.zeros((6, n)), M)
    M_ref = bm.dynamics(m, m.make_data(), q, qd, ag, False)[0]
    assert np.abs(M - M_ref).max() <= 1e-12 * np.abs(M_ref).max()


@pytest.mark.parametrize("order, quadrature", [(2, "gregory"), (4, "gregory"), (4, "lobatto")])
@pytest.mark.parametrize("scale", [20.0, 1e-3, 0.0])
def test_the_planar_recursions_equal_the_general_ones_on_a_planar_beam(order, quadrature, scale):
    """``_beam.newton_euler_planar`` and ``mass_matrix_planar`` (3-twists of se(2)) against ``newton_euler`` and
    ``mass_matrix_pieces`` on a beam that bends about y, stretches and shears in z only, with a tilted base, a
    gravity out of its plane and two point wrenches (one spatial) with out-of-plane parts: the same discrete
    model, so they agree to rounding (1e-12 relative), the frames included. The general mask is not planar."""
    from soroshapes import _beam
    rng = np.random.default_rng(7)
    base = np.eye(4)
    base[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    if np.linalg.det(base[:3, :3]) < 0:
        base[:3, 0] *= -1.0
    base[:3, 3] = rng.normal(size=3) * 0.01
    shp = Shapes(Basis.chebyshev(3), (0, 3, 0, 2, 0, 1), length=L, section=sdf.Circle(R), material=MAT,
                 segments=6, order=order, quadrature=quadrature, base=base)
    m = shp.model
    assert _beam.is_planar(m.rows, m.X0)
    full = Shapes(Basis.chebyshev(3), (3, 3, 3, 2, 1, 1), length=L, section=sdf.Circle(R), material=MAT).model
    assert not _beam.is_planar(full.rows, full.X0)
    n, P = m.n, m.h.shape[0]
    q, qd, a = scale * rng.normal(size=n), 3.0 * rng.normal(size=n), 10.0 * rng.normal(size=n)
    ag = np.array([0.3, 2.1, -9.81])
    nodes, W, spatial = np.array([P, P // 2], dtype=np.int64), rng.normal(size=(2, 6)), np.array([True, False])
    out = {}
    for label, ne, mm in (("general", _beam.newton_euler, _beam.mass_matrix_pieces),
                          ("planar", _beam.newton_euler_planar, _beam.mass_matrix_planar)):
        d = m.make_data()
        f, M = np.zeros(n), np.zeros((n, n))
        ne(q, qd, a, m.order, m.h, m.B, m.rows, m.X0, m.base, m.weights, m.Md, ag, nodes, W, spatial, d.G, d.eta,
           d.acc, d.SA, d.SX, d.E, d.NE, f)
        mm(m.order, m.h, m.B, m.rows, m.weights, m.Md, d.SA, d.SX, np.zeros((6, 6)), np.zeros((P + 1, 6, n)),
           np.zeros((P + 1, 6, n)), np.zeros((6, n)), M)
        out[label] = f, M, d.G.copy(), d.eta.copy()
    (f0, M0, G0, e0), (f1, M1, G1, e1) = out["general"], out["planar"]
    assert np.abs(f1 - f0).max() <= 1e-12 * np.abs(f0).max()
    assert np.abs(M1 - M0).max() <= 1e-12 * np.abs(M0).max()
    assert np.abs(G1 - G0).max() <= 1e-14 and np.abs(e1 - e0).max() <= 1e-12 * np.abs(e0).max()


def test_the_compiled_loop_follows_the_python_integrator_and_converges_in_few_iterations():
    """The same implicit midpoint rule in the compiled loop (Newton-Euler residual, M-based iteration matrix,
    extrapolating predictor) and in Python (a zero user force sends the rod there): the same trajectory to a few
    Newton tolerances (1e-10 here, so 1e-8 L on the tip). And the compiled loop's Newton effort on a swinging
    15-DOF rod swinging under gravity: at most 2.6 residual evaluations per step on average (measured 2.19 with
    the linearized-step predictor, 3.19 with the extrapolating predictor alone; the loop before issue 18 needed
    4.5), every step compiled, and the trajectory of a 1e-12 tolerance run to 1e-6 L."""
    fast = rod()
    slow = rod().add_force(lambda s, q, qd, t: np.zeros(7))
    assert fast.evaluation_path == "compiled" and slow.evaluation_path.startswith("python")
    q0 = np.array([0.5, 2.0, -1.0, 0.5, 1.0, 0.0, -0.5])
    a = fast.simulate(0.05, 1e-3, q0=q0, tol=1e-10)
    b = slow.simulate(0.05, 1e-3, q0=q0, tol=1e-10)
    assert a.stats["compiled_steps"] == 50 and b.stats["compiled_steps"] == 0
    assert np.abs(a.tip - b.tip).max() < 1e-8 * L
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=0.0, segments=10, order=2).add_gravity()
    tr = shp.simulate(0.3, 1e-3, record_every=10)
    assert tr.stats["compiled_steps"] == 300
    assert tr.stats["newton_iterations_per_step"] <= 2.6
    ref = shp.simulate(0.3, 1e-3, record_every=10, tol=1e-12)
    assert np.abs(tr.tip - ref.tip).max() < 1e-6 * L


@pytest.mark.parametrize("tau", [0.0, 1e-3])
def test_the_predictor_solves_a_linear_step_exactly(tau):
    """Small free vibrations (no gravity, tip amplitude 1e-5 L: the equations are linear to ~1e-10) with and
    without damping: the predictor, the exact midpoint step of the linearized equations, leaves Newton nothing
    to do, so a step costs one residual evaluation (mean <= 1.1; measured 1.013, the rest are the refreshes of
    the iteration matrix; an extrapolating predictor needs 2.0 here), and the trajectory equals a 1e-12
    tolerance run."""
    shp = Shapes(Basis.chebyshev(5), dofs=(5, 5, 5, 0, 0, 0), length=L, section=sdf.Circle(R), material=MAT,
                 damping=tau, segments=10, order=2)
    qd0 = np.r_[np.zeros(5), 1e-2 * np.ones(5), np.zeros(5)]
    tr = shp.simulate(0.3, 1e-3, qd0=qd0)
    assert tr.stats["compiled_steps"] == 300
    assert tr.stats["newton_iterations_per_step"] <= 1.1
    ref = shp.simulate(0.3, 1e-3, qd0=qd0, tol=1e-12)
    scale = np.abs(ref.tip[:, 1:]).max()
    assert scale > 1e-6 * L and np.abs(tr.tip - ref.tip).max() < 1e-7 * scale


def test_contact_with_an_obstacle_runs_in_the_compiled_loop_and_follows_the_python_integrator():
    """A three-chamber finger (the Suzumori finger's section: 80 mm, R 6 mm) bent by a chamber ramp onto a
    cylinder across its path, with damping and Coulomb friction 0.6: the contact runs inside the compiled loop
    (``compiled_steps`` = all; its force at the points between the Newton-Euler recursions, its stiffness and
    damping in the iteration matrix) and gives the trajectory of the Python step loop (a zero user force sends
    the finger there) to a few Newton tolerances (1e-10 here: 1e-8 L on the tip; measured 3.5e-13 m). The
    finger presses the cylinder (normal force > 0.1 N at the end) and slides on it (friction along the rod)."""
    from sorofem.units import kPa, mm

    def finger(python=False):
        shp = Shapes(Basis.chebyshev(3), (0, 3, 3, 0, 0, 0), length=80 * mm, section=sdf.Circle(6 * mm),
                     material=materials.NeoHookean(E=1e6, nu=0.3, density=2000.0, damping=0.1), segments=12,
                     contact_radius=6 * mm)
        shp.add_chamber(np.pi * (1.5 * mm) ** 2, (0.0, 3 * mm), name="c").add_gravity((0.0, 0.0, -9.81))
        shp.add_contact(sdf.Cylinder(10 * mm, 0.1, center=(60 * mm, 0.0, -20 * mm), axis=(0.0, 1.0, 0.0)),
                        stiffness=2e5, damping=20.0, friction=0.6, regularization=2e-3)
        return shp.add_force(lambda s, q, qd, t: np.zeros(s.n)) if python else shp

    def u(t):
        return [min(t / 0.2, 1.0) * 200 * kPa]
    fast, slow = finger(), finger(python=True)
    assert bm.integrator_loads(fast.model, fast.loads) is not None
    a = fast.simulate(0.5, 2e-3, u=u, tol=1e-10)
    b = slow.simulate(0.5, 2e-3, u=u, tol=1e-10)
    assert a.stats["compiled_steps"] == 250 and b.stats["compiled_steps"] == 0
    assert np.abs(a.tip - b.tip).max() < 1e-8 * 0.08
    F = fast.contact_forces(a.q[-1]).sum(axis=0)
    assert F[2] > 0.1 and abs(F[0]) > 1e-4


def test_an_obstacle_without_a_program_form_keeps_the_python_loop():
    """An SDF the program interpreter cannot run (a torus: no program form) sends the beam to the Python loop,
    which still integrates it (the contacts' lowering says None, not an error)."""
    shp = rod().add_contact(sdf.Torus(0.05, 0.01, center=(0.1, 0.0, -0.05)))
    assert bm.integrator_loads(shp.model, shp.loads) is None
    tr = shp.simulate(0.01, 1e-3)
    assert tr.stats["compiled_steps"] == 0 and len(tr.t) == 11
