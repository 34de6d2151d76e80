"""`langpref experiment improve --env ENV`: the paper's Fig. 4 (iterative improvement, N = 15, 100 seeds): Eq. 4 as
the paper's text describes it (`paper`) and as it prints it (`paper-printed`), and the history strategy beside them.

Writes into the output directory (default `results/improve/ENV`): `improve.json` (the curves and the config),
`improve.png` (mean +- std per iteration, dashed optimum), `improve.md` (a section for docs/results.md) and
`runs.json`, the finished runs. Interrupted, it resumes: a finished seed is not rerun. `RunCache` is shared with the
reward-learning experiments.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.experiments.alignment import default_model

PAPER_FIG4 = ("Fig. 4 (no numbers printed): in both envs the true reward rises consistently over 15 iterations but "
              "stays below the dashed average optimum, because each step uses only the last feedback and can loop "
              "between good, non-optimal trajectories.")


CURVES: dict[str, dict[str, str]] = {
    "paper": {"strategy": "paper", "objective": "cosine"},
    "paper-printed": {"strategy": "paper", "objective": "printed"},
    "history": {"strategy": "history"},
}
"""The curves of the experiment: name -> the `ImproveConfig` fields that make it."""
CURVE_LABELS = {"paper": "Eq. 4, cosine of the difference", "paper-printed": "Eq. 4 as printed",
                "history": "feedback history"}


def _unset_dropped(value: Any) -> Any:
    """`value` without the dict entries that are None, so an option added later (unset by default) keeps the caches
    made before it valid."""
    if isinstance(value, dict):
        return {k: _unset_dropped(v) for k, v in value.items() if v is not None}
    return value


class RunCache:
    """Finished runs of an experiment, keyed by name, saved atomically after each; tied to one configuration."""

    def __init__(self, path: Path, config: dict[str, Any], force: bool = False):
        self.path = Path(path)
        self.key = hashlib.sha256(json.dumps(_unset_dropped(config), sort_keys=True, default=str).encode()
                                  ).hexdigest()[:16]
        self.runs: dict[str, Any] = {}
        if self.path.is_file() and not force:
            try:
                saved = json.loads(self.path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError):
                raise LangprefError(f"{self.path} is corrupt; delete it or pass --force to start over") from None
            if saved.get("config_key") != self.key:
                raise LangprefError(f"{self.path} holds runs made with another configuration; pass --force to start "
                                    "over or choose another --out")
            self.runs = saved.get("runs", {})

    def __contains__(self, name: str) -> bool:
        return name in self.runs

    def put(self, name: str, value: Any) -> None:
        self.runs[name] = value
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        tmp.write_text(json.dumps({"config_key": self.key, "runs": self.runs}))
        tmp.replace(self.path)


@dataclass(frozen=True)
class SweepConfig:
    """Where the runs of an experiment execute (each run is one task: a seed, or a human x seed x method)."""

    backend: str = "local"
    """local worker processes or Ray tasks."""
    workers: int = 1
    """Parallel workers (local processes, or CPUs of a local Ray instance)."""
    ray_address: str | None = None
    """A running Ray cluster to join; default a local instance."""


def worker_space(data: Path, model: Path | None, env: str, perfect: bool, phrasings: str | None = None):
    from langpref.feedback.space import load_space

    return load_space(data, model, env=env, perfect=perfect, phrasings=phrasings)


def run_sweep(job_fn, todo: list, space, space_args: tuple, cache: RunCache, sweep: SweepConfig, desc: str,
              progress: bool) -> None:
    """Run every job of `todo` and store each result in `cache` as it finishes (a rerun skips what is there).

    In-process runs use `space` as it is; worker processes and Ray tasks rebuild it from `space_args` (data, model,
    env, perfect), so on a cluster every node needs the dataset and the model at the same paths.
    """
    from tqdm import tqdm

    from langpref.backends import run_jobs

    if sweep.backend == "local" and sweep.workers <= 1:
        results = (job_fn(space, job) for job in todo)
    else:
        results = run_jobs(job_fn, todo, setup=worker_space, setup_args=space_args, backend=sweep.backend,
                           workers=sweep.workers, ray_address=sweep.ray_address)
    for key, value in tqdm(results, total=len(todo), desc=desc, disable=not progress, file=sys.stderr):
        cache.put(key, value)


def _improvement_job(space, job) -> tuple[str, dict]:
    from langpref.improve import human_weights, run_improvement

    key, cfg, s = job
    w = human_weights(len(space.feature_names), cfg.seed, s)
    return key, asdict(run_improvement(space, w, cfg, (cfg.seed, s)))


def default_paths(kind: str, env: str, data: str | Path | None, model: str | Path | None, out: str | Path | None,
                  perfect: bool, variant: str = "") -> tuple[Path, Path | None, Path]:
    """data/ENV, the co-finetuned model of `langpref experiment alignment` (results/alignment/ENV/cofinetuned) and
    results/KIND/ENV (ENV-perfect for the oracle space, then -VARIANT if given, e.g. ENV-mlp) unless given."""
    data = Path(data) if data else Path("data") / env
    model = None if perfect else (Path(model) if model else default_model(env))
    name = env + ("-perfect" if perfect else "") + (f"-{variant}" if variant else "")
    out = Path(out) if out else Path("results") / kind / name
    return data, model, out


def command_line(kind: str, env: str, data: Path, model: Path | None, out: Path, extra: str = "") -> str:
    where = "--perfect-latent" if model is None else f"--model {model}"
    return f"langpref experiment {kind} --env {env} --data {data} {where} --out {out}{extra}"


def cli_flags(base, default, names: tuple[str, ...]) -> str:
    """The `langpref experiment` options that reproduce the config `base`: each of `names` where it differs from
    `default`, and where its language human's phrasings come from when that is not the default."""
    flags = "".join(f" --{k} {getattr(base, k)}" for k in names if getattr(base, k) != getattr(default, k))
    if base.human.phrasings:
        return flags + f" --phrasings {base.human.phrasings}"
    if base.human.phrasing_split != default.human.phrasing_split:
        return flags + f" --phrasing-split {base.human.phrasing_split}"
    return flags


