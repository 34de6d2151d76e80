"""An interrupted `generate` resumes without rolling out again what is on disk, and ends with the same dataset.

This test needs only the simulator, not Ray (it used to sit in tests/test_backends.py, behind that module's
`importorskip("ray")`, and so was skipped wherever Ray was not installed).
"""

import numpy as np

from langpref.dataset.generate import GenerateConfig, generate
from langpref.dataset.storage import load_dataset


def test_rerun_skips_what_is_done(tmp_path):
    cfg = GenerateConfig(env="metaworld", out=tmp_path / "d", num_trajectories=4, horizon=30, workers=1, seed=2)
    generate(cfg)
    first = load_dataset(tmp_path / "d")
    observations = [first.load(i).observations for i in range(len(first))]
    (tmp_path / "d" / "meta.json").unlink()  # as if interrupted before the end
    stamp = (tmp_path / "d" / "trajectories" / "000001.npz").stat().st_mtime_ns
    summary = generate(cfg)
    assert (tmp_path / "d" / "trajectories" / "000001.npz").stat().st_mtime_ns == stamp
    assert summary["steps_per_s"] is None  # nothing was rolled out again
    np.testing.assert_array_equal(load_dataset(tmp_path / "d").features, first.features)

    (tmp_path / "d" / "meta.json").unlink()  # interrupted earlier: one rollout never written
    (tmp_path / "d" / "trajectories" / "000002.npz").unlink()
    summary = generate(cfg)
    assert summary["steps_per_s"] is not None  # the missing one was rolled out
    assert (tmp_path / "d" / "trajectories" / "000001.npz").stat().st_mtime_ns == stamp  # the others were not
    again = load_dataset(tmp_path / "d")
    np.testing.assert_array_equal(again.features, first.features)
    for i in range(len(again)):
        np.testing.assert_array_equal(again.load(i).observations, observations[i])
