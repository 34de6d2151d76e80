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

Candidates `generated` (`langpref.propose`): C grows with new trajectories made in the simulator. After each feedback,
the proposer searches the controller's parameters for rollouts maximising the step's objective (Eq. 4's cosine, or the
history strategy's learned reward) and the argmax runs over C_t = the base split (`base_split`, default test) + every
trajectory generated in this run so far + this step's new rollouts. The start and the normalisation still come from
the base split, so a normalised reward above 1 is a trajectory better than any of that split. The synthetic human's
tau* (Eq. 10) stays the best of the base split; it answers about a generated trajectory from that trajectory's
real features, which the proposer never sees.
"""

from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from langpref.dataset.splits import Split
from langpref.errors import LangprefError
from langpref.feedback.humans import HumanConfig, normalised_reward, sample_weights, true_reward
from langpref.feedback.language import LanguageHuman, LanguageQuery, language_pairs
from langpref.feedback.space import LatentSpace
from langpref.propose import GENERATED
from langpref.reward import RewardConfig, RewardLearner

Strategy = Literal["paper", "history"]
Objective = Literal["cosine", "printed"]
RECORDED = "recorded"
CandidateSplit = Literal["train", "val", "test", "generated", "recorded"]
"""A dataset split; `generated` (`langpref.propose.GENERATED`): the base split plus trajectories made in the
simulator; `recorded`: every trajectory of the dataset, whatever its split (the baseline `generated` must beat, as
the generator starts from and learns on all of them)."""
IMPROVE_STRATEGIES: tuple[str, ...] = get_args(Strategy)
OBJECTIVES: tuple[str, ...] = get_args(Objective)


@dataclass
class ImproveConfig:
    """`langpref improve`: N iterations of language feedback from a random start, over many seeds."""

    iterations: int = 15
    """N, feedback rounds per run (the paper's 15)."""
    seeds: int = 100
    """Runs (the paper's 100); each draws its own human weights w and start."""
    seed: int = 0
    """Master seed: the same seed gives the same numbers."""
    candidate_split: CandidateSplit = "test"
    """The candidate set C the argmax searches (and whose best/worst define the normalised reward); `generated`:
    the base split plus new trajectories made in the simulator (`langpref.propose`); `recorded`: every trajectory
    of the dataset."""
    base_split: Split | None = None
    """With candidates `generated` or `recorded`: the split of the start trajectory, whose best/worst define the
    normalised reward (above 1: better than any trajectory of it) and of which the synthetic human knows the best;
    None: test."""
    generated_out: str | None = None
    """With candidates `generated`: also store every generated trajectory shown as a dataset in this directory (it
    replays from its stored parameters and seed; `langpref render` makes its video)."""
    strategy: Strategy = "paper"
    """`paper` (Eq. 4, last feedback only) or `history` (reward learned from all feedback so far)."""
    objective: Objective = "cosine"
    """`paper` only: Eq. 4 as the text describes it, `cosine`: cos(phi' - phi^t, psi_l), or as printed, `printed`:
    psi_l . (phi' - phi^t) / (|phi'| |phi^t|); see the module docstring."""
    exclude_shown: bool = False
    """`history` only: never show a trajectory twice (off: once at the best, staying there is right)."""
    human: HumanConfig = field(default_factory=HumanConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)

    @property
    def generated(self) -> bool:
        return self.candidate_split == GENERATED

    @property
    def split(self) -> str:
        """The split of the start trajectory and of the normalisation."""
        return (self.base_split or "test") if self.candidate_split in (GENERATED, RECORDED) else self.candidate_split

    def validate(self) -> None:
        if self.strategy not in IMPROVE_STRATEGIES:
            raise LangprefError(f"unknown strategy {self.strategy!r}: choose one of {', '.join(IMPROVE_STRATEGIES)}")
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


def improvement_step(
    phi_candidates: np.ndarray, phi_current: np.ndarray, psi: np.ndarray, objective: str = "cosine"
) -> int:
    """Row of `phi_candidates` maximising Eq. 4 (`objective`: `cosine` or `printed`; the first one on ties)."""
    score = cosine_objective if objective == "cosine" else printed_objective
    return int(np.argmax(score(phi_candidates, phi_current, psi)))


def human_weights(num_features: int, seed: int, run: int) -> np.ndarray:
    """The reward weights of improvement run `run` of experiment seed `seed`."""
    return sample_weights(num_features, np.random.default_rng([seed, 104729, run]))


@dataclass
class ImprovementRun:
    shown: list[int]
    """Row of tau^0 ... tau^N: a dataset index, or (candidates `generated`) len(dataset) + k for the k-th
    trajectory generated in the run."""
    reward: list[float]
    """Normalised true reward of each (0 worst, 1 best of the candidate set, or of the base split)."""
    raw_reward: list[float]
    optimal_raw: float
    feedback: list[str]
    generated: list[bool] = field(default_factory=list)
    """Whether each shown trajectory was generated (candidates `generated`)."""
    step_s: list[float] = field(default_factory=list)
    """Wall time of each generation step (candidates `generated`)."""


def _objective(
    cfg: ImproveConfig,
    learner: RewardLearner | None,
    view: LatentSpace,
    phi_current: np.ndarray,
    answer,
    rng_neg: np.random.Generator,
):
    """What the next trajectory maximises after `answer`: Eq. 4 (or the printed objective) from the current
    trajectory and the sentence, or, for the history strategy, the reward refit on every answer so far."""
    if learner is None:
        score = cosine_objective if cfg.objective == "cosine" else printed_objective
        return partial(score, phi_current=phi_current, psi=view.psi_of(answer.text))
    learner.add(language_pairs(view, answer, cfg.reward, rng_neg))
    learner.fit()
    return learner.predict


def _with_room(space: LatentSpace, generation, cfg: ImproveConfig):
    """phi, theta, controller units and a latent-space view with one empty row per iteration after the dataset's,
    for candidates `generated`. Rows n.. hold the trajectories generated in a run, filled as they are shown: phi for
    the method, theta for the human (and the score). The proposer sees only phi, through the objective. Otherwise the
    dataset's own arrays."""
    if cfg.generated and generation is None:
        raise LangprefError(
            "candidates `generated` need the simulator and the dataset's controller parameters "
            "(langpref.propose.Generation)"
        )
    extra = cfg.iterations if cfg.generated else 0
    if not extra:
        return space.phi, space.theta, None, space
    phi = np.concatenate([space.phi, np.zeros((extra, space.dim))])
    theta = np.concatenate([space.theta, np.zeros((extra, space.theta.shape[1]))])
    units = np.concatenate([generation.units, np.zeros((extra, generation.units.shape[1]))])
    return phi, theta, units, replace(space, phi=phi, theta=theta)


def run_improvement(
    space: LatentSpace, w: np.ndarray, cfg: ImproveConfig, run_seed: tuple[int, ...], generation=None, store=None
) -> ImprovementRun:
    """One improvement run with the synthetic human of weights `w`. Candidates `generated` need a
    `langpref.propose.Generation` (and store the generated trajectories shown in `store`, a `GeneratedStore`)."""
    cfg.validate()
    cands = space.split(cfg.split)
    R_split = true_reward(w, space.theta[cands])
    rng_start, rng_human, rng_neg = (np.random.default_rng([*run_seed, k]) for k in (1, 2, 3))
    n, extra = len(space.phi), (cfg.iterations if cfg.generated else 0)
    phi, theta, units, view = _with_room(space, generation, cfg)
    human = LanguageHuman(
        w,
        theta,
        space.table(cfg.human.phrase_source),
        cands,
        space.feature_names,
        cfg.human.temperature,
        rng_human,
        direction=cfg.human.direction,
    )
    learner = RewardLearner(space.dim, cfg.reward, seed=int(run_seed[-1])) if cfg.strategy == "history" else None
    proposer = generation.proposer(key=(*run_seed, 52711)) if cfg.generated else None
    pool = list(range(n)) if cfg.candidate_split == RECORDED else list(cands)
    cur = int(rng_start.choice(cands))
    shown, said, step_s = [cur], [], []
    for it in range(cfg.iterations):
        answer = human.answer(LanguageQuery(cur))
        said.append(answer.text)
        objective = _objective(cfg, learner, view, phi[cur], answer, rng_neg)
        rows = np.array(pool)
        scores = objective(phi[rows])
        if learner is not None and cfg.exclude_shown and len(set(shown) & set(pool)) < len(pool):
            scores[np.isin(rows, shown)] = -np.inf
        best = int(np.argmax(scores))
        cur = int(rows[best])
        if proposer is not None:
            proposal = proposer.propose(objective, units[cur], (it,))
            step_s.append(proposal.wall_s)
            if proposal.scores[0] > scores[best]:
                cur = n + len(pool) - len(cands)
                traj = proposal.trajectories[0]
                phi[cur], theta[cur], units[cur] = proposal.phi[0], generation.theta(traj), proposal.units[0]
                pool.append(cur)
                if store is not None:
                    store.add(traj, run=[int(x) for x in run_seed], iteration=it + 1, strategy=cfg.strategy)
        shown.append(cur)
    raw = true_reward(w, theta[shown])
    return ImprovementRun(
        shown,
        normalised_reward(raw, R_split).tolist(),
        raw.tolist(),
        float(R_split.max()),
        said,
        [s >= n for s in shown] if extra else [],
        step_s,
    )


def summarise_improvement(runs: list[ImprovementRun]) -> dict:
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


def improve(space: LatentSpace, cfg: ImproveConfig, progress: bool = True, generation=None) -> dict:
    """`cfg.seeds` runs; `curve` (mean normalised true reward per iteration, iteration 0 first), `curve_std`,
    `optimal` (the mean normalised reward of the candidate set's best: 1), raw-reward versions and the config.
    Candidates `generated` need `generation` (`langpref.propose.Generation`, with its search settings) and add the
    generation steps' latency, the share of generated trajectories shown and the search settings."""
    from tqdm import tqdm

    cfg.validate()
    store = None
    if cfg.generated and cfg.generated_out:
        from langpref.propose import GeneratedStore

        store = GeneratedStore(
            cfg.generated_out,
            space.env,
            generation.horizon,
            {"source": generation.source, "command": "improve", "config": asdict(cfg)},
        )
    runs = [
        run_improvement(
            space, human_weights(len(space.feature_names), cfg.seed, s), cfg, (cfg.seed, s), generation, store
        )
        for s in tqdm(range(cfg.seeds), desc=f"improve {cfg.strategy}", disable=not progress, file=sys.stderr)
    ]
    out = {**summarise_improvement(runs), "strategy": cfg.strategy, "config": asdict(cfg), "space": space.description}
    if cfg.generated:
        out.update(generation_stats(runs), generated_out=cfg.generated_out, propose=asdict(generation.cfg))
    return out


def generation_stats(runs: list[ImprovementRun]) -> dict:
    """Latency of the generation steps (p50, p95, max, in seconds) and the share of shown trajectories generated."""
    steps = np.concatenate([r.step_s for r in runs]) if runs else np.zeros(0)
    shown = np.array([g for r in runs for g in r.generated[1:]], dtype=bool)
    return {
        "step_s_p50": float(np.percentile(steps, 50)) if len(steps) else None,
        "step_s_p95": float(np.percentile(steps, 95)) if len(steps) else None,
        "step_s_max": float(steps.max()) if len(steps) else None,
        "generated_share": float(shown.mean()) if len(shown) else 0.0,
    }


def plot_improvement(results: dict[str, dict], out: str | Path, title: str = "") -> Path:
    """Fig. 4 analogue: mean +- std of the normalised true reward per iteration, one line per result, and the
    dashed optimum."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("improvement figure")

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
    top = max([1.1] + [float(np.max(np.array(r["curve"]) + np.array(r["curve_std"]))) + 0.05 for r in results.values()])
    ax.set_ylim(-0.05, top)  # a generated trajectory may score above 1, the best of the split
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, out, dpi=120, trim=False)
