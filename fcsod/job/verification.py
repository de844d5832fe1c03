"""Grasp verification of a job's design in simulation (fcso.sim, METHOD §12).

With a delivery policy other than ``always``, the design step verifies
every finger set's finger before it is placed, one set or several alike
(:func:`choose_by_verification`), and a finger that misses the policy holds
the job; with ``[verify] top_k > 0`` each set's candidates are verified in
the order of the design's measure and the first that passes every scenario
is delivered, one set or several alike. These
verifications are then part of the job's output (``verification.json``,
the report's section, ``verification.mcap``, in each set's folder with
several, recorded in ``job.mcap``) and their messages follow the ``done``
status. Otherwise, with ``[verify] enabled``, the worker verifies the
designs after the job is ``done`` and its design published
(:func:`verify_done_job`). A job of several finger sets publishes each
set's on ``.../verification/<set>``. Its section goes
into ``verification.html`` beside ``report.html``, which stays as
``job.mcap`` vouches for it. The daemon
journals that verification as running from the moment the job is done, so
a crash or a stop during it runs it again after the restart from the job's
output folder (:func:`verify_again`); its files are written only once every
set is simulated, and its messages published only once they are all
written. A verification over ``time_limit_seconds`` or that fails is
published as ``failed`` on the verification key, with nothing of it on disk;
the job stays done. A job the finger library serves designs nothing: each
reused finger is verified after it is done on the job's own parts and the
grasps delivered for them (:func:`reused_designs`). ``[verify] enabled =
false`` turns all of it off, the choice among ``top_k`` candidates included.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import trimesh

from fcso.layout import FINGER_STL, FINGERPAD_STL, REPORT_HTML, REPORT_JSON, VERIFICATION_JSON, set_folder
from fcso.output.read import read_report, read_stl, reload_parts
from fcso.output.verification_page import load_design, ranking_html, write_verification
from fcso.sim.choose import verify_top
from fcso.sim.config import VerifyConfig, with_print_density
from fcso.sim.report import (
    VerificationReport,
    better_than_flat,
    not_held,
    reused_note,
    scenario_verdict,
    verdict_text,
    weakest_hold_n,
)
from fcso.sim.verify import DesignUnderTest, design_under_test, finger_hull, grasp_case, verify_delivered

from ..bus.messages import BusMessage, ScenarioOutcome, VerificationMessage
from ..config import VerifySettings
from ..record.recorder import (
    TOPIC_BUS,
    TOPIC_VERIFICATION,
    TOPIC_VERIFICATION_SCENE,
    VERIFICATION_RECORD_NAME,
    Recorder,
)
from ..record.scene import scene_updates
from .events import Emit, Log, VerificationFinished, VerificationStarted
from .inputs import read_manifest
from .reuse import ReuseReport
from .task import (
    SetVerified,
    TimeLimitExceeded,
    VerificationTask,
    Verified,
    time_limit_error,
    unfinished_verification_message,
)


def job_settings(daemon: VerifySettings, manifest: VerifySettings | None) -> VerifySettings:
    """The job's ``[verify]``: its manifest's when it has one, else the daemon's."""
    return manifest if manifest is not None else daemon


