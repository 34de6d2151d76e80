"""Built-in task `metaworld`: a Sawyer arm pressing a button (Meta-World v3 `button-press-v3`), the paper's first
simulated setting. `env.py` wraps the simulator, `controller.py` is the scripted policy that generates datasets,
`utterances.json` is the task's bank (split train/val/test).
"""

from __future__ import annotations

from importlib import resources

from langpref.tasks.base import Simulator, Task
from langpref.tasks.metaworld.controller import CONTROLLER_DIM, make_controller
from langpref.tasks.metaworld.env import ACTION_DIM, FEATURES, OBS_LAYOUT, SIMULATOR_VERSION, make

TASK = Task(
    name="metaworld",
    features=FEATURES,
    feature_descriptions=(
        "height of the robot's hand above the table",
        "how fast the hand moves",
        "how far the hand stays from the button",
    ),
    obs_layout=OBS_LAYOUT,
    action_dim=ACTION_DIM,
    robot="a simulated Sawyer robot arm",
    description="The robot stands at a table with a button on it, and its task is to press the button. Trajectories "
    "differ in how high the arm moves, how fast it moves, and how close it comes to the button.",
    examples=("Move faster.", "Stay lower.", "Get closer to the button."),
    utterances=resources.files(__name__).joinpath("utterances.json"),
    default_splits=(260, 32, 32),
    simulator=Simulator(
        make_env=make,
        make_controller=make_controller,
        controller_dim=CONTROLLER_DIM,
        default_horizon=500,
        default_num_trajectories=324,
        success_name="button pressed",
        extra="metaworld",
        version=SIMULATOR_VERSION,
    ),
)
