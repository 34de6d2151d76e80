"""`make lerobot-check`: LeRobot's own `LeRobotDataset` loads a copy that `langpref label` wrote.

Two halves, run in two venvs (lerobot 0.4.4 pins torch < 2.11; langpref pins 2.13.0, so they cannot share one):

    .venv/bin/python -m benchmarks.lerobot_check prepare build/lerobot-check
        (langpref's venv) a small random reward for the fixture's sizes (6 state numbers, 3 action numbers), and
        labelled copies of tests/fixtures/lerobot/tiny (a video camera) and tiny-images (image columns)
    .venv-lerobot/bin/python -m benchmarks.lerobot_check verify build/lerobot-check
        (lerobot's venv) each copy opened with `lerobot.datasets.lerobot_dataset.LeRobotDataset`: the label
        columns are features, every frame reads (video frames decoded with PyAV), each episode's reward shares sum
        to its episode reward, and the original columns equal the original dataset's as LeRobot reads it

The verify half imports only lerobot, numpy and the standard library (no langpref). It prints one JSON object and
exits non-zero if a check fails. The random reward exercises the format, not a learned behaviour: which reward
fills the columns does not change how LeRobot reads them.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "fixtures" / "lerobot"
DATASETS = ("tiny", "tiny-images")
COLUMNS = ("langpref.reward_share", "langpref.reward_progress", "langpref.episode_reward", "next.reward")


def write_random_reward(
    out: Path, obs_dim: int, action_dim: int, *, task: str = "lerobot-fixture", kind: str = "linear", seed: int = 0
) -> Path:
    """A saved reward (OUT/reward.json) with a random per-step encoder in OUT/model: the files `langpref.reward.load`
    reads (a checkpoint's config.json and encoders.safetensors holding only the trajectory encoder), for data of any
    size without training a model. `kind` "mlp" gives a reward whose per-step shares depend on the history."""
    from safetensors.numpy import save_file

    rng = np.random.default_rng(seed)
    dim, hidden, latent = 2 * obs_dim + action_dim, 16, 8  # observation deltas on: (s, s - s_prev, a)
    model = Path(out) / "model"
    model.mkdir(parents=True, exist_ok=True)
    weights = {
        "traj.mean": rng.normal(size=dim).astype(np.float32),
        "traj.std": (0.5 + rng.random(dim)).astype(np.float32),
        "traj.body.0.weight": (rng.normal(size=(hidden, dim)) * 0.3).astype(np.float32),
        "traj.body.0.bias": (rng.normal(size=hidden) * 0.1).astype(np.float32),
        "traj.out.weight": (rng.normal(size=(latent, hidden)) * 0.3).astype(np.float32),
        "traj.out.bias": (rng.normal(size=latent) * 0.1).astype(np.float32),
    }
    save_file(weights, str(model / "encoders.safetensors"))
    blob = (model / "encoders.safetensors").read_bytes()
    sha = hashlib.sha256(blob).hexdigest()
    config = {
        "format": "langpref-latent-model",
        "format_version": 1,
        "model": {"observations": "state", "observation_deltas": True},
        "data": {"env": task, "obs_dim": obs_dim, "action_dim": action_dim, "horizon": 20},
        "files": {"encoders.safetensors": {"bytes": len(blob), "sha256": sha}},
        "lang_model": "none",
    }
    (model / "config.json").write_text(json.dumps(config))
    if kind == "linear":
        params = {"xi": rng.normal(size=latent).tolist()}
    else:
        params = {"w1": rng.normal(size=(latent, 6)).tolist(), "b1": rng.normal(size=6).tolist()}
        params["w2"] = rng.normal(size=6).tolist()
    doc = {
        "format": "langpref-reward",
        "format_version": 1,
        "task": task,
        "kind": kind,
        "params": params,
        "model": {"path": str(model.resolve()), "sha256": sha},
        "obs_dim": obs_dim,
        "action_dim": action_dim,
    }
    (Path(out) / "reward.json").write_text(json.dumps(doc))
    return Path(out) / "reward.json"


def prepare(out: Path) -> dict:
    """(langpref's venv) The random reward and the labelled copies of the fixtures under `out`."""
    from langpref.dataset.label import LabelConfig, label_dataset
    from langpref.reward import load

    reward = write_random_reward(out / "reward", 6, 3)
    summaries = {}
    for name in DATASETS:
        cfg = LabelConfig(dataset=FIXTURES / name, reward=reward, out=out / name, force=True)
        summaries[name] = label_dataset(cfg, load(cfg.reward), progress=False)
    return summaries


def _verify_one(original: Path, labelled: Path) -> dict:
    """Open both with LeRobotDataset and compare them frame by frame; the checks' results."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    orig = LeRobotDataset("langpref/original", root=original, video_backend="pyav")
    lab = LeRobotDataset("langpref/labelled", root=labelled, video_backend="pyav")
    missing = [c for c in COLUMNS if c not in lab.features or c not in lab.meta.stats]
    same, sums, cameras = True, [], list(lab.meta.camera_keys)
    shares: dict[int, float] = {}
    totals: dict[int, float] = {}
    for i in range(len(lab)):
        a, b = orig[i], lab[i]
        for key, value in a.items():
            other = b[key]
            if hasattr(value, "numpy"):
                same &= bool(np.array_equal(value.numpy(), other.numpy()))
            else:
                same &= value == other
        ep = int(b["episode_index"])
        same &= float(b["next.reward"]) == float(b[COLUMNS[0]])  # LeRobot's reward name holds the reward share
        shares[ep] = shares.get(ep, 0.0) + float(b[COLUMNS[0]])
        totals[ep] = float(b[COLUMNS[2]])
    for ep, total in totals.items():
        sums.append(abs(shares[ep] - total) <= 1e-4 * max(1.0, abs(total)))
    return {
        "frames": len(lab),
        "episodes": lab.num_episodes,
        "cameras": cameras,
        "label_features_and_stats": not missing,
        "original_columns_equal": same,
        "shares_sum_to_episode_reward": all(sums) and bool(sums),
    }


def verify(out: Path) -> dict:
    """(lerobot's venv) Each labelled copy under `out` checked against its fixture."""
    import lerobot

    result = {"lerobot": lerobot.__version__ if hasattr(lerobot, "__version__") else "?"}
    try:
        import torch

        result["torch"] = torch.__version__
    except ImportError:
        pass
    for name in DATASETS:
        result[name] = _verify_one(FIXTURES / name, out / name)
    return result


def record(recording: Path, out: Path, fps: int = 20) -> dict:
    """(lerobot's venv) A plain recording folder (NAME.npz episodes) rewritten by lerobot's own writer as a
    LeRobotDataset v3 at `out`, state and action only (no camera): real-size data for timing `langpref label` on
    the LeRobot layout and for loading its labelled copy."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    files = sorted(recording.glob("*.npz"))
    with np.load(files[0]) as first:
        obs_dim, action_dim = first["observations"].shape[1], first["actions"].shape[1]
    features = {
        "observation.state": {"dtype": "float32", "shape": (obs_dim,), "names": None},
        "action": {"dtype": "float32", "shape": (action_dim,), "names": None},
    }
    dataset = LeRobotDataset.create(
        repo_id="langpref/recording", fps=fps, features=features, root=out, use_videos=False
    )
    for path in files:
        with np.load(path) as npz:
            for state, action in zip(npz["observations"], npz["actions"]):
                frame = {"observation.state": state.astype(np.float32), "action": action.astype(np.float32)}
                dataset.add_frame({**frame, "task": recording.name})
        dataset.save_episode()
    dataset.finalize()
    return {"episodes": len(files), "frames": dataset.meta.total_frames, "out": str(out)}


def verify_one(original: Path, labelled: Path) -> dict:
    """(lerobot's venv) `_verify_one` for any original and its labelled copy."""
    return _verify_one(original, labelled)


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] in ("record", "verify-one"):
        run = record if argv[0] == "record" else verify_one
        print(json.dumps(run(Path(argv[1]), Path(argv[2]))))
        return 0
    if len(argv) != 2 or argv[0] not in ("prepare", "verify"):
        print("usage: python -m benchmarks.lerobot_check prepare|verify OUT | record RECORDING OUT", file=sys.stderr)
        print("       python -m benchmarks.lerobot_check verify-one ORIGINAL LABELLED", file=sys.stderr)
        return 2
    out = Path(argv[1])
    if argv[0] == "prepare":
        print(json.dumps(prepare(out)))
        return 0
    result = verify(out)
    print(json.dumps(result))
    checks = [v for d in result.values() if isinstance(d, dict) for k, v in d.items() if isinstance(v, bool)]
    return 0 if checks and all(checks) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
