"""`langpref experiment observations --env ENV`: what the trajectory encoder gains from the camera.

The same dataset with frames (default data/ENV-images, made by `generate --images` when missing) trains one model
per observation kind (state, images, images+state; `langpref.model.inputs`) with the default `langpref train`
configuration otherwise, and each is evaluated on the test split's trajectories with the bank's test phrasings and,
when given, with a held-out utterance file. Each training runs in a fresh process, so its peak memory (resident set
size, and on CUDA the most memory torch held) is its own; training time is the training loop's, without loading.

Finished kinds are kept in `runs.json` under the output folder: an interrupted run goes on with the kinds that are
left. The table goes to observations.md, everything to observations.json, and a figure of each model's latent space
(`langpref visualize`, test split) to latent-KIND.png.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.model.config import OBSERVATIONS, TrainConfig, check_observations

RESULTS_ROOT = Path("results") / "observations"


def default_data(env: str) -> str:
    """The dataset with frames used when none is given (generated with --images when missing)."""
    return str(Path("data") / f"{env}-images")


@dataclass(frozen=True)
class ObservationsConfig:
    """`langpref experiment observations`: state vs images vs images+state on one dataset with frames."""

    env: str
    """Task of the dataset (metaworld, robosuite, or a recorded task whose dataset has frames)."""
    data: str | None = None
    """A dataset with frames; default data/ENV-images, generated with --images (default frame options) if missing."""
    out: str | None = None
    """Output folder (models, runs.json, observations.md/.json); default results/observations/ENV."""
    kinds: tuple[str, ...] = OBSERVATIONS
    """Observation kinds to compare (comma-separated)."""
    heldout: str | None = None
    """An utterance file written apart from the bank (e.g. heldout/utterances.json): its accuracy is reported
    beside the bank's test phrasings'."""
    seed: int = 0
    """Training seed of every model."""
    device: str = "auto"
    """auto (cuda when available), cpu or cuda."""
    force: bool = False
    """Start over: retrain every kind, overwrite the models in `out`."""

    def resolved(self) -> ObservationsConfig:
        """Defaults filled in and checked, before any work."""
        for kind in self.kinds:
            check_observations(kind)
        if not self.kinds:
            raise LangprefError("--kinds needs at least one of " + ", ".join(OBSERVATIONS))
        return replace(self, data=self.data or default_data(self.env), out=self.out or str(RESULTS_ROOT / self.env))


def _train_one(train_cfg: dict[str, Any]) -> dict[str, Any]:
    """In a fresh process: train one model; its results with the process's peak memory."""
    import resource

    import torch

    from langpref.model.train import train

    result = train(TrainConfig.from_dict(train_cfg), progress=False)
    peak_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    cuda = torch.cuda.max_memory_allocated() / 2**20 if torch.cuda.is_available() else None
    return {**result.results, "peak_rss_mib": peak_rss, "peak_cuda_mib": cuda}


def _train_in_child(train_cfg: dict[str, Any]) -> dict[str, Any]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_train_one, train_cfg).result()


def _ensure_data(cfg: ObservationsConfig) -> Path:
    """The dataset, generated with frames when the default one is missing; refused in one line without frames."""
    from langpref.dataset.storage import load_dataset

    data = Path(str(cfg.data))
    if not data.exists() and cfg.data == default_data(cfg.env):
        from langpref.dataset.frames import FrameOptions
        from langpref.dataset.generate import GenerateConfig, generate

        generate(GenerateConfig(env=cfg.env, out=data, frames=FrameOptions(images=True)))
    dataset = load_dataset(data, env=cfg.env)
    if dataset.frame_spec is None:
        raise LangprefError(
            f"dataset {data} has no camera frames: make one with `langpref generate --env {cfg.env} --images "
            f"--out {data}` (or `langpref import --images`)"
        )
    return data


def _evaluate(model_dir: Path, data: Path, env: str, heldout: str | None) -> dict[str, Any]:
    """Test accuracy (bank test phrasings, and the held-out file's when given) and a figure of the latent space."""
    from langpref.dataset.storage import load_dataset
    from langpref.language.bank import load_bank, load_user_utterances
    from langpref.language.pairs import phrasings_from_bank, phrasings_from_mapping
    from langpref.model.checkpoint import load_model
    from langpref.model.evaluate import evaluate_split
    from langpref.model.visualize import visualize

    dataset = load_dataset(data, env=env)
    model = load_model(model_dir, dataset=dataset)
    test = evaluate_split(model, dataset, "test", phrasings_from_bank(load_bank(env), "test", dataset.feature_names))
    figure = model_dir.parent / f"latent-{model_dir.name}.png"
    out = {"test": test, "figure": visualize(model, dataset, figure, split="test")["out"]}
    if heldout:
        mapping = load_user_utterances(heldout, env)
        phr = phrasings_from_mapping(mapping, dataset.feature_names, require_all=False, source=heldout)
        out["heldout"] = evaluate_split(model, dataset, "test", phr)
    return out


