"""Phrasings proposed by an instruction model (`langpref bank augment --proposer local|endpoint`), for concepts that
no template or corpus covers: a lab's own feature, described in its task file, with its bank's few phrasings as
examples.

A small instruction model picks a feature and direction right far less often than it writes a fluent sentence, so it
proposes and the task's own language side decides: a proposal that the feedback gate refuses (praise, small talk:
`screen`) is dropped, and every other one is read back (`langpref.language.check.
read_against`, the reading of `bank check --utterances`: nearest prototype of the bank's train phrasings, with the
pretrained sentence encoder or a trained checkpoint's) and kept only when it is read as the meaning it was asked for.
What is dropped is counted with why. Nothing here writes into a bank: the caller writes the kept proposals to a
review file, as it does the templates' (`langpref.language.augment`).

The model is asked for plain JSON, `{"phrasings": [...]}`, in the prompt and with the standard `response_format`;
the answer is validated here (a reply that is not that JSON is asked once more, then counted as bad JSON).
"""

from __future__ import annotations

import json
import re
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from langpref.errors import LangprefError
from langpref.language.bank import DIRECTIONS, normalise
from langpref.language.banksource import BankSource, Phrasings
from langpref.language.check import Embed, meaning_name, read_against
from langpref.language.llm import Chat, Messages

MAX_WORDS = 20
"""A proposal longer than this is not a piece of feedback."""
EXAMPLES = 6
"""Train phrasings of the meaning shown to the model."""
SYSTEM = (
    "You write short sentences that a person says to a robot to change how it does a task. "
    "You answer with JSON only, an object with one key, phrasings, a list of strings."
)
_ONE_SHOT = (
    "Task: a robot vacuum cleans a living room.\n"
    "What is measured: noise, how loud the vacuum is.\n"
    "The person wants less noise than the robot just showed.\n"
    "Sentences people said for this:\n- Be quieter.\n- Turn the noise down.\n"
    "Write 5 new, different sentences that mean the same."
)
_ONE_SHOT_ANSWER = json.dumps(
    {
        "phrasings": [
            "Quieter, please.",
            "Don't be so loud.",
            "That is far too noisy.",
            "Make less noise.",
            "You're way too loud.",
        ]
    }
)


class BadJSON(LangprefError):
    """A model's reply that is not the JSON asked for."""


@dataclass(frozen=True)
class TaskWords:
    """What the prompt says of a task: its description and each feature's."""

    description: str
    features: dict[str, str]
    """feature -> a one-line description (the feature's name in words when the task has none)."""


def task_words(source: BankSource, where: str | Path) -> TaskWords:
    """The description of the task a bank belongs to: its task file, the task a dataset stores, or a task by name."""
    from langpref.tasks import get_task

    task = None
    path = Path(where)
    if path.suffix == ".toml" and path.is_file():
        from langpref.tasks.taskfile import read_task_file

        task = read_task_file(path)
    elif path.is_dir():
        from langpref.tasks.taskfile import load_stored_task

        task = load_stored_task(path)
    if task is None:
        try:
            task = get_task(source.task)
        except (LangprefError, KeyError):
            task = None
    described = dict(zip(task.features, task.feature_descriptions)) if task is not None else {}
    words = {f: described.get(f) or f.replace("_", " ") for f in source.features}
    return TaskWords(task.description if task is not None else f"the task {source.task}", words)


def prompt(words: TaskWords, feature: str, direction: str, examples: Sequence[str], n: int) -> Messages:
    """The chat asking for `n` phrasings of (feature, direction): a one-shot example about another machine, then the
    task, the feature's description, the direction in words and the meaning's own phrasings."""
    name = feature.replace("_", " ")
    more = "more" if direction == "increase" else "less"
    shown = "\n".join(f"- {t}" for t in examples[:EXAMPLES]) or "- (none yet)"
    user = (
        f"Task: {words.description}\n"
        f"What is measured: {name}, {words.features.get(feature, name)}.\n"
        f"The person wants {more} {name} than the robot just showed.\n"
        f"Sentences people said for this:\n{shown}\n"
        f"Write {n} new, different sentences that mean the same: plain requests, negations of the opposite "
        "request, and remarks about what the robot did wrong."
    )
    return [
        {"role": "system", "content": SYSTEM},
        {"role": "user", "content": _ONE_SHOT},
        {"role": "assistant", "content": _ONE_SHOT_ANSWER},
        {"role": "user", "content": user},
    ]


