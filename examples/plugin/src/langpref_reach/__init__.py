"""An example langpref task plugin: a Sawyer arm reaching for a point in the air (Meta-World v3 `reach-v3`).

A plugin is a pip-installable package that declares a `langpref.tasks` entry point (see this package's
pyproject.toml) pointing at a `langpref.tasks.Task`. Once installed, `langpref tasks` lists it and
`langpref generate --env metaworld-reach` makes datasets of it, with no edit inside langpref.

`env.py` wraps the simulator and computes the features, `controller.py` is the scripted policy that generates
datasets, `utterances.json` is the task's bank of comparative feedback (split train/val/test).
"""

from __future__ import annotations

from importlib import resources

from langpref.tasks import Simulator, Task

from langpref_reach.controller import CONTROLLER_DIM, make_controller
from langpref_reach.env import ACTION_DIM, FEATURES, OBS_LAYOUT, make

TASK = Task(
    name="metaworld-reach",
    features=FEATURES,
    feature_descriptions=(
        "height of the robot's fingertips above the table",
        "how fast the fingertips move",
        "how far the fingertips stay from the red target point",
    ),
    obs_layout=OBS_LAYOUT,
    action_dim=ACTION_DIM,
    robot="a simulated Sawyer robot arm",
    description="The robot stands at a table, and its task is to reach a small red dot floating above the table "
    "with its fingertips (the dark cylinder on the table plays no part). Trajectories differ in how high "
    "the arm moves, how fast it moves, and how close it comes to the dot.",
    examples=("Move faster.", "Keep lower.", "Get closer to the red dot."),
    utterances=resources.files(__name__).joinpath("utterances.json"),
    default_splits=(160, 20, 20),
    simulator=Simulator(
        make_env=make,
        make_controller=make_controller,
        controller_dim=CONTROLLER_DIM,
        default_horizon=150,
        default_num_trajectories=200,
        success_name="target reached",
    ),
    source="plugin",
)

__all__ = ["TASK"]
