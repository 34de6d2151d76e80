"""A background worker process beside the server's threads (the video renderer, `langpref.study.server.videos`, and
Study 1's generator, `langpref.study.session.generated`): it yields the CPU to the server's requests and exits by
itself when the server dies; a failed job and a stop are handled the same way for both."""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any


def watch_parent(parent: int, interval: float = 0.5) -> None:
    """Exit this worker as soon as `parent` (the server) is gone: a SIGKILLed server leaves no render worker."""
    while True:
        time.sleep(interval)
        if os.getppid() != parent:
            os._exit(0)


def worker_init(parent: int | None = None) -> None:
    """A worker yields the CPU to the server's requests and dies with its `parent` (the server) when one is given."""
    if parent is not None:
        threading.Thread(target=watch_parent, args=(parent,), name="parent-watch", daemon=True).start()
    try:
        os.nice(10)
    except (AttributeError, OSError):
        pass


def job_failure(exc: BaseException, pool: ProcessPoolExecutor | None) -> tuple[str, ProcessPoolExecutor | None]:
    """A failed job's one-line reason (300 characters at most), and the worker pool to go on with: None when the
    failure broke it (its worker died), so that the next job starts a fresh one instead of failing too."""
    broken = pool is not None and getattr(pool, "_broken", False)
    return f"{type(exc).__name__}: {exc}"[:300], None if broken else pool


def stop_worker(pool: Any, thread: threading.Thread | None, timeout: float) -> None:
    """Kill `pool`'s worker processes at once (a job in flight is lost: its caller requeues or rewrites it), let the
    thread feeding it end within `timeout` seconds, and shut the pool down without waiting."""
    if pool is not None:
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            try:
                proc.kill()
            except (OSError, AttributeError):
                pass
    if thread is not None:
        thread.join(timeout=timeout)
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
