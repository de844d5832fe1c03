"""A design's report assembled from its results: the entries of ``report.json`` (:class:`DesignReport`)."""

from __future__ import annotations

import numpy as np

from ..config import DesignConfig
from ..evaluate import CandidateEvaluation, Scenario, ScenarioEvaluation, VersusFlat
from ..grasps import tcp_pose
from ..parts import Part
from ..report.models import (
    CandidateReport,
    CaptureLandscapeReport,
    GraspReport,
    PartReport,
    PrintFitEffect,
    PrintFitReport,
    RepairReport,
    SampleReport,
    ScenarioQuality,
    ScenarioReport,
    UngraspableReport,
)
from ..screen import ScreenedCandidate

#: One sentence per rejection reason, for a scenario that reason emptied.
_REJECTION_SENTENCES = {
    "contact": "no pad box holds the least contact area ({area:g} mm² per side) on both sides",
    "fit": "wherever the pads meet it, the part is too wide for the open gripper ({opening:g} mm) or too narrow to "
    "close on",
    "collision_pads": "the two pads would meet beside a part thinner than twice their penetration",
    "collision_finger": "the finger plate behind every pad would hit the part",
    "collision_descent": "the open fingers would hit the part on their way down",
}


def ungraspable_report(scenario: Scenario, config: DesignConfig) -> UngraspableReport:
    result = scenario.sampler_result
    if result.tried == 0:
        reason = "no pad footprint meets the part above the table clearance"
    else:
        worst = max(result.rejected, key=lambda k: result.rejected[k])
        reason = _REJECTION_SENTENCES[worst].format(
            area=config.sampler.min_contact_area, opening=config.gripper.max_opening_mm
        )
        reason = f"{reason} ({result.rejected[worst]} of {result.tried} samples)"
    return ungraspable_entry(scenario, reason)


def ungraspable_entry(scenario: Scenario, reason: str) -> UngraspableReport:
    """A scenario left out of the design, with its sampler's counts and ``reason`` (one sentence)."""
    result = scenario.sampler_result
    return UngraspableReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        pose_probability=round(float(scenario.probability), 6),
        tried_samples=result.tried,
        rejected=dict(result.rejected),
        reason=reason,
    )


def rounded(value: float) -> float:
    """``value`` as the reports give numbers: a float to 6 decimals."""
    return round(float(value), 6)


def print_fit_report(
    config: DesignConfig, exact: CandidateEvaluation, fitted: CandidateEvaluation, thinnest_wall_mm: float
) -> PrintFitReport:
    """``[print]`` as used, the chosen pad's thinnest wall, and the chosen candidate exact (METHOD §4-6) and as printed.

    Parameters
    ----------
    config : DesignConfig
    exact, fitted : CandidateEvaluation
        The chosen candidate with its exact pocket and as carved for printing, both with their pads.
    thinnest_wall_mm : float
        The fitted pad's thinnest wall, mm (inf for an empty pad).
    """
    fit = config.print.resolved()
    sampler = config.sampler
    box_volume = sampler.thickness_mm * sampler.length_mm * sampler.width_mm

    def effect(evaluation: CandidateEvaluation) -> PrintFitEffect:
        return PrintFitEffect(
            pocket_volume_mm3=rounded(box_volume - evaluation.fingerpad.pad.volume()),
            contact_area_mm2=[rounded(e.contact_area_mm2) for e in evaluation.scenarios],
            effective_area=[rounded(e.effective_area) for e in evaluation.scenarios],
            seat_offsets_mm=[[rounded(c.offset_mm) for c in e.contacts] for e in evaluation.scenarios],
            quality=rounded(evaluation.quality),
        )

    return PrintFitReport(
        profile=config.print.profile,
        **{k: rounded(v) for k, v in fit.items()},
        thinnest_wall_mm=rounded(thinnest_wall_mm) if np.isfinite(thinnest_wall_mm) else None,
        exact=effect(exact),
        fitted=effect(fitted),
    )


def part_report(part: Part) -> PartReport:
    return PartReport(
        name=part.name,
        file=part.path,
        scale_to_mm=rounded(part.scale),
        extents_mm=[rounded(x) for x in part.mesh.extents],
        volume_mm3=rounded(part.mesh.volume),
        faces=len(part.mesh.faces),
        repairs=part.repairs,
        repair=repair_report(part),
        shells=part.shells,
        solid_index=part.solid_index,
        shell_handling=part.shell_note,
    )


def repair_report(part: Part) -> RepairReport | None:
    """The part's repair in mm, or None when it was loaded without repair."""
    summary = part.repair
    if summary is None:
        return None
    return RepairReport(
        holes_filled=summary.holes_filled,
        faces_added=summary.faces_added,
        faces_flipped=summary.faces_flipped,
        faces_removed=summary.degenerate_removed + summary.duplicates_removed,
        shells_inverted=summary.shells_inverted,
        shells_in=summary.shells_in,
        shells_dropped=summary.shells_dropped,
        solids_out=summary.solids_out,
        volume_before_mm3=rounded(summary.volume_before * part.scale**3),
        volume_after_mm3=rounded(summary.volume_after * part.scale**3),
        volume_change_percent=rounded(summary.volume_change_percent),
        max_surface_deviation_mm=rounded(summary.max_deviation * part.scale),
    )


