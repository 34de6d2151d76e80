"""`langpref generate | import | tasks | inspect | render | demo`: making and looking at datasets."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from langpref.cli.common import DIR, JSON, figure, with_figure
from langpref.cli.outputs import check_writable, status
from langpref.cli_config import RERUN, beside, command, config, emit, from_args, opt, path, record
from langpref.errors import LangprefError
from langpref.extras import require


@command(
    "generate",
    "roll out scripted policies in the simulator and store a trajectory dataset",
    [
        config(
            "langpref.dataset.generate:GenerateConfig",
            {"env": {"metavar": "TASK"}, "frames.frame_size": {"metavar": "WIDTH,HEIGHT"}},
        ),
        JSON,
        RERUN,
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
            {
                "src": {"positional": True},
                "splits": {"metavar": "TRAIN,VAL,TEST"},
                "frames.frame_size": {"metavar": "WIDTH,HEIGHT"},
            },
            common=("src", "task", "out", "force", "frames.images"),
        ),
        JSON,
        RERUN,
    ],
    "Read a recording of your own robot into a langpref dataset of the task described by a task file (TOML: "
    "name, description, features, features_from, utterances). A plain folder holds NAME.npz episodes "
    "(observations (T, obs_dim), actions (T, A), optional features and success) with an optional "
    "NAME.mp4/.webm video each; a LeRobotDataset (v3) is read with pyarrow and PyAV. Episodes may differ in "
    "length. See docs/own-robot.md.",
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
    check_writable(cfg.out, "--out", folder=True)
    summary = import_recording(cfg, task, bank)
    record(args, Path(summary["out"]) / "import.config.json", cfg)
    for warning in summary["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    if cfg.bank_check:
        summary["bank_check"] = _bank_check(Path(summary["out"]))
    emit(
        summary,
        args.json,
        lambda s: (
            f"imported {s['num_trajectories']} episodes of task {s['task']} into "
            f"{s['out']} (splits {s['splits']}, videos: {'yes' if s['videos'] else 'no'}, {s['wall_s']:.1f} s)"
        ),
    )


@command(
    "label",
    "a copy of a LeRobotDataset (v3) or plain recording with per-frame columns of a learned reward",
    [
        config("langpref.dataset.label:LabelConfig", {"dataset": {"positional": True}}),
        figure("each episode's learned reward so far (v_t) along its frames, the best and worst highlighted"),
        JSON,
        RERUN,
    ],
    "Write a copy of DATASET with three float32 columns per frame from the saved reward (`learn-reward "
    "--save-reward`): langpref.reward_share (the frame's share; an episode's frames sum to its learned reward), "
    "langpref.reward_progress (the learned reward of the episode so far) and langpref.episode_reward (the "
    "episode's learned reward). Original columns keep their bytes, videos are hard-linked, and a LeRobotDataset's "
    "meta/info.json, meta/stats.json and per-episode statistics list the new columns. See docs/policy.md, 'Labelling a "
    "dataset with the learned reward'.",
)
def cmd_label(args: argparse.Namespace) -> None:
    from langpref.dataset.label import LabelConfig, label_dataset

    cfg = from_args(LabelConfig, args)
    if args.figure:
        require("plots", "label --figure")  # before the episodes are labelled, not after
    check_writable(cfg.out, "--out", folder=True)
    check_writable(args.figure, "--figure")
    status(f"loading torch and the reward {cfg.reward} with its model")
    from langpref.reward import load

    summary = label_dataset(cfg, load(cfg.reward), figure=args.figure)
    record(args, Path(summary["out"]) / "label.config.json", cfg)
    emit(
        summary,
        args.json,
        with_figure(
            lambda s: (
                f"labelled {s['episodes']} episodes ({s['frames']} frames) of a {s['format']} dataset into {s['out']} "
                f"({s['seconds']:.1f} s); columns: {', '.join(s['columns'])}"
            )
        ),
    )


def _bank_check(dataset: Path) -> dict:
    """`langpref bank check DATASET` with the language model `train` starts from (`bank_reader_for`): its one-line
    summary, what chance and good are, a warning per meaning weak for a reason training does not fix (read as another
    feature) and a note on those read as their own opposite direction (expected before training), on stderr; overall
    accuracy and weak meanings for the --json summary."""
    from langpref.cli.bank import before_training_note, chance_line, opposite_only
    from langpref.cli.outputs import status
    from langpref.language.banksource import open_bank
    from langpref.language.lab_default import bank_reader_for
    from langpref.language.models import canonical_name

    source = open_bank(dataset)
    name = canonical_name(bank_reader_for(source.task))
    status(f"checking the bank with {name}, which training starts from (10-30 s; --no-bank-check skips it)")
    from langpref.language.check import leave_one_out
    from langpref.language.loading import sentence_embedder

    result = leave_one_out(
        source.split("train"), source.features, sentence_embedder(name), task=source.task, encoder=f"pretrained {name}"
    )
    print(result.summary(), file=sys.stderr)
    print(chance_line(result), file=sys.stderr)
    flipped = opposite_only(result)
    for name in result.weak:
        if name not in flipped:
            print(f"warning: weak meaning {name}: {result.meanings[name].advice}", file=sys.stderr)
    note = before_training_note(result, dataset)
    if note:
        print(f"note: {note}", file=sys.stderr)
    elif result.weak:
        print(
            "note: this reads the bank with the pretrained language model alone; training on the bank teaches it "
            f"more. After `langpref train`, check again with `langpref bank check {dataset} --model MODEL`",
            file=sys.stderr,
        )
    return {"accuracy": result.accuracy, "weak": result.weak, "weak_opposite_direction": flipped}


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


@command(
    "inspect",
    "describe a dataset: sizes, splits, feature ranges, correlations and checksum",
    [DIR, figure("each feature's spread (histograms) and the feature correlation heatmap"), JSON],
)
def cmd_inspect(args: argparse.Namespace) -> None:
    from langpref.dataset.inspect import describe, format_description, plot_dataset

    if args.figure:
        require("plots", "inspect --figure")
    check_writable(args.figure, "--figure")
    out = describe(args.dir)
    if args.figure:
        out["figure"] = str(plot_dataset(args.dir, args.figure))
    emit(out, args.json, with_figure(format_description))


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
        RERUN,
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
        RERUN,
    ],
)
def cmd_demo(args: argparse.Namespace) -> None:
    from langpref.demo import run_demo

    run_demo(Path(args.out), workers=args.workers)
    record(args, Path(args.out) / "demo.config.json")
