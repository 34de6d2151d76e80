import json

import numpy as np
import pytest

from langpref.dataset.storage import load_dataset, trajectory_path
from langpref.errors import LangprefError


def test_round_trip(synthetic_dataset):
    ds = load_dataset(synthetic_dataset, env="metaworld")
    assert len(ds) == 12 and ds.feature_names == ["height", "speed", "distance_to_button"]
    traj = ds.load(4)
    np.testing.assert_allclose(ds.features[4], traj.features, rtol=1e-6)
    obs, act = ds.arrays("train")
    assert obs.shape == (len(ds.split("train")), 20, 39) and act.shape[-1] == 4
    assert traj.controller_params == {"i": 4}


def test_wrong_env(synthetic_dataset):
    with pytest.raises(LangprefError, match="metaworld dataset, but robosuite"):
        load_dataset(synthetic_dataset, env="robosuite")


def test_missing_dir(tmp_path):
    with pytest.raises(LangprefError, match="does not exist"):
        load_dataset(tmp_path / "nope")


def test_wrong_schema(synthetic_dataset):
    meta = json.loads((synthetic_dataset / "meta.json").read_text())
    meta["schema_version"] = 99
    (synthetic_dataset / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(LangprefError, match="schema version 99"):
        load_dataset(synthetic_dataset)


def test_corrupt_meta(synthetic_dataset):
    (synthetic_dataset / "meta.json").write_text("{not json")
    with pytest.raises(LangprefError, match="not valid JSON"):
        load_dataset(synthetic_dataset)


def test_truncated_trajectory(synthetic_dataset):
    path = trajectory_path(synthetic_dataset, 2)
    path.write_bytes(path.read_bytes()[:100])
    ds = load_dataset(synthetic_dataset)
    with pytest.raises(LangprefError, match="truncated or corrupt"):
        ds.load(2)


def test_mismatched_features_table(synthetic_dataset):
    np.save(synthetic_dataset / "features.npy", np.zeros((5, 3)))
    with pytest.raises(LangprefError, match="features.npy has shape"):
        load_dataset(synthetic_dataset)


def test_unknown_split(synthetic_dataset):
    with pytest.raises(LangprefError, match="no split 'tset'"):
        load_dataset(synthetic_dataset).split("tset")


def test_schema_1_datasets_still_load(synthetic_dataset):
    """A dataset written before schema 2 (every trajectory simulated, one length) reads as it did."""
    meta = json.loads((synthetic_dataset / "meta.json").read_text())
    meta["schema_version"] = 1
    for key in ("lengths", "videos"):
        meta.pop(key)
    (synthetic_dataset / "meta.json").write_text(json.dumps(meta))
    ds = load_dataset(synthetic_dataset)
    assert ds.meta.schema_version == 1 and ds.lengths("train") is None and ds.video_path(0) is None
    traj = ds.load(3)
    assert traj.seed == 3 and traj.qpos.shape == (20, 2) and traj.source is None


def test_trajectories_of_different_lengths_pad_with_their_last_step(synthetic_dataset):
    from langpref.dataset.storage import Trajectory, save_trajectory

    meta = json.loads((synthetic_dataset / "meta.json").read_text())
    lengths = [20] * 12
    lengths[5] = 7
    traj = load_dataset(synthetic_dataset).load(5)
    short = Trajectory(
        5, traj.observations[:7], traj.actions[:7], traj.step_features[:7], None, None, True, None, source="episode-5"
    )
    save_trajectory(synthetic_dataset, short)
    meta["lengths"] = lengths
    (synthetic_dataset / "meta.json").write_text(json.dumps(meta))
    ds = load_dataset(synthetic_dataset)
    obs, _ = ds.arrays(None)
    assert obs.shape[1] == 20 and ds.lengths(None)[5] == 7
    np.testing.assert_array_equal(obs[5, 7:], np.repeat(obs[5, 6:7], 13, axis=0))
    assert ds.load(5).source == "episode-5" and ds.load(5).qpos is None


def test_lengths_that_do_not_fit_the_horizon(synthetic_dataset):
    meta = json.loads((synthetic_dataset / "meta.json").read_text())
    meta["lengths"] = [5] * 12
    (synthetic_dataset / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(LangprefError, match="'lengths'"):
        load_dataset(synthetic_dataset)
