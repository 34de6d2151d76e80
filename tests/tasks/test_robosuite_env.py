import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from langpref.tasks import get_task, make_env
from langpref.tasks.robosuite.controller import CONTROLLER_DIM, lift_unit, make_controller, params_from_unit
from langpref.tasks.robosuite.env import (
    FEATURES,
    GRASP_WEIGHT,
    MIN_CUBE_BOTTLE_GAP,
    OBS_DIM,
    OBS_LAYOUT,
    REACH_WEIGHT,
    SUCCESS_HEIGHT,
    TABLE_HEIGHT,
    compute_features,
    lift_success_value,
)

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)

FIELDS = {f.name: slice(f.start, f.stop) for f in OBS_LAYOUT}
F = {name: i for i, name in enumerate(FEATURES)}


# ---- without a simulator ------------------------------------------------------------------------------------------


def test_spec_is_the_contract():
    spec = get_task("robosuite")
    assert spec.features == FEATURES
    assert spec.name == "robosuite"
    assert spec.features == ("height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success")
    assert spec.action_dim == 4 and spec.simulator.default_horizon == 500
    assert spec.simulator.default_num_trajectories == 448 and spec.default_splits == (359, 44, 45)
    assert sum(spec.default_splits) == spec.simulator.default_num_trajectories
    assert spec.simulator.success_name == "cube lifted"
    stops = [0] + [f.stop for f in spec.obs_layout]
    assert [f.start for f in spec.obs_layout] == stops[:-1]  # contiguous, no gaps
    assert spec.obs_dim == 28
    assert {"eef_pos", "cube_pos", "bottle_pos"} <= set(FIELDS)


def test_compute_features_by_hand():
    eef = np.array([0.0, 0.0, TABLE_HEIGHT + 0.2])
    prev = eef - np.array([0.0, 0.0, 0.01])  # 1 cm in one 0.025 s step: 0.4 m/s
    cube = eef + np.array([0.3, 0.4, 0.0])  # 0.5 m away (3-4-5)
    bottle = eef + np.array([0.0, -0.06, -0.08])  # 0.1 m away (3-4-5 again)
    cube[2] = TABLE_HEIGHT + 0.02  # on the table
    f = compute_features(eef, prev, np.array([0.3, 0.4, cube[2]]), bottle, grasping=False, dt=0.025)
    assert f[F["height"]] == pytest.approx(0.2)
    assert f[F["speed"]] == pytest.approx(0.4)
    d = math.dist(eef, [0.3, 0.4, cube[2]])
    assert f[F["distance_to_cube"]] == pytest.approx(d)
    assert f[F["distance_to_bottle"]] == pytest.approx(0.1)
    assert f[F["lift_success"]] == pytest.approx(REACH_WEIGHT * (1 - math.tanh(10 * d)))


def test_lift_success_is_one_only_when_lifted():
    on_table, lifted = TABLE_HEIGHT + 0.021, TABLE_HEIGHT + SUCCESS_HEIGHT + 0.001
    assert lift_success_value(lifted, 0.3, grasping=False) == 1.0
    assert lift_success_value(on_table, 0.0, grasping=True) == pytest.approx(REACH_WEIGHT + GRASP_WEIGHT)
    assert lift_success_value(on_table, 0.0, grasping=True) < 1.0  # a failure always scores below a lift
    assert lift_success_value(on_table, 0.05, False) > lift_success_value(on_table, 0.10, False) > 0.0
    assert lift_success_value(on_table, 0.05, True) - lift_success_value(on_table, 0.05, False) == pytest.approx(0.25)


def test_params_cover_their_ranges_and_serialise():
    lo, hi = params_from_unit(np.zeros(CONTROLLER_DIM)), params_from_unit(np.full(CONTROLLER_DIM, 0.999))
    assert lo.lift and not hi.lift
    assert lo.excursion_steps == 0 < hi.excursion_steps
    assert lo.circle_radius == 0.0 < hi.circle_radius
    assert lo.far_height < 0.05 < 0.2 < hi.far_height
    assert lo.carry_height < 0.1 < 0.3 < hi.carry_height
    assert lo.gain < hi.gain and lo.max_step < hi.max_step
    # phases shrink with the horizon and leave room for a lift
    short = params_from_unit(np.full(CONTROLLER_DIM, 0.5), horizon=250)
    assert short.excursion_steps + short.carry_steps + short.retreat_steps <= 250 - 150
    ctrl = make_controller(np.random.default_rng(0).random(CONTROLLER_DIM), np.random.default_rng(1))
    assert json.loads(json.dumps(ctrl.params)) == ctrl.params
    with pytest.raises(ValueError):
        params_from_unit(np.zeros(CONTROLLER_DIM + 1))


