"""The comparative-feedback corpus (langpref.language.corpus) and how a feature is tied to its concepts
(langpref.language.ties). The corpus against every held-out text is checked by the one test that may read all of
heldout/ (the overlap tripwire beside the reporting set's schema tests)."""

from __future__ import annotations

import pytest

from langpref.language.corpus import build_corpus, concept_split, copies, excluded_texts, fingerprint, generate
from langpref.language.lexicon import DIRECTIONS, KINDS, load_lexicon
from langpref.language.ties import name_words, tie_feature


def test_every_concept_has_both_directions_and_every_kind():
    lex = load_lexicon()
    assert len(lex["concepts"]) >= 12
    for concept in lex["concepts"].values():
        for direction in DIRECTIONS:
            assert all(concept[direction][k] for k in KINDS)


def test_generation_is_deterministic_from_its_seed():
    a, b, c = generate(0, 20), generate(0, 20), generate(1, 20)
    assert fingerprint(a) == fingerprint(b)
    assert fingerprint(a) != fingerprint(c)


def test_every_meaning_gets_its_share_and_every_kind():
    made = generate(0, 24)
    lex = load_lexicon()
    for name in lex["concepts"]:
        for direction in DIRECTIONS:
            mine = [e for e in made if e.concept == name and e.direction == direction]
            assert len(mine) == 24
            assert {e.source for e in mine} == {f"template:{k}" for k in KINDS}


def test_an_object_concept_names_its_object():
    made = [e for e in generate(0, 30, ["distance"]) if e.obj]
    assert made and all(e.obj in e.text for e in made)
    assert all("{" not in e.text for e in generate(0, 30))


def test_no_val_or_test_phrasing_of_a_built_in_bank():
    """No made sentence copies a val/test phrasing (the banks' own train phrasings enter as they are)."""
    corpus = build_corpus(0, 40)
    held = excluded_texts()
    assert len(held) > 300
    assert not copies([e.text for e in corpus if e.source.startswith("template:")], held, 0.9)
    made = generate(0, 40)
    assert copies([e.text for e in made], held, 0.9), "the filter had nothing to remove: the test cannot fail"


def test_copies_finds_exact_and_near_copies_only():
    assert copies(["Move faster.", "Move fastr!", "Go up."], ["move faster", "Lower the arm."], 0.9) == {
        "Move faster.",
        "Move fastr!",
    }


def test_bank_phrasings_carry_their_feature_tie():
    corpus = build_corpus(0, 4)
    bank = [e for e in corpus if e.source == "bank:metaworld"]
    assert {e.concept for e in bank} == {"height", "speed", "distance"}
    assert {e.obj for e in bank if e.concept == "distance"} == {"button"}
    assert any(e.concept == "robosuite/lift_success" for e in corpus)


def test_no_sentence_carries_two_meanings():
    corpus = build_corpus(0, 40)
    meanings: dict[str, set[str]] = {}
    for e in corpus:
        meanings.setdefault(e.text.lower(), set()).add(e.meaning)
    assert all(len(m) == 1 for m in meanings.values())


def test_concept_split_holds_out_whole_concepts():
    train, val = concept_split(generate(0, 10), ["tilt", "reach"])
    assert {e.concept for e in val} == {"tilt", "reach"}
    assert not {e.concept for e in train} & {"tilt", "reach"}


@pytest.mark.parametrize(
    "name,concept,sign,obj",
    [
        ("speed", "speed", 1, None),
        ("height", "height", 1, None),
        ("distance_to_button", "distance", 1, "button"),
        ("distance_to_puck", "distance", 1, "puck"),
        ("drawer_opening", "opening", 1, "drawer"),
        ("drawer_closure", "opening", -1, "drawer"),
        ("gripper_closure", "grip", 1, None),
        ("gripper_opening", "grip", -1, None),
        ("hand_sideways", "lateral", 1, None),
        ("handLeft", "lateral", -1, None),
    ],
)
def test_a_feature_name_ties_to_its_concept(name, concept, sign, obj):
    tie = tie_feature(name)
    assert tie is not None and (tie.concept, tie.sign, tie.obj) == (concept, sign, obj)


def test_a_name_no_concept_knows_ties_to_nothing():
    assert tie_feature("lift_success") is None
    assert name_words("gripperOpening2") == ["gripper", "opening"]
