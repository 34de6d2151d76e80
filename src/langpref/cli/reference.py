"""The command-line reference page, written from the commands' own help, so that it never drifts from them.

`python -m langpref.cli.reference` writes docs/reference/cli.md: every command and command group, in the order
`langpref --help` lists them, with its whole `--help-all` text (every option, not only the common ones);
`--check` writes nothing and exits 1 when the page differs from what the commands print now.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path

WIDTH = 110
"""Columns the help is wrapped to, whatever the terminal."""

PAGE = Path("docs") / "reference" / "cli.md"
"""Where the page lives, from the repository root."""

HEADER = """# Command-line reference

Every command's full help (`--help-all`), as the commands print it. This page is written by
`python -m langpref.cli.reference` from the command-line parser itself, and a test fails when it differs from what the
commands print, so it never drifts. `langpref COMMAND --help` shows the common options only.
"""


def commands(parser: argparse.ArgumentParser, words: tuple[str, ...] = ("langpref",)) -> Iterator[tuple[str, ...]]:
    """The words of every command and command group below `parser` (itself first), depth first, in help order."""
    yield words
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, (*words, name))


def _parser_of(root: argparse.ArgumentParser, words: tuple[str, ...]) -> argparse.ArgumentParser:
    parser = root
    for word in words[1:]:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[word]
    return parser


def render() -> str:
    """The page: a contents list, then one section per command with its help as a text block."""
    from langpref.cli import build_parser

    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)  # argparse wraps to the terminal's width, read from COLUMNS first
    try:
        root = build_parser()  # no argv: every command with every option (the --help-all text)
        names = list(commands(root))
        helps = {words: _parser_of(root, words).format_help().rstrip() for words in names}
    finally:
        if before is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = before
    toc = "\n".join(f"- [`{' '.join(w)}`](#{'-'.join(w)})" for w in names)
    body = "\n\n".join(f"## `{' '.join(w)}`\n\n```text\n{helps[w]}\n```" for w in names)
    return f"{HEADER}\n{toc}\n\n{body}\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m langpref.cli.reference", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=PAGE, help=f"the page to write (default {PAGE})")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 when the page is out of date")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = args.out.read_text() if args.out.is_file() else ""
        if current != text:
            print(f"{args.out} is out of date: run python -m langpref.cli.reference", file=sys.stderr)
            return 1
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out} ({len(text.splitlines())} lines)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
