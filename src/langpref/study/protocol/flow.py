"""The participant's path through the study, as a state machine: (step, answer) -> next step.

    pre_survey --> improve: language -> satisfaction -> (not satisfied, rounds left) language -> ... --> improve_survey
      --> pref_<first method>: query 1..Q, a rating of the best trajectory after every `rating_every` queries
      --> pref_<second method>: the same --> pref_survey --> done

With `--confirm-margin`, a Study-2 language answer whose reading is uncertain is followed by a confirm step (the
model's top readings and "none of these", one click) before the robot learns from it.

Nothing here touches the database or the model: `advance` gets the current `Step`, a parsed `Answer` and a `Robot`
(the learning side, `langpref.study.session.engine`), and returns the next `Step` with the rows to store. The app writes
both in one transaction. Every step fixes what it shows when it is made, so showing it again (a reload, a restart)
shows the same thing.

The robot's feedback goes one way for every kind: the kind (`langpref.feedback.kind`) parses the answer into its
typed answer, says what of it is stored, and the robot learns from it; each Study-2 method is the kind of its name,
and the kinds a study runs are its config's (`StudyConfig.kinds`, `langpref.study.protocol.kinds`).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind
from langpref.study.protocol import kinds as study_kinds
from langpref.study.protocol.config import METHODS, StudyConfig
from langpref.study.protocol.surveys import survey_questions, validate_answers

if TYPE_CHECKING:
    from langpref.study.protocol.queries import Chosen

MAX_CLIENT_MS = 24 * 3600 * 1000
NONE_OF_THESE = "none of these"
"""The last option of a confirm step (its `meaning` is null): the answer is stored and not learned from."""


class AnswerError(LangprefError):
    """An answer that cannot be taken; `status` is the HTTP status (400 bad input, 409 wrong step)."""

    status = 400


class WrongStep(AnswerError):
    status = 409


@dataclass(frozen=True)
class Participant:
    id: str
    number: int
    method_order: tuple[str, str]
    seed: int


@dataclass(frozen=True)
class Confirmed:
    """What a participant confirmed a language answer meant: `meaning` (an index of the engine's meanings,
    `langpref.study.session.learners.Meanings`), or None for "none of these" (the answer is stored and not learned
    from)."""

    meaning: int | None


@dataclass(frozen=True)
class Step:
    """One screen. `number`: Study 1 rounds of feedback given so far; Study 2 the query number (1-based), or for a
    rating the queries it follows. `extra` is shown as is (e.g. how the last feedback was understood); `selection`
    (Study-2 queries: strategy, score, candidates scored) is stored, never shown; so is `confirm` (a confirm step:
    the answer it asks about, `shown` and `text`, and the reading's `margin` and options with their probabilities)."""

    seq: int
    phase: str
    kind: str
    shown: tuple[int, ...] = ()
    survey: str | None = None
    number: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
    selection: dict[str, Any] | None = None
    confirm: dict[str, Any] | None = None

    def payload(self) -> str:
        out = {"shown": list(self.shown), "survey": self.survey, "number": self.number, "extra": self.extra}
        if self.selection is not None:
            out["selection"] = self.selection
        if self.confirm is not None:
            out["confirm"] = self.confirm
        return json.dumps(out)

    @classmethod
    def from_row(cls, row: dict[str, Any]) -> Step:
        p = json.loads(row["payload"])
        return cls(
            int(row["seq"]),
            row["phase"],
            row["kind"],
            tuple(p["shown"]),
            p["survey"],
            int(p["number"]),
            p.get("extra") or {},
            p.get("selection"),
            p.get("confirm"),
        )

    @property
    def method(self) -> str | None:
        """The Study-2 method (feedback kind) of the step's phase `pref_NAME`, else None."""
        if self.phase.startswith("pref_") and self.phase != "pref_survey":
            return self.phase[len("pref_") :]
        return None


@dataclass(frozen=True)
class Answer:
    """A checked answer to a step; `value` is the feedback kind's typed answer on language and comparison steps;
    `body` is what is stored of the request: the contract's fields only, checked and cleaned."""

    kind: str
    value: Any
    client_ms: float | None = None
    body: dict[str, Any] = field(default_factory=dict)


_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f]")
_BIDI = re.compile(r"[\u202a-\u202e\u2066-\u2069]")
"""Bidirectional embeddings, overrides and isolates: invisible, they reverse how a line is shown (dashboard, CSV)."""
SURROGATES = re.compile(r"[\ud800-\udfff]")
"""Lone UTF-16 surrogates (`"\\ud800"` in JSON): no character, they cannot be written as UTF-8 (database, export)."""
MAX_TEXT_DEPTH = 32
"""Deepest nesting of lists and objects `clean_text` walks (the app refuses deeper bodies before)."""


