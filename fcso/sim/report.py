"""``verification.json``: pydantic models of the simulated grasp tests (METHOD §12)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from .config import VerifyConfig


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class TrialResult(_Model):
    """One precision trial."""

    dx_mm: float = Field(description="Start error along the table's x axis, mm")
    dy_mm: float = Field(description="Start error along the table's y axis, mm")
    yaw_deg: float = Field(description="Start error about the vertical, degrees")
    held: bool = Field(description="The part rose with the gripper")
    error_mm: float = Field(
        description="Centre-of-mass distance from the nominal seated pose in the gripper after the lift, mm"
    )
    error_deg: float = Field(description="Rotation from the nominal seated pose in the gripper after the lift, degrees")
    success: bool = Field(description="Held, and within success_mm and success_deg")


class PoseSnapshot(_Model):
    """Where things are at one instant of a simulated trial."""

    time_s: float
    part_pose: list[list[float]] = Field(description="4x4, part resting frame to world (table frame), mm")
    gripper_pose: list[list[float]] = Field(description="4x4, TCP frame to world, mm")
    opening_mm: float = Field(description="Finger joint q (0 = the design's seated pad, > 0 open), mm")


class FingerResult(_Model):
    """The tests of one finger (the designed one or the flat control) on one scenario."""

    kind: str = Field(description="fcso (the designed pad) or flat (plain pad of thickness T - D)")
    nominal_held: bool = Field(description="The unperturbed grasp held the part after the lift")
    nominal_offset_mm: float = Field(
        description="Simulated seated pose of the unperturbed grasp against the design's nominal one (centre of "
        "mass), mm"
    )
    nominal_offset_deg: float = Field(description="The same rotation, degrees")
    trials: list[TrialResult]
    success_rate: float = Field(description="Share of successful trials, 0..1")
    median_error_mm: float | None = Field(description="Median final position error over the trials, mm")
    worst_error_mm: float | None
    median_error_deg: float | None
    worst_error_deg: float | None
    holding_n: dict[str, float | None] = Field(
        description="Push direction in the gripper frame (+x: along the pads, +y: closing axis, +z: approach, down) -> "
        "force at which the part slipped, N; null: held at hold_force_n; 0: not held at all; empty: not tested (the "
        "precision trials had already failed, stop_early)"
    )
    trial_start: PoseSnapshot | None = Field(None, description="First perturbed trial, at the start (for the picture)")
    trial_end: PoseSnapshot | None = Field(None, description="First perturbed trial, after the lift")


class Fidelity(_Model):
    """How exact the collision geometry is (METHOD §12)."""

    part_pieces: int = Field(description="Convex pieces of the part")
    part_volume_error: float | None = Field(
        description="Volume of the union of the part's pieces outside the part / part volume: where the pads reach, "
        "none (the pieces are prisms under its surface); elsewhere the hulls by cells bridge the part's concavities. "
        "Null: not measured (a precision-only run of the choice by truth, whose candidate failed its trials)"
    )
    part_missing_fraction: float | None = Field(
        description="Share of the part's volume outside every piece: the material under the shell of prisms where "
        "the pads reach; null: not measured, as part_volume_error"
    )
    pad_pieces: int = Field(description="Convex pieces of the fingerpad")
    pad_volume_error: float | None = Field(
        description="(union of the pad's pieces - fingerpad volume) / fingerpad volume; null: not measured, as "
        "part_volume_error"
    )
    seated_penetration_mm: float = Field(
        description="Deepest overlap of the part's pieces and the pads, part at its nominal seated grasp, mm"
    )
    seated_pads_overlap_mm: float = Field(
        0.0,
        description="Deepest overlap of the two pads with each other at the nominal seated grasp (the fingers meet "
        "before the part is seated), mm",
    )
    decomposition_cached: bool = Field(description="The part's collision pieces came from the cache")


class ScenarioVerification(_Model):
    """Both fingers' tests on one part in one pose."""

    part: str
    pose_index: int
    fidelity: Fidelity
    fcso: FingerResult
    flat: FingerResult
    holds_as_flat: bool | None = Field(
        description="Pushed in every direction, the designed finger holds at least the flat pads' force, within "
        "hold_tolerance_n; null: not tested (the precision trials had already failed, stop_early)"
    )
    stopped_after_trials: int | None = Field(
        None,
        description="The designed finger's precision trials stopped after this many: it could no longer reach "
        "pass_success_rate (stop_early); the flat control ran none (with reuse_simulations, whose designed trials run "
        "first), else as many; null: every trial ran",
    )
    passed: bool = Field(
        description="The designed finger's success rate reaches pass_success_rate, it holds as well as flat pads, and "
        "its unperturbed grasp holds the part at its designed seat (METHOD §5b)"
    )
    frames: list[PoseSnapshot] = Field(
        description="The designed finger's unperturbed grasp, 20 frames per second (MCAP scene)"
    )
    reused_simulations: int = Field(
        0,
        description="Grasps and holding pushes of this scenario whose outcome was read from the cache: simulated "
        "before with the same geometry, start, settings and code (reuse_simulations)",
    )
    failure_reason: str | None = Field(
        None,
        description="Why the scenario could not be simulated and failed (MuJoCo ran out of its arena, arena_mb, "
        "after its retry); null: it was simulated",
    )


