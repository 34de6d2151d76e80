"""`langpref bank check`: how well a task's bank is read, meaning by meaning, before a study (and, with a
checkpoint, after training). The other `bank ...` commands live beside it: `augment`, and `scope` and `gate` in
`relevance`."""

from __future__ import annotations

import argparse
from pathlib import Path

from langpref.cli.common import BANK_SEED, BANK_WHERE, JSON, NEGATION, bank_embedder, figure, with_figure
from langpref.cli.outputs import check_writable, status
from langpref.cli_config import command, emit, opt, path
from langpref.errors import LangprefError
from langpref.extras import require


@command(
    "bank check",
    "how well each meaning of a bank is read from its own held-back phrasings, before a study",
    [
        BANK_WHERE,
        path(
            "--model", default=None, help="read with this checkpoint's language encoder (default: the pretrained one)"
        ),
        opt(
            "--lang-model",
            default=None,
            metavar="NAME_OR_PATH",
            help="pretrained sentence encoder without --model (default: the one `train` starts from: "
            "comparative-aligned for a recorded task once built, else minilm); with --model, the model must name it",
        ),
        path(
            "--utterances",
            default=None,
            help="read this file's phrasings (docs/design.md#utterance-files) against the bank's instead of leaving "
            "one out",
        ),
        opt(
            "--split",
            default="train",
            choices=("train", "val", "test"),
            help="bank split to check (default train; with --model, val or test holds phrasings the model never saw)",
        ),
        opt("--threshold", type=float, default=None, help="flag a meaning read right less often (default 0.8)"),
        BANK_SEED,
        NEGATION,
        figure("the confusion matrix of meanings (which is read as which) and each meaning's accuracy"),
        JSON,
    ],
    "Leave-one-out over the bank's train split: each phrasing is read as the meaning (feature, direction) whose "
    "prototype, the mean of that meaning's other phrasings' embeddings, is nearest in cosine. Per meaning: accuracy, "
    "the meanings it is taken for, and advice for weak ones. With --utterances, the file's phrasings are read against "
    "the prototypes of the whole split. Reads with the pretrained sentence encoder, or a checkpoint's (--model).",
)
def cmd_bank_check(args: argparse.Namespace) -> None:
    from langpref.language.banksource import open_bank
    from langpref.language.check import WEAK_BELOW, leave_one_out, read_against

    threshold = WEAK_BELOW if args.threshold is None else args.threshold
    if not 0 <= threshold <= 1:
        raise LangprefError(f"--threshold must be within 0..1, got {threshold}")
    source = open_bank(args.where, seed=args.seed)
    phrasings = source.split(args.split)
    queries = None
    if args.utterances is not None:
        from langpref.language.bank import load_user_utterances

        mapping = load_user_utterances(args.utterances, source.task, source.features)
        queries = {f: {d: list(t) for d, t in by.items()} for f, by in mapping.items()}
    if args.figure:
        require("plots", "bank check --figure")  # before the model loads, not after
    args.lang_model_given = args.lang_model is not None
    if args.lang_model is None:
        from langpref.language.lab_default import bank_reader_for

        args.lang_model = bank_reader_for(source.task)
    check_writable(args.figure, "--figure")
    if args.model is None:
        from langpref.language.models import check_available

        check_available(args.lang_model)  # an unknown name fails here, before the slow imports
    status(f"loading torch to read the bank with {'the model ' + str(args.model) if args.model else args.lang_model}")
    embed, encoder = bank_embedder(args, source.task)
    if queries is None:
        result = leave_one_out(
            phrasings, source.features, embed, task=source.task, encoder=encoder, threshold=threshold
        )
    else:
        result = read_against(
            phrasings,
            queries,
            source.features,
            embed,
            task=source.task,
            encoder=encoder,
            method=f"{args.utterances} against the {args.split} split",
            threshold=threshold,
        )
    out = {**result.to_dict(), "chance": 1 / len(result.meanings), "good": threshold}
    if args.figure:
        from langpref.language.check_figure import plot_bank_check

        out["figure"] = str(plot_bank_check(result, args.figure))
    note = before_training_note(result, args.where) if args.model is None else None
    emit(out, args.json, with_figure(lambda _: _human(result) + (f"\nnote: {note}" if note else "")))


def chance_line(result) -> str:
    """What chance is for a bank check and the bar for a good meaning, so its numbers read by themselves."""
    m = len(result.meanings)
    return (
        f"chance: 1/{m} = {1 / m:.2f} (a phrasing read as one of {m} meanings: {m // 2} features x 2 directions); "
        f"good: {result.threshold:.2f} or more per meaning (--threshold; below it a meaning is flagged weak)"
    )


def opposite_only(result) -> list[str]:
    """The weak meanings read mostly as their own feature's other direction (speed/increase as speed/decrease)."""
    out = []
    for name in result.weak:
        top = next(iter(result.meanings[name].confused_with), None)
        if top is not None and top.rsplit("/", 1)[0] == name.rsplit("/", 1)[0]:
            out.append(name)
    return out


def before_training_note(result, where: str | Path) -> str | None:
    """Why weak meanings read as their own opposite direction are expected from a pretrained model before any
    training, and what to look at after `langpref train`; None when there are none."""
    flipped = opposite_only(result)
    if not flipped:
        return None
    shown = ", ".join(flipped[:4]) + (f" and {len(flipped) - 4} more" if len(flipped) > 4 else "")
    return (
        f"{len(flipped)} of {len(result.meanings)} meanings ({shown}) are read as their own opposite direction. "
        "Before training this is expected: a frozen general sentence model reads what a phrasing is about more than "
        "which way it asks, and `langpref train` teaches the direction from the bank. After training, look at "
        f"`langpref evaluate --model MODEL --data DATASET` (pair accuracy: chance 0.5, good 0.80 or more) and "
        f"`langpref bank check {where} --model MODEL --split val` (chance {1 / len(result.meanings):.2f}, good "
        f"{result.threshold:.2f} per meaning); a meaning still weak there needs more or clearer phrasings "
        "(`langpref bank augment`)"
    )


def _human(result) -> str:
    lines = [result.summary(), chance_line(result)]
    for name, m in result.meanings.items():
        acc = "  n/a" if m.accuracy is None else f"{m.accuracy:5.2f}"
        confused = ", ".join(f"{k} x{v}" for k, v in m.confused_with.items())
        lines.append(f"  {name:<32} {acc} of {m.count:<3}" + (f" read as {confused}" if confused else ""))
        if m.advice:
            lines.append(f"    -> {m.advice}")
    for rep in result.repeated:
        lines.append(f"  repeated under {', '.join(rep['meanings'])}: {rep['text']!r}")
    return "\n".join(lines)
