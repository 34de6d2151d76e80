"""Iterative trajectory improvement with language feedback (paper Sec. 4.2.1, Eq. 4), and a history-aware variant.

Strategy `paper` (Eq. 4): shown tau^t and feedback l^t, the next trajectory is the candidate tau' of the set C whose
difference with tau^t best aligns with psi_l "based on cosine similarity", as the paper's text puts it. Two readings:

    objective `cosine`  (default)  argmax_{tau' in C} psi_l . (phi' - phi^t) / (|psi_l| |phi' - phi^t|)
    objective `printed`            argmax_{tau' in C} psi_l . (phi' - phi^t) / (|phi'| |phi^t|)

`cosine` is the cosine similarity the text describes; `printed` is the formula as the paper prints it, which is not a
cosine of anything: its denominator favours candidates of small |phi'| whatever the feedback says. With a trained
model, whose |phi| varies, `cosine` gains clearly more (docs/results.md). Each step sees only the last feedback,
so the loop can cycle between good but non-optimal trajectories (as the paper notes).

Strategy `history`: after every feedback, fit the language reward of `langpref.reward` (L_Explicit + L_Implicit)
on *all* feedback so far and show the candidate it ranks best (optionally never one already shown). Neither
strategy reads the true reward; it is only used to score the curve.

A run starts from a trajectory of C drawn at random; the curve is the normalised true reward (0 = worst, 1 = best of
C) of tau^0 ... tau^N. `improve` averages it over seeds, each seed a new synthetic human (weights w) and start.
"""

from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.humans import HumanConfig, normalised_reward, sample_weights, true_reward
from langpref.feedback.language import LanguageHuman, LanguageQuery, language_pairs
from langpref.feedback.space import LatentSpace
from langpref.reward import RewardConfig, RewardLearner

STRATEGIES = ("paper", "history")
OBJECTIVES = ("cosine", "printed")


@dataclass
class ImproveConfig:
    """`langpref improve`: N iterations of language feedback from a random start, over many seeds."""

    iterations: int = 15
    """N, feedback rounds per run (the paper's 15)."""
    seeds: int = 100
    """Runs (the paper's 100); each draws its own human weights w and start."""
    seed: int = 0
    """Master seed: the same seed gives the same numbers."""
    candidate_split: str = "test"
    """The candidate set C the argmax searches (and whose best/worst define the normalised reward)."""
    strategy: str = "paper"
    """`paper` (Eq. 4, last feedback only) or `history` (reward learned from all feedback so far)."""
    objective: str = "cosine"
    """`paper` only: Eq. 4 as the text describes it, `cosine`: cos(phi' - phi^t, psi_l), or as printed, `printed`:
    psi_l . (phi' - phi^t) / (|phi'| |phi^t|); see the module docstring."""
    exclude_shown: bool = False
    """`history` only: never show a trajectory twice (off: once at the best, staying there is right)."""
    human: HumanConfig = field(default_factory=HumanConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)

    def validate(self) -> None:
        if self.strategy not in STRATEGIES:
            raise LangprefError(f"unknown strategy {self.strategy!r}: choose one of {', '.join(STRATEGIES)}")
        if self.objective not in OBJECTIVES:
            raise LangprefError(f"unknown objective {self.objective!r}: choose one of {', '.join(OBJECTIVES)}")
        if self.iterations < 0 or self.seeds < 1:
            raise LangprefError(f"iterations must be >= 0 and seeds >= 1, got {self.iterations} and {self.seeds}")
        self.human.validate()
        self.reward.validate()


