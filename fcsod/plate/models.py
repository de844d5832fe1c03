"""The ``[build]`` settings and the placement report: models only, light to import (the daemon's config uses them)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from fcso.errors import MeshError


class BuildConfig(BaseModel):
    """The ``[build]`` section: build volume, spacing and finger copies."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    volume_mm: tuple[float, float, float] = Field(
        (380.0, 284.0, 380.0), description="Build volume x, y, z, mm (default HP MJF 5200)"
    )
    origin_mm: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="Lower corner of the build volume in the build's coordinates, mm"
    )
    spacing_mm: float = Field(5.0, ge=0, description="Minimum gap between any two items, mm")
    wall_margin_mm: float = Field(
        10.0, ge=0, description="Minimum gap between an item and the volume's walls, floor and top, mm"
    )
    finger_copies: int = Field(2, ge=1, description="Finger copies the job needs (a gripper's pair)")
    spare_fingers: int = Field(0, ge=0, description="Extra finger copies, placed when there is room")
    finger_orientations: Literal["axis_aligned", "pad_up"] = Field(
        "axis_aligned",
        description="axis_aligned: the 24 axis-aligned rotations, pad face up preferred; pad_up: only the 4 with the "
        "pad face up",
    )
    part_orientations: Literal["as_given", "z_rotations", "axis_aligned"] = Field(
        "z_rotations", description="Rotations allowed when packing unplaced parts (z_rotations keeps each part's up)"
    )
    voxel_mm: float = Field(2.0, gt=0, description="Voxel size of the placement search, mm (smaller: tighter, slower)")

    @model_validator(mode="after")
    def _room_inside_margins(self) -> BuildConfig:
        if any(size <= 0 for size in self.volume_mm):
            raise ValueError(f"volume_mm must be positive, got {self.volume_mm}")
        if any(size <= 2.0 * self.wall_margin_mm for size in self.volume_mm):
            raise ValueError(f"wall_margin_mm {self.wall_margin_mm} leaves no room in volume_mm {self.volume_mm}")
        return self


class PlacedItemReport(BaseModel):
    """One item of the placed build."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    kind: Literal["part", "finger"]
    placed_by: Literal["build", "placer"] = Field(description="build: the job's own placement; placer: placed by fcsod")
    transform: list[list[float]] = Field(description="4x4 row-major, mesh frame to build-volume frame, mm")
    bounds_mm: list[list[float]] = Field(description="[[xmin, ymin, zmin], [xmax, ymax, zmax]] of the placed mesh, mm")
    nearest_distance_mm: float | None = Field(
        description="Gap to the nearest other item (exact to 0.1 mm); None when alone"
    )
    nearest_item: str | None


class PlacementReport(BaseModel):
    """The placement section of report.json, the MCAP placement channel and zenoh."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    mode: Literal["add_fingers", "pack"] = Field(
        description="add_fingers: the job's build was placed, fingers added; pack: unplaced parts and fingers packed"
    )
    fingers_fit: bool = Field(description="All finger_copies are in the build")
    all_items_placed: bool = Field(description="Every part and finger copy (spares included) is in the build")
    finger_copies_requested: int = Field(description="finger_copies + spare_fingers")
    finger_copies_placed: int
    volume_mm: tuple[float, float, float]
    spacing_mm: float
    wall_margin_mm: float
    voxel_mm: float
    build_height_mm: float = Field(description="Top of the highest item above the volume floor, mm")
    packing_density: float = Field(description="Volume of the items / (volume x * y * build height)")
    extra_height_needed_mm: float | None = Field(
        description="When items did not fit: the build height missing to fit them; None when everything fits or "
        "nothing would"
    )
    items: list[PlacedItemReport]
    unplaced_items: list[str]
    message: str
    warnings: list[str]
    placement_seconds: float


def parse_transform(value, source: str = "transform") -> np.ndarray:
    """A 4x4 transform from a manifest value.

    Parameters
    ----------
    value : sequence
        Row-major list of 16 numbers, or 4 rows of 4 numbers, mm.
    source : str
        Names the setting in error messages.

    Returns
    -------
    (4, 4) float
        The transform; its last row is ``0 0 0 1``.

    Raises
    ------
    MeshError
        Wrong shape, non-finite numbers, a last row other than ``0 0 0 1`` or a
        singular (flattening) 3x3 part.
    """
    try:
        matrix = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MeshError(source, "transform must be 16 numbers or 4 rows of 4 numbers") from None
    if matrix.size != 16 or matrix.ndim not in (1, 2) or (matrix.ndim == 2 and matrix.shape != (4, 4)):
        raise MeshError(source, f"transform must be 16 numbers or 4 rows of 4 numbers, got shape {matrix.shape}")
    matrix = matrix.reshape(4, 4)
    if not np.all(np.isfinite(matrix)):
        raise MeshError(source, "transform holds a non-finite number")
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0]):
        raise MeshError(source, f"transform's last row must be 0 0 0 1, got {matrix[3].tolist()}")
    if abs(np.linalg.det(matrix[:3, :3])) < 1e-9:
        raise MeshError(source, "transform is singular (it flattens the part)")
    return matrix
