"""Throughput of the simulators, the generator, Ray and `langpref import` (`python -m benchmarks.pipeline` writes
the tables): raw `env.step` with random actions, the generator on one worker (target: >= 0.8 of raw), the speed-up of
2 workers over 1 (target >= 1.7x), Ray's overhead against local processes (target < 15%), the import rate, and the
wall time of a default dataset.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import ROOT


def env_steps_per_s(env_name: str, episodes: list[tuple[int, np.ndarray]]) -> float:
    """`env.step` (plus the step features) alone over the given episodes, each (reset seed, actions (T, A))."""
    from langpref.tasks import make_env

    horizon = len(episodes[0][1])
    env = make_env(env_name, horizon)
    start = time.perf_counter()
    for seed, actions in episodes:
        env.reset(seed)
        for action in actions:
            env.step(action)
            env.step_features()
    rate = len(episodes) * horizon / (time.perf_counter() - start)
    env.close()
    return rate


def raw_steps_per_s(env_name: str, episodes: int, horizon: int) -> float:
    """`env.step` with uniform random actions, in episodes of `horizon` steps, each from a reset (as the generator)."""
    from langpref.tasks import get_task

    rng = np.random.default_rng(0)
    dim = get_task(env_name).action_dim
    return env_steps_per_s(env_name, [(e, rng.uniform(-1, 1, (horizon, dim))) for e in range(episodes)])


def generator_steps_per_s(
    env_name: str, n: int, horizon: int, workers: int, backend: str = "local", replay: bool = False
) -> tuple[float, float | None]:
    """The generator's rate; with `replay`, also `env.step` alone replaying the generated actions.

    The replay runs the same physics as the generator (the same contacts: a pressed button costs Meta-World about
    40% more per step than random flailing), so generator / replay is the generator's own overhead.
    """
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.storage import load_dataset

    with tempfile.TemporaryDirectory() as tmp:
        s = generate(
            GenerateConfig(
                env=env_name, out=Path(tmp) / "d", num_trajectories=n, horizon=horizon, workers=workers, backend=backend
            )
        )
        if not replay:
            return s["steps_per_s"], None
        episodes = [(t.seed, t.actions) for t in load_dataset(Path(tmp) / "d").trajectories()]
    return s["steps_per_s"], env_steps_per_s(env_name, episodes)


def _noop(state, job):
    """A task that does nothing: timing it times the workers' start-up alone."""
    return job


def worker_startup_seconds(setup, setup_args: tuple, workers: int) -> float:
    """Wall time for `workers` fresh processes to start and build their per-process state (a simulator, a latent
    space): the one-off cost before their first task."""
    from langpref.backends import run_jobs

    start = time.perf_counter()
    list(run_jobs(_noop, list(range(workers)), setup=setup, setup_args=setup_args, workers=workers))
    return time.perf_counter() - start


def ray_init_seconds(workers: int) -> float:
    """Seconds to start a local Ray instance for `workers` workers (a one-off cost kept out of the rates)."""
    from langpref.backends import init_ray

    start = time.perf_counter()
    init_ray(None, workers)
    return time.perf_counter() - start


