"""Which phrasings of a set written apart from the bank are near-copies of a bank phrasing of the same meaning.

A set written apart (a reporting-only one, a lab's own) measures how the model reads words nobody trained it on; a
phrasing that is a train phrasing of its own meaning with a typo or a changed word ("Move fastr." for "Move
faster.") measures recall of the bank instead. Reports give the accuracy with and without them
(docs/design.md#the-command-line).

Near-copy: after lower-casing and keeping only words (letters, digits, apostrophes), difflib's similarity ratio to
some train phrasing of the same feature and direction is at least `NEAR_COPY_RATIO`. The threshold was fixed on the
older held-out set and the negated set (never a reporting-only one): at 0.9 it takes typos and one-word swaps in short
phrasings ("not so far away from the drawer" / "not so far from the drawer") and leaves rewordings apart; 0.8 also
takes a changed word in a long phrasing ("ease off the gas pedal" / "ease off the gas lever").
`evaluate --near-copy-ratio` sets it.
"""

from __future__ import annotations

import difflib
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the CLI reads NEAR_COPY_RATIO for --help, which must not import numpy
    from langpref.language.bank import Bank
    from langpref.language.pairs import Phrasings

NEAR_COPY_RATIO = 0.9


def definition(ratio: float = NEAR_COPY_RATIO) -> str:
    return f"difflib ratio >= {ratio:g} to a train phrasing of the same meaning, lower-cased, words only"


def normalise(text: str) -> str:
    """Lower case, words only (letters, digits, apostrophes), single spaces."""
    return " ".join(re.findall(r"[a-z0-9']+", text.lower()))


def similarity(a: str, b: str) -> float:
    """difflib's ratio of the normalised texts: 1 for equal, 2 * matched characters / total characters."""
    return difflib.SequenceMatcher(None, normalise(a), normalise(b), autojunk=False).ratio()


def near_copies(
    phrasings: Phrasings, bank: Bank, split: str = "train", ratio: float = NEAR_COPY_RATIO
) -> dict[str, str]:
    """{text: the bank phrasing it nearly copies} for every phrasing of `phrasings` within `ratio` of a phrasing of
    the same (feature, direction) in the bank's `split`."""
    by_meaning: dict[tuple[str, str], list[str]] = {}
    for text, feature, direction in bank.all_of_split(split):
        by_meaning.setdefault((feature, direction), []).append(text)
    out = {}
    for g, ids in enumerate(phrasings.group_ids):
        candidates = by_meaning.get(phrasings.group_name(g), [])
        for i in ids:
            text = phrasings.texts[i]
            best = max(candidates, key=lambda c: similarity(text, c), default=None)
            if best is not None and similarity(text, best) >= ratio:
                out[text] = best
    return out
