"""What `langpref experiment rl` reports: per reward source the learning curves and final evaluation (means over
humans x seeds), paired 95% intervals between sources, the learned rewards' CMA-ES optima, the issue's targets, the
figure and the section for docs/results.md."""

from __future__ import annotations

import datetime
import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from langpref.experiments.common import figure_link
from langpref.experiments.rl_policy import LEARNED

CONTRASTS = (
    ("language", "comparison"),
    ("language", "true"),
    ("comparison", "true"),
    ("true", "success"),
    ("language", "success"),
)
"""Paired differences reported (first minus second), where both sources ran."""
TARGET_SHARE = 0.8
"""Issue 33: the language policy reaches at least this share of the true-reward policy's true return."""
METRICS = ("true_reward", "success")


def _pairs(cfg) -> list[str]:
    return [f"h{h}-s{s}" for h in range(cfg.humans) for s in range(cfg.seeds)]


def source_summary(runs: dict[str, dict], source: str, cfg) -> dict[str, Any]:
    """Mean and std over runs of each curve (per evaluation) and of the final evaluation, the per-run finals and the
    mean wall time."""
    mine = [runs[f"policy-{source}-{p}"] for p in _pairs(cfg)]
    out: dict[str, Any] = {"steps": mine[0]["curve"]["steps"], "num_runs": len(mine)}
    for key in mine[0]["final"]:
        curves = np.array([r["curve"][key] for r in mine], dtype=np.float64)
        finals = np.array([r["final"][key] for r in mine], dtype=np.float64)
        out[key] = curves.mean(axis=0).tolist()
        out[f"{key}_std"] = curves.std(axis=0).tolist()
        out[f"final_{key}"] = float(finals.mean())
        out[f"final_{key}_std"] = float(finals.std())
        out[f"final_{key}_runs"] = finals.tolist()
    out["wall_s"] = float(np.mean([r["wall_s"] for r in mine]))
    return out


def paired(a: list[float], b: list[float], humans: int = 0) -> dict[str, float | None]:
    """Mean of a - b over paired runs (same human and seed; ordered human by human, as `_pairs`) with its two-sided
    95% t-interval over humans: each human's seeds are averaged first, so the unit is the human and correlated seeds
    never count as more people (`humans` 0: every run its own unit). None: one human, no interval."""
    from langpref.experiments.reward import paired_difference, per_human

    seeds = len(a) // (humans or len(a))
    d = paired_difference(per_human(np.asarray(a)[:, None], seeds), per_human(np.asarray(b)[:, None], seeds))
    return {k: float(v[0]) if np.isfinite(v[0]) else None for k, v in d.items()}  # None: one unit, no interval


def reward_summary(rewards: dict[str, dict], cfg) -> dict[str, Any]:
    """Per learned kind: the reward-learning metrics after Q answers and, where made, the CMA-ES optimum's true
    reward and success (means over runs, and per run)."""
    out = {}
    for kind in (s for s in cfg.sources if s in LEARNED):
        mine = [rewards[f"reward-{kind}-{p}"] for p in _pairs(cfg)]
        res = {
            "true_reward_of_best": float(np.mean([r["true_reward_of_best"] for r in mine])),
            "kendall_tau": float(np.mean([r["kendall_tau"] for r in mine])),
        }
        if all("cmaes" in r for r in mine):
            for key in METRICS:
                res[f"cmaes_{key}_runs"] = [float(r["cmaes"][key]) for r in mine]
                res[f"cmaes_{key}"] = float(np.mean(res[f"cmaes_{key}_runs"]))
        out[kind] = res
    return out


def targets(sources: dict[str, dict]) -> dict[str, bool]:
    """Issue 33's Meta-World targets where the sources they compare ran."""
    if not {"language", "true"} <= set(sources):
        return {}
    lang, true = sources["language"]["final_true_reward"], sources["true"]["final_true_reward"]
    out = {
        f"language reaches {TARGET_SHARE:.0%} of the true-reward policy's true reward ({lang:.3f} vs {true:.3f})": bool(
            true > 0 and lang >= TARGET_SHARE * true
        )
    }
    if "comparison" in sources:
        comp = sources["comparison"]["final_true_reward"]
        out[f"language above comparisons ({lang:.3f} vs {comp:.3f})"] = bool(lang > comp)
    return out


