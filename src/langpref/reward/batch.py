"""Every candidate query of one active selection with its score, and how the next query, or a batch of K, is drawn
from them.

A strategy scores its candidates once (`Scored`). The next query is the best one: `pick(scored, 1)` is the argmax of
the scores (per modelled second when the candidates have costs, as a mixed learner's do). A batch of K
(`--query-batch K`; the learner is refit only after all K answers) is chosen greedily: the best first, then each next
by its score times (1 - its largest similarity to a query already in the batch), so that a batch does not ask K times
about the same thing. Batch active learning for comparisons (Biyik & Sadigh 2018; APReL's `greedy`, `medoids`,
`dpp` batch methods) has the same two parts, informativeness and diversity; this greedy penalty is ours, chosen for
being one readable line that also spans kinds.

Where a query points. Each candidate carries a direction in the latent space, anchors[pos] - anchors[neg]:

- a comparison of tau_a and tau_b: phi_a - phi_b (its answer depends on xi . (phi_a - phi_b) alone);
- a language query about tau: phi* - phi_tau, the gap from the shown trajectory to the one the person would call
  best, which is what the answer model reads (per feature axis); phi* is the strategy's guess of the best trajectory
  (for `infogain`, the mean over posterior draws of the pool's best under each draw).

Similarity is the squared cosine of two directions (their sign does not matter: (a, b) and (b, a) are one question).
So two trajectories shown for language are alike when their gaps to phi* are parallel, and a language query about tau
is close to a comparison of tau with a trajectory near tau*. A direction of length 0 (tau is phi* itself) is like
nothing. Ties of the penalised score go to the candidate least like the batch so far.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError

DIVERSITY = 1.0
"""Weight of the similarity penalty in a batch: 1 makes a query parallel to one already chosen worth nothing."""


@dataclass(frozen=True)
class Scored:
    """Candidate queries c = 0..C-1 of one selection: what each shows, its score, its cost and its direction."""

    kinds: tuple[str, ...]
    """The feedback kinds among the candidates; candidate c is of kind kinds[kind[c]]."""
    kind: np.ndarray
    """(C,) index into `kinds`."""
    first: np.ndarray
    """(C,) dataset index of the trajectory shown (language) or of the first one (comparison)."""
    second: np.ndarray
    """(C,) dataset index of a comparison's second trajectory; -1 for a query that shows one."""
    gains: np.ndarray
    """(C,) the strategy's score (nats of information for `infogain`)."""
    anchors: np.ndarray
    """(A, D) latent points the directions are differences of."""
    pos: np.ndarray
    """(C,) candidate c points along anchors[pos[c]] - anchors[neg[c]]."""
    neg: np.ndarray
    costs: np.ndarray | None = None
    """(C,) modelled seconds per candidate; None: all alike, candidates ranked by their score alone."""

    @property
    def rates(self) -> np.ndarray:
        """Score per modelled second (the score itself without costs)."""
        return self.gains if self.costs is None else self.gains / self.costs

    def query(self, c: int) -> Any:
        """The query of candidate `c`."""
        from langpref.feedback.kind import get_kind

        kind = get_kind(self.kinds[int(self.kind[c])])
        if kind.shows == 1:
            return kind.query(int(self.first[c]))
        return kind.query(int(self.first[c]), int(self.second[c]))


def shown_candidates(kind: str, rows: np.ndarray, gains: np.ndarray, phi_rows: np.ndarray, star: np.ndarray) -> Scored:
    """Queries of `kind` (one that shows one trajectory, as language does) showing each of `rows` (latent points
    `phi_rows`), pointing from it to `star` (phi*)."""
    n = len(rows)
    return Scored(
        (kind,),
        np.zeros(n, dtype=np.int64),
        np.asarray(rows, dtype=np.int64),
        np.full(n, -1, dtype=np.int64),
        np.asarray(gains, dtype=np.float64),
        np.vstack([phi_rows, star[None, :]]),
        np.full(n, n, dtype=np.int64),
        np.arange(n, dtype=np.int64),
    )


