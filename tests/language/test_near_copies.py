"""Near-copies of a bank phrasing in a set written apart: a typo or a swapped word of a same-meaning train phrasing
is one; the same words under the opposite meaning, or a rewording, are not; the scores without them are the
per-phrasing counts of the rest."""

from __future__ import annotations

import pytest

from langpref.language.bank import load_bank
from langpref.language.near_copies import near_copies, similarity
from langpref.language.pairs import phrasings_from_mapping
from langpref.model.evaluate import evaluate_split, summary_only, without_phrasings


@pytest.fixture(scope="module")
def bank():
    return load_bank("metaworld")


def _train_text(bank, feature: str, direction: str) -> str:
    return bank.phrasings["train"][feature][direction][0]


def test_a_typo_of_a_same_meaning_train_phrasing_is_a_near_copy(bank):
    text = _train_text(bank, "speed", "increase")
    typo = text[:-2] + text[-1].upper() + "!"  # a dropped letter and changed punctuation
    assert similarity(typo, text) >= 0.9
    phr = phrasings_from_mapping(
        {"speed": {"increase": [typo, "The robot ought to get a move on, really."]}}, bank.features, require_all=False
    )
    assert near_copies(phr, bank) == {typo: text}


def test_the_same_words_under_another_meaning_are_not_a_near_copy(bank):
    text = _train_text(bank, "speed", "increase")
    phr = phrasings_from_mapping({"speed": {"decrease": [text]}}, bank.features, require_all=False)
    assert near_copies(phr, bank) == {}


def test_a_lower_ratio_takes_more(bank):
    text = _train_text(bank, "height", "increase")
    changed = text.replace("higher", "upper") if "higher" in text else text + " now please"
    phr = phrasings_from_mapping({"height": {"increase": [changed]}}, bank.features, require_all=False)
    ratio = similarity(changed, text)
    assert ratio < 1
    assert changed in near_copies(phr, bank, ratio=ratio - 0.01)
    assert changed not in near_copies(phr, bank, ratio=min(1.0, ratio + 0.01))


def test_scores_without_near_copies_are_the_rest_of_the_counts(trained, tiny_data, tiny_texts):
    from langpref.dataset.storage import load_dataset

    ds = load_dataset(tiny_data)
    phr = phrasings_from_mapping(tiny_texts[0], ds.feature_names)
    out = evaluate_split(trained.model, ds, "train", phr)
    assert without_phrasings(out, set())["accuracy"] == pytest.approx(out["accuracy"])
    assert without_phrasings(out, set())["reading_accuracy"] == pytest.approx(out["reading_accuracy"])
    worst = min(out["per_phrasing"], key=lambda t: out["per_phrasing"][t]["accuracy"])
    rest = without_phrasings(out, {worst})
    assert rest["num_left_out"] == 1 and rest["num_phrasings"] == out["num_phrasings"] - 1
    kept = [p for t, p in out["per_phrasing"].items() if t != worst]
    expected = sum(p["accuracy"] * p["num_samples"] for p in kept) / sum(p["num_samples"] for p in kept)
    assert rest["accuracy"] == pytest.approx(expected)
    if out["per_phrasing"][worst]["accuracy"] < out["accuracy"]:
        assert rest["accuracy"] > out["accuracy"]
    short = summary_only(out)
    assert "per_phrasing" not in short and "misread" not in short and short["accuracy"] == out["accuracy"]
    assert not any(t in repr(short) for t in phr.texts)
