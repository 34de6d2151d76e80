"""`study serve` on a recorded dataset (`langpref import`): the study shows each trajectory's recorded video (told
apart here by a colour per episode), transcoded once to the served format or copied as is, and never re-rendered;
the task's own bank is feedback the study accepts; the --on-show hook is told the recording's episode."""

from __future__ import annotations

import json
import shlex
import sys
from dataclasses import replace
from pathlib import Path

import av
import numpy as np
import pytest

COLOURS = {
    "ep_red": (220, 30, 30),
    "ep_green": (30, 200, 40),
    "ep_blue": (30, 40, 220),
    "ep_yellow": (230, 220, 30),
    "ep_magenta": (210, 40, 210),
    "ep_cyan": (40, 210, 220),
    "ep_white": (235, 235, 235),
    "ep_black": (15, 15, 15),
}
FEATURES = ("speed", "height")
BANK = {
    "speed": {
        "increase": ["Move faster.", "Speed up.", "Go quicker.", "Hurry up a bit."],
        "decrease": ["Move slower.", "Slow down.", "Go more slowly.", "Take it easy."],
    },
    "height": {
        "increase": ["Move higher.", "Go up more.", "Raise the gripper.", "Lift your hand up."],
        "decrease": ["Move lower.", "Go down more.", "Lower the gripper.", "Keep your hand down."],
    },
}
TASK_TOML = """name = "tiny-colours"
description = "Wave the gripper over the table."
features = ["speed", "height"]
utterances = "utterances.json"
robot = "a tiny test arm"
"""


def write_video(path: Path, colour: tuple[int, int, int], frames: int = 5) -> None:
    """A 32x32 H.264 mp4 of one colour, a few frames long."""
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 32, 32, "yuv420p"
        image = np.broadcast_to(np.asarray(colour, np.uint8), (32, 32, 3)).copy()
        for _ in range(frames):
            out.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        out.mux(stream.encode(None))


