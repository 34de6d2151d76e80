"""The hand-written lexicon of comparative concepts (`data/comparative_concepts.json`): concepts a lab's robot is
likely to have, each with both directions in every kind of sentence, the words that tie a feature's name to a
concept, and the templates. Read by the corpus (`langpref.language.corpus`) that makes sentences of it and by the
ties (`langpref.language.ties`) that name a task's feature by it; its checksum keys the built language model."""

from __future__ import annotations

import hashlib
import json
from importlib import resources
from typing import Any

from langpref.errors import LangprefError

DIRECTIONS = ("increase", "decrease")
KINDS = ("requests", "adjectives", "acts", "indirect")
"""The kinds of sentence each (concept, direction) of the lexicon gives: plain requests, complaints, negations of
what to stop doing, indirect forms."""
FILE = "data/comparative_concepts.json"
"""The lexicon, under the package `langpref.language`."""


def load_lexicon() -> dict[str, Any]:
    """The shipped lexicon, checked: every concept has both directions and every kind."""
    text = resources.files("langpref.language").joinpath(FILE).read_text("utf-8")
    lex = json.loads(text)
    for name, concept in lex["concepts"].items():
        for direction in DIRECTIONS:
            entry = concept.get(direction)
            if not isinstance(entry, dict) or any(not entry.get(k) for k in KINDS):
                raise LangprefError(f"comparative_concepts.json: {name}.{direction} lacks one of {', '.join(KINDS)}")
        if concept.get("object") not in (None, *lex["objects"]):
            raise LangprefError(f"comparative_concepts.json: {name}.object names no object list")
    return lex


def lexicon_version() -> str:
    """A short checksum of the lexicon file: part of the built model's cache key."""
    data = resources.files("langpref.language").joinpath(FILE).read_bytes()
    return hashlib.sha256(data).hexdigest()[:12]
