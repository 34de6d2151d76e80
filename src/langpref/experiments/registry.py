"""The paper's experiments by name: one `Experiment` record each, which `langpref experiment NAME` is built from.

A record holds cheap strings only (as Gymnasium's specs hold `entry_point`): its config dataclass and its run
function are `module:name` references imported when the command runs, so listing the experiments (`--help`) imports
nothing heavy. The CLI loops over `EXPERIMENTS`; nothing composes a module or a function name from an experiment's.

Experiments of the latent space's uses (`inputs="space"`) share one run signature:

    run(env, data, model, out, *, perfect, config, force, sweep, command) -> summary

(`data`, `model` and `out` None for their defaults, `config` the record's config class, `sweep` a `SweepConfig`,
`command` the command line recorded in the summary), written once: `langpref.experiments.common.space_experiment`
makes it around a body that takes them as one `Inputs`. Experiments that train their own models (`inputs="own"`) take
their own arguments; their commands live beside `langpref train` (`langpref.cli.latent`). An installed package's
experiment (entry-point group `langpref.experiments`) becomes `langpref experiment NAME` too: of the uses, with the
shared flags; `inputs="own"`, with its config's flags alone, run as `run(config)` (the config's `out` its folder).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from langpref.errors import LangprefError
from langpref.registry import Registry


def load_ref(ref: str) -> Any:
    """The object a `module:name` reference names."""
    module, name = ref.split(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Experiment:
    """One experiment of `langpref experiment`."""

    name: str
    """`langpref experiment NAME`; also its default output folder, results/NAME/ENV."""
    help: str
    """One line for `langpref experiment --help` (what it shows and with how many runs)."""
    run: str
    """`module:function` that runs it and returns its summary (the JSON it writes)."""
    config: str | None = None
    """`module:Class` of its config dataclass; None: its flags are its own (`inputs="own"`)."""
    flags: tuple[str, ...] = ()
    """The (dotted) config fields given a flag; the others keep the experiment's settings."""
    options: Mapping[str, Any] = field(default_factory=dict)
    """Flag overrides for this experiment (`langpref.cli_config.add_config`'s `opts`), e.g. another default."""
    inputs: Literal["space", "own"] = "space"
    """`space`: a latent space of a dataset and a model (or the oracle space), the shared run signature above;
    `own`: it trains its own models."""
    default_out: str = ""
    """Where its results go without `--out`, as `--help` says it."""
    common: tuple[str, ...] | None = None
    """Of `flags`, those `--help` shows (the size of the run, as a rule); the others only `--help-all`. None: all."""

    def config_class(self) -> type:
        if self.config is None:
            raise LangprefError(f"experiment {self.name!r} has no config dataclass")
        return load_ref(self.config)

    def runner(self) -> Callable[..., dict[str, Any]]:
        return load_ref(self.run)


REGISTRY: Registry[Experiment] = Registry("experiment", Experiment, "langpref.experiments")
"""The experiments (`langpref.registry`); an installed package adds one through the entry-point group
`langpref.experiments`."""
EXPERIMENTS: dict[str, Experiment] = REGISTRY.items
"""Every experiment by name, in the order `--help` lists them."""
register_experiment = REGISTRY.register
experiment_names = REGISTRY.names
get_experiment = REGISTRY.get


_PHRASING = ("human.phrasing_split", "human.phrasings", "human.feature_scale", "human.direction")
_REWARD_FLAGS = ("seeds", "humans", "queries", "reward.model", *_PHRASING)
_SIZE = ("queries", "humans", "seeds")
"""The flags of a reward experiment's size, which its `--help` shows."""
_IMPROVE, _LEARN = "langpref.improve:ImproveConfig", "langpref.reward:LearnRewardConfig"
_OUT = "results/{name}/ENV, or ENV-perfect"

