"""The study database: SQLite in WAL mode, every answer with its timestamps. What its tables hold and how each schema
version adds to them: `langpref.study.protocol.schema`; here, opening (creating or migrating) a database, the
transactions every write runs in, and the few writes and reads that more than one room shares.

The app keeps one connection per server thread (`connect`); every write is one `BEGIN IMMEDIATE` transaction, so a
killed server loses nothing committed and a half-applied answer never exists. WAL with synchronous=NORMAL is durable
against a killed process (a power cut may lose the last commits, never corrupt the file).
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.feedback.kind import FeedbackKind, get_kind
from langpref.study.protocol.kinds import kind_answer
from langpref.study.protocol.schema import KIND_TABLE, KIND_TABLES, MIGRATIONS, SCHEMA_VERSION, TABLES, backfill_queries

RESUME_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
"""Resume codes: no 0/O, 1/I/L, so that a code read aloud or copied by hand is typed right."""


def connect(path: str | Path) -> sqlite3.Connection:
    """A connection in autocommit mode (transactions are explicit), WAL, foreign keys on, rows as dicts."""
    try:
        conn = sqlite3.connect(str(path), timeout=30.0, isolation_level=None, check_same_thread=False)
        conn.row_factory = sqlite3.Row
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=NORMAL")  # durable against a killed process; fsync at checkpoints
        conn.execute("PRAGMA foreign_keys=ON")
        conn.execute("PRAGMA busy_timeout=30000")
    except sqlite3.DatabaseError as exc:
        raise LangprefError(f"{path} is not a usable SQLite database ({exc}); pass another --db") from None
    return conn


_WRITERS: dict[str, threading.RLock] = {}
"""One lock per database file: the writers of this process take turns on it rather than in SQLite."""
_WRITERS_GUARD = threading.Lock()


def _writer_lock(conn: sqlite3.Connection) -> threading.RLock:
    """The lock of `conn`'s database file (an in-memory database: its own)."""
    path = conn.execute("PRAGMA database_list").fetchone()[2] or f"memory:{id(conn)}"
    with _WRITERS_GUARD:
        return _WRITERS.setdefault(path, threading.RLock())


@contextmanager
def transaction(conn: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    """BEGIN IMMEDIATE ... COMMIT, rolled back on any exception. The threads of one process write one at a time on a
    lock of their own: a writer SQLite finds busy sleeps 1, 2, 5, 10, 15 ms ... before it asks again, and with 20
    participants answering at once those sleeps were most of an answer's time in the database (12-15 ms at the mean
    for 0.4 ms of work); a thread waiting on the lock goes on the moment it is free. Other processes (an export, a
    second server) still meet SQLite's own lock and its busy timeout."""
    with _writer_lock(conn):
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        conn.execute("COMMIT")


def schema_version(conn: sqlite3.Connection) -> int:
    has_meta = conn.execute("SELECT 1 FROM sqlite_master WHERE type='table' AND name='meta'").fetchone()
    if not has_meta:
        return 0
    row = conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
    return int(row["value"]) if row else 0


def init_db(path: str | Path, meta: dict[str, Any]) -> dict[str, Any]:
    """Create or migrate the database; on first creation store `meta`. Returns the stored meta (decoded)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    conn = connect(path)
    try:
        try:
            version = schema_version(conn)
        except sqlite3.DatabaseError as exc:
            raise LangprefError(f"{path} is not a usable SQLite database ({exc}); pass another --db") from None
        if version == 0 and conn.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]:
            raise LangprefError(
                f"{path} is an SQLite database of something else (no langpref study schema); pass another --db"
            )
        if version > SCHEMA_VERSION:
            raise LangprefError(
                f"{path} has study schema version {version}, this langpref knows up to "
                f"{SCHEMA_VERSION}; upgrade langpref"
            )
        with transaction(conn):
            for v in range(version + 1, SCHEMA_VERSION + 1):
                # one statement at a time: executescript would COMMIT in the middle of the transaction
                for statement in filter(str.strip, MIGRATIONS[v].split(";")):
                    conn.execute(statement)
                conn.execute("INSERT OR REPLACE INTO meta VALUES ('schema_version', ?)", (str(v),))
            for (pid,) in conn.execute("SELECT id FROM participants WHERE resume_code IS NULL").fetchall():
                conn.execute("UPDATE participants SET resume_code=? WHERE id=?", (new_resume_code(conn), pid))
            if 0 < version < 3:
                backfill_queries(conn)
            if version == 0:
                for key, value in meta.items():
                    conn.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, json.dumps(value)))
                conn.execute("INSERT OR REPLACE INTO meta VALUES ('created_at', ?)", (json.dumps(time.time()),))
        return read_meta(conn)
    finally:
        conn.close()


def add_query(conn: sqlite3.Connection, participant_id: str, step: Any, created_at: float) -> None:
    """The `queries` row of a Study-2 query step (`flow.Step` with a `selection`), in the caller's transaction."""
    sel, shown = step.selection, list(step.shown)
    conn.execute(
        "INSERT INTO queries (participant_id, seq, method, number, a, b, strategy, score, candidates, created_at) "
        "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        (
            participant_id,
            step.seq,
            step.kind,
            step.number,
            shown[0],
            shown[1] if len(shown) > 1 else None,
            sel["strategy"],
            sel.get("score"),
            sel.get("candidates"),
            created_at,
        ),
    )


