"""One job, run in a worker process started with the spawn method.

The worker checks the job's inputs, runs :func:`fcso.design_sets`, writes the
results into ``<output_root>/.tmp-<job_id>/`` and records ``job.mcap`` as it
goes (flushed after every stage), then renames the folder to
``<output_root>/<job_id>/``. A failed job's folder holds ``job.mcap`` only.
The worker never touches zenoh: the messages to publish go back to the
daemon over a pipe, after they are in the record.

The job runs as a list of steps (:data:`STEPS`); each takes the
:class:`JobRun` and records what it made: inputs, loading (the parts to
design and the job's build), design, its record, build placement
(``build.3mf``, the placement section of ``report.json``), output files.
"""

from __future__ import annotations

import base64
import ctypes
import errno
import hashlib
import os
import shutil
import signal
import time
import traceback
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Callable

import fcso
import numpy as np
import trimesh
from fcso import DesignConfig, DesignResult, FcsoError, MeshError, load_parts
from fcso.output import output_files
from fcso.sets import SetsResult, design_sets
from fcso.sets_output import sets_output_files

from . import __version__
from .build3mf import Build, BuildItem, export_build_3mf
from .config import DaemonConfig, JobManifest
from .finger_sets import design_messages, finger_file, place_sets, plan_message, several
from .jobs import PartInput, check_parts, hash_inputs, job_inputs, read_manifest
from .messages import (
    BusMessage,
    CandidateRecord,
    DesignAttachment,
    DesignRecord,
    ENCODING_STL,
    FoxgloveTime,
    GraspsMessage,
    InputFile,
    InputHashesRecord,
    JobSpecRecord,
    LogRecord,
    OutputFilesRecord,
    PlacementMessage,
    PoseRecord,
    QualityMessage,
    SamplesRecord,
    ScenarioSummary,
    SceneEntity,
    SceneUpdate,
    StateChangeRecord,
    StatusMessage,
    TriangleListPrimitive,
    job_key,
    utc_now,
)
from .ros2 import record_ros2
from .recorder import (
    TOPIC_BUS,
    TOPIC_CANDIDATES,
    TOPIC_DESIGN,
    TOPIC_GRASPS,
    TOPIC_INPUTS,
    TOPIC_LOG,
    TOPIC_OUTPUTS,
    TOPIC_PLACEMENT,
    TOPIC_POSES,
    TOPIC_SAMPLES,
    TOPIC_SCENE,
    TOPIC_SPEC,
    TOPIC_STATE,
    Recorder,
    salvage,
)
from .placement import BuildConfig, PlacementReport, place_fingers
from .verification import choose_by_verification, job_settings, verify_done_job

#: Name of the record in every job's output folder.
RECORD_NAME = "job.mcap"

#: Shortest interval between two progress lines of the same stage, s.
PROGRESS_INTERVAL_S = 1.0

#: The placed build in every done job's output folder.
BUILD_NAME = "build.3mf"

#: Number of the finger set of a job served by one finger, in ``build.3mf``.
FINGER_SET = 1


class JobFolderDeleted(Exception):
    """The job folder disappeared while its job ran: the print job was withdrawn."""

    def __init__(self, folder: Path):
        super().__init__(f"{folder}: the job folder was deleted while its job ran: the job is withdrawn, nothing of it is published")


class TimeLimitExceeded(BaseException):
    """Raised in the worker when the daemon signals that the job ran out of time.

    A BaseException so that libraries catching ``Exception`` cannot swallow it.
    """


class Withdrawn(BaseException):
    """Raised in the worker when the daemon signals that the job's folder was deleted (a BaseException, as above)."""


#: The signals by which the daemon stops a running job: out of time, or withdrawn.
SIGNAL_TIME_LIMIT = signal.SIGUSR1
SIGNAL_WITHDRAWN = signal.SIGUSR2


def time_limit_error(limit_seconds: float) -> str:
    """The error of a job stopped by its time limit."""
    return f"time limit exceeded: the job ran longer than jobs.time_limit_seconds ({limit_seconds:g} s)"


@dataclass
class JobTask:
    """What the daemon hands a worker.

    Attributes
    ----------
    job_id, folder : str
        The job and its watched folder.
    attempt : int
        Run number (more than 1 after a restart re-queued the job).
    queued_at, started_at : str
        UTC ISO 8601 times from the journal.
    config : DaemonConfig
        The daemon's settings.
    """

    job_id: str
    folder: str
    attempt: int
    queued_at: str
    started_at: str
    config: DaemonConfig


