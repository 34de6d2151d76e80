"""Train the language side alone on the comparative-feedback corpus (`langpref.language.corpus`) before it meets any
task: the stage that makes the registered language model `comparative` from `minilm`.

The objective teaches meaning and direction: a supervised contrastive loss over the corpus's meanings
(concept/direction[/object]) on the sentence embeddings a task's language head later reads (the attention-masked mean
of the last hidden states). Each batch takes a few concepts and, for each, sentences of BOTH directions, so the
opposite direction of the same concept is always in the batch as the hardest negative ("Move faster." must sit
apart from "No need to rush."), and other objects of the same concept are negatives too ("closer to the cup" is not
"closer to the bowl").

Settings are chosen on a val part of the corpus that holds whole concepts out (`corpus.concept_split`): how well the
embeddings of concepts never trained on sort their sentences into meaning and direction (`read_val`), never on any
bank's test phrasings or held-out texts.

The settings, and the record a built model carries, are `langpref.language.recipes`. `build` writes a model into a
directory; `ensure_built` into the cache, before the model's first load by name (`langpref.language.loading`).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from langpref.errors import LangprefError
from langpref.language.corpus import Example, build_corpus, fingerprint
from langpref.language.lexicon import lexicon_version
from langpref.language.models import canonical_name, comparative_dir, lookup, resolve
from langpref.language.recipes import BUILD_RECORD, OBJECTIVES, PretrainConfig, preset
from langpref.language.transformer import SentenceEncoder, open_transformer, save_transformer


def _groups(examples: list[Example]) -> dict[str, dict[str, list[int]]]:
    """{concept key (concept[/object]): {direction: [example index]}} for keys with sentences in both directions."""
    out: dict[str, dict[str, list[int]]] = {}
    for i, e in enumerate(examples):
        key = f"{e.concept}/{e.obj}" if e.obj else e.concept
        out.setdefault(key, {}).setdefault(e.direction, []).append(i)
    return {k: v for k, v in out.items() if len(v) == 2}


def _batch(groups: dict[str, dict[str, list[int]]], cfg: PretrainConfig, rng: np.random.Generator) -> list[int]:
    """Example indices of one batch: `concepts_per_step` concept keys (each concept drawn as often as any other,
    whatever its number of objects), both directions each, `sentences_per_meaning` sentences per meaning."""
    by_concept: dict[str, list[str]] = {}
    for key in groups:
        by_concept.setdefault(key.split("/")[0] if "/" in key else key, []).append(key)
    names = sorted(by_concept)
    picked = rng.choice(len(names), size=min(cfg.concepts_per_step, len(names)), replace=False)
    out = []
    for c in picked:
        keys = by_concept[names[c]]
        key = keys[int(rng.integers(len(keys)))]
        for direction in sorted(groups[key]):
            idx = groups[key][direction]
            take = rng.choice(len(idx), size=min(cfg.sentences_per_meaning, len(idx)), replace=False)
            out += [idx[t] for t in take]
    return out


def contrastive_loss(z: torch.Tensor, labels: list[str], temperature: float) -> torch.Tensor:
    """Supervised contrastive loss: each sentence's softmax over the cosine similarities to every other sentence of
    the batch puts its mass on those of its own meaning."""
    z = torch.nn.functional.normalize(z, dim=-1)
    sim = z @ z.T / temperature
    n = len(labels)
    eye = torch.eye(n, dtype=torch.bool, device=z.device)
    ids = {label: i for i, label in enumerate(sorted(set(labels)))}
    lab = torch.tensor([ids[x] for x in labels], device=z.device)
    positive = (lab[:, None] == lab[None, :]) & ~eye
    log_prob = sim.masked_fill(eye, float("-inf")).log_softmax(dim=1)
    per = -(log_prob.masked_fill(~positive, 0.0).sum(1)) / positive.sum(1).clamp(min=1)
    return per[positive.any(1)].mean()


@torch.no_grad()
def read_val(encoder, examples: list[Example], seed: int = 0, per_meaning: int = 24) -> dict[str, float]:
    """How the embeddings sort sentences: leave-one-out nearest meaning centroid among all meanings of `examples`
    (`meaning`), and among the two directions of the sentence's own concept only (`direction`)."""
    rng = np.random.default_rng(seed)
    by_meaning: dict[str, list[int]] = {}
    for i, e in enumerate(examples):
        by_meaning.setdefault(e.meaning, []).append(i)
    chosen = []
    for m in sorted(by_meaning):
        idx = by_meaning[m]
        chosen += [idx[j] for j in rng.choice(len(idx), size=min(per_meaning, len(idx)), replace=False)]
    texts = [examples[i].text for i in chosen]
    labels = [examples[i].meaning for i in chosen]
    was = encoder.training
    encoder.eval()
    z = torch.nn.functional.normalize(encoder.pooled_texts(texts), dim=-1)
    encoder.train(was)
    names = sorted(set(labels))
    lab = torch.tensor([names.index(x) for x in labels])
    onehot = torch.nn.functional.one_hot(lab, len(names)).float()
    sums, counts = onehot.T @ z, onehot.sum(0)
    own = (sums[lab] - z) / (counts[lab] - 1).clamp(min=1)[:, None]
    cent = sums / counts[:, None]
    scores = z @ cent.T
    scores[torch.arange(len(lab)), lab] = (z * own).sum(1)
    meaning = float((scores.argmax(1) == lab).float().mean())
    opposite = {}
    for m in names:
        parts = m.split("/")
        parts[1] = "decrease" if parts[1] == "increase" else "increase"
        opposite[m] = "/".join(parts)
    opp = torch.tensor([names.index(opposite[x]) if opposite[x] in names else -1 for x in labels])
    ok = opp >= 0
    rows = torch.arange(len(lab))[ok]
    direction = float((scores[rows, lab[ok]] > scores[rows, opp[ok]]).float().mean()) if ok.any() else float("nan")
    return {"meaning": meaning, "direction": direction, "sentences": len(texts)}


