"""`langpref experiment rl`: the policy trains on the learned reward (not the env's), every reward source pays what
it says, finished runs are skipped on a rerun, and the config refuses what cannot run."""

from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.experiments.rl import RLConfig, RunFiles, judges, learn_rewards, policy_jobs
from langpref.experiments.rl_policy import Judge, PolicyJob, make_env, train_policy
from langpref.reward import RewardConfig
from tests.factories import require

torch.set_num_threads(1)
require("stable_baselines3", "pip install 'langpref[test]'")

SMALL = RewardConfig(num_negatives=3, max_iter=20)


def _checkpoint(root, latent_dim: int):
    """A Meta-World checkpoint with a small random trajectory encoder of `latent_dim` (what a reward reads)."""
    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.encoders import step_input_dim
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    task = get_task("metaworld")
    torch.manual_seed(0)
    cfg = ModelConfig(latent_dim=latent_dim, traj_hidden=(16,), max_length=12)
    dims = (task.obs_dim, task.action_dim, 20, 2)
    info = DataInfo("metaworld", list(task.features), [asdict(f) for f in task.obs_layout], *dims, [0.1] * 3, [1.0] * 3)
    dim = step_input_dim(task.obs_dim, task.action_dim, True)
    rng = np.random.default_rng(0)
    model = build_model(cfg, info, rng.normal(size=dim) * 0.1, 0.5 + rng.random(dim))
    return save_model(model, root / "ckpt", model_cfg=cfg, lang_finetuned=False)


