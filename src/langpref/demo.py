"""`langpref demo` / `make demo`: the pipeline at small size on Meta-World, ending with what it made.

Each stage is a library call (the same ones the CLI commands make); the demo only chooses small sizes and prints.
"""

from __future__ import annotations

import json
import time
from pathlib import Path


def _banner(text: str) -> None:
    print(f"\n== {text}", flush=True)


def run_demo(
    out: Path, workers: int | None = None, num_trajectories: int = 100, horizon: int = 500, train_config=None
) -> dict:
    """Generate, inspect, render, train, evaluate, improve and learn rewards at small size under `out`; what it made
    (name -> path or figure), also written with the numbers into `out/summary.json`. `num_trajectories` and
    `horizon` size the generated dataset, `train_config` (a `TrainConfig`; data and out are set here) the training,
    by default the demo's 12 + 6 epochs: a test runs the whole demo smaller still."""
    start = time.time()
    out = Path(out)
    data = out / "data_metaworld"
    made: dict = {}
    ds = _dataset_stages(out, data, made, workers, num_trajectories, horizon)
    model_dir, accuracy = _latent_stage(out, data, ds, made, train_config)
    space, improvement = _improvement_stage(out, data, model_dir, made)
    rewards = _reward_stage(out, space, made)
    (out / "summary.json").write_text(
        json.dumps(
            {
                "made": made,
                "accuracy": accuracy,
                "improvement": {s: r["curve"] for s, r in improvement.items()},
                "reward": {
                    fb: {k: r[k] for k in ("cross_entropy", "true_reward_of_best")} for fb, r in rewards.items()
                },
            },
            indent=2,
        )
    )
    _goodbye(out, made, start)
    return made


def _dataset_stages(out: Path, data: Path, made: dict, workers: int | None, num_trajectories: int, horizon: int):
    """Stages 1-3: generate (or reuse) the dataset, describe it, render a success and a failure; the dataset."""
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.inspect import describe, format_description
    from langpref.dataset.render import render_trajectory
    from langpref.dataset.storage import load_dataset

    _banner(f"1. Generating {num_trajectories} Meta-World button-press trajectories (T = {horizon}) in the simulator")
    if (data / "meta.json").exists():
        print(f"   reusing {data} (delete it to regenerate)")
    else:
        cfg = GenerateConfig(
            env="metaworld", out=data, num_trajectories=num_trajectories, horizon=horizon, workers=workers, force=True
        )
        generate(cfg)
    made["dataset"] = str(data)

    _banner("2. Inspecting the dataset: feature ranges and how independent the features are")
    description = describe(data)
    print(format_description(description))
    (out / "inspect.json").write_text(json.dumps(description, indent=2))
    made["inspect"] = str(out / "inspect.json")

    _banner("3. Rendering one successful and one failed trajectory to video (offscreen, EGL)")
    ds = load_dataset(data)
    for label, idx in (("success", int(ds.success.argmax())), ("failure", int((~ds.success).argmax()))):
        video = render_trajectory(data, idx, out / f"trajectory_{idx}_{label}.mp4", stride=2, fps=20)
        made[f"video_{label}"] = str(video)
        print(f"   {label}: trajectory {idx} -> {video}")
    return ds


