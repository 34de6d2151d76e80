import numpy as np
import pytest

from langpref.tasks import get_task, make_env
from langpref.tasks.metaworld.controller import CONTROLLER_DIM, expert_unit, make_controller, params_from_unit
from langpref.tasks.metaworld.env import step_features

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)


def test_step_features_on_hand_built_states():
    prev = np.zeros(39)
    obs = np.zeros(39)
    prev[0:3] = [0.0, 0.5, 0.2]
    obs[0:3] = [0.0, 0.5, 0.2125]  # moved 1.25 cm up in one 0.0125 s step: 1 m/s
    obs[4:7] = [0.0, 0.5 + 0.3, 0.2125 + 0.4]  # button 0.5 m away (3-4-5)
    height, speed, dist = step_features(prev, obs, dt=0.0125)
    assert height == pytest.approx(0.2125)
    assert speed == pytest.approx(1.0)
    assert dist == pytest.approx(0.5)


def test_spec_is_the_contract():
    spec = get_task("metaworld")
    assert spec.features == ("height", "speed", "distance_to_button")
    assert spec.obs_dim == 39 and spec.action_dim == 4 and spec.default_splits == (260, 32, 32)


def test_params_cover_their_ranges():
    lo, hi = params_from_unit(np.zeros(CONTROLLER_DIM)), params_from_unit(np.full(CONTROLLER_DIM, 0.999))
    assert lo.dwell_height < 0.1 < 0.3 < hi.dwell_height
    assert lo.press and not hi.press


@pytest.fixture(scope="module")
def env():
    e = make_env("metaworld", horizon=150)
    yield e
    e.close()


def test_reset_is_deterministic_and_state_round_trips(env):
    a = env.reset(7)
    b = env.reset(7)
    c = env.reset(8)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[4:7], c[4:7])  # another seed moves the button
    qpos, qvel = env.get_state()
    for _ in range(5):
        env.step(np.array([1.0, 0.0, 0.0, -1.0]))
    env.set_state(qpos, qvel)
    np.testing.assert_allclose(env.get_state()[0], qpos)


def test_expert_controller_presses_the_button(env):
    obs = env.reset(3)
    ctrl = make_controller(expert_unit(), np.random.default_rng(0))
    dists = []
    for t in range(150):
        obs = env.step(ctrl.act(env, obs, t))
        dists.append(env.step_features()[2])
    assert env.is_success()
    assert dists[-1] < 0.09  # the hand rests on the pressed button (the button face is 7 cm above the finger tips)
    assert dists[0] > 0.2


def test_a_hovering_controller_does_not_press(env):
    u = expert_unit()
    u[7] = 0.9  # hover instead of press
    u[8] = 0.999  # keep 20 cm off
    obs = env.reset(3)
    ctrl = make_controller(u, np.random.default_rng(0))
    for t in range(150):
        obs = env.step(ctrl.act(env, obs, t))
    assert not env.is_success()


def test_every_step_observes_the_goal(env):
    """obs[36:39] is the goal on reset and on every step after it (Meta-World clips each step's observation to a
    space it cached with the goal slot bounded to zero), and the observation space admits it."""
    from langpref.tasks import get_simulator

    assert get_simulator("metaworld").version == 2
    obs = env.reset(5)
    goal = obs[36:39].copy()
    assert np.linalg.norm(goal) > 0.5  # the button's pressed position, about 0.8 m from the origin
    np.testing.assert_allclose(goal, env._env._target_pos, atol=1e-6)
    space = env._env.observation_space
    for t, action in enumerate([[1.0, 0.0, 0.0, -1.0], [0.0, 1.0, -1.0, 1.0], [-1.0, -1.0, 1.0, 0.0]] * 2):
        obs = env.step(np.array(action))
        np.testing.assert_array_equal(obs[36:39], goal, err_msg=f"step {t}")
        assert space.contains(obs.astype(np.float64)), f"step {t}"
    assert np.all(space.low[36:39] <= goal) and np.all(goal <= space.high[36:39])
