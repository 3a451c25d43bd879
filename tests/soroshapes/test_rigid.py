"""Validation of rigid bodies (soroshapes.rigid) against closed forms.

References: conservation of kinetic energy and spatial angular momentum of a torque-free body (exact for the
midpoint rule, a quadratic-invariant-preserving integrator), steady rotation about a principal axis at
omega t, free fall z = z0 + vz t - g t^2/2, exponential decay of linearly damped rates, Newton's third law and
the potential of a conservative penalty contact (finite differences), and the sense in which friction turns a
bolt.
"""
import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ParameterError
from soroshapes import Basis, Model, Shapes, lie
from soroshapes.rigid import (RigidBody, SpinningBody, beam_contact, couple_contact, couple_grasp, couple_ground,
                              grasp_force, ground_contact)

I_BODY = np.array([1.0, 2.0, 3.0]) * 1e-3        # kg m^2


def rotation_angle(R):
    return np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))


# --------------------------------------------------------------------------------------------------------
# free body
# --------------------------------------------------------------------------------------------------------
def test_equations_follow_the_lie_conventions():
    rng = np.random.default_rng(0)
    b = RigidBody(0.3, [[2e-3, 1e-4, 0], [1e-4, 3e-3, 2e-4], [0, 2e-4, 4e-3]], gravity=(0, 0, 0))
    eta, u = rng.normal(size=6), rng.normal(size=6)
    g = lie.expSE3(rng.normal(size=6))
    xd = b.rhs(b.state(g, eta), u, 0.0)
    M = b.mass_matrix
    assert np.allclose(M @ xd[12:], lie.ad6(eta).T @ M @ eta + u, rtol=1e-12, atol=1e-12)
    assert np.allclose(xd[3:12].reshape(3, 3), g[:3, :3] @ lie.hat3(eta[:3]), atol=1e-12)
    assert np.allclose(xd[:3], g[:3, :3] @ eta[3:], atol=1e-12)


def test_torque_free_body_conserves_energy_and_angular_momentum_over_many_rotations():
    # omega mostly about the major axis with a tilt: the body tumbles (omega_b wanders) for ~10 turns
    b = RigidBody(0.2, I_BODY, twist0=[3.0, 2.0, 20.0, 0, 0, 0], gravity=(0, 0, 0), name="b")
    tr = Model().add(b).simulate(3.0, 2e-3, "midpoint", rtol=1e-11, record_every=25)
    X = tr["b"].x
    E = np.array([b.energy(x)["kinetic"] for x in X])
    L = np.array([b.momentum(x)[:3] for x in X])
    R = X[:, 3:12].reshape(-1, 3, 3)
    turns = np.sum(np.abs(X[:, 14])) * 25 * 2e-3 / (2 * np.pi)
    assert turns > 8
    assert np.ptp(X[:, 12]) > 1.0                                        # really tumbling
    assert np.max(np.abs(E / E[0] - 1)) < 1e-9
    assert np.max(np.linalg.norm(L - L[0], axis=1)) / np.linalg.norm(L[0]) < 1e-8
    assert np.max(np.abs(R.transpose(0, 2, 1) @ R - np.eye(3))) < 1e-9


def test_trapezoidal_keeps_the_invariants_to_its_truncation_error():
    b = RigidBody(0.2, I_BODY, twist0=[2.0, 0.3, 5.0, 0, 0, 0], gravity=(0, 0, 0), name="b")
    tr = Model().add(b).simulate(4.0, 1e-3, rtol=1e-10, record_every=50)
    X = tr["b"].x
    E = np.array([b.energy(x)["kinetic"] for x in X])
    L = np.array([b.momentum(x)[:3] for x in X])
    assert np.max(np.abs(E / E[0] - 1)) < 1e-6
    assert np.max(np.linalg.norm(L - L[0], axis=1)) / np.linalg.norm(L[0]) < 2e-6


def test_rotation_about_a_principal_axis_at_the_analytic_rate_second_order():
    w, T = 10.0, 1.0
    errors = []
    for dt in (2e-3, 1e-3):
        b = RigidBody(0.2, I_BODY, twist0=[0, 0, w, 0, 0, 0], gravity=(0, 0, 0), name="b")
        tr = Model().add(b).simulate(T, dt, rtol=1e-10, record_every=100)
        for t, x in zip(tr.t, tr["b"].x):
            assert np.allclose(x[12:15], [0, 0, w], atol=1e-9)                # stays about the axis
        Rexp = lie.expSO3(np.array([0, 0, w * T]))
        errors.append(rotation_angle(Rexp.T @ b.pose(tr["b"].x[-1])[:3, :3]))
    assert errors[1] < 1e-4                                                 # (h w)^3/12 per step: 8.3e-5
    assert 3.6 < errors[0] / errors[1] < 4.4