def parse_phrasings(text: str) -> tuple[list[str], list[str]]:
    """(the phrasings of a reply `{"phrasings": [strings]}`, the entries that are not a sentence). A code fence
    around the JSON is allowed; anything else raises `BadJSON` saying what was wrong."""
    body = re.sub(r"^\s*```(?:json)?\s*|\s*```\s*$", "", text.strip())
    try:
        doc = json.loads(body)
    except json.JSONDecodeError as exc:
        raise BadJSON(f"not JSON ({exc.msg} at character {exc.pos}): {body[:60]!r}") from None
    items = doc.get("phrasings") if isinstance(doc, dict) else None
    if not isinstance(items, list):
        raise BadJSON(f'not an object with a "phrasings" list: {body[:60]!r}')
    good = [" ".join(t.split()) for t in items if isinstance(t, str) and _sentence(t)]
    junk = [str(t)[:80] for t in items if not (isinstance(t, str) and _sentence(t))]
    return good, junk


def _sentence(text: str) -> bool:
    words = re.findall(r"[A-Za-z']+", text)
    return 1 <= len(words) <= MAX_WORDS and "..." not in text and len(text) <= 160


@dataclass
class Proposals:
    """The kept proposals per meaning, and every proposal dropped with why."""

    kept: Phrasings
    asked: dict[str, int]
    """meaning -> phrasings the model returned for it (valid sentences, before any filter)."""
    dropped: dict[str, list[dict[str, str]]] = field(default_factory=dict)
    """meaning -> [{"text", "why"}] for each proposal dropped."""
    bad_replies: int = 0
    """Requests whose every reply was bad JSON."""
    requests: int = 0
    seconds: float = 0.0

    def drop(self, meaning: str, text: str, why: str) -> None:
        self.dropped.setdefault(meaning, []).append({"text": text, "why": why})

    def reasons(self) -> dict[str, int]:
        """why -> how many were dropped for it ("read back as X/Y" counted as "read back as another meaning")."""
        whys = [d["why"] for ds in self.dropped.values() for d in ds]
        return dict(Counter("read back as another meaning" if w.startswith("read back as") else w for w in whys))


def reply_schema(n: int) -> dict:
    """The JSON schema of a reply of at most `n` phrasings, each one short sentence."""
    item = {"type": "string", "minLength": 4, "maxLength": 120}
    listed = {"type": "array", "items": item, "minItems": 1, "maxItems": n}
    return {"type": "object", "properties": {"phrasings": listed}, "required": ["phrasings"]}


def ask(chat: Chat, messages: Messages, n: int, seed: int, tries: int = 2) -> tuple[list[str], list[str], bool]:
    """(phrasings, entries not a sentence, whether every try was bad JSON) of one request, asked again on a bad
    reply (with the next seed)."""
    for k in range(tries):
        try:
            good, junk = parse_phrasings(chat(messages, 24 * n + 64, 0.7, seed + k, reply_schema(n)))
            return good, junk, False
        except BadJSON:
            continue
    return [], [], True