class RankedCandidate(_Model):
    """A candidate verified by ``--verify-top`` (candidates are verified in the order of the design's measure)."""

    rank_by_quality: int = Field(description="1 = best by the design's measure (METHOD §7b; Q under the paper's)")
    index: int = Field(description="Candidate index (report.json candidates)")
    quality: float = Field(description="The design's measure of the candidate (Q under the paper's measure), mm²")
    success_rates: list[float] = Field(description="Designed finger's success rate per verified scenario")
    flat_success_rates: list[float | None] = Field(
        description="Flat control's success rate per verified scenario; null where it ran no trial: the control's "
        "trials run once the designed finger has passed every scenario's (stop_early), and the delivered candidate's "
        "always"
    )
    trials_run: list[int] = Field(
        default_factory=list,
        description="Precision trials run per verified scenario (fewer than the settings' trials: stopped once the "
        "candidate could no longer pass; scenarios after a failed one are not verified, stop_early)",
    )
    passed: bool
    chosen: bool


class VerificationReport(_Model):
    """Everything ``fcso verify`` measured (``verification.json``)."""

    fcso_version: str
    mujoco_version: str
    settings: VerifyConfig
    scenarios: list[ScenarioVerification]
    passed: bool = Field(description="Every scenario passed")
    unverified_scenarios: list[str] = Field(
        default_factory=list,
        description="Scenarios not verified because an earlier one had failed, so the design could not pass "
        "(stop_early)",
    )
    unseated_scenarios: list[str] = Field(
        default_factory=list,
        description="Scenarios whose designed finger's unperturbed grasp drops the part or holds it off its designed "
        "seat by more than success_mm or success_deg where the flat control's holds it there (METHOD §5b, never worse "
        "than flat): they fail; choosing among candidates "
        "(stop_early), every scenario's is checked before any trial and the first such one stops the verification",
    )
    warnings: list[str]
    timings_s: dict[str, float] = Field(description="Wall time per stage, s")
    ranking: list[RankedCandidate] | None = Field(
        None, description="--verify-top: the verified candidates in the measure's order and which was chosen"
    )
    choice: str | None = Field(None, description="--verify-top: which candidate was delivered and why")


def reused_note(verification: VerificationReport) -> str:
    """How many simulations were read from the cache, or "" when none were."""
    reused = sum(s.reused_simulations for s in verification.scenarios)
    if not reused:
        return ""
    return (
        f"{reused} grasps and holding pushes were read from the cache: simulated before with the same geometry, "
        "start, settings and code (--simulate-again runs them again)"
    )


def weakest_hold_n(finger: FingerResult, hold_force_n: float) -> float | None:
    """The smallest push at which the finger let its part slip, over the six directions, N: ``hold_force_n`` when it
    held every push, 0 when it did not hold the part at all; None when the holding test did not run."""
    if not finger.holding_n:
        return None
    return min(hold_force_n if force is None else force for force in finger.holding_n.values())


