"""The FCSO pipeline: parts in, fingerpad, finger and quality table out."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import manifold3d
import numpy as np
import trimesh

from . import __version__
from .config import DesignConfig
from .contact import PadContact, SurfaceSamples, sample_surface, seat
from .errors import NoGraspError
from .finger import FlatFinger, finger_plate, fuse, load_finger, pad_to_finger, parametric_finger
from .geometry import to_manifold, to_trimesh
from .grasps import tcp_pose
from .pad import Fingerpad, PadGeometry, build_fingerpad, pad_geometry
from .parts import Part, load_parts
from .poses import select_poses, stable_poses
from .printfit import carve, closing_travel_mm, open_thin_walls, thinnest_wall_mm
from .report import (
    CandidateReport,
    DesignReport,
    FingerReport,
    GraspReport,
    PartReport,
    PrintFitEffect,
    PrintFitReport,
    RepairReport,
    SampleReport,
    ScenarioQuality,
    ScenarioReport,
    SearchReport,
    UngraspableReport,
)
from .rles import rles
from .parallel import WorkerPool, resolve_jobs
from .sampler import SIDES, GraspSample, SamplerResult, sample_grasps
from .screen import NormalLattice, ScreenedCandidate, ScreenGeometry, ScreenGrid, carve_heights, column_heights, prepare_geometry, screen, screened_bound
from .search import candidate_index, quality_upper_bound, search

#: ``progress(stage, done, total, note)``: called as long work advances; ``note``
#: says more in words (the best screened Q and the upper bound while searching).
Progress = Callable[[str, int, int, str], None]

#: Samples per pad-geometry task and candidates per screening task sent to a worker.
_GEOMETRY_CHUNK = 4
_SCREEN_CHUNK = 64
#: Sampling tasks per worker to aim for when scenarios and yaws are few.
_SAMPLE_TASKS_PER_WORKER = 4


@dataclass
class SampleGeometry:
    """A valid sample with everything candidate evaluation needs from it."""

    sample: GraspSample
    frames: tuple[np.ndarray, np.ndarray]
    geometries: tuple[PadGeometry, PadGeometry]
    surfaces: tuple[SurfaceSamples, SurfaceSamples]
    effective_area_bound: float
    screen: tuple[ScreenGeometry, ScreenGeometry]
    screened_bound: float


@dataclass
class Scenario:
    """A part in one chosen stable pose, with its valid samples."""

    part_index: int
    part: Part
    pose_index: int
    probability: float
    rest_transform: np.ndarray
    mesh: trimesh.Trimesh
    sampler_result: SamplerResult
    samples: list[SampleGeometry] = field(default_factory=list)


@dataclass
class ScenarioEvaluation:
    """One candidate in one scenario: seating of both pads and the quality."""

    contacts: tuple[PadContact, PadContact]
    contact_normals: np.ndarray
    rles: float
    contact_area_mm2: float
    effective_area: float


@dataclass
class CandidateEvaluation:
    """A candidate evaluated exactly (METHOD §6-7); ``fingerpad`` only when asked to keep it."""

    choice: tuple[int, ...]
    scenarios: list[ScenarioEvaluation]
    quality: float
    mean_effective_area: float
    case: str
    block_depth_mm: float | None
    fingerpad: Fingerpad | None = None


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


def prepare(parts: Sequence[Part | str | Path], config: DesignConfig, progress: Progress | None = None, repair: bool = False) -> Prepared:
    """Load, pose, sample and intersect: everything before the search (METHOD §1-5).

    Parameters and errors as :func:`design`.

    Returns
    -------
    Prepared
    """
    report_progress = _progress_with_note(progress)
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    loaded = [
        one
        for p in parts
        for one in ([p] if isinstance(p, Part) else load_parts(p, repair=repair, split_bodies=config.parts.split_bodies))
    ]
    warnings = list(dict.fromkeys(w for p in loaded for w in p.warnings))
    finger = load_finger(config.finger, repair=repair) if config.finger.mesh else parametric_finger(config.sampler, config.gripper)
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
    sample_tasks = [(number, yaw, (k, subsets)) for number in range(len(scenarios)) for yaw in yaws for k in range(subsets)]
    with WorkerPool((scenarios, config, plate), jobs) as pool:
        pieces = pool.map(_sample_task, sample_tasks)
    for number, scenario in enumerate(scenarios):
        scenario.sampler_result = _merge_sampler_results([(yaw, r) for (n, yaw, _), r in zip(sample_tasks, pieces) if n == number])
    report_progress("sampling", len(scenarios), len(scenarios))
    timings["sampling"] = time.perf_counter() - clock
    empty = [s for s in scenarios if not s.sampler_result.samples]
    if len(empty) == len(scenarios):
        raise NoGraspError("; ".join(_no_grasp_message(s, config) for s in empty))
    ungraspable = [_ungraspable_report(s, config) for s in empty]
    for entry in ungraspable:
        warnings.append(f"{entry.part} in stable pose {entry.pose_index} cannot be grasped and is left out: {entry.reason}")
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
    with WorkerPool((scenarios, config, grid, lattice), jobs) as pool:
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
    return _evaluate(prepared.scenarios, tuple(choice), config, keep_pad=False)


def finish_candidate(
    scenarios: list[Scenario], choice: Sequence[int], config: DesignConfig
) -> tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """One candidate built as :func:`design` builds its choice: carved with ``[print]``'s fit, its pad kept.

    Returns the fitted evaluation, its grasps and print-fit report as
    ``report.json`` lists them, and the print-fit warnings.
    """
    choice = tuple(choice)
    fitted = _evaluate(scenarios, choice, config, keep_pad=True, fitted=True)
    warnings: list[str] = []
    print_fit = _print_fit_report(scenarios, choice, fitted, config, warnings)
    return fitted, [_grasp_report(s, k, e, config) for s, k, e in zip(scenarios, choice, fitted.scenarios)], print_fit, warnings


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
    prepared = prepare(parts, config, progress=progress, repair=repair)
    return design_prepared(prepared, config, progress)


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
    report_progress = _progress_with_note(progress)
    scenarios, lattice, jobs = prepared.scenarios, prepared.lattice, prepared.jobs
    loaded, finger, ungraspable = prepared.parts, prepared.finger, prepared.ungraspable
    warnings, timings = list(prepared.warnings), dict(prepared.timings_s)

    clock = time.perf_counter()
    counts = [len(s.samples) for s in scenarios]
    total = int(np.prod(counts, dtype=object))
    budget = config.search.max_exhaustive if total <= config.search.max_exhaustive else config.search.max_evaluations
    expected = min(total, budget)
    screened_bounds = [np.array([g.screened_bound for g in s.samples]) for s in scenarios]
    screen_data = ([[g.screen for g in s.samples] for s in scenarios], config, lattice)
    screened_count, best_screened = 0, 0.0
    screened_bound = quality_upper_bound(screened_bounds)
    # when every candidate the search screens is listed in the report, keep
    # their per-scenario values as they are screened instead of screening again
    keep_screens = expected <= config.search.report_candidates
    kept_screens: dict[tuple[int, ...], ScreenedCandidate] = {}
    with WorkerPool(screen_data, jobs) as pool:

        def evaluate(choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
            nonlocal screened_count, best_screened
            chunks = [choices[i : i + _SCREEN_CHUNK] for i in range(0, len(choices), _SCREEN_CHUNK)]
            if keep_screens:
                screened = [c for chunk in pool.map(_screen_batch, chunks) for c in chunk]
                kept_screens.update(zip(choices, screened))
                scored = [(c.quality, c.mean_effective_area) for c in screened]
            else:
                scored = [pair for chunk in pool.map(_screen_task, chunks) for pair in chunk]
            screened_count += len(choices)
            best_screened = max([best_screened] + [q for q, _ in scored])
            report_progress("screening", min(screened_count, expected), expected, f"best Q {best_screened:.1f} of bound {screened_bound:.1f} mm² (screened)")
            return scored

        outcome = search(counts, screened_bounds, evaluate, config.search.max_exhaustive, config.search.max_evaluations)
        indices = {choice: candidate_index(choice, counts) for choice in outcome.evaluated}
        ranked = sorted(outcome.evaluated, key=lambda c: (outcome.evaluated[c][0], outcome.evaluated[c][1], -indices[c]), reverse=True)
        finalists = ranked[: config.search.exact_top_k]
        # the report lists each screened candidate's per-scenario values: screen those not kept again, on every core
        listed = ranked[config.search.exact_top_k : config.search.report_candidates]
        missing = [c for c in listed if c not in kept_screens]
        chunks = [missing[i : i + _SCREEN_CHUNK] for i in range(0, len(missing), _SCREEN_CHUNK)]
        kept_screens.update(zip(missing, (c for chunk in pool.map(_screen_batch, chunks) for c in chunk)))
        listed_screens = {c: kept_screens[c] for c in listed}
    report_progress("screening", expected, expected)
    timings["screening"] = time.perf_counter() - clock

    clock = time.perf_counter()
    report_progress("exact", 0, len(finalists))
    with WorkerPool((scenarios, config), jobs) as pool:
        exact = dict(zip(finalists, pool.map(_exact_task, finalists)))
    report_progress("exact", len(finalists), len(finalists), f"best Q {max(e.quality for e in exact.values()):.1f} mm² (exact)")
    best_choice = max(finalists, key=lambda c: (exact[c].quality, exact[c].mean_effective_area, -indices[c]))
    upper_bound = max(quality_upper_bound([np.array([g.effective_area_bound for g in s.samples]) for s in scenarios]), exact[best_choice].quality)
    if not outcome.proven_optimal:
        warnings.append(
            f"search screened {len(outcome.evaluated)} of {outcome.total} candidates (search.max_evaluations) "
            f"without proving the best optimal; Q is {exact[best_choice].quality / upper_bound:.0%} of its upper bound"
        )
    timings["exact"] = time.perf_counter() - clock

    clock = time.perf_counter()
    best, grasps, print_fit, fit_warnings = finish_candidate(scenarios, best_choice, config)
    transform = pad_to_finger(finger, config.sampler)
    fused = fuse(finger, best.fingerpad.pad, config.sampler, config.finger.overlap_mm)
    # a clearance deepens the pocket by c: the carving demands that much less
    floor = config.sampler.thickness_mm - config.sampler.penetration_mm - config.print.resolved()["clearance_mm"]
    if fused.min_pad_thickness_mm < floor - 1e-3:
        warnings.append(f"thinnest pad section is {fused.min_pad_thickness_mm:.3f} mm, below T - D - clearance = {floor:.3f} mm")
    warnings.extend(fit_warnings)
    timings["finger"] = time.perf_counter() - clock

    report = DesignReport(
        fcso_version=__version__,
        parts=[_part_report(p) for p in loaded],
        scenarios=[_scenario_report(s) for s in scenarios],
        candidates=_candidate_reports(ranked[: config.search.report_candidates], exact, listed_screens, indices),
        best=indices[best_choice],
        search=SearchReport(
            kind=outcome.kind,
            evaluated=len(outcome.evaluated),
            screened=len(outcome.evaluated),
            exact=len(exact),
            candidates_total=outcome.total,
            proven_optimal=outcome.proven_optimal,
            jobs=jobs,
            quality_upper_bound=_round(upper_bound),
            gap=_round(exact[best_choice].quality / upper_bound) if upper_bound > 0 else 1.0,
        ),
        grasps=grasps,
        ungraspable=ungraspable,
        finger=FingerReport(
            source=finger.source,
            repairs=finger.repairs,
            volume_mm3=_round(fused.volume_mm3),
            bodies=fused.bodies,
            watertight=bool(fused.mesh.is_watertight),
            min_pad_thickness_mm=_round(fused.min_pad_thickness_mm),
        ),
        timings_s={k: round(v, 3) for k, v in timings.items()},
        warnings=warnings,
        settings=config,
        print_fit=print_fit,
    )
    return DesignResult(
        report=report,
        finger=fused.mesh,
        fingerpad=to_trimesh(best.fingerpad.pad),
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
    rejected = ", ".join(f"{k} {v}" for k, v in scenario.sampler_result.rejected.items() if v) or "no footprint met the part"
    return (
        f"{scenario.part.path}: no valid grasp in stable pose {scenario.pose_index} "
        f"(rejected: {rejected}; gripper opening {config.gripper.max_opening_mm:g} mm)"
    )


#: One sentence per rejection reason, for a scenario that reason emptied.
_REJECTION_SENTENCES = {
    "contact": "no pad box holds the least contact area ({area:g} mm² per side) on both sides",
    "fit": "wherever the pads meet it, the part is too wide for the open gripper ({opening:g} mm) or too narrow to close on",
    "collision_finger": "the finger plate behind every pad would hit the part",
    "collision_descent": "the open fingers would hit the part on their way down",
}


def _ungraspable_report(scenario: Scenario, config: DesignConfig) -> UngraspableReport:
    result = scenario.sampler_result
    if result.tried == 0:
        reason = "no pad footprint meets the part above the table clearance"
    else:
        worst = max(result.rejected, key=lambda k: result.rejected[k])
        reason = _REJECTION_SENTENCES[worst].format(area=config.sampler.min_contact_area, opening=config.gripper.max_opening_mm)
        reason = f"{reason} ({result.rejected[worst]} of {result.tried} samples)"
    return UngraspableReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        tried_samples=result.tried,
        rejected=dict(result.rejected),
        reason=reason,
    )


def _progress_with_note(progress: Progress | None) -> Progress:
    """``progress`` with its note optional, or a no-op."""
    if progress is None:
        return lambda stage, done, total, note="": None
    return lambda stage, done, total, note="": progress(stage, done, total, note)


def _sample_task(context, task: tuple[int, float, tuple[int, int]]) -> SamplerResult:
    scenarios, config, plate = context
    number, yaw, centres = task
    sampler = config.sampler.model_copy(update={"yaw_deg": [yaw]})
    return sample_grasps(scenarios[number].mesh, sampler, config.gripper, plate, centres)


def _merge_sampler_results(results: list[tuple[float, SamplerResult]]) -> SamplerResult:
    """One scenario's sampler result from its results per yaw angle and subset of pad positions, in (yaw, s, h) order."""
    rejected = {reason: sum(r.rejected[reason] for _, r in results) for reason in results[0][1].rejected}
    yaws = list(dict.fromkeys(yaw for yaw, _ in results))
    # each position lies in one subset, its samples in h order: a stable sort by s restores (s, h)
    samples = [
        sample for yaw in yaws for sample in sorted((x for y, r in results if y == yaw for x in r.samples), key=lambda x: x.s_mm)
    ]
    return SamplerResult(samples, rejected, sum(r.tried for _, r in results))


