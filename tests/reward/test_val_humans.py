"""Runs scored on val meet other synthetic humans (and run seeds) than the test runs of the same --seed (issue 42,
item 3): a choice made on val never sees a test human, and a human speaking val phrasings is read by a reader fitted
on none of them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from langpref.feedback import toy_latent_space
from langpref.feedback.humans import HumanConfig, sample_weights
from langpref.reward import LearnRewardConfig, human_weights, learn_reward, run_reward_learning
from langpref.reward.answer_model import AnswerReader
from langpref.reward.learners import get_learner
from langpref.reward.loop import human_stream


def test_the_test_stream_is_the_master_seed_as_before():
    assert human_stream(4) == human_stream(4, "test") == (4,)
    expected = sample_weights(3, np.random.default_rng([4, 7919, 2]))
    assert np.array_equal(human_weights(3, 4, 2), expected)
    assert np.array_equal(human_weights(3, human_stream(4), 2), expected)


def test_val_humans_are_none_of_the_test_humans():
    """For every master seed of a range, no val human's weights equal any test human's, of that seed or another."""
    test = {tuple(human_weights(3, seed, h)) for seed in range(20) for h in range(10)}
    val = {tuple(human_weights(3, human_stream(seed, "val"), h)) for seed in range(20) for h in range(10)}
    assert len(val) == 200 and not test & val
    assert human_stream(0, "val") != human_stream(0, "train")


def test_learn_reward_on_val_uses_the_val_stream():
    """Same --seed, val and test: the runs are the val stream's (humans and run seeds), not the test stream's."""
    space = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    cfg = LearnRewardConfig(feedback="comparison", queries=3, humans=2, seeds=1, eval_split="val")
    out = learn_reward(space, cfg, progress=False)
    stream = human_stream(0, "val")
    own = [run_reward_learning(space, human_weights(3, stream, h), cfg, (*stream, h, 0)) for h in range(2)]
    assert np.allclose(out["cross_entropy"], np.mean([c.cross_entropy for c in own], axis=0))
    as_test = [run_reward_learning(space, human_weights(3, 0, h), cfg, (0, h, 0)) for h in range(2)]
    assert not np.allclose(out["cross_entropy"], np.mean([c.cross_entropy for c in as_test], axis=0))
    test_out = learn_reward(space, replace(cfg, eval_split="test"), progress=False)
    assert test_out["config"]["eval_split"] == "test"


def test_the_experiments_runs_on_val_use_the_val_stream_too():
    """`experiment active` (and every experiment of experiments/reward.py) runs each (method, human, seed) through
    one job: on val it meets the val stream's human, on test the test stream's, as learn-reward does."""
    from dataclasses import asdict

    from langpref.experiments.reward import _reward_job

    space = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    for split in ("val", "test"):
        cfg = LearnRewardConfig(feedback="comparison", queries=3, humans=1, seeds=1, eval_split=split)
        stream = human_stream(0, split)
        _, got = _reward_job(space, ("m/1/0", cfg, 1, 0))
        want = run_reward_learning(space, human_weights(3, stream, 1), cfg, (*stream, 1, 0))
        assert got == asdict(want)


def _with_val(space, seed):
    """The toy space plus a val split of the bank whose psi are noise (seeded): a reader fitted on them shows it."""
    test = space.phrases["test"]
    val = replace(test, psi=np.random.default_rng(seed).standard_normal(test.psi.shape))
    return replace(space, phrases={**space.phrases, "val": val})


def test_a_human_speaking_val_is_read_by_a_reader_fitted_on_none_of_it():
    """The answer model's reader fits T_read and its confusion on the bank's val phrasings, unless the human speaks
    them: then on the train split, each phrasing left out of its own prototype. Changing val's psi moves the reader
    of a test-speaking human and leaves the val-speaking human's reader as it was."""
    toy = toy_latent_space("metaworld", n=40, dim=8, seed=3)
    one, other = _with_val(toy, 0), _with_val(toy, 1)
    features = np.arange(len(toy.feature_names))

    def reader(s, spoken):
        return AnswerReader(s, features, "train", None, spoken)

    for spoken in ("val", "all"):
        a, b = reader(one, spoken), reader(other, spoken)
        assert a.temperature == b.temperature and np.array_equal(a.confusion, b.confusion)
    assert not np.array_equal(reader(one, "test").confusion, reader(other, "test").confusion)


def test_learn_reward_tells_the_learner_which_phrasings_its_human_speaks():
    space = _with_val(toy_latent_space("metaworld", n=40, dim=8, seed=3), 0)
    features = np.arange(len(space.feature_names))
    readers = {}
    for split in ("val", "test"):
        cfg = LearnRewardConfig(learner="answer-model", human=HumanConfig(phrasing_split=split))
        readers[split] = get_learner("answer-model").make(space, space.split("train"), cfg, 0).reader
        assert np.array_equal(readers[split].confusion, AnswerReader(space, features, "train", None, split).confusion)
    assert not np.array_equal(readers["val"].confusion, readers["test"].confusion)