@pytest.mark.parametrize("spin", [0.0, 5.0])
def test_free_fall_matches_the_parabola(spin):
    g, z0, vz = 9.81, 0.3, 0.5
    pose0 = np.eye(4)
    pose0[2, 3] = z0
    b = RigidBody(0.05, I_BODY, pose0=pose0, twist0=[spin, 0, 0, 0, 0, vz], name="b")
    tr = Model().add(b).simulate(0.8, 1e-3, rtol=1e-10, record_every=40)
    z = np.array([b.pose(x)[2, 3] for x in tr["b"].x])
    xy = np.array([b.pose(x)[:2, 3] for x in tr["b"].x])
    # the spin turns the body frame, not the path of the centre of mass
    zexact = z0 + vz * tr.t - g * tr.t ** 2 / 2
    # without spin the trapezoidal rule is exact; with it the body-frame gravity turns at 5 rad/s and the
    # rule's O((h w)^2) error of the rotated force leaves 2.0e-5 m after 0.8 s (measured)
    assert np.max(np.abs(z - zexact)) < (1e-10 if spin == 0 else 3e-5)
    assert np.max(np.abs(xy)) < (1e-12 if spin == 0 else 3e-5)


def test_linear_and_angular_damping_decay_exponentially():
    m, cv, cw = 0.5, 0.8, 2e-3
    b = RigidBody(m, I_BODY, twist0=[0, 0, 4.0, 0.3, -0.2, 0.1], gravity=(0, 0, 0), damping=(cv, cw), name="b")
    tr = Model().add(b).simulate(1.0, 1e-3, rtol=1e-10, record_every=50)
    X = tr["b"].x
    # spin about z and body velocity: omega x v rotates v in the body, |v| decays at exactly cv/m
    speed = np.linalg.norm(X[:, 15:18], axis=1)
    assert np.allclose(speed, speed[0] * np.exp(-cv / m * tr.t), rtol=1e-5)            # measured 4.3e-6
    assert np.allclose(X[:, 14], 4.0 * np.exp(-cw / I_BODY[2] * tr.t), rtol=1e-7)      # measured 2.5e-8
    # position: the spatial velocity R v = v0_s exp(-cv t / m) (spin only rotates the body frame)
    p = np.array([b.pose(x)[:3, 3] for x in X])
    assert np.allclose(p, np.outer(1 - np.exp(-cv / m * tr.t), [0.3, -0.2, 0.1]) * m / cv, atol=1e-6)


# --------------------------------------------------------------------------------------------------------
# contact
# --------------------------------------------------------------------------------------------------------
R_BOLT, R_TUBE = 0.008, 0.003


def hexagon_prism(flat_radius, height):
    ang = np.arange(6) * np.pi / 3
    rc = flat_radius / np.cos(np.pi / 6)
    return sdf.Polygon(np.c_[rc * np.cos(ang), rc * np.sin(ang)]).extrude(height)


def finger(push=None, segments=10):
    """A finger hanging along -z, its tube overlapping the bolt's side (y = +R_BOLT) by 0.5 mm."""
    base = np.eye(4)
    base[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    base[:3, 3] = [0, R_BOLT + R_TUBE - 5e-4, 0.05]
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), length=0.05, section=sdf.Circle(R_TUBE),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), base=base, segments=segments,
                 damping=0.01)
    if push is not None:
        shp.add_point_load(force=push)
    return shp


def contact_scene():
    rng = np.random.default_rng(3)
    shp = finger()
    q, qd = 0.2 * rng.normal(size=shp.n), 2.0 * rng.normal(size=shp.n)
    g = lie.expSE3(np.array([0.02, -0.03, 0.4, 0.0005, 0.0, 0.0]))
    body = RigidBody(0.05, 1e-5, shape=hexagon_prism(R_BOLT, 0.04))
    x = body.state(g, [0.3, -0.2, 2.0, 0.01, 0.02, -0.01])
    return shp, body, q, qd, x


def test_contact_forces_obey_newtons_third_law():
    shp, body, q, qd, x = contact_scene()
    f, W, F = beam_contact(shp, body, 1e7, damping=50.0, friction=0.6, q=q, qd=qd, x=x, nodes=True)
    hit = np.nonzero(np.linalg.norm(F, axis=1))[0]
    assert len(hit) >= 3
    G = shp.forward_kinematics(q)
    g = body.pose(x)
    R, p = g[:3, :3], g[:3, 3]
    # force and moment about the body origin: equal and opposite
    assert np.allclose(R @ W[3:], -F.sum(axis=0), rtol=1e-12, atol=1e-12 * np.abs(F).max())
    M_beam = np.cross(G[:, :3, 3] - p, F).sum(axis=0)
    assert np.allclose(R @ W[:3], -M_beam, rtol=1e-10, atol=1e-12 * np.abs(M_beam).max())
    # the generalized force is the work-conjugate of the node forces
    J = shp.jacobian(q, at="all")
    f_nodes = sum(J[i, 3:].T @ (G[i, :3, :3].T @ F[i]) for i in range(len(F)))
    assert np.allclose(f, f_nodes, rtol=1e-12, atol=1e-14)
    # power: what the beam and the body receive is the power of the forces on the relative velocity
    eta_n = np.einsum("kij,j->ki", J, qd)
    v_node = np.einsum("kij,kj->ki", G[:, :3, :3], eta_n[:, 3:])
    Pb = (G[:, :3, 3] - p) @ R
    etab = body.twist(x)
    v_body = (etab[3:] + np.cross(etab[:3], Pb)) @ R.T
    assert np.isclose(f @ qd + W @ etab, np.sum(F * (v_node - v_body)), rtol=1e-10)


