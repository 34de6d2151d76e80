"""What each registered language model costs and how well it reads a bank by itself (`langpref lang-models
--measure`): install size, time to embed one sentence on this machine's CPU, and the accuracy of the frozen pretrained
model reading a bank's val and test phrasings by the nearest prototype (mean unit embedding) of its train phrasings.

The numbers are what the choice of `--lang-model` trades: a bigger model costs disk and milliseconds per sentence
and may read the words of a small bank better before any training.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from langpref.language.banksource import BankSource
from langpref.language.check import Embed, read_against
from langpref.language.models import LangModelSpec


def _tree_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) if path.is_dir() else 0


def package_bytes(spec: LangModelSpec) -> int:
    """Bytes of every installed file of the model's distributions (as `du` of what pip installed)."""
    total = 0
    for dist in spec.distributions:
        for f in metadata.distribution(dist).files or []:
            p = Path(str(f.locate()))
            if p.is_file():
                total += p.stat().st_size
    return total


def unpacked_bytes(spec: LangModelSpec, local_dir: str) -> int:
    """Bytes the model takes outside its packages (an archive unpacked into the cache); 0 when it loads in place."""
    path = Path(local_dir)
    inside = any(str(path).startswith(str(metadata.distribution(d).locate_file(""))) for d in spec.distributions)
    return 0 if inside else _tree_bytes(path)


def latency_ms(embed: Embed, sentences: Sequence[str], repeats: int) -> dict[str, float]:
    """p50 and p95 of the wall time to embed ONE sentence (a batch of one, as a study embeds a typed sentence),
    over `repeats` calls cycling through `sentences`, after five warm-up calls."""
    for text in sentences[:5]:
        embed([text])
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        embed([sentences[i % len(sentences)]])
        times.append(1000 * (time.perf_counter() - start))
    return {"p50": float(np.percentile(times, 50)), "p95": float(np.percentile(times, 95)), "calls": repeats}


def bank_accuracy(embed: Embed, source: BankSource, splits: Sequence[str] = ("val", "test")) -> dict[str, Any]:
    """Share of each split's phrasings read as their own meaning by the nearest train prototype, with counts."""
    out: dict[str, Any] = {}
    for split in splits:
        check = read_against(source.split("train"), source.split(split), source.features, embed)
        out[split] = check.accuracy
        out[f"{split}_phrasings"] = sum(m.count for m in check.meanings.values())
    return out


__all__ = ["bank_accuracy", "latency_ms", "package_bytes", "unpacked_bytes"]
