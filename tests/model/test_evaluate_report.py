"""`evaluate --json` beside `accuracy`: accuracy per phrasing (with its meaning), and accuracy with the tie samples
(features that differ by no more than the tie threshold) put back, scored at chance and scored by the model."""

import numpy as np
import pytest

from langpref.language.pairs import Pairs, Phrasings, phrasings_from_mapping
from langpref.model.evaluate import alignment_counts, evaluate_split, per_phrasing, phrasing_counts


def test_per_phrasing_counts_on_hand_built_embeddings():
    phi = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    psi = np.array([[1.0, 0.0], [-1.0, 0.0], [-2.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    pairs = Pairs(
        a=np.array([0, 1, 2, 0]),
        b=np.array([1, 0, 1, 2]),
        feature=np.array([0, 0, 0, 1]),
        direction=np.array([0, 1, 1, 0]),
    )
    groups = (np.array([0, 2]), np.array([1]), np.array([3]), np.array([4]))
    correct, total = phrasing_counts(phi, psi, pairs, groups, 5)
    assert correct.tolist() == [1, 2, 0, 0, 0] and total.tolist() == [1, 2, 1, 1, 0]
    small = phrasing_counts(phi, psi, pairs, groups, 5, chunk=1)
    assert [x.tolist() for x in small] == [correct.tolist(), total.tolist()]
    per_feature = alignment_counts(phi, psi, pairs, groups, 2)
    assert [correct[[0, 1, 2]].sum(), correct[[3, 4]].sum()] == per_feature[0].tolist()
    table = Phrasings(("up", "down", "wrong up", "f1 up", "f1 down"), ("a", "b"), groups)
    out = per_phrasing(correct, total, table)
    assert out["down"] == {"meaning": "a/decrease", "accuracy": 1.0, "num_samples": 2}
    assert out["wrong up"]["accuracy"] == 0.0 and "f1 down" not in out  # no samples, left out


def test_evaluate_reports_per_phrasing_and_ties(trained, tiny_data, tiny_texts):
    from langpref.dataset.storage import load_dataset

    ds = load_dataset(tiny_data)
    phr = phrasings_from_mapping(tiny_texts[0], ds.feature_names)
    out = evaluate_split(trained.model, ds, "train", phr)
    per = out["per_phrasing"]
    assert set(per) == set(phr.texts)
    assert sum(v["num_samples"] for v in per.values()) == out["num_samples"]
    weighted = sum(v["accuracy"] * v["num_samples"] for v in per.values()) / out["num_samples"]
    assert abs(weighted - out["accuracy"]) < 1e-12
    assert per["Move faster."]["meaning"] == "speed/increase"
    n, ties = out["num_samples"], out["num_tie_samples"]
    assert ties > 0  # the tiny data has near-equal features, so the threshold leaves some samples out
    assert out["accuracy_ties_at_chance"] == pytest.approx((out["accuracy"] * n + 0.5 * ties) / (n + ties))
    # every sample the threshold kept, scored as before, plus the tie samples scored by the model: between none and
    # all of the ties right
    right_on_ties = out["accuracy_no_tie_threshold"] * (n + ties) - out["accuracy"] * n
    assert -1e-9 <= right_on_ties <= ties + 1e-9 and abs(right_on_ties - round(right_on_ties)) < 1e-6
    thresholds = np.asarray(trained.model.info.tie_thresholds)
    assert thresholds.max() > 0  # so `accuracy_no_tie_threshold` differs in what it counts