def choose_by_verification(run) -> Verified | None:
    """Design step, for every finger set alike (one or several): with a delivery policy other than ``always``,
    verify each set's finger before it is placed; with ``top_k > 0`` each set's candidates are verified in the
    measure's order and the first that passes is delivered (:func:`fcso.sim.choose.verify_top`). The job is held
    (:attr:`Verified.held`) when a finger misses the policy (:func:`held_reason`). None when nothing is verified
    before the job is done."""
    settings = _settings(run)
    several = run.sets.several
    choosing = settings.top_k > 0
    if not settings.enabled or not (choosing or settings.deliver != "always"):
        return None
    sets, fingers, held, warnings = run.sets, [], [], []
    for number, result in enumerate(run.sets.designs, start=1):
        label = f"finger set {number}: " if several else ""
        config = _verify_config(settings, result.report.settings, run.task.config.state.dir)
        if choosing:
            chosen, verification, design, ranking = verify_top(result, settings.top_k, config, _progress(run.log))
            if chosen is not result:
                # the sets' report and the pick plan (the plan message, the finger library) follow the delivered finger
                sets = sets.delivered(number, chosen, verification.choice)
            fingers.append(SetVerified(verification, design, ranking_html(ranking, verification.choice)))
            run.log("info", f"verification delivered {verification.choice}")
        else:
            design = design_under_test(result)
            verification = verify_delivered(design, config, _progress(run.log))
            fingers.append(SetVerified(verification, design, ""))
        run.log("info" if verification.passed else "warning", f"{label}verification: {verdict_text(verification)}")
        if missed := not_held(verification):
            # a finger near zero quality: said on the done status too, whatever the policy
            warnings.append(
                f"{label}the finger does not hold its part at all in {', '.join(missed)} (0 N in every push)"
            )
        if (reason := held_reason(verification, settings.deliver)) is not None:
            held.append(f"{label}{reason}")
    if held:
        run.log("warning", f"held for an operator: {'; '.join(held)}")
    return Verified(sets, tuple(fingers), "; ".join(held) or None, tuple(warnings))


def held_reason(verification: VerificationReport, deliver: str) -> str | None:
    """Why a finger with this verification misses the delivery policy ``deliver`` (``[verify] deliver``), or None
    when it is delivered."""
    verdict = verdict_text(verification)
    if deliver == "verified" and not verification.passed:
        missed = "did not pass verification"
    elif deliver == "better_than_flat" and not better_than_flat(verification):
        missed = "is not better than flat pads"
    else:
        return None
    return (
        f"the finger {missed} ([verify] deliver = {deliver!r}; {verdict}): fcsod approve places and publishes it, "
        "fcsod reject fails the job"
    )


#: The page of a verification made after the job is done: ``report.html`` stays as ``job.mcap`` vouches for it.
VERIFICATION_HTML = "verification.html"


def write_chosen_verification(run) -> tuple[dict[str, bytes], tuple[BusMessage, ...]]:
    """Output step: the verifications :func:`choose_by_verification` made, into the work folder (each set's into its
    folder with several; after the job's files are written, before they are hashed).

    Returns
    -------
    files : dict
        ``verification.json``, the report's section and ``verification.mcap`` of each (path -> content), to join the
        job's files (hashed in ``job.mcap`` like the others); empty when nothing was verified.
    after_done : tuple of BusMessage
        Their messages, recorded, to publish after the ``done`` status.
    """
    if run.verified is None:
        return {}, ()
    several = run.sets.several
    files, messages = {}, []
    for number, finger in enumerate(run.verified.fingers, start=1):
        folder = f"{set_folder(number)}/" if several else ""
        message = _bus_message(
            run.task.config,
            run.task.job_id,
            finger.verification,
            f"{folder}{VERIFICATION_JSON}",
            number if several else None,
        )
        written = _write(
            run.work_dir / folder,
            finger.verification,
            finger.design,
            finger.ranking_html,
            message,
            run.task.config.mcap,
            REPORT_HTML,
        )
        files.update({f"{folder}{path.name}": path.read_bytes() for path in written})
        run.record_published(message)
        messages.append(message)
    return files, tuple(messages)


def verification_after_done(run) -> VerifySettings | None:
    """The job's ``[verify]`` when its design is to be verified after it is done, else None.

    Not when verification is off, nor when the design step already verified
    the delivered designs; a job the finger library serves has its reused
    fingers verified on its own parts.
    """
    settings = _settings(run)
    if not settings.enabled or run.verified is not None:
        return None
    return settings


