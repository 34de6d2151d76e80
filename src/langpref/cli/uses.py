"""`langpref improve | learn-reward | experiment improve|reward|ablation|prior|active|generate`: uses of the
latent space, with synthetic humans."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from langpref import cli_config as cc
from langpref.cli.common import JSON, TASK, run_config_experiment
from langpref.cli_config import RERUN, beside, command, command_of, config, emit, from_args, opt, path, record
from langpref.errors import LangprefError
from langpref.experiments.registry import EXPERIMENTS, REGISTRY, Experiment, get_experiment
from langpref.extras import require


def _use_opts(experiment: bool = False) -> dict[str, Any]:
    """The flags of the synthetic human, the reward model and the splits where they differ from the derived ones
    (`choices` come from the fields' `Literal` types, the feedback kinds from their registry)."""
    from langpref.feedback.humans import HumanConfig
    from langpref.reward import DEFAULT_WEIGHT_DECAY, feedback_choices
    from langpref.reward.learners import learner_names

    docs, out = cc.field_docs(HumanConfig), (lambda s: f" Results go to ENV-{s} unless --out." if experiment else "")
    return {
        "human.phrasing_split": {"help": docs["phrasing_split"] + out("bank-SPLIT")},
        "human.phrasings": {"metavar": "FILE", "help": docs["phrasings"] + out("phrasings")},
        "human.feature_scale": {"help": docs["feature_scale"] + out("paper-scale")},
        "human.direction": {"help": docs["direction"] + out("toward-best")},
        "human.feature_rule": {"help": docs["feature_rule"] + out("largest-change")},
        "human.vague": {"help": docs["vague"] + out("vagueP")},
        "human.no_change_logit": {
            "flag": "--human-no-change-logit",
            "metavar": "C",
            "help": docs["no_change_logit"] + out("nochangeC"),
        },
        "human.no_change_margin": {
            "flag": "--human-no-change-margin",
            "metavar": "M",
            "help": docs["no_change_margin"] + out("nochange-marginM"),
        },
        "reward.model": "--reward-model",
        "reward.hidden": "--reward-hidden",
        "reward.negative_split": None,
        "reward.weight_decay": {
            "help": "L2 prior on r_xi's parameters, against the weighted mean loss over feedback "
            "pairs (default "
            + ", ".join(f"{v:g} for {k}" for k, v in DEFAULT_WEIGHT_DECAY.items())
            + "; `langpref experiment prior` shows how the linear one was chosen)"
        },
        "candidate_split": "--candidates",
        "generated_out": {"metavar": "DIR"},
        "feedback": {"required": True, "choices": feedback_choices()},
        "learner": {"choices": learner_names()},
    }


def _space_options(experiment: bool = False) -> list[cc.Options]:
    return [
        path(
            "--model",
            default=None,
            help="checkpoint directory (`langpref train`)"
            + ("; default results/alignment/ENV/cofinetuned, from `experiment alignment`" if experiment else ""),
        ),
        path(
            "--data",
            required=not experiment,
            default=None,
            help="dataset directory" + (" (default data/ENV)" if experiment else " (`langpref generate`)"),
        ),
        opt(
            "--perfect-latent",
            action="store_true",
            help="ORACLE: use phi = normalised features and psi = +-e_f instead of a model (an upper bound)",
        ),
    ]


def _opened(args: argparse.Namespace) -> tuple[Any, Any]:
    """(the dataset of `--data`, the latent space through `--model` or `--perfect-latent`): the command's one load
    of each, passed on as objects (to the generation, to the value-order metric), never reopened from paths."""
    from langpref.feedback.space import open_space

    return open_space(
        args.data,
        args.model,
        perfect=args.perfect_latent,
        phrasings=getattr(args, "human.phrasings"),
        feature_scale=getattr(args, "human.feature_scale", "standardised"),
    )


def _space(args: argparse.Namespace):
    """The latent space of `_opened`, for a command that needs no more of the dataset."""
    return _opened(args)[1]


PROPOSE = config("langpref.propose:ProposeConfig", prefix="propose.", common=())
"""The simulator search's knobs, behind `--help-all`."""


def _generation(args: argparse.Namespace, dataset, space):
    """The simulator search of `langpref.propose` over the dataset's controllers, with the search flags: new
    rollouts are embedded by the space's own trajectory encoder (`LatentSpace.phi_of`)."""
    from langpref.propose import ProposeConfig, open_generation

    return open_generation(dataset, space, from_args(ProposeConfig, args, "propose."))


@command(
    "improve",
    "iterative trajectory improvement with a synthetic language human (Eq. 4)",
    [
        *_space_options(),
        config(
            "langpref.improve:ImproveConfig",
            lambda: {**_use_opts(), "human.rationality": None},
            common=("iterations", "seeds", "candidate_split", "strategy"),
        ),
        PROPOSE,
        path("--figure", default=None, help="also draw the curve into this PNG"),
        JSON,
        RERUN,
    ],
    "From a random trajectory of the candidate split, N rounds of synthetic language feedback, each followed by "
    "the argmax over the candidates of Eq. 4's cosine objective (strategy paper) or of the reward learned from "
    "all feedback so far (strategy history). Reports the mean normalised true reward per iteration (0 = worst, "
    "1 = best candidate).",
)
def cmd_improve(args: argparse.Namespace) -> None:
    from langpref.improve import ImproveConfig, improve, plot_improvement

    cfg = from_args(ImproveConfig, args)
    cfg.validate()
    dataset, space = _opened(args)
    result = improve(space, cfg, generation=_generation(args, dataset, space) if cfg.generated else None)
    if args.figure:
        result["figure"] = str(plot_improvement({cfg.strategy: result}, args.figure, f"strategy {cfg.strategy}"))
        record(args, beside(args.figure), cfg, data=args.data, model=args.model, perfect=args.perfect_latent)
    emit(
        result,
        args.json,
        lambda r: (
            "mean normalised true reward per iteration: "
            + " ".join(f"{v:.2f}" for v in r["curve"])
            + f"\ngain {r['gain']:+.3f} over {r['num_runs']} runs"
            + (f"; figure {r['figure']}" if "figure" in r else "")
        ),
    )


def _space_and_episodes(args: argparse.Namespace, cfg: Any) -> tuple[Any, Any, Any]:
    """(the dataset of `--data`, its latent space through `--model`, the eval split's successful episodes step by
    step for the value-order metric, None with --perfect-latent), each announced at a terminal before its seconds
    pass; the dataset is read once, for all three."""
    from langpref.cli.outputs import status

    status(
        f"loading torch and the dataset {args.data}"
        + ("" if args.perfect_latent else f", then reading it and the bank's phrasings through the model {args.model}")
    )
    dataset, space = _opened(args)
    if args.perfect_latent:
        return dataset, space, None
    from langpref.reward.steps import success_prefixes

    status(f"reading the {cfg.eval_split} split's successful episodes step by step through the model")
    return dataset, space, success_prefixes(dataset, args.model, cfg.eval_split, cfg.human.feature_scale)


@command(
    "learn-reward",
    "reward learning from synthetic language feedback or comparisons",
    [
        *_space_options(),
        config(
            "langpref.reward:LearnRewardConfig",
            _use_opts,
            common=("feedback", "queries", "humans", "seeds", "learner", "query_selection"),
        ),
        cc.rare(
            opt(
                "--optimize",
                action="store_true",
                help="after the last query, generate r_xi's optimum in the simulator (`langpref.propose`): adds "
                "optimized_true_reward (above 1: better than the eval split's best) and recorded_true_reward",
            )
        ),
        PROPOSE,
        path(
            "--save-reward",
            default=None,
            metavar="DIR",
            help="write each run's r_xi into DIR (reward.json: the first run's) for `langpref.reward.load`, "
            "`langpref label` and the Gymnasium wrapper (synthetic humans: each from a random hidden reward)",
        ),
        path(
            "--answers",
            default=None,
            metavar="FILE",
            help="learn from real people's recorded answers (JSON Lines: a `study export`'s answers.jsonl, or the "
            "answers format of docs/api/reward.md), one reward per participant, instead of synthetic humans",
        ),
        cc.rare(
            opt("--participant", default=None, metavar="P", help="with --answers: only this participant's answers"),
            opt("--pooled", action="store_true", help="with --answers: one reward from every participant's answers"),
        ),
        path(
            "--figure",
            default=None,
            help="also draw the curves into this PNG (with --answers: what each learned reward wants, per feature)",
        ),
        JSON,
        RERUN,
    ],
    "Each query shows one train trajectory (language: the human says how to improve it; L_Explicit + "
    "L_Implicit, Eq. 5-9) or a random train pair (comparison: Bradley-Terry). After every query, r_xi is refit "
    "on all feedback so far and scored on the test split.",
)
def cmd_learn_reward(args: argparse.Namespace) -> None:
    from langpref.cli.outputs import check_writable
    from langpref.reward import LearnRewardConfig, learn_reward

    cfg = from_args(LearnRewardConfig, args)
    cfg.validate()
    check_writable(args.save_reward, "--save-reward", folder=True)  # before the runs: their rewards are not lost
    check_writable(args.figure, "--figure")
    if args.answers is not None or args.participant is not None or args.pooled:
        return _learn_from_answers(args, cfg)
    if args.figure:
        require("plots", "learn-reward --figure")  # before the runs, not after them
    dataset, space, episodes = _space_and_episodes(args, cfg)
    result = learn_reward(
        space,
        cfg,
        generation=_generation(args, dataset, space) if args.optimize else None,
        save_reward=args.save_reward,
        model=None if args.perfect_latent else args.model,
        episodes=episodes,
    )
    if args.figure:
        from langpref.reward.figures import plot_reward_curves

        result["figure"] = str(plot_reward_curves({cfg.feedback: result}, args.figure, f"{cfg.feedback} feedback"))
        record(args, beside(args.figure), cfg, data=args.data, model=args.model, perfect=args.perfect_latent)
    emit(
        result,
        args.json,
        lambda r: (
            f"{r['feedback']} feedback, {r['num_runs']} runs\n"
            + "cross-entropy per query:        "
            + " ".join(f"{v:.3f}" for v in r["cross_entropy"])
            + "\n"
            + "true reward of the best, per q: "
            + " ".join(f"{v:.2f}" for v in r["true_reward_of_best"])
            + f"\narea under the true-reward curve {r['auc_true_reward']:.3f}; reaches 0.95 after "
            + f"{r['queries_to_0.95']} queries"
            + f"\nafter {len(r['kendall_tau']) - 1} queries: Kendall tau {r['kendall_tau'][-1]:.3f}, "
            + f"EPIC distance {r['epic_distance'][-1]:.3f}"
            + (
                f", value-order correlation {r['value_order_correlation']:.3f} "
                f"(the true reward's {r.get('value_order_correlation_true_reward', float('nan')):.3f})"
                if "value_order_correlation" in r
                else ""
            )
            + (f"; figure {r['figure']}" if "figure" in r else "")
            + (
                f"\ngenerated r_xi optimum: mean normalised true reward {r['optimized_true_reward_mean']:.2f}, "
                f"above the split's best in {r['optimized_beats_best_of_split']:.0%} of runs; r_xi's best recorded "
                f"trajectory (every split) {r['recorded_true_reward_mean']:.2f}, beaten in "
                f"{r['optimized_beats_recorded']:.0%}"
                if "optimized_true_reward" in r
                else ""
            )
        ),
    )


def _learn_from_answers(args: argparse.Namespace, cfg) -> None:
    """`learn-reward --answers FILE`: a reward per participant (or one, or pooled) from recorded answers."""
    from langpref.cli.outputs import status
    from langpref.reward.recorded import rewards_from_answers

    if args.answers is None:
        raise LangprefError("--participant and --pooled choose among recorded answers: pass --answers FILE")
    if args.participant is not None and args.pooled:
        raise LangprefError("pass --participant P or --pooled, not both")
    if args.perfect_latent:
        raise LangprefError("--answers learns on a trained model's latent space: pass --model, not --perfect-latent")
    if args.figure:
        require("plots", "learn-reward --figure")  # before the model loads, not after
    status(f"loading torch, the dataset {args.data} and the model {args.model}")
    result = rewards_from_answers(
        args.answers, args.data, args.model, cfg, args.participant, args.pooled, args.save_reward, lambda: _space(args)
    )
    if args.figure:
        from langpref.reward.wants import plot_wants

        result["figure"] = str(plot_wants(result["rewards"], args.figure))
    emit(
        result,
        args.json,
        lambda r: "\n".join(
            [
                f"{r['answers']} answers ({r['left_out']} of other kinds and {r['out_of_task']} about what the task "
                f"does not measure left out), learner {r['learner']}"
            ]
            + [
                f"  {e['name']} ({e['answers']} answers): {e['summary']}" + (f" -> {e['path']}" if "path" in e else "")
                for e in r["rewards"]
            ]
            + ([] if "save_reward" in r else ["(pass --save-reward DIR to keep the rewards)"])
            + ([f"figure {r['figure']}"] if "figure" in r else [])
        ),
    )


def cmd_experiment_uses(args: argparse.Namespace) -> None:
    from langpref.experiments.common import SweepConfig

    experiment = get_experiment(args.experiment)
    require("plots", f"langpref experiment {experiment.name}")  # every experiment ends with its figure
    kw = {
        "env": args.env,
        "data": args.data,
        "model": args.model,
        "out": args.out,
        "perfect": args.perfect_latent,
        "force": args.force,
        "sweep": from_args(SweepConfig, args),
    }
    cfg = from_args(experiment.config_class(), args)
    summary = experiment.runner()(**kw, config=cfg, command=command_of(args, shown=True))
    md = Path(summary["figure"]).with_suffix(".md")
    record(
        args,
        beside(md),
        cfg,
        **{**kw, "data": summary.get("data", kw["data"]), "model": summary.get("model", kw["model"]), "out": md.parent},
    )
    emit(
        summary,
        args.json,
        lambda s: md.read_text() + f"\n(wrote {md.parent}/: {md.stem}.json, .png, .md, .config.json)",
    )


def _experiment_options(experiment: Experiment) -> list[cc.Options]:
    """The flags of `langpref experiment NAME` for an experiment of the latent space's uses."""
    return [
        TASK,
        *_space_options(experiment=True),
        path("--out", default=None, help=f"output directory (default {experiment.default_out})"),
        config(
            experiment.config,
            lambda e=experiment: {**_use_opts(True), **e.options},
            only=experiment.flags,
            common=experiment.common,
        ),
        opt("--force", action="store_true", help="discard finished runs in --out and start over"),
        config("langpref.experiments.common:SweepConfig", common=("workers",)),
        RERUN,
        JSON,
    ]


def cmd_experiment_own(args: argparse.Namespace) -> None:
    """`langpref experiment NAME` for a plugin's experiment that takes only its config (`inputs="own"`)."""
    run_config_experiment(args, args.experiment)


def add_experiment_commands(plugins: bool = False) -> None:
    """`langpref experiment NAME` for every experiment not yet a command: of the latent space's uses, with the
    shared flags; a plugin's of `inputs="own"` with its config's flags alone (`run(config)`, the built-in ones have
    their own commands beside `langpref train`). `plugins`: also the experiments of installed packages (the
    `langpref.experiments` entry-point group), loaded only for a command line that asks for an experiment so that
    no other command imports them."""
    if plugins:
        REGISTRY.load_plugins()
    for experiment in list(REGISTRY.items.values()):
        name = f"experiment {experiment.name}"
        if name in cc.COMMANDS:
            continue
        if experiment.inputs == "space":
            command(
                name,
                experiment.help,
                _experiment_options(experiment),
                experiment.help + ". Writes NAME.json, NAME.png and NAME.md (a section for docs/results.md); an "
                "interrupted run resumes without redoing finished seeds.",
            )(cmd_experiment_uses)
        elif plugins and experiment.config is not None:
            command(name, experiment.help, [config(experiment.config), JSON, RERUN])(cmd_experiment_own)


add_experiment_commands()


@command(
    "experiment verdict",
    EXPERIMENTS["verdict"].help,
    [config(EXPERIMENTS["verdict"].config, {"env": {"metavar": "TASK"}}), JSON, RERUN],
    "Reads each folder's runs.json (written by `langpref experiment reward`, e.g. one per training seed: --model "
    "models/ENV-seedN --out results/reward/ENV-seedN --humans 10), pairs language with comparisons run by run, and "
    "writes verdict.md/.json: per model and over every model, language minus comparisons in the AUC of the true "
    "reward and in the mean cross-entropy, with 95% intervals whose unit is the human (a bootstrap over humans and "
    "models: the models share their humans and seeds), and the verdict worded from the intervals over every model. "
    "--interval pooled gives the old t-interval over every pair as if independent, for the record.",
)
def cmd_experiment_verdict(args: argparse.Namespace) -> None:
    from langpref.experiments.verdict import verdict_table

    run_config_experiment(args, "verdict", verdict_table)
