"""What the experiments share: where they read and write by default, their base command line, the
finished-run cache that makes them resume, and the sweep that runs their jobs locally or on Ray.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from langpref.backends import Backend
from langpref.errors import LangprefError
from langpref.experiments.alignment import default_model


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
        self.key = hashlib.sha256(json.dumps(_unset_dropped(config), sort_keys=True, default=str).encode()).hexdigest()[
            :16
        ]
        self.runs: dict[str, Any] = {}
        if self.path.is_file() and not force:
            try:
                saved = json.loads(self.path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError):
                raise LangprefError(f"{self.path} is corrupt; delete it or pass --force to start over") from None
            if saved.get("config_key") != self.key:
                raise LangprefError(
                    f"{self.path} holds runs made with another configuration; pass --force to start "
                    "over or choose another --out"
                )
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

    backend: Backend = "local"
    """local worker processes or Ray tasks."""
    workers: int = 1
    """Parallel workers (local processes, or CPUs of a local Ray instance)."""
    ray_address: str | None = None
    """A running Ray cluster to join; default a local instance."""


def worker_space(
    data: Path,
    model: Path | None,
    env: str,
    perfect: bool,
    phrasings: str | None = None,
    feature_scale: str = "standardised",
):
    from langpref.feedback.space import load_space

    return load_space(data, model, env=env, perfect=perfect, phrasings=phrasings, feature_scale=feature_scale)


def run_sweep(
    job_fn,
    todo: list,
    space,
    space_args: tuple,
    cache: RunCache,
    sweep: SweepConfig,
    desc: str,
    progress: bool,
    setup=worker_space,
) -> None:
    """Run every job of `todo` and store each result in `cache` as it finishes (a rerun skips what is there).

    In-process runs use `space` as it is; worker processes and Ray tasks rebuild it with `setup(*space_args)` (by
    default `worker_space`: data, model, env, perfect), so on a cluster every node needs the dataset and the model at
    the same paths.
    """
    from tqdm import tqdm

    from langpref.backends import run_jobs

    if sweep.backend == "local" and sweep.workers <= 1:
        results = (job_fn(space, job) for job in todo)
    else:
        results = run_jobs(
            job_fn,
            todo,
            setup=setup,
            setup_args=space_args,
            backend=sweep.backend,
            workers=sweep.workers,
            ray_address=sweep.ray_address,
        )
    for key, value in tqdm(results, total=len(todo), desc=desc, disable=not progress, file=sys.stderr):
        cache.put(key, value)


def default_paths(
    kind: str,
    env: str,
    data: str | Path | None,
    model: str | Path | None,
    out: str | Path | None,
    perfect: bool,
    variant: str = "",
) -> tuple[Path, Path | None, Path]:
    """data/ENV, the co-finetuned model of `langpref experiment alignment` (results/alignment/ENV/cofinetuned) and
    results/KIND/ENV (ENV-perfect for the oracle space, then -VARIANT if given, e.g. ENV-mlp) unless given."""
    data = Path(data) if data else Path("data") / env
    model = None if perfect else (Path(model) if model else default_model(env))
    name = env + ("-perfect" if perfect else "") + (f"-{variant}" if variant else "")
    out = Path(out) if out else Path("results") / kind / name
    return data, model, out


@dataclass(frozen=True)
class Inputs:
    """What an experiment of the latent space's uses runs on: the arguments of the shared run signature
    (`langpref.experiments.registry`), written once here (`space_experiment`)."""

    env: str
    data: str | Path | None = None
    model: str | Path | None = None
    out: str | Path | None = None
    perfect: bool = False
    config: Any = None
    """The record's config dataclass; None: the experiment's settings."""
    force: bool = False
    progress: bool = True
    sweep: SweepConfig | None = None
    command: str | None = None
    """The command line recorded in the summary; None, from Python: the experiment's base command."""

    def paths(self, kind: str, variant: str = "") -> tuple[Path, Path | None, Path]:
        """Its data, model and output folder, the defaults where not given (`default_paths`)."""
        return default_paths(kind, self.env, self.data, self.model, self.out, self.perfect, variant)