def verify_done_job(run, final_dir: Path, settings: VerifySettings) -> None:
    """After the job is done and journalled: verify every finger set's design (in memory), write, record, publish.

    A job the finger library served verifies each reused finger on this job's parts and grasps
    (:func:`reused_designs`). Ends with one :class:`~fcsod.job.events.VerificationFinished`.
    """
    if run.reuse is not None:
        parts = {p.name: p.mesh for p in run.loaded}
        _verify_designs(run.task.config, run.task.job_id, reused_designs(final_dir, parts), settings, run.emit)
        return
    several = run.sets.several
    designs = [
        (final_dir / set_folder(number) if several else final_dir, number if several else None, result)
        for number, result in enumerate(run.sets.designs, start=1)
    ]
    _verify_designs(
        run.task.config,
        run.task.job_id,
        [(out, number, lambda r=r: (design_under_test(r), r.report.settings)) for out, number, r in designs],
        settings,
        run.emit,
    )


def verify_again(task: VerificationTask, emit: Emit) -> None:
    """Run a done job's verification again (after a crash or a stop cut it off), from its output folder.

    The job's ``[verify]`` is read again from its folder's ``job.toml`` under
    the daemon's current settings. Starts with :class:`VerificationStarted`
    and ends with one :class:`VerificationFinished`.
    """
    config = task.config
    final_dir = config.output.root / task.job_id
    _remove_verification_files(final_dir)
    try:
        manifest, _ = read_manifest(Path(task.folder), config.design, config.limits, config.build)
        settings = job_settings(config.verify, manifest.verify)
    except Exception as exc:  # the job folder changed or went away since the job ran
        emit(VerificationStarted(config.verify.time_limit_seconds))
        _unfinished(config, task.job_id, [None], "failed", f"the job's settings cannot be read again: {exc}", emit)
        return
    emit(VerificationStarted(settings.time_limit_seconds))
    if is_reuse_report(final_dir):
        try:
            designs = reused_designs(final_dir, None)
        except Exception as exc:  # the job's report cannot be read: its verification cannot run again
            _unfinished(config, task.job_id, [None], "failed", f"{type(exc).__name__}: {exc}", emit)
            return
    else:
        sets = sorted(final_dir.glob(f"set-*/{REPORT_JSON}"))
        folders = [(p.parent, int(p.parent.name.removeprefix("set-"))) for p in sets] or [(final_dir, None)]
        designs = [(out, number, lambda out=out: _loaded(out)) for out, number in folders]
    if not settings.enabled:
        _unfinished(config, task.job_id, [n for _, n, _ in designs], "skipped", "verification is off now", emit)
        return
    _verify_designs(config, task.job_id, designs, settings, emit)


def _loaded(folder: Path):
    report, design = load_design(folder)
    return design, report.settings


def is_reuse_report(folder: Path) -> bool:
    """Whether the job output ``folder`` is a job the finger library served (its ``report.json`` names reused
    fingers)."""
    path = folder / REPORT_JSON
    return path.is_file() and "reused" in json.loads(path.read_text(encoding="utf-8"))


def reused_designs(final_dir: Path, parts: dict[str, trimesh.Trimesh] | None) -> list[tuple]:
    """The designs under test of a job the finger library served: each reused finger with this job's parts and the
    grasps it delivered for them, in the form :func:`_verify_designs` takes.

    Each finger is read from the delivering job's folder (its finger, pad and ``report.json`` with the settings it
    was designed with, which a reuse requires to be this job's); ``parts`` are the job's loaded meshes, or None to
    read them again from the files the job's report names. A job served by several fingers verifies each as its
    set (``set-<n>/``, ``.../verification/<n>``), as a job of several finger sets does.
    """
    report = ReuseReport.model_validate_json((final_dir / REPORT_JSON).read_text(encoding="utf-8"))
    several = len(report.reused) > 1

    def build(number: int):
        reused = report.reused[number - 1]
        meshes = parts
        if meshes is None:
            meshes = {part.name: part.mesh for part in reload_parts(report, final_dir)}
        delivered = (final_dir / reused.finger_file).parent
        design = read_report(delivered)
        served = {p.part for p in reused.parts}
        cases = [grasp_case(design, g, meshes[g.part]) for g in report.grasps if g.part in served]
        finger = read_stl(delivered / FINGER_STL)
        if several:
            (final_dir / set_folder(number)).mkdir(exist_ok=True)
        return DesignUnderTest(cases, read_stl(delivered / FINGERPAD_STL), finger_hull(design, finger)), design.settings

    return [
        (
            final_dir / set_folder(number) if several else final_dir,
            number if several else None,
            lambda n=number: build(n),
        )
        for number in range(1, len(report.reused) + 1)
    ]


