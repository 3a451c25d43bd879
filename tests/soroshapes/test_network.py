"""The compiled network (soroshapes.network) against the Python path of Model.simulate on the same networks.

Each block and coupling kind that lowers (beams with gravity and chambers, isothermal/polytropic/regulated
reservoirs, constant or StateMap volumes, output couplings, StateMap input couplings, Schedule controllers) is run
on both paths: the trajectories agree to the Newton tolerance (the compiled Newton stops on a rate-based error
estimate of the same tolerance, per connected component, so the two differ by far less than the tolerance
``rtol |x| + atol s`` itself). Closed forms anchor the compiled path too (Boyle's law). Bad input gives clear
errors; a failed run leaves the model usable.
"""
import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ConvergenceError, DataError, ParameterError
from soroshapes import Basis, Fluidic, Model, Shapes, StateSpace
from soroshapes.network import Schedule, StateMap

V0 = 1e-6


def finger(modes=2, gravity=True):
    mat = materials.NeoHookean(E=1e6, nu=0.45, density=1000)
    shp = Shapes(Basis.chebyshev(modes), dofs=(0, 0, modes, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
                 material=mat, damping=0.03, segments=6)
    if gravity:
        shp = shp.add_gravity((0, -9.81, 0))
    return shp.add_chamber(area=5e-5, offset=(0.003, 0))


def hand_like(fingers=2):
    """Fingers, each with a regulated reservoir whose volume follows the finger (StateMap) and a periodic
    set-point table."""
    mdl = Model()
    for i in range(fingers):
        fl = Fluidic(None, V0=V0, regulator=dict(kp=2e-9, ki=2e-7, max_flow=1e-5))
        mdl.add(finger(), f"f{i}").add(fl, f"p{i}")
        mdl.connect(f"p{i}", f"f{i}")
        mdl.connect(StateMap(f"f{i}", [0.1], index=0, offset=V0, scale=0.2 * V0, function="tanh"), f"p{i}",
                    port="volume")
    t = np.linspace(0.0, 0.5, 51)
    mdl.set_controller(Schedule(t, {f"p{i}": 30e3 * np.sin(2 * np.pi * 2 * t + i)[:, None] for i in range(fingers)},
                                period=0.5))
    return mdl


def both(make, *args, **kw):
    a = make().simulate(*args, compiled=True, **kw)
    b = make().simulate(*args, compiled=False, **kw)
    assert a.stats["path"] == "compiled" and b.stats["path"] == "python"
    return a, b


def close(a, b, rtol, atol, scale=1.0):
    """Agreement well inside the Newton tolerance (1e-3 of which each step's iterate is within)."""
    err = np.abs(a - b) / (rtol * np.abs(b) + atol * scale)
    return float(np.max(err))


@pytest.mark.parametrize("method", ["trapezoidal", "midpoint", "bdf2"])
def test_beams_reservoirs_statemaps_and_schedules_compiled_equal_python(method):
    rtol, atol = 1e-7, 1e-9
    a, b = both(hand_like, 0.4, 2e-3, method, rtol=rtol, atol=atol)
    for i in range(2):
        # beam states O(1..100): a few tolerances after 200 steps of error propagation
        assert close(a[f"f{i}"].x, b[f"f{i}"].x, rtol, atol) < 10
        assert np.max(np.abs(a[f"p{i}"].pressure - b[f"p{i}"].pressure)) < 1e-5 * 30e3
        assert np.allclose(a[f"p{i}"].volume, b[f"p{i}"].volume, rtol=1e-9)
    assert np.allclose(a.u, b.u, rtol=1e-5, atol=1e-3)
    assert a["f0"].q.shape == b["f0"].q.shape and np.array_equal(a.t, b.t)


def test_beams_run_second_order_on_their_model_matrix_kept_across_steps():
    """The compiled step solves the beams second order with the model iteration matrix (M, K, D and the
    differenced input force): no differenced Jacobian, no failed model matrix, and the factored matrix serves
    several steps (the reuse rule), on the hand-like network whose trajectory the test above compares."""
    tr = hand_like(2).simulate(0.2, 1e-3, "bdf2", rtol=1e-6, atol=1e-9, compiled=True)
    st = tr.stats
    assert st["path"] == "compiled" and st["cut_steps"] == 0
    assert st["jacobians"] == 0 and st["model_matrix_failures"] == 0
    assert 1 <= st["matrices"] < st["steps"]


def test_a_beam_bending_in_one_plane_takes_the_planar_recursions_and_equals_python():
    """Fingers that bend about their body y axis only lower with the planar flag (their residual and mass matrix
    by soroshapes._beam.newton_euler_planar / mass_matrix_planar); the compiled run equals the Python path's
    (the general recursions) to a few tolerances, as the hand-like network above does. The hand-like fingers,
    which bend about z, keep the general recursions."""
    def make():
        mdl = Model()
        mat = materials.NeoHookean(E=1e6, nu=0.45, density=1000)
        for i in range(2):
            shp = Shapes(Basis.chebyshev(3), dofs=(0, 3, 0, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
                         material=mat, damping=0.03, segments=6).add_gravity((0, 0.3, -9.81))
            shp.add_chamber(area=5e-5, offset=(0, 0.003))
            fl = Fluidic(None, V0=V0, regulator=dict(kp=2e-9, ki=2e-7, max_flow=1e-5))
            mdl.add(shp, f"f{i}").add(fl, f"p{i}")
            mdl.connect(f"p{i}", f"f{i}")
            mdl.connect(StateMap(f"f{i}", [0.1], index=0, offset=V0, scale=0.2 * V0, function="tanh"), f"p{i}",
                        port="volume")
        t = np.linspace(0.0, 0.5, 51)
        mdl.set_controller(Schedule(t, {f"p{i}": 30e3 * np.sin(2 * np.pi * 2 * t + i)[:, None] for i in range(2)},
                                    period=0.5))
        return mdl
    assert make()._lowered().arrays[1][:, 9].tolist() == [1, 1]
    assert hand_like()._lowered().arrays[1][:, 9].tolist() == [0, 0]
    rtol, atol = 1e-7, 1e-9
    a, b = both(make, 0.4, 2e-3, "bdf2", rtol=rtol, atol=atol)
    for i in range(2):
        assert close(a[f"f{i}"].x, b[f"f{i}"].x, rtol, atol) < 10
        assert np.max(np.abs(a[f"p{i}"].pressure - b[f"p{i}"].pressure)) < 1e-5 * 30e3
    assert np.ptp(a["f0"].q[:, 0]) > 1.0                                  # the fingers do bend


def test_recording_and_continuing_from_t0_on_the_compiled_path():
    full = hand_like(1).simulate(0.2, 2e-3, "trapezoidal", compiled=True)
    sparse = hand_like(1).simulate(0.2, 2e-3, "trapezoidal", compiled=True, record_every=7)
    assert np.allclose(sparse.t, np.r_[full.t[::7], full.t[-1]])
    assert np.array_equal(sparse.x, np.vstack([full.x[::7], full.x[-1:]]))
    # a run continued from t0 (the periodic schedule sees the absolute time) equals one run
    mdl = hand_like(1)
    first = mdl.simulate(0.1, 2e-3, "trapezoidal", compiled=True)
    second = mdl.simulate(0.1, 2e-3, "trapezoidal", compiled=True, x0=first.x[-1], t0=0.1)
    assert second.t[0] == pytest.approx(0.1) and second.t[-1] == pytest.approx(0.2)
    assert np.allclose(second.x[-1], full.x[-1], rtol=1e-6, atol=1e-9)


def test_evaluation_paths_say_which_path_runs_and_why():
    mdl = hand_like(1)
    assert mdl.evaluation_path == "compiled"
    assert mdl.evaluation_paths["controller"] == "compiled"
    mdl.set_controller(lambda m: {"p0": [1e3]})
    why = mdl.evaluation_path
    assert why.startswith("python:") and "Python controller" in why
    with pytest.raises(ParameterError, match="no compiled form.*Python controller"):
        mdl.simulate(0.01, 1e-3, compiled=True)
    # still runs, on the Python path
    assert mdl.simulate(0.01, 2e-3).stats["path"] == "python"


def loaded_beam(frame, planar, load=True):
    """A damped beam under gravity with a constant tip load (force and, off the plane, a moment) in ``frame``;
    ``planar``: it bends about its body y axis only (the planar recursions); ``load`` False: without the load."""
    mat = materials.NeoHookean(E=1e6, nu=0.45, density=1000)
    dofs = (0, 3, 0, 0, 0, 0) if planar else (0, 2, 2, 0, 0, 0)
    shp = Shapes(Basis.chebyshev(3 if planar else 2), dofs=dofs, length=0.1, section=sdf.Circle(0.005),
                 material=mat, damping=0.03, segments=6).add_gravity((0, 0, -9.81))
    if not load:
        return shp
    return shp.add_point_load(force=(0.0, 0.02, -0.05), moment=None if planar else (1e-3, 0.0, 0.0), frame=frame)


@pytest.mark.parametrize("frame", ["spatial", "body"])
@pytest.mark.parametrize("planar", [False, True])
def test_a_beam_with_a_constant_point_load_runs_compiled_and_equals_python(frame, planar):
    """A constant point load (a dead load in the spatial frame, a follower load in the body frame) lowers with
    its beam: nodes, wrenches and frames in the network's flat arrays, evaluated by the beam's own recursions
    (soroshapes._beam.newton_euler, planar or not). The compiled trajectory equals the Python path's (the same
    load through Shapes' kernels) to 10 Newton tolerances, and differs from the unloaded beam's by far more."""
    def make(load=True):
        return Model().add(loaded_beam(frame, planar, load), "b")
    mdl = make()
    assert mdl.evaluation_path == "compiled" and mdl.evaluation_paths == {"b": "compiled"}
    bint = mdl._lowered().arrays[1]
    assert bint[0, 9] == int(planar) and bint[0, 12] == 1        # the planar flag, one point load
    rtol, atol = 1e-7, 1e-9
    a, b = both(make, 0.2, 2e-3, "bdf2", rtol=rtol, atol=atol)
    assert close(a["b"].x, b["b"].x, rtol, atol) < 10
    free = make(load=False).simulate(0.2, 2e-3, "bdf2", rtol=rtol, atol=atol, compiled=True)
    assert np.max(np.abs(free["b"].q - a["b"].q)) > 0.1 * np.max(np.abs(a["b"].q))


def test_a_time_varying_point_load_keeps_the_python_path_and_says_why():
    shp = finger().add_point_load(force=lambda t: (0.0, -0.01 * t, 0.0))
    mdl = Model().add(shp, "f")
    assert shp.evaluation_path == "compiled"                        # the beam alone: its own kernels
    why = mdl.evaluation_path
    assert why.startswith("python: beam 'f' (a time-varying point load") and "constant ones run compiled" in why
    assert mdl.evaluation_paths["f"].startswith("python: a time-varying point load")
    with pytest.raises(ParameterError, match="no compiled form.*time-varying point load"):
        mdl.simulate(0.01, 1e-3, compiled=True)
    assert mdl.simulate(0.01, 2e-3).stats["path"] == "python"


def test_contact_with_a_shape_without_program_or_a_statespace_keeps_the_python_path():
    shp = finger().add_contact(sdf.Torus(0.01, 0.003).translate((0.05, -0.1, 0.0)), stiffness=1e4)
    path = Model().add(shp, "f").evaluation_path
    assert path.startswith("python: beam 'f' (contact with an obstacle: the SDF node 'torus' (no program form")
    from soroshapes import StateSpace
    ss = StateSpace(lambda x, u, t: -x, 1, 0)
    assert "StateSpace" in Model().add(ss, "s").evaluation_path


@pytest.mark.parametrize("polytropic", [1.0, 1.4])
def test_reservoir_with_a_statemap_volume_of_a_beam(polytropic):
    """An unregulated reservoir fed by a scheduled mass flow, its volume a linear map of a beam's state."""
    def make():
        fl = Fluidic(None, V0=V0, polytropic=polytropic, filter_gain=200.0)
        mdl = Model().add(finger(), "f").add(fl, "p").connect("p", "f")
        mdl.connect(StateMap("f", [[1e-8, 0.0]], index=[0, 1], offset=V0), "p", port="volume")
        return mdl.set_controller(Schedule([0.0, 0.1, 0.2], {"p": [[0.0], [2e-7], [0.0]]}))
    rtol, atol = 1e-8, 1e-10
    a, b = both(make, 0.3, 1e-3, "bdf2", rtol=rtol, atol=atol)
    assert close(a["f"].x, b["f"].x, rtol, atol) < 10
    assert np.max(np.abs(a["p"].pressure - b["p"].pressure)) < 1e-6 * np.max(np.abs(b["p"].pressure))
    assert np.max(np.abs(b["p"].pressure)) > 1e3            # something happened


def test_compiled_closed_reservoir_follows_boyles_law():
    """A closed isothermal reservoir whose volume is a StateMap of a beam: pV = mRT = const on the compiled
    path (the state is the mass: exact to round-off whatever the beam does)."""
    fl = Fluidic(None, V0=V0)
    mdl = Model().add(finger(gravity=True), "f").add(fl, "p")
    mdl.connect(StateMap("f", [[0.05, 0.0]], index=[0, 1], offset=V0, scale=0.5 * V0, function="tanh"), "p",
                port="volume")
    tr = mdl.simulate(0.3, 1e-3, "bdf2", compiled=True, rtol=1e-8)
    pabs = tr["p"].pressure + fl.p0
    assert np.ptp(tr["p"].volume) > 1e-3 * V0                 # the beam sags under gravity: the volume moves
    assert np.max(np.abs(pabs * tr["p"].volume / (fl.p0 * tr["p"].volume[0]) - 1)) < 1e-12


def test_statemap_input_coupling_and_beam_output_coupling():
    """A beam's state mapped into another beam's chamber pressure (StateMap input), and a beam's full state as
    the output of a named system into a reservoir-free chain."""
    def make():
        mdl = Model().add(finger(), "a").add(finger(), "b")
        mdl.connect(StateMap("a", [2e5], index=0), "b")
        return mdl.set_controller(Schedule([0.0, 0.2], {"a": [[0.0], [20e3]]}))
    rtol, atol = 1e-8, 1e-10
    a, b = both(make, 0.2, 1e-3, "trapezoidal", rtol=rtol, atol=atol)
    assert close(a["b"].x, b["b"].x, rtol, atol) < 10
    assert np.allclose(a["b"].u[:, 0], 2e5 * a["a"].q[:, 0])
    assert np.max(np.abs(a["b"].q)) > 1e-3


@pytest.mark.parametrize("feedthrough", [False, True])
def test_linear_statespace_blocks_compiled_equal_python(feedthrough):
    """A first-order pressure lag (StateSpace.linear) between a scheduled set point and a beam's chamber, and a
    second linear system filtering the beam's first coordinate (StateMap input): both compiled."""
    from soroshapes import StateSpace

    def make():
        D = [[0.5]] if feedthrough else None
        lag = StateSpace.linear([[-50.0]], [[50.0]], [[1.0 if not feedthrough else 0.5]], D)
        filt = StateSpace.linear([[-20.0, 0.0], [1.0, 0.0]], [[20.0], [0.0]])
        mdl = Model().add(finger(), "f").add(lag, "lag").add(filt, "filt")
        mdl.connect("lag", "f").connect(StateMap("f", [1.0], index=0), "filt")
        return mdl.set_controller(Schedule([0.0, 0.05, 0.3], {"lag": [[0.0], [20e3], [20e3]]}))
    assert make().evaluation_path == "compiled"
    rtol, atol = 1e-8, 1e-10
    a, b = both(make, 0.3, 1e-3, "bdf2", rtol=rtol, atol=atol)
    assert close(a["f"].x, b["f"].x, rtol, atol) < 10
    assert close(a["filt"].x, b["filt"].x, rtol, atol) < 10
    assert np.max(np.abs(a["lag"].x - b["lag"].x)) < 1e-6 * 20e3
    # the filter's second state integrates its first: x1(t) = int x0 (a closed-form check of the wiring)
    x0, x1 = a["filt"].x[:, 0], a["filt"].x[:, 1]
    assert abs(x1[-1] - np.trapz(x0, a.t)) < 1e-3 * np.max(np.abs(x1))


def test_schedule_tables_interpolate_and_repeat():
    s = Schedule([0.0, 1.0, 2.0], [[0.0, 1.0], [2.0, 1.0], [0.0, 1.0]], period=2.0)
    assert np.allclose(s.at(0.5), [1.0, 1.0]) and np.allclose(s.at(2.5), [1.0, 1.0]) and np.allclose(s.at(-1.0),
                                                                                                     [2.0, 1.0])
    held = Schedule([0.0, 1.0], [[1.0], [3.0]])
    assert held.at(-1.0)[0] == 1.0 and held.at(5.0)[0] == 3.0
    sampled = Schedule.sample(lambda t: [np.sin(t)], None, 1e-3, period=2 * np.pi)
    assert abs(sampled.at(1.0)[0] - np.sin(1.0)) < 1e-6 / 8 * 1.01
    with pytest.raises(ParameterError, match="increasing"):
        Schedule([0.0, 0.0], [[1.0], [2.0]])
    with pytest.raises(ParameterError, match="period"):
        Schedule([0.0, 1.0], [[1.0], [2.0]], period=2.0)
    with pytest.raises(ParameterError, match="finite"):
        Schedule([0.0, 1.0], [[1.0], [np.nan]])
    with pytest.raises(ParameterError, match="function"):
        StateMap("f", [1.0], function="sin")
    with pytest.raises(ParameterError, match="columns"):
        StateMap("f", [[1.0, 2.0]], index=0)


def test_schedule_of_the_wrong_width_names_the_system():
    mdl = Model().add(finger(), "f").set_controller(Schedule([0.0, 1.0], {"f": [[0.0, 1.0], [0.0, 1.0]]}))
    with pytest.raises(ParameterError, match="'f'"):
        mdl.simulate(0.01, 1e-3)


def test_non_finite_initial_state_and_a_failed_run_leave_the_model_usable():
    mdl = hand_like(1)
    x0 = mdl.initial_state()
    bad = x0.copy()
    bad[0] = np.nan
    with pytest.raises(DataError, match="NaN"):
        mdl.simulate(0.01, 1e-3, x0=bad)
    huge = x0.copy()
    huge[0] = 1e200                     # frames overflow: the start is checked before the kernel runs
    with pytest.raises(DataError, match="overflow"):
        mdl.simulate(0.01, 1e-3, x0=huge, compiled=True)
    ref = hand_like(1).simulate(0.05, 1e-3, compiled=True)
    again = mdl.simulate(0.05, 1e-3, compiled=True)
    assert np.array_equal(ref.x, again.x)


def test_a_volume_map_that_turns_negative_is_a_clear_error():
    fl = Fluidic(None, V0=V0)
    mdl = Model().add(finger(), "f").add(fl, "p").connect("p", "f")
    mdl.connect(StateMap("f", [1.0], index=0, offset=V0, scale=-2 * V0, function="tanh"), "p", port="volume")
    with pytest.raises((ConvergenceError, DataError), match="t = |volume"):
        mdl.simulate(0.5, 1e-3, x0=np.r_[5.0, 0, 0, 0, fl.initial_state(V0)], compiled=True)


def test_warm_up_runs_every_kind():
    from soroshapes.precompile import warm_up
    assert warm_up() > 0


def test_module_entry_warms_the_kernels():
    """`python -m soroshapes.precompile` (the bootstrap's precompile step) runs warm_up in a fresh process."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "soroshapes.precompile"], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    assert "network kernels ready" in run.stdout



def rigid_network(normalization=0.0):
    """A free rigid body with a full inertia matrix, gravity, damping and an initial tumbling twist; a scheduled
    wrench on four of its inputs and a linear lag (output coupling) on the other two."""
    from soroshapes import RigidBody

    inertia = np.array([[2.0, 0.3, -0.1], [0.3, 1.5, 0.2], [-0.1, 0.2, 1.0]]) * 1e-4
    body = RigidBody(0.2, inertia, twist0=[3.0, -1.0, 5.0, 0.1, 0.0, -0.2], damping=(0.05, 1e-5),
                     normalization=normalization)
    lag = StateSpace.linear([[-20.0, 0.0], [0.0, -5.0]], np.eye(2))
    t = np.linspace(0.0, 0.4, 9)
    mdl = Model().add(body, "top").add(lag, "lag")
    mdl.connect("lag", "top", ["moment_z", "force_x"])
    # free inputs of the body: moment_x, moment_y, force_y, force_z
    wrench = np.column_stack([1e-4 * np.sin(10 * t), np.zeros_like(t), 0.5 * np.cos(7 * t), np.full_like(t, 0.3)])
    return mdl.set_controller(Schedule(t, {"top": wrench, "lag": np.column_stack([np.full_like(t, 2e-4), t])}))


@pytest.mark.parametrize("method,normalization", [("trapezoidal", 0.0), ("midpoint", 0.0), ("bdf2", 20.0)])
def test_rigid_body_compiled_equals_python(method, normalization):
    """Newton-Euler on SE(3) (Euler's equations with a full inertia, gravity, damping, the normalization pulling
    R onto SO(3)) compiled against RigidBody.rhs on the Python path."""
    rtol, atol = 1e-8, 1e-10
    assert rigid_network().evaluation_path == "compiled"
    a, b = both(lambda: rigid_network(normalization), 0.4, 2e-3, method, rtol=rtol, atol=atol)
    assert close(a["top"].x, b["top"].x, rtol, atol) < 10
    assert close(a["lag"].x, b["lag"].x, rtol, atol) < 10
    # the midpoint rule keeps R^T R = I to the Newton tolerance; trapezoidal and BDF2 (normalized) to an
    # O((h |omega|)^2) bound, (2 ms x 6 rad/s)^2 ~ 1.4e-4
    R = a["top"].x[-1, 3:12].reshape(3, 3)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-6 if method == "midpoint" else 1e-3)


def test_spinning_body_runs_compiled_and_matches_its_closed_form():
    r"""A SpinningBody is linear: :math:`I\ddot\theta = -c\dot\theta + m_z` from rest under a constant moment gives
    :math:`\dot\theta = (m_z/c)(1 - e^{-ct/I})`; the trapezoidal rule's error at dt = 1 ms and c/I = 25 1/s is
    O((c h / I)^2 / 12) ~ 5e-5 relative."""
    from soroshapes import RigidBody

    def make():
        bolt = RigidBody.spinning((0.0, 0.0, 1.0), 2e-5, 5e-4)
        return Model().add(bolt, "bolt").set_controller(Schedule([0.0, 1.0], {"bolt": [[0, 0, 1e-3, 0, 0, 0]] * 2}))

    assert make().evaluation_path == "compiled"
    a, b = both(make, 0.2, 1e-3, "trapezoidal", rtol=1e-9, atol=1e-12)
    exact = 1e-3 / 5e-4 * (1.0 - np.exp(-25.0 * a.t))
    assert np.allclose(a["bolt"].x[:, 1], exact, rtol=0, atol=1e-4 * exact.max())
    assert np.allclose(a["bolt"].x, b["bolt"].x, rtol=1e-7, atol=1e-10)


def cylinder_on_table():
    """The cylinder of demos/manipulator_pick standing on the table on its rim (12 points, penalty, damping,
    regularized Coulomb friction), launched with a sideways velocity and a spin: it slides, rocks and comes to
    rest."""
    from soroshapes import RigidBody
    from soroshapes.rigid import couple_ground

    r, h, m = 0.02, 0.04, 0.045
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.0, h / 2 - m * 9.81 / (12 * 3e3))          # on the table, at its static sinkage
    cyl = RigidBody(m, [m * (3 * r * r + h * h) / 12] * 2 + [m * r * r / 2], pose0=pose,
                    twist0=[0.3, -0.2, 2.0, 0.05, 0.02, 0.0], damping=(0.05, 1e-4), normalization=20.0)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full(12, -h / 2)])
    mdl = Model().add(cyl, "cylinder")
    return couple_ground(mdl, "cylinder", rim, stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)


def test_ground_contact_compiled_equals_python():
    """couple_ground on a free rigid body runs compiled (its parameters as data) and agrees with the Python path
    (ground_contact) through impact, sliding and sticking; the body comes to rest on the table."""
    rtol, atol = 1e-7, 1e-9
    assert cylinder_on_table().evaluation_path == "compiled"
    # dt = 0.2 ms: the regularized friction (mu f_n / eps ~ 220 N s/m on 45 g, a rate of ~5000 1/s) needs no
    # step splitting on either path, so both solve the same discrete equations (at 1 ms the Python path splits
    # steps where the compiled one does not, and the two then differ by a discretization error)
    a, b = both(cylinder_on_table, 0.1, 2e-4, "bdf2", rtol=rtol, atol=atol)
    assert a.stats["cut_steps"] == b.stats["cut_steps"] == 0
    assert close(a["cylinder"].x, b["cylinder"].x, rtol, atol) < 10
    assert abs(a["cylinder"].x[-1, 2] - 0.02) < 1e-4                 # on the table (sinkage m g / (12 k) = 12 um)
    assert np.abs(a["cylinder"].x[-1, 12:]).max() < 1e-6              # stuck by friction: at rest


def test_a_coupling_without_compiled_form_keeps_the_python_path():
    """A grasp engaged by a Python callable on the body that also stands on the table: the network runs in
    Python, and says why."""
    from soroshapes.rigid import couple_grasp

    mdl = cylinder_on_table().add(finger(), "arm")
    couple_grasp(mdl, "arm", "cylinder", anchor=(0.0, 0.0, 0.02), stiffness=400.0, damping=4.0,
                 engaged=lambda t: min(t / 0.1, 1.0))
    assert mdl.evaluation_path.startswith("python: ")


def impedance_arm(setpoint):
    """The arm of demos/manipulator_pick (three PCC segments, one generalized torque each, gravity) under the
    Cartesian impedance controller of soroshapes.control, starting bent (IK to a point off its set-point)."""
    from soroshapes.control import impedance

    down = np.eye(4)
    down[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    down[2, 3] = 0.32
    shp = Shapes(Basis.pcc(3), (0, 3, 0, 0, 0, 0), length=0.3, section=sdf.Circle(0.012),
                 material=materials.DragonSkin30(), base=down, segments=12).add_gravity((0.0, 0.0, -9.81))
    for i in range(3):
        shp.add_actuator(np.eye(3)[i], name=f"segment{i}")
    start = shp.inverse_kinematics(np.array([0.10, 0.0, 0.06]), q0=np.array([-2.0, -1.0, -1.0]))
    ctrl = impedance("arm", stiffness=150.0, damping=12.0, setpoint=setpoint, axes=(0, 2), null_damping=2e-3)
    return Model().add(shp, "arm", x0=np.concatenate([start.q, np.zeros(3)])).set_controller(ctrl)


@pytest.mark.parametrize("kind", ["constant", "schedule"])
def test_impedance_controller_compiled_equals_python(kind):
    """Cartesian impedance (task Jacobian and its rate, Cartesian inertia by a pseudo-inverse, Coriolis term,
    gravity/elastic compensation, null-space damping) compiled against soroshapes.control.impedance; the tip
    converges to the set-point."""
    t = np.linspace(0.0, 0.6, 13)
    sp = (np.array([0.08, 0.09]) if kind == "constant" else
          Schedule(t, np.column_stack([0.10 - 0.05 * t, 0.06 + 0.05 * t])))
    rtol, atol = 1e-7, 1e-9
    assert impedance_arm(sp).evaluation_path == "compiled"
    a, b = both(lambda: impedance_arm(sp), 0.6, 2e-3, "bdf2", rtol=rtol, atol=atol)
    assert close(a["arm"].x, b["arm"].x, rtol, atol) < 10
    assert np.allclose(a.u, b.u, rtol=1e-5, atol=1e-7)
    mdl = impedance_arm(sp)
    tip = mdl["arm"].system.positions(a["arm"].q[-1])[-1]
    goal = sp if kind == "constant" else sp.at(0.6)
    # a moving set-point (0.07 m/s) is followed with the lag D_c v / K_c = 12 x 0.07 / 150 = 5.7 mm
    lag = 0.0 if kind == "constant" else 12.0 * 0.05 * np.sqrt(2) / 150.0
    assert np.hypot(tip[0] - goal[0], tip[2] - goal[1]) < lag + 5e-3


def test_impedance_with_a_python_setpoint_keeps_the_python_path():
    mdl = impedance_arm(lambda t: np.array([0.1, 0.06]))
    assert mdl.evaluation_path.startswith("python: the impedance set-point")


def pick(engaged):
    """The pick of demos/manipulator_pick in short: the impedance-controlled arm holding the cylinder on the
    table through a grasp that closes, then lifting it."""
    from soroshapes.rigid import couple_grasp, couple_ground

    mdl = impedance_arm(Schedule([0.0, 0.1, 0.4], [[0.10, 0.042], [0.10, 0.042], [0.10, 0.07]]))
    cyl = cylinder_on_table()["cylinder"].system
    mdl.add(cyl, "cylinder")
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    rim = np.column_stack([0.02 * np.cos(ang), 0.02 * np.sin(ang), np.full(12, -0.02)])
    couple_ground(mdl, "cylinder", rim, stiffness=3e3, damping=6.0, friction=0.5, regularization=1e-3)
    return couple_grasp(mdl, "arm", "cylinder", anchor=(0.0, 0.0, 0.02), stiffness=400.0, damping=4.0,
                        engaged=engaged)


def test_grasp_compiled_equals_python():
    """couple_grasp (beam node <-> body point spring-damper, equal and opposite, scaled by an engagement table)
    with the impedance controller and the ground: the compiled network against the Python path."""
    rtol, atol = 1e-7, 1e-9
    closing = Schedule([0.0, 0.05, 0.15], [[0.0], [0.0], [1.0]])
    assert pick(closing).evaluation_path == "compiled"
    assert pick(lambda t: 1.0).evaluation_path.startswith("python: ")
    # dt = 0.2 ms: no split steps on either path (the table's regularized friction is stiff, see
    # test_ground_contact_compiled_equals_python); the right-hand sides agree to round-off, the trajectories by
    # the Newton stopping error accumulated over 1000 steps of a stiff network (observed ~60 tolerances)
    a, b = both(lambda: pick(closing), 0.2, 2e-4, "bdf2", rtol=rtol, atol=atol)
    assert a.stats["cut_steps"] == b.stats["cut_steps"] == 0
    assert close(a.x, b.x, rtol, atol) < 200
    assert a["cylinder"].x[-1, 2] > 0.02 + 0.003                # lifted by the grasp (3.5 mm at 0.2 s)


# ------------------------------------------------------------------------------------------------------------
# beam-SDF contact (soroshapes._contact, the obstacle as an SDF program)
# ------------------------------------------------------------------------------------------------------------
def finger_on_a_wall(obstacle):
    """A two-mode finger bent by its chamber against a fixed obstacle (Shapes.add_contact: penalty, damping,
    regularized friction), its chamber pressure ramped by a Schedule."""
    shp = finger().add_contact(obstacle, stiffness=2e5, damping=20.0, friction=0.4, regularization=1e-3)
    mdl = Model().add(shp, "f")
    return mdl.set_controller(Schedule([0.0, 0.05, 0.2], {"f": [[0.0], [0.0], [80e3]]}))


WALLS = {"plane": sdf.Plane(point=(0.0, -0.012, 0.0), normal=(0.0, 1.0, 0.0)),
         "grooved": sdf.Plane(point=(0.0, -0.012, 0.0), normal=(0.0, 1.0, 0.0)).smooth_difference(
             sdf.Cylinder(0.004, 0.05, center=(0.07, -0.014, 0.0), axis=(0.0, 0.0, 1.0)), 0.002)}


@pytest.mark.parametrize("wall", sorted(WALLS))
def test_contact_with_a_fixed_obstacle_compiled_equals_python(wall):
    """The compiled contact (the wall's SDF program, its gradient analytic) against Shapes.add_contact on the
    Python path, through the impact and sliding of the bending finger; the finger does touch the wall."""
    rtol, atol = 1e-7, 1e-9
    assert finger_on_a_wall(WALLS[wall]).evaluation_path == "compiled"
    a, b = both(lambda: finger_on_a_wall(WALLS[wall]), 0.2, 5e-4, "bdf2", rtol=rtol, atol=atol)
    assert a.stats["cut_steps"] == b.stats["cut_steps"] == 0
    assert close(a.x, b.x, rtol, atol) < 50
    shp = finger_on_a_wall(WALLS[wall])["f"].system
    force = np.linalg.norm(shp.contact_forces(a["f"].q[-1], a["f"].qd[-1]).sum(axis=0))
    assert force > 1e-3                                              # in contact at the end


def finger_and_bolt(spinning):
    """A finger pressed on a hexagonal bolt head (an extruded polygon) that spins about z (SpinningBody) or is a
    free body held by a soft ground plane: couple_contact, friction drags the bolt."""
    from soroshapes.rigid import RigidBody, couple_contact, couple_ground

    hexagon = sdf.Polygon([(0.01 * np.cos(t), 0.01 * np.sin(t)) for t in np.arange(6) * np.pi / 3]).extrude(0.02)
    pose = np.eye(4)
    pose[:3, 3] = (0.06, -0.02, 0.0)
    if spinning:
        body = RigidBody.spinning((0.0, 0.0, 1.0), 2e-6, 1e-5, hexagon, pose0=pose, name="bolt")
    else:
        body = RigidBody(0.02, 2e-6, shape=hexagon, pose0=pose, gravity=(0.0, 0.0, 0.0), damping=(0.5, 1e-4),
                         name="bolt")
    mdl = Model().add(finger(), "f").add(body)
    couple_contact(mdl, "f", "bolt", stiffness=2e5, damping=20.0, friction=0.5, regularization=2e-3)
    if not spinning:
        rim = np.array([[0.0, 0.0, -0.01], [0.0, 0.0, 0.01]])
        couple_ground(mdl, "bolt", rim, stiffness=50.0, damping=0.5, plane=((0.0, 0.0, -0.01), (0.0, 0.0, 1.0)))
    return mdl.set_controller(Schedule([0.0, 0.05, 0.2], {"f": [[0.0], [0.0], [80e3]]}))


@pytest.mark.parametrize("spinning", [True, False], ids=["spinning", "free"])
def test_beam_body_contact_compiled_equals_python(spinning):
    """couple_contact against a spinning or a free body: the compiled term (the bolt's SDF program, the body's
    pose and twist, equal and opposite forces) against beam_contact on the Python path; the bolt turns. The two
    agree to the Newton tolerance until the finger strikes the bolt (52 ms). Through the impact they split
    different steps (after a failed Newton the compiled step retries with fresh model rows at the failed iterate,
    closed form for a spinning body's contact, the Python path with its differenced Jacobian), so they part there
    by more than the tolerance; their end states then agree within the scene's time-discretization error (the
    Python path at half the step: bolt 2.2e-5 rad and 1.0e-5 rad/s, finger 5.8e-5 spinning; bolt 2.4e-6 m, finger
    8.1e-4 free; the two paths measured 4.1e-6, 1.9e-6, 2.7e-5 and 1.3e-6, 2.2e-4)."""
    rtol, atol = 1e-7, 1e-9
    assert finger_and_bolt(spinning).evaluation_path == "compiled"
    a, b = both(lambda: finger_and_bolt(spinning), 0.2, 5e-4, "bdf2", rtol=rtol, atol=atol)
    before = a.t < 0.05
    assert close(a.x[before], b.x[before], rtol, atol) < 50
    body = slice(0, 2) if spinning else slice(0, 3)
    assert np.abs(a["bolt"].x[-1, body] - b["bolt"].x[-1, body]).max() < (2.2e-5 if spinning else 2.4e-6)
    assert np.abs(a["f"].x[-1] - b["f"].x[-1]).max() < (5.8e-5 if spinning else 8.1e-4)
    moved = abs(a["bolt"].x[-1, 0]) if spinning else np.abs(a["bolt"].x[-1, :3] - a["bolt"].x[0, :3]).max()
    assert moved > 1e-4


def fingers_on_a_bolt():
    """Two fingers on opposite sides of a spinning hexagonal bolt head, both pressed on it (couple_contact)."""
    from soroshapes.rigid import RigidBody, couple_contact

    hexagon = sdf.Polygon([(0.01 * np.cos(t), 0.01 * np.sin(t)) for t in np.arange(6) * np.pi / 3]).extrude(0.02)
    pose = np.eye(4)
    pose[:3, 3] = (0.06, -0.02, 0.0)
    mdl = Model().add(finger(), "f0")
    flipped = finger()
    base = np.eye(4)
    base[:3, 3] = (0.0, -0.04, 0.0)
    base[:3, :3] = np.diag([1.0, -1.0, -1.0])           # mirrored across the bolt's plane y = -0.02
    mdl.add(Shapes(Basis.chebyshev(2), dofs=(0, 0, 2, 0, 0, 0), length=0.1, section=sdf.Circle(0.005),
                   material=materials.NeoHookean(E=1e6, nu=0.45, density=1000), damping=0.03, segments=6,
                   base=base).add_chamber(area=5e-5, offset=(0.003, 0)), "f1")
    mdl.add(RigidBody.spinning((0.0, 0.0, 1.0), 2e-6, 1e-5, hexagon, pose0=pose, name="bolt"))
    for name in ("f0", "f1"):
        couple_contact(mdl, name, "bolt", stiffness=2e5, damping=20.0, friction=0.5, regularization=2e-3)
    return mdl.set_controller(Schedule([0.0, 0.05, 0.2], {"f0": [[0.0], [0.0], [80e3]], "f1": [[0.0], [0.0],
                                                                                                   [60e3]]}))


def test_contact_jacobian_columns_reevaluate_only_the_contacts_they_move():
    """The compiled differenced Jacobian takes, per column, the contact terms that do not read the column's
    block from their values at the base point (soroshapes.network._wrench_sum): at a state where a finger
    presses on the bolt it equals forward differences of the network's derivative re-evaluated in full per
    column, to the rounding of the summation order; the bolt's columns reach the fingers' rows and each
    finger's columns the bolt's."""
    from soroshapes import network
    from soroshapes.numerics import FD_STEP
    from soroshapes.rigid import beam_contact

    tr = fingers_on_a_bolt().simulate(0.1, 5e-4, "bdf2", rtol=1e-7, atol=1e-9, compiled=True)
    mdl = fingers_on_a_bolt()
    t, x = 0.1, tr.x[-1].copy()
    f_beam, _ = beam_contact(mdl["f0"].system, mdl["bolt"].system, 2e5, 20.0, 0.5, 2e-3, q=tr["f0"].q[-1],
                             qd=tr["f0"].qd[-1], x=tr["bolt"].x[-1])
    assert np.abs(f_beam).max() > 1e-4                                 # in contact
    net = mdl._lowered()
    N = x.size
    Jc, JF = np.zeros((N, N)), np.zeros((N, N))
    w, f0, fp, xp = np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N)
    assert network.jacobian(t, x, net.arrays, np.ones(N), w, f0, fp, xp, Jc, JF)
    alls = np.ones(3, np.bool_)
    assert network.rhs(t, x, net.arrays, w, f0, alls)
    Jr = np.zeros((N, N))
    for j in range(N):                                # every column: every contact re-evaluated
        xj = x.copy()
        xj[j] += FD_STEP * max(abs(x[j]), 1.0)
        assert network.rhs(t, xj, net.arrays, w, fp, alls)
        Jr[:, j] = (fp - f0) / (xj[j] - x[j])
    scale = np.maximum(np.abs(Jr).max(axis=1, keepdims=True), 1e-12)
    assert np.abs(Jc - Jr).max() / 1.0 <= 1e-6 * scale.max() and np.all(np.abs(Jc - Jr) <= 1e-6 * scale)
    assert np.abs(Jr[2:4, 8:10]).max() > 1e3 and np.abs(Jr[9, 0:4]).max() > 0     # f0 <-> bolt


# ------------------------------------------------------------------------------------------------------------
# the joint-space controllers and feed-forwards of soroshapes.control, compiled
# ------------------------------------------------------------------------------------------------------------
def controlled_arm(kind):
    """A three-segment PCC arm (one unit actuator per coordinate, gravity, damping) under one controller of
    soroshapes.control, starting bent."""
    from soroshapes import control

    shp = Shapes(Basis.pcc(3), dofs=(0, 3, 0, 0, 0, 0), length=0.3, section=sdf.Circle(0.01),
                 material=materials.NeoHookean(E=2e5, nu=0.45, density=1000), damping=0.02,
                 segments=12).add_gravity()
    for i in range(3):
        shp.add_actuator(np.eye(3)[i])
    mdl = Model().add(shp, "arm", x0=[2.0, -1.0, 1.5, 0.0, 0.0, 0.0])
    goal = np.array([3.0, 1.0, -2.0])
    table = Schedule([0.0, 0.1, 0.3], np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.5], [1.0, -1.0, 2.0]]))
    if kind == "compensation":
        ctrl = control.gravity_compensation("arm")
    elif kind == "pd":
        ctrl = control.pd("arm", kp=[2e-3, 1e-3, 5e-4], kd=2e-4, setpoint=goal)
    elif kind == "pd_schedule":
        ctrl = control.pd("arm", kp=2e-3, kd=2e-4, setpoint=table, gravity=False)
    elif kind == "pid":
        ctrl = control.pid(mdl, "arm", kp=2e-3, ki=4e-3, kd=2e-4, setpoint=goal, elastic=False)
    elif kind == "ff_inputs":
        ctrl = control.feedforward("arm", Schedule([0.0, 0.3], [[0.0, 0.0, 0.0], [1e-3, -2e-3, 1e-3]]))
    elif kind == "ff_torque":
        ctrl = control.feedforward("arm", Schedule([0.0, 0.3], [[0.0, 0.0, 0.0], [1e-3, -2e-3, 1e-3]]),
                                   space="torque")
    elif kind == "ff_configuration":
        ctrl = control.feedforward("arm", table, space="configuration")
    else:                                                                 # combine
        ctrl = control.combine(control.pd("arm", kp=1e-3, kd=2e-4, setpoint=goal, gravity=False, elastic=False),
                               control.gravity_compensation("arm"))
    return mdl.set_controller(ctrl)


@pytest.mark.parametrize("kind", ["compensation", "pd", "pd_schedule", "pid", "ff_inputs", "ff_torque",
                                  "ff_configuration", "combine"])
def test_joint_controllers_and_feedforward_compiled_equal_python(kind):
    """Each controller's parameters as data (gains, constant or Schedule set-points and profiles, the PID's
    integral as a linear block fed by a StateMap) in the compiled network against its Python closure."""
    rtol, atol = 1e-7, 1e-9
    assert controlled_arm(kind).evaluation_path == "compiled"
    a, b = both(lambda: controlled_arm(kind), 0.3, 2e-3, "bdf2", rtol=rtol, atol=atol)
    assert a.stats["cut_steps"] == b.stats["cut_steps"] == 0
    assert close(a.x, b.x, rtol, atol) < 10
    assert np.allclose(a.u, b.u, rtol=1e-5, atol=1e-9)
    assert np.abs(a.u).max() > 1e-4                                      # the controller did act


def test_a_pid_with_a_moving_setpoint_or_a_python_part_keeps_the_python_path():
    from soroshapes import control

    mdl = controlled_arm("compensation")
    ctrl = control.pid(mdl, "arm", kp=1e-3, ki=1e-3, kd=1e-4, setpoint=lambda t: np.zeros(3))
    assert mdl.set_controller(ctrl).evaluation_path.startswith("python: ")
    mdl = controlled_arm("compensation")
    mdl.set_controller(control.combine(control.gravity_compensation("arm"), lambda m: {"arm": np.zeros(3)}))
    assert mdl.evaluation_path.startswith("python: ")


# ------------------------------------------------------------------------------------------------------------
# the closed-form rows of the Newton matrix (network._analytic_rows) against the differenced ones (_fd_rows)
# ------------------------------------------------------------------------------------------------------------
def _saturating_hand():
    """hand_like with a valve that saturates (a tiny max_flow) and a leak."""
    mdl = Model()
    fl = Fluidic(None, V0=V0, leak=1e-12, regulator=dict(kp=2e-9, ki=2e-7, max_flow=1e-9))
    mdl.add(finger(), "f").add(fl, "p").connect("p", "f")
    mdl.connect(StateMap("f", [0.1], index=0, offset=V0, scale=0.2 * V0, function="tanh"), "p", port="volume")
    return mdl.set_controller(Schedule([0.0, 1.0], {"p": [[30e3], [30e3]]}))


def _polytropic_chain():
    """A regulated polytropic reservoir with a volume filter, whose volume follows a beam, driving a linear
    lag with feedthrough (through its gauge pressure) that drives the beam's chamber; a linear filter reads the
    beam (StateMap)."""
    fl = Fluidic(None, V0=V0, polytropic=1.4, filter_gain=200.0, leak=1e-12,
                 regulator=dict(kp=2e-9, ki=2e-7, max_flow=1e-5))
    lag = StateSpace.linear([[-50.0]], [[50.0]], [[0.5]], [[0.5]])
    filt = StateSpace.linear([[-20.0, 0.0], [1.0, 0.0]], [[20.0], [0.0]])
    mdl = Model().add(finger(), "f").add(fl, "p").add(lag, "lag").add(filt, "filt")
    mdl.connect("p", "lag").connect("lag", "f").connect(StateMap("f", [1.0], index=0), "filt")
    mdl.connect(StateMap("f", [[1e-8, 2e-8]], index=[0, 1], offset=V0), "p", port="volume")
    return mdl.set_controller(Schedule([0.0, 1.0], {"p": [[0.0], [40e3]]}))


@pytest.mark.parametrize("make", [hand_like, _saturating_hand, _polytropic_chain])
def test_closed_form_newton_rows_equal_the_differenced_ones(make):
    """The rows of every reservoir, linear system and beam input force in closed form (ideal gas, PI regulator,
    valve slope 1 or 0, leak, polytropic law and volume filter, StateMap volume with tanh, output couplings with
    feedthrough, G u) equal their forward differences (step 1.5e-8 relative: truncation and round-off leave ~1e-7
    of a row's size; 1e-5 allowed) at random states; and they need no network evaluation. Where the valve
    saturates, the integral's row is exactly -k_i/k_p on the integral (its differences are round-off: the row
    is e - nu/k_p, two terms of ~1e4 Pa that cancel), checked against that closed form."""
    from soroshapes import network
    mdl = make()
    mdl._prepare_layout()
    net = mdl._lowered()
    assert not isinstance(net, str)
    table = net.arrays[0]
    assert np.all(table[:, 7] == 1)
    rng = np.random.default_rng(3)
    x0 = mdl.initial_state()
    scale = mdl._scales(x0)
    N = len(x0)
    saturated = 0
    for trial in range(6):
        x = x0 + 0.3 * scale * rng.standard_normal(N)
        for b in range(table.shape[0]):                   # keep masses and pressures positive
            if table[b, 0] == network.FLUIDIC:
                x[table[b, 1]] = abs(x0[table[b, 1]]) * (1.0 + 0.2 * rng.random())
        ws = [np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N)]
        JA, JD = np.zeros((N, N)), np.zeros((N, N))
        assert network._cheap_rows(0.3, x, net.arrays, scale, *ws, JA, True, True)
        assert network._cheap_rows(0.3, x, net.arrays, scale, *ws, JD, True, False)
        w = mdl._assemble(0.3, x)
        exact = set()
        for name in mdl.systems:
            blk = mdl._blocks[name]
            if blk.kind != "fluidic" or blk.system.regulator is None:
                continue
            fl, xb = blk.system, x[blk.sl]
            kp, ki, mx = fl.regulator
            nu = kp * (w[blk.wsl.start] - fl.pressure(xb, w[blk.wsl.start + 1])) + ki * xb[-1]
            if abs(nu) > mx:
                i = blk.sl.stop - 1
                ref = np.zeros(N)
                ref[i] = -ki / kp
                assert np.array_equal(JA[i], ref)
                exact.add(i)
        saturated += len(exact)
        for i in set(range(N)) - exact:
            size = max(np.max(np.abs(JD[i])), 1e-300)
            assert np.max(np.abs(JA[i] - JD[i])) <= 1e-5 * size, (trial, i, JA[i], JD[i])
    assert saturated > 0 or make is _polytropic_chain      # both branches of the valve were seen


def test_a_refresh_of_some_components_rebuilds_their_rows_and_factors_only():
    """The integrator refreshes the Newton matrix of the connected components whose Newton contracted slowly
    (``_cheap_rows_of`` / ``_iteration_matrix_of`` with a selection): the selected component's rows and factor
    equal those of a full refresh, the other's are left exactly as they were (here: a marker value)."""
    from soroshapes import network
    mdl = hand_like(2)
    mdl._prepare_layout()
    net = mdl._lowered()
    comps, block_comp = net.arrays[18], net.arrays[19]
    assert comps.shape[0] == 2
    x = mdl.initial_state()
    x[0] = 3.0                                          # a bent finger: a mass matrix away from the straight one
    scale = mdl._scales(x)
    N = len(x)
    ws = [np.zeros(net.NW), np.zeros(N), np.zeros(N), np.zeros(N)]
    table = net.arrays[0]
    assert network.residual(0.1, x, x, x, 1e-3, net.arrays, np.zeros(net.NW), np.zeros(N),
                            np.ones(table.shape[0], np.bool_))
    for b in range(table.shape[0]):                     # the beams' mass matrices at x (the pass just made)
        if table[b, 0] == network.BEAM:
            network._beam_mass_matrix(table[b, 5], net.arrays)
    mc = comps.shape[1]
    full_J, full_LU = np.zeros((N, N)), np.zeros((2, mc, mc))
    assert network._cheap_rows(0.1, x, net.arrays, scale, *ws, full_J, True, True)
    assert network._iteration_matrix(1e-3, 1.3e-3, net.arrays, full_J, full_LU, np.zeros((2, mc), np.int64))
    sel_c = np.array([False, True])
    J, LU = np.full((N, N), 7.0), np.full((2, mc, mc), 7.0)
    assert network._cheap_rows_of(0.1, x, net.arrays, scale, *ws, J, True, True, sel_c[block_comp])
    assert network._iteration_matrix_of(1e-3, 1.3e-3, net.arrays, J, LU, np.zeros((2, mc), np.int64), sel_c)
    rows1 = comps[1][comps[1] >= 0]
    rows0 = comps[0][comps[0] >= 0]
    assert np.array_equal(J[rows1], full_J[rows1]) and np.all(J[rows0] == 7.0)
    assert np.array_equal(LU[1], full_LU[1]) and np.all(LU[0] == 7.0)


def test_bdf2_linearized_predictor_is_exact_for_a_linear_network():
    r"""Two coupled linear systems (a stiff lag, time constant 1 ms, feeding a lightly damped oscillator at
    10 Hz; BDF2, dt = 2 ms): the step of the equations linearized about the last state (one solve with the
    factored iteration matrix, :func:`soroshapes.integrate._predict`) is the step itself for a linear network,
    so from the third step on Newton's first correction is round-off and every step takes one sweep (the
    extrapolation through the last states took two: its error is ~1e-3 of the state, far above the tolerance).
    The trajectory is the Python path's, whose Newton solves each step to the tolerance."""
    w0 = 2 * np.pi * 10.0

    def make():
        lag = StateSpace.linear([[-1000.0]], [[1000.0]], x0=[1.0])
        osc = StateSpace.linear([[0.0, 1.0], [-w0 * w0, -2 * 0.05 * w0]], [[0.0], [w0 * w0]], [[1.0, 0.0]],
                                x0=[0.0, 0.0])
        return Model().add(lag, "lag").add(osc, "osc").connect("lag", "osc").set_controller(
            Schedule([0.0, 1.0], {"lag": [[0.2], [0.2]]}))
    rtol, atol = 1e-7, 1e-9
    a, b = both(make, 0.4, 2e-3, "bdf2", rtol=rtol, atol=atol)
    st = a.stats
    assert st["linearized_predictions"] > 0.9 * st["steps"]
    assert st["newton_iterations"] <= st["steps"] + 4, st
    assert close(a["osc"].x, b["osc"].x, rtol, atol) < 10
    assert np.max(np.abs(a["osc"].x[:, 0])) > 0.1                  # it moved