def mean_colour(path: Path) -> np.ndarray:
    """The mean RGB of the middle frame of a video (it must decode)."""
    with av.open(str(path)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert frames, f"{path} has no frames"
    return frames[len(frames) // 2].reshape(-1, 3).mean(axis=0)


def nearest_episode(rgb: np.ndarray) -> str:
    return min(COLOURS, key=lambda name: float(np.sum((np.asarray(COLOURS[name]) - rgb) ** 2)))


@pytest.fixture(scope="module")
def recorded_data(tmp_path_factory) -> Path:
    """A plain recording (8 episodes of 12-26 steps, per-episode features, a colour video each) imported."""
    from langpref.dataset.importer import ImportConfig, import_recording
    from langpref.language.bank import check_bank, split_bank
    from langpref.tasks.taskfile import read_task_file

    root = tmp_path_factory.mktemp("recorded")
    src = root / "recording"
    src.mkdir()
    rng = np.random.default_rng(0)
    for i, name in enumerate(COLOURS):
        steps = 12 + 2 * i
        obs = (rng.uniform(-1, 1, 4) + 0.2 * rng.standard_normal((steps, 4))).astype(np.float32)
        actions = rng.standard_normal((steps, 2)).astype(np.float32)
        np.savez(
            src / f"{name}.npz",
            observations=obs,
            actions=actions,
            features=obs[:, :2].mean(axis=0),
            success=np.asarray(i % 2 == 0),
        )
        write_video(src / f"{name}.mp4", COLOURS[name])
    (root / "utterances.json").write_text(json.dumps(BANK))
    (root / "task.toml").write_text(TASK_TOML)
    task = read_task_file(root / "task.toml")
    bank = split_bank(task.utterances, task.features, seed=0)
    check_bank(bank, task.name, task.features, "test bank")
    out = root / "data"
    import_recording(ImportConfig(src=src, task=root / "task.toml", out=out), task, bank, progress=False)
    return out


@pytest.fixture(scope="module")
def recorded_model(recorded_data, tmp_path_factory) -> Path:
    from langpref.model.config import ModelConfig, TrainConfig
    from langpref.model.train import train

    out = tmp_path_factory.mktemp("recorded_model") / "model"
    train(
        TrainConfig(
            data=str(recorded_data),
            out=str(out),
            model=ModelConfig(latent_dim=16, max_length=16),
            stage1_epochs=2,
            stage1_batch_size=256,
            stage2_epochs=0,
            patience=0,
            device="cpu",
            seed=0,
        ),
        progress=False,
    )
    return out


@pytest.fixture
def recorded_state(recorded_model, recorded_data, tmp_path, h):
    """A tiny study over the recorded dataset, its --on-show hook writing each run's environment to `runs.jsonl`."""
    from langpref.study.server.serve import build_state

    script = tmp_path / "record_env.py"
    script.write_text(
        "import json, os, sys\nwith open(sys.argv[1], 'a') as f:\n"
        "    f.write(json.dumps({k: v for k, v in os.environ.items() if k.startswith('LANGPREF_')}) + "
        "'\\n')\n"
    )
    cfg = replace(
        h.serve_config(tmp_path / "study.sqlite"),
        model=str(recorded_model),
        data=str(recorded_data),
        on_show=shlex.join([sys.executable, str(script), str(tmp_path / "runs.jsonl")]),
    )
    state = build_state(cfg, progress=False)
    yield state
    state.hook.close()
    state.videos.close()


def test_study_shows_the_recorded_videos(recorded_state, recorded_data, tmp_path, h):
    from fastapi.testclient import TestClient

    from langpref.dataset.storage import load_dataset
    from langpref.study.server.app import create_app

    ds = load_dataset(recorded_data)
    assert ds.meta.videos and ds.meta.lengths is not None  # a recorded dataset, episodes of different lengths
    with TestClient(create_app(recorded_state)) as client:
        pid, headers = h.join(client)
        step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
        seen: list[tuple[str, int]] = []  # (step kind, trajectory) of every video handed out
        language_answers = 0
        while step["kind"] != "comparison":
            for url in step["videos"]:
                seen.append((step["kind"], recorded_state.videos.index_of(url.rsplit("/", 1)[1])))
                r = client.get(url)
                assert r.status_code == 200 and r.headers["content-type"] == "video/webm"
                served = tmp_path / "served.webm"
                served.write_bytes(r.content)
                # the recording's own video (its episode's colour), transcoded to webm
                assert nearest_episode(mean_colour(served)) == ds.load(seen[-1][1]).source
            said = step["kind"] == "language"
            if said:  # feedback phrased as in the task's bank
                body = {
                    "feedback": BANK["height"]["decrease"][language_answers % 4],
                    "client_ms": 1.0,
                    "seq": step["seq"],
                }
                language_answers += 1
            else:
                body = h.answer_for(step)
            r = client.post(f"/api/participants/{pid}/answer", json=body, headers=headers)
            assert r.status_code == 200, r.text
            step = r.json()
            if said:  # the robot says how it read each sentence
                assert step["understood"]["feature"] in FEATURES
        # the comparison step shows two recorded videos too
        assert len(step["videos"]) == 2
        for url in step["videos"]:
            index = recorded_state.videos.index_of(url.rsplit("/", 1)[1])
            seen.append(("comparison", index))
            served = tmp_path / "served.webm"
            served.write_bytes(client.get(url).content)
            assert nearest_episode(mean_colour(served)) == ds.load(index).source
    assert language_answers >= 2
    stored = (
        recorded_state.connect().execute("SELECT count(*) FROM feedback WHERE participant_id=?", (pid,)).fetchone()[0]
    )
    assert stored == language_answers
    # the hook learnt each shown trajectory's recorded episode
    assert recorded_state.hook.wait(timeout=60)
    runs = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert [(r["LANGPREF_KIND"], int(r["LANGPREF_TRAJECTORY"])) for r in runs] == seen
    assert all(r["LANGPREF_EPISODE"] == ds.load(int(r["LANGPREF_TRAJECTORY"])).source for r in runs)


def test_mp4_study_serves_the_recorded_file_as_is(recorded_data, tmp_path):
    from langpref.dataset.storage import load_dataset
    from langpref.study.server.settings import VideoConfig
    from langpref.study.server.videos import VideoCache

    ds = load_dataset(recorded_data)
    cache = VideoCache(recorded_data, tmp_path / "videos", VideoConfig(format="mp4", width=64), [0, 3], progress=False)
    try:
        for index in (0, 3):
            assert cache.ensure(index, timeout=120).read_bytes() == ds.video_path(index).read_bytes()
    finally:
        cache.close()
    # the render settings do not name (or invalidate) recorded videos; the format does
    assert cache.tag == VideoCache(recorded_data, tmp_path / "videos", VideoConfig(format="mp4"), [0]).tag


def test_every_command_runs_on_the_recorded_task(recorded_data, recorded_model, tmp_path, capsys):
    """evaluate (the bank's test split and a user file keyed by the task's name), embed, improve and learn-reward
    on the imported task: the synthetic humans speak its bank."""
    from langpref.cli import main

    def run(*argv: str) -> dict:
        assert main([*argv, "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    m, d = str(recorded_model), str(recorded_data)
    ev = run("evaluate", "--model", m, "--data", d)
    assert set(ev["per_feature"]) == set(FEATURES) and ev["num_samples"] > 0
    mine = tmp_path / "mine.json"
    mine.write_text(
        json.dumps(
            {
                "tiny-colours": {"speed": {"increase": ["Zoom along faster."]}},
                "some-other-lab-task": {"grip": {"increase": ["Hold tighter."]}},
            }
        )
    )
    assert run("evaluate", "--model", m, "--data", d, "--utterances", str(mine))["num_phrasings"] == 1
    assert run("embed", "--model", m, "Go quicker.")["feature"] in FEATURES
    improve = run("improve", "--model", m, "--data", d, "--iterations", "2", "--seeds", "2")
    assert len(improve["curve"]) == 3
    for feedback in ("language", "comparison"):
        reward = run(
            "learn-reward",
            "--model",
            m,
            "--data",
            d,
            "--feedback",
            feedback,
            "--queries",
            "3",
            "--humans",
            "2",
            "--seeds",
            "1",
        )
        assert len(reward["cross_entropy"]) == 4 and len(reward["true_reward_of_best"]) == 4


def test_generated_candidates_need_a_simulator_one_line_before_the_model_loads(recorded_data, h, tmp_path):
    from langpref.errors import LangprefError
    from langpref.study.server.serve import build_state

    cfg = replace(
        h.serve_config(tmp_path / "gen.sqlite", improve_candidates="generated"),
        model=str(tmp_path / "no-model-here"),  # never read: the task is checked first
        data=str(recorded_data),
    )
    with pytest.raises(LangprefError, match="task 'tiny-colours' has no simulator") as err:
        build_state(cfg, progress=False)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "gen.sqlite").exists()
