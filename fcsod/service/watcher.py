"""Watching the job roots and deciding when a job folder is complete.

A watchdog observer (inotify, or polling for network shares written by
other machines) marks folders as changed; a full rescan at start-up, at a
fixed interval and after an inotify queue overflow catches whatever the
observer missed. :class:`Readiness` applies PRODUCT.md's rules: a job is
ready when its inputs (the manifest and the files it names, or every file
without a manifest) have kept their size and mtime for ``settle_seconds``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from watchdog.events import FileSystemEvent, FileSystemEventHandler
from watchdog.observers import Observer
from watchdog.observers.polling import PollingObserver

from ..job.inputs import FileStat, FolderInputs, job_inputs, stat_inputs

log = logging.getLogger("fcsod.watcher")


class _OverflowAlarm(logging.Handler):
    """Turns watchdog's "Inotify queue overflowed" warning into a rescan request (events were lost)."""

    def __init__(self, rescan: threading.Event):
        super().__init__(logging.WARNING)
        self.rescan = rescan

    def emit(self, record: logging.LogRecord) -> None:
        if "overflow" in record.getMessage().lower():
            self.rescan.set()


#: Events that change nothing; reading a folder (hashing it) causes them.
_READ_ONLY_EVENTS = {"opened", "closed_no_write"}


class _Handler(FileSystemEventHandler):
    def __init__(self, watcher: FolderWatcher):
        self.watcher = watcher

    def on_any_event(self, event: FileSystemEvent) -> None:
        if event.event_type in _READ_ONLY_EVENTS:
            return
        for path in (event.src_path, getattr(event, "dest_path", "")):
            if path:
                self.watcher.mark(Path(path.decode() if isinstance(path, bytes) else path))


class FolderWatcher:
    """Collects the job folders that changed below the watched roots.

    Parameters
    ----------
    roots : list of Path
        Watched roots; each direct sub-folder is a job folder.
    polling : bool
        Use the polling observer (network shares) instead of inotify.
    poll_interval_seconds : float
        Interval of the polling observer, s.
    """

    def __init__(self, roots: list[Path], polling: bool = False, poll_interval_seconds: float = 1.0):
        self.roots = [Path(r).resolve() for r in roots]
        self.polling = polling
        self.rescan_requested = threading.Event()
        self._changed: set[Path] = set()
        self._lock = threading.Lock()
        self._observer = PollingObserver(timeout=poll_interval_seconds) if polling else Observer()
        self._alarm = _OverflowAlarm(self.rescan_requested)

    def start(self) -> None:
        """Start observing every root (recursively)."""
        handler = _Handler(self)
        for root in self.roots:
            self._observer.schedule(handler, str(root), recursive=True)
        logging.getLogger("watchdog").addHandler(self._alarm)
        self._observer.start()

    def stop(self) -> None:
        self._observer.stop()
        self._observer.join(timeout=10)
        logging.getLogger("watchdog").removeHandler(self._alarm)

    def job_folder(self, path: Path) -> Path | None:
        """The job folder a changed path belongs to, or None for a root itself, a hidden folder or a path elsewhere."""
        for root in self.roots:
            try:
                relative = path.relative_to(root)
            except ValueError:
                continue
            if not relative.parts or relative.parts[0].startswith("."):
                return None
            return root / relative.parts[0]
        return None

    def mark(self, path: Path) -> None:
        """Note that something changed at ``path`` (called from the observer's thread)."""
        folder = self.job_folder(path)
        if folder is not None:
            with self._lock:
                self._changed.add(folder)

    def take_changed(self) -> set[Path]:
        """The job folders that changed since the last call."""
        with self._lock:
            changed, self._changed = self._changed, set()
        return changed

    def all_folders(self) -> list[Path]:
        """Every job folder below the roots (hidden folders, used for writing before a rename, and symlinks
        excluded).
        """
        folders = []
        for root in self.roots:
            try:
                entries = sorted(root.iterdir())
            except OSError as exc:
                log.error("cannot list watch root", extra={"root": str(root), "error": str(exc)})
                continue
            folders.extend(p for p in entries if p.is_dir() and not p.is_symlink() and not p.name.startswith("."))
        return folders


@dataclass
class ReadyFolder:
    """A job folder whose inputs have settled."""

    folder: Path
    inputs: FolderInputs
    signature: tuple


class Readiness:
    """Tracks changing job folders until their inputs settle.

    Parameters
    ----------
    settle_seconds : float
        How long the inputs must stay unchanged, s.
    clock : callable
        Source of monotonic time, s (default ``time.monotonic``).
    """

    def __init__(self, settle_seconds: float, clock: Callable[[], float] = time.monotonic):
        self.settle_seconds = settle_seconds
        self.clock = clock
        self._pending: dict[Path, tuple[tuple | None, float]] = {}
        self._waiting_logged: set[tuple[Path, tuple[str, ...]]] = set()

    def touch(self, folder: Path) -> None:
        """Consider ``folder`` again (it changed or a rescan found it)."""
        self._pending.setdefault(folder, (None, self.clock()))

    @property
    def pending(self) -> list[Path]:
        return list(self._pending)

    def poll(self) -> list[ReadyFolder]:
        """The pending folders that are ready now; they stop being pending."""
        now, ready = self.clock(), []
        for folder, (previous, since) in list(self._pending.items()):
            if not folder.is_dir():
                del self._pending[folder]
                continue
            inputs = job_inputs(folder)
            if not inputs.files and not inputs.missing:
                # an empty folder: its first file will bring it back
                del self._pending[folder]
                continue
            signature = signature_of(folder, inputs)
            if signature != previous:
                self._pending[folder] = (signature, now)
                continue
            if inputs.missing:
                if (folder, inputs.missing) not in self._waiting_logged:
                    self._waiting_logged.add((folder, inputs.missing))
                    log.info(
                        "waiting for files the manifest names",
                        extra={"folder": str(folder), "missing": list(inputs.missing)},
                    )
                continue
            if now - since >= self.settle_seconds:
                del self._pending[folder]
                ready.append(ReadyFolder(folder, inputs, signature))
        return ready


def signature_of(folder: Path, inputs: FolderInputs) -> tuple[tuple[str, ...], tuple[FileStat, ...]]:
    """What must stay unchanged for a folder to be ready: missing names and each input's size and mtime."""
    return inputs.missing, stat_inputs(folder, inputs)
