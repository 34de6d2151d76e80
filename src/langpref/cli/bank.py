"""`langpref bank check | bank augment | bank gate | lang-models`: a task's bank before a study, and the language
models to read it with."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from langpref.cli.common import JSON, NEGATION, figure, with_figure
from langpref.cli.outputs import check_writable, status
from langpref.cli_config import command, emit, opt, path
from langpref.errors import LangprefError
from langpref.extras import require

WHERE = opt(
    "where",
    metavar="DATASET_OR_TASK",
    help="a task name (metaworld, robosuite, a plugin's), a dataset directory, or a task file (.toml) before import",
)
SEED = opt(
    "--seed", type=int, default=0, help="seed of an unsplit bank's split, as `langpref import --seed` (default 0)"
)


def _embedder(args: argparse.Namespace, task: str):
    """(texts -> embeddings, what reads them): a checkpoint's language encoder (psi) with --model, else the
    pretrained sentence encoder --lang-model."""
    if args.model is None:
        from langpref.language.models import canonical_name
        from langpref.language.transformer import sentence_embedder

        return sentence_embedder(args.lang_model), f"pretrained {canonical_name(args.lang_model)}"
    from langpref.model.checkpoint import load_model

    model = load_model(
        args.model, lang_model=args.lang_model if args.lang_model_given else None, negation=args.negation
    )
    if model.info.env != task:
        raise LangprefError(f"model {args.model} was trained on task {model.info.env!r}, the bank is task {task!r}")
    return (lambda texts: model.encode_texts(list(texts)).double().cpu().numpy()), f"model {args.model}"


@command(
    "bank check",
    "how well each meaning of a bank is read from its own held-back phrasings, before a study",
    [
        WHERE,
        path(
            "--model", default=None, help="read with this checkpoint's language encoder (default: the pretrained one)"
        ),
        opt(
            "--lang-model",
            default=None,
            metavar="NAME_OR_PATH",
            help="pretrained sentence encoder without --model (default minilm); with --model, the model must name it",
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
        SEED,
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
    args.lang_model = args.lang_model or "minilm"
    check_writable(args.figure, "--figure")
    if args.model is None:
        from langpref.language.models import check_available

        check_available(args.lang_model)  # an unknown name fails here, before the slow imports
    status(f"loading torch to read the bank with {'the model ' + str(args.model) if args.model else args.lang_model}")
    embed, encoder = _embedder(args, source.task)
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


# `bank augment` lives in its own module (its proposers); imported here so that --help lists it in this place
from langpref.cli import augment as _augment  # noqa: E402, F401


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
        SEED,
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
        WHERE,
        path("--feedback", default=None, help="an utterance file (docs/design.md#utterance-files) of real feedback"),
        path("--not-feedback", default=None, help='JSON {"texts": [...]} of texts that are not feedback'),
        SEED,
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


@command(
    "lang-models",
    "the registered language models (--lang-model NAME); with --measure, their size, speed and reading of banks",
    [
        opt("--measure", action="store_true", help="load each installed model and measure it (about a minute)"),
        opt(
            "--bank",
            action="append",
            default=None,
            metavar="DATASET_OR_TASK",
            help="a bank to read (repeatable; default metaworld and robosuite); a task file or dataset works too",
        ),
        opt("--repeats", type=int, default=200, help="one-sentence embeddings timed per model (default 200)"),
        opt("--threads", type=int, default=1, help="torch CPU threads while measuring (default 1)"),
        JSON,
    ],
    "Lists every registered language model with its packages and whether they are installed. With --measure, for each "
    "installed one: install size (its packages, and what it unpacks into the cache), p50/p95 time to embed one "
    "sentence on this CPU, and how well the frozen pretrained model alone reads each bank's val and test phrasings "
    "by the nearest prototype of the train phrasings.",
)
def cmd_lang_models(args: argparse.Namespace) -> None:
    import datetime
    import time

    from langpref.language.models import get_lang_model, lang_model_names

    if args.repeats < 1:
        raise LangprefError(f"--repeats must be >= 1, got {args.repeats}")
    out: dict = {"models": {}}
    sources = []
    if args.measure:
        import torch

        from langpref.language.banksource import open_bank

        if args.threads < 1:
            raise LangprefError(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
        sources = [open_bank(w) for w in (args.bank or ["metaworld", "robosuite"])]
        out["measured"] = {
            "date": datetime.date.today().isoformat(),
            "torch_threads": torch.get_num_threads(),
            "cpu_count": os.cpu_count(),
            "load_average_before": [round(x, 2) for x in os.getloadavg()],
            "banks": [s.origin for s in sources],
        }
    for name in lang_model_names():
        spec = get_lang_model(name)
        row = {
            "title": spec.title,
            "installed": spec.installed(),
            "extra": spec.extra,
            "install": spec.install_hint(),
            "packages": spec.versions(),
        }
        if args.measure and row["installed"]:
            row.update(_measure(spec, sources, args.repeats, time))
        out["models"][name] = row
    if args.measure:
        out["measured"]["load_average_after"] = [round(x, 2) for x in os.getloadavg()]
    emit(out, args.json, _human_models)


def _measure(spec, sources, repeats: int, time) -> dict:
    from langpref.language.measure import bank_accuracy, latency_ms, package_bytes, unpacked_bytes
    from langpref.language.models import resolve
    from langpref.language.transformer import sentence_embedder

    start = time.perf_counter()
    local = resolve(spec.name)
    embed = sentence_embedder(spec.name)
    load_s = time.perf_counter() - start
    sentences = [t for s in sources for by in s.split("test").values() for ts in by.values() for t in ts]
    return {
        "package_mb": round(package_bytes(spec) / 2**20, 1),
        "unpacked_mb": round(unpacked_bytes(spec, local) / 2**20, 1),
        "load_s": round(load_s, 1),
        "latency_ms": latency_ms(embed, sentences or ["Move faster."], repeats),
        "accuracy": {s.task: bank_accuracy(embed, s) for s in sources},
    }


def _human_models(out: dict) -> str:
    lines = []
    for name, m in out["models"].items():
        state = "installed" if m["installed"] else f"not installed ({m['install']})"
        lines.append(f"{name:<8} {m['title']}: {state}")
        if "latency_ms" in m:
            lat = m["latency_ms"]
            lines.append(
                f"         {m['package_mb']:.0f} MB packages + {m['unpacked_mb']:.0f} MB unpacked; one sentence "
                f"p50 {lat['p50']:.1f} ms, p95 {lat['p95']:.1f} ms"
            )
            for task, acc in m["accuracy"].items():
                lines.append(
                    f"         {task}: val {acc['val']:.3f} ({acc['val_phrasings']}), "
                    f"test {acc['test']:.3f} ({acc['test_phrasings']})"
                )
    return "\n".join(lines)


@command(
    "lang-model build",
    "build a language model langpref makes (minilm trained on comparative feedback) into the cache, with progress",
    [
        opt("name", choices=["comparative", "comparative-aligned"], help="the model to build"),
        opt("--seed", type=int, default=0, help="seed of the corpus and the training (default 0, the cached one)"),
        opt("--steps", type=int, default=None, help="optimiser steps (default: PretrainConfig.steps)"),
        opt("--lr", type=float, default=None, help="learning rate (default: PretrainConfig.lr)"),
        opt("--temperature", type=float, default=None, help="contrastive temperature (default: PretrainConfig's)"),
        opt("--per-meaning", type=int, default=None, help="made sentences per concept and direction"),
        opt(
            "--objective",
            choices=["contrastive", "aligned"],
            default=None,
            help="contrastive over meanings (default), or aligned: signed concept axes, the co-finetuning loss "
            "without trajectories (langpref.language.pretrain_aligned)",
        ),
        opt("--head-lr", type=float, default=None, help="learning rate of the aligned objective's head"),
        opt("--threads", type=int, default=None, help="torch CPU threads (default: torch's own choice)"),
        opt(
            "--val-concepts",
            default=None,
            metavar="C1,C2,...",
            help="choose settings: hold these concepts out of training and report how the model sorts their sentences "
            "by meaning and direction before and during training (needs --out; nothing goes into the cache)",
        ),
        path("--out", default=None, help="build into this directory instead of the cache"),
        opt("--force", action="store_true", help="build again even when the cached model exists"),
        JSON,
    ],
    "Makes the comparative-feedback corpus (a hand-written lexicon of concepts made into sentences from the seed, and "
    "the built-in banks' train splits) and trains all-MiniLM-L6-v2 on it: `comparative` with a contrastive loss over "
    "meaning and direction (langpref.language.pretrain), `comparative-aligned` with the co-finetuning loss against a "
    "fixed signed axis per concept, no simulator (langpref.language.pretrain_aligned). `langpref train --lang-model "
    "NAME` builds it by itself when it is missing. With --val-concepts, a settings run: the named concepts are held "
    "out and read.",
)
def cmd_lang_model_build(args: argparse.Namespace) -> None:
    import dataclasses
    import time

    from langpref.language.models import comparative_dir
    from langpref.language.pretrain import build, preset, pretrain, read_record

    given = {"seed": args.seed, "steps": args.steps, "lr": args.lr, "temperature": args.temperature}
    given.update(per_meaning=args.per_meaning, objective=args.objective, head_lr=args.head_lr)
    if args.threads is not None:
        if args.threads < 1:
            raise LangprefError(f"--threads must be >= 1, got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    cfg = dataclasses.replace(preset(args.name), **{k: v for k, v in given.items() if v is not None})
    cfg.validate()
    if args.val_concepts:
        from langpref.language.corpus import build_corpus, concept_split, load_lexicon

        held = [c.strip() for c in args.val_concepts.split(",") if c.strip()]
        unknown = sorted(set(held) - set(load_lexicon()["concepts"]))
        if unknown:
            raise LangprefError(f"--val-concepts: unknown concept(s) {', '.join(unknown)}")
        if args.out is None:
            raise LangprefError("--val-concepts needs --out (a settings run never goes into the cache)")
        start = time.perf_counter()
        train, val = concept_split(build_corpus(cfg.seed, cfg.per_meaning), held)
        _, history = pretrain(train, cfg, val=val)
        out = {
            "config": dataclasses.asdict(cfg),
            "val_concepts": held,
            "train_sentences": len(train),
            "val_sentences": len(val),
            "val": [h for h in history if "meaning" in h],
            "seconds": round(time.perf_counter() - start, 1),
        }
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "val.json").write_text(json.dumps(out, indent=2) + "\n")
        emit(out, args.json, lambda o: "\n".join(f"step {h['step']}: {h}" for h in o["val"]))
        return
    target = args.out or comparative_dir(cfg.seed, args.name)
    if cfg != preset(args.name, cfg.seed) and args.out is None:
        raise LangprefError("settings other than the defaults build only with --out (the cache holds the defaults)")
    if (target / "model.safetensors").is_file() and not args.force:
        record = read_record(target) or {}
        out = {"path": str(target), "built": False, "record": record}
    else:
        record = build(target, cfg)
        out = {"path": str(target), "built": True, "record": record}
    out["size_mb"] = round(sum(f.stat().st_size for f in target.iterdir() if f.is_file()) / 2**20, 1)
    emit(out, args.json, lambda o: f"{'built' if o['built'] else 'already built'}: {o['path']} ({o['size_mb']} MB)")
