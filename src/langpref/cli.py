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

TASK_HELP = "task name: metaworld, robosuite, a plugin's task, or a recorded task (then give its dataset's --data)"


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
        backend=args.backend,
        ray_address=args.ray_address,
    )
    summary = generate(cfg)
    _emit(summary, args.json, lambda s: f"wrote {s['num_trajectories']} trajectories to {s['out']} "
          f"({s['success_rate']:.0%} succeed, {s['wall_s']:.0f} s)")


def cmd_inspect(args: argparse.Namespace) -> None:
    from langpref.dataset.inspect import describe, format_description

    _emit(describe(args.dir), args.json, format_description)


def cmd_import(args: argparse.Namespace) -> None:
    from langpref.dataset.importer import ImportConfig, import_recording
    from langpref.language.bank import check_bank, split_bank
    from langpref.tasks.taskfile import read_task_file

    task = read_task_file(args.task)
    bank = split_bank(task.utterances, task.features, seed=args.seed)
    check_bank(bank, task.name, task.features, f"utterances file {task.utterances}")
    shares = tuple(float(x) for x in args.splits.split(",")) if args.splits else None
    if shares is not None and (len(shares) != 3 or min(shares) <= 0):
        raise LangprefError(f"--splits {args.splits!r} must be three positive shares TRAIN,VAL,TEST, e.g. 0.8,0.1,0.1")
    cfg = ImportConfig(src=args.src, task=args.task, out=args.out, seed=args.seed, force=args.force,
                       state_key=args.state_key, action_key=args.action_key, camera=args.camera,
                       **({"splits": shares} if shares else {}))
    summary = import_recording(cfg, task, bank)
    _emit(summary, args.json, lambda s: f"imported {s['num_trajectories']} episodes of task {s['task']} into "
          f"{s['out']} (splits {s['splits']}, videos: {'yes' if s['videos'] else 'no'}, {s['wall_s']:.1f} s)")


def cmd_tasks(args: argparse.Namespace) -> None:
    from langpref.tasks import get_task, task_names

    if args.data:
        from langpref.dataset.storage import load_dataset

        load_dataset(args.data)
    out = {}
    for name in task_names():
        task = get_task(name)
        out[name] = {"source": task.source, "simulator": task.simulator is not None,
                     "features": dict(zip(task.features, task.feature_descriptions)), "description": task.description,
                     "obs_dim": task.obs_dim, "action_dim": task.action_dim}
    _emit(out, args.json, lambda o: "\n".join(
        f"{n:<16} {'simulated' if d['simulator'] else 'recorded '} {d['source']:<9} features: "
        f"{', '.join(d['features'])}" for n, d in o.items()))


def cmd_render(args: argparse.Namespace) -> None:
    from langpref.dataset.render import render_trajectory

    out = render_trajectory(args.dir, args.index, args.out, width=args.width, height=args.height, fps=args.fps)
    _emit({"video": str(out)}, args.json, lambda o: f"wrote {o['video']}")


def cmd_demo(args: argparse.Namespace) -> None:
    from langpref.demo import run_demo

    run_demo(Path(args.out), workers=args.workers)


# ---- latent-space commands (train, evaluate, embed, visualize, utterances, experiment alignment) ------------------


def _train_config(args: argparse.Namespace):
    from langpref.model.config import ModelConfig, TrainConfig

    d = TrainConfig()
    model = ModelConfig(lang_model=args.lang_model, latent_dim=args.latent_dim, max_length=args.max_length,
                        observation_deltas=args.observation_deltas)
    return TrainConfig(
        data=str(args.data), out=str(args.out), model=model, extend_bank=args.extend_bank,
        utterances=str(args.utterances) if args.utterances else None,
        freeze_language=args.freeze_language, seed=args.seed, device=args.device, force=args.force,
        mixed_precision=args.mixed_precision,
        stage1_epochs=d.stage1_epochs if args.epochs is None else args.epochs,
        stage1_batch_size=d.stage1_batch_size if args.batch_size is None else args.batch_size,
        stage2_epochs=d.stage2_epochs if args.finetune_epochs is None else args.finetune_epochs,
        stage2_batch_size=d.stage2_batch_size if args.finetune_batch_size is None else args.finetune_batch_size,
        stage2_phrasings_per_step=args.phrasings_per_step, stage1_lr=args.lr, stage2_lm_lr=args.lm_lr,
        patience=args.patience, norm_a=args.norm_a, norm_b=args.norm_b, tie_fraction=args.tie_fraction,
        time_samples=args.time_samples, stage1_head_lr=args.head_lr,
    )


