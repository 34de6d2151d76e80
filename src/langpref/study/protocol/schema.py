"""The study database's schema: its tables, one SQL script per version, and what a migration fills in that SQL cannot.

Tables (one CSV each in `langpref study export`):

    meta              key/value: schema_version, study config, model and data it was created with, created_at
    participants      unguessable id, sha256 of the token, arrival number, Study-2 method order, seed, times
    steps             every step a participant was given, in order (seq); the last unanswered one is the current
                      step. Its payload (trajectories shown, query numbers, how feedback was understood) is fixed when
                      the step is made, so a reload or a server restart shows exactly the same step.
    answers           every answer as received (JSON body), with client and server times
    survey_responses  one row per survey question answered
    feedback          language feedback: shown trajectory, text, how the model understood it, the improved trajectory
    comparisons       pairwise choices
    satisfaction      Study 1 "are you satisfied?" answers
    ratings           Study 2 ratings of the best trajectory under the reward learned so far

Schema 2 adds to `participants` a short `resume_code` (shown to the participant and on the dashboard; it restores a
session in any browser, `POST /api/participants/resume`) and `excluded`/`excluded_reason` (set from the dashboard:
left out of the analyses), and the table `participant_tokens`: further tokens of a participant, issued on resume
(never exported).

Schema 3 adds the table `queries`: every Study-2 query shown, with what it shows (`a`, and `b` for a comparison) and
why: the query selection strategy, the shown query's score (None for `random`) and how many candidates were scored.
A database of an earlier schema gets a row (strategy `random`) for each query it has shown: it had no other. It also
adds `generated`: the trajectories Study 1 made in the simulator (`--improve-candidates generated`,
`langpref.study.session.generated`): the id shown, the participant, the feedback (seq) and round it answers, the
trajectory it improves (`shown`), where the search started (`start`, `start_score`: Eq. 4's objective), its own `score`,
its index in the generated dataset, the step's wall time, its controller parameters and phi (JSON).

Schema 4 adds the table `rewards`: the reward a participant's Study-2 learner has learned after each answer (the
query `number` of `method`, the `learner`), as JSON: `latent_weights` xi (r = xi . phi), `feature_weights` (the
answer-model learner's weights over the bank's feature axes, by feature name; empty for the paper's learner) and
`ranking` (the study set's dataset indices, best first). A database of an earlier schema has none for the answers it
took before.

Schema 5 adds the table `confirmations` (`--confirm-margin`): a participant's answer to a confirm step, for the
language answer `number` (`shown`, `text`): the reading's `margin`, the `options` offered (JSON: meaning, words,
feature, direction, probability, likeliest first), and what was chosen (`meaning`, `feature`, `direction`, `rank`
among the options; all empty for "none of these").

A feedback kind beyond the paper's two (`StudyConfig.kinds`, `langpref.study.protocol.kinds`) stores its Study-2 answers
in a table of its own name (`FeedbackKind.table`), made when a study that runs it starts (`add_kind_tables`): the
columns every answer has (participant_id, seq, number, client_ms, server_ms, answered_at) and the kind's `to_record`
as JSON (`answer`). A study of the paper's two kinds has no such table, and its schema stays the one above.

How the database is opened, migrated and written: `langpref.study.protocol.db`.
"""

from __future__ import annotations

import json
import sqlite3

SCHEMA_VERSION = 5

