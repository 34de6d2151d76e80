"""`langpref experiment verdict --env ENV --runs DIR,DIR,...`: the reward experiment's verdict over training seeds.

One `langpref experiment reward` run per trained model (training seeds 0, 1, 2, each with the same synthetic humans
and seeds) says how language and comparisons compare *for that model*; one model can be lucky. This reads their
finished runs (runs.json) and pairs language with comparisons run by run (same model, human and seed), then gives
per-run differences, language minus comparisons:
- the area under the true-reward curve (the mean over query counts 0..Q of the normalised true reward of the test
  trajectory r_xi ranks first; higher is better);
- the mean cross-entropy over query counts 1..Q (lower is better);
over every model and per model, and words the verdict from the intervals over every model: language is better,
worse, or not told apart. `--methods A,B` compares two other methods of the same runs instead (e.g. of `experiment
active`: `am-language-infogain,comparison-infogain`). Writes verdict.json and verdict.md.

The models share their humans and seeds, so their pairs are not independent (`clustered`). The unit of the interval
is the human: by default (`--interval humans-models`) a 95% percentile interval of a bootstrap that resamples the
humans and the models, crossed, keeping every seed of a drawn (model, human); `--interval humans` resamples the
humans alone, the models held fixed. Per model it is the bootstrap over that model's humans. `--interval pooled` is
the old reading, kept for the record of the verdicts published with it: a t-interval over every pair as if the
90 were independent, which is too narrow when the human decides most of a difference.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal

from langpref.errors import LangprefError

RESULTS_ROOT = Path("results") / "verdict"


@dataclass(frozen=True)
class VerdictConfig:
    """`langpref experiment verdict`: language vs comparisons over several reward experiments (one per model)."""

    env: str
    """Task the reward experiments ran on (a label for the table)."""
    runs: tuple[str, ...] = ()
    """Output folders of `langpref experiment reward`, one per trained model (comma-separated)."""
    methods: tuple[str, ...] = ("language", "comparison")
    """The two methods compared, A minus B (comma-separated): `experiment reward`'s by default, or two of
    `experiment active`'s."""
    out: str | None = None
    """Output folder for verdict.json/.md; default results/verdict/ENV."""
    interval: Literal["humans-models", "humans", "pooled"] = "humans-models"
    """The interval the verdict is worded from: humans-models, a bootstrap over humans and models, crossed (the unit
    is the human; every seed of a drawn model and human kept); humans, over humans with the models held fixed;
    pooled, the old t-interval over every pair as if independent (for the record: too narrow when models share
    humans)."""
    bootstraps: int = 10000
    """Draws of the bootstrap."""
    seed: int = 0
    """Seed of the bootstrap's draws (same seed, same interval)."""

    def resolved(self) -> VerdictConfig:
        if len(self.runs) < 1:
            raise LangprefError("--runs needs at least one `experiment reward` output folder")
        if len(self.methods) != 2 or self.methods[0] == self.methods[1]:
            raise LangprefError(f"--methods needs two different methods A,B, got {','.join(self.methods)}")
        if self.interval != "pooled" and self.bootstraps < 100:
            raise LangprefError(f"--bootstraps needs at least 100 draws for a 95% interval, got {self.bootstraps}")
        return replace(self, out=self.out or str(RESULTS_ROOT / self.env))


def _read_runs(folder: str) -> dict[str, dict]:
    """{`method/human/seed`: curves} of one finished reward experiment, refused in one line when missing."""
    path = Path(folder) / "runs.json"
    try:
        runs = json.loads(path.read_text())["runs"]
    except FileNotFoundError:
        raise LangprefError(f"{path} not found: run `langpref experiment reward --out {folder}` first") from None
    except (json.JSONDecodeError, KeyError, UnicodeDecodeError):
        raise LangprefError(f"{path} is not the runs file of `langpref experiment reward`") from None
    return runs


