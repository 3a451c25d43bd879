"""Trees of bodies (soroshapes.tree): kinematics, Jacobians and dynamics against finite differences and closed
cases.

Checks and tolerances:

* Jacobians: every tree body Jacobian against forward differences of the frames (``numerics.fd_columns``,
  relative step 1.5e-8: truncation ~1e-8 of the second derivative, so 1e-6 of the largest entry); the
  Jacobian rate against differences of the Jacobian along the rates (same tolerance).
* A beam on the tip of a beam is one beam of the two lengths with the two-piece basis: same frames, M, C and
  f_g to round-off (1e-12 relative): the same segments, Magnus steps and Gregory weights (per piece) meet.
* A link glued by a fixed joint is one rigid body with the combined mass, centre of mass and inertia (parallel
  axes): same M, C, f_g to round-off.
* M symmetric positive definite; the kinetic energy 1/2 qd^T M qd against the energy summed from twists
  differenced from the frames; the Coriolis vector against the Lagrangian's
  :math:`\\dot M\\dot q - \\tfrac12\\partial_q(\\dot q^TM\\dot q)` with M differenced (forward differences of M:
  relative error ~1e-7, tolerance 1e-5 of the largest term); f_g against the differenced potential.
* Inverse dynamics undoes forward dynamics (1e-9 relative).
* Energy of an undamped beam-on-beam swing under gravity (implicit midpoint of the Model integrators).
* A beam on a hub spinning at a prescribed rate (a revolute joint with ``motion=spin(...)``): its first
  flapwise frequency, from the linearization about the relative equilibrium, against
  ``analytic.rotating_cantilever_frequency`` (the same rod as tests/soroshapes/test_constraints.py, which put
  the centrifugal field in as a user force; here the rotation is the library's own rotating base, so the
  sections' rotary inertia and all Coriolis terms are in: their effect is (r/L)^2 = 4e-6). Tolerance 1e-4.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import DataError, ParameterError
from soroshapes import Basis, Shapes, lie
from soroshapes.numerics import fd_columns
from soroshapes.tree import Tree, kinematics, spin

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from analytic import rotating_cantilever_frequency  # noqa: E402

MAT = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)


def rod(length=0.1, dofs=(1, 2, 2, 1, 0, 0), basis=None, segments=6, radius=5e-3, base=None):
    return Shapes(basis or Basis.chebyshev(2), dofs=dofs, length=length, section=sdf.Circle(radius), material=MAT,
                  segments=segments, damping=0.0, base=base)


def pose(w, p):
    g = np.eye(4)
    g[:3, :3], g[:3, 3] = lie.expSO3(np.asarray(w, dtype=float)), p
    return g


def mixed_tree():
    """A revolute hub (off-centre mass), a beam on it, a beam on that beam's middle node, a prismatic slider on
    the second beam's tip and a link glued to the slider, under gravity."""
    return (Tree(gravity=(0.0, -3.0, -9.81))
            .add_link("hub", 0.05, [1e-5, 2e-5, 3e-5], com=(0.01, 0.0, 0.002), joint="revolute", axis=(0, 0.3, 1),
                      offset=pose([0.1, 0, 0], [0, 0, 0.01]))
            .add_beam("arm", rod(), parent="hub", offset=pose([0, 0.2, 0], [0.02, 0, 0]))
            .add_beam("finger", rod(0.06, segments=4), parent="arm", at=0.05, offset=pose([0, 0, 0.7], [0, 0, 0]))
            .add_link("slider", 0.01, 1e-7, com=(0, 0.003, 0), parent="finger", joint="prismatic", axis=(1, 1, 0))
            .add_link("pad", 0.004, [1e-7, 3e-7, 2e-7], com=(0.002, 0, 0), parent="slider",
                      offset=pose([0.3, 0.2, 0.1], [0.01, 0, 0])))


FRAMES = [("hub", None), ("arm", 0.05), ("arm", None), ("finger", None), ("slider", None), ("pad", None)]


def state(tree, seed=1, size=1.0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=tree.n) * size, rng.normal(size=tree.n) * size


def body_differences(tree, q, body, at):
    """Columns vee(G^-1 dG/dq_k) by forward differences of the frame."""
    g0 = tree.frame(q, body, at)
    dG = fd_columns(lambda x: tree.frame(x, body, at).ravel(), q, g0.ravel(), np.ones(tree.n))
    Gi = lie.invSE3(g0)
    return np.column_stack([lie.vee6(Gi @ dG[:, k].reshape(4, 4)) for k in range(tree.n)])


