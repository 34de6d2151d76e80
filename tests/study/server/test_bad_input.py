"""Every bad input is a 4xx with one line, never a 500 with a traceback, and the keep-alive connection that carried
it keeps working: deeply nested JSON, integers of thousands of digits, NaN, bytes that are not UTF-8."""

from __future__ import annotations

import json
import socket

import pytest

BIG = "9" * 5000  # over Python's 4300-digit limit for int(str)
NESTED = b"[" * 30000 + b"]" * 30000


def bodies(step_seq: int) -> list[bytes]:
    return [
        NESTED,
        b'{"feedback": "Move faster.", "client_ms": 1, "seq": ' + str(step_seq).encode() + b', "x": ' + NESTED + b"}",
        ('{"feedback": "Move faster.", "client_ms": ' + BIG + "}").encode(),
        ('{"feedback": "Move faster.", "client_ms": ' + "9" * 4000 + f', "seq": {step_seq}}}').encode(),
        ('{"rating": ' + "9" * 4000 + "}").encode(),
        b'{"feedback": "Move faster.", "client_ms": NaN, "seq": 1}',
        b'{"feedback": "Move faster.", "client_ms": Infinity, "seq": 1}',
        b'{"feedback": "Move faster.", "client_ms": 1e999, "seq": 1}',
        b"\xc3\x28",
    ]


def http(sock: socket.socket, method: str, path: str, body: bytes = b"", headers: dict | None = None):
    """One request on an open connection; (status, headers, body)."""
    head = [
        f"{method} {path} HTTP/1.1",
        "Host: 127.0.0.1",
        f"Content-Length: {len(body)}",
        "Content-Type: application/json",
        *(f"{k}: {v}" for k, v in (headers or {}).items()),
    ]
    sock.sendall(("\r\n".join(head) + "\r\n\r\n").encode() + body)
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = sock.recv(65536)
        assert chunk, "the server closed the connection"
        buf += chunk
    raw_head, rest = buf.split(b"\r\n\r\n", 1)
    lines = raw_head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    hdrs = {k.lower(): v.strip() for k, v in (x.split(":", 1) for x in lines[1:])}
    n = int(hdrs.get("content-length", 0))
    while len(rest) < n:
        chunk = sock.recv(65536)
        assert chunk, "the server closed the connection"
        rest += chunk
    return status, hdrs, rest[:n]


@pytest.fixture
def live(engine, h, tmp_path):
    from langpref.study.server.serve import BackgroundServer, build_state

    state = build_state(h.serve_config(tmp_path / "bad.sqlite"), engine=engine, progress=False)
    with BackgroundServer(state) as url:
        yield state, url
    state.videos.close()


def test_bad_bodies_are_one_line_4xx_on_a_connection_that_survives(live, h):
    state, url = live
    port = int(url.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        status, _, body = http(sock, "POST", "/api/participants", b"{}")
        me = json.loads(body)
        auth = {"X-Participant-Token": me["token"]}
        path = f"/api/participants/{me['participant_id']}"
        status, _, body = http(sock, "GET", f"{path}/step", headers=auth)
        step = json.loads(body)
        status, _, body = http(
            sock, "POST", f"{path}/answer", json.dumps({**h.answer_for(step), "seq": 0}).encode(), auth
        )
        assert status == 200, body
        step = json.loads(body)
        assert step["kind"] == "language"
        invalid = [NESTED, b'{"a": ' + BIG.encode() + b"}", b"\xc3\x28", b'{"a": NaN}']
        for bad in [*bodies(step["seq"]), *invalid]:
            targets = (
                f"{path}/answer",
                "/api/participants/resume",
                *(("/api/participants",) if bad in invalid else ()),
            )
            for target in targets:
                status, hdrs, body = http(sock, "POST", target, bad, auth)
                assert 400 <= status < 500, (target, bad[:60], status, body[:300])
                err = json.loads(body)
                assert set(err) == {"error"} and "\n" not in err["error"] and len(err["error"]) < 300
                assert hdrs.get("connection", "").lower() != "close"
        # the same connection still serves, and nothing was stored
        status, _, body = http(sock, "GET", f"{path}/step", headers=auth)
        assert status == 200 and json.loads(body)["seq"] == step["seq"]
    conn = state.connect()
    assert conn.execute("SELECT count(*) FROM answers").fetchone()[0] == 1


def walk_to(client, h, kind: str) -> tuple[str, dict[str, str], dict]:
    """A new participant, answered up to the first step of `kind`."""
    pid, headers = h.join(client)
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    while step["kind"] != kind:
        step = client.post(f"/api/participants/{pid}/answer", json=h.answer_for(step), headers=headers).json()
    return pid, headers, step


def test_lone_surrogates_are_refused_where_text_comes_in(client, h, study_state):
    """`"\\ud800"` in JSON is no character: stored, it broke the export; in feedback and a reason it was a 500."""
    pid, headers, step = walk_to(client, h, "survey")
    survey = json.dumps(h.answer_for(step)).replace('"some words"', '"3\\ud800"')
    assert "\\ud800" in survey
    feedback = b'{"feedback": "Move faster.\\udfff", "client_ms": 1.0}'
    reason = b'{"excluded": true, "reason": "bot \\ud83d"}'
    for path, body, hdrs in (
        (f"/api/participants/{pid}/answer", survey.encode(), headers),
        (f"/api/participants/{pid}/answer", b'{"answers": {"\\ud800": 1}}', headers),
        (f"/api/admin/participants/{pid}/exclude", reason, h.admin),
    ):
        r = client.post(path, content=body, headers={**hdrs, "Content-Type": "application/json"})
        assert r.status_code == 400 and "surrogate" in r.json()["error"], (path, r.status_code, r.text)
    pid, headers, step = walk_to(client, h, "language")
    r = client.post(f"/api/participants/{pid}/answer", content=feedback, headers=headers)
    assert r.status_code == 400 and "surrogate" in r.json()["error"], r.text
    conn = study_state.connect()
    assert conn.execute("SELECT count(*) FROM participants WHERE excluded=1").fetchone()[0] == 0
    assert conn.execute("SELECT count(*) FROM feedback").fetchone()[0] == 0
    # a pair of surrogates is one character (an emoji), and is taken
    r = client.post(
        f"/api/participants/{pid}/answer",
        content=b'{"feedback": "Move faster \\ud83d\\ude80", "client_ms": 1.0}',
        headers=headers,
    )
    assert r.status_code == 200, r.text


def test_feedback_padded_past_the_limit_is_refused_before_it_is_stored(client, h, study_state):
    from langpref.feedback.language import MAX_FEEDBACK

    pid, headers, step = walk_to(client, h, "language")
    padded = "Move faster. " + "x" * (MAX_FEEDBACK - 31) + " " * 60_000  # under the limit once trimmed
    r = client.post(f"/api/participants/{pid}/answer", json={"feedback": padded, "client_ms": 1.0}, headers=headers)
    assert r.status_code == 400 and "characters long" in r.json()["error"], r.text[:300]
    conn = study_state.connect()
    assert conn.execute("SELECT max(length(body)) FROM answers").fetchone()[0] < 10_000
    r = client.post(
        f"/api/participants/{pid}/answer", json={"feedback": "Move faster.  ", "client_ms": 1.0}, headers=headers
    )
    assert r.status_code == 200
