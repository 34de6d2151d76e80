"""`langpref study serve | export`: the web app for user studies with real people."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from langpref import cli_config as cc
from langpref.cli.common import JSON
from langpref.cli_config import RERUN, command, config, emit, from_args, opt, path, record
from langpref.dataset.splits import SPLITS


@command(
    "study serve",
    "serve a study in the browser (Study 1: improvement, Study 2: language vs comparisons)",
    [
        config(
            "langpref.study.server.settings:ServeConfig",
            {
                "study": None,
                "video": None,
                "on_show": {"metavar": "CMD"},
                "on_show_timeout": {"metavar": "SECONDS"},
                "generated": {"metavar": "DIR"},
                # repeatable, and each may list several: --allowed-hosts a.example,b.example --allowed-host c
                "allowed_hosts": {
                    "metavar": "NAME[,NAME...]",
                    "aliases": ("--allowed-host",),
                    "action": "extend",
                    "default": [],
                },
                # repeatable: --trusted-proxy 127.0.0.1 --trusted-proxy ::1 (or 127.0.0.1,::1)
                "trusted_proxies": {
                    "flag": "--trusted-proxy",
                    "metavar": "ADDR[,ADDR...]",
                    "action": "extend",
                    "default": [],
                },
                "prerender": {
                    "help": "Do not render the study videos ahead at start: each is made when a participant first "
                    "needs it (they may then wait for it)."
                },
            },
            common=("model", "data", "db", "host", "port", "admin_token", "on_show"),
        ),
        config(
            "langpref.study.protocol.config:StudyConfig",
            lambda: {
                "study.split": {"choices": (*SPLITS, "all")},
                "study.improve_candidates": {"choices": ("split", "generated")},
                "study.learner": {"choices": importlib.import_module("langpref.reward.learners").learner_names()},
            },
            prefix="study.",
            unset=True,
            common=("study.split", "study.kinds", "study.pref_queries", "study.learner", "study.confirm_margin"),
        ),
        config(
            "langpref.study.server.settings:VideoConfig",
            lambda: {
                "video.format": {"choices": importlib.import_module("langpref.study.server.settings").VIDEO_FORMATS}
            },
            prefix="video.",
            flag_prefix="video-",
            common=(),
        ),
    ],
    "Prints the participant URL and an admin token. State lives in the SQLite --db: a restart on the same --db "
    "continues every participant where they were. Protocol options are fixed when the database is created.",
)
def cmd_study_serve(args: argparse.Namespace) -> None:
    from langpref.extras import needs
    from langpref.study.server.settings import ServeConfig

    with needs("study", "langpref study serve"):
        from langpref.study.server.serve import exit_now, resolve_study_config, serve
    if serve(from_args(ServeConfig, args, study=resolve_study_config(args.db, cc.args_of(args, "study.")))):
        exit_now(0)  # stopped by SIGTERM and cleaned up: the interpreter's own teardown would take seconds


@command(
    "study simulate",
    "simulated participants (synthetic humans) run whole sessions against a study server",
    [
        config(
            "langpref.study.server.settings:SimulateConfig",
            {"split": {"choices": (*SPLITS, "all")}, "data": {"metavar": "DIR"}, "generated": {"metavar": "DIR"}},
        ),
        config("langpref.study.server.simulate:SimConfig", {"think_ms": {"metavar": "LO,HI"}}),
        JSON,
    ],
    "Load tests, demo data, a dry run of a protocol. They answer like the library's synthetic humans over the study's "
    "dataset (--data, or the one --db was created with), at random without one. Run it on the server's machine: "
    "with --improve-candidates generated it reads the trajectories the server makes from --db and its generated "
    "dataset. Prints finished sessions, answers and latency per answer kind.",
)
def cmd_study_simulate(args: argparse.Namespace) -> None:
    from langpref.extras import needs
    from langpref.study.server.settings import SimulateConfig

    with needs("study", "langpref study simulate"):
        import httpx  # noqa: F401 (the participants' HTTP client)

        from langpref.study.server.simulate import SimConfig, simulate, study_of
    cfg = from_args(SimulateConfig, args)
    stored = study_of(cfg.db) if cfg.db else {}
    split = cfg.split or stored.get("split") or "test"
    out = simulate(cfg.url, from_args(SimConfig, args), cfg.data or stored.get("data"), split, cfg.db, cfg.generated)
    emit(
        out,
        args.json,
        lambda o: (
            f"{o['completed']} of {o['participants']} participants finished without errors, {o['answers']} answers "
            f"in {o['wall_s']:.0f} s" + (f"; first error: {o['errors'][0]}" if o["errors"] else "")
        ),
    )


@command(
    "study export",
    "CSV tables, analyses and figures of a study (HTML report + JSON)",
    [
        config("langpref.study.analysis.settings:ExportConfig"),
        opt(
            "--force",
            action="store_true",
            help="overwrite an existing --bank-additions file (never the study database)",
        ),
        RERUN,
        JSON,
    ],
    "Writes the tables, summary.json, learned_rewards.json, the figures and report.html into --out; answers.jsonl "
    "(every answer, for `learn-reward --answers`) and rewards/METHOD/reward-P<N>.json (each participant's reward, "
    "and a pooled one, for `langpref.reward.load`, `label` and the Gymnasium wrapper).",
)
def cmd_study_export(args: argparse.Namespace) -> None:
    from langpref.study.analysis.export import export
    from langpref.study.analysis.settings import ExportConfig

    cfg = from_args(ExportConfig, args)
    out = export(
        cfg.db, cfg.out, exclude=cfg.exclude, bank_additions_file=cfg.bank_additions, force=args.force, model=cfg.model
    )
    record(args, Path(cfg.out) / "export.config.json", cfg)
    emit(out, args.json, _export_text)


def _export_text(o: dict) -> str:
    """What `study export` wrote, in words: the report, the answers, the rewards and what each wants."""
    lines = [
        f"wrote {o['report']} ({o['participants']} participants, {o['finished']} finished), {len(o['tables'])} "
        f"tables and {len(o['figures'])} figures in {o['out']}",
        f"{o['num_answers']} answers in {o['answers']}",
    ]
    if "rewards_skipped" in o:
        lines.append(f"no rewards: {o['rewards_skipped']}")
    else:
        pooled = isinstance(o["pooled"], list)
        lines.append(
            f"{len(o['rewards'])} participant rewards"
            + (f" and {len(o['pooled'])} pooled" if pooled else "")
            + f" in {o['out']}/rewards"
            + ("" if pooled else f" (no pooled ones: {o['pooled']})")
        )
        lines += [f"  {r['participant']} {r['method']}: {r['wants']}" for r in o["rewards"] if "wants" in r]
    if "bank_additions" in o:
        lines.append(
            f"{o['bank_additions_phrasings']} bank additions ({o['bank_additions_flagged']} flagged) to review in "
            f"{o['bank_additions']}: langpref bank review {o['bank_additions']}"
        )
    return "\n".join(lines)


@command(
    "bank review",
    "the lab's review of a study's bank additions: the accepted phrasings as an utterances file",
    [
        path("additions", help="the file `study export --bank-additions` wrote, with each addition's accept set"),
        path("--out", default=None, help="write the accepted phrasings here (an utterances file); else only report"),
        opt(
            "--accept-unflagged",
            action="store_true",
            help="take an undecided addition without flags as accepted (a flagged one always needs accept set)",
        ),
        opt("--force", action="store_true", help="overwrite an existing --out file"),
        JSON,
    ],
    "A study's confirmed phrasings come with their count, participants and flags (the same text confirmed as "
    "another meaning, a text naming no change, the bank's own reading) and are no bank until reviewed: set each "
    "addition's accept to true or false, then this writes the accepted ones as an utterances file for `bank check "
    "--utterances` and `train --utterances`. Refused while an addition is undecided or a text is accepted as two "
    "meanings.",
)
def cmd_bank_review(args: argparse.Namespace) -> None:
    import json

    from langpref.errors import LangprefError
    from langpref.language.additions import load_additions, review

    data = load_additions(args.additions)
    if args.out is None:
        emit(_review_listing(data), args.json, _review_text)
        return
    if args.out.exists() and (args.out.resolve() == args.additions.resolve() or not args.force):
        raise LangprefError(f"--out {args.out} already exists; pass --force to overwrite it, or another file")
    bank, report = review(data, accept_unflagged=args.accept_unflagged)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(bank, indent=2) + "\n", encoding="utf-8")
    report["out"] = str(args.out)
    emit(
        report,
        args.json,
        lambda o: (
            f"wrote {o['written']} phrasings of {o['accepted']} accepted additions (of {o['additions']}; "
            f"{o['rejected']} rejected) to {o['out']}; check them: "
            f"langpref bank check {o['task']} --utterances {o['out']}"
        ),
    )


def _review_listing(data: dict) -> dict:
    """What a bank additions file holds, for the lab to read: each addition's meaning, count, flags and decision."""
    rows = [
        {k: a.get(k) for k in ("text", "feature", "direction", "count", "participants", "flags", "accept")}
        for a in data["additions"]
    ]
    return {"task": data["task"], "additions": rows, "undecided": sum(r["accept"] is None for r in rows)}


def _review_text(o: dict) -> str:
    lines = [f"{len(o['additions'])} additions to {o['task']}'s bank, {o['undecided']} undecided:"]
    for a in o["additions"]:
        decision = {None: "undecided", True: "accepted", False: "rejected"}[a["accept"]]
        lines.append(f"  {a['text']!r} as {a['feature']}/{a['direction']}: x{a['count']}, {decision}")
        lines.extend(f"      ! {flag}" for flag in a["flags"])
    return "\n".join(lines)
