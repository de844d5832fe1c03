"""The FCSO pipeline: parts in, fingerpad, finger and quality table out."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import trimesh

from . import __version__
from .config import DesignConfig
from .errors import GeometryError, NoGraspError, UnwritableSolidError
from .evaluate import (
    CandidateEvaluation,
    SampleGeometry,
    Scenario,
    candidate_fingerpad,
    evaluate_candidate,
    fit_key,
    fitted_sample,
    opened_pad,
    printed_lead_in_deg,
    sample_geometry,
    screen_on_pad,
    versus_flat,
)
from .finger import (
    FlatFinger,
    FusedFinger,
    finger_plate,
    fuse,
    load_finger,
    pad_to_finger,
    parametric_finger,
    print_ready,
)
from .geometry import mesh_arrays, solid_from_mesh_arrays, to_manifold
from .measure import quality_words, scenario_measure
from .pad import Fingerpad, PadGeometry
from .parallel import WorkerPool, resolve_jobs
from .parts import Part, load_parts
from .poses import select_poses, stable_poses
from .printfit import thinnest_wall_mm
from .progress import Progress
from .report.design import (
    candidate_reports,
    grasp_report,
    part_report,
    print_fit_report,
    rounded,
    scenario_report,
    ungraspable_report,
)
from .report.models import (
    CandidateReport,
    DesignReport,
    FingerReport,
    GraspReport,
    PadSizeReport,
    PrintFitReport,
    SearchReport,
    UngraspableReport,
    chosen_candidate,
)
from .sampler import SamplerResult, face_yaws, sample_grasps
from .screen import NormalLattice, ScreenedCandidate, ScreenGrid, carve_heights, screen
from .search import SearchOutcome, candidate_index, quality_upper_bound, rerank, search

#: Samples per pad-geometry task and candidates per screening task sent to a worker.
_GEOMETRY_CHUNK = 4
_SCREEN_CHUNK = 64
#: Candidates per task screened on their whole pad (a few milliseconds each).
_PAD_CHUNK = 8
#: Sampling tasks per worker to aim for when scenarios and yaws are few.
_SAMPLE_TASKS_PER_WORKER = 4

#: A design of one pad size: a finger's (:class:`DesignResult`) or a job's finger sets'.
Designed = TypeVar("Designed")


@dataclass(frozen=True)
class SizeScore:
    """How one pad size's design competes with the others' (:func:`best_pad_size`).

    Attributes
    ----------
    rank : tuple
        Compared as a tuple: the largest is delivered.
    quality : float
        Reported: the design's quality (for finger sets the worst set's).
    flat_pads : bool
        It delivered flat pads somewhere.
    """

    rank: tuple
    quality: float
    flat_pads: bool


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


@dataclass
class Prepared:
    """A batch ready for the candidate search: scenarios with their samples' pad geometries.

    Attributes
    ----------
    parts : list of Part
    finger : FlatFinger
    scenarios : list of Scenario
        The graspable ones, each with its :class:`SampleGeometry` list.
    ungraspable : list of UngraspableReport
    lattice : NormalLattice
        The screening's normal quantisation (its RLES cache fills as candidates are screened).
    jobs : int
        Worker processes.
    warnings : list of str
    timings_s : dict
    """

    parts: list[Part]
    finger: FlatFinger
    scenarios: list[Scenario]
    ungraspable: list[UngraspableReport]
    lattice: NormalLattice
    jobs: int
    warnings: list[str]
    timings_s: dict[str, float]


def flat_finger(config: DesignConfig, repair: bool = False) -> FlatFinger:
    """The finger the pads are fused onto: ``[finger] mesh`` when given, else the parametric finger of ``[sampler]`` and
    ``[gripper]``.

    ``repair`` repairs a finger mesh that is not a closed volume.
    """
    return (
        load_finger(config.finger, repair=repair)
        if config.finger.mesh
        else parametric_finger(config.sampler, config.gripper)
    )


def load_batch(parts: Sequence[Part | str | Path], config: DesignConfig, repair: bool = False) -> list[Part]:
    """A batch's parts: each path loaded in mm with :func:`fcso.load_parts` (a file may give several), parts as given.

    ``repair`` repairs meshes that are not closed volumes; ``[parts] split_bodies`` decides what separate solids in
    one file become.
    """
    return [
        one
        for p in parts
        for one in (
            [p]
            if isinstance(p, Part)
            else load_parts(
                p,
                repair=repair,
                split_bodies=config.parts.split_bodies,
                max_repair_volume_change_percent=config.parts.repair_max_volume_change_percent,
                max_repair_deviation_mm=config.parts.repair_max_deviation_mm,
            )
        )
    ]


def prepare(
    parts: Sequence[Part | str | Path], config: DesignConfig, progress: Progress | None = None, repair: bool = False
) -> Prepared:
    """Load, pose, sample and intersect: everything before the search (METHOD §1-5).

    Parameters and errors as :func:`design`.

    Returns
    -------
    Prepared

    Raises
    ------
    ValueError
        ``config`` holds several pad sizes: each is prepared apart (:meth:`DesignConfig.pad_size_configs`).
    """
    if len(config.sampler.pad_sizes()) > 1:
        raise ValueError("prepare() takes one pad size; design each of config.pad_size_configs() apart")
    report_progress = _progress_with_note(progress)
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    loaded = load_batch(parts, config, repair)
    warnings = list(dict.fromkeys(w for p in loaded for w in p.warnings))
    finger = flat_finger(config, repair=repair)
    timings["load"] = time.perf_counter() - clock

    clock = time.perf_counter()
    scenarios = _choose_scenarios(loaded, config, warnings)
    timings["poses"] = time.perf_counter() - clock

    jobs = resolve_jobs(config.search.jobs)
    clock = time.perf_counter()
    plate = finger_plate(finger, config.sampler, config.gripper)
    report_progress("sampling", 0, len(scenarios))
    # tasks of one scenario, yaw angle and every n-th pad position: with
    # few scenarios, interleaved positions still give each worker several
    # tasks of about equal size
    yaws = config.sampler.yaw_deg
    subsets = max(1, -(-_SAMPLE_TASKS_PER_WORKER * jobs // (len(scenarios) * len(yaws))))
    # closing square to side faces the configured yaws miss (a chamfer, a hexagon's face): samples on features
    extra_yaws = [
        face_yaws(s.mesh, yaws, config.sampler.min_contact_area) if config.sampler.face_yaws else [] for s in scenarios
    ]
    sample_tasks = [
        (number, yaw, (k, subsets), yaw in extra_yaws[number])
        for number in range(len(scenarios))
        for yaw in yaws + extra_yaws[number]
        for k in range(subsets)
    ]
    with WorkerPool((scenarios, config, plate), jobs, config.compute.scheduler) as pool:
        pieces = pool.map(_sample_task, sample_tasks)
    for number, scenario in enumerate(scenarios):
        scenario.sampler_result = _merge_sampler_results(
            [(yaw, r) for (n, yaw, _, _), r in zip(sample_tasks, pieces) if n == number]
        )
    report_progress("sampling", len(scenarios), len(scenarios))
    timings["sampling"] = time.perf_counter() - clock
    empty = [s for s in scenarios if not s.sampler_result.samples]
    if len(empty) == len(scenarios):
        raise NoGraspError("; ".join(_no_grasp_message(s, config) for s in empty))
    ungraspable = [ungraspable_report(s, config) for s in empty]
    for entry in ungraspable:
        warnings.append(
            f"{entry.part} in stable pose {entry.pose_index} cannot be grasped and is left out: {entry.reason}"
        )
    scenarios = [s for s in scenarios if s.sampler_result.samples]

    clock = time.perf_counter()
    grid, lattice = ScreenGrid.for_config(config), NormalLattice()
    tasks = [
        (number, start, min(start + _GEOMETRY_CHUNK, len(s.sampler_result.samples)))
        for number, s in enumerate(scenarios)
        for start in range(0, len(s.sampler_result.samples), _GEOMETRY_CHUNK)
    ]
    total_samples = sum(len(s.sampler_result.samples) for s in scenarios)
    report_progress("pad geometries", 0, total_samples)
    with WorkerPool((scenarios, config, grid, lattice), jobs, config.compute.scheduler) as pool:
        for (number, _, _), made in zip(tasks, pool.map(_geometry_task, tasks)):
            scenarios[number].samples.extend(made)
            report_progress("pad geometries", sum(len(x.samples) for x in scenarios), total_samples)
    timings["pad_geometries"] = time.perf_counter() - clock

    return Prepared(loaded, finger, scenarios, ungraspable, lattice, jobs, warnings, timings)


def screen_choice(prepared: Prepared, choice: Sequence[int], config: DesignConfig) -> ScreenedCandidate:
    """Screened quality of one candidate (METHOD §8b), one sample index per scenario."""
    return screen([prepared.scenarios[m].samples[k].screen for m, k in enumerate(choice)], config, prepared.lattice)


def evaluate_exact(prepared: Prepared, choice: Sequence[int], config: DesignConfig) -> CandidateEvaluation:
    """Exact quality of one candidate (METHOD §6-7), one sample index per scenario."""
    return evaluate_candidate(prepared.scenarios, tuple(choice), config, keep_pad=False)


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
    report_progress = _progress_with_note(progress)
    report_progress("fingers", 0, len(candidates), f"{len(missing)} printed-fit pockets")
    cache = {} if pads is None else pads
    # each candidate's pad is built and opened as soon as its own pockets are carved, while other pockets are still
    # being carved: one long carving or one large pad no longer leaves the other workers waiting (the union of a large
    # set's pockets is minutes of Booleans)
    waiting: list[set[int]] = []  # per candidate, the missing pockets it waits for
    for (scenarios, choice), fitted_config in zip(candidates, configs):
        used = {(number[id(s)], k) for s, k in zip(scenarios, choice)}
        angle = fitted_config.print.lead_in_deg
        waiting.append({m for m, (n, k, a) in enumerate(missing) if (n, k) in used and a == angle})
    keys: list[str | None] = [None] * len(candidates)
    started: set[str] = set()

    def pad_tasks(ready: list[int]) -> list[tuple]:
        tasks = []
        for c in ready:
            (scenarios, choice), fitted_config = candidates[c], configs[c]
            samples = [s.samples[k] for s, k in zip(scenarios, choice)]
            keys[c] = pad_key(samples, fitted_config, flat)
            # a pad carved by several candidates is made once
            if keys[c] in cache or keys[c] in started:
                continue
            started.add(keys[c])
            fit = fit_key(fitted_config)
            pockets = (
                {}
                if flat or fit is None
                else {(number[id(s)], k): s.samples[k].fitted[fit] for s, k in zip(scenarios, choice)}
            )
            item = ([number[id(s)] for s in scenarios], choice, fitted_config.print.lead_in_deg, pockets)
            tasks.append((_pad_task, item, ("pad", keys[c])))
        return tasks

    finished: dict[int, tuple] = {}

    def finish_made() -> None:
        # each candidate is evaluated on its pad here as soon as the pad is made, while the workers open the others
        for c, ((scenarios, choice), fitted_config, (_, why)) in enumerate(zip(candidates, configs, fits)):
            if c not in finished and keys[c] in cache:
                fingerpad = Fingerpad(solid_from_mesh_arrays(*cache[keys[c]][0]), *cache[keys[c]][1:])
                finished[c] = _finished(scenarios, choice, fitted_config, flat, fingerpad, why, known[c])
                if on_finished is not None:
                    on_finished(c, finished[c])

    def on_done(tag: tuple, result) -> list[tuple]:
        kind, what = tag
        if kind == "pad":
            cache[what] = result
            finish_made()
            return []
        n, k, angle = missing[what]
        shared[n].samples[k].fitted[fit_key(_with_lead_in(config, angle))] = result
        ready = []
        for c, needs in enumerate(waiting):
            if what in needs:
                needs.discard(what)
                if not needs:
                    ready.append(c)
        return pad_tasks(ready)

    tasks = [(_fit_task, item, ("pocket", m)) for m, item in enumerate(missing)]
    tasks += pad_tasks([c for c, needs in enumerate(waiting) if not needs])
    workers = min(jobs, len(missing) + len(candidates))
    with WorkerPool((shared, config, flat), workers, config.compute.scheduler) as pool:
        finish_made()
        pool.run(tasks, on_done)
    finish_made()
    report_progress("fingers", len(candidates), len(candidates), "")
    return [finished[c] for c in range(len(candidates))]


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


def design(
    parts: Sequence[Part | str | Path],
    config: DesignConfig | None = None,
    progress: Progress | None = None,
    repair: bool = False,
) -> DesignResult:
    """Design one fingerpad and finger for a batch of parts (METHOD §1-9).

    Parameters
    ----------
    parts : sequence of Part or path
        The parts; paths are loaded in mm with :func:`fcso.load_parts` (a
        file may give several parts; load them yourself for other units or
        scaling).
    config : DesignConfig, optional
        Settings; defaults reproduce the paper's set-up.
    progress : callable, optional
        ``progress(stage, done, total, note)``.
    repair : bool
        Repair part and finger meshes that are not closed volumes.

    Returns
    -------
    DesignResult

    Raises
    ------
    MeshError, ConfigError
        Bad input, naming the file and the defect.
    NoGraspError
        No scenario has a valid sample. Scenarios without one are left out
        and listed in the report's ``ungraspable`` when others can be served.
    """
    config = config or DesignConfig()

    def design_one_size(sized: DesignConfig) -> DesignResult:
        return design_prepared(prepare(parts, sized, progress=progress, repair=repair), sized, progress)

    def score(result: DesignResult) -> SizeScore:
        chosen = chosen_candidate(result.report)
        flat = result.report.finger.flat_pads
        return SizeScore((not flat, chosen.quality, chosen.mean_effective_area), chosen.quality, flat)

    result, sizes = best_pad_size(config, design_one_size, score, progress)
    result.report = result.report.model_copy(update={"pad_sizes": sizes})
    return result


def best_pad_size(
    config: DesignConfig,
    run: Callable[[DesignConfig], Designed],
    score: Callable[[Designed], SizeScore],
    progress: Progress | None = None,
) -> tuple[Designed, list[PadSizeReport]]:
    """Design with every pad size of ``[sampler]`` and keep the best (METHOD §3b).

    The two fingers carry one pad box, so a size is a choice for the whole
    design: each size is designed in full and they compete by ``score``.

    Parameters
    ----------
    config : DesignConfig
        Settings, ``length_mm`` / ``width_mm`` possibly lists.
    run : callable
        Designs with the settings of one size (:meth:`DesignConfig.pad_size_configs`).
    score : callable
        A result's :class:`SizeScore`: the largest rank is delivered, the first size on a tie.
    progress : callable, optional
        ``progress("pad size", done, total, note)`` when there are several sizes.

    Returns
    -------
    result, sizes
        The best size's result and every size's entry for the report.

    Raises
    ------
    NoGraspError
        No size can grasp any part (the first size's error).
    """
    report_progress = _progress_with_note(progress)
    sized = config.pad_size_configs()
    results: list[Designed | None] = []
    notes: list[str | None] = []
    for number, one in enumerate(sized):
        if len(sized) > 1:
            report_progress(
                "pad size", number, len(sized), f"{one.sampler.length_mm:g} x {one.sampler.width_mm:g} mm pads"
            )
        try:
            results.append(run(one))
            notes.append(None)
        except NoGraspError as error:
            if len(sized) == 1:
                raise
            results.append(None)
            notes.append(f"no grasp: {error}")
    if all(r is None for r in results):
        raise NoGraspError(f"no pad size grasps any part: {notes[0]}")
    scores = [score(r) if r is not None else None for r in results]
    chosen = max((k for k in range(len(sized)) if scores[k] is not None), key=lambda k: (scores[k].rank, -k))
    if len(sized) > 1:
        report_progress("pad size", len(sized), len(sized), "")
    entries = [
        PadSizeReport(
            length_mm=one.sampler.length_mm,
            width_mm=one.sampler.width_mm,
            quality=rounded(scores[k].quality) if scores[k] is not None else None,
            flat_pads=scores[k] is not None and scores[k].flat_pads,
            chosen=k == chosen,
            note=notes[k],
        )
        for k, one in enumerate(sized)
    ]
    return results[chosen], entries


def subset(prepared: Prepared, scenario_numbers: Sequence[int]) -> Prepared:
    """The prepared batch reduced to some of its scenarios, for designing a finger for them alone (METHOD §11).

    Samples, pad geometries and their contact-sample seeds stay those of the
    whole batch, so a scenario is evaluated the same in every subset.

    Parameters
    ----------
    prepared : Prepared
    scenario_numbers : sequence of int
        Positions in ``prepared.scenarios``, in increasing order.

    Returns
    -------
    Prepared
        Its parts are the parts of those scenarios, its ungraspable entries
        theirs; warnings and timings are left to the whole batch.
    """
    scenarios = [prepared.scenarios[m] for m in scenario_numbers]
    indices = sorted({s.part_index for s in scenarios})
    names = {prepared.parts[i].name for i in indices}
    return dataclasses.replace(
        prepared,
        parts=[prepared.parts[i] for i in indices],
        scenarios=scenarios,
        ungraspable=[u for u in prepared.ungraspable if u.part in names],
        warnings=[],
        timings_s={},
    )


def design_prepared(prepared: Prepared, config: DesignConfig, progress: Progress | None = None) -> DesignResult:
    """Search, re-evaluate and fuse: :func:`design` after :func:`prepare` (METHOD §6-9).

    Parameters
    ----------
    prepared : Prepared
        From :func:`prepare`, or a :func:`subset` of it.
    config : DesignConfig
        The settings ``prepared`` was made with.
    progress : callable, optional
        ``progress(stage, done, total, note)``.

    Returns
    -------
    DesignResult
    """
    return finish_design(prepared, choose_candidate(prepared, config, progress), config, progress)


@dataclass
class ChosenCandidate:
    """A design's search and exact re-evaluation done (METHOD §6-8), its finger not yet made (:func:`finish_design`).

    Attributes
    ----------
    choice : tuple of int
        The chosen candidate: one sample per scenario.
    candidate : CandidateReport
        Its entry as ``report.json`` lists it (exact figures per scenario).
    """

    choice: tuple[int, ...]
    candidate: CandidateReport
    outcome: SearchOutcome = dataclasses.field(repr=False)
    ranked: list[tuple[int, ...]] = dataclasses.field(repr=False)
    exact: dict[tuple[int, ...], CandidateEvaluation] = dataclasses.field(repr=False)
    #: per-scenario screened values of the report's listed candidates kept from the search (:func:`listed_screens`
    #: screens the others)
    kept_screens: dict[tuple[int, ...], ScreenedCandidate] = dataclasses.field(repr=False)
    indices: dict[tuple[int, ...], int] = dataclasses.field(repr=False)
    upper_bound: float = 0.0
    warnings: list[str] = dataclasses.field(default_factory=list, repr=False)
    timings_s: dict[str, float] = dataclasses.field(default_factory=dict, repr=False)


def choose_candidate(prepared: Prepared, config: DesignConfig, progress: Progress | None = None) -> ChosenCandidate:
    """The search and exact re-evaluation of :func:`design_prepared`: its choice, before any finger is made.

    A finger set judged by its exact figures (METHOD §11 revision 3) needs only these; its printed-fit pockets and
    fused finger (:func:`finish_design`) are made when the set is delivered.

    Parameters
    ----------
    prepared, config, progress
        As for :func:`design_prepared`.

    Returns
    -------
    ChosenCandidate
    """
    report_progress = _progress_with_note(progress)
    scenarios, jobs = prepared.scenarios, prepared.jobs
    warnings, timings = list(prepared.warnings), dict(prepared.timings_s)

    clock = time.perf_counter()
    counts = [len(s.samples) for s in scenarios]
    total = int(np.prod(counts, dtype=object))
    budget = config.search.max_exhaustive if total <= config.search.max_exhaustive else config.search.max_evaluations
    expected = min(total, budget)
    screened_bounds = [np.array([g.screened_bound for g in s.samples]) for s in scenarios]
    screen_data = _screen_context(prepared, config)
    screened_count, best_screened = 0, 0.0
    screened_bound = quality_upper_bound(screened_bounds)
    # when every candidate the search screens is listed in the report, keep
    # their per-scenario values as they are screened instead of screening again
    keep_screens = expected <= config.search.report_candidates
    kept_screens: dict[tuple[int, ...], ScreenedCandidate] = {}
    with WorkerPool(screen_data, jobs, config.compute.scheduler) as pool:

        def evaluate(choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
            nonlocal screened_count, best_screened
            # a batch under a chunk per worker is split among them: the coordinate ascent's batches are a few dozen
            # candidates, and one chunk ran in this process while the workers waited (the 12-part job: 200 such
            # batches, 1.2 s)
            size = min(_SCREEN_CHUNK, -(-len(choices) // jobs))
            chunks = [choices[i : i + size] for i in range(0, len(choices), size)]
            if keep_screens:
                screened = [c for chunk in pool.map(_screen_batch, chunks) for c in chunk]
                kept_screens.update(zip(choices, screened))
                scored = [(c.quality, c.mean_effective_area) for c in screened]
            else:
                scored = [pair for chunk in pool.map(_screen_task, chunks) for pair in chunk]
            screened_count += len(choices)
            best_screened = max([best_screened] + [q for q, _ in scored])
            report_progress(
                "screening",
                min(screened_count, expected),
                expected,
                f"best {quality_words(best_screened, config.quality.measure)} of bound {screened_bound:.3g} (screened)",
            )
            return scored

        outcome = search(counts, screened_bounds, evaluate, config.search.max_exhaustive, config.search.max_evaluations)
        indices = {choice: candidate_index(choice, counts) for choice in outcome.evaluated}
        ranked = sorted(
            outcome.evaluated,
            key=lambda c: (outcome.evaluated[c][0], outcome.evaluated[c][1], -indices[c]),
            reverse=True,
        )
        if config.quality.measure == "capture":
            # the search ranked by each sample's own capture: the best are screened again on the candidate's pad
            top = ranked[: config.search.pad_top_k]
            chunks = [top[i : i + _PAD_CHUNK] for i in range(0, len(top), _PAD_CHUNK)]
            on_pad = dict(zip(top, (c for chunk in pool.map(_pad_batch, chunks) for c in chunk)))
            kept_screens.update(on_pad)
            ranked = rerank(ranked, {c: (s.quality, s.mean_effective_area) for c, s in on_pad.items()}, counts)
        finalists = ranked[: config.search.exact_top_k]
        # the report lists each screened candidate's per-scenario values: those not kept are screened again only
        # when the finger is made (:func:`listed_screens`): a finger set judged and not delivered never needs them
        listed = ranked[config.search.exact_top_k : config.search.report_candidates]
        kept = {c: kept_screens[c] for c in listed if c in kept_screens}
    report_progress("screening", expected, expected)
    timings["screening"] = time.perf_counter() - clock

    clock = time.perf_counter()
    report_progress("exact", 0, len(finalists))
    with WorkerPool((scenarios, config), jobs, config.compute.scheduler) as pool:
        exact = dict(zip(finalists, pool.map(_exact_task, finalists)))
    report_progress(
        "exact",
        len(finalists),
        len(finalists),
        f"best {quality_words(max(e.quality for e in exact.values()), config.quality.measure)} (exact)",
    )
    best_choice = max(finalists, key=lambda c: (exact[c].quality, exact[c].mean_effective_area, -indices[c]))
    upper_bound = max(
        quality_upper_bound(
            [
                np.array([scenario_measure(1.0, 1.0, g.effective_area_bound, config) for g in s.samples])
                for s in scenarios
            ]
        ),
        exact[best_choice].quality,
    )
    if not outcome.proven_optimal:
        warnings.append(
            f"search screened {len(outcome.evaluated)} of {outcome.total} candidates (search.max_evaluations) "
            f"without proving the best optimal; Q is {exact[best_choice].quality / upper_bound:.0%} of its upper bound"
        )
    timings["exact"] = time.perf_counter() - clock
    candidate = candidate_reports([best_choice], {best_choice: exact[best_choice]}, {}, indices)[0]
    return ChosenCandidate(
        best_choice, candidate, outcome, ranked, exact, kept, indices, upper_bound, warnings, timings
    )


def choose_candidates(
    prepared: Prepared,
    subsets: Sequence[Sequence[int]],
    config: DesignConfig,
    then: Callable[[Sequence[int], ChosenCandidate | GeometryError], Sequence[Sequence[int]]] | None = None,
    progress: Progress | None = None,
) -> list[ChosenCandidate | GeometryError]:
    """:func:`choose_candidate` of several :func:`subset` s of one batch, side by side.

    Each design runs whole on one worker, as ``jobs = 1`` would run it: a
    design's coordinate ascent screens a few dozen candidates a batch, too
    few to share out without leaving the workers waiting on each other,
    while several designs keep every worker busy. A design's choice does
    not depend on its number of workers. With one design and no ``then``,
    or on a cluster (``[compute] scheduler``), the designs run one after
    another, each over every worker.

    Parameters
    ----------
    prepared : Prepared
    subsets : sequence of sequence of int
        Scenario numbers of each design (positions in ``prepared.scenarios``, increasing).
    config : DesignConfig
    then : callable, optional
        ``then(numbers, chosen)``, called in this process as each design
        finishes (in the order they finish): further subsets to design
        beside the others; its answer must not depend on that order.
    progress : callable, optional
        Hears of each design's stages when they run one after another.

    Returns
    -------
    list of ChosenCandidate or GeometryError
        Per design, ``subsets`` first, then those ``then`` asked for in the
        order asked: the choice, or the error of a pad Boolean that failed.
    """
    follow = then or (lambda numbers, chosen: [])
    designs = [list(numbers) for numbers in subsets]
    chosen: dict[int, ChosenCandidate | GeometryError] = {}
    side_by_side = prepared.jobs > 1 and not config.compute.scheduler and (len(designs) > 1 or then is not None)
    waiting = [(_choose_task, numbers, n) for n, numbers in enumerate(designs)]

    def on_done(number: int, result: ChosenCandidate | GeometryError) -> list[tuple]:
        chosen[number] = result
        tasks = []
        for numbers in follow(designs[number], result):
            designs.append(list(numbers))
            tasks.append((_choose_task, designs[-1], len(designs) - 1))
        if side_by_side and len(designs) - len(chosen) == len(tasks) == 1:
            # a design asked for when every other is done runs on every worker, after
            waiting.extend(tasks)
            return []
        return tasks

    while waiting:
        tasks, waiting[:] = list(waiting), []
        # side by side, the workers are not told of progress: they cannot reach whoever listens
        workers = min(prepared.jobs, len(tasks) + (then is not None)) if side_by_side else 1
        with WorkerPool((prepared, config, side_by_side, None if side_by_side else progress), workers) as pool:
            pool.run(tasks, on_done)
        side_by_side = False
    return [chosen[n] for n in range(len(designs))]


@contextlib.contextmanager
def listed_screens(
    designs: Sequence[tuple[Prepared, ChosenCandidate]], config: DesignConfig
) -> Iterator[Callable[[], list[dict[tuple[int, ...], ScreenedCandidate]]]]:
    """Per-scenario screened values of the candidates each design's ``report.json`` lists after its exact finalists,
    screened on workers while this process goes on.

    Those the search kept (:attr:`ChosenCandidate.kept_screens`) are taken as they are; the others are screened again
    (screening is a function of the candidate: the same values), every design's on one pool of workers, from entering
    the context on.

    Parameters
    ----------
    designs : sequence of (Prepared, ChosenCandidate)
    config : DesignConfig

    Yields
    ------
    callable
        Waits for the screenings and returns, per design, candidate (one sample per scenario) -> its screening; to be
        called once, inside the context.
    """
    listed = [chosen.ranked[config.search.exact_top_k : config.search.report_candidates] for _, chosen in designs]
    known = [dict(chosen.kept_screens) for _, chosen in designs]
    tasks = []
    for number, candidates in enumerate(listed):
        missing = [c for c in candidates if c not in known[number]]
        tasks += [(number, missing[i : i + _SCREEN_CHUNK]) for i in range(0, len(missing), _SCREEN_CHUNK)]
    contexts = [_screen_context(prepared, config) for prepared, _ in designs] if tasks else []
    jobs = min(max(prepared.jobs for prepared, _ in designs), len(tasks))
    with WorkerPool(contexts, jobs, config.compute.scheduler if tasks else None) as pool:
        screened = pool.map_later(_listed_batch, tasks)

        def results() -> list[dict[tuple[int, ...], ScreenedCandidate]]:
            for (number, chunk), screens in zip(tasks, screened()):
                known[number].update(zip(chunk, screens))
            return [{c: screens[c] for c in candidates} for candidates, screens in zip(listed, known)]

        yield results


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


def _choose_scenarios(parts: list[Part], config: DesignConfig, warnings: list[str]) -> list[Scenario]:
    scenarios = []
    for part_index, part in enumerate(parts):
        transforms, probabilities = stable_poses(part.mesh)
        chosen, notes = select_poses(probabilities, config.poses, part_index, part.name)
        warnings.extend(notes)
        for pose in chosen:
            mesh = part.mesh.copy()
            mesh.apply_transform(transforms[pose])
            scenarios.append(
                Scenario(
                    part_index=part_index,
                    part=part,
                    pose_index=pose,
                    probability=float(probabilities[pose]),
                    rest_transform=transforms[pose],
                    mesh=mesh,
                    sampler_result=SamplerResult([], {}, 0),
                )
            )
    return scenarios


def _no_grasp_message(scenario: Scenario, config: DesignConfig) -> str:
    rejected = (
        ", ".join(f"{k} {v}" for k, v in scenario.sampler_result.rejected.items() if v) or "no footprint met the part"
    )
    return (
        f"{scenario.part.path}: no valid grasp in stable pose {scenario.pose_index} "
        f"(rejected: {rejected}; gripper opening {config.gripper.max_opening_mm:g} mm)"
    )


def _progress_with_note(progress: Progress | None) -> Progress:
    """``progress`` with its note optional, or a no-op."""
    if progress is None:
        return lambda stage, done, total, note="": None
    return lambda stage, done, total, note="": progress(stage, done, total, note)


def _sample_task(context, task: tuple[int, float, tuple[int, int], bool]) -> SamplerResult:
    scenarios, config, plate = context
    number, yaw, centres, face_yaw = task
    sampler = config.sampler.model_copy(update={"yaw_deg": [yaw]})
    result = sample_grasps(scenarios[number].mesh, sampler, config.gripper, plate, centres)
    if face_yaw:
        result.samples = [dataclasses.replace(sample, on_feature=True) for sample in result.samples]
    return result


def _merge_sampler_results(results: list[tuple[float, SamplerResult]]) -> SamplerResult:
    """One scenario's sampler result from its results per yaw angle and subset of pad positions, in (yaw, s, h)
    order.
    """
    rejected = {reason: sum(r.rejected[reason] for _, r in results) for reason in results[0][1].rejected}
    yaws = list(dict.fromkeys(yaw for yaw, _ in results))
    # each position lies in one subset, its samples in h order: a stable sort by s restores (s, h)
    samples = [
        sample
        for yaw in yaws
        for sample in sorted((x for y, r in results if y == yaw for x in r.samples), key=lambda x: x.s_mm)
    ]
    return SamplerResult(samples, rejected, sum(r.tried for _, r in results))


def _geometry_task(context, task: tuple[int, int, int]) -> list[SampleGeometry]:
    scenarios, config, grid, lattice = context
    number, start, stop = task
    scenario = scenarios[number]
    part_manifold = to_manifold(scenario.mesh)
    return [
        sample_geometry(
            part_manifold, scenario.mesh, scenario.sampler_result.samples[index], config, (number, index), grid, lattice
        )
        for index in range(start, stop)
    ]


def _screen_context(prepared: Prepared, config: DesignConfig) -> tuple:
    """What the screening workers share (:func:`_screen_batch`, :func:`_pad_batch`): every sample's screening
    geometries, the scenarios, the settings and the normal lattice."""
    scenarios = prepared.scenarios
    return [[g.screen for g in s.samples] for s in scenarios], scenarios, config, prepared.lattice


def _with_lead_in(config: DesignConfig, lead_in_deg: float) -> DesignConfig:
    """``config`` with the pockets drafted by ``lead_in_deg`` (a candidate printed with a wider lead-in)."""
    return (
        config if lead_in_deg == config.print.lead_in_deg else config.updated({"print": {"lead_in_deg": lead_in_deg}})
    )


def _screen_batch(context, choices: list[tuple[int, ...]]) -> list[ScreenedCandidate]:
    screens, _, config, lattice = context
    # a batch of coordinate moves shares every scenario but one: carve those once
    first = choices[0]
    shared = [m for m in range(len(first)) if all(choice[m] == first[m] for choice in choices)]
    carved = (
        carve_heights([screens[m][k] for m, k in enumerate(first)], shared)
        if len(choices) > 1 and len(shared) > 1
        else None
    )
    return [screen([screens[m][k] for m, k in enumerate(choice)], config, lattice, carved) for choice in choices]


def _listed_batch(contexts, task: tuple[int, list[tuple[int, ...]]]) -> list[ScreenedCandidate]:
    """:func:`_screen_batch` of one design of :func:`listed_screens`: ``task`` is (design number, candidates)."""
    number, choices = task
    return _screen_batch(contexts[number], choices)


def _pad_batch(context, choices: list[tuple[int, ...]]) -> list[ScreenedCandidate]:
    _, scenarios, config, lattice = context
    return [screen_on_pad(scenarios, choice, config, lattice) for choice in choices]


def _screen_task(context, choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
    return [(c.quality, c.mean_effective_area) for c in _screen_batch(context, choices)]


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


def _exact_task(context, choice: tuple[int, ...]) -> CandidateEvaluation:
    scenarios, config = context
    return evaluate_candidate(scenarios, choice, config, keep_pad=False)


def _choose_task(context, numbers: list[int]) -> ChosenCandidate | GeometryError:
    """:func:`choose_candidate` of one subset of :func:`choose_candidates`, in this one process when side by side."""
    prepared, config, side_by_side, progress = context
    one = subset(prepared, numbers)
    try:
        return choose_candidate(dataclasses.replace(one, jobs=1) if side_by_side else one, config, progress)
    except GeometryError as error:
        return error
