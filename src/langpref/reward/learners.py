"""Reward learners as parts: what `--learner NAME` names, built and taught the same way by `learn-reward`, recorded
answers (`langpref.reward.recorded`) and Study 2 (`langpref.study.session.engine`), and saved the same way
(`langpref.reward.saved`).

A learner (`RewardLearner` of the paper, `AnswerModelLearner`) is taught answers one at a time and refit with `fit`;
`predict(phi)` is its reward of latent points. What differs between learners lives in its `LearnerType`:

- `make(space, pool, settings, seed)`: a fresh learner over the latent space, its queries drawn from `pool`;
- `teach(learner, space, kind, answer, settings, rng, meaning)`: one answer of feedback kind `kind`, read as the
  model reads it, or as `meaning` (dataset feature index, direction 0 increase / 1 decrease) when the person said
  what they meant; not fit yet;
- `saved(learner)`: (reward model kind, parameters, settings) as a saved reward holds them;
- what else is its own: the config field it reads (`own_config`), its check of a run's config (`check`), the kinds it
  can read (`reads`), its active query selection in `learn-reward` (`selector`) and in the study (`scores`), asking a
  person to confirm what they meant (`confirm`), a check of its belief after a run (`credible`), and whether a caller
  that teaches it one answer at a time fits it after each (`fits_each_answer`).

No caller compares a learner's name: each asks its type.

A learner from another package registers its own type (`register_learner`) or names one under the entry-point group
`langpref.learners`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import MIXED, FeedbackKind, asked_kinds, get_kind
from langpref.feedback.space import LatentSpace
from langpref.registry import Registry
from langpref.reward import answer_model as am
from langpref.reward import readings
from langpref.reward.answer_model import AnswerModelConfig, AnswerModelInfoGain, AnswerModelLearner
from langpref.reward.learner import RewardConfig, RewardLearner

Meaning = tuple[int, int]
"""(dataset feature index, direction: 0 increase, 1 decrease)."""


class Settings(Protocol):
    """What a learner is configured by: `LearnRewardConfig` and `StudyConfig`-derived settings both carry these."""

    reward: RewardConfig
    answer_model: AnswerModelConfig
    spoken_phrasings: str | None
    """The phrase table of the space the person speaks from (a synthetic human's), None for real people: a learner
    fits nothing on the sentences it will be told."""


@dataclass
class LearnerSettings:
    """The settings of every built-in learner, for callers without a `LearnRewardConfig`."""

    reward: RewardConfig
    answer_model: AnswerModelConfig
    spoken_phrasings: str | None = None


@dataclass(frozen=True)
class LearnerType:
    """One learner: how it is made, taught and saved (module docstring)."""

    name: str
    cls: type
    """The class of the learners it makes (how a learner object is told apart)."""
    make: Callable[[LatentSpace, np.ndarray, Settings, int], Any]
    teach: Callable[..., None]
    saved: Callable[[Any], tuple[str, dict[str, list], dict[str, Any]]]
    description: str = ""
    selections: tuple[str, ...] | None = ("random",)
    """The query selections it can ask with (`--query-selection`; an active one reads its posterior); None: all."""
    own_config: str | None = None
    """The field of the settings that holds its own config (`answer_model`), recorded with its results only."""
    check: Callable[[Any], None] | None = None
    """(a run's config: `feedback`, its own config) -> None, or a one-line LangprefError."""
    reads: Callable[[str], bool] = lambda kind: True
    """Whether it can learn from answers of feedback `kind`."""
    selector: Callable[[Any, LatentSpace, np.ndarray], Any] | None = None
    """(a run's config, space, pool) -> the selector of its active query selection (None: random); None: each kind's
    own strategies (`langpref.reward.selection`), or `mixed`'s."""
    scores: Callable[[Any, str, np.ndarray, np.random.Generator, int], Any] | None = None
    """(learner, kind, rows, rng, draws) -> Study 2's candidate queries scored by the learner itself; None: by the
    kind's selector."""
    confirm: Callable[[Any, FeedbackKind, Any, float], tuple[bool, Meaning | None] | None] | None = None
    """(learner, kind, answer, margin) -> (asked, the meaning clicked or None for "none of these"), or None where it
    never asks about that kind: a person asked what they meant when the learner is unsure (`--confirm-margin`).
    None: it never asks."""
    credible: Callable[[Any, np.ndarray], bool] | None = None
    """(learner, true weights w) -> whether w lies in its belief's credible region (a calibration check)."""
    feature_weights: Callable[[Any, LatentSpace], dict[str, float]] | None = None
    """(learner, space) -> its reward's weight per task feature, where it has them (the study export's)."""
    fits_each_answer: bool = False
    """Whether a caller that teaches it answers one at a time (Study 2, replays included) fits it after each: its
    belief depends on when it is fit (the answer-model learner resamples); False: one fit after the last is the same
    (Eq. 9's convex loss)."""


def meaning_psi(space: LatentSpace, split: str, meaning: Meaning) -> np.ndarray:
    """psi of a meaning: the mean psi of the bank split's phrasings of (feature, direction); minus the opposite
    direction's mean when the bank has none of this one."""
    table = space.table(split)
    feature, direction = int(meaning[0]), int(meaning[1])
    rows, other = table.rows(feature, direction), table.rows(feature, 1 - direction)
    if len(rows):
        return table.psi[rows].mean(axis=0)
    if len(other):
        return -table.psi[other].mean(axis=0)
    raise LangprefError(f"feature {space.feature_names[feature]!r} has no phrasings in the bank's {split} split")


# ---- the paper's learner (Eq. 5-9, Eq. 11) ------------------------------------------------------------------------


def _make_paper(space: LatentSpace, pool: np.ndarray, settings: Settings, seed: int) -> RewardLearner:
    return RewardLearner(space.dim, settings.reward, seed=seed)


def _teach_paper(
    learner: RewardLearner,
    space: LatentSpace,
    kind: FeedbackKind,
    answer: Any,
    settings: Settings,
    rng: np.random.Generator,
    meaning: Meaning | None = None,
) -> None:
    """The answer's Bradley-Terry pairs; a said meaning replaces psi of the sentence by the meaning's mean psi."""
    extra = {} if meaning is None else {"psi": meaning_psi(space, settings.reward.negative_split, meaning)}
    learner.add(kind.pairs(space, answer, settings.reward, rng, **extra))


def _saved_paper(learner: RewardLearner) -> tuple[str, dict[str, list], dict[str, Any]]:
    kind = learner.cfg.model
    values = [p.detach().cpu().numpy().astype(np.float64).tolist() for p in learner.params]
    params = dict(zip(("xi",) if kind == "linear" else ("w1", "b1", "w2"), values))
    return kind, params, dict(vars(learner.cfg))


# ---- the answer-model learner -------------------------------------------------------------------------------------


def _make_answer_model(space: LatentSpace, pool: np.ndarray, settings: Settings, seed: int) -> AnswerModelLearner:
    return AnswerModelLearner(
        space, pool, settings.answer_model, settings.reward.negative_split, seed, settings.spoken_phrasings
    )


def _teach_answer_model(learner: AnswerModelLearner, *lesson: Any, meaning: Meaning | None = None) -> None:
    """`LearnerType.teach` of the answer model: `lesson` is (space, kind, answer, settings, rng[, meaning]); it reads
    the answer itself (settings and rng are the paper's learner's), a said meaning as its own meaning index."""
    _, kind, answer, *rest = lesson
    said = rest[2] if len(rest) > 2 else meaning
    learner.observe(kind.name, answer, None if said is None else learner.meaning_index(*said))


def _saved_answer_model(learner: AnswerModelLearner) -> tuple[str, dict[str, list], dict[str, Any]]:
    """The posterior-mean reward as the linear r = xi . phi it is (up to a constant, which shifts every trajectory
    alike)."""
    return "linear", {"xi": learner.latent_weights().tolist()}, {"learner": readings.NAME, **asdict(learner.cfg)}


def _reads_answer_model(kind: str) -> bool:
    return readings.NAME in get_kind(kind).readings


def _check_answer_model(cfg: Any) -> None:
    """Its own config, and feedback of kinds it reads."""
    cfg.answer_model.validate()
    unread = [k for k in asked_kinds(cfg.feedback) if not _reads_answer_model(k)]
    if unread:
        read = " and ".join(readings.read_kinds())
        raise LangprefError(f"the answer-model learner takes {read}, not {cfg.feedback!r}")


def _answer_model_selector(cfg: Any, space: LatentSpace, pool: np.ndarray) -> AnswerModelInfoGain | None:
    """`infogain` under its own answer model (None for `random`: the loop draws uniformly)."""
    from langpref.reward.selection import DEFAULT_SAMPLES

    if cfg.selection == "random":
        return None
    samples = DEFAULT_SAMPLES if cfg.posterior_samples is None else cfg.posterior_samples
    return AnswerModelInfoGain(space, pool, asked_kinds(cfg.feedback), cfg.costs, cfg.candidates, samples)


def _answer_model_scores(learner: AnswerModelLearner, kind: str, rows: np.ndarray, rng: np.random.Generator, n: int):
    """Study 2's candidates `rows` of `kind`, scored under the learner's answer model from `n` draws of its belief."""
    v, best = learner.draw(n, rng)
    return readings.reading_of(kind).candidates(learner, v, best, rows, learner.space.phi[rows])


def _confirm_answer_model(
    learner: AnswerModelLearner, kind: FeedbackKind, answer: Any, margin: float
) -> tuple[bool, Meaning | None] | None:
    """`answer_model.confirm` for a kind whose reading can be confirmed, its meaning as (feature, direction)."""
    if not readings.reading_of(kind).confirmable:
        return None
    asked, meaning = am.confirm(learner, answer, margin)
    if not asked or meaning is None:
        return asked, None
    return True, (int(learner.features[meaning // 2]), meaning % 2)


def _answer_model_feature_weights(learner: AnswerModelLearner, space: LatentSpace) -> dict[str, float]:
    """The posterior mean v per feature: its belief is over the bank's feature axes."""
    return {space.feature_names[int(f)]: float(x) for f, x in zip(learner.features, learner.mean())}


def paper_selector(cfg: Any, space: LatentSpace, pool: np.ndarray):
    """The paper's learner's active strategy of `cfg` (None for random: the loop draws uniformly): each kind's own
    (`langpref.reward.selection.make_selector`), or `mixed`'s information per second."""
    from langpref.reward.selection import DEFAULT_SAMPLES, make_selector

    if cfg.feedback == MIXED:  # the config's check has seen the strategy (infogain) and the linear reward
        from langpref.reward.mixed import MixedInfoGain

        samples = DEFAULT_SAMPLES if cfg.posterior_samples is None else cfg.posterior_samples
        return MixedInfoGain(space, pool, cfg.reward, cfg.costs, cfg.candidates, samples)
    kind = get_kind(cfg.feedback)
    return make_selector(cfg.selection, kind, space, pool, cfg.reward, cfg.candidates, cfg.posterior_samples)


REGISTRY: Registry[LearnerType] = Registry("learner", LearnerType, "langpref.learners")
"""The learners (`langpref.registry`), `--learner NAME`; the built-in ones first."""
register_learner = REGISTRY.register
learner_names = REGISTRY.names
get_learner = REGISTRY.get


def learner_type_of(learner: Any) -> LearnerType:
    """The registered type a learner object was made by (by its class)."""
    for t in REGISTRY.items.values():
        if isinstance(learner, t.cls):
            return t
    raise LangprefError(f"{type(learner).__name__} is not a learner of a registered type")


register_learner(
    LearnerType(
        "paper",
        RewardLearner,
        _make_paper,
        _teach_paper,
        _saved_paper,
        "Eq. 9: Bradley-Terry pairs on phi, refit on all answers",
        selections=None,
    )
)
register_learner(
    LearnerType(
        readings.NAME,
        AnswerModelLearner,
        _make_answer_model,
        _teach_answer_model,
        _saved_answer_model,
        "a belief over the reward; a sentence read given the trajectory it was said about",
        selections=("random", "infogain"),
        own_config="answer_model",
        check=_check_answer_model,
        reads=_reads_answer_model,
        selector=_answer_model_selector,
        scores=_answer_model_scores,
        confirm=_confirm_answer_model,
        credible=lambda learner, w: learner.credible(np.asarray(w)[learner.features]),
        feature_weights=_answer_model_feature_weights,
        fits_each_answer=True,
    )
)
