"""Study videos: made once per trajectory, cached on disk, served by name.

A recorded dataset (`langpref import`) has its own camera video per trajectory: it is served as recorded, copied
when it is already in the served format and transcoded once when not; it is never re-rendered. A simulated dataset's
videos are rendered from the stored simulator states. Names are `traj000012-<tag>.webm`, the tag a hash of the
dataset and (for rendered videos) the render settings, so a cache folder never serves a video made another way.
Videos are made in one worker process (MuJoCo on EGL, or PyAV's encoder, apart from the server's threads) that keeps
its env between trajectories. At start every study trajectory is queued (`prerender`), and a video asked for before
its turn goes to the front of the queue (`request`); no server thread waits for it: the app answers 503 with
Retry-After, or waits asynchronously for a short while (`langpref.study.server.participants`). The worker exits by
itself when the server process dies (it watches its parent), and `close` kills it rather than waiting for a render to
finish.

Study 1 with generated candidates (`langpref.study.session.generated`, `attach`): a generated trajectory's video is
named `gen000123-<tag>.webm` (the tag also hashes the folder of the generated dataset, so a video folder shared by two
studies never mixes their generated trajectories); until the trajectory is made, `request` says `generating`, then
it is rendered from the generated dataset like any other.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import re
import sys
import threading
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.study.server.settings import VideoConfig
from langpref.study.session.workers import job_failure, stop_worker, worker_init

MEDIA_TYPES = {"webm": "video/webm", "mp4": "video/mp4"}
_NAME = re.compile(r"(traj|gen)([0-9]{6})-([0-9a-f]{10})\.(webm|mp4)", re.ASCII)
"""A video's name, matched whole (`fullmatch`: no trailing newline) and in ASCII digits only."""

# ---- the worker process ----------------------------------------------------------------------------------------

_WORKER_STATE: dict[str, Any] = {}
"""data_dir -> (dataset, its task's env or None until a simulated trajectory is rendered)."""


def _close_worker_envs() -> None:
    for _, env in _WORKER_STATE.values():
        try:
            if env is not None:
                env.close()
        except Exception:  # noqa: BLE001, S110 (closing at exit: nothing to do about it)
            pass
    _WORKER_STATE.clear()


def _worker_init(parent: int | None = None) -> None:
    """The video worker closes its envs at exit, yields the CPU to the server's requests and dies with its parent."""
    atexit.register(_close_worker_envs)
    worker_init(parent)


def make_video(
    data_dir: str, index: int, out: str, width: int, height: int, fps: int, stride: int, reload: bool = False
) -> str:
    """Write the video of trajectory `index` into `out` (runs in the worker process): a recorded dataset's own video
    (the render settings do not apply), else a replay of the stored states (the env is kept for the next one).
    `reload`: read the dataset's metadata again (a generated dataset grows)."""
    from langpref.dataset.render import recorded_video, replay_video

    if data_dir not in _WORKER_STATE:
        _WORKER_STATE[data_dir] = (load_dataset(data_dir), None)
    elif reload:
        _WORKER_STATE[data_dir] = (load_dataset(data_dir), _WORKER_STATE[data_dir][1])
    ds, env = _WORKER_STATE[data_dir]
    if ds.meta.videos:
        return str(recorded_video(ds, index, Path(out)))
    if env is None:
        from langpref.tasks import make_env

        env = make_env(ds.env, ds.meta.horizon)
        _WORKER_STATE[data_dir] = (ds, env)
    return str(replay_video(ds, index, Path(out), env, width, height, fps, stride))


# ---- the cache -------------------------------------------------------------------------------------------------


