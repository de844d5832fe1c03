"""The job journal (SQLite): job states with times and errors, and the latest bus messages of each job.

queued -> running -> done | failed | held; held -> done (``fcsod approve``) | failed (``fcsod reject``): a job
whose finger misses the delivery policy (``[verify] deliver``) waits, its finger not placed, for an operator.
The job id is the primary key, so a
job (same folder, same content) is recorded, and therefore run, once (an
operator's ``fcsod retry`` runs a failed one again).
A done job whose design is verified after it is done has a verification
row, ``running`` from the moment the job is journalled done (in the same
transaction) until the verification is ``done``, ``failed`` or
``skipped``: one left ``running`` by a crash or a stop runs again at the
next start.
Writes commit at once (WAL, synchronous=FULL): after ``kill -9`` the
journal holds every state change made before it.

Only the daemon writes the ``jobs`` and ``messages`` tables. The operator
commands (``fcsod retry | cancel | approve | reject``) only add a row to ``requests``, each in
a transaction of its own (SQLite's locks order it with the daemon's): the
daemon takes the requests in its loop, acts on them between its own state
changes, and writes the outcome back into the row, which the command reads.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ..bus.messages import BusMessage, JobState, StoredMessage
from ..storage import connect_database

VerificationState = Literal["running", "done", "failed", "skipped"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    job_id      TEXT PRIMARY KEY,
    folder      TEXT NOT NULL,
    state       TEXT NOT NULL CHECK (state IN ('queued', 'running', 'done', 'failed', 'held')),
    attempt     INTEGER NOT NULL DEFAULT 0,
    queued_at   TEXT,
    started_at  TEXT,
    finished_at TEXT,
    error       TEXT
);
CREATE TABLE IF NOT EXISTS verifications (
    job_id      TEXT PRIMARY KEY REFERENCES jobs (job_id),
    state       TEXT NOT NULL CHECK (state IN ('running', 'done', 'failed', 'skipped')),
    attempt     INTEGER NOT NULL DEFAULT 1,
    started_at  TEXT,
    finished_at TEXT,
    error       TEXT
);
CREATE TABLE IF NOT EXISTS messages (
    job_id     TEXT NOT NULL REFERENCES jobs (job_id),
    topic      TEXT NOT NULL,
    key_expr   TEXT NOT NULL,
    encoding   TEXT NOT NULL,
    payload    BLOB,
    attachment TEXT,
    file       TEXT,
    PRIMARY KEY (job_id, topic)
);
CREATE TABLE IF NOT EXISTS requests (
    request_id   INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id       TEXT NOT NULL,
    action       TEXT NOT NULL CHECK (action IN ('retry', 'cancel', 'approve', 'reject')),
    requested_at TEXT NOT NULL,
    handled_at   TEXT,
    accepted     INTEGER,
    outcome      TEXT,
    requested_by TEXT
);
"""

#: What an operator can ask of the daemon about a job.
RequestAction = Literal["retry", "cancel", "approve", "reject"]

#: Tables whose CHECK constraints grew since a journal was made (the held state, approve and reject), with the value
#: whose absence from the stored table's definition says it is the older one.
_GROWN_CHECKS = {"jobs": "'held'", "requests": "'approve'"}


#: Columns added since a journal was made: table -> (column, its SQL type), each last in its table.
_GROWN_COLUMNS = {"requests": ("requested_by", "TEXT")}


def _add_grown_columns(db: sqlite3.Connection) -> None:
    """Add the columns of :data:`_GROWN_COLUMNS` a journal's existing tables lack (null in the rows they have)."""
    with db:
        for table, (column, kind) in _GROWN_COLUMNS.items():
            present = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
            if present and column not in present:
                db.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")