def cosine_objective(phi_candidates: np.ndarray, phi_current: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Eq. 4 as the text describes it, for every candidate: cos(phi' - phi^t, psi_l). A candidate equal to the
    current trajectory scores 0, so the loop stays put only when no candidate moves along psi."""
    delta = np.asarray(phi_candidates, dtype=np.float64) - phi_current
    den = np.linalg.norm(delta, axis=1) * max(float(np.linalg.norm(psi)), 1e-12)
    return np.where(den > 1e-12, delta @ psi / np.maximum(den, 1e-12), 0.0)


def printed_objective(phi_candidates: np.ndarray, phi_current: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Eq. 4 as printed, for every candidate: psi_l . (phi' - phi^t) / (|phi'| |phi^t|)."""
    phi_c = np.asarray(phi_candidates, dtype=np.float64)
    num = (phi_c - phi_current) @ psi
    den = np.maximum(np.linalg.norm(phi_c, axis=1), 1e-12) * max(float(np.linalg.norm(phi_current)), 1e-12)
    return num / den


def improvement_step(phi_candidates: np.ndarray, phi_current: np.ndarray, psi: np.ndarray,
                     objective: str = "cosine") -> int:
    """Row of `phi_candidates` maximising Eq. 4 (`objective`: `cosine` or `printed`; the first one on ties)."""
    score = cosine_objective if objective == "cosine" else printed_objective
    return int(np.argmax(score(phi_candidates, phi_current, psi)))


def human_weights(num_features: int, seed: int, run: int) -> np.ndarray:
    """The reward weights of improvement run `run` of experiment seed `seed`."""
    return sample_weights(num_features, np.random.default_rng([seed, 104729, run]))


@dataclass
class ImprovementRun:
    shown: list[int]
    """Dataset index of tau^0 ... tau^N."""
    reward: list[float]
    """Normalised true reward of each (0 worst, 1 best of the candidate set)."""
    raw_reward: list[float]
    optimal_raw: float
    feedback: list[str]


def run_improvement(space: LatentSpace, w: np.ndarray, cfg: ImproveConfig, run_seed: tuple[int, ...]
                    ) -> ImprovementRun:
    """One improvement run with the synthetic human of weights `w`."""
    cfg.validate()
    cands = space.split(cfg.candidate_split)
    R = true_reward(w, space.theta)
    rng_start, rng_human, rng_neg = (np.random.default_rng([*run_seed, k]) for k in (1, 2, 3))
    human = LanguageHuman(w, space.theta, space.table(cfg.human.phrase_source), cands, space.feature_names,
                          cfg.human.temperature, rng_human)
    learner = RewardLearner(space.dim, cfg.reward, seed=int(run_seed[-1])) if cfg.strategy == "history" else None
    phi_c = space.phi[cands]
    cur = int(rng_start.choice(cands))
    shown, said = [cur], []
    for _ in range(cfg.iterations):
        answer = human.answer(LanguageQuery(cur))
        said.append(answer.text)
        if learner is None:
            cur = int(cands[improvement_step(phi_c, space.phi[cur], space.psi_of(answer.text), cfg.objective)])
        else:
            learner.add(language_pairs(space, answer, cfg.reward, rng_neg))
            learner.fit()
            scores = learner.predict(phi_c)
            if cfg.exclude_shown and len(set(shown)) < len(cands):
                scores[np.isin(cands, shown)] = -np.inf
            cur = int(cands[int(np.argmax(scores))])
        shown.append(cur)
    raw = R[shown]
    return ImprovementRun(shown, normalised_reward(raw, R[cands]).tolist(), raw.tolist(), float(R[cands].max()),
                          said)


def summarise(runs: list[ImprovementRun]) -> dict:
    curves = np.array([r.reward for r in runs])
    raw = np.array([r.raw_reward for r in runs])
    return {
        "curve": curves.mean(axis=0).tolist(),
        "curve_std": curves.std(axis=0).tolist(),
        "optimal": 1.0,
        "curve_raw": raw.mean(axis=0).tolist(),
        "curve_raw_std": raw.std(axis=0).tolist(),
        "optimal_raw": float(np.mean([r.optimal_raw for r in runs])),
        "gain": float(curves[:, -1].mean() - curves[:, 0].mean()),
        "num_runs": len(runs),
    }


def improve(space: LatentSpace, cfg: ImproveConfig, progress: bool = True) -> dict:
    """`cfg.seeds` runs; `curve` (mean normalised true reward per iteration, iteration 0 first), `curve_std`,
    `optimal` (the mean normalised reward of the candidate set's best: 1), raw-reward versions and the config."""
    from tqdm import tqdm

    cfg.validate()
    runs = [run_improvement(space, human_weights(len(space.feature_names), cfg.seed, s), cfg, (cfg.seed, s))
            for s in tqdm(range(cfg.seeds), desc=f"improve {cfg.strategy}", disable=not progress, file=sys.stderr)]
    return {**summarise(runs), "strategy": cfg.strategy, "config": asdict(cfg), "space": space.description}


def plot_improvement(results: dict[str, dict], out: str | Path, title: str = "") -> Path:
    """Fig. 4 analogue: mean +- std of the normalised true reward per iteration, one line per result, and the
    dashed optimum."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for label, res in results.items():
        mean, std = np.array(res["curve"]), np.array(res["curve_std"])
        x = np.arange(len(mean))
        ax.plot(x, mean, marker="o", ms=3, label=label)
        ax.fill_between(x, mean - std, mean + std, alpha=0.2)
    ax.axhline(1.0, ls="--", color="k", lw=1, label="optimal")
    ax.set_xlabel("iteration")
    ax.set_ylabel("normalised true reward")
    ax.set_ylim(-0.05, 1.1)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
