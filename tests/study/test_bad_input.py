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
    from langpref.study.serve import BackgroundServer, build_state

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