def clean_text(value: Any) -> Any:
    """Every string in `value` with bidirectional controls removed; control characters (NUL, escape, ...; tab and
    line breaks are fine), lone surrogates and nesting deeper than MAX_TEXT_DEPTH refused with an AnswerError.
    Walks without recursion."""
    out: list[Any] = [None]
    todo: list[tuple[Any, Any, Any, int]] = [(value, out, 0, 0)]  # (value, where its clean copy goes, key, depth)
    while todo:
        item, parent, key, level = todo.pop()
        if level > MAX_TEXT_DEPTH:
            raise AnswerError(f"the answer is nested too deeply (more than {MAX_TEXT_DEPTH} levels)")
        if isinstance(item, str):
            parent[key] = _clean_string(item)
        elif isinstance(item, list):
            parent[key] = copy = [None] * len(item)
            todo.extend((v, copy, i, level + 1) for i, v in enumerate(item))
        elif isinstance(item, dict):
            parent[key] = copy = {}
            for k, v in item.items():
                k = _clean_string(k) if isinstance(k, str) else k
                copy[k] = None  # keeps the order of the keys
                todo.append((v, copy, k, level + 1))
        else:
            parent[key] = item
    return out[0]


def _clean_string(text: str) -> str:
    if _CONTROL.search(text):
        raise AnswerError("the answer contains control characters (such as NUL); send plain text")
    if SURROGATES.search(text):
        raise AnswerError("the answer contains a lone UTF-16 surrogate (\\ud800-\\udfff), which is no character")
    return _BIDI.sub("", text)


class Robot(Protocol):
    """What the flow asks of the learning side (implemented by `engine.StudyRobot`)."""

    def start_trajectory(self, p: Participant) -> int: ...

    def improve(self, p: Participant, shown: int, text: str, round_: int) -> tuple[int, dict[str, Any]]:
        """Round `round_` (1-based) of Study 1: the trajectory shown next, and how the feedback was read."""

    def query(self, p: Participant, method: str, number: int) -> Chosen:
        """What query `number` (1-based) of a Study-2 method shows, and why; asked before answer `number - 1` is
        stored, right after `learn` has taken it."""

    def learn(
        self, p: Participant, method: str, number: int, answer: Any, confirmed: Confirmed | None = None
    ) -> dict[str, Any] | None:
        """Learn from answer `number` of `method` (as the meaning the participant `confirmed`, when asked); how the
        robot read it (language), or None."""

    def confirm(self, p: Participant, method: str, answer: Any) -> dict[str, Any] | None:
        """None when the robot reads `answer` surely enough (or never asks); else what to ask: `options` (each
        `{"meaning", "text", "feature", "direction", "p"}`, likeliest first), the reading's `margin`, and
        `understood` (as `learn` returns it)."""

    def best(self, p: Participant, method: str) -> int: ...

    def reward(self, p: Participant, method: str) -> dict[str, Any]:
        """The reward learned so far: `learner`, `latent_weights`, `feature_weights` (or None), `ranking`."""


def first_step() -> Step:
    return Step(0, "pre_survey", "survey", survey="pre")


def progress(cfg: StudyConfig, step: Step) -> dict[str, int]:
    """`{done, total}` within the step's phase: rounds of Study 1, queries of a Study-2 method."""
    if step.phase == "improve":
        return {"done": step.number, "total": cfg.improve_max_iterations}
    if step.method:
        done = step.number if step.kind == "rating" else step.number - 1
        return {"done": done, "total": cfg.pref_queries}
    if step.phase == "done":
        return {"done": 1, "total": 1}
    return {"done": 0, "total": 1}


