"""`langpref ...`: one thin function per command that parses arguments and calls the library.

Heavy modules (simulators, torch, transformers) are imported inside the command that needs them, so `--help` is
instant. Every `--json` prints exactly one JSON object on stdout; progress bars and messages go to stderr.
A `LangprefError` becomes a one-line `error: ...` on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable

from langpref.errors import LangprefError

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")

ENVS = ("metaworld", "robosuite")


def _emit(obj: Any, as_json: bool, human: Callable[[Any], str] | None = None) -> None:
    if as_json:
        print(json.dumps(obj))
    else:
        print(human(obj) if human else json.dumps(obj, indent=2))


# ---- dataset commands (foundation) -------------------------------------------------------------------------------


def cmd_generate(args: argparse.Namespace) -> None:
    from langpref.dataset.generate import GenerateConfig, generate

    cfg = GenerateConfig(
        env=args.env,
        out=args.out,
        num_trajectories=args.num_trajectories,
        horizon=args.horizon,
        workers=args.workers,
        seed=args.seed,
        force=args.force,
    )
    summary = generate(cfg)
    _emit(summary, args.json, lambda s: f"wrote {s['num_trajectories']} trajectories to {s['out']} "
          f"({s['success_rate']:.0%} succeed, {s['wall_s']:.0f} s)")


def cmd_inspect(args: argparse.Namespace) -> None:
    from langpref.dataset.inspect import describe, format_description

    _emit(describe(args.dir), args.json, format_description)


def cmd_render(args: argparse.Namespace) -> None:
    from langpref.envs.render import render_trajectory

    out = render_trajectory(args.dir, args.index, args.out, width=args.width, height=args.height, fps=args.fps)
    _emit({"video": str(out)}, args.json, lambda o: f"wrote {o['video']}")


def cmd_demo(args: argparse.Namespace) -> None:
    from langpref.demo import run_demo

    run_demo(Path(args.out), workers=args.workers)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="langpref",
        description="Teach robots with comparative language feedback: datasets, a shared latent space of trajectories "
        "and language, trajectory improvement and reward learning.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("generate", help="roll out scripted policies in the simulator and store a trajectory dataset",
                       description="Roll out closed-loop controllers whose parameters are drawn by Latin hypercube "
                       "sampling so that every feature is covered, and store the trajectories with their features.")
    p.add_argument("--env", required=True, choices=ENVS, help="simulated environment")
    p.add_argument("--out", required=True, type=Path, help="dataset directory to create")
    p.add_argument("--num-trajectories", type=int, default=None,
                   help="number of rollouts (default: the paper's, 324 metaworld / 448 robosuite)")
    p.add_argument("--horizon", type=int, default=None, help="steps per rollout (default 500, the paper's T)")
    p.add_argument("--workers", type=int, default=None, help="parallel worker processes (default: all cores)")
    p.add_argument("--seed", type=int, default=0, help="the same seed gives the same dataset, whatever --workers")
    p.add_argument("--force", action="store_true", help="overwrite an existing dataset in --out")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("inspect", help="describe a dataset: sizes, splits, feature ranges and correlations")
    p.add_argument("dir", type=Path, help="dataset directory")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("render", help="render a stored trajectory into a video (.mp4 or .webm)",
                       description="Replays the stored simulator states offscreen (EGL) into a video.")
    p.add_argument("dir", type=Path, help="dataset directory")
    p.add_argument("--index", type=int, required=True, help="trajectory index")
    p.add_argument("--out", type=Path, required=True, help="output video, .mp4 (H.264) or .webm (VP9)")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--fps", type=int, default=40, help="video frame rate (one frame per stored step)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="the whole story at small size on Meta-World, printing what it made")
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="where the demo writes (default demo_out/)")
    p.add_argument("--workers", type=int, default=None)
    p.set_defaults(func=cmd_demo)

    # ---- latent-space commands register below (train, evaluate, embed, utterances, visualize) ----

    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except LangprefError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