def test_frictionless_contact_is_the_gradient_of_its_penalty_energy():
    shp, body, q, _, x = contact_scene()
    k, r = 1e7, shp.contact_radius
    w = np.zeros(len(shp.sigma))
    w[:-1] += np.diff(shp.sigma) / 2
    w[1:] += np.diff(shp.sigma) / 2

    def energy(qq, g):
        P = (shp.forward_kinematics(qq)[:, :3, 3] - g[:3, 3]) @ g[:3, :3]
        delta = np.maximum(0.0, r - body.shape(P))
        return 0.5 * k * np.sum(w * delta ** 2)

    f, W = beam_contact(shp, body, k, q=q, x=x)
    g = body.pose(x)
    h = 1e-7
    fd_q = [-(energy(q + h * e, g) - energy(q - h * e, g)) / (2 * h) for e in np.eye(shp.n)]
    fd_w = [-(energy(q, g @ lie.expSE3(h * e)) - energy(q, g @ lie.expSE3(-h * e))) / (2 * h) for e in np.eye(6)]
    assert np.linalg.norm(f) > 1e-3 and np.linalg.norm(W) > 1e-3
    assert np.allclose(f, fd_q, rtol=1e-5, atol=1e-6 * np.abs(f).max())
    assert np.allclose(W, fd_w, rtol=1e-5, atol=1e-6 * np.abs(W).max())


@pytest.mark.parametrize("rate", [3.0, -3.0])
def test_a_spinning_body_drags_a_resting_finger_along_its_surface(rate):
    shp = finger()
    bolt = SpinningBody((0, 0, 1), 1e-6, shape=sdf.Cylinder(R_BOLT, 0.04), rate0=rate)
    q = np.zeros(shp.n)
    f0, W0, F0 = beam_contact(shp, bolt, 1e7, q=q, nodes=True)
    f, W, F = beam_contact(shp, bolt, 1e7, friction=0.5, regularization=1e-4, q=q, nodes=True)
    hit = np.nonzero(np.linalg.norm(F0, axis=1))[0]
    assert len(hit) >= 3
    # surface velocity at y = +R of a spin about +z is along -x * rate: friction pulls the finger that way
    # with |F_t| = mu |F_n| (slip 0.024 m/s >> regularization), and brakes the bolt
    Ft = F - F0
    assert np.allclose(Ft[hit, 0], -np.sign(rate) * 0.5 * np.linalg.norm(F0[hit], axis=1), rtol=1e-4)
    assert np.allclose(Ft[hit, 1:], 0.0, atol=1e-9)
    assert np.sign(W[2]) == -np.sign(rate) and abs(W0[2]) < 1e-12


def test_no_contact_gives_zero_forces():
    shp, body, q, qd, x = contact_scene()
    far = body.state(lie.expSE3(np.array([0, 0, 0, 1.0, 1.0, 1.0])))
    f, W = beam_contact(shp, body, 1e7, friction=0.5, q=q, qd=qd, x=far)
    assert not np.any(f) and not np.any(W)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_finger_rubbing_a_bolt_turns_it_with_friction_only(sign):
    rates = {}
    for mu in (0.0, 0.5):
        shp = finger(push=[sign * 0.05, 0, 0])                   # sweeps the finger along +-x
        bolt = RigidBody.spinning((0, 0, 1), 1e-6, 1e-6, sdf.Cylinder(R_BOLT, 0.04), name="bolt")
        mdl = Model().add(shp, "finger").add(bolt)
        couple_contact(mdl, "finger", "bolt", stiffness=1e7, friction=mu)
        tr = mdl.simulate(0.05, 1e-3)
        rates[mu] = tr["bolt"].x[-1, 1]
        tip = shp.forward_kinematics(tr["finger"].q[-1])[-1, :3, 3]
        assert sign * tip[0] > 1e-3                              # the finger did sweep
    # contact at y = +R: surface dragged along +x turns the bolt about -z (and a smooth cylinder not at all)
    assert abs(rates[0.0]) < 1e-9
    assert -sign * rates[0.5] > 1.0


