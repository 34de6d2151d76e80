"""The guide pages run as written: every code block of docs/start-to-finish.md, in order, in a fresh folder, at a
smaller size (`TINY`: each replacement must still find its text, so the page and this test cannot drift apart)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
GUIDE = ROOT / "docs" / "start-to-finish.md"
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
