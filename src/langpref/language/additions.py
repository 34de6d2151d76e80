"""Phrasings a study suggests for a task's bank, and the lab's review of them.

With `study serve --confirm-margin`, a participant whose sentence the model reads uncertainly clicks what they
meant among three offered meanings. `langpref study export --bank-additions FILE` gathers those sentences with the
meaning clicked. A click is not a label: a participant may click any offered meaning, two may disagree, and some
sentences name no change of any feature ("No change."). So the export writes a file to review, not a bank:

    {"format": "langpref-bank-additions/1", "task": TASK, "source": {"db": ..., "model": ..., ...},
     "additions": [{"text": "No rush.", "feature": "speed", "direction": "decrease", "count": 2,
                    "participants": [3, 7], "confirmations": [{"participant": 3, "query": 4, "seq": 17,
                    "shown": 12, "margin": 0.04, "rank": 2, "p": 0.31, "answered_at": "2026-..."}, ...],
                    "flags": ["conflict: also confirmed as speed/increase (x1)"], "accept": null}, ...]}

An addition is one text (as `bank.normalise` keys it) under one meaning: how many confirmations chose it, by which
participants (their numbers), and each confirmation's query, the reading's margin and the rank and probability of
the meaning chosen among the options (rank 1: the model's own top reading). Flags (`flags_of`): `conflict`, the same
text confirmed under another meaning or as "none of these"; `no change`, a text that names no change; `bank conflict`,
the task's bank holds it under another meaning; `in bank`, it holds it under this one (nothing to add).

The file is not an utterances file: every `--utterances` reader refuses it (`bank.load_user_utterances`). The lab
decides each addition, `"accept": true` or `false`, and `langpref bank review FILE --out BANK` (`review`) writes the
accepted ones as an utterances file (docs/design.md#utterance-files), which `bank check --utterances`, `train
--utterances` and the rest read. It refuses while an addition is undecided (`--accept-unflagged` accepts the
undecided ones without flags; a flagged one always needs the lab's word) and a text accepted under two meanings.
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.language.bank import ADDITIONS_FORMAT as FORMAT
from langpref.language.bank import DIRECTIONS, is_no_change, normalise

_SAYS_NO_CHANGE = re.compile(
    r"\b(no|without|zero) changes?\b|\b(dont|do not) change\b|\bnothing to change\b|\b(keep|leave) it( as it is)?$"
    r"|^(good|great|perfect|fine|ok|okay|nice|same)( job| work)?$|^as it is$"
)
"""What a text that names no change of the motion looks like, after `normalise` (apostrophes dropped)."""


def says_no_change(text: str) -> bool:
    """Whether `text` names no change of the robot's motion ("No change.", "Keep it as it is.", "Perfect."): such a
    text is no feature's meaning, whatever a participant clicked."""
    return is_no_change(text) or bool(_SAYS_NO_CHANGE.search(normalise(text)))


def meaning_name(feature: str, direction: str) -> str:
    return f"{feature}/{direction}"


def gather(confirmations: Iterable[Mapping[str, Any]]) -> tuple[list[dict[str, Any]], dict[str, dict[str, int]]]:
    """The additions of confirmation rows (each with `text`, `feature` and `direction`, both None for "none of
    these", and its provenance, `participant` ...), one per (normalised text, meaning) in order of first
    confirmation; and per normalised text the count of each meaning chosen (`"none of these"` included)."""
    additions: dict[tuple[str, str], dict[str, Any]] = {}
    chosen: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for row in confirmations:
        key = normalise(row["text"])
        if not key:
            continue
        if row["feature"] is None:
            chosen[key]["none of these"] += 1
            continue
        meaning = meaning_name(row["feature"], row["direction"])
        chosen[key][meaning] += 1
        entry = additions.setdefault(
            (key, meaning),
            {"text": row["text"], "feature": row["feature"], "direction": row["direction"], "confirmations": []},
        )
        entry["confirmations"].append({k: v for k, v in row.items() if k not in ("text", "feature", "direction")})
    out = []
    for entry in additions.values():
        people = [c["participant"] for c in entry["confirmations"]]
        entry["count"] = len(people)
        entry["participants"] = sorted(set(people), key=lambda p: (p is None, p))
        out.append(entry)
    return out, {k: dict(v) for k, v in chosen.items()}


def flags_of(entry: Mapping[str, Any], chosen: Mapping[str, int], bank: Mapping[str, str] | None) -> list[str]:
    """What the lab should look at before accepting `entry`: the other meanings (or "none of these") its text was
    confirmed as (`chosen`: meaning -> count, for its text), a text that names no change, and where the task's bank
    (`bank`: normalised text -> meaning) holds it."""
    own = meaning_name(entry["feature"], entry["direction"])
    flags = []
    others = {m: n for m, n in chosen.items() if m != own}
    if others:
        said = ", ".join(f"{m} (x{n})" for m, n in sorted(others.items()))
        flags.append(f"conflict: also confirmed as {said}")
    if says_no_change(entry["text"]):
        flags.append("no change: the text names no change of the motion, so no feature's meaning")
    held = None if bank is None else bank.get(normalise(entry["text"]))
    if held is not None and held != own:
        flags.append(f"bank conflict: the task's bank has it as {held}")
    elif held is not None:
        flags.append("in bank: the task's bank has it already (nothing to add)")
    return flags


