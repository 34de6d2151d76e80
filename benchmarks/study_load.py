"""Load benchmark of the study server: `python -m benchmarks.study_load` (part of `make bench`).

20 simulated participants (synthetic humans, `langpref.study.server.simulate`) run whole sessions of the paper's
protocol (10 improvement rounds at most, 20 queries per method, a rating every 5) at once against `langpref study serve`
in its own process on loopback, on this machine's cores. Measured on the client: the latency of every answer, by kind
and over all answers, and the machine's load average during each run (other work on the machine slows the server as
much as the participants do). Two runs:

- `paced`: each participant pauses 0.5-1.5 s before an answer (people take several seconds to watch and type);
- `burst` (unpaced): no pause at all, every participant answering as fast as the server allows. Target (issue 44):
  p95 over all its answers under 300 ms; the run prints whether it met it (`--no-paced`: this run alone).

The simulated participants type the bank's test phrasings (a few dozen texts, said again and again); the server reads
every bank phrasing at start, so the burst figure is that of texts it knows. A text it has never seen costs one
batched pass of each of three small encoders (the gate's, the scope check's, the model's), shared by the answers
that arrive together (`langpref.language.coalesce`).

Without --model it trains a model of the default architecture (MiniLM language encoder, D = 128; language model
frozen, one epoch: the serving cost does not depend on how well it is trained) on a fresh Meta-World dataset. The
paced run's database is exported (`langpref study export`) and summarised beside the load figures in the results
file (this checkout's docs/results.md unless --results says otherwise), between `<!-- bench:study-load -->` markers.
Videos are not part of the load (the simulated participants do not download them; a real study renders them ahead
at start).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from benchmarks.common import RESULTS, ROOT, shown, today, use_egl, write_section


def prepare(work: Path, num_trajectories: int) -> tuple[Path, Path]:
    """A fresh Meta-World dataset and a default-architecture model trained briefly on it."""
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.model.config import TrainConfig
    from langpref.model.train import train

    data, model = work / "data", work / "model"
    generate(GenerateConfig(env="metaworld", out=data, num_trajectories=num_trajectories, horizon=200, seed=5))
    train(
        TrainConfig(data=str(data), out=str(model), stage1_epochs=1, stage2_epochs=0, patience=0, device="cpu"),
        progress=True,
    )
    return data, model


def start_server(
    model: Path,
    data: Path,
    db: Path,
    split: str,
    env: dict[str, str] | None = None,
    quiet: bool = False,
    extra: tuple[str, ...] = (),
) -> tuple[subprocess.Popen, str]:
    """`langpref study serve` in a subprocess on a free port, once it answers /healthz: (process, base URL); `extra`:
    more options of `study serve`."""
    import httpx

    cmd = [
        sys.executable,
        "-m",
        "langpref",
        "study",
        "serve",
        "--model",
        str(model),
        "--data",
        str(data),
        "--db",
        str(db),
        "--port",
        "0",
        "--split",
        split,
        "--no-prerender",
        *extra,
    ]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL if quiet else None,
        text=True,
        env=None if env is None else {**os.environ, **env},
    )
    url = None
    for line in proc.stdout:
        m = re.search(r"participants: (http://\S+?)/?$", line.strip())
        if m:
            url = m.group(1)
            break
    if url is None:
        raise RuntimeError(f"the study server exited ({proc.wait()})")
    for _ in range(600):
        try:
            if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the study server did not answer")


TARGET_P95_MS = 300.0
"""Issue 44: p95 of all answers of the unpaced (burst) run of 20 participants, on 2 cores."""


class LoadWatch:
    """The machine's 1-minute load average, sampled every second while a run goes on (`with LoadWatch() as w`)."""

    def __init__(self, every_s: float = 1.0):
        self.every_s = every_s
        self.samples: list[float] = [os.getloadavg()[0]]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)

    def _watch(self) -> None:
        while not self._stop.wait(self.every_s):
            self.samples.append(os.getloadavg()[0])

    def __enter__(self) -> LoadWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.samples.append(os.getloadavg()[0])

    def summary(self) -> dict[str, float]:
        x = self.samples
        return {"start": x[0], "min": min(x), "mean": sum(x) / len(x), "max": max(x), "end": x[-1]}


