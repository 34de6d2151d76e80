"""What a command tells the person running it besides its result.

Output paths are checked before a command's long work: one that cannot be written fails at once in one line
(`error: ...`, exit 2) instead of a traceback after minutes of work, and the check itself creates and removes
nothing, so what a folder already holds is never lost to a bad path. A status line goes before any wait of more
than 2 s."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from langpref.errors import LangprefError


def _nearest_existing(path: Path) -> Path:
    """`path` itself if it exists, else its nearest existing ancestor (the folder a mkdir would start from)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_writable(path: str | Path | None, option: str, folder: bool = False) -> None:
    """Refuse, in one line, an output `path` (of `option`, e.g. `--out`) that cannot be written: an ancestor is a
    file, the path is a folder where a file goes (or a file where a folder goes, with `folder`), or the folder it
    would go into refuses a new file (read-only, no permission). A probe file is made and removed in that folder; no
    other file or folder is touched."""
    if path is None:
        return
    path = Path(path)
    base = _nearest_existing(path)
    if base == Path(os.path.abspath(path)):
        if folder and not base.is_dir():
            raise LangprefError(f"cannot write {option} {path}: it is a file, not a folder; choose another")
        if not folder and base.is_dir():
            raise LangprefError(f"cannot write {option} {path}: it is a folder; pass a file name")
        if not folder:
            base = base.parent
    if not base.is_dir():
        raise LangprefError(f"cannot write {option} {path}: {base} is a file, not a folder; choose another path")
    try:
        with tempfile.TemporaryFile(dir=base, prefix=".langpref-write-check-"):
            pass
    except OSError as exc:
        raise LangprefError(
            f"cannot write {option} {path}: {base} does not take new files ({exc.strerror or exc}); choose another path"
        ) from None


def status(text: str) -> None:
    """A status line on stderr before a wait of more than a couple of seconds, so a person at a terminal sees why
    the next seconds pass; only at a terminal (as the language model's loading line), so logs and pipes stay clean."""
    if sys.stderr.isatty():
        print(f"{text} ...", file=sys.stderr, flush=True)
