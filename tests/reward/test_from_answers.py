"""Rewards from recorded answers (`langpref learn-reward --answers`, `langpref.reward.recorded`): answers recorded from
a person with a reward of their own teach a reward that ranks as theirs does, the same file and seed give the same
reward, and the saved reward travels with its model and refuses another task."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import kendalltau

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.feedback.answers import answer_record, read_answers, write_answers
from langpref.feedback.humans import HumanConfig, true_reward
from langpref.feedback.kind import get_kind
from langpref.feedback.space import toy_latent_space
from langpref.reward import LearnRewardConfig
from langpref.reward.recorded import learn_from_answers
from tests.factories import untrained_checkpoint, write_dataset

UP = {"feature": "height", "direction": "increase"}
W = np.array([0.2, 1.0, -0.6])
"""A person who wants the arm faster, a little higher, nearer the button."""


def _recorded(space, tmp_path, people=("P1", "P2"), n=20):
    """Answers of people with reward W, as another UI would record them: language about random train trajectories."""
    pool = space.split("train")
    records = []
    for k, person in enumerate(people):
        rng = np.random.default_rng(k)
        human = get_kind("language").make_human(W, space, pool, HumanConfig(), rng)
        for i in range(n):
            answer = human.answer(get_kind("language").query(int(rng.choice(pool))))
            records.append(answer_record("language", answer, person, number=i + 1))
    path = tmp_path / "answers.jsonl"
    write_answers(path, records)
    return read_answers(path, len(space.theta), space.feature_names)


@pytest.mark.parametrize("learner", ["paper", "answer-model"])
def test_recorded_answers_teach_the_persons_reward(tmp_path, learner):
    space = toy_latent_space("metaworld", n=60, dim=8, seed=2)
    answers = _recorded(space, tmp_path)
    cfg = LearnRewardConfig(feedback="language", learner=learner)
    learned, left_out = learn_from_answers(space, answers, cfg)
    assert left_out == 0 and [g.name for g in learned] == ["P1", "P2"] and [g.answers for g in learned] == [20, 20]
    truth = true_reward(W, space.theta)
    for group in learned:
        tau = kendalltau(group.learner.predict(space.phi), truth).statistic
        assert tau > 0.5, (group.name, tau)
    (pooled,), _ = learn_from_answers(space, answers, cfg, pooled=True)
    assert pooled.name == "pooled" and pooled.answers == 40 and pooled.participants == ("P1", "P2")
    again, _ = learn_from_answers(space, answers, cfg)
    assert np.array_equal(again[0].learner.predict(space.phi), learned[0].learner.predict(space.phi))


def test_answers_of_other_kinds_are_left_out_and_a_missing_participant_is_one_line(tmp_path):
    space = toy_latent_space("metaworld", n=30, dim=8, seed=1)
    answers = _recorded(space, tmp_path, people=("P1",), n=3)
    with pytest.raises(LangprefError, match="no comparison answers among the 3 recorded"):
        learn_from_answers(space, answers, LearnRewardConfig(feedback="comparison"))
    with pytest.raises(LangprefError, match="no answers of participant 'P9'; the file has P1"):
        learn_from_answers(space, answers, LearnRewardConfig(feedback="language"), participant="P9")


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A lab's folder: a Meta-World-shaped dataset, a real (untrained) checkpoint in lab/model, recorded answers."""
    root = tmp_path_factory.mktemp("lab")
    data = write_dataset(root / "data", env="metaworld", n=24, horizon=8, like_task=True)
    untrained_checkpoint(root / "lab" / "model", 0)
    answers = root / "answers.jsonl"
    lines = [
        {"kind": "language", "shown": 1, "text": "Move faster.", "participant": "P1"},
        {"kind": "language", "shown": 3, "text": "Up!", "participant": "P1", "meaning": UP},
        {"kind": "language", "shown": 5, "no_change": True, "participant": "P1"},
        {"kind": "comparison", "shown": [2, 4], "choice": 0, "participant": "P2"},
        {"kind": "language", "shown": 6, "text": "Slow down.", "participant": "P2"},
        {"kind": "language", "shown": 7, "text": "Open the drawer further.", "participant": "P2"},
    ]
    answers.write_text("".join(json.dumps(line) + "\n" for line in lines))
    return root, data, answers


def test_learn_reward_from_answers_saves_rewards_that_move_with_their_model(lab, tmp_path, capsys):
    import shutil

    import gymnasium as gym

    from langpref.reward import load
    from langpref.reward.saved import LearnedReward

    root, data, answers = lab
    argv = ["learn-reward", "--model", str(root / "lab" / "model"), "--data", str(data), "--answers", str(answers)]
    saved, figure = str(root / "lab" / "rewards"), str(tmp_path / "wants.png")
    assert main([*argv, "--feedback", "mixed", "--save-reward", saved, "--figure", figure, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["figure"] == figure and (tmp_path / "wants.png").stat().st_size > 5000
    assert [r["name"] for r in out["rewards"]] == ["P1", "P2"] and [r["answers"] for r in out["rewards"]] == [3, 2]
    assert out["answers"] == 6 and out["out_of_task"] == 1  # the drawer: not something Meta-World measures
    wants = out["rewards"][0]["wants"]
    assert set(wants["features"]) == {"height", "speed", "distance_to_button"} and len(wants["best"]) == 3
    # the lab's folder copied elsewhere, the original gone: the reward finds its model beside it
    moved = tmp_path / "elsewhere"
    shutil.copytree(root / "lab", moved)
    shutil.move(root / "lab", tmp_path / "gone")
    try:
        reward = load(moved / "rewards" / "reward-P1.json")
        obs, act = np.zeros((5, reward.obs_dim)), np.zeros((5, reward.action_dim))
        assert np.isclose(reward.compute_reward(obs, act).sum(), reward.trajectory_reward(obs, act))
        assert reward.doc["learned_from"]["participants"] == ["P1"] and reward.doc["queries"] == 3
        with pytest.raises(LangprefError, match="not the one the reward"):
            load(moved / "rewards" / "reward-P1.json", model=untrained_checkpoint(tmp_path / "other", 1))
        # a reward of another task with the same observation sizes is refused by the wrapper in one line
        doc = json.loads((moved / "rewards" / "reward-P1.json").read_text())
        (moved / "rewards" / "reward-drawer.json").write_text(json.dumps({**doc, "task": "drawer-open"}))
        with pytest.raises(LangprefError, match="learned on task 'drawer-open', not on this env's task 'metaworld'"):
            LearnedReward(gym.make("langpref/metaworld"), moved / "rewards" / "reward-drawer.json")
    finally:
        shutil.move(tmp_path / "gone", root / "lab")
    assert main([*argv, "--feedback", "language", "--participant", "P7"]) == 2
    assert "no answers of participant 'P7'" in capsys.readouterr().err
    assert main([*argv, "--feedback", "language", "--pooled", "--participant", "P1"]) == 2
    assert "not both" in capsys.readouterr().err
