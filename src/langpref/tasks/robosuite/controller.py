"""The scripted controller of robosuite Lift-with-bottle: a closed-loop waypoint policy with 17 parameters per
trajectory (the stand-in for the paper's RL policies; see `LiftParams` for what each does).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from langpref.tasks.robosuite.env import GRIPPER_SPEED, OBS_LAYOUT, TABLE_HEIGHT

_SLICES = {f.name: slice(f.start, f.stop) for f in OBS_LAYOUT}

# Where the hand may be sent (world frame): in reach of the Jaco with the hand pointing down, above the table.
_HAND_LOW = np.array([-0.32, -0.32, TABLE_HEIGHT + 0.012])
_HAND_HIGH = np.array([0.20, 0.32, TABLE_HEIGHT + 0.42])
_BOTTLE_TOP = 0.095  # bottle top above its body origin
_BOTTLE_KEEP_OUT = 0.12  # horizontal clearance of the hand from the bottle's axis while below its top (open
# fingers reach 6.5 cm to the side of the hand, the bottle's radius is 3 cm)
_CUBE_KEEP_OUT = 0.06  # the same around the cube, on the way to and from far points
_HOVER_CLEARANCE = 0.03  # the hand hovers at least this far above the cube's centre (its fingers are higher)
_GRASP_OFFSET = np.array([-0.01, 0.0, -0.01])  # hand target relative to the cube centre for a grasp (measured)
_OPEN_LEVEL = 0.3  # gripper opening kept before a grasp (robosuite's Jaco command level: -1 closed, +1 open)
_CLOSED_LEVEL = -0.4  # close until here before lifting (the fingers' force saturates well before -1)
_CIRCLE_RATE = 0.15  # rad per step of the steady circling that adds speed (period about 1 s at 40 Hz)
_GRASP_STEPS = 150  # steps a lift typically needs from leaving the hover point (approach, descend, close, raise)
_REACH_STEPS = 80  # steps the hand typically needs from the hover point down around the cube (approach, descend)
_LIFT_SHARE = 0.55  # share of controllers that attempt a lift (about 90% of attempts succeed)
_HOLD_LEVEL = -0.5  # gripper level held while carrying (grip force is saturated here; opening from it is quicker)
_RELEASED_LEVEL = 0.2  # open to here to drop the cube
_RELEASE_STEPS = 35  # steps from the hold level to the released level


@dataclass(frozen=True)
class LiftParams:
    """Physical parameters of one waypoint controller (drawn per trajectory from a Latin hypercube row).

    The episode is a timeline of stages (`LiftController.stage`):

      excursion  to a far point, circling there, for `excursion_steps`
      hover      near the cube, circling; this stage takes whatever time the others leave
      approach, descend   above the cube, then down around it with the fingers open
      lift mode:    close, settle, raise (to `carry_height`), carry (to a point at a drawn 3-D distance and bearing
                    from the bottle, circling there, `carry_steps` set aside), release (the cube drops to the table)
      no-lift mode: dwell around the cube with the fingers open, bobbing up and down (`carry_steps` set aside)
      retreat    to a far point (drawn like the first, from where the cube lies now), for `retreat_steps`

    The far point has a height and 3-D distances to the cube and to the bottle drawn independently, so these do
    not move together. Time near the cube is the filler, so time lifted and time far vary independently: that is
    what keeps lift_success from being only the mirror of distance_to_cube. `circle_radius` sets a steady circling
    (bobbing next to the cube) that raises speed without moving the hand far; `gain` and `max_step` set how fast it
    travels. Heights are above the table top, distances in metres, angles in radians, durations in steps.
    """

    lift: bool  # attempt to lift the cube, or only hover and dwell near it
    excursion_steps: int  # steps at (or on the way to) the far point first
    carry_steps: int  # steps set aside for carrying the raised cube (no-lift mode: for dwelling by the cube)
    retreat_steps: int  # steps at the far point at the end (0: the cube is held, or the dwell lasts, to the end)
    gain: float  # proportional gain on the position error (action units per metre)
    max_step: float  # largest commanded move per axis while travelling (action units; 1 = 5 cm of goal offset)
    far_height: float
    far_cube_distance: float
    far_bottle_distance: float
    far_side: int  # +1 or -1: which of the two points with those distances
    circle_radius: float
    hover_distance: float  # 3-D distance of the hover point to the cube
    hover_elevation: float  # elevation of the hover point seen from the cube
    carry_height: float  # lift mode: height of the hand while carrying the cube
    carry_bottle_distance: float  # lift mode: 3-D distance of the carry point to the bottle
    carry_bearing: float  # lift mode: direction of the carry point around the bottle, 0 = toward the cube
    noise: float = 0.02  # std of Gaussian noise on the move actions


CONTROLLER_DIM = 17


def params_from_unit(u: np.ndarray, horizon: int = 500) -> LiftParams:
    """Map 17 numbers in [0, 1) to controller parameters (uniform within each range; the gain log-uniform).

    The three heights (far point, hover elevation, carry) share 60% of their draw (u[16], the altitude), so that
    a trajectory is high or low as a whole rather than averaging out.

    Phase lengths scale with the horizon; where excursion, carry and retreat together leave no time for a lift,
    the three shrink in proportion.
    """
    u = np.asarray(u, dtype=np.float64)
    if u.shape != (CONTROLLER_DIM,):
        raise ValueError(f"the robosuite controller takes {CONTROLLER_DIM} unit numbers, got shape {u.shape}")

    def lo_hi(i: int, lo: float, hi: float) -> float:
        return lo + (hi - lo) * float(u[i])

    def high(i: int, lo: float, hi: float) -> float:  # a height: 60% the shared altitude u[16], 40% its own u[i]
        return lo + (hi - lo) * (0.6 * float(u[16]) + 0.4 * float(u[i]))

    lift = bool(u[0] < _LIFT_SHARE)
    # a fifth of the controllers do not retreat at the end (with a lift: they hold the cube to the end)
    steps = np.array([0.22 * u[1], 0.36 * u[2], 0.22 * max(0.0, (u[3] - 0.2) / 0.8)]) * horizon
    room = max(horizon - (_GRASP_STEPS if lift else _REACH_STEPS), 0)
    if steps.sum() > room:
        steps *= room / steps.sum()
    excursion, carry, retreat = (int(s) for s in steps)
    return LiftParams(
        lift=lift,
        excursion_steps=excursion,
        carry_steps=carry,
        retreat_steps=retreat,
        gain=float(np.exp(lo_hi(4, np.log(4.0), np.log(30.0)))),
        max_step=lo_hi(5, 0.1, 1.0),
        far_height=high(6, 0.02, 0.22),
        far_cube_distance=lo_hi(7, 0.20, 0.60),
        far_bottle_distance=lo_hi(8, 0.12, 0.50),
        far_side=1 if u[9] < 0.5 else -1,
        circle_radius=lo_hi(10, 0.0, 0.08),
        hover_distance=lo_hi(11, 0.05, 0.14),
        hover_elevation=high(12, 0.5, 1.5),
        carry_height=high(13, 0.06, 0.34),
        carry_bottle_distance=lo_hi(14, 0.10, 0.38),
        carry_bearing=lo_hi(15, -np.pi, np.pi),
    )


def _unit2(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v[:2]))
    return np.array([1.0, 0.0]) if n < 1e-9 else v[:2] / n


def _rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _horizontal(distance: float, dz: float) -> float:
    """Horizontal offset that puts a point `distance` away (3-D) from one `dz` below or above it; 0 if too close."""
    return math.sqrt(max(distance**2 - dz**2, 0.0))


def _two_circle_point(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float, side: int) -> np.ndarray:
    """A point in the plane at distance r1 from c1 and r2 from c2 (the `side` one of two); where none exists, the
    point at distance r1 from c1 on the line through both centres, on the side that best matches r2."""
    d_vec = c2 - c1
    d = float(np.linalg.norm(d_vec))
    if d < 1e-6:
        return c1 + r1 * np.array([1.0, 0.0])
    e = d_vec / d
    a = (r1**2 - r2**2 + d**2) / (2.0 * d)
    h2 = r1**2 - a**2
    if h2 < 0.0:
        return c1 + e * (r1 if a > 0 else -r1)
    return c1 + a * e + side * math.sqrt(h2) * np.array([-e[1], e[0]])


def _steer_around(move: np.ndarray, hand: np.ndarray, centre: np.ndarray, radius: float, top: float) -> np.ndarray:
    """Inside the keep-out cylinder, drop the part of a move that heads for the axis and push outwards; a move
    straight at the axis turns aside, so the hand slides around the obstacle instead of into it."""
    d = hand[:2] - centre[:2]
    n = float(np.linalg.norm(d))
    if hand[2] >= top or n >= radius:
        return move
    radial = d / n if n > 1e-9 else np.array([0.0, 1.0])
    move = move.copy()
    inward = -float(move[:2] @ radial)
    if inward > 0.0:
        tangent = np.array([-radial[1], radial[0]])
        side = 1.0 if float(move[:2] @ tangent) >= 0.0 else -1.0
        move[:2] += inward * radial + side * inward * tangent
    move[:2] += 10.0 * (radius - n) * radial
    return move


def _keep_out(p: np.ndarray, centre: np.ndarray, radius: float, top: float) -> np.ndarray:
    """Push a target below `top` out of the vertical cylinder of `radius` around `centre`."""
    d = p[:2] - centre[:2]
    n = float(np.linalg.norm(d))
    if p[2] < top and n < radius:
        p = p.copy()
        p[:2] = centre[:2] + (d / n if n > 1e-9 else np.array([0.0, 1.0])) * radius
    return p


class LiftController:
    """Closed-loop waypoint controller: far point, hover near the cube, [grasp, raise, carry, drop], far point.

    It reads the hand, cube and bottle positions from the observation, steers the hand with a capped proportional
    law (OSC_POSITION deltas) that slides around the bottle, and tracks the Jaco gripper's command level from its
    own gripper actions.
    """

    def __init__(self, unit: np.ndarray, rng: np.random.Generator, horizon: int | None = None):
        self._unit = np.asarray(unit, dtype=np.float64).copy()
        self._horizon = horizon
        self.p = params_from_unit(self._unit, 500 if horizon is None else horizon)
        self.params = asdict(self.p)
        self._rng = rng
        self._phase_offset = float(rng.uniform(0.0, 2.0 * np.pi))
        self._level = 0.0  # the gripper command level (robosuite resets it to 0 at every reset)
        self.stage = "excursion"
        self._stage_start = 0
        self._points: dict[str, np.ndarray] = {}

    # targets ------------------------------------------------------------------------------------------------------

    def _far_point(self, cube: np.ndarray, bottle: np.ndarray) -> np.ndarray:
        p = self.p
        z = TABLE_HEIGHT + p.far_height
        r_cube = _horizontal(p.far_cube_distance, z - cube[2])
        r_bottle = _horizontal(p.far_bottle_distance, z - bottle[2])
        xy = _two_circle_point(cube[:2], r_cube, bottle[:2], r_bottle, p.far_side)
        return np.clip(np.array([xy[0], xy[1], z]), _HAND_LOW, _HAND_HIGH)

    def _hover_point(self, cube: np.ndarray, bottle: np.ndarray) -> np.ndarray:
        p = self.p
        direction = _rotate(_unit2(cube - bottle), p.far_side * 0.5 * np.pi)
        xy = cube[:2] + p.hover_distance * math.cos(p.hover_elevation) * direction
        z = cube[2] + max(p.hover_distance * math.sin(p.hover_elevation), _HOVER_CLEARANCE)
        return np.clip(np.array([xy[0], xy[1], z]), _HAND_LOW, _HAND_HIGH)

    def _carry_point(self, cube: np.ndarray, bottle: np.ndarray) -> np.ndarray:
        p = self.p
        z = TABLE_HEIGHT + p.carry_height
        xy = bottle[:2] + _horizontal(p.carry_bottle_distance, z - bottle[2]) * _rotate(
            _unit2(cube - bottle), p.carry_bearing
        )
        return np.clip(np.array([xy[0], xy[1], z]), _HAND_LOW, _HAND_HIGH)

    def _point(self, name: str, make) -> np.ndarray:
        if name not in self._points:
            self._points[name] = make()
        return self._points[name]

    def _circle(self, t: int) -> np.ndarray:
        a = _CIRCLE_RATE * t + self._phase_offset
        ramp = min(1.0, (t - self._stage_start) / 20.0)  # start circling gently at each rest point
        return ramp * self.p.circle_radius * np.array([math.cos(a), math.sin(a), 0.0])

    def _bob(self, t: int) -> np.ndarray:
        """Up-and-down motion of up to `circle_radius` above a point next to the cube (where circling would hit it)."""
        a = _CIRCLE_RATE * t + self._phase_offset
        ramp = min(1.0, (t - self._stage_start) / 20.0)
        return ramp * self.p.circle_radius * np.array([0.0, 0.0, 0.5 * (1.0 - math.cos(a))])

    def _next(self, stage: str, t: int) -> None:
        self.stage, self._stage_start = stage, t

    def _grip_to(self, level: float) -> float:
        """Gripper action that moves the command level toward `level` and then holds it."""
        if self._level < level - 1e-9:
            return -1.0
        if self._level > level + 1e-9:
            return 1.0
        return 0.0

    def _plan(self, hand: np.ndarray, cube: np.ndarray, bottle: np.ndarray, t: int) -> tuple[np.ndarray, float, float]:
        """(hand target, move cap, gripper action) for step t; advances the stage machine."""
        p, horizon = self.p, self._horizon or 500
        hover_end = horizon - p.retreat_steps - p.carry_steps - (_GRASP_STEPS if p.lift else _REACH_STEPS)
        if self.stage == "excursion" and t >= p.excursion_steps:
            self._next("hover", t)
        if self.stage == "hover" and t >= hover_end:
            self._next("approach", t)
        elapsed = t - self._stage_start
        open_grip = self._grip_to(_OPEN_LEVEL)
        fast = max(p.max_step, 0.5)
        if self.stage == "excursion":
            target = self._point("far", lambda: self._far_point(cube, bottle))
            return target + self._circle(t), p.max_step, open_grip
        if self.stage == "hover":
            target = self._point("hover", lambda: self._hover_point(cube, bottle))
            return target + self._circle(t), p.max_step, open_grip
        if self.stage == "approach":
            above = cube + _GRASP_OFFSET + np.array([0.0, 0.0, 0.10])
            if (np.linalg.norm(hand[:2] - above[:2]) < 0.012 and abs(hand[2] - above[2]) < 0.02) or elapsed > 90:
                self._next("descend", t)
            return above, fast, open_grip
        if self.stage == "descend":
            target = cube + _GRASP_OFFSET
            if (np.linalg.norm(hand - target) < 0.012 and self._level >= _OPEN_LEVEL - 1e-9) or elapsed > 50:
                self._points["grasp"] = target
                self._next("close" if p.lift else "dwell", t)
            return target, 0.5, open_grip
        if self.stage == "dwell":  # no-lift mode: stay around the cube with the fingers open, then retreat
            if t >= horizon - p.retreat_steps:
                self._next("retreat", t)
            return self._points["grasp"] + self._bob(t), max(p.max_step, 0.25), open_grip
        if self.stage in ("close", "settle"):
            if self.stage == "close" and self._level <= _CLOSED_LEVEL + 1e-9:
                self._next("settle", t)
            elif self.stage == "settle" and elapsed >= 10:
                self._points["carry"] = self._carry_point(cube, bottle)
                self._next("raise", t)
            return self._points["grasp"], 0.25, 1.0
        if self.stage == "raise":  # straight up to the carry height
            grasp, carry = self._points["grasp"], self._points["carry"]
            raised = np.array([grasp[0], grasp[1], carry[2]])
            if abs(hand[2] - raised[2]) < 0.02 or elapsed > 40:
                self._next("carry", t)
            return raised, 0.5, self._grip_to(_HOLD_LEVEL)
        if self.stage == "carry":  # across to the carry point, circling there, until it is time to drop the cube
            if p.retreat_steps > 0 and t >= horizon - p.retreat_steps - _RELEASE_STEPS:
                self._next("release", t)
            return self._points["carry"] + self._circle(t), min(p.max_step, 0.5), self._grip_to(_HOLD_LEVEL)
        if self.stage == "release":  # open the hand where it is (the cube drops to the table), then retreat
            if self._level >= _RELEASED_LEVEL - 1e-9:
                self._next("retreat", t)
            return self._points["carry"], 0.25, self._grip_to(_RELEASED_LEVEL)
        target = self._point("retreat", lambda: self._far_point(cube, bottle))  # from where the cube is now
        return target + self._circle(t), p.max_step, self._grip_to(_RELEASED_LEVEL if p.lift else _OPEN_LEVEL)

    def act(self, env: object, obs: np.ndarray, t: int) -> np.ndarray:
        if self._horizon is None:  # phases are timed within the env's horizon, known once we see the env
            self._horizon = int(getattr(env, "horizon", 500))
            self.p = params_from_unit(self._unit, self._horizon)
            self.params = asdict(self.p)
        obs = np.asarray(obs, dtype=np.float64)
        hand, cube, bottle = obs[_SLICES["eef_pos"]], obs[_SLICES["cube_pos"]], obs[_SLICES["bottle_pos"]]
        target, cap, grip = self._plan(hand, cube, bottle, t)
        top = bottle[2] + _BOTTLE_TOP + 0.03
        if self.stage in ("excursion", "hover", "raise", "carry", "release", "retreat"):
            target = _keep_out(target, bottle, _BOTTLE_KEEP_OUT, top)
        if self.stage in ("excursion", "retreat"):
            target = _keep_out(target, cube, _CUBE_KEEP_OUT, cube[2] + 0.05)
        move = np.clip(self.p.gain * (target - hand), -cap, cap) + self._rng.normal(0.0, self.p.noise, size=3)
        if self.stage not in ("descend", "close", "settle"):
            move = _steer_around(move, hand, bottle, _BOTTLE_KEEP_OUT, top)
        self._level = float(np.clip(self._level - GRIPPER_SPEED * np.sign(grip), -1.0, 1.0))
        return np.concatenate([np.clip(move, -1.0, 1.0), [grip]]).astype(np.float32)


def make_controller(unit: np.ndarray, rng: np.random.Generator, horizon: int | None = None) -> LiftController:
    """The controller of one Latin hypercube row; its phases are timed within `horizon` (default: the env's)."""
    return LiftController(unit, rng, horizon)


def lift_unit() -> np.ndarray:
    """A unit vector for a lift-and-hold controller: no excursion, no circling, no retreat, the longest carry.

    Timed for a horizon of 250 (`make_controller(lift_unit(), rng, horizon=250)`) it goes for the cube at once and
    lifts it within about 150 steps; within 500 steps it first hovers for a while. A reference for tests.
    """
    u = np.full(CONTROLLER_DIM, 0.5)
    u[[0, 1, 2, 3, 10]] = [0.0, 0.0, 0.999, 0.0, 0.0]  # lift, no excursion, longest carry, no retreat, no circling
    u[[4, 5, 13, 16]] = [0.8, 0.8, 0.3, 0.3]  # stiff, fast, carry low
    return u
