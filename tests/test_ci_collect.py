"""Under CI a missing module fails one test that names it, and the run goes on (`tests/ci_collect.py`): before, a
module-level import of a missing extra was a collection error that interrupted the whole pytest run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

MODULES = {
    "test_fine.py": "def test_fine():\n    assert True\n",
    "test_needs_an_extra.py": "import langpref_no_such_extra  # noqa\n\n\ndef test_never_runs():\n    pass\n",
    "test_skips_itself.py": "import pytest\n\npytest.importorskip('langpref_no_skip')\n\n\ndef test_x():\n    pass",
    "test_broken.py": "def test_broken(:\n",
}


def _pytest(folder: Path, ci: bool, *only: str) -> subprocess.CompletedProcess:
    """pytest with this plugin (and no project conftest) on `folder`'s modules, under CI or not."""
    env = {k: v for k, v in os.environ.items() if k != "CI"} | ({"CI": "1"} if ci else {})
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    argv = [sys.executable, "-m", "pytest", "-p", "tests.ci_collect", "-q", "-rA", "-p", "no:cacheprovider"]
    argv += ["-c", str(folder / "pytest.ini"), "--rootdir", str(folder), *(str(folder / m) for m in only)]
    return subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True, timeout=120)


def _write(tmp_path: Path) -> Path:
    for name, text in MODULES.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    return tmp_path


def test_under_ci_a_missing_module_is_one_failing_test_named_after_it(tmp_path):
    folder = _write(tmp_path)
    run = _pytest(folder, True, "test_fine.py", "test_needs_an_extra.py", "test_skips_itself.py")
    out = run.stdout + run.stderr
    assert run.returncode == 1, out  # tests failed; 2 would be an interrupted run
    assert "Interrupted" not in out and "1 passed" in out and "2 failed" in out
    assert "test_needs_an_extra.py::missing_module[langpref_no_such_extra]" in out
    assert "module 'langpref_no_such_extra' is missing" in out
    assert "test_skips_itself.py::skipped_module" in out and "skipped under CI" in out


def test_outside_ci_skips_stay_skips_and_other_collection_errors_still_stop_the_run(tmp_path):
    folder = _write(tmp_path)
    run = _pytest(folder, False, "test_fine.py", "test_skips_itself.py")
    assert run.returncode == 0 and "1 passed, 1 skipped" in run.stdout, run.stdout + run.stderr
    run = _pytest(folder, True, "test_fine.py", "test_broken.py")
    assert run.returncode == 2 and "Interrupted" in run.stdout, run.stdout + run.stderr
