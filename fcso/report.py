"""The design report: pydantic models of ``report.json``."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from .config import DesignConfig


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class RepairReport(_Model):
    """What --repair changed on a part's file (METHOD: parts as a slicer takes them)."""

    holes_filled: int = Field(description="Boundary loops closed (MeshFix)")
    faces_added: int = Field(description="Triangles added to close holes")
    faces_flipped: int = Field(description="Triangles turned to agree with their shell's winding")
    faces_removed: int = Field(description="Degenerate and duplicated triangles removed")
    shells_inverted: int = Field(description="Closed shells turned over to face outward")
    shells_in: int = Field(description="Connected shells of the file's triangles after cleaning")
    shells_dropped: int = Field(description="Shells left out because they enclose no volume")
    solids_out: int = Field(description="Solids made of the closed shells (overlaps united with manifold3d), all parts of the file")
    volume_before_mm3: float = Field(description="Sum of the shells' absolute enclosed volumes before hole filling, mm³")
    volume_after_mm3: float = Field(description="Volume of the file's solids after repair and union, mm³")
    max_surface_deviation_mm: float = Field(description="Largest distance from a repaired corner to the file's triangles, mm")


class PartReport(_Model):
    """A part as it was used."""

    name: str
    file: str
    scale_to_mm: float = Field(description="Factor applied to the file's coordinates to get mm")
    extents_mm: list[float] = Field(description="Bounding-box size in the file frame after scaling, mm")
    volume_mm3: float
    faces: int
    repairs: list[str] = Field(description="What --repair changed; empty when nothing was repaired")
    repair: RepairReport | None = Field(None, description="What --repair changed, in figures; null without --repair")
    shells: int = Field(1, description="Closed shells of the file that make up this part")
    solid_index: int | None = Field(
        None, description="k of the name <file>#<k> when the file held several separate solids (1 = largest), else null"
    )
    shell_handling: str | None = Field(None, description="How the file's shells were made one solid; null for a single shell")


class UngraspableReport(_Model):
    """A part in a stable pose that no sample can grasp, left out of the design."""

    part: str
    pose_index: int
    tried_samples: int
    rejected: dict[str, int] = Field(description="Rejected samples per reason (METHOD §3)")
    reason: str = Field(description="Why, in one sentence")


class SampleReport(_Model):
    """One valid sample pair of a scenario and the filter labels of its two pads."""

    yaw_deg: float
    s_mm: float = Field(description="Footprint centre along the sliding axis, mm")
    h_mm: float = Field(description="Footprint bottom above the table, mm")
    a_max_mm: float = Field(description="Part's largest coordinate along the closing axis inside the footprint, mm")
    a_min_mm: float = Field(description="Part's smallest coordinate along the closing axis inside the footprint, mm")
    surface_area_mm2: list[float] = Field(description="Part surface inside the + and - pad boxes, mm²")
    labels: list[str] = Field(description="Filter label of the + and - geometries: good or bad")
    ratio: list[float] = Field(description="R = (V_B - V_I) / V_B of the + and - geometries")
    depth_mm: list[float] = Field(description="d_n of the + and - geometries, mm")
    effective_area_bound: float = Field(description="Upper bound of E for any candidate using this sample, mm²")


class ScenarioReport(_Model):
    """One grasp scenario: a part in one stable pose."""

    part: str
    pose_index: int = Field(description="Index among the part's stable poses, 0 = most probable")
    pose_probability: float
    rest_transform: list[list[float]] = Field(description="4x4, part file frame (mm) to resting frame (mm)")
    tried_samples: int = Field(description="Sample pairs whose footprint met the part")
    valid_samples: int
    rejected: dict[str, int] = Field(description="Rejection reason -> count")
    samples: list[SampleReport]


class ScenarioQuality(_Model):
    """Quality of one candidate in one scenario."""

    rles: float = Field(description="Radius of the largest empty sphere of contact normals (chord, 0..2)")
    contact_area_mm2: float = Field(description="A: contact area of both pads, mm²")
    effective_area: float = Field(description="E = A / RLES, mm²")
    seat_offsets_mm: list[float] = Field(description="Seating offset t of the + and - pads, mm")


class CandidateReport(_Model):
    """One evaluated candidate fingerpad."""

    index: int = Field(description="Position in the lexicographic enumeration of sample choices")
    samples: list[int] = Field(description="Chosen sample per scenario (same order as scenarios)")
    evaluation: Literal["exact", "screened"] = Field(
        "exact", description="exact: METHOD §6-7 (re-evaluated finalists); screened: the fast ranking of METHOD §8b"
    )
    per_scenario: list[ScenarioQuality]
    quality: float = Field(description="Q = min over scenarios of E, mm²")
    mean_effective_area: float = Field(description="Mean E over scenarios (first tie-break), mm²")
    pad_case: str = Field(description="good, bad or mixed (METHOD §5)")
    block_depth_mm: float | None = Field(None, description="d_B in the mixed case, mm")