def paired_runs(runs: dict[str, dict], methods: tuple[str, ...]) -> dict[str, Any]:
    """Per (human, seed) run both methods finished: AUC of the true-reward curve and mean CE over 1..Q, per method."""
    import numpy as np

    keys = sorted({k.split("/", 1)[1] for k in runs if k.split("/", 1)[0] in methods})
    keys = [k for k in keys if all(f"{m}/{k}" in runs for m in methods)]
    if not keys:
        known = sorted({k.split("/", 1)[0] for k in runs})
        raise LangprefError(f"no run of both {' and '.join(methods)} to pair; the runs hold {', '.join(known)}")
    out: dict[str, Any] = {"keys": keys}
    for m in methods:
        out[m] = {
            "auc": [float(np.mean(runs[f"{m}/{k}"]["true_reward_of_best"])) for k in keys],
            "mean_ce": [float(np.mean(runs[f"{m}/{k}"]["cross_entropy"][1:])) for k in keys],
        }
    return out


def interval(differences: list[float]) -> dict[str, float]:
    """Mean of paired differences with its two-sided 95% t-interval (infinite for one pair)."""
    import numpy as np
    from scipy import stats

    d = np.asarray(differences, dtype=np.float64)
    n = len(d)
    half = float(stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / np.sqrt(n)) if n > 1 else float("inf")
    mean = float(d.mean())
    return {"mean": mean, "low": mean - half, "high": mean + half, "n": n}


def _differences(pairs: dict[str, Any], methods: tuple[str, ...]) -> dict[str, dict[str, float]]:
    """Per metric, {`human/seed`: A minus B} of one model's paired runs."""
    first, second = pairs[methods[0]], pairs[methods[1]]
    return {
        metric: {k: a - b for k, a, b in zip(pairs["keys"], first[metric], second[metric])}
        for metric in ("auc", "mean_ce")
    }


def intervals(per_model: dict[str, dict[str, float]], cfg: VerdictConfig) -> dict[str, Any]:
    """The interval over every model, per `cfg.interval`, of {model: {`human/seed`: difference}}."""
    from langpref.experiments.clustered import cell_grid, cluster_bootstrap

    if cfg.interval == "pooled":
        return {**interval([d for diffs in per_model.values() for d in diffs.values()]), "method": "pooled"}
    grid = cell_grid(per_model)
    resample_models = cfg.interval == "humans-models"
    return cluster_bootstrap(grid, resample_models=resample_models, draws=cfg.bootstraps, seed=cfg.seed)


def _model_agreement(per_model: dict[str, dict[str, float]]) -> float | None:
    """The correlation of two models' per-human mean differences, averaged over pairs of models (None with one)."""
    import math

    from langpref.experiments.clustered import cell_grid, human_spread

    r = human_spread(cell_grid(per_model))
    return None if math.isnan(r) else r


