"""The participant state machine on its own, with a scripted robot: phases, rounds, rating points, validation."""

from __future__ import annotations

import itertools

import pytest

from langpref.errors import LangprefError
from langpref.feedback import ComparisonAnswer, ComparisonQuery, LanguageAnswer, LanguageQuery
from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.flow import (
    Answer,
    AnswerError,
    Participant,
    Step,
    WrongStep,
    advance,
    first_step,
    parse_answer,
    progress,
)
from langpref.study.protocol.queries import Chosen
from langpref.study.protocol.surveys import SURVEYS, validate_answers


class ScriptedRobot:
    """Improves trajectory t to t + 1, shows query q as trajectory 100 + q, best = 7; records what it learned."""

    def __init__(self):
        self.learned = []

    def start_trajectory(self, p):
        return 0

    def improve(self, p, shown, text, round_):
        return shown + 1, {"feature": "speed", "direction": "increase", "confidence": 0.9}

    def learn(self, p, method, number, answer):
        self.learned.append((method, number, answer))
        return {"feature": "speed", "direction": "increase", "confidence": 0.9} if method == "language" else None

    def query(self, p, method, number):
        shown = (100 + number,) if method == "language" else (100 + number, 200 + number)
        return Chosen(shown, "random", None, 300)

    def best(self, p, method):
        return 7

    def reward(self, p, method):
        return {"learner": "paper", "latent_weights": [0.5], "feature_weights": None, "ranking": [7, 3]}


def value_for(q, likert=3, text="x", multi=1):
    if q["type"] == "likert":
        return likert
    if q["type"] == "text":
        return text
    return q["options"][0] if q["type"] == "choice" else q["options"][:multi]


def survey_answer(survey):
    return Answer("survey", validate_answers(survey, {q["id"]: value_for(q) for q in SURVEYS[survey]}))


def run(cfg, p, answers):
    """Walk the flow, answering with `answers(step)`; the list of steps visited."""
    robot, step, steps = ScriptedRobot(), first_step(), []
    while step.kind != "done":
        steps.append(step)
        step = advance(cfg, p, step, answers(step), robot).next
        assert step.seq == steps[-1].seq + 1
    return steps + [step], robot


def default_answers(satisfied_at=None):
    def answer(step):
        if step.kind == "survey":
            return survey_answer(step.survey)
        if step.kind == "language":
            return Answer("language", LanguageAnswer(LanguageQuery(step.shown[0]), "Move faster."), 10.0)
        if step.kind == "comparison":
            return Answer("comparison", ComparisonAnswer(ComparisonQuery(*step.shown), 1), 10.0)
        if step.kind == "satisfaction":
            return Answer("satisfaction", satisfied_at is not None and step.number >= satisfied_at)
        return Answer("rating", 4)

    return answer


P_LANG = Participant("a", 1, ("language", "comparison"), 1)
P_COMP = Participant("b", 2, ("comparison", "language"), 2)


def test_whole_path_follows_the_paper():
    cfg = StudyConfig(improve_max_iterations=3, pref_queries=4, rating_every=2)
    steps, robot = run(cfg, P_LANG, default_answers())
    phases = [s.phase for s in steps]
    assert phases[0] == "pre_survey" and phases[-1] == "done"
    order = list(dict.fromkeys(phases))
    assert order == [
        "pre_survey",
        "improve",
        "improve_survey",
        "pref_language",
        "pref_comparison",
        "pref_survey",
        "done",
    ]
    improve = [(s.kind, s.number, s.shown) for s in steps if s.phase == "improve"]
    # never satisfied: 3 rounds of feedback, each followed by the improved trajectory
    assert improve == [
        ("language", 0, (0,)),
        ("satisfaction", 1, (1,)),
        ("language", 1, (1,)),
        ("satisfaction", 2, (2,)),
        ("language", 2, (2,)),
        ("satisfaction", 3, (3,)),
    ]
    lang = [(s.kind, s.number, s.shown) for s in steps if s.phase == "pref_language"]
    assert lang == [
        ("language", 1, (101,)),
        ("language", 2, (102,)),
        ("rating", 2, (7,)),
        ("language", 3, (103,)),
        ("language", 4, (104,)),
        ("rating", 4, (7,)),
    ]
    comp = [(s.kind, s.number) for s in steps if s.phase == "pref_comparison"]
    assert comp == [
        ("comparison", 1),
        ("comparison", 2),
        ("rating", 2),
        ("comparison", 3),
        ("comparison", 4),
        ("rating", 4),
    ]
    assert [x[1] for x in robot.learned if x[0] == "language"] == [1, 2, 3, 4]
    assert [x[2] for x in robot.learned if x[0] == "comparison"] == [
        ComparisonAnswer(ComparisonQuery(100 + q, 200 + q), 1) for q in (1, 2, 3, 4)
    ]
    # the step after every language answer says how the robot understood it
    after_language = [b for a, b in itertools.pairwise(steps) if a.kind == "language"]
    assert after_language and all(b.extra["understood"]["feature"] == "speed" for b in after_language)


