"""What the server refuses before a request reaches the study (`langpref.study.server.guard`): bodies over the limit
before they are read (by Content-Length, or counted as they stream in chunked), JSON nested too deeply, Host names that
are not the study's (DNS rebinding), wrong resume codes per client, so that one client cannot lock resume for all, and
sign-ups per client."""

from __future__ import annotations

import json
import socket
import threading

import pytest

from langpref.study.server.guard import MAX_BODY, HostCheck, RateLimiter, client_key, depth

RECV_S = 10.0
"""How long a test waits for the server's answer to a body it never finishes sending: without the guard the server
waits for the rest of the body, and the test fails at this timeout."""


@pytest.fixture
def live(engine, h, tmp_path):
    from langpref.study.server.serve import BackgroundServer, build_state

    state = build_state(h.serve_config(tmp_path / "guard.sqlite"), engine=engine, progress=False)
    with BackgroundServer(state) as url:
        yield state, int(url.rsplit(":", 1)[1])
    state.videos.close()


def response(sock: socket.socket) -> tuple[int, dict]:
    """The status and JSON body of the response on `sock` (it may close the connection after it)."""
    sock.settimeout(RECV_S)
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = sock.recv(65536)
        assert chunk, "the server closed the connection without answering"
        buf += chunk
    head, rest = buf.split(b"\r\n\r\n", 1)
    lines = head.decode("latin-1").split("\r\n")
    headers = {k.lower(): v.strip() for k, v in (x.split(":", 1) for x in lines[1:])}
    n = int(headers["content-length"])
    while len(rest) < n:
        chunk = sock.recv(65536)
        assert chunk
        rest += chunk
    return int(lines[0].split()[1]), json.loads(rest[:n])


def test_a_body_announced_over_the_limit_is_refused_before_it_is_sent(live):
    state, port = live
    with socket.create_connection(("127.0.0.1", port), timeout=RECV_S) as sock:
        head = (
            "POST /api/participants HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            f"Content-Length: {256 * 1024 * 1024}\r\n\r\n"
        )
        sock.sendall(head.encode() + b"{" + b" " * 1000)  # 256 MiB announced, a kilobyte sent
        status, body = response(sock)
    assert status == 413 and set(body) == {"error"} and "64 KiB" in body["error"]
    assert state.connect().execute("SELECT count(*) FROM participants").fetchone()[0] == 0


