"""Scoped negation of a comparative request: find it, strip its cue, and say whether the reading flips.

Why: a sentence encoder embeds "Don't go so fast." next to "Go so fast.": the negation is one short word among
the words that name the feature, so the model reads the right feature in the wrong direction. In the latent space
the training loss puts the two directions of a feature on opposite sides (psi . (phi_B - phi_A) > 0 for one,
< 0 for the other), so a negated request reads as psi("not X") = -psi("X"). `LatentModel.encode_texts` does that
when the model's `negation` setting is on, for the texts `detect` flags; everything else is read as it is.

What counts as a cue (`CUES`, applied in order, one match = one cue):

- "there's no need to / no need for" ("No need to rush." -> "Rush.");
- "don't", "do not", "never" (a negated imperative: "Don't go so high." -> "Go high.");
- n't on an auxiliary ("You shouldn't have lifted it." -> "You should have lifted it."), "cannot";
- "not" ("Try not to sink." -> "Try to sink."), "nowhere" ("Go nowhere near the bottle."); a clause that starts
  with "Not" has no verb, and its request is a copular one ("Not so far." = "(Don't be) so far.");
- "no" before a word ("Go no higher." -> "Go higher."); before a gerund it means "stop" ("No rushing.");
- "stop", "quit", "cease" before a gerund, replaced by "keep", the request they negate ("Stop hugging the table."
  -> "Keep hugging the table."; the bare gerund "Hugging the table." reads as a description, a complaint).

A negated clause also loses its degree words ("so", "too", "such", "so much", "that" before a measure word:
`DEGREE`): "Don't go so high." becomes "Go high.", not "Go so high.". A degree word marks the behaviour the speaker
objects to as excessive, and with it the words read as that complaint ("so high" like "You're so high", which asks
for lower), the opposite of the bare request; the sign flip must apply to the bare request.

What is left alone (`Negation.reason` says which), and why: in each, the un-negated words do not make a request
whose opposite is what was meant, or the encoder cannot be trusted to read them as one.

- a sentence-initial interjection "No," / "Nope!" refuses what the robot did, it does not negate the request that
  follows ("No, faster." asks for more speed); it is skipped and the rest is read as usual;
- "rhetorical": questions and suggestions with the negation on the fronted auxiliary ("Can't you go faster?", "Why
  don't you speed up?", "Why not go faster?") ask FOR the un-negated action; exclamations of feeling ("I can't
  believe how slow you are") negate something about the speaker, not the request;
- "double": two cues in one clause: English double negatives are either cancelling ("don't stop rushing" = keep
  rushing) or negative concord ("don't go nowhere near it" = one negation), which words alone cannot tell apart;
- "enough": "not ... enough" means more ("not fast enough" = faster), the same direction as its words;
- "description": a negated report of what the robot is or did ("It isn't open.", "You didn't lift it.") names a
  shortfall, and asks for more of what it names, the same direction as its words; a report of an obligation or a
  wish ("You weren't supposed to lift it.", "I don't want it so high.") is a request and flips;
- "state": a negated copular request ("Don't be so slow.", "No need to be so close.", "Not so far."): "be slow"
  names a state, not a change, and reads as a complaint about it as often as a request for it, so its opposite is
  no reading at all (measured: docs/results.md, "Negation as a sign flip in the latent space");
- "mixed": a sentence whose clauses are not all negated ("Don't hold back, go faster.", "Go low, not high."): a
  plain clause says the request outright, and the encoder reads it; flipping the whole sentence would undo it;
- words that negate by meaning, not by syntax ("avoid", "less", "barely", "without"), are no cues: the encoder
  learns them as words from the bank, and nothing can be removed from them.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

_AUX = r"(do|does|did|is|are|was|were|could|would|should|must|have|has|had|need|might)"
_GERUND = r"(?=\w+ing\b)(?!(?:any|every|no|some)thing\b)"
CUES: tuple[tuple[str, re.Pattern[str], str], ...] = (
    ("no need", re.compile(r"\b(?:(?:there's|there is|theres)\s+)?no\s+need\s+(?:to|for)\s+", re.I), ""),
    ("not (fragment)", re.compile(r"^(\s*(?:please\s+|just\s+)?)not\s+(?=\w)(?!to\b)", re.I), r"\1be "),
    ("don't", re.compile(r"\b(?:don'?t|do\s+not|never)\s+(?=\w)", re.I), ""),
    ("can't", re.compile(r"\b(?:can'?t|cannot)\b", re.I), "can"),
    ("won't", re.compile(r"\bwon'?t\b", re.I), "will"),
    ("ain't", re.compile(r"\bain't\b", re.I), "is"),
    ("n't", re.compile(rf"\b{_AUX}n'?t\b", re.I), r"\1"),
    ("not", re.compile(r"\b(?:not|nowhere)\s+", re.I), ""),
    ("no (gerund)", re.compile(rf"\bno\s+{_GERUND}", re.I), "keep "),
    ("no", re.compile(r"\bno\s+(?=\w)", re.I), ""),
    ("stop", re.compile(rf"\b(?:stop|quit|cease)\s+{_GERUND}", re.I), "keep "),
)
"""(name, pattern, replacement) of each negation cue, in the order they are matched and removed."""

_INTERJECTION = re.compile(r"^\s*(?:(?:no|nope|nah)\s*[,!.;:\-\u2013\u2014]+\s*)+", re.I)
_CLAUSE_BREAK = re.compile(r"(\s*[,;:]\s*|(?<=[.!?])\s+|\s+[-\u2013\u2014]+\s+|\s+but\s+)", re.I)
_RHETORICAL = (
    re.compile(r"^\s*(?:why|how come)\b.*(?:\bnot\b|n'?t\b)", re.I),  # why don't you / why not
    re.compile(r"^\s*\w+n'?t\b.*\?\s*$", re.I),  # "Can't you go faster?", "Isn't it too slow?"
    re.compile(r"^\s*(?:can'?t|couldn'?t|won'?t|wouldn'?t)\s+(?:you|we|it|the)\b", re.I),
)
_IDIOM = re.compile(r"\b(?:can'?t|cannot|couldn'?t)\s+(?:believe|stand|bear|wait)\b", re.I)
_DESCRIPTION = re.compile(
    r"\b(?:is|are|was|were|am|did|does|has|have|had)(?:n'?t|\s+not)\b|'(?:s|re|m)\s+not\b"
    r"|\b(?:i|you|it|we|they|he|she)\s+(?:don'?t|do\s+not)\b",
    re.I,
)
_WANT = re.compile(r"\b(?:supposed|meant|allowed|need|needs|have to|has to|had to|want|wants|like)\b", re.I)
_ENOUGH = re.compile(r"\benough\b", re.I)
_STATE = re.compile(r"\bbe(?:ing)?\b", re.I)
_MEASURE = "many|high|low|fast|slow|slowly|quickly|far|close|near|wide|hard|long|tight|big|little|open|closed"
DEGREE = re.compile(rf"\s*\b(?:so|too|that)\s+much\b|\b(?:so|too|such)\s+(?=\w)|\bthat\s+(?=(?:{_MEASURE})\b)", re.I)
"""Degree words removed from a negated clause with its cue (module docstring)."""
_FILLER = frozenset(
    "please ok okay hey no now robot just oh well again thanks thank you come on alright right so yes yeah "
    "seriously honestly really though this next time then and but".split()
)


@dataclass(frozen=True)
class Negation:
    """What `detect` found in one text."""

    text: str
    """The text to encode: the sentence with its negation cues removed when `flip`, else the input unchanged."""
    flip: bool
    """Read the text as the opposite of `text`'s reading (psi = -psi(text))."""
    reason: str
    """Why: "negated" (flip), "none" (no cue), or the exclusion that applied: "rhetorical", "double", "enough",
    "description", "state", "mixed" (module docstring)."""


