"""`langpref ...`: one thin function per command that parses arguments and calls the library.

A command's options come from its config dataclass (`config(...)`, see `langpref.cli_config`: one flag per field,
the field's docstring as its help); only inputs that are not config fields (paths, `--json`) are declared here. Each
command that writes a directory or file writes its resolved config, command line and langpref version beside it:
`NAME.config.json` inside an output directory (NAME the command) or beside an output file (NAME the file's stem).

Heavy modules (simulators, torch, transformers) are imported inside the command that needs them, and a command's
options are built only when that command runs, so `--help` is instant. Every `--json` prints exactly one JSON
object on stdout; progress bars and messages go to stderr. A `LangprefError` becomes a one-line `error: ...` on
stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path
from typing import Any

from langpref import cli_config as cc
from langpref.cli_config import beside, command, config, emit, from_args, opt, path, record
from langpref.errors import LangprefError

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")

TASK_HELP = "task name: metaworld, robosuite, a plugin's task, or a recorded task (then give its dataset's --data)"
SPLITS = ("train", "val", "test")
BACKENDS = ("local", "ray")
# Command groups: name -> (help, dest, metavar)
GROUPS = {
    "experiment": ("the paper's experiments, one command each", "experiment", "EXPERIMENT"),
    "study": ("the web app for user studies with real people (paper Sec. 5.2)", "study_command", "SUBCOMMAND"),
}


JSON = opt("--json", action="store_true", help="print one JSON object")
DIR = path("dir", help="dataset directory")
MODEL = path("--model", required=True, help="checkpoint directory (`langpref train`)")
DATA = path("--data", required=True, help="dataset directory (`langpref generate`)")
TASK = opt("--env", required=True, metavar="TASK", help=TASK_HELP)


# ---- datasets ----------------------------------------------------------------------------------------------------


@command(
    "generate",
    "roll out scripted policies in the simulator and store a trajectory dataset",
    [
        config(
            "langpref.dataset.generate:GenerateConfig", {"env": {"metavar": "TASK"}, "backend": {"choices": BACKENDS}}
        ),
        JSON,
    ],
    "Roll out closed-loop controllers whose parameters are drawn by Latin hypercube sampling so that every "
    "feature is covered, and store the trajectories with their features.",
)
def cmd_generate(args: argparse.Namespace) -> None:
    from langpref.dataset.generate import GenerateConfig, generate

    cfg = from_args(GenerateConfig, args)
    summary = generate(cfg)
    record(args, Path(summary["out"]) / "generate.config.json", cfg.resolved())
    emit(
        summary,
        args.json,
        lambda s: (
            f"wrote {s['num_trajectories']} trajectories to {s['out']} "
            f"({s['success_rate']:.0%} succeed, {s['wall_s']:.0f} s)"
        ),
    )


@command(
    "import",
    "a robot recording (plain folder of episodes or LeRobotDataset) into a dataset",
    [
        config(
            "langpref.dataset.importer:ImportConfig",
            {"src": {"positional": True}, "splits": {"metavar": "TRAIN,VAL,TEST"}},
        ),
        JSON,
    ],
    "Read a recording of your own robot into a langpref dataset of the task described by a task file (TOML: "
    "name, description, features, features_from, utterances). A plain folder holds NAME.npz episodes "
    "(observations (T, obs_dim), actions (T, A), optional features and success) with an optional "
    "NAME.mp4/.webm video each; a LeRobotDataset (v3) is read with pyarrow and PyAV. Episodes may differ in "
    "length. See README, 'Your own robot'.",
)
def cmd_import(args: argparse.Namespace) -> None:
    from langpref.dataset.importer import ImportConfig, import_recording
    from langpref.language.bank import check_bank, split_bank
    from langpref.tasks.taskfile import read_task_file

    task = read_task_file(args.task)
    bank = split_bank(task.utterances, task.features, seed=args.seed)
    check_bank(bank, task.name, task.features, f"utterances file {task.utterances}")
    cfg = from_args(ImportConfig, args)
    if len(cfg.splits) != 3 or min(cfg.splits) <= 0:
        raise LangprefError(
            f"--splits {','.join(map(str, cfg.splits))} must be three positive shares TRAIN,VAL,TEST, e.g. 0.8,0.1,0.1"
        )
    summary = import_recording(cfg, task, bank)
    record(args, Path(summary["out"]) / "import.config.json", cfg)
    emit(
        summary,
        args.json,
        lambda s: (
            f"imported {s['num_trajectories']} episodes of task {s['task']} into "
            f"{s['out']} (splits {s['splits']}, videos: {'yes' if s['videos'] else 'no'}, {s['wall_s']:.1f} s)"
        ),
    )


@command(
    "tasks",
    "list the tasks langpref knows: built-in, plugins, and a dataset's own",
    [path("--data", default=None, help="also the task of this dataset"), JSON],
    "Built-in tasks, tasks of installed plugins (entry-point group langpref.tasks), and with --data the "
    "recorded task a dataset carries.",
)
def cmd_tasks(args: argparse.Namespace) -> None:
    from langpref.tasks import get_task, task_names

    if args.data:
        from langpref.dataset.storage import load_dataset

        load_dataset(args.data)
    out = {}
    for name in task_names():
        task = get_task(name)
        out[name] = {
            "source": task.source,
            "simulator": task.simulator is not None,
            "features": dict(zip(task.features, task.feature_descriptions)),
            "description": task.description,
            "obs_dim": task.obs_dim,
            "action_dim": task.action_dim,
        }
    emit(
        out,
        args.json,
        lambda o: "\n".join(
            f"{n:<16} {'simulated' if d['simulator'] else 'recorded '} {d['source']:<9} features: "
            f"{', '.join(d['features'])}"
            for n, d in o.items()
        ),
    )


@command("inspect", "describe a dataset: sizes, splits, feature ranges and correlations", [DIR, JSON])
def cmd_inspect(args: argparse.Namespace) -> None:
    from langpref.dataset.inspect import describe, format_description

    emit(describe(args.dir), args.json, format_description)


@command(
    "render",
    "render a stored trajectory into a video (.mp4 or .webm)",
    [
        DIR,
        opt("--index", type=int, required=True, help="trajectory index"),
        path("--out", required=True, help="output video, .mp4 (H.264) or .webm (VP9)"),
        opt("--width", type=int, default=320, help="pixels (default %(default)s)"),
        opt("--height", type=int, default=240, help="pixels (default %(default)s)"),
        opt("--fps", type=int, default=40, help="frame rate, one frame per stored step (default %(default)s)"),
        JSON,
    ],
    "Replays the stored simulator states offscreen (EGL) into a video.",
)
def cmd_render(args: argparse.Namespace) -> None:
    from langpref.dataset.render import render_trajectory

    out = render_trajectory(args.dir, args.index, args.out, width=args.width, height=args.height, fps=args.fps)
    record(args, beside(out))
    emit({"video": str(out)}, args.json, lambda o: f"wrote {o['video']}")


@command(
    "demo",
    "the whole story at small size on Meta-World, printing what it made",
    [
        path("--out", default=Path("demo_out"), help="where the demo writes (default demo_out/)"),
        opt("--workers", type=int, default=None, help="parallel worker processes (default: all cores)"),
    ],
)
def cmd_demo(args: argparse.Namespace) -> None:
    from langpref.demo import run_demo

    run_demo(Path(args.out), workers=args.workers)
    record(args, Path(args.out) / "demo.config.json")


# ---- the latent space (train, evaluate, embed, visualize, utterances, experiment alignment) ------------------------


@command(
    "train",
    "learn the shared latent space of trajectories and language",
    [
        config(
            "langpref.model.config:TrainConfig",
            {
                "model.lang_model": {"metavar": "NAME_OR_PATH"},
                "device": {"choices": ("auto", "cpu", "cuda")},
                "stage1_epochs": "--epochs",
                "stage1_batch_size": "--batch-size",
                "stage1_lr": "--lr",
                "stage1_head_lr": "--head-lr",
                "stage2_epochs": "--finetune-epochs",
                "stage2_batch_size": "--finetune-batch-size",
                "stage2_phrasings_per_step": "--phrasings-per-step",
                "stage2_lr": "--finetune-lr",
                "stage2_lm_lr": "--lm-lr",
                "model.traj_hidden": {"metavar": "H1,H2,..."},
            },
        ),
        JSON,
    ],
    "Stage 1 trains the trajectory encoder and a language head with the language model frozen; stage 2 "
    "co-finetunes the transformer (paper Sec. 4.1). Keeps the epoch with the best validation accuracy, stops "
    "early, writes a checkpoint directory with a training curve.",
)
def cmd_train(args: argparse.Namespace) -> None:
    from langpref.model.config import TrainConfig
    from langpref.model.train import train

    cfg = from_args(TrainConfig, args)
    result = train(cfg, progress=True)
    record(args, Path(result.out) / "train.config.json", cfg.to_dict())
    r = result.results
    summary = {
        "out": str(result.out),
        "best_val_accuracy": r["best_val_accuracy"],
        "stages": r["stages"],
        "epochs": len(result.history),
        "wall_s": r["wall_s"],
        "samples_per_s": r["samples_per_s"],
        "train_pairs": r["train_pairs"],
        "device": r["device"],
    }
    emit(
        summary,
        args.json,
        lambda s: (
            f"wrote {s['out']}: validation accuracy {s['best_val_accuracy']:.3f} after "
            f"{s['stages']} stage(s), {s['epochs']} epochs, {s['wall_s']:.0f} s"
        ),
    )


def _load(args: argparse.Namespace, with_data: bool = True):
    from langpref.dataset.storage import load_dataset
    from langpref.model.checkpoint import load_model
    from langpref.model.train import resolve_device

    dataset = load_dataset(args.data) if with_data else None
    return load_model(args.model, device=resolve_device(getattr(args, "device", "cpu")), dataset=dataset), dataset


@command(
    "evaluate",
    "alignment accuracy of a model on a split (paper Sec. 5.1)",
    [
        MODEL,
        DATA,
        opt("--split", default="test", choices=SPLITS, help="default %(default)s"),
        opt(
            "--phrasing-split",
            default=None,
            choices=SPLITS,
            help="bank split of the phrasings (default: --split); "
            "`train` on test trajectories separates reading the trajectories from reading unseen words",
        ),
        path(
            "--utterances",
            default=None,
            help="utterance file (DESIGN.md schema) instead of the bank's phrasings of --split",
        ),
        opt("--device", choices=("auto", "cpu", "cuda"), default="cpu", help="default %(default)s"),
        JSON,
    ],
    "Over every ordered pair of the split's trajectories, every feature that differs (beyond the model's tie "
    "threshold) and every phrasing of it in the direction taking A to B: the share with psi_l . (phi_B - "
    "phi_A) > 0.",
)
def cmd_evaluate(args: argparse.Namespace) -> None:
    from langpref.language.pairs import phrasings_from_bank, phrasings_from_mapping
    from langpref.model.evaluate import evaluate_split

    model, dataset = _load(args)
    if args.utterances:
        from langpref.language.bank import load_user_utterances

        mapping = load_user_utterances(args.utterances, dataset.env)
        phrasings = phrasings_from_mapping(
            mapping, dataset.feature_names, require_all=False, source=str(args.utterances)
        )
    else:
        from langpref.language.bank import load_bank

        phrasing_split = args.phrasing_split or args.split
        phrasings = phrasings_from_bank(load_bank(dataset.env), phrasing_split, dataset.feature_names)
    out = evaluate_split(model, dataset, args.split, phrasings)
    out["utterances"] = str(args.utterances) if args.utterances else f"bank:{phrasing_split}"
    emit(
        out,
        args.json,
        lambda o: (
            f"accuracy {o['accuracy']:.3f} on {o['num_samples']} samples ({o['split']}, "
            f"{o['utterances']}); "
            + ", ".join(f"{f} {a:.3f}" for f, a in o["per_feature"].items())
            + (
                f"\nread as their own meaning by `langpref embed`: {o['reading_accuracy']:.3f} of "
                f"{o['num_phrasings']} phrasings"
                + "".join(f"\n  misread: {m['text']!r} ({m['meaning']}) as {m['read_as']}" for m in o["misread"])
                if "reading_accuracy" in o
                else ""
            )
        ),
    )


@command(
    "embed",
    "which feature and direction the model reads into a sentence",
    [
        MODEL,
        opt("text", help='free-form feedback, e.g. "you\'re way too slow"'),
        JSON,
        lambda p: setattr(
            p,
            "description",
            p.description.replace(
                "the gate's floor", str(importlib.import_module("langpref.language.relevance").RELEVANCE_FLOOR)
            ),
        ),
    ],
    "Nearest bank meaning by cosine: the mean psi of each feature/direction's training phrasings; confidence is "
    "a softmax over the cosines at temperature 0.1. A sentence that does not read as feedback on the robot's "
    "motion (relevance: its highest cosine to a bank phrasing in the pretrained MiniLM space, below the gate's "
    "floor) is refused with an error.",
)
def cmd_embed(args: argparse.Namespace) -> None:
    from langpref.language.relevance import FeedbackGate
    from langpref.model.evaluate import embed_text

    model, _ = _load(args, with_data=False)
    out = embed_text(model, args.text)  # an empty text fails here, before the gate is built
    out["relevance"] = round(FeedbackGate(model.info.env).check(args.text).score, 4)
    emit(
        out,
        args.json,
        lambda o: f"{o['feature']}/{o['direction']} (confidence {o['confidence']:.2f}, cosine {o['cosine']:.2f})",
    )


@command(
    "visualize",
    "draw the latent space: phi by PCA per feature, language directions as arrows",
    [
        MODEL,
        DATA,
        path("--out", required=True, help="image to write (.png, .pdf, .svg)"),
        opt("--split", default=None, choices=SPLITS, help="default: every trajectory"),
        JSON,
    ],
)
def cmd_visualize(args: argparse.Namespace) -> None:
    from langpref.model.visualize import visualize

    model, dataset = _load(args)
    out = visualize(model, dataset, args.out, split=args.split)
    record(args, beside(args.out))
    emit(out, args.json, lambda o: f"wrote {o['out']} ({o['num_trajectories']} trajectories)")


@command("utterances", "print the shipped utterance bank of an env (all splits merged)", [TASK, JSON])
def cmd_utterances(args: argparse.Namespace) -> None:
    from langpref.language.bank import load_bank

    emit(load_bank(args.env).merged(), args.json)


@command(
    "experiment alignment",
    "Appendix C: test accuracy, co-finetuned vs frozen language model",
    [
        TASK,
        path("--data", default=None, help="dataset directory (default data/ENV)"),
        path("--out", default=None, help="output directory (default results/alignment/ENV)"),
        opt("--force", action="store_true", help="overwrite models already in --out"),
        JSON,
    ],
    "Trains once (the frozen model is stage 1 of the co-finetuned one), evaluates both on the test split with "
    "the bank's test phrasings, writes alignment.md/.json.",
)
def cmd_experiment_alignment(args: argparse.Namespace) -> None:
    from langpref.experiments.alignment import alignment_table, default_out, run_alignment_experiment

    args.data, args.out = args.data or Path("data") / args.env, args.out or default_out(args.env)
    summary = run_alignment_experiment(args.env, args.data, args.out, force=args.force)
    record(args, Path(args.out) / "alignment.config.json")
    emit(summary, args.json, lambda s: alignment_table([s]) + f"\n(wrote {args.out}/alignment.md and alignment.json)")


# ---- uses of the latent space (improve, learn-reward, experiment improve|reward|ablation|prior) --------------------


def _use_opts(experiment: bool = False) -> dict[str, Any]:
    """The flags of the fields of the synthetic human, the reward model and the splits, where they differ from the
    derived ones."""
    from langpref.feedback import KINDS
    from langpref.feedback.humans import DIRECTION_RULES, FEATURE_SCALES, HumanConfig
    from langpref.feedback.space import PHRASING_SPLITS
    from langpref.improve import OBJECTIVES, STRATEGIES
    from langpref.reward import DEFAULT_WEIGHT_DECAY, LOSSES, MODELS, NEGATIVES

    docs, out = cc.field_docs(HumanConfig), (lambda s: f" Results go to ENV-{s} unless --out." if experiment else "")
    return {
        "human.phrasing_split": {"choices": PHRASING_SPLITS, "help": docs["phrasing_split"] + out("bank-SPLIT")},
        "human.phrasings": {"metavar": "FILE", "help": docs["phrasings"] + out("phrasings")},
        "human.feature_scale": {"choices": FEATURE_SCALES, "help": docs["feature_scale"] + out("paper-scale")},
        "human.direction": {"choices": DIRECTION_RULES, "help": docs["direction"] + out("toward-best")},
        "reward.model": {"flag": "--reward-model", "choices": MODELS},
        "reward.hidden": "--reward-hidden",
        "reward.loss": {"choices": LOSSES},
        "reward.negatives": {"choices": NEGATIVES},
        "reward.negative_split": None,
        "reward.weight_decay": {
            "help": "L2 prior on r_xi's parameters, against the weighted mean loss over feedback "
            "pairs (default "
            + ", ".join(f"{v:g} for {k}" for k, v in DEFAULT_WEIGHT_DECAY.items())
            + "; `langpref experiment prior` shows how the linear one was chosen)"
        },
        "candidate_split": {"flag": "--candidates", "choices": (*SPLITS, "generated")},
        "base_split": {"choices": SPLITS},
        "generated_out": {"metavar": "DIR"},
        "query_split": {"choices": SPLITS},
        "eval_split": {"choices": SPLITS},
        "strategy": {"choices": STRATEGIES},
        "objective": {"choices": OBJECTIVES},
        "feedback": {"required": True, "choices": sorted(KINDS, key=lambda k: k != "language")},
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


def _space(args: argparse.Namespace):
    from langpref.feedback.space import load_space

    return load_space(
        args.data,
        args.model,
        perfect=args.perfect_latent,
        phrasings=getattr(args, "human.phrasings"),
        feature_scale=getattr(args, "human.feature_scale", "standardised"),
    )


PROPOSE = config("langpref.propose:ProposeConfig", prefix="propose.")


def _generation(args: argparse.Namespace, space):
    """The simulator search of `langpref.propose` over the dataset's controllers, with the search flags."""
    from langpref.propose import ProposeConfig, open_generation

    return open_generation(
        args.data, None if args.perfect_latent else args.model, space, from_args(ProposeConfig, args, "propose.")
    )


