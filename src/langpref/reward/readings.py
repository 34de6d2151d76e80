"""How the answer-model learner (`langpref.reward.answer_model`) reads each kind of feedback: an `AnswerKind` per
kind, kept in the kind's own `FeedbackKind.readings` under the learner's name, so the learner reads any kind that
brings one (a plugin kind's too) and no table here lists kinds. The paper's two kinds' readings are registered at the
bottom, from the reward side, so `langpref.feedback` imports nothing of `langpref.reward`.

- language: what is kept is (shown trajectory, P(meaning | sentence)); its likelihood is sum_m P(m | l) P(m | v, tau)
  (the learner's `meaning_probabilities`), and a person may be asked to confirm the reading (`confirmable`);
- comparison: (winner, loser), Bradley-Terry on the belief's reward.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import KINDS, FeedbackKind, get_kind, kind_names, paper_first
from langpref.feedback.space import LatentSpace
from langpref.reward.batch import Scored, pair_candidates, shown_candidates


class Learner(Protocol):
    """What a reading may use of the answer-model learner (`langpref.reward.answer_model.AnswerModelLearner`, which
    reads the readings: named here, so that they need nothing of its module). A plugin kind's reading has these."""

    space: LatentSpace
    pool: np.ndarray
    """The dataset indices the learner asks about; a particle's tau* is a position in it."""
    z: np.ndarray
    """(N, F) every trajectory's latent features along the learner's axes, standardised over the pool."""
    cfg: Any
    """The learner's settings (`AnswerModelConfig`: `comparison_rationality`, the temperatures, ...)."""

    @property
    def num_features(self) -> int:
        """F: the answer model has 2F meanings of a feature and a direction, and "no change" after them."""

    @property
    def no_change(self) -> int:
        """The index of the meaning "that's good, no change"."""

    def reading(self, text: str) -> np.ndarray:
        """P(m | text) over the 2F meanings."""

    def meaning_probabilities(self, v: np.ndarray, best: np.ndarray, shown: np.ndarray) -> np.ndarray:
        """(n, C, 2F + 1) P(m | v_s, tau_c) for particles v with optima `best` and trajectories `shown`."""

    def language_gains(self, v: np.ndarray, best: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """I(v; reading | tau) in nats for each of `rows`."""

    def comparison_gains(self, v: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, I(v; choice) in nats) over the pairs i < j of `rows`."""


NAME = "answer-model"
"""The learner's name (`--learner answer-model`), and its key in a kind's `FeedbackKind.readings`."""


@dataclass(frozen=True)
class AnswerKind:
    """How the answer-model learner reads one kind of feedback: what it keeps of an answer (`record`, after the
    kind's name), the log-likelihood of what it kept under each particle, and the candidate queries it scores."""

    record: Callable[[Learner, Any, int | None], tuple]
    log_likelihood: Callable[[Learner, np.ndarray, np.ndarray, tuple], np.ndarray]
    candidates: Callable[[Learner, np.ndarray, np.ndarray, np.ndarray, np.ndarray], Scored]
    confirmable: bool = False
    """Whether the person can be asked to confirm the learner's reading of an answer (`confirm`)."""


def _record_language(learner: Learner, answer: Any, meaning: int | None) -> tuple:
    """(shown trajectory, P(m | answer) over the 2F + 1 meanings); a confirmed meaning replaces the reading, and "no
    change" is its own meaning (a sentence is never read as it)."""
    reading = np.zeros(2 * learner.num_features + 1)
    if answer.no_change:
        reading[learner.no_change] = 1.0
    elif meaning is None:
        reading[:-1] = learner.reading(answer.text)
    else:
        reading[int(meaning)] = 1.0
    return int(answer.query.shown), reading


def _language_log_likelihood(learner: Learner, v: np.ndarray, best: np.ndarray, rec: tuple) -> np.ndarray:
    """log sum_m P(m | l) P(m | v, tau): the sentence about the shown trajectory, under each particle."""
    _, shown, reading = rec
    p = learner.meaning_probabilities(v, best, np.array([shown]))[:, 0, :]
    return np.log(np.maximum(p @ reading, 1e-300))


def _language_candidates(learner: Learner, v, best, rows, phi) -> Scored:
    star = learner.space.phi[learner.pool[best]].mean(axis=0)
    return shown_candidates("language", rows, learner.language_gains(v, best, rows), phi, star)


def _record_comparison(learner: Learner, answer: Any, meaning: int | None) -> tuple:
    """(winner, loser)."""
    q = answer.query
    return int(answer.preferred), int(q.a if answer.preferred == q.b else q.b)


def _comparison_log_likelihood(learner: Learner, v: np.ndarray, best: np.ndarray, rec: tuple) -> np.ndarray:
    """Bradley-Terry: log sigmoid(beta v . (z_winner - z_loser))."""
    _, winner, loser = rec
    margin = learner.cfg.comparison_rationality * (v @ (learner.z[winner] - learner.z[loser]))
    return -np.logaddexp(0.0, -margin)


def _comparison_candidates(learner: Learner, v, best, rows, phi) -> Scored:
    return pair_candidates("comparison", rows, *learner.comparison_gains(v, rows), phi)


def register_reading(kind: str, reading: AnswerKind) -> None:
    """Teach the learner to read feedback `kind`: `reading` becomes the kind's `readings[NAME]`. The paper's kinds'
    are registered here (so `langpref.feedback` imports nothing of `langpref.reward`); a kind of another package puts
    its own in `FeedbackKind.readings`."""
    get_kind(kind).readings[NAME] = reading


def reading_of(kind: str | FeedbackKind) -> AnswerKind:
    """How the learner reads `kind` (the kind's `readings[NAME]`); a one-line error naming the kinds it reads."""
    if isinstance(kind, str):
        kind_names()  # loads the plugin kinds
    known = KINDS.get(kind) if isinstance(kind, str) else kind
    found = known.readings.get(NAME) if known is not None else None
    if found is None:
        name = kind.name if isinstance(kind, FeedbackKind) else kind
        raise LangprefError(f"the answer-model learner takes {' and '.join(read_kinds())} feedback, not {name!r}")
    return found


def read_kinds() -> tuple[str, ...]:
    """Every registered kind the learner can read (a plugin kind's too), the paper's first."""
    return paper_first([name for name in kind_names() if NAME in KINDS[name].readings])


register_reading("language", AnswerKind(_record_language, _language_log_likelihood, _language_candidates, True))
register_reading("comparison", AnswerKind(_record_comparison, _comparison_log_likelihood, _comparison_candidates))