def _upgrade(db: sqlite3.Connection) -> None:
    """Bring a journal made by an older fcsod to today's tables, keeping every row: the columns added since
    (:data:`_GROWN_COLUMNS`), then the tables whose CHECK constraints grew (:data:`_GROWN_CHECKS`) rebuilt: SQLite
    cannot alter a constraint, so each is created anew, filled, and renamed into place (the other tables' references
    name the table, which keeps its name)."""
    _add_grown_columns(db)
    stale = [
        name
        for name, value in _GROWN_CHECKS.items()
        if value not in (db.execute("SELECT sql FROM sqlite_master WHERE name = ?", (name,)).fetchone() or [value])[0]
    ]
    if not stale:
        return
    statements = {part.split("(")[0].split()[-1]: part for part in _SCHEMA.split(";") if "CREATE TABLE" in part}
    foreign_keys = db.execute("PRAGMA foreign_keys").fetchone()[0]
    db.execute("PRAGMA foreign_keys = OFF")
    try:
        with db:
            for name in stale:
                db.execute(statements[name].replace(f"EXISTS {name} ", f"EXISTS {name}_upgraded "))
                db.execute(f"INSERT INTO {name}_upgraded SELECT * FROM {name}")
                db.execute(f"DROP TABLE {name}")
                db.execute(f"ALTER TABLE {name}_upgraded RENAME TO {name}")
    finally:
        db.execute(f"PRAGMA foreign_keys = {int(foreign_keys)}")


@dataclass
class JobRow:
    """One job as the journal has it (times are UTC ISO 8601)."""

    job_id: str
    folder: str
    state: JobState
    attempt: int
    queued_at: str | None
    started_at: str | None
    finished_at: str | None
    error: str | None


@dataclass
class VerificationRow:
    """The verification of one done job as the journal has it (times are UTC ISO 8601)."""

    job_id: str
    state: VerificationState
    attempt: int
    started_at: str | None
    finished_at: str | None
    error: str | None


def stored_message(message: BusMessage, output_root: Path) -> StoredMessage:
    """How the journal keeps a published message: a design by the path of its ``finger.stl``, anything else whole."""
    design_file = str(output_root / message.job_id / "finger.stl") if message.topic == "design" else None
    return StoredMessage(
        message.job_id,
        message.topic,
        message.key_expr,
        message.encoding,
        None if design_file else message.payload,
        message.attachment.decode() if message.attachment is not None else None,
        design_file,
    )


@dataclass
class OperatorRequest:
    """An operator's request about a job, and the daemon's answer once it handled it (times UTC ISO 8601)."""

    request_id: int
    job_id: str
    action: RequestAction
    requested_at: str
    handled_at: str | None
    accepted: bool | None
    outcome: str | None
    requested_by: str | None = None


class JournalCorrupt(Exception):
    """The journal file cannot be trusted; the message names the file and the defect."""


