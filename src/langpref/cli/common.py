"""What the command modules share: the common options, the split and backend names, loading a model, and what the
`bank ...` commands read a bank with."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from langpref.cli_config import emit, from_args, opt, path, record
from langpref.errors import LangprefError

TASK_HELP = "task name: metaworld, robosuite, a plugin's task, or a recorded task (then give its dataset's --data)"
DEVICES = ("auto", "cpu", "cuda")
DEFAULT_DEVICE = "auto"
"""One default for every command that takes `--device` (`train`'s `TrainConfig.device`, `evaluate`): `auto` is
CUDA where there is one, else the CPU."""
# Command groups: name -> (help, dest, metavar)
GROUPS = {
    "experiment": ("the paper's experiments, one command each", "experiment", "EXPERIMENT"),
    "bank": ("a task's bank of phrasings before a study: check and augment it", "bank_command", "SUBCOMMAND"),
    "lang-model": ("language models langpref builds itself: build one", "lang_model_command", "SUBCOMMAND"),
    "study": ("the web app for user studies with real people (paper Sec. 5.2)", "study_command", "SUBCOMMAND"),
}


JSON = opt("--json", action="store_true", help="print one JSON object")
DIR = path("dir", help="dataset directory")
MODEL = path("--model", required=True, help="checkpoint directory (`langpref train`)")
DATA = path("--data", required=True, help="dataset directory (`langpref generate`)")
TASK = opt("--env", required=True, metavar="TASK", help=TASK_HELP)
DEVICE = opt(
    "--device",
    choices=DEVICES,
    default=DEFAULT_DEVICE,
    help="where the model runs: auto (CUDA when there is one, else the CPU), cpu or cuda (default %(default)s)",
)
NEGATION = opt(
    "--negation",
    action=argparse.BooleanOptionalAction,
    default=None,
    help='read a negated request ("Don\'t go so fast.") as the opposite of the request without its cue, or not '
    "(--no-negation); default: the checkpoint's setting (ModelConfig.negation)",
)
"""`--negation/--no-negation` of every command that loads a model to read text with it (`load`)."""
BANK_WHERE = opt(
    "where",
    metavar="DATASET_OR_TASK",
    help="a task name (metaworld, robosuite, a plugin's), a dataset directory, or a task file (.toml) before import",
)
"""The bank a `bank ...` command reads (`langpref.language.banksource.open_bank`)."""
BANK_SEED = opt(
    "--seed", type=int, default=0, help="seed of an unsplit bank's split, as `langpref import --seed` (default 0)"
)
"""`--seed` of a `bank ...` command: the split of a bank that ships unsplit."""


def figure(what: str):
    """The `--figure PNG` option of a command that can draw the picture beside its numbers, saying what it shows."""
    return path("--figure", default=None, metavar="PNG", help=f"also draw {what} into this PNG (needs matplotlib)")


def with_figure(text: Callable[[dict], str]) -> Callable[[dict], str]:
    """A command's text output, followed by a line naming its figure when it drew one."""
    return lambda o: text(o) + (f"\nfigure {o['figure']}" if o.get("figure") else "")


def load(args: argparse.Namespace, with_data: bool = True):
    """The model of `--model` (on `--device`, reading negations as `--negation` says, else as saved) and, with
    `with_data`, the dataset of `--data` it is checked against."""
    from langpref.dataset.storage import load_dataset
    from langpref.model.checkpoint import load_model
    from langpref.model.train import resolve_device

    dataset = load_dataset(args.data) if with_data else None
    device = resolve_device(getattr(args, "device", "cpu"))  # commands without --device run on the CPU
    negation = getattr(args, "negation", None)
    return load_model(args.model, device=device, dataset=dataset, negation=negation), dataset


def run_config_experiment(args: argparse.Namespace, name: str, table: Callable[[dict], str] | None = None) -> None:
    """`langpref experiment NAME` for an experiment whose only input is its config dataclass (its `out` the output
    folder, its `resolved()`, where it has one, filling in defaults): run it, record the config beside its output
    (NAME.config.json, so `--config` reruns it) and print `table` of its summary (without one, the summary)."""
    from langpref.experiments.registry import get_experiment

    experiment = get_experiment(name)
    cfg = from_args(experiment.config_class(), args)
    cfg = cfg.resolved() if hasattr(cfg, "resolved") else cfg
    summary = experiment.runner()(cfg)
    record(args, Path(str(cfg.out)) / f"{name}.config.json", cfg)
    text = None if table is None else (lambda s: table(s) + f"\n(wrote {cfg.out}/{name}.md and .json)")
    emit(summary, args.json, text)


def bank_embedder(args: argparse.Namespace, task: str) -> tuple[Callable[[list[str]], Any], str]:
    """(texts -> embeddings, what reads them) of `bank check` and `bank augment`: a checkpoint's language encoder
    (psi) with --model, else the pretrained sentence encoder --lang-model. A checkpoint of another task is refused,
    since its psi never learned this bank's words."""
    if args.model is None:
        from langpref.language.loading import sentence_embedder
        from langpref.language.models import canonical_name

        return sentence_embedder(args.lang_model), f"pretrained {canonical_name(args.lang_model)}"
    from langpref.model.checkpoint import load_model

    model = load_model(
        args.model, lang_model=args.lang_model if args.lang_model_given else None, negation=args.negation
    )
    if model.info.env != task:
        raise LangprefError(f"model {args.model} was trained on task {model.info.env!r}, the bank is task {task!r}")
    return (lambda texts: model.encode_texts(list(texts)).double().cpu().numpy()), f"model {args.model}"