@dataclass
class JobRun:
    """The state of a running job that steps read and extend."""

    task: JobTask
    folder: Path
    work_dir: Path
    recorder: Recorder
    emit: Callable[[tuple], None]
    manifest: JobManifest | None = None
    manifest_text: str | None = None
    inputs: list[InputFile] = field(default_factory=list)
    parts: list[PartInput] = field(default_factory=list)
    settings: DesignConfig | None = None
    build_settings: BuildConfig | None = None
    loaded: list[fcso.Part] = field(default_factory=list)
    build: Build = field(default_factory=Build)
    result: DesignResult | None = None
    sets: SetsResult | None = None
    files: dict[str, bytes] = field(default_factory=dict)
    outgoing: list[BusMessage] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    verified: tuple | None = None

    def log(self, level: str, message: str, **fields) -> None:
        """Record a log line and send it to the daemon's log."""
        self.recorder.write(TOPIC_LOG, LogRecord(level=level, message=message, **fields))
        self.emit(("log", level, message, fields))

    def record_published(self, message: BusMessage) -> None:
        """Record a message to publish on the bus channel and, in its ROS 2 form, on the ROS 2 channels."""
        self.recorder.write(TOPIC_BUS, message.record())
        record_ros2(self.recorder, message, self.task.config.ros2)

    def status(
        self,
        state: str,
        finished_at: str | None = None,
        error: str | None = None,
        outputs: list[str] | None = None,
        warnings: list[str] | None = None,
        record: bool = True,
    ) -> BusMessage:
        """The job's status message, recorded on the bus and ROS 2 channels and as a state change (unless ``record`` is false)."""
        message = status_message(self.task, state, finished_at, error, outputs, warnings)
        if record:
            self.record_published(message)
            self.recorder.write(TOPIC_STATE, StateChangeRecord(job_id=self.task.job_id, state=state, at=finished_at or utc_now(), error=error))
        return message


def status_message(
    task: JobTask,
    state: str,
    finished_at: str | None = None,
    error: str | None = None,
    outputs: list[str] | None = None,
    warnings: list[str] | None = None,
) -> BusMessage:
    """The status message of ``task`` in ``state`` (times UTC ISO 8601)."""
    body = StatusMessage(
        job_id=task.job_id,
        state=state,
        folder=task.folder,
        attempt=task.attempt,
        queued_at=task.queued_at,
        started_at=task.started_at,
        finished_at=finished_at,
        error=error,
        outputs=outputs or [],
        warnings=warnings or [],
    )
    return BusMessage.json_body(task.config.bus.prefix, task.config.bus.cell, "status", body)


# ------------------------------------------------------------------------ steps


def step_inputs(run: JobRun) -> None:
    """Hash the inputs, read and validate the manifest, check the part files against the limits."""
    config = run.task.config
    run.inputs = hash_inputs(run.folder, job_inputs(run.folder), config.limits.max_file_bytes)
    run.recorder.write(TOPIC_INPUTS, InputHashesRecord(job_id=run.task.job_id, files=run.inputs))
    try:
        run.manifest, run.manifest_text = read_manifest(run.folder, config.design, config.limits, config.build)
        run.settings = run.manifest.design_config(config.design)
        run.build_settings = run.manifest.build_config(config.build)
        run.parts = check_parts(run.folder, run.manifest, config.limits)
    finally:
        run.recorder.write(
            TOPIC_SPEC,
            JobSpecRecord(
                job_id=run.task.job_id,
                folder=run.task.folder,
                manifest=run.manifest_text,
                parts=[{**p.entry.model_dump(), "file": p.entry.file} for p in run.parts],
                settings=(run.settings or config.design).model_dump(mode="json"),
                build=(run.build_settings or config.build).model_dump(mode="json"),
                fcsod_version=__version__,
                fcso_version=fcso.__version__,
            ),
        )