def test_a_chunked_body_is_refused_once_it_passes_the_limit(live):
    state, port = live
    with socket.create_connection(("127.0.0.1", port), timeout=RECV_S) as sock:
        head = (
            "POST /api/participants HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            "Transfer-Encoding: chunked\r\n\r\n"
        )
        sock.sendall(head.encode())
        chunk = b" " * 16384
        for _ in range(MAX_BODY // len(chunk) + 2):  # past the limit, and the last chunk never comes
            sock.sendall(f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n")
        status, body = response(sock)
    assert status == 413 and set(body) == {"error"}
    assert state.connect().execute("SELECT count(*) FROM participants").fetchone()[0] == 0


def test_a_content_length_that_is_no_number_is_refused():
    import asyncio

    from langpref.study.server.guard import HttpError, read_body

    class Request:
        def __init__(self, length: str):
            self.headers = {"content-length": length}

        async def stream(self):
            yield b"{}"

    assert asyncio.run(read_body(Request("2"))) == b"{}"
    for length in ("abc", "\uff11\uff12", "-1"):  # full-width digits pass str.isdigit()
        with pytest.raises(HttpError) as exc:
            asyncio.run(read_body(Request(length)))
        assert exc.value.status == 400


def test_deep_nesting_is_a_one_line_400_wherever_it_is(client, h):
    pid, headers = h.join(client)
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    answers = h.answer_for(step)
    under_question = json.dumps({**answers, "answers": {**answers["answers"], "race": "NESTED"}})
    under_unknown = json.dumps({**answers, "extra": "NESTED"})  # a field that is dropped, after parsing
    for level in (40, 500, 700, 980):
        nested = "[" * level + "]" * level
        for body in (under_question, under_unknown):
            r = client.post(
                f"/api/participants/{pid}/answer", content=body.replace('"NESTED"', nested).encode(), headers=headers
            )
            assert r.status_code == 400, (level, r.status_code, r.text[:200])
            assert set(r.json()) == {"error"} and "nested too deeply" in r.json()["error"]
    assert client.get(f"/api/participants/{pid}/step", headers=headers).json()["seq"] == step["seq"]


def test_a_body_made_to_be_slow_is_refused_before_the_participant_lock(client, h, study_state):
    """21,000 empty lists fit in 63 KB and took 210 ms to handle while holding the participant's lock stripe (which
    other participants share): such bodies are refused (one line) while that lock is held elsewhere, so none of their
    work happens under it; a valid answer is then taken."""
    from langpref.study.server.guard import MAX_VALUES

    pid, headers = h.join(client)
    step = client.get(f"/api/participants/{pid}/step", headers=headers).json()
    lists = ",".join(["[]"] * 21_000)
    many = json.dumps({**h.answer_for(step), "extra": list(range(MAX_VALUES))})
    bodies = [f"[{lists}]", f'{{"feedback": [{lists}], "client_ms": 1}}', f'{{"answers": {{"age": [{lists}]}}}}', many]
    assert all(len(b) < 64 * 1024 for b in bodies)
    url, sent = f"/api/participants/{pid}/answer", {**headers, "Content-Type": "application/json"}
    answered, done = [], threading.Event()

    def send():
        try:
            answered.extend(client.post(url, content=body.encode(), headers=sent) for body in bodies)
        finally:
            done.set()

    with study_state.lock(pid):  # an answer of another participant of the stripe is being handled
        threading.Thread(target=send, daemon=True).start()
        assert done.wait(60), "a body refused for its shape waited for the participant's lock"
    assert [r.status_code for r in answered] == [400] * len(bodies), [r.text[:100] for r in answered]
    for r in answered:
        assert set(r.json()) == {"error"} and "\n" not in r.json()["error"]
    assert "too many values" in answered[1].json()["error"] and "too many values" in answered[3].json()["error"]
    r = client.post(url, json=h.answer_for(step), headers=headers)
    assert r.status_code == 200 and r.json()["seq"] == step["seq"] + 1, r.text


def test_shape_is_checked_in_bounded_steps():
    from langpref.study.server.guard import HttpError, check_shape

    with pytest.raises(HttpError, match="too many values"):
        check_shape([[] for _ in range(10**6)])  # refused by its length, none of its items looked at
    with pytest.raises(HttpError, match="nested too deeply"):
        check_shape({"a": [[[1]]]}, max_depth=3)
    check_shape({"a": [[[1]]]}, max_depth=4)
    check_shape({"a": list(range(99))}, max_values=100)


def test_depth_is_measured_without_recursion():
    value: list = []
    for _ in range(100_000):
        value = [value]
    assert depth(value) == 100_001 and depth({"a": [1, {"b": 2}]}) == 3 and depth("x") == 0


def test_clean_text_refuses_deep_values_without_recursion():
    from langpref.study.protocol.flow import AnswerError, clean_text

    value: dict = {}
    for _ in range(100_000):
        value = {"k": value}
    with pytest.raises(AnswerError, match="nested too deeply"):
        clean_text(value)
    assert clean_text({"a": ["x\u202ey", {"b": 1}], "c": None}) == {"a": ["xy", {"b": 1}], "c": None}


# ---- Host ----


def test_a_rebinding_host_is_refused_and_the_study_names_pass(client, study_state):
    evil = {"Host": "rebind.evil.example:8000", "Origin": "http://rebind.evil.example:8000"}
    r = client.post("/api/participants", json={}, headers=evil)
    assert r.status_code == 400 and set(r.json()) == {"error"} and "--allowed-hosts" in r.json()["error"]
    assert client.get("/healthz", headers={"Host": "rebind.evil.example"}).status_code == 400
    assert study_state.connect().execute("SELECT count(*) FROM participants").fetchone()[0] == 0
    for host in ("localhost:8000", "127.0.0.1:8000", "[::1]:8000", "192.168.1.5:8000", "study.localhost"):
        r = client.post("/api/participants", json={}, headers={"Host": host, "Origin": f"http://{host}"})
        assert r.status_code == 200, (host, r.text)


def test_host_check_takes_the_bind_host_allowed_names_and_origins():
    check = HostCheck(["labpc.local"], bind_host="study.lab.example", origins=["https://proxy.lab.example"])
    for ok in ("LABPC.local:8000", "study.lab.example", "proxy.lab.example:443", "localhost", "[::1]", "10.0.0.7"):
        assert check.refused(ok) is None, ok
    for bad in ("evil.example", "localhost.evil.example", "labpc.local.evil.example", ""):
        assert check.refused(bad), bad
    assert HostCheck().refused(None) is None  # HTTP/1.0 without Host: a tool, not a browser


# ---- resume codes ----


def test_one_clients_wrong_codes_do_not_lock_the_others_out(client, h, study_state):
    from langpref.study.server.guard import HttpError
    from langpref.study.server.participants import resume
    from langpref.study.server.state import MAX_RESUME_FAILURES

    pid, headers = h.join(client)
    code = client.get(f"/api/participants/{pid}/step", headers=headers).json()["resume_code"]
    wrong = json.dumps({"code": "BBBBB-BBBBB"}).encode()
    for _ in range(MAX_RESUME_FAILURES):
        with pytest.raises(HttpError) as exc:
            resume(study_state, wrong, "203.0.113.7")
        assert exc.value.status == 404
    for body in (wrong, json.dumps({"code": code}).encode()):  # that client is held back, even with a right code
        with pytest.raises(HttpError) as exc:
            resume(study_state, body, "203.0.113.7")
        assert exc.value.status == 429
    # everyone else: the right code restores the session, a wrong one is a plain 404
    assert resume(study_state, json.dumps({"code": code}).encode(), "198.51.100.2")["participant_id"] == pid
    with pytest.raises(HttpError) as exc:
        resume(study_state, wrong, "198.51.100.3")
    assert exc.value.status == 404
    # over HTTP the client is the connection's address
    assert client.post("/api/participants/resume", json={"code": code}).status_code == 200


def test_one_code_restores_a_bounded_number_of_sessions_a_minute(client, h, study_state):
    from langpref.study.server.state import MAX_RESUMES_PER_CODE

    pid, headers = h.join(client)
    code = client.get(f"/api/participants/{pid}/step", headers=headers).json()["resume_code"]
    statuses = [client.post("/api/participants/resume", json={"code": code}).status_code for _ in range(15)]
    assert statuses == [200] * MAX_RESUMES_PER_CODE + [429] * (15 - MAX_RESUMES_PER_CODE)


def test_sign_ups_are_limited_per_client(client, study_state):
    """Issue 44: 70 made-up participants from one client in 2.4 s took the robot's and the simulator's turns. One
    client starts at most `--signups-per-client` (20) in 10 minutes; other clients are not held back."""
    from langpref.study.server.guard import HttpError
    from langpref.study.server.participants import create_participant
    from langpref.study.server.settings import ServeConfig

    limit = ServeConfig.signups_per_client
    statuses = [client.post("/api/participants", json={}).status_code for _ in range(limit + 3)]
    assert statuses == [200] * limit + [429] * 3
    r = client.post("/api/participants", json={}, headers={"X-Forwarded-For": "198.51.100.9"})  # no named proxy
    assert r.status_code == 429 and "try again in 10 min" in r.json()["error"]
    assert 590 <= int(r.headers["retry-after"]) <= 600
    assert create_participant(study_state, b"{}", "198.51.100.2")["participant_id"]  # another client
    with pytest.raises(HttpError) as exc:
        create_participant(study_state, b"{}", "testclient")
    assert exc.value.status == 429
    count = study_state.connect().execute("SELECT count(*) FROM participants").fetchone()[0]
    assert count == limit + 1  # nothing stored for a refused sign-up


def test_a_rate_limiter_takes_an_event_only_below_its_limit():
    limiter = RateLimiter(2, window_s=600)
    assert [limiter.take("a", now=t) for t in (0.0, 1.0, 2.0)] == [0, 0, 598]
    assert limiter.take("b", now=2.0) == 0 and limiter.take("a", now=600.0) == 0


def _wrong_codes(url: str, forwarded: list[str | None]) -> list[int]:
    """The statuses of wrong resume codes sent to a real server, each with its X-Forwarded-For (None: without)."""
    import httpx

    with httpx.Client(base_url=url, timeout=30) as c:
        return [
            c.post(
                "/api/participants/resume",
                json={"code": "BBBBB-BBBBB"},
                headers={"X-Forwarded-For": xff} if xff else {},
            ).status_code
            for xff in forwarded
        ]


def test_forwarded_addresses_count_only_from_the_proxies_the_lab_names(engine, h, tmp_path):
    """30 wrong codes from this machine, each with another X-Forwarded-For, were 30 clients to the server (uvicorn
    takes the header from loopback by default) and never a 429: without --trusted-proxy the connection's address is
    the client; with it, the address its proxy forwards is."""
    from dataclasses import replace

    from langpref.study.server.serve import BackgroundServer, build_state
    from langpref.study.server.state import MAX_RESUME_FAILURES

    rotating = [f"198.51.100.{i}" for i in range(30)]
    n = MAX_RESUME_FAILURES
    state = build_state(h.serve_config(tmp_path / "direct.sqlite"), engine=engine, progress=False)
    try:
        with BackgroundServer(state) as url:
            assert _wrong_codes(url, rotating) == [404] * n + [429] * (30 - n)
    finally:
        state.videos.close()
    cfg = replace(h.serve_config(tmp_path / "proxied.sqlite"), trusted_proxies=("127.0.0.1",))
    cfg.validate()
    state = build_state(cfg, engine=engine, progress=False)
    try:
        with BackgroundServer(state) as url:
            assert _wrong_codes(url, rotating) == [404] * 30  # 30 participants behind the proxy, one code each
            # one of them, whatever it puts before the address the proxy appends; the others are not held back
            spoofed = [f"203.0.113.{i}, 192.0.2.9" for i in range(n + 1)]
            assert _wrong_codes(url, [*spoofed, "192.0.2.10", None]) == [404] * n + [429, 404, 404]
    finally:
        state.videos.close()


def test_trusted_proxies_name_the_client_only_from_a_named_proxy():
    from langpref.study.server.guard import TrustedProxies

    none = TrustedProxies()
    assert none.client("127.0.0.1", ["10.1.2.3"]) == "127.0.0.1" and none.client(None, ["10.1.2.3"]) is None
    local = TrustedProxies(["127.0.0.1", "::1", "10.0.0.0/24"])
    assert local.client("127.0.0.1", ["198.51.100.7"]) == "198.51.100.7"
    assert local.client("::ffff:127.0.0.1", ["198.51.100.7"]) == "198.51.100.7"
    assert local.client("::1", ["203.0.113.1, 198.51.100.7, 10.0.0.5"]) == "198.51.100.7"  # chain of two proxies
    assert local.client("127.0.0.1", ["203.0.113.1", "[2001:db8::1]:4711"]) == "2001:db8::1"
    assert local.client("127.0.0.1", ["1.2.3.4:80"]) == "1.2.3.4"
    assert local.client("127.0.0.1", []) == "127.0.0.1" and local.client("127.0.0.1", [" , "]) == "127.0.0.1"
    assert local.client("192.0.2.1", ["198.51.100.7"]) == "192.0.2.1"  # not a proxy: its header is ignored


def test_a_trusted_proxy_that_is_no_address_is_refused_in_one_line(h, tmp_path):
    from dataclasses import replace

    from langpref.errors import LangprefError

    cfg = replace(h.serve_config(tmp_path / "x.sqlite"), trusted_proxies=("127.0.0.1", " 10.0.0.0/8 ", "::1"))
    cfg.validate()
    assert cfg.trusted_proxies == ("127.0.0.1", "10.0.0.0/8", "::1")
    for bad in ("*", "proxy.lab.example", "10.0.0.0/99", ""):
        with pytest.raises(LangprefError, match="--trusted-proxy") as exc:
            replace(cfg, trusted_proxies=(bad,)).validate()
        assert "\n" not in str(exc.value)


def test_rate_limiter_forgets_old_events_and_bounds_its_keys():
    limiter = RateLimiter(2, window_s=60.0, max_keys=3)
    limiter.add("a", now=0.0)
    limiter.add("a", now=1.0)
    assert limiter.blocked("a", now=2.0) and not limiter.blocked("b", now=2.0)
    assert not limiter.blocked("a", now=60.5)  # the first one has left the window
    for key in "bcde":
        limiter.add(key, now=3.0)
    assert len(limiter._events) == 3


def test_client_key_groups_an_ipv6_network():
    assert client_key("2001:db8::1") == client_key("2001:db8::ffff") == "2001:db8::/64"
    assert client_key("::ffff:192.0.2.1") == "192.0.2.1" and client_key("192.0.2.1") == "192.0.2.1"
    assert client_key(None) == "?" and client_key("testclient") == "testclient"
