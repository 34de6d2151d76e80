"""Negation as a sign flip (langpref.language.negation, LatentModel.encode_texts): the detector flags and strips the
negations it is meant for and leaves the rest alone; a model with the setting on reads a negated request as the
opposite of the request; the setting travels with the checkpoint and can be overridden where a model is loaded."""

from __future__ import annotations

import json
import shutil

import pytest
import torch

from langpref.cli import main
from langpref.language.negation import detect, detect_all
from langpref.model.checkpoint import load_model
from langpref.model.config import ModelConfig
from langpref.model.evaluate import embed_text

FLIPPED = [
    ("Don't go so fast.", "Go fast."),
    ("Do not move faster.", "Move faster."),
    ("Please don't stay up in the air.", "Please stay up in the air."),
    ("Never swing that high above the table.", "Swing high above the table."),
    ("No need to rush.", "Rush."),
    ("There's no need to hurry.", "Hurry."),
    ("Try not to sink down.", "Try to sink down."),
    ("Go no higher.", "Go higher."),
    ("Go nowhere near the bottle.", "Go near the bottle."),
    ("Stop hugging the table so much.", "Keep hugging the table."),
    ("Quit keeping away from the button.", "Keep away from the button."),
    ("No rushing.", "Keep rushing."),
    ("You shouldn't have picked up the block.", "You should have picked up the block."),
    ("You weren't supposed to lift the cube.", "You were supposed to lift the cube."),
    ("I don't want the block in the air.", "I want the block in the air."),
    ("No, don't go so fast.", "Go fast."),
    ("Don\u2019t dawdle.", "Dawdle."),
    ("Don't rush, please.", "Rush, please."),
    ("Don't go too fast.", "Go fast."),
]

LEFT_ALONE = [
    ("Move slower.", "none"),
    ("Avoid the button.", "none"),
    ("Less height.", "none"),
    ("Stop.", "none"),
    ("Stop at the button.", "none"),
    ("No, go faster.", "none"),
    ("Can't you go faster?", "rhetorical"),
    ("Why don't you speed up?", "rhetorical"),
    ("Why not go faster?", "rhetorical"),
    ("Won't you speed up", "rhetorical"),
    ("I can't believe how slow you are.", "rhetorical"),
    ("Don't stop rushing.", "double"),
    ("Don't go nowhere near it.", "double"),
    ("You're not going fast enough.", "enough"),
    ("It's not open enough.", "enough"),
    ("It isn't open.", "description"),
    ("You didn't lift the block.", "description"),
    ("Don't be so slow.", "state"),
    ("No need to be so close to the cube.", "state"),
    ("Not so far from the bottle.", "state"),
    ("Don't hold back, go faster.", "mixed"),
    ("Go low, not high.", "mixed"),
    ("Don't wait. Lift it.", "mixed"),
]


@pytest.mark.parametrize(("text", "stripped"), FLIPPED)
def test_a_scoped_negation_is_flagged_and_stripped(text, stripped):
    found = detect(text)
    assert (found.flip, found.reason, found.text) == (True, "negated", stripped)


@pytest.mark.parametrize(("text", "reason"), LEFT_ALONE)
def test_non_negations_and_exclusions_are_left_alone(text, reason):
    found = detect(text)
    assert (found.flip, found.reason, found.text) == (False, reason, text)


def test_detect_all_keeps_the_order():
    texts = ["Move faster.", "Don't move faster.", "Why don't you move faster?"]
    assert [n.flip for n in detect_all(texts)] == [False, True, False]


def _psi(model, texts: list[str], negation: bool) -> torch.Tensor:
    model.negation = negation
    return model.encode_texts(texts).double()


def test_the_setting_reads_a_negation_as_the_opposite_of_its_request(trained):
    model = load_model(trained.out)
    plain = _psi(model, ["Move faster.", "Go lower, please"], negation=True)
    mixed = ["Don't move faster.", "Move faster.", "Never go lower, please", "Go lower, please"]
    on, off = _psi(model, mixed, negation=True), _psi(model, mixed, negation=False)
    assert torch.allclose(on[0], -plain[0], atol=1e-5) and torch.allclose(on[2], -plain[1], atol=1e-5)
    assert torch.allclose(on[1], plain[0], atol=1e-5) and torch.allclose(on[3], off[3], atol=1e-5)  # unflagged as is
    assert not torch.allclose(off[0], -plain[0], atol=1e-3)  # without the setting the encoder reads the words
    model.negation = True
    said, negated = embed_text(model, "Move faster."), embed_text(model, "Don't move faster.")
    assert (said["feature"], said["direction"]) == ("speed", "increase")
    assert negated["scores"] == pytest.approx({k: -v for k, v in said["scores"].items()}, abs=1e-5)
    assert negated["scores"]["speed/decrease"] > negated["scores"]["speed/increase"]


def test_prototypes_do_not_depend_on_the_setting(trained, phrasings):
    model = load_model(trained.out)
    before = model.prototypes.clone()
    model.negation = True
    model.set_prototypes(phrasings[0])
    assert torch.allclose(model.prototypes, before, atol=1e-5)


def test_the_checkpoint_round_trips_the_setting(trained, tmp_path):
    from langpref.model.checkpoint import _description, save_model

    model = load_model(trained.out)
    model_cfg, _ = _description(trained.out, model.config)
    model.negation = False
    out = save_model(model, tmp_path / "off", model_cfg=model_cfg, lang_finetuned=True)
    assert json.loads((out / "config.json").read_text())["model"]["negation"] is False
    assert load_model(out).negation is False
    assert load_model(out, negation=True).negation is True  # a reader's override


def test_a_checkpoint_from_before_the_setting_loads_with_the_default(trained, tmp_path):
    old = tmp_path / "old"
    shutil.copytree(trained.out, old)
    cfg = json.loads((old / "config.json").read_text())
    del cfg["model"]["negation"]
    (old / "config.json").write_text(json.dumps(cfg))
    assert load_model(old).negation is ModelConfig().negation
    assert load_model(old, negation=not ModelConfig().negation).negation is not ModelConfig().negation


def _evaluate(capsys, model, data, path, mapping: dict, *flags: str) -> dict:
    path.write_text(json.dumps({"metaworld": mapping}))
    argv = ["evaluate", "--model", str(model), "--data", str(data), "--utterances", str(path), *flags, "--json"]
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("flag", ["--negation", "--no-negation"])
def test_evaluate_and_embed_take_the_setting(trained, tiny_data, tmp_path, capsys, flag):
    assert main(["embed", "--model", str(trained.out), "Move faster.", "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert main(["embed", "--model", str(trained.out), "Don't move faster.", flag, "--json"]) == 0
    read = json.loads(capsys.readouterr().out)
    opposite = {k: -v for k, v in said["scores"].items()}
    assert (read["scores"] == pytest.approx(opposite, abs=1e-5)) == (flag == "--negation")
    if flag == "--negation":  # the reading says what the flip did
        assert read["negation"] == {"flipped": True, "reason": "negated", "read_as": "Move faster."}
    else:
        assert "negation" not in read
    # with the flip, "Don't move faster." as slower orders every pair as "Move faster." as faster does, reversed
    plain = _evaluate(capsys, trained.out, tiny_data, tmp_path / "p.json", {"speed": {"increase": ["Move faster."]}})
    negated = {"speed": {"decrease": ["Don't move faster."]}}
    got = _evaluate(capsys, trained.out, tiny_data, tmp_path / "n.json", negated, flag)
    assert (got["accuracy"] == pytest.approx(plain["accuracy"])) == (flag == "--negation")
