"""`langpref bank check`: how well each meaning (feature, direction) of a bank is read from phrasings held back from
it, before a study relies on that reading.

Leave-one-out over a split (the train split: the phrasings a model is built from): each phrasing is read as the
meaning whose prototype (the mean of that meaning's other unit-length sentence embeddings) is nearest in cosine; a
meaning's accuracy is the share of its phrasings read as itself, and the meanings it is read as instead are counted.
With phrasings from elsewhere (`--utterances`), each is read against the prototypes of all the split's phrasings.

The sentence embeddings come from a function (`Embed`), so the same check runs with the pretrained sentence encoder
(no model yet) or a trained checkpoint's language encoder (psi), and tests can pass a small stand-in.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from langpref.language.bank import DIRECTIONS, normalise
from langpref.language.banksource import Phrasings

Embed = Callable[[Sequence[str]], np.ndarray]
"""texts -> (len(texts), dim) embeddings (any scale: they are made unit length here)."""
WEAK_BELOW = 0.8
"""A meaning read right less often than this from its held-back phrasings is flagged as weak."""


def meaning_name(feature: str, direction: str) -> str:
    return f"{feature}/{direction}"


@dataclass(frozen=True)
class MeaningCheck:
    """How one meaning's phrasings were read."""

    meaning: str
    count: int
    """Phrasings of the meaning that were read."""
    accuracy: float | None
    """Share read as this meaning; None when none could be read (fewer than two phrasings to leave one out)."""
    confused_with: dict[str, int]
    """Meaning -> how many of this meaning's phrasings were read as it, most first."""
    weak: bool
    advice: str | None
    misread: list[tuple[str, str]] = field(default_factory=list)
    """(phrasing, the meaning it was read as) for each phrasing read wrong."""

    def to_dict(self) -> dict:
        return {
            "count": self.count,
            "accuracy": self.accuracy,
            "confused_with": self.confused_with,
            "weak": self.weak,
            "advice": self.advice,
            "misread": [{"text": t, "read_as": m} for t, m in self.misread],
        }


@dataclass(frozen=True)
class BankCheck:
    """The whole check: per meaning, overall accuracy, and phrasings that appear under two meanings."""

    task: str
    encoder: str
    method: str
    meanings: dict[str, MeaningCheck]
    repeated: list[dict[str, object]]
    threshold: float

    @property
    def accuracy(self) -> float | None:
        right = sum(round((m.accuracy or 0.0) * m.count) for m in self.meanings.values() if m.accuracy is not None)
        total = sum(m.count for m in self.meanings.values() if m.accuracy is not None)
        return right / total if total else None

    @property
    def weak(self) -> list[str]:
        return [name for name, m in self.meanings.items() if m.weak]

    def to_dict(self) -> dict:
        return {
            "task": self.task,
            "encoder": self.encoder,
            "method": self.method,
            "threshold": self.threshold,
            "accuracy": self.accuracy,
            "weak": self.weak,
            "meanings": {name: m.to_dict() for name, m in self.meanings.items()},
            "repeated": self.repeated,
        }

    def summary(self) -> str:
        """One line: overall accuracy and the weak meanings with what they are taken for."""
        acc = self.accuracy
        head = f"bank check of {self.task} ({self.encoder}, {self.method}): " + (
            f"{acc:.0%} of {sum(m.count for m in self.meanings.values())} phrasings read as their own meaning"
            if acc is not None
            else "no meaning has enough phrasings to check"
        )
        if not self.weak:
            return head + "; no weak meaning"
        parts = []
        weakest = sorted(
            self.weak, key=lambda n: -1.0 if self.meanings[n].accuracy is None else self.meanings[n].accuracy
        )
        for name in weakest[:3]:
            m = self.meanings[name]
            top = next(iter(m.confused_with), None)
            score = "n/a" if m.accuracy is None else f"{m.accuracy:.2f}"
            parts.append(f"{name} {score}" + (f" (read as {top})" if top else ""))
        more = f" and {len(weakest) - 3} more" if len(weakest) > 3 else ""
        return head + f"; {len(weakest)} of {len(self.meanings)} meanings weak: " + ", ".join(parts) + more


def _unit(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-12)


def _flatten(phrasings: Phrasings, features: Sequence[str]) -> tuple[list[str], list[str]]:
    texts, labels = [], []
    for f in features:
        for d in DIRECTIONS:
            for t in phrasings.get(f, {}).get(d, []):
                texts.append(t)
                labels.append(meaning_name(f, d))
    return texts, labels