def test_spinning_body_follows_its_axis_torque():
    bolt = SpinningBody((0, 0, 2.0), 2e-6, 4e-6, name="bolt", rate0=1.0)
    tr = Model().add(bolt).set_controller(lambda mdl: [0, 0, 1e-6, 5.0, 5.0, 5.0]).simulate(1.0, 1e-3,
                                                                                          rtol=1e-10)
    # I w' = -c w + tau: w = tau/c + (w0 - tau/c) exp(-c t / I)
    w_exact = 0.25 + 0.75 * np.exp(-2.0 * tr.t)
    assert np.allclose(tr["bolt"].x[:, 1], w_exact, rtol=1e-6)
    th = tr["bolt"].x[-1, 0]
    assert np.allclose(bolt.pose(tr["bolt"].x[-1])[:3, :3], lie.expSO3(np.array([0, 0, th])), atol=1e-12)


def test_a_cylinder_on_a_table_settles_and_the_table_carries_its_weight():
    """12 rim points on the plane z = 0, on an incline of the gravity below the friction angle: at rest the
    plane's wrench balances gravity exactly (force m g, no moment about the centre beyond the lever of the
    tilted gravity), and the body sinks by the penalty deflection m g cos / (12 k) only."""
    m, r, h, k = 0.045, 0.02, 0.04, 3e3
    grav = 9.81 * np.array([np.sin(0.2), 0.0, -np.cos(0.2)])        # 11.5 deg, mu = 0.5 holds it
    pose = np.eye(4)
    pose[2, 3] = h / 2
    body = RigidBody(m, [1e-5, 1e-5, 9e-6], pose0=pose, gravity=grav, name="cyl", normalization=20.0)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full(12, -h / 2)])
    mdl = couple_ground(Model().add(body), "cyl", rim, k, damping=2.0, friction=0.5, regularization=2e-4)
    tr = mdl.simulate(1.0, 2e-3, "bdf2", rtol=1e-7, atol=1e-10)
    x = tr["cyl"].x[-1]
    W = ground_contact(body, x, rim, k, 2.0, 0.5, 2e-4)
    R = body.pose(x)[:3, :3]
    assert np.allclose(R @ W[3:], -m * grav, rtol=2e-3, atol=1e-6)      # the table carries the weight
    sink = h / 2 - body.pose(x)[2, 3]
    assert sink == pytest.approx(m * 9.81 * np.cos(0.2) / (12 * k), rel=0.05)
    # at rest up to the regularized creep v = eps tan / sqrt(mu^2 - tan^2) = 0.44 eps
    assert np.linalg.norm(body.twist(x)[3:]) < 1e-4


def test_grasp_forces_are_equal_and_opposite_and_do_virtual_work():
    shp = finger()
    body = RigidBody(0.05, 1e-5, pose0=lie.expSE3(np.array([0.1, -0.2, 0.3, 0.004, R_BOLT, 0.001])))
    rng = np.random.default_rng(5)
    q, qd = 0.3 * rng.normal(size=shp.n), rng.normal(size=shp.n)
    x = body.state(body.pose(body.x0), np.array([0.5, -0.2, 0.1, 0.01, 0.02, -0.03]))
    anchor = np.array([0.0, 0.001, 0.002])
    F, fq, W = grasp_force(shp, body, q, qd, x, anchor, 500.0, 3.0)
    R = body.pose(x)[:3, :3]
    assert np.allclose(R @ W[3:], F) and np.allclose(W[:3], np.cross(anchor, R.T @ F))
    # the beam's generalized force is the work of -F at the tip: fq . dq = -F . dP_tip
    dq = 1e-7 * rng.normal(size=shp.n)
    dP = shp.positions(q + dq)[-1] - shp.positions(q - dq)[-1]
    assert fq @ (2 * dq) == pytest.approx(-F @ dP, rel=1e-5)


def test_a_closed_grasp_holds_a_hanging_body_and_an_open_one_lets_it_fall():
    shp = finger()
    tip = shp.positions(np.zeros(shp.n))[-1]
    pose = np.eye(4)
    pose[:3, 3] = tip - [0.0, 0.0, 0.01]                  # anchor 10 mm above the centre, at the tip
    for closed in (True, False):
        body = RigidBody(0.002, 2e-8, pose0=pose, name="load", normalization=20.0)
        mdl = Model().add(shp, "finger").add(body)
        couple_grasp(mdl, "finger", "load", anchor=(0, 0, 0.01), stiffness=200.0, damping=0.5,
                     engaged=(lambda t: 1.0) if closed else (lambda t: 0.0))
        tr = mdl.simulate(0.3, 2e-3, "bdf2")
        drop = pose[2, 3] - body.pose(tr["load"].x[-1])[2, 3]
        if closed:   # held: it hangs 2 g * 9.81 / 200 N/m + the finger's own sag below the start, not more
            assert drop < 0.002 * 9.81 / 200 + 1e-3
        else:
            assert drop == pytest.approx(9.81 * 0.3**2 / 2, rel=0.02)   # free fall


