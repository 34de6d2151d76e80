"""robosuite Jaco Lift with a cube AND a bottle on the table, the paper's features, and its scripted controller.

The scene is robosuite's `Lift` (Jaco arm, three-finger gripper, a small red cube; task: lift the cube) with a
`BottleObject` added by us, placed at random beside the cube and observed like the cube. Control is 4-dim:
OSC_POSITION (dx, dy, dz, in [-1, 1], 1 = 5 cm of goal offset; the hand keeps pointing down) plus the gripper
(+1 closes, -1 opens; the Jaco fingers move 0.01 of their range per step). It runs at 40 Hz (dt = 0.025 s): fewer
simulation substeps per step, because robosuite's Python controller runs once per substep.

Features per step (paper Appendix A), in metres and metres per second:
  height              end-effector (grip site) z above the table top (table top at z = 0.8)
  speed               end-effector velocity norm over the step, |p_{t+1} - p_t| / dt
  distance_to_cube    end-effector to the cube's centre
  distance_to_bottle  end-effector to the bottle's centre (its body origin, mid-height of the bottle)
  lift_success        1.0 while the cube is lifted (cube centre more than 0.04 above the table top, robosuite's
                      Lift success), else 0.5 * (1 - tanh(10 * distance_to_cube)) + 0.25 * grasping, which is at
                      most 0.75 (robosuite's own shaped Lift reward: reaching plus grasping, scaled by a half so a
                      failure always scores below a lift)

Observation (28 floats, `SPEC.obs_layout`): end-effector position and velocity, the six finger joint angles, the
cube's position and orientation (quaternion w, x, y, z), the bottle's position, and the vectors from the
end-effector to the cube and to the bottle. Object placement comes from the seed given to `reset` alone.

robosuite is imported only when an env is made, so importing this module is cheap.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np

from langpref.envs.base import EnvSpec, ObsField

SPEC = EnvSpec(
    name="robosuite",
    features=("height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success"),
    obs_layout=(
        ObsField("eef_pos", 0, 3),
        ObsField("eef_vel", 3, 6),
        ObsField("gripper_qpos", 6, 12),
        ObsField("cube_pos", 12, 15),
        ObsField("cube_quat", 15, 19),
        ObsField("bottle_pos", 19, 22),
        ObsField("eef_to_cube", 22, 25),
        ObsField("eef_to_bottle", 25, 28),
    ),
    action_dim=4,
    default_horizon=500,
    default_num_trajectories=448,
    default_splits=(359, 44, 45),
    success_name="cube lifted",
)

_SLICES = {f.name: slice(f.start, f.stop) for f in SPEC.obs_layout}

TABLE_HEIGHT = 0.8  # z of the table top (robosuite Lift's table_offset)
SUCCESS_HEIGHT = 0.04  # the cube counts as lifted when its centre is this far above the table top (robosuite Lift)
REACH_WEIGHT = 0.5  # lift_success of a failure: REACH_WEIGHT * (1 - tanh(10 d_cube)) + GRASP_WEIGHT * grasping
GRASP_WEIGHT = 0.25
CONTROL_FREQ = 40
CUBE_RANGE = 0.08  # cube centre x, y uniform in +-CUBE_RANGE around the table centre
BOTTLE_RANGE = (0.15, 0.20)  # bottle centre x, y uniform in +-these


def lift_success_value(cube_z: float, distance_to_cube: float, grasping: bool) -> float:
    """The paper's "how well the robot lifts the cube": 1 when lifted, else a weighted closeness plus grasp, < 1."""
    if cube_z > TABLE_HEIGHT + SUCCESS_HEIGHT:
        return 1.0
    return REACH_WEIGHT * (1.0 - math.tanh(10.0 * distance_to_cube)) + GRASP_WEIGHT * float(grasping)


def compute_features(
    eef: np.ndarray, prev_eef: np.ndarray, cube: np.ndarray, bottle: np.ndarray, grasping: bool, dt: float
) -> np.ndarray:
    """theta(s_t, a_t) in `SPEC.features` order from positions (world frame, metres) before and after one step."""
    d_cube = float(np.linalg.norm(eef - cube))
    return np.array(
        [
            eef[2] - TABLE_HEIGHT,
            float(np.linalg.norm(eef - prev_eef)) / dt,
            d_cube,
            float(np.linalg.norm(eef - bottle)),
            lift_success_value(float(cube[2]), d_cube, grasping),
        ]
    )