def generator_table(envs: list[str], repeats: int, today: str) -> str:
    """The generator-throughput table (see the module docstring)."""
    from langpref.dataset.generate import make_worker_env

    rows = []
    load_before = os.getloadavg()[0]
    for env_name in envs:
        horizon = 500
        n = 120 if env_name == "metaworld" else 16  # the same trajectories for 1 and 2 workers
        generator_steps_per_s(env_name, 3, horizon, 1)  # warm-up: the simulator is built once per process
        # Interleaved rounds, best of each: this shared machine's speed drifts, and the best is the least disturbed.
        rounds = []
        for _ in range(repeats):
            one, replayed = generator_steps_per_s(env_name, n, horizon, 1, replay=True)
            two, _ = generator_steps_per_s(env_name, n, horizon, 2)
            rounds.append(
                {
                    "raw": raw_steps_per_s(env_name, 8 if env_name == "metaworld" else 2, horizon),
                    "one": one,
                    "replay": replayed,
                    "two": two,
                    "startup": worker_startup_seconds(make_worker_env, (env_name, horizon), 2),
                }
            )
        best = {k: max(r[k] for r in rounds) for k in ("raw", "one", "replay", "two")}
        startup = min(r["startup"] for r in rounds)
        raw, one, replayed, two = best["raw"], best["one"], best["replay"], best["two"]
        steady = n * horizon / (n * horizon / two - startup)
        rows.append((env_name, raw, one, one / raw, replayed, one / replayed, two, two / one, startup, steady / one))
        print(json.dumps({"env": env_name, "rounds": rounds}), flush=True)
    table = [
        f"Measured {today} on this machine ({os.cpu_count()} cores, no GPU) with `make bench` "
        "(`python -m benchmarks.pipeline`). Horizon 500. Raw: episodes of `env.step` with uniform random actions "
        "(plus the step features), each from a reset. "
        "Generator: whole trajectories (controller, state recording, saving), the same trajectories on 1 and 2 "
        "workers; one worker is timed after a warm-up run. Replay: `env.step` alone on the generator's own actions "
        "(the same physics and contacts), so generator / replay is the generator's own overhead. Two workers are "
        "timed with their start-up (processes spawned, simulators imported and built), and without it (start-up "
        f"timed apart and subtracted). Best of {repeats} interleaved rounds; load average "
        f"{load_before:.2f} before the run.\n",
        "| env | raw env.step, random actions (steps/s) | generator, 1 worker (steps/s) | ratio to raw (target >= 0.8) "
        "| replay of the generator's actions (steps/s) | ratio to replay "
        "| generator, 2 workers (steps/s) | speed-up 2 vs 1 | 2-worker start-up (s) "
        "| speed-up without start-up (target >= 1.7) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for env_name, raw, one, ratio, replayed, ratio_replay, two, speedup, startup, steady in rows:
        table.append(
            f"| {env_name} | {raw:.0f} | {one:.0f} | {ratio:.2f} | {replayed:.0f} | {ratio_replay:.2f} "
            f"| {two:.0f} | {speedup:.2f}x | {startup:.1f} | {steady:.2f}x |"
        )
    return "\n".join(table)


def ray_overhead_table(envs: list[str], rounds: int, today: str) -> str:
    """Ray's overhead against local processes (target < 15%), 2 workers: per round the same trajectories generated
    both ways back to back (the order alternating, so the machine's drift falls on both), the overhead 1 - ray/local
    per round, and its mean with a 95% t-interval over rounds. One best-of figure sat within its own noise (a
    negative overhead on robosuite), which is why the interval is reported."""
    from langpref.experiments.reward import paired_difference

    ray_init = ray_init_seconds(2)
    lines = [
        f"Measured {today} with `python -m benchmarks.pipeline --ray-rounds {rounds}` ({rounds} rounds per env), 2 "
        "workers, horizon 500; per round the same trajectories generated with local processes and with Ray tasks "
        "back to back, the order alternating between rounds. Overhead per round: 1 - Ray rate / local rate; mean "
        "over rounds with its 95% t-interval. Ray was started once before timing (a local instance took "
        f"{ray_init:.1f} s to start; that one-off cost is not in the rates). Local processes are spawned by each "
        "run, so their rate includes their start-up (the throughput table's \"2-worker start-up\"); Ray's workers "
        "stay up between runs (a warm-up run built their simulators), which is why Ray can come out faster where a "
        "run is short against that start-up. Load average "
        f"{os.getloadavg()[0]:.2f} before the run.\n",
        "| env | rounds | local processes, mean (steps/s) | Ray tasks, mean (steps/s) "
        "| Ray overhead, mean [95% interval] (target < 15%) |",
        "|---|---|---|---|---|",
    ]
    for env_name in envs:
        n = 120 if env_name == "metaworld" else 16
        generator_steps_per_s(env_name, 3, 500, 2, backend="ray")  # warm-up: Ray's workers build their simulators
        local, ray = [], []
        for r in range(rounds):
            order = ("local", "ray") if r % 2 == 0 else ("ray", "local")
            rate = {b: generator_steps_per_s(env_name, n, 500, 2, backend=b)[0] for b in order}
            local.append(rate["local"])
            ray.append(rate["ray"])
            print(json.dumps({"env": env_name, "round": r, **rate}), flush=True)
        overhead = 1 - np.array(ray)[:, None] / np.array(local)[:, None]
        d = paired_difference(overhead, np.zeros_like(overhead))
        lines.append(
            f"| {env_name} | {rounds} | {np.mean(local):.0f} | {np.mean(ray):.0f} "
            f"| {d['mean'][0]:.1%} [{d['low'][0]:.1%}, {d['high'][0]:.1%}] |"
        )
    return "\n".join(lines)


def import_table(today: str, repeats: int) -> str:
    """`langpref import` of a plain recording without videos (300 episodes of 200 steps, 39-dim observations, features
    from a task-file function), best of `repeats`; target >= 50 episodes/s on 2 cores."""
    from langpref.dataset.importer import ImportConfig, import_recording
    from langpref.language.bank import split_bank
    from langpref.tasks.taskfile import read_task_file

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        rec = root / "rec"
        rec.mkdir()
        rng = np.random.default_rng(0)
        for i in range(300):
            np.savez_compressed(
                rec / f"ep{i:04d}.npz",
                observations=rng.normal(size=(200, 39)).astype(np.float32),
                actions=rng.normal(size=(200, 4)).astype(np.float32),
                success=np.array(True),
            )
        (root / "features.py").write_text(
            "import numpy as np\n\ndef f(o, a):\n    return np.stack([o[:, 0], np.linalg.norm(a, axis=1)], axis=1)\n"
        )
        words = {f: {d: [f"{d} the {f} {k}." for k in range(5)] for d in ("increase", "decrease")} for f in "ab"}
        (root / "bank.json").write_text(json.dumps(words))
        (root / "task.toml").write_text(
            'name = "bench"\ndescription = "x"\nfeatures = ["a", "b"]\n'
            'features_from = "features.py:f"\nutterances = "bank.json"\n'
        )
        task = read_task_file(root / "task.toml")
        bank = split_bank(task.utterances, task.features)
        rates = []
        for r in range(repeats):
            cfg = ImportConfig(src=rec, task=root / "task.toml", out=root / f"ds{r}")
            rates.append(import_recording(cfg, task, bank, progress=False)["episodes_per_s"])
    return (
        f"Measured {today} with `make bench` (`python -m benchmarks.pipeline`): `langpref import` of a plain recording "
        "(300 episodes x 200 steps, 39-dim observations, 4-dim actions, features from the task file's function, no "
        f"videos), best of {repeats}, one process.\n\n| episodes/s (target >= 50) |\n|---|\n| {max(rates):.0f} |"
    )


def default_dataset_wall(env_name: str, out: Path) -> dict:
    """Generate the default dataset of `env_name` into `out` (all cores) and describe it."""
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.inspect import describe

    s = generate(GenerateConfig(env=env_name, out=out, force=True))
    d = describe(out)
    return {"wall_s": s["wall_s"], "workers": s["workers"], "inspect": d}


def default_datasets_table(envs: list[str], today: str) -> str:
    """The wall time of each env's default dataset, written to data/ENV as `langpref generate` would."""
    lines = [
        f"Measured {today} with `python -m benchmarks.pipeline --default-datasets` (all cores).\n",
        "| env | trajectories | wall time | task success | largest abs off-diagonal feature correlation |",
        "|---|---|---|---|---|",
    ]
    for env_name in envs:
        r = default_dataset_wall(env_name, ROOT / "data" / env_name)
        d = r["inspect"]
        lines.append(
            f"| {env_name} | {d['num_trajectories']} | {r['wall_s'] / 60:.1f} min ({r['workers']} workers)"
            f" | {d['success_rate']:.1%} | {d['max_abs_off_diagonal_correlation']:.2f} |"
        )
    return "\n".join(lines)
