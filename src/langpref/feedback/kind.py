"""A kind of feedback as one value: its query and answer types, its synthetic human, its likelihood as Bradley-Terry
pairs, how an answer arrives over HTTP and how it is stored. APReL's taxonomy is the model (one query type with one
user model's `loglikelihood` each); here the likelihood is a list of weighted Bradley-Terry pairs, which the reward
learner (`langpref.reward`) fits whatever the kind.

    from langpref.feedback import get_kind
    kind = get_kind("comparison")
    human = kind.make_human(w, space, space.split("train"), HumanConfig(), rng)
    answer = human.answer(random_query(kind, space.split("train"), rng))
    batch = kind.pairs(space, answer, settings, rng)  # the learner's settings, e.g. langpref.reward.RewardConfig()

The two kinds of the paper are `langpref.feedback.language` and `langpref.feedback.comparison`; the package imports
both, so they are in `KINDS` whenever `langpref.feedback` is imported. A new kind is one module that builds a
`FeedbackKind` and passes it to `register_kind`; `langpref learn-reward` and the reward loop then take it by name.
An installed package adds a kind with no edit here by declaring an entry point in the group `langpref.feedback` (as
tasks do in `langpref.tasks`) that points at a `FeedbackKind` or at a function returning one; `kind_names()` and
`get_kind` load them on first use.

A kind that the study web app can ask people (`langpref study serve --kinds NAME,...`) says how in `page`, a
`StudyPage`: the widget its answer is given with (a text box, or a choice among the shown trajectories), its label
and the question above the videos; `parse` checks what the widget sends and `pairs` is what the learner takes.

A kind's active query selections are registered from the reward side (`langpref.reward.selection.register_strategy`:
the paper's kinds' are there); a kind of another package may also list its own in `strategies`. The reward loop and
Study 2 ask `langpref.reward.selection.selector_factories(kind)`. This package imports nothing of `langpref.reward`,
not even for type checkers: what a kind reads of the learner's settings it names in a Protocol of its own
(`langpref.feedback.language.PairSettings`), and a selector is the reward side's type (`SelectorFactory`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.registry import Registry

if TYPE_CHECKING:
    from langpref.feedback.bradley_terry import PairBatch
    from langpref.feedback.humans import HumanConfig
    from langpref.feedback.space import LatentSpace


WIDGETS = ("text", "choice")
"""How a study page takes an answer: `text`, a text box whose string is sent at `answer_key`; `choice`, one button per
shown trajectory, whose position (0-based) is sent."""


@dataclass(frozen=True)
class StudyPage:
    """How the study web app asks a query of one kind (`langpref.study`); the page itself is generic."""

    widget: str
    """One of `WIDGETS`: what the page shows under the query's videos and sends at the kind's `answer_key`."""
    label: str
    """The method's name for participants ("Pair-wise comparison"): titles, questionnaires, the guidelines."""
    prompt: str
    """The question above a query's videos ("Which trajectory do you prefer?")."""
    intro: str = ""
    """What the page says before the method's first query (how to answer; one or two sentences)."""
    option: str = "Trajectory {n}"
    """A `choice` widget's button for the n-th shown trajectory (`{n}` is 1-based): "I prefer trajectory {n}"."""

    def __post_init__(self) -> None:
        if self.widget not in WIDGETS:
            raise LangprefError(f"a study page's widget must be one of {', '.join(WIDGETS)}, got {self.widget!r}")


class Human(Protocol):
    """A synthetic human of one kind: answers that kind's queries."""

    def answer(self, query: Any) -> Any: ...


SelectorFactory = Callable[["LatentSpace", Sequence[int], Any, "int | None", int], Any]
"""(space, query pool, the learner's settings, candidates or None for the whole pool, posterior samples) -> the
selector of one active strategy. Settings and selector are the reward side's types (`langpref.reward.selection`):
a kind stores its factories and calls none of them, so it needs nothing of either."""