def scenario_verdict(scenario: ScenarioVerification, settings: VerifyConfig) -> str:
    """One scenario's figures as METHOD §12b words them: "designed 9/10, flat 1/10, holds 30 N"."""
    planned = max(settings.trials, len(scenario.fcso.trials))
    designed = sum(t.success for t in scenario.fcso.trials)
    flat = sum(t.success for t in scenario.flat.trials)
    weakest = weakest_hold_n(scenario.fcso, settings.hold_force_n)
    if weakest is None:
        hold = "holding not tested"
    elif weakest <= 0.0:
        hold = "does not hold the part"
    elif weakest >= settings.hold_force_n:
        hold = f"holds {weakest:g} N"
    else:
        hold = f"weakest hold {weakest:.1f} N"
    ran = len(scenario.fcso.trials)
    stopped = f" ({ran} of {planned} run)" if ran < planned else ""
    return f"designed {designed}/{planned}, flat {flat}/{planned}{stopped}, {hold}"


def verdict_text(verification: VerificationReport) -> str:
    """The verification's verdict, what every report and message leads with (METHOD §12b): whether it passed, then
    each scenario's figures, e.g. "verified: cube pose 0 designed 10/10, flat 1/10, holds 30 N"."""
    head = "verified" if verification.passed else "not verified"
    figures = [
        f"{s.part} pose {s.pose_index} {scenario_verdict(s, verification.settings)}" for s in verification.scenarios
    ]
    figures += [f"{name} not simulated" for name in verification.unverified_scenarios]
    if better_than_flat(verification) and not verification.passed:
        head += ", better than flat pads"
    if not_held(verification):
        head += ", NOT HELD in " + ", ".join(not_held(verification))
    if verification.unseated_scenarios:
        head += ", OFF ITS SEAT in " + ", ".join(verification.unseated_scenarios)
    return f"{head}: " + "; ".join(figures or ["no scenario"])


def better_than_flat(verification: VerificationReport) -> bool:
    """The designed finger does at least as well as flat pads in every scenario and better in one: no fewer successful
    precision trials and holding as well (``holds_as_flat``), and more successful trials somewhere; a verification
    that passed is better than flat (or as good, where flat pads pass too)."""
    if verification.passed:
        return True
    if verification.unverified_scenarios or not verification.scenarios:
        return False
    counts = _success_counts(verification)
    holds = all(s.holds_as_flat is not False for s in verification.scenarios)
    return holds and all(mine >= theirs for mine, theirs in counts) and any(mine > theirs for mine, theirs in counts)


def flat_beats(verification: VerificationReport) -> bool:
    """The flat control does better than a designed finger that did not pass: at least as many successful precision
    trials in every scenario, and more somewhere or a firmer hold somewhere (``holds_as_flat`` False). False for a
    verification that passed or that left a scenario unsimulated: no evidence against the design."""
    if verification.passed or verification.unverified_scenarios or not verification.scenarios:
        return False
    counts = _success_counts(verification)
    weaker = any(s.holds_as_flat is False for s in verification.scenarios)
    return all(theirs >= mine for mine, theirs in counts) and (weaker or any(theirs > mine for mine, theirs in counts))


def successes(trials: list[TrialResult]) -> int:
    """Successful trials."""
    return sum(t.success for t in trials)


def _success_counts(verification: VerificationReport) -> list[tuple[int, int]]:
    """Per scenario, the designed and the flat pads' successful precision trials."""
    return [(successes(s.fcso.trials), successes(s.flat.trials)) for s in verification.scenarios]


def not_held(verification: VerificationReport) -> list[str]:
    """Scenarios whose designed grasp does not hold its part at all (0 N in every push direction): a finger near zero
    quality, flagged wherever the verdict is shown."""
    return [
        f"{s.part} pose {s.pose_index}"
        for s in verification.scenarios
        if s.fcso.holding_n and all(force is not None and force <= 0.0 for force in s.fcso.holding_n.values())
    ]
