import numpy as np
import pytest

from langpref.errors import LangprefError
from langpref.language.pairs import (
    DECREASE,
    INCREASE,
    build_pairs,
    merge_phrasings,
    phrasings_from_mapping,
    sample_phrasings,
    sample_subset,
    tie_thresholds,
)

FEATS = ["height", "speed"]


def test_pairs_on_hand_built_features_skip_ties_and_get_directions_right():
    features = np.array(
        [
            [0.0, 1.0],
            [1.0, 1.02],  # speed within the tie threshold of trajectory 0
            [0.5, 3.0],
        ]
    )
    pairs = build_pairs(features, thresholds=np.array([0.1, 0.1]))
    got = {(int(a), int(b), int(f)): int(d) for a, b, f, d in zip(pairs.a, pairs.b, pairs.feature, pairs.direction)}
    assert got == {
        (0, 1, 0): INCREASE,
        (1, 0, 0): DECREASE,  # height 0 -> 1 and back; speed 1 vs 1.02 is a tie
        (0, 2, 0): INCREASE,
        (0, 2, 1): INCREASE,
        (2, 0, 0): DECREASE,
        (2, 0, 1): DECREASE,
        (1, 2, 0): DECREASE,
        (1, 2, 1): INCREASE,
        (2, 1, 0): INCREASE,
        (2, 1, 1): DECREASE,
    }
    assert pairs.a.dtype == np.int64 and len(pairs) == 10
    assert np.array_equal(pairs.group, 2 * pairs.feature + pairs.direction)


def test_every_ordered_pair_without_ties_and_no_self_pairs():
    rng = np.random.default_rng(0)
    features = rng.standard_normal((20, 3))
    pairs = build_pairs(features, np.zeros(3))
    assert len(pairs) == 20 * 19 * 3
    assert not np.any(pairs.a == pairs.b)
    delta = features[pairs.b, pairs.feature] - features[pairs.a, pairs.feature]
    assert np.all((delta > 0) == (pairs.direction == INCREASE))


def test_tie_thresholds_are_a_fraction_of_the_train_std():
    feats = np.array([[0.0, 10.0], [2.0, 10.0]])
    assert np.allclose(tie_thresholds(feats, 0.05), [0.05, 0.0])
    with pytest.raises(LangprefError):
        tie_thresholds(feats[:1])


def test_phrasings_table_groups_and_errors():
    mapping = {
        "height": {"increase": ["Up.", " Up. ", "Higher."], "decrease": ["Down."]},
        "speed": {"increase": ["Faster."], "decrease": ["Slower."]},
    }
    ph = phrasings_from_mapping(mapping, FEATS)
    assert ph.texts == ("Up.", "Higher.", "Down.", "Faster.", "Slower.")  # whitespace-normalised, deduplicated
    assert [list(ids) for ids in ph.group_ids] == [[0, 1], [2], [3], [4]]
    assert ph.group_name(3) == ("speed", "decrease")
    assert ph.as_mapping()["height"]["increase"] == ["Up.", "Higher."]
    with pytest.raises(LangprefError, match="speed/decrease"):
        phrasings_from_mapping({"height": mapping["height"], "speed": {"increase": ["x"]}}, FEATS)
    with pytest.raises(LangprefError, match="'colour'"):
        phrasings_from_mapping({"colour": {"increase": ["x"]}}, FEATS)
    with pytest.raises(LangprefError, match="'sideways'"):
        phrasings_from_mapping({"height": {"sideways": ["x"]}}, FEATS)
    partial = phrasings_from_mapping({"speed": {"increase": ["Faster."]}}, FEATS, require_all=False)
    assert [len(ids) for ids in partial.group_ids] == [0, 0, 1, 0]
    merged = merge_phrasings(ph, partial)
    assert merged.texts == ph.texts


def test_sampling_stays_in_the_group_and_covers_it():
    mapping = {
        "height": {"increase": ["a", "b", "c"], "decrease": ["d"]},
        "speed": {"increase": ["e", "f"], "decrease": ["g", "h", "i", "j"]},
    }
    ph = phrasings_from_mapping(mapping, FEATS)
    rng = np.random.default_rng(0)
    groups = np.repeat(np.arange(4), 400)
    ids = sample_phrasings(groups, ph, rng)
    for g in range(4):
        got = set(ids[groups == g].tolist())
        assert got == set(ph.group_ids[g].tolist())
    subset = sample_subset(ph, 2, rng)
    assert [len(s) for s in subset] == [2, 1, 2, 2]
    ids = sample_phrasings(groups, ph, rng, subset)
    for g in range(4):
        assert set(ids[groups == g].tolist()) <= set(subset[g].tolist())
