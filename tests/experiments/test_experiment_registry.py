"""The experiment registry: every `langpref experiment NAME` comes from one `Experiment` record, and the flags'
choices come from the config fields' `Literal` types."""

from __future__ import annotations

import inspect
import typing

import pytest

from langpref.errors import LangprefError
from langpref.experiments.registry import EXPERIMENTS, Experiment, get_experiment, register_experiment


def _experiment_group():
    """The parser of `langpref experiment`."""
    import argparse

    from langpref.cli import build_parser

    (top,) = (a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return top.choices["experiment"]


def _experiment_parsers() -> dict[str, object]:
    import argparse

    (sub,) = (a for a in _experiment_group()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_experiment_command_is_a_registry_record_and_back():
    parsers = _experiment_parsers()
    assert list(parsers) == list(EXPERIMENTS)  # no command beside the registry, none missing, same order
    listing = " ".join(_experiment_group().format_help().split())
    for name, experiment in EXPERIMENTS.items():
        assert experiment.name == name and " ".join(experiment.help.split())[:40] in listing
        run = experiment.runner()
        # the record names its function (nobody composes it); its module is named for an experiment (the ablation's
        # is the reward experiment's)
        assert callable(run) and run.__name__ == f"run_{name}_experiment"
        assert run.__module__.rsplit(".", 1)[-1] in EXPERIMENTS
        if experiment.inputs == "space":
            assert {"config", "command", "sweep", "perfect", "force"} <= set(inspect.signature(run).parameters)
            cls = experiment.config_class()
            fields = set(typing.get_type_hints(cls))
            assert {f.split(".")[0] for f in experiment.flags} <= fields


def test_a_taken_name_and_an_unknown_name_are_one_line_errors():
    improve = EXPERIMENTS["improve"]
    assert register_experiment(improve) is improve  # the same record again: nothing changes
    with pytest.raises(LangprefError, match="already registered"):
        register_experiment(Experiment("improve", "another", "langpref.experiments.reward:run_reward_experiment"))
    with pytest.raises(LangprefError, match="unknown experiment 'fig9': choose one of .*improve"):
        get_experiment("fig9")
    with pytest.raises(LangprefError, match="no config dataclass"):
        EXPERIMENTS["alignment"].config_class()


def test_flag_choices_come_from_the_literal_fields():
    from langpref.backends import BACKENDS
    from langpref.feedback.humans import DIRECTION_RULES, FEATURE_RULES
    from langpref.feedback.space import FEATURE_SCALES, PHRASING_SPLITS
    from langpref.improve import IMPROVE_STRATEGIES, OBJECTIVES
    from langpref.reward.learner import LOSSES, MODELS, NEGATIVES
    from langpref.reward.learners import learner_names
    from tests.factories import parsers

    p = parsers()
    flags = {c: {a.option_strings[0]: a for a in p[c]._actions if a.option_strings} for c in p}
    lr, imp, ex = flags["learn-reward"], flags["improve"], flags["experiment reward"]
    assert lr["--feature-scale"].choices == FEATURE_SCALES == ("standardised", "paper")
    assert lr["--direction"].choices == DIRECTION_RULES and lr["--feature-rule"].choices == FEATURE_RULES
    assert lr["--phrasing-split"].choices == PHRASING_SPLITS == ("train", "val", "test", "all")
    assert lr["--reward-model"].choices == MODELS and lr["--loss"].choices == LOSSES
    assert lr["--negatives"].choices == NEGATIVES and lr["--learner"].choices == learner_names()
    assert lr["--query-split"].choices == lr["--eval-split"].choices == ("train", "val", "test")
    assert imp["--strategy"].choices == IMPROVE_STRATEGIES and imp["--objective"].choices == OBJECTIVES
    assert imp["--candidates"].choices == ("train", "val", "test", "generated", "recorded")
    assert imp["--base-split"].choices == ("train", "val", "test")
    assert ex["--backend"].choices == flags["generate"]["--backend"].choices == BACKENDS
    assert flags["experiment active"]["--humans"].default == 10 and ex["--humans"].default == 3
