"""Both kinds in one learner (`--feedback mixed`): the kind and item of most information per modelled second, equal
information goes to the cheaper kind and equal costs to the more informative query, both kinds' answers enter one
fit, the same seed asks the same, and the summary keeps its keys and says what was asked and when."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.feedback import ComparisonAnswer, ComparisonQuery, LanguageAnswer, LanguageQuery, toy_latent_space
from langpref.feedback.kind import kind_of
from langpref.reward import (
    LearnRewardConfig,
    RewardConfig,
    RewardLearner,
    human_weights,
    learn_reward,
    run_reward_learning,
)
from langpref.reward.cost import on_time_grid, query_costs, time_average
from langpref.reward.mixed import MixedInfoGain
from langpref.reward.posterior import laplace_posterior
from langpref.reward.selection import candidate_rows

torch.set_num_threads(1)


def _selector(costs: dict[str, float], seed: int = 0) -> tuple[MixedInfoGain, RewardLearner]:
    space = toy_latent_space("metaworld", n=20, seed=seed)
    return MixedInfoGain(space, space.split("train"), RewardConfig(), costs), RewardLearner(space.dim)


def _with_scores(monkeypatch, selector: MixedInfoGain, language, comparison) -> None:
    """Replace each kind's scores by `language(rows)` and `comparison(number of pairs)`, keeping the pairs."""
    pairs = selector.selectors["comparison"].scores
    monkeypatch.setattr(selector.selectors["language"], "scores", lambda xi, rows: language(len(rows)))

    def scores(xi, rows):
        i, j, _ = pairs(xi, rows)
        return i, j, comparison(len(i))

    monkeypatch.setattr(selector.selectors["comparison"], "scores", scores)


def test_the_paper_costs_language_113_percent_less_time():
    assert query_costs() == {"language": pytest.approx(0.887), "comparison": 1.0}  # each kind's own `seconds`
    assert query_costs({"language": 12.0, "comparison": 15.0}) == {"language": 12.0, "comparison": 15.0}
    assert query_costs({"language": None, "comparison": 2.0}) == {"language": pytest.approx(0.887), "comparison": 2.0}
    with pytest.raises(LangprefError, match="positive"):
        query_costs({"language": 0.0})


def test_equal_information_goes_to_the_cheaper_kind(monkeypatch):
    selector, learner = _selector(query_costs())
    _with_scores(monkeypatch, selector, lambda n: np.full(n, 0.3), lambda n: np.full(n, 0.3))
    assert isinstance(selector.select(learner, np.random.default_rng(0)).query, LanguageQuery)  # 0.887 < 1
    selector.costs = query_costs({"language": 1.2})
    chosen = selector.select(learner, np.random.default_rng(0))
    assert isinstance(chosen.query, ComparisonQuery) and chosen.score == pytest.approx(0.3)


def test_equal_costs_go_to_the_more_informative_query(monkeypatch):
    selector, learner = _selector(query_costs({"language": 1.0, "comparison": 1.0}))
    rows = candidate_rows(selector.pool, None, np.random.default_rng(0))

    def one_high(value, at):
        def scores(n):
            s = np.full(n, 0.2)
            s[at] = value
            return s

        return scores

    _with_scores(monkeypatch, selector, one_high(0.4, 2), one_high(0.5, 5))
    i, j = np.triu_indices(len(rows), k=1)
    assert selector.select(learner, np.random.default_rng(0)).query == ComparisonQuery(int(rows[i[5]]), int(rows[j[5]]))
    _with_scores(monkeypatch, selector, one_high(0.6, 2), one_high(0.5, 5))
    assert selector.select(learner, np.random.default_rng(0)).query == LanguageQuery(int(rows[2]))


@pytest.mark.parametrize("costs", [(1.0, 1.0), (None, None), (3.0, 1.0)])
def test_the_choice_is_the_best_information_per_second_of_either_kind_from_the_same_draws(costs):
    selector, learner = _selector(query_costs(dict(zip(("language", "comparison"), costs))), seed=4)
    chosen = selector.select(learner, np.random.default_rng(3))
    # the same draws again, each kind scored alone
    rng = np.random.default_rng(3)
    rows = candidate_rows(selector.pool, None, rng)
    xi = laplace_posterior(learner).sample(selector.samples, rng)
    lang = selector.selectors["language"].scores(xi, rows)
    _, _, comp = selector.selectors["comparison"].scores(xi, rows)
    c = selector.costs
    best = max(lang.max() / c["language"], comp.max() / c["comparison"])
    assert chosen.score / c[kind_of(chosen.query).name] == pytest.approx(best)
    assert chosen.candidates == len(lang) + len(comp)


def _config(**kw) -> LearnRewardConfig:
    base = {"feedback": "mixed", "queries": 8, "candidates": 10, "reward": RewardConfig(num_negatives=4, max_iter=50)}
    return LearnRewardConfig(**{**base, **kw})


