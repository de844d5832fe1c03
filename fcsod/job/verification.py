"""Grasp verification of a job's design in simulation (fcso.sim, METHOD §12), run after the job is done.

With ``[verify] enabled`` the worker, once the job is ``done`` and its
design published, runs the precision and holding tests, adds
``verification.json`` and the report section to the job's output folder,
records ``verification.mcap`` (the verification and a Foxglove scene of the
unperturbed grasp, frame by frame) and publishes a summary on
``<prefix>/<cell>/jobs/<job_id>/verification``. A design that does not
pass leaves the job done, with a warning in the log and the message.
With ``top_k > 0`` the K best candidates are verified inside the design
step and the best by Q that passes becomes the job's design. A job of
several finger sets verifies every set's finger, each on
``.../verification/<set>`` (choosing among candidates is for one finger).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from fcso.output.design_page import rebuild_report
from fcso.output.layout import set_folder
from fcso.output.verification_page import ranking_html, write_verification
from fcso.sim.choose import verify_top
from fcso.sim.config import VerifyConfig, with_print_density
from fcso.sim.report import VerificationReport
from fcso.sim.verify import DesignUnderTest, design_under_test, verify

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


def job_settings(daemon: VerifySettings, manifest: VerifySettings | None) -> VerifySettings:
    """The job's ``[verify]``: its manifest's when it has one, else the daemon's."""
    return manifest if manifest is not None else daemon


def choose_by_verification(run) -> None:
    """Design step: with ``top_k > 0``, verify the K best candidates and make the best that passes the job's design."""
    settings = _settings(run)
    if settings.top_k <= 0:
        return
    chosen, verification, design, ranking = verify_top(
        run.result,
        settings.top_k,
        with_print_density(VerifyConfig(trials=settings.trials), run.result.report.settings),
        _progress(run.log),
    )
    run.sets.designs[0] = chosen
    run.verified = (verification, design, ranking_html(ranking))
    run.log("info", f"verification chose candidate {chosen.report.best} among the {len(ranking)} best by Q")


def verify_done_job(run, final_dir: Path) -> None:
    """After the job is done: verify (unless ``choose_by_verification`` did), write, record and publish.

    A job of several finger sets verifies every set's finger: its results go
    into the set's folder and on ``.../verification/<set>``. Never raises: a
    failure is a warning, the job stays done.
    """
    settings = _settings(run)
    if not (settings.enabled or settings.top_k > 0) or run.reuse is not None:
        # a reused finger was verified when it was delivered
        return

    def log(level: str, message: str, **fields) -> None:
        # job.mcap is closed: these lines go to the daemon's log only
        run.emit(("log", level, message, fields))

    if run.sets.several:
        for number, result in enumerate(run.sets.designs, start=1):
            _verify_one(run, result, final_dir, set_folder(number), number, settings, log)
    else:
        _verify_one(run, run.result, final_dir, "", None, settings, log)


def _verify_one(
    run, result, final_dir: Path, folder: str, finger_set: int | None, settings: VerifySettings, log: Callable
) -> None:
    """Verify one finger's design, write into ``final_dir / folder``, record and publish; a failure is a warning."""
    name = f"verification of finger set {finger_set}" if finger_set is not None else "verification"
    out = final_dir / folder if folder else final_dir
    try:
        started = time.perf_counter()
        if run.verified is not None and finger_set is None:
            verification, design, extra = run.verified
            # the report's pictures follow the candidate verification chose (rebuilt from report.json)
            rebuild_report(out)
        else:
            log("info", f"{name}: started")
            design = design_under_test(result)
            verification, extra = (
                verify(
                    design,
                    with_print_density(VerifyConfig(trials=settings.trials), result.report.settings),
                    _progress(log),
                ),
                "",
            )
        write_verification(out, verification, design, extra)
        bus = run.task.config.bus
        topic = "verification" if finger_set is None else f"verification/{finger_set}"
        file = f"{folder}/verification.json" if folder else "verification.json"
        message = BusMessage.json_body(
            bus.prefix, bus.cell, topic, _message(run.task.job_id, verification, file, finger_set)
        )
        _record(out / VERIFICATION_RECORD_NAME, verification, design, message, run.task.config.mcap)
        run.emit(("publish", message))
        level = "info" if verification.passed else "warning"
        log(
            level,
            f"{name}: design {'passed' if verification.passed else 'did not pass'} in "
            f"{time.perf_counter() - started:.1f} s",
        )
        for warning in verification.warnings:
            log("warning", f"{name}: {warning}")
    except Exception as exc:  # the design is delivered; verification is extra
        log("warning", f"{name} failed: {type(exc).__name__}: {exc}")


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


def _message(job_id: str, verification: VerificationReport, file: str, finger_set: int | None) -> VerificationMessage:
    chosen = next((r.index for r in verification.ranking or [] if r.chosen), None)
    return VerificationMessage(
        job_id=job_id,
        passed=verification.passed,
        file=file,
        finger_set=finger_set,
        scenarios=[
            ScenarioOutcome(
                part=s.part,
                pose_index=s.pose_index,
                success_rate=s.fcso.success_rate,
                flat_success_rate=s.flat.success_rate,
                median_error_mm=s.fcso.median_error_mm,
                flat_median_error_mm=s.flat.median_error_mm,
                holding_n=s.fcso.holding_n,
                flat_holding_n=s.flat.holding_n,
            )
            for s in verification.scenarios
        ],
        chosen_candidate=chosen,
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
