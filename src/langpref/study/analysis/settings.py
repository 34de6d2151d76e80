"""The options of `langpref study export` (`ExportConfig`). Apart from `export.py` so that the CLI reads them to build
its options with no numpy imported."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class ExportConfig:
    """`langpref study export`: tables, analyses and figures of a study."""

    db: str = ""
    """The study's SQLite database (`langpref study serve --db`)."""
    out: str = ""
    """Output directory (created if missing; an existing file is refused)."""
    exclude: tuple[str, ...] = ()
    """Participants to leave out of the analyses (`--exclude 3,7`: arrival numbers, or ids as the dashboard shows them),
    besides those marked excluded on the dashboard; the tables keep every row."""
    bank_additions: str | None = None
    """Also write the phrasings participants confirmed the meaning of (`--confirm-margin`) to this JSON file for the
    lab to review: each text under each meaning chosen, with its count, participants, margins and flags (the same
    text confirmed otherwise, a text naming no change, the bank's own reading). No command reads it as a bank until
    `langpref bank review FILE --out BANK` writes the accepted ones. An existing file is refused without `--force`,
    and the study database always."""
    model: str | None = None
    """The study's model folder, where it is no longer where the study ran (the saved rewards refer to it)."""
