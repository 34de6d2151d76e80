"""Simulated participants that run whole study sessions through the HTTP API (load test, benchmark, demo data).

Each simulated participant is a thread with its own HTTP connection. It answers surveys with random valid answers
and, when it is given the dataset, answers the robot like the library's synthetic humans (`langpref.feedback.language`
and `.comparison`): a random reward w over the normalised features, language feedback by Eq. 10 with the bank's test
phrasings, comparisons by Eq. 11, "satisfied" once the shown trajectory is within 10% of the best of the study set,
and ratings 1 + 4 x the normalised reward. It reads which trajectory a video shows from the video's name
(`trajNNNNNN-...`), a shortcut only a simulation takes. Without the dataset it answers at random. The time per query
it reports is the time it really took from receiving the step to sending the answer (its optional think time
included).
"""

from __future__ import annotations

import re
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

_INDEX = re.compile(r"/videos/traj(\d{6})-")


@dataclass
class SimConfig:
    participants: int = 20
    """Simulated participants, all started at once."""
    seed: int = 0
    think_ms: tuple[float, float] = (0.0, 0.0)
    """Uniform range of the pause before each answer (0, 0: answer at once, the heaviest load)."""
    timeout_s: float = 60.0
    """Per request."""
    deadline_s: float = 600.0
    """The whole run stops by itself after this long."""


class _World:
    """What a simulated participant knows: normalised features of the study set and the bank's test phrasings."""

    def __init__(self, data_dir: str | Path, split: str):
        from langpref.dataset.storage import load_dataset
        from langpref.feedback.space import FeatureScale, phrase_table
        from langpref.language.bank import load_bank

        ds = load_dataset(data_dir)
        feats = np.asarray(ds.features, dtype=np.float64)
        self.theta = FeatureScale.fit(feats[ds.split("train")])(feats)
        self.study = np.arange(len(ds)) if split == "all" else np.asarray(ds.split(split))
        self.feature_names = ds.feature_names
        self.phrases = phrase_table(
            load_bank(ds.env), "test", ds.feature_names, lambda texts: np.zeros((len(texts), 1))
        )


