"""Choose by truth: verify candidates in the measure's order and deliver the first that passes (``--verify-top K``)."""

from __future__ import annotations

import dataclasses
import time

from ..errors import UnwritableSolidError
from ..evaluate import CandidateEvaluation
from ..finger import FusedFinger, fuse
from ..geometry import to_trimesh
from ..parallel import resolve_jobs
from ..pipeline import DesignResult, finish_candidates
from ..progress import Progress
from ..report.models import CandidateReport, DesignReport, FingerReport, GraspReport, PrintFitReport
from ..report.ranking import ranked_candidates
from .config import VerifyConfig
from .report import RankedCandidate, VerificationReport, flat_beats, successes, verdict_text
from .verify import DesignUnderTest, design_under_test, finger_hull, grasp_case, verify, verify_delivered


def candidate_designs(
    result: DesignResult, candidates: list[CandidateReport], jobs: int = 1, flat: bool = False
) -> list[tuple[DesignUnderTest, CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]]:
    """The simulation's inputs for evaluated candidates of a design, built as the design builds its choice.

    Each pad is carved with the design's ``[print]`` clearance and lead-in
    (:func:`fcso.pipeline.finish_candidates`), so the verified pad is the one
    that would be printed; the candidates' pads are made side by side on
    ``jobs`` workers (0: every available core). ``flat`` builds flat pads on
    the candidates' grasps instead.

    Parameters
    ----------
    result : DesignResult
    candidates : list of CandidateReport
        A pad that several of them carve is made once.
    jobs : int
    flat : bool

    Returns
    -------
    list of (design, evaluation, grasps, print_fit, warnings)
        Per candidate: its :class:`DesignUnderTest`; the candidate as printed, with its pad and contacts
        (:class:`CandidateEvaluation`); its grasps as ``report.json`` would list them; its print fit and that fit's
        warnings.
    """
    finished = finish_candidates(
        [(result.scenarios, tuple(c.samples)) for c in candidates],
        result.report.settings,
        flat=flat,
        jobs=resolve_jobs(jobs),
    )
    parts = {scenario.part.name: scenario.part.mesh for scenario in result.scenarios}
    built = []
    for evaluation, grasps, print_fit, warnings in finished:
        report = result.report.model_copy(update={"grasps": grasps})
        cases = [grasp_case(report, g, parts[g.part]) for g in grasps]
        design = DesignUnderTest(cases, to_trimesh(evaluation.fingerpad.pad), finger_hull(result.report, result.finger))
        built.append((design, evaluation, grasps, print_fit, warnings))
    return built


