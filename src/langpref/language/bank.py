"""The utterance bank: comparative language feedback per task, feature and direction, with its train/val/test splits.

Each task brings its bank (`Task.utterances`): `split -> feature -> direction -> [phrasings]`. The built-in banks
start from every original utterance of the paper's Appendix E (all in `train`) plus hand-written paraphrases.
Paraphrase families stay within one split, and no val/test phrasing equals a train phrasing after `normalise`.
A recorded task's bank may come unsplit (`feature -> direction -> [phrasings]`); `split_bank` splits it by phrasing.

A user file (`--utterances FILE`) uses the plain schema of docs/design.md#utterance-files, without splits, keyed by
task name: `{"metaworld": {"speed": {"increase": ["Move faster."], "decrease": ["Move slower."]}}}`. It may give only
some features and directions; keys starting with `_` (at any level) are comments and are ignored.

Every problem with a file raises `LangprefError` with a one-line message naming the file and the offending key.
"""

from __future__ import annotations

import json
import string
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.tasks import get_task, task_names

BANK_SPLITS: tuple[str, ...] = ("train", "val", "test")
DIRECTIONS: tuple[str, ...] = ("increase", "decrease")
VAGUE_FEEDBACK: tuple[str, ...] = (
    "Not quite.",
    "Hmm, try again.",
    "Could be better.",
    "Something is off.",
    "Do it differently.",
    "I don't like it.",
)
"""What a person says when they say nothing about any feature (a synthetic human's `vague` answers); the oracle
encoder reads them as the zero vector."""
NO_CHANGE_FEEDBACK = "That's good, no change."
"""The answer "that's good, no change" (a button in the study, `no_change` in a language answer): the shown trajectory
is as the person wants it. Recorded with this text; never read by the language model (the feedback gate refuses
praise without a direction when it is typed). Typed, it is recognised as `is_no_change` reads it."""
ADDITIONS_FORMAT = "langpref-bank-additions/1"
"""The `format` of a study's bank additions file (`langpref.language.additions`), which no utterances reader takes."""
_QUOTES = str.maketrans({"\u2019": "'", "\u2018": "'", "\u02bc": "'", "\u2032": "'", "`": "'", "\u00b4": "'"})
_AROUND = " \t\r\n\u00a0\"'\u201c\u201d\u00ab\u00bb"
_FINAL = ".!\u2026\u3002\uff01"
_NO_CHANGE_KEY = "that's good, no change"


def is_no_change(text: str) -> bool:
    """Whether typed `text` is the phrase `NO_CHANGE_FEEDBACK` as people type it: in any case, with a typographic
    apostrophe (a phone's "That\u2019s"), quoted, with spaces around it or doubled inside, and with or without its
    final full stop (or "!", "..."). Only the phrase itself: "that's good, no change needed" or "that's good, no
    change?" are not it."""
    if text == NO_CHANGE_FEEDBACK:
        return True
    if len(text) > 4 * len(NO_CHANGE_FEEDBACK):
        return False
    key = unicodedata.normalize("NFKC", text).translate(_QUOTES).strip(_AROUND).rstrip(_FINAL).strip(_AROUND)
    return " ".join(key.split()).lower() == _NO_CHANGE_KEY


SPLIT_SHARES = (0.6, 0.2, 0.2)  # the paper's real-robot bank: 297/99/100 phrasings

_APOSTROPHES = {"'", "\u2019", "\u2018", "`"}


def normalise(text: str) -> str:
    """Lowercase, strip punctuation, collapse whitespace: the key under which two phrasings count as the same.

    Apostrophes are dropped ("Don't" -> "dont"); every other punctuation mark becomes a space ("end-effector" ->
    "end effector").
    """
    out = []
    for ch in text.lower():
        if ch in _APOSTROPHES:
            continue
        out.append(" " if ch in string.punctuation or unicodedata.category(ch).startswith("P") else ch)
    return " ".join("".join(out).split())


def _features(task: str) -> tuple[str, ...]:
    """The task's feature names in canonical order (a one-line error for an unknown task)."""
    return get_task(task).features


