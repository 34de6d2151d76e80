"""Why a feature is ordered badly: what the trajectory side can see of each feature, without any language.

Three diagnostics on a dataset (val split; the test split is never read here):

  probe MODEL     a linear probe of each feature from a trained model's phi: ridge regression fit on the train
                  split's phi, scored on val as the share of val pairs (differing beyond the model's tie threshold)
                  whose predicted difference has the right sign. High where phi holds the feature at all, in any
                  direction of the latent space.
  inputs          the same probe on the time mean of the encoder's normalised per-step inputs, for each input
                  variant: what a trajectory side linear in its inputs could order (phi is an MLP, but it starts
                  near linear and a small recording gives it few steps).
  oracle          the trajectory encoder alone trained with an oracle language side (psi = +-u_f, fixed unit vectors,
                  one per feature: the true direction of every pair), scored on val pairs by feature after each
                  budget of optimiser steps. The trajectory side's own ceiling, per input variant.

    .venv/bin/python examples/reach/diagnose.py inputs --data data/reach60
    .venv/bin/python examples/reach/diagnose.py oracle --data data/reach60 --seeds 0 1 2
    .venv/bin/python examples/reach/diagnose.py probe --data data/reach60 --model runs/reach/base_s0
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from langpref.dataset.storage import load_dataset
from langpref.language.pairs import build_pairs
from langpref.model.encoders import TrajectoryEncoder, normalisation_stats, time_mean

VARIANTS = ("obs+act", "obs+delta+act", "obs+delta+absdelta+act", "obs+delta+act+time")


def variant_steps(obs: np.ndarray, act: np.ndarray, lengths: np.ndarray, variant: str) -> np.ndarray:
    """(N, T, d) per-step inputs of one variant: the observation, its change since the previous step, the change's
    magnitude per dimension, the step's time in seconds-free units (its index), the action."""
    delta = np.diff(obs, axis=1, prepend=obs[:, :1])
    parts = [obs]
    if "delta" in variant:
        parts.append(delta)
    if "absdelta" in variant:
        parts.append(np.abs(delta))
    parts.append(act)
    if variant.endswith("time"):
        t = np.broadcast_to(np.arange(obs.shape[1], dtype=np.float32)[None, :, None], (*obs.shape[:2], 1))
        parts.append(np.minimum(t, lengths[:, None, None] - 1))
    return np.concatenate(parts, axis=-1).astype(np.float32)


def split_arrays(dataset, split: str, variant: str) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """(steps, lengths, features) of one split."""
    obs, act = dataset.arrays(split)
    lengths = dataset.lengths(split)
    lengths = np.full(len(obs), obs.shape[1]) if lengths is None else lengths
    steps = variant_steps(obs, act, lengths, variant)
    return torch.from_numpy(steps), torch.as_tensor(lengths), dataset.features[dataset.split(split)]


def pair_accuracy(pred: np.ndarray, true: np.ndarray, thresholds: np.ndarray) -> list[float]:
    """Per feature, the share of ordered pairs differing beyond the threshold whose predicted delta has its sign."""
    pairs = build_pairs(true, thresholds)
    right = np.sign(pred[pairs.b, pairs.feature] - pred[pairs.a, pairs.feature]) == np.where(
        pairs.direction == 0, 1.0, -1.0
    )
    return [float(right[pairs.feature == f].mean()) for f in range(true.shape[1])]


def ridge_probe(x_train: np.ndarray, y_train: np.ndarray, x_val: np.ndarray, alpha: float = 1.0) -> np.ndarray:
    """Predictions on x_val of a ridge regression fit on standardised x_train (one fit for all features)."""
    mu, sd = x_train.mean(0), x_train.std(0) + 1e-8
    a, b = (x_train - mu) / sd, (x_val - mu) / sd
    a1, b1 = np.c_[a, np.ones(len(a))], np.c_[b, np.ones(len(b))]
    w = np.linalg.solve(a1.T @ a1 + alpha * np.eye(a1.shape[1]), a1.T @ y_train)
    return b1 @ w


def thresholds_of(dataset, tie_fraction: float = 0.05) -> np.ndarray:
    return tie_fraction * dataset.features[dataset.split("train")].std(axis=0)