def run_verdict_experiment(cfg: VerdictConfig) -> dict[str, Any]:
    """Pair the runs of every folder, put intervals on them per model and over every model, write
    verdict.{json,md} into `cfg.out`."""
    cfg = cfg.resolved()
    diffs = {folder: _differences(paired_runs(_read_runs(folder), cfg.methods), cfg.methods) for folder in cfg.runs}
    metrics = ("auc", "mean_ce")
    by_metric = {metric: {folder: d[metric] for folder, d in diffs.items()} for metric in metrics}
    per_model = {
        folder: {metric: intervals({folder: by_metric[metric][folder]}, cfg) for metric in metrics}
        for folder in cfg.runs
    }
    summary = {
        "env": cfg.env,
        "runs": list(cfg.runs),
        "methods": list(cfg.methods),
        "interval": cfg.interval,
        "overall": {metric: intervals(by_metric[metric], cfg) for metric in metrics},
        "per_model": per_model,
        "model_agreement": {metric: _model_agreement(by_metric[metric]) for metric in metrics},
        "config": asdict(cfg),
        "date": datetime.date.today().isoformat(),
    }
    summary["verdict"] = verdict(summary["overall"], cfg.methods)
    out = Path(str(cfg.out))
    out.mkdir(parents=True, exist_ok=True)
    (out / "verdict.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "verdict.md").write_text(verdict_table(summary) + "\n")
    return summary


INTERVAL_WORDS = {
    "humans-models": "bootstrap over humans and models",
    "humans": "bootstrap over humans, models fixed",
    "pooled": "pooled t-interval, every pair as independent: for the record, too narrow",
}
"""How the table names each `--interval`."""


def verdict(overall: dict[str, dict[str, float]], methods: tuple[str, ...] = ("language", "comparison")) -> dict:
    """Per metric, `A better`, `B better` or `not told apart` (the interval holds 0), for methods (A, B)."""
    first, second = (f"{m} better" for m in methods)

    def word(iv: dict[str, float], higher_is_better: bool) -> str:
        if iv["low"] > 0:
            return first if higher_is_better else second
        if iv["high"] < 0:
            return second if higher_is_better else first
        return "not told apart"

    return {"auc": word(overall["auc"], True), "mean_ce": word(overall["mean_ce"], False)}


def _rerun(summary: dict[str, Any]) -> str:
    """The command line that prints this table again."""
    a, b = summary["methods"]
    cfg = summary["config"]
    line = f"langpref experiment verdict --env {summary['env']} --runs {','.join(summary['runs'])}"
    line += f" --out {cfg['out']}" if cfg["out"] != str(RESULTS_ROOT / summary["env"]) else ""
    line += f" --methods {a},{b}" if (a, b) != ("language", "comparison") else ""
    line += f" --interval {cfg['interval']}" if cfg["interval"] != "humans-models" else ""
    if cfg["interval"] != "pooled":
        line += f" --bootstraps {cfg['bootstraps']}" if cfg["bootstraps"] != 10000 else ""
        line += f" --seed {cfg['seed']}" if cfg["seed"] != 0 else ""
    return line


def verdict_table(summary: dict[str, Any]) -> str:
    """Markdown: per model and over every model, A minus B with its 95% interval, and the verdict."""

    def cell(iv: dict[str, float]) -> str:
        return f"{iv['mean']:+.3f} ({iv['low']:+.3f} to {iv['high']:+.3f})"

    def humans(iv: dict[str, Any]) -> str:
        return str(iv.get("humans", "-"))

    a, b = summary["methods"]
    how = INTERVAL_WORDS[summary["interval"]]
    lines = [
        f"| reward runs | pairs | humans | AUC, {a} - {b} (95% CI) | mean CE 1..Q, {a} - {b} (95% CI) |",
        "|---|---|---|---|---|",
    ]
    for folder, m in summary["per_model"].items():
        lines.append(f"| `{folder}` | {m['auc']['n']} | {humans(m['auc'])} | {cell(m['auc'])} | {cell(m['mean_ce'])} |")
    o = summary["overall"]
    lines.append(
        f"| **all models** ({how}) | {o['auc']['n']} | {humans(o['auc'])} | **{cell(o['auc'])}** | "
        f"**{cell(o['mean_ce'])}** |"
    )
    v, agree = summary["verdict"], summary.get("model_agreement") or {}
    lines += [""]
    if agree.get("auc") is not None and agree.get("mean_ce") is not None:
        lines += [
            f"The models agree on a human: per-human mean differences correlate {agree['auc']:+.2f} between models "
            f"(AUC) and {agree['mean_ce']:+.2f} (CE), averaged over pairs of models.",
            "",
        ]
    lines.append(
        f"Verdict on {summary['env']} ({how}): AUC of the true reward, {v['auc']}; mean cross-entropy, "
        f"{v['mean_ce']}. `{_rerun(summary)}`, {summary['date']}."
    )
    return "\n".join(lines)