def scenario_report(scenario: Scenario, versus: VersusFlat | None) -> ScenarioReport:
    """A scenario's entry, with the chosen pad's capture against flat pads' (:func:`fcso.evaluate.versus_flat`)."""
    result = scenario.sampler_result
    return ScenarioReport(
        capture=None if versus is None else rounded(versus.capture.fraction),
        flat_capture=None if versus is None else rounded(versus.flat.fraction),
        beats_flat=True if versus is None else versus.beats_flat,
        capture_landscape=None if versus is None else capture_landscape_report(versus),
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        pose_probability=rounded(scenario.probability),
        rest_transform=[[rounded(x) for x in row] for row in scenario.rest_transform],
        tried_samples=result.tried,
        valid_samples=len(result.samples),
        rejected=dict(result.rejected),
        samples=[
            SampleReport(
                yaw_deg=g.sample.yaw_deg,
                s_mm=rounded(g.sample.s_mm),
                h_mm=rounded(g.sample.h_mm),
                a_max_mm=rounded(g.sample.a_max_mm),
                a_min_mm=rounded(g.sample.a_min_mm),
                surface_area_mm2=[rounded(g.sample.area_plus_mm2), rounded(g.sample.area_minus_mm2)],
                labels=["good" if p.good else "bad" for p in g.geometries],
                ratio=[rounded(p.ratio) for p in g.geometries],
                depth_mm=[rounded(p.depth_mm) for p in g.geometries],
                effective_area_bound=rounded(g.effective_area_bound),
                on_feature=g.sample.on_feature,
            )
            for g in scenario.samples
        ],
    )


def capture_landscape_report(versus: VersusFlat) -> CaptureLandscapeReport:
    """The chosen pad's landscape of one scenario as the report keeps it."""
    landscape = versus.capture
    box = landscape.in_box
    return CaptureLandscapeReport(
        offsets_mm=[rounded(x) for x in landscape.offsets_mm],
        yaws_deg=[rounded(x) for x in landscape.yaws_deg],
        separation_mm=[[rounded(x) if np.isfinite(x) else None for x in row] for row in landscape.separation_mm],
        captured=landscape.captured.tolist(),
        flat_captured=versus.flat.captured.tolist(),
        position_error_mm=rounded(np.abs(landscape.offsets_mm[box.any(axis=1)]).max()),
        yaw_error_deg=rounded(np.abs(landscape.yaws_deg[box.any(axis=0)]).max()),
    )


def candidate_reports(choices, exact: dict, screened: dict, indices: dict) -> list[CandidateReport]:
    """Report entries, by index: exact numbers for re-evaluated candidates, screened ones (``screened[choice]``) for the
    rest.
    """
    entries = []
    for choice in sorted(choices, key=lambda c: indices[c]):
        if choice in exact:
            entries.append(_candidate_report(exact[choice], indices[choice]))
        else:
            entries.append(_screened_report(choice, screened[choice], indices[choice]))
    for choice, evaluation in exact.items():
        if choice not in choices:
            entries.append(_candidate_report(evaluation, indices[choice]))
    return sorted(entries, key=lambda e: e.index)


def _candidate_report(evaluation: CandidateEvaluation, index: int) -> CandidateReport:
    return _candidate_entry(
        evaluation.choice,
        index,
        "exact",
        [
            (
                e.rles,
                e.contact_area_mm2,
                e.effective_area,
                [c.offset_mm for c in e.contacts],
                e.capture.fraction if e.capture else None,
                e.holding_n,
                e.measure,
            )
            for e in evaluation.scenarios
        ],
        evaluation.quality,
        evaluation.mean_effective_area,
        evaluation.case,
        evaluation.block_depth_mm,
    )


def _screened_report(choice: tuple[int, ...], screened: ScreenedCandidate, index: int) -> CandidateReport:
    return _candidate_entry(
        choice,
        index,
        "screened",
        [
            (e.rles, e.contact_area_mm2, e.effective_area, list(e.seat_offsets_mm), e.capture, None, e.measure)
            for e in screened.scenarios
        ],
        screened.quality,
        screened.mean_effective_area,
        screened.case,
        None,
    )


def _candidate_entry(choice, index, evaluation, per_scenario, quality, mean, case, block_depth) -> CandidateReport:
    """A report entry; ``per_scenario`` holds (RLES, A, E, seat offsets, capture, holding, measure) per scenario."""
    return CandidateReport(
        index=index,
        samples=list(choice),
        evaluation=evaluation,
        per_scenario=[
            ScenarioQuality(
                rles=rounded(radius),
                contact_area_mm2=rounded(area),
                effective_area=rounded(effective),
                seat_offsets_mm=[rounded(t) for t in offsets],
                capture=None if capture is None else rounded(capture),
                holding_n=None if holding is None else [rounded(f) for f in holding],
                measure=rounded(measure),
            )
            for radius, area, effective, offsets, capture, holding, measure in per_scenario
        ],
        quality=rounded(quality),
        mean_effective_area=rounded(mean),
        pad_case=case,
        block_depth_mm=None if block_depth is None else rounded(block_depth),
    )


def grasp_report(
    scenario: Scenario, sample_index: int, evaluation: ScenarioEvaluation, config: DesignConfig
) -> GraspReport:
    pose = tcp_pose(
        scenario.samples[sample_index].sample,
        evaluation.contacts[0].offset_mm,
        evaluation.contacts[1].offset_mm,
        config.sampler,
    )
    return GraspReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        sample=sample_index,
        rest_transform=[[rounded(x) for x in row] for row in scenario.rest_transform],
        position_mm=[rounded(x) for x in pose["position_mm"]],
        quaternion_wxyz=[rounded(x) for x in pose["quaternion_wxyz"]],
        approach_direction=pose["approach_direction"],
        closing_axis=[rounded(x) for x in pose["closing_axis"]],
        pad_gap_mm=rounded(pose["pad_gap_mm"]),
        closing_width_mm=rounded(pose["closing_width_mm"]),
    )