_V1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE participants (
    id TEXT PRIMARY KEY,
    token_sha256 TEXT NOT NULL,
    number INTEGER NOT NULL UNIQUE,
    method_order TEXT NOT NULL,
    seed INTEGER NOT NULL,
    created_at REAL NOT NULL,
    finished_at REAL,
    user_agent TEXT
);
CREATE TABLE steps (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    phase TEXT NOT NULL,
    kind TEXT NOT NULL,
    payload TEXT NOT NULL,
    created_at REAL NOT NULL,
    first_shown_at REAL,
    answered_at REAL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE answers (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    phase TEXT NOT NULL,
    kind TEXT NOT NULL,
    body TEXT NOT NULL,
    client_ms REAL,
    server_ms REAL NOT NULL,
    time_consistent INTEGER,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE survey_responses (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    survey TEXT NOT NULL,
    question_id TEXT NOT NULL,
    item INTEGER NOT NULL,
    method TEXT,
    value TEXT NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, survey, question_id)
);
CREATE TABLE feedback (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    phase TEXT NOT NULL,
    number INTEGER NOT NULL,
    shown INTEGER NOT NULL,
    text TEXT NOT NULL,
    understood_feature TEXT,
    understood_direction TEXT,
    understood_confidence REAL,
    improved INTEGER,
    client_ms REAL,
    server_ms REAL NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE comparisons (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    number INTEGER NOT NULL,
    a INTEGER NOT NULL,
    b INTEGER NOT NULL,
    choice INTEGER NOT NULL,
    preferred INTEGER NOT NULL,
    client_ms REAL,
    server_ms REAL NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE satisfaction (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    iteration INTEGER NOT NULL,
    shown INTEGER NOT NULL,
    satisfied INTEGER NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE ratings (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    method TEXT NOT NULL,
    after_queries INTEGER NOT NULL,
    shown INTEGER NOT NULL,
    rating INTEGER NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE INDEX steps_open ON steps (participant_id, answered_at);
"""

_V2 = """
ALTER TABLE participants ADD COLUMN resume_code TEXT;
ALTER TABLE participants ADD COLUMN excluded INTEGER NOT NULL DEFAULT 0;
ALTER TABLE participants ADD COLUMN excluded_reason TEXT;
CREATE UNIQUE INDEX participants_resume ON participants (resume_code);
CREATE TABLE participant_tokens (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    token_sha256 TEXT NOT NULL,
    created_at REAL NOT NULL,
    PRIMARY KEY (participant_id, token_sha256)
);
"""

_V3 = """
CREATE TABLE queries (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    method TEXT NOT NULL,
    number INTEGER NOT NULL,
    a INTEGER NOT NULL,
    b INTEGER,
    strategy TEXT NOT NULL,
    score REAL,
    candidates INTEGER,
    created_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
CREATE TABLE generated (
    id INTEGER PRIMARY KEY,
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    round INTEGER NOT NULL,
    shown INTEGER NOT NULL,
    start INTEGER NOT NULL,
    start_score REAL NOT NULL,
    score REAL NOT NULL,
    store_index INTEGER NOT NULL,
    wall_s REAL NOT NULL,
    unit TEXT NOT NULL,
    phi TEXT NOT NULL,
    created_at REAL NOT NULL
);
"""

_V4 = """
CREATE TABLE rewards (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    method TEXT NOT NULL,
    number INTEGER NOT NULL,
    learner TEXT NOT NULL,
    latent_weights TEXT NOT NULL,
    feature_weights TEXT,
    ranking TEXT NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
"""

_V5 = """
CREATE TABLE confirmations (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    method TEXT NOT NULL,
    number INTEGER NOT NULL,
    shown INTEGER NOT NULL,
    text TEXT NOT NULL,
    margin REAL NOT NULL,
    options TEXT NOT NULL,
    meaning INTEGER,
    feature TEXT,
    direction TEXT,
    rank INTEGER,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
);
"""

# schema version -> SQL taking the database from the previous version to it
MIGRATIONS: dict[int, str] = {1: _V1, 2: _V2, 3: _V3, 4: _V4, 5: _V5}
KIND_TABLES = ("feedback", "comparisons")
"""The schema's tables of feedback answers, a column per field (the paper's kinds'); any other kind's table holds its
answer as JSON (`langpref.study.protocol.kinds.kind_row`)."""
TABLES = (
    "meta",
    "participants",
    "steps",
    "answers",
    "survey_responses",
    "feedback",
    "comparisons",
    "satisfaction",
    "ratings",
    "queries",
    "generated",
    "rewards",
    "confirmations",
)
KIND_TABLE = """
CREATE TABLE IF NOT EXISTS {table} (
    participant_id TEXT NOT NULL REFERENCES participants(id),
    seq INTEGER NOT NULL,
    number INTEGER NOT NULL,
    answer TEXT NOT NULL,
    client_ms REAL,
    server_ms REAL NOT NULL,
    answered_at REAL NOT NULL,
    PRIMARY KEY (participant_id, seq)
)"""


BEFORE_V3_METHODS = ("language", "comparison")
"""The Study-2 methods a database made before schema 3 can hold: the paper's two, the only ones then."""


def backfill_queries(conn: sqlite3.Connection) -> None:
    """Rows of `queries` for the query steps of a database made before schema 3: all drawn at random."""
    marks = ", ".join("?" * len(BEFORE_V3_METHODS))
    for r in conn.execute(
        f"SELECT participant_id, seq, kind, payload, created_at FROM steps WHERE kind IN ({marks}) "
        f"AND phase IN ({marks})",
        (*BEFORE_V3_METHODS, *(f"pref_{m}" for m in BEFORE_V3_METHODS)),
    ).fetchall():
        p = json.loads(r["payload"])
        shown = p["shown"]
        b = shown[1] if len(shown) > 1 else None
        conn.execute(
            "INSERT OR IGNORE INTO queries (participant_id, seq, method, number, a, b, strategy, score, candidates, "
            "created_at) VALUES (?, ?, ?, ?, ?, ?, 'random', NULL, NULL, ?)",
            (r["participant_id"], r["seq"], r["kind"], p["number"], shown[0], b, r["created_at"]),
        )
