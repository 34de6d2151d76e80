"""Under CI (the env var CI set, as `.ci/run` sets it), a test module that cannot be collected because a module is
missing becomes one failing test named after that module, and the rest of the run goes on.

CI installs every extra, so there a missing module is a broken install and must fail. Left to pytest, a module-level
`import ray` (or `tests.factories.require`, which imports outright under CI) is a collection error, and one
collection error interrupts the whole run before any test runs: one missing extra hid every other result. A
module-level skip (`pytest.importorskip`, `pytest.skip(..., allow_module_level=True)`) becomes one failing test the
same way. Any other collection error (a syntax error, a failing conftest) still stops the run, as pytest has it.

`tests/conftest.py` takes the hook from here; a test runs pytest with `-p tests.ci_collect` on made-up modules.
"""

from __future__ import annotations

import os

import pytest
from _pytest.reports import CollectReport

UNDER_CI_SKIP = "skipped under CI, which must run every test"


class Uncollectable(pytest.Item):
    """The one failing test that stands, under CI, for a test module that could not be collected."""

    def __init__(self, *, why: str, **kwargs) -> None:
        super().__init__(**kwargs)
        self.why = why

    def runtest(self) -> None:
        pytest.fail(self.why, pytrace=False)

    def reportinfo(self):
        return self.path, None, f"{self.path.name}::{self.name}"


def missing_module(report: CollectReport) -> ImportError | None:
    """The ImportError behind a failed collection (pytest raises its CollectError from it), if that is the cause."""
    call = getattr(report, "call", None)
    exc = call.excinfo.value if call is not None and call.excinfo is not None else None
    while exc is not None and not isinstance(exc, ImportError):
        exc = exc.__cause__ or exc.__context__
    return exc


def uncollectable_test(collector: pytest.Collector, report: CollectReport) -> Uncollectable | None:
    """Under CI, the failing test that replaces `report` of a test module that a missing module or a module-level skip
    kept from being collected; None for anything else."""
    if not os.environ.get("CI") or not isinstance(collector, pytest.Module):
        return None
    if report.skipped:
        reason = report.longrepr[-1] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        return Uncollectable.from_parent(collector, name="skipped_module", why=f"{UNDER_CI_SKIP}: {reason}")
    exc = missing_module(report) if report.failed else None
    if exc is None:
        return None
    name = exc.name or "unknown"
    why = f"{collector.path.name} could not be imported: module {name!r} is missing ({type(exc).__name__}: {exc})"
    return Uncollectable.from_parent(collector, name=f"missing_module[{name}]", why=why)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    """A test module kept from collection by a missing module or a module-level skip is, under CI, one failing test
    (see the module docstring); a skip while collecting anything else fails that collection under CI."""
    outcome = yield
    report = outcome.get_result()
    item = uncollectable_test(collector, report)
    if item is not None:
        outcome.force_result(CollectReport(report.nodeid, "passed", None, [item]))
    elif os.environ.get("CI") and report.skipped:
        reason = report.longrepr[-1] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome, report.longrepr = "failed", f"{UNDER_CI_SKIP}: {reason}"