def _answer_survey(step: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    answers: dict[str, Any] = {}
    for q in step["questions"]:
        if q["type"] == "likert":
            answers[q["id"]] = int(rng.integers(q["min"], q["max"] + 1))
        elif q["type"] == "text":
            if q.get("required", True) or rng.random() < 0.3:
                answers[q["id"]] = "27" if q["id"] == "age" else "A simulated answer."
        elif q["type"] == "choice":
            answers[q["id"]] = str(rng.choice(q["options"]))
        else:
            opts = [o for o in q["options"] if o != "None of them"]
            pick = [o for o in opts if rng.random() < 0.5]
            answers[q["id"]] = pick or ["None of them"]
    return {"answers": answers}


class SimParticipant:
    def __init__(self, base_url: str, cfg: SimConfig, number: int, world: _World | None):
        import socket

        import httpx

        # TCP_NODELAY as browsers do: else Nagle's algorithm holds the body behind the headers for a delayed ACK (40 ms)
        transport = httpx.HTTPTransport(socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)])
        self.client = httpx.Client(base_url=base_url, timeout=cfg.timeout_s, transport=transport)
        self.cfg = cfg
        self.rng = np.random.default_rng([cfg.seed, number])
        self.world = world
        self.latency: dict[str, list[float]] = {}
        self.answers = 0
        self.errors: list[str] = []
        self.participant_id = ""
        if world is not None:
            from langpref.feedback.comparison import ComparisonHuman
            from langpref.feedback.humans import sample_weights
            from langpref.feedback.language import LanguageHuman

            w = sample_weights(world.theta.shape[1], self.rng)
            self.reward = world.theta @ w
            ref = self.reward[world.study]
            self.norm = (self.reward - ref.min()) / max(float(ref.max() - ref.min()), 1e-12)
            self.lang = LanguageHuman(w, world.theta, world.phrases, world.study, world.feature_names, 1.0, self.rng)
            self.comp = ComparisonHuman(w, world.theta, 1.0, self.rng)

    @staticmethod
    def _shown(step: dict[str, Any]) -> list[int]:
        return [int(m.group(1)) for m in map(_INDEX.search, step["videos"]) if m]

    def _body(self, step: dict[str, Any], received: float) -> dict[str, Any]:
        from langpref.feedback.comparison import ComparisonQuery
        from langpref.feedback.language import LanguageQuery

        kind, shown, rng, world = step["kind"], self._shown(step), self.rng, self.world
        if kind == "survey":
            return _answer_survey(step, rng)
        lo, hi = self.cfg.think_ms
        if hi > 0:
            time.sleep(float(rng.uniform(lo, hi)) / 1000.0)
        client_ms = (time.perf_counter() - received) * 1000.0
        if kind == "language":
            text = (
                self.lang.answer(LanguageQuery(shown[0])).text
                if world
                else str(rng.choice(["Move faster.", "Go higher.", "Slow down.", "Stay lower, please"]))
            )
            return {"feedback": text, "client_ms": round(client_ms, 1), "seq": step["seq"]}
        if kind == "comparison":
            choice = self.comp.answer(ComparisonQuery(*shown)).choice if world else int(rng.integers(2))
            return {"choice": int(choice), "client_ms": round(client_ms, 1), "seq": step["seq"]}
        if kind == "satisfaction":
            return {"satisfied": bool(self.norm[shown[0]] >= 0.9) if world else bool(rng.random() < 0.3)}
        return {"rating": int(1 + round(4 * self.norm[shown[0]])) if world else int(rng.integers(1, 6))}

    def run(self, stop_at: float) -> None:
        try:
            r = self.client.post("/api/participants", json={})
            r.raise_for_status()
            me = r.json()
            self.participant_id = me["participant_id"]
            headers = {"X-Participant-Token": me["token"]}
            path = f"/api/participants/{self.participant_id}"
            step = self.client.get(f"{path}/step", headers=headers).json()
            while step["kind"] != "done":
                if time.time() > stop_at:
                    self.errors.append("deadline reached")
                    return
                received = time.perf_counter()
                body = {**self._body(step, received), "seq": step["seq"]}  # every answer names its step
                t0 = time.perf_counter()
                r = self.client.post(f"{path}/answer", json=body, headers=headers)
                self.latency.setdefault(step["kind"], []).append((time.perf_counter() - t0) * 1000.0)
                if r.status_code != 200:
                    self.errors.append(f"{r.status_code} {r.text[:200]}")
                    return
                self.answers += 1
                step = r.json()
        except Exception as exc:  # noqa: BLE001 (reported in the summary)
            self.errors.append(f"{type(exc).__name__}: {exc}")
        finally:
            self.client.close()


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def simulate(
    base_url: str, cfg: SimConfig | None = None, data_dir: str | Path | None = None, split: str = "test"
) -> dict[str, Any]:
    """Run `cfg.participants` simulated participants at once against a study server; latency per answer kind."""
    cfg = cfg or SimConfig()
    world = _World(data_dir, split) if data_dir is not None else None
    sims = [SimParticipant(base_url, cfg, i, world) for i in range(cfg.participants)]
    stop_at = time.time() + cfg.deadline_s
    threads = [threading.Thread(target=s.run, args=(stop_at,), daemon=True) for s in sims]
    start = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=max(1.0, stop_at - time.time() + cfg.timeout_s))
    wall = time.perf_counter() - start
    kinds = sorted({k for s in sims for k in s.latency})
    latency = {}
    for k in kinds:
        vals = [v for s in sims for v in s.latency.get(k, [])]
        latency[k] = {
            "n": len(vals),
            "p50_ms": percentile(vals, 50),
            "p95_ms": percentile(vals, 95),
            "max_ms": max(vals),
        }
    return {
        "participants": cfg.participants,
        "completed": sum(1 for s in sims if not s.errors),
        "answers": sum(s.answers for s in sims),
        "wall_s": wall,
        "latency": latency,
        "errors": [e for s in sims for e in s.errors][:20],
        "per_participant": {s.participant_id: s.answers for s in sims if s.participant_id},
        "think_ms": list(cfg.think_ms),
    }