def journal_problem(path: str | Path) -> str | None:
    """What is wrong with a journal file (SQLite's own check and fcsod's tables), None when it is sound or absent."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        db = sqlite3.connect(path, timeout=30.0)
        try:
            found = [row[0] for row in db.execute("PRAGMA quick_check").fetchall()]
            tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            if found == ["ok"] and {"jobs", "messages"} <= tables:
                db.execute(
                    "SELECT job_id, folder, state, attempt, queued_at, started_at, finished_at, error FROM jobs"
                ).fetchall()
        finally:
            db.close()
    except sqlite3.DatabaseError as exc:
        return f"SQLite: {exc}"
    if found != ["ok"]:
        return "SQLite integrity check: " + "; ".join(found[:3])
    if not {"jobs", "messages"} <= tables:
        return "not an fcsod journal (no jobs and messages tables)"
    return None


class Journal:
    """The journal in ``<state_dir>/journal.sqlite3``.

    Parameters
    ----------
    path : Path
        The database file (created if missing).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._db = connect_database(self.path)
        _upgrade(self._db)
        self._db.executescript(_SCHEMA)

    def close(self) -> None:
        self._db.close()

    def add(self, job_id: str, folder: str, queued_at: str) -> bool:
        """Queue a new job; False (and no change) when the job id is already known."""
        with self._db:
            cursor = self._db.execute(
                "INSERT OR IGNORE INTO jobs (job_id, folder, state, queued_at) VALUES (?, ?, 'queued', ?)",
                (job_id, folder, queued_at),
            )
        return cursor.rowcount == 1

    def get(self, job_id: str) -> JobRow | None:
        row = self._db.execute("SELECT * FROM jobs WHERE job_id = ?", (job_id,)).fetchone()
        return JobRow(*row) if row else None

    def jobs(self, state: JobState | None = None) -> list[JobRow]:
        """Jobs in queue order, optionally only those in ``state``."""
        return _select_jobs(self._db, state)

    def mark_running(self, job_id: str, started_at: str) -> JobRow:
        """Start a run of the job (counts the attempt)."""
        with self._db:
            self._db.execute(
                "UPDATE jobs SET state = 'running', attempt = attempt + 1, started_at = ?, finished_at = NULL, error "
                "= NULL "
                "WHERE job_id = ?",
                (started_at, job_id),
            )
        return self.get(job_id)

    def mark_finished(
        self, job_id: str, state: JobState, finished_at: str, error: str | None = None, verifying: bool = False
    ) -> JobRow:
        """End the job as ``done`` or ``failed``; with ``verifying``, its verification starts in the same
        transaction."""
        with self._db:
            self._db.execute(
                "UPDATE jobs SET state = ?, finished_at = ?, error = ? WHERE job_id = ?",
                (state, finished_at, error, job_id),
            )
            if verifying:
                self._db.execute(
                    "INSERT OR REPLACE INTO verifications (job_id, state, attempt, started_at) "
                    "VALUES (?, 'running', 1, ?)",
                    (job_id, finished_at),
                )
        return self.get(job_id)

    def verification(self, job_id: str) -> VerificationRow | None:
        row = self._db.execute("SELECT * FROM verifications WHERE job_id = ?", (job_id,)).fetchone()
        return VerificationRow(*row) if row else None

    def unfinished_verifications(self) -> list[VerificationRow]:
        """Verifications left ``running`` by a crash or a stop, in the order they started."""
        rows = self._db.execute("SELECT * FROM verifications WHERE state = 'running' ORDER BY rowid").fetchall()
        return [VerificationRow(*r) for r in rows]

    def restart_verification(self, job_id: str, started_at: str) -> VerificationRow:
        """Run a job's unfinished verification again (counts the attempt)."""
        with self._db:
            self._db.execute(
                "UPDATE verifications SET attempt = attempt + 1, started_at = ?, finished_at = NULL, error = NULL "
                "WHERE job_id = ?",
                (started_at, job_id),
            )
        return self.verification(job_id)

    def finish_verification(
        self, job_id: str, state: VerificationState, finished_at: str, error: str | None, messages: list[StoredMessage]
    ) -> None:
        """End a job's verification and keep its messages, in one transaction (published after it)."""
        with self._db:
            self._db.execute(
                "UPDATE verifications SET state = ?, finished_at = ?, error = ? WHERE job_id = ?",
                (state, finished_at, error, job_id),
            )
            for message in messages:
                self._store(message)

    def restore(self, row: JobRow) -> None:
        """Put a job back as it was (rebuilding the journal from the job records)."""
        with self._db:
            self._db.execute(
                "INSERT OR REPLACE INTO jobs VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    row.job_id,
                    row.folder,
                    row.state,
                    row.attempt,
                    row.queued_at,
                    row.started_at,
                    row.finished_at,
                    row.error,
                ),
            )

    def requeue_running(self) -> list[str]:
        """Put jobs left ``running`` by a stop or a crash back into the queue; their ids."""
        ids = [r.job_id for r in self.jobs("running")]
        with self._db:
            self._db.execute("UPDATE jobs SET state = 'queued', started_at = NULL WHERE state = 'running'")
        return ids

    def requeue_failed(self, job_id: str, queued_at: str) -> bool:
        """Queue a failed job again (its attempt count is kept); False when it is not failed."""
        with self._db:
            cursor = self._db.execute(
                "UPDATE jobs SET state = 'queued', queued_at = ?, started_at = NULL, finished_at = NULL, error = NULL "
                "WHERE job_id = ? AND state = 'failed'",
                (queued_at, job_id),
            )
        return cursor.rowcount == 1

    def pending_requests(self) -> list[OperatorRequest]:
        """Operator requests not handled yet, oldest first."""
        rows = self._db.execute("SELECT * FROM requests WHERE handled_at IS NULL ORDER BY request_id").fetchall()
        return [_request(r) for r in rows]

    def answer_request(self, request_id: int, handled_at: str, accepted: bool, outcome: str) -> None:
        """Record what the daemon did with a request."""
        with self._db:
            self._db.execute(
                "UPDATE requests SET handled_at = ?, accepted = ?, outcome = ? WHERE request_id = ?",
                (handled_at, int(accepted), outcome, request_id),
            )

    def store_message(self, message: StoredMessage) -> None:
        """Keep the latest message of a topic of a job (what the queryable serves)."""
        with self._db:
            self._store(message)

    def _store(self, message: StoredMessage) -> None:
        self._db.execute(
            "INSERT OR REPLACE INTO messages VALUES (?, ?, ?, ?, ?, ?, ?)",
            (
                message.job_id,
                message.topic,
                message.key_expr,
                message.encoding,
                message.payload,
                message.attachment,
                message.file,
            ),
        )


