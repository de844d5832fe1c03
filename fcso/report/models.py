"""The reports: pydantic models of ``report.json``.

A design's ``report.json`` is a :class:`DesignReport`. A job served by
several finger sets (METHOD §11) writes a :class:`JobReport`, and every set's
own design report beside it; with one finger set the design report's
``finger_sets`` holds :class:`FingerSetsReport`.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from ..config import DesignConfig


class ReportModel(BaseModel):
    # the base of every report model: a field the model does not know is an error
    model_config = ConfigDict(extra="forbid")


class RepairReport(ReportModel):
    """What --repair changed on a part's file (parts as a slicer takes them)."""

    holes_filled: int = Field(description="Boundary loops closed (MeshFix)")
    faces_added: int = Field(description="Triangles added to close holes")
    faces_flipped: int = Field(description="Triangles turned to agree with their shell's winding")
    faces_removed: int = Field(description="Degenerate and duplicated triangles removed")
    shells_inverted: int = Field(description="Closed shells turned over to face outward")
    shells_in: int = Field(description="Connected shells of the file's triangles after cleaning")
    shells_dropped: int = Field(description="Shells left out because they enclose no volume")
    solids_out: int = Field(
        description="Solids made of the closed shells (overlaps united with manifold3d), all parts of the file"
    )
    volume_before_mm3: float = Field(
        description=(
            "Sum of the shells' absolute enclosed volumes before hole filling (an open shell's about the centre of "
            "its open edges), mm³"
        )
    )
    volume_after_mm3: float = Field(description="Volume of the file's solids after repair and union, mm³")
    volume_change_percent: float = Field(
        description=(
            "Change of the shells' volume by hole filling and dropped shells, % of volume_before_mm3 (before the "
            "union, so overlaps are no change); limited by [parts] repair_max_volume_change_percent"
        )
    )
    max_surface_deviation_mm: float = Field(
        description="Largest distance from a repaired corner to the file's triangles, mm"
    )


class PartReport(ReportModel):
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
    shell_handling: str | None = Field(
        None, description="How the file's shells were made one solid; null for a single shell"
    )


class UngraspableReport(ReportModel):
    """A part in a stable pose that no sample can grasp, left out of the design."""

    part: str
    pose_index: int
    pose_probability: float = Field(description="Probability of the stable pose (METHOD §2)")
    tried_samples: int
    rejected: dict[str, int] = Field(description="Rejected samples per reason (METHOD §3)")
    reason: str = Field(description="Why, in one sentence")


class SampleReport(ReportModel):
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
    on_feature: bool = Field(
        False,
        description="Its position or height was centred on a feature of the part (METHOD §3b), "
        "not taken from the stride",
    )


class CaptureLandscapeReport(ReportModel):
    """The squeeze of METHOD §7b over a grid of start errors, for a picture."""

    offsets_mm: list[float] = Field(description="Start errors along the sliding axis, mm (rows)")
    yaws_deg: list[float] = Field(description="Start errors about the vertical, degrees (columns)")
    separation_mm: list[list[float | None]] = Field(
        description="Jaw separation at first contact minus the seat's, mm; null where a pad loses the part"
    )
    captured: list[list[bool]] = Field(description="The start's squeeze ends at the seat")
    flat_captured: list[list[bool]] = Field(description="The same with flat pads")
    position_error_mm: float = Field(description="The test's start error box: -x..x along the sliding axis, mm")
    yaw_error_deg: float = Field(description="... and -x..x about the vertical, degrees")


class ScenarioReport(ReportModel):
    """One grasp scenario: a part in one stable pose."""

    part: str
    pose_index: int = Field(description="Index among the part's stable poses, 0 = most probable")
    pose_probability: float
    rest_transform: list[list[float]] = Field(description="4x4, part file frame (mm) to resting frame (mm)")
    tried_samples: int = Field(description="Sample pairs whose footprint met the part")
    valid_samples: int
    rejected: dict[str, int] = Field(description="Rejection reason -> count")
    samples: list[SampleReport]
    capture: float | None = Field(
        None,
        description="Share of the start errors the chosen pad seats (METHOD §7b), 0..1; null under the paper's measure",
    )
    capture_landscape: CaptureLandscapeReport | None = Field(
        None, description="The chosen pad's jaw separation over start errors and the starts it seats (METHOD §7b)"
    )
    flat_capture: float | None = Field(None, description="The same for flat pads on the chosen grasp, 0..1")
    beats_flat: bool = Field(
        True,
        description="Some pad tried captures this scenario better than flat pads; "
        "false: the design says flat is as good here",
    )


