"""The human whose "no change" follows a margin rule (issue 42, item 5) reaches the learners through learn-reward."""

from __future__ import annotations

from dataclasses import replace

from langpref.feedback import toy_latent_space
from langpref.feedback.humans import HumanConfig
from langpref.reward import LearnRewardConfig, learn_reward


def test_the_margin_human_says_no_change_in_a_run_and_is_recorded_in_the_config():
    space = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    cfg = LearnRewardConfig(feedback="language", queries=12, humans=2, seeds=1, learner="answer-model")
    plain = learn_reward(space, cfg, progress=False)
    assert "no_change_margin" not in plain["config"]["human"]
    margin = learn_reward(space, replace(cfg, human=HumanConfig(no_change_margin=0.5)), progress=False)
    assert margin["config"]["human"]["no_change_margin"] == 0.5
    assert margin["no_change_share"] > 0 and margin["cross_entropy"] != plain["cross_entropy"]
