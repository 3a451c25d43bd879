"""soroshapes.gym.ModelEnv: the Gymnasium API checker and a regulation episode on a fully actuated PCC arm."""
import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium", reason="gymnasium is not installed: pip install -c "
                                "/work/main/.venv/constraints.txt 'gymnasium>=1.0' into the venv")
from gymnasium.utils.env_checker import check_env  # noqa: E402

from sorofem import materials, sdf  # noqa: E402
from sorofem.errors import ParameterError  # noqa: E402
from soroshapes import Basis, Model, Shapes, StateSpace  # noqa: E402
from soroshapes.control import gravity_compensation  # noqa: E402
from soroshapes.gym import ModelEnv  # noqa: E402


def arm_model():
    shp = Shapes(Basis.pcc(2), dofs=(0, 2, 0, 0, 0, 0), length=0.2, section=sdf.Circle(0.01),
                 material=materials.NeoHookean(E=2e5, nu=0.45, density=1000), damping=0.05,
                 segments=8).add_gravity()
    for c in np.eye(2):
        shp.add_actuator(c)
    return Model().add(shp, "arm").set_controller(gravity_compensation("arm"))


def arm_env(dtype=np.float64, **kw):
    target = np.array([2.0, -1.0])
    return ModelEnv(arm_model(), observation=lambda m: m["arm"].x,
                    reward=lambda m, a: -float(np.sum((m["arm"].x[:2] - target) ** 2)),
                    dt=0.05, horizon=10, action_inputs=["arm.actuator0", "arm.actuator1"],
                    action_low=-1e-3, action_high=1e-3, dtype=dtype,
                    reset_fn=lambda rng: np.r_[rng.uniform(-1, 1, 2), 0.0, 0.0], **kw)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_check_env_passes(dtype):
    env = arm_env(dtype)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert obs.dtype == dtype and env.observation_space.contains(obs)


def test_episode_is_reproducible_and_truncates():
    env = arm_env(seed=3)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=7)
        rewards, done = [], False
        while not done:
            obs, r, term, trunc, info = env.step(np.array([5e-4, -5e-4]))
            rewards.append(r)
            done = term or trunc
        runs.append((obs, rewards))
    assert len(runs[0][1]) == 10 and info["t"] == pytest.approx(0.5)
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1]
    # the model's own controller (gravity + elastic compensation) keeps running beside the action: with a
    # zero action the arm stays where it starts, off its unforced equilibrium
    obs, _ = env.reset(options={"x0": np.array([2.0, -1.0, 0.0, 0.0])})
    for _ in range(5):
        obs, r, *_ = env.step(np.zeros(2))
    assert np.allclose(obs, [2.0, -1.0, 0.0, 0.0], atol=1e-6) and r > -1e-10


def test_step_matches_one_model_simulation():
    mdl = Model().add(StateSpace(lambda x, u, t: -x + u, 1, 1), "lag")
    env = ModelEnv(mdl, observation=lambda m: m["lag"].x, reward=lambda m, a: 0.0, dt=0.2, horizon=3,
                   substeps=4, action_low=-2.0, action_high=2.0)
    env.reset()
    obs, *_ = env.step(np.array([1.0]))
    ref = Model().add(StateSpace(lambda x, u, t: -x + u, 1, 1), "lag").set_controller(lambda m: [1.0])
    assert obs[0] == pytest.approx(ref.simulate(0.2, 0.05)["lag"].x[-1, 0], abs=1e-12)
    assert obs[0] == pytest.approx(1 - np.exp(-0.2), abs=1e-4)
    with pytest.raises(ParameterError, match="free input"):
        ModelEnv(mdl, observation=lambda m: m["lag"].x, reward=lambda m, a: 0.0, dt=0.1, horizon=2,
                 action_inputs=["lag.nope"])