@command(
    "improve",
    "iterative trajectory improvement with a synthetic language human (Eq. 4)",
    [
        *_space_options(),
        config("langpref.improve:ImproveConfig", lambda: {**_use_opts(), "human.rationality": None}),
        PROPOSE,
        path("--figure", default=None, help="also draw the curve into this PNG"),
        JSON,
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
    space = _space(args)
    result = improve(space, cfg, generation=_generation(args, space) if cfg.generated else None)
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


@command(
    "learn-reward",
    "reward learning from synthetic language feedback or comparisons",
    [
        *_space_options(),
        config("langpref.reward:LearnRewardConfig", _use_opts),
        opt(
            "--optimize",
            action="store_true",
            help="after the last query, generate r_xi's optimum in the simulator "
            "(`langpref.propose`); adds optimized_true_reward, one per human x seed run (above 1: better than the "
            "eval split's best)",
        ),
        PROPOSE,
        path(
            "--save-reward",
            default=None,
            metavar="DIR",
            help="write each run's r_xi into DIR (reward.json is "
            "the first run's) for the Gymnasium wrapper langpref.rewards.LearnedReward",
        ),
        path("--figure", default=None, help="also draw the curves into this PNG"),
        JSON,
    ],
    "Each query shows one train trajectory (language: the human says how to improve it; L_Explicit + "
    "L_Implicit, Eq. 5-9) or a random train pair (comparison: Bradley-Terry). After every query, r_xi is refit "
    "on all feedback so far and scored on the test split.",
)
def cmd_learn_reward(args: argparse.Namespace) -> None:
    from langpref.reward import LearnRewardConfig, learn_reward

    cfg = from_args(LearnRewardConfig, args)
    cfg.validate()
    space = _space(args)
    result = learn_reward(
        space,
        cfg,
        generation=_generation(args, space) if args.optimize else None,
        save_reward=args.save_reward,
        model=None if args.perfect_latent else args.model,
    )
    if args.figure:
        from langpref.experiments.reward import plot_reward_curves

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
            + (f"; figure {r['figure']}" if "figure" in r else "")
            + (
                f"\ngenerated r_xi optimum: mean normalised true reward {r['optimized_true_reward_mean']:.2f}, "
                f"above the split's best in {r['optimized_beats_best_of_split']:.0%} of runs"
                if "optimized_true_reward" in r
                else ""
            )
        ),
    )


