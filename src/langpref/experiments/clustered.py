"""Intervals for paired differences that share their synthetic humans: a cluster bootstrap with the human as the unit.

`experiment verdict` pairs two methods run by run over several trained models, each run with the same synthetic
humans (human h of one model is human h of every other: same master seed, same weights) and the same run seeds. Its
pairs are therefore not independent: the three models agree on a human far more than independent runs would, and the
seeds of one human share that human. Counting 3 models x 10 humans x 3 seeds as 90 independent pairs makes an
interval about sqrt(90 / 10) = 3 times too narrow when the human decides most of a difference.

Here the pairs sit in a grid of cells (model, human), each holding that human's seeds. A draw resamples the humans
with replacement (and, for `humans-models`, the models too, independently: the two are crossed, every model meeting
every human, as in Owen's pigeonhole bootstrap) and keeps every seed of a chosen cell, so whatever the seeds and the
models share with their human travels with it. The statistic is the mean over the drawn pairs (a cell drawn twice
counts twice); the interval is the percentile interval of that mean over the draws. Resampling the models as well
asks how the difference would come out on other trained models, the honest question with three of them; with one
model it is the cluster bootstrap over humans alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError


@dataclass(frozen=True)
class CellGrid:
    """Paired differences summed per (model, human) cell, with how many pairs (seeds) each cell holds."""

    models: tuple[str, ...]
    humans: tuple[str, ...]
    sums: np.ndarray
    """[model, human]: the sum of the cell's differences (0 for an empty cell)."""
    counts: np.ndarray
    """[model, human]: the number of pairs in the cell."""


def cell_grid(per_model: dict[str, dict[str, float]]) -> CellGrid:
    """The grid of `{model: {"HUMAN/SEED": difference}}`: humans are matched across models by their id (the part of
    the key before the first `/`), so human 3 of every model is one cluster."""
    models = tuple(per_model)
    humans = tuple(sorted({k.split("/", 1)[0] for d in per_model.values() for k in d}, key=_natural))
    where = {h: j for j, h in enumerate(humans)}
    sums = np.zeros((len(models), len(humans)))
    counts = np.zeros((len(models), len(humans)))
    for i, m in enumerate(models):
        for key, value in per_model[m].items():
            j = where[key.split("/", 1)[0]]
            sums[i, j] += value
            counts[i, j] += 1
    if counts.sum() == 0:
        raise LangprefError("no paired run to put an interval on")
    return CellGrid(models, humans, sums, counts)


def _natural(text: str) -> tuple:
    """Humans in numeric order when their ids are numbers ("2" before "10"), else in text order."""
    return (0, int(text), "") if text.isdigit() else (1, 0, text)


def _multiplicities(rng: np.random.Generator, draws: int, size: int) -> np.ndarray:
    """[draw, item]: how often each of `size` items is drawn in a resample of `size` with replacement."""
    picks = rng.integers(0, size, (draws, size))
    out = np.zeros((draws, size))
    np.add.at(out, (np.arange(draws)[:, None], picks), 1.0)
    return out


def cluster_bootstrap(
    grid: CellGrid, *, resample_models: bool, draws: int = 10000, seed: int = 0, confidence: float = 0.95
) -> dict[str, Any]:
    """Mean of the paired differences with the percentile interval of a bootstrap over humans (and, when
    `resample_models`, over models, crossed with the humans); every seed of a drawn cell is kept. Same `seed`, same
    interval."""
    if draws < 100:
        raise LangprefError(f"--bootstraps needs at least 100 draws for a 95% interval, got {draws}")
    rng = np.random.default_rng(seed)
    n_models, n_humans = grid.sums.shape
    by_human = _multiplicities(rng, draws, n_humans)
    by_model = _multiplicities(rng, draws, n_models) if resample_models else np.ones((draws, n_models))
    total = np.einsum("bm,mh,bh->b", by_model, grid.sums, by_human)
    count = np.einsum("bm,mh,bh->b", by_model, grid.counts, by_human)
    means = total[count > 0] / count[count > 0]
    mean = float(grid.sums.sum() / grid.counts.sum())
    if n_humans < 2:
        low, high = float("-inf"), float("inf")
    else:
        tail = (1.0 - confidence) / 2
        low, high = (float(q) for q in np.quantile(means, [tail, 1.0 - tail]))
    return {
        "mean": mean,
        "low": low,
        "high": high,
        "n": int(grid.counts.sum()),
        "humans": n_humans,
        "models": n_models,
        "method": "humans-models" if resample_models and n_models > 1 else "humans",
        "draws": draws,
        "seed": seed,
    }


def human_spread(grid: CellGrid) -> float:
    """How much of the pairs' spread is the human's: the correlation between two models' per-human means, averaged
    over pairs of models (nan with one model). Near 1, the models repeat one another and pooling them adds little."""
    means = np.divide(grid.sums, grid.counts, out=np.full(grid.sums.shape, np.nan), where=grid.counts > 0)
    pairs = [
        np.corrcoef(means[i], means[k])[0, 1]
        for i in range(len(grid.models))
        for k in range(i + 1, len(grid.models))
        if np.all(np.isfinite(means[[i, k]])) and means[[i, k]].std(axis=1).min() > 0
    ]
    return float(np.mean(pairs)) if pairs else float("nan")