def test_counterbalanced_order_and_satisfaction_ends_study_1():
    cfg = StudyConfig(improve_max_iterations=10, pref_queries=2, rating_every=5)
    steps, _ = run(cfg, P_COMP, default_answers(satisfied_at=2))
    order = list(dict.fromkeys(s.phase for s in steps))
    assert order.index("pref_comparison") < order.index("pref_language")
    assert [s.kind for s in steps if s.phase == "improve"] == ["language", "satisfaction"] * 2
    # Q = 2 is not a multiple of 5: the one rating comes after the last query
    assert cfg.rating_points() == [2]
    assert [(s.kind, s.number) for s in steps if s.phase == "pref_language"] == [
        ("language", 1),
        ("language", 2),
        ("rating", 2),
    ]


def test_rating_points_and_progress():
    cfg = StudyConfig()
    assert cfg.rating_points() == [5, 10, 15, 20]
    assert StudyConfig(pref_queries=7, rating_every=3).rating_points() == [3, 6, 7]
    assert progress(cfg, Step(5, "pref_language", "language", (1,), number=7)) == {"done": 6, "total": 20}
    assert progress(cfg, Step(5, "pref_language", "rating", (1,), number=10)) == {"done": 10, "total": 20}
    assert progress(cfg, Step(5, "improve", "satisfaction", (1,), number=2)) == {"done": 2, "total": 10}


@pytest.mark.parametrize(
    "body, status",
    [
        ([], 400),
        ({}, 400),
        ({"feedback": "x", "choice": 1, "seq": 3}, 400),
        ({"choice": 1, "client_ms": 3}, 409),
        ({"feedback": "   \n\t ", "client_ms": 3, "seq": 3}, 400),
        ({"feedback": "x" * 501, "client_ms": 3, "seq": 3}, 400),
        ({"feedback": 5, "client_ms": 3, "seq": 3}, 400),
        ({"feedback": "ok", "seq": 3}, 400),
        ({"feedback": "ok", "client_ms": -1, "seq": 3}, 400),
        ({"feedback": "ok", "client_ms": True, "seq": 3}, 400),
        ({"feedback": "ok", "client_ms": 3, "seq": 4}, 409),
        # a seq that is not an integer (without one, docs/design.md's clients, the answer is for the current step)
        ({"feedback": "Move faster.", "client_ms": 3, "seq": "3"}, 400),
        ({"feedback": "Move\x00 faster.", "client_ms": 3, "seq": 3}, 400),
        ({"feedback": "Move faster.", "client_ms": 10**400, "seq": 3}, 400),
    ],
)
def test_parse_answer_refuses_bad_language_answers(body, status):
    step = Step(3, "improve", "language", (0,))
    with pytest.raises(AnswerError) as info:
        parse_answer(body, step)
    assert info.value.status == status
    assert isinstance(info.value, WrongStep) == (status == 409)


