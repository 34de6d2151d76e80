import math

import numpy as np
import pytest
import torch

from langpref.language.pairs import Pairs, Phrasings
from langpref.model.evaluate import alignment_counts, reading, summarise_accuracy
from langpref.model.loss import align_loss, latent_loss, norm_loss


def test_losses_match_the_paper_equations_on_hand_numbers():
    phi_a = torch.tensor([[0.0, 0.0], [2.0, 0.0]])
    phi_b = torch.tensor([[1.0, 0.0], [0.0, 0.0]])
    psi = torch.tensor([[1.0, 0.0], [0.0, 3.0]])
    la = align_loss(phi_a, phi_b, psi)
    assert la[0].item() == pytest.approx(-math.log(1 / (1 + math.exp(-1.0))))
    assert la[1].item() == pytest.approx(math.log(2.0))  # psi . (phi_B - phi_A) = 0
    ln = norm_loss(phi_a, phi_b, psi, a=0.1, b=0.5)
    assert ln[0].item() == pytest.approx(0.0)  # |phi| <= 1, |psi| = 1
    assert ln[1].item() == pytest.approx(0.1 * 1.0 + 0.5 * 4.0)  # hinge |phi_A| - 1 = 1; (|psi| - 1)^2 = 4
    total, a, n = latent_loss(phi_a, phi_b, psi, 0.1, 0.5)
    assert total.item() == pytest.approx(a.item() + n.item())


def test_accuracy_on_hand_built_embeddings_with_known_answers():
    # 1-D features of 3 trajectories; phi = (feature0, feature1); psi: f0 up, f0 down, f1 up, f1 down
    phi = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])  # feature 1 not encoded at all: every score is 0 -> wrong
    psi = np.array(
        [
            [1.0, 0.0],
            [-1.0, 0.0],
            [-2.0, 0.0],  # phrasing 2 says "f0 up" but points down: always wrong
            [0.0, 1.0],
            [0.0, -1.0],
        ]
    )
    pairs = Pairs(
        a=np.array([0, 1, 2, 0]),
        b=np.array([1, 0, 1, 2]),
        feature=np.array([0, 0, 0, 1]),
        direction=np.array([0, 1, 1, 0]),
    )
    groups = [np.array([0, 2]), np.array([1]), np.array([3]), np.array([4])]
    correct, total = alignment_counts(phi, psi, pairs, groups, num_features=2)
    # pair (0,1) f0 up: phrasings 0 (right) and 2 (wrong); (1,0) down: phrasing 1 right; (2,1) down: right
    assert correct.tolist() == [3, 0]
    assert total.tolist() == [4, 1]
    out = summarise_accuracy(correct, total, ["a", "b"])
    assert out == {"accuracy": 3 / 5, "per_feature": {"a": 0.75, "b": 0.0}, "num_samples": 5}


def test_accuracy_chunks_give_the_same_counts():
    rng = np.random.default_rng(1)
    phi, psi = rng.standard_normal((30, 4)), rng.standard_normal((12, 4))
    n = 500
    pairs = Pairs(rng.integers(0, 30, n), rng.integers(0, 30, n), rng.integers(0, 2, n), rng.integers(0, 2, n))
    groups = [np.arange(0, 3), np.arange(3, 6), np.arange(6, 9), np.arange(9, 12)]
    big = alignment_counts(phi, psi, pairs, groups, 2)
    small = alignment_counts(phi, psi, pairs, groups, 2, chunk=7)
    assert [x.tolist() for x in big] == [x.tolist() for x in small]
    # brute force
    s = psi @ phi.T
    want = np.zeros(2, int)
    for i in range(n):
        g = 2 * pairs.feature[i] + pairs.direction[i]
        want[pairs.feature[i]] += int(np.sum(s[groups[g], pairs.b[i]] - s[groups[g], pairs.a[i]] > 0))
    assert big[0].tolist() == want.tolist()


def test_reading_accuracy_counts_phrasings_nearest_their_own_prototype():
    # prototypes of (f0 up, f0 down, f1 up, f1 down); one phrasing per meaning, the f1-down one points like f0 down
    protos = torch.tensor([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    psi = torch.tensor([[2.0, 0.1], [-0.5, 0.0], [0.1, 3.0], [-1.0, -0.5]])
    phrasings = Phrasings(("a", "b", "c", "d"), ("f0", "f1"), tuple(np.array([i]) for i in range(4)))
    out = reading(psi, protos, phrasings)
    assert out["reading_accuracy"] == pytest.approx(0.75)
    assert out["misread"] == [{"text": "d", "meaning": "f1/decrease", "read_as": "f0/decrease"}]
