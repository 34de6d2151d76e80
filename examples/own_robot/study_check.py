"""Run one participant through both studies on the example's recordings, over HTTP only, and check that every video
the study serves is the robot's recorded one (not a render).

It starts `langpref study serve` on the imported dataset with a tiny protocol, answers every step as a person would
(surveys, typed feedback, comparisons, satisfaction, ratings), fetches each step's videos, and compares them with the
dataset's recordings byte for byte (`--video-format mp4` serves the recorded H.264 files as they are). Prints one
JSON object.

    .venv/bin/python examples/own_robot/study_check.py --model models/own_robot --data data/own_robot
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

FEEDBACK = ["Pull the drawer out further.", "Hold the handle more to the left.", "Keep the gripper more open."]
VIDEO = re.compile(r"/videos/traj(\d{6})-")


def start(model: Path, data: Path, db: Path) -> tuple[subprocess.Popen, str]:
    cmd = [
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
        "--video-format",
        "mp4",
        "--pref-queries",
        "4",
        "--rating-every",
        "2",
        "--improve-max-iterations",
        "3",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    for line in proc.stdout:
        m = re.search(r"participants: (http://\S+?)/?$", line.strip())
        if m:
            return proc, m.group(1)
    raise SystemExit(f"the study server exited with status {proc.wait()}")


def answer(step: dict) -> dict:
    """A person's answer to a step, by its kind (DESIGN.md's study contract)."""
    kind, n = step["kind"], step["progress"]["done"]
    if kind == "survey":
        out = {}
        for q in step["questions"]:
            out[q["id"]] = {
                "likert": q.get("max", 5),
                "text": "Fine.",
                "choice": (q.get("options") or [""])[0],
                "multi": (q.get("options") or [""])[:1],
            }[q["type"]]
        return {"answers": out}
    return {
        "language": {"feedback": FEEDBACK[n % len(FEEDBACK)], "client_ms": 4000},
        "comparison": {"choice": n % 2, "client_ms": 3000},
        "satisfaction": {"satisfied": False},
        "rating": {"rating": 3},
    }[kind]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True)
    p.add_argument("--data", type=Path, required=True)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        proc, url = start(args.model, args.data, Path(tmp) / "study.sqlite")
        try:
            with httpx.Client(base_url=url, timeout=120) as http:
                for _ in range(600):
                    try:
                        if http.get("/healthz").status_code == 200:
                            break
                    except httpx.HTTPError:
                        time.sleep(0.1)
                created = http.post("/api/participants", json={}).json()
                headers = {"X-Participant-Token": created["token"]}
                base = f"/api/participants/{created['participant_id']}"
                step = http.get(f"{base}/step", headers=headers).json()
                kinds, videos, same = [], 0, 0
                while step["kind"] != "done" and len(kinds) < 200:
                    for video in step["videos"]:
                        served = http.get(video)
                        while served.status_code == 503:  # not ready yet: the server says when to ask again
                            time.sleep(float(served.headers.get("Retry-After", "1")))
                            served = http.get(video)
                        index = int(VIDEO.search(video).group(1))
                        recorded = (args.data / "videos" / f"{index:06d}.mp4").read_bytes()
                        videos += 1
                        same += served.content == recorded
                    body = {**answer(step), **({"seq": step["seq"]} if "seq" in step else {})}
                    reply = http.post(f"{base}/answer", json=body, headers=headers)
                    if reply.status_code != 200:
                        raise SystemExit(f"{step['kind']} answer refused: {reply.status_code} {reply.text}")
                    kinds.append(step["kind"])
                    step = reply.json()
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    print(
        json.dumps(
            {
                "answers": len(kinds),
                "done": step["kind"] == "done",
                "kinds": {k: kinds.count(k) for k in sorted(set(kinds))},
                "videos_served": videos,
                "videos_identical_to_recording": same,
            }
        )
    )


if __name__ == "__main__":
    main()
