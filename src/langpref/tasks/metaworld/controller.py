"""The scripted controller of Meta-World button press: a closed-loop waypoint policy with 14 parameters per
trajectory (the stand-in for the paper's RL policies; see `ButtonPressParams` for what each does).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

# Hand box of the Sawyer's mocap (Meta-World's own limits, slightly inside them).
_HAND_LOW = np.array([-0.45, 0.42, 0.06])
_HAND_HIGH = np.array([0.45, 0.95, 0.45])
# The hand sits this far above the point that touches the button (Meta-World's own expert policy aims 0.07 low).
_PRESS_Z_OFFSET = -0.07


@dataclass(frozen=True)
class ButtonPressParams:
    """Physical parameters of one waypoint controller (drawn per trajectory from a Latin hypercube row).

    The hand waits, travels to a dwell point (height and 3-D distance to the button drawn independently), dwells,
    then either presses the button (mode "press") or hovers in front of it (mode "hover"), holds, and retreats.
    `jitter` adds a fast oscillation that raises speed without moving the hand far.
    """

    wait: int  # steps standing still at the start
    max_step: float  # largest commanded move per step, in action units (1 = 1 cm per step)
    gain: float  # proportional gain on the position error
    dwell_height: float  # hand z at the dwell point
    dwell_distance: float  # 3-D distance of the dwell point to the button face
    dwell_azimuth: float  # direction of the dwell point around the button (radians, 0 = straight in front)
    dwell_steps: int
    press: bool  # press the button, or only hover in front of it
    hover_distance: float  # hover mode: distance of the hover point to the button
    hover_elevation: float  # hover mode: angle of the hover point above the button (radians)
    hold_steps: int  # steps held at the button (or hovering)
    retreat_height: float
    retreat_distance: float
    jitter: float  # amplitude of the oscillation added to the action
    noise: float = 0.05  # std of Gaussian action noise


CONTROLLER_DIM = 14


def params_from_unit(u: np.ndarray) -> ButtonPressParams:
    """Map 14 numbers in [0, 1) to controller parameters (uniform within each range; the gain log-uniform)."""
    lo_hi = lambda i, lo, hi: lo + (hi - lo) * float(u[i])  # noqa: E731
    return ButtonPressParams(
        wait=int(lo_hi(0, 0, 120)),
        max_step=lo_hi(1, 0.1, 1.0),
        gain=float(np.exp(lo_hi(2, np.log(3.0), np.log(40.0)))),
        dwell_height=lo_hi(3, 0.06, 0.35),
        dwell_distance=lo_hi(4, 0.15, 0.45),
        dwell_azimuth=lo_hi(5, -1.0, 1.0),
        dwell_steps=int(lo_hi(6, 0, 250)),
        press=bool(u[7] < 0.5),
        hover_distance=lo_hi(8, 0.04, 0.20),
        hold_steps=int(lo_hi(9, 20, 400)),
        retreat_height=lo_hi(10, 0.06, 0.35),
        retreat_distance=lo_hi(11, 0.15, 0.45),
        jitter=lo_hi(12, 0.0, 0.8),
        hover_elevation=lo_hi(13, -0.3, 1.4),
    )


def _clip(x: np.ndarray, low, high) -> np.ndarray:
    """np.clip, without its dispatch overhead on 3-vectors (the controller runs every simulator step)."""
    return np.minimum(np.maximum(x, low), high)


def _close(a: float, b: float, atol: float = 0.02) -> bool:
    """np.isclose for two scalars, same tolerance rule."""
    return abs(a - b) <= atol + 1e-5 * abs(b)


def _point_at(button: np.ndarray, height: float, distance: float, azimuth: float) -> np.ndarray:
    """A hand position at `height` and 3-D `distance` from the button, in front of it at angle `azimuth`."""
    dz = height - button[2]
    horizontal = np.sqrt(max(distance**2 - dz**2, 0.0))
    p = np.array([button[0] + horizontal * np.sin(azimuth), button[1] - horizontal * np.cos(azimuth), height])
    return _clip(p, _HAND_LOW, _HAND_HIGH)


class ButtonPressController:
    """Closed-loop waypoint controller: a finite sequence of phases, each steering the hand to a target."""

    def __init__(self, params: ButtonPressParams, rng: np.random.Generator):
        self.p = params
        self.params = asdict(params)
        self._rng = rng
        self._phase_start: dict[str, int] = {}
        self._aligned_at: int | None = None

    def _target(self, hand: np.ndarray, button: np.ndarray, t: int) -> np.ndarray:
        p = self.p
        t_dwell = p.wait
        t_act = t_dwell + p.dwell_steps
        if t < t_dwell:
            return hand
        if t < t_act:
            return _point_at(button, p.dwell_height, p.dwell_distance, p.dwell_azimuth)
        face = np.array([button[0], button[1], button[2] + _PRESS_Z_OFFSET])
        if self._aligned_at is None or t < self._aligned_at + p.hold_steps:
            if p.press:
                in_front = face + np.array([0.0, -0.10, 0.0])
                if _close(hand[0], face[0]) and _close(hand[2], face[2]) and hand[1] > face[1] - 0.12:
                    self._aligned_at = t if self._aligned_at is None else self._aligned_at
                    return face + np.array([0.0, 0.05, 0.0])  # push past the face: the button moves as pressed
                return in_front if self._aligned_at is None else face + np.array([0.0, 0.05, 0.0])
            elev, az = p.hover_elevation, p.dwell_azimuth
            direction = np.array([np.cos(elev) * np.sin(az), -np.cos(elev) * np.cos(az), np.sin(elev)])
            hover = _clip(button + p.hover_distance * direction, _HAND_LOW, _HAND_HIGH)
            if self._aligned_at is None and np.linalg.norm(hand - hover) < 0.02:
                self._aligned_at = t
            return hover
        return _point_at(button, p.retreat_height, p.retreat_distance, -p.dwell_azimuth)

    def act(self, env: object, obs: np.ndarray, t: int) -> np.ndarray:
        hand, button = obs[0:3].astype(np.float64), obs[4:7].astype(np.float64)
        delta = _clip(self.p.gain * (self._target(hand, button, t) - hand), -self.p.max_step, self.p.max_step)
        jitter = self.p.jitter * np.array([np.sin(0.9 * t), np.cos(1.3 * t), np.sin(1.1 * t + 1.0)])
        noise = self._rng.normal(0.0, self.p.noise, size=3)
        return np.concatenate([_clip(delta + jitter + noise, -1.0, 1.0), [-1.0]]).astype(np.float32)


def make_controller(unit: np.ndarray, rng: np.random.Generator) -> ButtonPressController:
    return ButtonPressController(params_from_unit(unit), rng)


def expert_unit() -> np.ndarray:
    """A unit vector whose controller presses the button early and holds it: a reference for tests."""
    u = np.full(CONTROLLER_DIM, 0.5)
    u[[0, 6, 7, 12]] = [0.0, 0.0, 0.0, 0.0]  # no wait, no dwell, press, no jitter
    u[[1, 2, 9]] = [0.9, 0.8, 0.999]  # fast, stiff, hold to the end
    return u