def verify_top(
    result: DesignResult,
    top: int,
    config: VerifyConfig,
    progress: Progress | None = None,
) -> tuple[DesignResult, VerificationReport, DesignUnderTest, list[RankedCandidate]]:
    """Verify candidates in the order of the design's measure (METHOD §7b) and deliver the first that passes.

    At most ``top`` candidates are verified, one after the other, stopping
    at the first whose every scenario passes; no further candidate is
    started once ``config.choice_budget_s`` went on verification. With
    ``config.stop_early`` a candidate's verification stops as soon as it can
    no longer pass (:func:`fcso.sim.schedule.scenario_simulations`), and one whose unperturbed grasp leaves any
    part off its seat where flat pads hold it there is rejected before its trials
    (:func:`fcso.sim.seats.nominal_seats`, METHOD §5b). When none
    of those tried passes, the best of them by truth is delivered: one that holds every part at its seat, then the
    highest worst-scenario success count over the planned trials
    (:func:`worst_success_share`), then the measure's order; but flat pads the
    design chose (``report.finger.flat_pads``) are kept unless a carving passes.
    The delivered candidate's verification is complete whatever stopped
    early in the choice (:func:`fcso.sim.verify.verify_delivered`, METHOD
    §12b): every trial and the holding test, designed and flat. A carving
    that did not pass and that flat pads beat (:func:`fcso.sim.report.flat_beats`), or that holds a part off its
    seat, is delivered as flat pads on its grasps: never worse than flat by the judge.
    None passing, the other pad sizes' candidates are verified alike, best size first, and the first that passes
    is delivered; none passing at any size, the best by truth of every size tried.

    Parameters
    ----------
    result : DesignResult
    top : int
        Most candidates to verify (K).
    config : VerifyConfig
    progress : callable, optional

    Returns
    -------
    result : DesignResult
        The design with the delivered candidate (the input itself when it is the design's own choice).
    verification : VerificationReport
        The delivered candidate's verification; its ``choice`` says which was delivered and why.
    design : DesignUnderTest
        Its simulation inputs (for the report's pictures).
    ranking : list of RankedCandidate
        The verified candidates in the measure's order with their outcome.
    """
    started, budget_s = time.monotonic(), config.choice_budget_s
    deadline = started + budget_s
    first_size = _pad_size(result)
    result, ranked, outcomes = _verified_by_size(result, top, config, progress, deadline)
    passing = [o for o in outcomes if o[3].passed]
    # flat pads were designed because no carving captures a part better: a carving replaces them only by passing
    flat_design = result.report.finger.flat_pads
    fallback = [o for o in outcomes if o[1].index == result.report.best] if flat_design else outcomes
    preferred = passing + sorted((o for o in fallback if not o[3].passed), key=_truth_rank, reverse=True)
    chosen, fused, unwritable = _deliverable(result, preferred, outcomes, config, progress)
    ranking = _ranking(outcomes, chosen[1].index)
    rank, candidate, built, verification = chosen
    kept_flat = flat_design and candidate.index == result.report.best and not verification.passed
    design = built[0]
    if not verification.passed and config.stop_early:
        # told in full (METHOD §12b): every trial and the holding test; the choice's trials come from the cache
        verification = verify_delivered(design, config, progress)
        ranking = [r.model_copy(update=trial_figures(verification)) if r.chosen else r for r in ranking]
    why = choice_text(
        rank,
        candidate,
        len(outcomes),
        len(ranked),
        verification.passed,
        time.monotonic() - started,
        budget_s,
        kept_flat,
        bool(passing),
    )
    size = _pad_size(result)
    if size != first_size:
        why = (
            f"pad size {size[0]:g} x {size[1]:g} mm, {why}, after none of the {first_size[0]:g} mm pads' "
            "candidates passed"
        )
    if not kept_flat and (flat_beats(verification) or verification.unseated_scenarios):
        # a part held off its seat is held where the robot does not expect it, whatever the other parts' trials
        beaten = "flat pads beat it" if flat_beats(verification) else "it holds a part off its seat (METHOD §5b)"
        why += f"; {beaten} ({verdict_text(verification)}): delivered with flat pads on its grasps"
        result, design, verification = _flat_delivery(
            result, candidate, [*unwritable, f"verification delivered {why}"], config, progress
        )
    elif candidate.index != result.report.best:
        result = _with_candidate(result, candidate, fused, *built[1:], [*unwritable, f"verification delivered {why}"])
    else:
        verification.warnings.extend(unwritable + ([] if verification.passed else [f"verification delivered {why}"]))
        if size != first_size:
            result.report = result.report.model_copy(
                update={"warnings": [*result.report.warnings, f"verification delivered {why}"]}
            )
    verification = verification.model_copy(update={"ranking": ranking, "choice": why})
    return result, verification, design, ranking


def _truth_rank(outcome: tuple) -> tuple:
    """How a verified ``(rank, candidate, built, verification)`` that did not pass ranks by truth, larger first: one
    that holds every part at its seat (METHOD §5b), then by its worst scenario's successful trials
    (:func:`worst_success_share`), then by the measure's order."""
    rank, _, _, verification = outcome
    return not verification.unseated_scenarios, worst_success_share(verification), -rank


def _verified_by_size(
    result: DesignResult, top: int, config: VerifyConfig, progress, deadline: float
) -> tuple[DesignResult, list[CandidateReport], list[tuple]]:
    """:func:`_verified_in_order` of ``result``, then, none passing, of each of its other pad sizes (best first) until
    one passes or ``deadline``; the design of the size that passed (:func:`_with_pad_size`), with its ranked and
    verified candidates. None passing, the size whose best verified candidate ranks first by truth
    (:func:`_truth_rank`), then by the measure's quality (as a design compares its sizes), among the sizes not
    designed as flat pads (a carving replaces them only by passing), and ``result`` when it is flat pads."""
    ranked, outcomes = _verified_in_order(result, top, config, progress, deadline)
    tried = [(result, ranked, outcomes)]
    # the other sizes' candidates are verified alike (stopped early), and only the delivered one in full
    # (verify_top): a size none of whose candidates passes costs its choice, not a delivery
    for other in result.other_sizes if not any(o[3].passed for o in outcomes) else []:
        if time.monotonic() >= deadline:
            break
        other_ranked, other_outcomes = _verified_in_order(other, top, config, progress, deadline)
        if any(o[3].passed for o in other_outcomes):
            return _with_pad_size(result, other), other_ranked, other_outcomes
        if not other.report.finger.flat_pads:
            # a size designed as flat pads is delivered only by a carving that passes, as the design's own size
            tried.append((other, other_ranked, other_outcomes))
    if result.report.finger.flat_pads:
        return result, ranked, outcomes
    # stopped at their first failed trial, candidates of any size compare by the trials they passed before it, then
    # as a design compares its sizes: by the measure's quality (fcso.pipeline.design)
    best = max(
        range(len(tried)),
        key=lambda k: (
            max((_truth_rank(o)[:2] for o in tried[k][2]), default=()),
            max((o[1].quality for o in tried[k][2]), default=0.0),
            -k,
        ),
    )
    other, other_ranked, other_outcomes = tried[best]
    return (result if best == 0 else _with_pad_size(result, other)), other_ranked, other_outcomes


