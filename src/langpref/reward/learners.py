"""Reward learners as parts: what `--learner NAME` names, built and taught the same way by `learn-reward`, recorded
answers (`langpref.reward.recorded`) and Study 2 (`langpref.study.engine`), and saved the same way
(`langpref.reward.saved`).

A learner (`RewardLearner` of the paper, `AnswerModelLearner`) is taught answers one at a time and refit with `fit`;
`predict(phi)` is its reward of latent points. What differs between learners lives in its `LearnerType`:

- `make(space, pool, settings, seed)`: a fresh learner over the latent space, its queries drawn from `pool`;
- `teach(learner, space, kind, answer, settings, rng, meaning)`: one answer of feedback kind `kind`, read as the
  model reads it, or as `meaning` (dataset feature index, direction 0 increase / 1 decrease) when the person said
  what they meant; not fit yet;
- `saved(learner)`: (reward model kind, parameters, settings) as a saved reward holds them.

A learner from another package registers its own type (`register_learner`) or names one under the entry-point group
`langpref.learners`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import FeedbackKind
from langpref.feedback.space import LatentSpace
from langpref.reward.answer_model import AnswerModelConfig, AnswerModelLearner
from langpref.reward.learner import RewardConfig, RewardLearner

Meaning = tuple[int, int]
"""(dataset feature index, direction: 0 increase, 1 decrease)."""


class Settings(Protocol):
    """What a learner is configured by: `LearnRewardConfig` and `StudyConfig`-derived settings both carry these."""

    reward: RewardConfig
    answer_model: AnswerModelConfig


@dataclass
class LearnerSettings:
    """The settings of every built-in learner, for callers without a `LearnRewardConfig`."""

    reward: RewardConfig
    answer_model: AnswerModelConfig


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
    return AnswerModelLearner(space, pool, settings.answer_model, settings.reward.negative_split, seed=seed)


def _teach_answer_model(
    learner: AnswerModelLearner,
    space: LatentSpace,
    kind: FeedbackKind,
    answer: Any,
    settings: Settings,
    rng: np.random.Generator,
    meaning: Meaning | None = None,
) -> None:
    index = None if meaning is None else learner.meaning_index(*meaning)
    learner.observe(kind.name, answer, index)


def _saved_answer_model(learner: AnswerModelLearner) -> tuple[str, dict[str, list], dict[str, Any]]:
    """The posterior-mean reward as the linear r = xi . phi it is (up to a constant, which shifts every trajectory
    alike)."""
    return "linear", {"xi": learner.latent_weights().tolist()}, {"learner": "answer-model", **asdict(learner.cfg)}


_LEARNERS: dict[str, LearnerType] = {}


def register_learner(learner: LearnerType) -> LearnerType:
    """Make a learner known by its name (`--learner NAME`); a name already taken is an error."""
    if learner.name in _LEARNERS and _LEARNERS[learner.name] is not learner:
        raise LangprefError(f"a learner named {learner.name!r} is already registered")
    _LEARNERS[learner.name] = learner
    return learner


def _load_plugins() -> None:
    from importlib.metadata import entry_points

    for ep in entry_points(group="langpref.learners"):
        if ep.name not in _LEARNERS:
            found = ep.load()
            register_learner(found() if callable(found) and not isinstance(found, LearnerType) else found)


def learner_names() -> tuple[str, ...]:
    """Every registered learner, the built-in ones first."""
    _load_plugins()
    return tuple(_LEARNERS)


def get_learner(name: str) -> LearnerType:
    """The learner of `name`; a one-line error naming the known ones."""
    if name not in _LEARNERS:
        _load_plugins()
    if name not in _LEARNERS:
        raise LangprefError(f"unknown learner {name!r}: choose one of {', '.join(learner_names())}")
    return _LEARNERS[name]


def learner_type_of(learner: Any) -> LearnerType:
    """The registered type a learner object was made by (by its class)."""
    for t in _LEARNERS.values():
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
        "answer-model",
        AnswerModelLearner,
        _make_answer_model,
        _teach_answer_model,
        _saved_answer_model,
        "a belief over the reward; a sentence read given the trajectory it was said about",
        selections=("random", "infogain"),
    )
)
