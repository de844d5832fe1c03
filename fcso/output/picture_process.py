"""A process that draws report pictures, started before the design so matplotlib loads beside it.

A one-shot ``fcso design`` would otherwise import matplotlib and the drawing
code (0.4-0.5 s on one core) after the design, on the command's critical
path. :class:`PictureProcess` forks as the command starts (the method's
modules are loaded, matplotlib is not): the process imports the drawing code
while this one loads the parts and designs, then draws every page it is sent
with :func:`fcso.output.design_page.pictures` (itself spread over forked workers)
and returns the PNG bytes. The pictures are the same as drawn in-process.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
from multiprocessing.connection import Connection

from ..errors import FcsoError
from ..parallel import die_with_parent
from ..progress import Progress
from ..startup import collector_paused
from .design_page import ReportInputs, picture_inputs


class PictureProcessError(FcsoError):
    """The picture process ended without answering."""


class PictureProcess:
    """A forked process that draws ``report.html`` pictures; call it as :func:`fcso.output.design_page.pictures`.

    Use as a context manager: leaving it ends the process.
    """

    def __init__(self):
        context = multiprocessing.get_context("fork")
        self._connection, child_end = context.Pipe()
        # not a daemonic process: it forks the picture workers itself
        self._process = context.Process(target=_serve, args=(child_end, os.getpid()), name="fcso-pictures")
        self._process.start()
        child_end.close()

    def __enter__(self) -> PictureProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __call__(self, inputs: ReportInputs, progress: Progress | None = None) -> dict[str, bytes]:
        """A page's pictures, name -> PNG bytes, drawn in the process; its exceptions are raised here."""
        try:
            self._connection.send(picture_inputs(inputs))
            while True:
                kind, payload = self._connection.recv()
                if kind == "progress":
                    if progress is not None:
                        progress(*payload)
                elif kind == "error":
                    raise payload
                else:
                    return payload
        except (EOFError, BrokenPipeError) as exc:
            raise PictureProcessError(f"the picture process ended (exit code {self._process.exitcode})") from exc

    def close(self) -> None:
        """End the process (it finishes the page it draws, if any)."""
        if self._process.is_alive():
            try:
                self._connection.send(None)
            except (BrokenPipeError, OSError):
                pass
        self._process.join(timeout=10)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join()
        self._connection.close()


def _serve(connection: Connection, parent_pid: int) -> None:
    # the command's end of the pipe is open here too: without this a killed command would leave the process waiting
    die_with_parent(parent_pid)
    # the drawing code loads now, while the design runs, not when the page arrives; it lives as long as the process
    with collector_paused():
        from . import pictures as drawing  # noqa: F401
        from .design_page import pictures

        gc.freeze()

    def report_progress(stage: str, done: int, total: int) -> None:
        connection.send(("progress", (stage, done, total)))

    while True:
        try:
            inputs = connection.recv()
        except EOFError:
            return
        if inputs is None:
            return
        try:
            connection.send(("pictures", pictures(inputs, report_progress)))
        except Exception as exc:  # raised again in the command, which reports it
            try:
                connection.send(("error", exc))
            except Exception:
                connection.send(("error", PictureProcessError(f"drawing the pictures failed: {exc!r}")))