def _strip_clause(clause: str) -> tuple[str, int]:
    """`clause` with every negation cue (and, when it had one, every degree word) removed, and how many cues there
    were."""
    count = 0
    for _, pattern, replacement in CUES:
        clause, n = pattern.subn(replacement, clause)
        count += n
    if count:
        clause = re.sub(r"\bkeep\s+keeping\b", "keep", DEGREE.sub("", clause), flags=re.I)
    return clause, count


def _has_content(clause: str) -> bool:
    """Whether a clause says something beyond politeness and address ("please", "okay", "robot")."""
    words = re.findall(r"[a-z']+", clause.lower())
    return any(w not in _FILLER for w in words)


def _tidy(text: str, like: str) -> str:
    """Collapse the spaces a removed cue leaves, and start with a capital when `like` did."""
    text = re.sub(r"\s+([,.;:!?])", r"\1", re.sub(r"\s{2,}", " ", text)).strip()
    if text and like[:1].isupper():
        text = text[0].upper() + text[1:]
    return text


def detect(text: str) -> Negation:
    """Whether `text` is a scoped negation of a comparative request, and the request without its cue (module
    docstring: the cues and the exclusions)."""
    plain = " ".join(str(text).replace("\u2019", "'").split())
    body = _INTERJECTION.sub("", plain)
    if any(p.search(body) for p in _RHETORICAL) or _IDIOM.search(body):
        return Negation(text, False, "rhetorical")
    parts = _CLAUSE_BREAK.split(body)
    clauses, breaks = parts[0::2], parts[1::2]
    stripped = [_strip_clause(c) for c in clauses]
    negated = [(c, n) for c, (_, n) in zip(clauses, stripped) if n]
    if not negated:
        return Negation(text, False, "none")
    if any(n > 1 for _, n in negated):
        return Negation(text, False, "double")
    if any(_ENOUGH.search(c) for c, _ in negated):
        return Negation(text, False, "enough")
    if any(_DESCRIPTION.search(c) and not _WANT.search(c) for c, _ in negated):
        return Negation(text, False, "description")
    if any(n == 0 and _has_content(c) for c, (_, n) in zip(clauses, stripped)):
        return Negation(text, False, "mixed")
    if any(_STATE.search(s) for s, n in stripped if n):
        return Negation(text, False, "state")
    out = "".join(s + (breaks[i] if i < len(breaks) else "") for i, (s, _) in enumerate(stripped))
    return Negation(_tidy(out, plain), True, "negated")


def detect_all(texts: Sequence[str]) -> list[Negation]:
    """`detect` of each text, in order."""
    return [detect(t) for t in texts]


__all__ = ["CUES", "DEGREE", "Negation", "detect", "detect_all"]
