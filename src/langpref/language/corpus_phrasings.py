"""A task's train phrasings extended by the comparative corpus's sentences of the concepts its features tie to
(issue 40): `TrainConfig.corpus_phrasings` (`langpref train --corpus-phrasings N`).

A feature tied to a corpus concept by its name (`langpref.language.ties`: `drawer_opening` is the concept `opening`
of the object `drawer`, `hand_sideways` the concept `lateral`) gets up to N of that concept's template sentences per
direction, made as the corpus makes them (`langpref.language.corpus.generate`, same seed, same order, each kind of
sentence in turn):

- in the feature's own direction: the feature's `increase` is the concept's `increase` for a tie of sign +1 and its
  `decrease` for a tie of sign -1 (`gripper_opening` grows as the corpus's `grip` falls);
- for a concept about a named object, with the feature's object in every sentence ("Pull the drawer out further."
  for `drawer_opening`), whether or not the lexicon lists that object; a feature of such a concept whose name gives no
  object gets none (sentences about some other object would teach the wrong thing);
- none that is an exact or near copy (`langpref.language.near_copies`, ratio 0.9) of a phrasing of the task's val
  or test split, or of a phrasing of another meaning of the train split, nor one two meanings would share.

They are added for training only, like `augment_phrasings`: never to val or test, never to the bank, never to the
checkpoint's prototypes (the means of the bank's own train phrasings). The built-in banks' phrasings in the corpus
are not added (they speak of the built-in tasks' objects). A feature no concept ties to keeps its phrasings.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence

from langpref.language.bank import DIRECTIONS

EXTRA_CANDIDATES = 2
"""Sentences drawn per wanted one before the copies are dropped (the rest fill the gaps they leave)."""


def _concept_lexicon(lex: dict, concept: str, obj: str | None) -> dict | None:
    """The lexicon with the concept's object list narrowed to `obj`; None for an object concept without one."""
    kind = lex["concepts"][concept].get("object")
    if not kind:
        return lex
    if not obj:
        return None
    narrowed = copy.copy(lex)
    narrowed["objects"] = {**lex["objects"], kind: [obj]}
    return narrowed


def _candidates(feature: str, per_meaning: int, seed: int, lex: dict) -> dict[str, list[str]]:
    """{direction of the feature: the tied concept's sentences in the corpus's order}; {} for an untied feature."""
    from langpref.language.corpus import generate
    from langpref.language.ties import tie_feature

    tie = tie_feature(feature, lex)
    narrowed = None if tie is None else _concept_lexicon(lex, tie.concept, tie.obj)
    if tie is None or narrowed is None:
        return {}
    made = generate(seed, per_meaning * EXTRA_CANDIDATES, [tie.concept], lexicon=narrowed)
    out: dict[str, list[str]] = {d: [] for d in DIRECTIONS}
    for example in made:
        d = example.direction if tie.sign > 0 else DIRECTIONS[1 - DIRECTIONS.index(example.direction)]
        out[d].append(example.text)
    return out


def tied_phrasings(
    feature_names: Sequence[str],
    per_meaning: int,
    *,
    seed: int = 0,
    exclude: Iterable[str] = (),
    train: dict[str, dict[str, Sequence[str]]] | None = None,
) -> dict[str, dict[str, list[str]]]:
    """{feature: {direction: up to `per_meaning` corpus sentences}} for the tied features of a task (the utterance
    schema; untied features are absent). `exclude`: texts no sentence may copy (the task's val and test phrasings);
    `train`: the train phrasings, {feature: {direction: texts}}, whose other meanings no sentence may copy."""
    from langpref.language.corpus import copies
    from langpref.language.lexicon import load_lexicon
    from langpref.language.near_copies import NEAR_COPY_RATIO, normalise

    exclude = list(exclude)
    if per_meaning <= 0:
        return {}
    lex = load_lexicon()
    made = {f: c for f in feature_names if (c := _candidates(f, per_meaning, seed, lex))}
    owner: dict[str, set[tuple[str, str]]] = {}
    for f, by_dir in made.items():
        for d, texts in by_dir.items():
            for t in texts:
                owner.setdefault(normalise(t), set()).add((f, d))
    out: dict[str, dict[str, list[str]]] = {}
    for f, by_dir in made.items():
        for d, texts in by_dir.items():
            other = [t for g, by in (train or {}).items() for e, ts in by.items() if (g, e) != (f, d) for t in ts]
            dropped = copies(texts, [*exclude, *other], NEAR_COPY_RATIO)
            kept = [t for t in texts if t not in dropped and len(owner[normalise(t)]) == 1]
            out.setdefault(f, {})[d] = kept[:per_meaning]
    return out


__all__ = ["EXTRA_CANDIDATES", "tied_phrasings"]
