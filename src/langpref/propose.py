"""New trajectories made in the simulator: search the scripted controller's parameters for the rollout whose
embedding best meets a latent objective.

    gen = Generation.open(dataset, space, ProposeConfig())  # the dataset's parameters, the space's phi and phi_of
    proposer = gen.proposer(key=(0, 7))                    # one per run: its own surrogate, its own seeds
    proposal = proposer.propose(objective, start_unit, step=(3,))   # objective: (n, D) phi -> (n,) scores

The objective is a function of embeddings only: Eq. 4's cos(phi' - phi^t, psi_l) for a piece of feedback
(`langpref.improve`), or a learned reward r_xi(phi') (`langpref.reward`). One generation step:

1. *Propose*: CMA-ES (the `cma` package) maximises the objective of a surrogate phi_hat(u) over the controller's unit
   parameters u in [0, 1)^d, starting from `start`. The surrogate is kernel ridge regression (an RBF kernel on u, on
   top of a linear ridge fit) from u to phi, fitted on the dataset's (u, phi) pairs and refitted on every real rollout
   the proposer makes, so it learns where it is searching.
2. *Decide*: the `rollouts` best distinct points the search visited run in the real simulator, each from a fresh
   seed, and the real trajectory encoder embeds them; the objective of those real embeddings is what the caller
   decides by. The surrogate only proposes.

What the proposer can see: the simulator, the dataset's controller parameters and embeddings, the encoder and the
objective it is given. Never the true reward, the features of what it generated or a synthetic human's weights
(tests/test_propose.py walks every object reachable from a proposer to check). A rollout stores what a dataset
trajectory stores (observations, actions, step features, MuJoCo states, seed, controller parameters with the unit
vector `unit`), so `GeneratedStore` writes proposals as a dataset (schema 2) that replays, renders and loads like any
other: `rollout(env, task, unit, seed, horizon, index)` remakes one bit for bit.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.rollouts import AffineScale, TrajectoryEncoder, model_trajectory_encoder

Objective = Callable[[np.ndarray], np.ndarray]
"""(n, D) embeddings -> (n,) scores, higher is better."""
Embedder = Callable[[Any], np.ndarray]
"""A rollout (`langpref.dataset.storage.Trajectory`) -> its phi (D,)."""
GENERATED = "generated"
"""The candidate set name of new trajectories (`langpref improve --candidates generated`)."""


@dataclass
class ProposeConfig:
    """How new trajectories are searched for in the simulator (`--candidates generated`, `--optimize`)."""

    rollouts: int = 6
    """Real rollouts per generation step: the surrogate's best distinct candidates, run in the simulator and
    embedded by the trajectory encoder, which decide."""
    search_generations: int = 30
    """CMA-ES generations on the surrogate per generation step."""
    search_sigma: float = 0.2
    """CMA-ES initial step size, in the controller's unit parameters ([0, 1) each)."""
    surrogate_ridge: float = 0.05
    """Ridge penalty of the surrogate (kernel ridge from controller parameters to phi)."""
    optimize_rounds: int = 3
    """`learn-reward --optimize`: generation steps for r_xi's optimum, each starting from the best rollout so far."""

    def validate(self) -> None:
        if self.rollouts < 1 or self.search_generations < 1 or self.optimize_rounds < 1:
            raise LangprefError("rollouts, search_generations and optimize_rounds must each be >= 1")
        if not 0 < self.search_sigma < 1 or self.surrogate_ridge <= 0:
            raise LangprefError("search_sigma must be in (0, 1) and surrogate_ridge > 0")


# ---- the surrogate ------------------------------------------------------------------------------------------------