@dataclass(frozen=True)
class Bank:
    """The shipped phrasings of one env: `phrasings[split][feature][direction]` is a tuple of strings."""

    env: str
    phrasings: dict[str, dict[str, dict[str, tuple[str, ...]]]]

    @property
    def features(self) -> tuple[str, ...]:
        return _features(self.env)

    def _check_split(self, split: str) -> None:
        if split not in self.phrasings:
            raise LangprefError(f"unknown split {split!r}: choose one of {', '.join(BANK_SPLITS)}")

    def get(self, split: str, feature: str, direction: str) -> tuple[str, ...]:
        self._check_split(split)
        if feature not in self.phrasings[split]:
            raise LangprefError(
                f"unknown feature {feature!r} for env {self.env}: choose one of {', '.join(self.features)}"
            )
        if direction not in DIRECTIONS:
            raise LangprefError(f"unknown direction {direction!r}: choose one of {', '.join(DIRECTIONS)}")
        return self.phrasings[split][feature][direction]

    def all_of_split(self, split: str) -> list[tuple[str, str, str]]:
        """Every phrasing of a split as (text, feature, direction), features in canonical order, increase first."""
        self._check_split(split)
        return [
            (text, feature, direction)
            for feature in self.features
            for direction in DIRECTIONS
            for text in self.phrasings[split][feature][direction]
        ]

    def merged(self) -> dict[str, dict[str, list[str]]]:
        """feature -> direction -> the phrasings of all splits (train, val, test order), the schema of
        docs/design.md#utterance-files."""
        return {
            feature: {
                direction: [text for split in BANK_SPLITS for text in self.phrasings[split][feature][direction]]
                for direction in DIRECTIONS
            }
            for feature in self.features
        }


def _visible(obj: dict[str, Any]) -> dict[str, Any]:
    """The entries of a JSON object that are not comments (keys starting with `_`)."""
    return {k: v for k, v in obj.items() if not (isinstance(k, str) and k.startswith("_"))}


def _type_name(value: Any) -> str:
    return {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"}.get(
        type(value), type(value).__name__
    )


def _parse_texts(texts: Any, where: str, key: str) -> tuple[str, ...]:
    """Validate one list of phrasings at dotted location `key`: stripped, none empty, duplicates dropped."""
    if not isinstance(texts, list):
        raise LangprefError(f"{where}: {key} must be a list of strings, got {_type_name(texts)}")
    if not texts:
        raise LangprefError(f"{where}: {key} is an empty list; give at least one phrasing or drop the key")
    kept: list[str] = []
    for i, text in enumerate(texts):
        if not isinstance(text, str):
            raise LangprefError(f"{where}: {key}[{i}] must be a string, got {_type_name(text)}")
        text = text.strip()
        if not normalise(text):
            raise LangprefError(f"{where}: {key}[{i}] is an empty phrasing")
        if text not in kept:
            kept.append(text)
    return tuple(kept)


def _parse_phrasings(
    section: Any, env: str, where: str, key: str, *, require_all: bool, valid: tuple[str, ...] | None = None
) -> dict[str, dict[str, tuple[str, ...]]]:
    """Validate a `feature -> direction -> [phrasings]` object; `key` is its dotted location for messages."""
    if not isinstance(section, dict):
        raise LangprefError(
            f"{where}: {key} must be an object of features, got {_type_name(section)}; "
            f'e.g. {{"speed": {{"increase": ["Move faster."]}}}}'
        )
    valid = valid or _features(env)
    out: dict[str, dict[str, tuple[str, ...]]] = {}
    entries = _visible(section)
    for feature in entries:
        if feature not in valid:
            raise LangprefError(
                f"{where}: unknown feature {feature!r} at {key}.{feature}; valid features for {env}: {', '.join(valid)}"
            )
    for feature in valid:  # canonical order
        if feature not in entries:
            if require_all:
                raise LangprefError(f"{where}: {key} lacks feature {feature!r}")
            continue
        directions = entries[feature]
        fkey = f"{key}.{feature}"
        if not isinstance(directions, dict):
            raise LangprefError(
                f'{where}: {fkey} must be an object {{"increase": [...], "decrease": [...]}}, '
                f"got {_type_name(directions)}"
            )
        dentries = _visible(directions)
        for direction in dentries:
            if direction not in DIRECTIONS:
                raise LangprefError(
                    f"{where}: unknown direction {direction!r} at {fkey}.{direction}; "
                    f"valid directions: {', '.join(DIRECTIONS)}"
                )
        parsed: dict[str, tuple[str, ...]] = {}
        for direction in DIRECTIONS:
            if direction in dentries:
                parsed[direction] = _parse_texts(dentries[direction], where, f"{fkey}.{direction}")
            elif require_all:
                raise LangprefError(f"{where}: {fkey} lacks direction {direction!r}")
        if parsed:
            out[feature] = parsed
    return out


