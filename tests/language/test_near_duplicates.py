"""Near-duplicate phrasings across the bank's splits: listed, and kept from growing.

The no-leak test of the bank (tests/language/test_bank.py) checks that no phrasing sits in two splits; it does not
catch a phrasing of one split that is a near copy of one of the same meaning in another (e.g. test "That was
rushed." and train "That was too rushed."). Such a pair makes "unseen phrasings" partly seen. Today's pairs, with a
difflib ratio of at least 0.85 and the same feature and direction, are listed below. They stay, and are not
rewritten or moved: the bank's splits fixed the numbers the results report (training, the test accuracy, the
synthetic humans' phrasings), and changing them would change every one of those numbers. The test fails when a new
one appears (an edit of the bank that adds a near copy across splits); remove an entry here when the bank loses it.

Counts today (the later split first): Meta-World 9 test-train, 6 val-train, 1 test-val; robosuite 4 test-train,
2 val-train.
"""

import difflib

import pytest

from langpref.language.bank import load_bank

RATIO = 0.85
PAIRS = (("test", "train"), ("val", "train"), ("test", "val"))

KNOWN = {
    "metaworld": {
        ("test", "train", "height", "decrease", "Drop down a bit.", "Go down a bit."),
        ("test", "train", "speed", "decrease", "Decrease the speed.", "Decrease the pace."),
        ("test", "train", "speed", "decrease", "That was rushed.", "That was too rushed."),
        ("test", "train", "distance_to_button", "increase", "Get off the button.", "Stay off the button."),
        (
            "test",
            "train",
            "distance_to_button",
            "decrease",
            "Narrow the distance to the button.",
            "Close the distance to the button.",
        ),
        ("test", "train", "distance_to_button", "decrease", "Home in on the button.", "Move in on the button."),
        ("test", "train", "distance_to_button", "decrease", "Home in on the button.", "Close in on the button."),
        ("test", "train", "distance_to_button", "decrease", "Zero in on the button.", "Move in on the button."),
        (
            "test",
            "train",
            "distance_to_button",
            "decrease",
            "Don't stay so far from the button.",
            "Not so far from the button.",
        ),
        ("val", "train", "speed", "increase", "Don't move so slowly.", "Don't go so slowly."),
        ("val", "train", "speed", "decrease", "Turn down the speed.", "Tone down the speed."),
        ("val", "train", "distance_to_button", "decrease", "Reach for the button.", "Head for the button."),
        ("val", "train", "distance_to_button", "decrease", "Reach for the button.", "Reach the button."),
        ("val", "train", "distance_to_button", "decrease", "Reach toward the button.", "Move toward the button."),
        ("val", "train", "distance_to_button", "decrease", "Reach toward the button.", "More toward the button."),
        ("test", "val", "speed", "decrease", "Move leisurely.", "Be leisurely."),
    },
    "robosuite": {
        ("test", "train", "distance_to_cube", "decrease", "Less distance to the cube.", "Less distance to the block."),
        (
            "test",
            "train",
            "distance_to_bottle",
            "increase",
            "Don't get so close to the bottle.",
            "Not so close to the bottle.",
        ),
        ("test", "train", "lift_success", "decrease", "Don't grab the cube.", "Don't take the cube."),
        ("test", "train", "lift_success", "decrease", "Don't grasp the block.", "Don't grip the block."),
        (
            "val",
            "train",
            "distance_to_cube",
            "increase",
            "Don't get so close to the cube.",
            "Not so close to the cube.",
        ),
        (
            "val",
            "train",
            "distance_to_bottle",
            "decrease",
            "Don't stay so far from the bottle.",
            "Not so far from the bottle.",
        ),
    },
}


def near_duplicates(env: str, ratio: float = RATIO) -> set[tuple[str, str, str, str, str, str]]:
    """(split, other split, feature, direction, phrasing, its near copy) for every pair of phrasings of the same
    meaning in two splits whose difflib ratio is at least `ratio`."""
    bank = load_bank(env)
    by_split = {s: bank.all_of_split(s) for s in {s for pair in PAIRS for s in pair}}
    found = set()
    for a, b in PAIRS:
        for text, f, d in by_split[a]:
            for other, f2, d2 in by_split[b]:
                if (f, d) == (f2, d2) and difflib.SequenceMatcher(None, text, other).ratio() >= ratio:
                    found.add((a, b, f, d, text, other))
    return found


@pytest.mark.parametrize("env", sorted(KNOWN))
def test_near_duplicates_across_splits_do_not_grow(env):
    found = near_duplicates(env)
    new = sorted(found - KNOWN[env])
    assert not new, f"new near-duplicate phrasings across the {env} bank's splits: {new}"
    assert len(found) <= len(KNOWN[env])


def test_the_check_finds_what_it_lists():
    for env, known in KNOWN.items():
        assert near_duplicates(env) == known  # the list is today's, not a superset
    assert ("test", "train", "speed", "decrease", "That was rushed.", "That was too rushed.") in near_duplicates(
        "metaworld", 0.85
    )