for _experiment in (
    Experiment(
        "alignment",
        "Appendix C: test accuracy, co-finetuned vs frozen language model",
        "langpref.experiments.alignment:run_alignment_experiment",
        inputs="own",
        default_out="results/alignment/ENV",
    ),
    Experiment(
        "seeds",
        "the alignment accuracy over training seeds (default 0, 1, 2): the seeds table, its mean and range",
        "langpref.experiments.seeds:run_seeds_experiment",
        "langpref.experiments.seeds:SeedsConfig",
        inputs="own",
        default_out="results/seeds/ENV",
    ),
    Experiment(
        "observations",
        "issue 19: state vs camera images vs both as the trajectory encoder's input",
        "langpref.experiments.observations:run_observations_experiment",
        "langpref.experiments.observations:ObservationsConfig",
        inputs="own",
        default_out="results/observations/ENV",
    ),
    Experiment(
        "improve",
        "Fig. 4: iterative improvement, Eq. 4 (cosine and as printed) and the history strategy, 100 seeds",
        "langpref.experiments.improve:run_improve_experiment",
        _IMPROVE,
        ("iterations", "seeds", *_PHRASING),
        default_out=_OUT.format(name="improve"),
        common=("iterations", "seeds"),
    ),
    Experiment(
        "reward",
        "Fig. 5: reward learning, language vs comparisons, 3 humans x 3 seeds, Q = 40",
        "langpref.experiments.reward:run_reward_experiment",
        _LEARN,
        _REWARD_FLAGS,
        default_out=_OUT.format(name="reward") + ", ENV-mlp",
        common=_SIZE,
    ),
    Experiment(
        "ablation",
        "Fig. 6: language reward loss, explicit + implicit vs each alone",
        "langpref.experiments.reward:run_ablation_experiment",
        _LEARN,
        _REWARD_FLAGS,
        default_out=_OUT.format(name="ablation") + ", ENV-mlp",
        common=_SIZE,
    ),
    Experiment(
        "prior",
        "the L2 prior's strength per reward-learning method, chosen on the val split",
        "langpref.experiments.prior:run_prior_experiment",
        _LEARN,
        _REWARD_FLAGS,
        default_out=_OUT.format(name="prior") + ", ENV-mlp",
        common=_SIZE,
    ),
    Experiment(
        "choose",
        'the answer-model learner\'s prior scale and "no change" logit, each value against the default on the val '
        "split with other humans (10 humans x 3 seeds, Q = 40)",
        "langpref.experiments.choose:run_choose_experiment",
        _LEARN,
        (*_REWARD_FLAGS, "human.no_change_logit", "human.no_change_margin"),
        {"humans": {"default": 10, "help": "synthetic humans (reward weights w), drawn from --seed (default 10)"}},
        default_out=_OUT.format(name="choose"),
        common=_SIZE,
    ),
    Experiment(
        "active",
        "active queries: language x {random, lal-infogain, infogain} and comparisons x {random, infogain, "
        "volume-removal}, and both kinds chosen per query by information per modelled second (mixed), 10 humans x 3 "
        "seeds, Q = 40",
        "langpref.experiments.active:run_active_experiment",
        _LEARN,
        (
            *_REWARD_FLAGS,
            "human.no_change_logit",
            "human.no_change_margin",
            "candidates",
            "posterior_samples",
            "query_batch",
            "language_seconds",
            "comparison_seconds",
        ),
        {"humans": {"default": 10, "help": "synthetic humans (reward weights w), drawn from --seed (default 10)"}},
        default_out=_OUT.format(name="active") + ", ENV-mlp, ENV-nochangeC, ENV-nochange-marginM",
        common=_SIZE,
    ),
    Experiment(
        "generate",
        "issue 18: improvement from dataset vs generated candidates, and r_xi's generated optimum vs the "
        "best test trajectory (10 humans x 3 seeds, Q = 40)",
        "langpref.experiments.generate:run_generate_experiment",
        _IMPROVE,
        ("iterations", "seeds"),
        default_out=_OUT.format(name="generate") + ", ENV-mlp",
    ),
    Experiment(
        "rl",
        "issue 33: policies (PPO) trained on the reward learned from language, from comparisons, the true reward "
        "and the task's success, judged by the true reward (1 human x 3 seeds, Q = 40)",
        "langpref.experiments.rl:run_rl_experiment",
        "langpref.experiments.rl:RLConfig",
        (
            "algorithm",
            "steps",
            "horizon",
            "eval_every",
            "eval_episodes",
            "sources",
            "queries",
            "humans",
            "seeds",
            "seed",
            "cmaes",
            "threads",
            "reward.model",
        ),
        default_out="results/rl/ENV",
        common=("steps", *_SIZE),
    ),
    Experiment(
        "verdict",
        "language vs comparisons over several reward experiments (one per trained model): paired intervals on AUC "
        "and mean CE, the human as the unit",
        "langpref.experiments.verdict:run_verdict_experiment",
        "langpref.experiments.verdict:VerdictConfig",
        inputs="own",
        default_out="results/verdict/ENV",
    ),
):
    register_experiment(_experiment)
