"""Alignment accuracy (paper Sec. 5.1, docs/design.md#the-command-line) and how the model reads one free-form sentence.

Accuracy: over every ordered pair (tau_A, tau_B) of a split, every feature whose value differs between them (by more
than the model's tie threshold), and every phrasing of that feature in the direction that takes tau_A to tau_B, the
share with psi_l . (phi_B - phi_A) > 0. The score is psi_l . phi_B - psi_l . phi_A, so S = Psi @ Phi^T is computed
once and every sample is two lookups.

Ties: a pair whose feature differs by no more than the model's tie threshold (a fraction of the feature's train
std, `tie_fraction` in training) is left out of `accuracy`. `accuracy_ties_at_chance` puts those samples back (every
pair whose feature differs at all, with every phrasing of the direction taking A to B) each scored 1/2, as a model
that cannot tell would; `accuracy_no_tie_threshold` scores them by the model (`tie_fraction` 0).

Per phrasing: `per_phrasing` gives each phrasing's accuracy over its samples, with its meaning.

Reading accuracy: the share of the phrasings that `embed_text` (`langpref embed`) reads as their own meaning, i.e.
whose psi is closest in cosine to that meaning's prototype; what a person typing one sentence sees.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection, Sequence
from pathlib import Path

import numpy as np
import torch

from langpref.errors import LangprefError
from langpref.language.bank import DIRECTIONS
from langpref.language.pairs import Pairs, Phrasings, build_pairs

CONFIDENCE_TEMPERATURE = 0.1  # softmax temperature over the cosines of `embed_text`


def alignment_counts(
    phi: np.ndarray | torch.Tensor,
    psi: np.ndarray | torch.Tensor,
    pairs: Pairs,
    group_ids: Sequence[np.ndarray],
    num_features: int,
    chunk: int = 1 << 22,
) -> tuple[np.ndarray, np.ndarray]:
    """(correct, total) per feature: every pair scored with every phrasing id of its (feature, direction) group.

    `phi` (N, D) are the rows `pairs.a`/`pairs.b` index; `psi` (P, D) the rows `group_ids[g]` index, with
    g = 2 * feature + direction. A score of exactly 0 counts as wrong.
    """
    phi_t = torch.as_tensor(phi, dtype=torch.float64)
    psi_t = torch.as_tensor(psi, dtype=torch.float64).to(phi_t.device)
    scores = psi_t @ phi_t.T  # (P, N)
    correct = np.zeros(num_features, dtype=np.int64)
    total = np.zeros(num_features, dtype=np.int64)
    groups = pairs.group
    for g, ids in enumerate(group_ids):
        if len(ids) == 0:
            continue
        sel = np.nonzero(groups == g)[0]
        if len(sel) == 0:
            continue
        s = scores[torch.as_tensor(np.asarray(ids), device=scores.device)]  # (n_phr, N)
        step = max(1, chunk // len(ids))
        for start in range(0, len(sel), step):
            idx = sel[start : start + step]
            a = torch.as_tensor(pairs.a[idx], device=s.device)
            b = torch.as_tensor(pairs.b[idx], device=s.device)
            correct[g // 2] += int(((s[:, b] - s[:, a]) > 0).sum())
        total[g // 2] += len(sel) * len(ids)
    return correct, total


def phrasing_counts(
    phi, psi, pairs: Pairs, group_ids: Sequence[np.ndarray], num_phrasings: int, chunk: int = 1 << 22
) -> tuple[np.ndarray, np.ndarray]:
    """(correct, total) per phrasing id: the samples of `alignment_counts`, counted by the phrasing that scored them."""
    phi_t = torch.as_tensor(phi, dtype=torch.float64)
    scores = torch.as_tensor(psi, dtype=torch.float64).to(phi_t.device) @ phi_t.T  # (P, N)
    correct = np.zeros(num_phrasings, dtype=np.int64)
    total = np.zeros(num_phrasings, dtype=np.int64)
    for g, ids in enumerate(group_ids):
        sel = np.nonzero(pairs.group == g)[0]
        if len(ids) == 0 or len(sel) == 0:
            continue
        ids = np.asarray(ids)
        s = scores[torch.as_tensor(ids, device=scores.device)]
        step = max(1, chunk // len(ids))
        for start in range(0, len(sel), step):
            a = torch.as_tensor(pairs.a[sel[start : start + step]], device=s.device)
            b = torch.as_tensor(pairs.b[sel[start : start + step]], device=s.device)
            correct[ids] += ((s[:, b] - s[:, a]) > 0).sum(dim=1).cpu().numpy()
        total[ids] += len(sel)
    return correct, total


def per_phrasing(correct: np.ndarray, total: np.ndarray, phrasings: Phrasings) -> dict[str, dict]:
    """{text: {"meaning": "feature/direction", "accuracy", "num_samples"}} for every phrasing with samples."""
    out = {}
    for g, ids in enumerate(phrasings.group_ids):
        for i in ids:
            if total[i]:
                out[phrasings.texts[i]] = {
                    "meaning": "/".join(phrasings.group_name(g)),
                    "accuracy": float(correct[i] / total[i]),
                    "num_samples": int(total[i]),
                }
    return out


def summarise_accuracy(correct: np.ndarray, total: np.ndarray, feature_names: Sequence[str]) -> dict:
    """{"accuracy", "per_feature", "num_samples"}; features without samples are left out of per_feature."""
    n = int(total.sum())
    return {
        "accuracy": float(correct.sum() / n) if n else float("nan"),
        "per_feature": {f: float(c / t) for f, c, t in zip(feature_names, correct, total) if t},
        "num_samples": n,
    }


def without_phrasings(out: dict, texts: Collection[str]) -> dict:
    """Accuracy and reading accuracy of an `evaluate_split` result with the phrasings `texts` left out, from its
    per-phrasing counts: {"num_left_out", "accuracy", "reading_accuracy" (when read), "num_phrasings"}."""
    kept = {t: p for t, p in out["per_phrasing"].items() if t not in texts}
    samples = sum(p["num_samples"] for p in kept.values())
    correct = sum(p["accuracy"] * p["num_samples"] for p in kept.values())
    num = out["num_phrasings"] - sum(t in texts for t in out["per_phrasing"])
    res = {
        "num_left_out": out["num_phrasings"] - num,
        "num_phrasings": num,
        "accuracy": correct / samples if samples else float("nan"),
    }
    if "misread" in out:
        misread = sum(m["text"] not in texts for m in out["misread"])
        res["reading_accuracy"] = 1.0 - misread / num if num else float("nan")
    return res


def summary_only(out: dict) -> dict:
    """An `evaluate` result without a single phrasing's text: for sets that must not steer anything
    (reporting-only phrasings written apart), whose individual errors nobody should read."""
    out = {k: v for k, v in out.items() if k not in ("per_phrasing", "misread")}
    if "near_copies" in out:
        out["near_copies"] = {k: v for k, v in out["near_copies"].items() if k != "texts"}
    return out


def reading(psi: torch.Tensor, prototypes: torch.Tensor, phrasings: Phrasings) -> dict:
    """{"reading_accuracy", "misread"}: the share of `phrasings` whose nearest prototype (cosine; row g = 2 * feature
    + direction, as the phrasing groups) is their own meaning, and those that are not, with what they were read as."""
    cos = (
        torch.nn.functional.normalize(psi.double(), dim=-1)
        @ torch.nn.functional.normalize(prototypes.double(), dim=-1).T
    )
    read = cos.argmax(dim=1).cpu().numpy()
    misread, n = [], 0
    for g, ids in enumerate(phrasings.group_ids):
        n += len(ids)
        misread += [
            {
                "text": phrasings.texts[i],
                "meaning": "/".join(phrasings.group_name(g)),
                "read_as": "/".join(phrasings.group_name(int(read[i]))),
            }
            for i in ids
            if read[i] != g
        ]
    return {"reading_accuracy": 1.0 - len(misread) / n if n else float("nan"), "misread": misread}


def evaluate_split(model, dataset, split: str, phrasings: Phrasings) -> dict:
    """Alignment accuracy of a `LatentModel` on one split of a dataset with the given phrasings."""
    model.check_dataset(dataset)
    if tuple(phrasings.feature_names) != tuple(model.feature_names):
        raise LangprefError("the phrasings' features do not match the model's")
    if not phrasings.texts:
        raise LangprefError("no phrasings to evaluate with")
    idx = dataset.split(split)
    if len(idx) < 2:
        raise LangprefError(f"split {split!r} of {dataset.root} has {len(idx)} trajectories; need at least 2")
    phi = model.encode_dataset(dataset, split).double().cpu()
    psi = model.encode_texts(phrasings.texts).double().cpu()
    pairs = build_pairs(dataset.features[idx], np.asarray(model.info.tie_thresholds))
    correct, total = alignment_counts(phi, psi, pairs, phrasings.group_ids, len(model.feature_names))
    out = summarise_accuracy(correct, total, model.feature_names)
    out.update(split=split, num_trajectories=len(idx), num_phrasings=len(phrasings.texts), num_pairs=len(pairs))
    out.update(_with_ties(phi, psi, dataset.features[idx], phrasings, correct, total, len(model.feature_names)))
    out["per_phrasing"] = per_phrasing(
        *phrasing_counts(phi, psi, pairs, phrasings.group_ids, len(phrasings.texts)), phrasings
    )
    if bool(model.prototypes.abs().sum() > 0):
        out.update(reading(psi, model.prototypes.cpu(), phrasings))
    return out


def _with_ties(
    phi, psi, features: np.ndarray, phrasings: Phrasings, correct: np.ndarray, total: np.ndarray, num_features: int
) -> dict:
    """The accuracy with the samples the tie threshold left out: scored at chance, and scored by the model."""
    every = build_pairs(features, np.zeros(features.shape[1]))
    correct_all, total_all = alignment_counts(phi, psi, every, phrasings.group_ids, num_features)
    ties = int(total_all.sum() - total.sum())
    n = int(total_all.sum())
    return {
        "accuracy_ties_at_chance": float((correct.sum() + 0.5 * ties) / n) if n else float("nan"),
        "accuracy_no_tie_threshold": float(correct_all.sum() / n) if n else float("nan"),
        "num_tie_samples": ties,
    }


def embed_text(model, text: str, temperature: float = CONFIDENCE_TEMPERATURE) -> dict:
    """Which (feature, direction) the model takes `text` to mean: the prototype (mean psi of that meaning's train
    phrasings) with the highest cosine to psi(text). Confidence: softmax over the cosines at `temperature`, taken at
    the winner (1 / number of meanings when all are equally close, near 1 when one stands out)."""
    text = " ".join(str(text).split())
    if not text:
        raise LangprefError('the text is empty; pass a sentence such as "Move faster."')
    if not bool(model.prototypes.abs().sum() > 0):
        raise LangprefError("this checkpoint has no prototypes of the bank meanings; retrain it with this langpref")
    psi = model.encode_texts([text])[0].double()
    protos = model.prototypes.double()
    cos = torch.nn.functional.cosine_similarity(protos, psi.unsqueeze(0), dim=-1)
    probs = torch.softmax(cos / temperature, dim=0)
    best = int(torch.argmax(cos))
    feature, direction = model.meanings[best]
    assert direction in DIRECTIONS
    out = {
        "text": text,
        "feature": feature,
        "direction": direction,
        "confidence": float(probs[best]),
        "cosine": float(cos[best]),
        "scores": {f"{f}/{d}": float(c) for (f, d), c in zip(model.meanings, cos)},
    }
    if getattr(model, "negation", False):  # what the negation setting did to this text (`langpref.language.negation`)
        from langpref.language.negation import detect

        found = detect(text)
        out["negation"] = {"flipped": found.flip, "reason": found.reason, "read_as": found.text}
    return out


def plot_evaluation(out: dict, path) -> Path:
    """`langpref evaluate --figure`: left, the accuracy on each feature (`out["per_feature"]`) against chance (0.5)
    and the overall accuracy; right, what the misread phrasings (`out["misread"]`) were read as, each pair (meaning,
    read as) a bar of how many phrasings."""
    from langpref.extras import pyplot, save_figure

    plt = pyplot("the figure of an evaluation")
    fig, (left, right) = plt.subplots(
        1, 2, figsize=(12.0, 0.9 + 0.45 * max(len(out["per_feature"]), 8)), layout="constrained"
    )
    _feature_bars(left, out)
    _misread_bars(right, out)
    oracle = f", oracle {out['oracle']} side" if out.get("oracle") else ""
    fig.suptitle(
        f"alignment on the {out['split']} split ({out['utterances']}{oracle}): {out['num_samples']} samples, "
        f"{out['num_phrasings']} phrasings"
    )
    return save_figure(fig, path)


def _feature_bars(ax, out: dict) -> None:
    names, acc = list(out["per_feature"]), list(out["per_feature"].values())
    y = np.arange(len(names))
    ax.barh(y, acc, color=["tab:blue" if a > 0.5 else "tab:red" for a in acc])
    for k, a in enumerate(acc):
        ax.text(a + 0.02, k, f"{a:.3f}", va="center", fontsize=8, bbox={"facecolor": "white", "edgecolor": "none"})
    ax.axvline(0.5, color="grey", linestyle=":", label="chance (0.5)")
    ax.axvline(out["accuracy"], color="k", linestyle="--", linewidth=1, label=f"all features ({out['accuracy']:.3f})")
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xlim(0.0, 1.1)
    ax.set_xticks(np.linspace(0.0, 1.0, 6))
    ax.set_xlabel("accuracy: share of pairs ordered right by the phrasing")
    ax.set_title("accuracy per feature (red: at or below chance)", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")


def _misread_bars(ax, out: dict) -> None:
    if "misread" not in out:
        why = (
            f"--summary: aggregates only, no phrasing's reading\n({out['reading_accuracy']:.3f} of "
            f"{out['num_phrasings']} phrasings read as their own meaning)"
            if "reading_accuracy" in out
            else "this checkpoint has no prototypes to read phrasings by"
        )
        ax.text(0.5, 0.5, why, ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        ax.set_title("what misread phrasings were read as", fontsize=10)
        return
    counts = Counter(f"{m['meaning']} read as {m['read_as']}" for m in out["misread"])
    pairs = counts.most_common(15)
    y = np.arange(len(pairs))
    ax.barh(y, [n for _, n in pairs], color="tab:orange")
    ax.set_yticks(y, [p for p, _ in pairs], fontsize=8)
    ax.invert_yaxis()
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_xlabel("phrasings")
    shown = f"; the {len(pairs)} commonest of {len(counts)} confusions" if len(counts) > len(pairs) else ""
    ax.set_title(
        f"misread phrasings: what each was read as\n{len(out['misread'])} of {out['num_phrasings']} misread "
        f"(`langpref embed`){shown}",
        fontsize=10,
    )
    if not pairs:
        ax.text(0.5, 0.5, "every phrasing read as its own meaning", ha="center", va="center", transform=ax.transAxes)
