"""The study package stays split by job (issue 32): every module under 500 lines, and no function over 60 lines
unless `LONG` says why."""

from __future__ import annotations

import ast
from pathlib import Path

STUDY = Path(__file__).resolve().parents[2] / "src" / "langpref" / "study"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60
LONG: dict[str, str] = {}
"""`module.function` -> why it is longer than MAX_FUNCTION_LINES (none is, today)."""


def modules() -> list[Path]:
    found = sorted(STUDY.rglob("*.py"))
    assert len(found) > 10, f"no study package at {STUDY}"
    return found


def test_study_modules_stay_under_500_lines():
    sizes = {str(p.relative_to(STUDY)): len(p.read_text().splitlines()) for p in modules()}
    big = {name: n for name, n in sizes.items() if n >= MAX_MODULE_LINES}
    assert not big, f"split these by job (modules of src/langpref/study/ stay under {MAX_MODULE_LINES} lines): {big}"


def test_study_functions_stay_short_or_say_why():
    long = {}
    for path in modules():
        module = ".".join(path.relative_to(STUDY).with_suffix("").parts)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES and f"{module}.{node.name}" not in LONG:
                    long[f"{module}.{node.name}"] = lines
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: split them, or write why in LONG: {long}"