def _verify_designs(config, job_id: str, designs, settings: VerifySettings, emit: Emit) -> None:
    """Verify every design, then write each one's files, then send :class:`VerificationFinished` with every message.

    ``designs``: (output folder, finger set or None, callable giving the
    DesignUnderTest and the design's settings). A time limit or a failure
    removes whatever was written and sends a ``failed`` message per key.
    """

    def log(level: str, message: str, **fields) -> None:
        # job.mcap is closed: these lines go to the daemon's log only
        emit(Log(level, message, fields))

    started = time.perf_counter()
    try:
        results = []
        for out, number, build in designs:
            name = "verification" if number is None else f"verification of finger set {number}"
            log("info", f"{name}: started")
            design, design_settings = build()
            config_of_design = _verify_config(settings, design_settings, config.state.dir)
            verification = verify_delivered(design, config_of_design, _progress(log))
            results.append((out, number, name, design, verification))
        messages = []
        for out, number, name, design, verification in results:
            file = VERIFICATION_JSON if number is None else f"{set_folder(number)}/{VERIFICATION_JSON}"
            message = _bus_message(config, job_id, verification, file, number)
            _write(out, verification, design, "", message, config.mcap, VERIFICATION_HTML)
            messages.append(message)
            reused = reused_note(verification)
            log(
                "info" if verification.passed else "warning",
                f"{name}: design {'passed' if verification.passed else 'did not pass'} in "
                f"{time.perf_counter() - started:.1f} s"
                + (f" ({reused})" if reused else "")
                + f": {verdict_text(verification)}",
            )
            for warning in verification.warnings:
                log("warning", f"{name}: {warning}")
    except TimeLimitExceeded:
        error = time_limit_error(settings.time_limit_seconds, "verification", "verify.time_limit_seconds")
        _unfinished(config, job_id, [number for _, number, _ in designs], "failed", error, emit, designs)
        return
    except Exception as exc:  # the design is delivered; its verification failed
        error = f"{type(exc).__name__}: {exc}"
        _unfinished(config, job_id, [number for _, number, _ in designs], "failed", error, emit, designs)
        return
    emit(VerificationFinished("done", None, messages))


def _unfinished(config, job_id: str, sets: list, state: str, error: str, emit, designs=()) -> None:
    """Remove what a cut-off verification wrote and send :class:`VerificationFinished`, a message per key."""
    for out, _, _ in designs:
        _remove_verification_files(out)
    emit(Log("warning", f"verification {state}: {error}"))
    emit(
        VerificationFinished(
            state,
            error,
            [unfinished_verification_message(config.bus, job_id, state, error, number) for number in sets],
        )
    )


def _remove_verification_files(folder: Path) -> None:
    """Remove a verification's files (and their temporary names) from a job's folder and its set folders."""
    for path in [folder, *sorted(folder.glob("set-*"))]:
        for name in (VERIFICATION_JSON, VERIFICATION_RECORD_NAME, VERIFICATION_HTML):
            for leftover in (path / name, path / f".{name}.tmp"):
                leftover.unlink(missing_ok=True)


def _write(
    out: Path,
    verification: VerificationReport,
    design: DesignUnderTest,
    extra: str,
    message: BusMessage,
    mcap,
    page_name: str,
) -> list[Path]:
    """``verification.mcap``, the verification section in the page ``page_name`` and ``verification.json`` (last: it
    says the verification is there), each written under a temporary name and renamed; the files written."""
    record = out / VERIFICATION_RECORD_NAME
    temporary = out / f".{VERIFICATION_RECORD_NAME}.tmp"
    _record(temporary, verification, design, message, mcap)
    temporary.replace(record)
    return [record, *reversed(write_verification(out, verification, design, extra, page_name))]