def cmd_train(args: argparse.Namespace) -> None:
    from langpref.model.train import train

    result = train(_train_config(args), progress=True)
    r = result.results
    summary = {"out": str(result.out), "best_val_accuracy": r["best_val_accuracy"], "stages": r["stages"],
               "epochs": len(result.history), "wall_s": r["wall_s"], "samples_per_s": r["samples_per_s"],
               "train_pairs": r["train_pairs"], "device": r["device"]}
    _emit(summary, args.json, lambda s: f"wrote {s['out']}: validation accuracy {s['best_val_accuracy']:.3f} after "
          f"{s['stages']} stage(s), {s['epochs']} epochs, {s['wall_s']:.0f} s")


def _load(args: argparse.Namespace, with_data: bool = True):
    from langpref.dataset.storage import load_dataset
    from langpref.model.checkpoint import load_model
    from langpref.model.train import resolve_device

    dataset = load_dataset(args.data) if with_data else None
    return load_model(args.model, device=resolve_device(getattr(args, "device", "cpu")), dataset=dataset), dataset


def cmd_evaluate(args: argparse.Namespace) -> None:
    from langpref.language.pairs import phrasings_from_bank, phrasings_from_mapping
    from langpref.model.evaluate import evaluate_split

    model, dataset = _load(args)
    if args.utterances:
        from langpref.language.bank import load_user_utterances

        mapping = load_user_utterances(args.utterances, dataset.env)
        phrasings = phrasings_from_mapping(mapping, dataset.feature_names, require_all=False,
                                           source=str(args.utterances))
    else:
        from langpref.language.bank import load_bank

        phrasing_split = args.phrasing_split or args.split
        phrasings = phrasings_from_bank(load_bank(dataset.env), phrasing_split, dataset.feature_names)
    out = evaluate_split(model, dataset, args.split, phrasings)
    out["utterances"] = str(args.utterances) if args.utterances else f"bank:{phrasing_split}"
    _emit(out, args.json, lambda o: f"accuracy {o['accuracy']:.3f} on {o['num_samples']} samples ({o['split']}, "
          f"{o['utterances']}); " + ", ".join(f"{f} {a:.3f}" for f, a in o["per_feature"].items())
          + (f"\nread as their own meaning by `langpref embed`: {o['reading_accuracy']:.3f} of "
             f"{o['num_phrasings']} phrasings" + "".join(f"\n  misread: {m['text']!r} ({m['meaning']}) as "
                                                        f"{m['read_as']}" for m in o["misread"])
             if "reading_accuracy" in o else ""))


def cmd_embed(args: argparse.Namespace) -> None:
    from langpref.language.relevance import FeedbackGate
    from langpref.model.evaluate import embed_text

    model, _ = _load(args, with_data=False)
    out = embed_text(model, args.text)  # an empty text fails here, before the gate is built
    out["relevance"] = round(FeedbackGate(model.info.env).check(args.text).score, 4)
    _emit(out, args.json, lambda o: f"{o['feature']}/{o['direction']} (confidence {o['confidence']:.2f}, "
          f"cosine {o['cosine']:.2f})")


def cmd_visualize(args: argparse.Namespace) -> None:
    from langpref.model.visualize import visualize

    model, dataset = _load(args)
    out = visualize(model, dataset, args.out, split=args.split)
    _emit(out, args.json, lambda o: f"wrote {o['out']} ({o['num_trajectories']} trajectories)")


def cmd_utterances(args: argparse.Namespace) -> None:
    from langpref.language.bank import load_bank

    _emit(load_bank(args.env).merged(), args.json)


def cmd_experiment_alignment(args: argparse.Namespace) -> None:
    from langpref.experiments.alignment import alignment_table, default_out, run_alignment_experiment

    data = args.data or Path("data") / args.env
    out = args.out or default_out(args.env)
    summary = run_alignment_experiment(args.env, data, out, force=args.force)
    _emit(summary, args.json, lambda s: alignment_table([s]) + f"\n(wrote {out}/alignment.md and alignment.json)")


