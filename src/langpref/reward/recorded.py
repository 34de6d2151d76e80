"""Rewards from recorded answers of real people (`langpref learn-reward --answers FILE`): no synthetic human, no
hidden reward; each answer is taught to the learner in the order it was given, as Study 2 teaches it
(`langpref.reward.learners`), and the learned r_xi is what the lab takes to its policy (`--save-reward`).

One reward per participant by default; one participant's (`participant`), or one over everybody's answers
(`pooled`). The answers of the kinds the learner is asked to learn from (`LearnRewardConfig.feedback`: one kind, or
`mixed` for language and comparisons in one learner) are taught; the others are counted and left out. Every random
choice (the learner's start, the paper learner's implicit negatives) is drawn from `LearnRewardConfig.seed`, the
group's name and the answer's position, so the same file and seed give the same reward.
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.answers import RecordedAnswer
from langpref.feedback.kind import MIXED, asked_kinds, get_kind
from langpref.feedback.space import LatentSpace
from langpref.language.bank import DIRECTIONS
from langpref.reward.learners import get_learner
from langpref.reward.loop import LearnRewardConfig

POOLED = "pooled"


@dataclass
class LearnedFrom:
    """A reward learned from one group of answers: its name (the participant, or `pooled`), the learner after the
    group's last answer, and what it was taught."""

    name: str
    learner: Any
    answers: int
    participants: tuple[str, ...]


def groups(
    answers: Sequence[RecordedAnswer], participant: str | None = None, pooled: bool = False
) -> dict[str, list[RecordedAnswer]]:
    """name -> answers, in file order: one group per participant, the one `participant`, or all `pooled`."""
    if participant is not None:
        chosen = [a for a in answers if a.participant == participant]
        if not chosen:
            names = sorted({a.participant for a in answers})
            raise LangprefError(
                f"no answers of participant {participant!r}; the file has {', '.join(names[:8])}"
                + (" ..." if len(names) > 8 else "")
            )
        return {participant: chosen}
    if pooled:
        return {POOLED: list(answers)}
    out: dict[str, list[RecordedAnswer]] = {}
    for a in answers:
        out.setdefault(a.participant, []).append(a)
    return out


def learn_group(
    space: LatentSpace,
    name: str,
    answers: Sequence[RecordedAnswer],
    cfg: LearnRewardConfig,
    pool: np.ndarray | None = None,
) -> LearnedFrom:
    """The learner of `cfg.learner` taught `answers` one by one, refit after each (module docstring), over the
    trajectories `pool` (default `cfg.query_split`'s: where the answer-model learner looks for the best one)."""
    learner_type = get_learner(cfg.learner)
    pool = space.split(cfg.query_split) if pool is None else pool
    key = zlib.crc32(name.encode("utf-8"))
    learner = learner_type.make(space, pool, cfg, int(np.random.default_rng([cfg.seed, key]).integers(2**31)))
    features = list(space.feature_names)
    for i, a in enumerate(answers):
        meaning = None if a.meaning is None else (features.index(a.meaning[0]), DIRECTIONS.index(a.meaning[1]))
        rng = np.random.default_rng([cfg.seed, key, 4, i])
        learner_type.teach(learner, space, get_kind(a.kind), a.answer, cfg, rng, meaning)
        learner.fit()
    return LearnedFrom(name, learner, len(answers), tuple(dict.fromkeys(a.participant for a in answers)))


def learn_from_answers(
    space: LatentSpace,
    answers: Sequence[RecordedAnswer],
    cfg: LearnRewardConfig,
    participant: str | None = None,
    pooled: bool = False,
) -> tuple[list[LearnedFrom], int]:
    """A reward per group of `answers` (`groups`) of the kinds `cfg.feedback` learns from; and how many answers of
    other kinds were left out. A one-line error when no answer of those kinds is left."""
    kinds = asked_kinds(cfg.feedback)
    taught = [a for a in answers if a.kind in kinds]
    if not taught:
        found = sorted({a.kind for a in answers})
        raise LangprefError(
            f"no {' or '.join(kinds)} answers among the {len(answers)} recorded ({', '.join(found)}); "
            f"pass --feedback {found[0] if len(found) == 1 else MIXED}"
        )
    learned = [learn_group(space, name, group, cfg) for name, group in groups(taught, participant, pooled).items()]
    return learned, len(answers) - len(taught)


def in_task(answers: Sequence[RecordedAnswer], task: str) -> tuple[list[RecordedAnswer], int]:
    """The answers without the sentences about something the task does not measure (`langpref.language.scope`,
    unless the person confirmed a meaning), and how many were left out: a learner would read them as one of the
    task's features, which the person never asked for."""
    from langpref.language.relevance import FeedbackGate

    said = [a for a in answers if isinstance(getattr(a.answer, "text", None), str)]  # answers that are sentences
    sentences = [a for a in said if a.meaning is None and not getattr(a.answer, "no_change", False)]
    if not sentences:
        return list(answers), 0
    gate = FeedbackGate(task)
    outside = {id(a) for a in sentences if (s := gate.scope(a.answer.text)) is not None and s.outside}
    return [a for a in answers if id(a) not in outside], len(outside)


def file_name(name: str) -> str:
    """A participant's name as the NAME of reward-NAME.json (letters, digits, `-`, `_`, `.`)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "participant"
    return safe[:80]


def rewards_from_answers(
    answers_file: str | Path,
    data: str | Path,
    model: str | Path,
    cfg: LearnRewardConfig,
    participant: str | None,
    pooled: bool,
    save_to: str | Path | None,
    open_space: Callable[[], LatentSpace],
) -> dict[str, Any]:
    """`learn-reward --answers`: the answers of `answers_file` read against the dataset `data` (before the model is
    opened: a bad file costs no model load), a reward per group learned in the space `open_space()` gives, each
    described by what it wants and, with `save_to`, saved for `langpref.reward.load`."""
    from langpref.dataset.storage import load_dataset
    from langpref.feedback.answers import read_answers
    from langpref.reward.saved import check_saveable, save_learned_reward
    from langpref.reward.wants import describe, what_it_wants

    if save_to is not None:
        check_saveable(model)
    dataset = load_dataset(data)
    answers = read_answers(answers_file, len(dataset), dataset.feature_names, dataset.episode_names)
    answers, outside = in_task(answers, dataset.env)
    space = open_space()
    learned, skipped = learn_from_answers(space, answers, cfg, participant, pooled)
    rewards = []
    for i, group in enumerate(learned):
        wants = what_it_wants(group.learner.predict(space.phi), space.theta, space.feature_names)
        entry = {"name": group.name, "answers": group.answers, "participants": list(group.participants)}
        entry |= {"wants": wants, "summary": describe(wants)}
        if save_to is not None:
            source = {"answers": str(Path(answers_file).resolve()), "group": group.name, "num_answers": group.answers}
            extra = {"learned_from": {**source, "participants": list(group.participants)}}
            path = save_learned_reward(
                group.learner,
                save_to,
                env=space.env,
                model=model,
                name=file_name(group.name),
                default=i == 0,
                space=space,
                extra=extra,
            )
            entry["path"] = str(path)
        rewards.append(entry)
    out = {"answers": len(answers) + outside, "left_out": skipped, "out_of_task": outside}
    out |= {"feedback": cfg.feedback, "learner": cfg.learner}
    return {**out, "rewards": rewards, **({"save_reward": str(save_to)} if save_to is not None else {})}