def step_load(run: JobRun) -> None:
    """Load and validate every part (closed volume, units, shells, face limit) and assemble the job's build.

    Parts come from :func:`fcso.load_parts`, the loader ``fcso design`` uses:
    overlapping shells are one solid, separate solids are separate parts,
    a 3MF gives one part per distinct object. A loose part is designed once
    and is ``quantity`` build items, placed when its manifest entry has a
    transform; a 3MF part keeps the transform of every build item holding it.
    """
    max_faces = run.task.config.limits.max_faces
    items: list[BuildItem] = []
    for part in run.parts:
        loaded = load_parts(
            part.path,
            units=part.entry.units,
            scale_to_mm=part.entry.scale_to_mm,
            repair=run.manifest.repair,
            split_bodies=run.settings.parts.split_bodies,
            max_uncompressed_bytes=run.task.config.limits.max_3mf_uncompressed_bytes,
        )
        for one in loaded:
            if len(one.mesh.faces) > max_faces:
                raise MeshError(part.path, f"{one.name}: {len(one.mesh.faces)} triangles, more than limits.max_faces ({max_faces})")
            if part.path.suffix.lower() == ".3mf":
                items.extend(BuildItem(one.name, one.mesh, transform, "part", part.path.stem) for transform in one.instances)
            else:
                transform = None if part.entry.transform is None else np.asarray(part.entry.transform, dtype=float)
                items.extend(BuildItem(one.name, one.mesh, transform, "part", part.path.stem) for _ in range(part.entry.quantity))
                # the pieces to pick (fcso counts a part's build items)
                one.instances = [transform] * part.entry.quantity
            run.loaded.append(one)
            shells = f", {one.shell_note}" if one.shell_note else ""
            run.log("info", f"loaded {part.entry.file} as {one.name}: {len(one.mesh.faces)} triangles, extents {np.round(one.mesh.extents, 2).tolist()} mm{shells}")
            for warning in one.warnings:
                run.log("warning", warning)
    if len(run.loaded) > run.task.config.limits.max_parts:
        raise MeshError(run.folder, f"{len(run.loaded)} distinct part meshes, more than limits.max_parts ({run.task.config.limits.max_parts})")
    _make_names_unique(items)
    run.build = Build(items=items, source=str(run.folder))
    placed = sum(1 for item in items if item.transform is not None)
    run.log("info", f"build: {len(items)} part items, {placed} placed by the job, {len(items) - placed} to pack")


def _make_names_unique(items: list[BuildItem]) -> None:
    """Number the repeated names of build items (copies of a part): ``cube``, ``cube_2``... (in place)."""
    seen: dict[str, int] = {}
    for item in items:
        seen[item.name] = seen.get(item.name, 0) + 1
        if seen[item.name] > 1:
            item.name = f"{item.name}_{seen[item.name]}"


def step_design(run: JobRun) -> None:
    """Run fcso's design, logging progress per stage."""
    last: dict[str, float] = {}

    def progress(stage: str, done: int, total: int, note: str = "") -> None:
        now = time.monotonic()
        if stage in last and done < total and now - last[stage] < PROGRESS_INTERVAL_S:
            return
        last[stage] = now
        run.log("info", f"{stage} {done}/{total}" + (f": {note}" if note else ""), stage=stage, done=done, total=total)

    run.sets = design_sets(run.loaded, run.settings, progress=progress)
    run.result = run.sets.designs[0]
    job = run.sets.job_report or run.result.report
    # what the design warns of (parts left out as ungraspable, files split into
    # several solids) travels with the job's done status
    run.warnings.extend(job.warnings)
    for entry in run.sets.report.ungraspable if run.sets.report else run.result.report.ungraspable:
        run.log("warning", f"{entry.part} (pose {entry.pose_index}) cannot be grasped: {entry.reason}")
    if run.sets.report is not None:
        for line in run.sets.report.search.description, *(f"set {s.set}: {', '.join(s.parts)} (Q = {s.quality:.1f} mm², worst retained {s.worst_retained:.3f})" for s in run.sets.report.sets):
            run.log("info", f"finger sets: {line}")


def step_choose_by_verification(run: JobRun) -> None:
    """Choose among the best candidates by verification; a job of several finger sets keeps its designs (each is verified when done)."""
    if several(run.sets):
        settings = job_settings(run.task.config.verify, run.manifest.verify if run.manifest is not None else None)
        if settings.top_k > 0:
            run.log("warning", "verify top_k chooses among one finger's candidates: with several finger sets each set's design is verified as it is")
        return
    choose_by_verification(run)


def step_record_design(run: JobRun) -> None:
    """Record poses, samples with rejections, every candidate row, the design, the grasps and the 3D scene."""
    recorder = run.recorder
    designs = run.sets.designs if several(run.sets) else [run.result]
    run.files = {}
    for number, result in enumerate(designs, start=1):
        _record_one_design(run, result, number)
    recorder.write(TOPIC_GRASPS, GraspsMessage(job_id=run.task.job_id, grasps=[g for d in designs for g in d.report.grasps]))


