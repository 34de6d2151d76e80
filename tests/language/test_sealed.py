"""The sealed held-out phrasings (heldout/sealed/): well-formed, read by no code, disjoint from the shipped bank.

The sealed set is for final reporting only (see heldout/sealed/README.md). These tests check its schema, that no file
of the repository but prose refers to it or globs its way into heldout/, and that none of its phrasings is (after
normalisation) a phrasing of the bank of the same task.
"""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import tomllib
from pathlib import Path

import pytest

import langpref.tasks  # noqa: F401  (registers the built-in tasks before the bank is used)
from langpref.language.bank import load_bank, load_user_utterances, normalise

ROOT = Path(__file__).resolve().parents[2]
SEALED = ROOT / "heldout" / "sealed" / "utterances.json"
NOT_FEEDBACK = ROOT / "heldout" / "sealed" / "not_feedback.json"
PER_DIRECTION = 10
TASKS = ("metaworld", "robosuite", "drawer-open", "metaworld-reach")


DRAWER_TASK_FILE = ROOT / "examples" / "own_robot" / "task.toml"
# Meta-World's Sawyer: 39-number observation ([observation] in task.toml), 4 actions
DRAWER_OBS_DIM, DRAWER_ACTION_DIM = 39, 4


@pytest.fixture(scope="module", autouse=True)
def _drawer_open_registered():
    """drawer-open is a recorded task (examples/own_robot), absent from a bare process's registry; register it from
    its task file (as tests/tasks and tests/dataset do for theirs) so that the loader accepts the whole sealed file
    and its bank can be compared. metaworld-reach comes from the example plugin's entry point when it is installed."""
    if "drawer-open" not in langpref.tasks.task_names():
        from langpref.tasks.taskfile import read_task_file

        task_file = read_task_file(DRAWER_TASK_FILE)
        langpref.tasks.register_task(task_file.task(DRAWER_OBS_DIM, DRAWER_ACTION_DIM, task_file.utterances))
    yield


def _task_features(task: str) -> tuple[str, ...]:
    """The task's feature names: from the registry when it is there, else from the task's own definition file."""
    if task in langpref.tasks.task_names():
        return tuple(langpref.tasks.get_task(task).features)
    if task == "drawer-open":
        return tuple(tomllib.loads(DRAWER_TASK_FILE.read_text())["features"])
    if task == "metaworld-reach":
        from tests.factories import require

        TASK = require("langpref_reach", "pip install -e examples/plugin, as make install does").TASK

        return tuple(TASK.features)
    raise AssertionError(f"unknown task {task}")


def _sealed() -> dict:
    return json.loads(SEALED.read_text(encoding="utf-8"))


def _phrasings(section: dict) -> list[str]:
    return [
        p for f, dirs in section.items() if not f.startswith("_") for d in ("increase", "decrease") for p in dirs[d]
    ]


@pytest.mark.parametrize("task", TASKS)
def test_loads_with_the_user_utterance_loader(task):
    if task not in langpref.tasks.task_names():
        pytest.skip(f"{task} is not registered in this process (test_schema checks its section)")
    if not set(t for t in _sealed() if not t.startswith("_")) <= set(langpref.tasks.task_names()):
        pytest.skip("the loader rejects a file naming an unregistered task; test_schema checks every section")
    loaded = load_user_utterances(SEALED, task)
    assert set(loaded) == set(_task_features(task))
    for feature, dirs in loaded.items():
        assert set(dirs) == {"increase", "decrease"}, feature
        for direction, phrasings in dirs.items():
            assert len(phrasings) == PER_DIRECTION, (feature, direction)


@pytest.mark.parametrize("task", TASKS)
def test_schema(task):
    data = _sealed()
    assert task in data, f"no {task} section"
    section = data[task]
    features = _task_features(task)
    assert set(f for f in section if not f.startswith("_")) == set(features)
    for feature in features:
        assert set(k for k in section[feature] if not k.startswith("_")) == {"increase", "decrease"}, feature
        for direction in ("increase", "decrease"):
            phrasings = section[feature][direction]
            assert len(phrasings) == PER_DIRECTION, (feature, direction)
            assert all(isinstance(p, str) and p.strip() for p in phrasings), (feature, direction)
    normalised = [normalise(p) for p in _phrasings(section)]
    duplicates = sorted({n for n in normalised if normalised.count(n) > 1})
    assert not duplicates, f"{task}: phrasings repeated after normalisation: {duplicates}"