def _geometry_task(context, task: tuple[int, int, int]) -> list[SampleGeometry]:
    scenarios, config, grid, lattice = context
    number, start, stop = task
    scenario = scenarios[number]
    part_manifold = to_manifold(scenario.mesh)
    return [
        _sample_geometry(part_manifold, scenario.mesh, scenario.sampler_result.samples[index], config, (number, index), grid, lattice)
        for index in range(start, stop)
    ]


def _screen_batch(context, choices: list[tuple[int, ...]]) -> list[ScreenedCandidate]:
    screens, config, lattice = context
    # a batch of coordinate moves shares every scenario but one: carve those once
    first = choices[0]
    shared = [m for m in range(len(first)) if all(choice[m] == first[m] for choice in choices)]
    carved = carve_heights([screens[m][k] for m, k in enumerate(first)], shared) if len(choices) > 1 and len(shared) > 1 else None
    return [screen([screens[m][k] for m, k in enumerate(choice)], config, lattice, carved) for choice in choices]


def _screen_task(context, choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
    return [(c.quality, c.mean_effective_area) for c in _screen_batch(context, choices)]


def _exact_task(context, choice: tuple[int, ...]) -> CandidateEvaluation:
    scenarios, config = context
    return _evaluate(scenarios, choice, config, keep_pad=False)


def _sample_geometry(
    part_manifold: manifold3d.Manifold, mesh: trimesh.Trimesh, sample: GraspSample, config: DesignConfig, seed, grid: ScreenGrid, lattice: NormalLattice
) -> SampleGeometry:
    frames = tuple(sample.pad_frame(side, config.sampler) for side in SIDES)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    geometries = tuple(pad_geometry(part_manifold, vertices, faces, f, config.sampler, config.filter) for f in frames)
    surfaces = tuple(
        contact_samples(g.surface_vertices, g.surface_faces, config, *seed, side_number) for side_number, g in enumerate(geometries)
    )
    # contact points and normals are subsets of these samples, so A <= the sampled
    # area and RLES >= the RLES of all sampled normals: E can never exceed this
    area = sum(len(s.points) * s.area_per_point_mm2 for s in surfaces)
    normals = np.vstack([s.normals @ f[:3, :3] for s, f in zip(surfaces, frames)])
    bound = area / rles(normals) if len(normals) else 0.0
    screens = tuple(
        prepare_geometry(
            column_heights(g.surface_vertices, g.surface_faces, grid),
            g.good,
            g.depth_mm,
            s.points,
            s.normals @ f[:3, :3],
            s.area_per_point_mm2,
            grid,
            lattice,
        )
        for g, s, f in zip(geometries, surfaces, frames)
    )
    return SampleGeometry(
        sample=sample,
        frames=frames,
        geometries=geometries,
        surfaces=surfaces,
        effective_area_bound=float(bound),
        screen=screens,
        screened_bound=screened_bound(screens, lattice),
    )


def contact_samples(
    vertices: np.ndarray, faces: np.ndarray, config: DesignConfig, scenario_number: int, sample_index: int, side_number: int
) -> SurfaceSamples:
    """The design's surface samples of one pad geometry.

    The seed is ``[contact.seed, scenario, sample, side]`` so a report can be
    rebuilt with exactly the samples the design used.

    Parameters
    ----------
    vertices, faces : ndarray
        Part surface inside the pad box, pad frame (:func:`fcso.pad.surface_in_pad`).
    config : DesignConfig
    scenario_number, sample_index, side_number : int
        Position of the scenario in the design, of the sample in the scenario,
        and the side (0: "+", 1: "-").
    """
    seed = [config.contact.seed, scenario_number, sample_index, side_number]
    return sample_surface(vertices, faces, config.contact.sample_density_per_mm2, seed)


def _evaluate(
    scenarios: list[Scenario], choice: tuple[int, ...], config: DesignConfig, keep_pad: bool, fitted: bool = False
) -> CandidateEvaluation:
    """Carve, seat and score one candidate (METHOD §4-7).

    ``fitted`` (the chosen candidate) carves with the clearance and lead-in
    of ``[print]``, removes thin walls and lets the pads close the clearance
    (:mod:`fcso.printfit`); the search ranks candidates on exact pockets.
    """
    chosen = [scenario.samples[k] for scenario, k in zip(scenarios, choice)]
    geometries = [g for sample in chosen for g in sample.geometries]
    fit = config.print.resolved()
    if fitted:
        geometries = _fitted_geometries(scenarios, chosen, config)
    fingerpad = build_fingerpad(geometries, config.sampler, config.filter)
    if fitted:
        sampler = config.sampler
        opened = open_thin_walls(fingerpad.pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm, fit["min_wall_mm"])
        fingerpad = Fingerpad(opened, fingerpad.case, fingerpad.block_depth_mm)
    pad_mesh = fingerpad.pad.to_mesh()
    vertices = np.asarray(pad_mesh.vert_properties[:, :3], dtype=np.float64)
    faces = np.asarray(pad_mesh.tri_verts, dtype=np.int64)
    travel = closing_travel_mm(fit["clearance_mm"]) if fitted else 0.0
    surfaces = [surface for sample in chosen for surface in sample.surfaces]
    seated = iter(seat(surfaces, vertices, faces, config.contact.eps_mm, travel_mm=travel))
    results = []
    for sample in chosen:
        contacts = (next(seated), next(seated))
        normals = np.vstack(
            [s.normals[c.contact] @ f[:3, :3] for s, c, f in zip(sample.surfaces, contacts, sample.frames)]
        )
        area = float(sum(c.contact_area_mm2 for c in contacts))
        radius = rles(normals) if len(normals) else 2.0
        effective = area / radius if area > 0 else 0.0
        results.append(ScenarioEvaluation(contacts, normals, radius, area, effective))
    effective_areas = [r.effective_area for r in results]
    return CandidateEvaluation(
        choice=choice,
        scenarios=results,
        quality=float(min(effective_areas)),
        mean_effective_area=float(np.mean(effective_areas)),
        case=fingerpad.case,
        block_depth_mm=fingerpad.block_depth_mm,
        fingerpad=fingerpad if keep_pad else None,
    )


def _fitted_geometries(scenarios: list[Scenario], chosen: list[SampleGeometry], config: DesignConfig) -> list[PadGeometry]:
    """The chosen samples' geometries with each good one's ``I_n`` replaced by its printed-fit carving."""
    fit = config.print.resolved()
    if fit["clearance_mm"] <= 0 and fit["lead_in_deg"] <= 0:
        return [g for sample in chosen for g in sample.geometries]
    sampler = config.sampler
    size = (sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    fitted = []
    for scenario, sample in zip(scenarios, chosen):
        part = to_manifold(scenario.mesh)
        for geometry, frame in zip(sample.geometries, sample.frames):
            if geometry.good:
                carved = carve(part, frame, size, sampler.penetration_mm, fit["clearance_mm"], fit["lead_in_deg"])
                geometry = dataclasses.replace(geometry, intersection=carved)
            fitted.append(geometry)
    return fitted


def _round(value: float) -> float:
    return round(float(value), 6)


def _print_fit_report(
    scenarios: list[Scenario], choice: tuple[int, ...], best: CandidateEvaluation, config: DesignConfig, warnings: list[str]
) -> PrintFitReport:
    """``[print]`` as used, the chosen pad's thinnest wall, and the chosen candidate exact (METHOD §4-6) and as printed."""
    fit = config.print.resolved()
    sampler = config.sampler
    exact = _evaluate(scenarios, choice, config, keep_pad=True) if any(v > 0 for k, v in fit.items() if k != "density_g_cm3") else best
    thinnest = thinnest_wall_mm(best.fingerpad.pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    # the opening's ball is a polyhedron and the wall is measured by rays: 0.05 mm of slack
    if fit["min_wall_mm"] > 0 and thinnest < fit["min_wall_mm"] - 0.05:
        warnings.append(f"the pad keeps a wall of {thinnest:.3f} mm, thinner than print.min_wall_mm = {fit['min_wall_mm']:.3f} mm")
    box_volume = sampler.thickness_mm * sampler.length_mm * sampler.width_mm

    def effect(evaluation: CandidateEvaluation) -> PrintFitEffect:
        return PrintFitEffect(
            pocket_volume_mm3=_round(box_volume - evaluation.fingerpad.pad.volume()),
            contact_area_mm2=[_round(e.contact_area_mm2) for e in evaluation.scenarios],
            effective_area=[_round(e.effective_area) for e in evaluation.scenarios],
            seat_offsets_mm=[[_round(c.offset_mm) for c in e.contacts] for e in evaluation.scenarios],
            quality=_round(evaluation.quality),
        )

    return PrintFitReport(
        profile=config.print.profile,
        **{k: _round(v) for k, v in fit.items()},
        thinnest_wall_mm=_round(thinnest) if np.isfinite(thinnest) else None,
        exact=effect(exact),
        fitted=effect(best),
    )


def _part_report(part: Part) -> PartReport:
    return PartReport(
        name=part.name,
        file=part.path,
        scale_to_mm=_round(part.scale),
        extents_mm=[_round(x) for x in part.mesh.extents],
        volume_mm3=_round(part.mesh.volume),
        faces=len(part.mesh.faces),
        repairs=part.repairs,
        repair=_repair_report(part),
        shells=part.shells,
        solid_index=part.solid_index,
        shell_handling=part.shell_note,
    )


def _repair_report(part: Part) -> RepairReport | None:
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
        volume_before_mm3=_round(summary.volume_before * part.scale**3),
        volume_after_mm3=_round(summary.volume_after * part.scale**3),
        max_surface_deviation_mm=_round(summary.max_deviation * part.scale),
    )


def _scenario_report(scenario: Scenario) -> ScenarioReport:
    result = scenario.sampler_result
    return ScenarioReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        pose_probability=_round(scenario.probability),
        rest_transform=[[_round(x) for x in row] for row in scenario.rest_transform],
        tried_samples=result.tried,
        valid_samples=len(result.samples),
        rejected=dict(result.rejected),
        samples=[
            SampleReport(
                yaw_deg=g.sample.yaw_deg,
                s_mm=_round(g.sample.s_mm),
                h_mm=_round(g.sample.h_mm),
                a_max_mm=_round(g.sample.a_max_mm),
                a_min_mm=_round(g.sample.a_min_mm),
                surface_area_mm2=[_round(g.sample.area_plus_mm2), _round(g.sample.area_minus_mm2)],
                labels=["good" if p.good else "bad" for p in g.geometries],
                ratio=[_round(p.ratio) for p in g.geometries],
                depth_mm=[_round(p.depth_mm) for p in g.geometries],
                effective_area_bound=_round(g.effective_area_bound),
            )
            for g in scenario.samples
        ],
    )


def _candidate_reports(choices, exact: dict, screened: dict, indices: dict) -> list[CandidateReport]:
    """Report entries, by index: exact numbers for re-evaluated candidates, screened ones (``screened[choice]``) for the rest."""
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
        [(e.rles, e.contact_area_mm2, e.effective_area, [c.offset_mm for c in e.contacts]) for e in evaluation.scenarios],
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
        [(e.rles, e.contact_area_mm2, e.effective_area, list(e.seat_offsets_mm)) for e in screened.scenarios],
        screened.quality,
        screened.mean_effective_area,
        screened.case,
        None,
    )