class Surrogate:
    """phi_hat(u) = linear ridge(u) + RBF kernel ridge on its residuals, fitted on (unit parameters, phi) pairs. The
    kernel's length scale is the median distance between the fitted points; far from every point the prediction
    falls back to the linear part."""

    def __init__(self, ridge: float = 0.05):
        self.ridge = float(ridge)
        self.U = np.zeros((0, 0))
        self.Y = np.zeros((0, 0))

    def fit(self, U: np.ndarray, Y: np.ndarray) -> Surrogate:
        U, Y = np.asarray(U, dtype=np.float64), np.asarray(Y, dtype=np.float64)
        if U.ndim != 2 or Y.ndim != 2 or len(U) != len(Y) or len(U) < 2:
            raise LangprefError(f"the surrogate needs >= 2 (parameters, phi) pairs, got {U.shape} and {Y.shape}")
        self.U, self.Y = U, Y
        X = np.hstack([U, np.ones((len(U), 1))])
        reg = self.ridge * np.eye(X.shape[1])
        reg[-1, -1] = 0.0
        self.B = np.linalg.solve(X.T @ X + reg, X.T @ Y)
        d2 = ((U[:, None, :] - U[None, :, :]) ** 2).sum(-1)
        self.gamma = 1.0 / max(float(np.median(d2[np.triu_indices(len(U), 1)])), 1e-9)
        K = np.exp(-self.gamma * d2)
        self.A = np.linalg.solve(K + self.ridge * np.eye(len(U)), Y - X @ self.B)
        return self

    def add(self, U: np.ndarray, Y: np.ndarray) -> Surrogate:
        """Refit with more pairs (the real rollouts of a generation step)."""
        return self.fit(np.vstack([self.U, np.atleast_2d(U)]), np.vstack([self.Y, np.atleast_2d(Y)]))

    def predict(self, U: np.ndarray) -> np.ndarray:
        U = np.atleast_2d(np.asarray(U, dtype=np.float64))
        d2 = (U * U).sum(1)[:, None] + (self.U * self.U).sum(1)[None, :] - 2 * U @ self.U.T
        lin = np.hstack([U, np.ones((len(U), 1))]) @ self.B
        return lin + np.exp(-self.gamma * np.maximum(d2, 0.0)) @ self.A


# ---- embedders ----------------------------------------------------------------------------------------------------


def model_embedder(model) -> Embedder:
    """phi of a rollout from a trained `LatentModel`'s trajectory encoder, as the model's latent space embeds one
    (`langpref.feedback.rollouts.model_trajectory_encoder`; `LatentSpace.phi_of`), for a caller holding the model
    but no space (a study session)."""
    return embedder_of(model_trajectory_encoder(model))


def embedder_of(encode: TrajectoryEncoder) -> Embedder:
    """One rollout at a time through a space's trajectory encoder (`LatentSpace.encode_trajectories`), as
    `LatentSpace.phi_of` embeds it; the closure holds the encoder alone, not the space (whose theta is the synthetic
    humans' view, which a proposer must not reach)."""
    return lambda traj: encode([traj])[0]


# ---- the dataset's controller parameters -------------------------------------------------------------------------


def dataset_units(dataset) -> np.ndarray:
    """The unit parameter vector of every trajectory of a simulated dataset: stored as `unit` (a generated dataset),
    or the Latin hypercube row `langpref generate` drew it from, checked against the stored parameters."""
    import json as _json

    from langpref.dataset.generate import controller_units
    from langpref.tasks import get_simulator

    sim = get_simulator(dataset.env)
    trajs = [dataset.load(i) for i in range(len(dataset))]
    if all("unit" in t.controller_params for t in trajs):
        return np.array([t.controller_params["unit"] for t in trajs], dtype=np.float64)
    seed = dataset.meta.config.get("seed")
    if seed is None or any(t.seed is None for t in trajs):
        raise LangprefError(
            f"dataset {dataset.root} does not say how its controllers were drawn (no seed); "
            "generate it with `langpref generate`"
        )
    units = controller_units(dataset.env, len(dataset), int(seed))
    for i, t in enumerate(trajs):
        params = _json.loads(_json.dumps(sim.make_controller(units[i], np.random.default_rng(t.seed)).params))
        if params != {k: v for k, v in t.controller_params.items() if k != "unit"}:
            raise LangprefError(
                f"trajectory {i} of {dataset.root} was not made by the controller parameters "
                "`langpref generate` draws; regenerate the dataset"
            )
    return units


def rollout_seed(key: tuple[int, ...]) -> int:
    return int(np.random.SeedSequence([abs(int(k)) for k in key] + [8191]).generate_state(1)[0])


def _env(name: str, horizon: int):
    """One live simulator per (task, horizon) per process, reused by every proposer (`langpref.tasks.live_env`)."""
    from langpref.tasks import live_env

    return live_env(name, horizon)


# ---- the proposer -------------------------------------------------------------------------------------------------


@dataclass
class Proposal:
    """The real rollouts of one generation step, best first by the objective of their real embeddings."""

    trajectories: list
    units: np.ndarray
    phi: np.ndarray
    scores: np.ndarray
    surrogate_scores: np.ndarray
    wall_s: float

    @classmethod
    def ranked(cls, trajectories: list, units, phi, scores, predicted, wall_s: float) -> Proposal:
        """The rollouts sorted best first by `scores` (ties keep their order)."""
        order = np.argsort(-np.asarray(scores), kind="stable")
        return cls([trajectories[i] for i in order], units[order], phi[order], scores[order], predicted[order], wall_s)


