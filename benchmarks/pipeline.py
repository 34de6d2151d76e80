"""`make bench`: the library's speed figures, each written into this checkout's docs/results.md between its
`<!-- bench:NAME -->` markers (`python -m benchmarks.pipeline --help` for what to skip).

Measures, per env: raw `env.step` with random actions, the generator on one worker (target: >= 0.8 of raw), the
speed-up of 2 workers over 1 (target >= 1.7x), Ray's overhead against local processes (target < 15%), the import
rate (`benchmarks.throughput`); an experiment sweep's projected against measured wall time, the latency of a reward
update and an improvement step, the feedback gate, a generation step, the training times (`benchmarks.latency`);
the latency of choosing an active query (`benchmarks.selection`); and (optionally) the wall time of a default
dataset. Not part of the tests: timings belong in benchmarks, not in unit tests that flake on shared machines.
"""

from __future__ import annotations

import argparse

from benchmarks.common import RESULTS, today, use_egl, write_section
from benchmarks.latency import gate_table, generation_table, sweep_table, training_table, uses_table
from benchmarks.selection import selection_table
from benchmarks.throughput import default_datasets_table, generator_table, import_table, ray_overhead_table


def parser() -> argparse.ArgumentParser:
    """The options: the envs, the number of rounds, and a `--no-X` to skip each table."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    skips = (
        ("uses", "the reward-update and improvement-step latencies (need the default model)"),
        ("sweep", "the experiment-sweep projection (needs the default dataset data/ENV)"),
        ("gate", "the feedback-gate table (held-out phrasings let through, nonsense refused)"),
        ("import", "the `langpref import` rate"),
        ("selection", "the active query selection latency"),
        ("generation", "the latency of a generation step (needs the default dataset and model)"),
    )
    for name, what in skips:
        p.add_argument(
            f"--no-{name}", dest=name.replace("import", "import_"), action="store_false", help=f"skip {what}"
        )
    p.add_argument("--repeats", type=int, default=3, help="interleaved rounds per measurement; the best is kept")
    return p


def main(argv: list[str] | None = None) -> None:
    """Measure what the options ask for and rewrite those tables of docs/results.md."""
    args = parser().parse_args(argv)
    day = today()
    if args.generator:
        write_section("generator-throughput", generator_table(args.envs, args.repeats, day))
    if args.ray_rounds:
        write_section("ray-overhead", ray_overhead_table(args.envs, args.ray_rounds, day))
    if args.import_:
        write_section("import-throughput", import_table(day, args.repeats))
    if args.uses:
        write_section("uses-latency", uses_table(args.envs, day))
    if args.gate:
        write_section("feedback-gate", gate_table(args.envs, day))
    if args.selection:
        write_section("selection-latency", selection_table(args.envs, day))
    if args.generation:
        write_section("generation-latency", generation_table(args.envs, day))
    training = training_table(day)
    if training:
        write_section("training-time", training)
    if args.sweep:
        write_section("sweep-projection", sweep_table(args.envs, day))
    if args.default_datasets:
        write_section("default-datasets", default_datasets_table(args.envs, day))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    use_egl()
    main()
