"""`langpref experiment rl --env ENV`: policies trained on the learned reward, against the true reward and the task's
success (issue 33).

Per synthetic human and seed, a Stable-Baselines3 policy (PPO by default, or SAC) is trained in the task's Gymnasium
env (`langpref/metaworld-button-press`, the env's own observations) on each reward source (`rl_policy.SOURCES`):
(a) the reward learned from Q language answers and (b) from Q comparisons, both by the paper's learner exactly as
`langpref learn-reward --feedback KIND --save-reward` learns them (the same run seeds), paid by
`langpref.reward.saved.LearnedReward`; (c) the synthetic human's true reward; (d) the task's sparse success. Every
policy is evaluated every `eval_every` steps by the true reward (0..1 on the test split's scale) and the success of
deterministic rollouts from fixed scenes. Beside them, a cheap "policy" with no RL at all: the learned reward's
optimum in the scripted controller's parameter space (CMA-ES, `langpref.propose`, as `learn-reward --optimize`).

Resumes run by run: each learned reward (and its CMA-ES optimum) and each policy's result is its own JSON file under
OUT/runs/, written when it finishes, so a rerun after an interruption skips them (runs of another configuration are
refused unless --force; more humans, seeds or sources reuse what is there). Writes OUT/rl.json (curves, final means,
paired 95% intervals between sources, the issue's targets checked, the config), OUT/rl.png and OUT/rl.md.

Budget (2 CPU cores, one torch thread): PPO makes about 1,000 steps per second here, so the default 100,000 steps of
150-step episodes take a minute or two a policy; SAC makes 50-100, 20-35 minutes a policy, under the hour the issue
allows. `RLConfig.tiny()` is the tests'.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from langpref.errors import LangprefError
from langpref.experiments.common import Inputs, SweepConfig, run_sweep, space_experiment
from langpref.experiments.rl_policy import LEARNED, SOURCES, Judge, PolicyJob, policy_job
from langpref.feedback.humans import HumanConfig
from langpref.reward.learner import RewardConfig

Algorithm = Literal["sac", "ppo"]


@dataclass
class RLConfig:
    """`langpref experiment rl`: reward sources x synthetic humans x seeds, one policy each."""

    algorithm: Algorithm = "ppo"
    """Stable-Baselines3 `ppo` or `sac`. Chosen on a val human (master seed 1, the true reward, 20,000 steps, 2 seeds):
    the same final true reward (0.659 both), PPO's rollouts press the button (success 0.67 against 0.00) and it trains
    12 times faster (docs/results.md, "Policies on the learned reward, three seeds")."""
    steps: int = 100_000
    """Environment steps per policy (the budget)."""
    horizon: int = 150
    """Steps per episode of training and evaluation (the button is reached in well under 150)."""
    eval_every: int = 5_000
    """Evaluate the policy every this many steps (its learning curve)."""
    eval_episodes: int = 5
    """Deterministic rollouts per evaluation, from the same scenes for every run."""
    hidden: tuple[int, ...] = (256, 256)
    """Hidden layers of the policy and value networks."""
    batch_size: int = 256
    """Minibatch size of SAC's updates (PPO's too)."""
    learning_starts: int = 1_000
    """SAC: random steps before the first update."""
    sources: tuple[str, ...] = SOURCES
    """Rewards to train on: language, comparison (learned from Q answers), true (the synthetic human's), success
    (the task's sparse success)."""
    queries: int = 40
    """Q, answers each learned reward is learned from."""
    humans: int = 1
    """Synthetic humans (reward weights w), drawn from `seed` as `learn-reward` draws them."""
    seeds: int = 3
    """Runs per human and source (reward learning, policy and scene seeds)."""
    seed: int = 0
    """Master seed: the same seed gives the same humans, rewards and policies."""
    cmaes: bool = True
    """Also report each learned reward's optimum in the controller's parameter space (CMA-ES, no RL)."""
    normalise: bool = True
    """Divide the learned and true rewards by the std of their trajectory reward over the dataset."""
    threads: int = 1
    """torch threads per run."""
    human: HumanConfig = field(default_factory=HumanConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)

    @classmethod
    def tiny(cls, **kw: Any) -> RLConfig:
        """A setting that runs in seconds, for tests."""
        base = {"steps": 64, "horizon": 8, "eval_every": 32, "eval_episodes": 1, "hidden": (8,), "batch_size": 16}
        return cls(**{**base, "learning_starts": 16, "queries": 2, "seeds": 1, "cmaes": False, **kw})

    def learn_config(self, kind: str):
        """The `LearnRewardConfig` of the learned reward of `kind` (the `learn-reward` run it equals)."""
        from langpref.reward import LearnRewardConfig

        return LearnRewardConfig(
            feedback=kind,
            queries=self.queries,
            humans=self.humans,
            seeds=self.seeds,
            seed=self.seed,
            human=self.human,
            reward=self.reward,
        )

    def validate(self) -> None:
        if self.algorithm not in ("sac", "ppo"):
            raise LangprefError(f"unknown algorithm {self.algorithm!r}: choose sac or ppo")
        unknown = [s for s in self.sources if s not in SOURCES]
        if unknown or not self.sources or len(set(self.sources)) != len(self.sources):
            raise LangprefError(f"sources must be distinct names from {', '.join(SOURCES)}, got {self.sources}")
        for name in ("steps", "horizon", "eval_every", "eval_episodes", "batch_size", "humans", "seeds", "threads"):
            if getattr(self, name) < 1:
                raise LangprefError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.eval_every > self.steps:
            raise LangprefError(f"eval_every ({self.eval_every}) must not exceed steps ({self.steps})")
        if not self.hidden or min(self.hidden) < 1 or self.learning_starts < 0:
            raise LangprefError("hidden needs at least one layer of >= 1 units, and learning_starts must be >= 0")
        if self.human.feature_scale != "standardised":
            raise LangprefError("experiment rl scores rollouts on the standardised feature scale only")
        if any(s in LEARNED for s in self.sources):
            self.learn_config("language").validate()
        else:
            self.human.validate()

    def key(self) -> dict[str, Any]:
        """What a finished run depends on: every field but those that only choose which runs there are."""
        record = asdict(self)
        for name in ("humans", "seeds", "sources", "threads"):
            del record[name]
        if self.human.no_change_margin is None:  # added later: the runs made before it stay valid
            del record["human"]["no_change_margin"]
        return record


class RunFiles:
    """Finished runs, one JSON file each under `root` (written atomically), tied to a configuration key."""

    def __init__(self, root: Path, config: dict[str, Any], force: bool = False):
        self.root = Path(root)
        self.key = hashlib.sha256(json.dumps(config, sort_keys=True, default=str).encode()).hexdigest()[:16]
        if force and self.root.is_dir():
            for old in self.root.glob("*.json"):
                old.unlink()

    def _path(self, name: str) -> Path:
        return self.root / f"{name}.json"

    def __contains__(self, name: str) -> bool:
        return self.get(name) is not None

    def get(self, name: str) -> Any:
        """The saved result of run `name`, None if it has not finished."""
        path = self._path(name)
        if not path.is_file():
            return None
        try:
            doc = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise LangprefError(f"{path} is corrupt; delete it or pass --force to start over") from None
        if doc.get("config_key") != self.key:
            raise LangprefError(
                f"{path} is a run made with another configuration; pass --force to start over or choose another --out"
            )
        return doc["result"]

    def put(self, name: str, value: Any) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        tmp = self.root / f".{name}.tmp-{os.getpid()}"
        tmp.write_text(json.dumps({"config_key": self.key, "result": value}) + "\n")
        tmp.replace(self._path(name))


def judges(dataset, space, cfg: RLConfig) -> list[Judge]:
    """The experimenter's scorer of each synthetic human (weights, the train split's feature scale, the test
    split's range of true rewards), from the dataset the space was opened on."""
    from langpref.feedback.space import FeatureScale
    from langpref.reward import human_weights

    scale = FeatureScale.fit(np.asarray(dataset.features, dtype=np.float64)[dataset.split("train")])
    out = []
    for h in range(cfg.humans):
        w = human_weights(len(space.feature_names), cfg.seed, h)
        test = space.theta[space.split("test")] @ w
        out.append(Judge(w, scale.mean, scale.std, float(test.min()), float(test.max())))
    return out


def learn_rewards(space, cfg: RLConfig, model: Path, out: Path, store: RunFiles, judge: list[Judge], generation):
    """Each learned reward (kind x human x seed) saved under OUT/rewards/, with its scale, its reward-learning
    metrics and (with `generation`) its CMA-ES optimum's true reward and success; finished ones are skipped."""
    for kind in (s for s in cfg.sources if s in LEARNED):
        for h in range(cfg.humans):
            for s in range(cfg.seeds):
                name = f"reward-{kind}-h{h}-s{s}"
                if not _have_reward(store, out, name):
                    store.put(name, learn_one(space, cfg, kind, (h, s), model, out, judge[h], generation))


def _have_reward(store: RunFiles, out: Path, name: str) -> bool:
    """Whether the learned reward `name` has finished and its file is still there."""
    known = store.get(name)
    return known is not None and (out / known["file"]).is_file()


def learn_one(space, cfg: RLConfig, kind: str, run: tuple[int, int], model: Path, out: Path, judge: Judge, generation):
    """One learned reward, as `langpref learn-reward --feedback KIND --save-reward` makes run h{h}-s{s} (the same
    run seeds): its saved file, scale and metrics, and its CMA-ES optimum scored by `judge`."""
    from langpref.reward import run_reward_learning
    from langpref.reward.loop import optimize_reward
    from langpref.reward.saved import save_learned_reward

    h, s = run
    learners: list = []
    curves = run_reward_learning(space, judge.w, cfg.learn_config(kind), (cfg.seed, h, s), learners=learners)
    learner = learners[0]
    path = save_learned_reward(learner, out / "rewards", env=space.env, model=model, name=f"{kind}-h{h}-s{s}")
    record = {
        "file": path.relative_to(out).as_posix(),
        "scale": float(np.std(learner.predict(space.phi))) if cfg.normalise else 1.0,
        "true_reward_of_best": curves.true_reward_of_best[-1],
        "kendall_tau": curves.kendall_tau[-1],
    }
    if generation is not None:
        best = optimize_reward(generation, learner, (cfg.seed, h, s)).trajectories[0]
        record["cmaes"] = {"true_reward": judge.true_reward(best.step_features), "success": float(bool(best.success))}
    return record


def policy_jobs(space, cfg: RLConfig, store: RunFiles, judge: list[Judge], out: Path) -> list[PolicyJob]:
    """One job per source x human x seed, in that order (learned rewards read from under `out`)."""
    jobs = []
    for source in cfg.sources:
        for h in range(cfg.humans):
            true_scale = float(np.std(space.theta @ judge[h].w)) if cfg.normalise else 1.0
            for s in range(cfg.seeds):
                reward = store.get(f"reward-{source}-h{h}-s{s}") if source in LEARNED else None
                scale = reward["scale"] if reward else (true_scale if source == "true" else 1.0)
                path = str(out / reward["file"]) if reward else None
                seed = int(np.random.SeedSequence([cfg.seed, h, s, 4099]).generate_state(1)[0] % 2**31)
                jobs.append(PolicyJob(f"policy-{source}-h{h}-s{s}", space.env, source, h, seed, judge[h], scale, path))
    return jobs


def _no_setup() -> None:
    return None


@space_experiment
def run_rl_experiment(run: Inputs) -> dict[str, Any]:
    """Every source x human x seed of `config` on `env` (see the module docstring); writes rl.json/.png/.md and
    returns the summary."""
    from langpref.experiments.rl_report import write_report
    from langpref.feedback.space import open_space

    cfg: RLConfig = run.config or RLConfig()
    cfg.validate()
    data, model, out = run.paths("rl")
    learned = any(s in LEARNED for s in cfg.sources)
    if learned:
        from langpref.reward.saved import check_saveable

        check_saveable(model)  # a learned reward needs a trajectory encoder: one line, before any work
    dataset, space = open_space(data, model, env=run.env, perfect=run.perfect, phrasings=cfg.human.phrasings)
    store = RunFiles(out / "runs", {**cfg.key(), "data": str(data), "model": str(model)}, run.force)
    judge = judges(dataset, space, cfg)
    generation = None
    if cfg.cmaes and not all(_have_reward(store, out, name) for name in _reward_names(cfg)):  # only if needed
        from langpref.propose import open_generation

        generation = open_generation(dataset, space)
    if learned:
        learn_rewards(space, cfg, Path(model), out, store, judge, generation)
    jobs = policy_jobs(space, cfg, store, judge, out)
    todo = [(job, cfg) for job in jobs if job.name not in store]
    sweep = run.sweep or SweepConfig()
    run_sweep(policy_job, todo, None, (), store, sweep, f"rl {cfg.algorithm}", run.progress, setup=_no_setup)
    runs = {job.name: store.get(job.name) for job in jobs}
    rewards = {name: store.get(name) for name in _reward_names(cfg)}
    return write_report(run.env, data, model, out, space, cfg, runs, rewards, run.command)


def _reward_names(cfg: RLConfig) -> list[str]:
    return [
        f"reward-{k}-h{h}-s{s}"
        for k in cfg.sources
        if k in LEARNED
        for h in range(cfg.humans)
        for s in range(cfg.seeds)
    ]
