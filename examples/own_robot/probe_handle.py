"""Where does the drawer stand? Diagnostics for the recording made with `record.py --hide-handle` (issue 19).

The drawer's x (Meta-World's only random reset variable) is in the camera only. This script replays each episode's
drawn plan to recover it, then

1. probes how well the frame CNN of an images+state model tells it: a ridge regression from the episode mean of the
   CNN's features to the handle's x, fitted on the train episodes, R^2 on the val episodes; first with the CNN as
   initialised, then after `--pretrain-steps` steps of langpref's episode-contrastive pretraining
   (`langpref train --frame-pretrain-steps`);
2. with `--oracle-out DIR`, writes a copy of the dataset (without frames) whose observations carry the handle's x as
   a ninth number: a state model trained on it shows what the features and phrasings allow once the drawer's place
   is known.

    .venv/bin/python examples/own_robot/probe_handle.py data/own_robot_hidden --oracle-out data/own_robot_oracle
    langpref train --data data/own_robot_oracle --out models/own_robot_oracle --observations state
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
from record import draw_plan  # beside this script


def handle_x(data: Path, recording_seed: int) -> np.ndarray:
    """The handle's x of every trajectory of an imported dataset, from the plan its source episode drew."""
    xs = []
    for path in sorted((data / "trajectories").glob("*.npz")):
        with np.load(path) as traj:
            index = int(str(traj["source"]).rsplit("_", 1)[-1])  # "episode_0042" -> 42
        xs.append(draw_plan(np.random.default_rng([recording_seed, index])).handle_x)
    return np.array(xs)


def probe_r2(trainer, target: np.ndarray) -> float:
    """R^2 on the val episodes of a ridge fit (on the train episodes) of `target` from the episode-mean CNN features."""
    import torch

    def episode_features(split) -> np.ndarray:
        encoder, stride = trainer.model.traj.frames, trainer.model.info.frames["stride"]
        lengths = np.full(len(split.frames), split.steps.shape[1]) if split.lengths is None else split.lengths
        encoder.eval()
        with torch.no_grad():
            out = [encoder(split.frames[i, : -(-int(n) // stride)]).mean(dim=0).numpy() for i, n in enumerate(lengths)]
        encoder.train()
        return np.array(out)

    x_train, x_val = episode_features(trainer.train), episode_features(trainer.val)
    y_train = target[trainer.dataset.split("train")]
    y_val = target[trainer.dataset.split("val")]
    mu, sd = x_train.mean(axis=0), x_train.std(axis=0) + 1e-6

    def design(x: np.ndarray) -> np.ndarray:
        return np.hstack([(x - mu) / sd, np.ones((len(x), 1))])

    a = design(x_train)
    w = np.linalg.solve(a.T @ a + np.eye(a.shape[1]), a.T @ y_train)
    return float(1.0 - np.mean((design(x_val) @ w - y_val) ** 2) / np.var(y_val))


def write_oracle(data: Path, out: Path, xs: np.ndarray) -> None:
    """A copy of dataset `data` without frames whose observations end with the handle's x."""
    if out.exists():
        raise SystemExit(f"{out} exists; remove it or choose another --oracle-out")
    (out / "trajectories").mkdir(parents=True)
    for name in ("features.npy", "task.json", "utterances.json"):
        if (data / name).exists():
            shutil.copy(data / name, out / name)
    meta = json.loads((data / "meta.json").read_text())
    meta["obs_layout"].append({"name": "handle_x", "start": 8, "stop": 9})
    for key in ("frames", "videos"):
        meta.pop(key, None)
    (out / "meta.json").write_text(json.dumps(meta, indent=2))
    for x, path in zip(xs, sorted((data / "trajectories").glob("*.npz"))):
        traj = dict(np.load(path))
        obs = traj["observations"]
        traj["observations"] = np.hstack([obs, np.full((len(obs), 1), x, dtype=obs.dtype)])
        np.savez_compressed(out / "trajectories" / path.name, **traj)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=Path, help="a dataset imported with --images from a --hide-handle recording")
    parser.add_argument("--recording-seed", type=int, default=0, help="the --seed the recording was made with")
    parser.add_argument("--pretrain-steps", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=0, help="training seed of the CNN")
    parser.add_argument("--oracle-out", type=Path, help="also write the dataset with the handle's x observed here")
    args = parser.parse_args(argv)

    from langpref.model.config import ModelConfig, TrainConfig
    from langpref.model.train import Trainer

    xs = handle_x(args.data, args.recording_seed)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = TrainConfig(
            data=str(args.data),
            out=str(Path(tmp) / "unused"),
            model=ModelConfig(observations="images+state"),
            frame_pretrain_steps=args.pretrain_steps,
            seed=args.seed,
            device="cpu",
        )
        trainer = Trainer(cfg)
        before = probe_r2(trainer, xs)
        trainer.pretrain_frames()
        after = probe_r2(trainer, xs)
    print(
        f"handle x from the episode-mean CNN features, R^2 on the val episodes: {before:.3f} as initialised, "
        f"{after:.3f} after {args.pretrain_steps} steps of episode-contrastive pretraining"
    )
    if args.oracle_out:
        write_oracle(args.data, args.oracle_out, xs)
        print(f"wrote {args.oracle_out}: observations with the handle's x")


if __name__ == "__main__":
    main()
