"""Language feedback (paper Eq. 5-10): one trajectory shown, a comparative sentence back ("Move faster.").

Human (Eq. 10). Shown tau^0, with tau* the best trajectory of its candidate set under w, it samples a feature f from
softmax(w (.) (theta*_f - theta0_f) / temperature), says the direction that raises its reward (`increase` when
w_f >= 0; with `direction="toward-best"`, the direction that takes theta0_f toward theta*_f), and picks a phrasing
of that feature and direction uniformly from one split of the bank (default `test`, phrasings the model never trained
on). The paper's Eq. 10 has no temperature (temperature 1).

Likelihood. Feedback l about tau becomes Bradley-Terry pairs on the frozen embeddings: the imagined improvement
phi + psi_l beats phi (L_Explicit, Eq. 7), and beats phi + psi_l~ for k other utterances l~ of the robot's own pool
(L_Implicit, Eq. 9). The pool is a split of the bank (default `train`, the phrasings the model was trained on); by
default the negatives are drawn among pool utterances of *other meanings* than the one the model reads l as (nearest
meaning prototype by cosine: the model's reading, never the synthetic human's label), so a paraphrase of l is never
a negative. Of L_Explicit + L_Implicit, an answer weighs 2 (its explicit pair, and k implicit pairs of weight 1/k);
of either alone, 1.

A synthetic human also records *why* it answered (the feature and direction it meant). Those fields are ground truth
for analysis only: no learning method reads them (a real participant's answers leave them `None`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.bradley_terry import PairBatch
from langpref.feedback.humans import DIRECTION_RULES, FEATURE_RULES, HumanConfig, Seed, rng_of, softmax, true_reward
from langpref.feedback.kind import FeedbackKind, StudyPage, register_kind
from langpref.feedback.space import LatentSpace, PhraseTable
from langpref.language.bank import DIRECTIONS, NO_CHANGE_FEEDBACK, VAGUE_FEEDBACK, is_no_change

PAPER_TIME_SAVING = 0.113
"""Language's time per query is 11.3% below that of comparisons (paper Sec. 5.2): its modelled `seconds`."""


class PairSettings(Protocol):
    """What the language kind's likelihood (`language_pairs`) reads of the learner's settings: which terms of Eq. 9
    it fits, and how L_Implicit draws its negatives. The reward learner's config has these fields and is what it
    passes; the kind names them here, so that it needs nothing of the reward side."""

    @property
    def loss(self) -> str:
        """`both` (L_Explicit + L_Implicit), `explicit` or `implicit`."""

    @property
    def num_negatives(self) -> int:
        """k, other utterances per answer for L_Implicit."""

    @property
    def negatives(self) -> str:
        """`other_meaning` (of another meaning than the model's reading of the answer) or `any` (another text)."""

    @property
    def negative_split(self) -> str:
        """The bank split the negatives are drawn from."""


MAX_FEEDBACK = 500
"""Longest feedback a study participant may send, in characters."""
MAX_FEEDBACK_RAW = 2 * MAX_FEEDBACK
"""Longest feedback text taken before it is trimmed (the request's text is stored as sent)."""


@dataclass(frozen=True)
class LanguageQuery:
    """Show one trajectory and ask how it should change."""

    shown: int
    """Dataset index of the trajectory shown."""


@dataclass(frozen=True)
class LanguageAnswer:
    """Comparative language feedback about the shown trajectory, e.g. "Move faster."."""

    query: LanguageQuery
    text: str
    feature: str | None = None
    """What a synthetic human meant (ground truth; never read by a method). `None` for a real participant."""
    direction: str | None = None
    """`increase` or `decrease`, what a synthetic human meant; `None` for a real participant."""

    def __post_init__(self) -> None:
        if not self.text.strip():
            raise LangprefError("language feedback is empty; give a sentence such as 'Move faster.'")

    @property
    def no_change(self) -> bool:
        """ "That's good, no change" (the text `NO_CHANGE_FEEDBACK`, a button in the study, or that phrase as typed:
        `is_no_change`): the shown trajectory is as the person wants it. The answer-model learner reads it as its own
        meaning; Eq. 9 learns nothing from it."""
        return is_no_change(self.text)


