"""`langpref bank check`: leave-one-out reading of a bank's meanings, flags for weak ones, and the import warning.

Most tests read with a small bag-of-words embedding (fast, no model); one reads a built-in bank with the pretrained
MiniLM through the command line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from langpref.errors import LangprefError
from langpref.language.check import leave_one_out, read_against

FEATURES = ("speed", "height")
BANK = {
    "speed": {
        "increase": ["move faster", "go faster", "faster please", "faster now"],
        "decrease": ["move slower", "go slower", "slower please", "slower now"],
    },
    "height": {
        "increase": ["move higher", "go higher", "higher please", "higher now"],
        "decrease": ["move lower", "go lower", "lower please", "lower now"],
    },
}


def bag_of_words(texts):
    vocab = sorted({w for by in BANK.values() for ts in by.values() for t in ts for w in t.split()} | {"crawl"})
    out = np.zeros((len(texts), len(vocab)))
    for i, t in enumerate(texts):
        for w in t.split():
            if w in vocab:
                out[i, vocab.index(w)] += 1
    return out + 1e-3


def test_a_distinct_bank_is_read_right_and_nothing_is_flagged():
    result = leave_one_out(BANK, FEATURES, bag_of_words, task="t", encoder="bow")
    assert result.accuracy == 1.0 and result.weak == [] and result.repeated == []
    d = result.to_dict()["meanings"]["speed/increase"]
    assert d["accuracy"] == 1.0 and d["confused_with"] == {} and d["count"] == 4
    assert "no weak meaning" in result.summary()


def test_a_meaning_whose_phrasings_copy_another_meanings_is_flagged():
    bank = json.loads(json.dumps(BANK))
    bank["speed"]["decrease"] = list(bank["speed"]["increase"])  # copies
    result = leave_one_out(bank, FEATURES, bag_of_words, task="t", encoder="bow")
    meanings = result.to_dict()["meanings"]
    assert "speed/decrease" in result.weak and meanings["speed/decrease"]["accuracy"] < 0.8
    assert meanings["speed/decrease"]["confused_with"] == {"speed/increase": 4}
    assert "add phrasings of speed/decrease" in meanings["speed/decrease"]["advice"]
    assert not {"height/increase", "height/decrease"} & set(result.weak)
    assert {r["text"] for r in result.repeated} == set(BANK["speed"]["increase"])
    assert result.summary().count("\n") == 0 and "weak: " in result.summary()


def test_a_meaning_with_one_phrasing_cannot_be_checked_and_says_so():
    bank = json.loads(json.dumps(BANK))
    bank["height"]["decrease"] = ["lower now"]
    m = leave_one_out(bank, FEATURES, bag_of_words).meanings["height/decrease"]
    assert m.accuracy is None and m.weak and "at least 2" in m.advice


def test_phrasings_from_elsewhere_are_read_against_the_whole_split():
    queries = {"speed": {"increase": ["faster", "higher"]}}
    result = read_against(BANK, queries, FEATURES, bag_of_words)
    m = result.meanings["speed/increase"]
    assert m.count == 2 and m.accuracy == 0.5 and m.confused_with == {"height/increase": 1}
    assert result.meanings["speed/decrease"].count == 0 and not result.meanings["speed/decrease"].weak


def _task_file(tmp_path, bank):
    (tmp_path / "bank.json").write_text(json.dumps(bank))
    task = tmp_path / "task.toml"
    task.write_text('name = "toy"\ndescription = "d"\nfeatures = ["speed", "height"]\nutterances = "bank.json"\n')
    return task


def test_cli_flags_a_copied_meaning_of_a_task_file_with_the_pretrained_model(tmp_path, capsys):
    from langpref.cli import main

    bank = {f: {d: [t.capitalize() + "." for t in ts] * 1 for d, ts in by.items()} for f, by in BANK.items()}
    bank["height"]["decrease"] = list(bank["height"]["increase"])
    split = {s: bank for s in ("train", "val", "test")}  # split given as is: train holds all four per meaning
    assert main(["bank", "check", str(_task_file(tmp_path, split)), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["task"] == "toy" and out["encoder"].startswith("pretrained ") and out["method"] == "leave-one-out"
    assert "height/decrease" in out["weak"] and out["meanings"]["height/decrease"]["confused_with"]
    assert set(out["meanings"]) == {f"{f}/{d}" for f in FEATURES for d in ("increase", "decrease")}
    assert all({"accuracy", "confused_with"} <= set(m) for m in out["meanings"].values())


def test_bad_inputs_are_one_line_errors(tmp_path):
    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "langpref", "bank", "check", *args], capture_output=True, text=True, check=False
        )

    for args, words in (
        ((str(tmp_path / "nope" / "x"),), "not found"),
        (("no-such-task",), "unknown task"),
        ((str(tmp_path),), "not a langpref dataset"),
        (("metaworld", "--threshold", "2"), "--threshold"),
    ):
        proc = run(*args)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and words in lines[0], proc.stderr


def test_open_bank_refuses_a_file_that_is_not_a_task_file(tmp_path):
    from langpref.language.banksource import open_bank

    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(LangprefError, match="not a task file"):
        open_bank(tmp_path / "x.json")


def test_a_task_file_whose_split_bank_is_malformed_is_one_line(tmp_path):
    from langpref.language.banksource import open_bank

    with pytest.raises(LangprefError, match="not a bank of the utterance schema"):
        open_bank(_task_file(tmp_path, {"train": ["Move faster."], "val": {}, "test": {}}))
