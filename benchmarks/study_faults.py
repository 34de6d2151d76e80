"""Fault and freeze figures of the study server: `python -m benchmarks.study_faults --model M --data D`.

1. 80 concurrent requests for videos that are not made yet (no prerender, a fresh cache): the latency of `/healthz`
   and `POST /api/participants` meanwhile (target: under 1 s), and how the 80 were answered (200 or 503).
2. SIGTERM while a video is being made: seconds until the server has exited (target: under 5 s), and whether any
   process of it is left.
3. SIGKILL of the server while a video is being made: whether any process of it is left 5 s later (target: none).
4. Three parallel 256 MiB uploads to `POST /api/participants`, announced by Content-Length, then three sent chunked:
   how they were answered and the server's resident memory before and at its peak (target: a few MiB more).
5. SIGKILL of a server whose `--on-show` hook is running (a replay that would take 5 minutes and has a child of its
   own): whether any process of the hook is left 5 s later (target: none).

Each server is `langpref study serve` in its own process on loopback, with a fresh database in a temporary folder.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.common import alive, cmdline, descendants, rss_mib, use_egl
from benchmarks.study_load import start_server

CASES = ("freeze", "sigterm", "sigkill", "uploads", "hook_kill")


def _start(model: Path, data: Path, db: Path, split: str) -> tuple[subprocess.Popen, str]:
    return start_server(
        model, data, db, split, env={"LANGPREF_STUDY_ADMIN_TOKEN": "faultbench-admin-token-0123"}, quiet=True
    )


def _video_urls(url: str, n: int) -> list[str]:
    """Video URLs of `n` participants' first Study-1 steps (distinct trajectories where the seeds give them)."""
    import httpx

    urls = []
    with httpx.Client(base_url=url, timeout=30) as c:
        for _ in range(n):
            me = c.post("/api/participants", json={}).json()
            headers = {"X-Participant-Token": me["token"]}
            base = f"/api/participants/{me['participant_id']}"
            step = c.get(f"{base}/step", headers=headers).json()
            answers = {}
            for q in step["questions"]:
                answers[q["id"]] = {
                    "likert": q["min"],
                    "text": "x",
                    "choice": (q["options"] or [None])[0],
                    "multi": q["options"][:1],
                }[q["type"]]
            step = c.post(f"{base}/answer", json={"answers": answers, "seq": step["seq"]}, headers=headers).json()
            urls += step["videos"]
    return urls


def freeze(url: str, requests: int = 80) -> dict[str, Any]:
    import httpx

    videos = sorted(set(_video_urls(url, 8)))

    async def main() -> dict[str, Any]:
        limits = httpx.Limits(max_connections=requests + 10, max_keepalive_connections=requests + 10)
        async with (
            httpx.AsyncClient(base_url=url, timeout=60, limits=limits) as c,
            httpx.AsyncClient(base_url=url, timeout=60) as other,
        ):
            t0 = time.perf_counter()
            tasks = [asyncio.create_task(c.get(videos[k % len(videos)])) for k in range(requests)]
            await asyncio.sleep(0.5)
            lat: dict[str, list[float]] = {"healthz": [], "post_participant": []}
            for _ in range(5):
                for key, method, path in (
                    ("healthz", "GET", "/healthz"),
                    ("post_participant", "POST", "/api/participants"),
                ):
                    t = time.perf_counter()
                    r = await other.request(method, path, json={} if method == "POST" else None)
                    lat[key].append(time.perf_counter() - t)
                    assert r.status_code == 200, r.text
                await asyncio.sleep(0.1)
            done = await asyncio.gather(*tasks)
            return {
                "requests": requests,
                "distinct_videos": len(videos),
                "healthz_max_s": round(max(lat["healthz"]), 3),
                "post_participant_max_s": round(max(lat["post_participant"]), 3),
                "answered": {
                    str(s): sum(r.status_code == s for r in done) for s in sorted({r.status_code for r in done})
                },
                "all_answered_within_s": round(time.perf_counter() - t0, 2),
            }

    return asyncio.run(main())


def _rendering(url: str, proc: subprocess.Popen) -> set[int]:
    import httpx

    video = _video_urls(url, 1)[0]
    httpx.get(url + video, timeout=30)
    deadline = time.time() + 60
    while not (kids := descendants(proc.pid)):
        if time.time() > deadline:
            raise RuntimeError("no render worker started")
        time.sleep(0.05)
    return kids


def stop(model: Path, data: Path, work: Path, split: str, sig: int) -> dict[str, Any]:
    proc, url = _start(model, data, work / f"stop{sig}.sqlite", split)
    kids = _rendering(url, proc) | descendants(proc.pid)
    t = time.time()
    proc.send_signal(sig)
    proc.wait(timeout=120)
    took = time.time() - t
    deadline = time.time() + 5
    while alive(kids) and time.time() < deadline:
        time.sleep(0.05)
    return {
        "signal": signal.Signals(sig).name,
        "exit_s": round(took, 2),
        "returncode": proc.returncode,
        "processes_of_it": len(kids),
        "left_after_5_s": len(alive(kids)),
    }