def _number(body: dict, key: str, lo: float, hi: float, what: str, integer: bool) -> Any:
    value = body.get(key)
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    # the range first: math.isnan of a huge integer raises OverflowError
    if isinstance(value, bool) or not ok or not lo <= value <= hi or math.isnan(value):
        raise AnswerError(f"{key!r} must be {what}")
    return value


def parse_answer(body: Any, step: Step, kinds: tuple[str, ...] = METHODS) -> Answer:
    """Check an answer body against the current step of a study of `kinds`: a WrongStep (409) for another kind or
    another step's `seq`, else AnswerError (400): a bad value, control characters in text."""
    key = _answer_key(body, step, study_kinds.answer_keys(kinds))
    kind = step.kind
    body = clean_text(body)
    client_ms = None
    if study_kinds.asks_feedback(kind):
        client_ms = float(
            _number(
                body,
                "client_ms",
                0,
                MAX_CLIENT_MS,
                "the milliseconds from showing the videos to the answer (a number >= 0)",
                integer=False,
            )
        )
    value = _answer_value(kind, body, step, kinds)
    if step.phase == "improve" and getattr(value, "no_change", False):
        raise AnswerError("here, type how the robot should change; after it moves you are asked if you are satisfied")
    stored: dict[str, Any] = {"seq": step.seq}
    if kind == "survey":
        stored["answers"] = value
    else:
        stored[key] = body[key]
        if client_ms is not None:
            stored["client_ms"] = client_ms
    return Answer(kind, value, client_ms, stored)


def _answer_key(body: Any, step: Step, keys: dict[str, tuple[str, ...]]) -> str:
    """The answer field `body` holds (one of `keys`, `kinds.answer_keys`), checked against the current step (its kind
    and, when sent, its `seq`)."""
    if not isinstance(body, dict):
        raise AnswerError("the body must be a JSON object")
    # only the contract's fields are read and stored. `seq` (the step answered) is optional, as in docs/design.md's
    # contract that outside clients follow; when it is sent, an old answer sent again is never taken for the current
    # step (our pages and simulated participants always send it)
    found = [k for k in body if k in keys]
    if not found:
        raise AnswerError("missing answer field: send one of " + ", ".join(f"'{k}'" for k in keys))
    if len(found) > 1:
        raise AnswerError("send one answer at a time: the body has fields of several kinds")
    key = found[0]
    if step.kind == "done":
        raise WrongStep("the study is finished; there is nothing left to answer")
    if step.kind not in keys[key]:
        raise WrongStep(f"the current step is a {step.kind} step, not {keys[key][0]}: GET the step and answer it")
    if "seq" in body and (isinstance(body["seq"], bool) or not isinstance(body["seq"], int)):
        raise AnswerError("'seq' must be the integer seq of the step you answer")
    if body.get("seq", step.seq) != step.seq:
        raise WrongStep(f"step {body['seq']!r} was already answered; the current step is {step.seq}")
    return key


def _answer_value(kind: str, body: dict[str, Any], step: Step, kinds: tuple[str, ...]) -> Any:
    """The answer's value, checked (a feedback kind parses its own; a library error becomes an AnswerError)."""
    try:
        if study_kinds.asks_feedback(kind):
            feedback = get_kind(kind)
            return feedback.parse(body[feedback.answer_key], feedback.query(*step.shown))
        if kind == "survey":
            return validate_answers(step.survey or "", body["answers"], kinds)
        if kind == "confirm":
            value = body["meaning"]
            offered = [o["meaning"] for o in step.extra.get("options", ())]
            if isinstance(value, bool) or not (value is None or isinstance(value, int)) or value not in offered:
                raise AnswerError("'meaning' must be the meaning of one of the options, or null for none of these")
            return value
        if kind == "satisfaction":
            if not isinstance(body["satisfied"], bool):
                raise AnswerError("'satisfied' must be true or false")
            return body["satisfied"]
        return _number(body, "rating", 1, 5, "an integer from 1 to 5", integer=True)
    except AnswerError:
        raise
    except LangprefError as exc:
        raise AnswerError(str(exc)) from None


@dataclass
class Transition:
    next: Step
    records: list[tuple[str, dict[str, Any]]]
    """(table, row) to store with the answer; every row also gets participant_id, seq and answered_at."""