def _recorder():
    """An SB3 callback keeping, per finished episode, what the agent saw, did and was paid (from the rollout's own
    locals: the reward that goes into its replay buffer)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Recorder(BaseCallback):
        def __init__(self):
            super().__init__()
            self.episodes, self._obs, self._act, self._rew = [], [], [], []

        def _on_step(self) -> bool:
            self._obs.append(np.array(self.model._last_obs[0]))
            sent = self.locals.get("clipped_actions", self.locals["actions"])  # PPO clips what it sends to the env
            self._act.append(np.array(sent[0]))
            self._rew.append(float(self.locals["rewards"][0]))
            if self.locals["dones"][0]:
                self.episodes.append((np.array(self._obs), np.array(self._act), np.array(self._rew)))
                self._obs, self._act, self._rew = [], [], []
            return True

    return Recorder()


def test_the_policy_is_paid_the_learned_reward_not_the_envs(tmp_path, make_synthetic_dataset):
    from langpref.feedback.space import open_space
    from langpref.reward import load

    data = make_synthetic_dataset(tmp_path / "d", n=24)
    dataset, space = open_space(data, None, env="metaworld", perfect=True)
    cfg = RLConfig.tiny(sources=("language",), reward=SMALL)
    store = RunFiles(tmp_path / "runs", cfg.key())
    judge = judges(dataset, space, cfg)
    learn_rewards(space, cfg, _checkpoint(tmp_path, space.dim), tmp_path, store, judge, None)
    (job,) = policy_jobs(space, cfg, store, judge, tmp_path)
    assert job.reward_path and job.scale > 0 and job.scale != 1.0  # normalised by its spread over the dataset
    recorder = _recorder()
    result = train_policy(job, cfg, (recorder,))
    assert len(recorder.episodes) == cfg.steps // cfg.horizon
    reward = load(job.reward_path)
    for obs, act, paid in recorder.episodes:
        expected = cfg.horizon * reward.compute_reward(obs, act) / job.scale  # T r_t, scaled
        np.testing.assert_allclose(paid, expected, rtol=1e-4, atol=1e-6)
        assert np.abs(paid).max() > 0  # the env itself pays 0 every step
    curve = result["curve"]
    assert curve["steps"] == [0, 32, 64] and len(curve["true_reward"]) == 3 and "own_reward" in curve
    assert result["final"]["true_reward"] == curve["true_reward"][-1]


def test_true_and_success_sources_pay_what_they_say():
    rng = np.random.default_rng(0)
    judge = Judge(rng.normal(size=3), rng.normal(size=3), 0.5 + rng.random(3), -1.0, 1.0)
    for source, scale in (("true", 2.0), ("success", 1.0)):
        env = make_env(PolicyJob("x", "metaworld", source, 0, 0, judge, scale), horizon=5)
        env.reset(seed=1)
        for _ in range(5):
            _, r, _, _, info = env.step(env.action_space.sample())
            f = (info["features"] - judge.mean) / judge.std
            assert r == pytest.approx(judge.w @ f / scale if source == "true" else float(info["success"]))
            assert info["env_reward"] == 0.0


def test_a_rerun_skips_finished_runs_and_refuses_another_config(tmp_path, make_synthetic_dataset, monkeypatch):
    from langpref.experiments import rl_policy
    from langpref.experiments.rl import run_rl_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=24)
    cfg = RLConfig.tiny(sources=("true", "success"), seeds=2)
    calls = []
    real = rl_policy.train_policy
    monkeypatch.setattr(rl_policy, "train_policy", lambda job, c, cb=(): calls.append(job.name) or real(job, c, cb))

    def run(config=cfg, **kw):
        return run_rl_experiment("metaworld", data, None, tmp_path / "o", perfect=True, config=config, **kw)

    first = run(progress=False)
    assert sorted(calls) == sorted(f"policy-{s}-h0-s{k}" for s in ("true", "success") for k in (0, 1))
    assert set(first["sources"]) == {"true", "success"} and "true - success" in first["contrasts"]
    assert (tmp_path / "o" / "rl.png").is_file() and "| true |" in (tmp_path / "o" / "rl.md").read_text()
    (tmp_path / "o" / "runs" / "policy-true-h0-s1.json").unlink()  # interrupted before this run finished
    calls.clear()
    again = run(progress=False)
    assert calls == ["policy-true-h0-s1"]
    assert again["sources"]["success"] == first["sources"]["success"]
    calls.clear()
    run(config=replace(cfg, seeds=3), progress=False)  # one more seed reuses the two finished
    assert sorted(calls) == ["policy-success-h0-s2", "policy-true-h0-s2"]
    with pytest.raises(LangprefError, match="another configuration; pass --force"):
        run(config=replace(cfg, steps=96, eval_every=48), progress=False)
    calls.clear()
    run(config=replace(cfg, steps=96, eval_every=48), progress=False, force=True)
    assert len(calls) == 4


def test_a_learned_reward_needs_a_model(tmp_path, make_synthetic_dataset):
    from langpref.experiments.rl import run_rl_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=24)
    with pytest.raises(LangprefError, match="needs --model"):
        run_rl_experiment("metaworld", data, None, tmp_path / "o", perfect=True, config=RLConfig.tiny())


@pytest.mark.parametrize(
    "change, message",
    [
        ({"sources": ("language", "tru")}, "sources must be distinct names"),
        ({"sources": ("true", "true")}, "sources must be distinct names"),
        ({"algorithm": "dqn"}, "unknown algorithm 'dqn'"),
        ({"steps": 0}, "steps must be >= 1"),
        ({"eval_every": 65}, "must not exceed steps"),
        ({"hidden": ()}, "hidden needs at least one layer"),
        ({"queries": 0}, "queries, humans and seeds must each be >= 1"),
    ],
)
def test_the_config_refuses_what_cannot_run_in_one_line(change, message):
    RLConfig().validate()
    RLConfig.tiny().validate()
    with pytest.raises(LangprefError, match=message) as err:
        replace(RLConfig.tiny(), **change).validate()
    assert "\n" not in str(err.value)


def test_the_cli_builds_the_config_from_its_flags():
    from langpref.cli_config import from_args
    from tests.factories import parsers

    p = parsers()["experiment rl"]
    args = p.parse_args(["--env", "metaworld", "--sources", "true,success", "--steps", "500", "--no-cmaes"])
    cfg = from_args(RLConfig, args)
    assert cfg.sources == ("true", "success") and cfg.steps == 500 and not cfg.cmaes and cfg.horizon == 150


def test_the_command_runs_records_its_config_and_prints_one_json(tmp_path, make_synthetic_dataset, capsys):
    import json

    from langpref.cli import main

    data = make_synthetic_dataset(tmp_path / "d", n=24)
    out = tmp_path / "o"
    argv = ["experiment", "rl", "--env", "metaworld", "--data", str(data), "--perfect-latent", "--out", str(out)]
    flags = ["--sources", "true", "--seeds", "1", "--steps", "16", "--horizon", "8", "--eval-every", "16"]
    assert main([*argv, *flags, "--eval-episodes", "1", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert list(printed["sources"]) == ["true"] and printed["sources"]["true"]["steps"] == [0, 16]
    saved = json.loads((out / "rl.config.json").read_text())
    assert (
        saved["command"].startswith("langpref experiment rl --env metaworld")
        and saved["config"]["config"]["steps"] == 16
    )
    assert "--json" not in printed["command"] and printed["command"] in (out / "rl.md").read_text()


def test_paired_intervals_and_targets():
    from langpref.experiments.rl_report import _interval, paired, targets

    d = paired([1.0, 2.0, 3.0], [0.0, 1.0, 1.0])
    assert d["mean"] == pytest.approx(4 / 3) and d["low"] < d["mean"] < d["high"]
    one = paired([1.0], [0.5])
    assert one == {"mean": 0.5, "low": None, "high": None} and "no interval" in _interval(one)
    met = targets({s: {"final_true_reward": v} for s, v in (("language", 0.85), ("comparison", 0.9), ("true", 1.0))})
    assert list(met.values()) == [True, False]


def test_the_share_of_the_true_reward_policy_counts_humans_not_seeds():
    """Ratios of means over humans on both scales; duplicating every seed changes neither the ratio nor the interval
    (a human's seeds are one unit), and the untrained policy is the zero of the second scale."""
    from langpref.experiments.rl_report import ratios

    def runs_of(seeds: int) -> dict:
        out = {}
        for h, (lang, true) in enumerate([(1.0, 2.0), (2.0, 2.0), (1.5, 3.0)]):
            for s in range(seeds):
                for source, final in (("language", lang), ("true", true)):
                    out[f"policy-{source}-h{h}-s{s}"] = {
                        "final": {"true_reward": final},
                        "curve": {"true_reward": [0.5]},
                    }
        return out

    one = ratios(runs_of(1), RLConfig(humans=3, seeds=1, sources=("language", "true")))["language"]
    three = ratios(runs_of(3), RLConfig(humans=3, seeds=3, sources=("language", "true")))["language"]
    assert one["as_evaluated"]["mean"] == pytest.approx(4.5 / 7) and one["above_untrained"]["mean"] == pytest.approx(
        3 / 5.5
    )
    assert one["as_evaluated"]["low"] < one["as_evaluated"]["mean"] < one["as_evaluated"]["high"]
    assert one == three and one["untrained_true_reward"] == 0.5


def test_paired_differences_count_humans_not_seeds():
    """Issue 42, item 4: with a human's seeds copied, the contrast's interval is the same as from one seed each (the
    unit is the human), and narrower than runs counted as independent would give."""
    from langpref.experiments.rl_report import paired

    a, b = [1.0, 2.0, 3.0], [0.0, 1.0, 1.0]
    copied = paired([x for x in a for _ in range(3)], [x for x in b for _ in range(3)], humans=3)
    assert copied == paired(a, b, humans=3) == paired(a, b)
    as_runs = paired([x for x in a for _ in range(3)], [x for x in b for _ in range(3)])
    assert as_runs["mean"] == pytest.approx(copied["mean"]) and as_runs["high"] < copied["high"]
