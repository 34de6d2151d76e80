"""`langpref bank augment`: template proposals per meaning, written for review and never into a bank."""

from __future__ import annotations

import hashlib
import json

import pytest

from langpref.cli import main
from langpref.language.augment import base_of, comparatives, negations_of, propose
from langpref.language.bank import normalise
from langpref.tasks import get_task


def test_the_features_own_words_make_negations_of_the_opposite_direction():
    assert base_of("slower") == "slow" and base_of("closer") == "close" and base_of("bigger") == "big"
    assert comparatives("Get closer to the button.") == [("closer", "to the button")]
    assert comparatives("Open the drawer more.") == [] and comparatives("Lower the gripper.") == []
    negs = negations_of(["Move slower.", "Slow down."])
    assert "You're too slow." in negs and "Don't be so slow." in negs and "Don't slow down." in negs
    assert "You're too close to the button." in negations_of(["Get closer to the button."])
    assert not any("Don't don't" in n for n in negations_of(["Don't rush."]))


def test_proposals_are_new_per_meaning_and_never_for_two_meanings():
    train = {
        "speed": {"increase": ["Move faster.", "Speed up."], "decrease": ["Move slower.", "Slow down."]},
        "height": {"increase": ["Move higher."], "decrease": ["Move lower."]},
    }
    out = propose(train, ("speed", "height"), existing=["You're too slow."])
    inc = out["speed"]["increase"]
    assert "Don't be so slow." in inc and "Move much faster." in inc and "Could you move faster?" in inc
    assert "You're too slow." not in inc  # already in the bank
    assert "You're too fast." in out["speed"]["decrease"]
    keys = [normalise(t) for by in out.values() for ts in by.values() for t in ts]
    assert len(keys) == len(set(keys))
    assert len(propose(train, ("speed", "height"), per_meaning=3)["speed"]["increase"]) == 3


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_cli_writes_a_bank_shaped_file_for_review_and_leaves_the_bank_alone(tmp_path, capsys):
    bank_file = get_task("metaworld").utterances
    before = _sha(bank_file)
    out = tmp_path / "proposed.json"
    assert main(["bank", "augment", "metaworld", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    doc = json.loads(out.read_text())
    assert "review" in doc["_comment"] and set(doc) == {"_comment", "metaworld"}
    assert set(doc["metaworld"]) == set(get_task("metaworld").features)
    assert all(doc["metaworld"][f][d] for f in doc["metaworld"] for d in ("increase", "decrease"))
    assert summary["out"] == str(out) and all(n > 0 for n in summary["proposed"].values())
    from langpref.language.bank import load_user_utterances

    assert load_user_utterances(out, "metaworld")  # usable as --utterances FILE as it is
    assert _sha(bank_file) == before
    # an existing file is kept unless --force
    out.write_text("{}")
    assert main(["bank", "augment", "metaworld", "--out", str(out)]) == 2
    assert out.read_text() == "{}"
    assert main(["bank", "augment", "metaworld", "--out", str(out), "--force"]) == 0
    assert "metaworld" in json.loads(out.read_text())


@pytest.mark.parametrize("which", ["bank", "task"])
def test_cli_refuses_to_write_into_the_bank_or_task_file_even_with_force(tmp_path, capsys, which):
    bank = {"speed": {d: [f"{w} {d} {i}." for i in range(4)] for d, w in (("increase", "Go"), ("decrease", "Be"))}}
    (tmp_path / "bank.json").write_text(json.dumps(bank))
    task = tmp_path / "task.toml"
    task.write_text('name = "toy"\ndescription = "d"\nfeatures = ["speed"]\nutterances = "bank.json"\n')
    target = tmp_path / ("bank.json" if which == "bank" else "task.toml")
    before = _sha(target)
    assert main(["bank", "augment", str(task), "--out", str(target), "--force"]) == 2
    assert "never writes into a bank" in capsys.readouterr().err
    assert _sha(target) == before


def test_adverbs_of_manner_only():
    from langpref.language.augment import adverbs

    assert adverbs("Move slowly.") == ["slowly"] and adverbs("Go slowly to the button.") == ["slowly"]
    assert adverbs("Lift the cube less effectively.") == [] and adverbs("Pass dangerously close.") == []
