"""Choose by truth, not only by Q: verify the K best candidates and keep the best that passes (``--verify-top K``)."""

from __future__ import annotations

from ..design import DesignResult
from ..finger import fuse
from ..geometry import to_trimesh
from ..grasps import tcp_pose
from ..pad import build_fingerpad
from ..report import CandidateReport, DesignReport, FingerReport, GraspReport
from ..table import ranked_candidates
from .config import VerifyConfig
from .report import RankedCandidate, VerificationReport
from .verify import DesignUnderTest, Progress, finger_hull, grasp_case, verify


def candidate_design(result: DesignResult, candidate: CandidateReport) -> tuple[DesignUnderTest, list[GraspReport], object]:
    """The simulation's inputs for any evaluated candidate of a design.

    Returns
    -------
    design : DesignUnderTest
    grasps : list of GraspReport
        The candidate's grasps, as ``report.json`` would list them.
    fingerpad : fcso.pad.Fingerpad
        The carved pad (manifold) of the candidate.
    """
    config = result.report.settings
    chosen = [scenario.samples[k] for scenario, k in zip(result.scenarios, candidate.samples)]
    fingerpad = build_fingerpad([g for sample in chosen for g in sample.geometries], config.sampler, config.filter)
    grasps = []
    for scenario, reported, k, sample, quality in zip(
        result.scenarios, result.report.scenarios, candidate.samples, chosen, candidate.per_scenario
    ):
        pose = tcp_pose(sample.sample, quality.seat_offsets_mm[0], quality.seat_offsets_mm[1], config.sampler)
        grasps.append(
            GraspReport(
                part=scenario.part.name,
                pose_index=scenario.pose_index,
                sample=k,
                rest_transform=reported.rest_transform,
                position_mm=pose["position_mm"],
                quaternion_wxyz=pose["quaternion_wxyz"],
                approach_direction=pose["approach_direction"],
                closing_axis=pose["closing_axis"],
                pad_gap_mm=pose["pad_gap_mm"],
                closing_width_mm=pose["closing_width_mm"],
            )
        )
    parts = {scenario.part.name: scenario.part.mesh for scenario in result.scenarios}
    report = result.report.model_copy(update={"grasps": grasps})
    cases = [grasp_case(report, g, parts[g.part]) for g in grasps]
    return DesignUnderTest(cases, to_trimesh(fingerpad.pad), finger_hull(result.report, result.finger)), grasps, fingerpad


def verify_top(
    result: DesignResult, top: int, config: VerifyConfig, progress: Progress | None = None
) -> tuple[DesignResult, VerificationReport, DesignUnderTest, list[RankedCandidate]]:
    """Verify the ``top`` best candidates by Q and choose the best Q among those whose every scenario passes.

    When none passes, the design's own choice (best Q) stays.

    Returns
    -------
    result : DesignResult
        The design with the chosen candidate (the input itself when it stays).
    verification : VerificationReport
        The chosen candidate's verification.
    design : DesignUnderTest
        Its simulation inputs (for the report's pictures).
    ranking : list of RankedCandidate
        The verified candidates in Q order with their outcome.
    """
    ranked = ranked_candidates(result.report, top)
    outcomes = []
    for rank, candidate in enumerate(ranked):
        design, grasps, fingerpad = candidate_design(result, candidate)
        verification = verify(design, config, progress)
        outcomes.append((rank, candidate, design, grasps, fingerpad, verification))
    passing = [o for o in outcomes if o[5].passed]
    chosen = passing[0] if passing else outcomes[0]
    ranking = [
        RankedCandidate(
            rank_by_quality=rank + 1,
            index=candidate.index,
            quality=candidate.quality,
            success_rates=[s.fcso.success_rate for s in verification.scenarios],
            flat_success_rates=[s.flat.success_rate for s in verification.scenarios],
            passed=verification.passed,
            chosen=candidate.index == chosen[1].index,
        )
        for rank, candidate, _, _, _, verification in outcomes
    ]
    rank, candidate, design, grasps, fingerpad, verification = chosen
    if candidate.index != result.report.best:
        why = (
            f"verification chose candidate {candidate.index} (rank {rank + 1} by Q, Q = {candidate.quality:.1f}) over "
            f"candidate {result.report.best}: it is the best by Q whose every scenario reached the success threshold"
        )
        result = _with_candidate(result, candidate, grasps, fingerpad, why)
    elif not passing:
        verification.warnings.append(f"none of the {len(outcomes)} best candidates by Q passed verification; kept the best by Q")
    verification = verification.model_copy(update={"ranking": ranking})
    return result, verification, design, ranking


def _with_candidate(result: DesignResult, candidate: CandidateReport, grasps, fingerpad, why: str) -> DesignResult:
    """The design result with another candidate chosen: its pad fused onto the finger, its grasps in the report."""
    config = result.report.settings
    fused = fuse(result.flat_finger, fingerpad.pad, config.sampler, config.finger.overlap_mm)
    report: DesignReport = result.report.model_copy(
        update={
            "best": candidate.index,
            "grasps": grasps,
            "finger": FingerReport(
                source=result.report.finger.source,
                repairs=result.report.finger.repairs,
                volume_mm3=round(float(fused.volume_mm3), 6),
                bodies=fused.bodies,
                watertight=bool(fused.mesh.is_watertight),
                min_pad_thickness_mm=round(float(fused.min_pad_thickness_mm), 6),
            ),
            "warnings": result.report.warnings + [why],
        }
    )
    return DesignResult(
        report=report,
        finger=fused.mesh,
        fingerpad=to_trimesh(fingerpad.pad),
        scenarios=result.scenarios,
        best=result.best,
        flat_finger=result.flat_finger,
        pad_to_finger=result.pad_to_finger,
    )


CHOSEN = ' class="chosen"'


def ranking_html(ranking: list[RankedCandidate]) -> str:
    """The ranking before (by Q) and after verification, and why, as an HTML fragment."""
    if not ranking:
        return ""
    rows = "".join(
        f"<tr{CHOSEN if r.chosen else ''}><td>{r.rank_by_quality}</td><td>{r.index}</td><td>{r.quality:.1f}</td>"
        f"<td>{' / '.join(f'{x:.0%}' for x in r.success_rates)}</td><td>{' / '.join(f'{x:.0%}' for x in r.flat_success_rates)}</td>"
        f"<td>{'yes' if r.passed else 'no'}</td><td>{'&#9733;' if r.chosen else ''}</td></tr>"
        for r in ranking
    )
    return (
        "<h3>Choice by verification (--verify-top)</h3>"
        "<p>The best candidates by Q, in Q order, each verified; the chosen one is the best by Q whose every scenario "
        "reached the success threshold (or the best by Q when none did).</p>"
        "<table><tr><th>rank by Q</th><th>candidate</th><th>Q</th><th>designed success per scenario</th>"
        "<th>flat success</th><th>passed</th><th>chosen</th></tr>" + rows + "</table>"
    )