def quiet_robosuite() -> None:
    """Keep robosuite's import-time and run-time chatter (macro file, optional robots, IK) off the console.

    robosuite installs its own handler and level on the logger "robosuite_logs" when imported, so a logger filter
    (which survives that) is what holds: only errors get through.
    """
    logger = logging.getLogger("robosuite_logs")
    if not any(getattr(f, "_langpref", False) for f in logger.filters):

        def _errors_only(record: logging.LogRecord) -> bool:
            return record.levelno >= logging.ERROR

        _errors_only._langpref = True  # type: ignore[attr-defined]
        logger.addFilter(_errors_only)


@lru_cache(maxsize=1)
def _lift_with_bottle_class() -> type:
    """robosuite's Lift plus a bottle; built on first use so that robosuite is imported only then."""
    quiet_robosuite()
    from robosuite.environments.manipulation.lift import Lift
    from robosuite.models.objects import BottleObject
    from robosuite.models.tasks import ManipulationTask
    from robosuite.utils.observables import Observable, sensor
    from robosuite.utils.placement_samplers import SequentialCompositeSampler, UniformRandomSampler

    class LiftWithBottle(Lift):
        """Lift with a `BottleObject` ("bottle") placed beside the cube and a `bottle_pos` observable."""

        def _load_model(self):
            # Lift adds the cube to an existing initializer on every (hard) reset; start from none each time.
            self.placement_initializer = None
            super()._load_model()
            self.bottle = BottleObject(name="bottle")
            sampler = SequentialCompositeSampler(name="ObjectSampler")
            for obj, (rx, ry) in ((self.cube, (CUBE_RANGE, CUBE_RANGE)), (self.bottle, BOTTLE_RANGE)):
                sampler.append_sampler(
                    UniformRandomSampler(
                        name=f"{obj.name}Sampler",
                        mujoco_objects=obj,
                        x_range=[-rx, rx],
                        y_range=[-ry, ry],
                        rotation=None,
                        ensure_object_boundary_in_range=False,
                        ensure_valid_placement=True,
                        reference_pos=self.table_offset,
                        z_offset=0.01,
                        rng=self.rng,
                    )
                )
            self.placement_initializer = sampler
            self.model = ManipulationTask(
                mujoco_arena=self.model.mujoco_arena,
                mujoco_robots=[robot.robot_model for robot in self.robots],
                mujoco_objects=[self.cube, self.bottle],
            )

        def _setup_references(self):
            super()._setup_references()
            self.bottle_body_id = self.sim.model.body_name2id(self.bottle.root_body)

        def _setup_observables(self):
            observables = super()._setup_observables()
            if self.use_object_obs:

                @sensor(modality="object")
                def bottle_pos(obs_cache):
                    return np.array(self.sim.data.body_xpos[self.bottle_body_id])

                observables["bottle_pos"] = Observable(
                    name="bottle_pos", sensor=bottle_pos, sampling_rate=self.control_freq
                )
            return observables

        def seed_placement(self, seed: int) -> None:
            """Draw the next reset's object placement and arm noise from `seed` alone."""
            rng = np.random.default_rng(seed)
            self.rng = rng
            for sub in self.placement_initializer.samplers.values():
                sub.rng = rng

    return LiftWithBottle


def _controller_config() -> dict:
    """Jaco's BASIC composite config with only the right arm, driven by OSC_POSITION, its gripper kept (4-dim)."""
    from robosuite.controllers import load_composite_controller_config, load_part_controller_config

    cfg = load_composite_controller_config(controller="BASIC", robot="Jaco")
    arm = load_part_controller_config(default_controller="OSC_POSITION")
    arm["gripper"] = cfg["body_parts"]["right"]["gripper"]
    cfg["body_parts"] = {"right": arm}
    return cfg