# --------------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, word", [
    (dict(mass=0.0), "mass"), (dict(mass=-1.0), "mass"), (dict(mass="heavy"), "mass"),
    (dict(inertia=[1e-3, -1e-3, 1e-3]), "inertia"), (dict(inertia=[[1e-3, 2e-3, 0], [0, 1e-3, 0], [0, 0, 1e-3]]),
                                                     "inertia"),
    (dict(inertia=np.ones((2, 2))), "inertia"), (dict(pose0=2 * np.eye(4)), "pose0"),
    (dict(twist0=np.zeros(5)), "twist0"), (dict(gravity=(0, -9.81)), "gravity"),
    (dict(damping=(-1.0, 0.0)), "damping"), (dict(shape=sdf.Circle(0.01)), "shape"),
])
def test_bad_parameters_name_the_parameter(kwargs, word):
    args = dict(mass=1.0, inertia=1e-3)
    args.update(kwargs)
    with pytest.raises(ParameterError, match=word):
        RigidBody(**args)


def test_bad_wrench_and_contact_inputs():
    b = RigidBody(1.0, 1e-3)
    with pytest.raises(ParameterError, match="wrench"):
        b.rhs(b.x0, np.zeros(3), 0.0)
    with pytest.raises(ParameterError, match="wrench"):
        SpinningBody((0, 0, 1), 1e-6).rhs(np.zeros(2), np.zeros(7), 0.0)
    with pytest.raises(ParameterError, match="inertia"):
        RigidBody.spinning((0, 0, 1), 0.0)
    with pytest.raises(ParameterError, match="axis"):
        SpinningBody((0, 0, 0), 1e-6)
    shp = finger()
    with pytest.raises(ParameterError, match="shape"):
        beam_contact(shp, b, 1e7, q=np.zeros(shp.n))
    with pytest.raises(ParameterError, match="stiffness"):
        beam_contact(shp, RigidBody(1.0, 1e-3, shape=sdf.Sphere(0.01)), 0.0, q=np.zeros(shp.n))
    mdl = Model().add(shp, "finger").add(b, "body")
    with pytest.raises(ParameterError, match="not a Shapes"):
        couple_contact(mdl, "body", "finger", 1e7)


# ------------------------------------------------------------------------------------------------------------
# contact between points on a tree's bodies and a rigid body (tree_contact, couple_tree_contact)
# ------------------------------------------------------------------------------------------------------------
def finger_tree():
    """A hub on a revolute joint with a two-mode finger on it (7 points on its face, 3 mm off its backbone)."""
    from soroshapes.tree import Tree
    shp = Shapes(Basis.chebyshev(2), dofs=(0, 2, 2, 0, 0, 0), length=0.05, section=sdf.Circle(0.004),
                 material=materials.NeoHookean(E=1e6, nu=0.45, density=1000.0), damping=0.0, segments=6)
    tree = Tree(gravity=(0.0, 0.0, -9.81)).add_link("hub", 0.02, 4e-6, joint="revolute", axis=(0, 1, 0))
    tree.add_beam("finger", shp, parent="hub")
    pts = [("finger", float(s), (0.0, 0.0, -0.003), 0.001) for s in shp.sigma[1:]]
    return tree, pts


