"""How long a person waits for the next active query: the learner's update and the choice of the next query, at
study sizes (`python -m benchmarks.pipeline` writes the table into docs/results.md). Benchmark code: outside the
package, so the wheel holds none of it."""

from __future__ import annotations

import os
import time

import numpy as np


def selection_timings(
    env_name: str, answers: int = 40, candidates: int = 300, trials: int = 30, dim: int = 128
) -> dict:
    """Active query selection with `answers` answers so far and `candidates` candidate trajectories (comparisons:
    every pair of them), in a toy latent space of D = `dim` (no dataset or model needed: the cost depends only on
    the sizes): the Laplace posterior at the fit, its draws and the scores. Milliseconds per trial, (median, p95)."""
    from langpref.feedback import get_kind, random_query, sample_weights, toy_latent_space
    from langpref.feedback.humans import HumanConfig
    from langpref.reward import RewardConfig, RewardLearner
    from langpref.reward.selection import make_selector
    from langpref.study.server.serve import limit_blas_threads

    limit_blas_threads(1)  # as `langpref study serve` runs it (one BLAS thread per request)

    space = toy_latent_space(env_name, n=int(candidates / 0.6) + 2, dim=dim, seed=0)
    pool = space.split("train")[:candidates]
    cfg = RewardConfig()
    times: dict[str, list[float]] = {}
    for kind_name, strategies in (
        ("language", ("infogain", "lal-infogain")),
        ("comparison", ("infogain", "volume-removal")),
    ):
        kind = get_kind(kind_name)
        rng = np.random.default_rng([7, len(kind_name)])
        human = kind.make_human(sample_weights(len(space.feature_names), rng), space, pool, HumanConfig(), rng)
        learner = RewardLearner(space.dim, cfg)
        history = [human.answer(random_query(kind, pool, rng)) for _ in range(answers)]
        for answer in history:
            learner.add(kind.pairs(space, answer, cfg, rng))
        learner.fit()
        for strategy in strategies:
            selector = make_selector(strategy, kind, space, pool, cfg)
            for answer in history:
                selector.observe(space, answer)
            key = f"{kind_name} {strategy}"
            times[key] = []
            for trial in range(trials):
                start = time.perf_counter()
                selector.select(learner, np.random.default_rng(trial))
                times[key].append(1e3 * (time.perf_counter() - start))
        times[f"{kind_name} infogain, answer-model learner: update + selection"] = answer_model_timings(
            space, pool, kind_name, history, human, rng, trials
        )
    return {k: (float(np.median(v)), float(np.percentile(v, 95))) for k, v in times.items()}


def answer_model_timings(space, pool, kind_name: str, history: list, human, rng, trials: int) -> list[float]:
    """Milliseconds per trial of the answer-model learner taking one more answer after `history` (`observe` +
    `fit`, including a resample-move when its belief needs one) and choosing the next query of `kind_name`."""
    import copy

    from langpref.feedback import random_query
    from langpref.feedback.kind import get_kind
    from langpref.reward.answer_model import AnswerModelInfoGain, AnswerModelLearner

    learner = AnswerModelLearner(space, pool, seed=0)
    for answer in history:
        learner.observe(kind_name, answer)
        learner.fit()
    selector = AnswerModelInfoGain(space, pool, (kind_name,))
    out = []
    for trial in range(trials):
        trial_learner = copy.deepcopy(learner)
        answer = human.answer(random_query(get_kind(kind_name), pool, rng))
        start = time.perf_counter()
        trial_learner.observe(kind_name, answer)
        trial_learner.fit()
        selector.select(trial_learner, np.random.default_rng(trial))
        out.append(1e3 * (time.perf_counter() - start))
    return out


def selection_table(envs: list[str], today: str, answers: int = 40, candidates: int = 300, trials: int = 30) -> str:
    """The markdown table of `selection_timings` per env (`trials` per strategy), with how it was measured."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    lines = [
        f"Measured {today} with `python -m benchmarks.pipeline` (`benchmarks.selection`), {cores} CPU cores, "
        f"{trials} trials: choosing the next query with {answers} answers so far and {candidates} candidate "
        f"trajectories (comparisons: all {candidates * (candidates - 1) // 2} pairs), D = 128, 64 posterior draws "
        "(lal-infogain: its own 10 x 100), one BLAS thread as the study server runs it. Includes the Laplace "
        "posterior at the fit; not the refit itself (see the reward update above). Target: p95 < 100 ms.\n",
        "| env | strategy | median (ms) | p95 (ms) |",
        "|---|---|---|---|",
    ]
    for env_name in envs:
        for what, (med, p95) in selection_timings(env_name, answers, candidates, trials).items():
            lines.append(f"| {env_name} | {what} | {med:.1f} | {p95:.1f} |")
    return "\n".join(lines)
