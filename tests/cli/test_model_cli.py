import json

import pytest

from langpref.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_train_evaluate_embed_visualize_end_to_end(tiny_data, tmp_path, capsys):
    model = tmp_path / "m"
    code, out, err = run(
        capsys,
        "train",
        "--data",
        str(tiny_data),
        "--out",
        str(model),
        "--freeze-language",
        "--epochs",
        "3",
        "--batch-size",
        "64",
        "--latent-dim",
        "16",
        "--max-length",
        "16",
        "--device",
        "cpu",
        "--json",
    )
    assert code == 0, err
    summary = json.loads(out)
    assert summary["stages"] == 1 and summary["out"] == str(model)
    assert "stage 1" in err  # the progress bar goes to stderr

    code, out, err = run(
        capsys, "evaluate", "--model", str(model), "--data", str(tiny_data), "--split", "val", "--json"
    )
    assert code == 0, err
    res = json.loads(out)
    assert (
        0 <= res["accuracy"] <= 1
        and res["num_samples"] > 0
        and set(res["per_feature"]) <= {"height", "speed", "distance_to_button"}
    )

    code, out, err = run(
        capsys,
        "evaluate",
        "--model",
        str(model),
        "--data",
        str(tiny_data),
        "--split",
        "val",
        "--phrasing-split",
        "train",
        "--json",
    )
    assert code == 0 and json.loads(out)["utterances"] == "bank:train", err

    user = tmp_path / "mine.json"
    user.write_text(json.dumps({"_note": "mine", "metaworld": {"speed": {"increase": ["Hurry up!"]}}}))
    code, out, err = run(
        capsys, "evaluate", "--model", str(model), "--data", str(tiny_data), "--utterances", str(user), "--json"
    )
    assert code == 0, err
    res = json.loads(out)
    assert list(res["per_feature"]) == ["speed"]
    hurry = res["reading_accuracy"]

    code, out, err = run(capsys, "embed", "--model", str(model), "Hurry up!", "--json")
    assert code == 0, err
    read = json.loads(out)
    assert set(read) >= {"feature", "direction", "confidence"}
    # evaluate's reading accuracy is embed's reading of each phrasing, scored against the file's label
    assert hurry == float((read["feature"], read["direction"]) == ("speed", "increase"))
    assert len(res["misread"]) == 1 - hurry and read["out_of_task"] is None

    # several texts in one model load; one about what Meta-World does not measure says so, small talk is refused
    texts = ["Hurry up!", "Open the drawer further.", "I had soup today."]
    code, out, err = run(capsys, "embed", "--model", str(model), *texts, "--json")
    assert code == 0, err
    readings = json.loads(out)["readings"]
    assert [r["text"] for r in readings] == texts and readings[0]["out_of_task"] is None
    assert (
        readings[1]["out_of_task"]["concept"] == "opening"
        and "does not measure" in readings[1]["out_of_task"]["message"]
    )
    assert "error" in readings[2] and "feature" in readings[2]

    code, out, err = run(
        capsys, "visualize", "--model", str(model), "--data", str(tiny_data), "--out", str(tmp_path / "v.png")
    )
    assert code == 0, err and (tmp_path / "v.png").stat().st_size > 1000

    code, out, err = run(capsys, "train", "--data", str(tiny_data), "--out", str(model), "--freeze-language")
    assert code == 2 and "already exists" in err and err.count("\n") == 1

    code, out, err = run(
        capsys,
        "train",
        "--data",
        str(tiny_data),
        "--out",
        str(tmp_path / "m2"),
        "--freeze-language",
        "--utterances",
        str(user),
        "--extend-bank",
        "--epochs",
        "1",
        "--latent-dim",
        "8",
        "--no-observation-deltas",
        "--json",
    )
    assert code == 0, err
    saved = json.loads((tmp_path / "m2" / "config.json").read_text())
    assert saved["train_config"]["utterances"] == str(user) and saved["train_config"]["extend_bank"] is True
    assert saved["model"]["observation_deltas"] is False and len(saved["normalisation"]["mean"]) == 6 + 2


@pytest.mark.parametrize(
    "argv,match",
    [
        (["embed", "--model", "MODEL", "   "], "empty"),
        (["embed", "--model", "MODEL", "qwertyuiop"], "does not read as feedback"),
        (["evaluate", "--model", "NOPE", "--data", "DATA"], "does not exist"),
    ],
)
def test_one_line_errors(trained, tiny_data, capsys, argv, match):
    argv = [str(trained.out) if a == "MODEL" else str(tiny_data) if a == "DATA" else a for a in argv]
    code, out, err = run(capsys, *argv)
    assert code == 2 and match in err and err.count("\n") == 1 and out == ""


def test_utterances_prints_the_bank(capsys):
    code, out, _ = run(capsys, "utterances", "--env", "metaworld", "--json")
    assert code == 0
    bank = json.loads(out)
    assert set(bank) == {"height", "speed", "distance_to_button"}
    assert "Move faster." in bank["speed"]["increase"]


def test_evaluate_summary_names_no_phrasing_and_counts_near_copies(trained, tiny_data, tmp_path, capsys):
    from langpref.language.bank import load_bank

    copied = load_bank("metaworld").phrasings["train"]["speed"]["increase"][0]
    typo = copied.rstrip(".!") + "!!"
    user = tmp_path / "apart.json"
    user.write_text(json.dumps({"metaworld": {"speed": {"increase": [typo, "Pick up the pace, would you."]}}}))
    argv = ["evaluate", "--model", str(trained.out), "--data", str(tiny_data), "--utterances", str(user), "--json"]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    full = json.loads(out)
    assert full["near_copies"]["num"] == 1 and full["near_copies"]["texts"] == {typo: copied}
    assert full["near_copies"]["without"]["num_phrasings"] == 1
    assert (
        full["near_copies"]["without"]["accuracy"] == full["per_phrasing"]["Pick up the pace, would you."]["accuracy"]
    )
    code, out, err = run(capsys, *argv, "--summary")
    assert code == 0, err
    assert typo not in out and "Pick up the pace" not in out
    assert json.loads(out)["near_copies"]["without"] == full["near_copies"]["without"]
    code, out, err = run(capsys, *argv[:-1], "--summary")
    assert code == 0 and "near-copies of a train phrasing" in out and "Pick up" not in out, err


def test_bank_gate_counts_without_printing_a_text(tmp_path, capsys):
    feedback = tmp_path / "feedback.json"
    feedback.write_text(json.dumps({"metaworld": {"speed": {"increase": ["Could you hurry it along a bit?"]}}}))
    junk = tmp_path / "junk.json"
    junk.write_text(json.dumps({"texts": ["asdfgh", "What time is lunch?", "Move a little faster."]}))
    code, out, err = run(
        capsys, "bank", "gate", "metaworld", "--feedback", str(feedback), "--not-feedback", str(junk), "--json"
    )
    assert code == 0, err
    report = json.loads(out)
    assert report["feedback"] == {"num": 1, "let_through": 1, "lowest_score": report["feedback"]["lowest_score"]}
    assert report["not_feedback"]["num"] == 3 and report["not_feedback"]["refused"] == 2  # the last is feedback
    assert "asdfgh" not in out and "lunch" not in out
    junk.write_text("{not json")
    code, out, err = run(capsys, "bank", "gate", "metaworld", "--not-feedback", str(junk))
    assert code == 2 and "cannot be read as JSON" in err and err.count("\n") == 1