def test_tree_contact_is_equal_and_opposite_and_does_virtual_work():
    """The tree's generalized force is the work-conjugate of the point forces (finite differences of the points'
    positions), the body's wrench is minus their force and moment, and the contact power is the forces' power
    on the relative velocity."""
    from soroshapes.rigid import tree_contact
    tree, pts = finger_tree()
    q = np.array([0.1, 2.0, -1.0, 0.5, 0.3])
    qd = np.array([0.4, -3.0, 1.0, 2.0, -1.0])
    # a block whose face cuts through the finger's lower face
    X0 = np.array([tree.frame(q, "finger", at=float(s))[:3, 3] + tree.frame(q, "finger", at=float(s))[:3, :3]
                   @ (0, 0, -0.003) for _, s, _, _ in pts])
    g = lie.expSE3(np.array([0.1, -0.2, 0.05, 0.0, 0.0, 0.0]))
    body = RigidBody(0.05, 1e-5, shape=sdf.Box((0.2, 0.2, 0.02)))
    n = g[:3, 2]
    g[:3, 3] = X0.mean(axis=0) - n * (0.01 + 0.0005)          # its top face 0.5 mm below the points' mean
    x = body.state(g, [0.3, -0.2, 1.0, 0.01, 0.02, -0.01])
    f, W, F, X = tree_contact(tree, body, pts, 2000.0, damping=1.0, friction=0.5, q=q, qd=qd, x=x, forces=True)
    assert np.allclose(X, X0, atol=1e-15)
    hit = np.nonzero(np.linalg.norm(F, axis=1))[0]
    assert len(hit) >= 2
    R, p = g[:3, :3], g[:3, 3]
    assert np.allclose(R @ W[3:], -F.sum(axis=0), rtol=1e-12, atol=1e-12 * np.abs(F).max())
    assert np.allclose(R @ W[:3], -np.cross(X - p, F).sum(axis=0), rtol=1e-10, atol=1e-12 * np.abs(F).max())

    def points(qq):
        return np.array([tree.frame(qq, "finger", at=float(s)) @ np.r_[0.0, 0.0, -0.003, 1.0] for _, s, _, _ in pts])
    h = 1e-7
    dX = [(points(q + h * e) - points(q - h * e))[:, :3] / (2 * h) for e in np.eye(tree.n)]
    assert np.allclose(f, [np.sum(F * d) for d in dX], rtol=1e-6, atol=1e-8 * np.abs(f).max())
    v_pts = sum(qd[i] * dX[i] for i in range(tree.n))
    etab = body.twist(x)
    v_body = (etab[3:] + np.cross(etab[:3], (X - p) @ R)) @ R.T
    assert np.isclose(f @ qd + W @ etab, np.sum(F * (v_pts - v_body)), rtol=1e-6)


def test_tree_contact_needs_force_inputs_and_a_shape():
    from soroshapes.rigid import TreeContact, couple_tree_contact
    tree, pts = finger_tree()
    c = TreeContact(tree, pts, 1000.0)
    mdl = Model().add(tree.system(name="t")).add(RigidBody(0.05, 1e-5, shape=sdf.Sphere(0.01), name="b"))
    with pytest.raises(ParameterError, match="force_inputs=True"):
        couple_tree_contact(mdl, "t", "b", c)
    mdl = Model().add(tree.system(name="t", force_inputs=True)).add(RigidBody(0.05, 1e-5, name="b"))
    with pytest.raises(ParameterError, match="no shape"):
        couple_tree_contact(mdl, "t", "b", c)
    with pytest.raises(ParameterError, match="stiffness"):
        TreeContact(tree, pts, -1.0)
    with pytest.raises(ParameterError, match="sit at a beam.s nodes"):
        TreeContact(tree, [("finger", 0.0123, (0, 0, 0), 0.001)], 1000.0)




def _finger_ball_model():
    """The finger tree (force inputs, compiled) swinging about its hub onto a floating ball (no gravity on it),
    coupled by tree contact; returns (model, tree). The finger lies along x from the hub; its face points (3 mm
    below its backbone, -z) hit a ball of 10 mm radius whose top is 2 mm below the face at x = 40 mm, so the
    falling finger meets it within ~20 ms."""
    from soroshapes.rigid import TreeContact, couple_tree_contact
    tree, pts = finger_tree()
    ball = RigidBody(0.02, 1e-6, pose0=lie.expSE3(np.array([0.0, 0.0, 0.0, 0.04, 0.0, -0.003 - 0.002 - 0.01])),
                     gravity=(0.0, 0.0, 0.0), shape=sdf.Sphere(0.01), name="ball")
    mdl = Model().add(tree.system(name="finger", q0=np.zeros(tree.n), force_inputs=True)).add(ball)
    couple_tree_contact(mdl, "finger", "ball", TreeContact(tree, pts, 2000.0, damping=0.5, friction=0.5,
                                                           regularization=1e-3))
    return mdl, tree


def test_tree_contact_runs_in_the_compiled_network_as_on_the_python_path():
    """couple_tree_contact compiled (the contact term puts its force on the tree block itself, the body gets the
    opposite wrench; soroshapes.network): the finger swings down about its hub onto a floating ball (no gravity
    on it) and pushes it. From a state in contact (30 ms, reached on the Python path) both paths take five steps
    and agree to the Newton tolerance (rtol = 1e-8: 1e-9 of the largest state; measured 1.4e-13 relative). Over
    the whole impact the two drift apart by far more (stiff pads, accelerations of 1e4 rad/s^2: round-off grows
    through the impact), so the window is short; the right-hand sides agree exactly at that state."""
    mdl, tree = _finger_ball_model()
    x0 = mdl.simulate(0.03, 1e-3, "bdf2", rtol=1e-8, atol=1e-10, compiled=False).x[-1]
    fast, slow = (mdl.simulate(0.005, 1e-3, "bdf2", x0=x0, t0=0.03, rtol=1e-8, atol=1e-10, compiled=c)
                  for c in (True, False))
    assert fast.stats["path"] == "compiled" and slow.stats["path"] == "python"
    assert np.abs(fast.x - slow.x).max() < 1e-9 * np.abs(slow.x).max()
    v = slow["ball"].x[:, 15:18]
    assert np.linalg.norm(v[0]) > 1e-2 and np.linalg.norm(v[-1] - v[0]) > 1e-6      # pushed, and still in contact


