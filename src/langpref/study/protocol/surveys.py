"""The study's questionnaires (paper Appendix B) and task descriptions (Appendix D, adapted), as data.

A question is `{"id", "text", "type", "min", "max", "options"}` (the HTTP contract) plus `item` (its number in
Appendix B), `required`, `labels` (the words at both ends of a Likert scale) and `method` (which Study-2 method a
per-method question is about). The post-study preference-learning items about the methods (1, 3-6) are asked once
per method, so that the export can put the two methods side by side as the paper does; a study of other kinds
(`StudyConfig.kinds`) asks them about each of its kinds, by the kind's label (`survey_questions`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import Any

from langpref.errors import LangprefError
from langpref.study.protocol.config import METHODS
from langpref.study.protocol.kinds import label
from langpref.tasks import get_task

NONE_OF_THEM = "None of them"
ASPECTS = ("Adaptability", "Time efficiency", "Convenience")
METHOD_LABELS = {m: label(m) for m in METHODS}
"""The paper's two methods as participants read them (their kinds' `StudyPage.label`)."""
MAX_TEXT = 2000


def _q(
    qid: str,
    item: int,
    text: str,
    type_: str,
    *,
    options: list[str] | None = None,
    labels=None,
    required: bool = True,
    method: str | None = None,
    lo: int = 1,
    hi: int = 5,
) -> dict[str, Any]:
    likert = type_ == "likert"
    return {
        "id": qid,
        "text": text,
        "type": type_,
        "min": lo if likert else None,
        "max": hi if likert else None,
        "options": list(options or []),
        "item": item,
        "required": required,
        "labels": list(labels) if labels else None,
        "method": method,
    }


PRE = [
    _q("age", 1, "Age", "text"),
    _q("gender", 2, "Gender", "choice", options=["Female", "Male", "Non-binary", "Other", "Prefer not to say"]),
    _q(
        "race",
        3,
        "Race",
        "multi",
        options=[
            "American Indian or Alaska Native",
            "Asian",
            "Black or African American",
            "Hispanic or Latino",
            "Middle Eastern or North African",
            "Native Hawaiian or Pacific Islander",
            "White",
            "Other",
            "Prefer not to say",
        ],
    ),
    _q(
        "education",
        4,
        "Highest level of education",
        "choice",
        options=[
            "High school or less",
            "Some college",
            "Bachelor's degree",
            "Master's degree",
            "Doctorate",
            "Other",
            "Prefer not to say",
        ],
    ),
    _q(
        "robotics_experience",
        5,
        "Please describe your level of robotics experience, on a scale from 1 to 5.",
        "likert",
        labels=("No experience", "Expert"),
    ),
    _q(
        "ml_experience",
        6,
        "Please describe your level of machine learning experience, on a scale from 1 to 5.",
        "likert",
        labels=("No experience", "Expert"),
    ),
    _q("robot_interaction", 7, "Have you ever interacted with a robot before? Please describe:", "text"),
]

IMPROVE = [
    _q(
        "satisfied_final",
        1,
        "Are you satisfied with the final trajectory?",
        "likert",
        labels=("Completely unsatisfied", "Completely satisfied"),
    ),
    _q(
        "iterations_to_adapt",
        2,
        "How many iterations did it take for the robot to adapt to your feedback?",
        "choice",
        options=[str(i) for i in range(1, 11)] + ["It did not adapt"],
    ),
    _q(
        "adapt_speed", 3, "How fast does the robot adapt to your feedback?", "likert", labels=("Very slow", "Very fast")
    ),
    _q(
        "experience",
        4,
        "How did the robot's learning capabilities affect your interaction experience?",
        "likert",
        labels=("Negatively", "Positively"),
    ),
    _q("effective", 5, "Overall, do you think the approach is effective?", "choice", options=["Yes", "No"]),
    _q("comments", 6, "Do you have any other comments?", "text", required=False),
]

# The per-method Likert items of the preference-learning survey: (id stem, item, text, labels).
PREF_LIKERT = [
    (
        "adapt_speed",
        3,
        "How long did it take for the robot to adapt to your feedback?",
        ("Very slowly", "Very quickly"),
    ),
    (
        "experience",
        4,
        "How did the robot's learning capabilities affect your interaction experience?",
        ("Negatively", "Positively"),
    ),
    (
        "noticed_learning",
        5,
        "Did you notice the robot learning or adapting to your behavior?",
        ("Not at all", "Constantly"),
    ),
    (
        "trust",
        6,
        "How did the robot's learning process affect your level of trust in its capabilities?",
        ("Negatively", "Positively"),
    ),
]


def _pref(kinds: Sequence[str]) -> list[dict[str, Any]]:
    """The preference-learning survey of a study of `kinds` (the paper's items 1 and 3-6 once per kind; item 7's
    options the kinds in reverse order, as the paper lists its two: comparison first)."""
    qs = []
    for m in kinds:
        qs.append(
            _q(
                f"aspects_{m}",
                1,
                f"{label(m)}: what did you like about this method? Tick each aspect in "
                "which you found the method satisfactory.",
                "multi",
                options=[*ASPECTS, NONE_OF_THEM],
                method=m,
            )
        )
    qs.append(_q("aspects_reasons", 2, "Could you explain the reasons?", "text", required=False))
    for stem, item, text, labels in PREF_LIKERT:
        for m in kinds:
            qs.append(_q(f"{stem}_{m}", item, f"{label(m)}: {text}", "likert", labels=labels, method=m))
    qs.append(
        _q(
            "preferred",
            7,
            "Overall, which method do you prefer?",
            "choice",
            options=[label(m) for m in reversed(kinds)],
        )
    )
    qs.append(_q("preferred_why", 8, "Why do you prefer this method?", "text", required=False))
    qs.append(
        _q("wish", 9, "Is there anything you wish the system would do but currently does not?", "text", required=False)
    )
    qs.append(_q("comments", 10, "Do you have any other comments?", "text", required=False))
    return qs


PREF = _pref(METHODS)
SURVEYS: dict[str, list[dict[str, Any]]] = {"pre": PRE, "improve": IMPROVE, "pref": PREF}
"""The questionnaires of the paper's study (its two kinds)."""
SURVEY_TITLES = {
    "pre": "Before we begin",
    "improve": "About Experiment 1: improving a trajectory",
    "pref": "About Experiment 2: learning your preferences",
}


