"""A feedback kind from an installed package (entry-point group `langpref.feedback`) joins the registry with no edit
in langpref: it is a `learn-reward --feedback` choice and runs through the reward loop; a broken plugin is skipped
with a warning naming it. The installed distribution is faked by monkeypatching its entry points, as
tests/tasks/test_registry.py does for tasks."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from test_kinds import TRIPLE

import langpref.registry
from langpref.feedback import KINDS, kind
from langpref.feedback.kind import ENTRY_POINT_GROUP, get_kind, kind_names


class _EntryPoint:
    def __init__(self, name: str, load):
        self.name, self.value, self.load = name, f"fake_pkg:{name}", load


@pytest.fixture
def installed(monkeypatch):
    """The fake package's entry points: the best-of-three kind (a function returning it), and two broken ones."""

    def broken():
        raise ImportError("no module named fancy_feedback")

    eps = [
        _EntryPoint("broken", broken),
        _EntryPoint("best_of_three", lambda: lambda: TRIPLE),
        _EntryPoint("not-a-kind", lambda: 42),
        _EntryPoint("mixed", lambda: replace(TRIPLE, name="mixed")),
    ]
    monkeypatch.setattr(langpref.registry, "entry_points", lambda group: eps if group == ENTRY_POINT_GROUP else [])
    monkeypatch.setattr(kind.REGISTRY, "loaded", False)
    yield
    KINDS.pop(TRIPLE.name, None)


def test_an_installed_kind_is_a_learn_reward_choice_and_runs(installed, tmp_path, capsys):
    from langpref.cli import main
    from tests.factories import parsers, write_dataset

    with pytest.warns(UserWarning) as record:
        names = kind_names()
    messages = " ".join(str(w.message) for w in record)
    assert "fancy_feedback" in messages and "not a langpref.feedback.FeedbackKind" in messages
    assert "'mixed'" in messages and set(names[:2]) == {"language", "comparison"} and names[2:] == ("best_of_three",)
    assert get_kind("best_of_three") is TRIPLE
    flags = {a.option_strings[0]: a for a in parsers()["learn-reward"]._actions if a.option_strings}
    assert flags["--feedback"].choices == (*names, "mixed")

    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    argv = ["learn-reward", "--data", str(data), "--perfect-latent", "--feedback", "best_of_three"]
    assert main([*argv, "--queries", "2", "--humans", "1", "--seeds", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["feedback"] == "best_of_three" and len(out["cross_entropy"]) == 3
    assert main([*argv, "--query-selection", "infogain"]) == 2  # strategies are the kind's own: only random
    assert "not defined for best_of_three feedback: choose one of random" in capsys.readouterr().err


def test_each_kind_has_its_own_strategies_registered_from_the_reward_side():
    from langpref.reward.selection import STRATEGIES, known_strategies, strategies_of

    assert strategies_of("language") == ("random", "infogain", "lal-infogain")
    assert strategies_of("comparison") == ("random", "infogain", "volume-removal")
    assert strategies_of("mixed") == ("infogain",) and strategies_of("best_of_three") == ("random",)
    assert known_strategies() == STRATEGIES
    assert tuple(get_kind("language").strategies) == ("random",)  # the feedback side lists none of the reward's