def run_observations_experiment(cfg: ObservationsConfig, *, train_config: TrainConfig | None = None) -> dict[str, Any]:
    """Train and evaluate one model per observation kind; write observations.{json,md} into `cfg.out`.

    `train_config` is the `TrainConfig` every model starts from (data, out, seed, device and the observation kind
    are set here); the default is the default `langpref train` configuration.
    """
    from langpref.experiments.common import RunCache

    cfg = cfg.resolved()
    data, out = _ensure_data(cfg), Path(str(cfg.out))
    start = train_config or TrainConfig()
    identity = {k: v for k, v in asdict(cfg).items() if k not in ("out", "force")}
    cache = RunCache(out / "runs.json", {**identity, "train": start.to_dict() | {"data": "", "out": ""}}, cfg.force)
    for kind in cfg.kinds:
        if kind in cache:
            continue
        model_dir = out / kind.replace("+", "-")
        base = replace(start, data=str(data), out=str(model_dir), seed=cfg.seed, device=cfg.device, force=True)
        train_cfg = replace(base, model=replace(base.model, observations=kind)).to_dict()
        t0 = time.perf_counter()
        trained = _train_in_child(train_cfg)
        run = {"model": str(model_dir), "train": trained, "wall_s": time.perf_counter() - t0}
        cache.put(kind, {**run, **_evaluate(model_dir, data, cfg.env, cfg.heldout)})
    summary = {
        "env": cfg.env,
        "data": str(data),
        "runs": {kind: cache.runs[kind] for kind in cfg.kinds},
        "command": observations_command(cfg, start, _threads_used(cache.runs[kind] for kind in cfg.kinds)),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "observations.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "observations.md").write_text(observations_table(summary) + "\n")
    return summary


def _threads_used(runs) -> int | None:
    """The thread count every CPU run trained on, or None (a GPU run, an older run that did not say, or counts that
    differ)."""
    counts = {r["train"].get("torch_threads") if r["train"].get("device") == "cpu" else None for r in runs}
    return counts.pop() if len(counts) == 1 else None


def observations_command(cfg: ObservationsConfig, train: TrainConfig | None = None, threads: int | None = None) -> str:
    """The `langpref experiment observations` command that reproduces this run: on CPU with `--threads`, the
    threads its models trained on (`threads`, else the config's), as an image model is bit-reproducible only on
    as many threads (`TrainConfig.threads`)."""
    threads = threads or (train.threads if train is not None else None)
    flags = f" --data {cfg.data} --out {cfg.out}"
    default = TrainConfig()
    if train is not None and train.stage1_epochs != default.stage1_epochs:
        flags += f" --epochs {train.stage1_epochs}"
    if train is not None and train.stage2_epochs != default.stage2_epochs:
        flags += f" --finetune-epochs {train.stage2_epochs}"
    if train is not None and train.frame_contrastive is not None:
        flags += f" --frame-contrastive {train.frame_contrastive:g}"
    if train is not None and train.frame_pretrain_steps is not None:
        flags += f" --frame-pretrain-steps {train.frame_pretrain_steps}"
    if train is not None and train.augment_phrasings is not None:
        flags += f" --augment-phrasings {train.augment_phrasings}"
    if threads:
        flags += f" --threads {threads}"
    if tuple(cfg.kinds) != OBSERVATIONS:
        flags += f" --kinds {','.join(cfg.kinds)}"
    if cfg.heldout:
        flags += f" --heldout {cfg.heldout}"
    if cfg.seed:
        flags += f" --seed {cfg.seed}"
    return f"langpref experiment observations --env {cfg.env}{flags}"


def observations_table(summary: dict[str, Any]) -> str:
    """Markdown: one row per observation kind (accuracy, per feature, training time, peak memory)."""
    runs = summary["runs"]
    heldout = all("heldout" in r for r in runs.values())
    features = list(next(iter(runs.values()))["test"]["per_feature"]) if runs else []
    head = ["observations", "test accuracy", *(["held-out accuracy"] if heldout else []), *features]
    head += ["training (min)", "peak memory (MiB)", "device"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for kind, r in runs.items():
        train = r["train"]
        memory = train["peak_cuda_mib"] if train.get("peak_cuda_mib") else train["peak_rss_mib"]
        cells = [kind, f"{r['test']['accuracy']:.3f}"]
        cells += [f"{r['heldout']['accuracy']:.3f}"] if heldout else []
        cells += [f"{r['test']['per_feature'][f]:.3f}" for f in features]
        cells += [f"{train['train_s'] / 60:.1f}", f"{memory:.0f}", train["device"]]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "Per-feature columns: test accuracy with the bank's test phrasings. Training: the training loop's time. "
        "Peak memory: the most GPU memory torch held on CUDA, else the training process's peak resident size.",
        "",
        f"`{summary['command']}`",
    ]
    return "\n".join(lines)