def _record_one_design(run: JobRun, result: DesignResult, number: int) -> None:
    """Record one finger set's poses, samples, candidates, design and scene; keep its meshes for the outputs."""
    recorder, report = run.recorder, result.report
    for scenario in report.scenarios:
        recorder.write(
            TOPIC_POSES,
            PoseRecord(part=scenario.part, pose_index=scenario.pose_index, probability=scenario.pose_probability, rest_transform=scenario.rest_transform),
        )
        recorder.write(
            TOPIC_SAMPLES,
            SamplesRecord(
                part=scenario.part,
                pose_index=scenario.pose_index,
                tried_samples=scenario.tried_samples,
                valid_samples=scenario.valid_samples,
                rejected=scenario.rejected,
                samples=[s.model_dump() for s in scenario.samples],
            ),
        )
    for candidate in report.candidates:
        recorder.write(TOPIC_CANDIDATES, CandidateRecord(candidate=candidate, best=candidate.index == report.best, per_scenario=candidate.per_scenario))
    # report.json and report.html wait for the placement section (step_outputs)
    folder = finger_file(run.sets, number).removesuffix("finger.stl")
    finger = run.files[f"{folder}finger.stl"] = result.finger.export(file_type="stl")
    pad = run.files[f"{folder}fingerpad.stl"] = result.fingerpad.export(file_type="stl")
    recorder.write(
        TOPIC_DESIGN,
        DesignRecord(
            finger_stl_base64=_base64(finger),
            finger_sha256=hashlib.sha256(finger).hexdigest(),
            fingerpad_sha256=hashlib.sha256(pad).hexdigest(),
            finger_volume_mm3=report.finger.volume_mm3,
            finger_watertight=report.finger.watertight,
            finger_set=number,
        ),
    )
    recorder.write(TOPIC_SCENE, scene_update(result, prefix=f"set-{number}-" if several(run.sets) else ""))


def step_placement(run: JobRun) -> None:
    """Place the finger copies into the job's build volume: ``build.3mf``, the report's placement section, record, scene, bus message.

    Fingers that do not fit leave the job done with its design, a warning
    and the free build height that was missing.
    """
    if several(run.sets):
        step_placement_sets(run)
        return
    result = run.result
    placed = place_fingers(run.build, result.finger, run.build_settings, pad_normal=result.flat_finger.contact_normal, finger_name=f"fcso-finger-{FINGER_SET}")
    report = placed.report
    run.recorder.write(TOPIC_PLACEMENT, report)
    run.files[BUILD_NAME] = export_build_3mf(
        placed.items, job_id=run.task.job_id, application=f"fcsod {__version__}", creation_date=utc_now(), finger_set=FINGER_SET
    )
    update: dict = {"placement": report.model_dump(mode="json")}
    if not report.fingers_fit:
        run.warnings.append(report.message)
        update["warnings"] = [*result.report.warnings, report.message]
    result.report = result.report.model_copy(update=update)
    run.log("info" if report.fingers_fit else "warning", f"placement: {report.message}")
    for warning in report.warnings:
        run.log("warning", f"placement: {warning}")
    run.recorder.write(TOPIC_SCENE, build_scene_update(placed.items, report, run.build_settings))
    bus = run.task.config.bus
    summary = report.model_dump(include=set(PlacementMessage.model_fields) - {"job_id", "file"})
    body = PlacementMessage(job_id=run.task.job_id, file=BUILD_NAME, **summary)
    # published after the design's messages (step_outputs puts them first)
    run.outgoing.append(BusMessage.json_body(bus.prefix, bus.cell, "placement", body))