def _read_json(text: str, where: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise LangprefError(f"{where} is not valid JSON: {exc}") from None


def _check_top(data: Any, where: str) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise LangprefError(
            f'{where}: the top level must be an object like {{"metaworld": {{...}}}}, got {_type_name(data)}'
        )
    return _visible(data)


def load_user_utterances(
    path: str | Path, env: str, features: tuple[str, ...] | None = None
) -> dict[str, dict[str, tuple[str, ...]]]:
    """Read a user's utterance file (docs/design.md#utterance-files, no splits) and return `feature -> direction ->
    phrasings` for `env`: only the features and directions the file gives, in canonical order. Every section of a
    task known in this process is validated, not only `env`'s; sections of other tasks (a shared file may cover tasks
    whose dataset is not open here) are skipped, and named in the error if `env`'s own section is missing. `features`
    names the features of a task not registered in this process (a task file not imported yet)."""
    if features is None:
        _features(env)
    path = Path(path)
    where = f"utterances file {path}"
    if not path.exists():
        raise LangprefError(f"{where} not found")
    if path.is_dir():
        raise LangprefError(f"{where} is a directory, not a JSON file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise LangprefError(f"{where} is not UTF-8 text: {exc}") from None
    except OSError as exc:
        raise LangprefError(f"{where} cannot be read: {exc.strerror or exc}") from None
    data = _read_json(text, where)
    _refuse_additions(data, where, path)
    entries = _check_top(data, where)
    known = set(task_names()) | {env}
    parsed = {
        name: _parse_phrasings(section, name, where, name, require_all=False, valid=features if name == env else None)
        for name, section in entries.items()
        if name in known
    }
    if env not in parsed:
        present = ", ".join(entries) or "none"
        raise LangprefError(f"{where} has no {env!r} section (tasks present: {present})")
    if not parsed[env]:
        raise LangprefError(f"{where}: section {env!r} gives no phrasings")
    return parsed[env]


def _refuse_additions(data: Any, where: str, path: Path) -> None:
    """Refuse a study's bank additions file where an utterances file is read: its phrasings are not reviewed."""
    if isinstance(data, dict) and data.get("format") == ADDITIONS_FORMAT:
        raise LangprefError(
            f"{where} is a study's bank additions file, not reviewed: set each addition's accept to true or false, "
            f"then write the accepted ones with `langpref bank review {path} --out BANK.json` and use that file"
        )


def _parse_bank(data: Any, env: str, where: str, features: tuple[str, ...] | None = None) -> Bank:
    if not isinstance(data, dict):
        raise LangprefError(f"{where}: the top level must be an object of splits, got {_type_name(data)}")
    splits = _visible(data)
    for split in splits:
        if split not in BANK_SPLITS:
            raise LangprefError(f"{where}: unknown split {split!r}; valid splits: {', '.join(BANK_SPLITS)}")
    phrasings: dict[str, dict[str, dict[str, tuple[str, ...]]]] = {}
    for split in BANK_SPLITS:
        if split not in splits:
            raise LangprefError(f"{where}: the bank lacks split {split!r}")
        phrasings[split] = _parse_phrasings(splits[split], env, where, split, require_all=True, valid=features)
    # No phrasing twice in a task (after normalise), so no val/test phrasing equals a train one.
    seen: dict[str, str] = {}
    for split in BANK_SPLITS:
        for feature, by_direction in phrasings[split].items():
            for direction, texts in by_direction.items():
                for text in texts:
                    key = normalise(text)
                    here = f"{split}.{feature}.{direction}"
                    if key in seen:
                        raise LangprefError(f"{where}: {text!r} at {here} repeats a phrasing at {seen[key]}")
                    seen[key] = here
    return Bank(env=env, phrasings=phrasings)


def load_bank(env: str) -> Bank:
    """The bank of task `env`, all splits, validated."""
    source = get_task(env).utterances
    where = f"utterance bank of task {env} ({source})"
    try:
        text = source.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{where} cannot be read ({exc})") from None
    return _parse_bank(_read_json(text, where), env, where)


def check_bank(data: Any, task: str, features: tuple[str, ...], where: str) -> None:
    """Check a split bank for a task not registered yet (`langpref import` checks before it writes anything)."""
    _parse_bank(data, task, where, features)


def split_bank(path: Path, features: tuple[str, ...], seed: int = 0) -> dict[str, Any]:
    """A task file's bank as `{train, val, test: {feature: {direction: [...]}}}`, ready to store with a dataset.

    A bank given with `train`/`val`/`test` keys is used as given. An unsplit one (`{feature: {direction: [...]}}`)
    is split by phrasing, seeded, in the paper's proportions (60/20/20), so every feature and direction has at least
    one phrasing in every split; it then needs at least three distinct phrasings per feature and direction.
    Phrasings are checked as every bank is (features, directions, no repeats) when the dataset's task is loaded.
    """
    where = f"utterances file {path}"
    try:
        data = _read_json(path.read_text(encoding="utf-8"), where)
    except (OSError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{where} cannot be read ({exc})") from None
    if not isinstance(data, dict):
        raise LangprefError(f"{where}: the top level must be an object, got {_type_name(data)}")
    data = _visible(data)
    if set(data) & set(BANK_SPLITS):
        return data
    out: dict[str, Any] = {split: {} for split in BANK_SPLITS}
    rng = np.random.default_rng([seed, 7])
    for feature in features:
        if feature not in data or not isinstance(data[feature], dict):
            raise LangprefError(
                f"{where}: no phrasings for feature {feature!r} (the task's features: {', '.join(features)})"
            )
        for split in BANK_SPLITS:
            out[split][feature] = {}
        for direction in DIRECTIONS:
            texts = data[feature].get(direction)
            if not isinstance(texts, list) or not all(isinstance(x, str) for x in texts):
                raise LangprefError(f"{where}: {feature}.{direction} must be a list of phrasings")
            distinct: dict[str, str] = {}
            for text in texts:
                distinct.setdefault(normalise(text), text.strip())
            distinct.pop("", None)
            unique = list(distinct.values())
            if len(unique) < 3:
                raise LangprefError(
                    f"{where}: {feature}.{direction} has {len(unique)} distinct phrasing(s); an "
                    "unsplit bank needs at least 3 per feature and direction (one per split)"
                )
            order = [unique[i] for i in rng.permutation(len(unique))]
            n_val = max(1, round(len(order) * SPLIT_SHARES[1]))
            n_test = max(1, round(len(order) * SPLIT_SHARES[2]))
            n_train = len(order) - n_val - n_test
            parts = {
                "train": order[:n_train],
                "val": order[n_train : n_train + n_val],
                "test": order[n_train + n_val :],
            }
            for split in BANK_SPLITS:
                out[split][feature][direction] = parts[split]
    unknown = sorted(set(data) - set(features))
    if unknown:
        raise LangprefError(
            f"{where}: unknown feature(s) {', '.join(unknown)}; the task's features: {', '.join(features)}"
        )
    return out


__all__ = [
    "DIRECTIONS",
    "BANK_SPLITS",
    "Bank",
    "load_bank",
    "load_user_utterances",
    "normalise",
    "is_no_change",
    "check_bank",
    "split_bank",
]
