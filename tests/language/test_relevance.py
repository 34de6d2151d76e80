"""The feedback gate: phrasings people wrote without seeing the bank pass; nonsense and small talk are refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from langpref.language.bank import load_user_utterances
from langpref.language.relevance import FeedbackGate, NotFeedbackError

HELDOUT = Path(__file__).resolve().parents[2] / "heldout" / "utterances.json"

NONSENSE = ("asdf", "qwertyuiop", "!!!???", "123 456", "I like pizza.", "What is the weather today?")


@pytest.fixture(scope="module", params=("metaworld", "robosuite"))
def gate(request) -> FeedbackGate:
    return FeedbackGate(request.param)


def test_every_heldout_phrasing_passes(gate):
    mapping = load_user_utterances(HELDOUT, gate.env)
    texts = [t for by_direction in mapping.values() for ts in by_direction.values() for t in ts]
    refused = [(t, round(r.score, 3)) for t in texts if not (r := gate.score(t)).ok]
    assert not refused


@pytest.mark.parametrize("text", NONSENSE)
def test_nonsense_is_refused_with_one_line(gate, text):
    assert not gate.score(text).ok
    with pytest.raises(NotFeedbackError, match="does not read as feedback") as err:
        gate.check(text)
    assert "\n" not in str(err.value)


def test_a_bank_phrasing_scores_one(gate):
    rel = gate.check(gate.phrasings[0])
    assert rel.score == pytest.approx(1.0, abs=1e-6) and rel.nearest == gate.phrasings[0]


def test_small_talk_above_the_floor_is_refused_as_off_topic(gate):
    # "Good evening, everyone!" was refused here through "good morning", one of the off-topic texts removed because
    # they copied a reporting set's (issue 42, item 1); it now passes, just above its nearest off-topic text.
    rel = gate.score("Good afternoon!")
    assert rel.score >= 0.35  # the floor alone would let it through
    assert rel.off_topic > rel.score and not rel.ok
    with pytest.raises(NotFeedbackError, match="something other than feedback") as err:
        gate.check("Good afternoon!")
    assert "how are you doing" in str(err.value) and "\n" not in str(err.value)


def test_the_off_topic_texts_copy_no_heldout_text():
    import json

    from langpref.language.relevance import OFF_TOPIC

    ours = {t.lower().strip(" .!?") for t in json.loads(OFF_TOPIC.read_text())["texts"]}
    heldout = json.loads((HELDOUT.parent / "not_feedback.json").read_text())["texts"]
    assert not ours & {t.lower().strip(" .!?") for t in heldout}