def step_placement_sets(run: JobRun) -> None:
    """Place every finger set's copies into the build (:func:`fcsod.finger_sets.place_sets`): ``build.3mf``, the job report's placement, record, scene, bus message."""
    placements = place_sets(run.build, run.sets, run.build_settings)
    report = placements[-1].report
    for placed in placements:
        run.recorder.write(TOPIC_PLACEMENT, placed.report)
    run.files[BUILD_NAME] = export_build_3mf(placements[-1].items, job_id=run.task.job_id, application=f"fcsod {__version__}", creation_date=utc_now())
    per_set = [
        {"set": k, "finger_copies_placed": p.report.finger_copies_placed, "fingers_fit": p.report.fingers_fit, "message": p.report.message}
        for k, p in enumerate(placements, start=1)
    ]
    job = run.sets.job_report
    update: dict = {"placement": {**report.model_dump(mode="json"), "finger_sets": per_set}}
    for entry in per_set:
        run.log("info" if entry["fingers_fit"] else "warning", f"placement of set {entry['set']}: {entry['message']}")
        if not entry["fingers_fit"]:
            run.warnings.append(f"set {entry['set']}: {entry['message']}")
            update["warnings"] = [*update.get("warnings", job.warnings), f"set {entry['set']}: {entry['message']}"]
    run.sets.job_report = job.model_copy(update=update)
    run.recorder.write(TOPIC_SCENE, build_scene_update(placements[-1].items, report, run.build_settings))
    bus = run.task.config.bus
    summary = report.model_dump(include=set(PlacementMessage.model_fields) - {"job_id", "file"})
    summary.update(fingers_fit=all(e["fingers_fit"] for e in per_set), finger_copies_placed=sum(e["finger_copies_placed"] for e in per_set))
    summary["finger_copies_requested"] = sum(p.report.finger_copies_requested for p in placements)
    run.outgoing.append(BusMessage.json_body(bus.prefix, bus.cell, "placement", PlacementMessage(job_id=run.task.job_id, file=BUILD_NAME, **summary)))


def step_outputs(run: JobRun) -> None:
    """Write every output file into the work folder and record their hashes; record the bus messages.

    ``report.json`` and ``report.html`` are made here, after every step that
    adds to the report; the meshes are those the design record holds.
    """
    run.files = {**(sets_output_files(run.sets) if several(run.sets) else output_files(run.result)), **run.files}
    for name, data in run.files.items():
        path = run.work_dir / name
        try:
            path.parent.mkdir(exist_ok=True)
            path.write_bytes(data)
        except OSError as exc:
            # a failed write() does not say which file it was writing
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
    run.recorder.write(
        TOPIC_OUTPUTS,
        OutputFilesRecord(
            job_id=run.task.job_id,
            files=[InputFile(path=n, size_bytes=len(d), sha256=hashlib.sha256(d).hexdigest()) for n, d in run.files.items()],
        ),
    )
    bus, report = run.task.config.bus, run.result.report
    if run.sets is not None and run.sets.report is not None:
        copies = [int(p.get("finger_copies_placed", 0)) for p in (run.sets.job_report or report).placement.get("finger_sets", [])] or [
            report.placement["finger_copies_placed"]
        ]
        plan = plan_message(bus.prefix, bus.cell, run.task.job_id, run.sets, run.files, copies)
    if several(run.sets):
        grasps = [g for d in run.sets.designs for g in d.report.grasps]
        run.outgoing = [
            BusMessage.json_body(bus.prefix, bus.cell, "grasps", GraspsMessage(job_id=run.task.job_id, grasps=grasps)),
            *design_messages(bus.prefix, bus.cell, run.task.job_id, run.sets, run.files),
            plan,
            *run.outgoing,
        ]
        for message in run.outgoing:
            run.record_published(message)
        return
    best = next(c for c in report.candidates if c.index == report.best)
    quality = QualityMessage(
        job_id=run.task.job_id,
        quality_mm2=best.quality,
        mean_effective_area_mm2=best.mean_effective_area,
        pad_case=best.pad_case,
        candidates_evaluated=report.search.evaluated,
        candidates_total=report.search.candidates_total,
        proven_optimal=report.search.proven_optimal,
        scenarios=[
            ScenarioSummary(part=s.part, pose_index=s.pose_index, rles=q.rles, contact_area_mm2=q.contact_area_mm2, effective_area_mm2=q.effective_area)
            for s, q in zip(report.scenarios, best.per_scenario)
        ],
        finger_volume_mm3=report.finger.volume_mm3,
        finger_watertight=report.finger.watertight,
        min_pad_thickness_mm=report.finger.min_pad_thickness_mm,
        warnings=report.warnings,
        timings_s=report.timings_s,
    )
    finger = run.files["finger.stl"]
    attachment = DesignAttachment(job_id=run.task.job_id, sha256=hashlib.sha256(finger).hexdigest(), size_bytes=len(finger))
    run.outgoing = [
        BusMessage.json_body(bus.prefix, bus.cell, "quality", quality),
        BusMessage.json_body(bus.prefix, bus.cell, "grasps", GraspsMessage(job_id=run.task.job_id, grasps=report.grasps)),
        BusMessage(
            run.task.job_id,
            "design",
            job_key(bus.prefix, bus.cell, run.task.job_id, "design"),
            ENCODING_STL,
            finger,
            attachment.model_dump_json().encode(),
        ),
        *([plan] if run.sets is not None and run.sets.report is not None else []),
        *run.outgoing,
    ]
    for message in run.outgoing:
        run.record_published(message)


