"""One registry shape (`langpref.registry`, issue 43): tasks, feedback kinds, learners and experiments are each a
`Registry` with register, get, names and plugins by entry point, and a plugin experiment joins like any other part."""

from __future__ import annotations

from dataclasses import replace

import pytest

import langpref.registry
from langpref.errors import LangprefError
from langpref.registry import Registry


class _EntryPoint:
    def __init__(self, name: str, load):
        self.name, self.value, self.load = name, f"fake:{name}", load


def test_every_registry_of_named_parts_is_one_shape():
    from langpref import tasks
    from langpref.experiments import registry as experiments
    from langpref.feedback import kind
    from langpref.reward import learners

    groups = {r.group for r in (tasks.REGISTRY, kind.REGISTRY, learners.REGISTRY, experiments.REGISTRY)}
    assert all(isinstance(r, Registry) for r in (tasks.REGISTRY, kind.REGISTRY, learners.REGISTRY))
    assert isinstance(experiments.REGISTRY, Registry)
    assert groups == {"langpref.tasks", "langpref.feedback", "langpref.learners", "langpref.experiments"}
    assert kind.get_kind("language") is kind.REGISTRY.items["language"] and "paper" in learners.learner_names()


def test_a_plugin_experiment_joins_and_a_broken_one_is_skipped(monkeypatch):
    from langpref.experiments import registry as experiments

    extra = replace(experiments.get_experiment("reward"), name="reward-again", help="the reward experiment again")

    def broken():
        raise ImportError("no module named fancy_experiments")

    eps = [_EntryPoint("again", lambda: extra), _EntryPoint("broken", broken), _EntryPoint("odd", lambda: 42)]
    monkeypatch.setattr(langpref.registry, "entry_points", lambda group: eps if group == "langpref.experiments" else [])
    monkeypatch.setattr(experiments.REGISTRY, "loaded", False)
    monkeypatch.setattr(experiments.REGISTRY, "items", dict(experiments.REGISTRY.items))
    with pytest.warns(UserWarning) as record:
        names = experiments.experiment_names()
    messages = " ".join(str(w.message) for w in record)
    assert "fancy_experiments" in messages and "gives a int" in messages
    assert names[-1] == "reward-again" and experiments.get_experiment("reward-again") is extra
    with pytest.raises(LangprefError, match="an experiment named 'reward-again' is already registered"):
        experiments.register_experiment(replace(extra, help="another"))
    with pytest.raises(LangprefError, match="unknown experiment 'nope': choose one of alignment, "):
        experiments.get_experiment("nope")
