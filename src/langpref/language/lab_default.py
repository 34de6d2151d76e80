"""Which language model a task trains on when `--lang-model` is not given: `comparative-aligned` for a task loaded
from a task file or a recording, the paper's pretrained `minilm` for the built-in and plugin tasks.

Why: on the drawer example (a recorded task, docs/results.md, issue 40) a language side that had been aligned to
signed concept axes before it met the lab's bank read the val split better than `minilm` (full recording and the
60-episode cut); the built-in tasks' numbers and golden tests were measured on `minilm` and keep it.

Nothing here reads a checkpoint: a trained model keeps the language model it names. `lang_model_for` is meant to be
called by the trainer where the task is known (beside `langpref.model.keep.resolve_corpus`), with
`ModelConfig.lang_model` left unset when `--lang-model` is not given; until that is wired, `minilm` stays the default
everywhere and a lab passes `--lang-model comparative-aligned`.
"""

from __future__ import annotations

AUTO_LANG_MODEL = "comparative-aligned"
"""The language model a recorded task trains on by default."""
PAPER_LANG_MODEL = "minilm"
"""The language model of the built-in and plugin tasks (the paper's protocol, with an offline encoder)."""


def lang_model_for(requested: str | None, env: str) -> str:
    """`requested` as given, else `AUTO_LANG_MODEL` for a recorded task and `PAPER_LANG_MODEL` otherwise."""
    if requested:
        return requested
    from langpref.tasks import get_task

    return AUTO_LANG_MODEL if get_task(env).source == "recorded" else PAPER_LANG_MODEL


__all__ = ["AUTO_LANG_MODEL", "PAPER_LANG_MODEL", "lang_model_for"]
