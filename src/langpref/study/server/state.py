"""What every request of the study server shares: `StudyApp`, one per server, handed to each router.

It holds the database path (one connection per thread), the engine and the robot (a reward learner per participant),
the video cache, the admin token, the `--on-show` hook, Study 1's generated candidates, the checks of Host and
Origin, the proxies trusted to name the client, the per-participant locks that keep concurrent requests apart, and
the rate limits (wrong resume codes, sign-ups per client).
"""

from __future__ import annotations

import hashlib
import threading
from pathlib import Path
from typing import Any

from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.flow import Confirmed, Participant, Step
from langpref.study.server.guard import HostCheck, HttpError, RateLimiter, TrustedProxies
from langpref.study.server.hook import ShowHook
from langpref.study.server.videos import VideoCache
from langpref.study.session.engine import StudyEngine, StudyRobot
from langpref.study.session.generated import Generator

LOCK_STRIPES = 64
"""Locks that answers of one participant take (by hash of the id): a fixed number, so memory stays bounded."""
MAX_RESUME_FAILURES = 20
"""Wrong resume codes taken per minute from one client (an address; IPv6 by its /64), then 429 for that client only:
about 2^50 codes cannot be tried, and no client can lock resume for the others."""
MAX_RESUMES_PER_CODE = 10
"""Sessions restored per minute with one resume code (each adds a token), then 429 for that code."""
SIGNUP_WINDOW_S = 600.0
"""The window of `--signups-per-client`: sign-ups counted per client over the last 10 minutes."""


def sha256(text: str) -> str:
    """Hex SHA-256 of a text (tokens are stored only as this)."""
    return hashlib.sha256(text.encode()).hexdigest()


class StudyApp:
    """Everything a request needs: the database path, the engine, the video cache, the admin token, the
    `--on-show` hook (told of every step handed out; it never blocks a request) and Study 1's generated candidates
    (`--improve-candidates generated`)."""

    def __init__(
        self,
        db_path: str | Path,
        engine: StudyEngine,
        videos: VideoCache,
        admin_token: str,
        cfg: StudyConfig | None = None,
        hook: ShowHook | None = None,
        allowed_origins: tuple[str, ...] = (),
        generated: Generator | None = None,
        allowed_hosts: tuple[str, ...] = (),
        bind_host: str | None = None,
        trusted_proxies: tuple[str, ...] = (),
        signups_per_client: int = 0,
    ):
        self.db_path = str(db_path)
        self.engine = engine
        self.cfg = cfg or engine.cfg
        self.videos = videos
        self.admin_token = admin_token
        self.hook = hook
        self.generated = generated
        self.robot = StudyRobot(
            engine, self._history, cfg=self.cfg, generated=generated, confirmations=self._confirmations
        )
        # answers of one participant run one at a time; a fixed set of locks (by hash of the id, taken only after
        # the token is checked) keeps memory bounded whatever ids unauthenticated requests send
        self._locks = [threading.Lock() for _ in range(LOCK_STRIPES)]
        self.resume_failures = RateLimiter(MAX_RESUME_FAILURES)
        self.resumes = RateLimiter(MAX_RESUMES_PER_CODE)
        self.signups = RateLimiter(signups_per_client, SIGNUP_WINDOW_S) if signups_per_client else None
        """New participants per client in `SIGNUP_WINDOW_S` (None: no limit); in memory only, nothing is stored."""
        self._local = threading.local()
        self.video_waiters = 0  # requests waiting for a video; changed only on the event loop
        self.stopping = threading.Event()
        """Set when the server begins to stop: a request waiting for a video is answered (503) at once, so that the
        server's graceful stop waits only for answers in flight."""
        self.allowed_origins = {o.rstrip("/").lower() for o in allowed_origins}
        self.hosts = HostCheck(allowed_hosts, bind_host, self.allowed_origins)
        self.proxies = TrustedProxies(trusted_proxies)  # whose X-Forwarded-For names the client

    def connect(self):
        """This thread's connection, kept open: closing the last connection of a WAL database checkpoints it
        (an fsync per request)."""
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = self._local.conn = sdb.connect(self.db_path)
        return conn

    def _history(self, pid: str, method: str) -> list[Any]:
        """The participant's stored Study-2 answers of `method`, in order, as its feedback kind's answers."""
        return sdb.stored_answers(self.connect(), pid, method)

    def _confirmations(self, pid: str, method: str) -> dict[int, Confirmed]:
        """What the participant confirmed their Study-2 answers of `method` meant, by query number."""
        return {n: Confirmed(m) for n, m in sdb.confirmed_meanings(self.connect(), pid, method).items()}

    def lock(self, pid: str) -> threading.Lock:
        """The lock that answers of participant `pid` hold (shared with the other ids of its stripe)."""
        return self._locks[int(sha256(pid)[:8], 16) % LOCK_STRIPES]

    @staticmethod
    def participant(row) -> Participant:
        """A `participants` row as the flow's participant."""
        return Participant(row["id"], int(row["number"]), tuple(row["method_order"].split(",")), int(row["seed"]))

    @staticmethod
    def current_step(conn, pid: str) -> tuple[Step, dict]:
        """The participant's current (latest) step and its row."""
        row = conn.execute("SELECT * FROM steps WHERE participant_id=? ORDER BY seq DESC LIMIT 1", (pid,)).fetchone()
        if row is None:
            raise HttpError(409, "this participant has no step (the database was edited?)")
        return Step.from_row(dict(row)), dict(row)