class ScenarioQuality(ReportModel):
    """Quality of one candidate in one scenario."""

    rles: float = Field(description="Radius of the largest empty sphere of contact normals (chord, 0..2)")
    contact_area_mm2: float = Field(description="A: contact area of both pads, mm²")
    effective_area: float = Field(description="E = A / RLES, mm²")
    seat_offsets_mm: list[float] = Field(description="Seating offset t of the + and - pads, mm")
    capture: float | None = Field(
        None,
        description="Share of the start errors that closing the jaws seats (METHOD §7b), 0..1; "
        "screened: the sample's pads alone, or the candidate's whole pad for the search.pad_top_k best; "
        "null under the paper's measure",
    )
    holding_n: list[float] | None = Field(
        None,
        description="Largest push at the centre of mass held, in the test's six directions "
        "(+b, -b, +a, -a, +z, -z), N; "
        "exact candidates under the capture measure only",
    )
    measure: float = Field(
        0.0,
        description="What ranks the scenario: E in mm² (paper), or (floor(20 c h) + E / (E + L W)) / 20 with c the "
        "capture and h = min(1, worst holding / hold force) (capture, fcso.measure; screened: h = 1), no unit",
    )


class CandidateReport(ReportModel):
    """One evaluated candidate fingerpad."""

    index: int = Field(description="Position in the lexicographic enumeration of sample choices")
    samples: list[int] = Field(description="Chosen sample per scenario (same order as scenarios)")
    evaluation: Literal["exact", "screened"] = Field(
        "exact", description="exact: METHOD §6-7 (re-evaluated finalists); screened: the fast ranking of METHOD §8b"
    )
    per_scenario: list[ScenarioQuality]
    quality: float = Field(
        description="The worst scenario's measure: Q = min E in mm² under the paper's measure; under the capture "
        "measure (fcso.measure) capture x holding in bands of 1/20, then E within a band, no unit"
    )
    mean_effective_area: float = Field(
        description="Mean measure over scenarios (first tie-break; mean E in mm² under the paper's measure)"
    )
    pad_case: str = Field(description="good, bad or mixed (METHOD §5)")
    block_depth_mm: float | None = Field(None, description="d_B in the mixed case, mm")


class SearchReport(ReportModel):
    """How the candidates were searched (METHOD §8, §8b)."""

    kind: str = Field(
        description="exhaustive, branch_and_bound or branch_and_bound+coordinate_ascent (over screened quality)"
    )
    evaluated: int = Field(description="Candidates evaluated (screened)")
    screened: int = Field(0, description="Candidates screened")
    exact: int = Field(0, description="Best screened candidates re-evaluated exactly; the design is the best of these")
    candidates_total: int = Field(description="C = product of valid samples per scenario")
    proven_optimal: bool = Field(
        description="Every candidate was screened, or branch and bound proved the screened best"
    )
    jobs: int = Field(1, description="Worker processes used")
    quality_upper_bound: float | None = Field(
        None, description="No candidate's exact Q exceeds this (per-sample bounds), mm²"
    )
    gap: float | None = Field(None, description="Chosen Q over quality_upper_bound (1 = provably optimal)")


