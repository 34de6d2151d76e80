"""Models that see camera frames: the image encoder learns what only the pixels show, round-trips through a
checkpoint, and refuses data without frames (or with other frames) in one line."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
import torch

from langpref.dataset.storage import load_dataset
from langpref.errors import LangprefError
from langpref.model.checkpoint import load_model
from langpref.model.evaluate import evaluate_split
from langpref.model.inputs import dataset_input, resolve_observations, trajectories_input
from langpref.model.vision import ImageTrajectoryEncoder
from tests.factories import make_image_dataset, tiny_config


def _train(data, out, phrasings, observations):
    from langpref.model.train import train

    cfg = tiny_config(data, out, stage1_epochs=12, stage1_batch_size=128, freeze_language=True)
    cfg.model.observations = observations
    return train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)


@pytest.fixture(scope="module")
def squares(tmp_path_factory):
    return make_image_dataset(tmp_path_factory.mktemp("squares") / "data", n=48)


@pytest.fixture(scope="module")
def image_model(squares, phrasings, tmp_path_factory):
    return _train(squares, tmp_path_factory.mktemp("image-model") / "m", phrasings, "images")


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text
    return text


def test_the_image_encoder_learns_what_only_the_pixels_show(image_model, squares, phrasings, tmp_path):
    """Where the square is and how red it is are the features; the observations are noise."""
    history = image_model.history
    assert history[-1]["loss"] < 0.7 * history[0]["loss"]
    # (the first epoch already follows the CNN's episode-contrastive pretraining, so it starts well above chance)
    assert image_model.results["best_val_accuracy"] > 0.65, [round(h["val_acc"], 3) for h in history]
    dataset = load_dataset(squares)
    seen = evaluate_split(image_model.model, dataset, "test", phrasings[0])["accuracy"]
    state = _train(squares, tmp_path / "state", phrasings, "state")  # the same data without the pixels: chance
    blind = evaluate_split(state.model, dataset, "test", phrasings[0])["accuracy"]
    assert state.results["best_val_accuracy"] < 0.6 and blind < 0.6
    assert seen > 0.75 and seen > blind + 0.2  # measured: 0.86 and 0.40


def test_an_image_checkpoint_round_trips(image_model, squares):
    dataset = load_dataset(squares)
    loaded = load_model(image_model.out, dataset=dataset)
    assert loaded.observations == "images" and loaded.sees_images
    assert torch.equal(loaded.encode_dataset(dataset, "test"), image_model.model.encode_dataset(dataset, "test"))
    cfg = json.loads((image_model.out / "config.json").read_text())
    assert cfg["model"]["observations"] == "images" and cfg["model"]["frame_channels"] == [16, 32, 32]
    assert cfg["data"]["frames"] == {"width": 32, "height": 32, "stride": 2, "source": "render"}
    assert cfg["data"]["schema_version"] == 3 and len(cfg["normalisation"]["mean"]) == 2  # the actions alone
    obs, act = dataset.arrays("test")
    frames = dataset.frames("test")
    assert torch.equal(loaded.encode_trajectories(obs, act, frames=frames), loaded.encode_dataset(dataset, "test"))
    with pytest.raises(LangprefError, match="sees camera frames") as info:
        loaded.encode_trajectories(obs, act)
    _one_line(info)
    with pytest.raises(LangprefError, match=r"\(16, 16\) given, the model was trained on 32 x 32") as info:
        loaded.encode_trajectories(obs, act, frames=frames[:, :, :16, :16])
    _one_line(info)
    with pytest.raises(LangprefError, match="K >= 4") as info:
        loaded.encode_trajectories(obs, act, frames=frames[:, :2])
    _one_line(info)


def test_an_image_model_refuses_a_dataset_without_frames_or_with_other_frames(image_model, squares, tmp_path):
    bare = tmp_path / "bare"
    shutil.copytree(squares, bare)
    meta = json.loads((bare / "meta.json").read_text())
    del meta["frames"]
    (bare / "meta.json").write_text(json.dumps({**meta, "schema_version": 2}))
    with pytest.raises(LangprefError, match="has none") as info:
        load_model(image_model.out, dataset=load_dataset(bare))
    _one_line(info)
    meta["frames"] = {"width": 16, "height": 16, "stride": 2, "source": "render"}
    (bare / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(LangprefError, match="16x16 frames.*--frame-size 32,32") as info:
        load_model(image_model.out, dataset=load_dataset(bare))
    _one_line(info)


def test_training_on_images_needs_frames_and_defaults_to_them(tiny_data, squares, phrasings, tmp_path):
    with pytest.raises(LangprefError, match="needs camera frames") as info:
        _train(tiny_data, tmp_path / "m", phrasings, "images+state")
    _one_line(info)
    assert not (tmp_path / "m").exists()
    assert resolve_observations(None, True, "d") == "images+state" and resolve_observations(None, False, "d") == "state"
    with pytest.raises(LangprefError, match="must be one of state, images, images\\+state"):
        resolve_observations("pixels", True, "d")


def test_padding_and_frame_sampling_do_not_change_phi(squares):
    """A trajectory padded to a longer horizon embeds as its own steps; the training path that passes only the
    frames of the sampled steps gives what indexing all frames gives."""
    torch.manual_seed(0)
    inp = dataset_input(load_dataset(squares), "train", "images+state", True)
    enc = ImageTrajectoryEncoder(inp.steps.shape[-1], [16], 8, "images+state", (4, 8), 8, observation_deltas=True)
    steps, frames = torch.from_numpy(inp.steps[:2]), torch.from_numpy(inp.frames[:2])
    index = torch.from_numpy(inp.frame_index[:2])
    short = enc(steps[:1, :5], None, frames[:1], index[:1, :5])
    both = enc(steps, torch.tensor([5, 8]), frames, index)
    torch.testing.assert_close(both[0], short[0])
    t = torch.tensor([[0, 3, 6], [1, 2, 7]])
    rows = torch.arange(2)
    shown = index[rows.unsqueeze(1), t]
    sampled = enc(steps[rows.unsqueeze(1), t], None, frames[rows.unsqueeze(1), shown], torch.arange(3).expand(2, 3))
    torch.testing.assert_close(sampled, enc(steps[rows.unsqueeze(1), t], None, frames, shown))


def test_frames_of_another_number_of_trajectories_are_refused():
    """One frame stack per trajectory: more stacks than trajectories, or too few frames, is a one-line error."""
    obs, act = np.zeros((2, 6, 3)), np.zeros((2, 6, 1))
    ok = np.zeros((2, 3, 8, 8, 3), dtype=np.uint8)
    assert trajectories_input(obs, act, "images", False, frames=ok, frame_stride=2).frames.shape == ok.shape
    for bad in (np.zeros((3, 1, 8, 8, 3), dtype=np.uint8), np.zeros((2, 2, 8, 8, 3), dtype=np.uint8)):
        with pytest.raises(LangprefError) as exc:
            trajectories_input(obs, act, "images", False, frames=bad, frame_stride=2)
        assert "with N = 2 and K >= 3" in _one_line(exc)


def test_frames_are_read_only_when_asked(squares):
    dataset = load_dataset(squares)
    assert dataset.frame_spec is not None and dataset.frame_spec.count(8) == 4
    assert dataset.frames("val").shape == (len(dataset.split("val")), 4, 32, 32, 3)
    assert dataset_input(dataset, "val", "state", True).frames is None
    shown = dataset_input(dataset, "val", "images", True).frame_index[0]
    np.testing.assert_array_equal(shown, [0, 0, 1, 1, 2, 2, 3, 3])


def test_downstream_takes_a_model_of_generated_frames_as_a_state_model(tmp_path, phrasings):
    """Meta-World with rendered frames: training defaults to images+state, and evaluation, the latent space of
    reward learning and new rollouts (rendered as generation renders them) all take the image model."""
    from langpref.dataset.frames import FrameOptions
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.feedback.space import load_space
    from langpref.model.train import train

    frames = FrameOptions(images=True, frame_size=(32, 32), frame_stride=5)
    data = tmp_path / "mw"
    generate(GenerateConfig(env="metaworld", out=data, num_trajectories=20, horizon=10, workers=1, frames=frames))
    cfg = tiny_config(data, tmp_path / "m", stage1_epochs=2, freeze_language=True)
    result = train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)
    model, dataset = result.model, load_dataset(data)
    assert model.observations == "images+state"
    # above chance (0.5) where it trained (0.81 of 1844 pairs at seed 0) and on the test split (0.88 of 16)
    fit, test = (evaluate_split(model, dataset, split, phrasings[0]) for split in ("train", "test"))
    assert fit["accuracy"] > 0.7 and fit["num_samples"] > 1000, fit["accuracy"]
    assert test["accuracy"] > 0.5 and test["num_samples"] > 0, test["accuracy"]
    space = load_space(data, result.out, env="metaworld")
    np.testing.assert_allclose(space.phi, model.encode_dataset(dataset).double().numpy())
    rollouts = [dataset.load(i) for i in dataset.split("test")]
    torch.testing.assert_close(model.encode_rollouts(rollouts), model.encode_dataset(dataset, "test"))
    from langpref.propose import model_embedder

    embed = model_embedder(model)  # generation's embedder renders in one live env, reused between rollouts
    phi = np.stack([embed(t) for t in rollouts + rollouts[:1]])
    np.testing.assert_allclose(phi[:-1], model.encode_dataset(dataset, "test").double().numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(phi[-1], phi[0], rtol=1e-6, atol=1e-6)


def test_an_image_step_draws_its_pairs_among_a_few_trajectories(squares, phrasings, tmp_path):
    """The CNN's cost grows with a step's distinct trajectories: an image model's step takes its pairs among a random
    subset just large enough for its batch, a different one each step, and a state model's from all of them."""
    from langpref.model.train import Trainer

    cfg = tiny_config(squares, tmp_path / "m", stage1_batch_size=64, freeze_language=True)
    cfg.model.observations = "images"
    trainer = Trainer(cfg, phrasings[0], phrasings[1], progress=False)
    n, pairs = len(trainer.train.features), trainer.train.pairs
    m = trainer.step_trajectories(64)
    assert 2 <= m < n
    seen = [np.unique(np.concatenate([pairs.a[rows], pairs.b[rows]])) for rows in trainer._epoch_batches(64, 20)]
    assert len(seen) == 20 and all(len(s) <= m for s in seen)
    assert np.mean([len(rows) for rows in trainer._epoch_batches(64, 20)]) > 0.9 * 64  # batches stay full
    assert len({tuple(s) for s in seen}) > 15  # a fresh subset each step
    state = replace(cfg, model=replace(cfg.model, observations="state"))
    assert Trainer(state, phrasings[0], phrasings[1], progress=False).step_trajectories(64) == n


