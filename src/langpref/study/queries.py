"""Which trajectories a Study-2 query shows, by the study's query selection (`StudyConfig.query_selection`).

- `random` (the paper's, the default): language shows one pass over the study set in a random order, then another;
  comparisons show two distinct trajectories drawn afresh for every query. Both fixed by the study and participant
  seeds, as before active selection existed.
- an active strategy of `langpref.reward.selection` (`infogain`, `lal-infogain` for language; `infogain`,
  `volume-removal` for comparisons): the library's scores, over at most `query_candidates` trajectories of the study
  set drawn for the query, from the participant's reward learner fit on their answers so far (`infogain`,
  `volume-removal`: its Laplace posterior) or from their answers themselves (`lal-infogain`). The highest score is
  shown.

With the answer-model learner (`--learner answer-model`), `infogain` is that learner's own: the mutual information
between its belief and the person's answer under its answer model (`language_gains`, `comparison_gains`), from draws
of its belief made with the query's generator (never the learner's own stream, which its fits use).

Study-specific choices (the reward loop of `langpref.reward` does not make them): a language query never shows a
trajectory the participant already gave feedback on in this method while unseen ones remain (as random's pass over
the set does); the two videos of a comparison are put left and right at random (the scores are symmetric).

Every draw comes from a generator seeded by (study seed, participant seed, method, query number), never from a
stream: what query n shows depends only on the seeds and the first n - 1 answers, so a restarted server that has
rebuilt the learner from the database chooses as the running one would have. The cost is bounded by
`query_candidates` (comparisons score every pair of them): a few milliseconds per query.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from langpref.feedback.kind import get_kind
from langpref.feedback.language import LanguageAnswer
from langpref.feedback.space import LatentSpace
from langpref.reward import RewardConfig
from langpref.reward.posterior import laplace_posterior
from langpref.reward.selection import DEFAULT_SAMPLES, ComparisonActive, LalInfoGain, LanguageInfoGain, candidate_rows
from langpref.study.config import StudyConfig

ANSWER_MODEL_SAMPLES = 64
"""Draws of the answer-model learner's belief per active query (as `AnswerModelInfoGain` in `langpref.reward`)."""
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
        self.strategies = cfg.selections()
        self.answer_model = cfg.learner == "answer-model"
        # the stateless scorers, built once (the language one embeds the bank's feature axes); lal-infogain keeps a
        # record of the answers, so it is made per query; the answer-model learner scores with its own model
        language, comparison = self.strategies.get("language", "random"), self.strategies.get("comparison", "random")
        paper = not self.answer_model
        self._info = LanguageInfoGain(space, self.study, reward) if paper and language == "infogain" else None
        self._pairs = ComparisonActive(space, self.study, comparison) if paper and comparison != "random" else None

    def choose(
        self, method: str, number: int, rng: Rng, learner: Callable[[], Any], history: Callable[[], list]
    ) -> Chosen:
        """Query `number` (1-based) of `method`. `learner` gives the participant's learner fit on the first
        `number - 1` answers and `history` those answers; either is asked for only when the strategy needs it."""
        strategy = self.strategies[method]
        if strategy == "random":
            return self._random(method, number, rng)
        gen = rng(5, self.cfg.kinds.index(method), number)
        if method == "language":
            past = history()
            seen = {int(a.query.shown) for a in past}
            fresh = self.study[~np.isin(self.study, list(seen))]
            rows = candidate_rows(fresh if len(fresh) else self.study, self.cfg.query_candidates, gen)
            if strategy == "lal-infogain":
                scores = self._lal_scores(past, rows, gen)
            elif self.answer_model:
                model = learner()
                scores = model.language_gains(*model.draw(ANSWER_MODEL_SAMPLES, gen), rows)
            else:
                xi = laplace_posterior(learner()).sample(DEFAULT_SAMPLES, gen)
                scores = self._info.scores(xi, rows)
            best = int(np.argmax(scores))
            return Chosen((int(rows[best]),), strategy, float(scores[best]), len(rows))
        rows = candidate_rows(self.study, self.cfg.query_candidates, gen)
        if self.answer_model:
            model = learner()
            i, j, scores = model.comparison_gains(model.draw(ANSWER_MODEL_SAMPLES, gen)[0], rows)
        else:
            i, j, scores = self._pairs.scores(laplace_posterior(learner()).sample(DEFAULT_SAMPLES, gen), rows)
        best = int(np.argmax(scores))
        pair = (int(rows[i[best]]), int(rows[j[best]]))
        if gen.random() < 0.5:
            pair = pair[::-1]
        return Chosen(pair, strategy, float(scores[best]), len(scores))

    def _random(self, method: str, number: int, rng: Rng) -> Chosen:
        study, shows = self.study, get_kind(method).shows
        if shows == 1:
            cycle, pos = divmod(number - 1, len(study))
            return Chosen((int(rng(1, cycle).permutation(study)[pos]),), "random", None, len(study))
        shown = tuple(int(i) for i in rng(2, number).choice(study, size=shows, replace=False))
        return Chosen(shown, "random", None, len(study))

    def _lal_scores(self, past: list, rows: np.ndarray, gen: np.random.Generator) -> np.ndarray:
        """The follow-up's scores of `rows` after the answers `past` (text read with its whitespace collapsed, as
        the learner reads it)."""
        lal = LalInfoGain(self.space, self.study)
        for answer in past:
            if isinstance(answer, LanguageAnswer):
                answer = replace(answer, text=" ".join(answer.text.split()))
            lal.observe(self.space, answer)
        w, l_samples = lal.samples(gen)
        return lal.scores(w, l_samples, rows)