def pair_candidates(
    kind: str, rows: np.ndarray, i: np.ndarray, j: np.ndarray, gains: np.ndarray, phi_rows: np.ndarray
) -> Scored:
    """Queries of `kind` (one that shows two trajectories, as a comparison does) of rows[i] with rows[j] (positions
    into `rows`, latent points `phi_rows`)."""
    rows = np.asarray(rows, dtype=np.int64)
    return Scored(
        (kind,),
        np.zeros(len(i), dtype=np.int64),
        rows[i],
        rows[j],
        np.asarray(gains, dtype=np.float64),
        np.asarray(phi_rows, dtype=np.float64),
        np.asarray(i, dtype=np.int64),
        np.asarray(j, dtype=np.int64),
    )


def join(parts: Sequence[Scored], costs: Mapping[str, float]) -> Scored:
    """The candidates of every part as one set, each with the modelled seconds of its kind (a mixed learner)."""
    kinds = tuple(k for p in parts for k in p.kinds)
    if len(set(kinds)) != len(kinds):
        raise LangprefError(f"join needs parts of distinct kinds, got {', '.join(kinds)}")
    missing = [k for k in kinds if k not in costs]
    if missing:
        raise LangprefError(f"no time per query for feedback {', '.join(missing)}")
    offsets = np.cumsum([0] + [len(p.anchors) for p in parts[:-1]])
    shift = np.cumsum([0] + [len(p.kinds) for p in parts[:-1]])
    kind = np.concatenate([p.kind + s for p, s in zip(parts, shift)])
    return Scored(
        kinds,
        kind,
        np.concatenate([p.first for p in parts]),
        np.concatenate([p.second for p in parts]),
        np.concatenate([p.gains for p in parts]),
        np.vstack([p.anchors for p in parts]),
        np.concatenate([p.pos + o for p, o in zip(parts, offsets)]),
        np.concatenate([p.neg + o for p, o in zip(parts, offsets)]),
        np.array([float(costs[kinds[k]]) for k in kind]),
    )


def similarity_to(scored: Scored, c: int, gram: np.ndarray | None = None) -> np.ndarray:
    """(C,) squared cosine between every candidate's direction and candidate `c`'s (0 where either has length 0)."""
    g = scored.anchors @ scored.anchors.T if gram is None else gram
    p, n = scored.pos, scored.neg
    dots = g[p, p[c]] - g[p, n[c]] - g[n, p[c]] + g[n, n[c]]
    norms = g[p, p] + g[n, n] - 2.0 * g[p, n]
    denom = norms * norms[c]
    tiny = 1e-12 * max(float(np.max(norms)), 1e-300) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        cos2 = np.where(denom > tiny, dots * dots / denom, 0.0)
    return np.clip(cos2, 0.0, 1.0)


def pick(scored: Scored, k: int = 1) -> list[int]:
    """Candidates to ask, best first: the argmax of `scored.rates`, then (for a batch, k > 1) greedily by rate times
    (1 - DIVERSITY * the largest similarity to one already picked); min(k, C) distinct candidates."""
    rates = np.asarray(scored.rates, dtype=np.float64)
    if len(rates) == 0:
        raise LangprefError("no candidate query to choose from")
    chosen = [int(np.argmax(rates))]
    k = min(int(k), len(rates))
    if k == 1:
        return chosen
    quality = rates - min(0.0, float(rates.min()))  # a strategy whose scores can be negative (lal-infogain)
    gram = scored.anchors @ scored.anchors.T
    penalty = np.zeros(len(rates))
    taken = np.zeros(len(rates), dtype=bool)
    taken[chosen[0]] = True
    while len(chosen) < k:
        penalty = np.maximum(penalty, similarity_to(scored, chosen[-1], gram))
        value = np.where(taken, -np.inf, quality * (1.0 - DIVERSITY * penalty))
        ties = np.flatnonzero(value >= value.max())
        c = int(ties[np.argmin(penalty[ties])])
        chosen.append(c)
        taken[c] = True
    return chosen