def test_import_is_cheap_and_robosuite_stays_quiet():
    """Importing the module loads no robosuite; making an env prints none of robosuite's warnings."""
    code = (
        "import sys\n"
        "import langpref.tasks.robosuite.env as R\n"
        "assert 'robosuite' not in sys.modules, 'robosuite imported at module import'\n"
        "e = R.make(10); e.reset(0); e.step([0, 0, 0, 0]); e.close()\n"
        "print('ok')\n"
    )
    env = dict(os.environ, MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("ok")
    assert "[robosuite WARNING]" not in out.stderr and "[robosuite INFO]" not in out.stderr


# ---- with the simulator -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def env():
    e = make_env("robosuite", horizon=500)
    yield e
    e.close()


def _body_id(model, name: str) -> int:
    import mujoco

    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)


def _free_joint_qpos_adr(model, body: str) -> int:
    import mujoco

    bid = _body_id(model, body)
    jid = model.body_jntadr[bid]
    assert model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_FREE
    return int(model.jnt_qposadr[jid])


def test_bottle_is_in_the_scene_and_observed(env):
    import mujoco

    model, data = env.mujoco_handles()
    assert isinstance(model, mujoco.MjModel) and isinstance(data, mujoco.MjData)
    bodies = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i) or "" for i in range(model.nbody)]
    geoms = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, i) or "" for i in range(model.ngeom)]
    assert "bottle_main" in bodies and any("bottle" in g for g in geoms)
    assert "cube_main" in bodies
    obs = env.reset(3)
    for _ in range(5):
        obs = env.step(np.array([0.3, 0.0, 0.0, -1.0]))
    bid, cid = _body_id(model, "bottle_main"), _body_id(model, "cube_main")
    np.testing.assert_allclose(obs[FIELDS["bottle_pos"]], data.xpos[bid], atol=1e-6)
    np.testing.assert_allclose(obs[FIELDS["cube_pos"]], data.xpos[cid], atol=1e-6)
    np.testing.assert_allclose(obs[FIELDS["eef_to_bottle"]], data.xpos[bid] - obs[FIELDS["eef_pos"]], atol=1e-5)
    assert obs.dtype == np.float32 and obs.shape == (OBS_DIM,)
    cam = env.camera()
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cam["name"]) >= 0


def test_reset_is_deterministic_per_seed(env):
    a, b, c = env.reset(11), env.reset(11), env.reset(12)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[FIELDS["cube_pos"]], c[FIELDS["cube_pos"]])
    assert not env.is_success()
    for seed in range(10):
        o = env.reset(seed)
        gap = np.linalg.norm(o[FIELDS["cube_pos"]][:2] - o[FIELDS["bottle_pos"]][:2])
        assert gap >= MIN_CUBE_BOTTLE_GAP - 1e-6
        assert abs(o[FIELDS["bottle_pos"]][2] - (TABLE_HEIGHT + 0.066)) < 0.01  # standing on the table


def test_same_seed_and_actions_replay_exactly(env):
    actions = np.random.default_rng(1).uniform(-1, 1, (30, 4))
    runs = []
    for _ in range(2):
        obs = [env.reset(21)]
        obs += [env.step(a) for a in actions]
        runs.append((np.stack(obs), env.get_state()[0]))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_state_round_trips(env):
    env.reset(5)
    rng = np.random.default_rng(0)
    for _ in range(10):
        env.step(np.append(rng.uniform(-1, 1, 3), 1.0))
    qpos, qvel = env.get_state()
    obs_then = env.observation()
    for _ in range(10):
        env.step(np.append(rng.uniform(-1, 1, 3), -1.0))
    assert not np.allclose(env.get_state()[0], qpos)
    env.set_state(qpos, qvel)
    q2, v2 = env.get_state()
    np.testing.assert_array_equal(q2, qpos)
    np.testing.assert_array_equal(v2, qvel)
    now = env.observation()
    skip = FIELDS["eef_vel"]  # set_state starts a new step: velocity over it is zero
    np.testing.assert_allclose(np.delete(now, np.r_[skip]), np.delete(obs_then, np.r_[skip]), atol=1e-6)


