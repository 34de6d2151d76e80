"""`langpref experiment verdict --env ENV --runs DIR,DIR,...`: the reward experiment's verdict over training seeds.

One `langpref experiment reward` run per trained model (training seeds 0, 1, 2, each with the same synthetic humans
and seeds) says how language and comparisons compare *for that model*; one model can be lucky. This reads their
finished runs (runs.json) and pairs language with comparisons run by run (same model, human and seed), then gives
per-run differences, language minus comparisons, with a two-sided 95% t-interval:
- the area under the true-reward curve (the mean over query counts 0..Q of the normalised true reward of the test
  trajectory r_xi ranks first; higher is better);
- the mean cross-entropy over query counts 1..Q (lower is better);
pooled over every model and per model, and words the verdict from the pooled intervals: language is better, worse,
or not told apart. `--methods A,B` compares two other methods of the same runs instead (e.g. of `experiment active`:
`am-language-infogain,comparison-infogain`). Writes verdict.json and verdict.md.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

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

    def resolved(self) -> VerdictConfig:
        if len(self.runs) < 1:
            raise LangprefError("--runs needs at least one `experiment reward` output folder")
        if len(self.methods) != 2 or self.methods[0] == self.methods[1]:
            raise LangprefError(f"--methods needs two different methods A,B, got {','.join(self.methods)}")
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


def _differences(pairs: dict[str, Any], methods: tuple[str, ...]) -> dict[str, list[float]]:
    first, second = pairs[methods[0]], pairs[methods[1]]
    return {metric: [a - b for a, b in zip(first[metric], second[metric])] for metric in ("auc", "mean_ce")}


def run_verdict_experiment(cfg: VerdictConfig) -> dict[str, Any]:
    """Pair the runs of every folder, pool them, write verdict.{json,md} into `cfg.out`."""
    cfg = cfg.resolved()
    per_model, pooled = {}, {"auc": [], "mean_ce": []}
    for folder in cfg.runs:
        diffs = _differences(paired_runs(_read_runs(folder), cfg.methods), cfg.methods)
        per_model[folder] = {metric: interval(d) for metric, d in diffs.items()}
        for metric, d in diffs.items():
            pooled[metric] += d
    summary = {
        "env": cfg.env,
        "runs": list(cfg.runs),
        "methods": list(cfg.methods),
        "pooled": {metric: interval(d) for metric, d in pooled.items()},
        "per_model": per_model,
        "config": asdict(cfg),
        "date": datetime.date.today().isoformat(),
    }
    summary["verdict"] = verdict(summary["pooled"], cfg.methods)
    out = Path(str(cfg.out))
    out.mkdir(parents=True, exist_ok=True)
    (out / "verdict.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "verdict.md").write_text(verdict_table(summary) + "\n")
    return summary


def verdict(pooled: dict[str, dict[str, float]], methods: tuple[str, ...] = ("language", "comparison")) -> dict:
    """Per metric, `A better`, `B better` or `not told apart` (the interval holds 0), for methods (A, B)."""
    first, second = (f"{m} better" for m in methods)

    def word(iv: dict[str, float], higher_is_better: bool) -> str:
        if iv["low"] > 0:
            return first if higher_is_better else second
        if iv["high"] < 0:
            return second if higher_is_better else first
        return "not told apart"

    return {"auc": word(pooled["auc"], True), "mean_ce": word(pooled["mean_ce"], False)}


def verdict_table(summary: dict[str, Any]) -> str:
    """Markdown: per model and pooled, language minus comparisons with its interval, and the verdict."""

    def cell(iv: dict[str, float]) -> str:
        return f"{iv['mean']:+.3f} ({iv['low']:+.3f} to {iv['high']:+.3f})"

    a, b = summary["methods"]
    lines = [
        f"| reward runs | pairs | AUC, {a} - {b} (95% CI) | mean CE 1..Q, {a} - {b} (95% CI) |",
        "|---|---|---|---|",
    ]
    for folder, m in summary["per_model"].items():
        lines.append(f"| `{folder}` | {m['auc']['n']} | {cell(m['auc'])} | {cell(m['mean_ce'])} |")
    p = summary["pooled"]
    lines.append(f"| **pooled** | {p['auc']['n']} | **{cell(p['auc'])}** | **{cell(p['mean_ce'])}** |")
    v = summary["verdict"]
    runs = ",".join(summary["runs"])
    out = summary["config"]["out"]
    runs += f" --out {out}" if out != str(RESULTS_ROOT / summary["env"]) else ""
    runs += f" --methods {a},{b}" if (a, b) != ("language", "comparison") else ""
    lines += [
        "",
        f"Verdict on {summary['env']} (pooled paired intervals): AUC of the true reward, {v['auc']}; mean "
        f"cross-entropy, {v['mean_ce']}. `langpref experiment verdict --env {summary['env']} --runs {runs}`, "
        f"{summary['date']}.",
    ]
    return "\n".join(lines)
