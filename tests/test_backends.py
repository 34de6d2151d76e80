"""Ray backend: same results as local processes, across a two-node cluster, and after a worker is killed."""

import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from langpref.backends import run_jobs
from langpref.dataset.generate import GenerateConfig, generate
from langpref.dataset.storage import load_dataset
from tests.factories import require

ray = require("ray", "pip install 'langpref[ray]'")
os.environ.setdefault("RAY_AUTH_MODE", "disabled")


def _square(state, job):
    time.sleep(0.2)  # long enough that both nodes get work
    return job, job * job + state, ray.get_runtime_context().get_node_id()


def _offset(base):
    return base


def _die_once(marker_dir, job):
    """The first attempt of job 2 kills its own worker process, as a crashed or preempted machine would."""
    marker = Path(marker_dir) / f"attempt-{job}"
    if job == 2 and not marker.exists():
        marker.touch()
        os._exit(1)
    return job, job * 10


@pytest.fixture(scope="module")
def cluster():
    from ray.cluster_utils import Cluster

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    c.add_node(num_cpus=1)
    c.wait_for_nodes()
    ray.init(address=c.address, include_dashboard=False, log_to_driver=False)
    yield c
    ray.shutdown()
    c.shutdown()


def test_tasks_spread_over_two_nodes_with_the_local_results(cluster):
    jobs = list(range(8))
    local = sorted(r[:2] for r in run_jobs(_square, jobs, setup=_offset, setup_args=(1,), workers=1))
    remote = list(run_jobs(_square, jobs, setup=_offset, setup_args=(1,), backend="ray", workers=2))
    assert sorted(r[:2] for r in remote) == local
    assert len({node for _, _, node in remote}) == 2


def test_generation_on_two_nodes_equals_local(cluster, tmp_path):
    cfg = dict(env="metaworld", num_trajectories=6, horizon=40, seed=11)
    generate(GenerateConfig(out=tmp_path / "local", workers=1, **cfg))
    generate(GenerateConfig(out=tmp_path / "ray", workers=2, backend="ray", **cfg))
    a, b = load_dataset(tmp_path / "local"), load_dataset(tmp_path / "ray")
    np.testing.assert_array_equal(a.features, b.features)
    for i in range(len(a)):
        np.testing.assert_array_equal(a.load(i).observations, b.load(i).observations)


def test_a_killed_worker_is_retried_and_the_result_unchanged(cluster, tmp_path):
    results = sorted(
        run_jobs(_die_once, list(range(5)), setup=_offset, setup_args=(str(tmp_path),), backend="ray", workers=2)
    )
    assert (tmp_path / "attempt-2").exists()  # the first attempt really died
    assert results == [(j, j * 10) for j in range(5)]


def test_reward_sweep_on_two_nodes_equals_local(cluster, tmp_path):
    from langpref.experiments.common import SweepConfig
    from langpref.experiments.reward import run_reward_experiment
    from langpref.reward import LearnRewardConfig

    generate(GenerateConfig(env="metaworld", out=tmp_path / "data", num_trajectories=30, horizon=20, workers=1))
    cfg = LearnRewardConfig(queries=3, humans=2, seeds=1)
    kw = dict(env="metaworld", data=tmp_path / "data", perfect=True, config=cfg, progress=False)
    local = run_reward_experiment(out=tmp_path / "local", **kw)
    remote = run_reward_experiment(out=tmp_path / "ray", sweep=SweepConfig("ray", 2), **kw)
    for method in ("language", "comparison"):
        assert local["methods"][method]["cross_entropy"] == remote["methods"][method]["cross_entropy"]
        assert local["methods"][method]["true_reward_of_best"] == remote["methods"][method]["true_reward_of_best"]