class VideoCache:
    """Videos of the study set in `cache_dir`; `ensure(index)` makes one now if needed."""

    def __init__(self, data_dir: str | Path, cache_dir: str | Path, cfg: VideoConfig, indices, progress: bool = True):
        cfg.validate()
        self.data_dir = str(Path(data_dir).resolve())
        self.dir = Path(cache_dir).resolve()
        self.dir.mkdir(parents=True, exist_ok=True)
        self.cfg = cfg
        self.indices = sorted({int(i) for i in indices})
        self._allowed = set(self.indices)
        meta = Path(self.data_dir) / "meta.json"
        ident: dict[str, Any] = {"data": self.data_dir, "meta_sha": hashlib.sha256(meta.read_bytes()).hexdigest()}
        if load_dataset(self.data_dir).meta.videos:
            ident["recorded"] = True
        else:
            ident.update(width=cfg.width, height=cfg.height, fps=cfg.fps, stride=cfg.stride)
        self.tag = hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:10]
        self.show_progress = progress
        self._queue: deque[int] = deque()
        self._urgent: deque[int] = deque()
        self._cond = threading.Condition()
        self._errors: dict[int, str] = {}
        self._thread: threading.Thread | None = None
        self._pool: ProcessPoolExecutor | None = None
        self._stopped = False
        self._rendering: int | None = None
        self._active = False  # a render thread is running (changed only under `_cond`)
        self.generated = None  # langpref.study.session.generated.Generator, with `attach`
        self.gen_tag = ""

    def attach(self, generated) -> None:
        """Serve the trajectories of a `langpref.study.session.generated.Generator` too; each is rendered once it is
        made."""
        self.generated = generated
        ident = {"tag": self.tag, "store": str(Path(generated.store.root).resolve())}
        self.gen_tag = hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:10]
        generated.on_made.append(self.request)

    def _is_generated(self, index: int) -> bool:
        return self.generated is not None and self.generated.owns(index)

    # names and paths
    def name(self, index: int) -> str:
        if self._is_generated(index):
            return f"gen{int(index):06d}-{self.gen_tag}.{self.cfg.format}"
        return f"traj{int(index):06d}-{self.tag}.{self.cfg.format}"

    def url(self, index: int) -> str:
        return f"/videos/{self.name(index)}"

    def path(self, index: int) -> Path:
        return self.dir / self.name(index)

    def index_of(self, name: str) -> int | None:
        """The study trajectory a video name stands for; None for anything else (other tags, `../`, unknown)."""
        m = _NAME.fullmatch(name)
        if not m or m.group(4) != self.cfg.format:
            return None
        index = int(m.group(2))
        if m.group(1) == "gen":
            if m.group(3) != self.gen_tag or not self._is_generated(index) or not self.generated.known(index):
                return None
        elif m.group(3) != self.tag or index not in self._allowed:
            return None
        path = (self.dir / name).resolve()
        return index if path.parent == self.dir else None

    @property
    def media_type(self) -> str:
        return MEDIA_TYPES[self.cfg.format]

    def cached(self, index: int) -> bool:
        return self.path(index).is_file()

    def progress(self) -> dict[str, Any]:
        done = sum(self.cached(i) for i in self.indices)
        return {
            "done": done,
            "total": len(self.indices),
            "running": self._active,
            "errors": {str(k): v for k, v in self._errors.items()},
        }

    # rendering
    def start(self, prerender: bool = True) -> None:
        """Start the render thread; with `prerender`, queue every study video not yet cached."""
        with self._cond:
            if prerender:
                self._queue.extend(i for i in self.indices if not self.cached(i))
            self._ensure_thread()

    def _ensure_thread(self) -> None:
        """Start the render thread unless one runs (call with `_cond` held)."""
        if not self._active and not self._stopped:
            self._active = True
            self._thread = threading.Thread(target=self._run, name="video-render", daemon=True)
            self._thread.start()

    def _next(self) -> int | None:
        with self._cond:
            while not self._stopped:
                for q in (self._urgent, self._queue):
                    while q:
                        i = q.popleft()
                        if not self.cached(i):
                            self._rendering = i
                            return i
                self._cond.wait(timeout=1.0)
                if not self._urgent and not self._queue:
                    break
            self._active = False
            return None

    def _run(self) -> None:
        import multiprocessing
        import os

        bar = None
        if self.show_progress and self._queue:
            from tqdm import tqdm

            bar = tqdm(
                total=len(self.indices),
                initial=len(self.indices) - len(self._queue),
                desc="study videos",
                unit="video",
                file=sys.stderr,
            )
        try:
            while True:
                index = self._next()
                if index is None:
                    return
                try:
                    if self._pool is None:
                        self._pool = ProcessPoolExecutor(
                            max_workers=1,
                            mp_context=multiprocessing.get_context("spawn"),
                            initializer=_worker_init,
                            initargs=(os.getpid(),),
                        )
                    c, source, row = self.cfg, self.data_dir, index
                    if self._is_generated(index):
                        made, row = self.generated.status(index)
                        if made != "ready":
                            raise LangprefError(f"generated trajectory {index} is not made yet ({made})")
                        source = str(Path(self.generated.store.root).resolve())
                    out = str(self.path(index))
                    gen = source != self.data_dir
                    self._pool.submit(make_video, source, row, out, c.width, c.height, c.fps, c.stride, gen).result()
                    self._errors.pop(index, None)
                except Exception as exc:  # noqa: BLE001 (reported per video, the server keeps running)
                    self._errors[index], self._pool = job_failure(exc, self._pool)
                finally:
                    with self._cond:
                        self._rendering = None
                        self._cond.notify_all()
                if bar is not None:
                    bar.n = sum(self.cached(i) for i in self.indices)
                    bar.refresh()
        except BaseException:
            with self._cond:
                self._active = False
                self._cond.notify_all()
            raise
        finally:
            if bar is not None:
                bar.close()

    def request(self, index: int) -> tuple[str, Any]:
        """Ask for the video of `index` without waiting: `("ready", path)`, `("pending", videos ahead of it)` (it is
        now at the front of the queue) or `("failed", message)` (the last try failed; asking again retries it); a
        generated trajectory not made yet: `("generating", trajectories ahead of it)`, or `("failed", message)`."""
        path = self.path(index)
        if path.is_file():
            return "ready", path
        if self._is_generated(index):
            status, info = self.generated.status(index)
            if status != "ready":
                return ("failed", info) if status == "failed" else ("generating", info or 0)
        with self._cond:
            if index in self._errors and index not in self._urgent and self._rendering != index:
                message = self._errors.pop(index)
                self._urgent.append(index)
                self._ensure_thread()
                self._cond.notify_all()
                return "failed", message
            if self._rendering == index:
                return "pending", 0
            if index not in self._urgent:
                self._urgent.append(index)
                self._ensure_thread()
                self._cond.notify_all()
            return "pending", 1 + list(self._urgent).index(index) - (self._rendering is None)

    def ensure(self, index: int, timeout: float = 180.0) -> Path:
        """The video of `index`, made first (ahead of the queue) if it is not cached yet."""
        path = self.path(index)
        if path.is_file():
            return path
        with self._cond:
            self._errors.pop(index, None)
            self._urgent.append(index)
            self._ensure_thread()
            self._cond.notify_all()
            ok = self._cond.wait_for(lambda: path.is_file() or index in self._errors or self._stopped, timeout)
        if path.is_file():
            return path
        if index in self._errors:
            raise LangprefError(f"video of trajectory {index} could not be made: {self._errors[index]}")
        raise LangprefError(f"video of trajectory {index} is not ready yet (timed out: {not ok}); try again")

    def wait(self, timeout: float = 600.0) -> bool:
        """Wait until the queue is empty (tests, benchmarks)."""
        with self._cond:
            return self._cond.wait_for(
                lambda: not self._queue and not self._urgent and self._rendering is None, timeout
            )

    def close(self, timeout: float = 3.0) -> None:
        """Stop rendering now: the worker is killed (a half-written video is never served: it is written to a
        temporary name first), the render thread ends within `timeout` seconds."""
        with self._cond:
            self._stopped = True
            self._queue.clear()
            self._urgent.clear()
            self._cond.notify_all()
        stop_worker(self._pool, self._thread, timeout)
        self._pool = None
