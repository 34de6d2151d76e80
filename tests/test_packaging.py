"""Packaging: a small core with extras per optional part, ranges in pyproject and exact pins in the constraints file,
one line naming the extra when a command needs one that is missing, the version, the license and the changelog.

The wheel itself is built, installed with only the core into a fresh venv and smoke-tested by `make wheel-check`.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

import langpref
from langpref import extras

ROOT = Path(__file__).parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PROJECT = PYPROJECT["project"]
CORE = [Requirement(r) for r in PROJECT["dependencies"]]
OPTIONAL = {name: [Requirement(r) for r in reqs] for name, reqs in PROJECT["optional-dependencies"].items()}
NOT_IN_CORE = ("metaworld", "robosuite", "mujoco", "fastapi", "uvicorn", "ray", "pyarrow", "pytest")


def constraints() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "requirements" / "constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not an exact pin"
            pins[canonicalize_name(name)] = version
    return pins


def test_core_has_ranges_and_torch_exactly():
    by_name = {canonicalize_name(r.name): r for r in CORE}
    assert str(by_name["torch"].specifier) == "==2.13.0"
    exact = [str(r) for r in CORE if r.name != "torch" and any(s.operator == "==" for s in r.specifier)]
    assert not exact, f"core dependencies pinned exactly (pins belong in requirements/constraints.txt): {exact}"
    assert not set(by_name) & set(NOT_IN_CORE), "a simulator, the study app, Ray, pyarrow or pytest in the core"


def test_every_extra_of_the_code_is_declared_and_in_all():
    all_extra = {x for r in OPTIONAL["all"] for x in r.extras if canonicalize_name(r.name) == "langpref"}
    for extra in extras.EXTRAS:
        assert extra in OPTIONAL, f"extras.py names extra {extra!r}, which pyproject.toml does not declare"
        assert extra in all_extra, f"langpref[all] leaves out {extra!r}"
    assert {"test", "docs"} <= set(OPTIONAL)


def test_every_dependency_has_a_known_good_pin_that_its_range_admits():
    pins = constraints()
    for req in CORE + [r for reqs in OPTIONAL.values() for r in reqs if canonicalize_name(r.name) != "langpref"]:
        name = canonicalize_name(req.name)
        assert name in pins, f"{req} has no exact pin in requirements/constraints.txt"
        assert req.specifier.contains(pins[name], prereleases=True), f"{req} does not admit the pin {pins[name]}"


def test_version_everywhere(capsys):
    from langpref.cli import main

    assert re.fullmatch(r"\d+\.\d+\.\d+", langpref.__version__)
    assert PROJECT["dynamic"] == ["version"]  # read from langpref.__version__, so there is one place to bump it
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"langpref {langpref.__version__}"
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert f"## [{langpref.__version__}]" in changelog, "CHANGELOG.md has no section for this version"


def test_license_file_is_the_declared_one():
    assert PROJECT["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")


def test_cli_modules_stay_small():
    sizes = {p.name: len(p.read_text().splitlines()) for p in (ROOT / "src" / "langpref" / "cli").glob("*.py")}
    assert sizes and max(sizes.values()) < 500, sizes


def test_simulated_tasks_name_their_extra():
    from langpref.tasks import get_task

    assert get_task("metaworld").simulator.extra == "metaworld"
    assert get_task("robosuite").simulator.extra == "robosuite"


def test_needs_turns_only_the_extras_own_modules_into_one_line():
    with pytest.raises(
        extras.MissingExtra,
        match=r"^--backend ray needs ray, which is not installed: "
        r"pip install 'langpref\[ray\]'$",
    ):
        with extras.needs("ray", "--backend ray"):
            raise ModuleNotFoundError("No module named 'ray'", name="ray")
    with pytest.raises(ModuleNotFoundError):  # a module of another part is a bug to see, not an extra to install
        with extras.needs("ray", "--backend ray"):
            raise ModuleNotFoundError("No module named 'grpc'", name="grpc")


HIDE = "import sys\nfor m in {mods!r}: sys.modules[m] = None  # as if not installed\n"


def run_cli_without(modules: tuple[str, ...], args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    code = HIDE.format(mods=modules) + f"from langpref.cli import main\nsys.exit(main({args!r}))\n"
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    "extra, modules, args",
    [
        (
            "metaworld",
            ("metaworld",),
            ["generate", "--env", "metaworld", "--out", "gen", "--num-trajectories", "4", "--workers", "2"],
        ),
        ("robosuite", ("robosuite",), ["generate", "--env", "robosuite", "--out", "gen", "--num-trajectories", "4"]),
        ("metaworld", ("mujoco",), ["generate", "--env", "metaworld", "--out", "gen", "--num-trajectories", "4"]),
    ],
)
def test_a_command_that_needs_a_missing_extra_says_which_in_one_line(tmp_path, extra, modules, args):
    proc = run_cli_without(modules, args, tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and f"pip install 'langpref[{extra}]'" in lines[0]
    assert not (tmp_path / "gen" / "trajectories").exists() or not any((tmp_path / "gen" / "trajectories").iterdir())


def test_study_serve_and_lerobot_import_without_their_extras(tmp_path):
    proc = run_cli_without(
        ("fastapi", "uvicorn"),
        ["study", "serve", "--model", "m", "--data", "d", "--db", str(tmp_path / "s.db")],
        tmp_path,
    )
    assert proc.returncode == 2 and proc.stderr.strip() == (
        "error: langpref study serve needs fastapi, which is not installed: pip install 'langpref[study]'"
    ), proc.stderr
    task = tmp_path / "task.toml"
    (tmp_path / "bank.json").write_text(
        '{"reach": {"increase": ["Reach further.", "Go further out.", "Stretch out."],'
        ' "decrease": ["Reach less.", "Stay closer in.", "Keep your arm in."]}}'
    )
    task.write_text('name = "lr"\ndescription = "d"\nfeatures = ["reach"]\nutterances = "bank.json"\n')
    fixture = ROOT / "tests" / "fixtures" / "lerobot" / "tiny"
    proc = run_cli_without(("pyarrow",), ["import", str(fixture), "--task", str(task), "--out", "ds"], tmp_path)
    assert proc.returncode == 2 and proc.stderr.strip().endswith("pip install 'langpref[lerobot]'"), proc.stderr


def test_core_modules_import_without_any_extra(tmp_path):
    hidden = ("metaworld", "robosuite", "mujoco", "fastapi", "starlette", "uvicorn", "ray", "pyarrow")
    code = HIDE.format(mods=hidden) + (
        "import langpref.cli, langpref.dataset.importer, langpref.dataset.storage, langpref.model.train, "
        "langpref.model.evaluate, langpref.improve, langpref.reward, langpref.reward.saved, langpref.propose, "
        "langpref.feedback, langpref.tasks, langpref.tasks.gym\n"
        "from langpref.tasks import task_names, get_task\n"
        "assert {'metaworld', 'robosuite'} <= set(task_names()); [get_task(n) for n in task_names()]\n"
        "langpref.cli.build_parser()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