def test_frame_shift_moves_training_frames_only():
    """--frame-shift moves each training frame by its own whole-pixel offset within the bound, the picture otherwise
    intact; in evaluation (validation and every use of a trained model) frames are not moved."""
    from langpref.model.vision import FrameEncoder, random_shift

    torch.manual_seed(0)
    x = torch.zeros(64, 1, 16, 16)
    x[:, :, 8, 8] = 1.0  # one bright pixel in the middle
    moved = random_shift(x, 3)
    where = torch.stack([torch.nonzero(m[0])[0] for m in moved]) - 8
    assert where.abs().max() <= 3 and len({tuple(w.tolist()) for w in where}) > 10
    assert torch.all(moved.sum(dim=(1, 2, 3)) == 1.0)
    enc = FrameEncoder((4, 8), 8, shift=3)
    frames = torch.randint(0, 255, (5, 16, 16, 3), dtype=torch.uint8)
    enc.eval()
    torch.testing.assert_close(enc(frames), enc(frames))
    enc.train()
    assert not torch.allclose(enc(frames), enc(frames))


def test_the_episode_contrastive_loss_rewards_frames_that_find_their_partner():
    from langpref.model.loss import episode_contrastive_loss

    torch.manual_seed(0)
    z = torch.randn(16, 8)
    matched = episode_contrastive_loss(z, z + 0.05 * torch.randn(16, 8))
    shuffled = episode_contrastive_loss(z, z[torch.randperm(16)])
    assert matched < 0.1 < 2.0 < shuffled