class GraspReport(ReportModel):
    """What the robot runs for one part in one pose."""

    part: str
    pose_index: int
    sample: int
    rest_transform: list[list[float]] = Field(description="4x4, part file frame to resting frame (mm)")
    position_mm: list[float] = Field(description="TCP position in the resting frame, mm")
    quaternion_wxyz: list[float] = Field(
        description="TCP orientation in the resting frame (z: approach, y: closing axis)"
    )
    approach_direction: list[float]
    closing_axis: list[float]
    pad_gap_mm: float = Field(description="Distance between the two pad faces at contact, mm")
    closing_width_mm: float = Field(description="Distance between the flat fingers' contact faces at contact, mm")
    finger_set: int | None = Field(
        None, description="Finger set making this grasp (METHOD §11), 1 = first; null with [finger_sets] max = 1"
    )


class FingerReport(ReportModel):
    source: str = Field(description="built-in or the finger mesh file")
    repairs: list[str]
    volume_mm3: float
    bodies: int
    watertight: bool
    min_pad_thickness_mm: float
    flat_pads: bool = Field(
        description="The pads are flat: no carving tried captures any scenario better than flat pads (METHOD §7b), "
        "so none is printed"
    )


class PrintFitEffect(ReportModel):
    """The chosen candidate carved one way (exact or with clearance and lead-in), both after thin-wall removal."""

    pocket_volume_mm3: float = Field(description="Pad box volume minus pad volume, mm³")
    contact_area_mm2: list[float] = Field(description="A per scenario (same order as scenarios), mm²")
    effective_area: list[float] = Field(description="E per scenario, mm²")
    seat_offsets_mm: list[list[float]] = Field(
        description="Seating offset t of the + and - pads per scenario (negative: the pad closed a clearance), mm"
    )
    quality: float = Field(
        description="The worst scenario's measure as the design's quality (Q = min E, mm², or the capture measure)"
    )


class PrintFitReport(ReportModel):
    """``[print]`` as used and what clearance and lead-in changed on the chosen candidate."""

    profile: str
    clearance_mm: float = Field(description="Effective clearance (profile or explicit), mm")
    lead_in_deg: float = Field(
        description="Lead-in draft as printed: the effective lead_in_deg, or the wider alternative taken, degrees"
    )
    min_wall_mm: float = Field(description="Effective minimum wall, mm")
    density_g_cm3: float = Field(description="Effective part material density, g/cm³")
    thinnest_wall_mm: float | None = Field(
        description="Thinnest wall of the chosen pad (fused side excluded), mm; null for an empty pad"
    )
    exact: PrintFitEffect = Field(
        description="The chosen candidate with the exact pocket of METHOD §4 (no clearance, no lead-in)"
    )
    fitted: PrintFitEffect = Field(description="The chosen candidate as designed, with clearance and lead-in")


# the finger sets of a job (METHOD §11)


class SetScenarioReport(ReportModel):
    """One scenario (a part in one stable pose) in the finger set that serves it."""

    part: str
    pose_index: int
    set: int | None = Field(description="Finger set serving it (1 = first); null when the scenario is ungraspable")
    quality: float = Field(
        description="E of the scenario with its set's finger as printed, read as the scenario's quality (METHOD §11): "
        "E in mm² under the paper's measure, METHOD §7b's measure (no unit) under the capture measure"
    )
    solo_quality: float = Field(
        description="E*: best quality of a design for this scenario alone (0: ungraspable), as quality"
    )
    retained: float | None = Field(description="E / E*; null when E* = 0")
    screened_retained: float | None = Field(
        description="E / E* under screening, as the partition search saw it; null when not screened"
    )


class FingerSetReport(ReportModel):
    """One finger set: a finger designed for some of the job's parts."""

    set: int = Field(description="Set number, 1 = first (sets numbered by their first part in job order)")
    folder: str = Field(
        description="Folder of its finger.stl, fingerpad.stl and report, relative to the job's report ('.' with one "
        "set)"
    )
    parts: list[str] = Field(description="Distinct parts it serves, job order")
    quality: float = Field(description="Q = min E over its scenarios (exact, as printed), mm²")
    worst_retained: float = Field(description="Least E / E* over its scenarios")
    mean_retained: float = Field(description="Mean E / E* over its scenarios")
    pad_case: str = Field(description="good, bad or mixed (METHOD §5)")
    chosen_by_truth: str | None = Field(
        None,
        description="Why the choice by truth (--verify-top, the daemon's [verify] top_k) delivered another candidate "
        "or pad size than the measure's, when it did: quality and retained are then the delivered finger's, and its "
        "parts stay served (its finger is the best of those simulated); null: the measure's choice is delivered",
    )