def test_both_kinds_are_answered_by_their_own_human_into_one_learner_and_seeds_repeat():
    space = toy_latent_space("metaworld", n=30, seed=1)
    w = human_weights(len(space.feature_names), 0, 0)
    cfg = _config(language_seconds=3.0)  # language three times a comparison's time: both kinds are asked
    runs = []
    for seed in ((0, 1, 2), (0, 1, 2), (0, 1, 3)):
        record: list = []
        learners: list = []
        curves = run_reward_learning(space, w, cfg, seed, record, learners=learners)
        runs.append((record, curves, learners[0]))
    record, curves, learner = runs[0]
    assert set(curves.kinds) == {"language", "comparison"}
    for (chosen, answer), kind, batch in zip(record, curves.kinds, learner.batches):
        expected = (LanguageAnswer, 1 + 4) if kind == "language" else (ComparisonAnswer, 1)
        assert isinstance(answer, expected[0]) and answer.query == chosen.query and len(batch.weights) == expected[1]
    assert len(learner.batches) == 8
    assert curves.seconds == pytest.approx(np.cumsum([0.0] + [3.0 if k == "language" else 1.0 for k in curves.kinds]))
    # the same seed asks the same, another seed not
    assert [c.query for c, _ in runs[1][0]] == [c.query for c, _ in record] and runs[1][1] == curves
    assert [c.query for c, _ in runs[2][0]] != [c.query for c, _ in record]


@pytest.mark.parametrize("cheap", ["language", "comparison"])
def test_a_mixed_run_that_asks_one_kind_is_that_kinds_infogain_run(cheap):
    """Common random numbers: with one kind far cheaper, mixed asks it alone, and its queries, answers and curves are
    those of the single-kind infogain run (the same draws, the same human stream, the same negatives)."""
    space = toy_latent_space("metaworld", n=30, seed=1)
    w = human_weights(len(space.feature_names), 0, 1)
    cheaper = {f"{cheap}_seconds": 1e-3}
    runs = []
    for cfg in (_config(queries=5, **cheaper), _config(queries=5, feedback=cheap, query_selection="infogain")):
        record: list = []
        runs.append((run_reward_learning(space, w, cfg, (0, 2, 0), record), [a for _, a in record]))
    (mixed, mixed_answers), (single, single_answers) = runs
    assert mixed.kinds == [cheap] * 5 and mixed_answers == single_answers
    assert mixed.cross_entropy == single.cross_entropy and mixed.true_reward_of_best == single.true_reward_of_best


def test_learn_reward_mixed_keeps_its_keys_and_adds_kinds_and_seconds():
    space = toy_latent_space("metaworld", n=30, seed=1)
    cfg = _config(humans=2, seeds=1, queries=4)
    out = json.loads(json.dumps(learn_reward(space, cfg, progress=False)))
    assert len(out["cross_entropy"]) == len(out["true_reward_of_best"]) == 5
    assert out["feedback"] == "mixed" and out["query_selection"] == "infogain" and out["num_runs"] == 2
    assert len(out["kinds_asked"]) == 2 and all(len(k) == 4 for k in out["kinds_asked"])
    assert all(k in ("language", "comparison") for ks in out["kinds_asked"] for k in ks)
    assert np.allclose(np.sum([s for s in out["kind_share"].values()], axis=0), 1.0)
    seconds = out["modelled_seconds"]
    assert len(seconds) == 5 and seconds[0] == 0.0 and np.all(np.diff(seconds) > 0)
    # a single kind records its kind and time too
    single = learn_reward(space, LearnRewardConfig(feedback="comparison", queries=3, humans=1, seeds=1), progress=False)
    assert single["kind_share"] == {"comparison": [1.0, 1.0, 1.0]} and single["modelled_seconds"] == [0, 1, 2, 3]


@pytest.mark.parametrize(
    "kw,message",
    [
        ({"query_selection": "random"}, "not defined for mixed feedback"),
        ({"query_selection": "volume-removal"}, "not defined for mixed feedback"),
        ({"reward": RewardConfig(model="mlp")}, "linear reward"),
        ({"query_batch": 0}, "query_batch"),
        ({"comparison_seconds": -1.0}, "positive"),
    ],
)
def test_bad_mixed_configs_are_one_line_errors(kw, message):
    with pytest.raises(LangprefError, match=message):
        LearnRewardConfig(feedback="mixed", **kw).validate()
    with pytest.raises(LangprefError, match="mixed"):
        LearnRewardConfig(feedback="spoken").validate()


def test_curves_over_modelled_seconds_are_step_functions():
    curve, seconds = [0.0, 0.5, 0.9], [0.0, 0.887, 1.887]
    at = on_time_grid(curve, seconds, [0.0, 0.5, 0.887, 1.0, 1.887, 5.0])
    np.testing.assert_allclose(at, [0, 0, 0.5, 0.5, 0.9, 0.9])
    assert time_average(curve, seconds, 1.887) == pytest.approx((0.0 * 0.887 + 0.5 * 1.0) / 1.887)
    assert time_average(curve, seconds, 1.0) == pytest.approx(0.5 * 0.113 / 1.0)
