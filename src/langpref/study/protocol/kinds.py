"""The kinds of feedback a study runs (`StudyConfig.kinds`, `langpref study serve --kinds language,comparison`), as
data: Study 2 asks each in turn, and everything it needs of one is the kind's own (`langpref.feedback.FeedbackKind`).

- its step: the step's `kind` and the method are the kind's name, its phase `pref_NAME`; a query shows `shows`
  trajectories;
- its page (`FeedbackKind.page`, a `StudyPage`): the widget the answer is given with (`text` or `choice`), its label
  for participants, the question above the videos and an introduction; the page (`static/study-steps.js`) draws any kind
  from these, sent in the step's `widget`;
- its answer: the body's field `answer_key`, checked by `parse` into the typed answer, which the learner takes as the
  kind's `pairs`; stored by `to_record` in the kind's `table` (`kind_row`).

A kind from an installed package (entry-point group `langpref.feedback`) runs with no edit here. Study 1 stays the
paper's improvement with language (`STUDY1`: Eq. 4 reads a sentence). A kind's own active query selections
(`FeedbackKind.strategies`) choose its queries (`langpref.study.protocol.queries`, through `Selector.score_rows`); a
learner reads the kinds it says it reads (`LearnerType.reads`: the answer-model learner, those with a reading in
`FeedbackKind.readings`); a study of any other kind under it is refused before it starts (`StudyConfig.validate`). The
paper's two keep their own pages and the analyses (`langpref.study.analysis`) compare them.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from typing import Any

from langpref.errors import LangprefError
from langpref.feedback.kind import FeedbackKind, get_kind
from langpref.study.protocol.schema import KIND_TABLES, TABLES

STUDY1 = "language"
"""The kind of Study 1's feedback steps (phase `improve`), whatever kinds Study 2 runs."""
STEP_KINDS = ("survey", "confirm", "satisfaction", "rating", "done")
"""The study's own kinds of step, which ask no feedback kind (no kind may take these names)."""
OWN_KEYS = {"answers": "survey", "meaning": "confirm", "satisfied": "satisfaction", "rating": "rating"}
"""Answer fields of the study's own steps (docs/design.md#the-study-apps-http-contract)."""
RESERVED_KEYS = frozenset({*OWN_KEYS, "seq", "client_ms"})
"""Fields a kind's `answer_key` cannot be: the study's own."""
NAME = re.compile(r"[a-z][a-z0-9_]{0,39}")
"""What a kind's name and table must look like for the study (a step kind, a phase, an SQL table)."""


def study_kind(name: str) -> FeedbackKind:
    """The registered kind `name` (a plugin's too), checked for what the study needs: a page, a name usable as a step
    kind, an answer field of its own and a table name (one of the schema's feedback tables, or a new one)."""
    kind = get_kind(name)
    if kind.page is None:
        raise LangprefError(
            f"--kinds {name}: this feedback kind has no study page (FeedbackKind.page); it cannot be asked"
        )
    if not NAME.fullmatch(name) or name in STEP_KINDS:
        raise LangprefError(f"--kinds {name}: a study kind needs a lower-case name that is no step kind ({STEP_KINDS})")
    if kind.answer_key in RESERVED_KEYS:
        raise LangprefError(f"--kinds {name}: its answer field {kind.answer_key!r} is one of the study's own")
    if not NAME.fullmatch(kind.table) or (kind.table in TABLES and kind.table not in KIND_TABLES):
        raise LangprefError(f"--kinds {name}: its table {kind.table!r} is no new lower-case name nor a feedback table")
    return kind


def check_kinds(names: Sequence[str]) -> tuple[str, ...]:
    """The kinds of a study, checked: one or more, each once, each a `study_kind`, and each storing its answers in a
    table of its own (Study 1's language and Study 2's share `feedback`, whose rows say their phase)."""
    if isinstance(names, str):
        names = tuple(x.strip() for x in names.split(","))
    names = tuple(names)
    if not names or len(set(names)) != len(names):
        raise LangprefError(f"--kinds {','.join(map(str, names))}: name one or more feedback kinds, each once")
    owner = {get_kind(STUDY1).table: STUDY1}
    for name in names:
        table = study_kind(name).table
        if owner.setdefault(table, name) != name:
            raise LangprefError(f"--kinds: {name} and {owner[table]} both store their answers in table {table!r}")
    return names


def answer_keys(kinds: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """Answer field -> the kinds of step that take it: surveys, the feedback kinds (Study 1's and `kinds`), then the
    study's own steps. Two kinds may share a field; the current step says which one an answer is."""
    out: dict[str, tuple[str, ...]] = {"answers": ("survey",)}
    for name in dict.fromkeys((STUDY1, *kinds)):
        key = get_kind(name).answer_key
        out[key] = (*out.get(key, ()), name)
    out.update({key: (kind,) for key, kind in OWN_KEYS.items() if key != "answers"})
    return out


def asks_feedback(step_kind: str) -> bool:
    """Whether a step of this kind asks a feedback kind (Study 1's language, or a Study-2 query)."""
    return step_kind not in STEP_KINDS


def method_order(kinds: Sequence[str], number: int) -> tuple[str, ...]:
    """Counterbalancing: the order in which participant `number` (1-based arrival) meets the study's kinds, rotated
    by one per arrival (for the paper's two: odd arrivals language first, even ones comparisons first)."""
    k = (int(number) - 1) % len(kinds)
    return (*kinds[k:], *kinds[:k])


def label(name: str) -> str:
    """The kind's name for participants ("Language feedback")."""
    page = get_kind(name).page
    return page.label if page is not None else name.replace("_", " ").capitalize()


def widget(name: str) -> dict[str, Any]:
    """What the page needs to ask a query of kind `name` (the step's `widget`): how the answer is given (`type`),
    where it is sent (`answer_key`), how many trajectories it shows, and the kind's words."""
    kind = study_kind(name)
    page = kind.page
    assert page is not None  # study_kind checked it
    return {
        "type": page.widget,
        "answer_key": kind.answer_key,
        "shows": kind.shows,
        "label": page.label,
        "prompt": page.prompt,
        "intro": page.intro,
        "option": page.option,
    }


def said(kind: FeedbackKind, answer: Any) -> str | None:
    """What the person typed in `answer` (the kind's `sentence` field), which the model reads; None when the kind's
    answers hold no sentence, or this one is "that's good, no change" (a button, never read)."""
    if kind.sentence is None or (kind.says_no_change and answer.no_change):
        return None
    return getattr(answer, kind.sentence)


def kind_row(kind: FeedbackKind, answer: Any, read: dict[str, Any] | None = None) -> dict[str, Any]:
    """The columns of `kind.table` that store `answer` and how the robot `read` it (language; the study adds the
    query number and times)."""
    record = {**kind.to_record(answer), **(read or {})}
    return record if kind.table in KIND_TABLES else {"answer": json.dumps(record)}


def kind_answer(kind: FeedbackKind, row: dict[str, Any]) -> Any:
    """A stored row of `kind.table` as the kind's answer again (`kind_row`'s inverse)."""
    return kind.from_record(row if kind.table in KIND_TABLES else {**row, **json.loads(row["answer"])})
