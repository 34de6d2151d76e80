"""Study 1 with generated candidates (`study serve --improve-candidates generated`): every improvement step makes a new
trajectory in the simulator (`langpref.propose`) instead of picking one from the study set.

After a participant's feedback l on trajectory tau^t (round r), the step's objective is Eq. 4's cosine,
cos(phi' - phi^t, psi_l), as in `langpref improve --candidates generated`. The CMA-ES search starts from the best of
the participant's candidates so far by that objective (the study set and their own earlier generated trajectories,
whose (parameters, phi) pairs also join the surrogate), runs `improve_rollouts` real rollouts and the best of them
by the objective of its real embedding is shown. Unlike `langpref improve`, which keeps a split trajectory when the
search found nothing better, the study always shows the new trajectory: a participant waited for it (the score of the
search's start is stored beside the new one's, so the analysis sees which was higher).

Where things live and how a restart continues:

- The answer is not held up: the flow gives the new trajectory its id at once, `len(dataset) + (arrival number - 1)
  x improve_max_iterations + (r - 1)` (no two participants or rounds share one), and the satisfaction step shows it.
  The feedback row (stored with the answer) is the job: once it is stored, the job is queued; a server that starts
  finds the stored feedback rows whose trajectory is not made yet and queues them again.
- One worker process (the model's trajectory encoder and a live simulator, apart from the server's threads, like
  the video worker) makes them one at a time, a later round before an earlier one (in the order of the answers
  within a round, except first rounds: the newest first, so that made-up sign-ups' first feedback cannot keep a
  new participant waiting; a participant has at most one waiting, as their next answer waits for it: `_place`);
  every seed comes from (study seed, participant seed, round), so a job run again makes the same trajectory.
- A made trajectory is appended to a dataset (`langpref.propose.GeneratedStore`, one split `generated`, default
  `DB.generated/` beside the database) that replays, renders and loads like any other, and its row in the database
  table `generated` (id, round, where the search started, scores, its parameters and phi, its index in that dataset)
  says what it is. Its video is then rendered like any other (`langpref.study.server.videos`).
- Until then its video is answered 503 with Retry-After (`langpref.study.server.participants`), and the page says the
  robot is making a new trajectory; an answer about a trajectory that is not made yet is answered 503 the same way
  (`NotReady`).
- The `--on-show` hook (`langpref.study.server.hook`) runs for a generated trajectory once it is made, given its index
  in the generated dataset; simulated participants (`langpref.study.server.simulate`) read its features from there.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from langpref.errors import LangprefError
from langpref.improve import cosine_objective
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.session.workers import job_failure, stop_worker, worker_init

if TYPE_CHECKING:
    from langpref.study.protocol.flow import Participant
    from langpref.study.session.engine import StudyEngine

log = logging.getLogger("langpref.study")


class NotReady(LangprefError):
    """Feedback on a trajectory the simulator is still making (the app answers 503 with Retry-After)."""


def check_generation(data_dir: str | Path) -> None:
    """One line when the dataset cannot have generated candidates: a recorded task (no simulator), episodes of
    different lengths. Reads only the dataset's metadata (before any model is loaded)."""
    from langpref.dataset.storage import load_dataset
    from langpref.propose import cannot_generate

    why = cannot_generate(load_dataset(data_dir))
    if why is not None:
        raise LangprefError(
            f"--improve-candidates generated makes trajectories of one horizon in a simulator, and {why}; drop the "
            "option (the study set is used)"
        )


# ---- the worker process ----------------------------------------------------------------------------------------

_WORKER: dict[str, Any] = {}
"""The worker's `Generation` (encoder, controller parameters and phi of the dataset, search settings)."""


def _worker_init(model_dir: str, data_dir: str, units: np.ndarray, phi: np.ndarray, propose: dict, parent: int) -> None:
    """Load the model's trajectory encoder and open the simulator once, in the worker process."""
    worker_init(parent)  # lower priority than the server's requests; dies with the server
    import torch

    from langpref.dataset.storage import load_dataset
    from langpref.model.checkpoint import load_model
    from langpref.propose import Generation, ProposeConfig, model_embedder

    torch.set_num_threads(1)
    ds = load_dataset(data_dir)
    model = load_model(model_dir, device="cpu", dataset=ds)
    _WORKER["gen"] = Generation(
        ds.env, ds.meta.horizon, units, phi, model_embedder(model), None, ProposeConfig(**propose), str(ds.root)
    )


