"""`langpref experiment generate` (experiments.generate): a run depends on its seed only."""

from __future__ import annotations

import pytest

from langpref.improve import ImproveConfig
from langpref.propose import ProposeConfig

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)


def test_a_generate_experiment_run_depends_on_its_seed_only(real_data, tmp_path, monkeypatch):
    """`experiment generate --seeds 4` and seed 2 run alone (its own simulator and worker state, in a sweep of
    another length) give seed 2 the same trajectories and numbers: what splicing the runs of two sweeps into one
    result (issue 30, item 4) relies on. Every curve (dataset and generated candidates) and a reward run with its
    generated optimum."""
    import json
    from dataclasses import replace

    from langpref import propose, tasks
    from langpref.experiments import generate as experiment
    from langpref.reward import LearnRewardConfig

    small, real_open = ProposeConfig(rollouts=2, search_generations=5, optimize_rounds=2), propose.open_generation
    monkeypatch.setattr(propose, "open_generation", lambda dataset, space, cfg=None: real_open(dataset, space, small))
    monkeypatch.setattr(experiment, "REWARD_RUNS", {"humans": 1, "seeds": 4, "queries": 3})
    base = ImproveConfig(seeds=4, iterations=2)
    out = tmp_path / "out"
    run = experiment.run_generate_experiment
    run("metaworld", real_data.root, None, out, perfect=True, config=base, progress=False)
    together = json.loads((out / "runs.json").read_text())["runs"]

    monkeypatch.setattr(tasks, "_LIVE_ENVS", {})  # a fresh simulator, as a new process has
    state = experiment._worker(real_data.root, None, "metaworld", True, base.human.phrasings)
    alone = replace(base, seeds=3)
    jobs = [
        (f"{name}/2", replace(alone, strategy=strategy, candidate_split=split), (alone.seed, 2))
        for name, (strategy, split) in experiment.CURVES.items()
    ]
    rcfg = LearnRewardConfig(feedback="language", human=base.human, seed=base.seed, humans=1, seeds=3, queries=3)
    jobs.append(("reward/0/2", rcfg, (rcfg.seed, 0, 2)))
    try:
        for job in jobs:
            key, run = experiment._job(state, job)
            run = json.loads(json.dumps(run))
            if "step_s" in run:  # wall times of the generation steps: the only thing allowed to differ
                assert len(run.pop("step_s")) == len(together[key].pop("step_s"))
            assert run == together[key], key
    finally:
        for env in tasks._LIVE_ENVS.values():
            env.close()
    assert any(together["paper-generated/2"]["generated"] + together["history-generated/2"]["generated"])
    assert together["reward/0/2"]["optimized_true_reward"] is not None


def test_experiment_generate_from_the_command_line(real_data, tmp_path, monkeypatch, capsys):
    """`langpref experiment generate` on a tiny simulated dataset (oracle space, 2 seeds, 2 iterations; 2 humans x 1
    seed of 3 queries): the four curves start from one trajectory on the test split's scale, the dataset curves stay
    within it, the reward section's shares and targets are those of its own runs, the files it names are there, and a
    rerun resumes every finished run from runs.json without running one again."""
    import json
    from pathlib import Path

    import numpy as np

    from langpref import propose
    from langpref.cli import main
    from langpref.experiments import generate as experiment

    small, real_open = ProposeConfig(rollouts=2, search_generations=5, optimize_rounds=2), propose.open_generation
    monkeypatch.setattr(propose, "open_generation", lambda dataset, space, cfg=None: real_open(dataset, space, small))
    monkeypatch.setattr(experiment, "REWARD_RUNS", {"humans": 2, "seeds": 1, "queries": 3})
    out = tmp_path / "out"
    argv = ["experiment", "generate", "--env", "metaworld", "--data", str(real_data.root), "--perfect-latent"]
    argv += ["--seeds", "2", "--iterations", "2", "--out", str(out)]
    assert main([*argv, "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["command"] == " ".join(["langpref", *argv]) and s["perfect"] and s["seeds"] == 2
    assert s == json.loads((out / "generate.json").read_text())
    for name in ("figure", "reward_figure"):
        assert Path(s[name]).parent == out and Path(s[name]).read_bytes()[:4] == b"\x89PNG"
    assert f"`{s['command']}`" in (out / "generate.md").read_text()

    curves = {name: np.array(r["curve"]) for name, r in s["improve"].items()}
    assert set(curves) == set(experiment.CURVES) and all(len(c) == 3 for c in curves.values())
    assert len({c[0] for c in curves.values()}) == 1  # one start and one scale for dataset and generated candidates
    assert curves["paper"].max() <= 1.0 + 1e-12 and curves["history"].max() <= 1.0 + 1e-12  # the test split's best
    for name in ("paper-generated", "history-generated"):
        r = s["improve"][name]
        assert r["num_runs"] == 2 and r["step_s_p50"] > 0 and 0 < r["generated_share"] <= 1
        final = curves[name][-1]
        assert s["targets"]["generated_above_1"][name] == bool(final > 1.0)
        assert s["targets"]["generated_above_history_on_dataset"][name] == bool(final > curves["history"][-1])

    runs = json.loads((out / "runs.json").read_text())["runs"]
    reward = [runs[f"reward/{h}/0"] for h in range(2)]
    picked = np.array([r["true_reward_of_best"][-1] for r in reward])
    made = np.array([r["optimized_true_reward"] for r in reward])
    rw = s["reward"]
    assert rw["runs"] == 2 and rw["queries"] == 3 and np.isfinite(made).all()
    assert rw["true_reward_of_best"] == picked.tolist() and rw["optimized_true_reward"] == made.tolist()
    assert rw["share_optimized_above_best_test"] == (made > 1.0).mean()
    assert rw["share_optimized_above_picked"] == (made > picked).mean()
    assert s["targets"]["optimum_beats_best_test_for_60pct"] == bool((made > 1.0).mean() >= 0.6)

    def no_run(state, job):
        raise AssertionError(f"run {job[0]} ran again; runs.json holds it")

    monkeypatch.setattr(experiment, "_job", no_run)
    assert main([*argv, "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert {k: v for k, v in again.items() if k != "date"} == {k: v for k, v in s.items() if k != "date"}