class LanguageHuman:
    """Answers language queries about trajectories with Eq. 10, relative to the best of its candidate set."""

    def __init__(
        self,
        w: np.ndarray,
        theta: np.ndarray,
        phrases: PhraseTable,
        candidates: Sequence[int],
        feature_names: Sequence[str],
        temperature: float = 1.0,
        seed: Seed = 0,
        direction: str = "reward",
        feature_rule: str = "eq10",
        vague: float = 0.0,
        no_change_logit: float | None = None,
        no_change_margin: float | None = None,
    ):
        self.w = np.asarray(w, dtype=np.float64)
        self.theta = np.asarray(theta, dtype=np.float64)
        if self.theta.shape[1] != len(self.w):
            raise LangprefError(f"{len(self.w)} weights for {self.theta.shape[1]} features")
        if not temperature > 0:
            raise LangprefError(f"the language human's temperature must be > 0, got {temperature}")
        self.phrases = phrases
        self.feature_names = tuple(feature_names)
        self.temperature = float(temperature)
        if direction not in DIRECTION_RULES:
            raise LangprefError(f"unknown direction rule {direction!r}: choose one of {', '.join(DIRECTION_RULES)}")
        self.direction_rule = direction
        if feature_rule not in FEATURE_RULES:
            raise LangprefError(f"unknown feature rule {feature_rule!r}: choose one of {', '.join(FEATURE_RULES)}")
        self.feature_rule = feature_rule
        self.vague = float(vague)
        self.no_change_logit = None if no_change_logit is None else float(no_change_logit)
        cands = np.asarray(candidates, dtype=np.int64)
        rewards = true_reward(self.w, self.theta[cands])
        self.best = int(cands[np.argmax(rewards)])
        """tau*, the best trajectory of the candidate set under w."""
        self.good_enough = (
            None if no_change_margin is None else float(rewards.max() - no_change_margin * np.ptp(rewards))
        )
        """With a no-change margin, the true reward from which the human says "no change" (else None)."""
        self.rng = rng_of(seed)

    def feature_probabilities(self, shown: int) -> np.ndarray:
        """softmax(w (.) (theta* - theta0) / temperature) over the features (Eq. 10)."""
        return softmax(self.w * (self.theta[self.best] - self.theta[shown]) / self.temperature)

    def direction(self, feature: int, shown: int | None = None) -> int:
        """The direction (0 increase, 1 decrease) of `feature` that raises the reward; with the `toward-best` rule
        and the `shown` trajectory, the one that takes theta0_f toward theta*_f (the reward's when they are equal)."""
        if self.direction_rule == "toward-best" and shown is not None:
            gap = self.theta[self.best, feature] - self.theta[shown, feature]
            if gap != 0:
                return 0 if gap > 0 else 1
        return 0 if self.w[feature] >= 0 else 1

    def no_change_probability(self, shown: int) -> float:
        """P("that's good, no change" | shown): 0 for the paper's human (`no_change_logit` None); 0 or 1 under a
        no-change margin."""
        if self.good_enough is not None:
            return float(true_reward(self.w, self.theta[shown]) >= self.good_enough)
        if self.no_change_logit is None:
            return 0.0
        if self.feature_rule == "largest-change":
            return float(shown == self.best)
        logits = self.w * (self.theta[self.best] - self.theta[shown]) / self.temperature
        return float(softmax(np.append(logits, self.no_change_logit))[-1])

    def answer(self, query: LanguageQuery) -> LanguageAnswer:
        if self.vague > 0 and self.rng.random() < self.vague:  # draws nothing for the default human
            return LanguageAnswer(query, VAGUE_FEEDBACK[int(self.rng.integers(len(VAGUE_FEEDBACK)))])
        if self.good_enough is not None and self.no_change_probability(query.shown):  # a threshold: draws nothing
            return LanguageAnswer(query, NO_CHANGE_FEEDBACK)
        if self.no_change_logit is not None and self.rng.random() < self.no_change_probability(query.shown):
            return LanguageAnswer(query, NO_CHANGE_FEEDBACK)
        if self.feature_rule == "largest-change":
            gap = self.theta[self.best] - self.theta[query.shown]
            feature = int(np.argmax(np.abs(gap)))
            direction = 0 if gap[feature] > 0 or (gap[feature] == 0 and self.w[feature] >= 0) else 1
        else:  # (given it named a feature, Eq. 10's softmax over features is the same with or without "no change")
            feature = int(self.rng.choice(len(self.w), p=self.feature_probabilities(query.shown)))
            direction = self.direction(feature, query.shown)
        rows = self.phrases.rows(feature, direction)
        if len(rows) == 0:
            raise LangprefError(
                f"the phrasings this human speaks from have none of {self.feature_names[feature]}/"
                f"{DIRECTIONS[direction]}"
            )
        row = int(rows[self.rng.integers(len(rows))])
        return LanguageAnswer(query, self.phrases.texts[row], self.feature_names[feature], DIRECTIONS[direction])