def test_tree_force_inputs_act_as_a_generalized_force():
    """Tree.system(force_inputs=True): n more inputs ``force<i>`` whose values enter as f_ext does."""
    tree, _ = finger_tree()
    fe = np.array([0.01, -0.2, 0.1, 0.05, 0.02])
    a = tree.system(name="a", force_inputs=True)
    b = tree.system(name="b", f_ext=lambda q, qd, t: fe)
    assert a.m == tree.n and a.input_names == [f"force{i}" for i in range(tree.n)]
    x = np.r_[np.array([0.1, 2.0, -1.0, 0.5, 0.3]), np.array([0.4, -3.0, 1.0, 2.0, -1.0])]
    assert np.allclose(a.rhs(x, fe, 0.0), b.rhs(x, np.zeros(0), 0.0), rtol=1e-12, atol=1e-12)
    assert not np.allclose(a.rhs(x, fe, 0.0), a.rhs(x, np.zeros(tree.n), 0.0))


def _finger_on_ball():
    """The scene of the test above and its trajectory over the first bounces of the finger on the ball (in contact
    at about 16, 34-36 and 46 ms)."""
    mdl, tree = _finger_ball_model()
    return mdl, tree, mdl.simulate(0.05, 1e-3, "bdf2", rtol=1e-8, atol=1e-10)


def test_the_tree_rows_of_the_newton_matrix_are_its_model_rows_and_contract_newton_like_the_differenced_ones():
    r"""The compiled network's Newton matrix takes the tree's rows as model rows (network._cheap_rows with model
    rows, and network.jacobian: :math:`M^{-1}(\partial f_{in}/\partial x - [K\;D])`, the contact term's force
    differenced, not the tree's dynamics; _treeblock.block_model_rows) and the body's rows by differences. At the
    states in contact of the finger bouncing on the ball, against forward differences of the whole network's
    right-hand side (network.rhs, the same steps):

    * the tree's rows in the ball's columns agree to the differences' round-off (the same differences of the
      contact force carried by the same :math:`M^{-1}`; measured 2e-11 of the block's largest entry, 1e-6 asked);
      the ball's rows are the same differences;
    * in the tree's own columns they leave out the inertial and gravity derivatives, so the Newton iteration
      with the model matrix :math:`A_m = I - cJ_m` on the true one :math:`A = I - cJ` contracts by the spectral
      radius of :math:`I - A_m^{-1}A`; at BDF2's c = 2h/3 with h = 2 ms (the manipulator demo's step) it is at
      most 1.7e-4 here (1e-3 asked), far below the rate (THETA_REFRESH = 0.1) at which the integrator refreshes a
      matrix."""
    from soroshapes import network
    from soroshapes.numerics import FD_STEP
    mdl, tree, traj = _finger_on_ball()
    net = mdl._lowered()
    N, n = traj.x.shape[1], tree.n
    acc, ball = slice(n, 2 * n), slice(2 * n, N)
    alls = np.ones(2, np.bool_)
    c = 2 * 2e-3 / 3
    touching = 0
    for t, x in zip(traj.t, traj.x):
        ws = (np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N))
        Jm, Jj, Jc = np.zeros((N, N)), np.zeros((N, N)), np.zeros((N, N))
        assert network._cheap_rows(t, x.copy(), net.arrays, np.ones(N), *ws, Jm, True, True)
        assert network.jacobian(t, x.copy(), net.arrays, np.ones(N), *ws, Jc, Jj)
        f0, fp, Jd = np.zeros(N), np.zeros(N), np.zeros((N, N))
        assert network.rhs(t, x, net.arrays, ws[0], f0, alls)
        for j in range(N):
            xj = x.copy()
            xj[j] += FD_STEP * max(abs(x[j]), 1.0)
            assert network.rhs(t, xj, net.arrays, ws[0], fp, alls)
            Jd[:, j] = (fp - f0) / (xj[j] - x[j])
        assert np.allclose(Jm, Jj, rtol=0, atol=1e-12 * np.abs(Jj).max())   # both modes: the tree's model rows
        assert np.array_equal(Jm[:n], np.eye(N)[n:2 * n])              # q' = qd
        assert np.allclose(Jm[ball], Jd[ball], rtol=0, atol=1e-9 * np.abs(Jd[ball]).max())
        big = np.abs(Jd[acc, ball]).max()
        assert np.allclose(Jm[acc, ball], Jd[acc, ball], rtol=0, atol=1e-6 * big)
        touching += big > 0.0                          # in contact: the ball moves the finger
        A, Am = np.eye(N) - c * Jd, np.eye(N) - c * Jm
        assert np.abs(np.linalg.eigvals(np.eye(N) - np.linalg.solve(Am, A))).max() < 1e-3
    assert touching >= 3


