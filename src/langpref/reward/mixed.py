"""Several kinds in one learner (`learn-reward --feedback mixed`): at every query, the kind (language or comparison,
and any kind registered with `FeedbackKind.mixed`) and the item with the most expected information per expected
second of the person's time.

One candidate set of trajectories per query (the query split, or `candidates` of it drawn afresh), one set of draws xi
from the Laplace posterior of the one learner that fits every answer, and on them each kind's `infogain` score (its
selector's `scored`, `langpref.reward.selection`): for language, I(xi; answer | tau) under the latent Eq. 10 answer
model, over every trajectory; for comparisons, I(xi; choice) under Bradley-Terry, over every pair. Both are mutual
information in nats between the reward and the person's answer, from the same draws, so they are on one scale. Each is
divided by its kind's modelled seconds per query (`langpref.reward.cost`: by default the paper's measurement, language
11.3% faster than comparisons) and the best rate is asked, of whichever kind. Equal information goes to the cheaper
kind; equal costs to the more informative query. A batch (`--query-batch K`) mixes kinds too (`langpref.reward.batch`).

The answers go into the same learner whatever their kind (`langpref.reward.RewardLearner`): each kind's `pairs`
turns an answer into weighted Bradley-Terry pairs, and the fit is their weighted mean loss plus the prior. In
simulation a language query is answered by the Eq. 10 human and a comparison by the Eq. 11 human, both with the same
true reward w, each drawing from the stream its kind's own runs use: a mixed run that only ever asks one kind is that
kind's `infogain` run, answer for answer, so paired differences against the single kinds show only what mixing
changed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import MIXED, get_kind, mixed_kinds
from langpref.reward.batch import Scored, join
from langpref.reward.posterior import laplace_posterior
from langpref.reward.selection import DEFAULT_SAMPLES, Selector, candidate_rows, selector_factories

if TYPE_CHECKING:
    from langpref.feedback.space import LatentSpace
    from langpref.reward import RewardConfig, RewardLearner

__all__ = ["MIXED", "MixedInfoGain"]


class MixedInfoGain(Selector):
    """`infogain` over the queries of every mixed kind (`mixed_kinds`) at once, ranked by nats per modelled second."""

    name = "infogain"

    def __init__(
        self,
        space: LatentSpace,
        pool: Sequence[int],
        reward: RewardConfig,
        costs: Mapping[str, float],
        candidates: int | None = None,
        samples: int = DEFAULT_SAMPLES,
    ):
        self.pool = np.asarray(pool, dtype=np.int64)
        self.candidates = candidates
        self.samples = int(samples)
        self.costs = dict(costs)
        # each kind's `infogain` selector; only its `scored` is used, on this selector's candidates and draws
        self.selectors = {k: _infogain(k)(space, pool, reward, candidates, self.samples) for k in mixed_kinds()}

    def score(self, learner: RewardLearner, rng: np.random.Generator) -> Scored:
        rows = candidate_rows(self.pool, self.candidates, rng)
        xi = laplace_posterior(learner).sample(self.samples, rng)
        return join([s.scored(xi, rows) for s in self.selectors.values()], self.costs)


def _infogain(name: str):
    """The factory of kind `name`'s `infogain` selector; a one-line error when it has none."""
    factory = selector_factories(get_kind(name)).get("infogain")
    if factory is None:
        raise LangprefError(f"feedback {name!r} is mixed but has no infogain query selection to be scored by")
    return factory
