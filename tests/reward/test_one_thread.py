"""Fits on several threads at once (the study server's participants): each runs torch on one thread, they run side
by side rather than one after another, and the process's thread count is given back once the last one ends."""

from __future__ import annotations

import threading

import torch

from langpref.reward.learner import _one_thread


def test_sections_overlap_run_on_one_thread_and_restore_the_count():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        inside = threading.Barrier(2, timeout=10)  # both sections inside at once, or the barrier times out
        seen: list[int] = []

        def section() -> None:
            with _one_thread(torch):
                inside.wait()
                seen.append(torch.get_num_threads())
                inside.wait()

        threads = [threading.Thread(target=section) for _ in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=30)
        assert seen == [1, 1]
        assert torch.get_num_threads() == 2
        with _one_thread(torch):
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
