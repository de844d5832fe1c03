"""The finger sets of a job and its pick plan: pydantic models of ``report.json`` (METHOD §11).

With one finger set a job's ``report.json`` is a :class:`~fcso.report.DesignReport`
whose ``finger_sets`` holds :class:`FingerSetsReport`; with several it is a
:class:`JobReport`, and every set's own design report is in ``set-<k>/report.json``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from .config import DesignConfig
from .report import GraspReport, PartReport, UngraspableReport


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SetScenarioReport(_Model):
    """One scenario (a part in one stable pose) in the finger set that serves it."""

    part: str
    pose_index: int
    set: int | None = Field(description="Finger set serving it (1 = first); null when the scenario is ungraspable")
    effective_area: float = Field(description="E of the scenario with its set's finger (exact pocket, METHOD §6-7), mm²")
    solo_effective_area: float = Field(description="E*: best E of a design for this scenario alone (0: ungraspable), mm²")
    retained: float | None = Field(description="E / E*; null when E* = 0")
    screened_retained: float | None = Field(description="E / E* under screening, as the partition search saw it; null when not screened")


class FingerSetReport(_Model):
    """One finger set: a finger designed for some of the job's parts."""

    set: int = Field(description="Set number, 1 = first (sets numbered by their first part in job order)")
    folder: str = Field(description="Folder of its finger.stl, fingerpad.stl and report, relative to the job's report ('.' with one set)")
    parts: list[str] = Field(description="Distinct parts it serves, job order")
    quality: float = Field(description="Q = min E over its scenarios (exact, as printed), mm²")
    worst_retained: float = Field(description="Least E / E* over its scenarios")
    mean_retained: float = Field(description="Mean E / E* over its scenarios")
    pad_case: str = Field(description="good, bad or mixed (METHOD §5)")


class IdenticalPartsReport(_Model):
    """Parts with the same geometry (after units and shell union), designed once."""

    part: str = Field(description="The one designed (first in job order)")
    copies: list[str] = Field(description="Every part of the job with this geometry, itself included, job order")
    quantity: int = Field(description="Pieces to pick: build items over all the copies")


class PairConflictReport(_Model):
    """Two parts screened as one finger set."""

    parts: list[str] = Field(description="The two parts")
    retained: list[float] = Field(description="Worst screened E / E* of each when they share a finger")


class PartitionSearchReport(_Model):
    """How the parts were split into sets and what bounds the split."""

    method: Literal["single_set", "single_part", "exhaustive", "conflict_graph_colouring+local_moves"] = Field(
        description="single_set: [finger_sets] max = 1; single_part: one distinct graspable part; "
        "exhaustive: every partition screened; conflict_graph_colouring+local_moves: greedy sets from pair conflicts, improved by moving parts"
    )
    description: str = Field(description="The same in words, with what it proves")
    proven: bool = Field(description="The partition is the best under screening (every partition into at most max sets screened)")
    sets_tried: list[int] = Field(description="Numbers of sets the search tried")
    set_screenings: int = Field(description="Distinct candidate sets screened")
    lower_bound_sets: int = Field(description="Largest group of pairwise conflicting parts: no partition reaching min_retained has fewer sets")
    conflict_clique: list[str] = Field(description="That group of parts")
    worst_retained_bound: float | None = Field(
        description="When that group is larger than max, two of its parts share a set: no partition keeps a larger worst E / E* (screened)"
    )
    blocking_pairs: list[PairConflictReport] = Field(description="Pairs of parts that keep less than min_retained when they share a finger")
    explanation: str | None = Field(description="Why min_retained is not reached, when it is not")


class PickPart(_Model):
    """A part the cell picks with the mounted finger set."""

    part: str = Field(description="Part designed (its copies are listed in copies)")
    copies: list[str] = Field(description="Every job part with this geometry")
    quantity: int = Field(description="Pieces to pick")
    grasps: list[GraspReport] = Field(description="Grasp per stable pose the part may lie in")


class PickStep(_Model):
    """Mount one finger set, then pick its parts."""

    set: int
    finger: str = Field(description="The finger to mount: its STL, relative to the job's report")
    parts: list[PickPart]


class FingerSetsReport(_Model):
    """The job's finger sets (METHOD §11) and the pick plan for the cell."""

    max_sets: int = Field(description="[finger_sets] max")
    min_retained: float = Field(description="[finger_sets] min_retained")
    sets: list[FingerSetReport]
    scenarios: list[SetScenarioReport] = Field(description="Every scenario of every distinct part: those with samples in job order, then those without")
    worst_retained: float | None = Field(description="Least E / E* over graspable scenarios")
    median_retained: float | None = Field(description="Median E / E* over graspable scenarios")
    min_retained_reached: bool = Field(description="Every graspable scenario keeps at least min_retained (exact)")
    identical_parts: list[IdenticalPartsReport] = Field(description="Groups of identical parts designed once (only groups of two or more)")
    ungraspable_parts: list[str] = Field(description="Parts no set can grasp in any chosen pose: not in the pick plan")
    ungraspable: list[UngraspableReport] = Field(description="Every ungraspable scenario")
    pick_plan: list[PickStep] = Field(description="Finger sets in the order to mount them, each with the parts to pick")
    search: PartitionSearchReport


class JobReport(_Model):
    """``report.json`` of a job served by two or more finger sets."""

    fcso_version: str
    parts: list[PartReport]
    finger_sets: FingerSetsReport
    timings_s: dict[str, float] = Field(description="Wall time per stage, s")
    warnings: list[str]
    settings: DesignConfig
    placement: dict | None = Field(
        None, description="Where every set's finger copies go in the job's build volume, added by fcsod (schema: schemas/placement-report.json)"
    )
