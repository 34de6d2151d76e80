"""Is feedback about something the task measures? "Move faster." said of a drawer task that has no speed is not a
request about any of its features, and reading it as the nearest one ("close the gripper") teaches the learner
something the person never said.

The check works in the sentence space of the language model that has read comparative feedback
(`--lang-model comparative`, `langpref.language.pretrain`: trained to keep concepts and directions apart; built once
into the cache, on first use or by `make install`), against the comparative-feedback corpus
(`langpref.language.corpus`: sentences over concepts people ask of a robot, speed, height, distance, the grip, force,
rotation, ..., and the built-in banks' train phrasings). The concepts a task
speaks of are *covered*: those its features' names tie to (`langpref.language.ties`), and, for a feature whose name
ties to none, the concept most of its bank phrasings are nearest to. A sentence is *outside the task* when its
nearest corpus sentence belongs to a concept that is not covered, and that sentence is more similar to it than the
nearest phrasing of the task's bank, by more than `SCOPE_MARGIN`: it is then said so ("this task does not measure
speed") instead of read as one of the task's features.

`SCOPE_MARGIN` was chosen on val data only (`langpref bank scope --split val`, docs/results.md): the val phrasings of
each built-in bank and of the drawer example's as real feedback, and the val phrasings of the *other* banks' features
whose concepts a task lacks as sentences about what it does not measure. In the pretrained MiniLM space the feedback
gate works in, the same check said only 60% of those outside on Meta-World's val (docs/results.md).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

SCOPE_MARGIN = -0.05
"""How much nearer to a concept the task lacks than to its bank a sentence must be to be said outside the task
(negative: a sentence nearest to such a concept is said outside unless a bank phrasing is within 0.05 of it)."""
SCOPE_LANG_MODEL = "comparative"
"""The sentence space of the check."""
PER_MEANING = 20
"""Corpus sentences per (concept, direction) the check compares with (and at most as many bank phrasings)."""

Embed = Callable[[list[str]], np.ndarray]
"""texts -> unit-normalised embeddings (N, D)."""


@dataclass(frozen=True)
class Scope:
    """Where a sentence stands against the task's bank and the concepts it does not speak of."""

    task_score: float
    """Highest cosine to a phrasing of the task's bank."""
    concept: str | None
    """The concept of its nearest corpus sentence, when the task does not speak of it (else None)."""
    concept_score: float
    margin: float = SCOPE_MARGIN

    @property
    def outside(self) -> bool:
        """Whether the sentence is about something the task does not measure."""
        return self.concept is not None and self.concept_score - self.task_score > self.margin

    @property
    def words(self) -> str:
        """The concept as a person reads it: `robosuite/lift_success` -> "lift success"."""
        return (self.concept or "").rsplit("/", 1)[-1].replace("_", " ")

    def as_dict(self) -> dict:
        return {
            "outside": self.outside,
            "concept": self.concept,
            "score": round(self.concept_score, 4),
            "task_score": round(self.task_score, 4),
        }


@lru_cache(maxsize=2)
def corpus_sentences(per_meaning: int = PER_MEANING, seed: int = 0) -> tuple[tuple[str, str], ...]:
    """(concept, sentence) pairs: `per_meaning` template sentences per (concept, direction) and as many of each bank
    meaning's train phrasings (the first in the bank's order)."""
    from langpref.language.corpus import bank_examples, generate

    out: list[tuple[str, str]] = [(e.concept, e.text) for e in generate(seed, per_meaning)]
    taken: dict[tuple[str, str, str], int] = {}
    for e in bank_examples():
        key = (e.source, e.concept, e.direction)
        if taken.get(key, 0) < per_meaning:
            taken[key] = taken.get(key, 0) + 1
            out.append((e.concept, e.text))
    return tuple(out)


def covered_concepts(
    features: Sequence[str], bank_emb: np.ndarray, bank_features: Sequence[str], names: np.ndarray, emb: np.ndarray
) -> frozenset[str]:
    """The concepts a task speaks of: its features' ties, and for an untied feature the concept most of its bank
    phrasings are nearest to."""
    from langpref.language.ties import tie_features

    covered = set()
    feats = np.asarray(bank_features)
    for feature, tie in tie_features(list(features)).items():
        if tie is not None:
            covered.add(tie.concept)
            continue
        rows = np.flatnonzero(feats == feature)
        if len(rows):
            votes, counts = np.unique(names[np.argmax(bank_emb[rows] @ emb.T, axis=1)], return_counts=True)
            covered.add(str(votes[np.argmax(counts)]))
    return frozenset(covered)


@dataclass(frozen=True)
class ScopeCheck:
    """The corpus embedded once against one task's bank."""

    bank: np.ndarray
    """The bank's phrasings, embedded."""
    names: np.ndarray
    """The concept of each corpus sentence."""
    corpus: np.ndarray
    """The corpus sentences, embedded."""
    covered: frozenset[str]

    @classmethod
    def build(cls, features: Sequence[str], bank: Sequence[str], bank_features: Sequence[str], embed: Embed):
        """The check of a task with `features` whose bank phrasings are `bank` (the feature of each in
        `bank_features`); the bank's own phrasings are left out of the corpus it compares with."""
        own = {t.lower() for t in bank}
        pairs = [(c, t) for c, t in corpus_sentences() if t.lower() not in own]
        names = np.asarray([c for c, _ in pairs])
        emb = embed([t for _, t in pairs])
        bank_emb = embed(list(bank))
        return cls(bank_emb, names, emb, covered_concepts(features, bank_emb, bank_features, names, emb))

    def scope(self, emb: np.ndarray, margin: float = SCOPE_MARGIN) -> Scope:
        """The scope of one sentence embedded as `emb` (D,)."""
        task = float((self.bank @ emb).max())
        sims = self.corpus @ emb
        best = int(np.argmax(sims))
        concept = str(self.names[best])
        return Scope(task, None if concept in self.covered else concept, float(sims[best]), margin)


