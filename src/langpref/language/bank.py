"""The utterance bank: comparative language feedback per env, feature and direction, with its train/val/test splits.

The shipped bank (`language/data/utterances.json`) holds, per env, `split -> feature -> direction -> [phrasings]`.
It starts from every original utterance of the paper's Appendix E (all in `train`) plus hand-written paraphrases.
Paraphrase families stay within one split, and no val/test phrasing equals a train phrasing after `normalise`.

A user file (`--utterances FILE`) uses the plain schema of DESIGN.md, without splits:
`{"metaworld": {"speed": {"increase": ["Move faster."], "decrease": ["Move slower."]}}}`. It may give only some
features and directions; keys starting with `_` (at any level) are comments and are ignored.

Every problem with a file raises `LangprefError` with a one-line message naming the file and the offending key.
"""

from __future__ import annotations

import json
import string
import unicodedata
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

SPLITS: tuple[str, ...] = ("train", "val", "test")
DIRECTIONS: tuple[str, ...] = ("increase", "decrease")

# Canonical feature names, in canonical order. This mirrors `langpref.envs.get_spec(env).features` (a test checks
# that they agree); it is repeated here so the language data can be loaded without importing the simulators' code.
FEATURES: dict[str, tuple[str, ...]] = {
    "metaworld": ("height", "speed", "distance_to_button"),
    "robosuite": ("height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success"),
}

_BANK_RESOURCE = ("data", "utterances.json")
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


def _check_env(env: str) -> None:
    if env not in FEATURES:
        raise LangprefError(f"unknown env {env!r}: choose one of {', '.join(FEATURES)}")


@dataclass(frozen=True)
class Bank:
    """The shipped phrasings of one env: `phrasings[split][feature][direction]` is a tuple of strings."""

    env: str
    phrasings: dict[str, dict[str, dict[str, tuple[str, ...]]]]

    @property
    def features(self) -> tuple[str, ...]:
        return FEATURES[self.env]

    def _check_split(self, split: str) -> None:
        if split not in self.phrasings:
            raise LangprefError(f"unknown split {split!r}: choose one of {', '.join(SPLITS)}")

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
        """feature -> direction -> the phrasings of all splits (train, val, test order): DESIGN.md's schema."""
        return {
            feature: {
                direction: [text for split in SPLITS for text in self.phrasings[split][feature][direction]]
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


def _parse_phrasings(
    section: Any, env: str, where: str, key: str, *, require_all: bool
) -> dict[str, dict[str, tuple[str, ...]]]:
    """Validate a `feature -> direction -> [phrasings]` object; `key` is its dotted location for messages."""
    if not isinstance(section, dict):
        raise LangprefError(
            f"{where}: {key} must be an object of features, got {_type_name(section)}; "
            f'e.g. {{"speed": {{"increase": ["Move faster."]}}}}'
        )
    valid = FEATURES[env]
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
                f"{where}: {fkey} must be an object {{\"increase\": [...], \"decrease\": [...]}}, "
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
            dkey = f"{fkey}.{direction}"
            if direction not in dentries:
                if require_all:
                    raise LangprefError(f"{where}: {fkey} lacks direction {direction!r}")
                continue
            texts = dentries[direction]
            if not isinstance(texts, list):
                raise LangprefError(f"{where}: {dkey} must be a list of strings, got {_type_name(texts)}")
            if not texts:
                raise LangprefError(f"{where}: {dkey} is an empty list; give at least one phrasing or drop the key")
            kept: list[str] = []
            for i, text in enumerate(texts):
                if not isinstance(text, str):
                    raise LangprefError(f"{where}: {dkey}[{i}] must be a string, got {_type_name(text)}")
                text = text.strip()
                if not normalise(text):
                    raise LangprefError(f"{where}: {dkey}[{i}] is an empty phrasing")
                if text not in kept:
                    kept.append(text)
            parsed[direction] = tuple(kept)
        if parsed:
            out[feature] = parsed
    return out


def _read_json(text: str, where: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise LangprefError(f"{where} is not valid JSON: {exc}") from None


def _check_top(data: Any, where: str, allowed: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise LangprefError(
            f'{where}: the top level must be an object like {{"metaworld": {{...}}}}, got {_type_name(data)}'
        )
    entries = _visible(data)
    for key in entries:
        if key not in allowed:
            raise LangprefError(f"{where}: unknown env key {key!r}; valid envs: {', '.join(allowed)}")
    return entries


def load_user_utterances(path: str | Path, env: str) -> dict[str, dict[str, tuple[str, ...]]]:
    """Read a user's utterance file (DESIGN.md schema, no splits) and return `feature -> direction -> phrasings`
    for `env`: only the features and directions the file gives, in canonical order. Every env section present in the
    file is validated, not only `env`'s."""
    _check_env(env)
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
    entries = _check_top(_read_json(text, where), where, tuple(FEATURES))
    parsed = {
        name: _parse_phrasings(section, name, where, name, require_all=False) for name, section in entries.items()
    }
    if env not in parsed:
        present = ", ".join(parsed) or "none"
        raise LangprefError(f"{where} has no {env!r} section (envs present: {present})")
    if not parsed[env]:
        raise LangprefError(f"{where}: section {env!r} gives no phrasings")
    return parsed[env]


def _bank_text() -> tuple[str, str]:
    ref = resources.files("langpref.language").joinpath(*_BANK_RESOURCE)
    where = f"shipped utterance bank {'/'.join(('langpref', 'language') + _BANK_RESOURCE)}"
    try:
        return ref.read_text(encoding="utf-8"), where
    except (OSError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{where} cannot be read ({exc}); reinstall langpref") from None


def _parse_bank(data: Any, env: str, where: str) -> Bank:
    entries = _check_top(data, where, tuple(FEATURES))
    if env not in entries:
        raise LangprefError(f"{where} has no {env!r} section")
    section = entries[env]
    if not isinstance(section, dict):
        raise LangprefError(f"{where}: {env} must be an object of splits, got {_type_name(section)}")
    splits = _visible(section)
    for split in splits:
        if split not in SPLITS:
            raise LangprefError(f"{where}: unknown split {split!r} at {env}.{split}; valid splits: {', '.join(SPLITS)}")
    phrasings: dict[str, dict[str, dict[str, tuple[str, ...]]]] = {}
    for split in SPLITS:
        if split not in splits:
            raise LangprefError(f"{where}: {env} lacks split {split!r}")
        phrasings[split] = _parse_phrasings(splits[split], env, where, f"{env}.{split}", require_all=True)
    # No phrasing twice in an env (after normalise), so no val/test phrasing equals a train one.
    seen: dict[str, str] = {}
    for split in SPLITS:
        for feature, by_direction in phrasings[split].items():
            for direction, texts in by_direction.items():
                for text in texts:
                    key = normalise(text)
                    here = f"{env}.{split}.{feature}.{direction}"
                    if key in seen:
                        raise LangprefError(f"{where}: {text!r} at {here} repeats a phrasing at {seen[key]}")
                    seen[key] = here
    return Bank(env=env, phrasings=phrasings)


def load_bank(env: str) -> Bank:
    """The phrasings shipped with langpref for `env`, all splits, validated."""
    _check_env(env)
    text, where = _bank_text()
    return _parse_bank(_read_json(text, where), env, where)


__all__ = ["DIRECTIONS", "FEATURES", "SPLITS", "Bank", "load_bank", "load_user_utterances", "normalise"]