class IdenticalPartsReport(ReportModel):
    """Parts with the same geometry (after units and shell union), designed once."""

    part: str = Field(description="The one designed (first in job order)")
    copies: list[str] = Field(description="Every part of the job with this geometry, itself included, job order")
    quantity: int = Field(description="Pieces to pick: build items over all the copies")


class PairConflictReport(ReportModel):
    """Two parts screened as one finger set."""

    parts: list[str] = Field(description="The two parts")
    retained: list[float] = Field(description="Worst screened E / E* of each when they share a finger")


class PartitionAttemptReport(ReportModel):
    """A partition judged exactly (METHOD §11 revision 3): what screening promised, what its sets keep exactly (the
    exact evaluation of each set's screened best candidate, or its sets' designs when designed).
    """

    sets: int = Field(description="Number of finger sets")
    parts: list[list[str]] = Field(description="Distinct parts of each set, sets numbered by their first part")
    screened_worst_retained: float | None = Field(
        description="Least screened E / E* over its graspable scenarios; null for one finger designed to compare and "
        "for losers moved to a set of their own (not screened as sets: their designs judge them)"
    )
    exact_worst_retained: float = Field(
        description="Least exact E / E*: of its sets' designs when designed, else of the exact evaluation of each "
        "set's screened best candidate"
    )
    source: Literal["search", "one_finger", "moved_losers", "moved_by_truth", "merged"] = Field(
        description="search: proposed by the partition search; one_finger: every part on one finger, designed to "
        "compare when min_retained was not reached; moved_losers: a designed partition that missed min_retained "
        "with sets left, its parts below min_retained moved to a set of their own; moved_by_truth: a delivered "
        "partition whose verified finger failed a scenario its part's own finger passed, that part moved to a set "
        "of its own; merged: with max = 'auto', the delivered partition with single-part sets merged into others "
        "where every part of the merged set keeps min_retained by its design"
    )
    designed: bool = Field(
        False,
        description="Its sets' candidates were designed by METHOD §6-8 (full search, exact re-evaluation): the best "
        "proposal, and one finger when that misses min_retained; only the delivered one's fingers are made (§9)",
    )
    chosen: bool = Field(description="The partition delivered (the best of the designed ones by the exact objective)")
    failure: str | None = Field(
        None, description="Why one of its fingers could not be made (it then keeps nothing and is not delivered)"
    )


class PartitionSearchReport(ReportModel):
    """How the parts were split into sets and what bounds the split."""

    method: Literal[
        "single_set",
        "single_part",
        "exhaustive",
        "quick_screening+colouring+local_moves",
        "carving_neighbours+colouring+local_moves",
    ] = Field(
        description="single_set: [finger_sets] max = 1; single_part: one distinct graspable part; "
        "exhaustive: every partition screened; quick_screening+colouring+local_moves: every pair quick-screened (one "
        "candidate each), the conflict clique certified by set searches, greedy sets improved by moving parts, set "
        "searches only where the quick figure falls short; carving_neighbours+colouring+local_moves: the same with "
        "only each part's nearest neighbours by what it carves, and the pairs of the most dissimilar parts, "
        "quick-screened (a sparse conflict graph)"
    )
    description: str = Field(description="The same in words, with what it proves")
    proven: bool = Field(
        description="The partition is the best under screening (every partition into at most max sets screened)"
    )
    fewest_sets_proven: bool = Field(
        False,
        description="The first proposal, under screening alone, reaches min_retained and no partition reaching it "
        "under screening has fewer sets: every partition was screened, or it has lower_bound_sets sets (if a part "
        "never keeps more of its quality in a larger set)",
    )
    sets_tried: list[int] = Field(description="Numbers of sets the search tried")
    set_screenings: int = Field(description="Distinct candidate sets screened")
    lower_bound_sets: int = Field(
        description="Largest group of pairwise conflicting parts: no partition reaching min_retained has fewer sets"
    )
    conflict_clique: list[str] = Field(description="That group of parts")
    worst_retained_bound: float | None = Field(
        description="When that group is larger than max, two of its parts share a set: no partition keeps a larger "
        "worst E / E* (screened)"
    )
    blocking_pairs: list[PairConflictReport] = Field(
        description="Pairs of parts that keep less than min_retained when they share a finger"
    )
    explanation: str | None = Field(description="Why min_retained is not reached, when it is not")
    attempts: list[PartitionAttemptReport] = Field(
        default_factory=list,
        description="Every partition designed exactly, in the order designed; the search saw each one's exact figures "
        "before proposing the next",
    )


