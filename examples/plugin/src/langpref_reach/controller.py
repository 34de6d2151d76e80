"""The scripted controller of the reach task: a closed-loop waypoint policy with 10 parameters per trajectory, each
drawn from [0, 1) (one Latin hypercube row per trajectory, see `ReachParams` for what each does).

The parameters are chosen so that the three features vary independently of each other: the detour point's height
and its distance to the goal are drawn separately (so a high detour is not always a far one), the final stop may
be short of the goal in any direction (so being close does not mean being low or high), and `jitter` makes the hand
fast without carrying it anywhere.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from langpref_reach.env import MetaWorldReach

CONTROLLER_DIM = 10
# The hand body (what observations report) sits this far above the fingertip centre (what features measure).
_TIP_OFFSET = np.array([0.0, 0.0, 0.045])
# Targets stay inside reach-v3's hand box (slightly inside it).
_HAND_LOW = np.array([-0.45, 0.42, 0.06])
_HAND_HIGH = np.array([0.45, 0.95, 0.45])


@dataclass(frozen=True)
class ReachParams:
    """Physical parameters of one trajectory. Phase lengths are shares of the horizon, so the same row gives the
    same kind of motion at any `--horizon`."""

    wait: float  # share of the horizon standing still at the start
    max_step: float  # largest commanded move per step, in action units (1 = 1 cm per step)
    gain: float  # proportional gain on the position error
    detour_height: float  # fingertip height of the detour point (m)
    detour_distance: float  # 3-D distance of the detour point to the goal (m)
    detour_azimuth: float  # direction of the detour point around the goal (radians, 0 = towards the robot)
    detour: float  # share of the horizon spent at the detour point before heading for the goal
    stop_distance: float  # how far short of the goal the hand stops (m; Meta-World counts < 5 cm as reached)
    stop_elevation: float  # direction of the stop point from the goal (radians above the horizontal)
    jitter: float  # amplitude of a fast oscillation added to the action (speed without displacement)
    noise: float = 0.05  # std of Gaussian action noise


def params_from_unit(u: np.ndarray) -> ReachParams:
    """Map `CONTROLLER_DIM` numbers in [0, 1) to parameters (uniform within each range; the gain log-uniform)."""

    def lo_hi(i: int, lo: float, hi: float) -> float:
        return lo + (hi - lo) * float(u[i])

    return ReachParams(
        wait=lo_hi(0, 0.0, 0.25),
        max_step=lo_hi(1, 0.15, 1.0),
        gain=float(np.exp(lo_hi(2, np.log(3.0), np.log(30.0)))),
        detour_height=lo_hi(3, 0.03, 0.38),
        detour_distance=lo_hi(4, 0.10, 0.40),
        detour_azimuth=lo_hi(5, -1.2, 1.2),
        detour=lo_hi(6, 0.0, 0.45),
        stop_distance=lo_hi(7, 0.0, 0.15),
        stop_elevation=lo_hi(8, -0.6, 1.3),
        jitter=lo_hi(9, 0.0, 0.7),
    )


def _clip(x: np.ndarray, low: np.ndarray | float, high: np.ndarray | float) -> np.ndarray:
    """np.clip without its dispatch overhead on 3-vectors (the controller runs every simulator step)."""
    return np.minimum(np.maximum(x, low), high)


def _hand_target(tip: np.ndarray) -> np.ndarray:
    """Where to send the hand so that the fingertips end up at `tip`."""
    return _clip(tip + _TIP_OFFSET, _HAND_LOW, _HAND_HIGH)


class ReachController:
    """Wait, go to a detour point, then to a stop point at `stop_distance` from the goal, and stay there."""

    def __init__(self, params: ReachParams, rng: np.random.Generator) -> None:
        self.p = params
        self.params = asdict(params)  # stored with every trajectory
        self._rng = rng

    def _tip_target(self, goal: np.ndarray, t: int, horizon: int) -> np.ndarray | None:
        """The fingertip target at step t, or None while waiting."""
        p = self.p
        t_go = p.wait * horizon
        if t < t_go:
            return None
        if t < t_go + p.detour * horizon:
            dz = p.detour_height - goal[2]
            horizontal = np.sqrt(max(p.detour_distance**2 - dz**2, 0.0))
            az = p.detour_azimuth
            return np.array([goal[0] + horizontal * np.sin(az), goal[1] - horizontal * np.cos(az), p.detour_height])
        el, az = p.stop_elevation, p.detour_azimuth
        direction = np.array([np.cos(el) * np.sin(az), -np.cos(el) * np.cos(az), np.sin(el)])
        return goal + p.stop_distance * direction

    def act(self, env: MetaWorldReach, obs: np.ndarray, t: int) -> np.ndarray:
        """The action at step t: a clipped proportional move towards the phase's target, plus jitter and noise.
        Phase lengths are shares of `env.horizon` (the controller is made before the horizon is known to it)."""
        hand, goal = obs[0:3].astype(np.float64), obs[36:39].astype(np.float64)
        tip = self._tip_target(goal, t, env.horizon)
        delta = np.zeros(3) if tip is None else self.p.gain * (_hand_target(tip) - hand)
        delta = _clip(delta, -self.p.max_step, self.p.max_step)
        jitter = self.p.jitter * np.array([np.sin(0.9 * t), np.cos(1.3 * t), np.sin(1.1 * t + 1.0)])
        noise = self._rng.normal(0.0, self.p.noise, size=3)
        return np.concatenate([_clip(delta + jitter + noise, -1.0, 1.0), [-1.0]]).astype(np.float32)


def make_controller(unit: np.ndarray, rng: np.random.Generator) -> ReachController:
    """The `Simulator.make_controller` of the task."""
    return ReachController(params_from_unit(unit), rng)


def expert_unit() -> np.ndarray:
    """A parameter row whose controller goes straight to the goal and stays on it: a reference for tests."""
    u = np.full(CONTROLLER_DIM, 0.5)
    u[[0, 6, 7, 9]] = 0.0  # no wait, no detour, stop on the goal, no jitter
    u[[1, 2]] = [0.9, 0.8]  # fast and stiff
    return u