def _register_latent_commands(sub) -> None:
    from langpref.language.relevance import RELEVANCE_FLOOR
    from langpref.model.config import DEFAULT_LANG_MODEL, ModelConfig, TrainConfig

    d, m = TrainConfig(), ModelConfig()
    p = sub.add_parser("train", help="learn the shared latent space of trajectories and language",
                       description="Stage 1 trains the trajectory encoder and a language head with the language model "
                       "frozen; stage 2 co-finetunes the transformer (paper Sec. 4.1). Keeps the epoch with the best "
                       "validation accuracy, stops early, writes a checkpoint directory with a training curve.")
    p.add_argument("--data", required=True, type=Path, help="dataset directory (`langpref generate`)")
    p.add_argument("--out", required=True, type=Path, help="checkpoint directory to create")
    p.add_argument("--lang-model", default=DEFAULT_LANG_MODEL, metavar="NAME_OR_PATH",
                   help=f"Hugging Face encoder: {DEFAULT_LANG_MODEL} (offline, default), a hub name such as t5-small "
                   "(its encoder), or a local directory")
    p.add_argument("--freeze-language", action="store_true", help="stop after stage 1 (language model frozen)")
    p.add_argument("--utterances", type=Path, default=None,
                   help="utterance file (DESIGN.md schema) to train with instead of the bank's train split")
    p.add_argument("--extend-bank", action="store_true", help="with --utterances: add the file to the bank's train "
                   "split instead of replacing it")
    p.add_argument("--epochs", type=int, default=None, help=f"most epochs of stage 1 (default {d.stage1_epochs})")
    p.add_argument("--finetune-epochs", type=int, default=None,
                   help=f"most epochs of stage 2 (default {d.stage2_epochs}; 0 = --freeze-language)")
    p.add_argument("--batch-size", type=int, default=None, help=f"pairs per step, stage 1 (default {d.stage1_batch_size})")
    p.add_argument("--finetune-batch-size", type=int, default=None,
                   help=f"pairs per step, stage 2 (default {d.stage2_batch_size})")
    p.add_argument("--phrasings-per-step", type=int, default=d.stage2_phrasings_per_step,
                   help="distinct utterances through the transformer per stage-2 step (default %(default)s)")
    p.add_argument("--lr", type=float, default=d.stage1_lr,
                   help="stage-1 learning rate of the trajectory encoder (default %(default)s)")
    p.add_argument("--head-lr", type=float, default=d.stage1_head_lr,
                   help="stage-1 learning rate of the language head (default %(default)s)")
    p.add_argument("--lm-lr", type=float, default=d.stage2_lm_lr,
                   help="stage-2 learning rate of the transformer (default %(default)s)")
    p.add_argument("--latent-dim", type=int, default=m.latent_dim, help="D, size of phi and psi (default %(default)s)")
    p.add_argument("--max-length", type=int, default=m.max_length, help="tokens per utterance (default %(default)s)")
    p.add_argument("--no-observation-deltas", dest="observation_deltas", action="store_false",
                   help="trajectory encoder on (observation, action) only, as the authors' code, without each "
                        "step's change of observation")
    p.add_argument("--patience", type=int, default=d.patience,
                   help="early stopping: epochs without a better validation accuracy (default %(default)s; 0 = off)")
    p.add_argument("--norm-a", type=float, default=d.norm_a, help="a of L_norm, hinge on |phi| (default %(default)s)")
    p.add_argument("--norm-b", type=float, default=d.norm_b, help="b of L_norm, (|psi|-1)^2 (default %(default)s)")
    p.add_argument("--tie-fraction", type=float, default=d.tie_fraction,
                   help="a feature differs when |delta| > this times its train std (default %(default)s)")
    p.add_argument("--time-samples", type=int, default=d.time_samples,
                   help="time steps per trajectory per training step, stratified (default %(default)s; 0 = all)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="default: cuda when available")
    p.add_argument("--no-mixed-precision", dest="mixed_precision", action="store_false",
                   help="on CUDA, train in float32 instead of under bfloat16 autocast (CPU is always float32)")
    p.add_argument("--seed", type=int, default=0, help="the same seed gives the same model on CPU")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("evaluate", help="alignment accuracy of a model on a split (paper Sec. 5.1)",
                       description="Over every ordered pair of the split's trajectories, every feature that differs "
                       "(beyond the model's tie threshold) and every phrasing of it in the direction taking A to B: the "
                       "share with psi_l . (phi_B - phi_A) > 0.")
    p.add_argument("--model", required=True, type=Path, help="checkpoint directory (`langpref train`)")
    p.add_argument("--data", required=True, type=Path, help="dataset directory")
    p.add_argument("--split", default="test", choices=("train", "val", "test"), help="default %(default)s")
    p.add_argument("--phrasing-split", default=None, choices=("train", "val", "test"),
                   help="bank split of the phrasings (default: --split); `train` on test trajectories separates "
                        "reading the trajectories from reading unseen words")
    p.add_argument("--utterances", type=Path, default=None,
                   help="utterance file (DESIGN.md schema) instead of the bank's phrasings of --split")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="cpu")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("embed", help="which feature and direction the model reads into a sentence",
                       description="Nearest bank meaning by cosine: the mean psi of each feature/direction's training "
                       "phrasings; confidence is a softmax over the cosines at temperature 0.1. A sentence that does "
                       "not read as feedback on the robot's motion (relevance: its highest cosine to a bank phrasing "
                       f"in the pretrained MiniLM space, below {RELEVANCE_FLOOR}) is refused with an error.")
    p.add_argument("--model", required=True, type=Path, help="checkpoint directory")
    p.add_argument("text", help="free-form feedback, e.g. \"you're way too slow\"")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_embed)

    p = sub.add_parser("visualize", help="draw the latent space: phi by PCA per feature, language directions as arrows")
    p.add_argument("--model", required=True, type=Path, help="checkpoint directory")
    p.add_argument("--data", required=True, type=Path, help="dataset directory")
    p.add_argument("--out", required=True, type=Path, help="image to write (.png, .pdf, .svg)")
    p.add_argument("--split", default=None, choices=("train", "val", "test"), help="default: every trajectory")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_visualize)

    p = sub.add_parser("utterances", help="print the shipped utterance bank of an env (all splits merged)")
    p.add_argument("--env", required=True, metavar="TASK", help=TASK_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_utterances)

    p = sub.add_parser("experiment", help="the paper's experiments, one command each")
    exp = p.add_subparsers(dest="experiment", required=True, metavar="EXPERIMENT")
    p = exp.add_parser("alignment", help="Appendix C: test accuracy, co-finetuned vs frozen language model",
                       description="Trains once (the frozen model is stage 1 of the co-finetuned one), evaluates both "
                       "on the test split with the bank's test phrasings, writes alignment.md/.json.")
    p.add_argument("--env", required=True, metavar="TASK", help=TASK_HELP)
    p.add_argument("--data", type=Path, default=None, help="dataset directory (default data/ENV)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/alignment/ENV)")
    p.add_argument("--force", action="store_true", help="overwrite models already in --out")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_experiment_alignment)


