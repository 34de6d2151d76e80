"""Simulated environments, by name. Simulators are imported only when an env is made, so the CLI starts instantly.

Each env module defines `SPEC` (an `EnvSpec`), `make(horizon) -> SimEnv`, `CONTROLLER_DIM` (how many unit-interval
numbers parameterise its scripted controller) and `make_controller(unit, rng) -> Controller`.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from langpref.envs.base import Controller, EnvSpec, ObsField, SimEnv
from langpref.errors import LangprefError

_MODULES = {"metaworld": "langpref.envs.metaworld_env", "robosuite": "langpref.envs.robosuite_env"}
ENV_NAMES: tuple[str, ...] = tuple(_MODULES)


def env_module(name: str) -> ModuleType:
    if name not in _MODULES:
        raise LangprefError(f"unknown env {name!r}: choose one of {', '.join(ENV_NAMES)}")
    return importlib.import_module(_MODULES[name])


def get_spec(name: str) -> EnvSpec:
    return env_module(name).SPEC


def make_env(name: str, horizon: int | None = None) -> SimEnv:
    spec = get_spec(name)
    return env_module(name).make(horizon or spec.default_horizon)


__all__ = ["ENV_NAMES", "Controller", "EnvSpec", "ObsField", "SimEnv", "env_module", "get_spec", "make_env"]
