"""Recorded tasks: a task file (TOML) for a robot langpref has no simulator of, and how a dataset carries its task.

    name = "kitchen-spoon"
    description = "Pick up the spoon without passing over the pan."   # shown to participants
    features = ["speed", "height", "distance_to_pan"]
    features_from = "features.py:step_features"  # optional: f(observations, actions) -> (T, F) per-step features
    utterances = "utterances.json"                # {feature: {increase, decrease}} or {train|val|test: {...}}
    robot = "a WidowX arm"                        # optional
    examples = ["Move faster.", "Stay away from the pan."]   # optional, for the study's guidelines
    [feature_descriptions]                        # optional, one line each
    distance_to_pan = "how far the gripper stays from the pan"
    [observation]                                 # optional: names of the observation's slices, in order
    joint_pos = 7
    gripper = 1

Relative paths are relative to the task file. The observation and action sizes come from the recording itself.
A dataset made by `langpref import` stores its task as `task.json` with the (split) bank beside it, so the dataset
alone tells every later command what its task is.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.tasks.base import ObsField, Task

TASK_JSON = "task.json"
BANK_JSON = "utterances.json"
_NAME = re.compile(r"^[a-z0-9][a-z0-9_.-]{0,63}$")
_KEYS = {
    "name",
    "description",
    "features",
    "features_from",
    "utterances",
    "robot",
    "examples",
    "feature_descriptions",
    "observation",
}

StepFeatures = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class TaskFile:
    """A parsed task file: everything about the task except the sizes only the recording knows."""

    path: Path
    name: str
    description: str
    features: tuple[str, ...]
    feature_descriptions: tuple[str, ...]
    utterances: Path
    robot: str
    examples: tuple[str, ...]
    observation: tuple[tuple[str, int], ...]
    features_from: str | None

    def task(self, obs_dim: int, action_dim: int, utterances: Path) -> Task:
        """The task, with the recording's sizes and the bank file to read (the dataset's own copy)."""
        if self.observation:
            total = sum(size for _, size in self.observation)
            if total != obs_dim:
                raise LangprefError(
                    f"{self.path}: [observation] sizes add up to {total}, the recording's "
                    f"observations have {obs_dim} dims"
                )
            layout, start = [], 0
            for field, size in self.observation:
                layout.append(ObsField(field, start, start + size))
                start += size
        else:
            layout = [ObsField("observation", 0, obs_dim)]
        return Task(
            name=self.name,
            features=self.features,
            feature_descriptions=self.feature_descriptions,
            obs_layout=tuple(layout),
            action_dim=action_dim,
            description=self.description,
            utterances=utterances,
            robot=self.robot,
            examples=self.examples,
            source="recorded",
        )

    def step_features(self) -> StepFeatures | None:
        """The feature function named by `features_from`, loaded from its file; None when the task file has none."""
        if self.features_from is None:
            return None
        return load_function(self.features_from, self.path.parent, where=f"{self.path}: features_from")


def _str(raw: dict[str, Any], key: str, where: Path, default: str | None = None) -> str:
    value = raw.get(key, default)
    if not isinstance(value, str) or not value.strip():
        raise LangprefError(
            f"{where}: {key!r} must be a non-empty string" + ("" if default is not None else " (it is required)")
        )
    return value.strip()


def _str_list(raw: dict[str, Any], key: str, where: Path) -> tuple[str, ...]:
    value = raw.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, str) and v.strip() for v in value):
        raise LangprefError(f"{where}: {key!r} must be a list of non-empty strings")
    return tuple(v.strip() for v in value)


def read_task_file(path: str | Path) -> TaskFile:
    """Parse and check a task file; every problem is one line naming the file and the key."""
    path = Path(path)
    if not path.is_file():
        raise LangprefError(f"task file {path} not found" if not path.exists() else f"task file {path} is not a file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise LangprefError(f"task file {path} is not valid TOML: {exc}") from None
    unknown = sorted(set(raw) - _KEYS)
    if unknown:
        raise LangprefError(f"{path}: unknown key(s) {', '.join(unknown)}; known keys: {', '.join(sorted(_KEYS))}")
    name = _str(raw, "name", path)
    if not _NAME.match(name):
        raise LangprefError(f"{path}: name {name!r} must be lowercase letters, digits, '-', '_' or '.' (at most 64)")
    features = _str_list(raw, "features", path)
    if not features:
        raise LangprefError(f"{path}: 'features' must list at least one feature name")
    for f in features:
        if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", f):
            raise LangprefError(f"{path}: feature name {f!r} must be an identifier (letters, digits, '_')")
    if len(set(features)) != len(features):
        raise LangprefError(f"{path}: 'features' names a feature twice")
    descriptions = raw.get("feature_descriptions", {})
    if not isinstance(descriptions, dict) or not all(isinstance(v, str) for v in descriptions.values()):
        raise LangprefError(f"{path}: [feature_descriptions] must map feature names to one-line strings")
    extra = sorted(set(descriptions) - set(features))
    if extra:
        raise LangprefError(f"{path}: [feature_descriptions] describes unknown feature(s) {', '.join(extra)}")
    observation = raw.get("observation", {})
    if not isinstance(observation, dict) or not all(isinstance(v, int) and v > 0 for v in observation.values()):
        raise LangprefError(f"{path}: [observation] must map slice names to positive sizes, e.g. joint_pos = 7")
    features_from = raw.get("features_from")
    if features_from is not None and (not isinstance(features_from, str) or ":" not in features_from):
        raise LangprefError(f"{path}: 'features_from' must be 'FILE.py:FUNCTION', got {features_from!r}")
    utterances = (path.parent / _str(raw, "utterances", path)).resolve()
    if not utterances.is_file():
        raise LangprefError(f"{path}: utterances file {utterances} not found")
    return TaskFile(
        path=path,
        name=name,
        description=_str(raw, "description", path),
        features=features,
        feature_descriptions=tuple(descriptions.get(f, f.replace("_", " ")) for f in features),
        utterances=utterances,
        robot=_str(raw, "robot", path, "a robot arm"),
        examples=_str_list(raw, "examples", path),
        observation=tuple(observation.items()),
        features_from=features_from,
    )


def load_function(ref: str, base: Path, where: str) -> Callable[..., Any]:
    """`FILE.py:FUNCTION` (FILE relative to `base`) -> the function, imported from that file."""
    file_part, _, func_name = ref.rpartition(":")
    file = (base / file_part).resolve()
    if not file.is_file():
        raise LangprefError(f"{where}: {file} not found")
    module_name = f"_langpref_taskfile_{abs(hash(str(file)))}"
    spec = importlib.util.spec_from_file_location(module_name, file)
    if spec is None or spec.loader is None:
        raise LangprefError(f"{where}: {file} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        raise LangprefError(f"{where}: importing {file} failed: {type(exc).__name__}: {exc}") from None
    func = getattr(module, func_name, None)
    if not callable(func):
        raise LangprefError(f"{where}: {file.name} has no function {func_name!r}")
    return func


# ---- a task stored with its dataset or model ----------------------------------------------------------------------


def save_task(task: Task, root: Path, bank: dict[str, Any]) -> None:
    """Write `task.json` and the bank (`utterances.json`, split) into a dataset or model directory."""
    root.mkdir(parents=True, exist_ok=True)
    (root / BANK_JSON).write_text(json.dumps(bank, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    desc = {
        "name": task.name,
        "description": task.description,
        "robot": task.robot,
        "examples": list(task.examples),
        "features": list(task.features),
        "feature_descriptions": list(task.feature_descriptions),
        "obs_layout": [[f.name, f.start, f.stop] for f in task.obs_layout],
        "action_dim": task.action_dim,
    }
    (root / TASK_JSON).write_text(json.dumps(desc, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def stored_task_files(root: Path) -> dict[str, Path]:
    """The files of a task stored in `root` ({} when it has none), to carry into a model trained on it."""
    files = {name: Path(root) / name for name in (TASK_JSON, BANK_JSON)}
    return files if all(p.is_file() for p in files.values()) else {}


def load_stored_task(root: Path) -> Task | None:
    """The task stored in a dataset or model directory, or None if it has none (a built-in or plugin task)."""
    path = root / TASK_JSON
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        return Task(
            name=d["name"],
            features=tuple(d["features"]),
            feature_descriptions=tuple(d["feature_descriptions"]),
            obs_layout=tuple(ObsField(n, a, b) for n, a, b in d["obs_layout"]),
            action_dim=int(d["action_dim"]),
            description=d["description"],
            utterances=root / BANK_JSON,
            robot=d["robot"],
            examples=tuple(d["examples"]),
            source="recorded",
        )
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as exc:
        raise LangprefError(f"{path} is corrupt ({type(exc).__name__}: {exc}); import the recording again") from None


__all__ = [
    "BANK_JSON",
    "TASK_JSON",
    "TaskFile",
    "stored_task_files",
    "load_function",
    "load_stored_task",
    "read_task_file",
    "save_task",
]
