"""Choose by truth, not only by Q: verify the K best candidates and keep the best that passes (``--verify-top K``)."""

from __future__ import annotations

from ..design import DesignResult, finish_candidate
from ..evaluate import CandidateEvaluation
from ..finger import fuse
from ..geometry import to_trimesh
from ..progress import Progress
from ..report.models import CandidateReport, DesignReport, FingerReport, GraspReport, PrintFitReport, ranked_candidates
from .config import VerifyConfig
from .report import RankedCandidate, VerificationReport
from .verify import DesignUnderTest, design_under_test, finger_hull, grasp_case, verify


def candidate_design(
    result: DesignResult, candidate: CandidateReport
) -> tuple[DesignUnderTest, CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """The simulation's inputs for any evaluated candidate of a design, built as the design builds its choice.

    The pad is carved with the design's ``[print]`` clearance and lead-in
    (:func:`fcso.design.finish_candidate`), so the verified pad is the one
    that would be printed.

    Returns
    -------
    design : DesignUnderTest
    evaluation : CandidateEvaluation
        The candidate as printed, with its pad and contacts.
    grasps : list of GraspReport
        Its grasps, as ``report.json`` would list them.
    print_fit : PrintFitReport
    warnings : list of str
        The print fit's warnings.
    """
    evaluation, grasps, print_fit, warnings = finish_candidate(
        result.scenarios, candidate.samples, result.report.settings
    )
    parts = {scenario.part.name: scenario.part.mesh for scenario in result.scenarios}
    report = result.report.model_copy(update={"grasps": grasps})
    cases = [grasp_case(report, g, parts[g.part]) for g in grasps]
    design = DesignUnderTest(cases, to_trimesh(evaluation.fingerpad.pad), finger_hull(result.report, result.finger))
    return design, evaluation, grasps, print_fit, warnings


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
        # the design's own choice is already built as printed
        built = (
            (design_under_test(result), result.best, result.report.grasps, result.report.print_fit, [])
            if candidate.index == result.report.best
            else candidate_design(result, candidate)
        )
        verification = verify(built[0], config, progress)
        outcomes.append((rank, candidate, built, verification))
    passing = [o for o in outcomes if o[3].passed]
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
        for rank, candidate, _, verification in outcomes
    ]
    rank, candidate, built, verification = chosen
    design = built[0]
    if candidate.index != result.report.best:
        why = (
            f"verification chose candidate {candidate.index} (rank {rank + 1} by Q, Q = {candidate.quality:.1f}) over "
            f"candidate {result.report.best}: it is the best by Q whose every scenario reached the success threshold"
        )
        result = _with_candidate(result, candidate, *built[1:], why)
    elif not passing:
        verification.warnings.append(
            f"none of the {len(outcomes)} best candidates by Q passed verification; kept the best by Q"
        )
    verification = verification.model_copy(update={"ranking": ranking})
    return result, verification, design, ranking


def _with_candidate(
    result: DesignResult,
    candidate: CandidateReport,
    evaluation: CandidateEvaluation,
    grasps,
    print_fit,
    fit_warnings,
    why: str,
) -> DesignResult:
    """The design result with another candidate chosen: its printed pad fused onto the finger, its grasps and print fit
    in the report.
    """
    config = result.report.settings
    fused = fuse(result.flat_finger, evaluation.fingerpad.pad, config.sampler, config.finger.overlap_mm)
    report: DesignReport = result.report.model_copy(
        update={
            "best": candidate.index,
            "grasps": grasps,
            "print_fit": print_fit,
            "finger": FingerReport(
                source=result.report.finger.source,
                repairs=result.report.finger.repairs,
                volume_mm3=round(float(fused.volume_mm3), 6),
                bodies=fused.bodies,
                watertight=bool(fused.mesh.is_watertight),
                min_pad_thickness_mm=round(float(fused.min_pad_thickness_mm), 6),
            ),
            "warnings": result.report.warnings + fit_warnings + [why],
        }
    )
    return DesignResult(
        report=report,
        finger=fused.mesh,
        fingerpad=to_trimesh(evaluation.fingerpad.pad),
        scenarios=result.scenarios,
        best=evaluation,
        flat_finger=result.flat_finger,
        pad_to_finger=result.pad_to_finger,
    )