def _warm() -> bool:
    """Open the simulator before the first job with one rollout (the initializer has loaded the model)."""
    gen = _WORKER["gen"]
    gen.proposer().rollout(gen.units[0], 0)
    return True


def _propose(job: dict[str, Any]) -> dict[str, Any]:
    """One generation step in the worker: the best real rollout for Eq. 4's cosine objective of the job."""
    from functools import partial

    gen = _WORKER["gen"]
    proposer = gen.proposer(key=tuple(job["key"]))
    if len(job["extra_units"]):
        proposer.surrogate.add(np.asarray(job["extra_units"]), np.asarray(job["extra_phi"]))
    objective = partial(cosine_objective, phi_current=np.asarray(job["phi_current"]), psi=np.asarray(job["psi"]))
    proposal = proposer.propose(objective, np.asarray(job["start_unit"]), ())
    return {
        "trajectory": proposal.trajectories[0],
        "unit": [float(x) for x in proposal.units[0]],
        "phi": [float(x) for x in proposal.phi[0]],
        "score": float(proposal.scores[0]),
        "wall_s": float(proposal.wall_s),
    }


# ---- the server side -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """A generated trajectory to make: id `id` for round `round` of a participant, from feedback `text` on `start`."""

    id: int
    participant_id: str
    participant_seed: int
    seq: int
    round: int
    shown: int
    text: str


@dataclass(frozen=True)
class Made:
    """A generated trajectory made: its row in the store, its controller parameters and phi."""

    store_index: int
    participant_id: str
    round: int
    unit: np.ndarray
    phi: np.ndarray


