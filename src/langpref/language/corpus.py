"""The comparative-feedback corpus: sentences asking a robot for more or less of something, each labelled with its
meaning (concept, direction and, for a concept about a named object, the object), made reproducibly from a seed.

Two sources, nothing else:
- templates over the hand-written lexicon `data/comparative_concepts.json` (concepts a lab's robot is likely to have,
  both directions, plain requests with intensities, complaints "You're too slow.", negations "No need to dawdle.",
  indirect forms "You're crawling.");
- the built-in banks' TRAIN splits (Meta-World's and robosuite's), each phrasing labelled with the concept its feature
  ties to (`langpref.language.ties`) or, where none does, with the feature itself.

No bank's val or test phrasing enters it: a generated sentence that is an exact or near copy
(`langpref.language.near_copies`) of any val/test phrasing of any built-in bank is dropped. The held-out sets are read
by no code here; a test checks the corpus against them.

The language model `comparative` (`langpref.language.pretrain`) is trained on this corpus before it meets any task.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from langpref.language.lexicon import DIRECTIONS, KINDS, load_lexicon
from langpref.language.ties import tie_feature

BUILT_IN_BANKS = ("metaworld", "robosuite")
DEFAULT_PER_MEANING = 160
"""Generated sentences per (concept, direction); sentences of an object concept spread over its objects."""


@dataclass(frozen=True)
class Example:
    """One sentence of the corpus and what it means."""

    text: str
    concept: str
    """A lexicon concept (`speed`), or `TASK/feature` for a bank feature no concept ties to."""
    direction: str
    obj: str | None
    """The named object of an object concept (`cup` in "Move closer to the cup."), else None."""
    source: str
    """`template:KIND` or `bank:TASK`."""

    @property
    def meaning(self) -> str:
        """The label sentences of one meaning share: concept/direction[/object]."""
        base = f"{self.concept}/{self.direction}"
        return f"{base}/{self.obj}" if self.obj else base


def _sentence(text: str) -> str:
    """Upper-case the first letter; single spaces."""
    text = " ".join(text.split())
    return text[:1].upper() + text[1:] if text else text


def _rank(seed: int, text: str) -> bytes:
    """A seeded order of sentences that does not depend on the others: removing one lexicon entry removes only its
    sentences and lets the next ones in, the rest stay."""
    return hashlib.sha256(f"{seed}\t{text}".encode()).digest()


def _expand(phrase: str, intensities: list[str], objects: list[str | None]) -> list[tuple[str, str | None]]:
    """Every (phrase, object) a phrase gives: each intensity in its `{i}`, each object in its `{obj}`."""
    filled = [phrase.replace("{i}", i) for i in intensities] if "{i}" in phrase else [phrase]
    if "{obj}" not in phrase:
        return [(f, None) for f in filled]
    return [(f.replace("{obj}", o), o) for f in filled for o in objects if o is not None]


_SLOT = {"requests": "r", "adjectives": "a", "acts": "c", "indirect": "s"}


def _sentences(lex: dict[str, Any], concept: dict[str, Any], direction: str) -> dict[str, dict[str, str | None]]:
    """{kind: {sentence: object}}: every sentence the templates make of one (concept, direction)."""
    entry = concept[direction]
    objects = lex["objects"][concept["object"]] if concept.get("object") else [None]
    out: dict[str, dict[str, str | None]] = {}
    for kind in KINDS:
        templates = []
        for tpl in lex["templates"][kind]:
            templates += [tpl.replace("{t}", too) for too in lex["too"]] if "{t}" in tpl else [tpl]
        made = out.setdefault(kind, {})
        for phrase in entry[kind]:
            for filled, obj in _expand(phrase, lex["intensities"], objects):
                for tpl in templates:
                    made.setdefault(_sentence(tpl.replace("{" + _SLOT[kind] + "}", filled)), obj)
    return out


def generate(
    seed: int = 0,
    per_meaning: int = DEFAULT_PER_MEANING,
    concepts: Iterable[str] | None = None,
    lexicon: dict[str, Any] | None = None,
) -> list[Example]:
    """Template sentences: for each (concept, direction), `per_meaning` of every sentence its templates make, taken
    in a seeded order, each kind (requests, complaints, negations, indirect forms) in turn so no kind crowds out
    another. The same seed gives the same list. `lexicon` (default: the shipped one) lets a caller narrow an object
    concept to one object (`langpref.language.corpus_phrasings`)."""
    lex = load_lexicon() if lexicon is None else lexicon
    names = list(lex["concepts"]) if concepts is None else list(concepts)
    out: list[Example] = []
    for name in names:
        for direction in DIRECTIONS:
            by_kind = _sentences(lex, lex["concepts"][name], direction)
            queues = {k: sorted(v, key=lambda t: _rank(seed, t), reverse=True) for k, v in by_kind.items()}
            seen: set[str] = set()
            while len(seen) < per_meaning and any(queues.values()):
                for kind in KINDS:
                    if queues[kind] and len(seen) < per_meaning:
                        text = queues[kind].pop()
                        if text.lower() not in seen:
                            seen.add(text.lower())
                            out.append(Example(text, name, direction, by_kind[kind][text], f"template:{kind}"))
    return out


def bank_examples(tasks: Iterable[str] = BUILT_IN_BANKS) -> list[Example]:
    """The TRAIN phrasings of the built-in banks, labelled through the feature's tie to a concept (its object the
    feature's object), or with `TASK/feature` where no concept ties."""
    import langpref.tasks  # noqa: F401  (registers the built-in tasks)
    from langpref.language.bank import load_bank

    out = []
    for task in tasks:
        bank = load_bank(task)
        for feature in bank.features:
            tie = tie_feature(feature)
            for direction in DIRECTIONS:
                for text in bank.get("train", feature, direction):
                    if tie is None:
                        out.append(Example(text, f"{task}/{feature}", direction, None, f"bank:{task}"))
                    else:
                        d = direction if tie.sign > 0 else DIRECTIONS[1 - DIRECTIONS.index(direction)]
                        out.append(Example(text, tie.concept, d, tie.obj, f"bank:{task}"))
    return out


