"""`langpref ...`: one thin function per command that parses arguments and calls the library (the commands live in
`data`, `latent`, `bank`, `augment`, `relevance`, `lang_models`, `uses` and `study`, by the stage of the pipeline
they serve).

A command's options come from its config dataclass (`config(...)`, see `langpref.cli_config`: one flag per field,
the field's docstring as its help); only inputs that are not config fields (paths, `--json`) are declared here. Each
command that writes a directory or file writes its resolved config, command line and langpref version beside it:
`NAME.config.json` inside an output directory (NAME the command) or beside an output file (NAME the file's stem).
`--config PATH` reruns such a record: its command line, with the options given after it overriding the record's.

Heavy modules (simulators, torch, transformers) are imported inside the command that needs them, and a command's
options are built only when that command runs, so `--help` is instant. Every `--json` prints exactly one JSON
object on stdout; progress bars and messages go to stderr. A `LangprefError` becomes a one-line `error: ...` on
stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys

from langpref import cli_config as cc
from langpref.errors import LangprefError

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")

# the command modules register their commands when imported, in the order `--help` lists them
# isort: off
from langpref.cli import data, latent, bank, augment, relevance, lang_models, uses, study  # noqa: E402, F401

# isort: on
from langpref.cli.common import GROUPS  # noqa: E402


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """Every command with its help; a command's options only when `argv` names it (all of them without `argv`)."""
    from langpref import __version__

    _plugin_experiments(argv)
    parser = cc.make_parser(
        "langpref",
        "Teach robots with comparative language feedback: datasets, a shared latent "
        "space of trajectories and language, trajectory improvement and reward learning. A command "
        "that writes a directory or a file writes its resolved config beside it: "
        "DIR/COMMAND.config.json, STEM.config.json; `--config` on that command reruns it.",
        GROUPS,
        argv,
    )
    parser.add_argument("--version", action="version", version=f"langpref {__version__}")
    return parser


def _plugin_experiments(argv: list[str] | None) -> None:
    """The commands of installed packages' experiments, when `argv` asks for an experiment (or for every command):
    only then are the plugins imported."""
    if argv is None or argv[:1] == ["experiment"]:
        uses.add_experiment_commands(plugins=True)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        _plugin_experiments(argv)  # before `--config` looks the command up
        argv = cc.expand_rerun(argv, build_parser)  # `--config PATH`: the record's command line, overridden
        args = build_parser(argv).parse_args(argv)
        args.argv = argv
        args.func(args)
    except LangprefError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `langpref ... --json | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0
