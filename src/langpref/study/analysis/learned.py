"""What Study 2's learners learned and were told, for `langpref study export` and `GET /api/admin/export`:

- `learned_rewards`: every participant's learned reward per method (table `rewards`), written as
  `learned_rewards.json` for analyses outside langpref;
- `confirmations`: how often participants were asked what they meant (`--confirm-margin`) and what they chose
  (table `confirmations`), in `summary.json`;
- `bank_additions`: the phrasings they confirmed, with their provenance, counts and conflicts, as a file for the lab
  to review before any of them enters a bank (`--bank-additions FILE`, then `langpref bank review`).

Each takes the study's tables (`analysis.tables.read_tables`) and the ids of the participants left out of the analyses.
"""

from __future__ import annotations

import html
import json
import time
from collections.abc import Callable, Collection
from datetime import UTC, datetime
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.study.protocol import db as sdb
from langpref.study.protocol.flow import SURROGATES

Tables = dict[str, list[dict[str, Any]]]


def learned_rewards(tables: Tables, excluded: Collection[str] = ()) -> dict[str, Any]:
    """Every participant's learned reward per Study-2 method, as their learner held it after their last answer of it
    (table `rewards`): `latent_weights` xi (the reward of a trajectory is xi . phi, plus a constant, phi from the
    study's model), `feature_weights` (the answer-model learner's weights over the bank's feature axes; None for the
    paper's learner), `ranking` (the study set's dataset indices, best first). Participants left out of the analyses
    (`excluded` ids) are listed with `excluded` true."""
    numbers = {p["id"]: p["number"] for p in tables["participants"]}
    latest: dict[tuple[str, str], dict[str, Any]] = {}
    for r in tables.get("rewards", []):
        key = (r["participant_id"], r["method"])
        if key not in latest or r["number"] > latest[key]["number"]:
            latest[key] = r
    rewards = [
        {
            "participant_id": pid,
            "number": numbers.get(pid),
            "excluded": pid in excluded,
            "method": method,
            "learner": r["learner"],
            "after_answers": r["number"],
            "latent_weights": json.loads(r["latent_weights"]),
            "feature_weights": json.loads(r["feature_weights"]) if r["feature_weights"] else None,
            "ranking": json.loads(r["ranking"]),
        }
        for (pid, method), r in sorted(latest.items(), key=lambda kv: (numbers.get(kv[0][0]) or 0, kv[0][1]))
    ]
    meta = sdb.decode_meta(tables.get("meta", []))
    return {
        "learner": (meta.get("study") or {}).get("learner", "paper"),
        "model": meta.get("model"),
        "data": meta.get("data"),
        "rewards": rewards,
    }


def confirmations(tables: Tables, study: dict[str, Any]) -> dict[str, Any]:
    """How often participants were asked what they meant (`--confirm-margin`) and what they chose: the rank of the
    chosen reading among the options (1: the model's top reading), "none of these", the meanings chosen, the seconds
    to each confirm click (not in the time per language query, which is the typed answer's own)."""
    rows = tables.get("confirmations", [])
    asked: dict[str, int] = {}
    for r in tables["steps"]:
        if r["kind"] == "confirm":
            asked[r["participant_id"]] = asked.get(r["participant_id"], 0) + 1
    answers = len(sdb.method_rows(tables["feedback"], "language"))
    ranks = [r["rank"] for r in rows]
    per = {pid: {"asked": n, "answered": 0, "none_of_these": 0} for pid, n in asked.items()}
    meanings: dict[str, int] = {}
    for r in rows:
        entry = per.setdefault(r["participant_id"], {"asked": 0, "answered": 0, "none_of_these": 0})
        entry["answered"] += 1
        entry["none_of_these"] += r["meaning"] is None
        if r["meaning"] is not None:
            key = f"{r['feature']}/{r['direction']}"
            meanings[key] = meanings.get(key, 0) + 1
    total = sum(asked.values())
    seconds = [r["server_ms"] / 1000.0 for r in tables["answers"] if r["kind"] == "confirm"]
    return {
        "margin": study.get("confirm_margin"),
        "language_answers": answers,
        "asked": total,
        "asked_share": total / answers if answers else None,
        "answered": len(rows),
        "chosen_rank": {str(k): ranks.count(k) for k in sorted({k for k in ranks if k is not None})},
        "none_of_these": ranks.count(None),
        "chosen_meanings": dict(sorted(meanings.items())),
        "time_s": {
            "mean": float(np.mean(seconds)) if seconds else None,
            "median": float(np.median(seconds)) if seconds else None,
            "n": len(seconds),
        },
        "per_participant": per,
    }