def space_experiment(body: Callable[..., dict[str, Any]]) -> Callable[..., dict[str, Any]]:
    """The run function of an experiment of the latent space's uses: the shared signature, calling
    `body(Inputs(...), **options)` (options: an experiment's own keywords, e.g. the prior's `grid`)."""

    def run(
        env: str,
        data: str | Path | None = None,
        model: str | Path | None = None,
        out: str | Path | None = None,
        *,
        perfect: bool = False,
        config: Any = None,
        force: bool = False,
        progress: bool = True,
        sweep: SweepConfig | None = None,
        command: str | None = None,
        **options: Any,
    ) -> dict[str, Any]:
        return body(Inputs(env, data, model, out, perfect, config, force, progress, sweep, command), **options)

    for name in ("__name__", "__qualname__", "__doc__", "__module__"):
        setattr(run, name, getattr(body, name))
    return run


def summary_head(env: str, data: Path, model: Path | None, space: Any, cfg: Any) -> dict[str, Any]:
    """What the summary of a reward experiment starts with: its inputs, its space and its humans x seeds x queries."""
    return {
        "env": env,
        "data": str(data),
        "model": str(model) if model else None,
        "perfect": model is None,
        "space": space.description,
        "humans": cfg.humans,
        "seeds": cfg.seeds,
        "queries": cfg.queries,
    }


def improve_head(run: Inputs, space: Any, cfg: Any) -> dict[str, Any]:
    """What the summary of an improvement experiment starts with: its inputs (`run`, paths resolved), its space and
    its seeds x iterations."""
    return {
        "env": run.env,
        "data": str(run.data),
        "model": str(run.model) if run.model else None,
        "perfect": run.perfect,
        "space": space.description,
        "seeds": cfg.seeds,
        "iterations": cfg.iterations,
    }


def base_command(kind: str, env: str, data: Path, model: Path | None, out: Path) -> str:
    """The base command of an experiment run from Python (its options are in the summary's configs); a run of
    `langpref experiment` records its own command line instead."""
    where = "--perfect-latent" if model is None else f"--model {model}"
    return f"langpref experiment {kind} --env {env} --data {data} {where} --out {out}"


def phrasing_variant(human) -> list[str]:
    """The part of an experiment's default output name that says where its human's phrasings come from (none for
    the bank's test split, the default): `phrasings` for an utterance file, `bank-SPLIT` for another bank split; then
    the humans' feature scale and direction rule when not the defaults (`HumanConfig.variant`)."""
    scale = human.variant()
    if human.phrasings:
        return ["phrasings", *scale]
    return ([] if human.phrasing_split == "test" else [f"bank-{human.phrasing_split}"]) + scale


def title_suffix(perfect: bool, human) -> str:
    """What sets an experiment's figure apart from the default one, for its title: the oracle space, and where the
    human's phrasings come from."""
    parts = ["perfect latent"] if perfect else []
    if human.phrasings:
        parts.append(f"phrasings: {human.phrasings}")
    elif human.phrasing_split != "test":
        parts.append(
            "all bank phrasings" if human.phrasing_split == "all" else f"bank {human.phrasing_split} phrasings"
        )
    if human.feature_scale != "standardised":
        parts.append(f"{human.feature_scale} feature scale")
    if human.direction != "reward":
        parts.append(f"direction {human.direction}")
    if human.feature_rule != "eq10":
        parts.append(f"feature rule {human.feature_rule}")
    if human.vague:
        parts.append(f"{human.vague:g} vague")
    if human.no_change_logit is not None:
        parts.append(f"says no change, logit {human.no_change_logit:g}")
    if human.no_change_margin is not None:
        parts.append(f"says no change within {human.no_change_margin:g} of its best")
    return f" ({', '.join(parts)})" if parts else ""


def figure_link(figure: str | Path) -> str:
    """A figure's path as seen from docs/results.md (relative paths are relative to the repository root)."""
    figure = Path(figure)
    return str(figure) if figure.is_absolute() else f"../{figure.as_posix()}"
