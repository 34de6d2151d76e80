"""`langpref train`: learn the shared latent space in the paper's two stages (Sec. 4.1, Appendix C).

Stage 1 freezes the language model: its pooled sentence embeddings are computed once, and only the trajectory
encoder (Adam, lr 1e-3, as the authors) and the language head (lr 1e-4: on frozen embeddings a faster head soon fits
the train phrasings' quirks) learn. Stage 2 co-finetunes the transformer too (lr 1e-4, the token embedding table
kept frozen); `freeze_language` stops after stage 1. Every epoch ends with the validation accuracy (val trajectories
x the bank's val phrasings); each stage keeps its best epoch and stops early after `patience` epochs without a better
one.

Cost on a CPU. A step computes phi once per distinct trajectory of its batch, over `time_samples` stratified random
time steps of each (50 of 500: the mean of the per-step embeddings is estimated without bias at a tenth of the cost;
validation and every later use take all steps), and, in stage 2, psi once per distinct utterance. The transformer
dominates, so stage 2 draws a few phrasings per (feature, direction) group for each step (`stage2_phrasings_per_step`)
and lets each pair pick among its group's; a pair's phrasing stays uniform over its group. Pairs themselves cost
almost nothing, which is why stage 2 takes large batches of them.

A model that sees camera frames (`ModelConfig.observations`, default images+state when the dataset has frames)
trains the same way; its frame CNN runs on the frames of the sampled steps only (`image_time_samples` of them per
trajectory, as its cost dominates), and the frames of the train and val splits are held on the device as uint8.
As the CNN's cost grows with the distinct trajectories of a step, each step takes its pairs from a random subset of
the train trajectories, just large enough to hold twice the batch on average (`image_step_trajectories`): every pair
is still equally likely in every step, and a step costs a fraction of one over all trajectories. Before stage 1,
and beside the language loss in both stages, the CNN also learns to tell episodes apart from their frames
(`frame_contrastive`, `frame_pretrain_steps`): a few hundred episodes' comparisons alone do not teach it where an
object stands.

With `windows` (`langpref.model.windows`), each epoch also draws random windows of the train episodes, trajectories
whose features are the time mean of the window's per-step features, and the epoch's pairs are built among episodes
and windows; validation and every later use see whole episodes.
"""

from __future__ import annotations

import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from langpref.errors import LangprefError
from langpref.extras import missing_modules
from langpref.language.pairs import Phrasings
from langpref.model.checkpoint import save_model
from langpref.model.config import TrainConfig
from langpref.model.latent import LatentModel
from langpref.model.trainer import Trainer, resolve_device
from langpref.model.trainset import load_phrasings
from langpref.tasks.taskfile import stored_task_files


@dataclass
class TrainResult:
    model: LatentModel
    out: Path
    history: list[dict[str, Any]]
    results: dict[str, Any]
    stage1_out: Path | None = None
    extras: dict[str, Any] = field(default_factory=dict)


def _save(trainer: Trainer, out: Path, lang_finetuned: bool, results: dict, force: bool) -> Path:
    model, cfg = trainer.model, trainer.cfg
    model.set_prototypes(trainer.bank_train_phr)
    history = [h for h in trainer.history if lang_finetuned or h["stage"] == 1]
    with tempfile.TemporaryDirectory() as tmp:
        curve = {}  # without the plots extra the curve is only the history in config.json
        if not missing_modules("plots"):
            title = f"{model.info.env}: {'co-finetuned' if lang_finetuned else 'frozen language model'}"
            from langpref.model.visualize import plot_history

            curve["training_curve.png"] = plot_history(history, Path(tmp) / "training_curve.png", title=title)
        return save_model(
            model,
            out,
            model_cfg=cfg.model,
            lang_finetuned=lang_finetuned,
            train_config=cfg.to_dict(),
            history=history,
            results=results,
            force=force,
            extra_files={**curve, **stored_task_files(trainer.dataset.root)},
        )


