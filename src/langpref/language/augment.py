"""`langpref bank augment`: proposed extra phrasings for each meaning (feature, direction) of a bank, for a lab to
read, edit and add by hand. Nothing here writes into a bank.

The misreads of a small bank are mostly the direction of negated and indirect phrasings ("no rush", "don't dawdle",
"you're too high up"), which a bank of plain imperatives ("Move slower.") never shows. So the proposals are built from
templates over the feature's own words as the bank's train phrasings use them:

- negations of the opposite direction: the opposite's comparatives ("slower" -> "Don't be so slow.", "You're too
  slow.", "No need to be so slow."), its -ly adverbs ("Don't move so slowly.") and its short imperatives that carry no
  negation already ("Slow down." -> "Don't slow down.");
- intensifiers of the meaning's own comparatives ("Move faster." -> "Move much faster.", "Move a bit faster.");
- indirect forms ("It should be faster.", "Could you move faster?").

A comparative keeps what follows it ("closer to the button" -> "You're too close to the button."), so a distance to
one object is never proposed as a distance to another. Proposals that repeat a phrasing of the bank (any split, after
`normalise`) or each other are dropped.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from langpref.language.bank import DIRECTIONS, normalise
from langpref.language.banksource import Phrasings

OPPOSITE = {"increase": "decrease", "decrease": "increase"}
_IRREGULAR = {
    "farther": "far",
    "further": "far",
    "closer": "close",
    "wider": "wide",
    "looser": "loose",
    "safer": "safe",
    "later": "late",
    "gentler": "gentle",
    "simpler": "simple",
    "larger": "large",
    "nearer": "near",
}
_NOT_COMPARATIVE = {
    "after", "another", "border", "center", "corner", "cover", "drawer", "either", "ever", "finger", "gripper",
    "handler", "holder", "inner", "lever", "marker", "neither", "never", "number", "order", "other", "outer", "over",
    "paper", "power", "rather", "remember", "timer", "together", "under", "upper", "user", "water", "whether",
    "container", "computer", "controller", "shoulder", "cylinder", "counter", "however", "whatever", "wherever",
    "prefer", "hover", "answer", "consider", "deliver", "enter", "offer", "wonder", "bother", "gather", "register",
    "trigger", "matter", "member", "manner", "danger", "character", "monitor", "quarter", "chamber", "forever",
    "whenever", "linger", "hammer", "steer", "cheer", "sheer", "tower",
}  # fmt: skip
_DETERMINERS = {"the", "a", "an", "your", "its", "this", "that", "my", "our", "their", "his", "her"}
_NEGATIONS = re.compile(r"\b(?:not|no|never|don'?t|dont|do not|stop|avoid|less|without|nor)\b|n't\b", re.I)
_NOT_ADVERB = {
    "only", "really", "early", "likely", "fully", "nearly", "simply", "actually", "finally", "slightly", "hardly",
    "properly", "mostly", "barely", "exactly", "directly", "completely", "entirely", "partly", "mainly", "totally",
}  # fmt: skip
_PREPOSITIONS = {
    "to", "from", "above", "over", "toward", "towards", "on", "in", "off", "out", "up", "down", "back", "apart",
    "together", "away", "at", "along", "into", "onto", "under", "below", "behind", "beside", "near", "around",
}  # fmt: skip
_MODIFIERS = {"a", "bit", "lot", "much", "even", "way", "far", "little", "slightly", "somewhat", "any", "no", "still"}
_NOT_VERB_START = {
    "i", "you", "you're", "youre", "your", "the", "a", "an", "it", "its", "it's", "this", "that", "my", "we", "little",
    "bit", "much", "even", "way", "too", "not", "more", "less", "please", "next", "again", "lot", "there", "here",
    "what", "why", "how", "can", "could", "would", "should", "will", "is", "are", "at", "in", "on", "with", "by",
    "for", "to", "from", "as", "so", "very", "all", "just", "now", "then", "maybe", "perhaps", "let's", "lets", "no",
    "up", "down", "off", "out", "away", "back",
}  # fmt: skip
_NOT_IMPERATIVE = re.compile(r"\b(?:is|are|was|were|should|ought|too|i|i'm|you're|it's)\b|\?", re.I)
_INTENSIFIERS = ("much", "a lot", "a bit", "even", "way")


def _words(text: str) -> list[str]:
    return re.findall(r"[A-Za-z']+", text)


def base_of(comparative: str) -> str:
    """The plain adjective of a comparative: faster -> fast, closer -> close, bigger -> big, easier -> easy."""
    w = comparative.lower()
    if w in _IRREGULAR:
        return _IRREGULAR[w]
    stem = w[:-2]
    if w.endswith("ier"):
        return w[:-3] + "y"
    if len(stem) >= 3 and stem[-1] == stem[-2] and stem[-1] not in "aeiouls":
        return stem[:-1]
    return stem


def comparatives(text: str) -> list[tuple[str, str]]:
    """(comparative, what follows it up to the end of the clause) in a phrasing: "Get closer to the button." ->
    [("closer", "to the button")]. A word ending in -er counts unless a determiner stands before it or it is a known
    noun or preposition ("the drawer", "over")."""
    words = _words(text)
    out = []
    for i, w in enumerate(words):
        lw = w.lower()
        if not (lw.endswith("er") and len(lw) >= 5) or lw in _NOT_COMPARATIVE:
            continue
        if i > 0 and words[i - 1].lower() in _DETERMINERS:
            continue
        if i > 0 and words[i - 1].lower() in ("more", "less"):
            continue
        if i + 1 < len(words) and words[i + 1].lower() in _DETERMINERS:
            continue  # a verb: "lower the gripper"
        tail = " ".join(words[i + 1 :])
        tail = re.split(r"\b(?:please|and|but|so|than|this|next|again|as|when|while)\b", tail, maxsplit=1, flags=re.I)
        tail = tail[0].strip().rstrip(",;:")
        if tail and tail.split()[0].lower() not in _PREPOSITIONS:
            tail = ""
        out.append((lw, tail))
    return out


def is_imperative(text: str) -> bool:
    """A short phrasing that starts with a verb and says nothing else ("Slow down.", "Move faster."): safe to put
    after "Don't" or "Could you"."""
    words = _words(text)
    if not words or len(words) > 8 or _NOT_IMPERATIVE.search(text) or _NEGATIONS.search(text):
        return False
    first = words[0].lower()
    return first not in _NOT_VERB_START and not comparatives(words[0]) and not first.endswith("ly")


def adverbs(text: str) -> list[str]:
    """-ly adverbs of manner in a phrasing ("Move slowly."): at the end of the clause or before a preposition, not
    after "less" (negating "less X" is not "so X"), not degree words ("dangerously close") nor "only" or "really"."""
    words = [w.lower() for w in _words(text)]
    out = []
    for i, w in enumerate(words):
        if not (w.endswith("ly") and len(w) > 4) or w in _NOT_ADVERB:
            continue
        if i > 0 and words[i - 1] == "less":
            continue
        if i + 1 < len(words) and words[i + 1] not in _PREPOSITIONS and words[i + 1] != "please":
            continue
        out.append(w)
    return out


def _sentence(text: str) -> str:
    text = " ".join(text.split()).strip()
    return text[0].upper() + text[1:]


def _clause(text: str) -> str:
    """A phrasing as a clause to put inside a template: no final punctuation, first letter lower case."""
    text = text.strip().rstrip(".!?").strip()
    return text[:1].lower() + text[1:]


def _with(word: str, tail: str) -> str:
    return f"{word} {tail}".strip()


def negations_of(opposite: Iterable[str]) -> list[str]:
    """Phrasings that mean this meaning by negating the opposite direction's words."""
    out: list[str] = []
    for text in opposite:
        for comp, tail in comparatives(text):
            base = _with(base_of(comp), tail)
            out += [f"Don't be so {base}.", f"You're too {base}.", f"No need to be so {base}.", f"Not so {base}."]
            out.append(f"Don't go any {_with(comp, tail)}.")
        for adv in adverbs(text):
            out += [f"Don't move so {adv}.", f"Stop moving so {adv}."]
        if is_imperative(text) and len(_words(text)) <= 6 and not comparatives(text):
            out.append(f"Don't {_clause(text)}.")
    return out


