import json
import subprocess
import sys

from langpref.cli import main


def run(*args):
    return subprocess.run([sys.executable, "-m", "langpref", *args], capture_output=True, text=True)


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