def _candidate_entry(choice, index, evaluation, per_scenario, quality, mean, case, block_depth) -> CandidateReport:
    """A report entry; ``per_scenario`` holds (RLES, A, E, seat offsets) per scenario."""
    return CandidateReport(
        index=index,
        samples=list(choice),
        evaluation=evaluation,
        per_scenario=[
            ScenarioQuality(
                rles=_round(radius),
                contact_area_mm2=_round(area),
                effective_area=_round(effective),
                seat_offsets_mm=[_round(t) for t in offsets],
            )
            for radius, area, effective, offsets in per_scenario
        ],
        quality=_round(quality),
        mean_effective_area=_round(mean),
        pad_case=case,
        block_depth_mm=None if block_depth is None else _round(block_depth),
    )


def _grasp_report(scenario: Scenario, sample_index: int, evaluation: ScenarioEvaluation, config: DesignConfig) -> GraspReport:
    pose = tcp_pose(
        scenario.samples[sample_index].sample, evaluation.contacts[0].offset_mm, evaluation.contacts[1].offset_mm, config.sampler
    )
    return GraspReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        sample=sample_index,
        rest_transform=[[_round(x) for x in row] for row in scenario.rest_transform],
        position_mm=[_round(x) for x in pose["position_mm"]],
        quaternion_wxyz=[_round(x) for x in pose["quaternion_wxyz"]],
        approach_direction=pose["approach_direction"],
        closing_axis=[_round(x) for x in pose["closing_axis"]],
        pad_gap_mm=_round(pose["pad_gap_mm"]),
        closing_width_mm=_round(pose["closing_width_mm"]),
    )