def generate(
    chat: Chat, source: BankSource, words: TaskWords, n: int, seed: int = 0, progress: bool = False
) -> Proposals:
    """Ask the model for `n` phrasings per meaning; keep those new to the bank (any split) and proposed for one
    meaning only (a text asked for two meanings reads as neither). Raises `BadJSON` when no reply was the JSON asked
    for."""
    from tqdm import tqdm

    train = source.split("train")
    out = Proposals({f: {d: [] for d in DIRECTIONS} for f in source.features}, {})
    owners: dict[str, set[str]] = {}
    start = time.perf_counter()
    meanings = [(f, d) for f in source.features for d in DIRECTIONS]
    for i, (f, d) in enumerate(tqdm(meanings, desc="asking the model", unit="meaning", disable=not progress)):
        name = meaning_name(f, d)
        texts, junk, failed = ask(chat, prompt(words, f, d, train[f][d], n), n, seed + 101 * i)
        out.requests += 1
        out.bad_replies += failed
        out.asked[name] = len(texts)
        for text in junk:
            out.drop(name, text, "not a sentence")
        for text in _new(out, name, texts, _known(source)):
            owners.setdefault(normalise(text), set()).add(name)
            out.kept[f][d].append(text)
    out.seconds = time.perf_counter() - start
    if out.bad_replies == out.requests:
        raise BadJSON(f'bad JSON from the model: none of its {out.requests} replies was {{"phrasings": [...]}}')
    for f, d in meanings:
        name = meaning_name(f, d)
        for text in out.kept[f][d]:
            if len(owners[normalise(text)]) > 1:
                others = sorted(owners[normalise(text)] - {name})
                out.drop(name, text, "also proposed for " + ", ".join(others))
        out.kept[f][d] = [t for t in out.kept[f][d] if len(owners[normalise(t)]) == 1]
    return out


def _known(source: BankSource) -> set[str]:
    """The bank's phrasings of every split and the prompt's example, normalised."""
    known = {
        normalise(t) for split in source.splits.values() for by in split.values() for ts in by.values() for t in ts
    }
    return known | {normalise(t) for t in json.loads(_ONE_SHOT_ANSWER)["phrasings"]}


def _new(out: Proposals, name: str, texts: list[str], known: set[str]) -> list[str]:
    """The texts of one reply that repeat neither the bank, the prompt's example nor each other (the rest dropped)."""
    seen: set[str] = set()
    new = []
    for text in texts:
        key = normalise(text)
        if key in known:
            out.drop(name, text, "repeats a bank phrasing or the prompt's example")
        elif key in seen:
            out.drop(name, text, "repeats another proposal")
        else:
            seen.add(key)
            new.append(text)
    return new


def screen(proposals: Proposals, is_feedback: Callable[[str], bool]) -> None:
    """Drop the proposals that are not feedback on how the robot moves at all (praise, small talk, questions): the
    read-back's nearest prototype would still read each as some meaning. `is_feedback` is the feedback gate's test
    (`langpref.language.relevance.FeedbackGate`, as the study and `embed` use it)."""
    for f, by in proposals.kept.items():
        for d, texts in by.items():
            for text in texts:
                if not is_feedback(text):
                    proposals.drop(meaning_name(f, d), text, "not feedback on the robot's motion (the feedback gate)")
            by[d] = [t for t in texts if is_feedback(t)]


def read_back(proposals: Proposals, train: Phrasings, features: Sequence[str], embed: Embed, encoder: str) -> None:
    """Keep only the proposals that `embed`'s reading of the bank (nearest train prototype) reads as their own
    meaning; the others move to `dropped` with the meaning they were read as."""
    check = read_against(train, proposals.kept, features, embed, encoder=encoder, method="read back")
    for f in features:
        for d in DIRECTIONS:
            name = meaning_name(f, d)
            wrong = dict(check.meanings[name].misread)
            for text in proposals.kept[f][d]:
                if text in wrong:
                    proposals.drop(name, text, f"read back as {wrong[text]}")
            proposals.kept[f][d] = [t for t in proposals.kept[f][d] if t not in wrong]


__all__ = [
    "BadJSON",
    "Proposals",
    "TaskWords",
    "ask",
    "generate",
    "parse_phrasings",
    "prompt",
    "read_back",
    "reply_schema",
    "screen",
]
