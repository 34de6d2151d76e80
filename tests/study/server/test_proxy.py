"""The documented TLS reverse proxy (src/langpref/study/deploy/nginx-study.conf) passes `nginx -t`, and a study
behind it works: a participant joins and answers over HTTPS, with the browser's Origin accepted; a cross-site page's
POST is refused; a client cannot pass itself off as another address to the resume-code limit. Cross-site requests are
refused without a proxy too. Needs Debian's nginx (skipped without it, except under CI) and openssl."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from dataclasses import replace
from pathlib import Path

import httpx
import pytest

CONF = Path(__file__).resolve().parents[3] / "src" / "langpref" / "study" / "deploy" / "nginx-study.conf"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def nginx_bin():
    found = shutil.which("nginx") or ("/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists() else None)
    if found is None or shutil.which("openssl") is None:
        if os.environ.get("CI"):
            pytest.fail("nginx and openssl are needed for this test in CI: apt-get install nginx openssl")
        pytest.skip("nginx is not installed (apt-get install nginx)")
    return found


def local_config(tmp_path: Path, upstream: int, https: int, http: int) -> Path:
    """The shipped site file, made to run here: its ports, a self-signed certificate, a prefix in tmp_path."""
    cert, key = tmp_path / "fullchain.pem", tmp_path / "privkey.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=study.lab.example",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
    )
    site = CONF.read_text()
    for old, new in (
        ("127.0.0.1:8000", f"127.0.0.1:{upstream}"),
        ("listen 443 ssl", f"listen 127.0.0.1:{https} ssl"),
        ("listen 80", f"listen 127.0.0.1:{http}"),
        ("/etc/ssl/langpref-study/fullchain.pem", str(cert)),
        ("/etc/ssl/langpref-study/privkey.pem", str(key)),
    ):
        assert old in site, old
        site = site.replace(old, new)
    (tmp_path / "site.conf").write_text(site)
    (tmp_path / "logs").mkdir(exist_ok=True)
    main = tmp_path / "nginx.conf"
    main.write_text(f"""daemon off;
master_process off;
pid {tmp_path}/nginx.pid;
error_log stderr warn;
events {{ worker_connections 64; }}
http {{
    access_log off;
    client_body_temp_path {tmp_path}/body;
    proxy_temp_path {tmp_path}/proxy;
    include {tmp_path}/site.conf;
}}
""")
    return main


def test_cross_site_posts_are_refused(client, h):
    site = {"Origin": "https://evil.example"}
    r = client.post("/api/participants", content=b"{}", headers={**site, "Content-Type": "text/plain"})
    assert r.status_code == 403 and "cross-site" in r.json()["error"]
    r = client.post("/api/participants", content=b"{}", headers={"Origin": "null"})
    assert r.status_code == 403
    r = client.post("/api/participants", content=b"{}", headers={"Referer": "https://evil.example/page"})
    assert r.status_code == 403
    assert client.post("/api/participants", json={}, headers={"Origin": "http://testserver"}).status_code == 200
    assert client.post("/api/participants", json={}).status_code == 200  # tools send no Origin
    assert client.get("/healthz", headers=site).status_code == 200  # reading is not changing


def test_the_documented_nginx_proxy_serves_the_study_over_tls(nginx_bin, engine, h, tmp_path):
    from langpref.study.server.serve import BackgroundServer, build_state
    from langpref.study.server.state import MAX_RESUME_FAILURES

    cfg = replace(  # as documented: its public name, and nginx named as the proxy whose X-Forwarded-For counts
        h.serve_config(tmp_path / "p.sqlite"), allowed_hosts=("study.lab.example",), trusted_proxies=("127.0.0.1",)
    )
    state = build_state(cfg, engine=engine, progress=False)
    with BackgroundServer(state) as url:
        upstream = int(url.rsplit(":", 1)[1])
        https, http = free_port(), free_port()
        conf = local_config(tmp_path, upstream, https, http)
        check = subprocess.run(
            [nginx_bin, "-t", "-p", str(tmp_path), "-c", str(conf)], check=False, capture_output=True, text=True
        )
        assert check.returncode == 0, check.stderr
        proc = subprocess.Popen([nginx_bin, "-p", str(tmp_path), "-c", str(conf)], stderr=subprocess.PIPE, text=True)
        try:
            base = f"https://127.0.0.1:{https}"
            with httpx.Client(base_url=base, verify=False, timeout=10) as c:
                deadline = time.time() + 20
                while True:
                    try:
                        if c.get("/healthz").status_code == 200:
                            break
                    except httpx.HTTPError:
                        pass
                    assert time.time() < deadline and proc.poll() is None, "nginx did not come up"
                    time.sleep(0.05)
                page = {"Origin": base}  # what a browser sends from the study's own page behind the proxy
                r = c.post("/api/participants", json={}, headers=page)
                assert r.status_code == 200, r.text
                me = r.json()
                auth = {**page, "X-Participant-Token": me["token"]}
                step = c.get(f"/api/participants/{me['participant_id']}/step", headers=auth).json()
                r = c.post(f"/api/participants/{me['participant_id']}/answer", json=h.answer_for(step), headers=auth)
                assert r.status_code == 200 and r.json()["kind"] == "language"
                r = c.post("/api/participants", json={}, headers={"Origin": "https://evil.example"})
                assert r.status_code == 403
                assert c.get("/").headers["strict-transport-security"]
                # the public name passes through the proxy; a DNS-rebinding page's name does not
                assert c.get("/healthz", headers={"Host": "study.lab.example"}).status_code == 200
                assert c.get("/healthz", headers={"Host": "rebind.evil.example"}).status_code == 400
                # nginx replaces the X-Forwarded-For a client sends: wrong resume codes count against its address
                # however the client names itself
                wrong = [
                    c.post(
                        "/api/participants/resume",
                        json={"code": "BBBBB-BBBBB"},
                        headers={**page, "X-Forwarded-For": f"198.51.100.{i}"},
                    ).status_code
                    for i in range(MAX_RESUME_FAILURES + 1)
                ]
                assert wrong == [404] * MAX_RESUME_FAILURES + [429]
            r = httpx.get(f"http://127.0.0.1:{http}/study", follow_redirects=False)
            assert r.status_code == 301 and r.headers["location"].startswith("https://")
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    state.videos.close()
