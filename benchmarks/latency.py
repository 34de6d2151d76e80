"""What people and sweeps wait for (`python -m benchmarks.pipeline` writes the tables): a reward update and an
improvement step of a live session, the feedback gate, a generation step of Study 1, an experiment sweep's projected
against measured wall time, and the training times recorded by `langpref experiment alignment`.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import ROOT, in_repo, shown
from benchmarks.throughput import worker_startup_seconds


def sweep_timings(env_name: str, workers: int) -> dict:
    """A reward-learning sweep (language vs comparisons, 3 humans x 3 seeds, Q = 40: 18 tasks) on the default dataset
    and model, on 1 worker, then on `workers` local processes and Ray tasks: the projection from per-task time
    against the measured wall time. Uses the oracle latent space where no default model exists yet."""
    from langpref.experiments.alignment import default_model
    from langpref.experiments.common import SweepConfig, worker_space
    from langpref.experiments.reward import run_reward_experiment

    data, model = ROOT / "data" / env_name, in_repo(default_model(env_name))
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
        "space": "oracle" if perfect else shown(model),
        "tasks": tasks,
        "per_task_s": per_task,
        "startup_s": startup_s,
        "walls": walls,
        "workers": workers,
        "projected_s": startup_s + per_task * -(-tasks // workers),
    }


def sweep_table(envs: list[str], today: str) -> str:
    lines = [
        f"Measured {today} with `make bench` (`python -m benchmarks.pipeline`): `langpref experiment reward` "
        "(language vs comparisons, 3 humans x 3 seeds, Q = 40: one task per run) on the default dataset. "
        "Projected wall time on k workers: their start-up (processes spawned, torch and the model loaded, "
        "the bank encoded; timed apart) plus ceil(tasks / k) tasks at the 1-worker per-task time.\n",
        "| env | latent space | tasks | per-task time, 1 worker | 1 worker wall | workers | worker start-up "
        "| projected wall | measured, local processes | measured, Ray tasks | speed-up (local) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        if not (ROOT / "data" / env_name / "meta.json").exists():
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

    space = load_space(ROOT / "data" / env_name, in_repo(default_model(env_name)), env=env_name)
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
        f"Measured {today} with `make bench` (`python -m benchmarks.pipeline`) on the default dataset and the "
        "co-finetuned model, 2 CPU cores, 30 trials: the work a live session waits for. Reward update: "
        "add the 40th query and refit r_xi on all 40 (L-BFGS, warm start). Targets: update median < 50 ms "
        "and p95 < 100 ms; improvement step < 10 ms.\n",
        "| env | what | median (ms) | p95 (ms) |",
        "|---|---|---|---|",
    ]
    for env_name in envs:
        if not (in_repo(default_model(env_name)) / "config.json").exists():
            print(f"uses bench: no model {in_repo(default_model(env_name))}; skipped", file=sys.stderr)
            continue
        for what, (med, p95) in uses_timings(env_name).items():
            lines.append(f"| {env_name} | {what} | {med:.1f} | {p95:.1f} |")
    return "\n".join(lines)


def gate_table(envs: list[str], today: str) -> str:
    """The feedback gate on text it must let through (heldout/utterances.json, people-written phrasings outside the
    bank) and on text it should refuse (heldout/not_feedback.json)."""
    from langpref.language.bank import load_user_utterances
    from langpref.language.relevance import RELEVANCE_FLOOR, UNKNOWN_WORDS_FLOOR, FeedbackGate, gate_report

    nonsense = json.loads((ROOT / "heldout" / "not_feedback.json").read_text())["texts"]
    lines = [
        f"Measured {today} with `make bench` (`python -m benchmarks.pipeline`): `langpref.language.relevance` "
        f"(highest cosine to a bank phrasing in the pretrained MiniLM space; refused below {RELEVANCE_FLOOR}, "
        f"or below {UNKNOWN_WORDS_FLOOR} when no word is in the tokenizer's vocabulary, or when nearer to one of the "
        "gate's off-topic texts than to every bank phrasing) on the 12 x features x 2 held-out phrasings of "
        "`heldout/utterances.json` and the 25 texts of `heldout/not_feedback.json` (`langpref bank gate ENV "
        "--feedback heldout/utterances.json --not-feedback heldout/not_feedback.json`).\n",
        "| env | held-out phrasings let through | lowest held-out score | not-feedback texts refused "
        "| highest score among those let through | check, median (ms) |",
        "|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        gate = FeedbackGate(env_name)
        mapping = load_user_utterances(ROOT / "heldout" / "utterances.json", env_name)
        held = [t for by_dir in mapping.values() for ts in by_dir.values() for t in ts]
        report = gate_report(gate, held, nonsense)
        ms = []
        for text in nonsense:
            start = time.perf_counter()
            gate.score(text)
            ms.append(1e3 * (time.perf_counter() - start))
        fb, junk = report["feedback"], report["not_feedback"]
        high = junk["highest_score_let_through"]
        lines.append(
            f"| {env_name} | {fb['let_through']} / {fb['num']} | {fb['lowest_score']:.3f} "
            f"| {junk['refused']} / {junk['num']} | {high if high is None else f'{high:.3f}'} "
            f"| {np.median(ms):.1f} |"
        )
    return "\n".join(lines)


def training_table(today: str) -> str | None:
    """Training time and throughput per env, from the runs of `langpref experiment alignment` (default config)."""
    from langpref.experiments.alignment import RESULTS_ROOT

    lines = []
    for path in sorted(in_repo(RESULTS_ROOT).glob("*/alignment.json")):
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


def generation_table(envs: list[str], today: str, steps: int = 10) -> str:
    """One generation step as Study 1 waits for it (`experiments.generate.step_latency`) on the default dataset and
    model of each env, at the dataset's horizon."""
    from langpref.experiments.alignment import default_model
    from langpref.experiments.generate import step_latency

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    lines = [
        f"Measured {today} with `python -m benchmarks.pipeline` (`generation_table`), {cores} CPU cores, {steps} "
        "steps per env, each Eq. 4's objective for a test phrasing from a random dataset trajectory, on data/ENV with "
        "results/alignment/ENV/cofinetuned. Targets: p95 < 5 s on Meta-World, < 30 s on robosuite.\n",
        "| env | horizon | rollouts per step | p50 (s) | p95 (s) | max (s) |",
        "|---|---|---|---|---|---|",
    ]
    for env_name in envs:
        r = step_latency(ROOT / "data" / env_name, in_repo(default_model(env_name)), steps=steps)
        lines.append(
            f"| {env_name} | {r['horizon']} | {r['rollouts']} | {r['p50_s']:.2f} | {r['p95_s']:.2f} "
            f"| {r['max_s']:.2f} |"
        )
    return "\n".join(lines)
