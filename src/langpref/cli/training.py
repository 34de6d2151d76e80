"""What `langpref train` says when it ends: where its training curve is and what it shows, whether validation was
still improving when the epochs ran out (and how many to try), and the optional TensorBoard scalars."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from langpref.errors import LangprefError

if TYPE_CHECKING:
    from langpref.model.config import TrainConfig


def train_text(s: dict) -> str:
    """`langpref train`'s text output: what it wrote, where its curve is and what it shows, and a warning for each
    stage whose validation accuracy was still rising when its epochs ran out."""
    lines = [
        f"wrote {s['out']}: validation accuracy {s['best_val_accuracy']:.3f} after {s['stages']} stage(s), "
        f"{s['epochs']} epochs, {s['wall_s']:.0f} s"
    ]
    if s["training_curve"]:
        lines.append(
            f"training curve {s['training_curve']}: train loss, and alignment accuracy on train and validation per "
            "epoch (stage 2 right of the dashed line); the model kept is each stage's best validation epoch"
        )
    for w in s["still_improving"]:
        lines.append(
            f"warning: stage {w['stage']}'s validation accuracy was still improving at its last epoch "
            f"(best at epoch {w['best_epoch']} of {w['epochs']}, +{w['rise']:.3f} over the last {w['window']}): "
            f"try {w['flag']} {w['suggest']}"
        )
    if s.get("tensorboard"):
        lines.append(f"TensorBoard: tensorboard --logdir {s['tensorboard']}")
    return "\n".join(lines)


STILL_RISING = 0.01
"""A stage counts as still improving when its validation accuracy rose by more than this over its last epochs."""


def still_improving(history: list[dict], cfg: TrainConfig) -> list[dict]:
    """The stages whose validation accuracy was still rising when their epochs ran out, by one documented rule: the
    stage ran all its epochs (early stopping did not end it), its best validation epoch is among its last 10% of
    epochs (at least the last two), and validation rose by more than `STILL_RISING` over its last three epochs (or
    all, if fewer). Each with the flag and the number of epochs to try (twice as many)."""
    flags = {1: ("--epochs", cfg.stage1_epochs), 2: ("--finetune-epochs", cfg.stage2_epochs)}
    out = []
    for stage, (flag, planned) in flags.items():
        val = [h["val_acc"] for h in history if h["stage"] == stage]
        if len(val) < 2 or len(val) < planned:
            continue
        best = max(range(len(val)), key=lambda i: (val[i], i)) + 1
        last = max(2, -(-len(val) // 10))
        window = min(3, len(val) - 1)
        rise = val[-1] - val[-1 - window]
        if best > len(val) - last and rise > STILL_RISING:
            out.append(
                {
                    "stage": stage,
                    "epochs": len(val),
                    "best_epoch": best,
                    "rise": rise,
                    "window": window,
                    "flag": flag,
                    "suggest": 2 * planned,
                }
            )
    return out


def tensorboard_writer(logdir: str | Path | None = None):
    """torch's TensorBoard SummaryWriter on `logdir` (none made without it: the import check alone); a one-line
    error when the tensorboard package is not installed."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        raise LangprefError("--tensorboard needs the tensorboard package: pip install tensorboard") from None
    return None if logdir is None else SummaryWriter(log_dir=str(logdir))


def write_tensorboard(history: list[dict], logdir: str | Path) -> Path:
    """Each epoch of `history` (both stages, one step per epoch) as TensorBoard scalars in `logdir`, written when
    training ends: loss, L_align, train and validation accuracy, seconds."""
    writer = tensorboard_writer(logdir)
    for step, h in enumerate(history, start=1):
        for key in ("loss", "align", "train_acc", "val_acc", "seconds"):
            if key in h:
                writer.add_scalar(f"train/{key}", float(h[key]), step)
        writer.add_scalar("train/stage", float(h["stage"]), step)
    writer.close()
    return Path(logdir)
