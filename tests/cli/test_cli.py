import json
import subprocess
import sys

import pytest

from langpref.cli import main
from tests.factories import parsers, write_dataset


def run(*args):
    return subprocess.run([sys.executable, "-m", "langpref", *args], capture_output=True, text=True, check=False)


def test_help_lists_the_commands():
    proc = run("--help")
    assert proc.returncode == 0
    for command in ("generate", "inspect", "render", "demo"):
        assert command in proc.stdout


def test_inspect_json_has_the_contract_keys(synthetic_dataset, capsys):
    assert main(["inspect", str(synthetic_dataset), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("num_trajectories", "horizon", "splits", "features", "feature_correlation"):
        assert key in out
    assert out["splits"] == {"train": 10, "val": 1, "test": 1}


def test_errors_are_one_line(tmp_path):
    proc = run("inspect", str(tmp_path / "typo"), "--json")
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "does not exist" in lines[0]


# ---- flags derived from the config dataclasses -------------------------------------------------------------------

LEGACY_FLAGS = {  # every flag of the hand-written parser this one replaced: scripts and docs rely on them
    "demo": "--out --workers",
    "embed": "--model",
    "evaluate": "--data --device --model --phrasing-split --split --utterances",
    "experiment alignment": "--data --env --force --out",
    "experiment improve": "--backend --data --env --force --iterations --model --out --perfect-latent "
    "--phrasing-split --phrasings --ray-address --seeds --workers",
    "generate": "--backend --env --force --horizon --num-trajectories --out --ray-address --seed --workers",
    "import": "--action-key --camera --force --out --seed --splits --state-key --task",
    "improve": "--candidates --data --exclude-shown --figure --iterations --loss --model --negatives --num-negatives "
    "--objective --perfect-latent --phrasing-split --phrasings --reward-model --seed --seeds --strategy "
    "--temperature --weight-decay",
    "learn-reward": "--data --eval-split --feedback --figure --humans --loss --model --negatives --num-negatives "
    "--perfect-latent --phrasing-split --phrasings --queries --query-split --rationality "
    "--reward-model --seed --seeds --temperature --weight-decay",
    "render": "--fps --height --index --out --width",
    "study export": "--db --out",
    "study serve": "--admin-token --data --db --host --improve-max-iterations --model --no-prerender --num-negatives "
    "--on-show --on-show-timeout --port --pref-queries --rating-every --seed --split --torch-threads "
    "--video-format --video-fps --video-height --video-stride --video-width --videos",
    "tasks": "--data",
    "train": "--batch-size --data --device --epochs --extend-bank --finetune-batch-size --finetune-epochs --force "
    "--freeze-language --head-lr --lang-model --latent-dim --lm-lr --lr --max-length --no-mixed-precision "
    "--no-observation-deltas --norm-a --norm-b --out --patience --phrasings-per-step --seed --tie-fraction "
    "--time-samples --utterances",
    "utterances": "--env",
    "visualize": "--data --model --out --split",
}
for _name in ("reward", "ablation", "prior"):
    LEGACY_FLAGS[f"experiment {_name}"] = LEGACY_FLAGS["experiment improve"].replace(
        "--iterations", "--humans --queries --reward-model"
    )


def test_every_legacy_flag_is_still_there_and_every_option_has_help():
    all_parsers = parsers()
    for command, flags in LEGACY_FLAGS.items():
        have = {o for a in all_parsers[command]._actions for o in a.option_strings}
        assert set(flags.split()) <= have, (command, set(flags.split()) - have)
    for command, p in all_parsers.items():
        for a in p._actions:
            if a.option_strings and a.dest != "help":
                assert a.help, f"{command} {a.option_strings[0]} has no help"


def test_flags_carry_the_dataclass_defaults_and_docstrings():
    from langpref.model.config import ModelConfig, TrainConfig
    from langpref.reward import LearnRewardConfig
    from langpref.study.protocol.config import StudyConfig

    p = parsers()
    train = {a.option_strings[0]: a for a in p["train"]._actions if a.option_strings}
    d = TrainConfig()
    assert train["--epochs"].default == d.stage1_epochs and train["--lm-lr"].default == d.stage2_lm_lr
    assert train["--latent-dim"].default == ModelConfig().latent_dim
    assert train["--no-observation-deltas"].dest == "model.observation_deltas"
    assert "co-finetun" not in train["--time-samples"].help and "0 = all" in train["--time-samples"].help
    assert train["--device"].choices == ("auto", "cpu", "cuda")
    lr = {a.option_strings[0]: a for a in p["learn-reward"]._actions if a.option_strings}
    assert lr["--queries"].default == LearnRewardConfig().queries and lr["--feedback"].required
    assert set(lr["--feedback"].choices) == {"language", "comparison", "mixed"}
    assert lr["--reward-model"].choices == ("linear", "mlp") and lr["--weight-decay"].default is None
    serve = {a.option_strings[0]: a for a in p["study serve"]._actions if a.option_strings}
    assert serve["--split"].default is None and f"default {StudyConfig().split}" in serve["--split"].help
    assert serve["--video-format"].choices == ("webm", "mp4")


def test_study_serve_takes_repeated_allowed_hosts_and_says_what_no_prerender_does():
    from langpref.cli import build_parser
    from langpref.cli_config import from_args
    from langpref.study.server.settings import ServeConfig

    serve = {a.option_strings[0]: a for a in parsers()["study serve"]._actions if a.option_strings}
    assert serve["--no-prerender"].help.startswith("Do not render")  # it said what the default does
    assert "--allowed-host" in serve["--allowed-hosts"].option_strings
    argv = ["study", "serve", "--model", "m", "--data", "d"]
    given = [*argv, "--allowed-hosts", "a.example,b.example", "--allowed-host", "c.example"]
    cfg = from_args(ServeConfig, build_parser(given).parse_args(given))
    assert list(cfg.allowed_hosts) == ["a.example", "b.example", "c.example"]
    assert list(from_args(ServeConfig, build_parser(argv).parse_args(argv)).allowed_hosts) == []


def test_config_round_trip_through_the_parser():
    import argparse
    from dataclasses import dataclass, field

    from langpref.cli_config import add_config, field_docs, from_args

    @dataclass
    class Inner:
        width: int = 3
        """How wide."""

    @dataclass
    class Outer:
        name: str
        """Required: no default."""
        sizes: tuple[int, ...] = (1, 2)
        """Sizes, 100% of them."""
        fast: bool = True
        """Go fast."""
        label: str | None = None
        inner: Inner = field(default_factory=Inner)

    assert field_docs(Outer)["sizes"] == "Sizes, 100% of them."
    p = argparse.ArgumentParser()
    add_config(p, Outer, {"label": "--tag", "inner.width": {"choices": (3, 4)}})
    help_text = p.format_help()
    assert "--no-fast" in help_text and "--tag" in help_text and "How wide." in help_text and "100%" in help_text
    no_fast = next(a for a in p._actions if "--no-fast" in a.option_strings)
    assert no_fast.help == "Turn off, on by default: Go fast."  # the docstring describes the on state
    cfg = from_args(Outer, p.parse_args(["--name", "x", "--sizes", "4,5,6", "--no-fast", "--width", "4"]))
    assert cfg == Outer("x", (4, 5, 6), False, None, Inner(4))
    assert from_args(Outer, p.parse_args(["--name", "y"])) == Outer("y")


def test_help_imports_nothing_heavy():
    code = (
        "import sys; from langpref.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('torch', 'numpy', 'transformers', 'mujoco') if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and proc.stdout.strip().endswith("[]"), proc.stdout + proc.stderr


def test_the_study_server_does_not_import_the_cli():
    code = "import sys, langpref.study.server.serve; print('langpref.cli' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 0 and proc.stdout.strip() == "False", proc.stderr


# ---- the resolved config beside every output ---------------------------------------------------------------------


def test_improve_and_experiments_write_their_resolved_config(tmp_path, capsys):

    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    figure = tmp_path / "figs" / "curve.png"
    assert (
        main(
            [
                "improve",
                "--data",
                str(data),
                "--perfect-latent",
                "--seeds",
                "2",
                "--iterations",
                "2",
                "--temperature",
                "0.5",
                "--figure",
                str(figure),
                "--json",
            ]
        )
        == 0
    )
    printed = json.loads(capsys.readouterr().out)
    saved = json.loads((tmp_path / "figs" / "curve.config.json").read_text())
    assert saved["command"].startswith("langpref improve --data") and saved["langpref_version"]
    assert saved["config"]["config"] == printed["config"]  # the same resolved config --json prints
    assert saved["config"]["config"]["human"]["temperature"] == 0.5 and saved["config"]["perfect"] is True

    out = tmp_path / "res"
    assert (
        main(
            [
                "experiment",
                "reward",
                "--env",
                "metaworld",
                "--data",
                str(data),
                "--perfect-latent",
                "--out",
                str(out),
                "--seeds",
                "1",
                "--humans",
                "1",
                "--queries",
                "2",
                "--json",
            ]
        )
        == 0
    )
    capsys.readouterr()
    saved = json.loads((out / "reward.config.json").read_text())
    assert saved["config"]["config"]["queries"] == 2 and saved["config"]["sweep"] == {
        "backend": "local",
        "workers": 1,
        "ray_address": None,
    }
    assert saved["config"]["data"] == str(data) and saved["config"]["out"] == str(out)


# ---- --config PATH: rerun a record ---------------------------------------------------------------------------------


def _learn_reward(data, *extra):
    return ["learn-reward", "--data", str(data), "--perfect-latent", "--feedback", "comparison", *extra]


def test_config_reruns_a_recorded_command_to_identical_output(tmp_path, capsys, monkeypatch):

    monkeypatch.chdir(tmp_path)
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    first = _learn_reward(data, "--queries", "3", "--humans", "1", "--seeds", "1", "--rationality", "2")
    assert main([*first, "--figure", "a.png", "--json"]) == 0
    recorded = json.loads(capsys.readouterr().out)
    assert main(["learn-reward", "--config", "a.config.json", "--figure", "b.png"]) == 0  # --json from the record
    again = json.loads(capsys.readouterr().out)
    assert again.pop("figure") == "b.png" and recorded.pop("figure") == "a.png"
    assert again == recorded
    record = json.loads((tmp_path / "b.config.json").read_text())
    assert "--config" not in record["command"] and record["command"].endswith("--json --figure b.png")
    assert record["command"].count("--figure") == 1  # the record's --figure replaced, not repeated
    assert record["config"] == json.loads((tmp_path / "a.config.json").read_text())["config"]

    assert main(["learn-reward", "--config=b.config.json", "--queries", "2", "--figure", "c.png"]) == 0
    assert len(json.loads(capsys.readouterr().out)["cross_entropy"]) == 3  # a flag given here overrides the record
    assert main(["learn-reward", "--config", "c.config.json", "--no-perfect-latent", "--model", "m"]) == 2
    assert "m" in capsys.readouterr().err  # the switch turned off: now it reads --model m, which is not there


def test_config_warns_in_one_line_when_the_record_is_of_another_version(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    assert main([*_learn_reward(data, "--queries", "1", "--humans", "1", "--seeds", "1"), "--figure", "a.png"]) == 0
    assert main(["learn-reward", "--config", "a.config.json", "--figure", "b.png"]) == 0
    assert "warning" not in capsys.readouterr().err  # the same version: nothing to say
    record = json.loads((tmp_path / "a.config.json").read_text())
    (tmp_path / "old.config.json").write_text(json.dumps({**record, "langpref_version": "0.0.1"}))
    assert main(["learn-reward", "--config", "old.config.json", "--figure", "c.png"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(warned) == 1 and "0.0.1" in warned[0], warned


def test_config_errors_are_one_line(tmp_path, capsys):
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "other.config.json").write_text(json.dumps({"command": "langpref improve --data d"}))
    for argv, text in (
        (["learn-reward", "--config", str(tmp_path / "none.json")], "no such file"),
        (["learn-reward", "--config", str(tmp_path / "bad.json")], "not a resolved config"),
        (["learn-reward", "--config", str(tmp_path / "other.config.json")], "not `langpref learn-reward`"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and text in err[0], err
    with pytest.raises(SystemExit):
        main(["inspect", "d", "--config", str(tmp_path / "other.config.json")])  # inspect records nothing


def test_a_command_takes_config_exactly_when_it_records_and_one_device_default():
    import inspect
    import re

    from langpref.cli.common import DEFAULT_DEVICE
    from langpref.cli_config import COMMANDS, RERUN
    from langpref.model.config import TrainConfig

    parsers()  # registers every command
    rerun = {name for name, (_, _, options, _) in COMMANDS.items() if RERUN in options}
    writes = {
        name
        for name, (_, _, _, run) in COMMANDS.items()
        if re.search(r"(?<![\w.])(record|run_config_experiment)\(\s*args\b", inspect.getsource(run))
    }
    assert {"train", "generate", "import", "learn-reward", "improve", "bank augment", "study export"} <= writes
    assert {f"experiment {name}" for name in ("alignment", "observations", "reward", "active")} <= writes
    assert rerun == writes  # --config offered where there is no record to rerun, or a record --config cannot rerun
    p = parsers()
    devices = {name: a.default for name, q in p.items() for a in q._actions if "--device" in a.option_strings}
    assert {"train", "evaluate", "experiment observations"} <= set(devices)
    assert set(devices.values()) == {DEFAULT_DEVICE} == {TrainConfig().device}


MAX_HELP_LINES = 60
"""A command's default `--help` at 80 columns has fewer lines (issue 43 item 6: a help a person reads)."""


def _help(argv):
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main(argv)
    return out.getvalue()


def _hidden(words):
    """The options of command `words` (("langpref", ...)) that `--help` leaves out and `--help-all` lists."""
    import argparse

    from langpref.cli import build_parser
    from langpref.cli.reference import _parser_of

    def suppressed(flag):
        parser = _parser_of(build_parser([*words[1:], flag]), words)
        return {
            a.option_strings[0] if a.option_strings else a.dest for a in parser._actions if a.help is argparse.SUPPRESS
        }

    return suppressed("--help") - suppressed("--help-all")


def test_every_commands_help_is_under_60_lines_and_names_help_all_where_it_hides_options(monkeypatch):
    from langpref.cli import build_parser
    from langpref.cli.reference import commands
    from langpref.cli_config import COMMANDS

    monkeypatch.setenv("COLUMNS", "80")
    long, silent, hiding = {}, [], []
    for words in commands(build_parser()):
        short = _help([*words[1:], "--help"])
        if len(short.splitlines()) >= MAX_HELP_LINES:
            long[" ".join(words)] = len(short.splitlines())
        if " ".join(words[1:]) in COMMANDS and _hidden(words):
            hiding.append(" ".join(words[1:]))
            flat = " ".join(short.split())
            if (
                "Shown: the common options" not in flat
                or "--help-all show every option, not only the common" not in flat
            ):
                silent.append(" ".join(words))
    assert not long, f"--help of {MAX_HELP_LINES} lines or more at 80 columns (the rest goes to --help-all): {long}"
    assert not silent, f"--help hides options without saying that --help-all lists them: {silent}"
    assert {"train", "learn-reward", "improve", "experiment active", "import", "bank augment"} <= set(hiding)


def test_help_all_lists_every_option_of_every_command(monkeypatch):
    import argparse

    from langpref.cli import build_parser
    from langpref.cli.reference import _parser_of
    from langpref.cli_config import COMMANDS

    monkeypatch.setenv("COLUMNS", "80")
    for name in COMMANDS:
        words = ("langpref", *name.split())
        parser = _parser_of(build_parser([*words[1:], "--help-all"]), words)
        shown = {a.dest for a in parser._actions if a.help is not argparse.SUPPRESS}
        assert {a.dest for a in parser._actions} == shown, name  # unlisted: only a rerun's --no-x of a listed switch
        full = _help([*words[1:], "--help-all"])
        assert all(flag in full for flag in _hidden(words)), name
    assert "--latent-dim" in _hidden(("langpref", "train")) and "--negatives" in _hidden(("langpref", "learn-reward"))
