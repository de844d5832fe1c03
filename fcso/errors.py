"""Typed errors. Every message names the file (or setting) and the defect."""

from __future__ import annotations

from pathlib import Path


class FcsoError(Exception):
    """Base class of every error fcso raises on purpose."""


class MeshError(FcsoError):
    """A mesh file that cannot be used as a part or a finger.

    Parameters
    ----------
    path : str or Path
        The file at fault.
    defect : str
        What is wrong with it, in words a user can act on.
    """

    def __init__(self, path: str | Path, defect: str):
        self.path = str(path)
        self.defect = defect
        super().__init__(f"{self.path}: {defect}")


class ConfigError(FcsoError):
    """A configuration file or value that is not valid."""

    def __init__(self, source: str | Path, defect: str):
        self.source = str(source)
        self.defect = defect
        super().__init__(f"{self.source}: {defect}")


class GeometryError(FcsoError):
    """A Boolean or mesh operation whose result breaks the method's contract."""


class NoGraspError(FcsoError):
    """A grasp scenario with no valid sample, so no finger can be designed."""


class ComputeError(FcsoError):
    """The compute cluster a design was sent to (``[compute] scheduler``) cannot run it."""