class PickPart(ReportModel):
    """A part the cell picks with the mounted finger set."""

    part: str = Field(description="Part designed (its copies are listed in copies)")
    copies: list[str] = Field(description="Every job part with this geometry")
    quantity: int = Field(description="Pieces to pick")
    grasps: list[GraspReport] = Field(description="Grasp per stable pose the part may lie in")


class PickStep(ReportModel):
    """Mount one finger set, then pick its parts."""

    set: int
    finger: str = Field(description="The finger to mount: its STL, relative to the job's report")
    parts: list[PickPart]


class NotServedPart(ReportModel):
    """A part no finger set serves: the set that holds it best keeps less than ``min_retained`` of its solo quality,
    or its verified finger fails a scenario the part's own finger passes ([finger_sets] truth_budget_s). The pick
    plan sends it to the cell's fallback, never to that set's finger."""

    part: str = Field(description="Part designed (its copies are listed in copies)")
    copies: list[str] = Field(description="Every job part with this geometry")
    quantity: int = Field(description="Pieces to pick")
    best_set: int = Field(description="The finger set that holds it best (the one it was designed in)")
    retained: float = Field(description="Least E / E* over its scenarios in that set")
    reason: str = Field(description="Why no set serves it")
    fallback: Literal["flat_fingers", "manual"] = Field(
        description="Where the pick plan sends it ([finger_sets] unserved_fallback): the cell's flat fingers, or by "
        "hand"
    )


class VerifiedSetScenario(ReportModel):
    """One scenario of a finger set as simulated (METHOD §12): the set's finger against flat pads."""

    part: str
    pose_index: int
    trials: int = Field(description="Precision trials run with the set's finger")
    successes: int = Field(description="Of those, the successful ones")
    flat_trials: int = Field(description="Precision trials run with flat pads")
    flat_successes: int = Field(description="Of those, the successful ones")
    passed: bool = Field(description="The scenario passed ([verify] pass_success_rate, holding as flat pads)")
    solo_passed: bool | None = Field(
        None, description="Where the set's finger failed: whether the part's own finger passes it; null: not simulated"
    )


class VerifiedSet(ReportModel):
    """A delivered finger set's finger as simulated during the design."""

    set: int
    scenarios: list[VerifiedSetScenario]


class SetsTruthReport(ReportModel):
    """Sets judged by truth ([finger_sets] truth_budget_s): the delivered sets' fingers simulated, and what moved."""

    budget_s: float = Field(description="[finger_sets] truth_budget_s, s")
    spent_s: float = Field(description="Time spent, s: the simulations and the parts' own fingers designed for them")
    sets: list[VerifiedSet] = Field(description="Delivered sets verified within the budget, in set order")
    unverified_sets: list[int] = Field(description="Delivered sets left unverified when the budget ran out")
    moved_parts: list[str] = Field(description="Parts a shared finger failed where their own passed, given own sets")
    not_served_parts: list[str] = Field(description="Such parts left where no set was left for them: not_served")
    notes: list[str] = Field(default_factory=list, description="Fingers MuJoCo could not simulate, and why")