def _advice(name: str, accuracy: float | None, confused: dict[str, int], count: int) -> str:
    if accuracy is None:
        return f"add phrasings of {name}: it has {count}, at least 2 are needed to check it (10 or more to rely on it)"
    top = next(iter(confused), None)
    unlike = f" that say it apart from {top}" if top else ""
    kinds = "negations of the opposite direction, indirect forms: `langpref bank augment`"
    return f"add phrasings of {name}{unlike} ({kinds})"


def _result(
    name: str, reads: list[tuple[str, str]], count_only: int, threshold: float, allow_none: bool
) -> MeaningCheck:
    """A meaning's check from (text, read_as) of each phrasing read; `count_only` phrasings it has in all."""
    if not reads:
        acc = None
        weak = allow_none
    else:
        acc = sum(r == name for _, r in reads) / len(reads)
        weak = acc < threshold
    confused = dict(Counter(r for _, r in reads if r != name).most_common())
    misread = [(t, r) for t, r in reads if r != name]
    advice = _advice(name, acc, confused, count_only) if weak else None
    return MeaningCheck(name, len(reads), acc, confused, weak, advice, misread)


def repeated_phrasings(texts: Sequence[str], labels: Sequence[str]) -> list[dict[str, object]]:
    """Phrasings (after `normalise`) that appear under more than one meaning: a reader cannot tell them apart."""
    where: dict[str, set[str]] = {}
    first: dict[str, str] = {}
    for t, m in zip(texts, labels):
        key = normalise(t)
        where.setdefault(key, set()).add(m)
        first.setdefault(key, t)
    return [{"text": first[k], "meanings": sorted(ms)} for k, ms in where.items() if len(ms) > 1]


def leave_one_out(
    phrasings: Phrasings,
    features: Sequence[str],
    embed: Embed,
    *,
    task: str = "",
    encoder: str = "",
    threshold: float = WEAK_BELOW,
) -> BankCheck:
    """Each phrasing read by the nearest prototype built from every other phrasing (its own meaning's without it)."""
    texts, labels = _flatten(phrasings, features)
    names = [meaning_name(f, d) for f in features for d in DIRECTIONS]
    vecs = _unit(embed(texts)) if texts else np.zeros((0, 1))
    lab = np.array([names.index(m) for m in labels], dtype=int)
    sums = np.zeros((len(names), vecs.shape[1]))
    np.add.at(sums, lab, vecs)
    counts = np.bincount(lab, minlength=len(names)).astype(float)
    reads: dict[str, list[tuple[str, str]]] = {n: [] for n in names}
    for i, (text, g) in enumerate(zip(texts, lab)):
        if counts[g] < 2:
            continue  # nothing left to build its own prototype from
        protos = sums.copy()
        protos[g] -= vecs[i]
        have = counts.copy()
        have[g] -= 1
        scores = np.where(have > 0, _unit(protos) @ vecs[i], -np.inf)
        reads[names[g]].append((text, names[int(np.argmax(scores))]))
    meanings = {n: _result(n, reads[n], int(counts[k]), threshold, allow_none=True) for k, n in enumerate(names)}
    return BankCheck(task, encoder, "leave-one-out", meanings, repeated_phrasings(texts, labels), threshold)


def read_against(
    reference: Phrasings,
    queries: Phrasings,
    features: Sequence[str],
    embed: Embed,
    *,
    task: str = "",
    encoder: str = "",
    method: str = "against the bank",
    threshold: float = WEAK_BELOW,
) -> BankCheck:
    """Each phrasing of `queries` read by the nearest prototype of `reference`'s phrasings (meanings without a
    phrasing in `reference` cannot be read as)."""
    ref_texts, ref_labels = _flatten(reference, features)
    q_texts, q_labels = _flatten(queries, features)
    names = [meaning_name(f, d) for f in features for d in DIRECTIONS]
    vecs = _unit(embed([*ref_texts, *q_texts]))
    ref, qv = vecs[: len(ref_texts)], vecs[len(ref_texts) :]
    lab = np.array([names.index(m) for m in ref_labels], dtype=int)
    sums = np.zeros((len(names), vecs.shape[1]))
    np.add.at(sums, lab, ref)
    present = np.bincount(lab, minlength=len(names)) > 0
    scores = np.where(present[None, :], qv @ _unit(sums).T, -np.inf)
    reads: dict[str, list[tuple[str, str]]] = {n: [] for n in names}
    for text, label, row in zip(q_texts, q_labels, scores):
        reads[label].append((text, names[int(np.argmax(row))]))
    meanings = {n: _result(n, reads[n], len(reads[n]), threshold, allow_none=False) for n in names}
    return BankCheck(task, encoder, method, meanings, repeated_phrasings(q_texts, q_labels), threshold)


__all__ = ["WEAK_BELOW", "BankCheck", "Embed", "MeaningCheck", "leave_one_out", "meaning_name", "read_against"]
