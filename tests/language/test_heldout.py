"""The held-out utterance file (heldout/utterances.json): loads, is complete, and never overlaps the shipped bank."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from langpref.language.bank import load_bank, load_user_utterances, normalise
from langpref.tasks import get_task

ENV_NAMES = ("metaworld", "robosuite")

HELDOUT = Path(__file__).resolve().parents[2] / "heldout" / "utterances.json"
DIRECTIONS = ("increase", "decrease")


@pytest.mark.parametrize("env", ENV_NAMES)
def test_heldout_loads_with_user_loader(env: str) -> None:
    mapping = load_user_utterances(HELDOUT, env)
    assert mapping, f"no phrasings for {env}"


def test_heldout_comment_present() -> None:
    data = json.loads(HELDOUT.read_text(encoding="utf-8"))
    assert "_comment" in data
    assert "2026-11-23" in data["_comment"]


@pytest.mark.parametrize("env", ENV_NAMES)
def test_heldout_covers_every_feature_and_direction(env: str) -> None:
    mapping = load_user_utterances(HELDOUT, env)
    features = tuple(get_task(env).features)
    assert set(mapping) == set(features)
    for feature in features:
        for direction in DIRECTIONS:
            texts = mapping[feature].get(direction, ())
            assert len(texts) >= 12, f"{env}/{feature}/{direction}: only {len(texts)} phrasings"
            keys = [normalise(t) for t in texts]
            assert len(set(keys)) == len(keys), f"{env}/{feature}/{direction}: duplicate phrasings"


@pytest.mark.parametrize("env", ENV_NAMES)
def test_heldout_disjoint_from_bank(env: str) -> None:
    bank_keys = {
        normalise(text)
        for directions in load_bank(env).merged().values()
        for texts in directions.values()
        for text in texts
    }
    collisions = [
        f"{feature}/{direction}: {text!r}"
        for feature, directions in load_user_utterances(HELDOUT, env).items()
        for direction, texts in directions.items()
        for text in texts
        if normalise(text) in bank_keys
    ]
    assert not collisions, "held-out phrasings also in the bank:\n" + "\n".join(collisions)


PROBES = Path(__file__).resolve().parents[2] / "docs" / "probes"


@pytest.mark.parametrize("env", ENV_NAMES)
def test_probe_phrasings_are_train_only_candidates(env: str) -> None:
    """A probe file (docs/probes, phrasings tried for the train split and reported in docs/results.md) loads with
    the user loader and repeats no bank phrasing nor any held-out one: its numbers measure unseen phrasings."""
    mapping = load_user_utterances(PROBES / f"contrast-completion-{env}.json", env)
    probe = {normalise(t) for by_dir in mapping.values() for texts in by_dir.values() for t in texts}
    bank = load_bank(env)
    shipped = {normalise(t) for split in ("train", "val", "test") for t, _, _ in bank.all_of_split(split)}
    heldout = {
        normalise(t)
        for by_dir in load_user_utterances(HELDOUT, env).values()
        for texts in by_dir.values()
        for t in texts
    }
    assert probe and not probe & shipped and not probe & heldout


NEGATED = HELDOUT.parent / "negated" / "utterances.json"
DRAWER_BANK = Path(__file__).resolve().parents[2] / "examples" / "own_robot" / "utterances.json"


@pytest.mark.parametrize("env", (*ENV_NAMES, "drawer-open"))
def test_negated_set_is_complete_and_shares_nothing_with_any_bank(env: str) -> None:
    """heldout/negated/: 7-10 negated or indirect phrasings per meaning, none in the env's bank (nor the drawer's)."""
    mapping = json.loads(NEGATED.read_text(encoding="utf-8"))[env]
    if env == "drawer-open":
        bank = json.loads(DRAWER_BANK.read_text(encoding="utf-8"))  # {feature: {direction: [texts]}}, unsplit
        bank_texts = [t for f, by in bank.items() if not f.startswith("_") for ts in by.values() for t in ts]
    else:
        bank_texts = [t for by in load_bank(env).merged().values() for ts in by.values() for t in ts]
    bank_keys = {normalise(t) for t in bank_texts}
    for feature, by_direction in mapping.items():
        assert set(by_direction) == set(DIRECTIONS)
        for direction, texts in by_direction.items():
            assert 7 <= len(texts) <= 10, f"{env}/{feature}/{direction}"
            assert not {normalise(t) for t in texts} & bank_keys, f"{env}/{feature}/{direction} overlaps the bank"