def confirmations_html(c: dict[str, Any], fmt: Callable[[Any], str]) -> str:
    """The report's paragraph on `confirmations` (nothing when nobody was asked)."""
    if not c["asked"]:
        return ""
    ranks = ", ".join(f"reading {k}: {n}" for k, n in c["chosen_rank"].items())
    return (
        f"<h3>Asked what they meant</h3><p>{c['asked']} of {c['language_answers']} language answers "
        f"(margin {fmt(c['margin'])}); chosen: {html.escape(ranks or '-')}; none of these: {c['none_of_these']}.</p>"
    )


def bank_additions(
    tables: Tables, env: str, excluded: Collection[str] = (), db: str | None = None
) -> tuple[dict[str, Any], int]:
    """The phrasings participants confirmed the meaning of, as a bank additions file for the lab to review
    (`langpref.language.additions`: each text under each meaning chosen, with its count, the participants and every
    confirmation's query, margin and rank, and flags: the same text confirmed otherwise, a text naming no change,
    the bank's own reading); "none of these" counts against a text, and `excluded` participants are left out. No
    utterances reader takes the file before `langpref bank review`. (The file's content, its number of additions.)"""
    from langpref.language.additions import additions_file

    numbers = {p["id"]: p["number"] for p in tables["participants"]}
    rows = [
        _confirmation(r, numbers.get(r["participant_id"]))
        for r in sorted(tables.get("confirmations", []), key=lambda r: r["answered_at"])
        if r["participant_id"] not in excluded
    ]
    meta = sdb.decode_meta(tables.get("meta", []))
    source = {
        "db": db,
        "model": meta.get("model"),
        "data": meta.get("data"),
        "confirm_margin": (meta.get("study") or {}).get("confirm_margin"),
        "participants": len({r["participant"] for r in rows}),
        "excluded_participants": len(set(excluded)),
        "exported_at": _iso(time.time()),
    }
    out = additions_file(env, rows, _bank_of(env), source)
    return out, len(out["additions"])


def _confirmation(r: dict[str, Any], number: int | None) -> dict[str, Any]:
    """A `confirmations` row as a confirmation of the additions file: the text and meaning chosen, and where it
    came from (the participant's number, the query, the reading's margin, the chosen meaning's rank and p)."""
    options = json.loads(r["options"]) if r.get("options") else []
    chosen = next((o for o in options if o.get("meaning") == r["meaning"]), None)
    return {
        "text": " ".join(SURROGATES.sub("\ufffd", r["text"]).split()),
        "feature": r["feature"] if r["meaning"] is not None else None,
        "direction": r["direction"] if r["meaning"] is not None else None,
        "participant": number,
        "method": r["method"],
        "query": r["number"],
        "seq": r["seq"],
        "shown": r["shown"],
        "margin": r["margin"],
        "rank": r["rank"],
        "p": None if chosen is None else chosen.get("p"),
        "answered_at": _iso(r["answered_at"]),
    }


def _bank_of(env: str) -> dict[str, str] | None:
    """normalised text -> meaning of task `env`'s bank, all splits; None when the bank cannot be read here (a task
    not registered in this process): the additions are then not checked against it."""
    from langpref.language.additions import bank_meanings
    from langpref.language.bank import load_bank

    try:
        return bank_meanings(load_bank(env).phrasings)
    except (LangprefError, KeyError, ValueError):
        return None


def _iso(t: float) -> str:
    return datetime.fromtimestamp(float(t), tz=UTC).isoformat(timespec="seconds")