BOOTSTRAPS = 10_000
"""Resamples of the humans for the ratios' intervals."""


def ratios(runs: dict[str, dict], cfg, seed: int = 0) -> dict[str, Any]:
    """Per learned source, the mean final true reward of its policies as a share of the true-reward policies', on two
    scales: as evaluated (0 = the test split's worst trajectory) and above the untrained policy (each run's
    evaluation at step 0, the untrained network: the share of the true-reward policies' gain). A ratio of means over
    humans (a human's seeds averaged first): the interval is a percentile bootstrap over humans (seeded), so
    correlated seeds never count as more humans, and a human whose true-reward policy gained little does not blow
    the ratio up."""
    if "true" not in cfg.sources:
        return {}

    def per_human(source: str, value) -> np.ndarray:
        return np.array(
            [np.mean([value(runs[f"policy-{source}-h{h}-s{s}"]) for s in range(cfg.seeds)]) for h in range(cfg.humans)]
        )

    final = lambda r: r["final"]["true_reward"]  # noqa: E731
    start = lambda r: r["curve"]["true_reward"][0]  # noqa: E731
    picks = np.random.default_rng(seed).integers(0, cfg.humans, size=(BOOTSTRAPS, cfg.humans))
    best, untrained = per_human("true", final), per_human("true", start)
    out = {}
    for source in (s for s in cfg.sources if s != "true"):
        mine, zero = per_human(source, final), (per_human(source, start) + untrained) / 2
        scales = {"as_evaluated": (mine, best), "above_untrained": (mine - zero, best - zero)}
        out[source] = {}
        for scale, (num, den) in scales.items():
            out[source][scale] = _ratio_of_means(num, den, picks)
        out[source]["untrained_true_reward"] = float(zero.mean())
    return out


def _ratio_of_means(num: np.ndarray, den: np.ndarray, picks: np.ndarray) -> dict[str, float | None]:
    """mean(num) / mean(den) with a percentile interval over the resampled rows `picks`; None where the true-reward
    policies gained nothing (no scale to share), and resamples without a gain left out."""
    if den.mean() == 0:
        return {"mean": None, "low": None, "high": None}
    top, bottom = num[picks].mean(axis=1), den[picks].mean(axis=1)
    boot = top[bottom != 0] / bottom[bottom != 0]
    low, high = np.percentile(boot, [2.5, 97.5])
    return {"mean": float(num.mean() / den.mean()), "low": float(low), "high": float(high)}


def summarise(runs: dict[str, dict], rewards: dict[str, dict], cfg) -> dict[str, Any]:
    """The experiment's results: per source, paired contrasts, the learned rewards, the targets."""
    sources = {s: source_summary(runs, s, cfg) for s in cfg.sources}
    contrasts = {
        f"{a} - {b}": {
            key: paired(sources[a][f"final_{key}_runs"], sources[b][f"final_{key}_runs"], cfg.humans) for key in METRICS
        }
        for a, b in CONTRASTS
        if a in sources and b in sources
    }
    return {
        "sources": sources,
        "untrained": untrained(runs, cfg),
        "contrasts": contrasts,
        "learned_rewards": reward_summary(rewards, cfg),
        "targets": targets(sources),
        "ratios": ratios(runs, cfg),
    }


def untrained(runs: dict[str, dict], cfg) -> dict[str, float]:
    """The untrained policy, a baseline beside the task-success policy: every run's evaluation at step 0, before
    any update (the same network for every source of a human and seed), averaged over all of them."""
    mine = [runs[f"policy-{source}-{p}"]["curve"] for source in cfg.sources for p in _pairs(cfg)]
    return {key: float(np.mean([c[key][0] for c in mine])) for key in METRICS}


