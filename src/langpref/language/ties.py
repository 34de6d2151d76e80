"""How a task's feature is tied to a concept of the comparative-feedback corpus, by its name: `distance_to_puck` is
the concept `distance` about the object `puck`, `gripper_opening` the concept `grip` with its sign flipped (the
corpus's `grip` grows as the fingers close), `drawer_opening` the concept `opening` of the object `drawer`.

The words that name each concept and say which way its number grows are data (`name_words` in
`data/comparative_concepts.json`). A feature's name is split into words at underscores, hyphens, digits and case
changes; each concept scores the number of distinct name words it knows, plus one when a word is one of the objects
the concept speaks of; the highest positive score wins (the lexicon's order breaks ties). A name no concept knows
(`lift_success`) is tied to nothing.

The tie labels the built-in banks' phrasings in the corpus (so "Move closer to the button." and "Get nearer to the
cup." share the concept `distance`), and says which of the corpus's meanings a lab's feature is.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from langpref.language.lexicon import load_lexicon

_LINKS = ("to", "from", "of", "with", "above", "near")


@dataclass(frozen=True)
class Tie:
    """A feature's concept in the corpus."""

    feature: str
    concept: str
    sign: int
    """+1 when the feature grows with the concept's `increase`, -1 when it grows with its `decrease`."""
    obj: str | None
    """The named object (`puck` of `distance_to_puck`), for a concept about one; else None."""
    words: tuple[str, ...]
    """The name's words that decided it."""


def name_words(name: str) -> list[str]:
    """Lower-case words of a feature name: `distance_to_puck` -> distance, to, puck; `gripperOpening` -> gripper,
    opening."""
    spaced = re.sub(r"([a-z])([A-Z])", r"\1 \2", name)
    return [w for w in re.split(r"[^A-Za-z]+", spaced.lower()) if w]


def _object(words: list[str], known: set[str], concept_words: set[str], objects: list[str]) -> str | None:
    """The object a name speaks of: the words after its last link word (`to`, `from`, ...), else a word of the
    concept's object list."""
    for i in range(len(words) - 1, -1, -1):
        if words[i] in _LINKS and i + 1 < len(words):
            rest = [w for w in words[i + 1 :] if w not in concept_words]
            if rest:
                return " ".join(rest)
    joined = " ".join(words)
    for obj in objects:
        if re.search(rf"\b{re.escape(obj)}\b", joined):
            return obj
    return None


def tie_feature(name: str, lexicon: dict[str, Any] | None = None) -> Tie | None:
    """The concept a feature's name ties to, or None."""
    if lexicon is None:
        lexicon = load_lexicon()
    words = name_words(name)
    joined = "_".join(words)
    best: tuple[int, str, set[str]] | None = None
    for concept_name, concept in lexicon["concepts"].items():
        nw = concept["name_words"]
        vocab = {w for key in ("any", "increase", "decrease") for w in nw[key]}
        hit = {w for w in vocab if ("_" in w and re.search(rf"(^|_){re.escape(w)}(_|$)", joined)) or w in words}
        score = len(hit)
        objects = lexicon["objects"].get(concept.get("object") or "", [])
        if hit and any(o in words for o in objects):
            score += 1
        if score and (best is None or score > best[0]):
            best = (score, concept_name, hit)
    if best is None:
        return None
    _, concept_name, hit = best
    concept = lexicon["concepts"][concept_name]
    nw = concept["name_words"]
    up, down = hit & set(nw["increase"]), hit & set(nw["decrease"])
    sign = -1 if down and not up else 1
    obj = None
    if concept.get("object"):
        vocab = {w for key in ("any", "increase", "decrease") for w in nw[key]}
        obj = _object(words, vocab, vocab, lexicon["objects"][concept["object"]])
    return Tie(name, concept_name, sign, obj, tuple(sorted(hit)))


def tie_features(names: list[str] | tuple[str, ...]) -> dict[str, Tie | None]:
    """{feature: its tie or None} for a task's features."""
    lexicon = load_lexicon()
    return {name: tie_feature(name, lexicon) for name in names}


__all__ = ["Tie", "name_words", "tie_feature", "tie_features"]
