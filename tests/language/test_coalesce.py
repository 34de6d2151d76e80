"""Concurrent embedding calls merged into one batch (`langpref.language.coalesce`): each caller gets its own rows, in
its order; calls that arrive while a pass runs share the next pass; one pass at a time; errors reach every caller
of the pass; remembered texts cost no pass."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from langpref.language.coalesce import Coalesced


class Encoder:
    """A fake encoder: a text's row is (len, first letter code); records its batches, and notes two at once."""

    def __init__(self, delay: float = 0.0):
        self.delay = delay
        self.batches: list[list[str]] = []
        self.inside = 0
        self.overlapped = False
        self._lock = threading.Lock()

    def __call__(self, texts: list[str]) -> np.ndarray:
        with self._lock:
            self.inside += 1
            self.overlapped |= self.inside > 1
            self.batches.append(list(texts))
        time.sleep(self.delay)
        with self._lock:
            self.inside -= 1
        return np.array([[len(t), ord(t[0]) if t else 0] for t in texts], dtype=np.float64).reshape(len(texts), 2)


def expected(texts: list[str]) -> np.ndarray:
    return np.array([[len(t), ord(t[0])] for t in texts], dtype=np.float64)


def test_a_caller_alone_gets_its_rows_in_its_order_in_one_pass():
    enc = Encoder()
    embed = Coalesced(enc)
    texts = ["Move faster.", "go", "Move faster.", "Stay low"]
    np.testing.assert_array_equal(embed(texts), expected(texts))
    assert enc.batches == [["Move faster.", "go", "Stay low"]]  # a text asked twice is embedded once
    assert embed([]).shape == (0, 2)


def test_concurrent_callers_share_passes_and_never_run_two_at_once():
    enc = Encoder(delay=0.05)
    embed = Coalesced(enc)
    texts = [f"text number {i}" for i in range(12)]
    got: dict[int, np.ndarray] = {}

    def ask(i: int) -> None:
        got[i] = embed([texts[i]])

    threads = [threading.Thread(target=ask, args=(i,)) for i in range(12)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    for i in range(12):
        np.testing.assert_array_equal(got[i], expected([texts[i]]))
    assert not enc.overlapped
    assert embed.passes == len(enc.batches) < 12  # those that waited went together
    assert sorted(t for b in enc.batches for t in b) == sorted(texts)


def test_a_pass_takes_at_most_max_batch_distinct_texts():
    enc = Encoder(delay=0.05)
    embed = Coalesced(enc, max_batch=3)
    threads = [threading.Thread(target=embed, args=([f"t{i}", f"u{i}"],)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert all(len(b) == 2 for b in enc.batches)  # two calls together would be 4 distinct texts


def test_an_error_reaches_every_caller_of_its_pass_and_the_next_pass_runs():
    calls = []

    def failing(texts: list[str]) -> np.ndarray:
        calls.append(texts)
        if "bad" in texts:
            raise RuntimeError("encoder broke")
        return np.zeros((len(texts), 1))

    embed = Coalesced(failing)
    with pytest.raises(RuntimeError, match="encoder broke"):
        embed(["bad"])
    assert embed(["good"]).shape == (1, 1)  # not stuck: the failed pass released the encoder

    def short(texts: list[str]) -> np.ndarray:
        return np.zeros((0, 1))

    with pytest.raises(ValueError, match="0 rows for 1 texts"):
        Coalesced(short)(["x"])


def test_remembered_texts_cost_no_pass_and_the_oldest_are_forgotten():
    enc = Encoder()
    embed = Coalesced(enc, remember=2)
    embed(["a1", "b22"])
    np.testing.assert_array_equal(embed(["a1", "b22"]), expected(["a1", "b22"]))
    np.testing.assert_array_equal(embed(["b22"]), expected(["b22"]))
    assert embed.passes == 1
    embed(["c333"])  # a1 was used least recently: forgotten
    embed(["b22"])
    assert embed.passes == 2
    embed(["a1"])
    assert embed.passes == 3 and enc.batches[-1] == ["a1"]
