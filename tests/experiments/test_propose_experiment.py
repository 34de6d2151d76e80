"""`langpref experiment generate` (experiments.propose): a run depends on its seed only."""

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

    from langpref import propose
    from langpref.experiments import propose as experiment
    from langpref.reward import LearnRewardConfig

    small, real_open = ProposeConfig(rollouts=2, search_generations=5, optimize_rounds=2), propose.open_generation
    monkeypatch.setattr(
        propose, "open_generation", lambda data, model, space, cfg=None: real_open(data, model, space, small)
    )
    monkeypatch.setattr(experiment, "REWARD_RUNS", {"humans": 1, "seeds": 4, "queries": 3})
    base = ImproveConfig(seeds=4, iterations=2)
    out = tmp_path / "out"
    experiment.run_propose_experiment("metaworld", real_data.root, None, out, perfect=True, config=base, progress=False)
    together = json.loads((out / "runs.json").read_text())["runs"]

    monkeypatch.setattr(propose, "_ENVS", {})  # a fresh simulator, as a new process has
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
        for env in propose._ENVS.values():
            env.close()
    assert any(together["paper-generated/2"]["generated"] + together["history-generated/2"]["generated"])
    assert together["reward/0/2"]["optimized_true_reward"] is not None
