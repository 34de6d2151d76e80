"""The example task plugin (`examples/plugin`, task `metaworld-reach`) works through langpref's registry alone:
installed as a package, found through the `langpref.tasks` entry point, generated, replayed and described with no
edit inside langpref. `make install` installs it; these tests fail (not skip) when it is missing.
"""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

import numpy as np
import pytest

from langpref.tasks import ENTRY_POINT_GROUP, get_task, make_env, task_names

TASK = "metaworld-reach"
FEATURES = ["height", "speed", "distance_to_goal"]
N, HORIZON = 6, 30


def langpref(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "langpref", *args], capture_output=True, text=True, timeout=300, check=False
    )


@pytest.fixture(scope="module", autouse=True)
def installed() -> None:
    try:
        dist = distribution("langpref-reach-example")
    except PackageNotFoundError:
        pytest.fail("the example plugin is not installed: run `make install` (it pip-installs examples/plugin)")
    assert [ep.name for ep in dist.entry_points if ep.group == ENTRY_POINT_GROUP] == [TASK]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("plugin") / "reach"
    proc = langpref(
        "generate",
        "--env",
        TASK,
        "--out",
        str(out),
        "--num-trajectories",
        str(N),
        "--horizon",
        str(HORIZON),
        "--workers",
        "1",
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["env"] == TASK and summary["num_trajectories"] == N and summary["horizon"] == HORIZON
    return out


def test_the_plugin_is_registered_and_listed():
    assert TASK in task_names()
    task = get_task(TASK)
    assert task.source == "plugin" and task.simulator is not None
    proc = langpref("tasks", "--json")
    assert proc.returncode == 0, proc.stderr
    listed = json.loads(proc.stdout)[TASK]
    assert listed["simulator"] is True and listed["source"] == "plugin"
    assert list(listed["features"]) == FEATURES and all(listed["features"].values())
    assert listed["obs_dim"] == 39 and listed["action_dim"] == 4


def test_generate_stores_the_plugins_task_and_varied_features(dataset):
    meta = json.loads((dataset / "meta.json").read_text())
    assert meta["env"] == TASK and meta["feature_names"] == FEATURES
    features = np.load(dataset / "features.npy")
    assert features.shape == (N, len(FEATURES))
    assert np.all(features.std(axis=0) > 1e-3), features  # every feature differs across trajectories


def test_the_same_seed_gives_byte_identical_trajectories(dataset, tmp_path):
    from langpref.dataset.generate import GenerateConfig, generate

    again = tmp_path / "again"
    generate(GenerateConfig(env=TASK, out=again, num_trajectories=N, horizon=HORIZON, workers=1, seed=0))
    files = sorted(p.name for p in (dataset / "trajectories").iterdir())
    assert len(files) == N and files == sorted(p.name for p in (again / "trajectories").iterdir())
    for name in files:
        assert (dataset / "trajectories" / name).read_bytes() == (again / "trajectories" / name).read_bytes(), name
    assert (dataset / "features.npy").read_bytes() == (again / "features.npy").read_bytes()


def test_the_bank_loads_with_all_splits():
    from langpref.language.bank import BANK_SPLITS, load_bank

    bank = load_bank(TASK)  # validates: every feature and direction, no phrasing repeated across splits
    assert bank.features == tuple(FEATURES)
    for split in BANK_SPLITS:
        for text, _, _ in bank.all_of_split(split):
            assert text.strip()
        assert all(len(bank.get(split, f, d)) >= 5 for f in FEATURES for d in ("increase", "decrease"))


def test_env_resets_by_seed_round_trips_state_and_reaches_with_the_expert():
    from langpref_reach.controller import expert_unit, make_controller

    env = make_env(TASK, horizon=80)
    try:
        a, b, c = env.reset(7), env.reset(7), env.reset(8)
        np.testing.assert_array_equal(a, b)
        assert not np.allclose(a[36:39], c[36:39])  # another seed moves the goal
        obs = env.reset(3)
        qpos, qvel = env.get_state()
        ctrl = make_controller(expert_unit(), np.random.default_rng(0))
        dists = []
        for t in range(80):
            obs = env.step(ctrl.act(env, obs, t))
            dists.append(env.step_features()[2])
        assert np.linalg.norm(obs[36:39]) > 0.5  # the goal is still in the observation after stepping
        assert env.is_success() and dists[-1] < 0.05 and dists[0] > 0.15  # started far, ended on the goal
        env.set_state(qpos, qvel)
        np.testing.assert_allclose(env.get_state()[0], qpos)
    finally:
        env.close()


def test_a_stored_trajectory_re_renders(dataset):
    from langpref.dataset.storage import load_dataset
    from langpref.tasks.render import render_frames

    traj = load_dataset(dataset).load(0)
    env = make_env(TASK, HORIZON)
    try:
        env.reset(traj.seed)
        frames = render_frames(env, traj.qpos, traj.qvel, width=80, height=60, stride=10)
    finally:
        env.close()
    assert frames.shape == (3, 60, 80, 3) and frames[0].std() > 10