def _settings(run) -> VerifySettings:
    manifest = run.manifest.verify if run.manifest is not None else None
    return job_settings(run.task.config.verify, manifest)


def _progress(log: Callable) -> Callable[[str, int, int], None]:
    last = [0.0]

    def progress(stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        if done < total and now - last[0] < 2.0:
            return
        last[0] = now
        log("info", f"{stage} {done}/{total}", stage=stage, done=done, total=total)

    return progress


#: The daemon's cache of collision pieces and simulation outcomes, in its state folder beside the journal: a
#: verification restarted after a kill or a restart reads what was simulated before it (:mod:`fcso.sim.outcomes`).
VERIFICATION_CACHE_NAME = "verification-cache"


def _verify_config(settings: VerifySettings, design_settings, state_dir: Path) -> VerifyConfig:
    """fcso's ``[verify]`` of a job: its settings, the time budget of its time limit and the daemon's cache
    (``state_dir`` / :data:`VERIFICATION_CACHE_NAME`) unless it sets its own, the part density of the design's print
    profile unless it sets its own."""
    config = settings.verify_config()
    defaults = {"choice_budget_s": settings.time_limit_seconds, "cache_dir": state_dir / VERIFICATION_CACHE_NAME}
    config = config.model_copy(update={k: v for k, v in defaults.items() if k not in config.model_fields_set})
    return with_print_density(config, design_settings)


def _bus_message(
    config, job_id: str, verification: VerificationReport, file: str, finger_set: int | None
) -> BusMessage:
    """The verification's message on ``.../verification`` (or ``.../verification/<set>``)."""
    topic = "verification" if finger_set is None else f"verification/{finger_set}"
    body = _message(job_id, verification, file, finger_set)
    return BusMessage.json_body(config.bus.prefix, config.bus.cell, topic, body)


def _message(job_id: str, verification: VerificationReport, file: str, finger_set: int | None) -> VerificationMessage:
    chosen = next((r.index for r in verification.ranking or [] if r.chosen), None)
    settings = verification.settings
    return VerificationMessage(
        job_id=job_id,
        verdict=verdict_text(verification),
        passed=verification.passed,
        better_than_flat=better_than_flat(verification),
        not_held=not_held(verification),
        file=file,
        finger_set=finger_set,
        scenarios=[
            ScenarioOutcome(
                part=s.part,
                pose_index=s.pose_index,
                verdict=scenario_verdict(s, settings),
                weakest_holding_n=weakest_hold_n(s.fcso, settings.hold_force_n),
                success_rate=s.fcso.success_rate,
                flat_success_rate=s.flat.success_rate,
                trials_run=len(s.fcso.trials),
                median_error_mm=s.fcso.median_error_mm,
                flat_median_error_mm=s.flat.median_error_mm,
                holding_n=s.fcso.holding_n,
                flat_holding_n=s.flat.holding_n,
            )
            for s in verification.scenarios
        ],
        chosen_candidate=chosen,
        choice=verification.choice,
        warnings=verification.warnings,
    )


def _record(path: Path, verification: VerificationReport, design: DesignUnderTest, message: BusMessage, mcap) -> None:
    """``verification.mcap``: the verification, a Foxglove scene per frame of the first scenario's unperturbed grasp,
    the bus message.
    """
    recorder = Recorder(path, mcap.compression, mcap.chunk_size_bytes)
    try:
        start = time.time_ns()
        recorder.write(TOPIC_VERIFICATION, verification, start)
        for update, at in scene_updates(verification, design, start):
            recorder.write_foxglove(TOPIC_VERIFICATION_SCENE, update, at)
        recorder.write(TOPIC_BUS, message.record(), start)
    finally:
        recorder.finish()