@contextmanager
def _deterministic_on_cpu(device: str, threads: int | None):
    """Multi-threaded CPU kernels may sum in a different order from run to run (differences of 1e-7 in the first
    epoch's loss, a different model after ten); torch's deterministic algorithms make two runs with the same seed
    bit-identical on the same number of threads (`threads`, else torch's own count; the sums of a convolution's and a
    matrix product's gradients are split among them). CUDA keeps its fast kernels (documented there as not
    bit-reproducible)."""
    previous, before = torch.are_deterministic_algorithms_enabled(), torch.get_num_threads()
    torch.use_deterministic_algorithms(previous or resolve_device(device).type == "cpu", warn_only=True)
    if threads:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(previous)
        torch.set_num_threads(before)


def numerics() -> dict[str, Any]:
    """What else a CPU run's numbers depend on, beside the seed and `torch_threads` (provenance in the results): the
    torch build and the instruction set its kernels chose for this CPU (AVX2 and AVX-512 kernels round otherwise)."""
    return {"torch": torch.__version__, "cpu_capability": torch.backends.cpu.get_cpu_capability()}


def train(
    cfg: TrainConfig,
    *,
    train_phrasings: Phrasings | None = None,
    val_phrasings: Phrasings | None = None,
    progress: bool = True,
    stage1_out: str | Path | None = None,
) -> TrainResult:
    """Train and save a latent-space model into `cfg.out`.

    `stage1_out`, when given, also saves the stage-1 (frozen language model) checkpoint there: the frozen ablation
    and the co-finetuned model share stage 1, so one run yields both. Phrasings default to the bank's (train, val).
    On CPU the same seed gives the same model bit for bit, in one process or two, on the same number of threads
    (`cfg.threads`, recorded in the results as `torch_threads`) and the same kind of CPU.
    """
    cfg.validate()
    with _deterministic_on_cpu(cfg.device, cfg.threads):
        return _train(cfg, train_phrasings, val_phrasings, progress, stage1_out)


def _train(
    cfg: TrainConfig,
    train_phrasings: Phrasings | None,
    val_phrasings: Phrasings | None,
    progress: bool,
    stage1_out: str | Path | None,
) -> TrainResult:
    if stage1_out is not None and Path(stage1_out).exists() and not cfg.force:
        raise LangprefError(f"{stage1_out} already exists; pass --force to overwrite it")
    t_start = time.perf_counter()
    trainer = Trainer(cfg, train_phrasings, val_phrasings, progress=progress)
    setup_s = time.perf_counter() - t_start
    trainer.pretrain_frames()
    acc1 = trainer.stage1()

    def results(stage: int, best: float) -> dict[str, Any]:
        s = sum(trainer.seconds[k] for k in range(1, stage + 1))
        n = sum(trainer.samples_seen[k] for k in range(1, stage + 1))
        return {
            "best_val_accuracy": best,
            "stages": stage,
            "train_pairs": len(trainer.train.pairs),  # with windows: of the last epoch
            "train_windows": trainer.cfg.windows * len(trainer.train.features),  # per epoch
            "train_phrasings": len(trainer.train_phr.texts),
            "val_phrasings": len(trainer.val_phr.texts),
            "setup_s": setup_s,
            "train_s": s + trainer.seconds[0],  # with the frames-alone pretraining, if any
            "samples": n,
            "samples_per_s": n / s if s else 0.0,
            "device": str(trainer.device),
            "torch_threads": torch.get_num_threads(),
            "numerics": numerics(),
            "stage_seconds": {str(k): v for k, v in trainer.seconds.items() if k <= stage and (k or v)},
            "stage_samples_per_s": {
                str(k): trainer.samples_seen[k] / trainer.seconds[k] for k in range(1, stage + 1) if trainer.seconds[k]
            },
        }

    s1 = None
    if stage1_out is not None:
        s1 = _save(trainer, Path(stage1_out), False, results(1, acc1), cfg.force)
    if cfg.freeze_language or cfg.stage2_epochs == 0:
        res = results(1, acc1)
        out = _save(trainer, Path(cfg.out), False, res, cfg.force)
    else:
        acc2 = trainer.stage2(acc1)
        res = results(2, acc2)
        res["stage1_val_accuracy"] = acc1
        out = _save(trainer, Path(cfg.out), True, res, cfg.force)
    res["wall_s"] = time.perf_counter() - t_start
    return TrainResult(trainer.model, out, trainer.history, res, s1)


__all__ = ["TrainResult", "Trainer", "load_phrasings", "resolve_device", "train"]
