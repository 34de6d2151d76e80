"""Which bank a `langpref bank ...` command reads: a task's name, a dataset (whose task brings the bank), or a task file
(TOML, before `langpref import`, so a lab can check its phrasings before it records or imports anything).

All three give the same `BankSource`: the task, its features, the bank as `split -> feature -> direction -> [text]`,
and the files that must never be written over (the bank file itself, the task file).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from langpref.errors import LangprefError
from langpref.language.bank import BANK_SPLITS, DIRECTIONS

Phrasings = dict[str, dict[str, list[str]]]
"""feature -> direction -> phrasings."""


@dataclass(frozen=True)
class BankSource:
    """A task's bank as read from its name, a dataset or a task file."""

    task: str
    features: tuple[str, ...]
    splits: dict[str, Phrasings]
    """split -> feature -> direction -> phrasings (every split, every feature and direction, maybe empty lists)."""
    protected: tuple[Path, ...]
    """Files a command must never write: the bank file and, for a task file, the task file itself."""
    origin: str
    """What was opened, for messages: 'task metaworld', 'dataset DIR', 'task file FILE'."""

    def split(self, name: str) -> Phrasings:
        return self.splits[name]


def _filled(raw: dict, features: tuple[str, ...], where: str = "the bank") -> dict[str, Phrasings]:
    """Every split, feature and direction present (missing ones as empty lists), texts stripped."""
    try:
        return _fill(raw, features)
    except (AttributeError, TypeError):
        raise LangprefError(
            f"{where} is not a bank of the utterance schema: "
            "{split: {feature: {increase: [...], decrease: [...]}}}"
        ) from None


def _fill(raw: dict, features: tuple[str, ...]) -> dict[str, Phrasings]:
    return {
        split: {
            f: {d: [str(t).strip() for t in raw.get(split, {}).get(f, {}).get(d, [])] for d in DIRECTIONS}
            for f in features
        }
        for split in BANK_SPLITS
    }


def _as_path(obj) -> Path | None:
    try:
        return Path(str(obj)).resolve()
    except (TypeError, ValueError):
        return None


def open_bank(where: str | Path, seed: int = 0) -> BankSource:
    """The bank of a task name, a dataset directory or a task file (TOML; an unsplit bank is split with `seed`, as
    `langpref import --seed` would). One line naming what is wrong otherwise."""
    from langpref.language.bank import load_bank
    from langpref.tasks import get_task

    path = Path(where)
    if path.suffix == ".toml" or path.is_file():
        from langpref.language.bank import split_bank
        from langpref.tasks.taskfile import read_task_file

        if path.suffix != ".toml":
            raise LangprefError(f"{path} is a file but not a task file (.toml); give a task name, dataset or task file")
        tf = read_task_file(path)
        raw = split_bank(tf.utterances, tf.features, seed=seed)
        return BankSource(
            tf.name,
            tf.features,
            _filled(raw, tf.features, f"utterances file {tf.utterances}"),
            (tf.utterances.resolve(), path.resolve()),
            f"task file {path}",
        )
    if path.is_dir():
        if not (path / "meta.json").is_file():
            raise LangprefError(f"{path} is a directory but not a langpref dataset (no meta.json)")
        from langpref.dataset.storage import load_dataset

        dataset = load_dataset(path)
        name, origin = dataset.env, f"dataset {path}"
    elif any(sep in str(where) for sep in ("/", "\\")):
        raise LangprefError(f"{where} not found: give a task name, a dataset directory or a task file (.toml)")
    else:
        name, origin = str(where), f"task {where}"
    bank = load_bank(name)
    raw = {s: {f: {d: list(bank.phrasings[s][f][d]) for d in DIRECTIONS} for f in bank.features} for s in BANK_SPLITS}
    file = _as_path(get_task(name).utterances)
    return BankSource(name, bank.features, _filled(raw, bank.features), (file,) if file else (), origin)


__all__ = ["BankSource", "Phrasings", "open_bank"]
