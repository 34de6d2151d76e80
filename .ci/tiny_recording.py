"""Write a tiny plain recording of a made-up robot, with its task file and bank, for the wheel's smoke test.

    python .ci/tiny_recording.py DIR   ->  DIR/recording/epNN.npz, DIR/task.toml, DIR/bank.json

Only numpy: this runs in the fresh core-only venv that `make wheel-check` builds.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

BANK = {
    "reach": {
        "increase": ["Reach further.", "Stretch out more.", "Extend your arm more.", "Go further out."],
        "decrease": ["Reach less.", "Stay closer in.", "Keep your arm in.", "Don't reach so far."],
    },
    "effort": {
        "increase": ["Push harder.", "Use more force.", "Put more effort in.", "Be more forceful."],
        "decrease": ["Push softer.", "Use less force.", "Be gentler.", "Go easy."],
    },
}


def main(root: Path, episodes: int = 16) -> None:
    rec = root / "recording"
    rec.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for i in range(episodes):
        steps = 12 + i  # episodes of different lengths, as a real recording has
        obs = rng.normal(size=(steps, 5)).astype(np.float32)
        act = rng.normal(size=(steps, 2)).astype(np.float32)
        features = np.stack([obs[:, 0], np.abs(act).sum(axis=1)], axis=1)  # per step: (T, 2)
        np.savez(rec / f"ep{i:02d}.npz", observations=obs, actions=act, features=features, success=np.array(i % 2 == 0))
    (root / "bank.json").write_text(json.dumps(BANK, indent=1))
    (root / "task.toml").write_text(
        'name = "toy-reach"\ndescription = "A robot reaches for a cup."\nfeatures = ["reach", "effort"]\n'
        'utterances = "bank.json"\nexamples = ["Reach further."]\n'
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
