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


class RepairToleranceError(MeshError):
    """A repair that would change a part more than ``[parts]`` allows (the file is refused).

    Parameters
    ----------
    path : str or Path
        The file at fault.
    volume_change_percent : float
        How much hole filling and dropped shells changed the shells' volume, %.
    max_deviation_mm : float
        Largest distance from a repaired corner to the file's triangles, mm.
    limits : str
        The limits that were passed, in words with their config keys.
    """

    def __init__(self, path: str | Path, volume_change_percent: float, max_deviation_mm: float, limits: str):
        self.volume_change_percent = volume_change_percent
        self.max_deviation_mm = max_deviation_mm
        super().__init__(
            path,
            f"repair would change the part too much: volume {volume_change_percent:+.2f} %, largest surface "
            f"deviation {max_deviation_mm:.3f} mm ({limits}); fix the file or raise the limit",
        )


class ConfigError(FcsoError):
    """A configuration file or value that is not valid."""

    def __init__(self, source: str | Path, defect: str):
        self.source = str(source)
        self.defect = defect
        super().__init__(f"{self.source}: {defect}")


class GeometryError(FcsoError):
    """A Boolean or mesh operation whose result breaks the method's contract."""


class UnwritableSolidError(GeometryError):
    """A fused finger that is not one watertight body: as fused (a pad cut apart by its pockets) or once written to
    STL (its corners rounded to float32)."""


class NoGraspError(FcsoError):
    """A grasp scenario with no valid sample, so no finger can be designed."""


class ComputeError(FcsoError):
    """The compute cluster a design was sent to (``[compute] scheduler``) cannot run it."""
