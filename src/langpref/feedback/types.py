"""Queries a robot asks and the answers it gets: one typed vocabulary for language feedback and comparisons.

As in APReL's taxonomy, a language query is one more query type beside a pairwise comparison. Queries and answers
name trajectories by their dataset index; they are frozen so a feedback history can be stored, replayed and shared
between the synthetic humans, the learning methods and the study app.

A synthetic human also records *why* it answered (the feature and direction it meant). Those fields are ground
truth for analysis only: no learning method reads them (a real participant's answers leave them `None`).
"""

from __future__ import annotations

from dataclasses import dataclass

from langpref.errors import LangprefError


@dataclass(frozen=True)
class LanguageQuery:
    """Show one trajectory and ask how it should change."""

    shown: int
    """Dataset index of the trajectory shown."""


@dataclass(frozen=True)
class LanguageAnswer:
    """Comparative language feedback about the shown trajectory, e.g. "Move faster."."""

    query: LanguageQuery
    text: str
    feature: str | None = None
    """What a synthetic human meant (ground truth; never read by a method). `None` for a real participant."""
    direction: str | None = None
    """`increase` or `decrease`, what a synthetic human meant; `None` for a real participant."""

    def __post_init__(self) -> None:
        if not self.text.strip():
            raise LangprefError("language feedback is empty; give a sentence such as 'Move faster.'")


@dataclass(frozen=True)
class ComparisonQuery:
    """Show two trajectories and ask which one is better."""

    a: int
    b: int

    def __post_init__(self) -> None:
        if self.a == self.b:
            raise LangprefError(f"a comparison needs two different trajectories, got {self.a} twice")


@dataclass(frozen=True)
class ComparisonAnswer:
    """The choice of a comparison: 0 prefers `query.a`, 1 prefers `query.b`."""

    query: ComparisonQuery
    choice: int

    def __post_init__(self) -> None:
        if self.choice not in (0, 1):
            raise LangprefError(f"a comparison choice is 0 or 1, got {self.choice!r}")

    @property
    def preferred(self) -> int:
        return self.query.b if self.choice else self.query.a

    @property
    def rejected(self) -> int:
        return self.query.a if self.choice else self.query.b


Answer = LanguageAnswer | ComparisonAnswer