class Proposer:
    """Searches the controller parameters of task `env` (see the module docstring). `units` and `phi` are the
    (parameters, embedding) pairs the surrogate starts from; `key` makes its rollout seeds its own."""

    def __init__(
        self,
        env: str,
        horizon: int,
        units: np.ndarray,
        phi: np.ndarray,
        embed: Embedder,
        cfg: ProposeConfig | None = None,
        key: tuple[int, ...] = (0,),
    ):
        from langpref.tasks import get_simulator, get_task

        self.cfg = cfg or ProposeConfig()
        self.cfg.validate()
        self.env_name, self.horizon, self.key = env, int(horizon), tuple(int(k) for k in key)
        self.task = get_task(env)
        self.dim = get_simulator(env).controller_dim
        units = np.asarray(units, dtype=np.float64)
        if units.shape[1:] != (self.dim,):
            raise LangprefError(f"{env}'s controller has {self.dim} parameters, got units of shape {units.shape}")
        self.surrogate = Surrogate(self.cfg.surrogate_ridge).fit(units, phi)
        self.embed = embed

    def search(self, objective: Objective, start: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """CMA-ES on the surrogate from `start`: the `rollouts` best distinct points it visited, and their surrogate
        scores."""
        import cma

        top = 1.0 - 1e-9
        x0 = np.clip(np.asarray(start, dtype=np.float64), 0.02, 0.98)
        opts = {
            "bounds": [0.0, top],
            "seed": seed % (2**31 - 2) + 1,
            "verbose": -9,
            "maxiter": self.cfg.search_generations,
            "tolfun": 1e-9,
            "tolx": 1e-5,
        }
        es = cma.CMAEvolutionStrategy(x0, self.cfg.search_sigma, opts)
        seen, scores = [], []
        while not es.stop():
            xs = np.clip(np.array(es.ask()), 0.0, top)
            f = np.asarray(objective(self.surrogate.predict(xs)), dtype=np.float64)
            es.tell(list(xs), list(-f))
            seen.append(xs)
            scores.append(f)
        X, F = np.concatenate(seen), np.concatenate(scores)
        chosen: list[int] = []
        min_dist = 0.05 * np.sqrt(self.dim)
        for i in np.argsort(-F, kind="stable"):
            if all(np.linalg.norm(X[i] - X[j]) >= min_dist for j in chosen):
                chosen.append(int(i))
            if len(chosen) == self.cfg.rollouts:
                break
        return X[chosen], F[chosen]

    def rollout(self, unit: np.ndarray, seed: int, index: int = 0):
        """One real rollout of the controller `unit` from `seed`; its parameters record `unit` for replay."""
        from langpref.dataset.generate import rollout

        traj = rollout(_env(self.env_name, self.horizon), self.task, unit, seed, self.horizon, index)
        traj.controller_params = {**traj.controller_params, "unit": [float(x) for x in unit]}
        return traj

    def propose(self, objective: Objective, start: np.ndarray, step: tuple[int, ...] = ()) -> Proposal:
        """One generation step: search the surrogate, run the best candidates for real, embed and score them, and
        refit the surrogate on them. `step` (with the proposer's key) fixes the rollouts' seeds."""
        t0 = time.perf_counter()
        seed = rollout_seed((*self.key, *step))
        units, predicted = self.search(objective, start, seed)
        trajs = [self.rollout(u, rollout_seed((*self.key, *step, k))) for k, u in enumerate(units)]
        phi = np.stack([self.embed(t) for t in trajs])
        self.surrogate.add(units, phi)
        scores = np.asarray(objective(phi), dtype=np.float64)
        return Proposal.ranked(trajs, units, phi, scores, predicted, time.perf_counter() - t0)

    def optimise(self, objective: Objective, start: np.ndarray, step: tuple[int, ...] = ()) -> Proposal:
        """`optimize_rounds` generation steps, each starting from the best real rollout so far; all their rollouts,
        best first."""
        parts = []
        for r in range(self.cfg.optimize_rounds):
            best = max(parts, key=lambda p: p.scores[0]) if parts else None
            parts.append(self.propose(objective, start if best is None else best.units[0], (*step, r)))
        trajs = [t for p in parts for t in p.trajectories]
        units, phi = np.concatenate([p.units for p in parts]), np.concatenate([p.phi for p in parts])
        scores = np.concatenate([p.scores for p in parts])
        predicted = np.concatenate([p.surrogate_scores for p in parts])
        return Proposal.ranked(trajs, units, phi, scores, predicted, sum(p.wall_s for p in parts))


# ---- what a command needs: the dataset's parameters and embeddings, the encoder -----------------------------------


def cannot_generate(dataset) -> str | None:
    """Why no new trajectory can be generated for `dataset`, or None: its task is recorded (no simulator to roll
    out in), or its episodes differ in length (a search needs one horizon). Reads only the dataset's metadata, so a
    command checks it before any model loads; each caller words its own error around it."""
    from langpref.tasks import get_task

    if get_task(dataset.env).simulator is None:
        return f"task {dataset.env!r} has no simulator (a recorded task)"
    if dataset.meta.lengths is not None:
        return f"dataset {dataset.root} has episodes of different lengths"
    return None


@dataclass
class Generation:
    """Everything needed to make proposers for a dataset and latent space: controller units of every dataset row,
    phi of every row, the embedder of new rollouts, and the feature scale the *experimenter* uses to score them
    (the proposer never receives it)."""

    env: str
    horizon: int
    units: np.ndarray
    phi: np.ndarray
    embed: Embedder = field(repr=False)
    scale: Any = field(repr=False)
    cfg: ProposeConfig = field(default_factory=ProposeConfig)
    source: str = ""

    @classmethod
    def open(cls, dataset, space, cfg: ProposeConfig | None = None) -> Generation:
        """From a simulated dataset (already open), its latent space (new rollouts are embedded by its trajectory
        encoder, `LatentSpace.phi_of`: a trained model's, or the oracle's) and the search settings. Reads no file
        but the dataset's trajectories, for their controller parameters; loads no model."""
        why = cannot_generate(dataset)
        if why is not None:
            raise LangprefError(f"{why}: new trajectories are generated for simulated tasks of one horizon")
        if space.encode_trajectories is None:
            raise LangprefError(f"the latent space ({space.description}) cannot embed new trajectories")
        feats = np.asarray(dataset.features, dtype=np.float64)
        scale = AffineScale.fit(feats, space.theta)  # the humans' theta, whatever its scale (standardised, paper)
        embed = embedder_of(space.encode_trajectories)
        cfg = cfg or ProposeConfig()
        cfg.validate()
        _env(dataset.env, dataset.meta.horizon)  # start the simulator now, not in the first generation step
        return cls(
            dataset.env,
            dataset.meta.horizon,
            dataset_units(dataset),
            np.asarray(space.phi),
            embed,
            scale,
            cfg,
            str(dataset.root),
        )

    def proposer(self, key: tuple[int, ...] = (0,)) -> Proposer:
        return Proposer(self.env, self.horizon, self.units, self.phi, self.embed, self.cfg, key)

    def theta(self, traj) -> np.ndarray:
        """The normalised features of a rollout, as `LatentSpace.theta` holds them: for the synthetic human and the
        scores, never for the proposer."""
        return self.scale(traj.features)


def open_generation(dataset, space, cfg: ProposeConfig | None = None) -> Generation:
    """`Generation.open`: what a command calls with the dataset and the space it opened once
    (`langpref.feedback.space.open_space`), so that neither the dataset nor the model is read again."""
    return Generation.open(dataset, space, cfg)


# ---- storage ------------------------------------------------------------------------------------------------------


class GeneratedStore:
    """Generated trajectories as a dataset (schema 2, one split `generated`): `langpref render`, `inspect` and
    `load_dataset` read it, and each trajectory replays from its stored `unit` and seed. Written as it grows."""

    def __init__(self, root: str | Path, env: str, horizon: int, info: dict[str, Any] | None = None):
        from langpref.dataset.storage import load_dataset

        self.root, self.env, self.horizon, self.info = Path(root), env, int(horizon), dict(info or {})
        self.features: list[np.ndarray] = []
        if (self.root / "meta.json").exists():
            old = load_dataset(self.root, env=env)
            if old.meta.horizon != self.horizon:
                raise LangprefError(
                    f"{self.root} holds generated trajectories of horizon {old.meta.horizon}, "
                    f"not {horizon}; choose another directory"
                )
            self.features = list(np.asarray(old.features))

    def __len__(self) -> int:
        return len(self.features)

    def add(self, traj, **extra: Any) -> int:
        """Store a rollout (its parameters gain `extra`, e.g. the run and iteration); returns its index."""
        from langpref.dataset.storage import DatasetMeta, save_trajectory, write_meta, write_text_atomic
        from langpref.tasks import get_simulator, get_task

        task = get_task(self.env)
        traj.index = len(self.features)
        traj.controller_params = {**traj.controller_params, **extra}
        save_trajectory(self.root, traj)
        self.features.append(traj.features)
        n = len(self.features)
        meta = DatasetMeta.of_task(
            task,
            self.horizon,
            {GENERATED: list(range(n))},
            n,
            config={
                "generator": "langpref.propose (CMA-ES on a surrogate, decided by real rollouts)",
                "env_version": get_simulator(self.env).version,
                **self.info,
            },
        )
        write_meta(self.root, meta, np.array(self.features))
        write_text_atomic(self.root / "generated.json", json.dumps(self.info, indent=2, default=str) + "\n")
        return traj.index
