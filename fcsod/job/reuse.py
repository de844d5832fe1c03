"""Finger reuse in a job (METHOD §11b): serve a job from the cell's finger library, or add the job's fingers to it.

After loading, :func:`step_reuse` asks the library (:mod:`fcsod.job.fingers`)
for delivered fingers, designed with the job's own settings of the finger and
its grasps (:func:`finger_settings`), whose parts have the geometry of every
part of the job (a finger of other settings is named in the log with what
differs);
a part of no delivered geometry is evaluated on the pads of the fingers that
serve parts of about its size (``[reuse] similar_size_percent``) with
:func:`fcso.fit_pads`, and is served by the one it keeps most on, when every
one of its scenarios keeps ``[finger_sets] min_retained`` of its solo quality.
When they serve every part, the job designs nothing and prints no finger:
:func:`step_reused_outputs` writes ``build.3mf`` with the parts alone, a
``report.json`` that names the reused fingers (:class:`ReuseReport`), and
publishes the grasps, the placement and a pick plan whose sets name the
library's fingers (id, sha256, the job that delivered them). A job that
designs keeps its finger sets in the library when it is done
(:func:`step_add_to_library`).
"""

from __future__ import annotations

import io
import json

import trimesh
from pydantic import Field

import fcso
from fcso.config import DesignConfig
from fcso.layout import REPORT_JSON, set_finger_path
from fcso.pipeline.report import part_report
from fcso.report.models import GraspReport, PartReport, PickPart, ReportModel
from fcso.verify_config import CAPTURE_CONDITIONS

from .. import __version__
from ..bus.messages import BusMessage, GraspsMessage, PlacementMessage, PlanMessage, PlanSet, job_key, utc_now
from ..plate.build3mf import export_build_3mf
from ..plate.placement import place_fingers
from ..record.recorder import TOPIC_GRASPS, TOPIC_PLACEMENT
from .cell_grasps import cell_grasps, verification_note
from .fingers import (
    DeliveredFinger,
    DeliveredPart,
    FingerEntry,
    FingerLibrary,
    FittedPart,
    ServedPart,
    library_path,
)
from .task import BUILD_NAME, FINGER_SET, JobRun, Outputs, Reuse

#: The settings sections that shape a finger, its pad's evaluation and its grasps: a finger serves a job only when the
#: job's are the same (the gripper it opens in, the pad, the print, the measure, the poses planned for), and the
#: measure's test conditions in ``[verify]`` too (:func:`finger_settings`).
FINGER_SECTIONS = frozenset({"sampler", "gripper", "filter", "finger", "print", "contact", "quality", "poses"})

#: Most setting differences a log line names.
NAMED_DIFFERENCES = 4


class ReusedPartReport(ReportModel):
    """A part of the job and why the finger serves it."""

    part: str = Field(description="The part in this job")
    library_part: str | None = Field(
        description="The part of the same geometry in the job that delivered the finger; null when the part is not "
        "the same and keeps min_retained on the finger"
    )
    worst_retained: float | None = Field(
        description="With library_part null: the smallest E / E* of the part's scenarios on the finger (METHOD "
        "§11b), 0..1; null for the same geometry (the delivering job's worst_retained holds)"
    )


class ReusedFingerReport(ReportModel):
    """A finger from the cell's library that serves this job."""

    finger_id: int = Field(description="Id in the library (fcsod fingers list)")
    sha256: str = Field(description="SHA-256 of the finger STL, hex")
    delivered_by_job: str = Field(description="The job that designed and printed it")
    finger_file: str = Field(description="Its STL, relative to this job's output folder (the delivering job's)")
    finger_key: str = Field(description="zenoh key the delivering job published it on")
    jobs_served: int = Field(description="Jobs it has served, this one and the delivering one included")
    reprint_after_jobs: int = Field(description="[reuse] reprint_after_jobs: the wear limit")
    worst_retained: float = Field(
        description="The smallest E / E* over the parts it serves in this job (the delivering job's figure for "
        "parts of the same geometry), 0..1"
    )
    parts: list[ReusedPartReport]


class ReuseReport(ReportModel):
    """``report.json`` of a job served by fingers delivered before: nothing designed, no finger printed."""

    job_id: str
    fcsod_version: str
    fcso_version: str
    message: str = Field(description="What was reused, in one sentence")
    reused: list[ReusedFingerReport] = Field(description="The fingers to mount, in the pick plan's order")
    parts: list[PartReport] = Field(description="The job's parts as loaded (repair included)")
    grasps: list[GraspReport] = Field(description="The delivered grasps, rest transforms from this job's part files")
    placement: dict = Field(description="The parts in build.3mf, no finger copies (schema: placement-report.json)")
    warnings: list[str]