# ---- latent-space uses (improve, learn-reward, experiment improve|reward|ablation) ---------------------------------


def _human_config(args: argparse.Namespace):
    from langpref.feedback.humans import HumanConfig

    return HumanConfig(temperature=args.temperature, **_phrasing_source(args),
                       rationality=getattr(args, "rationality", HumanConfig.rationality))


def _reward_config(args: argparse.Namespace):
    from langpref.reward import RewardConfig

    return RewardConfig(model=args.reward_model, weight_decay=args.weight_decay, loss=args.loss,
                        num_negatives=args.num_negatives, negatives=args.negatives)


def _space(args: argparse.Namespace):
    from langpref.feedback.space import load_space

    return load_space(args.data, args.model, perfect=args.perfect_latent, phrasings=args.phrasings)


def cmd_improve(args: argparse.Namespace) -> None:
    from langpref.improve import ImproveConfig, improve, plot_improvement

    cfg = ImproveConfig(iterations=args.iterations, seeds=args.seeds, seed=args.seed, candidate_split=args.candidates,
                        strategy=args.strategy, objective=args.objective, exclude_shown=args.exclude_shown,
                        human=_human_config(args), reward=_reward_config(args))
    cfg.validate()
    result = improve(_space(args), cfg)
    if args.figure:
        result["figure"] = str(plot_improvement({args.strategy: result}, args.figure, f"strategy {args.strategy}"))
    _emit(result, args.json, lambda r: "mean normalised true reward per iteration: "
          + " ".join(f"{v:.2f}" for v in r["curve"]) + f"\ngain {r['gain']:+.3f} over {r['num_runs']} runs"
          + (f"; figure {r['figure']}" if "figure" in r else ""))


def cmd_learn_reward(args: argparse.Namespace) -> None:
    from langpref.reward import LearnRewardConfig, learn_reward

    cfg = LearnRewardConfig(feedback=args.feedback, queries=args.queries, humans=args.humans, seeds=args.seeds,
                            seed=args.seed, query_split=args.query_split, eval_split=args.eval_split,
                            human=_human_config(args), reward=_reward_config(args))
    cfg.validate()
    result = learn_reward(_space(args), cfg)
    if args.figure:
        from langpref.experiments.reward import plot_reward_curves

        result["figure"] = str(plot_reward_curves({args.feedback: result}, args.figure, f"{args.feedback} feedback"))
    _emit(result, args.json, lambda r: f"{r['feedback']} feedback, {r['num_runs']} runs\n"
          + "cross-entropy per query:        " + " ".join(f"{v:.3f}" for v in r["cross_entropy"]) + "\n"
          + "true reward of the best, per q: " + " ".join(f"{v:.2f}" for v in r["true_reward_of_best"])
          + f"\narea under the true-reward curve {r['auc_true_reward']:.3f}; reaches 0.95 after "
          + f"{r['queries_to_0.95']} queries" + (f"; figure {r['figure']}" if "figure" in r else ""))


def _or_default(value: int | None, default: int) -> int:
    """An override flag's value, or the paper's setting when it was not given (0 is a value, and is refused)."""
    return default if value is None else value