def test_tree_jacobians_match_finite_differences_of_the_frames():
    tree = mixed_tree()
    q, _ = state(tree, size=3.0)
    for body, at in FRAMES:
        J = tree.jacobian(q, body, at)
        Jfd = body_differences(tree, q, body, at)
        assert np.abs(J - Jfd).max() < 1e-6 * np.abs(J).max(), body
        g = tree.frame(q, body, at)
        assert np.allclose(tree.jacobian(q, body, at, frame="spatial"), lie.Ad(g) @ J, atol=1e-14)
    # the child's columns: the arm's strain moves the finger, the finger's strain never moves the arm
    assert np.abs(tree.jacobian(q, "finger")[:, tree.coordinates("arm")]).max() > 0
    assert np.abs(tree.jacobian(q, "arm")[:, tree.coordinates("finger")]).max() == 0


def test_jacobian_rates_match_differences_of_the_jacobians():
    tree = mixed_tree()
    q, qd = state(tree, 2, size=2.0)
    data = tree.make_data()
    kinematics(tree, data, q, qd, rate=True)
    J0, Jd = data.J.copy(), data.Jd.copy()

    def jac(x):
        kinematics(tree, data, x)
        return data.J.ravel().copy()
    dJ = fd_columns(jac, q, J0.ravel(), np.ones(tree.n)) @ qd
    assert np.abs(Jd.ravel() - dJ).max() < 1e-6 * np.abs(Jd).max()
    assert np.array_equal(tree.jacobian_rate(q, qd, "finger"), Jd[tree.row("finger")])


def test_a_beam_on_a_beam_tip_is_one_beam_of_the_two_lengths():
    L, dofs = 0.08, (2, 2, 2, 2, 0, 0)       # per piece (a piecewise basis holds n modes on each piece)
    base = pose([0, 0.3, 0.2], [0, 0.01, 0])
    one = rod(2 * L, tuple(2 * d for d in dofs), Basis.piecewise_chebyshev(2, 2), segments=8, base=base)
    tree = (Tree(gravity=(1.0, 0.0, -9.81)).add_beam("a", rod(L, dofs, segments=4), offset=base)
            .add_beam("b", rod(L, dofs, segments=4), parent="a"))
    one.add_gravity((1.0, 0.0, -9.81))
    # the single beam orders its coordinates by strain, then piece; the tree by body, then strain
    perm = []
    for r, d in enumerate(dofs):
        perm += [("a", r, j) for j in range(d)] + [("b", r, j) for j in range(d)]
    order = {}
    pos = {"a": 0, "b": tree.coordinates("b").start}
    for body in "ab":
        for r, d in enumerate(dofs):
            for j in range(d):
                order[(body, r, j)] = pos[body]
                pos[body] += 1
    P = np.array([order[key] for key in perm])          # single-beam coordinate i is tree coordinate P[i]
    q1, qd1 = state(tree, 3, size=4.0)
    q, qd = np.empty(tree.n), np.empty(tree.n)
    q[P], qd[P] = q1, qd1
    G1 = one.forward_kinematics(q1)
    assert np.allclose(tree.frames(q, "a"), G1[:5], atol=1e-14)
    assert np.allclose(tree.frames(q, "b"), G1[4:], atol=1e-14)
    M, C, fg = one.dynamics(q1, qd1)
    Mt, Ct, fgt = tree.mass_matrix(q), tree.coriolis(q, qd), tree.gravity_force(q)
    assert np.allclose(Mt[np.ix_(P, P)], M, rtol=0, atol=1e-12 * np.abs(M).max())
    assert np.allclose(Ct[np.ix_(P, P)], C, rtol=0, atol=1e-12 * np.abs(C).max())
    assert np.allclose(fgt[P], fg, rtol=0, atol=1e-12 * np.abs(fg).max())
    assert np.allclose(tree.K[np.ix_(P, P)], one.K, rtol=1e-12, atol=1e-12 * np.abs(one.K).max())