def finger_settings(config: DesignConfig) -> str:
    """The JSON of the settings a finger, its pad's evaluation and its grasps depend on, as the library keeps and
    compares them: :data:`FINGER_SECTIONS` and the ``[verify]`` test conditions the capture measure ranks candidates
    under (:data:`fcso.config.CAPTURE_CONDITIONS`)."""
    return config.model_dump_json(include={**dict.fromkeys(FINGER_SECTIONS, True), "verify": set(CAPTURE_CONDITIONS)})


def settings_difference(kept: str | None, job: str) -> str:
    """Why a finger designed with the settings ``kept`` (None: not recorded) does not serve a job of ``job``, e.g.
    ``gripper.max_opening_mm 50.0 -> 85.0``."""
    if kept is None:
        return "it was kept before the library recorded the settings a finger was designed with"
    before, now = _flat(json.loads(kept)), _flat(json.loads(job))
    names = sorted(n for n in before.keys() | now.keys() if before.get(n, "unset") != now.get(n, "unset"))
    words = [f"{n} {before.get(n, 'unset')} -> {now.get(n, 'unset')}" for n in names[:NAMED_DIFFERENCES]]
    more = f" and {len(names) - NAMED_DIFFERENCES} more" if len(names) > NAMED_DIFFERENCES else ""
    return "settings differ: " + ", ".join(words) + more


def _flat(settings: dict, prefix: str = "") -> dict[str, object]:
    """Nested settings as dotted names -> values."""
    flat = {}
    for name, value in settings.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{name}."))
        else:
            flat[f"{prefix}{name}"] = value
    return flat


def step_reuse(run: JobRun) -> Reuse | None:
    """Serve the job from the finger library when every part has the geometry of a part of an active finger or keeps
    ``min_retained`` on one."""
    config = run.task.config
    if not config.reuse.enabled or not run.loaded:
        return None
    meshes = {p.name: p.mesh for p in run.loaded}
    settings = finger_settings(run.settings)
    claim = (config.bus.cell, run.task.job_id, meshes, config.reuse.reprint_after_jobs, settings)
    library = FingerLibrary(library_path(config))
    try:
        served = library.claim(*claim)
        if served is None and config.reuse.similar_size_percent > 0:
            fitted = _fitted_parts(run, library)
            if fitted is not None:
                served = library.claim(*claim, fitted)
        other = library.other_settings(*claim) if served is None else {}
    finally:
        library.close()
    if served is None:
        for finger_id, kept in other.items():
            run.log(
                "info",
                f"finger library: finger {finger_id} holds parts of this job but does not serve it: "
                f"{settings_difference(kept, settings)}",
            )
        run.log("info", "finger library: not every part is served by a delivered finger; designing")
        return None
    run.log(
        "info", f"finger library: every part is served by finger {', '.join(_served_words(served))}: nothing to design"
    )
    return Reuse(served)


def _fitted_parts(run: JobRun, library: FingerLibrary) -> dict[str, FittedPart] | None:
    """The parts of no delivered geometry, each with the library finger it keeps most on (at least ``min_retained``
    in every scenario); None when one keeps that on none."""
    config, settings = run.task.config, run.settings
    near = library.near_fingers(
        config.bus.cell,
        run.task.job_id,
        {p.name: p.mesh for p in run.loaded},
        config.reuse.reprint_after_jobs,
        finger_settings(settings),
        config.reuse.similar_size_percent,
    )
    if near is None:
        return None
    parts = [p for p in run.loaded if p.name in near]
    finger_ids = sorted({i for ids in near.values() for i in ids}, reverse=True)
    run.log("info", f"finger library: evaluating finger {', '.join(map(str, finger_ids))} on {len(parts)} part(s)")
    try:
        fits = fcso.fit_pads(parts, [library.pad(i) for i in finger_ids], settings)
    except fcso.FcsoError as error:
        run.log("info", f"finger library: the parts cannot be evaluated ({error}); designing")
        return None
    fitted = {}
    min_retained = settings.finger_sets.min_retained
    for part in parts:
        kept = [
            (fit.part_worst_retained(part.name), finger_id, fit)
            for finger_id, fit in zip(finger_ids, fits)
            if finger_id in near[part.name]
        ]
        worst, finger_id, fit = max(kept, key=lambda k: (k[0], k[1]))
        grasps = [s.grasp for s in fit.scenarios if s.part == part.name and s.grasp is not None]
        run.log("info", f"finger library: {part.name} keeps {worst:.3f} (worst scenario) on finger {finger_id}")
        if worst < min_retained or not grasps:
            return None
        fitted[part.name] = FittedPart(finger_id, worst, grasps)
    return fitted