def additions_file(
    task: str, confirmations: Iterable[Mapping[str, Any]], bank: Mapping[str, str] | None, source: Mapping[str, Any]
) -> dict[str, Any]:
    """The review file (module docstring) of a study's `confirmations` of task `task`; `bank` (normalised text ->
    meaning; None: not known here) flags texts the bank holds; `source` says where they come from."""
    entries, chosen = gather(confirmations)
    for entry in entries:
        entry["flags"] = flags_of(entry, chosen[normalise(entry["text"])], bank)
        entry["accept"] = None
    order = ("text", "feature", "direction", "count", "participants", "flags", "accept", "confirmations")
    return {
        "_comment": (
            "Phrasings study participants typed, with the meaning they then clicked (langpref study export "
            "--bank-additions). A click is not a label: read each, with its flags, set accept to true or false, "
            "then write the accepted ones as an utterances file with `langpref bank review THIS_FILE --out BANK` "
            "(this file is not one, and no command reads it as one)."
        ),
        "format": FORMAT,
        "task": task,
        "source": dict(source),
        "additions": [{k: e[k] for k in order} for e in entries],
    }


def bank_meanings(phrasings: Mapping[str, Mapping[str, Mapping[str, Iterable[str]]]]) -> dict[str, str]:
    """normalised text -> meaning of every phrasing of a bank (`split -> feature -> direction -> texts`)."""
    return {
        normalise(t): meaning_name(f, d)
        for by_feature in phrasings.values()
        for f, by_direction in by_feature.items()
        for d, texts in by_direction.items()
        for t in texts
    }


def load_additions(path: str | Path) -> dict[str, Any]:
    """A bank additions file, its shape checked; one line naming the file when it is not one."""
    where = f"bank additions file {path}"
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LangprefError(f"{where} not found") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise LangprefError(f"{where} cannot be read as JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise LangprefError(f"{where} is not one (`study export --bank-additions` writes them; format {FORMAT})")
    if not isinstance(data.get("task"), str) or not isinstance(data.get("additions"), list):
        raise LangprefError(f"{where}: needs a task name and a list of additions")
    for k, entry in enumerate(data["additions"]):
        ok = isinstance(entry, dict) and isinstance(entry.get("text"), str) and entry.get("direction") in DIRECTIONS
        if not ok or not isinstance(entry.get("feature"), str) or not isinstance(entry.get("flags", []), list):
            raise LangprefError(f"{where}: addition {k} needs text, feature, direction (increase|decrease), flags")
        if entry.get("accept") not in (None, True, False):
            raise LangprefError(f"{where}: addition {k} ({entry['text']!r}): accept must be true, false or null")
    return data


def review(data: Mapping[str, Any], accept_unflagged: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """The accepted additions of a checked additions file (`load_additions`) as an utterances file
    (`{task: {feature: {direction: [texts]}}}`, with a `_comment` naming its review), and what the review decided.
    Refused (one line) while an addition is undecided (with `accept_unflagged`, one without flags is accepted) or
    when one text is accepted under two meanings."""
    decided = []
    for entry in data["additions"]:
        accept = entry.get("accept")
        if accept is None and accept_unflagged and not entry.get("flags"):
            accept = True
        decided.append((entry, accept))
    undecided = [e for e, a in decided if a is None]
    if undecided:
        flagged = sum(bool(e.get("flags")) for e in undecided)
        raise LangprefError(
            f"{len(undecided)} additions are undecided ({flagged} flagged), e.g. {undecided[0]['text']!r}: set "
            "accept to true or false in the file" + ("" if accept_unflagged else " (or pass --accept-unflagged)")
        )
    accepted = [e for e, a in decided if a]
    _refuse_two_meanings(accepted)
    section: dict[str, dict[str, list[str]]] = {}
    for entry in accepted:
        if not any(f.startswith("in bank") for f in entry.get("flags", [])):
            section.setdefault(entry["feature"], {}).setdefault(entry["direction"], []).append(entry["text"])
    task = data["task"]
    source = data.get("source") or {}
    note = (
        f"Phrasings of a study ({source.get('db', '?')}) reviewed with `langpref bank review`: {len(accepted)} of "
        f"{len(decided)} additions accepted."
    )
    report = {
        "task": task,
        "additions": len(decided),
        "accepted": len(accepted),
        "rejected": sum(a is False for _, a in decided),
        "written": sum(len(t) for d in section.values() for t in d.values()),
        "flagged_accepted": sum(bool(e.get("flags")) for e in accepted),
    }
    return {"_comment": note, task: section}, report


def _refuse_two_meanings(accepted: list[Mapping[str, Any]]) -> None:
    """One text accepted under two meanings contradicts itself: refused, naming both."""
    seen: dict[str, str] = {}
    for entry in accepted:
        key, meaning = normalise(entry["text"]), meaning_name(entry["feature"], entry["direction"])
        if seen.setdefault(key, meaning) != meaning:
            raise LangprefError(
                f"{entry['text']!r} is accepted as both {seen[key]} and {meaning}: accept at most one of them"
            )
