"""Tasks, by name: the one place that knows which robot tasks exist.

Three kinds of task reach the registry:
- built-in: `metaworld` and `robosuite`, each a subpackage here owning its env wrapper, controller, bank and text;
- plugins: a Python package that declares an entry point in the group `langpref.tasks` (as Gymnasium's
  `gymnasium.envs`), pointing at a `Task` or at a function returning one; `langpref generate --env NAME` then works
  with no edit inside langpref;
- recorded: a task file (TOML, see `taskfile.py`) imported with `langpref import`; the dataset (and every model
  trained on it) carries the task, and opening them registers it (`register_task`).

Simulators are imported only when an env is made, so looking a task up is cheap.
"""

from __future__ import annotations

import importlib
from dataclasses import replace

from langpref.errors import LangprefError
from langpref.registry import Registry
from langpref.tasks.base import Controller, ObsField, SimEnv, Simulator, Task

ENTRY_POINT_GROUP = "langpref.tasks"
_BUILTIN = {"metaworld": "langpref.tasks.metaworld", "robosuite": "langpref.tasks.robosuite"}


def _not_builtin(task: Task) -> None:
    if task.name in _BUILTIN:
        raise ValueError(f"it is named {task.name!r}, a built-in task's name")


def _add_plugin(task: Task) -> None:
    REGISTRY.items.setdefault(task.name, replace(task, source="plugin"))


REGISTRY: Registry[Task] = Registry(
    "task", Task, ENTRY_POINT_GROUP, check=_not_builtin, add=_add_plugin, type_name="langpref.tasks.Task"
)
"""The plugin and recorded tasks (`langpref.registry`); the built-in ones are imported from `_BUILTIN` when asked
for, so looking one up never imports a simulator it does not need. A plugin that fails to load, gives no `Task` or
takes a built-in name is skipped with a warning naming it."""


def register_task(task: Task) -> Task:
    """Add a task (a recorded one, or one built in code) to the registry. Registering an equal task again is a
    no-op; a different task under a taken name is refused unless both are recorded tasks (the later one wins, as
    when the same task file was imported again)."""
    if task.name in _BUILTIN:
        raise LangprefError(f"a task may not be named {task.name!r}: that is a built-in task")
    old = REGISTRY.items.get(task.name)
    if old is not None and old != task and old.source == "plugin":
        raise LangprefError(f"task {task.name!r} is already registered by a plugin; rename it in its task file")
    REGISTRY.items[task.name] = task
    return task


def task_names() -> tuple[str, ...]:
    """Every task known in this process: built-ins first, then plugins and recorded tasks."""
    return (*_BUILTIN, *(name for name in REGISTRY.names() if name not in _BUILTIN))


def get_task(name: str) -> Task:
    """The task called `name`: a built-in one (its module imported now), a plugin's or a recorded one."""
    if name in _BUILTIN:
        return importlib.import_module(_BUILTIN[name]).TASK
    if name not in REGISTRY.items:
        REGISTRY.load_plugins()
    if name not in REGISTRY.items:
        raise LangprefError(
            f"unknown task {name!r}: known tasks are {', '.join(task_names())}; a recorded task becomes known by "
            "opening its dataset or model (`langpref import` makes one), a plugin by installing its package"
        )
    return REGISTRY.items[name]


def get_simulator(name: str) -> Simulator:
    """The simulator of a task, or a one-line error for a recorded task (which has only its recordings)."""
    task = get_task(name)
    if task.simulator is None:
        raise LangprefError(
            f"task {name!r} has no simulator (it is a recorded task): its trajectories come from "
            "`langpref import`, and its videos from the recording"
        )
    if task.simulator.extra:
        from langpref.extras import require

        require(task.simulator.extra, f"task {name!r}")
    return task.simulator


def make_env(name: str, horizon: int | None = None) -> SimEnv:
    sim = get_simulator(name)
    return sim.make_env(horizon or sim.default_horizon)


_LIVE_ENVS: dict[tuple[str, int], SimEnv] = {}


def live_env(name: str, horizon: int) -> SimEnv:
    """One live simulator per (task, horizon) per process, kept open: the env new trajectories are rolled out in
    (`langpref.propose`) and an image model renders their frames in (`LatentSpace.phi_of`), made once, not per
    rollout."""
    if (name, horizon) not in _LIVE_ENVS:
        _LIVE_ENVS[(name, horizon)] = get_simulator(name).make_env(horizon)
    return _LIVE_ENVS[(name, horizon)]


__all__ = [
    "ENTRY_POINT_GROUP",
    "Controller",
    "ObsField",
    "SimEnv",
    "Simulator",
    "Task",
    "get_simulator",
    "get_task",
    "live_env",
    "make_env",
    "register_task",
    "task_names",
]