def _latent_stage(out: Path, data: Path, ds, made: dict, train_config=None) -> tuple[Path, dict]:
    """Stage 4: train (or reuse) the shared latent space and read unseen phrasings with it; the model's directory
    and its test accuracy."""
    from dataclasses import replace

    from langpref.language.bank import load_bank
    from langpref.language.pairs import phrasings_from_bank
    from langpref.model.checkpoint import load_model
    from langpref.model.config import TrainConfig
    from langpref.model.evaluate import evaluate_split
    from langpref.model.train import train

    _banner("4. Learning the shared latent space: trajectory encoder + pretrained MiniLM, frozen then co-finetuned")
    model_dir = out / "model_metaworld"
    if (model_dir / "config.json").exists():
        print(f"   reusing {model_dir} (delete it to retrain)")
    else:
        cfg = train_config or replace(TrainConfig(), stage1_epochs=12, stage2_epochs=6)
        train(replace(cfg, data=str(data), out=str(model_dir), force=True))
    made["model"] = str(model_dir)
    model = load_model(model_dir, dataset=ds)
    accuracy = evaluate_split(model, ds, "test", phrasings_from_bank(load_bank("metaworld"), "test", ds.feature_names))
    made["test_accuracy"] = f"{accuracy['accuracy']:.3f} on {accuracy['num_samples']} (pair, unseen phrasing) samples"
    print(f"   test accuracy with unseen phrasings: {made['test_accuracy']} (paper, full data: 0.829)")
    for name, acc in accuracy["per_feature"].items():
        print(f"     {name:<20} {acc:.3f}")
    curve = next((p for p in model_dir.glob("*.png")), None)
    if curve:
        made["training_curve"] = str(curve)
    return model_dir, accuracy


def _improvement_stage(out: Path, data: Path, model_dir: Path, made: dict):
    """Stage 5: iterative improvement, Eq. 4 against the feedback-history strategy; the latent space and results."""
    from langpref.feedback.space import load_space
    from langpref.improve import ImproveConfig, improve, plot_improvement

    _banner("5. Iterative improvement with a synthetic human (Eq. 4 vs the feedback-history strategy)")
    space = load_space(data, model_dir, env="metaworld")
    results = {s: improve(space, ImproveConfig(seeds=30, strategy=s)) for s in ("paper", "history")}
    made["improvement_figure"] = str(plot_improvement(results, out / "improvement.png", "Iterative improvement"))
    for s, r in results.items():
        print(f"   {s:<8} normalised true reward: iteration 0 {r['curve'][0]:.2f} -> iteration 15 {r['curve'][-1]:.2f}")
    return space, results


def _reward_stage(out: Path, space, made: dict) -> dict:
    """Stage 6: reward learning from language and from comparisons; each kind's `learn_reward` result."""
    from langpref.feedback.kind import PAPER_KINDS
    from langpref.reward import LearnRewardConfig, learn_reward
    from langpref.reward.figures import plot_reward_curves

    _banner("6. Reward learning: comparative language vs pairwise comparisons (2 humans x 2 seeds, 20 queries)")
    rewards = {
        fb: learn_reward(space, LearnRewardConfig(feedback=fb, queries=20, humans=2, seeds=2)) for fb in PAPER_KINDS
    }
    made["reward_figure"] = str(plot_reward_curves(rewards, out / "reward_learning.png", "Reward learning"))
    for fb, r in rewards.items():
        print(
            f"   {fb:<10} cross-entropy after 20 queries {r['cross_entropy'][-1]:.3f}, "
            f"true reward of the learned best {r['true_reward_of_best'][-1]:.2f}"
        )
    return rewards


def _goodbye(out: Path, made: dict, start: float) -> None:
    """What the demo made, and the commands that go further."""
    _banner(f"Done in {time.time() - start:.0f} s. What the demo made:")
    for key, value in made.items():
        print(f"   {key:<20} {value}")
    print(f"   {'summary':<20} {out / 'summary.json'}")
    print(
        "\nGo further:\n"
        "   langpref generate --env metaworld --out data/metaworld       # the paper's 324 trajectories (~2 min)\n"
        "   langpref train --data data/metaworld --out models/metaworld  # the full two-stage training\n"
        '   langpref embed --model models/metaworld "stay further from the button" --json\n'
        "   langpref experiment reward --env metaworld --model models/metaworld\n"
        "   langpref experiment active --env metaworld --model models/metaworld  # both learners, active queries\n"
        "   make reproduce                                               # every experiment, both envs (hours)\n"
        "   langpref study serve --model models/metaworld --data data/metaworld   # a user study in the browser\n"
        "   langpref import REC --task task.toml --out data/mine         # your own robot: docs/own-robot.md"
    )
