"""`study serve --on-show CMD`: the hook runs with the trajectory, episode and participant in its environment, once
per step handed out; failing, missing and hanging hooks are logged and counted on the dashboard while every answer
is stored and every step response comes back promptly."""

from __future__ import annotations

import json
import logging
import shlex
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from langpref.errors import LangprefError

RECORD_ENV = """import json, os, sys
with open(sys.argv[1], "a") as f:
    f.write(json.dumps({k: v for k, v in os.environ.items() if k.startswith("LANGPREF_")}) + "\\n")
"""
PROMPT_S = 5.0
"""The most a step response may take here (a model step on a shared CPU), far below what the hanging hooks take."""


def python_command(*args: str | Path) -> str:
    return shlex.join([sys.executable, *map(str, args)])


@pytest.fixture
def hooked(engine, h, tmp_path):
    """(state, TestClient) of a study whose --on-show is `command` (a factory: `hooked(command, timeout)`)."""
    from fastapi.testclient import TestClient

    from langpref.study.app import create_app
    from langpref.study.serve import build_state

    made = []

    def make(command: str, timeout: float = 60.0):
        cfg = replace(h.serve_config(tmp_path / f"study{len(made)}.sqlite"), on_show=command, on_show_timeout=timeout)
        state = build_state(cfg, engine=engine, progress=False)
        client = TestClient(create_app(state))
        made.append((state, client))
        return state, client

    yield make
    for state, client in made:
        client.close()
        state.hook.close()
        state.videos.close()


def walk(client, h, until_kind: str | None = None) -> tuple[str, dict[str, str], list[tuple[dict, float]]]:
    """A new participant answers steps (each response timed) until done, or until a step of `until_kind` comes:
    (participant id, headers, [(step, seconds), ...])."""
    pid, headers = h.join(client)
    t0 = time.perf_counter()
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    steps = [(step, time.perf_counter() - t0)]
    while step["kind"] != "done" and step["kind"] != until_kind:
        t0 = time.perf_counter()
        r = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers)
        assert r.status_code == 200, r.text
        step = r.json()
        steps.append((step, time.perf_counter() - t0))
    return pid, headers, steps


def shown(state, steps) -> list[tuple[str, int, int]]:
    """(kind, position, trajectory) of every video of the steps, in order."""
    return [
        (s["kind"], pos, state.videos.index_of(url.rsplit("/", 1)[1]))
        for s, _ in steps
        for pos, url in enumerate(s["videos"])
    ]


def answers_stored(state, pid: str) -> int:
    return state.connect().execute("SELECT count(*) FROM answers WHERE participant_id=?", (pid,)).fetchone()[0]


def test_hook_runs_once_per_shown_trajectory_with_its_environment(hooked, h, tmp_path, study_data):
    out = tmp_path / "runs.jsonl"
    (tmp_path / "record_env.py").write_text(RECORD_ENV)
    state, client = hooked(python_command(tmp_path / "record_env.py", out))
    pid, headers, steps = walk(client, h, until_kind="comparison")
    assert client.get(f"/api/participants/{pid}/step", headers=headers).status_code == 200  # a reload: no replay
    assert state.hook.wait(timeout=60)
    runs = [json.loads(line) for line in out.read_text().splitlines()]
    expected = shown(state, steps)
    assert any(kind == "comparison" for kind, _, _ in expected)
    assert [(r["LANGPREF_KIND"], int(r["LANGPREF_POSITION"]), int(r["LANGPREF_TRAJECTORY"])) for r in runs] == expected
    assert {r["LANGPREF_PARTICIPANT"] for r in runs} == {pid}
    assert {r["LANGPREF_DATA"] for r in runs} == {str(study_data.resolve())}
    assert {r["LANGPREF_EPISODE"] for r in runs} == {""}  # a simulated dataset has no recorded episodes
    status = state.hook.status()
    assert status["counts"]["ok"] == len(runs) and sum(status["counts"].values()) == len(runs)


def test_failing_and_missing_hooks_are_logged_and_counted(hooked, h, tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="langpref.study")
    state, client = hooked(python_command("-c", "import sys; print('robot offline'); sys.exit(1)"))
    pid, _, steps = walk(client, h)
    assert steps[-1][0]["kind"] == "done" and answers_stored(state, pid) == len(steps) - 1
    assert max(t for _, t in steps) < PROMPT_S
    assert state.hook.wait(timeout=60)
    n = len(shown(state, steps))
    status = client.get("/api/admin/status", headers=h.admin).json()["hooks"]
    assert status["counts"] == {"ok": 0, "failed": n, "timeout": 0, "error": 0, "skipped": 0}
    last = status["recent"][0]
    assert (last["status"], last["returncode"], last["participant"]) == ("failed", 1, pid)
    assert "robot offline" in last["output"]
    assert client.get("/api/admin/participants", headers=h.admin).json()["hooks"]["counts"]["failed"] == n
    assert any("--on-show hook failed" in r.getMessage() and "robot offline" in r.getMessage() for r in caplog.records)

    # a program that is gone by the time it runs: an error on the dashboard, the study goes on
    script = tmp_path / "replay.sh"
    script.write_text("#!/bin/sh\nexit 0\n")
    script.chmod(0o755)
    state, client = hooked(str(script))
    script.unlink()
    walk(client, h, until_kind="language")
    assert state.hook.wait(timeout=60)
    last = state.hook.status()["recent"][0]
    assert last["status"] == "error" and "cannot start" in last["output"]


