"""The learned reward as a stable API for robot-learning code: `langpref.reward.load(PATH)`.

    from langpref.reward import load
    reward = load("rewards/")                                  # DIR/reward.json, or a reward-NAME.json file
    r = reward.compute_reward(observations, actions)           # (T,) per step; r.sum() == reward.trajectory_reward(...)
    R = reward.trajectory_reward(observations, actions)        # r_xi(tau), the reward the learner ranks by
    v = reward.progress(observations, actions)                 # (T,) r_xi of the trajectory up to each step

`observations` is (T, obs_dim) and `actions` (T, A), one trajectory as the task's Gymnasium env gives it (the
observation before each action). A saved reward (`langpref learn-reward --save-reward DIR`) holds r_xi's parameters
and a reference to the checkpoint whose trajectory encoder makes phi (its path relative to the reward's folder, its
absolute path and the checksum of its weights): a reward copied together with its model (the same relative layout)
loads anywhere, and `load(PATH, model=DIR)` points at the model elsewhere. Only the trajectory encoder is read
(`langpref.reward.steps`).

Per step. phi(tau) is the time mean of per-step embeddings e_t, and phi_t the mean of e_1..e_t. The reward of the
trajectory so far is v_t = r_xi(phi_t) (`progress`), and step t's share of the trajectory reward is

    r_t = (t v_t - (t - 1) v_{t-1}) / T,    so that    sum_t r_t = v_T = r_xi(tau).

For the linear r_xi = xi . phi this is r_t = xi . e_t / T, a function of the step alone; for the `mlp` r_xi the sum is
the same but r_t depends on the history through phi_t (an exact shaping of r_xi(tau), not a Markov reward). The
Gymnasium wrapper `langpref.reward.saved.LearnedReward` pays T r_t at step t of an episode of T steps (it cannot know
T before the end): the same policy optimum for a fixed horizon, and a return of T r_xi(tau).

File format. `{"format": "langpref-reward", "format_version": N, ...}`. This langpref writes and reads version
`FORMAT_VERSION`; a file without `format_version` (none was ever written so) is read as version 1, and a newer
version is refused in one line: a change of meaning gets a new version, so that an old reader never misreads it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.reward.learner import MODELS
from langpref.reward.steps import StepEncoder, prefix_means

FORMAT = "langpref-reward"
FORMAT_VERSION = 1
"""The reward file version this langpref writes and the newest it reads."""
DEFAULT_NAME = "reward.json"
REQUIRED = ("task", "kind", "params", "model", "obs_dim", "action_dim")


def read_reward_file(path: str | Path) -> tuple[Path, dict[str, Any]]:
    """(path, document) of a saved reward, DIR/reward.json for a directory; one-line errors for a missing, foreign,
    newer or incomplete file."""
    path = Path(path)
    path = path / DEFAULT_NAME if path.is_dir() else path
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise LangprefError(
            f"no saved reward at {path}: write one with `langpref learn-reward ... --save-reward DIR`"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise LangprefError(f"{path} is not a saved reward (not JSON)") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise LangprefError(f"{path} is not a langpref reward (its format is not {FORMAT!r})")
    version = doc.get("format_version", 1)  # absent: the first version
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise LangprefError(f"{path} has an invalid reward format version {version!r}; save the reward again")
    if version > FORMAT_VERSION:
        raise LangprefError(
            f"{path} is a langpref reward of format version {version}, newer than this langpref reads "
            f"(up to {FORMAT_VERSION}): upgrade langpref, or save the reward again with this one"
        )
    missing = [k for k in REQUIRED if k not in doc]
    if missing:
        raise LangprefError(f"{path} is an incomplete langpref reward (no {', '.join(missing)}); save it again")
    if doc["kind"] not in MODELS:
        raise LangprefError(f"{path} holds a reward model {doc['kind']!r} this langpref does not know ({MODELS})")
    return path, doc


@dataclass(frozen=True, eq=False)
class Reward:
    """A learned reward r_xi with the per-step trajectory encoder it reads (numpy throughout)."""

    path: Path
    doc: dict[str, Any]
    """The saved file as read: task, kind, params, model, learner settings."""
    encoder: StepEncoder
    params: dict[str, np.ndarray]

    @property
    def task(self) -> str:
        """The task the reward was learned on (its Gymnasium env is `langpref/TASK`)."""
        return str(self.doc["task"])

    @property
    def kind(self) -> str:
        """`linear` (r_xi = xi . phi) or `mlp`."""
        return str(self.doc["kind"])

    @property
    def obs_dim(self) -> int:
        return self.encoder.obs_dim

    @property
    def action_dim(self) -> int:
        return self.encoder.action_dim

    def values(self, phi: np.ndarray) -> np.ndarray:
        """r_xi of each row of phi (N, D)."""
        phi = np.asarray(phi, dtype=np.float64)
        p = self.params
        if self.kind == "linear":
            return phi @ p["xi"]
        return np.maximum(phi @ p["w1"] + p["b1"], 0.0) @ p["w2"]

    def value(self, phi: np.ndarray) -> float:
        """r_xi(phi) of one embedding (D,)."""
        return float(self.values(np.asarray(phi)[None])[0])

    def step_embeddings(self, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """e_t of every step (T, D) of one trajectory."""
        return self.encoder.embeddings(observations, actions)

    def progress(self, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """v_t = r_xi(phi_t) (T,): the reward of the trajectory up to each step; the last is `trajectory_reward`."""
        return self.values(prefix_means(self.step_embeddings(observations, actions)))

    def trajectory_reward(self, observations: np.ndarray, actions: np.ndarray) -> float:
        """r_xi(tau) = r_xi(phi(tau)) of one trajectory: the reward the learner ranks trajectories by."""
        return float(self.progress(observations, actions)[-1])

    def compute_reward(self, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Per-step rewards (T,) of one trajectory, each step's share of `trajectory_reward`:
        r_t = (t v_t - (t - 1) v_{t-1}) / T, which sums to r_xi(tau) (module docstring)."""
        e = self.step_embeddings(observations, actions)
        T = len(e)
        if self.kind == "linear":  # telescoped exactly: xi . e_t / T
            return (e @ self.params["xi"]) / T
        paid = np.arange(1, T + 1) * self.values(prefix_means(e))
        return np.diff(paid, prepend=0.0) / T


