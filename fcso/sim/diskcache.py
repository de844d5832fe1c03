"""A folder of cache entries by content hash: written whole, read by any number of processes, bounded in size.

The verification keeps its collision pieces (:mod:`fcso.sim.collision`) and
the outcomes of its simulations (:mod:`fcso.sim.outcomes`) here, shared by
candidates, jobs, restarts and concurrent workers.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

#: Largest total size of a cache folder, bytes: the least recently used entries go first (an entry is a few kB to a
#: few hundred kB).
CACHE_MAX_BYTES = 500_000_000
#: A temporary file this old was left by a writer that died before renaming it (a write takes milliseconds), s.
ABANDONED_WRITE_S = 3600.0


def read_entry(path: Path) -> bytes | None:
    """An entry's bytes, or None when it is absent (or removed by another process's eviction meanwhile).

    Reading marks the entry as used (its modification time), so :func:`evict`
    removes the least recently used.
    """
    try:
        data = path.read_bytes()
        os.utime(path)
        return data
    except OSError:
        return None


def write_entry(path: Path, data: bytes) -> bool:
    """Write an entry under a name of its own and rename it into place; whether it was written.

    Several processes may write the same entry at once: each renames a whole
    file of identical content, so a reader never sees a part of one. A cache
    that cannot be written (full disk, read-only) costs time only.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp", delete=False) as f:
            f.write(data)
        os.replace(f.name, path)
    except OSError:
        return False
    return True


def evict(cache_dir: Path, max_bytes: int = CACHE_MAX_BYTES) -> None:
    """Remove the least recently used entries until the cache holds at most ``max_bytes``, and the temporary files of
    writers that died (a ``kill -9``) before renaming them, older than :data:`ABANDONED_WRITE_S`.

    Parameters
    ----------
    cache_dir : Path
        The cache folder (its ``*.npz`` entries).
    max_bytes : int
        Largest total size of the entries, bytes.
    """
    for leftover in Path(cache_dir).glob(".*.tmp"):
        try:
            if time.time() - leftover.stat().st_mtime > ABANDONED_WRITE_S:
                leftover.unlink()
        except OSError:
            continue
    entries = []
    for entry in Path(cache_dir).glob("*.npz"):
        try:
            stat = entry.stat()
        except OSError:
            continue
        entries.append((stat.st_mtime, stat.st_size, entry))
    total = sum(size for _, size, _ in entries)
    for _, size, entry in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        entry.unlink(missing_ok=True)
        total -= size