def cmd_experiment_uses(args: argparse.Namespace) -> None:
    from langpref.experiments.common import SweepConfig
    from langpref.feedback.humans import HumanConfig
    from langpref.improve import ImproveConfig
    from langpref.reward import LearnRewardConfig, RewardConfig

    human = HumanConfig(**_phrasing_source(args))
    kw = dict(env=args.env, data=args.data, model=args.model, out=args.out, perfect=args.perfect_latent,
              force=args.force, sweep=SweepConfig(args.backend, args.workers, args.ray_address))
    if args.experiment == "improve":
        from langpref.experiments.improve import run_improve_experiment

        d = ImproveConfig()
        cfg = ImproveConfig(iterations=_or_default(args.iterations, d.iterations),
                            seeds=_or_default(args.seeds, d.seeds), human=human)
        summary = run_improve_experiment(**kw, config=cfg)
    else:
        from langpref.experiments.reward import run_ablation_experiment, run_prior_experiment, run_reward_experiment

        d = LearnRewardConfig()
        cfg = LearnRewardConfig(queries=_or_default(args.queries, d.queries), humans=_or_default(args.humans, d.humans),
                                seeds=_or_default(args.seeds, d.seeds), reward=RewardConfig(model=args.reward_model),
                                human=human)
        run = {"reward": run_reward_experiment, "ablation": run_ablation_experiment,
               "prior": run_prior_experiment}[args.experiment]
        summary = run(**kw, config=cfg)
    md = Path(summary["figure"]).with_suffix(".md")
    _emit(summary, args.json, lambda s: md.read_text() + f"\n(wrote {md.parent}/: {md.stem}.json, .png, .md)")


def _add_phrasing_options(p: argparse.ArgumentParser, *, experiment: bool = False) -> None:
    """Where the synthetic language human's phrasings come from: a bank split, or an utterance file."""
    from langpref.feedback.humans import HumanConfig
    from langpref.feedback.space import PHRASING_SPLITS

    p.add_argument("--phrasing-split", choices=PHRASING_SPLITS, default=HumanConfig.phrasing_split,
                   help="bank split the language human phrases its feedback from (default %(default)s: phrasings "
                   "the model never trained on; all: every split, as the paper's synthetic human)"
                   + ("; default out: ENV-bank-SPLIT" if experiment else ""))
    p.add_argument("--phrasings", type=Path, default=None,
                   help="utterance file (DESIGN.md schema) the language human phrases its feedback from instead of "
                   "the bank, e.g. heldout/utterances.json (phrasings written by people who never saw the bank)"
                   + ("; default out: ENV-phrasings" if experiment else ""))


def _phrasing_source(args: argparse.Namespace) -> dict:
    """The `HumanConfig` fields of `_add_phrasing_options`."""
    return {"phrasing_split": args.phrasing_split, "phrasings": str(args.phrasings) if args.phrasings else None}


