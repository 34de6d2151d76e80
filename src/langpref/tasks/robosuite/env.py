"""robosuite Jaco Lift with a cube AND a bottle on the table, with the paper's features. Its scripted controller
is `langpref.tasks.robosuite.controller`.

The scene is robosuite's `Lift` (Jaco arm, three-finger gripper, a small red cube; task: lift the cube) with a
`BottleObject` added by us, placed at random beside the cube and observed like the cube. Control is 4-dim:
OSC_POSITION (dx, dy, dz, in [-1, 1], 1 = 5 cm of goal offset; the hand keeps pointing down) plus the gripper
(+1 closes, -1 opens; the Jaco fingers move 0.02 of their command range per step, twice robosuite's rate, so that
closing on the cube takes about a second). It runs at 40 Hz (dt = 0.025 s): fewer simulation substeps per step,
which is what makes it fast, because robosuite's Python arm controller runs once per substep.

Features per step (paper Appendix A), in metres and metres per second:
  height              end-effector (grip site) z above the table top (table top at z = 0.8)
  speed               end-effector velocity norm over the step, |p_{t+1} - p_t| / dt
  distance_to_cube    end-effector to the cube's centre
  distance_to_bottle  end-effector to the bottle's centre (its body origin, 6.5 cm above the table; the bottle
                      is 16 cm tall)
  lift_success        1.0 while the cube is lifted (cube centre more than 0.04 above the table top, robosuite's
                      Lift success), else 0.5 * (1 - tanh(10 * distance_to_cube)) + 0.25 * grasping, which is at
                      most 0.75 (robosuite's own shaped Lift reward: reaching plus grasping, scaled by a half so a
                      failure always scores below a lift)

Observation (28 floats, `OBS_LAYOUT`; the paper used 25): end-effector position and velocity (position change
over the last step / dt, zero after `reset` and `set_state`), the six finger joint angles, the cube's position and
orientation (quaternion w, x, y, z), the bottle's position, and the vectors from the end-effector to the cube and to
the bottle, all in the world frame. Object placement (and robosuite's small arm start noise) comes from the seed
given to `reset` alone; cube and bottle centres stand at least MIN_CUBE_BOTTLE_GAP apart.

robosuite is imported only when an env is made, so importing this module is cheap.
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache

import numpy as np

from langpref.tasks.base import ObsField

FEATURES = ("height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success")
OBS_LAYOUT = (
    ObsField("eef_pos", 0, 3),
    ObsField("eef_vel", 3, 6),
    ObsField("gripper_qpos", 6, 12),
    ObsField("cube_pos", 12, 15),
    ObsField("cube_quat", 15, 19),
    ObsField("bottle_pos", 19, 22),
    ObsField("eef_to_cube", 22, 25),
    ObsField("eef_to_bottle", 25, 28),
)
OBS_DIM = OBS_LAYOUT[-1].stop
ACTION_DIM = 4

_SLICES = {f.name: slice(f.start, f.stop) for f in OBS_LAYOUT}

TABLE_HEIGHT = 0.8  # z of the table top (robosuite Lift's table_offset)
SUCCESS_HEIGHT = 0.04  # the cube counts as lifted when its centre is this far above the table top (robosuite Lift)
REACH_WEIGHT = 0.5  # lift_success of a failure: REACH_WEIGHT * (1 - tanh(10 d_cube)) + GRASP_WEIGHT * grasping
GRASP_WEIGHT = 0.25
CONTROL_FREQ = 40
GRIPPER_SPEED = 0.02  # Jaco finger command change per step (robosuite: 0.01); a full stroke takes 2.5 s at 40 Hz
CUBE_RANGE = 0.08  # cube centre x, y uniform in +-CUBE_RANGE around the table centre
BOTTLE_RANGE = (0.15, 0.20)  # bottle centre x, y uniform in +-these
# robosuite places the bottle 2.4 cm too high (its mesh bottom is 6.5 cm below the body origin, not 8.2): start it
# 1 mm above the table instead of letting it drop at the first steps.
_BOTTLE_Z_OFFSET = -0.014
MIN_CUBE_BOTTLE_GAP = 0.13  # horizontal distance between cube and bottle centres, at least


def lift_success_value(cube_z: float, distance_to_cube: float, grasping: bool) -> float:
    """The paper's "how well the robot lifts the cube": 1 when lifted, else a weighted closeness plus grasp, < 1."""
    if cube_z > TABLE_HEIGHT + SUCCESS_HEIGHT:
        return 1.0
    return REACH_WEIGHT * (1.0 - math.tanh(10.0 * distance_to_cube)) + GRASP_WEIGHT * float(grasping)