def _verified_in_order(
    result: DesignResult, top: int, config: VerifyConfig, progress, deadline: float
) -> tuple[list[CandidateReport], list[tuple]]:
    """Verify ``result``'s best ``top`` candidates in the measure's order until one passes or ``deadline`` (a
    :func:`time.monotonic` time) has passed; the first is always verified.

    Returns
    -------
    ranked : list of CandidateReport
        The best ``top`` candidates by the measure.
    outcomes : list of (rank, candidate, built, verification)
        The verified ones, ``built`` as :func:`candidate_designs` gives it.
    """
    ranked = ranked_candidates(result.report, top)
    outcomes = []
    # the design's own choice is built as printed; the others are built together, side by side on the workers
    others: dict[int, tuple] = {}
    for rank, candidate in enumerate(ranked):
        if candidate.index == result.report.best:
            built = (design_under_test(result), result.best, result.report.grasps, result.report.print_fit, [])
        else:
            if candidate.index not in others:
                rest = [c for c in ranked[rank:] if c.index != result.report.best]
                others = dict(zip([c.index for c in rest], candidate_designs(result, rest, jobs=config.jobs)))
            built = others[candidate.index]
        verification = verify(built[0], config, progress)
        outcomes.append((rank, candidate, built, verification))
        if verification.passed or time.monotonic() >= deadline:
            break
    return ranked, outcomes


def _pad_size(result: DesignResult) -> tuple[float, float]:
    """A design's pad length and width, mm."""
    return result.report.settings.sampler.length_mm, result.report.settings.sampler.width_mm


def _with_pad_size(result: DesignResult, other: DesignResult) -> DesignResult:
    """``other``, a design of another of ``result``'s pad sizes, with ``result``'s list of pad sizes marking it
    chosen."""
    sizes = [
        s.model_copy(update={"chosen": (s.length_mm, s.width_mm) == _pad_size(other)})
        for s in result.report.pad_sizes or []
    ]
    return dataclasses.replace(other, report=other.report.model_copy(update={"pad_sizes": sizes}))


def _ranking(outcomes: list, chosen_index: int) -> list[RankedCandidate]:
    """The verified candidates' ``(rank, candidate, built, verification)`` as :class:`RankedCandidate` rows."""
    return [
        RankedCandidate(
            rank_by_quality=rank + 1,
            index=candidate.index,
            quality=candidate.quality,
            passed=verification.passed,
            chosen=candidate.index == chosen_index,
            **trial_figures(verification),
        )
        for rank, candidate, _, verification in outcomes
    ]


def _flat_delivery(
    result: DesignResult, candidate: CandidateReport, notes: list[str], config: VerifyConfig, progress
) -> tuple[DesignResult, DesignUnderTest, VerificationReport]:
    """The design with flat pads on ``candidate``'s grasps, its simulation inputs and its full verification;
    ``notes`` among its warnings."""
    built = candidate_designs(result, [candidate], jobs=config.jobs, flat=True)[0]
    settings = result.report.settings
    fused = fuse(result.flat_finger, built[1].fingerpad.pad, settings.sampler, settings.finger.overlap_mm)
    # the flat control's trials are in the simulation cache: flat pads verified on the same grasps read them back
    verification = verify_delivered(built[0], config, progress)
    return _with_candidate(result, candidate, fused, *built[1:], notes, flat_pads=True), built[0], verification


