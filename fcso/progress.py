"""The progress callback every long-running step of fcso accepts."""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    """``progress(stage, done, total, note="")``: called as long work advances.

    ``stage`` names the step ("sampling", "screening", "pictures", ...),
    ``done`` of ``total`` units are finished, and ``note`` says more in words
    (the best screened Q and the upper bound while searching); steps without
    anything to add leave it out.
    """

    def __call__(self, stage: str, done: int, total: int, note: str = "", /) -> None: ...


def progress_with_note(progress: Progress | None) -> Progress:
    """``progress`` with its note optional, or a no-op."""
    if progress is None:
        return lambda stage, done, total, note="": None
    return lambda stage, done, total, note="": progress(stage, done, total, note)
