"""The study server's threads write to its database one at a time on a lock of their own (`db.transaction`), never
in SQLite's busy wait, which sleeps 1, 2, 5, 10 ... ms before asking again: with SQLite's wait switched off, 8
threads writing at once still never find the database locked."""

from __future__ import annotations

import threading
import time

from langpref.study.protocol import db as sdb


def test_writers_of_one_process_take_turns_without_sqlites_busy_wait(tmp_path):
    path = tmp_path / "w.sqlite"
    setup = sdb.connect(path)
    setup.execute("CREATE TABLE t (thread INTEGER, i INTEGER)")
    errors: list[str] = []

    def write(k: int) -> None:
        conn = sdb.connect(path)
        conn.execute("PRAGMA busy_timeout=0")  # a locked database would fail at once
        try:
            for i in range(25):
                with sdb.transaction(conn):
                    conn.execute("INSERT INTO t VALUES (?, ?)", (k, i))
                    time.sleep(0.001)  # the write lock held while another thread runs
        except Exception as exc:  # noqa: BLE001 (collected and asserted below)
            errors.append(str(exc))
        finally:
            conn.close()

    threads = [threading.Thread(target=write, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert errors == []
    assert setup.execute("SELECT count(*) FROM t").fetchone()[0] == 8 * 25