class RobosuiteLiftBottle:
    """`SimEnv` over robosuite's Jaco Lift with a bottle."""

    spec = SPEC

    def __init__(self, horizon: int = 500):
        quiet_robosuite()
        cls = _lift_with_bottle_class()
        self.horizon = horizon
        self._env = cls(
            robots="Jaco",
            controller_configs=_controller_config(),
            has_renderer=False,
            has_offscreen_renderer=False,
            use_camera_obs=False,
            control_freq=CONTROL_FREQ,
            horizon=max(horizon, 1) + 1000,  # we count steps ourselves; robosuite must never end an episode
            ignore_done=True,
            hard_reset=False,  # same model for every episode (also keeps the cube size fixed); much faster
            seed=0,
        )
        self.dt = float(self._env.control_timestep)
        sim = self._env.sim
        self._model, self._data = sim.model._model, sim.data._data
        robot = self._env.robots[0]
        self._gripper = robot.gripper["right"]
        self._eef_site = robot.eef_site_id["right"]
        self._cube_body = self._env.cube_body_id
        self._bottle_body = self._env.bottle_body_id
        self._gripper_qpos_idx = np.asarray(robot._ref_gripper_joint_pos_indexes["right"])
        self._prev_eef = np.zeros(3)
        self._features = np.zeros(len(SPEC.features))
        self._success = False
        self._obs = np.zeros(SPEC.obs_dim)

    # -- state reading --------------------------------------------------------------------------------------------

    def _eef(self) -> np.ndarray:
        return self._data.site_xpos[self._eef_site].copy()

    def _cube(self) -> np.ndarray:
        return self._data.xpos[self._cube_body].copy()

    def _bottle(self) -> np.ndarray:
        return self._data.xpos[self._bottle_body].copy()

    def grasping(self) -> bool:
        """robosuite's grasp test: both finger groups touch the cube."""
        return bool(self._env._check_grasp(gripper=self._gripper, object_geoms=self._env.cube))

    def cube_lifted(self) -> bool:
        return bool(self._cube()[2] > TABLE_HEIGHT + SUCCESS_HEIGHT)

    def _observe(self, prev_eef: np.ndarray) -> np.ndarray:
        eef, cube, bottle = self._eef(), self._cube(), self._bottle()
        obs = np.empty(SPEC.obs_dim)
        obs[_SLICES["eef_pos"]] = eef
        obs[_SLICES["eef_vel"]] = (eef - prev_eef) / self.dt
        obs[_SLICES["gripper_qpos"]] = self._data.qpos[self._gripper_qpos_idx]
        obs[_SLICES["cube_pos"]] = cube
        obs[_SLICES["cube_quat"]] = self._data.xquat[self._cube_body]
        obs[_SLICES["bottle_pos"]] = bottle
        obs[_SLICES["eef_to_cube"]] = cube - eef
        obs[_SLICES["eef_to_bottle"]] = bottle - eef
        self._obs = obs
        self._features = compute_features(eef, prev_eef, cube, bottle, self.grasping(), self.dt)
        self._prev_eef = eef
        return obs.astype(np.float32)

    # -- SimEnv ----------------------------------------------------------------------------------------------------

    def reset(self, seed: int) -> np.ndarray:
        self._env.seed_placement(int(seed))
        self._env.reset()
        self._success = False
        return self._observe(self._eef())

    def step(self, action: np.ndarray) -> np.ndarray:
        action = np.clip(np.asarray(action, dtype=np.float64).reshape(SPEC.action_dim), -1.0, 1.0)
        prev = self._prev_eef
        self._env.step(action)
        obs = self._observe(prev)
        self._success = self._success or self.cube_lifted()
        return obs

    def step_features(self) -> np.ndarray:
        """Features of the step just taken (after `set_state`: of the state set, with speed 0)."""
        return self._features.copy()

    def is_success(self) -> bool:
        """Whether the cube has been lifted at any step of this episode so far."""
        return self._success

    def observation(self) -> np.ndarray:
        return self._obs.astype(np.float32)

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._data.qpos.copy(), self._data.qvel.copy()

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        import mujoco

        self._data.qpos[:] = np.asarray(qpos, dtype=np.float64)
        self._data.qvel[:] = np.asarray(qvel, dtype=np.float64)
        mujoco.mj_forward(self._model, self._data)
        self._observe(self._eef())

    def mujoco_handles(self) -> tuple[object, object]:
        return self._model, self._data

    def camera(self) -> dict:
        return {"name": "frontview"}

    def close(self) -> None:
        self._env.close()


def make(horizon: int = 500) -> RobosuiteLiftBottle:
    return RobosuiteLiftBottle(horizon)
