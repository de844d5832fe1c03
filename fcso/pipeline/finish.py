"""Chosen candidates made into fingers (METHOD §9): printed-fit pockets, each candidate's pad opened and evaluated,
the finger fused, the design's report."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from ..config import DesignConfig
from ..errors import GeometryError, UnwritableSolidError
from ..evaluate import (
    CandidateEvaluation,
    Scenario,
    versus_flat,
)
from ..finger import (
    FlatFinger,
    FusedFinger,
    fuse,
    pad_to_finger,
    print_ready,
)
from ..progress import Progress
from ..report.models import (
    DesignReport,
    FingerReport,
    GraspReport,
    PrintFitReport,
    SearchReport,
)
from ..screen import ScreenedCandidate
from ..version import __version__
from .choose import ChosenCandidate, listed_screens
from .pads import finish_candidates
from .prepare import Prepared
from .report import (
    candidate_reports,
    part_report,
    rounded,
    scenario_report,
)


@dataclass
class DesignResult:
    """What :func:`design` returns.

    Attributes
    ----------
    report : DesignReport
        The content of ``report.json``.
    finger : trimesh.Trimesh
        Print-ready finger (both fingers are this part), mm.
    fingerpad : trimesh.Trimesh
        The chosen pad alone, in its pad frame, mm.
    scenarios : list of Scenario
        Parts in their poses with their samples (for pictures and audits).
    best : CandidateEvaluation
        The chosen candidate with its contacts.
    flat_finger : FlatFinger
        The finger the pad was fused onto.
    pad_to_finger : (4, 4) float
        Pad frame to finger frame.
    other_sizes : iterable of DesignResult
        The designs of the other pad sizes of ``[sampler]`` (METHOD §3b), best by the size choice first, for the
        choice by truth (:func:`fcso.sim.choose.verify_top`); empty with one size. A finger set's are designed when
        the choice first asks for them (:class:`fcso.sets.other_sizes.OtherSizes`).
    """

    report: DesignReport
    finger: trimesh.Trimesh
    fingerpad: trimesh.Trimesh
    scenarios: list[Scenario]
    best: CandidateEvaluation
    flat_finger: FlatFinger
    pad_to_finger: np.ndarray
    other_sizes: Iterable[DesignResult] = dataclasses.field(default_factory=list)


def finish_design(
    prepared: Prepared, chosen: ChosenCandidate, config: DesignConfig, progress: Progress | None = None
) -> DesignResult:
    """The finger of a chosen candidate (METHOD §9) and the design's report: :func:`finish_designs` of that one.

    Raises
    ------
    GeometryError
        The fused finger is not one printable body.
    """
    made = finish_designs([(prepared, chosen)], config, progress)[0]
    if isinstance(made, GeometryError):
        raise made
    return made


#: Candidates tried, in the order of their exact figures, after a chosen one whose finger is not one watertight body
#: as written to STL, before its design fails.
WRITTEN_FALLBACKS = 3


def finish_designs(
    designs: Sequence[tuple[Prepared, ChosenCandidate]], config: DesignConfig, progress: Progress | None = None
) -> list[DesignResult | GeometryError]:
    """The fingers of chosen candidates (METHOD §9) and their designs' reports: the rest of :func:`design_prepared`.

    A design whose finger (or fingerpad) is not one watertight body as
    written to STL is made with the next of its exact finalists instead, up
    to ``WRITTEN_FALLBACKS`` of them, and its report's warnings say which
    and why (:func:`_written_or_next`).

    Parameters
    ----------
    designs : sequence of (Prepared, ChosenCandidate)
        Each batch and the candidate chosen on it (:func:`choose_candidate`).
    config : DesignConfig
    progress : callable, optional

    Returns
    -------
    list of DesignResult or GeometryError
        Per design, its result, or the error saying why its fused finger is not one printable body.
    """
    results = _finished_designs(designs, config, progress)
    return [_written_or_next(*design, made, config, progress) for design, made in zip(designs, results)]


def _written_or_next(
    prepared: Prepared,
    chosen: ChosenCandidate,
    made: DesignResult | GeometryError,
    config: DesignConfig,
    progress: Progress | None,
) -> DesignResult | GeometryError:
    """``made``, the design of ``chosen``; when its finger is not one watertight body as written to STL, the design
    of the next of the exact finalists (by their exact figures, as :func:`choose_candidate` chose) whose finger is,
    trying at most ``WRITTEN_FALLBACKS``; each one passed over is a warning of the report."""
    exact, indices = chosen.exact, chosen.indices
    ranked = sorted(exact, key=lambda c: (exact[c].quality, exact[c].mean_effective_area, -indices[c]), reverse=True)
    tried = [chosen.choice]
    while isinstance(made, UnwritableSolidError) and len(tried) <= WRITTEN_FALLBACKS:
        following = [c for c in ranked if c not in tried]
        if not following:
            break
        choice = following[0]
        note = (
            f"candidate {indices[tried[-1]]} is not delivered: {made}; candidate {indices[choice]}, the next by its "
            "exact figures, is tried instead"
        )
        chosen = dataclasses.replace(
            chosen,
            choice=choice,
            candidate=candidate_reports([choice], {choice: exact[choice]}, {}, indices)[0],
            warnings=[*chosen.warnings, note],
        )
        tried.append(choice)
        made = _finished_designs([(prepared, chosen)], config, progress)[0]
    return made


def _finished_designs(
    designs: Sequence[tuple[Prepared, ChosenCandidate]], config: DesignConfig, progress: Progress | None = None
) -> list[DesignResult | GeometryError]:
    """:func:`finish_designs` of the chosen candidates themselves.

    The candidates are finished together (:func:`finish_candidates`, on the
    batches' workers): a job's finger sets carve their printed-fit pockets
    and open their thin walls side by side. Each design's ``finger`` timing
    holds an equal share of that. Parameters and returns as :func:`finish_designs`.
    """
    clock = time.perf_counter()
    jobs = max(prepared.jobs for prepared, _ in designs)
    candidates = [(prepared.scenarios, chosen.choice) for prepared, chosen in designs]
    # per design: its finished candidate, compared with flat pads, whether flat pads are delivered, its fused finger
    fingers: dict[int, tuple] = {}

    def made_finger(n: int, made: tuple) -> None:
        # as soon as a candidate is finished, while the workers make the other pads
        prepared, chosen = designs[n]
        versus = versus_flat(prepared.scenarios, made[0], chosen.exact.values(), config)
        # no carving tried captures any scenario better than flat pads: printing one would be over-carving (METHOD
        # §7b)
        flat = all(v is not None and not v.beats_flat for v in versus)
        if flat:
            made = finish_candidates([candidates[n]], config, flat=True, progress=progress)[0]
            versus = versus_flat(prepared.scenarios, made[0], chosen.exact.values(), config)
        try:
            fused = fuse(prepared.finger, made[0].fingerpad.pad, config.sampler, config.finger.overlap_mm)
        except GeometryError as error:
            fused = error
        fingers[n] = (made, versus, flat, fused)

    # the listed candidates are screened beside the finishing, on workers of their own: they wait for nothing
    with listed_screens(designs, config) as listed_later:
        try:
            exact = [chosen.exact[chosen.choice] for _, chosen in designs]
            finish_candidates(candidates, config, jobs=jobs, progress=progress, exact=exact, on_finished=made_finger)
        except GeometryError as error:
            # a pad Boolean failed: each design alone says whose
            if len(designs) == 1:
                return [error]
            return [made for design in designs for made in _finished_designs([design], config, progress)]
        shared_s = (time.perf_counter() - clock) / len(designs)
        clock = time.perf_counter()
        listed = listed_later()
        listing_s = (time.perf_counter() - clock) / len(designs)
    results: list[DesignResult | GeometryError] = []
    for n, (prepared, chosen) in enumerate(designs):
        made, versus, flat, fused = fingers[n]
        try:
            if isinstance(fused, GeometryError):
                raise fused
            results.append(
                _finished_design(prepared, chosen, config, made, versus, flat, fused, shared_s, listed[n], listing_s)
            )
        except GeometryError as error:
            results.append(error)
    return results


def _finished_design(
    prepared: Prepared,
    chosen: ChosenCandidate,
    config: DesignConfig,
    finished: tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]],
    compared: list,
    flat_pads: bool,
    fused: FusedFinger,
    finishing_s: float,
    listed: dict[tuple[int, ...], ScreenedCandidate],
    listing_s: float,
) -> DesignResult:
    """One design of :func:`finish_designs`: its report, ``fused`` its finger, ``finishing_s`` its share of the
    candidates' finishing (the finger fused), ``listed`` its listed candidates' screenings (:func:`listed_screens`),
    ``listing_s`` its share of screening them."""
    scenarios, jobs = prepared.scenarios, prepared.jobs
    loaded, finger, ungraspable = prepared.parts, prepared.finger, prepared.ungraspable
    warnings, timings = list(chosen.warnings), dict(chosen.timings_s)
    outcome, ranked, exact, indices = chosen.outcome, chosen.ranked, chosen.exact, chosen.indices
    best_choice, upper_bound = chosen.choice, chosen.upper_bound
    timings["screening"] = timings.get("screening", 0.0) + listing_s
    clock = time.perf_counter() - finishing_s
    best, grasps, print_fit, fit_warnings = finished
    transform = pad_to_finger(finger, config.sampler)
    # the section behind a pocket runs to the pad's back, which is fused to the finger: thinner than T - D - clearance
    # is common and harmless (5 of 6 designs in issue 47's survey warned of it); thinner than the printer's thinnest
    # wall is not
    min_wall = config.print.resolved()["min_wall_mm"]
    if fused.min_pad_thickness_mm < min_wall - 1e-3:
        warnings.append(
            f"thinnest pad section is {fused.min_pad_thickness_mm:.3f} mm, below print.min_wall_mm = {min_wall:.3f} mm"
        )
    warnings.extend(fit_warnings)
    timings["finger"] = time.perf_counter() - clock
    for scenario, versus in zip(scenarios, compared):
        if versus is not None and not versus.beats_flat:
            warnings.append(
                f"{scenario.part.name} in stable pose {scenario.pose_index}: no pad captures it better than flat pads "
                f"(capture {versus.capture.fraction:.2f} against {versus.flat.fraction:.2f} for flat ones): "
                + ("the finger is delivered with flat pads" if flat_pads else "the carved pad is no improvement there")
            )

    report = DesignReport(
        fcso_version=__version__,
        parts=[part_report(p) for p in loaded],
        scenarios=[scenario_report(s, v) for s, v in zip(scenarios, compared)],
        candidates=candidate_reports(ranked[: config.search.report_candidates], exact, listed, indices),
        best=indices[best_choice],
        search=SearchReport(
            kind=outcome.kind,
            evaluated=len(outcome.evaluated),
            screened=len(outcome.evaluated),
            exact=len(exact),
            candidates_total=outcome.total,
            proven_optimal=outcome.proven_optimal,
            jobs=jobs,
            quality_upper_bound=rounded(upper_bound),
            gap=rounded(exact[best_choice].quality / upper_bound) if upper_bound > 0 else 1.0,
        ),
        grasps=grasps,
        ungraspable=ungraspable,
        finger=FingerReport(
            source=finger.source,
            repairs=finger.repairs,
            volume_mm3=rounded(fused.volume_mm3),
            bodies=fused.bodies,
            watertight=fused.watertight,
            min_pad_thickness_mm=rounded(fused.min_pad_thickness_mm),
            flat_pads=flat_pads,
        ),
        timings_s={k: round(v, 3) for k, v in timings.items()},
        warnings=warnings,
        settings=config,
        print_fit=print_fit,
    )
    return DesignResult(
        report=report,
        finger=fused.mesh,
        fingerpad=print_ready(best.fingerpad.pad, "fingerpad").mesh,
        scenarios=scenarios,
        best=best,
        flat_finger=finger,
        pad_to_finger=transform,
    )