def per_human(runs: dict[str, dict], cfg, feature_names, weights) -> list[dict[str, Any]]:
    """Per human: its weights (which say whether it wants the task done) and each source's final true reward and
    success, its seeds averaged."""
    out = []
    for h, w in enumerate(weights):
        row: dict[str, Any] = {"human": h, "weights": dict(zip(feature_names, (float(x) for x in w)))}
        for source in cfg.sources:
            finals = [runs[f"policy-{source}-h{h}-s{s}"]["final"] for s in range(cfg.seeds)]
            row[source] = {key: float(np.mean([f[key] for f in finals])) for key in METRICS}
        out.append(row)
    return out


def plot_rl(summary: dict[str, Any], out: Path, title: str) -> Path:
    """Two panels over environment steps: the policies' true reward (0..1 on the test split's scale) and success
    rate, mean with a +-std band per source; the learned rewards' CMA-ES optima as dashed lines."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the rl figure")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, key in enumerate(METRICS):
        ax = axes[k]
        for name, res in summary["sources"].items():
            x, mean, std = (np.array(res[f]) for f in ("steps", key, f"{key}_std"))
            (line,) = ax.plot(x, mean, label=f"{name} reward")
            ax.fill_between(x, mean - std, mean + std, alpha=0.15, color=line.get_color())
            cmaes = summary["learned_rewards"].get(name, {}).get(f"cmaes_{key}")
            if cmaes is not None:
                ax.axhline(cmaes, ls="--", lw=1, color=line.get_color(), label=f"{name}: CMA-ES optimum")
        ax.set_xlabel("environment steps")
        if key == "success":
            ax.set_ylim(-0.05, 1.05)
        ax.set_title(
            "(a) true reward of the policy's rollouts (0..1: test split)" if k == 0 else "(b) success rate", fontsize=10
        )
    axes[0].legend(fontsize=7)
    fig.suptitle(title)
    return save_figure(fig, out, dpi=120, trim=False)


def markdown(summary: dict[str, Any]) -> str:
    """The section for docs/results.md."""
    cfg = summary["config"]
    lines = [
        f"### Policies trained on the learned reward, {summary['env']}",
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {cfg['algorithm'].upper()}, "
        f"{cfg['steps']} steps of {cfg['horizon']}-step episodes; {summary['humans']} humans x {summary['seeds']} "
        f"seeds; Q = {cfg['queries']}). True reward: of the policy's deterministic rollouts from "
        f"{cfg['eval_episodes']} fixed scenes, on a scale whose 0 is the test split's worst recorded trajectory and 1 "
        f"its best (recordings of the dataset's own length; theta is a per-step mean, so the {cfg['horizon']}-step "
        "rollouts share its features, not its length; above 1 is better than any test recording); success at the "
        "last step.",
        "",
        "| trained on | true reward (final) | success (final) | its own learned reward | minutes per run |",
        "|---|---|---|---|---|",
    ]
    if "untrained" in summary:
        base = summary["untrained"]
        lines.append(
            f"| nothing (the untrained policy, step 0) | {base['true_reward']:.3f} | {base['success']:.2f} | | |"
        )
    for name, res in summary["sources"].items():
        own = f"{res['final_own_reward']:.3f}" if "final_own_reward" in res else "n/a"
        lines.append(
            f"| {name} | {res['final_true_reward']:.3f} +- {res['final_true_reward_std']:.3f} | "
            f"{res['final_success']:.2f} | {own} | {res['wall_s'] / 60:.1f} |"
        )
    for kind, res in summary["learned_rewards"].items():
        if "cmaes_true_reward" in res:
            lines.append(
                f"| {kind}: CMA-ES optimum, no RL | {res['cmaes_true_reward']:.3f} | {res['cmaes_success']:.2f} | | |"
            )
    if summary["contrasts"]:
        lines += ["", "Paired differences of the final evaluation (same human and seed), 95% t-intervals over the "]
        lines[-1] += f"{summary['humans']} humans (each human's seeds averaged first: the unit is the human):"
        lines += [""]
        lines += ["| contrast | true reward | success |", "|---|---|---|"]
        for name, c in summary["contrasts"].items():
            cells = [_interval(c[k]) for k in METRICS]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += _ratio_lines(summary)
    lines += _human_lines(summary)
    if summary["targets"]:
        lines += ["", "Targets: " + "; ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in summary["targets"].items())]
    lines += ["", f"![Policies on the learned reward, {summary['env']}]({figure_link(summary['figure'])})"]
    return "\n".join(lines) + "\n"


def _ratio_lines(summary: dict[str, Any]) -> list[str]:
    """The shares of the true-reward policies' true reward, on both scales, with their intervals."""
    if not summary.get("ratios"):
        return []
    lines = ["", "Share of the true-reward policies' true reward (ratio of means over humans; 95% percentile bootstrap"]
    lines[-1] += " over humans, each human's seeds averaged first; the untrained policy's true reward is each run's "
    lines[-1] += "step-0 evaluation):"
    lines += [
        "",
        "| trained on | as evaluated (0 = worst test trajectory) | above the untrained policy |",
        "|---|---|---|",
    ]
    for name, r in summary["ratios"].items():
        cells = [
            f"{r[k]['mean']:.0%} ({r[k]['low']:.0%} to {r[k]['high']:.0%})" if r[k]["mean"] is not None else "n/a"
            for k in ("as_evaluated", "above_untrained")
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def _human_lines(summary: dict[str, Any]) -> list[str]:
    """The per-human table: weights, then each source's final true reward / success (seeds averaged)."""
    rows = summary.get("per_human")
    if not rows:
        return []
    names, sources = list(rows[0]["weights"]), summary["config"]["sources"]
    lines = ["", "Per human (its weights on the standardised features; each source's final true reward / success):", ""]
    lines += ["| human | " + " | ".join(f"w {n}" for n in names) + " | " + " | ".join(sources) + " |"]
    lines += ["|---|" + "---|" * (len(names) + len(sources))]
    for row in rows:
        cells = [f"{row['weights'][n]:+.2f}" for n in names]
        cells += [f"{row[s]['true_reward']:.3f} / {row[s]['success']:.2f}" for s in sources]
        lines.append(f"| {row['human']} | " + " | ".join(cells) + " |")
    return lines


def _interval(d: dict[str, float | None]) -> str:
    """A paired difference with its interval (none from a single run)."""
    if d["low"] is None:
        return f"{d['mean']:+.3f} (one run: no interval)"
    return f"{d['mean']:+.3f} ({d['low']:+.3f} to {d['high']:+.3f})"


def write_report(env: str, data, model, out: Path, space, cfg, runs, rewards, command: str | None) -> dict[str, Any]:
    """Summarise, draw and write rl.json, rl.png and rl.md into `out`; the summary."""
    from langpref.experiments.common import base_command, summary_head

    summary = {
        **summary_head(env, data, model, space, cfg),
        **summarise(runs, rewards, cfg),
        "per_human": per_human(runs, cfg, space.feature_names, _weights(space, cfg)),
        "config": {**asdict(cfg), "hidden": list(cfg.hidden), "sources": list(cfg.sources)},
        "command": command or base_command("rl", env, data, model, out),
        "date": datetime.date.today().isoformat(),
    }
    summary["figure"] = str(plot_rl(summary, out / "rl.png", f"Policies on the learned reward, {env}"))
    (out / "rl.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "rl.md").write_text(markdown(summary))
    return summary


def _weights(space, cfg) -> list[np.ndarray]:
    """The synthetic humans' weights, as `experiments.rl.judges` draws them."""
    from langpref.reward import human_weights

    return [human_weights(len(space.feature_names), cfg.seed, h) for h in range(cfg.humans)]
