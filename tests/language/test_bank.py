"""The shipped utterance bank and the loader of users' utterance files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from langpref.errors import LangprefError
from langpref.language.bank import BANK_SPLITS, DIRECTIONS, Bank, load_bank, load_user_utterances, normalise
from langpref.tasks import get_task

# The paper's numbers (Sec. 5.1): total phrasings and train/val/test split sizes.
PAPER_TOTAL = {"metaworld": 660, "robosuite": 629}
PAPER_SPLITS = {"metaworld": {"train": 492, "val": 84, "test": 84}, "robosuite": {"train": 480, "val": 74, "test": 75}}

# Every original utterance of the paper's Appendix E, verbatim, by env, feature and direction.
APPENDIX_E = {
    "robosuite": {
        ("distance_to_cube", "increase"): [
            "Move farther from the cube.",
            "Move further from the cube.",
            "Move more distant from the cube.",
            "Move less nearby from the cube.",
        ],
        ("distance_to_cube", "decrease"): [
            "Move nearer to the cube.",
            "Move closer to the cube.",
            "Move more nearby to the cube.",
            "Move less distant to the cube.",
        ],
        ("distance_to_bottle", "increase"): [
            "Move further from the bottle.",
            "Move farther from the bottle.",
            "Move more distant from the bottle.",
            "Move less nearby from the bottle.",
        ],
        ("distance_to_bottle", "decrease"): [
            "Move nearer to the bottle.",
            "Move closer to the bottle.",
            "Move more nearby to the bottle.",
            "Move less distant to the bottle.",
        ],
        ("height", "increase"): [
            "Move taller.",
            "Move at a greater height.",
            "Move higher.",
            "Move to a greater height.",
        ],
        ("height", "decrease"): ["Move lower.", "Move at a lesser height.", "Move shorter.", "Move to a lower height."],
        ("speed", "increase"): [
            "Move quicker.",
            "Move swifter.",
            "Move at a higher speed.",
            "Move faster.",
            "Move more quickly.",
        ],
        ("speed", "decrease"): [
            "Move at a lower speed.",
            "Move more moderate.",
            "Move slower.",
            "Move more sluggish.",
            "Move more slowly.",
        ],
        ("lift_success", "increase"): [
            "Lift the cube better.",
            "Lift the cube more successfully.",
            "Lift the cube more effectively.",
        ],
        ("lift_success", "decrease"): [
            "Lift the cube worse.",
            "Lift the cube not as well.",
            "Lift the cube less successfully.",
        ],
    },
    "metaworld": {
        ("height", "increase"): [
            "Move higher.",
            "Move more up.",
            "Move higher up from the table.",
            "Increase the overall height of the trajectory.",
            "Go higher up.",
            "Move your gripper higher.",
            "Don't go down, instead go up.",
            "Stay higher and farther from the table.",
            "Move your hand up as you perform the task.",
            "Make sure to stay higher above the table, rather than lower.",
        ],
        ("height", "decrease"): [
            "Move lower.",
            "Move more down.",
            "Move lower to the table.",
            "Decrease the overall height of the trajectory.",
            "Go lower down.",
            "Move your gripper lower.",
            "Don't go up, instead go down.",
            "Stay lower and nearer to the table.",
            "Move your hand lower as you perform the task.",
            "Make sure to go lower to the table, rather than higher.",
        ],
        ("speed", "increase"): [
            "Move faster.",
            "Move at a quicker speed.",
            "Increase the pace.",
            "Press the button faster.",
            "Increase your velocity.",
            "Move your gripper faster.",
            "Move to the button faster.",
            "Don't go too slowly, instead go quickly.",
            "Move your hand faster as you perform the task.",
            "Make sure to go much faster, rather than slower.",
        ],
        ("speed", "decrease"): [
            "Move slower.",
            "Move at a more sluggish speed.",
            "Decrease the pace.",
            "Press the button slower.",
            "Decrease your velocity.",
            "Move your gripper slower.",
            "Move to the button slower.",
            "Don't go too fast, instead go more slowly.",
            "Move your hand slower as you perform the task.",
            "Make sure to go much slower, rather than faster.",
        ],
        ("distance_to_button", "increase"): [
            "Move farther from the button.",
            "Increase distance from the button.",
            "Stay farther from the button.",
            "Give wider berth to the button.",
            "Keep a larger distance from the button.",
            "Keep your gripper farther away from the button.",
            "Move your gripper away from the button.",
            "Don't go towards the button, instead move away from it.",
            "Move your hand farther from the button on the wall as you perform the task.",
            "Make sure to go much farther from the button, rather than closer to the button.",
        ],
        ("distance_to_button", "decrease"): [
            "Move closer to the button.",
            "Decrease distance from the button.",
            "Stay closer to the button.",
            "Get closer to the button.",
            "Keep a smaller distance to the button.",
            "Keep your gripper closer to the button.",
            "Move your gripper so that it is closer to the button.",
            "Don't go away from the button, instead go towards it.",
            "Move your hand closer to the button on the wall as you perform the task.",
            "Make sure to go much closer to the button, rather than farther from the button.",
        ],
    },
}

ENVS = ("metaworld", "robosuite")
FEATURES = {env: get_task(env).features for env in ENVS}


@pytest.fixture(scope="module")
def raw_bank() -> dict:
    """The shipped JSON as stored (the loader drops exact repeats, so duplicate checks read the raw file)."""
    raw = {env: json.loads(get_task(env).utterances.read_text(encoding="utf-8")) for env in ENVS}
    return {env: {k: v for k, v in bank.items() if not k.startswith("_")} for env, bank in raw.items()}


@pytest.fixture(scope="module")
def banks() -> dict[str, Bank]:
    return {env: load_bank(env) for env in ENVS}


def test_features_are_the_design_contract():
    assert FEATURES == {
        "metaworld": ("height", "speed", "distance_to_button"),
        "robosuite": ("height", "speed", "distance_to_cube", "distance_to_bottle", "lift_success"),
    }
    assert BANK_SPLITS == ("train", "val", "test")
    assert DIRECTIONS == ("increase", "decrease")


@pytest.mark.parametrize("env", ENVS)
def test_sizes_at_least_the_papers(banks, env):
    bank = banks[env]
    sizes = {split: len(bank.all_of_split(split)) for split in BANK_SPLITS}
    assert sum(sizes.values()) >= PAPER_TOTAL[env]
    for split in BANK_SPLITS:
        assert sizes[split] >= PAPER_SPLITS[env][split], (split, sizes)
    # near the paper's proportions (74.5% / 12.7% / 12.7%); train is a little larger for its contrast phrasings
    total = sum(sizes.values())
    assert 0.70 <= sizes["train"] / total <= 0.82
    assert 0.09 <= sizes["val"] / total <= 0.16
    assert 0.09 <= sizes["test"] / total <= 0.16


@pytest.mark.parametrize("env", ENVS)
def test_every_feature_and_direction_in_every_split_balanced(raw_bank, banks, env):
    assert set(raw_bank[env]) == set(BANK_SPLITS)
    for split in BANK_SPLITS:
        assert set(raw_bank[env][split]) == set(FEATURES[env])
        counts = []
        for feature in FEATURES[env]:
            assert set(raw_bank[env][split][feature]) == set(DIRECTIONS)
            for direction in DIRECTIONS:
                texts = banks[env].get(split, feature, direction)
                assert texts, (split, feature, direction)
                assert all(isinstance(t, str) and t.strip() == t and t for t in texts)
                counts.append(len(texts))
        assert max(counts) / min(counts) < 1.5, (split, counts)


@pytest.mark.parametrize("env", ENVS)
def test_no_duplicates_and_no_leak_between_splits(raw_bank, env):
    seen: dict[str, tuple[str, str, str]] = {}
    for split in BANK_SPLITS:
        for feature in FEATURES[env]:
            for direction in DIRECTIONS:
                for text in raw_bank[env][split][feature][direction]:
                    key = normalise(text)
                    assert key, text
                    assert key not in seen, f"{text!r} ({split}) repeats {seen[key]}"
                    seen[key] = (split, feature, direction)
    train = {k for k, (split, _, _) in seen.items() if split == "train"}
    held_out = {k for k, (split, _, _) in seen.items() if split != "train"}
    assert not train & held_out


@pytest.mark.parametrize("env", ENVS)
def test_every_appendix_e_original_is_in_train(banks, env):
    bank = banks[env]
    for (feature, direction), originals in APPENDIX_E[env].items():
        train = bank.get("train", feature, direction)
        for text in originals:
            assert text in train, (env, feature, direction, text)


def test_appendix_e_covers_every_feature_and_direction():
    for env in ENVS:
        assert set(APPENDIX_E[env]) == {(f, d) for f in FEATURES[env] for d in DIRECTIONS}
    assert sum(len(v) for v in APPENDIX_E["metaworld"].values()) == 60
    assert sum(len(v) for v in APPENDIX_E["robosuite"].values()) == 40


def test_normalise():
    assert normalise("  Don't   go SO high! ") == "dont go so high"
    assert normalise("Move the end-effector higher.") == "move the end effector higher"
    assert normalise("Move  faster.") == normalise("move faster")
    assert normalise("Don\u2019t rush\u2026") == "dont rush"
    assert normalise("?!.") == ""


def test_bank_api(banks):
    bank = banks["metaworld"]
    assert bank.env == "metaworld"
    assert bank.features == FEATURES["metaworld"]
    assert "Move faster." in bank.get("train", "speed", "increase")
    assert isinstance(bank.get("val", "height", "decrease"), tuple)
    rows = bank.all_of_split("test")
    assert len(rows) == sum(len(bank.get("test", f, d)) for f in bank.features for d in DIRECTIONS)
    assert all(f in bank.features and d in DIRECTIONS and isinstance(t, str) for t, f, d in rows)
    assert rows[0][1:] == ("height", "increase")
    with pytest.raises(LangprefError, match="split"):
        bank.get("dev", "speed", "increase")
    with pytest.raises(LangprefError, match="distance_to_cube"):
        bank.get("train", "distance_to_cube", "increase")
    with pytest.raises(LangprefError, match="sideways"):
        bank.get("train", "speed", "sideways")
    with pytest.raises(LangprefError, match="split"):
        bank.all_of_split("dev")


@pytest.mark.parametrize("env", ENVS)
def test_merged_schema(banks, env):
    bank = banks[env]
    merged = bank.merged()
    assert list(merged) == list(FEATURES[env])
    for feature, by_direction in merged.items():
        assert list(by_direction) == list(DIRECTIONS)
        for direction, texts in by_direction.items():
            assert isinstance(texts, list)
            assert texts == [t for s in BANK_SPLITS for t in bank.get(s, feature, direction)]
    # JSON-serialisable, and readable back as a user file
    assert json.loads(json.dumps(merged)) == merged


def test_merged_round_trips_as_user_file(banks, tmp_path):
    path = tmp_path / "all.json"
    path.write_text(json.dumps({"_comment": "dump", **{env: banks[env].merged() for env in ENVS}}))
    for env in ENVS:
        loaded = load_user_utterances(path, env)
        assert {f: {d: list(t) for d, t in dd.items()} for f, dd in loaded.items()} == banks[env].merged()


def test_load_bank_unknown_env():
    with pytest.raises(LangprefError, match="unknown task 'kitchen'"):
        load_bank("kitchen")


# ---- user files ------------------------------------------------------------------------------------------------


def _write(tmp_path: Path, content: object, name: str = "mine.json") -> Path:
    path = tmp_path / name
    path.write_text(content if isinstance(content, str) else json.dumps(content), encoding="utf-8")
    return path


def test_user_file_partial_and_comments_ignored(tmp_path):
    path = _write(
        tmp_path,
        {
            "_comment": "my phrasings",
            "_version": 3,
            "metaworld": {
                "_note": "only speed and height",
                "speed": {"increase": ["Go faster!", "  Hurry up. ", "Go faster!"]},
                "height": {"decrease": ["Go down."], "increase": ["Go up."]},
                "distance_to_button": {},
            },
        },
    )
    got = load_user_utterances(path, "metaworld")
    assert got == {
        "height": {"increase": ("Go up.",), "decrease": ("Go down.",)},
        "speed": {"increase": ("Go faster!", "Hurry up.")},
    }
    assert list(got) == ["height", "speed"]  # canonical order
    assert list(got["height"]) == ["increase", "decrease"]
    assert load_user_utterances(str(path), "metaworld") == got  # str paths too


def test_user_file_other_env_ignored_when_valid(tmp_path):
    path = _write(
        tmp_path,
        {
            "metaworld": {"speed": {"increase": ["Go faster."]}},
            "robosuite": {"lift_success": {"decrease": ["Drop it."]}},
        },
    )
    assert load_user_utterances(path, "robosuite") == {"lift_success": {"decrease": ("Drop it.",)}}
    assert load_user_utterances(path, "metaworld") == {"speed": {"increase": ("Go faster.",)}}


MALFORMED = [
    # (file content, env, substrings the one-line message must hold)
    ('{"metaworld": {"speed": ', "metaworld", ["is not valid JSON"]),
    ("[1, 2]", "metaworld", ["top level must be an object"]),
    ({"metaworld": {"speed": {"increase": ["x"]}}, "robosuite": {"speed": 3}}, "metaworld", ["robosuite.speed"]),
    ({"metaworld-typo": {"speed": {"increase": ["x"]}}}, "metaworld", ["no 'metaworld' section", "metaworld-typo"]),
    (
        {"metaworld": {"sped": {"increase": ["Go faster."]}}},
        "metaworld",
        ["unknown feature 'sped'", "metaworld.sped", "height, speed, distance_to_button"],
    ),
    (
        {"robosuite": {"distance_to_button": {"increase": ["Away."]}}},
        "robosuite",
        ["unknown feature 'distance_to_button'", "distance_to_cube", "lift_success"],
    ),
    (
        {"metaworld": {"speed": {"faster": ["Go faster."]}}},
        "metaworld",
        ["unknown direction 'faster'", "metaworld.speed.faster", "increase, decrease"],
    ),
    ({"metaworld": {"speed": {"increase": []}}}, "metaworld", ["metaworld.speed.increase", "empty list"]),
    ({"metaworld": {"speed": {"increase": ["Go faster.", 3]}}}, "metaworld", ["speed.increase[1]", "must be a string"]),
    ({"metaworld": {"speed": {"increase": ["Go faster.", " "]}}}, "metaworld", ["speed.increase[1]", "empty phrasing"]),
    ({"metaworld": {"speed": {"increase": "Go faster."}}}, "metaworld", ["metaworld.speed.increase", "must be a list"]),
    ({"metaworld": {"speed": ["Go faster."]}}, "metaworld", ["metaworld.speed", "must be an object"]),
    ({"metaworld": ["Go faster."]}, "metaworld", ["metaworld", "must be an object"]),
    ({"robosuite": {"speed": {"increase": ["Go faster."]}}}, "metaworld", ["no 'metaworld' section", "robosuite"]),
    ({"_comment": "nothing"}, "metaworld", ["no 'metaworld' section"]),
    ({"metaworld": {"speed": {}}}, "metaworld", ["'metaworld'", "gives no phrasings"]),
    # the other env's section is validated too
    (
        {"metaworld": {"speed": {"increase": ["Go faster."]}}, "robosuite": {"bottle": {"increase": ["Away."]}}},
        "metaworld",
        ["unknown feature 'bottle'", "robosuite.bottle"],
    ),
]


@pytest.mark.parametrize("content, env, expected", MALFORMED)
def test_user_file_malformed(tmp_path, content, env, expected):
    path = _write(tmp_path, content)
    with pytest.raises(LangprefError) as info:
        load_user_utterances(path, env)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    for part in expected:
        assert part in message, (part, message)


def test_user_file_missing_or_directory(tmp_path):
    missing = tmp_path / "nope.json"
    with pytest.raises(LangprefError, match="not found") as info:
        load_user_utterances(missing, "metaworld")
    assert str(missing) in str(info.value)
    with pytest.raises(LangprefError, match="directory"):
        load_user_utterances(tmp_path, "metaworld")


def test_user_file_not_utf8(tmp_path):
    path = tmp_path / "latin.json"
    path.write_bytes(b'{"metaworld": {"speed": {"increase": ["Schneller \xfc"]}}}')
    with pytest.raises(LangprefError, match="UTF-8"):
        load_user_utterances(path, "metaworld")


def test_user_file_unknown_env_argument(tmp_path):
    path = _write(tmp_path, {"metaworld": {"speed": {"increase": ["Go faster."]}}})
    with pytest.raises(LangprefError, match="unknown task 'kitchen'"):
        load_user_utterances(path, "kitchen")


@pytest.mark.parametrize(
    "typed",
    [
        "That's good, no change.",
        "that's good, no change.",  # was read as a feature and learned
        "That\u2019s good, no change.",  # a phone's apostrophe: was refused by the feedback gate
        "  THAT'S GOOD, NO CHANGE!  ",
        "\u201cthat\u2018s good,  no change\u201d",
        "That's good, no change",
        "That's good, no change\u2026",
    ],
)
def test_no_change_is_recognised_as_people_type_it(typed):
    from langpref.language.bank import is_no_change

    assert is_no_change(typed)


@pytest.mark.parametrize(
    "typed", ["that's good, no change needed", "That's good, no change?", "Not good, no change.", "good", ""]
)
def test_only_the_no_change_phrase_itself_is_it(typed):
    from langpref.language.bank import is_no_change

    assert not is_no_change(typed)
