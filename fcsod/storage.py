"""How fcsod keeps its own files: the state folder's lock, SQLite connections that survive ``kill -9``, hashes.

The journal (:mod:`fcsod.service.journal`), the finger library
(:mod:`fcsod.job.fingers`), the job inputs and the audit all use these; this
module imports nothing of fcsod so each of them can.
"""

from __future__ import annotations

import fcntl
import hashlib
import sqlite3
from pathlib import Path


def connect_database(path: Path) -> sqlite3.Connection:
    """A connection to one of the daemon's SQLite files: WAL, every commit synced (survives ``kill -9``)."""
    db = sqlite3.connect(path, timeout=30.0, isolation_level="DEFERRED")
    db.execute("PRAGMA journal_mode = WAL")
    db.execute("PRAGMA synchronous = FULL")
    return db


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's content, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class StateDirBusy(Exception):
    """Another daemon holds the state folder's lock."""


def lock_state_dir(state_dir: Path):
    """Take the state folder's lock (held while the returned file stays open).

    Raises
    ------
    StateDirBusy
        Another fcsod (daemon or journal repair) holds it.
    """
    lock_file = open(state_dir / "fcsod.lock", "w")
    try:
        fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        lock_file.close()
        raise StateDirBusy(f"{state_dir}: another fcsod is running with this state folder") from None
    return lock_file