def inputs_report(dataset) -> dict:
    """The linear probe on time-mean normalised inputs, per variant."""
    out = {}
    for variant in VARIANTS:
        xs = {}
        for split in ("train", "val"):
            steps, lengths, feats = split_arrays(dataset, split, variant)
            xs[split] = (steps, lengths, feats)
        mean, std = normalisation_stats(xs["train"][0].numpy(), xs["train"][1].numpy())
        mu, sd = torch.from_numpy(mean), torch.from_numpy(std)
        pooled = {s: time_mean((st - mu) / sd, ln).numpy() for s, (st, ln, _) in xs.items()}
        pred = ridge_probe(pooled["train"], xs["train"][2], pooled["val"])
        out[variant] = pair_accuracy(pred, xs["val"][2], thresholds_of(dataset))
    return out


def stratified_index(lengths: torch.Tensor, k: int, gen: torch.Generator) -> torch.Tensor:
    """One random step in each of k equal segments of every trajectory's own length (as training draws them)."""
    frac = (torch.arange(k)[None, :] + torch.rand(len(lengths), k, generator=gen)) / k
    return torch.minimum((frac * lengths[:, None]).long(), lengths[:, None] - 1)


def oracle_run(dataset, variant: str, seed: int, budgets: list[int], time_samples: int = 50) -> dict[int, list[float]]:
    """Train a trajectory encoder against psi = +-u_f (the oracle language side); val pair accuracy per feature
    after each budget of steps (batches of 1024 train pairs, Adam 1e-3, the loss of `langpref.model.loss`)."""
    from langpref.model.loss import latent_loss

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    tr_steps, tr_len, tr_feat = split_arrays(dataset, "train", variant)
    va_steps, va_len, va_feat = split_arrays(dataset, "val", variant)
    mean, std = normalisation_stats(tr_steps.numpy(), tr_len.numpy())
    enc = TrajectoryEncoder(tr_steps.shape[-1], (128,), 128, mean, std)
    u = torch.nn.functional.normalize(torch.randn(tr_feat.shape[1], 128, generator=gen), dim=-1)
    pairs = build_pairs(tr_feat, thresholds_of(dataset))
    sign = torch.as_tensor(np.where(pairs.direction == 0, 1.0, -1.0), dtype=torch.float32)
    opt = torch.optim.Adam(enc.parameters(), lr=1e-3)
    out, rows = {}, torch.arange(len(tr_steps))
    for step in range(1, max(budgets) + 1):
        t = stratified_index(tr_len, time_samples, gen)
        phi = enc(tr_steps[rows[:, None], t])
        batch = torch.randint(len(pairs.a), (1024,), generator=gen)
        a, b, f = (torch.as_tensor(x)[batch] for x in (pairs.a, pairs.b, pairs.feature))
        loss, _, _ = latent_loss(phi[a], phi[b], sign[batch, None] * u[f], 1e-2, 1e-2)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step in budgets:
            with torch.no_grad():
                score = (enc(va_steps, va_len) @ u.T).numpy()
            out[step] = pair_accuracy(score, va_feat, thresholds_of(dataset))
    return out


def model_probe(dataset, model_dir: str) -> dict:
    """The linear probe of each feature from a trained model's phi (fit on train, scored on val pairs)."""
    from langpref.model.checkpoint import load_model

    model = load_model(model_dir)
    with torch.no_grad():
        phi = {s: model.encode_dataset(dataset, s).double().cpu().numpy() for s in ("train", "val")}
    feats = {s: dataset.features[dataset.split(s)] for s in ("train", "val")}
    pred = ridge_probe(phi["train"], feats["train"], phi["val"])
    return {"linear_probe_val": pair_accuracy(pred, feats["val"], np.asarray(model.info.tie_thresholds))}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("inputs", "oracle", "probe"))
    parser.add_argument("--data", required=True)
    parser.add_argument("--model", help="a trained checkpoint (probe)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--budgets", type=int, nargs="+", default=[90, 300, 1000])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    dataset = load_dataset(args.data)
    names = dataset.feature_names
    if args.what == "inputs":
        res = {v: dict(zip(names, acc)) for v, acc in inputs_report(dataset).items()}
    elif args.what == "probe":
        res = {k: dict(zip(names, v)) for k, v in model_probe(dataset, args.model).items()}
    else:
        res = {}
        for variant in args.variants:
            runs = [oracle_run(dataset, variant, s, args.budgets) for s in args.seeds]
            res[variant] = {
                n: {f: round(float(np.mean([r[n][i] for r in runs])), 3) for i, f in enumerate(names)}
                for n in args.budgets
            }
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
