"""What co-finetuning keeps of the pretrained language model (`langpref.model.keep`)."""

import torch

from langpref.language.bank import normalise
from langpref.model.keep import Anchor, augmented, layer_stack
from langpref.model.train import Trainer
from tests.factories import tiny_config


def test_only_the_top_layers_move_and_the_lower_keep_their_pretrained_weights(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", finetune_layers=2), *phrasings, progress=False)
    transformer = trainer.model.lang.transformer
    stack = layer_stack(transformer)
    before = {k: v.clone() for k, v in transformer.state_dict().items()}
    trainer.stage1()
    trainer.stage2(0.0)
    after = transformer.state_dict()
    moved = {k for k in before if not torch.equal(before[k], after[k])}
    top = {str(len(stack) - 2), str(len(stack) - 1)}
    assert moved, "the top layers learnt nothing"
    assert all(".layer." in k and k.split(".layer.")[1].split(".")[0] in top for k in moved), sorted(moved)[:5]


def test_the_anchor_pulls_the_transformer_toward_its_pretrained_weights(tiny_data, phrasings, tmp_path):
    drift = {}
    for weight in (0.0, 100.0):
        trainer = Trainer(tiny_config(tiny_data, tmp_path / f"m{weight}", lm_anchor=weight), *phrasings, progress=False)
        transformer = trainer.model.lang.transformer
        start = [p.detach().clone() for p in transformer.parameters()]
        trainer.stage1()
        trainer.stage2(0.0)
        drift[weight] = sum(float(((p - p0) ** 2).sum()) for p, p0 in zip(transformer.parameters(), start))
    assert 0 < drift[100.0] < 0.5 * drift[0.0]


def test_anchor_penalty_is_zero_at_the_start_and_grows_with_the_distance():
    w = torch.nn.Parameter(torch.ones(3))
    anchor = Anchor([w], weight=2.0)
    assert float(anchor.penalty().detach()) == 0.0
    with torch.no_grad():
        w += 0.5
    assert float(anchor.penalty().detach()) == 2.0 * 3 * 0.25
    assert Anchor([w], weight=0.0).penalty() == 0.0


def test_augmentation_adds_negations_for_training_and_never_a_val_phrasing(phrasings):
    train, val = phrasings
    more = augmented(train, val, per_meaning=8)
    assert len(more.texts) > len(train.texts)
    assert set(train.texts) <= set(more.texts)
    assert not {normalise(t) for t in more.texts} & {normalise(t) for t in val.texts}
    assert augmented(train, val, per_meaning=0) is train


def test_saved_prototypes_are_the_banks_own_phrasings_not_the_proposals(tiny_data, phrasings, tmp_path):
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", augment_phrasings=8), *phrasings, progress=False)
    assert len(trainer.train_phr.texts) > len(trainer.bank_train_phr.texts)
    assert trainer.bank_train_phr is phrasings[0]


def test_augmentation_is_on_by_default_for_a_small_bank_only(phrasings):
    from langpref.language.pairs import phrasings_from_mapping
    from langpref.model.keep import AUTO_AUGMENT, SMALL_BANK, resolve_augment

    train, _ = phrasings
    assert resolve_augment(None, train) == AUTO_AUGMENT  # a few phrasings per meaning
    big = {
        f: {d: [f"{f} {d} {i}" for i in range(SMALL_BANK)] for d in ("increase", "decrease")}
        for f in train.feature_names
    }
    assert resolve_augment(None, phrasings_from_mapping(big, train.feature_names)) == 0
    assert resolve_augment(0, train) == 0 and resolve_augment(5, train) == 5