def verdict(r: dict[str, Any]) -> str:
    """One line on an unpaced run: its answers' p50 / p95 / max, the load during it, and whether p95 met the target."""
    lat, load = r["latency_all"], r["load"]
    met = lat["p95_ms"] is not None and lat["p95_ms"] < TARGET_P95_MS
    return (
        f"unpaced run, {r['participants']} participants ({r['completed']} finished), {lat['n']} answers: "
        f"p50 {lat['p50_ms']:.0f} ms, p95 {lat['p95_ms']:.0f} ms, max {lat['max_ms']:.0f} ms; load average "
        f"{load['mean']:.1f} ({load['min']:.1f}-{load['max']:.1f}) on {os.cpu_count()} cores; "
        f"p95 < {TARGET_P95_MS:.0f} ms: {'MET' if met else 'NOT MET'}"
    )


def run(
    model: Path,
    data: Path,
    db: Path,
    split: str,
    participants: int,
    think_ms: tuple[float, float],
    query_selection: str = "random",
    learner: str = "paper",
) -> dict[str, Any]:
    from langpref.study.server.simulate import SimConfig, simulate

    extra = ("--query-selection", query_selection, "--learner", learner)
    proc, url = start_server(model, data, db, split, extra=extra)
    try:
        with LoadWatch() as load:
            cfg = SimConfig(participants=participants, think_ms=think_ms, deadline_s=1800.0)
            result = simulate(url, cfg, data_dir=data, split=split)
        return {**result, "load": load.summary()}
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _row(name: str, r: dict[str, Any]) -> str:
    lat = r["latency"]
    cell = {
        k: f"{lat[k]['p50_ms']:.0f} / {lat[k]['p95_ms']:.0f}" if k in lat else "-"
        for k in ("language", "comparison", "rating", "satisfaction", "survey")
    }
    return (
        f"| {name} | {r['completed']}/{r['participants']} | {r['answers']} | {r['wall_s']:.0f} s | "
        f"{cell['language']} | {cell['comparison']} | {cell['rating']} | {cell['satisfaction']} | "
        f"{cell['survey']} |"
    )