@dataclass(frozen=True)
class FeedbackKind:
    """Everything the library needs to know about one kind of feedback."""

    name: str
    """`--feedback NAME`; in the study, the kind of step and the method of Study 2."""
    query: type
    """The frozen query type; `query(*indices)` is the query showing those dataset trajectories."""
    answer: type
    """The frozen answer type; every answer holds its `query`."""
    shows: int
    """How many trajectories a query shows (videos of a study step)."""
    make_human: Callable[[np.ndarray, LatentSpace, Sequence[int], HumanConfig, np.random.Generator], Human]
    """(w, space, candidates, config, rng) -> the synthetic human with true reward w . theta."""
    pairs: Callable[[LatentSpace, Any, Any, np.random.Generator], PairBatch]
    """(space, answer, the learner's settings, rng) -> the answer's likelihood as weighted Bradley-Terry pairs of
    embeddings. The pairs read only phi and psi, never the synthetic human's ground truth, and of the settings only
    what the kind names in its own Protocol (the language kind's `PairSettings`; the comparison kind reads none)."""
    answer_key: str
    """The field of an HTTP answer body that holds this kind's answer (docs/design.md#the-study-apps-http-contract)."""
    parse: Callable[[Any, Any], Any]
    """(the body's value at `answer_key`, the query shown) -> the answer; a one-line LangprefError for bad input."""
    value: Callable[[Any], Any]
    """answer -> what a client sends at `answer_key` (the inverse of `parse`)."""
    table: str
    """The study database table that stores this kind's answers."""
    to_record: Callable[[Any], dict[str, Any]]
    """answer -> its columns of `table` (the study adds the query number and times)."""
    from_record: Callable[[Mapping[str, Any]], Any]
    """A stored row of `table` -> the answer again (the study replays them to rebuild a learner)."""
    strategies: Mapping[str, SelectorFactory | None] = field(default_factory=lambda: {RANDOM: None})
    """`--query-selection` name -> the factory of its selector, beside those registered from the reward side, in the
    order errors list them; `random` (uniform, `random_query`; the paper's) has none. Study 2 runs a strategy whose
    selector can score the rows it is given (`Selector.score_rows`)."""
    page: StudyPage | None = None
    """How the study web app asks this kind (`langpref study serve --kinds`); None: the study cannot run it."""
    from_line: Callable[[dict[str, Any], str, Callable[[Any, str], int]], Any] | None = None
    """(a line of an answers file, where it is for errors, a resolver of a trajectory named by dataset index or
    episode name) -> the answer (`langpref.feedback.answers`); None: the line is read by `from_record`."""
    to_line: Callable[[Any], dict[str, Any]] | None = None
    """answer -> its fields in a line of an answers file (the inverse of `from_line`); None: `to_record`'s."""
    seconds: float = 1.0
    """Modelled time a person takes per query, in units of one comparison's (`langpref.reward.cost`): what a mixed
    learner weighs information against, and the time axis of the learning curves."""
    says_no_change: bool = False
    """Whether an answer may be "that's good, no change" (`answer.no_change`), which the curves count."""
    sentence: str | None = None
    """The field of its answer that holds what the person typed, which the model reads (the study shows back how it
    read it, asks when unsure, and refuses text that is no feedback); None: its answers hold no sentence."""
    mixed: bool = False
    """Whether `--feedback mixed` asks this kind beside the others that say so (each needs an `infogain` selection
    whose selector scores candidates, `scored`)."""
    readings: dict[str, Any] = field(default_factory=dict)
    """learner name -> how that learner reads this kind beyond `pairs` (the answer-model learner's is its
    `langpref.reward.answer_model.AnswerKind`); the paper's kinds' readings are registered from the reward side."""


RANDOM = "random"
"""The query selection every kind has: uniform over the pool (`random_query`)."""
ENTRY_POINT_GROUP = "langpref.feedback"
"""The entry-point group through which installed packages add kinds."""
MIXED = "mixed"
"""The `feedback` of a learner that asks either kind, chosen per query (`langpref.reward.mixed`); not a kind."""
PAPER_KINDS = ("language", "comparison")
"""The paper's two kinds, in its order: those Study 2 and the demo compare by default."""


def _not_mixed(kind: FeedbackKind) -> None:
    if kind.name == MIXED:
        raise ValueError(f"it is named {MIXED!r}, which is not a kind but both of the paper's")


REGISTRY: Registry[FeedbackKind] = Registry(
    "feedback kind",
    FeedbackKind,
    ENTRY_POINT_GROUP,
    unknown="unknown feedback",
    check=_not_mixed,
    type_name="langpref.feedback.FeedbackKind",
)
"""The kinds (`langpref.registry`): a plugin that fails to load, gives no `FeedbackKind`, is named `mixed` or takes a
taken name is skipped with a warning naming it."""
KINDS: dict[str, FeedbackKind] = REGISTRY.items
"""The registered kinds by name (plugins once `kind_names()` or `get_kind` has loaded them)."""
register_kind = REGISTRY.register
load_plugins = REGISTRY.load_plugins
kind_names = REGISTRY.names
"""Every kind known in this process: the paper's two, then those registered in code or by plugins."""
get_kind = REGISTRY.get


def paper_first(names: Sequence[str]) -> tuple[str, ...]:
    """`names` with the paper's kinds first, in its order, then the others as given."""
    return tuple(sorted(names, key=lambda n: PAPER_KINDS.index(n) if n in PAPER_KINDS else len(PAPER_KINDS)))


def mixed_kinds() -> tuple[str, ...]:
    """The kinds a mixed learner chooses between (`FeedbackKind.mixed`), the paper's first."""
    return paper_first([name for name in kind_names() if KINDS[name].mixed])


def asked_kinds(feedback: str) -> tuple[str, ...]:
    """The kinds a learner of `feedback` asks: every mixed kind for `mixed`, else that kind."""
    return mixed_kinds() if feedback == MIXED else (feedback,)


def random_query(kind: FeedbackKind, pool: np.ndarray, rng: np.random.Generator) -> Any:
    """A query of `kind` showing trajectories drawn uniformly from `pool` (distinct ones when it shows several)."""
    if kind.shows == 1:
        return kind.query(int(rng.choice(pool)))
    return kind.query(*(int(i) for i in rng.choice(pool, size=kind.shows, replace=False)))


def shown_by(query: Any) -> tuple[int, ...]:
    """The dataset trajectories `query` shows, in order: its fields, as `FeedbackKind.query(*indices)` made it."""
    return tuple(int(getattr(query, f.name)) for f in fields(query))


def kind_of(query: Any) -> FeedbackKind:
    """The registered kind whose query type `query` is (a mixed learner asks queries of several kinds)."""
    for kind in KINDS.values():
        if type(query) is kind.query:
            return kind
    raise LangprefError(f"no registered feedback kind asks a {type(query).__name__}")
