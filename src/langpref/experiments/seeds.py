"""`langpref experiment seeds --env ENV`: how much the alignment accuracy moves with the training seed.

One model per training seed (the default `langpref train` configuration otherwise), each evaluated on the test
split's trajectories with the bank's test phrasings: accuracy, accuracy with tie pairs at chance, and the share of
phrasings read as their own meaning. The table and the line under it (mean, range, standard deviation over the
seeds) are printed by this command, so no number of the seeds table is typed by hand.

A model that already exists where the seed's model goes (`--models`, default results/seeds/ENV/seedN) is evaluated
as it is, not retrained; finished seeds are kept in runs.json under the output folder, so an interrupted run goes on
with the seeds that are left. Writes seeds.json and seeds.md.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

RESULTS_ROOT = Path("results") / "seeds"
PAPER_ACCURACY = {"metaworld": 0.829, "robosuite": 0.849}
"""Appendix C, co-finetuned, test accuracy: what the paper reports for each built-in task."""


@dataclass(frozen=True)
class SeedsConfig:
    """`langpref experiment seeds`: the alignment accuracy of one model per training seed."""

    env: str
    """Task of the dataset (metaworld, robosuite, or a recorded task)."""
    data: str | None = None
    """Dataset directory; default data/ENV."""
    out: str | None = None
    """Output folder (runs.json, seeds.md/.json, and the models trained here); default results/seeds/ENV."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """Training seeds (comma-separated)."""
    models: str | None = None
    """Where seed N's model is, with {seed} for N (e.g. models/metaworld-seed{seed}): evaluated if it exists,
    trained there if not; default OUT/seed{seed}."""
    device: str = "auto"
    """auto (cuda when available), cpu or cuda."""
    force: bool = False
    """Start over: forget finished seeds (models that exist are still evaluated, not retrained)."""

    def resolved(self) -> SeedsConfig:
        """Defaults filled in and checked, before any work."""
        if not self.seeds:
            raise LangprefError("--seeds needs at least one training seed, e.g. 0,1,2")
        if len(set(self.seeds)) != len(self.seeds):
            raise LangprefError(f"--seeds repeats a seed: {','.join(map(str, self.seeds))}")
        if self.models is not None and "{seed}" not in self.models:
            raise LangprefError(f"--models must hold {{seed}} where the seed goes, got {self.models!r}")
        out = self.out or str(RESULTS_ROOT / self.env)
        return replace(
            self,
            data=self.data or str(Path("data") / self.env),
            out=out,
            models=self.models or str(Path(out) / "seed{seed}"),
        )


def _model_of(cfg: SeedsConfig, seed: int) -> Path:
    """Seed `seed`'s model, trained with the default configuration when it does not exist yet."""
    model_dir = Path(str(cfg.models).format(seed=seed))
    if not (model_dir / "config.json").is_file():
        from langpref.model.config import TrainConfig
        from langpref.model.train import train

        # force: a folder without config.json is an interrupted training, started over
        train(TrainConfig(data=str(cfg.data), out=str(model_dir), seed=seed, device=cfg.device, force=True))
    return model_dir


def _evaluate(model_dir: Path, data: str, env: str) -> dict[str, Any]:
    """Test accuracy with the bank's test phrasings, with ties at chance, and the reading accuracy."""
    from langpref.dataset.storage import load_dataset
    from langpref.language.bank import load_bank
    from langpref.language.pairs import phrasings_from_bank
    from langpref.model.checkpoint import load_model
    from langpref.model.evaluate import evaluate_split

    dataset = load_dataset(data, env=env)
    model = load_model(model_dir, dataset=dataset)
    res = evaluate_split(model, dataset, "test", phrasings_from_bank(load_bank(env), "test", dataset.feature_names))
    keep = ("accuracy", "accuracy_ties_at_chance", "reading_accuracy", "per_feature", "num_samples")
    return {"model": str(model_dir), **{k: res[k] for k in keep if k in res}}


def run_seeds_experiment(cfg: SeedsConfig) -> dict[str, Any]:
    """Evaluate (training where needed) one model per seed; write seeds.{json,md} into `cfg.out`."""
    from langpref.dataset.checksum import dataset_checksum
    from langpref.dataset.storage import load_dataset
    from langpref.experiments.common import RunCache

    cfg = cfg.resolved()
    out = Path(str(cfg.out))
    checksum = dataset_checksum(load_dataset(str(cfg.data), env=cfg.env))
    identity = {"env": cfg.env, "data_checksum": checksum, "models": cfg.models}
    cache = RunCache(out / "runs.json", identity, cfg.force)
    for seed in cfg.seeds:
        if str(seed) not in cache:
            cache.put(str(seed), {**_evaluate(_model_of(cfg, seed), str(cfg.data), cfg.env), "commit": source_commit()})
    runs = {seed: cache.runs[str(seed)] for seed in cfg.seeds}
    summary = {
        "env": cfg.env,
        "data": str(cfg.data),
        "data_checksum": checksum,
        "seeds": list(cfg.seeds),
        "runs": {str(s): r for s, r in runs.items()},
        "over_seeds": over_seeds([r["accuracy"] for r in runs.values()]),
        "over_seeds_ties_at_chance": over_seeds([r["accuracy_ties_at_chance"] for r in runs.values()]),
        "config": asdict(cfg),
        "date": datetime.date.today().isoformat(),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "seeds.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "seeds.md").write_text(seeds_table(summary) + "\n")
    return summary


def source_commit() -> str | None:
    """The commit of the langpref checkout this runs from (with `+dirty` when it has uncommitted changes), or None
    outside a git checkout (an installed wheel): which code made a row of the table."""
    import subprocess

    root = Path(__file__).resolve().parents[3]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "src"], capture_output=True)
    except OSError:
        return None
    if head.returncode != 0:
        return None
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def over_seeds(values: list[float]) -> dict[str, float]:
    """Mean, min, max and the sample standard deviation (0 for one seed) of per-seed numbers."""
    import numpy as np

    v = np.asarray(values, dtype=np.float64)
    return {
        "mean": float(v.mean()),
        "min": float(v.min()),
        "max": float(v.max()),
        "sd": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
    }


def seeds_table(summary: dict[str, Any]) -> str:
    """Markdown: one row per seed, then the mean, range and sd over the seeds (and the paper's number)."""
    env = summary["env"]
    lines = [
        "| env | training seed | test accuracy (bank test phrasings) | tie pairs at chance | reading accuracy | data "
        "checksum | commit evaluated at |",
        "|---|---|---|---|---|---|---|",
    ]
    for seed, r in summary["runs"].items():
        read = f"{r['reading_accuracy']:.3f}" if "reading_accuracy" in r else "-"
        lines.append(
            f"| {env} | {seed} | {r['accuracy']:.3f} | {r['accuracy_ties_at_chance']:.3f} | {read} "
            f"| {summary['data_checksum'][:12]} | {r.get('commit') or '-'} |"
        )
    s, t = summary["over_seeds"], summary["over_seeds_ties_at_chance"]
    paper = f"; paper {PAPER_ACCURACY[env]}" if env in PAPER_ACCURACY else ""
    seeds = ", ".join(summary["runs"])
    lines += [
        "",
        f"Over training seeds {seeds}: {env} mean **{s['mean']:.3f}** ({s['min']:.3f} to {s['max']:.3f}, sd "
        f"{s['sd']:.3f}{paper}), ties at chance {t['mean']:.3f}. Data checksum {summary['data_checksum']} "
        f"(`langpref inspect {summary['data']} --json`), {summary['date']}.",
    ]
    return "\n".join(lines)