def cmd_experiment_uses(args: argparse.Namespace) -> None:
    from langpref.experiments.common import SweepConfig

    kw = {
        "env": args.env,
        "data": args.data,
        "model": args.model,
        "out": args.out,
        "perfect": args.perfect_latent,
        "force": args.force,
        "sweep": from_args(SweepConfig, args),
    }
    module = "improve" if EXPERIMENTS[args.experiment][1] == "ImproveConfig" else "reward"
    cfg = from_args(getattr(importlib.import_module(f"langpref.{module}"), EXPERIMENTS[args.experiment][1]), args)
    runner = {"improve": "improve", "active": "active", "generate": "generate"}.get(args.experiment, "reward")
    run = getattr(importlib.import_module(f"langpref.experiments.{runner}"), f"run_{args.experiment}_experiment")
    summary = run(**kw, config=cfg)
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


PHRASING = ("human.phrasing_split", "human.phrasings", "human.feature_scale", "human.direction")
REWARD_FLAGS = ("seeds", "humans", "queries", "reward.model", *PHRASING)
EXPERIMENTS = {  # name: what it is, its config (in langpref.improve or langpref.reward), the fields given a flag
    "improve": (
        "Fig. 4: iterative improvement, Eq. 4 (cosine and as printed) and the history strategy, 100 seeds",
        "ImproveConfig",
        ("iterations", "seeds", *PHRASING),
    ),
    "reward": (
        "Fig. 5: reward learning, language vs comparisons, 3 humans x 3 seeds, Q = 40",
        "LearnRewardConfig",
        REWARD_FLAGS,
    ),
    "ablation": ("Fig. 6: language reward loss, explicit + implicit vs each alone", "LearnRewardConfig", REWARD_FLAGS),
    "prior": (
        "the L2 prior's strength per reward-learning method, chosen on the val split",
        "LearnRewardConfig",
        REWARD_FLAGS,
    ),
    "active": (
        "active queries: language x {random, lal-infogain, infogain} and comparisons x {random, infogain, "
        "volume-removal}, 10 humans x 3 seeds, Q = 40",
        "LearnRewardConfig",
        (*REWARD_FLAGS, "candidates", "posterior_samples"),
    ),
    "generate": (
        "issue 18: improvement from dataset vs generated candidates, and r_xi's generated optimum vs the "
        "best test trajectory (10 humans x 3 seeds, Q = 40)",
        "ImproveConfig",
        ("iterations", "seeds"),
    ),
}
ACTIVE_OPTS = {"humans": {"default": 10, "help": "synthetic humans (reward weights w), drawn from --seed (default 10)"}}
for _name, (_text, _cls, _only) in EXPERIMENTS.items():
    command(
        f"experiment {_name}",
        _text,
        [
            TASK,
            *_space_options(experiment=True),
            path(
                "--out",
                default=None,
                help=f"output directory (default results/{_name}/ENV, or ENV-perfect"
                + (")" if _name == "improve" else ", ENV-mlp)"),
            ),
            config(
                f"langpref.{'improve' if _cls == 'ImproveConfig' else 'reward'}:{_cls}",
                lambda n=_name: {**_use_opts(True), **(ACTIVE_OPTS if n == "active" else {})},
                only=_only,
            ),
            opt("--force", action="store_true", help="discard finished runs in --out and start over"),
            config("langpref.experiments.common:SweepConfig", {"backend": {"choices": BACKENDS}}),
            JSON,
        ],
        _text + ". Writes NAME.json, NAME.png and NAME.md (a section for docs/results.md); an interrupted run "
        "resumes without redoing finished seeds.",
    )(cmd_experiment_uses)


