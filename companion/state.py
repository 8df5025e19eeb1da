"""The companion's state on disk: what must survive a restart (SQLite, one file).

* ``runs`` -- every run we started or answered: the probing budget (:mod:`companion.runs.budget`)
  counts them per drone, per operator and in all, over a sliding hour, across restarts.
* ``requests`` -- run requests already answered (the requester's fingerprint and ephemeral
  key): a recorded request replayed later is refused, even after we restarted.
* ``counters`` -- the last beacon (time, counter) accepted from each drone (a replayed beacon
  is dropped), and our own (ours only ever grows, so peers never take a fresh beacon of ours
  for a replay).

Times are Unix seconds.  The directory is created with mode 0700.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from companion.errors import CompanionError

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (t REAL NOT NULL, drone BLOB NOT NULL, operator BLOB NOT NULL,
                                 role TEXT NOT NULL, bits INTEGER NOT NULL DEFAULT 0);
CREATE INDEX IF NOT EXISTS runs_t ON runs (t);
CREATE TABLE IF NOT EXISTS requests (key BLOB PRIMARY KEY, t REAL NOT NULL);
CREATE TABLE IF NOT EXISTS counters (drone BLOB PRIMARY KEY, counter INTEGER NOT NULL);
"""
OWN = b"own"


class StateError(CompanionError):
    """The state directory or database cannot be used."""


class StateStore:
    FILE = "state.sqlite3"

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        try:
            self.directory.mkdir(mode=0o700, parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.directory / self.FILE, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
            columns = {row[1] for row in self._db.execute("PRAGMA table_info(runs)")}
            if "bits" not in columns:  # a state directory from before the answer-bit budget
                self._db.execute("ALTER TABLE runs ADD COLUMN bits INTEGER NOT NULL DEFAULT 0")
        except (OSError, sqlite3.Error) as exc:
            raise StateError(f"state directory {self.directory}: {exc}") from None

    def close(self) -> None:
        self._db.close()

    # ------------------------------------------------------------------ runs

    def record_run(self, t: float, drone: bytes, operator: bytes, role: str, bits: int = 0) -> int:
        """Count one run (``bits``: the answer bits it opens to its requester); its ticket
        (to give it back with :meth:`forget_run`)."""
        cursor = self._db.execute(
            "INSERT INTO runs (t, drone, operator, role, bits) VALUES (?, ?, ?, ?, ?)",
            (t, drone, operator, role, bits),
        )
        assert cursor.lastrowid is not None
        return cursor.lastrowid

    def forget_run(self, ticket: int) -> None:
        self._db.execute("DELETE FROM runs WHERE rowid = ?", (ticket,))

    def count_runs(
        self,
        since: float,
        role: str,
        *,
        drone: bytes | None = None,
        operator: bytes | None = None,
        bits: bool = False,
    ) -> int:
        """Runs since ``since`` (or, with ``bits``, the answer bits they opened)."""
        what = "COALESCE(SUM(bits), 0)" if bits else "COUNT(*)"
        query = f"SELECT {what} FROM runs WHERE t > ? AND role = ?"  # noqa: S608 (fixed text)
        args: list[object] = [since, role]
        if drone is not None:
            query += " AND drone = ?"
            args.append(drone)
        if operator is not None:
            query += " AND operator = ?"
            args.append(operator)
        (count,) = self._db.execute(query, args).fetchone()
        return int(count)

    def forget_runs(self, before: float) -> None:
        self._db.execute("DELETE FROM runs WHERE t <= ?", (before,))

    # ------------------------------------------------------------------ replay cache

    def first_request(self, key: bytes, t: float, forget_before: float) -> bool:
        """Remember ``key``; False if it was seen before (a replay)."""
        self._db.execute("DELETE FROM requests WHERE t < ?", (forget_before,))
        try:
            self._db.execute("INSERT INTO requests VALUES (?, ?)", (key, t))
        except sqlite3.IntegrityError:
            return False
        return True

    # ------------------------------------------------------------------ beacon counters

    def last_counter(self, drone: bytes) -> int | None:
        row = self._db.execute("SELECT counter FROM counters WHERE drone = ?", (drone,)).fetchone()
        return None if row is None else int(row[0])

    def set_counter(self, drone: bytes, counter: int) -> None:
        self._db.execute(
            "INSERT INTO counters VALUES (?, ?) ON CONFLICT (drone) DO UPDATE SET counter = ?",
            (drone, counter, counter),
        )
