"""A study's bank additions (`langpref.language.additions`): each text under each meaning clicked with its count and
provenance, conflicts and texts naming no change flagged, never read as a bank before the lab's review (`langpref
bank review`), which writes only what the lab accepted."""

from __future__ import annotations

import json

import pytest

from langpref.errors import LangprefError
from langpref.language.additions import additions_file, bank_meanings, load_additions, review, says_no_change
from langpref.language.bank import load_bank, load_user_utterances


def confirmation(text, meaning, participant, query=1):
    feature, direction = meaning.split("/") if meaning else (None, None)
    return {
        "text": text,
        "feature": feature,
        "direction": direction,
        "participant": participant,
        "query": query,
        "margin": 0.05,
        "rank": 2,
        "p": 0.3,
    }


# what issue 44 found: "no rush" under two meanings, "No change." filed as height/increase
CLICKS = [
    confirmation("no rush", "speed/decrease", 1),
    confirmation("No rush.", "speed/decrease", 2, query=3),
    confirmation("no rush", "speed/increase", 3),
    confirmation("no rush", None, 4),
    confirmation("No change.", "height/increase", 2, query=5),
    confirmation("A touch lower, please.", "height/decrease", 1, query=2),
    confirmation("Move slower.", "speed/decrease", 3),
    confirmation("Move slower.", "speed/increase", 4, query=2),
]


@pytest.fixture
def additions(tmp_path):
    data = additions_file("metaworld", CLICKS, bank_meanings(load_bank("metaworld").phrasings), {"db": "s.sqlite"})
    path = tmp_path / "additions.json"
    path.write_text(json.dumps(data))
    return data, path


def test_each_addition_has_its_count_provenance_and_flags(additions):
    data, _ = additions
    got = {(a["text"], a["feature"], a["direction"]): a for a in data["additions"]}
    assert set(got) == {
        ("no rush", "speed", "decrease"),
        ("no rush", "speed", "increase"),
        ("No change.", "height", "increase"),
        ("A touch lower, please.", "height", "decrease"),
        ("Move slower.", "speed", "decrease"),
        ("Move slower.", "speed", "increase"),
    }
    slow = got[("no rush", "speed", "decrease")]  # "No rush." is the same text
    assert slow["count"] == 2 and slow["participants"] == [1, 2] and slow["accept"] is None
    assert [(c["participant"], c["query"], c["margin"], c["rank"]) for c in slow["confirmations"]] == [
        (1, 1, 0.05, 2),
        (2, 3, 0.05, 2),
    ]
    assert slow["flags"] == ["conflict: also confirmed as none of these (x1), speed/increase (x1)"]
    assert got[("no rush", "speed", "increase")]["flags"][0].startswith("conflict: also confirmed as none of these")
    assert any(f.startswith("no change") for f in got[("No change.", "height", "increase")]["flags"])
    assert got[("A touch lower, please.", "height", "decrease")]["flags"] == []
    assert got[("Move slower.", "speed", "decrease")]["flags"][-1].startswith("in bank")
    assert (
        "bank conflict: the task's bank has it as speed/decrease" in got[("Move slower.", "speed", "increase")]["flags"]
    )


def test_texts_that_name_no_change_are_told_from_feedback():
    said = ["No change.", "that's good, no change", "Don't change anything", "Keep it as it is.", "Perfect!"]
    assert all(map(says_no_change, said))
    assert not any(map(says_no_change, ["no rush", "Move slower.", "Keep it lower.", "Change the height."]))


def test_the_additions_file_is_no_bank_until_reviewed(additions, tmp_path):
    """Issue 44: the file loaded as it was as a `--utterances` bank, so unreviewed clicks could be trained on."""
    _, path = additions
    with pytest.raises(LangprefError, match="bank additions file, not reviewed.*langpref bank review"):
        load_user_utterances(path, "metaworld")


def test_the_review_writes_only_what_the_lab_accepted(additions):
    data, path = additions
    with pytest.raises(LangprefError, match="6 additions are undecided .5 flagged"):
        review(load_additions(path))
    with pytest.raises(LangprefError, match="5 additions are undecided .5 flagged"):
        review(load_additions(path), accept_unflagged=True)  # a flagged one always needs the lab's word
    decide = {"no rush": True, "No change.": False, "Move slower.": True}
    for a in data["additions"]:
        a["accept"] = decide.get(a["text"], a["accept"])
    path.write_text(json.dumps(data))
    with pytest.raises(LangprefError, match="'no rush' is accepted as both speed/decrease and speed/increase"):
        review(load_additions(path), accept_unflagged=True)
    for a in data["additions"]:
        a["accept"] = a["accept"] and a["direction"] == "decrease"
    path.write_text(json.dumps(data))
    bank, report = review(load_additions(path), accept_unflagged=True)
    # "Move slower." is in the bank already; the unflagged one is taken as accepted
    assert bank["metaworld"] == {"speed": {"decrease": ["no rush"]}, "height": {"decrease": ["A touch lower, please."]}}
    assert report == {
        "task": "metaworld",
        "additions": 6,
        "accepted": 3,
        "rejected": 3,
        "written": 2,
        "flagged_accepted": 2,
    }


def test_bank_review_on_the_command_line(additions, tmp_path, capsys):
    from langpref.cli import main

    data, path = additions
    out = tmp_path / "reviewed.json"
    assert main(["bank", "review", str(path)]) == 0
    listing = capsys.readouterr().out
    assert "6 additions to metaworld's bank, 6 undecided" in listing and "! no change" in listing
    assert main(["bank", "review", str(path), "--out", str(out)]) == 2 and not out.exists()
    assert "undecided" in capsys.readouterr().err
    for a in data["additions"]:
        a["accept"] = a["text"] == "A touch lower, please."
    path.write_text(json.dumps(data))
    assert main(["bank", "review", str(path), "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["written"] == 1
    assert load_user_utterances(out, "metaworld") == {"height": {"decrease": ("A touch lower, please.",)}}
    assert main(["bank", "review", str(path), "--out", str(out)]) == 2  # exists: --force
    assert main(["bank", "review", str(path), "--out", str(path), "--force"]) == 2  # never over the additions