def _served_words(served: dict[str, ServedPart]) -> list[str]:
    """Each serving finger with how: the same parts, or the worst retained quality of the parts fitted to it."""
    words = {}
    for part in served.values():
        fitted = [s.worst_retained for s in served.values() if s.finger.finger_id == part.finger.finger_id]
        kept = [w for w in fitted if w is not None]
        words[part.finger.finger_id] = f"{part.finger.finger_id}" + (
            f" (parts not the same keep at worst {min(kept):.3f})" if kept else " (the same parts)"
        )
    return [words[i] for i in sorted(words)]


def step_reused_outputs(run: JobRun) -> Outputs:
    """The outputs and messages of a job the library serves: build with the parts alone, report, grasps, plan."""
    config, job_id, served = run.task.config, run.task.job_id, run.reuse
    fingers: dict[int, FingerEntry] = {}
    for part in run.loaded:
        fingers.setdefault(served[part.name].finger.finger_id, served[part.name].finger)
    library = FingerLibrary(library_path(config))
    try:
        finger = trimesh.load(io.BytesIO(library.finger_stl(min(fingers))), file_type="stl")
    finally:
        library.close()
    # the placer with no finger copies packs the job's parts alone
    no_fingers = run.build_settings.model_copy(update={"finger_copies": 0, "spare_fingers": 0})
    placed = place_fingers(run.build, finger, no_fingers)
    run.recorder.write(TOPIC_PLACEMENT, placed.report)
    run.log("info", f"placement: {placed.report.message}")
    files = {
        BUILD_NAME: export_build_3mf(
            placed.items,
            job_id=job_id,
            application=f"fcsod {__version__}",
            creation_date=utc_now(),
            finger_set=FINGER_SET,
        )
    }
    # the reused finger's pads count as carved (D inside the outline): the wider, safe approach opening
    grasps = cell_grasps(
        job_id,
        [g for p in run.loaded for g in served[p.name].grasps],
        run.settings,
        False,
        None,
        verification_note(run.verify_settings.enabled, False),
    )
    run.recorder.write(TOPIC_GRASPS, GraspsMessage(job_id=job_id, grasps=grasps))
    min_retained = run.settings.finger_sets.min_retained
    reused, plan_sets, worst = reused_finger_sets(run.loaded, served, fingers, config.reuse.reprint_after_jobs)
    message = (
        f"every part is served by {len(fingers)} finger set(s) delivered before (library finger "
        f"{', '.join(_served_words(served))}; worst retained {worst:.3f}): no finger designed, none in build.3mf"
    )
    warnings = list(dict.fromkeys(w for p in run.loaded for w in p.warnings)) + placed.report.warnings
    report = ReuseReport(
        job_id=job_id,
        fcsod_version=__version__,
        fcso_version=fcso.__version__,
        message=message,
        reused=reused,
        parts=[part_report(p) for p in run.loaded],
        grasps=grasps,
        placement=placed.report.model_dump(mode="json"),
        warnings=warnings,
    )
    files[REPORT_JSON] = report.model_dump_json(indent=2).encode()
    bus = config.bus
    plan = PlanMessage(
        job_id=job_id,
        sets=plan_sets,
        min_retained=min_retained,
        min_retained_reached=worst >= min_retained,
        worst_retained=worst,
        ungraspable_parts=[],
        # reused only when every part keeps min_retained on a finger the cell has: all served by these sets
        sets_allowed=len(plan_sets),
        sets_needed=len(plan_sets),
        partition=f"reused: {message}",
    )
    summary = placed.report.model_dump(include=set(PlacementMessage.model_fields) - {"job_id", "file"})
    outgoing = (
        BusMessage.json_body(bus.prefix, bus.cell, "grasps", GraspsMessage(job_id=job_id, grasps=grasps)),
        BusMessage.json_body(bus.prefix, bus.cell, "plan", plan),
        BusMessage.json_body(
            bus.prefix, bus.cell, "placement", PlacementMessage(job_id=job_id, file=BUILD_NAME, **summary)
        ),
    )
    run.write_files(files)
    run.record_files(files)
    for published in outgoing:
        run.record_published(published)
    run.log("info", f"finger reuse: {message}")
    return Outputs(files, outgoing, warnings=tuple(placed.report.warnings))


