"""What the benchmarks share: where the repository is, writing a table into docs/results.md, and reading /proc.

Every path a benchmark reads or writes by default (docs/results.md, data/ENV, results/, heldout/) is resolved from
the repository root (`ROOT`), never from the working directory, so `python -m benchmarks.NAME` does the same from
anywhere inside or outside the checkout.
"""

from __future__ import annotations

import datetime as dt
import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository root (the folder that holds `benchmarks/`)."""
RESULTS = ROOT / "docs" / "results.md"
"""The results file whose `<!-- bench:NAME -->` blocks the benchmarks rewrite."""


def in_repo(path: str | Path) -> Path:
    """`path` if absolute, else the same path under the repository root."""
    path = Path(path)
    return path if path.is_absolute() else ROOT / path


def shown(path: str | Path) -> str:
    """`path` as the results file shows it: relative to the repository root where it lies inside it."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def today() -> str:
    """The date a table was measured, as the results file shows it."""
    return dt.date.today().isoformat()


def use_egl() -> None:
    """Headless rendering for a benchmark run as a script (a caller's own setting wins)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def write_section(name: str, body: str, path: Path = RESULTS) -> None:
    """Replace (or append) the block between `<!-- bench:NAME -->` markers of a results file; text outside the
    markers is left as it is."""
    path.parent.mkdir(parents=True, exist_ok=True)
    text = path.read_text() if path.exists() else "# Results\n"
    block = f"<!-- bench:{name} -->\n{body.strip()}\n<!-- /bench:{name} -->"
    pattern = re.compile(rf"<!-- bench:{name} -->.*?<!-- /bench:{name} -->", re.DOTALL)
    text = pattern.sub(lambda _: block, text) if pattern.search(text) else text.rstrip() + "\n\n" + block + "\n"
    path.write_text(text)


def descendants(pid: int) -> set[int]:
    """Every live process below `pid` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            children.setdefault(int(stat[stat.rindex(")") + 2 :].split()[1]), []).append(int(entry.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def alive(pids: set[int]) -> set[int]:
    """Those of `pids` that still run (not gone, not zombies)."""
    out = set()
    for p in pids:
        try:
            if Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                out.add(p)
        except OSError:
            pass
    return out


def rss_mib(pid: int) -> float:
    """Resident memory of process `pid` in MiB (from /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def cmdline(pid: int) -> str:
    """The command line of process `pid`, "" once it is gone."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""
