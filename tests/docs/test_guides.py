"""The guide pages run as written: every code block of docs/start-to-finish.md, in order, in a fresh folder, at a
smaller size (`TINY`: each replacement must still find its text, so the page and this test cannot drift apart), and
the snippets on a saved reward of docs/policy.md."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.factories import untrained_checkpoint, write_dataset

ROOT = Path(__file__).parents[2]
GUIDE = ROOT / "docs" / "start-to-finish.md"
POLICY = ROOT / "docs" / "policy.md"
TINY = {
    "--episodes 60": "--episodes 14",
    "--out models/drawer\n": "--out models/drawer --epochs 2 --finetune-epochs 1 --augment-phrasings 0\n",
    "--learner answer-model &": "--learner answer-model --split all --pref-queries 3 --improve-max-iterations 1 "
    "--rating-every 3 --no-prerender &",
    "--participants 5": "--participants 2",
    "total_timesteps=20_000, progress_bar=True": "total_timesteps=128",
}
"""The page's sizes -> the test's (14 episodes, a short training, two participants answering three queries each, a
few PPO steps)."""


def code_blocks(page: Path) -> list[tuple[str, str]]:
    """(language, code) of every fenced block of a Markdown page, in order."""
    return [(m[1], m[2]) for m in re.finditer(r"^```(\w+)\n(.*?)^```", page.read_text(), flags=re.M | re.S)]


def tiny(blocks: list[tuple[str, str]]) -> list[tuple[str, str]]:
    text = "\x00".join(code for _, code in blocks)
    for big, small in TINY.items():
        assert big in text, f"the guide no longer says {big!r}: update TINY"
        text = text.replace(big, small)
    return list(zip([lang for lang, _ in blocks], text.split("\x00")))


@pytest.mark.slow
def test_start_to_finish_runs_as_written(tmp_path):
    blocks = tiny(code_blocks(GUIDE))
    assert [lang for lang, _ in blocks].count("python") == 2 and len(blocks) >= 9
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        "HF_HUB_OFFLINE": "1",
    }
    for i, (lang, code) in enumerate(blocks):
        argv = ["bash", "-e", "-o", "pipefail", "-c", code] if lang == "bash" else [sys.executable, "-c", code]
        done = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, f"block {i} ({lang}) failed:\n{code}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    assert (tmp_path / "runs" / "drawer-export" / "answers.jsonl").stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "runs" / "drawer-export" / "rewards" / "language").iterdir()) == [
        "reward-P1.json",
        "reward-P2.json",
        "reward-pooled.json",
    ]
    assert (tmp_path / "recordings" / "drawer-labelled").is_dir() and (tmp_path / "runs" / "drawer-ppo.zip").is_file()


def test_the_policy_pages_reward_snippets_run(tmp_path):
    """docs/policy.md's Python blocks on a saved reward, as written, beside a reward saved by `learn-reward` (SAC's
    steps cut to a few); the LeRobot one runs in LeRobot's own venv (`make lerobot-check`)."""
    from langpref.cli import main

    blocks = [code for lang, code in code_blocks(POLICY) if lang == "python"]
    runnable = [b for b in blocks if "langpref.reward" in b and "lerobot" not in b]
    assert len(runnable) == 2 and all("lerobot" in b for b in blocks if b not in runnable)
    data = write_dataset(tmp_path / "data", env="metaworld", n=24, horizon=8, like_task=True)
    model = untrained_checkpoint(tmp_path / "model")
    argv = ["learn-reward", "--model", str(model), "--data", str(data), "--feedback", "language", "--queries", "2"]
    assert main([*argv, "--humans", "1", "--seeds", "1", "--save-reward", str(tmp_path / "rewards")]) == 0
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    for code in runnable:
        code = code.replace("total_timesteps=100_000", "total_timesteps=64")
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
        assert done.returncode == 0, f"{code}\n{done.stderr[-3000:]}"