def compute_features(
    eef: np.ndarray, prev_eef: np.ndarray, cube: np.ndarray, bottle: np.ndarray, grasping: bool, dt: float
) -> np.ndarray:
    """theta(s_t, a_t) in `FEATURES` order from positions (world frame, metres) before and after one step."""
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
    from langpref.extras import needs

    with needs("robosuite", "task 'robosuite'"):
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
            placements = ((self.cube, (CUBE_RANGE, CUBE_RANGE), 0.01), (self.bottle, BOTTLE_RANGE, _BOTTLE_Z_OFFSET))
            for obj, (rx, ry), z_offset in placements:
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
                        z_offset=z_offset,
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

        def _reset_internal(self):
            super()._reset_internal()  # places cube and bottle
            # Re-draw (from the same generator, so still a function of the seed) while the bottle stands so close
            # to the cube that open fingers around the cube would knock it over.
            xpos = self.sim.data.body_xpos
            for _ in range(100):
                gap = xpos[self.cube_body_id][:2] - xpos[self.bottle_body_id][:2]
                if self.deterministic_reset or np.linalg.norm(gap) >= MIN_CUBE_BOTTLE_GAP:
                    break
                for pos, quat, obj in self.placement_initializer.sample().values():
                    self.sim.data.set_joint_qpos(obj.joints[0], np.concatenate([np.array(pos), np.array(quat)]))
                self.sim.forward()

        def seed_placement(self, seed: int) -> None:
            """Draw the next reset's object placement and arm noise from `seed` alone."""
            rng = np.random.default_rng(seed)
            self.rng = rng
            for sub in self.placement_initializer.samplers.values():
                sub.rng = rng

    return LiftWithBottle


def _speed_up_gripper(gripper: object) -> None:
    """Make the Jaco fingers move GRIPPER_SPEED of their command range per step instead of robosuite's 0.01.

    robosuite's Jaco gripper integrates the sign of the gripper action at a fixed 0.01 per env step, which at our
    40 Hz means 5 s for a full stroke and most of an episode spent closing on the cube. The speed is a read-only
    property of the gripper class, so the instance gets a subclass that overrides it (nothing else changes).
    """
    cls = type(gripper)
    if getattr(cls, "_langpref_speed", None) == GRIPPER_SPEED:
        return
    attrs = {"speed": property(lambda self: GRIPPER_SPEED), "_langpref_speed": GRIPPER_SPEED}
    gripper.__class__ = type(cls.__name__, (cls,), attrs)


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
        import mujoco

        self._mujoco = mujoco
        robot = self._env.robots[0]
        self._gripper = robot.gripper["right"]
        _speed_up_gripper(self._gripper)
        self._eef_site = robot.eef_site_id["right"]
        self._cube_body = self._env.cube_body_id
        self._bottle_body = self._env.bottle_body_id
        self._gripper_qpos_idx = np.asarray(robot._ref_gripper_joint_pos_indexes["right"])
        self._prev_eef = np.zeros(3)
        self._features = np.zeros(len(FEATURES))
        self._success = False
        self._obs = np.zeros(OBS_DIM)

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
        """robosuite's Lift success, now: the cube's centre is more than SUCCESS_HEIGHT above the table top."""
        return bool(self._cube()[2] > TABLE_HEIGHT + SUCCESS_HEIGHT)

    def _observe(self, prev_eef: np.ndarray) -> np.ndarray:
        eef, cube, bottle = self._eef(), self._cube(), self._bottle()
        obs = np.empty(OBS_DIM)
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
        self._hide_sites()
        self._success = False
        return self._observe(self._eef())

    def step(self, action: np.ndarray) -> np.ndarray:
        action = np.clip(np.asarray(action, dtype=np.float64).reshape(ACTION_DIM), -1.0, 1.0)
        prev = self._prev_eef
        self._env.step(action)
        # robosuite ends a step on an integration, which leaves body positions one substep (2 ms) behind qpos;
        # bring them up to date so that what we observe is exactly the state `get_state` returns.
        self._mujoco.mj_kinematics(self._model, self._data)
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
        """The current observation (what the last `reset`, `step` or `set_state` saw)."""
        return self._obs.astype(np.float32)

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._data.qpos.copy(), self._data.qvel.copy()

    def set_state(self, qpos: np.ndarray, qvel: np.ndarray) -> None:
        self._data.qpos[:] = np.asarray(qpos, dtype=np.float64)
        self._data.qvel[:] = np.asarray(qvel, dtype=np.float64)
        self._mujoco.mj_forward(self._model, self._data)
        self._observe(self._eef())

    def mujoco_handles(self) -> tuple[object, object]:
        return self._model, self._data

    def _hide_sites(self) -> None:
        """Make robosuite's marker sites (grip-site cylinder, frames) invisible to a raw MuJoCo renderer.

        robosuite hides them with a negative alpha that only its own renderer honours, and rewrites them at every
        reset; a zero alpha hides them everywhere. Sites have no physics, so nothing else changes.
        """
        self._model.site_rgba[:, 3] = 0.0

    def camera(self) -> dict:
        """robosuite's "sideview": the whole arm, the cube and the bottle, with heights and gaps readable."""
        return {"name": "sideview"}

    def close(self) -> None:
        self._env.close()


def make(horizon: int = 500) -> RobosuiteLiftBottle:
    return RobosuiteLiftBottle(horizon)
