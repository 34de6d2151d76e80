"""Concurrent embedding calls merged into one batch: what keeps a sentence encoder fast when many threads ask at once.

A study server answers participants on many threads, and each typed answer is embedded by small transformers (the
feedback gate's, the scope check's, the model's). One sentence through MiniLM costs about 20 ms on one CPU core, eight
sentences in one batch about 45 ms: most of a single pass is per-call overhead (Python, under the GIL), not
arithmetic. An encoder behind a lock runs the sentences of 20 participants one after another; behind a `Coalesced`
it runs them in one pass.

    embed = Coalesced(lambda texts: encoder(texts))   # texts -> (N, D) array
    rows = embed(["Move faster."])                    # from any thread

The first caller to find the encoder idle runs it on its own texts and on every text that arrives while a pass runs
(they wait, then go together in the next pass); a caller alone waits for nothing. Only one pass runs at a time, so an
encoder that is not safe to call from two threads at once (a fast tokenizer) needs no lock of its own. A text asked
for twice in one batch is embedded once. An error in a pass is raised in every caller whose texts were in it.

With `remember=N` the rows of the last N distinct texts are kept (least recently used out): a text said again ("Move
faster.") costs no pass. The rows of a text do not depend on the batch it came in (to float rounding, about 1e-7).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["REMEMBERED", "Coalesced"]

MAX_BATCH = 64
"""Texts in one pass at most (beyond that the next pass takes the rest): bounds a pass's memory and time."""
REMEMBERED = 4096
"""Texts whose rows a remembering encoder keeps (`remember`): 4096 x 384 float64 rows, about 13 MB."""


class _Call:
    """One caller's texts, and their rows once a pass has made them (or the error it raised)."""

    __slots__ = ("texts", "rows", "error", "done")

    def __init__(self, texts: list[str]):
        self.texts = texts
        self.rows: np.ndarray | None = None
        self.error: BaseException | None = None
        self.done = False


class Coalesced:
    """`fn(texts) -> (N, D) array` (rows in the order of `texts`) with concurrent calls merged into batches of at
    most `max_batch` distinct texts; the rows of the last `remember` distinct texts kept."""

    def __init__(self, fn: Callable[[list[str]], np.ndarray], max_batch: int = MAX_BATCH, remember: int = 0):
        self.fn = fn
        self.max_batch = max_batch
        self.remember = remember
        self._cond = threading.Condition()
        self._waiting: list[_Call] = []
        self._running = False
        self._kept: OrderedDict[str, np.ndarray] = OrderedDict()
        self.passes = 0
        """Passes run so far (a count for tests and benchmarks)."""

    def __call__(self, texts: Sequence[str]) -> np.ndarray:
        call = _Call(list(texts))
        with self._cond:
            if call.texts and self.remember and all(t in self._kept for t in call.texts):
                for t in call.texts:
                    self._kept.move_to_end(t)
                return np.stack([self._kept[t] for t in call.texts])
            self._waiting.append(call)
            while not call.done and self._running:
                self._cond.wait()
            if call.done:
                return self._result(call)
            self._running = True  # this caller runs passes until its own texts are done
        try:
            while not call.done:
                self._run(self._take())
        finally:
            with self._cond:
                self._running = False
                self._cond.notify_all()
        return self._result(call)

    def _take(self) -> list[_Call]:
        """The calls of the next pass, oldest first: as many as fit in `max_batch` distinct texts (at least one)."""
        with self._cond:
            taken: list[_Call] = []
            distinct: set[str] = set()
            while self._waiting:
                more = distinct.union(self._waiting[0].texts)
                if taken and len(more) > self.max_batch:
                    break
                taken.append(self._waiting.pop(0))
                distinct = more
            return taken

    def _run(self, calls: list[_Call]) -> None:
        """One pass over the distinct texts of `calls`; each call gets its rows (or the pass's error)."""
        unique = list(dict.fromkeys(t for c in calls for t in c.texts))
        rows = None
        try:
            rows = np.asarray(self.fn(unique))
            if len(rows) != len(unique):
                raise ValueError(f"an embedding pass gave {len(rows)} rows for {len(unique)} texts")
            where = {t: i for i, t in enumerate(unique)}
            for c in calls:
                c.rows = rows[[where[t] for t in c.texts]]
        except BaseException as exc:  # every caller of this pass sees it, the running one included
            rows = None
            for c in calls:
                c.error = exc
        with self._cond:
            if self.remember and rows is not None:
                self._keep(unique, rows)
            self.passes += 1
            for c in calls:
                c.done = True
            self._cond.notify_all()

    def keep(self, texts: Sequence[str], rows: np.ndarray) -> None:
        """Remember `rows` as the rows of `texts`, made elsewhere by the same encoder (a bank embedded at start)."""
        if len(rows) != len(texts):
            raise ValueError(f"{len(rows)} rows for {len(texts)} texts")
        with self._cond:
            if self.remember:
                self._keep(list(texts), np.asarray(rows))

    def _keep(self, texts: list[str], rows: np.ndarray) -> None:
        """Remember the rows of `texts` (call with the condition held), the oldest forgotten beyond `remember`."""
        for text, row in zip(texts, rows):
            self._kept[text] = row.copy()  # not a view that keeps the whole batch
            self._kept.move_to_end(text)
        while len(self._kept) > self.remember:
            self._kept.popitem(last=False)

    @staticmethod
    def _result(call: _Call) -> np.ndarray:
        if call.error is not None:
            raise call.error
        assert call.rows is not None
        return call.rows
