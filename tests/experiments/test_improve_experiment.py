"""`langpref experiment improve` and what every experiment shares: writing, resuming, the recorded command and
refused overrides."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.improve import ImproveConfig
from tests.factories import write_dataset


def test_experiment_improve_writes_and_resumes(tmp_path, monkeypatch, capsys):
    import langpref.improve as improve_module
    from langpref.experiments.improve import run_improve_experiment

    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    out = tmp_path / "res"
    cfg = ImproveConfig(seeds=3, iterations=3)
    first = run_improve_experiment("metaworld", data, None, out, perfect=True, config=cfg, progress=False)
    assert {p.name for p in out.iterdir()} >= {"improve.json", "improve.png", "improve.md", "runs.json"}
    assert set(first["strategies"]) == {"paper", "paper-printed", "history"}
    assert first["strategies"]["paper-printed"]["config"]["objective"] == "printed"
    assert "| paper |" in (out / "improve.md").read_text()

    def boom(*args, **kwargs):
        raise AssertionError("a finished seed was rerun")

    monkeypatch.setattr(improve_module, "run_improvement", boom)
    again = run_improve_experiment("metaworld", data, None, out, perfect=True, config=cfg, progress=False)
    assert again["strategies"]["paper"]["curve"] == first["strategies"]["paper"]["curve"]
    with pytest.raises(LangprefError, match="another configuration"):
        run_improve_experiment(
            "metaworld", data, None, out, perfect=True, config=ImproveConfig(seeds=3, iterations=4), progress=False
        )
    monkeypatch.undo()
    assert (
        main(
            [
                "experiment",
                "improve",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--out",
                str(out),
                "--seeds",
                "3",
                "--iterations",
                "4",
                "--force",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert len(summary["strategies"]["history"]["curve"]) == 5
    assert asdict(ImproveConfig())["seeds"] == 100 and ImproveConfig().iterations == 15


@pytest.mark.parametrize("kind, flag", [("improve", "--seeds"), ("reward", "--queries"), ("prior", "--humans")])
def test_experiment_refuses_a_zero_override_and_writes_nothing(tmp_path, capsys, kind, flag):
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    out = tmp_path / "res"
    assert (
        main(
            [
                "experiment",
                kind,
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--out",
                str(out),
                flag,
                "0",
            ]
        )
        == 2
    )  # 0 is a value, not "use the paper's setting"
    assert "must" in capsys.readouterr().err and not out.exists()


def test_experiment_command_is_the_command_line_that_ran_it(tmp_path, monkeypatch, capsys):
    """The command an experiment writes into its .md/.json is the one that ran it (without --json); from Python,
    its base command, the options being in the summary's configs."""
    from langpref.experiments.improve import run_improve_experiment
    from langpref.feedback import HumanConfig

    monkeypatch.chdir(tmp_path)
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    phrasings = Path(__file__).resolve().parents[2] / "heldout" / "utterances.json"
    argv = ["experiment", "improve", "--env", "metaworld", "--data", str(data), "--perfect-latent"]
    argv += ["--seeds", "2", "--iterations", "2", "--phrasings", str(phrasings)]
    assert main([*argv, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert Path(res["figure"]).parent == Path("results/improve/metaworld-perfect-phrasings")
    assert res["command"] == " ".join(["langpref", *argv])
    assert f"`{res['command']}`" in Path(res["figure"]).with_suffix(".md").read_text()
    cfg = ImproveConfig(seeds=2, iterations=2, human=HumanConfig(phrasings=str(phrasings)))
    res = run_improve_experiment("metaworld", data, None, tmp_path / "o", perfect=True, config=cfg, progress=False)
    assert (
        res["command"]
        == f"langpref experiment improve --env metaworld --data {data} --perfect-latent --out {tmp_path / 'o'}"
    )
    assert res["strategies"]["paper"]["config"]["human"]["phrasings"] == str(phrasings)


def test_run_cache_outlives_an_option_added_later_but_not_a_changed_one(tmp_path):
    from langpref.experiments.common import RunCache

    path = tmp_path / "runs.json"
    RunCache(path, {"seeds": 3, "human": {"temperature": 1.0}}).put("paper/0", [0.5])
    again = RunCache(path, {"seeds": 3, "human": {"temperature": 1.0, "phrasings": None}})  # a new, unset option
    assert "paper/0" in again
    with pytest.raises(LangprefError, match="another configuration"):
        RunCache(path, {"seeds": 3, "human": {"temperature": 1.0, "phrasings": "mine.json"}})


def test_experiment_improve_with_another_phrasing_split(tmp_path, monkeypatch, capsys):
    """--phrasing-split all: its own default output, and the command that reproduces it."""
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    monkeypatch.chdir(tmp_path)
    assert (
        main(
            [
                "experiment",
                "improve",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--seeds",
                "2",
                "--iterations",
                "2",
                "--phrasing-split",
                "all",
                "--json",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert Path(summary["figure"]).parent == Path("results/improve/metaworld-perfect-bank-all")
    assert summary["command"].endswith("--phrasing-split all")
    assert summary["strategies"]["paper"]["config"]["human"]["phrasing_split"] == "all"