def test_a_fixed_joint_glues_a_rigid_body():
    m1, c1, I1 = 0.05, np.array([0.01, 0.0, 0.002]), np.diag([1e-5, 2e-5, 3e-5])
    m2, I2 = 0.02, np.array([[2e-6, 1e-7, 0], [1e-7, 3e-6, 0], [0, 0, 1e-6]])
    X = pose([0.2, -0.1, 0.4], [0.03, 0.01, 0])
    c2 = np.array([0.004, 0.0, 0.001])                  # in the glued link's axes
    glued = (Tree(gravity=(0, 0, -9.81)).add_link("hub", m1, I1, com=c1, joint="revolute", axis=(0, 1, 1))
             .add_link("block", m2, I2, com=c2, parent="hub", offset=X)
             .add_beam("arm", rod(), parent="block"))
    # the combined body in the hub's axes: centre of mass and inertia by the parallel-axis theorem
    c2h = X[:3, :3] @ c2 + X[:3, 3]
    m = m1 + m2
    c = (m1 * c1 + m2 * c2h) / m

    def shift(I, mass, d):
        return I + mass * (d @ d * np.eye(3) - np.outer(d, d))
    I = shift(I1, m1, c1 - c) + shift(X[:3, :3] @ I2 @ X[:3, :3].T, m2, c2h - c)
    one = (Tree(gravity=(0, 0, -9.81)).add_link("hub", m, I, com=c, joint="revolute", axis=(0, 1, 1))
           .add_beam("arm", rod(), parent="hub", offset=X))
    q, qd = state(glued, 4, size=3.0)
    for fn in ("mass_matrix", "gravity_force"):
        a, b = getattr(glued, fn)(q), getattr(one, fn)(q)
        assert np.allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max()), fn
    a, b = glued.coriolis(q, qd), one.coriolis(q, qd)
    assert np.allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())
    assert np.allclose(glued.frame(q, "arm"), one.frame(q, "arm"), atol=1e-15)


def test_mass_matrix_is_spd_and_gives_the_kinetic_energy_of_the_differenced_twists():
    tree = mixed_tree()
    q, qd = state(tree, 5, size=2.0)
    M = tree.mass_matrix(q)
    assert np.allclose(M, M.T, rtol=0, atol=1e-15 * np.abs(M).max())
    assert np.linalg.eigvalsh(M)[0] > 0
    # twists of every stacked frame from differences of the frames along qd (no Jacobian involved)
    data = tree.make_data()
    w, Md = tree.weights, tree.inertias
    kinematics(tree, data, q)
    G0 = data.G.copy()
    h = 1e-7
    kinematics(tree, data, q + h * qd)
    eta = np.array([lie.vee6(lie.invSE3(G0[i]) @ (data.G[i] - G0[i]) / h) for i in range(len(w))])
    T = 0.5 * np.sum(w[:, None] * Md * eta**2)
    assert 0.5 * qd @ M @ qd == pytest.approx(T, rel=1e-6)


def test_coriolis_and_gravity_forces_follow_from_the_lagrangian():
    tree = mixed_tree()
    q, qd = state(tree, 6, size=2.0)
    n = tree.n
    M0 = tree.mass_matrix(q)
    dM = fd_columns(lambda x: tree.mass_matrix(x).ravel(), q, M0.ravel(), np.ones(n)).reshape(n, n, n)
    Mdot = dM @ qd                                        # sum_k dM/dq_k qd_k
    grad = np.array([qd @ dM[:, :, k] @ qd for k in range(n)])
    c_lagrange = Mdot @ qd - 0.5 * grad
    c = tree.coriolis(q, qd) @ qd
    assert np.abs(c - c_lagrange).max() < 1e-5 * np.abs(c).max()
    # dM/dt - 2C is skew
    S = Mdot - 2 * tree.coriolis(q, qd)
    assert np.abs(S + S.T).max() < 1e-5 * np.abs(Mdot).max()
    V = lambda x: tree.energy(x)["gravity"]              # noqa: E731
    dV = fd_columns(lambda x: np.array([V(x)]), q, np.array([V(q)]), np.ones(n))[0]
    fg = tree.gravity_force(q)
    assert np.abs(fg + dV).max() < 1e-6 * np.abs(fg).max()


def test_inverse_dynamics_undoes_forward_dynamics():
    shp = rod()
    shp.add_chamber(1e-5, (0, 3e-3))
    tree = (Tree(gravity=(0, 0, -9.81)).add_link("hub", 0.05, 1e-5, joint="revolute", axis=(0, 0, 1), actuated=True,
                                                 damping=1e-4, stiffness=2e-3)
            .add_beam("arm", shp, parent="hub", damping=0.01).add_beam("tip", rod(0.05), parent="arm"))
    assert tree.inputs == ("hub.torque", "arm.chamber0")          # in the order of the bodies
    q, qd = state(tree, 7)
    u = np.array([2e3, 1e-3])
    a = tree.forward_dynamics(q, qd, u=u)
    lhs = tree.inverse_dynamics(q, qd, a)
    rhs = tree.input_matrix @ u - tree.D @ qd - tree.K @ q
    assert np.allclose(lhs, rhs, rtol=0, atol=1e-9 * np.abs(rhs).max())
    assert np.allclose(tree.generalized_force(q, qd, u=u), tree.mass_matrix(q) @ a, rtol=1e-9,
                       atol=1e-9 * np.abs(rhs).max())