class Generator:
    """The generated candidates of one study: ids, the job queue and its worker, the store and the `generated` rows.
    Each of `on_made` is called with the id (from the generator's thread) when a trajectory is stored: the video
    cache renders it, the `--on-show` hook runs for it."""

    def __init__(
        self,
        engine: StudyEngine,
        cfg: StudyConfig,
        db_path: str | Path,
        store_dir: str | Path,
        model_dir: str | Path,
        data_dir: str | Path,
    ):
        from langpref.propose import GeneratedStore, dataset_units

        self.engine, self.cfg = engine, cfg
        self.db_path = str(db_path)
        self.model_dir, self.data_dir = str(Path(model_dir).resolve()), str(Path(data_dir).resolve())
        self.first = len(engine.dataset)
        self.units = dataset_units(engine.dataset)  # one line here when the dataset was not made by `generate`
        self.store = GeneratedStore(
            store_dir,
            engine.env,
            engine.dataset.meta.horizon,
            {"source": self.data_dir, "command": "study serve", "db": str(Path(db_path).resolve())},
        )
        self.on_made: list[Callable[[int], None]] = []
        self._made: dict[int, Made] = {}
        self._queue: deque[Job] = deque()
        self._running: Job | None = None
        self._failed: dict[int, str] = {}
        self._retry: dict[int, Job] = {}
        self._known: set[int] = set()
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._pool: ProcessPoolExecutor | None = None
        self._stopped = False
        self._load()

    # ids
    def id_for(self, p: Participant, round_: int) -> int:
        """The id of the trajectory generated for round `round_` (1-based) of participant `p`."""
        return self.first + (p.number - 1) * self.cfg.improve_max_iterations + (round_ - 1)

    def owns(self, index: int) -> bool:
        return int(index) >= self.first

    def known(self, index: int) -> bool:
        """Whether `index` is a generated trajectory some stored feedback asked for (made, being made, or failed)."""
        with self._cond:
            return int(index) in self._known

    # state
    def _load(self) -> None:
        """The trajectories made before (from the database) and the jobs left undone (stored feedback asking for a
        trajectory that was not made): queued again."""
        conn = sdb.connect(self.db_path)
        try:
            for r in conn.execute("SELECT * FROM generated"):
                self._made[int(r["id"])] = Made(
                    int(r["store_index"]),
                    r["participant_id"],
                    int(r["round"]),
                    np.asarray(json.loads(r["unit"])),
                    np.asarray(json.loads(r["phi"])),
                )
            self._known.update(self._made)
            todo = conn.execute(
                "SELECT f.participant_id, f.seq, f.number, f.shown, f.text, f.improved, p.seed FROM feedback f "
                "JOIN participants p ON p.id = f.participant_id WHERE f.phase = 'improve' AND f.improved >= ? "
                "ORDER BY f.answered_at",
                (self.first,),
            ).fetchall()
        finally:
            conn.close()
        for r in todo:
            if int(r["improved"]) not in self._made:
                self.submit(self._job(r["participant_id"], int(r["seed"]), int(r["seq"]), r))

    @staticmethod
    def _job(participant_id: str, seed: int, seq: int, row: Any) -> Job:
        """The job of a Study-1 feedback row (`feedback` table columns)."""
        return Job(
            int(row["improved"]), participant_id, seed, seq, int(row["number"]), int(row["shown"]), str(row["text"])
        )

    def after_answer(self, p: Participant, seq: int, records: list[tuple[str, dict[str, Any]]]) -> None:
        """Queue the job of the Study-1 feedback row stored with answer `seq`, when it asks for a generated
        trajectory (call once the answer is stored)."""
        for table, row in records:
            if table == "feedback" and row.get("phase") == "improve" and self.owns(row.get("improved") or -1):
                self.submit(self._job(p.id, p.seed, seq, row))

    def submit(self, job: Job) -> None:
        with self._cond:
            self._known.add(job.id)
            queued = job.id in self._made or (self._running and self._running.id == job.id)
            if queued or any(j.id == job.id for j in self._queue):
                return
            self._failed.pop(job.id, None)
            self._queue.insert(self._place(job), job)
            self._ensure_thread()
            self._cond.notify_all()

    def _place(self, job: Job) -> int:
        """Where `job` joins the queue (call with `_cond` held). Turns are earned by answering: a later round first
        (its participant has answered a feedback and a satisfaction step per round before it), so sign-ups that gave
        one feedback and left never hold up a participant further into Study 1; each participant has at most one
        job waiting (an answer about a trajectory not made yet is not taken), so no participant has two turns to
        another's one. Among later rounds, in the order of the answers; among first rounds, the newest first: a
        participant who has just answered is waiting for it now, while a first round answered long ago may be a
        made-up sign-up's, which then can no longer keep a new participant waiting (made later, not dropped)."""
        newest_first = job.round <= 1
        for k, queued in enumerate(self._queue):
            if queued.round < job.round or (newest_first and queued.round == job.round):
                return k
        return len(self._queue)

    def status(self, index: int) -> tuple[str, Any]:
        """`("ready", store index)`, `("generating", jobs ahead of it)`, `("failed", message)` (it is queued again)
        or `("unknown", None)`."""
        index = int(index)
        with self._cond:
            made = self._made.get(index)
            if made is not None:
                return "ready", made.store_index
            if self._running is not None and self._running.id == index:
                return "generating", 0
            for k, job in enumerate(self._queue):
                if job.id == index:
                    return "generating", k + (self._running is not None)
            failed = self._failed.pop(index, None)
            retry = self._retry.pop(index, None)
        if failed is not None:
            if retry is not None:
                self.submit(retry)
            return "failed", failed
        return "unknown", None

    def store_index(self, index: int) -> int | None:
        """The index in the store of generated trajectory `index` once it is made; None until then."""
        with self._cond:
            made = self._made.get(int(index))
        return None if made is None else made.store_index

    def phi(self, index: int) -> np.ndarray:
        """phi of a dataset row or of a generated trajectory made; NotReady while it is being made."""
        index = int(index)
        if index < self.first:
            return self.engine.space.phi[index]
        with self._cond:
            made = self._made.get(index)
        if made is None:
            raise NotReady("the robot is still making this trajectory in the simulator; answer once its video plays")
        return made.phi

    def progress(self) -> dict[str, Any]:
        with self._cond:
            return {
                "made": len(self._made),
                "queued": len(self._queue),
                "running": self._running.id if self._running else None,
                "failed": {str(k): v for k, v in self._failed.items()},
            }

    # the generator thread
    def start(self) -> None:
        """Start the worker now (model and simulator loaded before the first participant needs them)."""
        with self._cond:
            self._ensure_thread()
            pool = self._worker()
        pool.submit(_warm)

    def _worker(self) -> ProcessPoolExecutor:
        if self._pool is None:
            c = self.cfg
            propose = {"rollouts": c.improve_rollouts, "search_generations": c.improve_search_generations}
            self._pool = ProcessPoolExecutor(
                max_workers=1,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_init,
                initargs=(
                    self.model_dir,
                    self.data_dir,
                    self.units,
                    np.asarray(self.engine.space.phi),
                    propose,
                    os.getpid(),
                ),
            )
        return self._pool

    def _ensure_thread(self) -> None:
        if (self._thread is None or not self._thread.is_alive()) and not self._stopped:
            self._thread = threading.Thread(target=self._run, name="study-generate", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._stopped:
                    self._cond.wait()
                if self._stopped:
                    return
                job = self._running = self._queue.popleft()
            try:
                self._make(job)
            except Exception as exc:  # noqa: BLE001 (reported per trajectory; asking for its video retries it)
                with self._cond:
                    self._failed[job.id], self._pool = job_failure(exc, self._pool)
                    self._retry[job.id] = job
            finally:
                with self._cond:
                    self._running = None
                    self._cond.notify_all()
            if job.id in self._made:
                for listener in self.on_made:
                    try:
                        listener(job.id)
                    except Exception:  # noqa: BLE001 (a listener's failure must not stop the generator)
                        log.exception("after generated trajectory %d was made", job.id)

    def _job_input(self, job: Job) -> dict[str, Any]:
        """What the worker needs: the objective (phi^t, psi_l), where the search starts (the participant's best
        candidate so far by the objective), the participant's earlier generated pairs and the seeds."""
        phi_current = self.phi(job.shown)
        psi = self.engine.psi(job.text)
        with self._cond:
            mine = [(m.round, i) for i, m in self._made.items() if m.participant_id == job.participant_id]
            earlier_ids = [i for r, i in sorted(mine) if r < job.round]
            earlier = [self._made[i] for i in earlier_ids]
        study = [int(i) for i in self.engine.study]
        pool = study + earlier_ids
        pool_phi = np.concatenate(
            [self.engine.space.phi[study], np.array([m.phi for m in earlier]).reshape(-1, len(psi))]
        )
        scores = cosine_objective(pool_phi, phi_current, psi)
        best = int(np.argmax(scores))
        start = pool[best]
        start_unit = self.units[start] if start < self.first else self._made[start].unit
        return {
            "phi_current": phi_current,
            "psi": psi,
            "start": start,
            "start_score": float(scores[best]),
            "start_unit": start_unit,
            "extra_units": np.array([m.unit for m in earlier]),
            "extra_phi": np.array([m.phi for m in earlier]),
            "key": (self.cfg.seed, job.participant_seed, job.round, 52711),
        }

    def _make(self, job: Job) -> None:
        """Run one job in the worker, store the trajectory and its `generated` row."""
        spec = self._job_input(job)
        with self._cond:
            pool = self._worker()
        out = pool.submit(_propose, {k: v for k, v in spec.items() if k not in ("start", "start_score")}).result()
        traj = out["trajectory"]
        index = self.store.add(traj, participant=job.participant_id, round=job.round, study_id=job.id)
        conn = sdb.connect(self.db_path)
        try:
            with sdb.transaction(conn):
                conn.execute(
                    "INSERT OR REPLACE INTO generated (id, participant_id, seq, round, shown, start, start_score, "
                    "score, store_index, wall_s, unit, phi, created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        job.id,
                        job.participant_id,
                        job.seq,
                        job.round,
                        job.shown,
                        spec["start"],
                        spec["start_score"],
                        out["score"],
                        index,
                        out["wall_s"],
                        json.dumps(out["unit"]),
                        json.dumps(out["phi"]),
                        time.time(),
                    ),
                )
        finally:
            conn.close()
        made = Made(index, job.participant_id, job.round, np.asarray(out["unit"]), np.asarray(out["phi"]))
        with self._cond:
            self._made[job.id] = made

    def close(self, timeout: float = 3.0) -> None:
        """Stop now: the worker is killed (a job it was running is queued again at the next start)."""
        with self._cond:
            self._stopped = True
            self._queue.clear()
            self._cond.notify_all()
            pool = self._pool
        stop_worker(pool, self._thread, timeout)
        self._pool = None
