"""Simulated participants that run whole study sessions through the HTTP API (load test, benchmark, demo data).

Each simulated participant is a thread with its own HTTP connection. It answers surveys with random valid answers
and, when it is given the dataset, answers the robot like the library's synthetic humans (`langpref.feedback.language`
and `.comparison`): a random reward w over the normalised features, and for every feedback kind the kind's own
synthetic human (`FeedbackKind.make_human`, with the bank's test phrasings: language by Eq. 10, comparisons by Eq. 11,
a plugin kind by its own), "satisfied" once the shown trajectory is within 10% of the best of the study set
(`satisfied_at`), and ratings 1 + 4 x the normalised reward. It reads which trajectory a video shows from the
video's name (`trajNNNNNN-...`, `genNNNNNN-...`), a shortcut only a simulation takes. Without the dataset it answers
at random by the kind's widget (`StudyPage.widget`, sent in the step's `widget`): a shown trajectory at random for
a choice, one of a few sentences for a text. The time per query it reports is the time it really took from receiving
the step to sending the answer (its optional think time included). A participant's reward is fixed by the seed and
its number: w = `sample_weights(D, np.random.default_rng([seed, number]))`.

Study 1 with generated candidates (`study serve --improve-candidates generated`): the trajectories the server makes in
the simulator are numbered from len(dataset) on (videos `genNNNNNN-...`). Given the server's database (`db`; the
simulation runs on the server's machine), a simulated participant looks each one up in its table `generated` (id ->
index in the generated dataset, default `DB.generated/`) and reads its features there, scaled with the study set's
train-split `FeatureScale`, so it answers about it by Eq. 10, satisfaction and rating like about any other. One the
server has not made yet is waited for as the page waits for it: its video is asked for again after each 503's
Retry-After until it plays. Any answer the server refuses with 503 and Retry-After is sent again after that many
seconds (never longer, never past the deadline).
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from langpref.errors import LangprefError

if TYPE_CHECKING:
    from langpref.feedback.kind import FeedbackKind

_INDEX = re.compile(r"/videos/(?:traj|gen)(\d{6})-")
SAYINGS = ("Move faster.", "Go higher.", "Slow down.", "Stay lower, please")
"""What a participant without the dataset types into a text widget, one at random."""


@dataclass
class SimConfig:
    participants: int = 20
    """Simulated participants, all started at once."""
    seed: int = 0
    """Seed of the synthetic humans (participant k's reward and answers come from the seed and k)."""
    think_ms: tuple[float, float] = (0.0, 0.0)
    """Uniform range of the pause before each answer in ms, LO,HI (0,0: answer at once, the heaviest load)."""
    timeout_s: float = 60.0
    """Seconds a request may take."""
    deadline_s: float = 600.0
    """Seconds after which the whole run stops by itself."""
    temperature: float = 1.0
    """Temperature of the synthetic humans' Eq. 10 (1: the paper's); near 0 they name the feature whose change
    raises their reward most."""
    satisfied_at: float = 0.9
    """Study 1: a synthetic human is satisfied with a trajectory whose normalised reward is at least this (0: the
    worst, 1: the best of the study set; a generated trajectory can exceed 1)."""


class _World:
    """What a simulated participant knows: normalised features of the study set (rows of `theta` in dataset order)
    and the bank's test phrasings; given the server's database, also those of the trajectories the server generates
    (`row` appends them as they are made)."""

    def __init__(
        self, data_dir: str | Path, split: str, db: str | Path | None = None, generated_dir: str | Path | None = None
    ):
        from langpref.dataset.storage import load_dataset
        from langpref.feedback.space import FeatureScale, phrase_table
        from langpref.language.bank import load_bank

        ds = load_dataset(data_dir)
        feats = np.asarray(ds.features, dtype=np.float64)
        self.dataset = ds
        self.scale = FeatureScale.fit(feats[ds.split("train")])
        self.theta = self.scale(feats)
        self.study = np.arange(len(ds)) if split == "all" else np.asarray(ds.split(split))
        self.feature_names = ds.feature_names
        self.phrases = phrase_table(
            load_bank(ds.env), "test", ds.feature_names, lambda texts: np.zeros((len(texts), 1))
        )
        self.db = None if db is None else Path(db)
        self.generated_dir = Path(generated_dir) if generated_dir else Path(f"{db}.generated") if db else None
        self._rows: dict[int, int] = {}
        self._lock = threading.Lock()

    def row(self, index: int) -> int | None:
        """The row of `theta` of trajectory `index` as the server numbers it: a dataset index is its own row; a
        generated one (index >= len(dataset)) gets a row once the server has made it, None until then."""
        index = int(index)
        if index < len(self.dataset):
            return index
        with self._lock:
            if index not in self._rows:
                self._read_generated(index)
            return self._rows.get(index)

    def _read_generated(self, index: int) -> None:
        """Append the rows of the generated trajectories made since the last look (call with `_lock` held): the
        database's table `generated` says where each is in the generated dataset, whose trajectories have the study
        set's task and horizon (`GeneratedStore` refuses others), so the study set's metadata reads them (its own
        meta.json is rewritten as it grows, a trajectory file never is)."""
        from langpref.dataset.storage import load_trajectory
        from langpref.study.protocol import db as sdb

        if self.db is None or self.generated_dir is None:
            raise LangprefError(
                f"the server shows trajectory {index}, one it generated (--improve-candidates generated): give the "
                "simulation the server's --db (and --generated DIR if the server was given one)"
            )
        conn = sdb.open_existing(self.db)
        try:
            made = conn.execute("SELECT id, store_index FROM generated ORDER BY id").fetchall()
        finally:
            conn.close()
        new = [(int(r["id"]), int(r["store_index"])) for r in made if int(r["id"]) not in self._rows]
        if not new:
            return
        try:
            feats = [load_trajectory(self.generated_dir, k, self.dataset.meta).features for _, k in new]
        except LangprefError as exc:
            raise LangprefError(
                f"{self.db} lists generated trajectories that {self.generated_dir} cannot give ({exc}); pass the "
                "--generated DIR the server stores them in"
            ) from None
        first = len(self.theta)
        self.theta = np.concatenate([self.theta, self.scale(np.asarray(feats))])  # a new array: readers keep theirs
        self._rows.update({i: first + n for n, (i, _) in enumerate(new)})


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
        self.retries = 0
        self.errors: list[str] = []
        self.participant_id = ""
        self.pause: Callable[[float], None] = time.sleep
        """How the participant waits for a Retry-After (a test records the pauses instead)."""
        if world is not None:
            from langpref.feedback.humans import sample_weights

            self.w = sample_weights(world.theta.shape[1], self.rng)
            self._meet(world.theta)

    def _meet(self, theta: np.ndarray) -> None:
        """The synthetic human over `theta` (the world's rows so far): its reward and the reward normalised over the
        study set (0 worst, 1 best); its answerer of each feedback kind is made when first asked (`_human`), and
        again once the world gains rows."""
        world = self.world
        self.theta = theta
        self.reward = theta @ self.w
        ref = self.reward[world.study]
        self.norm = (self.reward - ref.min()) / max(float(ref.max() - ref.min()), 1e-12)
        self._humans: dict[str, Any] = {}

    def _human(self, kind: FeedbackKind) -> Any:
        """The kind's synthetic human (`FeedbackKind.make_human`) with this participant's reward, in the world's
        latent view: theta and the bank's test phrasings (no embeddings: a human reads none), sharing its stream."""
        from langpref.feedback.humans import HumanConfig
        from langpref.feedback.space import LatentSpace

        if kind.name not in self._humans:
            world, theta = self.world, self.theta
            space = LatentSpace(
                world.dataset.env,
                tuple(world.feature_names),
                theta,
                np.zeros((len(theta), 1)),
                {},
                {"test": world.phrases},
            )
            config = HumanConfig(temperature=self.cfg.temperature, phrasing_split="test")
            self._humans[kind.name] = kind.make_human(self.w, space, world.study, config, self.rng)
        return self._humans[kind.name]

    def _rows(self, step: dict[str, Any], stop_at: float) -> list[int] | None:
        """The world's rows of the trajectories a step shows. A generated one the server has not made yet is waited
        for as the page waits for it (its video, asked for again after each 503's Retry-After); None when the
        deadline came first."""
        urls = [u for u in step["videos"] if _INDEX.search(u)]
        while True:
            rows = [self.world.row(int(_INDEX.search(u).group(1))) for u in urls]
            if None not in rows:
                if len(self.world.theta) > len(self.theta):
                    self._meet(self.world.theta)
                return rows
            url = urls[rows.index(None)]
            r = self.client.get(url)
            if r.status_code == 200:
                if self.world.row(int(_INDEX.search(url).group(1))) is None:
                    raise LangprefError(
                        f"{url} plays, but the server's database {self.world.db} has no row for it in "
                        f"{self.world.generated_dir}: pass the --db and --generated the server runs with"
                    )
            elif r.status_code != 503 or not self._wait(r, stop_at):
                self.errors.append(f"waiting for {url}: {r.status_code} {r.text[:200]}")
                return None

    def _wait(self, response: Any, stop_at: float) -> bool:
        """Wait as a 503's Retry-After (seconds) asks, never longer nor past the deadline; False when it names no
        wait or the deadline has come."""
        try:
            seconds = max(0.0, float(response.headers["Retry-After"]))
        except (KeyError, ValueError):
            return False
        left = stop_at - time.time()
        if left <= 0:
            return False
        self.retries += 1
        self.pause(min(seconds, left))
        return True

    def _body(self, step: dict[str, Any], received: float, shown: list[int]) -> dict[str, Any]:
        """The answer to a step; `shown` are the world's rows of its trajectories (empty without a world)."""
        from langpref.study.protocol.kinds import asks_feedback

        kind, rng, world = step["kind"], self.rng, self.world
        if kind == "survey":
            return _answer_survey(step, rng)
        lo, hi = self.cfg.think_ms
        if hi > 0:
            time.sleep(float(rng.uniform(lo, hi)) / 1000.0)
        client_ms = (time.perf_counter() - received) * 1000.0
        if asks_feedback(kind):  # Study 1's language or a Study-2 query, of any feedback kind
            return {**self._feedback(step, shown), "client_ms": round(client_ms, 1), "seq": step["seq"]}
        if kind == "confirm":  # asked what it meant: the robot's top reading
            return {"meaning": step["options"][0]["meaning"]}
        if kind == "satisfaction":
            satisfied = self.norm[shown[0]] >= self.cfg.satisfied_at if world else rng.random() < 0.3
            return {"satisfied": bool(satisfied)}
        rating = np.clip(1 + round(4 * self.norm[shown[0]]), 1, 5) if world else rng.integers(1, 6)
        return {"rating": int(rating)}

    def _feedback(self, step: dict[str, Any], shown: list[int]) -> dict[str, Any]:
        """The answer field of a feedback step: the kind's synthetic human's answer about the `shown` rows, as a
        client sends it (`FeedbackKind.value`); without a world, a random one by the kind's widget."""
        from langpref.feedback.kind import get_kind
        from langpref.study.protocol.kinds import widget

        if self.world is not None:
            kind = get_kind(step["kind"])
            return {kind.answer_key: kind.value(self._human(kind).answer(kind.query(*shown)))}
        page = step.get("widget") or widget(step["kind"])  # Study 1's language step has none: the kind's own
        if page["type"] == "choice":
            return {page["answer_key"]: int(self.rng.integers(len(step["videos"])))}
        return {page["answer_key"]: str(self.rng.choice(SAYINGS))}

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
                shown = self._rows(step, stop_at) if self.world is not None else []
                if shown is None:
                    return
                body = {**self._body(step, received, shown), "seq": step["seq"]}  # every answer names its step
                while True:  # an answer the server cannot take yet (503, Retry-After) is sent again
                    t0 = time.perf_counter()
                    r = self.client.post(f"{path}/answer", json=body, headers=headers)
                    if r.status_code != 503 or not self._wait(r, stop_at):
                        break
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


def study_of(db: str | Path) -> dict[str, Any]:
    """The dataset directory (`data`) and study split (`split`) the study in `db` was created with."""
    from langpref.study.protocol import db as sdb

    conn = sdb.open_existing(db)
    try:
        meta = sdb.read_meta(conn)
    finally:
        conn.close()
    return {"data": meta.get("data"), "split": (meta.get("study") or {}).get("split")}


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def summary(values: list[float]) -> dict[str, Any]:
    """Count, median, 95th percentile and maximum of latencies in ms (None where there are none)."""
    return {
        "n": len(values),
        "p50_ms": percentile(values, 50),
        "p95_ms": percentile(values, 95),
        "max_ms": max(values) if values else None,
    }


def simulate(
    base_url: str,
    cfg: SimConfig | None = None,
    data_dir: str | Path | None = None,
    split: str = "test",
    db: str | Path | None = None,
    generated_dir: str | Path | None = None,
) -> dict[str, Any]:
    """Run `cfg.participants` simulated participants at once against a study server; latency per answer kind.

    With `data_dir` (the server's dataset) and `split` (its study split) they answer as synthetic humans, else at
    random. `db` is the server's database, read (never written) for the trajectories it generates with
    `--improve-candidates generated`, whose dataset is `generated_dir` (default `DB.generated/`, as the server's).
    Latency per answer kind (`latency`) and over every answer (`latency_all`)."""
    cfg = cfg or SimConfig()
    world = _World(data_dir, split, db, generated_dir) if data_dir is not None else None
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
    latency = {k: summary([v for s in sims for v in s.latency.get(k, [])]) for k in kinds}
    return {
        "participants": cfg.participants,
        "completed": sum(1 for s in sims if not s.errors),
        "answers": sum(s.answers for s in sims),
        "retries": sum(s.retries for s in sims),
        "wall_s": wall,
        "latency": latency,
        "latency_all": summary([v for s in sims for vals in s.latency.values() for v in vals]),
        "errors": [e for s in sims for e in s.errors][:20],
        "per_participant": {s.participant_id: s.answers for s in sims if s.participant_id},
        "think_ms": list(cfg.think_ms),
    }
