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

    from langpref.study.server.app import create_app
    from langpref.study.server.serve import build_state

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


def walk(client, h, until_kind: str | None = None, settle=None) -> tuple[str, dict[str, str], list[tuple[dict, float]]]:
    """A new participant answers steps (each response timed) until done, or until a step of `until_kind` comes:
    (participant id, headers, [(step, seconds), ...]). `settle`, when given, is waited on after each response (out
    of its timing): a test of what every run did lets the hook's queue drain, so that no run is dropped for room
    (`per_participant`), however slowly the machine starts the hook's processes."""
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
        if settle is not None:
            assert settle()
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
    pid, headers, steps = walk(client, h, until_kind="comparison", settle=lambda: state.hook.wait(timeout=60))
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
    # each step's runs carry the steps with videos the participant had answered (from the stored answers): its turns
    recent = list(reversed(status["recent"]))
    seqs = sorted({r["seq"] for r in recent})
    assert [r["earned"] for r in recent] == [seqs.index(r["seq"]) for r in recent] and len(seqs) > 1


def test_failing_and_missing_hooks_are_logged_and_counted(hooked, h, tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="langpref.study")
    state, client = hooked(python_command("-c", "import sys; print('robot offline'); sys.exit(1)"))
    pid, _, steps = walk(client, h, settle=lambda: state.hook.wait(timeout=60))
    assert steps[-1][0]["kind"] == "done" and answers_stored(state, pid) == len(steps) - 1
    assert max(t for _, t in steps) < PROMPT_S
    assert state.hook.wait(timeout=60)
    n = len(shown(state, steps))
    status = client.get("/api/admin/status", headers=h.admin).json()["hooks"]
    assert status["counts"] == {"ok": 0, "failed": n, "timeout": 0, "error": 0, "skipped": 0}
    last = status["recent"][0]
    assert (last["status"], last["returncode"], last["participant"]) == ("failed", 1, pid)
    assert "robot offline" in last["output"]
    videos = {step["seq"]: len(step["videos"]) for step, _ in steps}  # the admin page names positions of several
    assert all(r["shows"] == videos[r["seq"]] for r in status["recent"])
    assert {r["shows"] for r in status["recent"]} == {1, 2}
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
    # every shown trajectory ran, waits, or was skipped (one participant holds at most a quarter of the queue)
    held = status["queued"] + status["counts"]["timeout"] + (status["running"] is not None)
    assert held + status["counts"]["skipped"] == len(shown(state, steps))


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

    from langpref.study.server.app import create_app
    from langpref.study.server.serve import build_state

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


class Dataset:
    """What the hook reads of a dataset: an episode name per trajectory and the folder."""

    root = Path(".")

    def load(self, index: int):
        from types import SimpleNamespace

        return SimpleNamespace(source=None)