def phrasing_variant(human) -> list[str]:
    """The part of an experiment's default output name that says where its human's phrasings come from (none for
    the bank's test split, the default): `phrasings` for an utterance file, `bank-SPLIT` for another bank split."""
    if human.phrasings:
        return ["phrasings"]
    return [] if human.phrasing_split == "test" else [f"bank-{human.phrasing_split}"]


def title_suffix(perfect: bool, human) -> str:
    """What sets an experiment's figure apart from the default one, for its title: the oracle space, and where the
    human's phrasings come from."""
    parts = ["perfect latent"] if perfect else []
    if human.phrasings:
        parts.append(f"phrasings: {human.phrasings}")
    elif human.phrasing_split != "test":
        parts.append("all bank phrasings" if human.phrasing_split == "all" else f"bank {human.phrasing_split} phrasings")
    return f" ({', '.join(parts)})" if parts else ""


def figure_link(figure: str | Path) -> str:
    """A figure's path as seen from docs/results.md (relative paths are relative to the repository root)."""
    figure = Path(figure)
    return str(figure) if figure.is_absolute() else f"../{figure.as_posix()}"


def _fmt(values: list[float], at: list[int]) -> str:
    return " | ".join(f"{values[i]:.3f}" for i in at)


def improve_markdown(summary: dict[str, Any]) -> str:
    env, strategies = summary["env"], summary["strategies"]
    n = len(next(iter(strategies.values()))["curve"]) - 1
    at = sorted({0, 1, n // 3, 2 * n // 3, n})
    lines = [
        f"### Iterative improvement, {env}" + (" (perfect latent space, oracle)" if summary["perfect"] else ""),
        "",
        f"`{summary['command']}` ({summary['date']}; {summary['space']}; {summary['seeds']} seeds, candidates: "
        f"{summary['candidate_split']} split). Mean normalised true reward (0 = worst, 1 = best candidate) of the "
        "trajectory shown at each iteration, std in the figure.",
        "",
        "| curve | " + " | ".join(f"it. {i}" for i in at) + " | gain 0 to N |",
        "|---|" + "---|" * (len(at) + 1),
    ]
    for name, res in strategies.items():
        lines.append(f"| {name} | {_fmt(res['curve'], at)} | {res['gain']:+.3f} |")
    lines += ["", f"![improvement {env}]({figure_link(summary['figure'])})", "", f"Paper: {PAPER_FIG4}"]
    return "\n".join(lines) + "\n"


def run_improve_experiment(env: str, data: str | Path | None = None, model: str | Path | None = None,
                           out: str | Path | None = None, *, perfect: bool = False, config=None,
                           force: bool = False,
                           progress: bool = True, sweep: SweepConfig | None = None) -> dict[str, Any]:
    """Every curve of `CURVES` with the paper's settings (or `config`, an `ImproveConfig`); writes JSON, PNG and
    markdown."""
    from langpref.feedback.space import load_space
    from langpref.improve import ImproveConfig, ImprovementRun, plot_improvement
    from langpref.improve import summarise as summarise_runs

    base = config or ImproveConfig()
    phrasings = base.human.phrasings
    data, model, out = default_paths("improve", env, data, model, out, perfect, "-".join(phrasing_variant(base.human)))
    space = load_space(data, model, env=env, perfect=perfect, phrasings=phrasings)
    cfgs = {name: replace(base, **fields) for name, fields in CURVES.items()}
    cache = RunCache(out / "runs.json", {"space": space.description, **{s: asdict(c) for s, c in cfgs.items()}},
                     force=force)
    for cfg in cfgs.values():
        cfg.validate()
    todo = [(f"{name}/{s}", cfg, s) for name, cfg in cfgs.items() for s in range(cfg.seeds)
            if f"{name}/{s}" not in cache]
    run_sweep(_improvement_job, todo, space, (data, model, env, perfect, phrasings), cache, sweep or SweepConfig(),
              f"improve {env}", progress)
    results = {name: {**summarise_runs([ImprovementRun(**cache.runs[f"{name}/{s}"]) for s in range(cfg.seeds)]),
                      "config": asdict(cfg)} for name, cfg in cfgs.items()}
    figure = plot_improvement({f"{n} ({CURVE_LABELS[n]})": r for n, r in results.items()}, out / "improve.png",
                              f"Iterative improvement, {env}" + title_suffix(perfect, base.human))
    summary = {
        "env": env, "data": str(data), "model": str(model) if model else None, "perfect": perfect,
        "space": space.description, "seeds": base.seeds, "iterations": base.iterations,
        "candidate_split": base.candidate_split, "strategies": results, "figure": str(figure),
        "paper": PAPER_FIG4, "command": command_line("improve", env, data, model, out,
                                                         cli_flags(base, ImproveConfig(), ("seeds", "iterations"))),
        "date": datetime.date.today().isoformat(),
    }
    (out / "improve.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "improve.md").write_text(improve_markdown(summary))
    return summary
