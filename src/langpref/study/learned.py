"""What Study 2's learners learned and were told, for `langpref study export` and `GET /api/admin/export`:

- `learned_rewards`: every participant's learned reward per method (table `rewards`), written as
  `learned_rewards.json` for analyses outside langpref;
- `confirmations`: how often participants were asked what they meant (`--confirm-margin`) and what they chose
  (table `confirmations`), in `summary.json`;
- `bank_additions`: the phrasings they confirmed, as a bank file for the lab to review (`--bank-additions FILE`).

Each takes the study's tables (`analysis.tables.read_tables`) and the ids of the participants left out of the analyses.
"""

from __future__ import annotations

import html
import json
from collections.abc import Callable, Collection
from typing import Any

import numpy as np

from langpref.study import db as sdb
from langpref.study.flow import SURROGATES

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


def bank_additions(tables: Tables, env: str, excluded: Collection[str] = ()) -> tuple[dict[str, Any], int]:
    """The phrasings participants confirmed (text -> the meaning they chose) as a bank file for `env` (docs/design.md,
    schema, `{TASK: {feature: {increase: [...], decrease: [...]}}}`) for the lab to review before adding any to its
    bank; "none of these" and `excluded` participants are left out. (The file's content, its number of phrasings.)"""
    section: dict[str, dict[str, list[str]]] = {}
    for r in sorted(tables.get("confirmations", []), key=lambda r: (r["feature"] or "", r["answered_at"])):
        if r["meaning"] is None or r["participant_id"] in excluded:
            continue
        text = " ".join(SURROGATES.sub("\ufffd", r["text"]).split())
        texts = section.setdefault(r["feature"], {}).setdefault(r["direction"], [])
        if text not in texts:
            texts.append(text)
    count = sum(len(t) for d in section.values() for t in d.values())
    note = (
        "Phrasings study participants typed and then confirmed the meaning of (langpref study export "
        "--bank-additions). Review them before adding any to the task's bank; nothing here is used by itself."
    )
    return {"_comment": note, env: section}, count
