"""The job's steps in order (:data:`STEPS`): inputs, loading, design, its record, build placement, output files.

Each step takes the :class:`~fcsod.job.task.JobRun`, records what it made and returns it, frozen
(:class:`~fcsod.job.task.JobInputs`, :class:`~fcsod.job.task.LoadedParts`, :class:`~fcsod.job.task.DesignedSets`,
...), which the runner keeps in the run for the steps after them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
from collections.abc import Callable, Iterator

import numpy as np

import fcso
from fcso import DesignResult, MeshError, load_parts
from fcso.layout import FINGER_STL, FINGERPAD_STL, set_folder
from fcso.output.files import sets_output_files
from fcso.sets import design_sets

from .. import __version__
from ..bus.messages import (
    ENCODING_STL,
    BusMessage,
    CandidateRecord,
    DesignAttachment,
    DesignRecord,
    GraspsMessage,
    InputHashesRecord,
    JobSpecRecord,
    PlacementMessage,
    PoseRecord,
    QualityMessage,
    SamplesRecord,
    ScenarioSummary,
    job_key,
    utc_now,
)
from ..plate.build3mf import Build, BuildItem, export_build_3mf, make_names_unique
from ..record.recorder import (
    TOPIC_CANDIDATES,
    TOPIC_DESIGN,
    TOPIC_GRASPS,
    TOPIC_INPUTS,
    TOPIC_PLACEMENT,
    TOPIC_POSES,
    TOPIC_SAMPLES,
    TOPIC_SPEC,
)
from ..record.scene import base64_text, build_scene_update, build_transforms, design_transforms, scene_update
from .cell_grasps import cell_grasps, verification_note
from .finger_sets import design_messages, place_sets, plan_message
from .inputs import check_parts, hash_inputs, job_inputs, read_manifest
from .reuse import step_add_to_library, step_reuse, step_reused_outputs
from .task import (
    BUILD_NAME,
    FINGER_SET,
    HELD_BUILD_NAME,
    PROGRESS_INTERVAL_S,
    DesignedSets,
    JobFolderDeleted,
    JobInputs,
    JobRun,
    LoadedParts,
    Outputs,
    Placed,
    RecordedDesign,
    StepResult,
    Verified,
)
from .verification import (
    VERIFICATION_CACHE_NAME,
    choose_by_verification,
    job_settings,
    write_chosen_verification,
)

#: Retained quality (E / E*) below which a finger set's part is flagged: a finger near zero quality for it.
NEAR_ZERO_RETAINED = 0.05


def step_inputs(run: JobRun) -> JobInputs:
    """Hash the inputs, read and validate the manifest, check the part files against the limits."""
    config = run.task.config
    files = hash_inputs(run.folder, job_inputs(run.folder), config.limits.max_file_bytes)
    run.recorder.write(TOPIC_INPUTS, InputHashesRecord(job_id=run.task.job_id, files=files))
    # the job's record holds what was read, as far as it went, even when a check fails
    manifest_text, settings, build_settings, parts = None, None, None, []
    try:
        manifest, manifest_text = read_manifest(run.folder, config.design, config.limits, config.build)
        # the daemon's [compute] says where every job runs; a manifest cannot send work elsewhere. The design's
        # measure predicts the verification the job's [verify] sets up, under its conditions
        verify_settings = job_settings(config.verify, manifest.verify)
        verify = verify_settings.verify_config()
        settings = manifest.design_config(config.design).updated(
            {"compute": config.compute.model_dump(), "verify": verify.model_dump()}
        )
        if not verify_settings.enabled:
            # [verify] enabled = false turns every simulation off: the sets are judged by the measure alone
            settings = settings.updated({"finger_sets": {"truth_budget_s": 0.0}})
        elif settings.finger_sets.truth_budget_s > 0 and "cache_dir" not in verify.model_fields_set:
            # the sets' fingers simulated during the design go to the cache the verification after done reads (the
            # daemon's state folder: the service may write nothing else), so it repeats none of them
            settings = settings.updated({"verify": {"cache_dir": str(config.state.dir / VERIFICATION_CACHE_NAME)}})
        build_settings = manifest.build_config(config.build)
        parts = check_parts(run.folder, manifest, config.limits)
    finally:
        run.recorder.write(
            TOPIC_SPEC,
            JobSpecRecord(
                job_id=run.task.job_id,
                folder=run.task.folder,
                manifest=manifest_text,
                parts=[{**p.entry.model_dump(), "file": p.entry.file} for p in parts],
                settings=(settings or config.design).model_dump(mode="json"),
                build=(build_settings or config.build).model_dump(mode="json"),
                fcsod_version=__version__,
                fcso_version=fcso.__version__,
            ),
        )
    return JobInputs(files, manifest, manifest_text, settings, verify_settings, build_settings, parts)


def step_load(run: JobRun) -> LoadedParts:
    """Load and validate every part (closed volume, units, shells, face limit) and assemble the job's build.

    Parts come from :func:`fcso.load_parts`, the loader ``fcso design`` uses:
    overlapping shells are one solid, separate solids are separate parts,
    a 3MF gives one part per distinct object. A loose part is designed once
    and is ``quantity`` build items, placed when its manifest entry has a
    transform; a 3MF part keeps the transform of every build item holding it.
    """
    max_faces = run.task.config.limits.max_faces
    items: list[BuildItem] = []
    distinct: list[fcso.Part] = []
    for part in run.job_inputs.parts:
        loaded = load_parts(
            part.path,
            units=part.entry.units,
            scale_to_mm=part.entry.scale_to_mm,
            repair=run.task.config.parts.repair if run.manifest.repair is None else run.manifest.repair,
            split_bodies=run.settings.parts.split_bodies,
            max_repair_volume_change_percent=run.settings.parts.repair_max_volume_change_percent,
            max_repair_deviation_mm=run.settings.parts.repair_max_deviation_mm,
            max_uncompressed_bytes=run.task.config.limits.max_3mf_uncompressed_bytes,
        )
        for one in loaded:
            if len(one.mesh.faces) > max_faces:
                raise MeshError(
                    part.path, f"{one.name}: {len(one.mesh.faces)} triangles, more than limits.max_faces ({max_faces})"
                )
            if part.path.suffix.lower() == ".3mf":
                items.extend(
                    BuildItem(one.name, one.mesh, transform, "part", part.path.stem) for transform in one.instances
                )
            else:
                transform = None if part.entry.transform is None else np.asarray(part.entry.transform, dtype=float)
                items.extend(
                    BuildItem(one.name, one.mesh, transform, "part", part.path.stem) for _ in range(part.entry.quantity)
                )
                # the pieces to pick (fcso counts a part's build items)
                one.instances = [transform] * part.entry.quantity
            distinct.append(one)
            shells = f", {one.shell_note}" if one.shell_note else ""
            run.log(
                "info",
                f"loaded {part.entry.file} as {one.name}: {len(one.mesh.faces)} triangles, extents "
                f"{np.round(one.mesh.extents, 2).tolist()} mm{shells}",
            )
            for warning in one.warnings:
                run.log("warning", warning)
    if len(distinct) > run.task.config.limits.max_parts:
        raise MeshError(
            run.folder,
            f"{len(distinct)} distinct part meshes, more than limits.max_parts ({run.task.config.limits.max_parts})",
        )
    make_names_unique(items)
    placed = sum(1 for item in items if item.transform is not None)
    run.log("info", f"build: {len(items)} part items, {placed} placed by the job, {len(items) - placed} to pack")
    return LoadedParts(distinct, Build(items=items, source=str(run.folder)))


def step_design(run: JobRun) -> DesignedSets:
    """Run fcso's design of the job's finger sets (one or several), logging progress per stage."""
    last: dict[str, float] = {}

    def progress(stage: str, done: int, total: int, note: str = "") -> None:
        now = time.monotonic()
        if stage in last and done < total and now - last[stage] < PROGRESS_INTERVAL_S:
            return
        last[stage] = now
        run.log("info", f"{stage} {done}/{total}" + (f": {note}" if note else ""), stage=stage, done=done, total=total)

    sets = design_sets(run.loaded, run.settings, progress=progress)
    job = sets.job_report or sets.designs[0].report
    # what the design warns of (parts left out as ungraspable, files split into
    # several solids) travels with the job's done status
    warnings = list(job.warnings)
    for entry in sets.report.ungraspable if sets.report else sets.designs[0].report.ungraspable:
        run.log("warning", f"{entry.part} (pose {entry.pose_index}) cannot be grasped: {entry.reason}")
    if sets.report is not None:
        for entry in sets.report.sets:
            if entry.worst_retained < NEAR_ZERO_RETAINED:
                note = (
                    f"finger set {entry.set} keeps {entry.worst_retained:.3f} of a part's quality (below "
                    f"{NEAR_ZERO_RETAINED}): near zero, route its parts elsewhere or approve them knowingly"
                )
                warnings.append(note)
                run.log("warning", note)
        for line in (
            sets.report.search.description,
            *(
                f"set {s.set}: {', '.join(s.parts)} ({fcso.quality_words(s.quality, run.settings.quality.measure)}, "
                f"worst retained {s.worst_retained:.3f})"
                for s in sets.report.sets
            ),
        ):
            run.log("info", f"finger sets: {line}")
    return DesignedSets(sets, tuple(warnings))


def step_choose_by_verification(run: JobRun) -> Verified | None:
    """Verify every finger set's finger before it is placed, where the job's ``[verify]`` asks it (one set: choose
    among the best candidates), and hold the job when one misses the delivery policy."""
    return choose_by_verification(run)


def step_record_design(run: JobRun) -> RecordedDesign:
    """Record poses, samples with rejections, every candidate row, the design, the grasps and the 3D scene."""
    files: dict[str, bytes] = {}
    for number, result in enumerate(run.sets.designs, start=1):
        files.update(_record_one_design(run, result, number))
    run.recorder.write(TOPIC_GRASPS, GraspsMessage(job_id=run.task.job_id, grasps=job_grasps(run)))
    return RecordedDesign(files)


def job_grasps(run: JobRun) -> list:
    """Every finger set's grasps as the cell runs them (:func:`fcsod.job.cell_grasps.cell_grasps`): the verdict of a
    verification made before the job is done, or where it follows."""
    several = run.sets.several
    unverified = verification_note(run.verify_settings.enabled, several)
    verifications = (
        [finger.verification for finger in run.verified.fingers]
        if run.verified is not None
        else [None] * len(run.sets.designs)
    )
    return [
        grasp
        for design, verification in zip(run.sets.designs, verifications)
        for grasp in cell_grasps(
            run.task.job_id,
            design.report.grasps,
            design.report.settings,
            design.report.finger.flat_pads,
            verification,
            unverified,
        )
    ]


def _record_one_design(run: JobRun, result: DesignResult, number: int) -> dict[str, bytes]:
    """Record one finger set's poses, samples, candidates, design and scene; its meshes for the outputs (path ->
    STL)."""
    recorder, report = run.recorder, result.report
    for scenario in report.scenarios:
        recorder.write(
            TOPIC_POSES,
            PoseRecord(
                part=scenario.part,
                pose_index=scenario.pose_index,
                probability=scenario.pose_probability,
                rest_transform=scenario.rest_transform,
            ),
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
        recorder.write(
            TOPIC_CANDIDATES,
            CandidateRecord(
                candidate=candidate, best=candidate.index == report.best, per_scenario=candidate.per_scenario
            ),
        )
    # report.json and report.html wait for the placement section (step_outputs)
    folder = f"{set_folder(number)}/" if run.sets.several else ""
    finger = result.finger.export(file_type="stl")
    pad = result.fingerpad.export(file_type="stl")
    recorder.write(
        TOPIC_DESIGN,
        DesignRecord(
            finger_stl_base64=base64_text(finger),
            finger_sha256=hashlib.sha256(finger).hexdigest(),
            fingerpad_sha256=hashlib.sha256(pad).hexdigest(),
            finger_volume_mm3=report.finger.volume_mm3,
            finger_watertight=report.finger.watertight,
            finger_set=number,
        ),
    )
    run.scene(
        scene_update(result, prefix=f"{set_folder(number)}-" if run.sets.several else ""),
        design_transforms(result, time.time_ns()),
    )
    return {f"{folder}{FINGER_STL}": finger, f"{folder}{FINGERPAD_STL}": pad}


def step_placement(run: JobRun) -> Placed:
    """Place every finger set's copies into the job's build volume (:func:`fcsod.job.finger_sets.place_sets`, one set or
    several):
    ``build.3mf``, the report's placement section, record, scene, bus message.

    Fingers that do not fit leave the job done with its design, a warning
    and the free build height that was missing.
    """
    several = run.sets.several
    placements = place_sets(run.build, run.sets, run.build_settings)
    report = placements[-1].report
    for placed in placements:
        run.recorder.write(TOPIC_PLACEMENT, placed.report)

    def build_3mf(items) -> bytes:
        return export_build_3mf(
            items,
            job_id=run.task.job_id,
            application=f"fcsod {__version__}",
            creation_date=utc_now(),
            finger_set=FINGER_SET,
        )

    if run.held is None:
        files = {BUILD_NAME: build_3mf(placements[-1].items)}
    else:
        # the finger waits for an operator: the build holds the parts, placed as they would be; the build with the
        # finger placed waits beside it for fcsod approve
        files = {
            BUILD_NAME: build_3mf([item for item in placements[-1].items if item.kind != "finger"]),
            HELD_BUILD_NAME: build_3mf(placements[-1].items),
        }
    # the job's report: the job report with several sets, the design's with one (the one verification may have chosen)
    job = run.sets.job_report if several else run.result.report
    placement = report.model_dump(mode="json")
    warnings, not_fitted = list(job.warnings), []
    for number, placed in enumerate(placements, start=1):
        label, prefix = (f"placement of set {number}", f"set {number}: ") if several else ("placement", "")
        run.log("info" if placed.report.fingers_fit else "warning", f"{label}: {placed.report.message}")
        if not placed.report.fingers_fit:
            not_fitted.append(f"{prefix}{placed.report.message}")
            warnings.append(f"{prefix}{placed.report.message}")
        if not several:
            for warning in placed.report.warnings:
                run.log("warning", f"placement: {warning}")
    if several:
        placement["finger_sets"] = [
            {
                "set": k,
                "finger_copies_placed": p.report.finger_copies_placed,
                "fingers_fit": p.report.fingers_fit,
                "message": p.report.message,
            }
            for k, p in enumerate(placements, start=1)
        ]
    update: dict = {"placement": placement}
    if len(warnings) > len(job.warnings):
        update["warnings"] = warnings
    if several:
        sets = dataclasses.replace(run.sets, job_report=job.model_copy(update=update))
    else:
        placed_design = dataclasses.replace(run.result, report=job.model_copy(update=update))
        sets = dataclasses.replace(run.sets, designs=[placed_design, *run.sets.designs[1:]])
    run.scene(
        build_scene_update(placements[-1].items, report, run.build_settings),
        build_transforms(placements[-1].items, run.build_settings, time.time_ns()),
    )
    bus = run.task.config.bus
    summary = report.model_dump(include=set(PlacementMessage.model_fields) - {"job_id", "file"})
    summary.update(
        fingers_fit=all(p.report.fingers_fit for p in placements),
        finger_copies_placed=sum(p.report.finger_copies_placed for p in placements),
        finger_copies_requested=sum(p.report.finger_copies_requested for p in placements),
    )
    body = PlacementMessage(job_id=run.task.job_id, file=BUILD_NAME, **summary)
    # published after the design's messages (step_outputs puts them first)
    message = BusMessage.json_body(bus.prefix, bus.cell, "placement", body)
    return Placed(sets, files, message, tuple(not_fitted))


def step_outputs(run: JobRun) -> Outputs:
    """Write every output file into the work folder and record their hashes; record the bus messages.

    ``report.json`` and ``report.html`` are made here, after every step that
    adds to the report; the meshes are those the design record holds. The
    delivered candidate's verification (``top_k``) is written here too.
    """
    files = {**sets_output_files(run.sets), **run.recorded.files, **run.placed.files}
    run.write_files(files)
    # the delivered candidate's verification (top_k) joins the files before they are hashed
    verification_files, after_done = write_chosen_verification(run)
    files.update(verification_files)
    run.record_files(files)
    bus, report = run.task.config.bus, run.result.report
    if run.sets is not None and run.sets.report is not None:
        copies = [
            int(p.get("finger_copies_placed", 0))
            for p in (run.sets.job_report or report).placement.get("finger_sets", [])
        ] or [report.placement["finger_copies_placed"]]
        plan = plan_message(bus.prefix, bus.cell, run.task.job_id, run.sets, files, copies)
    if run.sets.several:
        grasps = job_grasps(run)
        outgoing = [
            BusMessage.json_body(bus.prefix, bus.cell, "grasps", GraspsMessage(job_id=run.task.job_id, grasps=grasps)),
            *design_messages(bus.prefix, bus.cell, run.task.job_id, run.sets, files),
            plan,
            run.placed.message,
        ]
        for message in outgoing:
            run.record_published(message)
        return Outputs(files, tuple(outgoing), after_done)
    best = next(c for c in report.candidates if c.index == report.best)
    quality = QualityMessage(
        job_id=run.task.job_id,
        quality=best.quality,
        quality_measure=run.settings.quality.measure,
        mean_quality=best.mean_effective_area,
        pad_case=best.pad_case,
        candidates_evaluated=report.search.evaluated,
        candidates_total=report.search.candidates_total,
        proven_optimal=report.search.proven_optimal,
        scenarios=[
            ScenarioSummary(
                part=s.part,
                pose_index=s.pose_index,
                rles=q.rles,
                contact_area_mm2=q.contact_area_mm2,
                effective_area_mm2=q.effective_area,
            )
            for s, q in zip(report.scenarios, best.per_scenario)
        ],
        finger_volume_mm3=report.finger.volume_mm3,
        finger_watertight=report.finger.watertight,
        min_pad_thickness_mm=report.finger.min_pad_thickness_mm,
        warnings=report.warnings,
        timings_s=report.timings_s,
    )
    finger = files[FINGER_STL]
    attachment = DesignAttachment(
        job_id=run.task.job_id, sha256=hashlib.sha256(finger).hexdigest(), size_bytes=len(finger)
    )
    outgoing = [
        BusMessage.json_body(bus.prefix, bus.cell, "quality", quality),
        BusMessage.json_body(
            bus.prefix, bus.cell, "grasps", GraspsMessage(job_id=run.task.job_id, grasps=job_grasps(run))
        ),
        BusMessage(
            run.task.job_id,
            "design",
            job_key(bus.prefix, bus.cell, run.task.job_id, "design"),
            ENCODING_STL,
            finger,
            attachment.model_dump_json().encode(),
        ),
        *([plan] if run.sets is not None and run.sets.report is not None else []),
        run.placed.message,
    ]
    for message in outgoing:
        run.record_published(message)
    return Outputs(files, tuple(outgoing), after_done)


def step_folder_kept(run: JobRun) -> None:
    """Fail the job when its folder was deleted while it ran: a withdrawn print job gets no fingers."""
    if not run.folder.is_dir():
        raise JobFolderDeleted(run.folder)


#: The job's steps in order; each is logged and flushed to the record when it ends.
STEPS: list[Callable[[JobRun], StepResult]] = [
    step_inputs,
    step_load,
    step_reuse,
    step_design,
    step_choose_by_verification,
    step_record_design,
    step_placement,
    step_outputs,
    step_folder_kept,
    step_add_to_library,
]

#: The steps after :func:`step_reuse` of a job the finger library serves.
REUSED_STEPS: list[Callable[[JobRun], StepResult]] = [step_reused_outputs, step_folder_kept]


def job_steps(run: JobRun) -> Iterator[Callable[[JobRun], StepResult]]:
    """The job's steps: :data:`STEPS`, or :data:`REUSED_STEPS` once :func:`step_reuse` found every part served."""
    for step in STEPS:
        yield step
        if run.reuse is not None:
            yield from REUSED_STEPS
            return
