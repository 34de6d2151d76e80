"""Fault: the server is killed (SIGKILL) in the middle of a session and restarted on the same database; the
participant continues at the same step and nothing answered is lost, even with an answer in flight at the kill."""

from __future__ import annotations

import signal
import sqlite3
import threading
import time

import httpx


def test_sigkill_and_restart_lose_nothing(h, tmp_path):
    db = tmp_path / "fault.sqlite"
    proc, url = h.run_server(db, log=tmp_path / "server1.log")
    sent = 0
    try:
        c = httpx.Client(base_url=url, timeout=30)
        pid, headers = h.join(c)
        base = f"/api/participants/{pid}"
        step = c.get(f"{base}/step", headers=headers).json()
        # into Study 2, past a rating, so a reward learner holds answers in memory
        while not (step["phase"] == "pref_language" and step["number"] == 3):
            r = c.post(f"{base}/answer", json=h.answer_for(step, "Go a little higher."), headers=headers)
            assert r.status_code == 200, r.text
            sent += 1
            step = r.json()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL

    proc, url = h.run_server(db, log=tmp_path / "server2.log")
    try:
        c = httpx.Client(base_url=url, timeout=30)
        again = c.get(f"{base}/step", headers=headers).json()
        assert again == step  # the very same step: same trajectory, same query number
        conn = sqlite3.connect(db)
        assert conn.execute("SELECT count(*) FROM answers WHERE participant_id=?", (pid,)).fetchone()[0] == sent

        # kill with an answer in flight: afterwards it is either stored with its next step, or not at all
        def post():
            try:
                httpx.post(
                    f"{url}{base}/answer",
                    json={"feedback": "Move slower.", "client_ms": 4, "seq": step["seq"]},
                    headers=headers,
                    timeout=5,
                )
            except httpx.HTTPError:
                pass

        t = threading.Thread(target=post)
        t.start()
        time.sleep(0.02)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
        t.join()

    proc, url = h.run_server(db, log=tmp_path / "server3.log")
    try:
        c = httpx.Client(base_url=url, timeout=30)
        step = c.get(f"{base}/step", headers=headers).json()
        conn = sqlite3.connect(db)
        n = conn.execute("SELECT count(*) FROM answers WHERE participant_id=?", (pid,)).fetchone()[0]
        assert n in (sent, sent + 1)
        assert step["seq"] == n  # one answer per step before the current one, none lost, none doubled
        while step["kind"] != "done":
            r = c.post(f"{base}/answer", json=h.answer_for(step), headers=headers)
            assert r.status_code == 200, r.text
            step = r.json()
            n += 1
        seqs = [r[0] for r in conn.execute("SELECT seq FROM answers WHERE participant_id=? ORDER BY seq", (pid,))]
        assert seqs == list(range(n))
        assert (
            conn.execute(
                "SELECT count(*) FROM feedback WHERE participant_id=? AND phase='pref_language'", (pid,)
            ).fetchone()[0]
            == 4
        )
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    finally:
        h.stop(proc)
