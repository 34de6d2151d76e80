"""One size rule for all of src/langpref (issue 32): every module (and every script of the web pages, issue 43) under
500 lines, and no function over 60 lines unless a reason is written below. The rule is held by this test, not by
memory: size crept back a day after it held when only one package was checked."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "langpref"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60

LONG_MODULES: dict[str, str] = {}
"""Dotted module (under langpref) -> why it may reach MAX_MODULE_LINES."""

LONG_FUNCTIONS: dict[str, str] = {
    "tasks.robosuite.env._lift_with_bottle_class": (
        "builds robosuite's Lift subclass inside a function so robosuite is imported only when the task is made; "
        "its length is the class body, whose methods are each short"
    )
}
"""`module.function` -> why it may be longer than MAX_FUNCTION_LINES."""


def modules() -> dict[str, Path]:
    found = {".".join(p.relative_to(SRC).with_suffix("").parts): p for p in sorted(SRC.rglob("*.py"))}
    assert len(found) > 50, f"no package at {SRC}"
    return found


def test_modules_stay_under_500_lines():
    sizes = {name: len(p.read_text().splitlines()) for name, p in modules().items()}
    big = {name: n for name, n in sizes.items() if n >= MAX_MODULE_LINES and name not in LONG_MODULES}
    assert not big, f"split these by job (modules of src/langpref stay under {MAX_MODULE_LINES} lines): {big}"


def test_scripts_stay_under_500_lines():
    """The same size rule for the web pages' JavaScript (src/langpref/**/*.js): a page grows by a script, not by a
    longer one."""
    scripts = sorted(SRC.rglob("*.js"))
    assert scripts, f"no script under {SRC}"
    big = {str(p.relative_to(SRC)): n for p in scripts if (n := len(p.read_text().splitlines())) >= MAX_MODULE_LINES}
    assert not big, f"split these into scripts loaded in order (each under {MAX_MODULE_LINES} lines): {big}"


def test_functions_stay_short_or_say_why():
    long = {}
    for module, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES and f"{module}.{node.name}" not in LONG_FUNCTIONS:
                    long[f"{module}.{node.name}"] = lines
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: split them, or write why in LONG_FUNCTIONS: {long}"


def test_every_written_exception_is_still_needed():
    """A reason for a module or function that has since shrunk (or gone) is dropped, so the lists stay true."""
    paths = modules()
    for name in LONG_MODULES:
        assert name in paths and len(paths[name].read_text().splitlines()) >= MAX_MODULE_LINES, f"drop {name}"
    sizes: dict[str, int] = {}
    for module, path in paths.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                key = f"{module}.{node.name}"
                sizes[key] = max(sizes.get(key, 0), node.end_lineno - node.lineno + 1)
    stale = [name for name in LONG_FUNCTIONS if sizes.get(name, 0) <= MAX_FUNCTION_LINES]
    assert not stale, f"these are short now; drop them from LONG_FUNCTIONS: {stale}"


def test_test_modules_have_unique_names():
    """Test folders are not packages, so two test modules of one name cannot run in one session: keep names unique
    (`tests/experiments/test_improve_experiment.py` beside `tests/test_improve.py`)."""
    names: dict[str, list[str]] = {}
    for path in (SRC.parents[1] / "tests").rglob("test_*.py"):
        names.setdefault(path.name, []).append(str(path.relative_to(SRC.parents[1])))
    assert not {n: p for n, p in names.items() if len(p) > 1}, "rename one of each"


ONE_WAY = {"feedback": "reward", "dataset": "reward"}
"""package -> a package downstream of it that it must not import at run time (docs/design.md: nothing downstream
reaches back upstream). Imports under `if TYPE_CHECKING:` are for type checkers only and do not count."""


def _tree_and_type_only(path: Path) -> tuple[ast.Module, set[int]]:
    """A file's syntax tree and the ids of its nodes under `if TYPE_CHECKING:` (for type checkers only)."""
    tree = ast.parse(path.read_text())
    skip = {
        id(node)
        for block in ast.walk(tree)
        if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.unparse(block.test)
        for stmt in block.body
        for node in ast.walk(stmt)
    }
    return tree, skip


def _runtime_imports(path: Path) -> set[str]:
    """Every module a file imports outside `if TYPE_CHECKING:` blocks, at any depth (function-level imports too)."""
    tree, skip = _tree_and_type_only(path)
    found = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
    return found


def test_feedback_and_datasets_import_nothing_of_reward_learning():
    bad = {
        name: sorted(m for m in _runtime_imports(path) if m.startswith(f"langpref.{ONE_WAY[name.split('.')[0]]}"))
        for name, path in modules().items()
        if name.split(".")[0] in ONE_WAY
    }
    assert not {k: v for k, v in bad.items() if v}, "move the import to the downstream package, or pass the object in"


PIPELINE = ("tasks", "dataset", "language", "model", "feedback", "reward")
"""The packages of docs/design.md's pipeline, upstream first. A package imports none downstream of it, nor any of the
rest of langpref above them (improve, propose, experiments, study, cli, demo), by any import at all: at run time,
inside a function, or under `if TYPE_CHECKING:` (a reader and a type checker see that one too). Stronger than
ONE_WAY: what a package needs of one downstream it names in a Protocol of its own, or is passed."""
ABOVE_PIPELINE = ("improve", "propose", "experiments", "study", "cli", "demo")


def _every_import(path: Path) -> set[str]:
    """Every module a file imports anywhere, and each `from X import name` as `X.name` too (`from langpref import
    reward` imports the package)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    return found


def test_the_pipeline_imports_one_way_even_for_type_checkers():
    bad = {}
    for name, path in modules().items():
        package = name.split(".")[0]
        if package not in PIPELINE:
            continue
        downstream = [f"langpref.{p}" for p in (*PIPELINE[PIPELINE.index(package) + 1 :], *ABOVE_PIPELINE)]
        found = sorted(m for m in _every_import(path) if any(m == d or m.startswith(f"{d}.") for d in downstream))
        if found:
            bad[name] = found
    assert not bad, f"upstream imports downstream (docs/design.md, Pipeline): move it down, or pass it in: {bad}"


STUDY_ONE_WAY = {
    "study.protocol": ("study.session", "study.server", "study.analysis"),
    "study.session": ("study.server", "study.analysis"),
    "study.analysis": ("study.server", "study.session"),
}
"""A room of the study app -> the rooms above it that it must not import at run time (langpref/study/__init__.py):
server -> session -> protocol and server -> analysis -> protocol, never back. The server alone may import the rooms
below it. Imports under `if TYPE_CHECKING:` do not count, as for ONE_WAY."""


def _runtime_imports_and_names(path: Path) -> set[str]:
    """`_runtime_imports`, and each name a `from X import name` takes at run time as `X.name`: `from langpref.study
    import server` imports the room."""
    tree, skip = _tree_and_type_only(path)
    named = {
        f"{node.module}.{alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module and id(node) not in skip
        for alias in node.names
    }
    return _runtime_imports(path) | named


def test_the_study_rooms_import_one_way():
    bad = {}
    for name, path in modules().items():
        room = next((r for r in STUDY_ONE_WAY if name == r or name.startswith(f"{r}.")), None)
        if room is None:
            continue
        above = [f"langpref.{r}" for r in STUDY_ONE_WAY[room]]
        imported = _runtime_imports_and_names(path)
        found = sorted(m for m in imported if any(m == a or m.startswith(f"{a}.") for a in above))
        if found:
            bad[name] = found
    assert not bad, "move what both need down to the lower room, or pass it in (langpref/study/__init__.py)"
