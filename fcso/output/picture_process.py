"""A process that draws report pictures, started before the design so matplotlib loads beside it.

A one-shot ``fcso design`` would otherwise import matplotlib and the drawing
code (0.4-0.5 s on one core) after the design, on the command's critical
path. :class:`PictureProcess` forks as the command starts, once the
libraries the pictures share with the method are loaded (trimesh, scipy,
manifold3d) but before the method's modules (numba's kernels): the process
imports matplotlib and the drawing code (:mod:`fcso.output.pictures`) on
the other core while this one imports the method, and sits idle while the
design runs on both. It is sent a page's drawings
(:meth:`fcso.output.design_page.ReportInputs.drawings`: meshes, arrays,
strings and report models, which it unpickles without the method's
modules), draws them with :func:`fcso.output.pictures.draw_pictures`
(itself spread over forked workers) and returns the PNG bytes. The
pictures are the same as drawn in-process.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING

# what the drawings are made of (meshes, pad placements, report models) the command loads anyway: loaded before the
# process forks, it is inherited, and the process itself loads only matplotlib and the drawing code
from .. import contact, geometry  # noqa: F401
from ..errors import FcsoError
from ..parallel import die_with_parent, resolve_jobs
from ..progress import Progress
from ..report import models  # noqa: F401
from ..startup import collector_paused

if TYPE_CHECKING:
    from .design_page import ReportInputs


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
            self._connection.send((inputs.drawings(), resolve_jobs(inputs.report.settings.search.jobs)))
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
    # the drawing code loads now, while the command loads the method, not when the page arrives; it lives as long as
    # the process
    with collector_paused():
        from .pictures import draw_pictures

        gc.freeze()

    def report_progress(stage: str, done: int, total: int) -> None:
        connection.send(("progress", (stage, done, total)))

    while True:
        try:
            page = connection.recv()
        except EOFError:
            return
        if page is None:
            return
        try:
            connection.send(("pictures", draw_pictures(*page, report_progress)))
        except Exception as exc:  # raised again in the command, which reports it
            try:
                connection.send(("error", exc))
            except Exception:
                connection.send(("error", PictureProcessError(f"drawing the pictures failed: {exc!r}")))
