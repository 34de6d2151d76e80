"""(tau_A, tau_B, l) samples: ordered trajectory pairs, the feature that differs, its direction, and phrasings.

A sample of the latent-space dataset (paper Sec. 4.1) is an ordered pair of trajectories of one split, one feature
whose value differs between them, the direction that takes tau_A to tau_B (`increase` when theta_B > theta_A), and an
utterance saying so ("Move faster." for speed/increase). Pairs are stored as four int arrays, never one object per
pair: Meta-World's train split alone has about 260 * 259 * 3 = 200k of them.

Ties. Two trajectories whose feature values are nearly equal carry no comparative signal (a human would not say "move
higher" about a 1 mm difference), so a feature enters a pair only when |theta_B - theta_A| exceeds a tie threshold:
`TIE_FRACTION` (5%) of that feature's standard deviation on the train split. Training and evaluation use the same
thresholds (the checkpoint stores them).

Phrasings live in a `Phrasings` table: distinct texts plus, per (feature, direction) group `g = 2 * f + d`, the ids of
its texts. Training samples one phrasing per pair at random each epoch (`sample_phrasings`); evaluation uses every
phrasing of the group (`langpref.model.evaluate`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from langpref.errors import LangprefError
from langpref.language.bank import DIRECTIONS

INCREASE, DECREASE = 0, 1
TIE_FRACTION = 0.05  # a feature "differs" between two trajectories when |delta| > TIE_FRACTION * std(train)


def tie_thresholds(train_features: np.ndarray, fraction: float = TIE_FRACTION) -> np.ndarray:
    """Per-feature tie thresholds: `fraction` of each feature's standard deviation over the train split."""
    feats = np.asarray(train_features, dtype=np.float64)
    if feats.ndim != 2 or len(feats) < 2:
        raise LangprefError(f"need at least 2 train trajectories to set tie thresholds, got features {feats.shape}")
    if fraction < 0:
        raise LangprefError(f"tie fraction must be >= 0, got {fraction}")
    return fraction * feats.std(axis=0)


@dataclass(frozen=True)
class Pairs:
    """Samples (a[i], b[i], feature[i], direction[i]); `a`, `b` index the rows of the features they were built from."""

    a: np.ndarray
    b: np.ndarray
    feature: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return len(self.a)

    @property
    def group(self) -> np.ndarray:
        """(feature, direction) group id of each sample, `2 * feature + direction`."""
        return 2 * self.feature + self.direction

    def subset(self, mask_or_index: np.ndarray) -> Pairs:
        return Pairs(
            self.a[mask_or_index], self.b[mask_or_index], self.feature[mask_or_index], self.direction[mask_or_index]
        )


def build_pairs(features: np.ndarray, thresholds: np.ndarray) -> Pairs:
    """Every ordered pair (A, B), A != B, and every feature f with |theta_B[f] - theta_A[f]| > thresholds[f].

    `features` is (N, F), the trajectory features of one split; the returned indices are rows of it. Sorted by
    (a, b, feature), so the same inputs always give the same arrays.
    """
    feats = np.asarray(features, dtype=np.float64)
    thr = np.asarray(thresholds, dtype=np.float64)
    if feats.ndim != 2 or thr.shape != (feats.shape[1],):
        raise LangprefError(f"features {feats.shape} and thresholds {thr.shape} do not match")
    n, num_features = feats.shape
    a_all, b_all, f_all, d_all = [], [], [], []
    rows = np.arange(n)
    for a in range(n):  # one row of the (N, N, F) difference tensor at a time: O(N * F) memory
        delta = feats - feats[a]  # theta_B - theta_A for every B
        differs = np.abs(delta) > thr
        differs[a] = False
        b_idx, f_idx = np.nonzero(differs)
        a_all.append(np.full(len(b_idx), a, dtype=np.int64))
        b_all.append(rows[b_idx])
        f_all.append(f_idx)
        d_all.append(np.where(delta[b_idx, f_idx] > 0, INCREASE, DECREASE))
    if n == 0 or num_features == 0:
        empty = np.zeros(0, dtype=np.int64)
        return Pairs(empty, empty, empty, empty)
    return Pairs(*(np.concatenate(x).astype(np.int64) for x in (a_all, b_all, f_all, d_all)))