def test_inverse_kinematics_on_the_tree_reaches_poses_it_can_reach():
    """Targets made by the forward kinematics at a random q (so they are reachable): the finger's tip pose and
    the pad's position at once; the solution reproduces them to the tolerance (1e-8 m and rad x weight)."""
    tree = mixed_tree()
    q_true, _ = state(tree, 8, size=1.0)
    pose_tip, pad = tree.frame(q_true, "finger"), tree.frame(q_true, "pad")[:3, 3]
    ik = tree.inverse_kinematics([("finger", None, pose_tip), ("pad", None, pad)], q_true + 0.05, subtask="elastic")
    assert ik.converged and ik.error < 1e-8
    assert np.allclose(tree.frame(ik.q, "finger"), pose_tip, atol=1e-8)
    assert np.allclose(tree.frame(ik.q, "pad")[:3, 3], pad, atol=1e-8)


def test_base_wrenches_carry_the_joint_efforts_and_the_weight():
    """The wrench the parent exerts on a link's subtree, projected on the joint's screw, is the joint's row of
    the inverse dynamics (revolute hub, prismatic slider; 1e-10 relative); at rest the force on the whole tree
    is minus its weight (the straight beams' Gregory weights sum their masses exactly)."""
    tree = mixed_tree()
    q, qd = state(tree, 9)
    qdd = np.random.default_rng(10).normal(size=tree.n)
    tau = tree.inverse_dynamics(q, qd, qdd)
    for body, axis in (("hub", (0, 0.3, 1)), ("slider", (1, 1, 0))):
        a = np.array(axis, dtype=float) / np.linalg.norm(axis)
        screw = np.concatenate([a, np.zeros(3)]) if body == "hub" else np.concatenate([np.zeros(3), a])
        k = tree.coordinates(body).start
        assert screw @ tree.base_wrench(q, qd, qdd, body) == pytest.approx(tau[k], rel=1e-10, abs=1e-14)
    z = np.zeros(tree.n)
    mass = 0.05 + 0.01 + 0.004 + sum(1000.0 * np.pi * 5e-3**2 * length for length in (0.1, 0.06))
    W = tree.base_wrench(z, z, z, "hub")
    R = tree.frame(z, "hub")[:3, :3]
    assert np.allclose(W[3:], -mass * R.T @ tree.gravity, rtol=1e-12)


def test_tree_errors_name_the_fix():
    tree = Tree().add_beam("a", rod())
    with pytest.raises(ParameterError, match="already"):
        tree.add_beam("a", rod())
    with pytest.raises(ParameterError, match="add the parent first"):
        tree.add_beam("b", rod(), parent="nope")
    with pytest.raises(ParameterError, match="not one"):
        tree.add_beam("b", rod(), parent="a", at=0.0123)
    with pytest.raises(ParameterError, match="joint must be"):
        tree.add_link("l", joint="ball")
    with pytest.raises(ParameterError, match="fixed joint has no coordinate"):
        tree.add_link("l", actuated=True)
    with pytest.raises(ParameterError, match="gravity is the tree's"):
        tree.add_beam("b", rod().add_gravity(), parent="a")
    with pytest.raises(ParameterError, match="entries"):
        tree.frame(np.zeros(3), "a")
    with pytest.raises(DataError, match="NaN"):
        tree.frame(np.full(tree.n, np.nan), "a")
    data = tree.make_data()
    tree.add_beam("c", rod(), parent="a")
    with pytest.raises(ParameterError, match="make a new one"):
        kinematics(tree, data, np.zeros(tree.n))


# --------------------------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------------------------
def swing_tree():
    """Two soft rods, one on the other's tip, bending in a vertical plane, under gravity."""
    r = lambda: rod(0.1, (0, 0, 2, 0, 0, 0), segments=4, radius=2e-3)      # noqa: E731
    return Tree(gravity=(0, -9.81, 0)).add_beam("upper", r()).add_beam("lower", r(), parent="upper")