def stored_messages(path: str | Path) -> list[StoredMessage]:
    """Every stored message, read on a connection of its own (safe from any thread)."""
    db = connect_database(Path(path))
    try:
        rows = db.execute(
            "SELECT job_id, topic, key_expr, encoding, payload, attachment, file FROM messages ORDER BY rowid"
        ).fetchall()
    finally:
        db.close()
    return [StoredMessage(*r) for r in rows]


def submit_request(
    path: str | Path, job_id: str, action: RequestAction, requested_at: str, requested_by: str | None = None
) -> int:
    """Add an operator request for the daemon (one insert in its own transaction), from the login ``requested_by``;
    its id."""
    db = connect_database(Path(path))
    try:
        _add_grown_columns(db)
        with db:
            db.executescript(_SCHEMA)
        with db:
            cursor = db.execute(
                "INSERT INTO requests (job_id, action, requested_at, requested_by) VALUES (?, ?, ?, ?)",
                (job_id, action, requested_at, requested_by),
            )
        return cursor.lastrowid
    finally:
        db.close()


def read_request(path: str | Path, request_id: int) -> OperatorRequest:
    """One request as it stands now."""
    db = connect_database(Path(path))
    try:
        return _request(db.execute("SELECT * FROM requests WHERE request_id = ?", (request_id,)).fetchone())
    finally:
        db.close()


def read_jobs(path: str | Path, state: JobState | None = None) -> list[JobRow]:
    """The journal's jobs read on a connection of its own, which writes nothing (for the operator commands)."""
    db = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True, timeout=30.0)
    try:
        return _select_jobs(db, state)
    finally:
        db.close()


def _select_jobs(db: sqlite3.Connection, state: JobState | None) -> list[JobRow]:
    if state is None:
        rows = db.execute("SELECT * FROM jobs ORDER BY rowid").fetchall()
    else:
        rows = db.execute("SELECT * FROM jobs WHERE state = ? ORDER BY rowid", (state,)).fetchall()
    return [JobRow(*r) for r in rows]


def _request(row: tuple) -> OperatorRequest:
    request_id, job_id, action, requested_at, handled_at, accepted, outcome, requested_by = row
    return OperatorRequest(
        request_id,
        job_id,
        action,
        requested_at,
        handled_at,
        None if accepted is None else bool(accepted),
        outcome,
        requested_by,
    )