def _query(p: Participant, robot: Robot, seq: int, method: str, q: int) -> Step:
    """Query number `q` (1-based) of a Study-2 method; the kind of step is the method's name."""
    chosen = robot.query(p, method, q)
    return Step(seq, f"pref_{method}", method, chosen.shown, number=q, selection=chosen.record())


def _pref_start(cfg: StudyConfig, p: Participant, robot: Robot, seq: int, method: str) -> Step:
    return _query(p, robot, seq, method, 1)


def _after_method(cfg: StudyConfig, p: Participant, robot: Robot, seq: int, method: str) -> Step:
    later = p.method_order[p.method_order.index(method) + 1 :]
    if later:
        return _pref_start(cfg, p, robot, seq, later[0])
    return Step(seq, "pref_survey", "survey", survey="pref")


def advance(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot) -> Transition:
    """The next step after `answer` to `step` (already checked by `parse_answer`), and the rows to store."""
    if step.kind == "survey":
        return _after_survey(cfg, p, step, answer, robot)
    if step.phase == "improve":
        return _after_improve(cfg, p, step, answer, robot)
    assert step.method is not None, step  # Study 2 from here on: every step belongs to a method
    if step.kind == "rating":
        return _after_rating(cfg, p, step, answer, robot)
    if step.kind == "confirm":
        return _confirmed(cfg, p, step, answer, robot, step.method)
    return _after_query(cfg, p, step, answer, robot)


def _after_survey(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot) -> Transition:
    """A questionnaire answered: its responses, then Study 1 (after the first), Study 2 (after Study 1's) or done."""
    seq = step.seq + 1
    items = {q["id"]: q for q in survey_questions(step.survey or "", cfg.kinds)}
    records = [
        (
            "survey_responses",
            {
                "survey": step.survey,
                "question_id": qid,
                "item": items[qid]["item"],
                "method": items[qid]["method"],
                "value": json.dumps(v),
            },
        )
        for qid, v in answer.value.items()
    ]
    if step.survey == "pre":
        start = (robot.start_trajectory(p),)
        return Transition(Step(seq, "improve", study_kinds.STUDY1, start, number=0), records)
    if step.survey == "improve":
        return Transition(_pref_start(cfg, p, robot, seq, p.method_order[0]), records)
    return Transition(Step(seq, "done", "done"), records)


def _after_improve(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot) -> Transition:
    """Study 1: feedback improves the trajectory shown, then the participant says whether they are satisfied; the
    study goes on to its survey when they are, or when the rounds are used up."""
    seq = step.seq + 1
    shown = step.shown[0]
    if step.kind == study_kinds.STUDY1:
        text = answer.value.text
        improved, understood = robot.improve(p, shown, text, step.number + 1)
        row = {
            "phase": "improve",
            "number": step.number + 1,
            "shown": shown,
            "text": text,
            "improved": improved,
            **_understood_columns(understood),
            "client_ms": answer.client_ms,
        }
        extra = {"understood": {**understood, "text": text}, "previous": shown, "unchanged": improved == shown}
        return Transition(
            Step(seq, "improve", "satisfaction", (improved,), number=step.number + 1, extra=extra), [("feedback", row)]
        )
    row = {"iteration": step.number, "shown": shown, "satisfied": int(answer.value)}
    if answer.value or step.number >= cfg.improve_max_iterations:
        return Transition(Step(seq, "improve_survey", "survey", survey="improve"), [("satisfaction", row)])
    again = Step(seq, "improve", study_kinds.STUDY1, (shown,), number=step.number)
    return Transition(again, [("satisfaction", row)])


def _after_rating(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot) -> Transition:
    """Study 2: a rating of the best trajectory so far; then the next query, or the method is over."""
    method = step.method
    assert method is not None, step
    seq = step.seq + 1
    row = {"method": method, "after_queries": step.number, "shown": step.shown[0], "rating": answer.value}
    if step.number >= cfg.pref_queries:
        return Transition(_after_method(cfg, p, robot, seq, method), [("ratings", row)])
    return Transition(_query(p, robot, seq, method, step.number + 1), [("ratings", row)])


