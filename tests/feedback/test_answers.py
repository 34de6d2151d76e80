"""The answers format (`langpref.feedback.answers`): what a study export writes reads back as the same answers, and
a bad line is one error naming it."""

from __future__ import annotations

import json

import pytest

from langpref.errors import LangprefError
from langpref.feedback.answers import answer_record, read_answers, write_answers
from langpref.feedback.comparison import ComparisonAnswer, ComparisonQuery
from langpref.feedback.language import LanguageAnswer, LanguageQuery
from langpref.language.bank import NO_CHANGE_FEEDBACK

FEATURES = ["height", "speed", "distance_to_button"]


def test_answers_round_trip_through_the_file(tmp_path):
    given = [
        ("language", LanguageAnswer(LanguageQuery(3), "Move faster."), None),
        ("language", LanguageAnswer(LanguageQuery(4), NO_CHANGE_FEEDBACK), None),
        ("language", LanguageAnswer(LanguageQuery(5), "Lower!"), ("height", "decrease")),
        ("comparison", ComparisonAnswer(ComparisonQuery(7, 2), 1), None),
    ]
    records = [
        answer_record(kind, a, "P1", number=i, meaning=m, time="2026-12-03T10:00:00+00:00")
        for i, (kind, a, m) in enumerate(given, start=1)
    ]
    path = tmp_path / "answers.jsonl"
    assert write_answers(path, records) == 4
    back = read_answers(path, 10, FEATURES)
    assert [(r.kind, r.answer, r.meaning, r.number, r.participant) for r in back] == [
        (kind, a, m, i, "P1") for i, (kind, a, m) in enumerate(given, start=1)
    ]
    assert back[1].answer.no_change and json.loads(path.read_text().splitlines()[1])["no_change"] is True
    assert back[3].answer.preferred == 2


def test_trajectories_are_named_by_episode_and_the_names_are_read_only_when_used(tmp_path):
    path = tmp_path / "a.jsonl"
    calls = []

    def names():
        calls.append(1)
        return ["ep_a", None, "ep_c"]

    path.write_text(json.dumps({"kind": "language", "shown": 1, "text": "Higher."}) + "\n")
    read_answers(path, 3, FEATURES, names)
    assert calls == []
    path.write_text(json.dumps({"kind": "comparison", "shown": ["ep_c", "ep_a"], "choice": 0}) + "\n\n")
    (answer,) = read_answers(path, 3, FEATURES, names)
    assert (answer.answer.query.a, answer.answer.query.b, answer.answer.preferred) == (2, 0, 2)


@pytest.mark.parametrize(
    "line, says",
    [
        ("not json", "line 2: not JSON"),
        ('{"kind": "gesture", "shown": 1}', "'kind' must be one of"),
        ('{"kind": "language", "shown": 99, "text": "Faster."}', "trajectory 99 is not in the dataset"),
        ('{"kind": "language", "shown": true, "text": "Faster."}', "dataset index or an episode name"),
        ('{"kind": "language", "shown": "ep_x", "text": "Faster."}', "no episode named 'ep_x'"),
        ('{"kind": "language", "shown": 1, "text": "  "}', "needs 'text'"),
        ('{"kind": "comparison", "shown": [1, 1], "choice": 0}', "two different trajectories"),
        ('{"kind": "comparison", "shown": [1, 2], "choice": 2}', "'choice' must be 0"),
        ('{"kind": "language", "shown": 1, "text": "Hi.", "meaning": {"feature": "force"}}', "'meaning' is"),
        ('["a list"]', "an answer is a JSON object"),
    ],
)
def test_a_bad_line_is_one_error_naming_it(tmp_path, line, says):
    path = tmp_path / "a.jsonl"
    path.write_text(json.dumps({"kind": "language", "shown": 0, "text": "Faster."}) + "\n" + line + "\n")
    with pytest.raises(LangprefError, match="line 2") as err:
        read_answers(path, 10, FEATURES, lambda: ["ep_a"])
    assert says in str(err.value) and "\n" not in str(err.value)


def test_a_missing_empty_or_binary_file_is_one_line(tmp_path):
    for path, says in ((tmp_path / "nope.jsonl", "no answers file"), (tmp_path, "is a folder")):
        with pytest.raises(LangprefError, match=says):
            read_answers(path, 10, FEATURES)
    (tmp_path / "empty.jsonl").write_text("\n\n")
    with pytest.raises(LangprefError, match="holds no answers"):
        read_answers(tmp_path / "empty.jsonl", 10, FEATURES)
    (tmp_path / "bin.jsonl").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(LangprefError, match="not a text file"):
        read_answers(tmp_path / "bin.jsonl", 10, FEATURES)