def reused_finger_sets(
    loaded: list[fcso.Part], served: dict, fingers: dict[int, FingerEntry], reprint_after_jobs: int
) -> tuple[list[ReusedFingerReport], list[PlanSet], float]:
    """The report and the pick plan's set of each library finger that serves a job's parts.

    Parameters
    ----------
    loaded : list of fcso.Part
        The job's parts.
    served : dict
        Part name -> how the library serves it (:class:`~fcsod.job.fingers.ServedPart`).
    fingers : dict
        Finger id -> its library entry, in the order of the sets.
    reprint_after_jobs : int
        ``[reuse] reprint_after_jobs``.

    Returns
    -------
    reused : list of ReusedFingerReport
    plan_sets : list of PlanSet
    worst : float
        The worst retained fraction of any part on its finger.
    """
    # a part of a delivered geometry keeps what it kept in the delivering job; another, what it keeps on the finger
    kept = {
        p.name: served[p.name].finger.worst_retained
        if served[p.name].worst_retained is None
        else served[p.name].worst_retained
        for p in loaded
    }
    set_worst = {i: min(kept[n] for n, s in served.items() if s.finger.finger_id == i) for i in fingers}
    reused = []
    plan_sets = []
    for number, entry in enumerate(fingers.values(), start=1):
        parts = [p for p in loaded if served[p.name].finger.finger_id == entry.finger_id]
        finger_file = f"../{entry.job_id}/{entry.finger_file}"
        reused.append(
            ReusedFingerReport(
                finger_id=entry.finger_id,
                sha256=entry.sha256,
                delivered_by_job=entry.job_id,
                finger_file=finger_file,
                finger_key=entry.design_key,
                jobs_served=entry.jobs,
                reprint_after_jobs=reprint_after_jobs,
                worst_retained=set_worst[entry.finger_id],
                parts=[
                    ReusedPartReport(
                        part=p.name,
                        library_part=served[p.name].library_part,
                        worst_retained=served[p.name].worst_retained,
                    )
                    for p in parts
                ],
            )
        )
        plan_sets.append(
            PlanSet(
                set=number,
                finger_key=entry.design_key,
                finger_file=finger_file,
                finger_sha256=entry.sha256,
                finger_copies=0,
                quality=entry.quality,
                quality_measure=entry.quality_measure,
                worst_retained=set_worst[entry.finger_id],
                parts=[
                    PickPart(part=p.name, copies=[p.name], quantity=len(p.instances), grasps=served[p.name].grasps)
                    for p in parts
                ],
                finger_id=entry.finger_id,
                reused_from_job=entry.job_id,
            )
        )
    return reused, plan_sets, min(set_worst.values())


def step_add_to_library(run: JobRun) -> None:
    """Keep the done job's finger sets in the cell's library, each with its parts' geometry and grasps."""
    config = run.task.config
    if not config.reuse.enabled:
        return
    meshes = {p.name: p.mesh for p in run.loaded}
    report, several = run.sets.report, run.sets.several
    delivered = []
    for number in range(1, len(run.sets.designs) + 1):
        design = run.sets.designs[number - 1].report
        if report is not None:
            entry = next(s for s in report.sets if s.set == number)
            picks = [(pick.part, pick.grasps) for step in report.pick_plan if step.set == number for pick in step.parts]
            quality, worst = entry.quality, entry.worst_retained
        else:
            names = list(dict.fromkeys(g.part for g in design.grasps))
            picks = [(name, [g for g in design.grasps if g.part == name]) for name in names]
            quality, worst = next(c.quality for c in design.candidates if c.index == design.best), 1.0
        finger_file = set_finger_path(number, several)
        delivered.append(
            DeliveredFinger(
                job_id=run.task.job_id,
                finger_set=number,
                finger_file=finger_file,
                design_key=job_key(
                    config.bus.prefix, config.bus.cell, run.task.job_id, f"design/{number}" if several else "design"
                ),
                finger_stl=run.files[finger_file],
                quality=quality,
                quality_measure=run.settings.quality.measure,
                worst_retained=worst,
                parts=[DeliveredPart(name, meshes[name], grasps) for name, grasps in picks if name in meshes],
                design_settings=finger_settings(run.settings),
                pad_stl=run.sets.designs[number - 1].fingerpad.export(file_type="stl"),
            )
        )
    library = FingerLibrary(library_path(config))
    try:
        ids = [library.add(config.bus.cell, finger) for finger in delivered]
    finally:
        library.close()
    run.log("info", f"finger library: this job's finger set(s) kept as finger {', '.join(map(str, ids))}")
