"""The task registry: built-ins by name, plugins through entry points (a broken one skipped with a warning), recorded
tasks registered by the datasets and models that carry them."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

import langpref.registry
import langpref.tasks as tasks
from langpref.errors import LangprefError
from langpref.tasks import get_simulator, get_task, register_task, task_names
from langpref.tasks.base import ObsField, Task


def _task(name: str, path: Path) -> Task:
    return Task(
        name=name,
        features=("reach",),
        feature_descriptions=("how far it reaches",),
        obs_layout=(ObsField("observation", 0, 3),),
        action_dim=2,
        description="A robot reaches.",
        utterances=path,
        source="recorded",
    )


def test_built_ins_are_the_design_contract():
    assert task_names()[:2] == ("metaworld", "robosuite")
    assert get_task("metaworld").features == ("height", "speed", "distance_to_button")
    assert get_task("robosuite").features == (
        "height",
        "speed",
        "distance_to_cube",
        "distance_to_bottle",
        "lift_success",
    )
    for name in ("metaworld", "robosuite"):
        task = get_task(name)
        assert task.simulator is not None and len(task.feature_descriptions) == len(task.features)
        assert task.description and task.examples and task.utterances.is_file()


def test_unknown_task_is_one_line():
    with pytest.raises(LangprefError, match="unknown task 'kitchen'") as info:
        get_task("kitchen")
    assert "\n" not in str(info.value) and "metaworld" in str(info.value)


def test_recorded_tasks_register_and_have_no_simulator(tmp_path):
    register_task(_task("registry-reach", tmp_path / "bank.json"))
    assert "registry-reach" in task_names()
    with pytest.raises(LangprefError, match="no simulator"):
        get_simulator("registry-reach")
    register_task(_task("registry-reach", tmp_path / "other.json"))  # imported again: the later one wins
    assert get_task("registry-reach").utterances == tmp_path / "other.json"
    with pytest.raises(LangprefError, match="built-in"):
        register_task(_task("robosuite", tmp_path / "bank.json"))


def test_a_task_checks_its_own_shape(tmp_path):
    with pytest.raises(LangprefError, match="feature descriptions"):
        replace(_task("x", tmp_path), feature_descriptions=())
    with pytest.raises(LangprefError, match="twice"):
        replace(_task("x", tmp_path), features=("a", "a"), feature_descriptions=("", ""))


class _EntryPoint:
    def __init__(self, name: str, load):
        self.name, self.value, self.load = name, f"fake:{name}", load


def test_plugins_load_and_a_broken_one_is_skipped(monkeypatch, tmp_path):
    good = _task("fake-plugin", tmp_path / "bank.json")

    def broken():
        raise ImportError("no module named fancy_sim")

    eps = [
        _EntryPoint("broken", broken),
        _EntryPoint("good", lambda: lambda: good),
        _EntryPoint("not-a-task", lambda: 42),
    ]
    monkeypatch.setattr(langpref.registry, "entry_points", lambda group: eps if group == "langpref.tasks" else [])
    monkeypatch.setattr(tasks.REGISTRY, "loaded", False)
    monkeypatch.setattr(tasks.REGISTRY, "items", {})
    with pytest.warns(UserWarning) as record:
        names = task_names()
    messages = " ".join(str(w.message) for w in record)
    assert "fancy_sim" in messages and "not a langpref.tasks.Task" in messages
    assert "fake-plugin" in names and get_task("fake-plugin").source == "plugin"
