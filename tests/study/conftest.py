"""A tiny real setup for the study tests: a Meta-World dataset from the simulator (16 trajectories, T = 30), a latent
model trained for a few steps on it (language model frozen), and a tiny study protocol.

`study_state` gives a fresh database over the shared engine and `client` a TestClient on it; the fixture `h` holds
helpers: `h.join(client)`, `h.answer_for(step)`, `h.run_server(db, ...)` (`langpref study serve` as a real process,
for the load, fault and browser tests) and `h.stop(proc)`.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

torch.set_num_threads(1)

TINY = {"split": "all", "improve_max_iterations": 3, "pref_queries": 4, "rating_every": 2, "num_negatives": 5}
ADMIN = "admin-token-for-tests-0123456789"
SRC = str(Path(__file__).resolve().parents[2] / "src")


@pytest.fixture(scope="session")
def study_data(tmp_path_factory) -> Path:
    from langpref.dataset.generate import GenerateConfig, generate

    out = tmp_path_factory.mktemp("study") / "mw"
    generate(GenerateConfig(env="metaworld", out=out, num_trajectories=16, horizon=30, workers=1, seed=3))
    return out


@pytest.fixture(scope="session")
def study_model(study_data, tmp_path_factory, tiny_texts) -> Path:
    from langpref.language.pairs import phrasings_from_mapping
    from langpref.model.config import ModelConfig, TrainConfig
    from langpref.model.train import train

    features = ["height", "speed", "distance_to_button"]
    out = tmp_path_factory.mktemp("study_model") / "model"
    cfg = TrainConfig(
        data=str(study_data),
        out=str(out),
        model=ModelConfig(latent_dim=16, max_length=16),
        stage1_epochs=2,
        stage1_batch_size=256,
        stage2_epochs=0,
        patience=0,
        device="cpu",
        seed=0,
    )
    train_texts, val_texts = tiny_texts
    train(
        cfg,
        train_phrasings=phrasings_from_mapping(train_texts, features),
        val_phrasings=phrasings_from_mapping(val_texts, features),
        progress=False,
    )
    return out


@pytest.fixture(scope="session")
def engine(study_model, study_data):
    from langpref.study.protocol.config import StudyConfig
    from langpref.study.session.engine import StudyEngine

    return StudyEngine.load(study_model, study_data, StudyConfig(**TINY))


def serve_config(model: Path, data: Path, db: Path, **study):
    from langpref.study.protocol.config import StudyConfig
    from langpref.study.server.settings import ServeConfig

    return ServeConfig(
        model=str(model),
        data=str(data),
        db=str(db),
        admin_token=ADMIN,
        prerender=False,
        allowed_hosts=("testserver",),  # the Host of Starlette's TestClient
        study=StudyConfig(**{**TINY, **study}),
    )


@pytest.fixture
def study_state(engine, study_model, study_data, tmp_path):
    from langpref.study.server.serve import build_state

    state = build_state(serve_config(study_model, study_data, tmp_path / "study.sqlite"), engine=engine, progress=False)
    yield state
    state.videos.close()


@pytest.fixture
def client(study_state):
    from fastapi.testclient import TestClient

    from langpref.study.server.app import create_app

    with TestClient(create_app(study_state)) as c:
        yield c


def join(client) -> tuple[str, dict[str, str]]:
    r = client.post("/api/participants", json={})
    assert r.status_code == 200, r.text
    me = r.json()
    return me["participant_id"], {"X-Participant-Token": me["token"]}


def answer_for(step: dict, feedback: str = "Move faster.") -> dict:
    """A valid answer to any step (surveys: every question answered), with the step's `seq`."""
    return {**_answer_for(step, feedback), "seq": step["seq"]}


def _answer_for(step: dict, feedback: str) -> dict:
    kind = step["kind"]
    if kind == "confirm":  # asked what a language answer meant: the robot's top reading
        return {"meaning": step["options"][0]["meaning"]}
    if kind == "survey":
        answers = {}
        for q in step["questions"]:
            answers[q["id"]] = {
                "likert": q["min"],
                "text": "some words",
                "choice": q["options"][0] if q["options"] else None,
                "multi": q["options"][:1],
            }[q["type"]]
        return {"answers": answers}
    return {
        "language": {"feedback": feedback, "client_ms": 1.0},
        "comparison": {"choice": 1, "client_ms": 1.0},
        "satisfaction": {"satisfied": False},
        "rating": {"rating": 4},
    }[kind]


def run_server(
    model: Path, data: Path, db: Path, *extra: str, log: Path | None = None, prerender: bool = False, **study
) -> tuple[subprocess.Popen, str]:
    """`langpref study serve` in its own process on a free loopback port; (process, base URL) once it answers."""
    import httpx

    protocol = [x for k, v in {**TINY, **study}.items() for x in (f"--{k.replace('_', '-')}", str(v))]
    args = [
        sys.executable,
        "-m",
        "langpref",
        "study",
        "serve",
        "--model",
        str(model),
        "--data",
        str(data),
        "--db",
        str(db),
        "--port",
        "0",
        "--admin-token",
        ADMIN,
        *protocol,
        *([] if prerender else ["--no-prerender"]),
        *extra,
    ]
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", ""), "HF_HUB_OFFLINE": "1"}
    err = open(log, "w") if log else subprocess.DEVNULL  # noqa: SIM115 (the server writes it while it runs)
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=err, env=env, text=True)
    deadline = time.time() + 120
    url = None
    while time.time() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                raise RuntimeError(f"the server exited with {proc.returncode}" + (f"; see {log}" if log else ""))
            continue
        m = re.search(r"participants: (http://\S+?)/?$", line.strip())
        if m:
            url = m.group(1)
            break
    assert url, "the server printed no URL"
    while time.time() < deadline:
        try:
            if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the server did not answer /healthz")


def stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    if proc.stdout:
        proc.stdout.close()


class Helpers:
    def __init__(self, model: Path, data: Path):
        self.model, self.data = model, data
        self.join = join
        self.answer_for = answer_for
        self.stop = stop
        self.admin = {"Authorization": f"Bearer {ADMIN}"}

    def serve_config(self, db: Path, **study):
        return serve_config(self.model, self.data, db, **study)

    def run_server(self, db: Path, *extra: str, **kw) -> tuple[subprocess.Popen, str]:
        return run_server(self.model, self.data, db, *extra, **kw)


@pytest.fixture(scope="session")
def h(study_model, study_data) -> Helpers:
    return Helpers(study_model, study_data)