@pytest.mark.parametrize("case", ["beam_on_beam", "mixed"])
def test_undamped_swing_of_a_beam_on_a_beam_conserves_energy(case):
    """Energy kept to 1e-3 of the exchanged energy (the largest kinetic energy) by the implicit midpoint rule of
    the Model integrators at dt = 1 ms over 0.5 s (the beam-on-beam swing: measured 2.8e-5 of it); the mixed
    tree (hub, beams, slider, glued pad) over 0.1 s."""
    tree = swing_tree() if case == "beam_on_beam" else mixed_tree()
    traj = tree.simulate(0.5 if case == "beam_on_beam" else 0.1, 1e-3, method="midpoint")
    exchanged = traj.kinetic.max()
    drift = np.abs(traj.total - traj.total[0]).max()
    assert exchanged > 1e-4                                 # it swings: gravity does work on it
    assert drift < 1e-3 * exchanged


def test_a_tree_is_a_block_of_a_model_network_driven_by_its_controller():
    """A hub joint with an arm on it, PD-controlled to 0.5 rad through the network's controller (no gravity, no
    joint spring): it settles on the set point (the controller's integral-free law has no steady error here)."""
    from soroshapes import Model
    tree = (Tree().add_link("hub", 0.01, 1e-5, joint="revolute", axis=(0, 0, 1), actuated=True)
            .add_beam("arm", rod(0.1, (0, 0, 2, 0, 0, 0), segments=4, radius=2e-3), parent="hub", damping=0.01))
    block = tree.system()
    assert block.m == 1 and block.input_names == ["hub.torque"]
    net = Model().add(block, "tree")

    def pd(model):
        x = model["tree"].x
        return [0.05 * (0.5 - x[0]) - 0.01 * x[tree.n]]
    traj = net.set_controller(pd, reads=("tree",)).simulate(3.0, 0.01, "trapezoidal")
    q, _ = tree.state(traj.t[-1], traj["tree"].x[-1])
    assert q[0] == pytest.approx(0.5, abs=1e-3)


