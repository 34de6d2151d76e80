"""The benchmarks live in benchmarks/ at the repository root, outside the package (issue 32): the package holds no
benchmark code, each benchmark answers --help, and the results file they write is this checkout's docs/results.md
whatever the working directory."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ("pipeline", "study_load", "study_faults")


def test_the_package_holds_no_benchmark_code():
    src = ROOT / "src" / "langpref"
    named = [str(p.relative_to(src)) for p in src.rglob("*.py") if "bench" in p.name]
    assert not named, f"benchmark modules inside the package (they belong in benchmarks/): {named}"
    for path in src.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom | ast.Import):
                names = [node.module or ""] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
                assert not any(n.split(".")[0] == "benchmarks" for n in names), f"{path} imports benchmarks"


def test_results_resolve_from_the_repository_root(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from benchmarks import common

    assert common.ROOT == ROOT and common.RESULTS == ROOT / "docs" / "results.md" and common.RESULTS.is_file()
    assert common.in_repo("data/metaworld") == ROOT / "data" / "metaworld"
    assert common.in_repo(tmp_path) == tmp_path
    assert common.shown(ROOT / "results" / "study_bench") == "results/study_bench"


def test_write_section_replaces_only_its_own_block(tmp_path):
    from benchmarks.common import write_section

    results = tmp_path / "results.md"
    results.write_text("# Results\n\nours\n<!-- bench:a -->\nold\n<!-- /bench:a -->\nalso ours\n")
    write_section("a", "new", results)
    write_section("b", "added", results)
    assert results.read_text() == (
        "# Results\n\nours\n<!-- bench:a -->\nnew\n<!-- /bench:a -->\nalso ours\n\n<!-- bench:b -->\nadded\n"
        "<!-- /bench:b -->\n"
    )


@pytest.mark.parametrize("name", BENCHMARKS)
def test_every_benchmark_answers_help(name, capsys):
    module = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit) as exc:
        module.main(["--help"])
    assert exc.value.code == 0 and "usage" in capsys.readouterr().out


def test_selection_timings_measure_every_strategy_at_a_tiny_size():
    """The active-query timing bench (moved out of `langpref.reward`) still runs against the package's API."""
    from benchmarks.selection import selection_table

    table = selection_table(["metaworld"], "today", answers=3, candidates=12, trials=2)
    rows = [line for line in table.splitlines() if line.startswith("| metaworld |")]
    assert len(rows) == 6 and "`benchmarks.selection`" in table


def test_the_unpaced_run_says_whether_its_p95_met_the_target():
    """The study load benchmark's burst run prints p50 / p95 / max of all answers, the load, and the verdict."""
    from benchmarks.study_load import TARGET_P95_MS, verdict

    load = {"start": 1.0, "min": 1.0, "mean": 2.0, "max": 3.0, "end": 2.0}
    run = {"participants": 20, "completed": 20, "load": load}
    fast = {**run, "latency_all": {"n": 1000, "p50_ms": 40.0, "p95_ms": TARGET_P95_MS - 1, "max_ms": 900.0}}
    slow = {**run, "latency_all": {"n": 1000, "p50_ms": 40.0, "p95_ms": TARGET_P95_MS, "max_ms": 900.0}}
    assert verdict(fast).endswith(": MET") and "p95 299 ms" in verdict(fast) and "load average 2.0" in verdict(fast)
    assert verdict(slow).endswith(": NOT MET")
