"""The simulated world: feature normalisation, phrase tables, the perfect and toy latent spaces."""

from __future__ import annotations

import numpy as np
import pytest

from langpref.errors import LangprefError
from langpref.feedback import FeatureScale, perfect_encoder, toy_latent_space
from langpref.language.bank import load_bank


def test_feature_scale_uses_given_rows():
    feats = np.array([[1.0, 10.0], [3.0, 10.0], [100.0, -5.0]])
    scale = FeatureScale.fit(feats[:2])
    assert np.allclose(scale(feats[:2]), [[-1.0, 0.0], [1.0, 0.0]])  # a constant feature keeps std 1
    with pytest.raises(LangprefError):
        FeatureScale.fit(feats[:1])


def test_perfect_encoder_maps_meanings_to_signed_axes():
    bank = load_bank("metaworld")
    enc = perfect_encoder(bank.features, bank)
    text = bank.get("test", "distance_to_button", "decrease")[0]
    assert np.array_equal(enc([text])[0], [0.0, 0.0, -1.0])
    with pytest.raises(LangprefError):
        enc(["Dance a little."])


def test_toy_space_is_an_isometric_perfect_space():
    small, big = toy_latent_space(n=30, seed=1), toy_latent_space(n=30, dim=64, seed=1)
    assert big.phi.shape == (30, 64) and big.table("train").psi.shape[1] == 64
    i, j = 0, 1
    # psi . (phi_j - phi_i) equals the feature difference, in any embedding dimension
    text = big.table("test").texts[0]
    f = big.table("test").feature[0]
    sign = 1 if big.table("test").direction[0] == 0 else -1
    for space in (small, big):
        delta = space.psi_of(text) @ (space.phi[j] - space.phi[i])
        assert np.isclose(delta, sign * (space.theta[j, f] - space.theta[i, f]))
    assert set(small.splits["train"]).isdisjoint(small.splits["test"])
    with pytest.raises(LangprefError):
        small.psi_of("no such phrasing")
    with pytest.raises(LangprefError):
        small.table("val")  # only the test and train phrasings were embedded
    with pytest.raises(LangprefError):
        small.split("nope")


def test_a_language_human_can_speak_from_an_utterance_file(tmp_path):
    """--phrasings FILE: the space embeds the file's phrasings (in the oracle space, as the file labels them) and
    the language human says only those; a text the file and the bank file under different meanings is refused."""
    import json

    from langpref.feedback import HumanConfig, LanguageHuman, LanguageQuery, load_space
    from tests.factories import write_dataset

    data = write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True)
    mine = {
        "speed": {"increase": ["Zoom zoom."], "decrease": ["Easy, tiger."]},
        "height": {"increase": ["Up you go."], "decrease": ["Get down."]},
    }
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"metaworld": mine}))
    space = load_space(data, perfect=True, phrasings=path)
    human = HumanConfig(phrasings=str(path))
    table = space.table(human.phrase_source)
    assert set(table.texts) == {"Zoom zoom.", "Easy, tiger.", "Up you go.", "Get down."}
    speed = space.feature_names.index("speed")
    assert np.allclose(table.psi[table.texts.index("Easy, tiger.")][:3], -np.eye(3)[speed])
    w = np.zeros(3)
    w[speed] = 1.0  # wants speed only: every answer is a speed phrasing of the file
    test = space.split("test")
    said = {
        LanguageHuman(w, space.theta, table, test, space.feature_names, temperature=0.05, seed=s)
        .answer(LanguageQuery(int(test[np.argmin(space.theta[test, speed])])))
        .text
        for s in range(5)
    }
    assert said == {"Zoom zoom."}
    assert load_space(data, perfect=True).table("val")  # every bank split is embedded, val included
    path.write_text(json.dumps({"metaworld": {"speed": {"increase": ["Move slower."]}}}))
    with pytest.raises(LangprefError, match="two meanings"):
        load_space(data, perfect=True, phrasings=path)


def test_the_all_table_is_every_bank_split_in_order(tmp_path):
    """--phrasing-split all (the paper's human): train, val and test phrasings with their meanings and psi."""
    from langpref.feedback import load_space
    from tests.factories import write_dataset

    space = load_space(write_dataset(tmp_path / "d", n=40, horizon=10, like_task=True), perfect=True)
    parts = [space.table(s) for s in ("train", "val", "test")]
    every = space.table("all")
    assert every.texts == parts[0].texts + parts[1].texts + parts[2].texts
    assert np.array_equal(every.group, np.concatenate([p.group for p in parts]))
    assert np.allclose(every.psi, np.concatenate([p.psi for p in parts]))
    with pytest.raises(LangprefError, match="no phrasings of 'holdout'"):
        space.table("holdout")
