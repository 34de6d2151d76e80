"""Language answers over HTTP (`langpref.feedback.language.parse`): "that's good, no change" typed as people type it."""

from __future__ import annotations

import pytest

from langpref.feedback.language import LanguageAnswer, LanguageQuery, parse
from langpref.language.bank import NO_CHANGE_FEEDBACK


@pytest.mark.parametrize(
    "sent", ["that's good, no change.", "That\u2019s good, no change.", " THAT'S GOOD, NO CHANGE ", {"no_change": True}]
)
def test_no_change_typed_is_stored_as_the_canonical_phrase(sent):
    query = LanguageQuery(3)
    answer = parse(sent, query)
    assert answer.no_change and answer.text == NO_CHANGE_FEEDBACK and answer.query == query


def test_other_text_is_kept_as_typed():
    answer = parse("  that's good, no change needed  ", LanguageQuery(0))
    assert not answer.no_change and answer.text == "that's good, no change needed"


def test_an_answer_made_in_code_with_the_phrase_typed_is_no_change():
    assert LanguageAnswer(LanguageQuery(0), "that\u2019s good, no change").no_change