class FingerSetsReport(ReportModel):
    """The job's finger sets (METHOD §11) and the pick plan for the cell."""

    max_sets: int | Literal["auto"] = Field(description="[finger_sets] max")
    sets_allowed: int = Field(
        0, description="The most sets the job could use: max, or with 'auto' one per distinct graspable part"
    )
    sets_needed: int | None = Field(
        None,
        description="Sets this job needs so that every graspable part is served (min_retained reached): the sets "
        "delivered when they serve every part, null when they do not",
    )
    min_retained: float = Field(description="[finger_sets] min_retained")
    sets: list[FingerSetReport]
    scenarios: list[SetScenarioReport] = Field(
        description="Every scenario of every distinct part: those with samples in job order, then those without"
    )
    worst_retained: float | None = Field(description="Least E / E* over graspable scenarios")
    median_retained: float | None = Field(description="Median E / E* over graspable scenarios")
    min_retained_reached: bool = Field(description="Every graspable scenario keeps at least min_retained (exact)")
    identical_parts: list[IdenticalPartsReport] = Field(
        description="Groups of identical parts designed once (only groups of two or more)"
    )
    ungraspable_parts: list[str] = Field(description="Parts no set can grasp in any chosen pose: not in the pick plan")
    ungraspable: list[UngraspableReport] = Field(description="Every ungraspable scenario")
    pick_plan: list[PickStep] = Field(
        description="Finger sets in the order to mount them, each with the parts it serves (not_served parts are not "
        "in it)"
    )
    not_served: list[NotServedPart] = Field(
        default_factory=list,
        description="Parts whose best set keeps less than min_retained of their solo quality, job order: picked "
        "with the fallback named, not with a set's finger",
    )
    search: PartitionSearchReport
    truth: SetsTruthReport | None = Field(
        None, description="The delivered sets judged by simulation ([finger_sets] truth_budget_s > 0), else null"
    )
    pad_sizes: list[PadSizeReport] = Field(
        default_factory=list, description="Every pad size of [sampler], those screened out and which was delivered"
    )


class PadSizeReport(ReportModel):
    """One pad size of ``[sampler] length_mm`` x ``width_mm`` designed with (METHOD §3b)."""

    length_mm: float = Field(description="Pad length L, mm")
    width_mm: float = Field(description="Pad width W, mm")
    quality: float | None = Field(
        description="What chose among the sizes: the delivered design's quality (its worst scenario's measure), for "
        "finger sets the worst over the sets; null when no part could be grasped with this size or it was screened out"
    )
    flat_pads: bool = Field(False, description="Its design delivered flat pads (nothing beat flat): ranked last")
    chosen: bool = Field(
        description="The size delivered; with several finger sets, a size any set is delivered on (the choice by truth "
        "may deliver a set on another size)"
    )
    screened_out: bool = Field(False, description="Not designed in full: the sets' screen ruled it out (note says why)")
    note: str | None = Field(None, description="Why this size gave no design")


class DesignReport(ReportModel):
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
    timings_s: dict[str, float] = Field(
        description="Wall time per stage, s (the only field that varies between identical runs)"
    )
    warnings: list[str]
    settings: DesignConfig
    print_fit: PrintFitReport | None = Field(None, description="[print] as used and what clearance and lead-in changed")
    pad_sizes: list[PadSizeReport] = Field(
        default_factory=list,
        description="Every pad size designed with and which was delivered; settings holds the delivered size",
    )
    placement: dict | None = Field(
        None,
        description="Where the finger copies go in the job's build volume, added by fcsod (schema: "
        "schemas/placement-report.json)",
    )
    finger_sets: FingerSetsReport | None = Field(
        None,
        description="The job's finger sets and pick plan when it ran with [finger_sets] max > 1 and one set serves it "
        "(METHOD §11)",
    )


class JobReport(ReportModel):
    """``report.json`` of a job served by two or more finger sets."""

    fcso_version: str
    parts: list[PartReport]
    finger_sets: FingerSetsReport
    timings_s: dict[str, float] = Field(description="Wall time per stage, s")
    warnings: list[str]
    settings: DesignConfig
    placement: dict | None = Field(
        None,
        description="Where every set's finger copies go in the job's build volume, added by fcsod (schema: "
        "schemas/placement-report.json)",
    )
