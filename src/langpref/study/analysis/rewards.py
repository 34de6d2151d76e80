"""A study's answers and rewards as the lab takes them to its robot (`langpref study export`):

    DIR/answers.jsonl                      every Study-2 answer of the participants in the analyses, in the answers
                                           format (`langpref.feedback.answers`): `learn-reward --answers` reads it
    DIR/rewards/METHOD/reward-P<N>.json    participant N's reward of METHOD, as their learner held it after their last
                                           answer (the `rewards` table): `langpref.reward.load`, `label` and the
                                           Gymnasium wrapper take it as it is
    DIR/rewards/METHOD/reward-pooled.json  one reward of METHOD learned from every participant's answers in turn
                                           (`langpref.reward.recorded`, the study's learner and settings)

A saved reward refers to the study's model relative to itself and by its absolute path (`langpref.reward.saved`):
copy the model beside the export as it was beside the database, or pass `load(..., model=DIR)`. The rewards are written
only where the study's model (and, for the pooled ones, its dataset) is still where the study ran; otherwise the
export says why and writes the rest.
"""

from __future__ import annotations

import datetime
import json
from collections.abc import Collection
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.answers import answer_record, write_answers
from langpref.feedback.kind import get_kind
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.kinds import kind_answer

Tables = dict[str, list[dict[str, Any]]]
POOLED = "pooled"


def _iso(t: float | None) -> str | None:
    if t is None:
        return None
    return datetime.datetime.fromtimestamp(float(t), tz=datetime.UTC).isoformat(timespec="seconds")


def study_answers(tables: Tables, study: StudyConfig, excluded: Collection[str] = ()) -> list[dict[str, Any]]:
    """Every Study-2 answer of the participants not `excluded`, in the answers format, by participant number then
    method then query number; a confirmed meaning goes with its answer ("none of these" answers are left out: the
    learner did not learn from them)."""
    numbers = {p["id"]: int(p["number"]) for p in tables["participants"]}
    confirmed = {(r["participant_id"], r["method"], int(r["number"])): r for r in tables.get("confirmations", [])}
    records = []
    for method in study.kinds:
        kind = get_kind(method)
        for row in sdb.method_rows(tables.get(kind.table, []), method):
            pid = row["participant_id"]
            if pid in excluded or pid not in numbers:
                continue
            c = confirmed.get((pid, method, int(row["number"])))
            if c is not None and c["meaning"] is None:
                continue
            meaning = None if c is None else (c["feature"], c["direction"])
            answer = kind_answer(kind, row)
            record = answer_record(
                kind.name,
                answer,
                f"P{numbers[pid]}",
                method=method,
                number=int(row["number"]),
                meaning=meaning,
                time=_iso(row.get("answered_at")),
            )
            records.append((numbers[pid], method, int(row["number"]), record))
    return [r for *_, r in sorted(records, key=lambda x: x[:3])]


def _latest(tables: Tables, excluded: Collection[str]) -> dict[tuple[str, str], dict[str, Any]]:
    """(participant id, method) -> the `rewards` row after their last answer of it."""
    latest: dict[tuple[str, str], dict[str, Any]] = {}
    for r in tables.get("rewards", []):
        key = (r["participant_id"], r["method"])
        if r["participant_id"] not in excluded and (key not in latest or r["number"] > latest[key]["number"]):
            latest[key] = r
    return latest


def write_study_rewards(
    tables: Tables, out: Path, excluded: Collection[str] = (), model: str | Path | None = None
) -> dict[str, Any]:
    """answers.jsonl and rewards/ of the module docstring into `out`; what was written, and why not where it was
    not. `model` overrides the study's recorded model folder."""
    from langpref.reward.saved import check_saveable, write_reward
    from langpref.reward.wants import describe, what_it_wants

    meta = sdb.decode_meta(tables.get("meta", []))
    study = StudyConfig.from_dict(meta.get("study") or {})
    records = study_answers(tables, study, excluded)
    answers_path = out / "answers.jsonl"
    write_answers(answers_path, records)
    result: dict[str, Any] = {"answers": str(answers_path), "num_answers": len(records), "rewards": []}
    model = Path(model or meta.get("model") or "")
    if not (model / "config.json").is_file():
        result["rewards_skipped"] = (
            f"the study's model is not at {model}: copy it back or pass --model DIR to write the rewards"
        )
        return result
    try:
        check_saveable(model)
    except LangprefError as exc:
        result["rewards_skipped"] = str(exc)
        return result
    numbers = {p["id"]: int(p["number"]) for p in tables["participants"]}
    env = meta.get("env") or ""
    space = _space_of(model, meta.get("data"))
    for (pid, method), row in sorted(_latest(tables, excluded).items(), key=lambda kv: (numbers[kv[0][0]], kv[0][1])):
        xi = json.loads(row["latent_weights"])
        name = f"P{numbers[pid]}"
        wanted = None if space is None else what_it_wants(space.phi @ np.asarray(xi), space.theta, space.feature_names)
        path = write_reward(
            out / "rewards" / method,
            name,
            kind="linear",
            params={"xi": xi},
            reward_config={"learner": row["learner"], "study": study.to_dict()},
            env=env,
            model=model,
            queries=int(row["number"]),
            wants=wanted,
            extra={"learned_from": {"study_method": method, "participant": name, "answers": int(row["number"])}},
        )
        entry = {"method": method, "participant": name, "path": str(path)}
        result["rewards"].append(entry | ({"wants": describe(wanted)} if wanted else {}))
    result["pooled"] = (
        pooled_rewards(records, study, out / "rewards", model, space, meta["data"])
        if space is not None
        else f"the study's dataset is not at {meta.get('data')}: the pooled rewards need it"
    )
    return result


def pooled_rewards(
    records: list[dict[str, Any]], study: StudyConfig, out: Path, model: Path, space, data: str
) -> list[dict[str, Any]]:
    """One reward per method learned from every participant's answers in turn, with the study's learner and
    settings over the study set (`langpref.reward.recorded`), in the study's latent `space`."""
    from langpref.dataset.storage import load_dataset
    from langpref.feedback.answers import parse_records
    from langpref.reward import LearnRewardConfig, RewardConfig
    from langpref.reward.recorded import learn_group
    from langpref.reward.saved import save_learned_reward

    n = len(space.phi)
    pool = np.arange(n) if study.split == "all" else np.asarray(load_dataset(data).split(study.split))
    answers = parse_records(records, n, list(space.feature_names))
    written = []
    for method in study.kinds:
        chosen = [a for a in answers if a.group == method]
        if not chosen:
            continue
        cfg = LearnRewardConfig(
            feedback=method, learner=study.learner, reward=RewardConfig(num_negatives=study.num_negatives)
        )
        group = learn_group(space, POOLED, chosen, cfg, pool=pool)
        extra = {"learned_from": {"study_method": method, "participants": list(group.participants)}}
        path = save_learned_reward(
            group.learner, out / method, env=space.env, model=model, name=POOLED, space=space, extra=extra
        )
        written.append({"method": method, "answers": group.answers, "path": str(path)})
    return written


def _space_of(model: Path, data: str | None):
    """The study's latent space (its dataset through its model, the bank's train phrasings), read once for what each
    reward wants and for the pooled rewards; None when the dataset is gone."""
    if not data or not (Path(data) / "meta.json").is_file():
        return None
    from langpref.feedback.space import load_space

    return load_space(data, model, bank_splits=("train",))