def excluded_texts(tasks: Iterable[str] = BUILT_IN_BANKS) -> list[str]:
    """Every val and test phrasing of the built-in banks: what the corpus must not copy."""
    import langpref.tasks  # noqa: F401
    from langpref.language.bank import load_bank

    out = []
    for task in tasks:
        bank = load_bank(task)
        for split in ("val", "test"):
            out += [text for text, _, _ in bank.all_of_split(split)]
    return out


def copies(texts: list[str], others: list[str], ratio: float) -> set[str]:
    """The texts of `texts` that are exact or near copies (difflib ratio >= `ratio` after
    `near_copies.normalise`) of some text of `others`. Lengths too far apart to reach `ratio` are skipped."""
    import difflib

    from langpref.language.near_copies import normalise

    by_len: dict[int, list[str]] = {}
    for o in {normalise(o) for o in others}:
        by_len.setdefault(len(o), []).append(o)
    out = set()
    for text in texts:
        a = normalise(text)
        matcher = difflib.SequenceMatcher(None, autojunk=False)
        matcher.set_seq2(a)
        lo, hi = int(len(a) * ratio / (2 - ratio)), int(len(a) * (2 - ratio) / ratio) + 1
        for n in range(lo, hi + 1):
            for b in by_len.get(n, ()):
                if b == a:
                    out.add(text)
                    break
                matcher.set_seq1(b)
                if matcher.real_quick_ratio() >= ratio and matcher.quick_ratio() >= ratio and matcher.ratio() >= ratio:
                    out.add(text)
                    break
            if text in out:
                break
    return out


def build_corpus(
    seed: int = 0,
    per_meaning: int = DEFAULT_PER_MEANING,
    concepts: Iterable[str] | None = None,
    banks: Iterable[str] = BUILT_IN_BANKS,
) -> list[Example]:
    """Template sentences and the banks' train phrasings, without any copy of a bank's val/test phrasing
    (near-copy ratio `NEAR_COPY_RATIO`), sentences repeated across meanings dropped (they teach nothing)."""
    from langpref.language.near_copies import NEAR_COPY_RATIO

    banks = tuple(banks)
    made = generate(seed, per_meaning, concepts)
    dropped = copies([e.text for e in made], excluded_texts(banks), NEAR_COPY_RATIO) if banks else set()
    examples = [e for e in made if e.text not in dropped] + bank_examples(banks)
    meanings: dict[str, set[str]] = {}
    for e in examples:
        meanings.setdefault(e.text.lower(), set()).add(e.meaning)
    return [e for e in examples if len(meanings[e.text.lower()]) == 1]


def concept_split(examples: list[Example], val_concepts: Iterable[str]) -> tuple[list[Example], list[Example]]:
    """(train, val): the val part is every sentence of the concepts `val_concepts` (concept-held-out, to choose
    settings by how the model reads meanings it never trained on)."""
    held = set(val_concepts)
    return [e for e in examples if e.concept not in held], [e for e in examples if e.concept in held]


def fingerprint(examples: list[Example]) -> str:
    """A checksum of the corpus, text and labels, in order."""
    h = hashlib.sha256()
    for e in examples:
        h.update(f"{e.text}\t{e.meaning}\t{e.source}\n".encode())
    return h.hexdigest()[:16]


__all__ = [
    "Example",
    "build_corpus",
    "bank_examples",
    "concept_split",
    "copies",
    "excluded_texts",
    "fingerprint",
    "generate",
]
