"""`langpref experiment alignment`: the paper's Appendix C table (test accuracy, co-finetuned vs frozen language
model) on our default dataset of an env.

One training run gives both rows: the frozen model *is* the co-finetuned model's stage 1 (same seed, same data), so
its checkpoint is saved when stage 1 ends and stage 2 continues from it. Both are evaluated on the test split's
trajectories with the bank's test phrasings (neither seen in training).
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

RESULTS_ROOT = Path("results") / "alignment"


def default_out(env: str) -> Path:
    """Where `langpref experiment alignment --env ENV` writes by default."""
    return RESULTS_ROOT / env


def default_model(env: str) -> Path:
    """The co-finetuned model of `experiment alignment`: the model every other experiment uses by default."""
    return default_out(env) / "cofinetuned"


PAPER = {  # Appendix C, Table "Test Accuracy of training with frozen language model and co-finetuning"
    "robosuite": {"cofinetune": 0.8489, "frozen": 0.7625},
    "metaworld": {"cofinetune": 0.8288, "frozen": 0.7344},
}


def run_alignment_experiment(
    env: str, data_dir: str | Path, out_dir: str | Path, *, config=None, force: bool = False, progress: bool = True
) -> dict[str, Any]:
    """Train both models on `data_dir`, evaluate them on its test split, write `alignment.{json,md}` into `out_dir`.

    `config` is a `TrainConfig` to start from (data/out/freeze_language are set here); the default is the default
    `langpref train` configuration.
    """
    from langpref.dataset.storage import load_dataset
    from langpref.language.bank import load_bank
    from langpref.language.pairs import phrasings_from_bank
    from langpref.model.checkpoint import load_model
    from langpref.model.config import TrainConfig
    from langpref.model.evaluate import evaluate_split
    from langpref.model.train import train

    if env not in PAPER:
        raise LangprefError(f"unknown env {env!r}: choose one of {', '.join(PAPER)}")
    dataset = load_dataset(data_dir, env=env)
    out_dir = Path(out_dir)
    cofinetuned, frozen = out_dir / "cofinetuned", out_dir / "frozen"
    cfg = replace(config or TrainConfig(), data=str(data_dir), out=str(cofinetuned), freeze_language=False, force=force)
    t0 = time.perf_counter()
    result = train(cfg, stage1_out=frozen, progress=progress)
    train_s = time.perf_counter() - t0
    test_phr = phrasings_from_bank(load_bank(env), "test", dataset.feature_names)
    rows = {}
    for name, path in (("cofinetune", cofinetuned), ("frozen", frozen)):
        model = load_model(path, dataset=dataset)
        rows[name] = evaluate_split(model, dataset, "test", test_phr)
        rows[name]["model"] = str(path)
    summary = {
        "env": env,
        "data": str(data_dir),
        "cofinetune": rows["cofinetune"],
        "frozen": rows["frozen"],
        "paper": PAPER.get(env),
        "train": result.results,
        "train_wall_s": train_s,
        "command": f"langpref experiment alignment --env {env} --data {data_dir} --out {out_dir}",
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "alignment.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out_dir / "alignment.md").write_text(alignment_table([summary]) + "\n")
    return summary


def alignment_table(summaries: list[dict[str, Any]]) -> str:
    """Markdown: one column pair (ours, paper) per env, one row per method, as the paper's Appendix C table."""
    head = "| Method | " + " | ".join(f"{s['env']} (ours) | {s['env']} (paper)" for s in summaries) + " |"
    sep = "|---|" + "---|---|" * len(summaries)
    lines = [head, sep]
    for key, label in (("cofinetune", "Co-finetune"), ("frozen", "Frozen language model")):
        cells = " | ".join(
            f"{s[key]['accuracy']:.3f} | " + (f"{s['paper'][key]:.3f}" if s["paper"] else "-") for s in summaries
        )
        lines.append(f"| {label} | {cells} |")
    per = []
    for s in summaries:
        for key in ("cofinetune", "frozen"):
            feats = ", ".join(f"{f} {a:.3f}" for f, a in s[key]["per_feature"].items())
            per.append(f"- {s['env']}, {key}: {feats} ({s[key]['num_samples']} test samples)")
    return "\n".join(lines + [""] + per)
