"""`make bench`: throughput of the simulators and the generator, written into docs/results.md.

Measures, per env: raw `env.step` with random actions, the generator on one worker (target: >= 0.8 of raw), the
speed-up of 2 workers over 1 (target >= 1.7x), Ray's overhead against local processes (target < 15%), an
experiment sweep's projected against measured wall time, the latency of a reward update and an improvement step,
the latency of choosing an active query (`langpref.reward.latency`), the training times, and (optionally) the
wall time of a default dataset.
Not part of the tests: timings belong in benchmarks, not in unit tests that flake on shared machines.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path("docs/results.md")


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
    return job


def worker_startup_seconds(setup, setup_args: tuple, workers: int) -> float:
    """Wall time for `workers` fresh processes to start and build their per-process state (a simulator, a latent
    space): the one-off cost before their first task."""
    from langpref.backends import run_jobs

    start = time.perf_counter()
    list(run_jobs(_noop, list(range(workers)), setup=setup, setup_args=setup_args, workers=workers))
    return time.perf_counter() - start


def sweep_timings(env_name: str, workers: int) -> dict:
    """A reward-learning sweep (language vs comparisons, 3 humans x 3 seeds, Q = 40: 18 tasks) on the default dataset
    and model, on 1 worker, then on `workers` local processes and Ray tasks: the projection from per-task time
    against the measured wall time. Uses the oracle latent space where no default model exists yet."""
    from langpref.experiments.alignment import default_model
    from langpref.experiments.common import SweepConfig, worker_space
    from langpref.experiments.reward import run_reward_experiment

    data, model = Path("data") / env_name, default_model(env_name)
    perfect = not (model / "config.json").exists()
    model = None if perfect else model
    space_args = (data, model, env_name, perfect)
    worker_space(*space_args)  # warm imports and file cache, as a worker's later tasks find them
    start = time.perf_counter()
    worker_space(*space_args)
    warm_load_s = time.perf_counter() - start
    startup_s = worker_startup_seconds(worker_space, space_args, workers)
    walls = {}
    for name, sweep in (
        ("1 worker", SweepConfig(workers=1)),
        ("local", SweepConfig(workers=workers)),
        ("ray", SweepConfig(backend="ray", workers=workers)),
    ):
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            run_reward_experiment(env_name, data, model, Path(tmp), perfect=perfect, progress=False, sweep=sweep)
            walls[name] = time.perf_counter() - start
    tasks = 18
    per_task = (walls["1 worker"] - warm_load_s) / tasks
    return {
        "env": env_name,
        "space": "oracle" if perfect else str(model),
        "tasks": tasks,
        "per_task_s": per_task,
        "startup_s": startup_s,
        "walls": walls,
        "workers": workers,
        "projected_s": startup_s + per_task * -(-tasks // workers),
    }


def uses_timings(env_name: str, trials: int = 30, queries: int = 40) -> dict:
    """What a live session waits for, on the default dataset and model: one reward-learning refit after query number
    `queries` (language with L_Explicit + L_Implicit, and comparisons), one improvement step (Eq. 4 argmax over the
    test split), and embedding one new free-form sentence with the model. Milliseconds per trial."""
    from langpref.experiments.alignment import default_model
    from langpref.feedback.comparison import ComparisonHuman, ComparisonQuery, comparison_pairs
    from langpref.feedback.humans import sample_weights
    from langpref.feedback.language import LanguageHuman, LanguageQuery, language_pairs
    from langpref.feedback.space import load_space
    from langpref.improve import improvement_step
    from langpref.reward import RewardConfig, RewardLearner

    space = load_space(Path("data") / env_name, default_model(env_name), env=env_name)
    pool, cands = space.split("train"), space.split("test")
    times: dict[str, list[float]] = {
        "language update": [],
        "comparison update": [],
        "improvement step": [],
        "embed a new sentence": [],
    }
    for trial in range(trials):
        rng = np.random.default_rng([trial, 99])
        w = sample_weights(len(space.feature_names), rng)
        lang = LanguageHuman(w, space.theta, space.table("test"), pool, space.feature_names, 1.0, rng)
        comp = ComparisonHuman(w, space.theta, 1.0, rng)
        cfg = RewardConfig()
        for kind in ("language", "comparison"):
            learner = RewardLearner(space.dim, cfg, seed=trial)
            for q in range(queries):
                if kind == "language":
                    batch = language_pairs(space, lang.answer(LanguageQuery(int(rng.choice(pool)))), cfg, rng)
                else:
                    a, b = rng.choice(pool, size=2, replace=False)
                    batch = comparison_pairs(space, comp.answer(ComparisonQuery(int(a), int(b))))
                start = time.perf_counter()
                learner.add(batch)
                learner.fit()
                if q == queries - 1:
                    times[f"{kind} update"].append(1e3 * (time.perf_counter() - start))
        psi = space.psi_of(space.table("test").texts[trial % len(space.table("test").texts)])
        start = time.perf_counter()
        improvement_step(space.phi[cands], space.phi[int(rng.choice(cands))], psi)
        times["improvement step"].append(1e3 * (time.perf_counter() - start))
        start = time.perf_counter()
        space.encode([f"please move a little more carefully, attempt {trial}"])
        times["embed a new sentence"].append(1e3 * (time.perf_counter() - start))
    return {k: (float(np.median(v)), float(np.percentile(v, 95))) for k, v in times.items()}


def uses_table(envs: list[str], today: str) -> str:
    from langpref.experiments.alignment import default_model

    lines = [
        f"Measured {today} with `make bench` (`python -m langpref.bench`) on the default dataset and the "
        "co-finetuned model, 2 CPU cores, 30 trials: the work a live session waits for. Reward update: "
        "add the 40th query and refit r_xi on all 40 (L-BFGS, warm start). Targets: update median < 50 ms "
        "and p95 < 100 ms; improvement step < 10 ms.\n",
        "| env | what | median (ms) | p95 (ms) |",
        "|---|---|---|---|",
    ]
    for env_name in envs:
        if not (default_model(env_name) / "config.json").exists():
            print(f"uses bench: no model {default_model(env_name)}; skipped", file=sys.stderr)
            continue
        for what, (med, p95) in uses_timings(env_name).items():
            lines.append(f"| {env_name} | {what} | {med:.1f} | {p95:.1f} |")
    return "\n".join(lines)


def gate_table(envs: list[str], today: str) -> str:
    """The feedback gate on text it must let through (heldout/utterances.json, people-written phrasings outside the
    bank) and on text it should refuse (heldout/not_feedback.json)."""
    from langpref.language.bank import load_user_utterances
    from langpref.language.relevance import RELEVANCE_FLOOR, UNKNOWN_WORDS_FLOOR, FeedbackGate

    nonsense = json.loads(Path("heldout/not_feedback.json").read_text())["texts"]
    lines = [
        f"Measured {today} with `make bench` (`python -m langpref.bench`): `langpref.language.relevance` "
        f"(highest cosine to a bank phrasing in the pretrained MiniLM space; refused below {RELEVANCE_FLOOR}, "
        f"or below {UNKNOWN_WORDS_FLOOR} when no word is in the tokenizer's vocabulary) on the 12 x features x 2 "
        "held-out phrasings of `heldout/utterances.json` and the 25 texts of `heldout/not_feedback.json`.\n",
        "| env | held-out phrasings let through | lowest held-out score | not-feedback texts refused "
        "| highest score among those let through | check, median (ms) |",
        "|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        gate = FeedbackGate(env_name)
        mapping = load_user_utterances(Path("heldout/utterances.json"), env_name)
        held = [gate.score(t) for by_dir in mapping.values() for ts in by_dir.values() for t in ts]
        junk, ms = [], []
        for text in nonsense:
            start = time.perf_counter()
            junk.append(gate.score(text))
            ms.append(1e3 * (time.perf_counter() - start))
        passed = [r.score for r in junk if r.ok]
        lines.append(
            f"| {env_name} | {sum(r.ok for r in held)} / {len(held)} | {min(r.score for r in held):.3f} "
            f"| {len(junk) - len(passed)} / {len(junk)} | {max(passed, default=float('nan')):.3f} "
            f"| {np.median(ms):.1f} |"
        )
    return "\n".join(lines)


def sweep_table(envs: list[str], today: str) -> str:
    lines = [
        f"Measured {today} with `make bench` (`python -m langpref.bench`): `langpref experiment reward` "
        "(language vs comparisons, 3 humans x 3 seeds, Q = 40: one task per run) on the default dataset. "
        "Projected wall time on k workers: their start-up (processes spawned, torch and the model loaded, "
        "the bank encoded; timed apart) plus ceil(tasks / k) tasks at the 1-worker per-task time.\n",
        "| env | latent space | tasks | per-task time, 1 worker | 1 worker wall | workers | worker start-up "
        "| projected wall | measured, local processes | measured, Ray tasks | speed-up (local) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        if not (Path("data") / env_name / "meta.json").exists():
            print(f"sweep bench: no default dataset data/{env_name}; skipped", file=sys.stderr)
            continue
        t = sweep_timings(env_name, 2)
        w = t["walls"]
        lines.append(
            f"| {env_name} | {t['space']} | {t['tasks']} | {t['per_task_s']:.2f} s | {w['1 worker']:.1f} s "
            f"| {t['workers']} | {t['startup_s']:.1f} s | {t['projected_s']:.1f} s | {w['local']:.1f} s "
            f"| {w['ray']:.1f} s | {w['1 worker'] / w['local']:.2f}x |"
        )
    return "\n".join(lines)


def training_table(today: str) -> str | None:
    """Training time and throughput per env, from the runs of `langpref experiment alignment` (default config)."""
    from langpref.experiments.alignment import RESULTS_ROOT

    lines = []
    for path in sorted(RESULTS_ROOT.glob("*/alignment.json")):
        t = json.loads(path.read_text())["train"]
        st, sps = t["stage_seconds"], t["stage_samples_per_s"]
        lines.append(
            f"| {path.parent.name} | {t['device']} ({t['torch_threads']} threads) "
            f"| {t['wall_s'] / 60:.1f} min | {st['1']:.0f} s, {sps['1']:,.0f} samples/s "
            f"| {st.get('2', 0):.0f} s, {sps.get('2', 0):,.0f} samples/s | {t['train_pairs']:,} |"
        )
    if not lines:
        return None
    return "\n".join(
        [
            f"Collected {today} by `make bench` from `results/alignment/ENV/alignment.json`, written by "
            "`langpref experiment alignment --env ENV` (the default two-stage training on the default dataset; wall "
            "time includes loading the data and the language model). Target: Meta-World under 10 min on 2 CPU cores.\n",
            "| env | device | both stages, wall | stage 1 (frozen language model) | stage 2 (co-finetuning) "
            "| train pairs |",
            "|---|---|---|---|---|---|",
            *lines,
        ]
    )


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


def generator_sections(envs: list[str], repeats: int, today: str) -> None:
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
        "(`python -m langpref.bench`). Horizon 500. Raw: episodes of `env.step` with uniform random actions "
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
    write_section("generator-throughput", "\n".join(table))


def ray_overhead_table(envs: list[str], rounds: int, today: str) -> str:
    """Ray's overhead against local processes (target < 15%), 2 workers: per round the same trajectories generated
    both ways back to back (the order alternating, so the machine's drift falls on both), the overhead 1 - ray/local
    per round, and its mean with a 95% t-interval over rounds. One best-of figure sat within its own noise (a
    negative overhead on robosuite), which is why the interval is reported."""
    from langpref.experiments.reward import paired_difference

    ray_init = ray_init_seconds(2)
    lines = [
        f"Measured {today} with `python -m langpref.bench --ray-rounds {rounds}` ({rounds} rounds per env), 2 "
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
        f"Measured {today} with `make bench` (`python -m langpref.bench`): `langpref import` of a plain recording "
        "(300 episodes x 200 steps, 39-dim observations, 4-dim actions, features from the task file's function, no "
        f"videos), best of {repeats}, one process.\n\n| episodes/s (target >= 50) |\n|---|\n| {max(rates):.0f} |"
    )


def generation_table(envs: list[str], today: str, steps: int = 10) -> str:
    """One generation step as Study 1 waits for it (`experiments.generate.step_latency`) on the default dataset and
    model of each env, at the dataset's horizon."""
    from langpref.experiments.alignment import default_model
    from langpref.experiments.generate import step_latency

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    lines = [
        f"Measured {today} with `python -m langpref.bench` (`generation_table`), {cores} CPU cores, {steps} steps per "
        "env, each Eq. 4's objective for a test phrasing from a random dataset trajectory, on data/ENV with "
        "results/alignment/ENV/cofinetuned. Targets: p95 < 5 s on Meta-World, < 30 s on robosuite.\n",
        "| env | horizon | rollouts per step | p50 (s) | p95 (s) | max (s) |",
        "|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        r = step_latency(Path("data") / env_name, default_model(env_name), steps=steps)
        lines.append(
            f"| {env_name} | {r['horizon']} | {r['rollouts']} | {r['p50_s']:.2f} | {r['p95_s']:.2f} "
            f"| {r['max_s']:.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--envs", nargs="+", default=["metaworld", "robosuite"])
    p.add_argument(
        "--default-datasets",
        action="store_true",
        help="also time a full default dataset per env (writes data/ENV; robosuite takes ~20-40 min)",
    )
    p.add_argument(
        "--no-generator", dest="generator", action="store_false", help="skip the generator and Ray throughput tables"
    )
    p.add_argument(
        "--ray-rounds",
        type=int,
        default=6,
        help="paired rounds of local processes vs Ray tasks per env (the overhead's interval); 0 skips it",
    )
    p.add_argument(
        "--no-uses",
        dest="uses",
        action="store_false",
        help="skip the reward-update and improvement-step latencies (need the default model)",
    )
    p.add_argument(
        "--no-sweep",
        dest="sweep",
        action="store_false",
        help="skip the experiment-sweep projection (needs the default dataset data/ENV)",
    )
    p.add_argument(
        "--no-gate",
        dest="gate",
        action="store_false",
        help="skip the feedback-gate table (held-out phrasings let through, nonsense refused)",
    )
    p.add_argument("--no-import", dest="import_", action="store_false", help="skip the `langpref import` rate")
    p.add_argument(
        "--no-selection", dest="selection", action="store_false", help="skip the active query selection latency"
    )
    p.add_argument(
        "--no-generation",
        dest="generation",
        action="store_false",
        help="skip the latency of a generation step (needs the default dataset and model)",
    )
    p.add_argument("--repeats", type=int, default=3, help="interleaved rounds per measurement; the best is kept")
    args = p.parse_args(argv)
    today = dt.date.today().isoformat()
    if args.generator:
        generator_sections(args.envs, args.repeats, today)
    if args.ray_rounds:
        write_section("ray-overhead", ray_overhead_table(args.envs, args.ray_rounds, today))
    if args.import_:
        write_section("import-throughput", import_table(today, args.repeats))
    if args.uses:
        write_section("uses-latency", uses_table(args.envs, today))
    if args.gate:
        write_section("feedback-gate", gate_table(args.envs, today))
    if args.selection:
        from langpref.reward.latency import selection_table

        write_section("selection-latency", selection_table(args.envs, today))
    if args.generation:
        write_section("generation-latency", generation_table(args.envs, today))
    training = training_table(today)
    if training:
        write_section("training-time", training)
    if args.sweep:
        write_section("sweep-projection", sweep_table(args.envs, today))
    if args.default_datasets:
        lines = [
            f"Measured {today} with `python -m langpref.bench --default-datasets` (all cores).\n",
            "| env | trajectories | wall time | task success | largest abs off-diagonal feature correlation |",
            "|---|---|---|---|---|",
        ]
        for env_name in args.envs:
            r = default_dataset_wall(env_name, Path("data") / env_name)
            d = r["inspect"]
            lines.append(
                f"| {env_name} | {d['num_trajectories']} | {r['wall_s'] / 60:.1f} min ({r['workers']} workers)"
                f" | {d['success_rate']:.1%} | {d['max_abs_off_diagonal_correlation']:.2f} |"
            )
        write_section("default-datasets", "\n".join(lines))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