def pretrain(
    examples: list[Example],
    cfg: PretrainConfig,
    val: list[Example] | None = None,
    val_every: int = 50,
    progress: bool = True,
):
    """(encoder, history): `cfg.base`'s sentence encoder trained `cfg.steps` steps on `examples`; with `val`, its
    reading of `val` (`read_val`) before training and every `val_every` steps."""
    from tqdm import tqdm

    cfg.validate()
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng([cfg.seed, 40])
    ensure_built(cfg.base)  # a base langpref builds itself is built first, as any load of it by name does
    tokenizer, transformer = open_transformer(resolve(cfg.base), cfg.base)
    encoder = SentenceEncoder(tokenizer, transformer, cfg.max_length)
    embeddings = transformer.get_input_embeddings()
    for p in embeddings.parameters():  # the 30k-word table: most of the weights, and words the corpus never shows
        p.requires_grad_(False)
    params = [p for p in transformer.parameters() if p.requires_grad]
    target = None
    groups_lr = [{"params": params, "lr": cfg.lr}]
    if cfg.objective == "aligned":
        from langpref.language.pretrain_aligned import warmed_target

        target = warmed_target(encoder, examples, cfg.seed, cfg.head_warmup_steps, cfg.head_lr)
        groups_lr.append({"params": list(target.head.parameters()), "lr": cfg.head_lr})
    optimiser = torch.optim.AdamW(groups_lr, weight_decay=0.0)
    groups = _groups(examples)
    if len(groups) < 2:
        raise LangprefError("the corpus needs at least two concepts with sentences in both directions")
    history: list[dict[str, Any]] = []
    if val:
        history.append({"step": 0, **read_val(encoder, val, cfg.seed)})
    encoder.train()
    bar = tqdm(range(1, cfg.steps + 1), desc="comparative language model", disable=not progress, file=sys.stderr)
    for step in bar:
        idx = _batch(groups, cfg, rng)
        z = encoder.pooled_texts([examples[i].text for i in idx])
        if target is None:
            loss = contrastive_loss(z, [examples[i].meaning for i in idx], cfg.temperature)
        else:
            loss = target.loss(z, [examples[i] for i in idx])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        bar.set_postfix(loss=f"{loss.item():.3f}")
        history.append({"step": step, "loss": float(loss.item())})
        if val and (step % val_every == 0 or step == cfg.steps):
            history.append({"step": step, **read_val(encoder, val, cfg.seed)})
    encoder.eval()
    return encoder, history


def build(out: Path, cfg: PretrainConfig, progress: bool = True) -> dict[str, Any]:
    """Build the language model into directory `out` (atomically: a crash leaves none): the corpus of `cfg.seed`,
    `pretrain`, the weights and tokenizer, and `BUILD_RECORD`. Returns the record."""
    start = time.perf_counter()
    examples = build_corpus(cfg.seed, cfg.per_meaning)
    encoder, history = pretrain(examples, cfg, progress=progress)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    losses = [h["loss"] for h in history if "loss" in h]
    record = {
        "format": "langpref-language-model",
        "built_from": canonical_name(cfg.base),
        "objective": OBJECTIVES[cfg.objective],
        "config": asdict(cfg),
        "corpus": {
            "sentences": len(examples),
            "fingerprint": fingerprint(examples),
            "lexicon_version": lexicon_version(),
        },
        "loss_first_10": float(np.mean(losses[:10])),
        "loss_last_10": float(np.mean(losses[-10:])),
        "build_s": None,
        "torch_threads": torch.get_num_threads(),
    }
    try:
        save_transformer(encoder.tokenizer, encoder.transformer, tmp)
        record["build_s"] = round(time.perf_counter() - start, 1)
        (tmp / BUILD_RECORD).write_text(json.dumps(record, indent=2) + "\n")
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return record


def ensure_built(name: str) -> None:
    """Build the language model `name` into the cache where langpref makes it (`LangModelSpec.built`: `comparative`,
    `comparative-aligned`), its packages are installed and it is not there yet, with a progress bar on stderr; nothing
    for any other name. What loading a model by name does first (`langpref.language.loading`), so that
    `langpref train --lang-model comparative` builds it by itself the first time."""
    spec = lookup(name)
    if spec is None or not spec.built or not spec.installed():
        return  # a missing package is said by `resolve`, in one line
    out = comparative_dir(0, spec.name)
    if (out / "model.safetensors").is_file():
        return
    print(f"building the language model {spec.name!r} once (a few minutes on 2 CPU cores) into {out}", file=sys.stderr)
    build(out, preset(spec.name))


__all__ = ["build", "contrastive_loss", "ensure_built", "pretrain", "read_val"]
