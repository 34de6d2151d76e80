"""Recorded answers of real people, one JSON object per line (JSON Lines): what `langpref study export` writes as
`answers.jsonl`, what another UI or a spreadsheet can write, and what `langpref learn-reward --answers FILE` learns a
reward from (`langpref.reward.recorded`).

    {"kind": "language", "shown": 12, "text": "Move faster.", "participant": "P1"}
    {"kind": "language", "shown": "episode_0007", "no_change": true, "participant": "P1"}
    {"kind": "language", "shown": 3, "text": "Slow down.", "meaning": {"feature": "speed", "direction": "decrease"}}
    {"kind": "comparison", "shown": [3, 7], "choice": 0, "participant": "P2"}

Fields:
- `kind`: `language` (one trajectory shown, a sentence back), `comparison` (two shown, one chosen), or an installed
  kind's name (its other fields are its own study record's, `FeedbackKind.from_record`).
- `shown`: the trajectory shown (language) or the pair (comparison, in the order shown), each by dataset index
  (`langpref inspect`) or by the recording's episode name (the file stem `langpref import` read it from).
- `text` (language): what the person said; or `"no_change": true` when they said it is good as it is.
- `choice` (comparison): 0 the first of `shown` was preferred, 1 the second.
- optional: `meaning` `{"feature", "direction"}` when the person confirmed what they meant (it replaces the model's
  reading), `participant` (default `anonymous`), `method` (the study's method name; default the kind), `number`
  (the query's number within the participant's method), `time` (any text, e.g. ISO 8601).

Lines that are empty are skipped; anything else that is not one answer is an error naming its line.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind, kind_names
from langpref.language.bank import DIRECTIONS

ANONYMOUS = "anonymous"
OPTIONAL = ("meaning", "participant", "method", "number", "time")


@dataclass(frozen=True)
class RecordedAnswer:
    """One answer of the file: the kind's typed answer, with who gave it and what they confirmed it meant."""

    kind: str
    answer: Any
    participant: str = ANONYMOUS
    method: str | None = None
    number: int | None = None
    meaning: tuple[str, str] | None = None
    """(feature name, direction) the person confirmed; None: read by the model."""
    time: str | None = None
    line: int = 0

    @property
    def group(self) -> str:
        """The study method the answer belongs to (its kind when none was recorded)."""
        return self.method or self.kind


def answer_record(
    kind: str,
    answer: Any,
    participant: str = ANONYMOUS,
    *,
    method: str | None = None,
    number: int | None = None,
    meaning: tuple[str, str] | None = None,
    time: str | None = None,
) -> dict[str, Any]:
    """One line of the file (as a dict) for a kind's typed answer."""
    known = get_kind(kind)
    body = dict((known.to_line or known.to_record)(answer))
    record = {"kind": kind, **body, "participant": participant}
    extra = {"method": method if method != kind else None, "number": number, "time": time}
    record.update({k: v for k, v in extra.items() if v is not None})
    if meaning is not None:
        record["meaning"] = {"feature": meaning[0], "direction": meaning[1]}
    return record


def write_answers(path: str | Path, records: Iterable[dict[str, Any]]) -> int:
    """Write `records` (`answer_record`s) as JSON Lines; how many."""
    lines = [json.dumps(r, ensure_ascii=False) for r in records]
    Path(path).write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return len(lines)


class _Resolver:
    """Dataset index of a trajectory named by index or by its recording's episode name."""

    def __init__(self, num_trajectories: int, episodes: Callable[[], Sequence[str | None]] | None):
        self.n = num_trajectories
        self.episodes = episodes
        self._names: dict[str, int] | None = None

    def __call__(self, value: Any, where: str) -> int:
        if isinstance(value, bool):
            raise LangprefError(f"{where}: a trajectory is a dataset index or an episode name, not {value!r}")
        if isinstance(value, int):
            if not 0 <= value < self.n:
                raise LangprefError(f"{where}: trajectory {value} is not in the dataset (indices 0..{self.n - 1})")
            return value
        if isinstance(value, str) and value:
            if self._names is None:
                names = self.episodes() if self.episodes is not None else ()
                self._names = {name: i for i, name in enumerate(names) if name is not None}
            if value not in self._names:
                known = ", ".join(list(self._names)[:3])
                raise LangprefError(
                    f"{where}: no episode named {value!r} in the dataset"
                    + (f" (its episodes are named like {known})" if known else " (it has no recorded episode names)")
                )
            return self._names[value]
        raise LangprefError(f"{where}: a trajectory is a dataset index or an episode name, not {value!r}")