def test_the_soft_hand_on_one_palm_keeps_its_angular_momentum_about_a_free_wrist():
    """The seed's soft hand (the five fingers and chambers of demos/soft_hand.py) on one palm body hanging from a
    free revolute wrist across the bending planes, no gravity: the chambers curl the fingers (internal forces
    only), the palm turns the other way and the generalized momentum of the wrist, :math:`(M\\dot q)_\\theta`,
    stays zero (the wrist angle is cyclic). Implicit midpoint, dt = 2 ms, 0.2 s: measured 3.5e-6 of the palm's
    own momentum :math:`M_{\\theta\\theta}\\dot\\theta` (a nonlinear invariant, kept to O(dt^2)); tolerance 1e-4."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from demos import soft_hand as hand
    from sorofem.units import kPa
    section = sdf.RoundedRectangle(hand.WIDTH, hand.THICK, hand.CORNER)
    tree = Tree().add_link("palm", 0.1, [1e-4, 2e-4, 2e-4], com=(-0.03, 0, 0), joint="revolute", axis=(0, 1, 0))
    for i, (name, length) in enumerate(zip(hand.NAMES, hand.LENGTHS)):
        shp = Shapes(Basis.chebyshev(hand.MODES), dofs=(0, hand.MODES, 0, 0, 0, 0), length=length, section=section,
                     material=materials.DragonSkin10(), segments=10, order=2)
        shp.add_chamber(hand.CH_AREA, (0.0, hand.CH_OFFSET), name="chamber")
        tree.add_beam(name, shp, parent="palm", offset=hand.base_pose(i))
    assert tree.n == 26 and len(tree.inputs) == 5
    tr = tree.simulate(0.2, 2e-3, u=lambda t: np.full(5, 80 * kPa * min(t / 0.05, 1.0)), record_every=5)
    momentum = np.array([tree.mass_matrix(q)[0] @ qd for q, qd in zip(tr.q, tr.qd)])
    own = np.array([tree.mass_matrix(q)[0, 0] * qd[0] for q, qd in zip(tr.q, tr.qd)])
    assert abs(tr.q[-1, 0]) > 0.05                         # the palm turns (0.136 rad measured)
    assert np.abs(momentum).max() < 1e-4 * np.abs(own).max()


def spinning_frequency(spin_bar, modes=6):
    """(first flapwise frequency [rad/s] of the rod on a hub spinning about z at a prescribed rate, the
    reference)."""
    L, R = 0.5, 1e-3
    shp = Shapes(Basis.chebyshev(modes), dofs=(0, modes, 0, 1, 0, 0), length=L, section=sdf.Circle(R),
                 material=MAT, segments=20, damping=0.0)
    EI, rho_a = shp.E * np.pi * R**4 / 4, shp.density * np.pi * R**2
    rate = spin_bar * np.sqrt(EI / (rho_a * L**4))
    tree = Tree().add_link("hub", joint="revolute", axis=(0, 0, 1), motion=spin(rate)).add_beam("rod", shp,
                                                                                                parent="hub")
    free = tree.coordinates("rod")
    n = free.stop - free.start

    def acc(x):
        q, qd = np.zeros(tree.n), np.zeros(tree.n)
        q[free], qd[free] = x[:n], x[n:]
        return tree.forward_dynamics(q, qd)[free]
    x = np.zeros(2 * n)
    for _ in range(10):                  # the relative equilibrium: Newton on the accelerations at rest
        a = acc(x)
        if np.abs(a).max() < 1e-12 * (1 + rate**2):
            break
        x[:n] -= np.linalg.solve(fd_columns(lambda y: acc(np.concatenate([y, x[n:]])), x[:n], a,
                                            np.full(n, 1e-3)), a)
    a = acc(x)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:] = fd_columns(acc, x, a, np.full(2 * n, 1e-3))
    lam = np.linalg.eigvals(A)
    w = np.sort(np.abs(lam.imag[lam.imag > 1e-6]))[0]
    return w, rotating_cantilever_frequency(L, EI, rho_a, rate)


@pytest.mark.parametrize("spin_bar", [0.0, 2.0, 8.0])
def test_a_beam_on_a_spinning_hub_stiffens_like_the_rotating_cantilever(spin_bar):
    w, ref = spinning_frequency(spin_bar)
    assert w == pytest.approx(ref, rel=1e-4)


if __name__ == "__main__":        # the figures of the report: python tests/soroshapes/test_tree.py
    for name, tree, t_end, dt in [("beam-on-beam", swing_tree(), 0.5, d) for d in (2e-3, 1e-3, 5e-4)] + [
            ("mixed tree", mixed_tree(), 0.1, 1e-3)]:
        traj = tree.simulate(t_end, dt, method="midpoint")
        print(f"{name} swing over {t_end:g} s, midpoint, dt = {dt:g} s: exchanged energy {traj.kinetic.max():.4e} J, "
              f"drift {np.abs(traj.total - traj.total[0]).max():.3e} J "
              f"({np.abs(traj.total - traj.total[0]).max() / traj.kinetic.max():.2e} of it), "
              f"wall {traj.stats.get('wall_time', float('nan')):.2f} s")
    for sb in (0.0, 1.0, 2.0, 4.0, 8.0):
        w, ref = spinning_frequency(sb)
        print(f"beam on a spinning hub, spin {sb:g}: omega/omega_ref - 1 = {w / ref - 1:.2e}")


# ------------------------------------------------------------------------------------------------------------
# the compiled tree (soroshapes._treeblock), statics, controllers
# ------------------------------------------------------------------------------------------------------------
def test_the_compiled_tree_gives_the_accelerations_and_trajectory_of_the_per_body_path():
    """One compiled call over the tree (soroshapes._treeblock.tree_rhs) against soroshapes.tree.accelerations (a
    compiled call per body; the same equations): accelerations of the mixed tree with a prescribed spinning link
    to round-off (1e-10 relative); the undamped swing of the beam-on-beam tree on both paths to the Newton
    tolerance (1e-3 of rtol = 1e-6 relative per step, over 100 steps: 1e-7 of the largest coordinate)."""
    from soroshapes import _treeblock
    tree = mixed_tree().add_link("spinner", 0.01, 1e-6, com=(0.01, 0, 0), parent="hub", joint="revolute",
                                 axis=(1, 0, 0), motion=spin(3.0, 0.2))
    q, qd = state(tree, 4)
    free = tree._arrays()[7]
    qq, qqd, a, _ = tree._full(0.3, q[free], qd[free])
    u = np.linspace(0.1, 0.2, len(tree.inputs))
    low = _treeblock.lower(tree)
    out = np.zeros(tree.n)
    assert _treeblock.tree_rhs(*low.args, qq, qqd, a, u, np.zeros(tree.n), out)
    ref = tree.forward_dynamics(qq, qqd, 0.3, u)
    assert np.abs(out - ref).max() < 1e-10 * np.abs(ref).max()
    assert out[tree.coordinates("spinner")][0] == 0.0                # spin(3.0): no acceleration
    sw = swing_tree()
    q0 = np.zeros(sw.n)
    q0[sw.coordinates("upper")] = 2.0
    fast = sw.simulate(0.1, 1e-3, q0=q0)
    slow = sw.simulate(0.1, 1e-3, q0=q0, compiled=False)
    assert np.abs(fast.q - slow.q).max() < 1e-7 * np.abs(slow.q).max()


def test_statics_of_a_beam_on_a_beam_tip_is_that_of_one_beam_of_the_two_lengths():
    """Tree.statics under gravity against Shapes.statics of the two-piece beam (the same discrete model, see
    the test above): both Newton solves stop at 1e-9 of the elastic force, so the coordinates agree to 1e-7."""
    L, dofs = 0.08, (2, 2, 2, 2, 0, 0)
    one = rod(2 * L, tuple(2 * d for d in dofs), Basis.piecewise_chebyshev(2, 2), segments=8)
    tree = (Tree(gravity=(0.0, 0.0, -9.81)).add_beam("a", rod(L, dofs, segments=4))
            .add_beam("b", rod(L, dofs, segments=4), parent="a"))
    one.add_gravity((0.0, 0.0, -9.81))
    perm, pos = [], {"a": 0, "b": tree.coordinates("b").start}
    order = {}
    for body in "ab":
        for r, d in enumerate(dofs):
            for j in range(d):
                order[(body, r, j)] = pos[body]
                pos[body] += 1
    for r, d in enumerate(dofs):
        perm += [order[("a", r, j)] for j in range(d)] + [order[("b", r, j)] for j in range(d)]
    P = np.array(perm)
    got = tree.statics(steps=2)
    ref = one.statics(steps=2)
    ref = ref[0] if isinstance(ref, tuple) else getattr(ref, "q", ref)
    assert np.abs(got.q[P] - ref).max() < 1e-7 * np.abs(ref).max()
    assert np.abs(ref).max() > 0.5                                   # a large sag, not the linear regime
    tip = tree.frame(got.q, "b")[:3, 3]
    assert tip[2] < -0.02


def test_statics_of_a_two_link_arm_with_joint_springs_under_gravity():
    r"""Two links on revolute joints about y with springs :math:`k_1, k_2`, under gravity along -z: the
    equilibrium of :math:`V = \tfrac12 k_1\theta_1^2 + \tfrac12 k_2\theta_2^2 - g[(m_1l_1 + m_2L_1)\sin\theta_1
    + m_2 l_2\sin(\theta_1+\theta_2)]`, i.e. :math:`k_1\theta_1 = g[(m_1l_1 + m_2L_1)\cos\theta_1 + m_2l_2
    \cos(\theta_1+\theta_2)]`, :math:`k_2\theta_2 = g m_2 l_2\cos(\theta_1+\theta_2)` (solved by scipy to
    1e-14); Tree.statics to 1e-9 relative."""
    from scipy.optimize import fsolve
    g, m1, m2, l1, l2, L1, k1, k2 = 9.81, 0.2, 0.1, 0.05, 0.04, 0.1, 0.3, 0.05
    tree = (Tree(gravity=(0.0, 0.0, -g))
            .add_link("l1", m1, 1e-5, com=(l1, 0, 0), joint="revolute", axis=(0, 1, 0), stiffness=k1)
            .add_link("l2", m2, 1e-5, com=(l2, 0, 0), parent="l1", offset=pose([0, 0, 0], [L1, 0, 0]),
                      joint="revolute", axis=(0, 1, 0), stiffness=k2))

    def eqs(th):
        return [k1 * th[0] - g * ((m1 * l1 + m2 * L1) * np.cos(th[0]) + m2 * l2 * np.cos(th[0] + th[1])),
                k2 * th[1] - g * m2 * l2 * np.cos(th[0] + th[1])]
    ref = fsolve(eqs, [0.5, 0.3], xtol=1e-14)
    assert np.abs(eqs(ref)).max() < 1e-12
    got = tree.statics(steps=4)
    assert np.allclose(got.q, ref, rtol=1e-9, atol=0)
    assert ref[0] > 0.5                                                # a large rotation


def test_statics_refuses_a_tree_without_stiffness():
    tree = Tree(gravity=(0, 0, -9.81)).add_link("l", 0.1, 1e-5, com=(0.1, 0, 0), joint="revolute", axis=(0, 1, 0))
    with pytest.raises(ParameterError, match="stiffness"):
        tree.statics()


def controlled_arm():
    """A hub on a revolute joint about z (actuated: a torque) with a soft arm bending about z (two linear
    actuators on its two curvature modes), under gravity along -y: planar in x-y, 3 coordinates, 3 inputs."""
    arm = rod(0.1, (0, 0, 2, 0, 0, 0), segments=4, radius=2e-3)
    arm.add_actuator(np.array([1e-3, 0.0])).add_actuator(np.array([0.0, 1e-3]))
    return (Tree(gravity=(0.0, -9.81, 0.0))
            .add_link("hub", 0.01, 1e-6, joint="revolute", axis=(0, 0, 1), actuated=True, damping=1e-4)
            .add_beam("arm", arm, parent="hub", damping=0.01))


def test_the_impedance_controller_brings_a_tree_tip_to_its_set_point():
    r"""soroshapes.control.impedance on the whole tree (Tree.system's controller face: M, C, f_g, K, B and the
    arm's tip frame with its tree Jacobian over the hub and the arm): with elastic and gravity compensation the
    closed loop rests where :math:`J^T K_c(p_d - p)` balances the null-space term, which vanishes at the
    posture reached, so the tip sits on :math:`p_d`. From a bent arm (the straight one is a singular posture of
    the planar task: both columns move the tip along y only) the error decays about 5x per 0.1 s (measured:
    1.8e-9 m at 1 s); after 1.5 s within 1e-6 m (the Newton tolerance's share is far below)."""
    from soroshapes import Model
    from soroshapes.control import impedance, pd
    tree = controlled_arm()
    assert tree.n == 3 and len(tree.inputs) == 3
    target = np.array([0.05, 0.07])
    ctrl = impedance("tree", stiffness=1.0, damping=0.06, setpoint=target, axes=(0, 1), null_damping=1e-5)
    q0 = np.array([0.0, 8.0, 0.0])
    net = Model().add(tree.system(q0=q0), "tree").set_controller(ctrl)
    traj = net.simulate(1.5, 0.005, "trapezoidal")
    q, _ = tree.state(traj.t[-1], traj["tree"].x[-1])
    tip = tree.frame(q, "arm")[:3, 3]
    start = tree.frame(q0, "arm")[:3, 3]
    assert np.linalg.norm(start[:2] - target) > 0.05
    assert np.linalg.norm(tip[:2] - target) < 1e-6
    assert abs(q[0]) > 1e-3 and abs(q[2]) > 1e-4          # the hub and both arm modes took part
    # joint-space PD with compensation holds the whole tree's coordinates at a set-point
    qd = np.array([0.4, 5.0, -2.0])
    net = Model().add(tree.system(), "tree").set_controller(pd("tree", kp=[1e-2, 1e-3, 1e-4], kd=[1e-3, 1e-5, 1e-6],
                                                               setpoint=qd))
    traj = net.simulate(3.0, 0.005, "trapezoidal")
    assert np.allclose(traj["tree"].x[-1, :3], qd, atol=1e-4 * np.abs(qd).max())


def test_a_tree_block_runs_inside_the_compiled_network_kernel_as_on_the_python_path():
    """Tree.simulate picks the compiled network (soroshapes.network's TREE block, the integrator of
    soroshapes.integrate): the undamped beam-on-beam swing agrees with the Python path (compiled=False) to the
    Newton tolerance (corrections below 1e-3 of rtol = 1e-6 relative per step, two stopping rules: 1e-6 of the
    largest coordinate over 100 steps), and a hub torque from a Schedule controller drives the tree alike on
    both paths."""
    from soroshapes import Model
    from soroshapes.network import Schedule
    sw = swing_tree()
    q0 = np.zeros(sw.n)
    q0[sw.coordinates("upper")] = 2.0
    fast = sw.simulate(0.1, 1e-3, q0=q0)
    slow = sw.simulate(0.1, 1e-3, q0=q0, compiled=False)
    assert fast.stats["path"] == "compiled" and slow.stats["path"] == "python"
    assert np.abs(fast.q - slow.q).max() < 1e-6 * np.abs(slow.q).max()
    tree = controlled_arm()
    sched = Schedule([0.0, 0.1, 0.2], [[0.0, 0.0, 0.0], [2e-3, 0.01, -0.01], [0.0, 0.0, 0.0]])
    runs = [Model().add(tree.system(q0=np.array([0.0, 8.0, 0.0])), "tree").set_controller(sched)
            .simulate(0.3, 2e-3, "midpoint", compiled=c) for c in (None, False)]
    assert runs[0].stats["path"] == "compiled" and runs[1].stats["path"] == "python"
    x0, x1 = runs[0]["tree"].x, runs[1]["tree"].x
    assert np.abs(x0[:, :3] - x1[:, :3]).max() < 1e-6 * np.abs(x1[:, :3]).max()
    assert np.abs(x1[-1, 0]) > 1e-3                                   # the torque turned the hub