def model_of(path: Path, doc: dict[str, Any], model: str | Path | None = None) -> Path:
    """The checkpoint a saved reward reads phi with: `model` when given, else the one at its recorded path relative
    to the reward's folder (a reward moved together with its model), else at its recorded absolute path."""
    if model is not None:
        return Path(model)
    recorded = doc["model"]
    relative = recorded.get("relative")
    candidates = ([path.parent / relative] if relative else []) + [Path(recorded["path"])]
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    raise LangprefError(
        f"the model of the reward {path} is not at {candidates[0]}"
        + (f" nor at {candidates[1]}" if len(candidates) > 1 else "")
        + ": copy it there beside the reward, or pass its folder (`model=` / `--model`)"
    )


def load(path: str | Path, model: str | Path | None = None) -> Reward:
    """The reward saved at `path` (a `--save-reward` directory, whose reward.json is the first run's, or a
    reward-NAME.json file), with the trajectory encoder of the checkpoint it was learned on: `model`, or the one it
    recorded (`model_of`: relative to the reward first, so a reward copied together with its model loads). One-line
    errors for a missing or foreign file, a format version newer than this langpref reads, and a checkpoint other
    than (or changed since) the one the reward was learned with."""
    path, doc = read_reward_file(path)
    model = model_of(path, doc, model)
    encoder = StepEncoder.from_checkpoint(model)
    if encoder.sha256 != doc["model"].get("sha256"):
        raise LangprefError(
            f"the checkpoint {model} is not the one the reward {path} was learned with (or has changed since); "
            "learn the reward again with this model"
        )
    if (encoder.obs_dim, encoder.action_dim) != (int(doc["obs_dim"]), int(doc["action_dim"])):
        raise LangprefError(f"the reward {path} and its checkpoint {model} disagree on the observation/action sizes")
    params = {k: np.asarray(v, dtype=np.float64) for k, v in doc["params"].items()}
    return Reward(path, doc, encoder, params)
