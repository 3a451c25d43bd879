"""One trajectory type (:class:`soroshapes.trajectory.Trajectory`) for every simulation of soroshapes: its fields,
its errors, a network's systems, and the simulators that return it."""
import pickle

import numpy as np
import pytest

from sorofem import materials, sdf
from sorofem.errors import ParameterError
from soroshapes import Basis, Model, Shapes, StateSpace, Trajectory
from soroshapes.tree import Tree


def test_fields_present_and_absent():
    t = np.linspace(0.0, 0.2, 3)
    tr = Trajectory(t, q=np.ones((3, 2)), qd=np.zeros((3, 2)), kinetic=[1.0, 2.0, 3.0], potential=[3.0, 2.0, 1.0],
                    stats={"steps": 2})
    assert tr.fields == ("q", "qd", "kinetic", "potential") and tr.stats == {"steps": 2} and tr.systems == ()
    np.testing.assert_array_equal(tr.total, [4.0, 4.0, 4.0])
    with pytest.raises(AttributeError, match=r"no 'tip': it has t, q, qd, kinetic, potential, stats"):
        tr.tip  # noqa: B018
    assert not hasattr(tr, "x") and not hasattr(tr, "reactions")
    bare = Trajectory(t, x=np.zeros((3, 1)))
    with pytest.raises(AttributeError, match="no energies, so no 'total': it has t, x, stats"):
        bare.total  # noqa: B018
    with pytest.raises(KeyError, match="not a network"):
        bare["arm"]
    back = pickle.loads(pickle.dumps(tr))
    np.testing.assert_array_equal(back.q, tr.q)
    assert back.fields == tr.fields


def test_bad_fields_are_refused():
    with pytest.raises(ParameterError, match="unknown field"):
        Trajectory([0.0, 1.0], times=[0.0, 1.0])
    with pytest.raises(ParameterError, match="one row per recorded time"):
        Trajectory([0.0, 1.0], q=np.zeros((3, 2)))
    with pytest.raises(ParameterError, match="must be a Trajectory"):
        Trajectory([0.0], x=[[0.0]], systems={"a": {"x": [[0.0]]}})


def _rod():
    return Shapes(Basis.chebyshev(1), dofs=(0, 1, 0, 0, 0, 0), length=0.1, section=sdf.Circle(2e-3),
                  material=materials.NeoHookean(E=1e5, nu=0.45, density=1000.0), segments=4).add_gravity()


def test_every_simulator_returns_the_one_type():
    """A beam, a tree and a network (beam + state-space system) each give a Trajectory with their fields; a
    system of the network is a Trajectory of the same time grid."""
    beam = _rod().simulate(2e-3, 1e-3)
    assert type(beam) is Trajectory and {"q", "qd", "kinetic", "potential", "tip"} <= set(beam.fields)
    assert beam.q.shape == (3, 1) and beam.tip.shape == (3, 3)

    tree = Tree(gravity=(0, 0, -9.81)).add_beam("arm", Shapes(
        Basis.chebyshev(1), dofs=(0, 1, 0, 0, 0, 0), length=0.1, section=sdf.Circle(2e-3),
        material=materials.NeoHookean(E=1e5, nu=0.45, density=1000.0), segments=4)).simulate(2e-3, 1e-3)
    assert type(tree) is Trajectory and {"q", "qd", "kinetic", "potential"} <= set(tree.fields)

    osc = StateSpace(lambda x, u, t: [x[1], -x[0]], 2, 0, x0=[1.0, 0.0])
    run = Model().add(_rod(), "arm").add(osc, "osc").simulate(2e-3, 1e-3)
    assert type(run) is Trajectory and run.systems == ("arm", "osc") and {"x", "u"} <= set(run.fields)
    arm = run["arm"]
    assert type(arm) is Trajectory and arm.name == "arm" and np.array_equal(arm.t, run.t) and arm.q.shape == (len(run.t), 1)
    np.testing.assert_array_equal(run["osc"].x, run.x[:, 2:])
    with pytest.raises(KeyError, match="systems: arm, osc"):
        run["nope"]


def test_every_simulator_reports_the_one_stats_schema():
    """Shapes.simulate (compiled loop and Python steps), a constrained Assembly, a Tree and Model.simulate (both
    paths, fixed and adaptive steps) give ``stats`` with the keys of soroshapes.trajectory.STATS_KEYS first and
    the same meaning: totals over the run, and the per-step mean of the Newton iterations."""
    from soroshapes.constraints import Pin
    from soroshapes.trajectory import STATS_KEYS

    rod = _rod()
    runs = {"beam compiled": rod.simulate(4e-3, 1e-3), "beam python": _rod().add_force(
        lambda shp, q, qd, t: np.zeros(1)).simulate(4e-3, 1e-3),
        "assembly": rod.simulate(4e-3, 1e-3, constraints=[Pin(axes=("z",))]),
        "tree": Tree(gravity=(0, 0, -9.81)).add_beam("arm", Shapes(
            Basis.chebyshev(1), dofs=(0, 1, 0, 0, 0, 0), length=0.1, section=sdf.Circle(2e-3),
            material=materials.NeoHookean(E=1e5, nu=0.45, density=1000.0), segments=4)).simulate(4e-3, 1e-3)}
    osc = lambda: Model().add(StateSpace(lambda x, u, t: [x[1], -x[0]], 2, 0, x0=[1.0, 0.0]), "osc")  # noqa: E731
    for compiled in (None, False):
        for adaptive in (False, True):
            runs[f"model {compiled} {adaptive}"] = osc().simulate(4e-3, 1e-3, compiled=compiled, adaptive=adaptive)
    for name, tr in runs.items():
        st = tr.stats
        assert tuple(st)[:len(STATS_KEYS)] == STATS_KEYS, name
        assert st["steps"] >= 4 and isinstance(st["newton_iterations"], int), name
        assert st["newton_iterations_per_step"] == pytest.approx(st["newton_iterations"] / st["steps"]), name
        assert st["newton_iterations"] >= st["steps"] and st["matrices"] >= 1, name
        assert st["dt"] == pytest.approx(1e-3) and st["wall_time"] > 0, name
    for name in ("beam compiled", "beam python", "assembly"):
        assert runs[name].stats["newton_iterations"] == runs[name].stats["newton_iterations_by_step"].sum()
    assert runs["beam compiled"].stats["path"] == "compiled" and runs["beam python"].stats["path"] == "python"
    assert runs["model False True"].stats["adaptive"] and runs["model False True"].stats["path"] == "python"
