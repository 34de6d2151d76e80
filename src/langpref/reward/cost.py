"""What a query costs the person: modelled seconds per query of each kind, so that a learner that may ask either
kind (`--feedback mixed`) can choose by information per second, and learning curves can be drawn over the person's
time as well as over the number of queries.

The paper's measurement (Study 2, 10 participants, reward learning from either kind) is relative only: "our method
takes 11.3% less time for users to answer each query as shown in Fig. [Time per query], even though it includes the
time it took for users to type their feedback" (Sec. 5.2, User Studies, Results; App. C.2, "Response Time to Different
Feedback Types", shows the per-user times as a figure and adds that language's time varies more between users, but
prints no seconds). So the defaults are relative: a comparison costs 1.0 and a piece of language 1 - 0.113 = 0.887,
in units of one comparison's time. Set them in seconds where they were measured (the study app records `client_ms`
for every answer); only their ratio changes what a mixed learner asks.

    costs = query_costs()                              # {"language": 0.887, "comparison": 1.0}
    at = on_time_grid(curve, seconds, np.linspace(0, 30, 121))
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind, mixed_kinds
from langpref.feedback.language import PAPER_TIME_SAVING

__all__ = ["PAPER_TIME_SAVING", "elapsed", "on_time_grid", "query_costs", "time_average"]


def query_costs(given: Mapping[str, float | None] | None = None) -> dict[str, float]:
    """{kind: modelled seconds per query} of every kind a mixed learner asks and every kind in `given`: the given
    seconds, each kind's own (`FeedbackKind.seconds`, the paper's relative measurement) where None."""
    given = dict(given or {})
    names = dict.fromkeys([*mixed_kinds(), *given])
    costs = {k: float(get_kind(k).seconds if given.get(k) is None else given[k]) for k in names}
    for kind, cost in costs.items():
        if not (np.isfinite(cost) and cost > 0):
            raise LangprefError(f"the time per {kind} query must be a positive number of seconds, got {cost}")
    return costs


def elapsed(kinds: Sequence[str], costs: dict[str, float]) -> list[float]:
    """Modelled seconds after 0, 1, ..., Q queries of the given kinds (0 first)."""
    return np.concatenate([[0.0], np.cumsum([costs[k] for k in kinds])]).tolist()


def on_time_grid(curve: Sequence[float], seconds: Sequence[float], grid: np.ndarray) -> np.ndarray:
    """A curve over query counts 0..Q read at modelled times `grid`: at time t, its value after the last query
    finished by t (a step function; `seconds` are the times after 0..Q queries, non-decreasing)."""
    curve, seconds = np.asarray(curve, dtype=np.float64), np.asarray(seconds, dtype=np.float64)
    if curve.shape != seconds.shape:
        raise LangprefError(f"{len(curve)} curve values for {len(seconds)} times")
    done = seconds - 1e-9 * max(1.0, float(seconds[-1]))  # a query that ends at t (up to rounding) counts at t
    at = np.searchsorted(done, np.asarray(grid, dtype=np.float64), side="right") - 1
    return curve[np.clip(at, 0, len(curve) - 1)]


def time_average(curve: Sequence[float], seconds: Sequence[float], horizon: float) -> float:
    """The mean over modelled time 0..horizon of a curve over query counts read as a step function (`on_time_grid`):
    the area under a curve per second, as the mean over query counts is the area per query."""
    curve, seconds = np.asarray(curve, dtype=np.float64), np.asarray(seconds, dtype=np.float64)
    if not horizon > 0:
        raise LangprefError(f"the time horizon must be > 0, got {horizon}")
    starts = np.clip(seconds, 0.0, horizon)
    durations = np.diff(np.append(starts, horizon))
    return float(np.sum(curve * durations) / horizon)