@dataclass(frozen=True)
class Phrasings:
    """Distinct utterances and, per (feature, direction) group `g = 2 * f + d`, the ids of that group's texts."""

    texts: tuple[str, ...]
    feature_names: tuple[str, ...]
    group_ids: tuple[np.ndarray, ...]

    @property
    def num_groups(self) -> int:
        return len(self.group_ids)

    def group_name(self, g: int) -> tuple[str, str]:
        return self.feature_names[g // 2], DIRECTIONS[g % 2]

    def group_sizes(self) -> np.ndarray:
        return np.array([len(ids) for ids in self.group_ids], dtype=np.int64)

    def as_mapping(self) -> dict[str, dict[str, list[str]]]:
        """The utterance schema (docs/design.md#utterance-files) for one env: {feature: {direction: [texts]}}."""
        out: dict[str, dict[str, list[str]]] = {f: {} for f in self.feature_names}
        for g, ids in enumerate(self.group_ids):
            f, d = self.group_name(g)
            out[f][d] = [self.texts[i] for i in ids]
        return out


def phrasings_from_mapping(
    mapping: Mapping[str, Mapping[str, Sequence[str]]],
    feature_names: Sequence[str],
    *,
    require_all: bool = True,
    source: str = "utterances",
) -> Phrasings:
    """Build a `Phrasings` table from {feature: {direction: [texts]}} for the features of a dataset.

    With `require_all`, every feature and direction must have at least one phrasing (training needs all of them);
    without, missing ones are empty groups (evaluation then skips them). Unknown features or directions are errors.
    """
    feature_names = tuple(feature_names)
    for f, by_dir in mapping.items():
        if f.startswith("_"):
            continue
        if f not in feature_names:
            raise LangprefError(f"{source}: unknown feature {f!r}; this dataset has {', '.join(feature_names)}")
        for d in by_dir:
            if d not in DIRECTIONS:
                raise LangprefError(f"{source}: unknown direction {d!r} under {f!r}; use increase or decrease")
    texts: list[str] = []
    index: dict[str, int] = {}
    group_ids = []
    for f in feature_names:
        for d in DIRECTIONS:
            raw = mapping.get(f, {}).get(d, ())
            ids: list[int] = []
            for text in raw:
                text = " ".join(str(text).split())
                if not text:
                    continue
                if text not in index:
                    index[text] = len(texts)
                    texts.append(text)
                if index[text] not in ids:
                    ids.append(index[text])
            if require_all and not ids:
                raise LangprefError(
                    f"{source}: no phrasing for {f}/{d}; every feature and direction needs at least one"
                )
            group_ids.append(np.array(ids, dtype=np.int64))
    return Phrasings(tuple(texts), feature_names, tuple(group_ids))


def phrasings_from_bank(bank, split: str, feature_names: Sequence[str]) -> Phrasings:
    """The phrasings of one split (`train`, `val`, `test`) of an utterance bank (`langpref.language.bank.Bank`)."""
    mapping = {f: {d: list(bank.get(split, f, d)) for d in DIRECTIONS} for f in feature_names}
    return phrasings_from_mapping(mapping, feature_names, source=f"utterance bank, split {split}")


def merge_phrasings(first: Phrasings, second: Phrasings) -> Phrasings:
    """The union of two tables over the same features (e.g. the bank's train split extended by a user's file)."""
    if first.feature_names != second.feature_names:
        raise LangprefError("cannot merge phrasings of different feature sets")
    mapping = first.as_mapping()
    for f, by_dir in second.as_mapping().items():
        for d, texts in by_dir.items():
            mapping[f][d] = list(mapping[f].get(d, [])) + list(texts)
    return phrasings_from_mapping(mapping, first.feature_names, require_all=False)


def sample_phrasings(
    groups: np.ndarray, phrasings: Phrasings, rng: np.random.Generator, subset: Sequence[np.ndarray] | None = None
) -> np.ndarray:
    """One phrasing id per sample, uniformly among the ids of its group (or of `subset[g]`, when given).

    `subset` is how co-finetuning keeps the number of distinct utterances per batch small: draw a few phrasings per
    group, then let every sample pick among those. Each sample's phrasing is still uniform over its group.
    """
    pools = subset if subset is not None else phrasings.group_ids
    sizes = np.array([len(p) for p in pools], dtype=np.int64)
    if np.any(sizes[np.unique(groups)] == 0):
        missing = [phrasings.group_name(int(g)) for g in np.unique(groups) if sizes[g] == 0]
        raise LangprefError(f"no phrasing for {', '.join(f'{f}/{d}' for f, d in missing)}")
    flat = np.concatenate([np.asarray(p, dtype=np.int64) for p in pools]) if len(pools) else np.zeros(0, np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    pick = np.floor(rng.random(len(groups)) * sizes[groups]).astype(np.int64)
    return flat[starts[groups] + pick]


def sample_subset(phrasings: Phrasings, per_group: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Up to `per_group` distinct phrasing ids of each group, drawn without replacement."""
    return [
        ids if len(ids) <= per_group else rng.choice(ids, size=per_group, replace=False) for ids in phrasings.group_ids
    ]