def _add_use_options(p: argparse.ArgumentParser, *, reward: bool) -> None:
    from langpref.feedback.humans import HumanConfig
    from langpref.reward import DEFAULT_WEIGHT_DECAY, LOSSES, MODELS, NEGATIVES, RewardConfig

    h, r = HumanConfig(), RewardConfig()
    p.add_argument("--model", type=Path, default=None, help="checkpoint directory (`langpref train`)")
    p.add_argument("--data", required=True, type=Path, help="dataset directory (`langpref generate`)")
    p.add_argument("--perfect-latent", action="store_true",
                   help="ORACLE: use phi = normalised features and psi = +-e_f instead of a model (an upper bound)")
    p.add_argument("--seed", type=int, default=0, help="the same seed gives the same numbers (default 0)")
    p.add_argument("--temperature", type=float, default=h.temperature,
                   help="language human's softmax temperature over features, Eq. 10 (default %(default)s)")
    _add_phrasing_options(p)
    if reward:
        p.add_argument("--rationality", type=float, default=h.rationality,
                       help="comparison human's beta in sigmoid(beta (R_A - R_B)), Eq. 11 (default %(default)s)")
    p.add_argument("--loss", choices=LOSSES, default=r.loss,
                   help="language reward loss: L_Explicit + L_Implicit, or one alone (default %(default)s)")
    p.add_argument("--num-negatives", type=int, default=r.num_negatives,
                   help="k, other utterances per language query in L_Implicit (default %(default)s)")
    p.add_argument("--negatives", choices=NEGATIVES, default=r.negatives,
                   help="implicit negatives: other meanings than the model reads in l, or any other text "
                   "(default %(default)s)")
    p.add_argument("--reward-model", choices=MODELS, default=r.model,
                   help="r_xi on phi: linear (the authors') or a one-hidden-layer MLP (default %(default)s)")
    p.add_argument("--weight-decay", type=float, default=None,
                   help="L2 prior on r_xi's parameters, against the weighted mean loss over feedback pairs (default "
                   + ", ".join(f"{v:g} for {k}" for k, v in DEFAULT_WEIGHT_DECAY.items())
                   + "; `langpref experiment prior` shows how the linear one was chosen)")
    p.add_argument("--figure", type=Path, default=None, help="also draw the curve(s) into this PNG")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _register_latent_use_commands(sub) -> None:
    from langpref.improve import OBJECTIVES
    from langpref.reward import MODELS

    p = sub.add_parser("improve", help="iterative trajectory improvement with a synthetic language human (Eq. 4)",
                       description="From a random trajectory of the candidate split, N rounds of synthetic language "
                       "feedback, each followed by the argmax over the candidates of Eq. 4's cosine objective "
                       "(strategy paper) or of the reward learned from all feedback so far (strategy history). "
                       "Reports the mean normalised true reward per iteration (0 = worst, 1 = best candidate).")
    _add_use_options(p, reward=False)
    p.add_argument("--iterations", type=int, default=15, help="N, feedback rounds per run (default %(default)s)")
    p.add_argument("--seeds", type=int, default=100, help="runs, each a new human and start (default %(default)s)")
    p.add_argument("--strategy", choices=("paper", "history"), default="paper",
                   help="paper: Eq. 4 on the last feedback; history: reward learned from all feedback so far")
    p.add_argument("--objective", choices=OBJECTIVES, default="cosine",
                   help="paper: cosine: cos(phi' - phi^t, psi_l), Eq. 4 as the paper's text describes it (default); "
                   "printed: psi_l . (phi' - phi^t) / (|phi'| |phi^t|), the formula as printed")
    p.add_argument("--candidates", choices=("train", "val", "test"), default="test",
                   help="split searched by the argmax (default %(default)s)")
    p.add_argument("--exclude-shown", action="store_true", help="history: never show a trajectory twice")
    p.set_defaults(func=cmd_improve)

    p = sub.add_parser("learn-reward", help="reward learning from synthetic language feedback or comparisons",
                       description="Each query shows one train trajectory (language: the human says how to improve "
                       "it; L_Explicit + L_Implicit, Eq. 5-9) or a random train pair (comparison: Bradley-Terry). "
                       "After every query, r_xi is refit on all feedback so far and scored on the test split.")
    _add_use_options(p, reward=True)
    p.add_argument("--feedback", required=True, choices=("language", "comparison"))
    p.add_argument("--queries", type=int, default=40, help="Q, queries per run (default %(default)s)")
    p.add_argument("--humans", type=int, default=3, help="synthetic humans (default %(default)s)")
    p.add_argument("--seeds", type=int, default=3, help="runs per human (default %(default)s)")
    p.add_argument("--query-split", choices=("train", "val", "test"), default="train", help="default %(default)s")
    p.add_argument("--eval-split", choices=("train", "val", "test"), default="test", help="default %(default)s")
    p.set_defaults(func=cmd_learn_reward)

    exp_parser = sub.choices.get("experiment") or sub.add_parser("experiment", help="the paper's experiments")
    exp = next((a for a in exp_parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    if exp is None:
        exp = exp_parser.add_subparsers(dest="experiment", required=True, metavar="EXPERIMENT")
    for name, text in (("improve", "Fig. 4: iterative improvement, Eq. 4 (cosine and as printed) and the history "
                        "strategy, 100 seeds"),
                       ("reward", "Fig. 5: reward learning, language vs comparisons, 3 humans x 3 seeds, Q = 40"),
                       ("ablation", "Fig. 6: language reward loss, explicit + implicit vs each alone"),
                       ("prior", "the L2 prior's strength per reward-learning method, chosen on the val split")):
        p = exp.add_parser(name, help=text, description=text + ". Writes NAME.json, NAME.png and NAME.md (a "
                           "section for docs/results.md); an interrupted run resumes without redoing finished seeds.")
        p.add_argument("--env", required=True, metavar="TASK", help=TASK_HELP)
        p.add_argument("--data", type=Path, default=None, help="dataset directory (default data/ENV)")
        p.add_argument("--model", type=Path, default=None,
                       help="checkpoint (default results/alignment/ENV/cofinetuned, from `experiment alignment`)")
        p.add_argument("--perfect-latent", action="store_true", help="ORACLE latent space instead of a model")
        p.add_argument("--out", type=Path, default=None,
                       help=f"output directory (default results/{name}/ENV, or ENV-perfect"
                       + (")" if name == "improve" else ", ENV-mlp)"))
        p.add_argument("--seeds", type=int, default=None, help="override the paper's seeds (100 / 3 per human)")
        _add_phrasing_options(p, experiment=True)
        if name == "improve":
            p.add_argument("--iterations", type=int, default=None, help="override N = 15")
        else:
            p.add_argument("--humans", type=int, default=None, help="override the 3 synthetic humans")
            p.add_argument("--queries", type=int, default=None, help="override Q = 40")
            p.add_argument("--reward-model", choices=MODELS, default="linear",
                           help="r_xi on phi: linear (the authors', default) or a one-hidden-layer MLP")
        p.add_argument("--force", action="store_true", help="discard finished runs in --out and start over")
        p.add_argument("--backend", choices=("local", "ray"), default="local",
                       help="run the seeds as local processes (default) or as Ray tasks, one per run")
        p.add_argument("--workers", type=int, default=1, help="parallel runs (default %(default)s)")
        p.add_argument("--ray-address", default=None, help="with --backend ray: a cluster to join (default local)")
        p.add_argument("--json", action="store_true", help="print one JSON object")
        p.set_defaults(func=cmd_experiment_uses)


# ---- study commands (the web app for user studies) ---------------------------------------------------------------


def cmd_study_serve(args: argparse.Namespace) -> None:
    from langpref.study.config import ServeConfig, VideoConfig
    from langpref.study.serve import resolve_study_config, serve

    study = resolve_study_config(args.db, {
        "split": args.split, "improve_max_iterations": args.improve_max_iterations,
        "pref_queries": args.pref_queries, "rating_every": args.rating_every,
        "num_negatives": args.num_negatives, "seed": args.seed})
    video = VideoConfig(format=args.video_format, width=args.video_width, height=args.video_height,
                        fps=args.video_fps, stride=args.video_stride)
    serve(ServeConfig(model=str(args.model), data=str(args.data), db=str(args.db),
                      videos=str(args.videos) if args.videos else None, host=args.host, port=args.port,
                      admin_token=args.admin_token, prerender=not args.no_prerender, torch_threads=args.torch_threads,
                      on_show=args.on_show, on_show_timeout=args.on_show_timeout, study=study, video=video))


def cmd_study_export(args: argparse.Namespace) -> None:
    from langpref.study.export import export

    out = export(args.db, args.out)
    _emit(out, args.json, lambda o: f"wrote {o['report']} ({o['participants']} participants, {o['finished']} "
          f"finished), {len(o['tables'])} tables and {len(o['figures'])} figures in {o['out']}")


def _register_study_commands(sub) -> None:
    from langpref.study.config import ServeConfig, StudyConfig, VideoConfig

    d, v, s = StudyConfig(), VideoConfig(), ServeConfig()
    p = sub.add_parser("study", help="the web app for user studies with real people (paper Sec. 5.2)")
    st = p.add_subparsers(dest="study_command", required=True, metavar="SUBCOMMAND")
    p = st.add_parser("serve", help="serve a study in the browser (Study 1: improvement, Study 2: language vs "
                      "comparisons)",
                      description="Prints the participant URL and an admin token. State lives in the SQLite --db: a "
                      "restart on the same --db continues every participant where they were. Protocol options "
                      "are fixed when the database is created.")
    p.add_argument("--model", required=True, type=Path, help="checkpoint directory (`langpref train`)")
    p.add_argument("--data", required=True, type=Path, help="dataset directory (`langpref generate`, or `langpref "
                   "import`: the study then shows the recorded videos)")
    p.add_argument("--split", default=None, choices=("train", "val", "test", "all"),
                   help=f"trajectories the study shows and searches (default {d.split})")
    p.add_argument("--db", type=Path, default=Path("study.sqlite"), help="SQLite database (default %(default)s)")
    p.add_argument("--port", type=int, default=8000, help="default %(default)s; 0 picks a free port")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default %(default)s, this machine "
                   "only; 0.0.0.0 opens it to the network)")
    p.add_argument("--admin-token", default=None, help="token of the admin pages and export (default: a random one, "
                   "printed at start)")
    p.add_argument("--videos", type=Path, default=None, help="video cache folder (default DB.videos/)")
    p.add_argument("--improve-max-iterations", type=int, default=None,
                   help=f"Study 1: most rounds of feedback (default {d.improve_max_iterations})")
    p.add_argument("--pref-queries", type=int, default=None, help=f"Study 2: queries per method "
                   f"(default {d.pref_queries})")
    p.add_argument("--rating-every", type=int, default=None,
                   help=f"Study 2: rate the best trajectory after every N queries (default {d.rating_every})")
    p.add_argument("--num-negatives", type=int, default=None,
                   help=f"k, implicit negatives per language answer (default {d.num_negatives})")
    p.add_argument("--seed", type=int, default=None, help=f"study seed (default {d.seed})")
    p.add_argument("--no-prerender", action="store_true", help="make videos only when first asked for")
    p.add_argument("--video-format", choices=("webm", "mp4"), default=v.format,
                   help="webm (VP9, default) or mp4 (H.264; some Chromium builds cannot play it); recorded videos "
                   "in another format are transcoded once")
    p.add_argument("--video-width", type=int, default=v.width, help="rendered videos only (also height, fps, "
                   "stride); recorded ones keep their own")
    p.add_argument("--video-height", type=int, default=v.height)
    p.add_argument("--video-fps", type=int, default=v.fps)
    p.add_argument("--video-stride", type=int, default=v.stride, help="one frame per N stored steps")
    p.add_argument("--torch-threads", type=int, default=1, help="torch threads per request (default %(default)s)")
    p.add_argument("--on-show", metavar="CMD", default=None,
                   help="run CMD before each trajectory is shown to a participant, e.g. to replay it on the real "
                   "robot: one command line, split like a shell does but run without one, with LANGPREF_TRAJECTORY, "
                   "LANGPREF_EPISODE, LANGPREF_PARTICIPANT, LANGPREF_DATA, LANGPREF_KIND and LANGPREF_POSITION in "
                   "its environment; runs one at a time in the background, failures and timeouts are logged and "
                   "shown on the dashboard")
    p.add_argument("--on-show-timeout", metavar="SECONDS", type=float, default=s.on_show_timeout,
                   help="kill an --on-show run after this long (default %(default)g)")
    p.set_defaults(func=cmd_study_serve)

    p = st.add_parser("export", help="CSV tables, analyses and figures of a study (HTML report + JSON)")
    p.add_argument("--db", required=True, type=Path, help="the study's SQLite database")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_study_export)


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
    p.add_argument("--env", required=True, metavar="TASK", help="a task with a simulator: metaworld, robosuite, or a plugin's (see `langpref tasks`)")
    p.add_argument("--out", required=True, type=Path, help="dataset directory to create")
    p.add_argument("--num-trajectories", type=int, default=None,
                   help="number of rollouts (default: the task's; the paper's 324 metaworld / 448 robosuite)")
    p.add_argument("--horizon", type=int, default=None, help="steps per rollout (default 500, the paper's T)")
    p.add_argument("--workers", type=int, default=None, help="parallel worker processes (default: all cores)")
    p.add_argument("--seed", type=int, default=0, help="the same seed gives the same dataset, whatever --workers")
    p.add_argument("--force", action="store_true", help="overwrite an existing dataset in --out")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local worker processes (default) or Ray tasks (pip install 'langpref[ray]')")
    p.add_argument("--ray-address", default=None,
                   help="with --backend ray: join this cluster (auto, HOST:PORT); default a local Ray instance")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("import", help="a robot recording (plain folder of episodes or LeRobotDataset) into a dataset",
                       description="Read a recording of your own robot into a langpref dataset of the task described "
                       "by a task file (TOML: name, description, features, features_from, utterances). A plain folder "
                       "holds NAME.npz episodes (observations (T, obs_dim), actions (T, A), optional features and "
                       "success) with an optional NAME.mp4/.webm video each; a LeRobotDataset (v3) is read with "
                       "pyarrow and PyAV. Episodes may differ in length. See README, 'Your own robot'.")
    p.add_argument("src", type=Path, help="the recording: a plain folder of episodes or a LeRobotDataset folder")
    p.add_argument("--task", required=True, type=Path, help="task file (TOML)")
    p.add_argument("--out", required=True, type=Path, help="dataset directory to create")
    p.add_argument("--seed", type=int, default=0, help="seed of the trajectory split and of an unsplit bank's split")
    p.add_argument("--splits", default=None, help="train,val,test shares of the episodes (default 0.8,0.1,0.1)")
    p.add_argument("--state-key", default="observation.state", help="LeRobotDataset: feature read as observations")
    p.add_argument("--action-key", default="action", help="LeRobotDataset: feature read as actions")
    p.add_argument("--camera", default=None, help="LeRobotDataset: video feature kept per episode (default the "
                   "first; '' for none)")
    p.add_argument("--force", action="store_true", help="overwrite an existing dataset in --out")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("tasks", help="list the tasks langpref knows: built-in, plugins, and a dataset's own",
                       description="Built-in tasks, tasks of installed plugins (entry-point group langpref.tasks), "
                       "and with --data the recorded task a dataset carries.")
    p.add_argument("--data", type=Path, default=None, help="also the task of this dataset")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_tasks)

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
    _register_latent_commands(sub)
    _register_study_commands(sub)
    _register_latent_use_commands(sub)

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
    except BrokenPipeError:  # `langpref ... --json | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
