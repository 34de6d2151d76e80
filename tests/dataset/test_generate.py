import json
import os
import shutil

import numpy as np
import pytest

from langpref.cli import main
from langpref.dataset.checksum import checksum_parts, dataset_checksum
from langpref.dataset.generate import GenerateConfig, assign_splits, generate, split_sizes
from langpref.dataset.inspect import describe, format_description
from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError


def test_default_split_sizes_are_the_papers():
    assert split_sizes("metaworld", 324) == {"train": 260, "val": 32, "test": 32}
    assert split_sizes("robosuite", 448) == {"train": 359, "val": 44, "test": 45}
    small = split_sizes("metaworld", 40)
    assert small == {"train": 32, "val": 4, "test": 4}


def test_splits_partition_the_indices():
    splits = assign_splits("metaworld", 50, seed=3)
    everything = sorted(i for idx in splits.values() for i in idx)
    assert everything == list(range(50))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("gen")
    cfg = dict(env="metaworld", num_trajectories=6, horizon=60, seed=5)
    generate(GenerateConfig(out=root / "one", workers=1, **cfg))
    generate(GenerateConfig(out=root / "two", workers=2, **cfg))
    generate(GenerateConfig(out=root / "other", workers=1, **{**cfg, "seed": 6}))
    return root


def test_same_seed_same_dataset_whatever_the_workers(tiny):
    a, b = load_dataset(tiny / "one"), load_dataset(tiny / "two")
    np.testing.assert_array_equal(a.features, b.features)
    assert a.meta.splits == b.meta.splits
    for i in range(len(a)):
        ta, tb = a.load(i), b.load(i)
        np.testing.assert_array_equal(ta.observations, tb.observations)
        np.testing.assert_array_equal(ta.qpos, tb.qpos)
        assert ta.controller_params == tb.controller_params and ta.seed == tb.seed


def test_dataset_content(tiny):
    ds = load_dataset(tiny / "one")
    t = ds.load(0)
    assert t.observations.shape == (60, 39) and t.actions.shape == (60, 4) and t.qpos.shape[0] == 60
    assert np.isfinite(ds.features).all()
    assert {"numpy", "mujoco", "metaworld"} <= set(ds.meta.config["made_with"])  # the stack that rolled them out
    assert len({tuple(ds.load(i).controller_params.values()) for i in range(len(ds))}) == len(ds)
    d = describe(tiny / "one")
    assert d["num_trajectories"] == 6 and d["splits"] == {"train": 4, "val": 1, "test": 1}
    assert len(d["feature_correlation"]) == 3 and set(d["features"]["speed"]) == {"min", "max", "mean", "std"}


def test_inspect_prints_a_checksum_that_same_seed_generations_share(tiny, capsys):
    """Two generations with one seed (one worker and two, so meta.json's wall time and workers differ, and the files'
    times) print one checksum; another seed another."""
    sums = {}
    for name in ("one", "two", "other"):
        assert main(["inspect", str(tiny / name), "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert {"num_trajectories", "horizon", "splits", "features", "feature_correlation"} <= set(out)
        assert out["env_version"] == 2
        sums[name] = out["checksum"]
        assert len(sums[name]) == 64 and int(sums[name], 16) >= 0
    assert sums["one"] == sums["two"]
    assert sums["other"] != sums["one"]


def test_the_checksum_hashes_content_not_files(tiny, tmp_path):
    """Rewriting a trajectory file (uncompressed, newer time) keeps the checksum; one changed observation moves it,
    and only the trajectories' part."""
    root = tmp_path / "copy"
    shutil.copytree(tiny / "one", root)
    before = checksum_parts(load_dataset(root))
    path = root / "trajectories" / "000003.npz"
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    np.savez(path, **arrays)
    os.utime(path, (1e9, 1e9))
    assert checksum_parts(load_dataset(root)) == before
    arrays["observations"][10, 36] += 1e-6
    np.savez_compressed(path, **arrays)
    after = checksum_parts(load_dataset(root))
    assert {k for k in before if before[k] != after[k]} == {"trajectories"}
    assert dataset_checksum(load_dataset(root)) != dataset_checksum(load_dataset(tiny / "one"))


def test_inspect_says_when_a_dataset_predates_the_simulator(tiny, tmp_path):
    """A Meta-World dataset made before the goal-slot fix records no env_version: inspect says to regenerate it."""
    root = tmp_path / "old"
    shutil.copytree(tiny / "one", root)
    meta = json.loads((root / "meta.json").read_text())
    del meta["config"]["env_version"]
    (root / "meta.json").write_text(json.dumps(meta))
    old, new = describe(root), describe(tiny / "one")
    assert (old["env_version"], old["env_version_current"]) == (None, 2)
    assert "made by version 1 of the metaworld simulator" in format_description(old)
    assert (new["env_version"], new["env_version_current"]) == (2, 2)
    assert "made by version" not in format_description(new)


def test_refuses_to_overwrite(tiny):
    with pytest.raises(LangprefError, match="--force"):
        generate(GenerateConfig(env="metaworld", out=tiny / "one", num_trajectories=6, horizon=60, seed=5))


@pytest.mark.parametrize(
    "field, message", [("num_trajectories", "at least 3"), ("horizon", "at least 2"), ("workers", "at least 1")]
)
def test_a_zero_option_is_refused_not_taken_for_the_default(tmp_path, field, message):
    with pytest.raises(LangprefError, match=message):
        GenerateConfig(env="metaworld", out=tmp_path / "d", **{field: 0}).resolved()
    assert GenerateConfig(env="metaworld", out=tmp_path / "d").resolved().num_trajectories == 324