def test_parse_answer_accepts_and_trims():
    step = Step(3, "improve", "language", (0,))
    a = parse_answer({"feedback": "  Move faster.  ", "client_ms": 1200, "seq": 3}, step)
    assert (a.kind, a.value, a.client_ms) == ("language", LanguageAnswer(LanguageQuery(0), "Move faster."), 1200.0)
    assert parse_answer({"feedback": "x" * 500, "client_ms": 0, "seq": 3}, step).value.text == "x" * 500
    rating = Step(4, "pref_language", "rating", (0,), number=5)
    for bad in (0, 6, 2.5, "3", True, None):
        with pytest.raises(AnswerError):
            parse_answer({"rating": bad, "seq": 4}, rating)
    assert parse_answer({"rating": 5, "seq": 4}, rating).value == 5
    comp = Step(4, "pref_comparison", "comparison", (0, 1), number=1)
    for bad in (2, -1, True, "1", 0.0):
        with pytest.raises(AnswerError):
            parse_answer({"choice": bad, "client_ms": 1, "seq": 4}, comp)
    assert parse_answer({"choice": 1, "client_ms": 1, "seq": 4}, comp).value == ComparisonAnswer(
        ComparisonQuery(0, 1), 1
    )
    with pytest.raises(WrongStep):
        parse_answer({"rating": 3}, Step(9, "done", "done"))


def test_survey_validation():
    ok = {q["id"]: value_for(q, likert=5, multi=2) for q in SURVEYS["pre"]}
    assert validate_answers("pre", ok)["robotics_experience"] == 5
    for qid, bad in (
        ("robotics_experience", 6),
        ("robotics_experience", True),
        ("gender", "Robot"),
        ("race", "Asian"),
        ("race", ["Asian", "Asian"]),
        ("age", 27),
    ):
        with pytest.raises(LangprefError):
            validate_answers("pre", {**ok, qid: bad})
    with pytest.raises(LangprefError, match="unknown question"):
        validate_answers("pre", {**ok, "favourite_colour": "blue"})
    with pytest.raises(LangprefError, match="needs an answer"):
        validate_answers("pre", {k: v for k, v in ok.items() if k != "gender"})
    pref = {
        q["id"]: ["None of them"] if q["type"] == "multi" else value_for(q, likert=2, text="") for q in SURVEYS["pref"]
    }
    assert "comments" not in validate_answers("pref", pref)  # optional text left empty
    with pytest.raises(LangprefError, match="None of them"):
        validate_answers("pref", {**pref, "aspects_language": ["None of them", "Convenience"]})


def test_text_is_cleaned_and_only_contract_fields_are_kept():
    """Bidirectional overrides are removed from every text (they reverse a line on the dashboard); unknown fields are
    not stored."""
    step = Step(3, "improve", "language", (0,))
    a = parse_answer({"feedback": "\u202eMove faster.\u202c", "client_ms": 5, "seq": 3, "junk": "x" * 60000}, step)
    assert a.value.text == "Move faster."
    assert a.body == {"seq": 3, "feedback": "Move faster.", "client_ms": 5.0}
    survey = Step(0, "pre_survey", "survey", survey="pre")
    answers = {q["id"]: value_for(q, likert=3, multi=1) for q in SURVEYS["pre"]}
    answers["robot_interaction"] = "\u2066Never\u2069"
    a = parse_answer({"answers": answers, "seq": 0, "extra": {"a": 1}}, survey)
    assert a.body["answers"]["robot_interaction"] == "Never" and set(a.body) == {"seq", "answers"}


def test_said_is_the_typed_sentence_of_a_kind_that_holds_one():
    """What the model reads of an answer is the kind's own (`FeedbackKind.sentence`), no type checked by the study."""
    from langpref.feedback import get_kind
    from langpref.language.bank import NO_CHANGE_FEEDBACK
    from langpref.study.protocol.kinds import said

    language, comparison = get_kind("language"), get_kind("comparison")
    assert said(language, LanguageAnswer(LanguageQuery(3), "Go higher.")) == "Go higher."
    assert said(language, LanguageAnswer(LanguageQuery(3), NO_CHANGE_FEEDBACK)) is None  # a button, not read
    assert said(comparison, ComparisonAnswer(ComparisonQuery(1, 2), 0)) is None
