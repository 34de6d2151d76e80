"""Which trajectories a Study-2 query shows, by the study's query selection (`StudyConfig.query_selection`).

- `random` (the paper's, the default): a kind whose query shows one trajectory (language) shows one pass over the
  study set in a random order, then another; one that shows several (comparisons) shows distinct trajectories drawn
  afresh for every query. Both fixed by the study and participant seeds, as before active selection existed.
- an active strategy: the kind's own (`FeedbackKind.strategies`: `infogain`, `lal-infogain` for language;
  `infogain`, `volume-removal` for comparisons; any a plugin kind brings), whose selector scores at most
  `query_candidates` trajectories of the study set drawn for the query (`Selector.score_rows`), from the
  participant's reward learner fit on their answers so far (`infogain`, `volume-removal`: its Laplace posterior) or
  from their answers themselves (`lal-infogain`, a selector that `observes`). The highest score is shown.

A learner that scores queries itself (`LearnerType.scores`; the answer-model learner, `--learner answer-model`) has
its `infogain` its own: the mutual information between its belief and the person's answer under its answer model
(the kind's reading, `langpref.reward.answer_model.reading_of`), from draws of its belief made with the query's
generator (never the learner's own stream, which its fits use).

Study-specific choices (the reward loop of `langpref.reward` does not make them): a query that shows one trajectory
never shows one the participant already gave feedback on in this method while unseen ones remain (as random's pass
over the set does); the videos of a query that shows two are put left and right at random (the scores are
symmetric). The answers a strategy observes are as the learner reads them (the engine's `as_read`).

Every draw comes from a generator seeded by (study seed, participant seed, method, query number), never from a
stream: what query n shows depends only on the seeds and the first n - 1 answers, so a restarted server that has
rebuilt the learner from the database chooses as the running one would have. The cost is bounded by
`query_candidates` (comparisons score every pair of them): a few milliseconds per query.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import RANDOM, get_kind, shown_by
from langpref.feedback.space import LatentSpace
from langpref.reward import RewardConfig
from langpref.reward.batch import Scored
from langpref.reward.learners import get_learner
from langpref.reward.selection import DEFAULT_SAMPLES, Selector, candidate_rows, selector_factories
from langpref.study.protocol.config import StudyConfig

ANSWER_MODEL_SAMPLES = 64
"""Draws of a learner's belief per active query it scores itself (as `AnswerModelInfoGain` in `langpref.reward`)."""
Rng = Callable[..., np.random.Generator]
"""(*keys) -> a generator seeded by the study seed, the participant's seed and `keys`."""


@dataclass(frozen=True)
class Chosen:
    """What a query shows and why: the strategy, the shown query's score (None for `random`) and how many
    trajectories (language) or pairs (comparisons) were scored."""

    shown: tuple[int, ...]
    strategy: str
    score: float | None
    candidates: int

    def record(self) -> dict[str, Any]:
        """As stored in the step's payload (`flow.Step.selection`) and the `queries` table."""
        return {"strategy": self.strategy, "score": self.score, "candidates": self.candidates}


class QueryChooser:
    """The query selection of a study over its set `study` (dataset rows) in latent space `space`."""

    def __init__(self, space: LatentSpace, study: Sequence[int], cfg: StudyConfig, reward: RewardConfig):
        self.space = space
        self.study = np.asarray(study, dtype=np.int64)
        self.cfg = cfg
        self.reward = reward
        self.strategies = cfg.selections()
        self.own_scores = get_learner(cfg.learner).scores
        # each active method's selector, built once (language's infogain embeds the bank's feature axes); one that
        # keeps a record of the answers is made again per query; a learner that scores queries uses its own model
        active = [m for m, s in self.strategies.items() if s != RANDOM]
        self._selectors = {} if self.own_scores is not None else {m: self._selector(m) for m in active}

    def _selector(self, method: str) -> Selector:
        """The selector of `method`'s strategy (`langpref.reward.selection.selector_factories`)."""
        strategy = self.strategies[method]
        selector = selector_factories(get_kind(method))[strategy](
            self.space, self.study, self.reward, self.cfg.query_candidates, DEFAULT_SAMPLES
        )
        if type(selector).score_rows is Selector.score_rows:
            raise LangprefError(
                f"--query-selection {method}={strategy}: its selector cannot score the study's candidates "
                "(Selector.score_rows); ask it at random"
            )
        return selector

    def choose(
        self, method: str, number: int, rng: Rng, learner: Callable[[], Any], history: Callable[[], list]
    ) -> Chosen:
        """Query `number` (1-based) of `method`. `learner` gives the participant's learner fit on the first
        `number - 1` answers and `history` those answers; either is asked for only when the strategy needs it."""
        strategy = self.strategies[method]
        if strategy == RANDOM:
            return self._random(method, number, rng)
        gen = rng(5, self.cfg.kinds.index(method), number)
        selector = self._selectors.get(method)
        one = get_kind(method).shows == 1
        past = history() if one or (selector is not None and selector.observes) else []
        rows = candidate_rows(self._unseen(past) if one else self.study, self.cfg.query_candidates, gen)
        scored = self._scored(method, selector, rows, gen, learner, past)
        best = int(np.argmax(scored.gains))
        shown = (int(scored.first[best]),)
        if scored.second[best] >= 0:
            shown = (*shown, int(scored.second[best]))
            if gen.random() < 0.5:
                shown = shown[::-1]
        return Chosen(shown, strategy, float(scored.gains[best]), len(scored.gains))

    def _unseen(self, past: list) -> np.ndarray:
        """The study set less the trajectories the answers `past` were about (all of it once none is left)."""
        seen = [i for answer in past for i in shown_by(answer.query)]
        fresh = self.study[~np.isin(self.study, seen)]
        return fresh if len(fresh) else self.study

    def _scored(
        self,
        method: str,
        selector: Selector | None,
        rows: np.ndarray,
        gen: np.random.Generator,
        learner: Callable[[], Any],
        past: list,
    ) -> Scored:
        """`method`'s queries over `rows`, scored by the learner itself (`LearnerType.scores`) or by the kind's
        selector."""
        if self.own_scores is not None:
            return self.own_scores(learner(), method, rows, gen, ANSWER_MODEL_SAMPLES)
        assert selector is not None  # every active method has one (__init__)
        if selector.observes:  # a record of this participant's answers
            selector = self._selector(method)
            for answer in past:
                selector.observe(self.space, answer)
        return selector.score_rows(learner() if selector.reads_learner else None, rows, gen)

    def _random(self, method: str, number: int, rng: Rng) -> Chosen:
        study, shows = self.study, get_kind(method).shows
        if shows == 1:
            cycle, pos = divmod(number - 1, len(study))
            return Chosen((int(rng(1, cycle).permutation(study)[pos]),), "random", None, len(study))
        shown = tuple(int(i) for i in rng(2, number).choice(study, size=shows, replace=False))
        return Chosen(shown, "random", None, len(study))