def _after_query(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot) -> Transition:
    """Study 2: an answer to query number `step.number` of the step's method. The robot learns from it, or (with
    `--confirm-margin`, when unsure what a sentence meant) asks first in a confirm step."""
    method = step.method
    assert method is not None, step
    seq, q = step.seq + 1, step.number
    kind, feedback = get_kind(method), answer.value
    ask = robot.confirm(p, method, feedback) if cfg.confirm_margin is not None else None
    understood = ask["understood"] if ask is not None else robot.learn(p, method, q, feedback)
    # language: its reading is stored (the feedback table, Study 1's too, says the phase)
    read = {} if understood is None else {"phase": step.phase, "improved": None, **_understood_columns(understood)}
    row = {**study_kinds.kind_row(kind, feedback, read), "number": q, "client_ms": answer.client_ms}
    extra: dict[str, Any] = {}
    if understood is not None:
        extra = {"understood": {**understood, "text": feedback.text}}
    if ask is not None:  # the robot learns once the participant has said what they meant
        options = [{"meaning": o["meaning"], "text": o["text"]} for o in ask["options"]]
        nxt = Step(
            seq,
            step.phase,
            "confirm",
            number=q,
            extra={"said": feedback.text, "options": [*options, {"meaning": None, "text": NONE_OF_THESE}]},
            confirm={"shown": step.shown[0], "text": feedback.text, "margin": ask["margin"], "options": ask["options"]},
        )
        return Transition(nxt, [(kind.table, row)])
    records = [(kind.table, row), ("rewards", reward_row(robot, p, method, q))]
    return Transition(_after_answer(cfg, p, robot, seq, step.phase, method, q, extra), records)


def _after_answer(
    cfg: StudyConfig, p: Participant, robot: Robot, seq: int, phase: str, method: str, q: int, extra: dict[str, Any]
) -> Step:
    """After answer `q` of `method` is learned: a rating at a rating point, else the next query."""
    if q in cfg.rating_points():
        return Step(seq, phase, "rating", (robot.best(p, method),), number=q, extra=extra)
    return replace(_query(p, robot, seq, method, q + 1), extra=extra)


def _confirmed(cfg: StudyConfig, p: Participant, step: Step, answer: Answer, robot: Robot, method: str) -> Transition:
    """The answer to a confirm step: the robot learns the language answer as the meaning chosen (none: not at all)."""
    asked, meaning, q = step.confirm or {}, answer.value, step.number
    feedback = get_kind(method).from_record({"shown": asked["shown"], "text": asked["text"]})
    robot.learn(p, method, q, feedback, Confirmed(meaning))
    chosen = next((o for o in asked["options"] if o["meaning"] == meaning), None)
    row = {
        "method": method,
        "number": q,
        "shown": asked["shown"],
        "text": asked["text"],
        "margin": asked["margin"],
        "options": json.dumps(asked["options"]),
        "meaning": meaning,
        "feature": chosen and chosen["feature"],
        "direction": chosen and chosen["direction"],
        "rank": None if chosen is None else asked["options"].index(chosen) + 1,
    }
    records = [("confirmations", row), ("rewards", reward_row(robot, p, method, q))]
    return Transition(_after_answer(cfg, p, robot, step.seq + 1, step.phase, method, q, {}), records)


def reward_row(robot: Robot, p: Participant, method: str, number: int) -> dict[str, Any]:
    """The `rewards` row of the reward learned after answer `number` of `method` (JSON columns)."""
    learned = robot.reward(p, method)
    return {
        "method": method,
        "number": number,
        "learner": learned["learner"],
        **{k: None if learned[k] is None else json.dumps(learned[k]) for k in ("latent_weights", "feature_weights")},
        "ranking": json.dumps(learned["ranking"]),
    }


def _understood_columns(understood: dict[str, Any]) -> dict[str, Any]:
    return {
        "understood_feature": understood.get("feature"),
        "understood_direction": understood.get("direction"),
        "understood_confidence": understood.get("confidence"),
    }


def questions(step: Step, kinds: tuple[str, ...] = METHODS) -> list[dict[str, Any]]:
    """The questions of a survey step of a study of `kinds` (none for other steps)."""
    if step.kind != "survey" or not step.survey:
        return []
    return [dict(q) for q in survey_questions(step.survey, kinds)]