def make_human(
    w: np.ndarray, space: LatentSpace, candidates: Sequence[int], cfg: HumanConfig, rng: np.random.Generator
) -> LanguageHuman:
    """The Eq. 10 human speaking the phrasings `cfg` names, tau* the best of `candidates`."""
    return LanguageHuman(
        w,
        space.theta,
        space.table(cfg.phrase_source),
        candidates,
        space.feature_names,
        cfg.temperature,
        rng,
        direction=cfg.direction,
        feature_rule=cfg.feature_rule,
        vague=cfg.vague,
        no_change_logit=cfg.no_change_logit,
        no_change_margin=cfg.no_change_margin,
    )


# ---- likelihood -----------------------------------------------------------------------------------------------


def _prototypes(psi: np.ndarray, group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    groups = np.unique(group)
    protos = np.stack([psi[group == g].mean(axis=0) for g in groups])
    return groups, protos / np.maximum(np.linalg.norm(protos, axis=1, keepdims=True), 1e-12)


def read_meaning(space: LatentSpace, psi: np.ndarray, split: str = "train") -> int:
    """The meaning (2 * feature + direction) whose mean psi in `split` is closest in cosine to `psi`."""
    table = space.table(split)
    groups, protos = _prototypes(table.psi, table.group)
    return int(groups[np.argmax(protos @ (psi / max(float(np.linalg.norm(psi)), 1e-12)))])


def language_pairs(
    space: LatentSpace,
    answer: LanguageAnswer,
    cfg: PairSettings,
    rng: np.random.Generator,
    psi: np.ndarray | None = None,
) -> PairBatch:
    """Explicit and implicit pairs of one piece of language feedback (no ground-truth label is read); `psi`, when
    given, stands for the sentence's embedding (a study participant's confirmed meaning)."""
    phi = space.phi[answer.query.shown]
    if answer.no_change:  # Eq. 9 compares imagined improvements; "no change" names none
        empty = np.zeros((0, len(phi)))
        return PairBatch(empty, empty, np.zeros(0))
    psi = space.psi_of(answer.text) if psi is None else np.asarray(psi)
    hat = phi + psi
    winners, losers, weights = [], [], []
    if cfg.loss in ("both", "explicit"):
        winners.append(hat)
        losers.append(phi)
        weights.append(1.0)
    if cfg.loss in ("both", "implicit"):
        pool = space.table(cfg.negative_split)
        if cfg.negatives == "other_meaning":
            allowed = np.flatnonzero(pool.group != read_meaning(space, psi, cfg.negative_split))
        else:
            allowed = np.array([i for i, t in enumerate(pool.texts) if t != answer.text], dtype=np.int64)
        if len(allowed) == 0:
            raise LangprefError(f"bank split {cfg.negative_split!r} has no utterance to use as an implicit negative")
        chosen = rng.choice(allowed, size=min(cfg.num_negatives, len(allowed)), replace=False)
        for j in chosen:
            winners.append(hat)
            losers.append(phi + pool.psi[j])
            weights.append(1.0 / len(chosen))
    return PairBatch(np.array(winners), np.array(losers), np.array(weights))


# ---- over HTTP and in the study database ----------------------------------------------------------------------


def parse(value: Any, query: LanguageQuery) -> LanguageAnswer:
    """The body's `feedback`: text, trimmed, not empty, at most MAX_FEEDBACK characters (and at most
    MAX_FEEDBACK_RAW before trimming: the answer body stores the text as sent); or `{"no_change": true}`, "that's
    good, no change" (stored as the text `NO_CHANGE_FEEDBACK`, which also means it when typed, in any case, with a
    typographic apostrophe or without its full stop: `is_no_change`; it is then stored as that text too)."""
    if isinstance(value, dict) and list(value) == ["no_change"] and value["no_change"] is True:
        return LanguageAnswer(query, NO_CHANGE_FEEDBACK)
    if not isinstance(value, str):
        raise LangprefError("'feedback' must be text, or {\"no_change\": true} when the trajectory is good as it is")
    if len(value) > MAX_FEEDBACK_RAW:
        raise LangprefError(f"Your feedback is {len(value)} characters long; please keep it under {MAX_FEEDBACK}.")
    text = value.strip()
    if not text:
        raise LangprefError('Please type your feedback before continuing (for example: "Move faster.").')
    if len(text) > MAX_FEEDBACK:
        raise LangprefError(f"Your feedback is {len(text)} characters long; please keep it under {MAX_FEEDBACK}.")
    return LanguageAnswer(query, NO_CHANGE_FEEDBACK if is_no_change(text) else text)


def to_record(answer: LanguageAnswer) -> dict[str, Any]:
    return {"shown": answer.query.shown, "text": answer.text}


def from_record(row: Mapping[str, Any]) -> LanguageAnswer:
    return LanguageAnswer(LanguageQuery(int(row["shown"])), row["text"])


def to_line(answer: LanguageAnswer) -> dict[str, Any]:
    """A language answer's fields in an answers file: `shown`, and `text` or `"no_change": true`."""
    return {"shown": int(answer.query.shown), **({"no_change": True} if answer.no_change else {"text": answer.text})}


def from_line(obj: dict[str, Any], where: str, resolve: Callable[[Any, str], int]) -> LanguageAnswer:
    """A language answer of an answers file: `shown` (index or episode name) and `text`, or `"no_change": true`."""
    query = LanguageQuery(resolve(obj.get("shown"), where))
    if obj.get("no_change") is True:
        return LanguageAnswer(query, NO_CHANGE_FEEDBACK)
    text = obj.get("text")
    if not isinstance(text, str) or not text.strip():
        raise LangprefError(f"{where}: a language answer needs 'text' (what was said) or \"no_change\": true")
    if len(text) > MAX_FEEDBACK:
        raise LangprefError(f"{where}: 'text' is {len(text)} characters; at most {MAX_FEEDBACK}")
    return LanguageAnswer(query, " ".join(text.split()))


LANGUAGE = register_kind(
    FeedbackKind(
        name="language",
        query=LanguageQuery,
        answer=LanguageAnswer,
        shows=1,
        make_human=make_human,
        pairs=language_pairs,
        answer_key="feedback",
        parse=parse,
        value=lambda answer: answer.text,
        table="feedback",
        to_record=to_record,
        from_record=from_record,
        from_line=from_line,
        to_line=to_line,
        seconds=1.0 - PAPER_TIME_SAVING,
        says_no_change=True,
        sentence="text",
        mixed=True,
        page=StudyPage(
            widget="text",
            label="Language feedback",
            prompt="How should the robot move differently?",
            intro="Each query shows one trajectory. Type how the robot should move differently, as in Experiment 1. "
            "The robot does not change this trajectory: it learns what you prefer.",
        ),
    )
)