class SearchReport(_Model):
    """How the candidates were searched (METHOD §8, §8b)."""

    kind: str = Field(description="exhaustive, branch_and_bound or branch_and_bound+coordinate_ascent (over screened quality)")
    evaluated: int = Field(description="Candidates evaluated (screened)")
    screened: int = Field(0, description="Candidates screened")
    exact: int = Field(0, description="Best screened candidates re-evaluated exactly; the design is the best of these")
    candidates_total: int = Field(description="C = product of valid samples per scenario")
    proven_optimal: bool = Field(description="Every candidate was screened, or branch and bound proved the screened best")
    jobs: int = Field(1, description="Worker processes used")
    quality_upper_bound: float | None = Field(None, description="No candidate's exact Q exceeds this (per-sample bounds), mm²")
    gap: float | None = Field(None, description="Chosen Q over quality_upper_bound (1 = provably optimal)")


class GraspReport(_Model):
    """What the robot runs for one part in one pose."""

    part: str
    pose_index: int
    sample: int
    rest_transform: list[list[float]] = Field(description="4x4, part file frame to resting frame (mm)")
    position_mm: list[float] = Field(description="TCP position in the resting frame, mm")
    quaternion_wxyz: list[float] = Field(description="TCP orientation in the resting frame (z: approach, y: closing axis)")
    approach_direction: list[float]
    closing_axis: list[float]
    pad_gap_mm: float = Field(description="Distance between the two pad faces at contact, mm")
    closing_width_mm: float = Field(description="Distance between the flat fingers' contact faces at contact, mm")
    finger_set: int | None = Field(None, description="Finger set making this grasp (METHOD §11), 1 = first; null with [finger_sets] max = 1")


class FingerReport(_Model):
    source: str = Field(description="built-in or the finger mesh file")
    repairs: list[str]
    volume_mm3: float
    bodies: int
    watertight: bool
    min_pad_thickness_mm: float


class PrintFitEffect(_Model):
    """The chosen candidate carved one way (exact or with clearance and lead-in), both after thin-wall removal."""

    pocket_volume_mm3: float = Field(description="Pad box volume minus pad volume, mm³")
    contact_area_mm2: list[float] = Field(description="A per scenario (same order as scenarios), mm²")
    effective_area: list[float] = Field(description="E per scenario, mm²")
    seat_offsets_mm: list[list[float]] = Field(description="Seating offset t of the + and - pads per scenario (negative: the pad closed a clearance), mm")
    quality: float = Field(description="Q = min E, mm²")


class PrintFitReport(_Model):
    """``[print]`` as used and what clearance and lead-in changed on the chosen candidate."""

    profile: str
    clearance_mm: float = Field(description="Effective clearance (profile or explicit), mm")
    lead_in_deg: float = Field(description="Effective lead-in draft, degrees")
    min_wall_mm: float = Field(description="Effective minimum wall, mm")
    density_g_cm3: float = Field(description="Effective part material density, g/cm³")
    thinnest_wall_mm: float | None = Field(description="Thinnest wall of the chosen pad (fused side excluded), mm; null for an empty pad")
    exact: PrintFitEffect = Field(description="The chosen candidate with the exact pocket of METHOD §4 (no clearance, no lead-in)")
    fitted: PrintFitEffect = Field(description="The chosen candidate as designed, with clearance and lead-in")


class DesignReport(_Model):
    """Everything ``fcso design`` decided and why (``report.json``)."""

    fcso_version: str
    parts: list[PartReport]
    scenarios: list[ScenarioReport]
    candidates: list[CandidateReport]
    best: int = Field(description="Index of the chosen candidate (argmax Q, ties: larger mean E, then smaller index)")
    search: SearchReport
    grasps: list[GraspReport]
    ungraspable: list[UngraspableReport] = Field(
        default_factory=list, description="Parts in stable poses that no sample can grasp; the design serves the others"
    )
    finger: FingerReport
    timings_s: dict[str, float] = Field(description="Wall time per stage, s (the only field that varies between identical runs)")
    warnings: list[str]
    settings: DesignConfig
    print_fit: PrintFitReport | None = Field(None, description="[print] as used and what clearance and lead-in changed")
    placement: dict | None = Field(
        None, description="Where the finger copies go in the job's build volume, added by fcsod (schema: schemas/placement-report.json)"
    )
    finger_sets: "FingerSetsReport | None" = Field(
        None, description="The job's finger sets and pick plan when it ran with [finger_sets] max > 1 and one set serves it (METHOD §11)"
    )


# the finger-set models build on the ones above
from .sets_report import FingerSetsReport  # noqa: E402

DesignReport.model_rebuild()
