"""Chosen candidates made into fingers (METHOD §9): printed-fit pockets, each candidate's pad opened and evaluated,
the finger fused, the design's report."""

from __future__ import annotations

import dataclasses
import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from ..config import DesignConfig
from ..errors import GeometryError
from ..evaluate import (
    CandidateEvaluation,
    SampleGeometry,
    Scenario,
    candidate_fingerpad,
    evaluate_candidate,
    fit_key,
    fitted_sample,
    opened_pad,
    printed_lead_in_deg,
    versus_flat,
)
from ..finger import (
    FlatFinger,
    FusedFinger,
    fuse,
    pad_to_finger,
    print_ready,
)
from ..geometry import mesh_arrays, solid_from_mesh_arrays
from ..pad import Fingerpad, PadGeometry
from ..parallel import WorkerPool
from ..printfit import thinnest_wall_mm
from ..progress import Progress, progress_with_note
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
from .prepare import Prepared
from .report import (
    candidate_reports,
    grasp_report,
    part_report,
    print_fit_report,
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
    """

    report: DesignReport
    finger: trimesh.Trimesh
    fingerpad: trimesh.Trimesh
    scenarios: list[Scenario]
    best: CandidateEvaluation
    flat_finger: FlatFinger
    pad_to_finger: np.ndarray


def finish_candidate(
    scenarios: list[Scenario],
    choice: Sequence[int],
    config: DesignConfig,
    flat: bool = False,
    jobs: int = 1,
    pads: dict[str, tuple] | None = None,
) -> tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """One candidate built as :func:`design` builds its choice: :func:`finish_candidates` of that one."""
    return finish_candidates([(scenarios, tuple(choice))], config, flat, jobs, pads)[0]


def finish_candidates(
    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]],
    config: DesignConfig,
    flat: bool = False,
    jobs: int = 1,
    pads: dict[str, tuple] | None = None,
    progress: Progress | None = None,
    exact: Sequence[CandidateEvaluation | None] | None = None,
    on_finished: Callable[[int, tuple], None] | None = None,
) -> list[tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]]:
    """Candidates built as :func:`design` builds its choice: carved with ``[print]``'s fit, their pads kept.

    ``flat`` builds flat pads on the candidates' grasps instead (:func:`fcso.evaluate.evaluate_candidate`).
    The printed-fit pockets of every candidate's samples (two Minkowski sums
    each) are made on ``jobs`` workers (``[compute] scheduler``'s when set),
    and each candidate's pad (their union, its thin walls opened) as soon as
    its own pockets are: a job's finger sets are finished side by side. Each
    pad is rebuilt from its mesh, so it is the same wherever it was made;
    its evaluations are made here as each pad arrives.

    Parameters
    ----------
    candidates : sequence of (list of Scenario, tuple of int)
        Each candidate's scenarios (samples shared between candidates are carved once) and sample index per
        scenario.
    config : DesignConfig
    flat : bool
    jobs : int
    pads : dict, optional
        Printed pads made before (:func:`pad_key`: mesh arrays, case, block depth); new ones are added. The choice
        by truth keeps one for the candidates of a design, which often carve the same pad.
    progress : callable, optional
    exact : sequence of CandidateEvaluation or None, optional
        Per candidate, its exact evaluation with ``config`` (``keep_pad=False``) when made before, as
        :func:`choose_candidate` makes its finalists': the print-fit report takes its figures and makes only its pad,
        instead of evaluating the candidate again.
    on_finished : callable, optional
        ``on_finished(number, finished)``, called in this process as each candidate is finished (its entry of the
        list returned), while the workers make the others' pads.

    Returns
    -------
    list of (CandidateEvaluation, list of GraspReport, PrintFitReport, list of str)
        Per candidate: the fitted evaluation, its grasps and print-fit report
        as ``report.json`` lists them, and the print-fit warnings.
    """
    finishing = _finishing(candidates, config, flat, pads, exact, on_finished)
    report_progress = progress_with_note(progress)
    report_progress("fingers", 0, len(candidates), f"{len(finishing.missing)} printed-fit pockets")
    tasks = [(_fit_task, item, ("pocket", m)) for m, item in enumerate(finishing.missing)]
    tasks += _pad_tasks(finishing, [c for c, needs in enumerate(finishing.waiting) if not needs])
    workers = min(jobs, len(finishing.missing) + len(candidates))
    with WorkerPool((finishing.shared, config, flat), workers, config.compute.scheduler) as pool:
        _finish_made(finishing)
        pool.run(tasks, lambda tag, result: _on_done(finishing, tag, result))
    _finish_made(finishing)
    report_progress("fingers", len(candidates), len(candidates), "")
    return [finishing.finished[c] for c in range(len(candidates))]


@dataclass
class _Finishing:
    """What :func:`finish_candidates` keeps while its workers carve pockets and make pads.

    Attributes
    ----------
    candidates, config, flat, on_finished
        As given to :func:`finish_candidates`.
    configs : list of DesignConfig
        Per candidate, ``config`` with the lead-in it is printed with.
    fits : list of (float, str or None)
        Per candidate, its lead-in and why it differs from ``config``'s (None when it does not).
    known : list of CandidateEvaluation or None
        Per candidate, its exact evaluation made before, when it holds for the printed candidate.
    shared : list of Scenario
        Every scenario of the candidates once: the workers' shared context.
    number : dict
        ``id(scenario)`` -> its position in ``shared``.
    missing : list of (int, int, float)
        The printed-fit pockets to carve: scenario number in ``shared``, sample index, lead-in.
    waiting : list of set of int
        Per candidate, the positions in ``missing`` of the pockets it still waits for.
    cache : dict
        :func:`pad_key` -> the printed pad made (mesh arrays, case, block depth).
    keys : list of str or None
        Per candidate, its :func:`pad_key` once its pad is asked for.
    started : set of str
        Pads asked of the workers.
    finished : dict
        Candidate number -> its entry of the list returned.
    """

    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]]
    config: DesignConfig
    flat: bool
    on_finished: Callable[[int, tuple], None] | None
    configs: list[DesignConfig]
    fits: list[tuple[float, str | None]]
    known: list[CandidateEvaluation | None]
    shared: list[Scenario]
    number: dict[int, int]
    missing: list[tuple[int, int, float]]
    waiting: list[set[int]]
    cache: dict[str, tuple]
    keys: list[str | None]
    started: set[str] = dataclasses.field(default_factory=set)
    finished: dict[int, tuple] = dataclasses.field(default_factory=dict)


def _finishing(
    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]],
    config: DesignConfig,
    flat: bool,
    pads: dict[str, tuple] | None,
    exact: Sequence[CandidateEvaluation | None] | None,
    on_finished: Callable[[int, tuple], None] | None,
) -> _Finishing:
    """The start of :func:`finish_candidates`: each candidate's lead-in, the pockets to carve, who waits for which."""
    fits = [
        (config.print.lead_in_deg, None) if flat else printed_lead_in_deg(scenarios, choice, config)
        for scenarios, choice in candidates
    ]
    configs = [config if why is None else _with_lead_in(config, angle) for angle, why in fits]
    # every scenario of the candidates once: the workers' shared context
    shared = list({id(s): s for scenarios, _ in candidates for s in scenarios}.values())
    number = {id(s): n for n, s in enumerate(shared)}
    missing = list(
        dict.fromkeys(
            (number[id(scenarios[m])], k, fitted_config.print.lead_in_deg)
            for (scenarios, choice), fitted_config in zip(candidates, configs)
            if not flat and fit_key(fitted_config) is not None
            for m, k in enumerate(choice)
            if fit_key(fitted_config) not in scenarios[m].samples[k].fitted
        )
    )
    # an exact evaluation made before holds for a candidate printed with config's own lead-in
    known = [None if exact is None or flat or why is not None else exact[c] for c, (_, why) in enumerate(fits)]
    # each candidate's pad is built and opened as soon as its own pockets are carved, while other pockets are still
    # being carved: one long carving or one large pad no longer leaves the other workers waiting (the union of a large
    # set's pockets is minutes of Booleans)
    waiting: list[set[int]] = []  # per candidate, the missing pockets it waits for
    for (scenarios, choice), fitted_config in zip(candidates, configs):
        used = {(number[id(s)], k) for s, k in zip(scenarios, choice)}
        angle = fitted_config.print.lead_in_deg
        waiting.append({m for m, (n, k, a) in enumerate(missing) if (n, k) in used and a == angle})
    cache = {} if pads is None else pads
    return _Finishing(
        candidates,
        config,
        flat,
        on_finished,
        configs,
        fits,
        known,
        shared,
        number,
        missing,
        waiting,
        cache,
        [None] * len(candidates),
    )


def _pad_tasks(finishing: _Finishing, ready: list[int]) -> list[tuple]:
    """The workers' tasks making the pads of candidates ``ready``, whose pockets are all carved."""
    tasks = []
    keys, number = finishing.keys, finishing.number
    for c in ready:
        (scenarios, choice), fitted_config = finishing.candidates[c], finishing.configs[c]
        samples = [s.samples[k] for s, k in zip(scenarios, choice)]
        keys[c] = pad_key(samples, fitted_config, finishing.flat)
        # a pad carved by several candidates is made once
        if keys[c] in finishing.cache or keys[c] in finishing.started:
            continue
        finishing.started.add(keys[c])
        fit = fit_key(fitted_config)
        pockets = (
            {}
            if finishing.flat or fit is None
            else {(number[id(s)], k): s.samples[k].fitted[fit] for s, k in zip(scenarios, choice)}
        )
        item = ([number[id(s)] for s in scenarios], choice, fitted_config.print.lead_in_deg, pockets)
        tasks.append((_pad_task, item, ("pad", keys[c])))
    return tasks


def _finish_made(finishing: _Finishing) -> None:
    """Each candidate whose pad is made evaluated on it, here, while the workers open the others'."""
    for c, ((scenarios, choice), fitted_config, (_, why)) in enumerate(
        zip(finishing.candidates, finishing.configs, finishing.fits)
    ):
        key = finishing.keys[c]
        if c not in finishing.finished and key in finishing.cache:
            fingerpad = Fingerpad(solid_from_mesh_arrays(*finishing.cache[key][0]), *finishing.cache[key][1:])
            finishing.finished[c] = _finished(
                scenarios, choice, fitted_config, finishing.flat, fingerpad, why, finishing.known[c]
            )
            if finishing.on_finished is not None:
                finishing.on_finished(c, finishing.finished[c])


def _on_done(finishing: _Finishing, tag: tuple, result) -> list[tuple]:
    """A worker's pocket or pad arrived: keep it, finish what it completes; the pads now ready to make."""
    kind, what = tag
    if kind == "pad":
        finishing.cache[what] = result
        _finish_made(finishing)
        return []
    n, k, angle = finishing.missing[what]
    finishing.shared[n].samples[k].fitted[fit_key(_with_lead_in(finishing.config, angle))] = result
    ready = []
    for c, needs in enumerate(finishing.waiting):
        if what in needs:
            needs.discard(what)
            if not needs:
                ready.append(c)
    return _pad_tasks(finishing, ready)


def pad_key(samples: Sequence[SampleGeometry], config: DesignConfig, flat: bool) -> str:
    """What a candidate's printed pad depends on: its samples' printed-fit pockets (their exact meshes), the pad box,
    ``[filter]`` and ``[print]``'s minimum wall; or only the box for flat pads."""
    sampler, key = config.sampler, fit_key(config)
    sizes = [sampler.thickness_mm, sampler.length_mm, sampler.width_mm, sampler.penetration_mm]
    sizes += [config.filter.block_factor, config.print.resolved()["min_wall_mm"]]
    digest = hashlib.sha256(np.array(sizes + [float(flat)], dtype="<f8").tobytes())
    geometries = (
        [] if flat else [g for sample in samples for g in (sample.geometries if key is None else sample.fitted[key])]
    )
    for geometry in geometries:
        vertices, triangles = mesh_arrays(geometry.intersection)
        digest.update(np.array([geometry.good, geometry.depth_mm], dtype="<f8").tobytes())
        digest.update(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
        digest.update(np.ascontiguousarray(triangles, dtype="<i8").tobytes())
    return digest.hexdigest()


def _finished(
    scenarios: list[Scenario],
    choice: tuple[int, ...],
    config: DesignConfig,
    flat: bool,
    fingerpad: Fingerpad,
    why: str | None,
    known: CandidateEvaluation | None = None,
) -> tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """One candidate of :func:`finish_candidates` evaluated on its opened pad (``config`` with its lead-in);
    ``known`` its exact evaluation made before, if any."""
    fitted = evaluate_candidate(scenarios, choice, config, keep_pad=True, fitted=True, flat=flat, fingerpad=fingerpad)
    fit, sampler = config.print.resolved(), config.sampler
    if not any(v > 0 for k, v in fit.items() if k != "density_g_cm3"):
        exact = fitted
    elif known is not None:
        # the same evaluation: its figures, and the exact pad the report measures
        exact = dataclasses.replace(known, fingerpad=candidate_fingerpad(scenarios, choice, config))
    else:
        exact = evaluate_candidate(scenarios, choice, config, keep_pad=True, flat=flat)
    thinnest = thinnest_wall_mm(fitted.fingerpad.pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    warnings: list[str] = [] if why is None else [why]
    # the opening's ball is a polyhedron and the wall is measured by rays: 0.05 mm of slack
    if fit["min_wall_mm"] > 0 and thinnest < fit["min_wall_mm"] - 0.05:
        warnings.append(
            f"the pad keeps a wall of {thinnest:.3f} mm, thinner than print.min_wall_mm = {fit['min_wall_mm']:.3f} mm"
        )
    print_fit = print_fit_report(config, exact, fitted, thinnest)
    return (
        fitted,
        [grasp_report(s, k, e, config) for s, k, e in zip(scenarios, choice, fitted.scenarios)],
        print_fit,
        warnings,
    )


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


def finish_designs(
    designs: Sequence[tuple[Prepared, ChosenCandidate]], config: DesignConfig, progress: Progress | None = None
) -> list[DesignResult | GeometryError]:
    """The fingers of chosen candidates (METHOD §9) and their designs' reports: the rest of :func:`design_prepared`.

    The candidates are finished together (:func:`finish_candidates`, on the
    batches' workers): a job's finger sets carve their printed-fit pockets
    and open their thin walls side by side. Each design's ``finger`` timing
    holds an equal share of that.

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
            return [made for design in designs for made in finish_designs([design], config, progress)]
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
    # a clearance deepens the pocket by c: the carving demands that much less
    floor = config.sampler.thickness_mm - config.sampler.penetration_mm - config.print.resolved()["clearance_mm"]
    if fused.min_pad_thickness_mm < floor - 1e-3:
        warnings.append(
            f"thinnest pad section is {fused.min_pad_thickness_mm:.3f} mm, below T - D - clearance = {floor:.3f} mm"
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


def _with_lead_in(config: DesignConfig, lead_in_deg: float) -> DesignConfig:
    """``config`` with the pockets drafted by ``lead_in_deg`` (a candidate printed with a wider lead-in)."""
    return (
        config if lead_in_deg == config.print.lead_in_deg else config.updated({"print": {"lead_in_deg": lead_in_deg}})
    )


def _fit_task(context, task: tuple[int, int, float]) -> list[PadGeometry]:
    scenarios, config, _ = context
    number, index, lead_in_deg = task
    config = _with_lead_in(config, lead_in_deg)
    return fitted_sample(scenarios[number], scenarios[number].samples[index], config)


def _pad_task(context, task: tuple[list[int], tuple[int, ...], float, dict]) -> tuple:
    """A candidate's printed pad, built and opened from its samples' printed-fit pockets (scenario number, sample
    index -> carved geometries, carved after this worker was forked): its mesh arrays, case and block depth."""
    scenarios, config, flat = context
    numbers, choice, lead_in_deg, pockets = task
    config = _with_lead_in(config, lead_in_deg)
    for (number, index), carved in pockets.items():
        scenarios[number].samples[index].fitted[fit_key(config)] = carved
    pad = candidate_fingerpad([scenarios[n] for n in numbers], choice, config, fitted=True, flat=flat)
    return mesh_arrays(opened_pad(pad.pad, config)), pad.case, pad.block_depth_mm
