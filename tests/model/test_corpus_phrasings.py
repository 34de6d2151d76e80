"""The train phrasings extended by the comparative corpus's sentences of tied concepts (`--corpus-phrasings`)."""

import json

from langpref.language.bank import normalise
from langpref.language.corpus import _sentences, generate
from langpref.language.corpus_phrasings import tied_phrasings
from langpref.language.lexicon import load_lexicon
from langpref.model.train import Trainer, train
from tests.factories import tiny_config


def test_tied_sentences_take_the_ties_direction_and_the_features_object():
    out = tied_phrasings(["gripper_opening", "distance_to_charger", "lift_success"], 6)
    assert set(out) == {"gripper_opening", "distance_to_charger"}  # lift_success ties to no concept
    grip = generate(0, 12, ["grip"])  # the corpus's grip grows as the fingers close: gripper_opening's sign is -1
    closing = {e.text for e in grip if e.direction == "increase"}
    opening = {e.text for e in grip if e.direction == "decrease"}
    assert len(out["gripper_opening"]["increase"]) == 6 and set(out["gripper_opening"]["increase"]) <= opening
    assert set(out["gripper_opening"]["decrease"]) <= closing
    charger = out["distance_to_charger"]  # an object no lexicon list names: every sentence is about it
    assert all("charger" in t for d in ("increase", "decrease") for t in charger[d])
    assert "charger" not in json.dumps(load_lexicon()["objects"])
    first = charger["increase"][0]
    again = tied_phrasings(["distance_to_charger"], 6, exclude=[first])["distance_to_charger"]["increase"]
    assert first not in again and len(again) == 6  # an excluded text is dropped and the next one fills its place
    assert tied_phrasings(["gripper_opening"], 0) == {}


def test_the_option_extends_the_train_phrasings_only_and_the_checkpoint_records_it(tiny_data, phrasings, tmp_path):
    train_phr, val_phr = phrasings
    trainer = Trainer(tiny_config(tiny_data, tmp_path / "m", corpus_phrasings=3), *phrasings, progress=False)
    added = set(trainer.train_phr.texts) - set(train_phr.texts)
    assert len(added) == 3 * 2 * 3  # metaworld's three features all tie: height, speed, distance to the button
    assert trainer.val_phr is val_phr and trainer.bank_train_phr is train_phr  # val and the prototypes unchanged
    assert not {normalise(t) for t in added} & {normalise(t) for t in val_phr.texts}
    mapping = trainer.train_phr.as_mapping()
    farther = set(mapping["distance_to_button"]["increase"]) - set(
        train_phr.as_mapping()["distance_to_button"]["increase"]
    )
    assert len(farther) == 3 and all("button" in t for t in farther)
    lex = load_lexicon()
    made = {
        d: {t for by_kind in _sentences(lex, lex["concepts"]["distance"], d).values() for t in by_kind}
        for d in ("increase", "decrease")
    }
    assert farther <= made["increase"] and not farther & made["decrease"]  # the corpus's "farther", about the button
    assert Trainer(tiny_config(tiny_data, tmp_path / "d"), *phrasings, progress=False).cfg.corpus_phrasings == 0

    cfg = tiny_config(tiny_data, tmp_path / "saved", corpus_phrasings=2, stage1_epochs=1, stage2_epochs=0)
    result = train(cfg, train_phrasings=train_phr, val_phrasings=val_phr, progress=False)
    saved = json.loads((result.out / "config.json").read_text())
    assert saved["train_config"]["corpus_phrasings"] == 2
    assert result.results["train_phrasings"] == len(train_phr.texts) + 2 * 2 * 3