def uploads(url: str, pid: int, mib: int = 256, parallel: int = 3) -> dict[str, Any]:
    """`parallel` uploads of `mib` MiB each, first with Content-Length, then chunked: their answers and the server's
    memory (before, peak while they ran)."""
    import httpx

    block = b" " * (1 << 20)

    async def body():
        for _ in range(mib):
            yield block

    async def one(c: httpx.AsyncClient, chunked: bool) -> str:
        headers = {"Content-Type": "application/json"}
        if not chunked:
            headers["Content-Length"] = str(mib << 20)
        try:
            r = await c.post("/api/participants", content=body(), headers=headers)
        except httpx.HTTPError as exc:  # the server answered and closed while the body was still being sent
            return type(exc).__name__
        return str(r.status_code)

    async def run(chunked: bool) -> list[str]:
        async with httpx.AsyncClient(base_url=url, timeout=300) as c:
            return await asyncio.gather(*(one(c, chunked) for _ in range(parallel)))

    out: dict[str, Any] = {"uploads": parallel, "mib_each": mib}
    for chunked in (False, True):
        before = rss_mib(pid)
        t0 = time.perf_counter()
        answers, peak = while_sampling(pid, lambda chunked=chunked: asyncio.run(run(chunked)))
        out["chunked" if chunked else "content_length"] = {
            "answered": {a: answers.count(a) for a in sorted(set(answers))},
            "seconds": round(time.perf_counter() - t0, 2),
            "rss_before_mib": round(before),
            "rss_peak_mib": round(max(peak, before)),
        }
    return out


def while_sampling(pid: int, fn) -> tuple[Any, float]:
    """`fn()`, and the peak resident memory of process `pid` (MiB) while it ran, sampled every 20 ms."""
    import threading

    peak, done = [0.0], threading.Event()

    def sample() -> None:
        while not done.is_set():
            peak[0] = max(peak[0], rss_mib(pid))
            done.wait(0.02)

    sampler = threading.Thread(target=sample)
    sampler.start()
    try:
        return fn(), peak[0]
    finally:
        done.set()
        sampler.join()


HANGING_REPLAY = "import subprocess; subprocess.Popen(['sleep', '300']).wait()"


def hook_kill(model: Path, data: Path, work: Path, split: str) -> dict[str, Any]:
    """SIGKILL of a server while its `--on-show` hook runs a replay (with a child of its own): what is left of it."""
    import shlex
    import sys

    hook = shlex.join([sys.executable, "-c", HANGING_REPLAY])
    proc, url = start_server(
        model,
        data,
        work / "hook.sqlite",
        split,
        env={"LANGPREF_STUDY_ADMIN_TOKEN": "faultbench-admin-token-0123"},
        quiet=True,
        extra=("--on-show", hook, "--on-show-timeout", "600"),
    )
    _video_urls(url, 1)  # a step with a video: the hook starts
    deadline = time.time() + 60
    while not any(cmdline(p).startswith("sleep ") for p in descendants(proc.pid)):  # the replay's own child
        if time.time() > deadline:
            proc.kill()
            raise RuntimeError("the hook did not start")
        time.sleep(0.05)
    kids = {p for p in descendants(proc.pid) if cmdline(p).startswith("sleep ") or HANGING_REPLAY in cmdline(p)}
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    deadline = time.time() + 5
    while alive(kids) and time.time() < deadline:
        time.sleep(0.05)
    left = alive(kids)
    for p in left:  # leave nothing behind on the machine that ran the bench
        os.kill(p, signal.SIGKILL)
    return {"hook_processes": len(kids), "left_after_5_s": len(left)}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True)
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--split", default="all")
    p.add_argument("--only", nargs="+", choices=CASES, default=CASES, help="the cases to run (default: all)")
    args = p.parse_args(argv)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if "freeze" in args.only or "uploads" in args.only:
            proc, url = _start(args.model, args.data, work / "freeze.sqlite", args.split)
            try:
                if "freeze" in args.only:
                    out["freeze"] = freeze(url)
                if "uploads" in args.only:
                    out["uploads"] = uploads(url, proc.pid)
            finally:
                proc.terminate()
                proc.wait(timeout=60)
        if "sigterm" in args.only:
            out["sigterm"] = stop(args.model, args.data, work, args.split, signal.SIGTERM)
        if "sigkill" in args.only:
            out["sigkill"] = stop(args.model, args.data, work, args.split, signal.SIGKILL)
        if "hook_kill" in args.only:
            out["hook_kill"] = hook_kill(args.model, args.data, work, args.split)
    print(json.dumps(out), flush=True)
    return out


if __name__ == "__main__":
    use_egl()
    main()