def step_folder_kept(run: JobRun) -> None:
    """Fail the job when its folder was deleted while it ran: a withdrawn print job gets no fingers."""
    if not run.folder.is_dir():
        raise JobFolderDeleted(run.folder)


#: The job's steps in order; each is logged and flushed to the record when it ends.
STEPS: list[Callable[[JobRun], None]] = [
    step_inputs,
    step_load,
    step_design,
    step_choose_by_verification,
    step_record_design,
    step_placement,
    step_outputs,
    step_folder_kept,
]


# ------------------------------------------------------------------------ scene


def _base64(data: bytes) -> str:
    return base64.b64encode(data).decode()


def _triangles(mesh: trimesh.Trimesh, transform: np.ndarray, color: tuple[float, float, float, float]) -> TriangleListPrimitive:
    vertices = trimesh.transformations.transform_points(np.asarray(mesh.vertices), transform)
    return TriangleListPrimitive.model_validate(
        {
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
            "points": [{"x": x, "y": y, "z": z} for x, y, z in (vertices / 1000.0).tolist()],
            "color": dict(zip("rgba", color)),
            "indices": np.asarray(mesh.faces).reshape(-1).tolist(),
        }
    )


def scene_update(result: DesignResult, prefix: str = "") -> SceneUpdate:
    """Foxglove SceneUpdate: per scenario the rested part, both seated pads and both fingers, in metres.

    Scenarios are laid side by side along x so they do not overlap; entity ids
    are ``<prefix>scenario-<n>`` (the prefix names a finger set).
    """
    now = time.time_ns()
    stamp = FoxgloveTime(sec=now // 1_000_000_000, nsec=now % 1_000_000_000)
    to_pad = np.linalg.inv(result.pad_to_finger)
    entities, offset_x = [], 0.0
    for number, (scenario, sample_index, evaluation) in enumerate(zip(result.scenarios, result.best.choice, result.best.scenarios)):
        sample = scenario.samples[sample_index]
        bounds = scenario.mesh.bounds
        gap = 0.5 * float(np.ptp(bounds[:, 0])) + 60.0
        shift = np.eye(4)
        shift[0, 3] = offset_x - bounds[0, 0]
        triangles = [_triangles(scenario.mesh, shift, (0.6, 0.6, 0.65, 1.0))]
        for frame, contact in zip(sample.frames, evaluation.contacts):
            seated = np.eye(4)
            seated[0, 3] = contact.offset_mm
            pad_to_rest = shift @ np.linalg.inv(frame) @ seated
            triangles.append(_triangles(result.fingerpad, pad_to_rest, (0.9, 0.45, 0.1, 1.0)))
            triangles.append(_triangles(result.finger, pad_to_rest @ to_pad, (0.2, 0.4, 0.8, 0.35)))
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id="fcso_rest",
                id=f"{prefix}scenario-{number}",
                lifetime=FoxgloveTime(sec=0, nsec=0),
                frame_locked=False,
                metadata=[
                    {"key": "part", "value": scenario.part.name},
                    {"key": "pose_index", "value": str(scenario.pose_index)},
                ],
                triangles=triangles,
            )
        )
        offset_x += float(np.ptp(bounds[:, 0])) + gap
    return SceneUpdate(entities=entities)