def new_resume_code(conn: sqlite3.Connection) -> str:
    """A resume code no participant of this database has: 10 symbols (about 50 bits), shown as XXXXX-XXXXX."""
    import secrets

    while True:
        raw = "".join(secrets.choice(RESUME_ALPHABET) for _ in range(10))
        code = f"{raw[:5]}-{raw[5:]}"
        if conn.execute("SELECT 1 FROM participants WHERE resume_code=?", (code,)).fetchone() is None:
            return code


def normalise_resume_code(text: str) -> str | None:
    """A typed resume code in its stored form (case, spaces and dashes forgiven); None if it cannot be one."""
    raw = "".join(ch for ch in str(text).upper() if ch not in " -\t")
    if len(raw) != 10 or any(ch not in RESUME_ALPHABET for ch in raw):
        return None
    return f"{raw[:5]}-{raw[5:]}"


def read_meta(conn: sqlite3.Connection) -> dict[str, Any]:
    return decode_meta(conn.execute("SELECT key, value FROM meta"))


def decode_meta(rows) -> dict[str, Any]:
    """key -> value of `meta` rows, each value decoded from JSON (kept as text when it is none)."""
    out = {}
    for row in rows:
        try:
            out[row["key"]] = json.loads(row["value"])
        except json.JSONDecodeError:
            out[row["key"]] = row["value"]
    return out


def open_existing(path: str | Path) -> sqlite3.Connection:
    """A connection to an existing study database (for export); a clear error for anything else."""
    path = Path(path)
    if not path.is_file():
        raise LangprefError(f"study database {path} does not exist; pass the --db a `langpref study serve` wrote")
    conn = connect(path)
    try:
        version = schema_version(conn)
    except sqlite3.DatabaseError as exc:
        conn.close()
        raise LangprefError(f"{path} is not a study database ({exc})") from None
    if version != SCHEMA_VERSION:
        conn.close()
        raise LangprefError(
            f"{path} has study schema version {version}, expected {SCHEMA_VERSION}: "
            "open it once with `langpref study serve` to migrate it, or pass another --db"
        )
    return conn


def rows(conn: sqlite3.Connection, sql: str, args: tuple = ()) -> list[dict[str, Any]]:
    return [dict(r) for r in conn.execute(sql, args)]


def add_kind_tables(path: str | Path, kinds: tuple[FeedbackKind, ...]) -> None:
    """Make the table of each of `kinds` whose answers the schema has no table for (a plugin kind's; see above)."""
    conn = connect(path)
    try:
        with transaction(conn):
            for kind in kinds:
                if kind.table not in KIND_TABLES:
                    conn.execute(KIND_TABLE.format(table=kind.table))
    finally:
        conn.close()


def kind_tables(conn: sqlite3.Connection) -> list[str]:
    """The tables of kinds beyond the paper's in this database (none in a study of the paper's two kinds)."""
    names = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")]
    return [n for n in names if n not in TABLES and n != "participant_tokens" and not n.startswith("sqlite_")]


def method_rows(rows: list[dict[str, Any]], method: str) -> list[dict[str, Any]]:
    """The Study-2 answers of `method` among rows of its feedback kind's table: Study 1's language feedback shares the
    `feedback` table, where every row says its phase."""
    return [r for r in rows if r.get("phase", f"pref_{method}") == f"pref_{method}"]


def stored_answers(conn: sqlite3.Connection, participant_id: str, method: str) -> list[Any]:
    """A participant's stored Study-2 answers of `method`, in query order, as the kind's typed answers."""
    kind = get_kind(method)
    found = rows(conn, f"SELECT * FROM {kind.table} WHERE participant_id=? ORDER BY number", (participant_id,))
    return [kind_answer(kind, r) for r in method_rows(found, method)]


def confirmed_meanings(conn: sqlite3.Connection, participant_id: str, method: str) -> dict[int, int | None]:
    """{query number: the meaning a participant confirmed their answer meant (None: none of these)} of `method`."""
    found = rows(
        conn, "SELECT number, meaning FROM confirmations WHERE participant_id=? AND method=?", (participant_id, method)
    )
    return {int(r["number"]): r["meaning"] for r in found}
