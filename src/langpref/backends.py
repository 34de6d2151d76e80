"""Where parallel work runs: local worker processes (default, no extra dependency) or Ray tasks.

Both backends take the same jobs and the same per-process setup, and yield results as they finish. Determinism is
the caller's: every job carries its own seeds, so the results do not depend on the backend, the number of workers or
nodes, or on a job being retried after its worker died.

Ray: `--backend ray` starts a local Ray instance (as many CPUs as `workers`), or joins a running cluster with
`--ray-address` (e.g. `auto`, or `HOST:6379`). Tasks return their results to the driver, which writes them, so the
nodes need no shared file system. A task lost with its worker is retried by Ray (`max_retries`).
"""

from __future__ import annotations

import hashlib
import multiprocessing as mp
import os
import pickle
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Literal, get_args

from langpref.errors import LangprefError

Backend = Literal["local", "ray"]
"""Where jobs run: local worker processes or Ray tasks."""
BACKENDS: tuple[str, ...] = get_args(Backend)
_SETUP_CACHE: dict[tuple, Any] = {}


def _call_setup(setup: Callable[..., Any] | None, setup_args: tuple) -> Any:
    """Per-process state (e.g. a simulator), built once per worker process and reused by its later jobs."""
    if setup is None:
        return None
    key = (setup.__module__, setup.__qualname__, hashlib.sha1(pickle.dumps(setup_args)).hexdigest())
    if key not in _SETUP_CACHE:
        _SETUP_CACHE.clear()
        _SETUP_CACHE[key] = setup(*setup_args)
    return _SETUP_CACHE[key]


def _local_init(setup, setup_args, threads: int) -> None:
    """Give the worker its share of the cores, then build its state: torch's default of one thread per core in every
    worker oversubscribes them, and made a sweep of small fits (mlp rewards) 3x slower on 2 workers than on 1."""
    os.environ["OMP_NUM_THREADS"] = str(threads)  # read when torch is first imported, which setup usually does
    _call_setup(setup, setup_args)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def _local_run(payload):
    fn, setup, setup_args, job = payload
    return fn(_call_setup(setup, setup_args), job)


def _run_chunk(fn, setup, setup_args, jobs):
    state = _call_setup(setup, setup_args)
    return [fn(state, job) for job in jobs]


def run_jobs(
    fn: Callable[[Any, Any], Any],
    jobs: Sequence[Any],
    *,
    setup: Callable[..., Any] | None = None,
    setup_args: tuple = (),
    backend: str = "local",
    workers: int | None = None,
    ray_address: str | None = None,
    chunk: int = 1,
    max_retries: int = 3,
) -> Iterator[Any]:
    """Yield `fn(setup(*setup_args), job)` for every job, in completion order.

    `fn` and `setup` must be module-level functions (they are pickled to the workers).
    """
    if backend not in BACKENDS:
        raise LangprefError(f"unknown backend {backend!r}: choose one of {', '.join(BACKENDS)}")
    if not jobs:
        return
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    if backend == "ray":
        yield from _run_ray(fn, jobs, setup, setup_args, workers, ray_address, chunk, max_retries)
    elif workers == 1:  # in this process, reusing its state across calls (a second run skips the simulator start-up)
        state = _call_setup(setup, setup_args)
        for job in jobs:
            yield fn(state, job)
    else:
        threads = max(1, (os.cpu_count() or 1) // workers)
        with mp.get_context("spawn").Pool(workers, _local_init, (setup, setup_args, threads)) as pool:
            yield from pool.imap_unordered(_local_run, [(fn, setup, setup_args, job) for job in jobs])


def init_ray(address: str | None, num_cpus: int | None) -> None:
    """Connect to `address`, or start a local instance with `num_cpus` CPUs, unless already connected."""
    from langpref.extras import needs

    with needs("ray", "--backend ray"):
        import ray
    if ray.is_initialized():
        return
    if address is None:  # a private local instance: no token needed (Ray 2.60 turns token auth on by default)
        os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "logging_level": "ERROR"}
    try:
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=num_cpus, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        raise LangprefError(f"could not start or reach {where}: {str(exc).splitlines()[0]}") from None


def _run_ray(fn, jobs, setup, setup_args, workers, address, chunk, max_retries) -> Iterator[Any]:
    import ray

    init_ray(address, workers)
    remote = ray.remote(num_cpus=1, max_retries=max_retries)(_run_chunk)
    pending = [remote.remote(fn, setup, setup_args, list(jobs[i : i + chunk])) for i in range(0, len(jobs), chunk)]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for result in ray.get(done):
            yield from result