def wait_until(predicate, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_made_up_participants_cannot_take_the_robot():
    """Sign-ups that stop at their first step share the newcomers' places (the newest first); a participant who has
    answered takes a run's place only from one holding more; one participant holds at most `per_participant`."""
    from langpref.study.server.hook import ShowHook

    hook = ShowHook("sleep 60", Dataset(), queue_size=8)
    try:
        assert (hook.per_participant, hook.newcomer_slots) == (2, 2)
        hook.show("first", 1, "language", [0], earned=3)
        wait_until(lambda: hook.status()["running"] is not None)  # the robot is busy
        for k in range(4):
            hook.show(f"junk{k}", 1, "language", [k], earned=0)  # each newcomer's step takes the oldest's place
        status = hook.status()
        assert status["queued"] == 2 and status["counts"]["skipped"] == 2
        assert [r["participant"] for r in status["recent"] if r["status"] == "skipped"] == ["junk1", "junk0"]
        assert "answered no step since" in status["recent"][0]["output"]
        for name, seq in (("a", 5), ("b", 5), ("c", 5)):
            hook.show(name, seq, "comparison", [7, 8], earned=2)  # answered: not the newcomers' places
        assert hook.status()["queued"] == 8
        hook.show("a", 6, "language", [9], earned=3)  # a third waiting run of one participant: skipped
        hook.show("d", 5, "language", [10], earned=2)  # full: the oldest newcomer's step makes room
        hook.show("e", 5, "language", [11], earned=2)  # and the other
        hook.show("f", 5, "language", [12], earned=2)  # no newcomer left: the newest run of one holding 2
        hook.show("f", 6, "language", [13], earned=3)  # f holds 1, nobody holds 3: skipped
        skipped = [(r["participant"], r["trajectory"]) for r in hook.status()["recent"] if r["status"] == "skipped"]
        assert skipped[:5] == [("f", 13), ("a", 8), ("junk3", 3), ("junk2", 2), ("a", 9)]
        assert "holding fewer runs" in hook.status()["recent"][1]["output"]
    finally:
        hook.close()


WAIT_FOR_GO = 'echo "$LANGPREF_PARTICIPANT $LANGPREF_TRAJECTORY" >> runs.txt; while [ ! -e go ]; do sleep 0.01; done'
"""A replay that logs itself, then holds the robot until the test creates the file `go`."""


def test_a_real_participants_replays_come_next_however_many_sign_ups_came_first(tmp_path, monkeypatch):
    """Issue 44: 70 sign-ups that stop at their first video step filled the 64 places; the next real participant's
    first replay was skipped and their next one started after 63 others (8 min 17 s). Now the first comes after the
    run in flight, and after answering it the next one right after."""
    from langpref.study.server.hook import ShowHook

    monkeypatch.chdir(tmp_path)
    hook = ShowHook(shlex.join(["sh", "-c", WAIT_FOR_GO]), Dataset(), timeout_s=60)
    try:
        hook.show("first", 1, "language", [0], earned=0)
        wait_until(lambda: hook.status()["running"] is not None)  # the robot is busy with the first sign-up's
        for k in range(70):
            hook.show(f"junk{k}", 1, "language", [100 + k], earned=0)
        hook.show("real", 1, "language", [1], earned=0)
        assert hook.status()["counts"]["skipped"] == 70 + 1 - hook.newcomer_slots  # the oldest sign-ups'
        hook.show("real", 2, "comparison", [2, 3], earned=1)  # answered while the robot was still busy
        hook.show("junk69", 2, "language", [4], earned=1)  # a sign-up that answers too has its own turns
        (tmp_path / "go").touch()
        assert hook.wait(timeout=60)
        runs = [tuple(line.split()) for line in (tmp_path / "runs.txt").read_text().splitlines()]
    finally:
        hook.close()
    # one turn each, round robin (never served first, then the longest waiting): the newcomers share one, the
    # newest sign-up first; a sign-up that answered has its own; a participant's steps in order, a step's runs
    # together. The real participant's replays come after the run in flight and one turn of each other lane.
    turns = [("first", "0"), ("junk69", "169"), ("real", "1"), ("junk68", "168"), ("junk69", "4")]
    assert runs[:7] == [*turns, ("real", "2"), ("real", "3")]
    assert [int(t) for _, t in runs[7:]] == list(range(167, 154, -1))  # the newest first; the older ones skipped
    assert hook.status()["counts"]["ok"] == len(runs)


KEEP_GOING = """import os, subprocess, sys
child = subprocess.Popen(["sleep", "300"])  # a replay's own child: the whole group must end
with open(sys.argv[1] + ".tmp", "w") as f:
    f.write(f"{os.getpid()} {child.pid}")
os.rename(sys.argv[1] + ".tmp", sys.argv[1])
child.wait()
"""

SERVER = """import sys, time
sys.path.insert(0, sys.argv[3])
from pathlib import Path
from types import SimpleNamespace
from langpref.study.server.hook import ShowHook

class Dataset:
    root = Path(".")
    def load(self, index):
        return SimpleNamespace(source=None)

hook = ShowHook(sys.argv[1], Dataset(), timeout_s=float(sys.argv[2]))
hook.show("p", 1, "language", [0])
time.sleep(600)
"""


def test_a_replay_in_flight_ends_when_the_server_is_killed(tmp_path):
    """kill -9 of the server leaves no replay driving the robot: the watchdog ends the hook's process group."""
    import os
    import signal
    import subprocess

    from benchmarks.common import alive

    src = str(Path(__file__).resolve().parents[3] / "src")

    pids = tmp_path / "pids"
    (tmp_path / "keep_going.py").write_text(KEEP_GOING)
    (tmp_path / "server.py").write_text(SERVER)
    command = python_command(tmp_path / "keep_going.py", pids)
    server = subprocess.Popen([sys.executable, str(tmp_path / "server.py"), command, "600", src])
    try:
        wait_until(lambda: pids.exists() or server.poll() is not None)
        assert server.poll() is None, "the server script ended"
        hook_pid, child_pid = map(int, pids.read_text().split())
        assert alive({hook_pid, child_pid}) == {hook_pid, child_pid}
        os.kill(server.pid, signal.SIGKILL)
        server.wait()
        wait_until(lambda: not alive({hook_pid, child_pid}), timeout=10)
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
        if pids.exists():
            for pid in map(int, pids.read_text().split()):
                if alive({pid}):
                    os.kill(pid, signal.SIGKILL)
