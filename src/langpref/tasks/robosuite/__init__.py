"""Built-in task `robosuite`: a Kinova Jaco arm lifting a cube with a bottle beside it (robosuite `Lift`, the bottle
added by us), the paper's second simulated setting. `env.py` wraps the simulator, `controller.py` is the scripted
policy that generates datasets, `utterances.json` is the task's bank (split train/val/test).
"""

from __future__ import annotations

from importlib import resources

from langpref.tasks.base import Simulator, Task
from langpref.tasks.robosuite.controller import CONTROLLER_DIM, make_controller
from langpref.tasks.robosuite.env import ACTION_DIM, FEATURES, OBS_LAYOUT, make

TASK = Task(
    name="robosuite",
    features=FEATURES,
    feature_descriptions=(
        "height of the robot's hand above the table",
        "how fast the hand moves",
        "how far the hand stays from the cube",
        "how far the hand stays from the bottle",
        "how well the robot lifts the cube",
    ),
    obs_layout=OBS_LAYOUT,
    action_dim=ACTION_DIM,
    robot="a simulated Kinova Jaco robot arm",
    description="The robot stands at a table with a cube and a bottle on it, and its task is to lift the cube. "
    "Trajectories differ in how high and how fast the arm moves, how close it comes to the cube and to "
    "the bottle, and how well it lifts the cube.",
    examples=("Move slower.", "Keep away from the bottle.", "Be better at lifting the cube."),
    utterances=resources.files(__name__).joinpath("utterances.json"),
    default_splits=(359, 44, 45),
    simulator=Simulator(
        make_env=make,
        make_controller=make_controller,
        controller_dim=CONTROLLER_DIM,
        default_horizon=500,
        default_num_trajectories=448,
        success_name="cube lifted",
        extra="robosuite",
    ),
)