# ---- study (the web app for user studies) ---------------------------------------------------------------------


@command(
    "study serve",
    "serve a study in the browser (Study 1: improvement, Study 2: language vs comparisons)",
    [
        config(
            "langpref.study.config:ServeConfig",
            {"study": None, "video": None, "on_show": {"metavar": "CMD"}, "on_show_timeout": {"metavar": "SECONDS"}},
        ),
        config(
            "langpref.study.config:StudyConfig",
            {"study.split": {"choices": (*SPLITS, "all")}},
            prefix="study.",
            unset=True,
        ),
        config(
            "langpref.study.config:VideoConfig",
            lambda: {"video.format": {"choices": importlib.import_module("langpref.study.config").VIDEO_FORMATS}},
            prefix="video.",
            flag_prefix="video-",
        ),
    ],
    "Prints the participant URL and an admin token. State lives in the SQLite --db: a restart on the same --db "
    "continues every participant where they were. Protocol options are fixed when the database is created.",
)
def cmd_study_serve(args: argparse.Namespace) -> None:
    from langpref.extras import needs
    from langpref.study.config import ServeConfig

    with needs("study", "langpref study serve"):
        from langpref.study.serve import resolve_study_config, serve
    serve(from_args(ServeConfig, args, study=resolve_study_config(args.db, cc.args_of(args, "study."))))