def build_scene_update(items: list[BuildItem], report: PlacementReport, config: BuildConfig) -> SceneUpdate:
    """Foxglove SceneUpdate of the placed build in metres: the build volume, each part's bounding box and the finger copies.

    Parts are drawn as their boxes (a build may hold many large meshes); the
    fingers, small and the job's design, as triangles.

    Parameters
    ----------
    items : list of BuildItem
        The placed items (``PlacementResult.items``).
    report : PlacementReport
        Their bounding boxes and the placement's outcome.
    config : BuildConfig
        The build volume.
    """
    now = time.time_ns()
    stamp = FoxgloveTime(sec=now // 1_000_000_000, nsec=now % 1_000_000_000)
    identity = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}

    def box(lower, upper, color: tuple[float, float, float, float]) -> dict:
        lower, upper = np.asarray(lower, dtype=float) / 1000.0, np.asarray(upper, dtype=float) / 1000.0
        centre = (lower + upper) / 2.0
        return {
            "pose": {**identity, "position": dict(zip("xyz", centre.tolist()))},
            "size": dict(zip("xyz", (upper - lower).tolist())),
            "color": dict(zip("rgba", color)),
        }

    origin = np.asarray(config.origin_mm, dtype=float)
    cubes = [box(origin, origin + np.asarray(config.volume_mm), (0.5, 0.5, 0.5, 0.08))]
    cubes += [box(*placed.bounds_mm, (0.6, 0.6, 0.65, 0.8)) for placed in report.items if placed.kind == "part"]
    triangles = [_triangles(item.mesh, item.transform, (0.2, 0.4, 0.8, 1.0)) for item in items if item.kind == "finger"]
    entity = SceneEntity(
        timestamp=stamp,
        frame_id="fcso_build",
        id="build",
        lifetime=FoxgloveTime(sec=0, nsec=0),
        frame_locked=False,
        metadata=[
            {"key": "fingers_fit", "value": str(report.fingers_fit).lower()},
            {"key": "build_height_mm", "value": f"{report.build_height_mm:g}"},
            {"key": "message", "value": report.message},
        ],
        cubes=cubes,
        triangles=triangles,
    )
    return SceneUpdate(entities=[entity])


# ------------------------------------------------------------------------ running


def run_job(task: JobTask, emit: Callable[[tuple], None]) -> None:
    """Run one job start to end; always leaves a finished ``job.mcap`` in the job's output folder.

    Parameters
    ----------
    task : JobTask
    emit : callable
        Receives ``("log", level, message, fields)``, ``("publish", BusMessage)``
        and finally ``("finished", state, error, [BusMessage, ...])``.
    """
    config = task.config
    output_root = config.output.root
    work_dir = output_root / f".tmp-{task.job_id}"
    final_dir = output_root / task.job_id
    shutil.rmtree(work_dir, ignore_errors=True)
    try:
        work_dir.mkdir(parents=True)
        recorder = Recorder(work_dir / RECORD_NAME, config.mcap.compression, config.mcap.chunk_size_bytes)
    except OSError as exc:
        # not even the record can start (a full disk): the journal and the bus still say why
        error = io_failure(exc, Path(task.folder), output_root) or f"internal error: {type(exc).__name__}: {exc}"
        shutil.rmtree(work_dir, ignore_errors=True)
        emit(("log", "error", error, {}))
        emit(("finished", "failed", error, [status_message(task, "failed", finished_at=utc_now(), error=error)]))
        return
    run = JobRun(task=task, folder=Path(task.folder), work_dir=work_dir, recorder=recorder, emit=emit)
    recorder.write(TOPIC_STATE, StateChangeRecord(job_id=task.job_id, state="queued", at=task.queued_at))
    emit(("publish", run.status("running")))
    error = None
    try:
        recorder.flush()
        for step in STEPS:
            started = time.perf_counter()
            step(run)
            run.log("info", f"step {step.__name__.removeprefix('step_')} finished in {time.perf_counter() - started:.2f} s", stage=step.__name__.removeprefix("step_"))
            recorder.flush()
    except FcsoError as exc:
        # a part that vanished is the symptom; a deleted folder is the cause
        error = str(exc) if run.folder.is_dir() else str(JobFolderDeleted(run.folder))
    except TimeLimitExceeded:
        error = time_limit_error(config.jobs.time_limit_seconds)
    except JobFolderDeleted as exc:
        error = str(exc)
    except Withdrawn:
        error = str(JobFolderDeleted(run.folder))
    except OSError as exc:
        error = io_failure(exc, run.folder, output_root)
        if error is None:
            error = f"internal error: {type(exc).__name__}: {exc}"
            run.log("error", traceback.format_exc())
    except Exception as exc:  # a bug or an unexpected library error: the job fails, the daemon goes on
        error = f"internal error: {type(exc).__name__}: {exc}"
        run.log("error", traceback.format_exc())
    if error is None:
        try:
            outputs = sorted([*run.files, RECORD_NAME])
            final = run.status("done", finished_at=utc_now(), outputs=outputs, warnings=run.warnings)
            recorder.finish()
            _fsync_files(work_dir)
            publish = [*run.outgoing, final]
        except OSError as exc:
            # the disk filled up at the very end: the job fails like any other write failure
            error = io_failure(exc, run.folder, output_root) or f"internal error: {type(exc).__name__}: {exc}"
    if error is not None:
        final = _finish_failed(run, error)
        publish = [final]
    if work_dir.is_dir():
        os.replace(work_dir, final_dir)
        _fsync_dir(output_root)
    emit(("finished", "done" if error is None else "failed", error, publish))
    if error is None:
        verify_done_job(run, final_dir)


