"""The protocol of a study (`StudyConfig`): saved in its database when it is created, fixed for its lifetime. How
the study is served (`langpref.study.server.settings`) and exported (`langpref.study.analysis.settings`) is not the
protocol and lives with the room that does it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from langpref.errors import LangprefError

METHODS = ("language", "comparison")
"""The paper's two Study-2 methods (`langpref.feedback.kind.PAPER_KINDS`, spelled out here so that the CLI's help
imports no numpy): the default `StudyConfig.kinds`, and the two the analyses compare."""
IMPROVE_CANDIDATES = ("split", "generated")


@dataclass
class StudyConfig:
    """The protocol of the paper's two studies (Sec. 5.2); the defaults are the paper's."""

    split: str = "test"
    """Dataset split whose trajectories the study shows and searches (`train`, `val`, `test` or `all`)."""
    improve_max_iterations: int = 10
    """Study 1: most rounds of feedback before the improvement survey."""
    improve_candidates: str = "split"
    """Study 1: where an improvement step looks: `split` (the study set, the paper's) or `generated` (a new trajectory
    made in the simulator for each feedback, `langpref.propose`; simulated tasks only; the page shows progress while
    it is made)."""
    improve_rollouts: int = 6
    """Study 1 with generated candidates: real rollouts per improvement step, the best of which is shown."""
    improve_search_generations: int = 30
    """Study 1 with generated candidates: CMA-ES generations on the surrogate per improvement step."""
    kinds: tuple[str, ...] = METHODS
    """Study 2's methods: the feedback kinds it asks, each in turn (`langpref.study.protocol.kinds`), in the order the
    first participant meets them (each next arrival starts one later). Any registered kind with a study page runs, a
    plugin's too (entry-point group `langpref.feedback`); the paper's: language,comparison."""
    pref_queries: int = 20
    """Study 2: queries per method."""
    rating_every: int = 5
    """Study 2: after every this many queries, the best trajectory under the reward learned so far is rated 1-5."""
    num_negatives: int = 20
    """k, implicit-negative utterances per language answer in reward learning (Eq. 9)."""
    seed: int = 0
    """Seed of the study: with the participant's own seed it fixes every trajectory drawn for them."""
    query_selection: str = "random"
    """Study 2: how each query is chosen from the study set, from the participant's answers so far
    (`langpref.reward.selection`): `random` (the paper's), `infogain` (both methods), or one per method as
    `language=lal-infogain,comparison=volume-removal` (language: random, infogain, lal-infogain; comparisons: random,
    infogain, volume-removal; a method left out is random)."""
    query_candidates: int = 60
    """Study 2, active query selection: score at most this many trajectories of the study set per query (drawn for
    each query; comparisons score every pair of them), which bounds the time an answer waits for the next query."""
    learner: str = "paper"
    """Study 2's reward learner, for both methods: `paper` (Eq. 5-9's Bradley-Terry pairs, the paper's) or
    `answer-model` (a belief over the reward that reads a sentence given the trajectory it was said about, with
    comparisons in the same belief; `langpref.reward.answer_model`; random or infogain queries)."""
    confirm_margin: float | None = None
    """Study 2, ask when unsure: when the model's reading of a typed language answer is uncertain (P of its top
    meaning minus P of the second below this margin), the participant confirms the meaning with one click among its
    top 3 readings or "none of these" (then the answer is stored and not learned from). None: never, the paper's
    protocol; 1: always."""

    def validate(self) -> None:
        if self.split not in ("train", "val", "test", "all"):
            raise LangprefError(f"--split must be train, val, test or all, got {self.split!r}")
        if self.improve_candidates not in IMPROVE_CANDIDATES:
            raise LangprefError(
                f"--improve-candidates must be {' or '.join(IMPROVE_CANDIDATES)}, got {self.improve_candidates!r}"
            )
        names = ("improve_max_iterations", "pref_queries", "rating_every", "num_negatives", "improve_rollouts")
        for name in (*names, "improve_search_generations"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise LangprefError(f"{name} must be an integer >= 1, got {value!r}")
        if not isinstance(self.query_candidates, int) or self.query_candidates < 2:
            raise LangprefError(f"--query-candidates must be an integer >= 2, got {self.query_candidates!r}")
        margin = self.confirm_margin
        if margin is not None and (
            isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0 <= margin <= 1
        ):
            raise LangprefError(f"--confirm-margin must be a number from 0 to 1 (or unset: never ask), got {margin!r}")
        from langpref.feedback.kind import kind_names, paper_first
        from langpref.reward.learners import get_learner, learner_names

        known = learner_names()

        if self.learner not in known:
            raise LangprefError(f"--learner must be {' or '.join(known)}, got {self.learner!r}")
        from langpref.study.protocol.kinds import check_kinds

        self.kinds = check_kinds(self.kinds)
        selections = self.selections()
        learner = get_learner(self.learner)
        unread = sorted(k for k in self.kinds if not learner.reads(k))
        if unread:
            read = " and ".join(paper_first([k for k in kind_names() if learner.reads(k)]))
            raise LangprefError(f"--learner {self.learner} reads {read} only, not {', '.join(unread)}")
        other = sorted({s for s in selections.values() if learner.selections and s not in learner.selections})
        if other:
            asks = learner.selections
            raise LangprefError(
                f"--learner {self.learner} asks with {' or '.join(asks)} queries, not {', '.join(other)}; "
                f"pass --query-selection {asks[-1]}" + (f" (or {' or '.join(asks[:-1])})" if len(asks) > 1 else "")
            )

    def selections(self) -> dict[str, str]:
        """The query selection strategy of each Study-2 method, checked (one line naming the choices otherwise)."""
        from langpref.reward.selection import STRATEGIES, check_strategy

        text = str(self.query_selection).strip()
        if "=" not in text:
            out = dict.fromkeys(self.kinds, text)
        else:
            out = dict.fromkeys(self.kinds, "random")
            for item in filter(None, (x.strip() for x in text.split(","))):
                method, _, strategy = (x.strip() for x in item.partition("="))
                if method not in self.kinds:
                    raise LangprefError(
                        f"--query-selection {text}: {method!r} is no Study-2 method; name "
                        f"{' or '.join(self.kinds)}, e.g. language=infogain,comparison=volume-removal"
                    )
                out[method] = strategy
        for method, strategy in out.items():
            try:
                check_strategy(strategy, method)
            except LangprefError as exc:
                per_method = "=" not in text and strategy in STRATEGIES
                each = ",".join(f"{k}=NAME" for k in self.kinds)
                hint = f" (or give one per method: {each})" if per_method else ""
                raise LangprefError(f"--query-selection {text}: {exc}{hint}") from None
        return out

    def rating_points(self) -> list[int]:
        """Query counts after which the best trajectory is rated: every `rating_every`, and the last query."""
        points = list(range(self.rating_every, self.pref_queries + 1, self.rating_every))
        if not points or points[-1] != self.pref_queries:
            points.append(self.pref_queries)
        return points

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> StudyConfig:
        known = {f.name for f in fields(cls)}
        out = cls(**{k: v for k, v in raw.items() if k in known})
        out.kinds = tuple(out.kinds)  # a list in the database's JSON
        return out