def test_frame_pretraining_teaches_the_cnn_to_tell_the_episodes_apart(squares, phrasings, tmp_path):
    """--frame-pretrain-steps: the episode-contrastive loss alone falls, and afterwards a frame from one half of a
    trajectory finds its trajectory's frame from the other half among all trajectories' more often than before; the
    saved model holds no trace of the auxiliary head, and a state model ignores the option."""
    from langpref.model.train import Trainer, train

    def make(observations: str, steps: int | None, out: str = "m") -> Trainer:
        cfg = tiny_config(squares, tmp_path / out, stage1_epochs=1, freeze_language=True, frame_pretrain_steps=steps)
        cfg.model.observations = observations
        return Trainer(cfg, phrasings[0], phrasings[1], progress=False)

    def retrieval(trainer: Trainer) -> float:
        rows = np.arange(len(trainer.train.features))
        frames = trainer.train.frames[:, [0, -1]]  # first and last kept frame of each trajectory
        with torch.no_grad():
            z = trainer.frame_head(trainer.model.traj.frames(frames.flatten(0, 1))).reshape(len(rows), 2, -1)
        z = torch.nn.functional.normalize(z, dim=-1)
        return float(((z[:, 0] @ z[:, 1].T).argmax(dim=1) == torch.as_tensor(rows)).float().mean())

    trainer = make("images", 80)
    rows = np.arange(len(trainer.train.features))
    before_loss, before = trainer._episode_contrastive(rows).item(), retrieval(trainer)
    trainer.pretrain_frames()
    after_loss, after = trainer._episode_contrastive(rows).item(), retrieval(trainer)
    assert after_loss < 0.7 * before_loss and after > before + 0.2, (before_loss, after_loss, before, after)
    assert trainer.seconds[0] > 0

    cfg = replace(trainer.cfg, frame_contrastive=0.5, out=str(tmp_path / "saved"))
    saved = train(cfg, train_phrasings=phrasings[0], val_phrasings=phrasings[1], progress=False)
    assert set(load_model(saved.out).state_dict()) == set(make("images", 0, "plain").model.state_dict())
    assert make("state", 80, "s").frame_head is None
    # by default on for images+state (the proprioception brings what changes within an episode), off for images alone
    both, alone = make("images+state", None, "b").cfg, make("images", None, "a").cfg
    assert (both.frame_contrastive, alone.frame_contrastive, alone.frame_pretrain_steps) == (1.0, 0.0, 0)
