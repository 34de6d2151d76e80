"""One shape for every registry of named parts (tasks, feedback kinds, learners, experiments): `register`, `get`,
`names`, and parts from installed packages through an entry-point group, as Gymnasium's `gymnasium.envs`.

    KINDS_REGISTRY = Registry("feedback kind", FeedbackKind, "langpref.feedback", unknown="unknown feedback")
    KINDS_REGISTRY.register(LANGUAGE)
    KINDS_REGISTRY.get("language"); KINDS_REGISTRY.names()

An entry point names a part or a function that returns one. Plugins load once per process, on the first `names()`
or on a `get` of a name not registered yet; a plugin that fails to load, gives no part of the registry's type or is
refused by `check` is skipped with a warning naming it, so one broken package never breaks the others. Why one
shape: each registry was written by hand, three times with small differences, and a new sort of part (a learner)
copied one of them again.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

from langpref.errors import LangprefError

T = TypeVar("T")


class Registry(Generic[T]):
    """Parts of one type by their `name`, the built-in ones first, then those of plugins in the order they loaded."""

    def __init__(
        self,
        what: str,
        cls: type,
        group: str | None = None,
        *,
        unknown: str | None = None,
        check: Callable[[T], None] | None = None,
        add: Callable[[T], None] | None = None,
        type_name: str | None = None,
    ):
        self.what = what
        """The sort of part, for messages ("feedback kind")."""
        self.cls = cls
        self.group = group
        """The entry-point group installed packages add parts through; None: none."""
        self.unknown = unknown or f"unknown {what}"
        """How an unknown name's one-line error starts ("unknown feedback")."""
        self.check = check
        """Raises for a plugin's part that may not join (a reserved name); it is then skipped with a warning."""
        self.add = add
        """How a plugin's part joins (default `register`)."""
        self.type_name = type_name or f"{cls.__module__}.{cls.__name__}"
        """The type's public name, for messages ("langpref.tasks.Task")."""
        self.items: dict[str, T] = {}
        self.loaded = False

    def register(self, item: T) -> T:
        """Add `item` under its name; the same part again is a no-op, a different one under a taken name an error."""
        name = item.name  # type: ignore[attr-defined]
        known = self.items.get(name)
        if known is not None and known is not item and known != item:
            article = "an" if self.what[0] in "aeiou" else "a"
            raise LangprefError(f"{article} {self.what} named {name!r} is already registered")
        self.items[name] = item
        return item

    def load_plugins(self) -> None:
        """Register every part declared under the entry-point group (once per process)."""
        if self.loaded or self.group is None:
            return
        self.loaded = True
        for ep in entry_points(group=self.group):
            try:
                found = ep.load()
                item = found() if callable(found) and not isinstance(found, self.cls) else found
                if not isinstance(item, self.cls):
                    raise TypeError(f"it gives a {type(item).__name__}, not a {self.type_name}")
                if self.check is not None:
                    self.check(item)
                (self.add or self.register)(item)
            except Exception as exc:  # a broken plugin must not break the others: say which one and go on
                warnings.warn(
                    f"langpref: skipped the {self.what} plugin {ep.name!r} ({ep.value}): {type(exc).__name__}: {exc}",
                    stacklevel=3,
                )

    def names(self) -> tuple[str, ...]:
        """Every part known in this process (plugins loaded)."""
        self.load_plugins()
        return tuple(self.items)

    def get(self, name: Any) -> T:
        """The part called `name`; a one-line error naming the known ones."""
        if not isinstance(name, str) or name not in self.items:
            self.load_plugins()
        try:
            return self.items[name]
        except (KeyError, TypeError):
            raise LangprefError(f"{self.unknown} {name!r}: choose one of {', '.join(self.items)}") from None