def io_failure(exc: OSError, folder: Path, output_root: Path) -> str | None:
    """The job's error for an OS error it cannot go on after, naming the folder at fault; None for any other OS error.

    Parameters
    ----------
    exc : OSError
    folder : Path
        The job folder (its inputs).
    output_root : Path
        Where the job writes.
    """
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        written = f" ({exc.filename})" if exc.filename else ""
        return (
            f"{output_root}: no space left on device while writing the job's output{written}: "
            "the partial output was removed; free space, then change or rename the job folder to run it again"
        )
    if not folder.is_dir():
        return str(JobFolderDeleted(folder))
    return None


def _finish_failed(run: JobRun, error: str) -> BusMessage:
    """End a failed job: remove its outputs, record the failure and finish the record; the ``failed`` status.

    The outputs go first, so on a full disk their space is free for the
    record's end. When even that cannot be written, the cut-off record is
    salvaged into a new one; when that fails too, nothing of the job stays
    on disk and only the journal and the bus carry the failure.
    """
    for path in run.work_dir.iterdir():
        if path.is_dir():
            shutil.rmtree(path)
        elif path.name != RECORD_NAME:
            path.unlink()
    try:
        run.log("error", error)
        final = run.status("failed", finished_at=utc_now(), error=error)
        run.recorder.finish()
        _fsync_files(run.work_dir)
        return final
    except Exception:  # the record's writer may be broken by the write that failed: salvage what it holds
        run.recorder.close_unfinished()
    final = run.status("failed", finished_at=utc_now(), error=error, record=False)
    mcap = run.task.config.mcap
    salvaged = run.work_dir / f"salvaged-{RECORD_NAME}"
    try:
        recorder = salvage(run.work_dir / RECORD_NAME, salvaged, mcap.compression, mcap.chunk_size_bytes)
        recorder.write(TOPIC_LOG, LogRecord(level="error", message=error))
        recorder.write(TOPIC_BUS, final.record())
        record_ros2(recorder, final, run.task.config.ros2)
        recorder.write(TOPIC_STATE, StateChangeRecord(job_id=run.task.job_id, state="failed", at=utc_now(), error=error))
        recorder.finish()
        os.replace(salvaged, run.work_dir / RECORD_NAME)
        _fsync_files(run.work_dir)
    except OSError:
        shutil.rmtree(run.work_dir, ignore_errors=True)
        run.emit(("log", "error", "no space even for the job's record: nothing of the job is kept on disk", {"path": str(run.work_dir)}))
    return final


def _fsync_files(folder: Path) -> None:
    """Push every file of ``folder`` and its set folders to disk."""
    for path in folder.rglob("*"):
        if path.is_dir():
            continue
        with open(path, "rb") as stream:
            os.fsync(stream.fileno())


def _fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` durable."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def _die_with_parent(parent_pid: int) -> None:
    """Ask Linux to SIGKILL this process when the daemon dies, so no orphan finishes a job the restarted daemon re-runs."""
    libc = ctypes.CDLL(None, use_errno=True)
    pr_set_pdeathsig = 1
    libc.prctl(pr_set_pdeathsig, signal.SIGKILL)
    # the daemon may have died before prctl took effect
    if os.getppid() != parent_pid:
        os._exit(1)


def _time_limit(signum, frame) -> None:
    raise TimeLimitExceeded()


def _withdrawn(signum, frame) -> None:
    raise Withdrawn()


def worker_main(connection: Connection, parent_pid: int) -> None:
    """Entry point of a worker process: announce readiness, take one job, run it, report, exit.

    Parameters
    ----------
    connection : Connection
        Duplex pipe to the daemon.
    parent_pid : int
        The daemon's pid.
    """
    _die_with_parent(parent_pid)
    # Ctrl-C in a terminal reaches the whole process group: the daemon decides what happens to jobs
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(SIGNAL_TIME_LIMIT, _time_limit)
    signal.signal(SIGNAL_WITHDRAWN, _withdrawn)
    connection.send(("ready", os.getpid()))
    task = connection.recv()
    if task is None:
        return
    run_job(task, connection.send)
    connection.close()