def test_hanging_hook_is_killed_at_its_timeout_and_never_delays_a_step(hooked, h):
    state, client = hooked("sleep 60", timeout=1.0)
    pid, _, steps = walk(client, h)
    # every answer stored and every response prompt, though each shown trajectory holds the hook for a second
    assert steps[-1][0]["kind"] == "done" and answers_stored(state, pid) == len(steps) - 1
    assert max(t for _, t in steps) < PROMPT_S
    deadline = time.monotonic() + 30
    while state.hook.status()["counts"]["timeout"] < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    status = client.get("/api/admin/status", headers=h.admin).json()["hooks"]
    assert status["counts"]["timeout"] >= 2 and status["counts"]["ok"] == 0
    run = status["recent"][0]
    assert run["status"] == "timeout" and 1.0 <= run["seconds"] < 5.0 and "killed after 1 s" in run["output"]
    assert status["queued"] + status["counts"]["timeout"] + (status["running"] is not None) == len(shown(state, steps))


def test_a_hook_that_cannot_run_is_refused_at_start(h, tmp_path):
    for command, message in (
        ("", "not a command line"),
        ("'unbalanced", "not a command line"),
        (str(tmp_path / "no-such-replay.sh"), "not found"),
    ):
        cfg = replace(h.serve_config(tmp_path / "x.sqlite"), on_show=command)
        with pytest.raises(LangprefError, match=message):
            cfg.validate()
    with pytest.raises(LangprefError, match="on-show-timeout"):
        replace(h.serve_config(tmp_path / "x.sqlite"), on_show="true", on_show_timeout=0).validate()


RECORD_MADE = """import json, os, sys
made = os.path.join(os.environ["LANGPREF_DATA"], "trajectories", "%06d.npz" % int(os.environ["LANGPREF_TRAJECTORY"]))
with open(sys.argv[1], "a") as f:
    env = {k: v for k, v in os.environ.items() if k.startswith("LANGPREF_")}
    f.write(json.dumps({**env, "made": os.path.exists(made)}) + "\\n")
"""


def test_hook_runs_for_a_generated_trajectory_once_it_is_made(engine, h, tmp_path, study_data):
    """Study 1 with generated candidates: the satisfaction step about a trajectory still being made is handed out at
    once; its run waits aside and comes when the simulator has made it, with the generated dataset and the
    trajectory's index in it; the next step showing it runs at once; a reload runs nothing."""
    from fastapi.testclient import TestClient

    from langpref.study.app import create_app
    from langpref.study.serve import build_state

    out = tmp_path / "runs.jsonl"
    (tmp_path / "record.py").write_text(RECORD_MADE)
    db = tmp_path / "gen.sqlite"
    study = {"improve_candidates": "generated", "improve_rollouts": 2, "improve_search_generations": 3}
    cfg = replace(h.serve_config(db, **study), on_show=python_command(tmp_path / "record.py", out))
    state = build_state(cfg, engine=engine, progress=False)
    try:
        with TestClient(create_app(state)) as client:
            pid, headers, steps = walk(client, h, until_kind="language")
            t0 = time.perf_counter()
            r = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(steps[-1][0]), headers=headers)
            assert r.status_code == 200 and time.perf_counter() - t0 < PROMPT_S  # the hook never holds it up
            satisfaction = r.json()
            assert satisfaction["kind"] == "satisfaction" and "/gen" in satisfaction["videos"][0]
            assert state.hook.status()["waiting_for_generation"] == 1  # the worker is still starting
            assert state.hook.wait(timeout=120)  # made, and its run done
            assert client.get(f"/api/participants/{pid}/step", headers=headers).status_code == 200  # a reload
            r = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(satisfaction), headers=headers)
            assert r.status_code == 200 and r.json()["videos"] == satisfaction["videos"]  # not satisfied: again
            assert state.hook.wait(timeout=60)
    finally:
        state.hook.close()
        state.generated.close()
        state.videos.close()
    runs = [json.loads(line) for line in out.read_text().splitlines()]
    store = str((tmp_path / "gen.sqlite.generated").resolve())
    seen = [(r["LANGPREF_KIND"], r["LANGPREF_DATA"], r["LANGPREF_TRAJECTORY"], r["LANGPREF_EPISODE"]) for r in runs]
    first = state.videos.index_of(steps[-1][0]["videos"][0].rsplit("/", 1)[1])
    assert seen == [
        ("language", str(study_data.resolve()), str(first), ""),
        ("satisfaction", store, "0", ""),
        ("language", store, "0", ""),
    ]
    assert all(r["made"] for r in runs) and {r["LANGPREF_PARTICIPANT"] for r in runs} == {pid}
    assert state.hook.status()["counts"]["ok"] == 3