def test_has_a_comment():
    assert "_comment" in _sealed()


@pytest.mark.parametrize("name", ["not_feedback.json", "not_feedback_v2.json"])
def test_not_feedback(name):
    doc = json.loads((ROOT / "heldout" / "sealed" / name).read_text(encoding="utf-8"))
    texts = doc["texts"]
    assert len(texts) == 60
    assert all(isinstance(t, str) and t for t in texts)
    assert len({t.lower() for t in texts}) == len(texts)


def test_the_first_not_feedback_file_is_marked_spent_for_the_gate():
    assert "SPENT for the feedback gate" in json.loads(NOT_FEEDBACK.read_text(encoding="utf-8"))["_comment"]


# Who may name the sealed set: its own folder, this test, and prose (Markdown: the reporting command line is written in
# docs/results.md, and README and CHANGELOG tell of it). Nothing else in the repository, and no glob or listing that
# reaches into heldout/ (which a pattern such as `heldout/*/utterances.json` or a walk of the repository does).
MAY_NAME_IT = ("heldout/sealed/", "tests/language/test_sealed.py")
PROSE = (".md",)
SHELL = ("Makefile", ".sh", ".ci/", ".yml", ".yaml", ".toml", ".cfg", ".ini", ".txt")
_ROOT_DIR = r"""(?:ROOT|REPO\w*|repo_root|Path\s*\(\s*(?:["']\.?["'])?\s*\)|Path\.cwd\s*\(\s*\))"""
_NOT_A_FILE = r"""(?![\w/.-]*\.\w)"""  # `heldout` not followed by a file's path (heldout/utterances.json)
READS_IT = {
    "names the sealed set": re.compile(r"sealed", re.I),
    "a glob into heldout/": re.compile(r"""heldout/[^\s"'`]*[*?\[{]"""),
    "a glob onto the heldout folder": re.compile(r"""["']heldout["']\s*/\s*f?["'][^"'\n]*[*?\[{]"""),
    "lists the heldout folder": re.compile(r"""["']heldout/?["']\s*\)*\s*\.\s*(?:r?glob|iterdir|walk)\b"""),
    "lists a folder of heldout": re.compile(
        r"""\b(?:walk|listdir|scandir|i?glob|copytree|make_archive)\s*\([^)\n]*heldout""" + _NOT_A_FILE
    ),
    "walks the repository (heldout/sealed/ too)": re.compile(
        _ROOT_DIR
        + r"""\s*\)?\s*\.\s*(?:rglob\s*\(|walk\s*\(|glob\s*\(\s*f?["']\*\*)"""
        + r"""|\bos\.walk\s*\(\s*(?:ROOT|REPO\w*|repo_root|["']\.?["'])\s*[,)]"""
        + r"""|\bglob\.i?glob\s*\(\s*f?["']\*\*"""
    ),
}
SHELL_READS_IT = re.compile(r"""\b(?:find|ls|cp|rsync|tar|zip|du|grep\s+-r\w*)\s[^\n|;&]*\bheldout/?""" + _NOT_A_FILE)