@cache
def _surveys(kinds: tuple[str, ...]) -> dict[str, list[dict[str, Any]]]:
    return SURVEYS if kinds == METHODS else {"pre": PRE, "improve": IMPROVE, "pref": _pref(kinds)}


def survey_questions(survey: str, kinds: Sequence[str] = METHODS) -> list[dict[str, Any]]:
    """The questions of `survey` (`pre`, `improve`, `pref`) in a study of `kinds` (made once per kinds)."""
    return _surveys(tuple(kinds))[survey]


def validate_answers(survey: str, answers: Any, kinds: Sequence[str] = METHODS) -> dict[str, Any]:
    """The checked answers of one survey of a study of `kinds` (unknown ids, wrong types, missing required items: a
    LangprefError)."""
    if not isinstance(answers, dict):
        raise LangprefError("'answers' must be an object {question_id: value}")
    questions = {q["id"]: q for q in survey_questions(survey, kinds)}
    unknown = sorted(set(answers) - set(questions))
    if unknown:
        raise LangprefError(f"unknown question id(s) {', '.join(map(str, unknown[:5]))} for this survey")
    out: dict[str, Any] = {}
    for qid, q in questions.items():
        value = answers.get(qid)
        if (
            value is None
            or (q["type"] in ("text",) and isinstance(value, str) and not value.strip())
            or (q["type"] == "multi" and value == [])
        ):
            if q["required"]:
                raise LangprefError(f"question {qid!r} needs an answer")
            continue
        out[qid] = _check_value(q, value)
    return out


def _check_value(q: dict[str, Any], value: Any) -> Any:
    qid, kind = q["id"], q["type"]
    if kind == "likert":
        if isinstance(value, bool) or not isinstance(value, int) or not q["min"] <= value <= q["max"]:
            raise LangprefError(f"question {qid!r} takes an integer from {q['min']} to {q['max']}")
        return value
    if kind == "text":
        if not isinstance(value, str):
            raise LangprefError(f"question {qid!r} takes a text answer")
        if len(value) > MAX_TEXT:
            raise LangprefError(f"the answer to {qid!r} is over {MAX_TEXT} characters; please shorten it")
        return value.strip()
    if kind == "choice":
        if not isinstance(value, str) or value not in q["options"]:
            raise LangprefError(f"question {qid!r} takes one of: {', '.join(q['options'])}")
        return value
    if not isinstance(value, list) or not all(isinstance(v, str) and v in q["options"] for v in value):
        raise LangprefError(f"question {qid!r} takes a list of options among: {', '.join(q['options'])}")
    if len(set(value)) != len(value):
        raise LangprefError(f"question {qid!r} lists an option twice")
    if NONE_OF_THEM in value and len(value) > 1:
        raise LangprefError(f"question {qid!r}: '{NONE_OF_THEM}' cannot be ticked with another aspect")
    return [o for o in q["options"] if o in value]


def task_text(task_name: str) -> dict[str, Any]:
    """What the guidelines tell participants about the task: the robot, what it does, example phrasings."""
    task = get_task(task_name)
    return {"robot": task.robot, "task": task.description, "examples": list(task.examples)}
