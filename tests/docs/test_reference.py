"""The command-line reference page (docs/reference/cli.md) is what the commands print: written by
`python -m langpref.cli.reference` from the parser itself, it fails here as soon as a command's help changes without
the page being written again."""

from __future__ import annotations

from pathlib import Path

from langpref.cli import reference

ROOT = Path(__file__).parents[2]


def test_the_committed_page_is_the_generated_one():
    page = ROOT / reference.PAGE
    assert page.read_text() == reference.render(), (
        f"{reference.PAGE} differs from the commands' help: run `python -m langpref.cli.reference` and commit it"
    )


def test_every_command_has_a_section_with_its_every_option(tmp_path):
    text = reference.render()
    for words in (("langpref", "train"), ("langpref", "study", "serve"), ("langpref", "experiment", "verdict")):
        assert f"## `{' '.join(words)}`" in text and f"(#{'-'.join(words)})" in text
    train = text.split("## `langpref train`")[1].split("\n## ")[0]
    assert "--threads" in train and "--augment-phrasings" in train  # options --help alone does not show
    assert reference.main(["--out", str(tmp_path / "cli.md")]) == 0
    assert reference.main(["--check", "--out", str(tmp_path / "cli.md")]) == 0
    (tmp_path / "cli.md").write_text("stale\n")
    assert reference.main(["--check", "--out", str(tmp_path / "cli.md")]) == 1