@command(
    "study export",
    "CSV tables, analyses and figures of a study (HTML report + JSON)",
    [config("langpref.study.config:ExportConfig"), JSON],
    "Writes the tables, summary.json, the figures and report.html into --out.",
)
def cmd_study_export(args: argparse.Namespace) -> None:
    from langpref.study.config import ExportConfig
    from langpref.study.export import export

    cfg = from_args(ExportConfig, args)
    out = export(cfg.db, cfg.out, exclude=cfg.exclude)
    record(args, Path(cfg.out) / "export.config.json", cfg)
    emit(
        out,
        args.json,
        lambda o: (
            f"wrote {o['report']} ({o['participants']} participants, {o['finished']} "
            f"finished), {len(o['tables'])} tables and {len(o['figures'])} figures in {o['out']}"
        ),
    )


# ---- the parser ---------------------------------------------------------------------------------------------------


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """Every command with its help; a command's options only when `argv` names it (all of them without `argv`)."""
    from langpref import __version__

    parser = cc.make_parser(
        "langpref",
        "Teach robots with comparative language feedback: datasets, a shared latent "
        "space of trajectories and language, trajectory improvement and reward learning. A command "
        "that writes a directory or a file writes its resolved config beside it: "
        "DIR/COMMAND.config.json, STEM.config.json.",
        GROUPS,
        argv,
    )
    parser.add_argument("--version", action="version", version=f"langpref {__version__}")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(argv).parse_args(argv)
    args.argv = argv
    try:
        args.func(args)
    except LangprefError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `langpref ... --json | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
