"""The scope check (`langpref.language.scope`): feedback about something a task does not measure is said so, the
task's own feedback is not, and the corpus embeddings it keeps on disk are made again when damaged."""

from __future__ import annotations

import numpy as np
import pytest

from langpref.language.relevance import FeedbackGate, OutOfTaskError
from langpref.language.scope import cached_embeddings


@pytest.fixture(scope="module")
def gate():
    return FeedbackGate("metaworld")


@pytest.mark.parametrize(
    "text, concept",
    [("Open the drawer further.", "opening"), ("Close the gripper.", "grip"), ("Rotate the wrist.", "rotation")],
)
def test_feedback_about_what_the_task_lacks_is_said_so(gate, text, concept):
    scope = gate.scope(text)
    assert scope.outside and scope.concept == concept
    with pytest.raises(OutOfTaskError, match="which this task does not measure") as err:
        gate.check(text)
    assert "height, speed, distance to button" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("text", ["Move faster.", "Could you go a little higher?", "Keep away from the button."])
def test_the_tasks_own_feedback_is_read(gate, text):
    assert not gate.scope(text).outside
    assert gate.check(text).ok


def test_what_a_task_measures_comes_from_its_features(gate):
    assert gate.scope_check.covered == {"height", "speed", "distance"}
    assert FeedbackGate("robosuite").scope_check.covered >= {"height", "speed", "distance"}
    assert FeedbackGate("metaworld", ["Move faster."]).scope("Close the gripper.") is None  # bare phrasings: no check


def test_kept_embeddings_are_made_again_when_damaged(tmp_path, monkeypatch):
    monkeypatch.setenv("LANGPREF_CACHE", str(tmp_path))
    calls = []

    def embed(texts):
        calls.append(len(texts))
        return np.ones((len(texts), 3)) / np.sqrt(3)

    first = cached_embeddings(["a", "b"], embed, "m")
    again = cached_embeddings(["a", "b"], embed, "m")
    assert calls == [2] and np.array_equal(first, again)
    (kept,) = (tmp_path / "scope").glob("*.npy")
    kept.write_bytes(b"not numpy")
    assert np.array_equal(cached_embeddings(["a", "b"], embed, "m"), first) and calls == [2, 2]
