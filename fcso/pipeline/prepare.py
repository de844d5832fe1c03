"""Everything before the candidate search (METHOD §1-5): parts loaded, posed and sampled, every sample's pad
geometries; and a prepared batch cut down to some of its scenarios."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..closing_yaws import face_yaws
from ..config import DesignConfig
from ..errors import NoGraspError
from ..evaluate import (
    CandidateEvaluation,
    SampleGeometry,
    Scenario,
    evaluate_candidate,
    sample_geometry,
)
from ..finger import (
    FlatFinger,
    finger_plate,
    load_finger,
    parametric_finger,
)
from ..grid import ScreenGrid
from ..parallel import WorkerPool, resolve_jobs
from ..parts import Part, load_parts
from ..poses import select_poses, stable_poses
from ..progress import Progress, progress_with_note
from ..report.models import (
    UngraspableReport,
)
from ..sampler import SamplerResult, sample_grasps
from ..screen import NormalLattice, ScreenedCandidate, screen
from .report import (
    ungraspable_report,
)

#: Samples per pad-geometry task and candidates per screening task sent to a worker.
_GEOMETRY_CHUNK = 4


#: Sampling tasks per worker to aim for when scenarios and yaws are few.
_SAMPLE_TASKS_PER_WORKER = 4


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
    report_progress = progress_with_note(progress)
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
    samples = scenario.sampler_result.samples
    return [
        sample_geometry(scenario.solid(), scenario.mesh, samples[index], config, (number, index), grid, lattice)
        for index in range(start, stop)
    ]
