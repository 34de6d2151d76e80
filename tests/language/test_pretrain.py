"""The language side trained alone on the comparative corpus (langpref.language.pretrain), the registered model
`comparative`, and a checkpoint made on a built language model naming what it started from. Tiny: a handful of
concepts, a few steps."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch

from langpref.language.corpus import generate
from langpref.language.pretrain import build, contrastive_loss, pretrain
from langpref.language.recipes import PretrainConfig, read_record

TINY = PretrainConfig(steps=4, concepts_per_step=2, sentences_per_meaning=2, lr=1e-4, max_length=12)


def test_the_loss_prefers_a_batch_sorted_by_meaning():
    labels = ["a/increase", "a/increase", "a/decrease", "a/decrease"]
    sorted_ = torch.tensor([[1.0, 0.0], [0.9, 0.1], [-1.0, 0.0], [-0.9, -0.1]])
    mixed = torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.9, 0.1], [-0.9, -0.1]])
    assert contrastive_loss(sorted_, labels, 0.1) < contrastive_loss(mixed, labels, 0.1)


@pytest.fixture(scope="module")
def tiny_corpus():
    return generate(0, 6, ["speed", "height"])


def _loss_on(encoder, examples, temperature: float) -> float:
    with torch.no_grad():
        z = encoder.pooled_texts([e.text for e in examples])
    return float(contrastive_loss(z, [e.meaning for e in examples], temperature))


def test_a_tiny_build_runs_and_lowers_its_loss(tiny_corpus):
    from langpref.language.loading import load_transformer
    from langpref.language.transformer import SentenceEncoder

    before = SentenceEncoder(*load_transformer(TINY.base), TINY.max_length).eval()
    cfg = PretrainConfig(**{**asdict(TINY), "steps": 8})
    encoder, history = pretrain(tiny_corpus, cfg, val=tiny_corpus, val_every=4, progress=False)
    assert [h["step"] for h in history if "meaning" in h] == [0, 4, 8]
    assert _loss_on(encoder, tiny_corpus, cfg.temperature) < _loss_on(before, tiny_corpus, cfg.temperature)


def test_the_build_is_deterministic_from_its_seed(tiny_corpus):
    def weights(seed: int) -> np.ndarray:
        cfg = PretrainConfig(**{**asdict(TINY), "seed": seed})
        encoder, _ = pretrain(tiny_corpus, cfg, progress=False)
        return np.concatenate([p.detach().numpy().ravel()[:2000] for p in encoder.transformer.encoder.parameters()])

    a, b, c = weights(0), weights(0), weights(1)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_a_checkpoint_names_the_language_model_it_started_from(tmp_path, monkeypatch):
    """A built language model carries its record; a checkpoint made on it names it and the model it started from."""
    monkeypatch.setattr(
        "langpref.language.pretrain.build_corpus", lambda seed, per_meaning: generate(seed, 4, ["speed", "height"])
    )
    built = tmp_path / "lm"
    record = build(built, TINY, progress=False)
    assert read_record(built) == record and record["built_from"] == "minilm"
    assert record["loss_last_10"] > 0 and record["corpus"]["sentences"] == 16

    from langpref.model.checkpoint import build_model, save_model
    from langpref.model.config import ModelConfig
    from langpref.model.encoders import step_input_dim
    from langpref.model.latent import DataInfo
    from langpref.tasks import get_task

    spec = get_task("metaworld")
    layout = [asdict(f) for f in spec.obs_layout]
    info = DataInfo("metaworld", list(spec.features), layout, spec.obs_dim, spec.action_dim, 8, 1, [0.0] * 3, [1.0] * 3)
    dim = step_input_dim(spec.obs_dim, spec.action_dim, True)
    cfg = ModelConfig(lang_model=str(built), latent_dim=8, max_length=12)
    model = build_model(cfg, info, np.zeros(dim), np.ones(dim))
    out = save_model(model, tmp_path / "ckpt", model_cfg=cfg, lang_finetuned=False)
    saved = json.loads((out / "config.json").read_text())
    assert saved["lang_model"] == str(built)
    assert saved["lang_model_info"]["built_from"] == "minilm"
    assert saved["lang_model_info"]["build"]["corpus"] == record["corpus"]


def test_comparative_is_registered_and_builds_into_the_cache_when_missing(tmp_path, monkeypatch):
    """The registry names where the built model lies; loading it by name builds it there first, once."""
    from langpref.language import models
    from langpref.language.pretrain import ensure_built

    monkeypatch.setenv("LANGPREF_CACHE", str(tmp_path))
    calls = []

    def fake_build(out, cfg, progress=True):
        calls.append(cfg)
        out.mkdir(parents=True)
        (out / "model.safetensors").write_bytes(b"")

    monkeypatch.setattr("langpref.language.pretrain.build", fake_build)
    assert models.canonical_name("comparative") == "comparative"
    path = models.resolve("comparative")
    assert path.startswith(str(tmp_path)) and calls == []  # the registry builds nothing
    ensure_built("comparative")
    assert calls == [PretrainConfig()] and (Path(path) / "model.safetensors").is_file()
    ensure_built("comparative")
    assert models.resolve("comparative") == path and len(calls) == 1  # cached: built once