def intensified(own: Iterable[str]) -> list[str]:
    """The meaning's own phrasings with an intensifier before their comparative ("Move much faster.")."""
    out: list[str] = []
    for text in own:
        found = comparatives(text)
        if not found or _NEGATIONS.search(text):
            continue
        comp = found[0][0]
        words = [w.lower() for w in _words(text)]
        at = words.index(comp) if comp in words else 0
        if at > 0 and words[at - 1] in _MODIFIERS:
            continue  # already "a bit faster", "much higher"
        pattern = re.compile(rf"\b{re.escape(comp)}\b", re.I)
        for word in _INTENSIFIERS:
            out.append(_sentence(pattern.sub(f"{word} {comp}", _clause(text), count=1)) + ".")
    return out


def indirect(own: Iterable[str]) -> list[str]:
    """Indirect forms of the meaning's own phrasings ("It should be faster.", "Could you move faster?")."""
    out: list[str] = []
    for text in own:
        for comp, tail in [] if _NEGATIONS.search(text) else comparatives(text)[:1]:
            out += [f"It should be {_with(comp, tail)}.", f"I'd like it {_with(comp, tail)}."]
        if is_imperative(text):
            out.append(f"Could you {_clause(text)}?")
    return out


def propose(
    train: Phrasings, features: Iterable[str], existing: Iterable[str] = (), per_meaning: int = 24
) -> dict[str, dict[str, list[str]]]:
    """feature -> direction -> proposed phrasings (at most `per_meaning`, negations first, then intensified and
    indirect forms), none repeating a phrasing of `existing` or of `train`, none proposed for two meanings."""
    seen = {normalise(t) for t in existing}
    seen |= {normalise(t) for by_dir in train.values() for texts in by_dir.values() for t in texts}
    out: dict[str, dict[str, list[str]]] = {}
    claimed: dict[str, tuple[str, str]] = {}
    for feature in features:
        out[feature] = {}
        for direction in DIRECTIONS:
            own = train.get(feature, {}).get(direction, [])
            opp = train.get(feature, {}).get(OPPOSITE[direction], [])
            kept: list[str] = []
            for text in [*negations_of(opp), *intensified(own), *indirect(own)]:
                key = normalise(text)
                if not key or key in seen or any(normalise(k) == key for k in kept):
                    continue
                if key in claimed and claimed[key] != (feature, direction):
                    continue
                claimed[key] = (feature, direction)
                kept.append(text)
            out[feature][direction] = _spread(kept, per_meaning)
    # a text proposed for two meanings reads as neither: drop it from both
    twice = {
        k
        for k, fd in claimed.items()
        if sum(normalise(t) == k for d in out.values() for ts in d.values() for t in ts) > 1
    }
    return {f: {d: [t for t in ts if normalise(t) not in twice] for d, ts in by.items()} for f, by in out.items()}


def _spread(texts: list[str], n: int) -> list[str]:
    """At most n of `texts`, evenly over the list (so every template kind stays represented)."""
    if len(texts) <= n:
        return texts
    step = len(texts) / n
    return [texts[int(i * step)] for i in range(n)]


__all__ = ["base_of", "comparatives", "indirect", "intensified", "negations_of", "propose"]
