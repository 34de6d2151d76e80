"""The numbers the docs quote come from a command, and the synthetic humans' choices are options (issue 22).

`experiment reward` prints the count of query counts at which language's cross-entropy is lower, the mean CE over
1..Q, per-human curves and "queries to 0.95" read two ways; the humans' feature scale (`--feature-scale`) and Eq. 10's
direction (`--direction`) are options whose defaults leave every number as it was.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.feedback import LanguageHuman, LanguageQuery, toy_latent_space
from langpref.feedback.humans import HumanConfig
from langpref.feedback.space import load_space, paper_theta
from langpref.reward import LearnRewardConfig, learn_reward

# ---- "queries to 0.95", two readings ------------------------------------------------------------------------------


def test_queries_to_reads_first_touch_and_stays():
    from langpref.experiments.reward import queries_to

    assert queries_to([0.2, 0.96, 0.9, 0.97, 0.99]) == {"first_touch": 1, "stays": 3}
    assert queries_to([0.2, 0.5, 0.95, 0.95]) == {"first_touch": 2, "stays": 2}
    assert queries_to([0.96, 0.97]) == {"first_touch": 0, "stays": 0}
    assert queries_to([0.2, 0.96, 0.5]) == {"first_touch": 1, "stays": None}  # below at Q: it never stays
    assert queries_to([0.1, 0.2]) == {"first_touch": None, "stays": None}


def test_experiment_reward_prints_what_the_docs_quote(tmp_path, make_synthetic_dataset):
    from langpref.experiments.reward import run_ablation_experiment, run_reward_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=40)
    cfg = LearnRewardConfig(queries=5, humans=2, seeds=2)
    res = run_reward_experiment("metaworld", data, None, tmp_path / "r", perfect=True, config=cfg, progress=False)
    lang, comp = res["methods"]["language"], res["methods"]["comparison"]
    ce_l, ce_c = np.array(lang["cross_entropy"][1:]), np.array(comp["cross_entropy"][1:])
    lower, higher = int(np.sum(ce_l < ce_c)), int(np.sum(ce_l > ce_c))
    assert res["ce_language_lower"] == {"lower": lower, "higher": higher, "of": 5}
    runs = json.loads((tmp_path / "r" / "runs.json").read_text())["runs"]
    for name, m in res["methods"].items():
        assert m["mean_cross_entropy_1_to_q"] == pytest.approx(np.mean(m["cross_entropy"][1:]))
        assert m["queries_to_0.95_first_touch"] == m["queries_to_0.95"]  # the old key keeps its reading
        best = np.array(m["true_reward_of_best"])
        above = [q for q in range(len(best)) if (best[q:] >= 0.95).all()]
        assert m["queries_to_0.95_stays"] == (above[0] if above else None)
        assert set(m["per_human"]) == {"0", "1"}
        for h, curves in m["per_human"].items():  # each human's curve is the mean of its own seeds' runs
            own = np.array([runs[f"{name}/{h}/{s}"]["cross_entropy"] for s in range(2)])
            np.testing.assert_allclose(curves["cross_entropy"], own.mean(axis=0))
        np.testing.assert_allclose(
            np.mean([c["true_reward_of_best"] for c in m["per_human"].values()], axis=0), m["true_reward_of_best"]
        )  # equal seeds per human: the mean of the humans
    md = (tmp_path / "r" / "reward.md").read_text()
    assert f"language lower than comparisons at {lower} of 5 query counts" in md
    assert "mean CE 1..Q" in md and "queries to 0.95 (stays)" in md and "| language | " in md
    assert "Per synthetic human" in md and "human 1" in md
    saved = json.loads((tmp_path / "r" / "reward.json").read_text())
    assert saved["ce_language_lower"] == res["ce_language_lower"] and "per_human" in saved["methods"]["language"]
    abl = run_ablation_experiment("metaworld", data, None, tmp_path / "a", perfect=True, config=cfg, progress=False)
    assert "per_human" in abl["methods"]["both"] and "mean CE 1..Q" in (tmp_path / "a" / "ablation.md").read_text()


# ---- the humans' feature scale ------------------------------------------------------------------------------------


def test_paper_theta_is_the_sum_of_the_raw_step_features(tmp_path, make_synthetic_dataset):
    from langpref.dataset.storage import load_dataset

    data = make_synthetic_dataset(tmp_path / "d", n=12, horizon=20)
    ds = load_dataset(data)
    sums = np.stack([ds.load(i).step_features.astype(np.float64).sum(axis=0) for i in range(len(ds))])
    np.testing.assert_allclose(paper_theta(ds), sums, rtol=1e-12, atol=1e-9)
    std = load_space(data, perfect=True)
    paper = load_space(data, perfect=True, feature_scale="paper")
    np.testing.assert_allclose(paper.theta, sums, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(paper.phi, std.phi)  # the methods' view is the same
    assert "paper scale" in paper.description and "paper scale" not in std.description
    np.testing.assert_array_equal(load_space(data, perfect=True, feature_scale="standardised").theta, std.theta)
    with pytest.raises(LangprefError, match="feature scale"):
        load_space(data, perfect=True, feature_scale="summed")


def test_the_default_scale_and_direction_change_no_number(tmp_path, make_synthetic_dataset):
    data = make_synthetic_dataset(tmp_path / "d", n=30)
    space = load_space(data, perfect=True)
    cfg = LearnRewardConfig(queries=4, humans=2, seeds=1)
    explicit = replace(cfg, human=HumanConfig(feature_scale="standardised", direction="reward"))
    for fb in ("language", "comparison"):
        a = learn_reward(space, replace(cfg, feedback=fb), progress=False)
        b = learn_reward(
            load_space(data, perfect=True, feature_scale="standardised"), replace(explicit, feedback=fb), progress=False
        )
        assert a["cross_entropy"] == b["cross_entropy"] and a["true_reward_of_best"] == b["true_reward_of_best"]
    paper = learn_reward(
        load_space(data, perfect=True, feature_scale="paper"),
        replace(cfg, feedback="comparison", human=HumanConfig(feature_scale="paper")),
        progress=False,
    )
    assert (
        paper["cross_entropy"]
        != learn_reward(space, replace(cfg, feedback="comparison"), progress=False)["cross_entropy"]
    )


def test_cli_takes_the_scale_and_direction_and_names_the_output(tmp_path, make_synthetic_dataset, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    data = make_synthetic_dataset(tmp_path / "d", n=30)
    assert (
        main(
            [
                "learn-reward",
                "--data",
                str(data),
                "--perfect-latent",
                "--feedback",
                "comparison",
                "--queries",
                "2",
                "--humans",
                "1",
                "--seeds",
                "1",
                "--feature-scale",
                "paper",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["config"]["human"]["feature_scale"] == "paper" and "paper scale" in out["space"]
    assert (
        main(
            [
                "experiment",
                "reward",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--queries",
                "2",
                "--humans",
                "1",
                "--seeds",
                "1",
                "--feature-scale",
                "paper",
                "--direction",
                "toward-best",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["command"].endswith("--feature-scale paper --direction toward-best")
    assert (tmp_path / "results" / "reward" / "metaworld-perfect-paper-scale-toward-best" / "reward.json").is_file()
    with pytest.raises(SystemExit) as exc:
        main(
            [
                "learn-reward",
                "--data",
                str(data),
                "--perfect-latent",
                "--feedback",
                "language",
                "--feature-scale",
                "raw",
            ]
        )
    assert exc.value.code == 2


def test_both_humans_are_near_noiseless_on_the_paper_scale(tmp_path, make_synthetic_dataset):
    from langpref.feedback.comparison import ComparisonHuman
    from langpref.reward import human_weights

    data = make_synthetic_dataset(tmp_path / "d", n=30, horizon=200)
    std, paper = load_space(data, perfect=True), load_space(data, perfect=True, feature_scale="paper")
    w = human_weights(len(std.feature_names), 0, 0)

    def certainty(space):
        human = ComparisonHuman(w, space.theta)
        p = np.array([human.probability(a, b) for a in range(10) for b in range(10) if a != b])
        return float(np.mean(np.abs(p - 0.5)))

    assert certainty(paper) > certainty(std)


# ---- Eq. 10's direction -------------------------------------------------------------------------------------------


def test_direction_rules():
    space = toy_latent_space("metaworld", n=20, seed=0)
    w = np.array([1.0, -1.0, 0.5])
    cands = space.split("test")
    rule = {
        r: LanguageHuman(w, space.theta, space.table("test"), cands, space.feature_names, seed=0, direction=r)
        for r in ("reward", "toward-best")
    }
    best = rule["reward"].best
    for shown in range(len(space.theta)):
        for f in range(3):
            assert rule["reward"].direction(f, shown) == (0 if w[f] >= 0 else 1)
            gap = space.theta[best, f] - space.theta[shown, f]
            assert rule["toward-best"].direction(f, shown) == (
                (0 if gap > 0 else 1) if gap else rule["reward"].direction(f)
            )
    # some shown trajectory has a feature on the far side of tau*: there the two rules disagree
    assert any(
        rule["reward"].direction(f, s) != rule["toward-best"].direction(f, s)
        for s in range(len(space.theta))
        for f in range(3)
    )
    with pytest.raises(LangprefError, match="direction"):
        LanguageHuman(w, space.theta, space.table("test"), cands, space.feature_names, direction="up")
    with pytest.raises(LangprefError, match="direction"):
        HumanConfig(direction="up").validate()
    answer = rule["toward-best"].answer(LanguageQuery(0))
    assert answer.direction in ("increase", "decrease")


def test_improve_and_learn_reward_hand_the_direction_to_their_human(monkeypatch):
    import langpref.feedback.language as language_module
    import langpref.improve as improve_module
    from langpref.improve import ImproveConfig, improve

    space = toy_latent_space("metaworld", n=20, seed=0)
    seen = []
    for module in (improve_module, language_module):
        real = module.LanguageHuman

        def spy(*a, real=real, **k):
            seen.append(k.get("direction", "reward"))
            return real(*a, **k)

        monkeypatch.setattr(module, "LanguageHuman", spy)
    human = HumanConfig(direction="toward-best")
    improve(space, ImproveConfig(iterations=1, seeds=1, human=human), progress=False)
    learn_reward(space, LearnRewardConfig(queries=1, humans=1, seeds=1, human=human), progress=False)
    assert seen == ["toward-best", "toward-best"]


# ---- the L2 prior is chosen without the test split --------------------------------------------------------------


def test_the_prior_experiment_speaks_val_phrasings_only(tmp_path, make_synthetic_dataset, monkeypatch):
    import langpref.reward as reward_module
    from langpref.experiments.prior import run_prior_experiment

    data = make_synthetic_dataset(tmp_path / "d", n=40)
    spoken = []
    real = reward_module.run_reward_learning

    def spy(space, w, cfg, run_seed, record=None):
        spoken.append((cfg.human.phrase_source, cfg.eval_split))
        return real(space, w, cfg, run_seed, record)

    monkeypatch.setattr(reward_module, "run_reward_learning", spy)
    res = run_prior_experiment(
        "metaworld",
        data,
        None,
        tmp_path / "p",
        perfect=True,
        config=LearnRewardConfig(queries=2, humans=1, seeds=1),
        progress=False,
        grid=(1.0,),
    )
    assert spoken and set(spoken) == {("val", "val")}
    assert res["phrasings"] == "val" and "speaking val phrasings" in (tmp_path / "p" / "prior.md").read_text()
    assert (tmp_path / "p" / "prior.json").is_file()