@lru_cache(maxsize=1)
def scope_embedder() -> tuple[Embed, str]:
    """(texts -> unit-normalised embeddings in `SCOPE_LANG_MODEL`'s space, a key naming that exact build)."""
    import torch

    from langpref.language.coalesce import REMEMBERED, Coalesced
    from langpref.language.loading import load_transformer
    from langpref.language.models import resolve
    from langpref.language.transformer import SentenceEncoder

    tokenizer, transformer = load_transformer(SCOPE_LANG_MODEL)
    encoder = SentenceEncoder(tokenizer, transformer).eval()

    def embed(texts: list[str]) -> np.ndarray:
        out = []
        with torch.no_grad():
            for i in range(0, len(texts), 256):
                pooled = encoder.pooled_texts(list(texts[i : i + 256])).double()
                out.append(torch.nn.functional.normalize(pooled, dim=-1).numpy())
        return np.concatenate(out) if out else np.zeros((0, 1))

    # one pass at a time (the fast tokenizer is not safe across threads), concurrent texts in one batch, texts said
    # again read from memory
    return Coalesced(embed, remember=REMEMBERED), Path(resolve(SCOPE_LANG_MODEL)).name


def cached_embeddings(texts: list[str], embed: Embed, model: str) -> np.ndarray:
    """`embed(texts)`, kept on disk (the langpref cache, `LANGPREF_CACHE`) by the model's name and the texts, so the
    corpus is embedded once per machine rather than once per command."""
    import hashlib

    from langpref.language.models import cache_dir

    key = hashlib.sha256("\n".join([model, *texts]).encode("utf-8")).hexdigest()[:24]
    path = cache_dir() / "scope" / f"{key}.npy"
    if path.is_file():
        try:
            found = np.load(path)
            if found.shape[0] == len(texts):
                return found
        except (OSError, ValueError):
            pass  # a damaged cache file is made again
    out = embed(texts)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
        np.save(tmp, out)
        tmp.replace(path)
    except OSError:
        pass  # an unwritable cache only costs the time
    return out


MARGINS = (-0.1, -0.05, 0.0, 0.05, 0.1)
"""The margins `measure` tries."""
MAX_REAL_SHARE = 0.05
"""The most real feedback any bank may see said outside its task, at the chosen margin."""


def measure(banks: dict, split: str, margins: Sequence[float] = MARGINS) -> dict:
    """How the check treats, per bank (name -> `langpref.language.banksource.BankSource`), its own phrasings of
    `split` (real feedback: the share said outside, to keep low) and the other banks' phrasings of `split` about
    concepts it lacks (the share said outside, to keep high), at each margin; the check built from each bank's train
    split. The chosen margin: the one with the highest mean share said outside among those that keep every bank's
    real feedback at or under `MAX_REAL_SHARE`."""
    from langpref.language.ties import tie_features

    embed, key = scope_embedder()

    def cached(texts: list[str]) -> np.ndarray:
        return cached_embeddings(texts, embed, key)

    def concepts(name: str, features) -> dict[str, str]:
        return {f: (t.concept if t else f"{name}/{f}") for f, t in tie_features(list(features)).items()}

    def texts(source, which: str, keep=lambda f: True) -> list[str]:
        return [t for f, by in source.split(which).items() if keep(f) for ts in by.values() for t in ts]

    rows = {}
    for name, source in banks.items():
        pairs = [(t, f) for f, by in source.split("train").items() for ts in by.values() for t in ts]
        check = ScopeCheck.build(source.features, [t for t, _ in pairs], [f for _, f in pairs], cached)
        mine = set(concepts(name, source.features).values())
        lacked = []
        for other, ob in banks.items():
            if other != name:
                theirs = concepts(other, ob.features)
                lacked += texts(ob, split, lambda f, theirs=theirs, mine=mine: theirs[f] not in mine)
        real, outside = cached(texts(source, split)), cached(lacked)
        rows[name] = {
            "real": len(real),
            "lacked": len(lacked),
            "covered": sorted(check.covered),
            "by_margin": {
                str(m): {
                    "real_said_outside": float(np.mean([check.scope(e, m).outside for e in real])),
                    "lacked_said_outside": float(np.mean([check.scope(e, m).outside for e in outside])),
                }
                for m in margins
            },
        }
    ok = [
        m for m in margins if all(r["by_margin"][str(m)]["real_said_outside"] <= MAX_REAL_SHARE for r in rows.values())
    ]
    chosen = max(ok, key=lambda m: np.mean([r["by_margin"][str(m)]["lacked_said_outside"] for r in rows.values()]))
    return {"split": split, "banks": rows, "chosen_margin": chosen if ok else None, "margin_in_use": SCOPE_MARGIN}