def _deliverable(result: DesignResult, preferred: list, outcomes: list, config: VerifyConfig, progress):
    """The first of the ``preferred`` verified candidates whose finger is one watertight body as written to STL.

    The design's own choice was written when it was designed; another candidate's pad is fused onto the finger here,
    and one whose finger is refused (:class:`fcso.errors.UnwritableSolidError`) gives way to the next, as the design's
    own finalists do (:mod:`fcso.pipeline.finish`). When none can be written the design's own choice is delivered,
    verified here if the choice had not reached it.

    Returns
    -------
    chosen : tuple
        ``(rank, candidate, built, verification)`` of the delivered candidate.
    fused : FusedFinger or None
        Its fused finger; None for the design's own choice.
    unwritable : list of str
        One sentence per verified candidate passed over because its finger cannot be written.
    """
    unwritable = []
    for chosen in preferred:
        rank, candidate, built, _ = chosen
        if candidate.index == result.report.best:
            return chosen, None, unwritable
        settings = result.report.settings
        try:
            return (
                chosen,
                fuse(result.flat_finger, built[1].fingerpad.pad, settings.sampler, settings.finger.overlap_mm),
                unwritable,
            )
        except UnwritableSolidError as error:
            unwritable.append(f"candidate {candidate.index} (rank {rank + 1} by the measure) is not delivered: {error}")
    own = next((o for o in outcomes if o[1].index == result.report.best), None)
    if own is None:
        built = (design_under_test(result), result.best, result.report.grasps, result.report.print_fit, [])
        candidate = next(c for c in result.report.candidates if c.index == result.report.best)
        own = (len(outcomes), candidate, built, verify(built[0], config, progress))
    return own, None, unwritable


def trial_figures(verification: VerificationReport) -> dict[str, list]:
    """A :class:`RankedCandidate`'s figures of a verification: per scenario, the designed and the flat pads' success
    rates (None where the flat control ran no trial) and the designed pads' trials run."""
    return {
        "success_rates": [s.fcso.success_rate for s in verification.scenarios],
        "flat_success_rates": [s.flat.success_rate if s.flat.trials else None for s in verification.scenarios],
        "trials_run": [len(s.fcso.trials) for s in verification.scenarios],
    }


def worst_success_share(verification: VerificationReport) -> float:
    """The designed finger's successful trials over the planned ``trials`` in its worst scenario, 0..1.

    A full run's success rate; for a verification stopped early
    (``stop_early``) a lower bound of it (a scenario left unverified counts
    0): candidates stopped early are compared by how many trials they passed
    before they could no longer pass. 0 without trials.
    """
    planned = verification.settings.trials
    if planned == 0:
        return 0.0
    shares = [successes(s.fcso.trials) / planned for s in verification.scenarios]
    return min(shares + [0.0] * len(verification.unverified_scenarios), default=0.0)


def choice_text(
    rank: int,
    candidate: CandidateReport,
    tried: int,
    ranked: int,
    passed: bool,
    spent_s: float,
    budget_s: float,
    kept_flat: bool = False,
    any_passed: bool | None = None,
) -> str:
    """Which candidate was delivered and why, in a sentence (``verification.json``'s ``choice``).

    ``passed``: the delivered candidate passed; ``kept_flat``: the design's flat pads were kept because no carving
    passed; ``any_passed`` (default ``passed``): a verified candidate passed, though its finger may not be writable.
    """
    what = f"candidate {candidate.index} (rank {rank + 1} by the measure, {candidate.quality:.1f})"
    if passed:
        return f"{what}: the first whose every scenario passed, after {tried} of {ranked} verified"
    if any_passed:
        return f"{what}: the candidates that passed cannot be written as one watertight body; the best of the rest"
    stop = (
        f"the time budget of {budget_s:g} s ran out after {spent_s:.0f} s"
        if tried < ranked
        else f"all {ranked} candidates were verified"
    )
    kept = (
        "the design's flat pads are kept: only a carving that passes replaces them"
        if kept_flat
        else "the best of those by its worst scenario's successful trials"
    )
    return f"{what}: none of the {tried} verified passed ({stop}); {kept}"


def _with_candidate(
    result: DesignResult,
    candidate: CandidateReport,
    fused: FusedFinger,
    evaluation: CandidateEvaluation,
    grasps,
    print_fit,
    fit_warnings,
    notes: list[str],
    flat_pads: bool = False,
) -> DesignResult:
    """The design result with another candidate chosen: its printed pad fused onto the finger (``fused``), its grasps
    and print fit in the report, ``notes`` among its warnings; ``flat_pads``: the pad is the candidate's flat one.
    """
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
                flat_pads=flat_pads,
            ),
            "warnings": result.report.warnings + fit_warnings + notes,
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