def results_text(
    args: argparse.Namespace, val_acc: float | None, paced: dict, burst: dict | None, summary: dict[str, Any]
) -> str:
    """The `study-load` block: how it was measured, the latency table, and what the paced run's export says."""
    model_note = (
        f"model `{shown(args.model)}`"
        if args.model
        else "a model of the default architecture (MiniLM language encoder, D = 128) trained one epoch here"
    )
    if isinstance(val_acc, float):
        model_note += f", validation accuracy {val_acc:.3f}"
    n = args.participants
    lines = [
        (
            f"Measured {today()} with `python -m benchmarks.study_load` on this machine ({os.cpu_count()} cores, "
            "no GPU): "
            f"{n} simulated participants at once run whole sessions of the paper's protocol against "
            f"`langpref study serve --query-selection {args.query_selection} --learner {args.learner}` on loopback "
            "(server in its own "
            f"process; {model_note}). "
            "Latency per answer as the "
            f"client sees it, p50 / p95 in ms. Target (issue 44): p95 of all answers of the burst run under "
            f"{TARGET_P95_MS:.0f} ms.\n"
        ),
        "| run | sessions completed | answers | wall | language | comparison | rating | satisfaction | survey |",
        "|---|---|---|---|---|---|---|---|---|",
        _row("paced (0.5-1.5 s pause before each answer)", paced),
    ]
    if burst:
        lines.append(_row(f"burst (no pause: all {n} answer as fast as the server allows)", burst))
        lines += ["", f"Burst run, all answers: {verdict(burst)}."]
    r = summary["study2_ratings"]
    test = r["auc_paired_test"]

    def f(x, d=2):
        return "-" if x is None else f"{x:.{d}f}"

    lines += [
        "",
        (
            f"Export of the paced run (`langpref study export`, synthetic humans as participants; report in "
            f"`{shown(args.export_out)}/report.html`): {summary['participants']} participants, "
            f"{summary['finished']} finished, orders {summary['method_order']}. Area under the rating curve "
            f"(queries {r['points']}): language "
            f"{f(r['language']['auc']['mean'])} +- {f(r['language']['auc']['std'])}, comparison "
            f"{f(r['comparison']['auc']['mean'])} +- {f(r['comparison']['auc']['std'])}; paired t-test p = "
            f"{f(test['t_p_value'], 4)}, Wilcoxon p = {f(test['wilcoxon_p_value'], 4)} (n = {test['n']}). "
            f"Study 1: {summary['study1_iterations_to_satisfaction']['n']} of {summary['participants']} satisfied "
            "within the rounds. Times per query here are the simulated pauses, not human times; what the ratings say "
            "depends on how well the model is trained."
        ),
    ]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    """The options: the model and data (or none: made here), the participants, the runs, where results go."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, default=None, help="checkpoint (default: train one, see above)")
    p.add_argument("--data", type=Path, default=None, help="dataset of --model")
    p.add_argument("--split", default="test", help="study split (default %(default)s)")
    p.add_argument("--participants", type=int, default=20)
    p.add_argument("--num-trajectories", type=int, default=80, help="of the dataset made without --data")
    p.add_argument("--no-burst", action="store_true", help="only the paced run")
    p.add_argument(
        "--no-paced",
        action="store_true",
        help="only the burst (unpaced) run: its verdict printed, no export and no results block written",
    )
    p.add_argument(
        "--query-selection",
        default="random",
        help="Study 2's query selection, as `study serve --query-selection` (default %(default)s)",
    )
    p.add_argument(
        "--learner",
        default="paper",
        help="Study 2's reward learner, as `study serve --learner`; a learner other than the paper's writes its own "
        "block, `study-load-LEARNER` (default %(default)s)",
    )
    p.add_argument("--results", type=Path, default=RESULTS, help="results file to update (default %(default)s)")
    p.add_argument(
        "--export-out",
        type=Path,
        default=ROOT / "results" / "study_bench",
        help="where the paced run's export goes (default %(default)s)",
    )
    return p


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the paced and burst loads (or one of them), print the burst run's verdict, export the paced run, and
    rewrite the `study-load` block of the results (not with --no-paced: the block needs the paced run's export)."""
    p = parser()
    args = p.parse_args(argv)
    if (args.model is None) != (args.data is None):
        p.error("pass both --model and --data, or neither")
    if args.no_paced and args.no_burst:
        p.error("--no-paced and --no-burst leave nothing to run")
    from langpref.model.checkpoint import read_config
    from langpref.study.analysis.export import export

    paced = burst = exported = None
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        data, model = (args.data, args.model) if args.model else prepare(work, args.num_trajectories)
        val_acc = read_config(model).get("results", {}).get("best_val_accuracy")
        sel, learner, n = args.query_selection, args.learner, args.participants
        if not args.no_paced:
            paced = run(model, data, work / "paced.sqlite", args.split, n, (500.0, 1500.0), sel, learner)
            print(json.dumps({"paced": {k: v for k, v in paced.items() if k != "per_participant"}}), flush=True)
        if not args.no_burst:
            burst = run(model, data, work / "burst.sqlite", args.split, n, (0.0, 0.0), sel, learner)
            print(json.dumps({"burst": {k: v for k, v in burst.items() if k != "per_participant"}}), flush=True)
            print(verdict(burst), flush=True)
        if paced is not None:
            exported = export(work / "paced.sqlite", args.export_out)
            summary = json.loads(Path(exported["summary"]).read_text())
    if paced is not None:
        block = "study-load" if args.learner == "paper" else f"study-load-{args.learner}"
        write_section(block, results_text(args, val_acc, paced, burst, summary), args.results)
        print(f"wrote {args.results}", flush=True)
    return {"paced": paced, "burst": burst, "export": exported}


if __name__ == "__main__":
    use_egl()
    main()
