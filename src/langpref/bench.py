"""`make bench`: throughput of the simulators and the generator, written into docs/results.md.

Measures, per env: raw `env.step` with random actions, the generator on one worker (target: >= 0.8 of raw), the
speed-up of 2 workers over 1 (target >= 1.7x), and the wall time of a default dataset. Not part of the tests:
timings belong in benchmarks, not in unit tests that flake on shared machines.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import re
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path("docs/results.md")


def raw_steps_per_s(env_name: str, steps: int) -> float:
    from langpref.envs import get_spec, make_env

    env = make_env(env_name, steps + 1)
    rng = np.random.default_rng(0)
    env.reset(0)
    dim = get_spec(env_name).action_dim
    start = time.perf_counter()
    for _ in range(steps):
        env.step(rng.uniform(-1, 1, dim))
        env.step_features()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def generator_steps_per_s(env_name: str, n: int, horizon: int, workers: int, backend: str = "local") -> float:
    from langpref.dataset.generate import GenerateConfig, generate

    with tempfile.TemporaryDirectory() as tmp:
        s = generate(GenerateConfig(env=env_name, out=Path(tmp) / "d", num_trajectories=n, horizon=horizon,
                                    workers=workers, backend=backend))
    return s["steps_per_s"]


def ray_init_seconds(workers: int) -> float:
    from langpref.backends import init_ray

    start = time.perf_counter()
    init_ray(None, workers)
    return time.perf_counter() - start


def default_dataset_wall(env_name: str, out: Path) -> dict:
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.inspect import describe

    s = generate(GenerateConfig(env=env_name, out=out, force=True))
    d = describe(out)
    return {"wall_s": s["wall_s"], "workers": s["workers"], "inspect": d}


def write_section(name: str, body: str) -> None:
    """Replace (or append) the block between `<!-- bench:NAME -->` markers in docs/results.md."""
    RESULTS.parent.mkdir(exist_ok=True)
    text = RESULTS.read_text() if RESULTS.exists() else "# Results\n"
    block = f"<!-- bench:{name} -->\n{body.strip()}\n<!-- /bench:{name} -->"
    pattern = re.compile(rf"<!-- bench:{name} -->.*?<!-- /bench:{name} -->", re.S)
    text = pattern.sub(lambda _: block, text) if pattern.search(text) else text.rstrip() + "\n\n" + block + "\n"
    RESULTS.write_text(text)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--envs", nargs="+", default=["metaworld", "robosuite"])
    p.add_argument("--default-datasets", action="store_true",
                   help="also time a full default dataset per env (writes data/ENV; robosuite takes ~20-40 min)")
    p.add_argument("--no-ray", dest="ray", action="store_false", help="skip the Ray backend comparison")
    args = p.parse_args(argv)
    today = dt.date.today().isoformat()
    rows, ray_rows = [], []
    ray_init = ray_init_seconds(2) if args.ray else None
    for env_name in args.envs:
        horizon = 500
        raw = raw_steps_per_s(env_name, 2000 if env_name == "metaworld" else 500)
        n1 = 60 if env_name == "metaworld" else 12  # big enough that process start-up is a small share
        one = generator_steps_per_s(env_name, n1, horizon, 1)
        two = generator_steps_per_s(env_name, 2 * n1, horizon, 2)
        rows.append((env_name, raw, one, one / raw, two, two / one))
        if args.ray:
            ray_two = generator_steps_per_s(env_name, 2 * n1, horizon, 2, backend="ray")
            ray_rows.append((env_name, two, ray_two, 1 - ray_two / two))
        print(json.dumps({"env": env_name, "raw_steps_per_s": raw, "generator_1_worker": one,
                          "generator_2_workers": two}), flush=True)
    table = [
        f"Measured {today} on this machine ({os.cpu_count()} cores, no GPU) with `make bench` "
        "(`python -m langpref.bench`). Horizon 500.\n",
        "| env | raw env.step (steps/s) | generator, 1 worker (steps/s) | ratio to raw (target >= 0.8) "
        "| generator, 2 workers (steps/s) | speed-up 2 vs 1 (target >= 1.7) |",
        "|---|---|---|---|---|---|",
    ]
    for env_name, raw, one, ratio, two, speedup in rows:
        table.append(f"| {env_name} | {raw:.0f} | {one:.0f} | {ratio:.2f} | {two:.0f} | {speedup:.2f}x |")
    write_section("generator-throughput", "\n".join(table))
    if args.ray:
        lines = [f"Measured {today} with `make bench` (`python -m langpref.bench`), 2 workers, horizon 500. Ray was "
                 f"started once before timing (a local instance took {ray_init:.1f} s to start; that one-off cost "
                 "is not in the rates).\n",
                 "| env | local processes (steps/s) | Ray tasks (steps/s) | Ray overhead (target < 15%) |",
                 "|---|---|---|---|"]
        lines += [f"| {e} | {loc:.0f} | {r:.0f} | {ovh:.1%} |" for e, loc, r, ovh in ray_rows]
        write_section("ray-overhead", "\n".join(lines))
    if args.default_datasets:
        lines = [f"Measured {today} with `python -m langpref.bench --default-datasets` (all cores).\n",
                 "| env | trajectories | wall time | task success | largest abs off-diagonal feature correlation |",
                 "|---|---|---|---|---|"]
        for env_name in args.envs:
            r = default_dataset_wall(env_name, Path("data") / env_name)
            d = r["inspect"]
            lines.append(f"| {env_name} | {d['num_trajectories']} | {r['wall_s'] / 60:.1f} min ({r['workers']} workers)"
                         f" | {d['success_rate']:.1%} | {d['max_abs_off_diagonal_correlation']:.2f} |")
        write_section("default-datasets", "\n".join(lines))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