def _meaning(obj: dict[str, Any], where: str, features: Sequence[str]) -> tuple[str, str] | None:
    meaning = obj.get("meaning")
    if meaning is None:
        return None
    if (
        not isinstance(meaning, dict)
        or meaning.get("feature") not in features
        or meaning.get("direction") not in DIRECTIONS
    ):
        raise LangprefError(
            f'{where}: \'meaning\' is {{"feature": one of {", ".join(features)}, "direction": increase or decrease}}'
        )
    return meaning["feature"], meaning["direction"]


def _parse_line(obj: Any, where: str, line: int, resolve: _Resolver, features: Sequence[str]) -> RecordedAnswer:
    if not isinstance(obj, dict):
        raise LangprefError(f"{where}: an answer is a JSON object, got {type(obj).__name__}")
    kind = obj.get("kind")
    if kind not in kind_names():
        raise LangprefError(f"{where}: 'kind' must be one of {', '.join(kind_names())}, got {kind!r}")
    read_line = get_kind(kind).from_line
    if read_line is not None:  # the kind reads its own line, trajectories named by index or episode name
        answer = read_line(obj, where, resolve)
    else:
        try:
            answer = get_kind(kind).from_record(obj)
        except (KeyError, TypeError, ValueError) as exc:
            raise LangprefError(f"{where}: not a {kind} answer ({exc})") from None
    participant, number = obj.get("participant", ANONYMOUS), obj.get("number")
    if not isinstance(participant, str | int) or isinstance(participant, bool) or str(participant) == "":
        raise LangprefError(f"{where}: 'participant' must be a name or a number")
    if number is not None and (isinstance(number, bool) or not isinstance(number, int)):
        raise LangprefError(f"{where}: 'number' must be an integer")
    method, time = obj.get("method"), obj.get("time")
    return RecordedAnswer(
        kind,
        answer,
        str(participant),
        None if method is None else str(method),
        number,
        _meaning(obj, where, features),
        None if time is None else str(time),
        line,
    )


def read_answers(
    path: str | Path,
    num_trajectories: int,
    features: Sequence[str],
    episodes: Callable[[], Sequence[str | None]] | None = None,
) -> list[RecordedAnswer]:
    """The answers of a JSON Lines file (module docstring), trajectories checked against a dataset of
    `num_trajectories` whose recorded episode names `episodes()` gives (called only when an answer names one; None:
    by index only) and meanings against its `features`. One-line errors naming the line; an empty file is an error
    (nothing to learn from)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise LangprefError(f"no answers file at {path}") from None
    except IsADirectoryError:
        raise LangprefError(
            f"{path} is a folder; pass the answers file (JSON Lines), e.g. an export's answers.jsonl"
        ) from None
    except UnicodeDecodeError:
        raise LangprefError(f"{path} is not a text file of answers (JSON Lines)") from None
    resolve = _Resolver(num_trajectories, episodes)
    answers = []
    for i, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        where = f"{path} line {i}"
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as exc:
            raise LangprefError(f"{where}: not JSON ({exc.msg}); the file holds one JSON object per line") from None
        answers.append(_parse_line(obj, where, i, resolve, features))
    if not answers:
        raise LangprefError(f"{path} holds no answers")
    return answers


def parse_records(
    records: Sequence[dict[str, Any]], num_trajectories: int, features: Sequence[str]
) -> list[RecordedAnswer]:
    """`answer_record`s (as written, by dataset index) read back as answers."""
    resolve = _Resolver(num_trajectories, None)
    return [_parse_line(r, f"answer {i}", i, resolve, features) for i, r in enumerate(records, start=1)]