def test_features_on_hand_set_states(env):
    model, data = env.mujoco_handles()
    env.reset(2)
    qpos, qvel = env.get_state()
    eef = env.observation()[FIELDS["eef_pos"]].astype(np.float64)
    cube_adr = _free_joint_qpos_adr(model, "cube_main")
    bottle_adr = _free_joint_qpos_adr(model, "bottle_main")

    # cube 10 cm beside the hand in x, bottle 20 cm beside it in y; nothing touches, nothing is lifted
    q = qpos.copy()
    q[cube_adr : cube_adr + 3] = [eef[0] + 0.10, eef[1], TABLE_HEIGHT + 0.021]
    q[bottle_adr : bottle_adr + 3] = [eef[0], eef[1] + 0.20, eef[2]]
    env.set_state(q, np.zeros_like(qvel))
    f = env.step_features()
    d_cube = math.dist(eef, [eef[0] + 0.10, eef[1], TABLE_HEIGHT + 0.021])
    assert f[F["height"]] == pytest.approx(eef[2] - TABLE_HEIGHT, abs=1e-6)
    assert f[F["speed"]] == 0.0
    assert f[F["distance_to_cube"]] == pytest.approx(d_cube, abs=1e-6)
    assert f[F["distance_to_bottle"]] == pytest.approx(0.20, abs=1e-6)
    assert f[F["lift_success"]] == pytest.approx(REACH_WEIGHT * (1 - math.tanh(10 * d_cube)), abs=1e-6)
    assert f[F["lift_success"]] < 1.0

    # the same cube raised above the success height, well away from the hand: lifted
    q[cube_adr : cube_adr + 3] = [eef[0] + 0.15, eef[1], TABLE_HEIGHT + SUCCESS_HEIGHT + 0.02]
    env.set_state(q, np.zeros_like(qvel))
    assert env.step_features()[F["lift_success"]] == 1.0
    assert env.cube_lifted()
    assert not env.is_success()  # success is earned by stepping, not by setting a state


def test_speed_is_position_change_over_dt(env):
    env.reset(4)
    before = env.observation()[FIELDS["eef_pos"]].astype(np.float64)
    obs = env.step(np.array([0.0, 0.0, 1.0, 0.0]))
    after = obs[FIELDS["eef_pos"]].astype(np.float64)
    speed = env.step_features()[F["speed"]]
    assert speed == pytest.approx(np.linalg.norm(after - before) / env.dt, rel=1e-3, abs=1e-4)
    assert speed > 0.01
    np.testing.assert_allclose(obs[FIELDS["eef_vel"]], (after - before) / env.dt, rtol=1e-3, atol=1e-4)
    assert env.dt == pytest.approx(0.025)


def test_lifting_controller_lifts_the_cube(env):
    """The reference lift (timed for a 250-step horizon: it goes for the cube at once) lifts within ~200 steps."""
    lifted = 0
    for seed in (500, 501, 502):
        obs = env.reset(seed)
        ctrl = make_controller(lift_unit(), np.random.default_rng(seed), horizon=250)
        for t in range(230):
            obs = env.step(ctrl.act(env, obs, t))
            if env.is_success():
                assert env.step_features()[F["lift_success"]] == 1.0
                assert env.step_features()[F["distance_to_cube"]] < 0.05  # the cube is in the hand
                break
        lifted += env.is_success()
        if lifted >= 2:
            break
    assert lifted >= 2


def test_a_no_lift_controller_never_lifts(env):
    u = lift_unit()
    u[0] = 0.99  # hover and dwell instead of lifting
    obs = env.reset(500)
    ctrl = make_controller(u, np.random.default_rng(0), horizon=250)
    near = []
    for t in range(200):
        obs = env.step(ctrl.act(env, obs, t))
        near.append(env.step_features()[F["distance_to_cube"]])
    assert not env.is_success()
    assert min(near) < 0.05  # it did go right up to the cube
    assert ctrl.stage == "dwell"