def _repository_files() -> list[str]:
    """Every file of the checkout, tracked or new but not ignored, as a path from the root (outside a git checkout:
    every file below the root but the ignored build, data and environment folders)."""
    try:
        listed = subprocess.run(
            ["git", "-C", str(ROOT), "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            capture_output=True,
            check=True,
        ).stdout.decode()
        files = {f for f in listed.split("\0") if f}
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", ".venv-lerobot", "build", "dist", "data", "results", "models", "runs", "__pycache__"}
        files = {p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*") if not skip & set(p.relative_to(ROOT).parts)}
    return sorted(f for f in files if (ROOT / f).is_file())


def _offences(path: str, text: str) -> list[str]:
    """What in `text` (the file at `path`) names or reaches the sealed set (see READS_IT)."""
    if path.startswith(MAY_NAME_IT) or path.endswith(PROSE):
        return []
    found = [what for what, pattern in READS_IT.items() if pattern.search(text)]
    if (path.endswith(SHELL) or path.startswith(SHELL)) and SHELL_READS_IT.search(text):
        found.append("a shell command lists heldout/")
    return found


def test_no_file_reads_the_sealed_set():
    """No file of the repository but prose names the sealed set or globs, lists or walks its way into it: src, tests,
    benchmarks, examples, the Makefile, CI, configuration."""
    files = _repository_files()
    assert "Makefile" in files and "src/langpref/cli/__init__.py" in files and "heldout/sealed/utterances.json" in files
    offenders = {}
    for f in files:
        raw = (ROOT / f).read_bytes()
        if b"\0" in raw[:8192]:  # binary (figures, fixtures)
            continue
        if found := _offences(f, raw.decode("utf-8", errors="replace")):
            offenders[f] = found
    assert not offenders, f"these files refer to the sealed set or reach into heldout/: {offenders}"


@pytest.mark.parametrize(
    "path,text",
    [
        ("src/langpref/x.py", 'load_user_utterances("heldout/sealed/utterances.json", env)'),
        ("benchmarks/x.py", 'sorted(glob.glob("heldout/*/utterances.json"))'),
        ("examples/x.py", 'for p in (ROOT / "heldout").rglob("*.json"):'),
        ("src/langpref/x.py", 'files = Path("heldout").glob("**/utterances.json")'),
        ("src/langpref/x.py", 'ROOT / "heldout" / "*" / "utterances.json"'),
        ("src/langpref/x.py", 'f"heldout/{name}/utterances.json"'),
        ("src/langpref/x.py", "for d, _, names in os.walk(ROOT / 'heldout'):"),
        ("src/langpref/x.py", 'os.listdir("heldout")'),
        ("tests/x.py", 'phrasings = [json.loads(p.read_text()) for p in ROOT.rglob("utterances.json")]'),
        ("tests/x.py", "for d, _, names in os.walk(ROOT):"),
        ("benchmarks/x.py", 'glob.glob("**/utterances.json", recursive=True)'),
        ("Makefile", "\tfor f in heldout/*/utterances.json; do langpref evaluate --utterances $$f; done"),
        ("Makefile", "\tcp -r heldout build/"),
        (".ci/run", "find heldout -name '*.json'"),
    ],
)
def test_the_tripwire_catches_a_read_of_the_sealed_set(path, text):
    assert _offences(path, text), text


@pytest.mark.parametrize(
    "path,text",
    [
        ("src/langpref/x.py", 'load_user_utterances(ROOT / "heldout" / "utterances.json", env)'),
        ("benchmarks/x.py", 'json.loads((ROOT / "heldout" / "not_feedback.json").read_text())'),
        ("Makefile", "\tlangpref experiment improve --phrasings heldout/utterances.json"),
        ("tests/x.py", 'NEGATED = HELDOUT.parent / "negated" / "utterances.json"'),
        ("tests/x.py", 'for path in (ROOT / "src").rglob("*.py"):'),
        ("src/langpref/x.py", 'for old in self.root.glob("*.json"):'),
        ("docs/results.md", "langpref evaluate --utterances heldout/sealed/utterances.json"),
    ],
)
def test_the_tripwire_lets_the_named_held_out_files_be(path, text):
    assert not _offences(path, text), text


def _strings(obj, seen=None) -> set[str]:
    """Every string held anywhere in `obj` (dicts' keys and values, sequences, dataclasses, plain objects)."""
    seen = set() if seen is None else seen
    if isinstance(obj, str):
        return {obj}
    if id(obj) in seen:
        return set()
    seen.add(id(obj))
    out: set[str] = set()
    if isinstance(obj, dict):
        for k, v in obj.items():
            out |= _strings(k, seen) | _strings(v, seen)
    elif isinstance(obj, (list, tuple, set, frozenset)):
        for v in obj:
            out |= _strings(v, seen)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for field in dataclasses.fields(obj):
            out |= _strings(getattr(obj, field.name), seen)
    elif hasattr(obj, "__dict__") and not isinstance(obj, type):
        for v in vars(obj).values():
            out |= _strings(v, seen)
    return out


@pytest.mark.parametrize("task", TASKS)
def test_disjoint_from_the_shipped_bank(task):
    if task not in langpref.tasks.task_names():
        pytest.skip(f"{task} is not registered in this process; its bank cannot be loaded")
    if task == "drawer-open":
        # A recorded task ships its bank unsplit, next to its task file ({feature: {direction: [...]}}); the split
        # copy exists only inside an imported dataset, so read the shipped file itself.
        from langpref.tasks.taskfile import read_task_file

        shipped = json.loads(read_task_file(DRAWER_TASK_FILE).utterances.read_text(encoding="utf-8"))
    else:
        shipped = load_bank(task)
    bank = {normalise(s) for s in _strings(shipped)}
    assert len(bank) > 20, "the bank came back (nearly) empty; the scan did not find its phrasings"
    clashes = sorted(p for p in _phrasings(_sealed()[task]) if normalise(p) in bank)
    assert not clashes, f"{task}: sealed phrasings also in the shipped bank: {clashes}"


# Overlap tripwire (issue 42, item 1). Every held-out file, named one by one; `test_every_held_out_file_is_named`
# fails when a new one is added to heldout/ without being named here.
NOT_FEEDBACK_V2 = ROOT / "heldout" / "sealed" / "not_feedback_v2.json"
HELD_OUT = (
    ROOT / "heldout" / "utterances.json",
    ROOT / "heldout" / "not_feedback.json",
    ROOT / "heldout" / "negated" / "utterances.json",
    SEALED,
    NOT_FEEDBACK,
    NOT_FEEDBACK_V2,
)
# Every bank shipped in the repository: the built-in tasks' (split) and the examples' (the plugin's split, the
# drawer's unsplit: `langpref import` splits it, so any of its phrasings may be a train phrasing).
BANKS = (
    ROOT / "src" / "langpref" / "tasks" / "metaworld" / "utterances.json",
    ROOT / "src" / "langpref" / "tasks" / "robosuite" / "utterances.json",
    ROOT / "examples" / "plugin" / "src" / "langpref_reach" / "utterances.json",
    ROOT / "examples" / "own_robot" / "utterances.json",
    ROOT / "examples" / "reach" / "utterances.json",
)
# A data file under src/ (the gate's off-topic texts, any later one) must not copy a held-out text even loosely: at 0.8
# the helper also takes a changed word in a longer text ("what is the capital of Spain" / "... of Australia"), and a
# text of two or more words inside another ("write me a poem" / "write me a poem about autumn") is one too.
DATA_NEAR_COPY_RATIO = 0.8


def _src_data_files() -> list[Path]:
    """Every JSON file in a `data` folder under src/."""
    return sorted(p for p in (ROOT / "src").rglob("*.json") if "data" in p.relative_to(ROOT / "src").parts[:-1])


def _texts_of(obj) -> list[str]:
    """Every text of a data or utterance file: the strings under keys not starting with `_` (comments), in lists."""
    if isinstance(obj, str):
        return [obj]
    if isinstance(obj, dict):
        return [t for k, v in obj.items() if not str(k).startswith("_") for t in _texts_of(v)]
    if isinstance(obj, list):
        return [t for v in obj for t in _texts_of(v)]
    return []


def _held_out_texts() -> dict[str, list[str]]:
    return {p.relative_to(ROOT).as_posix(): _texts_of(json.loads(p.read_text(encoding="utf-8"))) for p in HELD_OUT}


def _key(text: str) -> str:
    """The bank's normalisation, or for a text of punctuation or symbols only the text itself without spaces."""
    return normalise(text) or "".join(text.split())


def _copies(ours: str, held: str) -> bool:
    """Whether `ours` is an exact or near copy of `held`: the same after normalisation, or (when both have Latin
    words) within `DATA_NEAR_COPY_RATIO` by the near-copy helper, or two or more words of one inside the other."""
    from langpref.language.near_copies import normalise as words
    from langpref.language.near_copies import similarity

    if _key(ours) == _key(held):
        return True
    a, b = words(ours), words(held)
    if not a or not b:  # no Latin words (symbols, other scripts): only an exact copy counts
        return False
    short, long = sorted((a, b), key=len)
    return similarity(ours, held) >= DATA_NEAR_COPY_RATIO or (len(short.split()) >= 2 and f" {short} " in f" {long} ")


def _bank_train_texts(path: Path, splits: tuple[str, ...] = ("train",)) -> list[str]:
    """The phrasings of a bank's `splits` (all of an unsplit bank's: `langpref import` splits it)."""
    doc = json.loads(path.read_text(encoding="utf-8"))
    return _texts_of({k: v for k, v in doc.items() if k in splits} if "train" in doc else doc)


def test_every_held_out_file_is_named():
    on_disk = {ROOT / f for f in _repository_files() if f.startswith("heldout/") and f.endswith(".json")}
    assert on_disk == set(HELD_OUT), f"held-out files not named in HELD_OUT: {sorted(on_disk - set(HELD_OUT))}"


def test_every_bank_is_named():
    found = {ROOT / f for f in _repository_files() if f.endswith("utterances.json") and not f.startswith("heldout/")}
    assert found == set(BANKS), f"banks not named in BANKS: {sorted(found - set(BANKS))}"


def _data_texts(path: Path) -> list[str]:
    """The texts of a data file under src/. The comparative corpus's lexicon holds word lists ("slow down", "a bit ")
    that any feedback contains, and whole sentences (its `indirect` forms): its whole sentences are its texts here,
    and the sentences it makes are checked as a corpus (`test_the_comparative_corpus_copies_no_held_out_text`)."""
    doc = json.loads(path.read_text(encoding="utf-8"))
    if path.name == "comparative_concepts.json":
        return [t for c in doc["concepts"].values() for d in ("increase", "decrease") for t in c[d]["indirect"]]
    return _texts_of(doc)


def test_no_data_file_under_src_copies_a_held_out_text():
    """No text of any data file under src/ (the gate's off-topic texts) is an exact or near copy of a held-out text:
    a set that shares texts with what the code ships measures recall of those texts."""
    data = _src_data_files()
    assert ROOT / "src" / "langpref" / "language" / "data" / "off_topic.json" in data
    held = _held_out_texts()
    clashes = [
        f"{path.relative_to(ROOT)}: {ours!r} ~ {name}: {text!r}"
        for path in data
        for ours in _data_texts(path)
        for name, texts in held.items()
        for text in texts
        if _copies(ours, text)
    ]
    assert not clashes, "data under src/ copies held-out texts:\n" + "\n".join(clashes)


def test_no_code_under_src_quotes_a_held_out_text():
    """No quoted text in the code under src/ (docstrings and examples included) is, after normalisation, a held-out
    text of two or more words: an example in the code is read by whoever tunes the code."""
    held = {_key(t): name for name, texts in _held_out_texts().items() for t in texts if len(t.split()) >= 2}
    quoted = re.compile(r"""["\u201c]([^"\u201c\u201d\n]{4,120})["\u201d]""")
    clashes = [
        f"{path.relative_to(ROOT)}: {text!r} is in {held[_key(text)]}"
        for path in sorted((ROOT / "src").rglob("*.py")) + sorted((ROOT / "src").rglob("*.js"))
        for text in quoted.findall(path.read_text(encoding="utf-8"))
        if _key(text) in held
    ]
    assert not clashes, "code under src/ quotes held-out texts:\n" + "\n".join(clashes)


def test_no_held_out_text_is_in_any_banks_train_or_val_split():
    """No held-out text, of any task, is (after normalisation) a train or val phrasing of any bank: train is what a
    model learns from, val what its checkpoint and the answer model's settings are chosen on."""
    held = _held_out_texts()
    clashes = []
    for bank in BANKS:
        seen = {_key(t) for t in _bank_train_texts(bank, ("train", "val"))}
        assert len(seen) >= 50, f"{bank}: the scan found (nearly) no train phrasings"
        clashes += [
            f"{bank.relative_to(ROOT)} train or val: {text!r} ({name})"
            for name, texts in held.items()
            for text in texts
            if _key(text) in seen
        ]
    assert not clashes, "held-out texts in a bank's train or val split:\n" + "\n".join(clashes)


@pytest.mark.parametrize(
    "ours,held,copies",
    [
        ("I had pasta for lunch", "I had pasta for lunch.", True),
        ("what is the capital of Spain?", "What is the capital of Australia?", True),
        ("write me a poem", "Write me a poem about autumn.", True),
        ("hola, ¿qué tal?", "Hola, ¿qué tal?", True),
        ("谢谢", "谢谢", True),
        ("?", "...", False),
        ("こんにちは", "谢谢", False),
        ("nice to meet you", "nice", False),
        ("good morning", "Did you watch the game last night?", False),
    ],
)
def test_the_overlap_tripwire_catches_copies_only(ours, held, copies):
    assert _copies(ours, held) is copies


def test_the_comparative_corpus_copies_no_held_out_text_nor_any_val_or_test_phrasing():
    """The corpus the `comparative` language model is built from (issue 40, item 1; its shipped seed and size) holds
    no exact or near copy (`langpref.language.near_copies`, ratio 0.9) of a held-out text, of a built-in bank's or
    the plugin's val or test phrasing, or of any phrasing of the drawer's unsplit bank, beyond the built-in banks'
    own train phrasings that it takes as they are (every built-in model trains on those). No text of it is an exact
    copy of a held-out text at all."""
    from langpref.language.corpus import build_corpus, copies
    from langpref.language.near_copies import NEAR_COPY_RATIO

    corpus = build_corpus()
    texts = sorted({e.text for e in corpus})
    assert len(texts) > 3000 and any(e.source.startswith("bank:") for e in corpus)
    train = {_key(t) for bank in BANKS[:2] for t in _bank_train_texts(bank)}
    held = [t for texts_ in _held_out_texts().values() for t in texts_]
    others = []
    for bank in BANKS:
        doc = json.loads(bank.read_text(encoding="utf-8"))
        others += _texts_of({k: v for k, v in doc.items() if k in ("val", "test")} if "train" in doc else doc)
    exact = {_key(t) for t in held} & {_key(t) for t in texts}
    assert not exact, f"{len(exact)} corpus texts are held-out texts"
    near_held = sorted(t for t in copies(texts, held, NEAR_COPY_RATIO) if _key(t) not in train)
    near_bank = sorted(t for t in copies(texts, others, NEAR_COPY_RATIO) if _key(t) not in train)
    # our texts only: a failure must not print a held-out text
    assert not near_held, f"corpus texts that nearly copy a held-out text: {near_held}"
    assert not near_bank, f"corpus texts that nearly copy a bank's val/test phrasing: {near_bank}"


def test_the_corpus_phrasings_the_drawer_trains_on_copy_no_held_out_text():
    """`train --corpus-phrasings N` adds the corpus's sentences of the concepts a task's features tie to, about the
    feature's object (`langpref.language.corpus_phrasings`): for the recorded drawer task, at every N measured or
    shipped as a default (up to 64; at 75 one of its sentences nearly copies a held-out text), none is an exact or
    near copy of a held-out text. Not so for the reach plugin (one of its distance-to-the-goal sentences at N = 16
    nearly copies one): it was not measured with them, and its default stays 0 (a plugin task)."""
    task = "drawer-open"
    from langpref.language.corpus import copies
    from langpref.language.corpus_phrasings import tied_phrasings
    from langpref.language.near_copies import NEAR_COPY_RATIO
    from langpref.model.keep import AUTO_CORPUS, CORPUS_SEED

    held = [t for texts_ in _held_out_texts().values() for t in texts_]
    for n in sorted({16, 32, 48, 64, AUTO_CORPUS} - {0}):
        made = tied_phrasings(_task_features(task), n, seed=CORPUS_SEED)
        texts = sorted({t for by_dir in made.values() for ts in by_dir.values() for t in ts})
        assert texts or task != "drawer-open"
        assert not {_key(t) for t in held} & {_key(t) for t in texts}, f"N={n}: a corpus phrasing is a held-out text"
        near = sorted(copies(texts, held, NEAR_COPY_RATIO))
        assert not near, f"N={n}: corpus phrasings that nearly copy a held-out text: {near}"  # ours only