def _finger_on_spinning_bolt():
    """A finger (compiled: no point load) whose tube overlaps the side of a hexagonal bolt head spinning about z
    (the suzumori demo's coupling, couple_contact with friction), and states in contact: the overlap of
    ``finger()`` with random coordinates and rates, the bolt turned and turning."""
    shp = finger(segments=8)
    shp.add_gravity((0.0, 0.0, -9.81))
    bolt = RigidBody.spinning((0, 0, 1), 2e-6, 1e-5, hexagon_prism(R_BOLT, 0.04), name="bolt")
    mdl = Model().add(shp, "finger").add(bolt)
    couple_contact(mdl, "finger", "bolt", stiffness=2e5, damping=20.0, friction=0.6, regularization=2e-3)
    rng = np.random.default_rng(7)
    states = [np.r_[0.05 * rng.normal(size=shp.n), 0.2 * rng.normal(size=shp.n), 0.1 * rng.normal(), rate]
              for rate in (0.0, 0.3, -2.0)]
    return mdl, shp, states


def test_the_beam_contact_rows_of_the_newton_matrix_are_closed_form_and_contract_newton_like_the_differences():
    r"""The rows of a beam in contact with a spinning body, and the body's, are closed form in the compiled
    network's Newton matrix (network._contact_rows: the penalty's stiffness :math:`k(n - \mu v_t/s)n^T` and the
    damping and regularized friction's derivative through the nodes' Jacobians, soroshapes._contact.
    contact_jacobian), no differenced column. Against forward differences of the whole network's right-hand side
    (network.rhs) at states in contact:

    * the body's rows (its wrench through B) agree to 5 % of their largest entry: they leave out the normal's
      turning along the surface (its curvature, at the hexagon's edges) and the geometric stiffness (measured
      1.6e-8, 1.4e-2, 1.5e-4 at the three states);
    * in the beam's rows they leave out the inertial and gravity derivatives as well (the beam's model rows), so
      the Newton iteration with the model matrix :math:`A_m = I - cJ_m` on the true one :math:`A = I - cJ`
      contracts by the spectral radius of :math:`I - A_m^{-1}A`; at BDF2's c = 2h/3 with the demo's h = 2 ms it
      is at most 8.2e-4 here (5e-3 asked), far below the rate (THETA_REFRESH = 0.1) at which the integrator
      refreshes a matrix."""
    from soroshapes import network
    from soroshapes.numerics import FD_STEP
    mdl, shp, states = _finger_on_spinning_bolt()
    net = mdl._lowered()
    assert not isinstance(net, str), net
    table = net.arrays[0]
    assert np.all(table[:, 7] == 1)                       # the beam and the bolt: closed form, nothing differenced
    N, n = len(states[0]), shp.n
    alls = np.ones(2, np.bool_)
    c = 2 * 2e-3 / 3
    for x in states:
        ws = (np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N))
        Jm = np.zeros((N, N))
        assert network._cheap_rows(0.0, x.copy(), net.arrays, np.ones(N), *ws, Jm, True, True)
        f0, fp, Jd = np.zeros(N), np.zeros(N), np.zeros((N, N))
        assert network.rhs(0.0, x, net.arrays, ws[0], f0, alls)
        for j in range(N):
            xj = x.copy()
            xj[j] += FD_STEP * max(abs(x[j]), 1.0)
            assert network.rhs(0.0, xj, net.arrays, ws[0], fp, alls)
            Jd[:, j] = (fp - f0) / (xj[j] - x[j])
        _, _, F = beam_contact(shp, mdl["bolt"].system, 2e5, 20.0, 0.6, 2e-3, q=x[:n], qd=x[n:2 * n],
                               x=x[2 * n:], nodes=True)
        assert np.count_nonzero(np.linalg.norm(F, axis=1)) >= 2        # in contact
        M = shp.mass_matrix(x[:n])
        J1 = Jm.copy()
        J1[n:2 * n] = np.linalg.solve(M, Jm[n:2 * n])                  # the beam's rows in first-order form
        assert np.array_equal(Jm[:n], np.eye(N)[n:2 * n])              # q' = qd
        bolt = slice(2 * n, N)
        assert np.abs(J1[bolt] - Jd[bolt]).max() < 5e-2 * np.abs(Jd[bolt]).max()
        A, Am = np.eye(N) - c * Jd, np.eye(N) - c * J1
        assert np.abs(np.linalg.eigvals(np.eye(N) - np.linalg.solve(Am, A))).max() < 5e-3
