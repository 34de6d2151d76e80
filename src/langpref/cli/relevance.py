"""`langpref bank scope | bank gate`: whether texts are feedback about the task at all: how often real feedback is
said to be about something the task does not measure, and what the feedback gate lets through. Counts only, no
text."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from langpref.cli.common import BANK_SEED, BANK_WHERE, JSON
from langpref.cli_config import command, emit, opt, path
from langpref.errors import LangprefError


def _texts(file: str) -> list[str]:
    """The texts of a not-feedback file: {"texts": [...]} or a JSON list of strings."""
    try:
        doc = json.loads(Path(file).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise LangprefError(f"--not-feedback {file} cannot be read as JSON ({exc})") from None
    texts = doc.get("texts") if isinstance(doc, dict) else doc
    if not isinstance(texts, list) or not all(isinstance(t, str) for t in texts):
        raise LangprefError(f'--not-feedback {file} must hold {{"texts": [strings]}} or a list of strings')
    return texts


@command(
    "bank scope",
    "how often feedback is said to be about something the task does not measure",
    [
        opt("--split", default="val", choices=["val", "test"], help="the banks' split to measure on (choose on val)"),
        path(
            "--task-file",
            action="append",
            default=None,
            help="a task file whose bank joins the built-in ones (repeatable; default examples/own_robot/task.toml "
            "when it exists)",
        ),
        BANK_SEED,
        JSON,
    ],
    "Each bank's own phrasings of --split (real feedback) and the other banks' phrasings of --split about concepts it "
    "lacks, through the scope check (langpref.language.scope) built on each bank's train split, at several margins; "
    "and the margin that keeps real feedback said outside at 5% or less on every bank with the most of the others "
    "said so. Counts only, no text.",
)
def cmd_bank_scope(args: argparse.Namespace) -> None:
    from langpref.language.banksource import open_bank
    from langpref.language.scope import measure

    files = args.task_file or [p for p in ["examples/own_robot/task.toml"] if Path(p).is_file()]
    banks = {name: open_bank(name, seed=args.seed) for name in ("metaworld", "robosuite")}
    for f in files:
        source = open_bank(f, seed=args.seed)
        banks[source.task] = source
    out = measure(banks, args.split)
    emit(out, args.json, _scope_text)


def _scope_text(o: dict) -> str:
    lines = [f"scope check on the {o['split']} phrasings (margin in use {o['margin_in_use']})"]
    for name, r in o["banks"].items():
        cells = ", ".join(
            f"{m}: {v['real_said_outside']:.1%} / {v['lacked_said_outside']:.1%}" for m, v in r["by_margin"].items()
        )
        lines.append(f"  {name} ({r['real']} own, {r['lacked']} about what it lacks): {cells}")
    which = "chosen by the rule" if o["split"] == "val" else "the rule would choose here (it chooses on val)"
    lines.append(f"margin {which}: {o['chosen_margin']}  (cells: own said outside / others said outside)")
    return "\n".join(lines)


@command(
    "bank gate",
    "how the feedback gate treats texts: feedback it must let through, other text it should refuse",
    [
        BANK_WHERE,
        path("--feedback", default=None, help="an utterance file (docs/design.md#utterance-files) of real feedback"),
        path("--not-feedback", default=None, help='JSON {"texts": [...]} of texts that are not feedback'),
        BANK_SEED,
        JSON,
    ],
    "Scores each text against the task's bank in the pretrained sentence space (langpref.language.relevance) and "
    "prints counts only: feedback let through and its lowest score, other texts refused and the highest score of "
    "those let through. No text is printed, so a reporting-only set can be reported without being read.",
)
def cmd_bank_gate(args: argparse.Namespace) -> None:
    from langpref.language.bank import load_user_utterances
    from langpref.language.banksource import open_bank
    from langpref.language.relevance import FeedbackGate, gate_report

    if not args.feedback and not args.not_feedback:
        raise LangprefError("give --feedback FILE, --not-feedback FILE or both")
    source = open_bank(args.where, seed=args.seed)
    feedback = []
    if args.feedback:
        mapping = load_user_utterances(args.feedback, source.task)
        feedback = [t for by in mapping.values() for ts in by.values() for t in ts]
    not_feedback = _texts(args.not_feedback) if args.not_feedback else []
    bank = [t for split in source.splits.values() for by in split.values() for ts in by.values() for t in ts]
    out = gate_report(FeedbackGate(source.task, bank), feedback, not_feedback)
    emit(out, args.json, _gate_text)


def _gate_text(o: dict) -> str:
    lines = [f"feedback gate of {o['env']} (floor {o['floor']}, {o['unknown_words_floor']} without a known word)"]
    if "feedback" in o:
        f = o["feedback"]
        lines.append(f"feedback let through: {f['let_through']} of {f['num']} (lowest score {f['lowest_score']:.3f})")
    if "not_feedback" in o:
        n = o["not_feedback"]
        high = n["highest_score_let_through"]
        lines.append(
            f"not feedback refused: {n['refused']} of {n['num']}"
            + (f" (highest score let through {high:.3f})" if high is not None else "")
        )
    return "\n".join(lines)
