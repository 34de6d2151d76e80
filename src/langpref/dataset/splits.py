"""The trajectory splits of a dataset (`train`, `val`, `test`), in a module of their own so the command line can
offer them as choices without importing numpy (`langpref --help` stays instant). The bank's phrasing splits are
`langpref.language.bank.BANK_SPLITS`: the same three names, another concept."""

from __future__ import annotations

from typing import Literal, get_args

Split = Literal["train", "val", "test"]
"""A trajectory split of a dataset."""
SPLITS: tuple[str, ...] = get_args(Split)
