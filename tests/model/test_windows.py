"""Windows of train episodes as extra training trajectories (`TrainConfig.windows`, `langpref.model.windows`)."""

import numpy as np
import pytest
import torch

from langpref.errors import LangprefError
from langpref.model.train import Trainer, train
from langpref.model.windows import sample_windows, segment_steps, whole_episodes, window_features
from tests.factories import tiny_config


def test_window_features_are_the_time_mean_of_the_windows_steps():
    rng = np.random.default_rng(3)
    episodes = [rng.normal(size=(t, 3)) for t in (9, 20, 4)]
    w = sample_windows(episodes, 5, 0.3, rng)
    assert len(w) == 15 and list(w.row) == [0] * 5 + [1] * 5 + [2] * 5
    for i in range(len(w)):
        steps = episodes[w.row[i]]
        assert 2 <= w.length[i] <= len(steps) and w.start[i] + w.length[i] <= len(steps)
        assert w.length[i] >= np.ceil(0.3 * len(steps))
        expected = steps[w.start[i] : w.start[i] + w.length[i]].mean(axis=0)
        assert np.allclose(w.features[i], expected, atol=1e-12)
        assert np.allclose(window_features(steps, w.start[i], w.length[i]), expected)
    whole = whole_episodes([9, 20, 4], np.stack([e.mean(axis=0) for e in episodes]))
    assert list(whole.start) == [0, 0, 0] and list(whole.length) == [9, 20, 4]
    with pytest.raises(LangprefError, match="window_min_fraction"):
        sample_windows(episodes, 1, 0.0, rng)


def test_segment_steps_pick_each_windows_own_steps():
    episodes = [np.arange(10.0)[:, None], np.arange(6.0)[:, None]]
    windows = sample_windows(episodes, 3, 0.2, np.random.default_rng(0))
    segs = whole_episodes([10, 6], np.array([[4.5], [2.5]])) + windows
    items = np.arange(len(segs))
    rows, steps, lens = segment_steps(segs, items, None)
    assert list(lens) == list(segs.length)
    for i in items:  # the real steps of each segment, then its last step repeated
        real = steps[i, : lens[i]]
        assert list(real) == list(range(segs.start[i], segs.start[i] + segs.length[i]))
        assert np.all(steps[i, lens[i] :] == segs.start[i] + segs.length[i] - 1)
    t = np.zeros((len(items), 2), dtype=np.int64)
    t[:, 1] = segs.length - 1
    _, picked, none = segment_steps(segs, items, t)
    assert none is None and np.all(picked[:, 0] == segs.start) and np.all(picked[:, 1] == segs.start + segs.length - 1)


def test_windows_come_from_train_episodes_only_and_carry_their_features(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", windows=3), *phrasings, progress=False)
    n_train = len(trainer.dataset.split("train"))
    before = len(trainer.train.pairs)
    trainer._resample_windows()
    segs = trainer.train.segments
    assert segs is not None and len(segs) == 4 * n_train
    assert segs.row.min() >= 0 and segs.row.max() < n_train  # rows of the train split, nothing else
    assert len(trainer.train.pairs) > 4 * before
    assert trainer.val.segments is None and trainer.val.step_features is None
    train_idx = trainer.dataset.split("train")
    for i in range(n_train, len(segs)):
        steps = trainer.dataset.load(train_idx[segs.row[i]]).step_features
        assert np.allclose(segs.features[i], steps[segs.start[i] : segs.start[i] + segs.length[i]].mean(axis=0))
    # phi of a window with every step equals the encoder on that window alone
    trainer.cfg.time_samples = 0
    item = n_train + 1
    with torch.no_grad():
        phi = trainer._phi_segments(trainer.train, np.array([item]))
        r, s, n = segs.row[item], segs.start[item], segs.length[item]
        alone = trainer.model.traj(trainer.train.steps[r : r + 1, s : s + n])
    assert torch.allclose(phi, alone, atol=1e-5)


def test_training_with_windows_runs_and_is_deterministic_for_a_seed(tiny_data, phrasings, tmp_path):
    def run(name: str, seed: int = 0):
        cfg = tiny_config(tiny_data, tmp_path / name, stage1_epochs=2, freeze_language=True, windows=2, seed=seed)
        return train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)

    a, b = run("a"), run("b")
    strip = [[{k: v for k, v in h.items() if k != "seconds"} for h in r.history] for r in (a, b)]
    assert strip[0] == strip[1] and len(strip[0]) == 2
    sa, sb = a.model.state_dict(), b.model.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert a.results["train_windows"] == 2 * 10  # 2 windows of each of the 10 train episodes
    other = run("c", seed=1)
    assert not torch.equal(other.model.traj.out.weight, a.model.traj.out.weight)
    with pytest.raises(LangprefError, match="windows"):
        train(tiny_config(tiny_data, tmp_path / "bad", windows=-1), progress=False)


def test_a_model_that_sees_images_encodes_windows_with_their_own_frames(image_data, phrasings, tmp_path):
    cfg = tiny_config(image_data, tmp_path / "img", windows=2, frame_pretrain_steps=0)
    trainer = Trainer(cfg, *phrasings, progress=False)
    trainer._resample_windows()
    segs = trainer.train.segments
    item = len(trainer.dataset.split("train")) + 3  # a window
    trainer.cfg.image_time_samples = 0  # every step of the window
    trainer.model.traj.eval()
    with torch.no_grad():
        phi = trainer._phi_segments(trainer.train, np.array([item]))
        r, s, n = int(segs.row[item]), int(segs.start[item]), int(segs.length[item])
        rows = torch.tensor([r])
        t = torch.arange(s, s + n).unsqueeze(0)
        alone = trainer.model.traj(trainer.train.steps[rows.unsqueeze(1), t], **trainer.train.frame_args(rows, t))
    assert torch.allclose(phi, alone, atol=1e-5)
