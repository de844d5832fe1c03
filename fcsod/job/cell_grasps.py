"""The grasps a cell runs: each design's grasp with the approach opening, the finger set, the verdict and the job id."""

from __future__ import annotations

from fcso import DesignConfig
from fcso.grasps import approach_gripper_opening_mm
from fcso.report.models import GraspReport
from fcso.sim.report import VerificationReport, scenario_verdict

from ..bus.messages import CellGrasp, rest_frame_id
from .task import FINGER_SET


def cell_grasps(
    job_id: str,
    grasps: list[GraspReport],
    settings: DesignConfig,
    flat_pads: bool,
    verification: VerificationReport | None,
    unverified: str,
) -> list[CellGrasp]:
    """Grasps as the bus carries them.

    Parameters
    ----------
    job_id : str
    grasps : list of GraspReport
        One finger's grasps (a grasp without a finger set is the job's one finger's, :data:`FINGER_SET`).
    settings : DesignConfig
        The design's: the pads' penetration D, the gripper's full opening, ``[verify] open_margin_mm``.
    flat_pads : bool
        The finger's pads are flat (their faces at the part's outline at the seated grasp, not D inside it).
    verification : VerificationReport or None
        The finger's verification when it ran before the grasps are published.
    unverified : str
        The verdict without a verification (why there is none, or where it follows).
    """
    inset = 0.0 if flat_pads else settings.sampler.penetration_mm
    scenarios = {(s.part, s.pose_index): s for s in verification.scenarios} if verification is not None else {}
    cell = []
    for grasp in grasps:
        if verification is None:
            verdict = unverified
        else:
            scenario = scenarios.get((grasp.part, grasp.pose_index))
            head = "verified" if verification.passed else "not verified"
            figures = "not simulated" if scenario is None else scenario_verdict(scenario, verification.settings)
            verdict = f"{head}: {figures}"
        opening = approach_gripper_opening_mm(
            grasp.closing_width_mm, inset, settings.verify.open_margin_mm, settings.gripper.max_opening_mm
        )
        cell.append(
            CellGrasp(
                **grasp.model_dump(exclude={"finger_set"}),
                job_id=job_id,
                frame_id=rest_frame_id(grasp.part, grasp.pose_index),
                finger_set=grasp.finger_set or FINGER_SET,
                approach_opening_mm=round(opening, 4),
                verified=None if verification is None else verification.passed,
                verdict=verdict,
            )
        )
    return cell


def verification_note(enabled: bool, several: bool) -> str:
    """The verdict of grasps published before their finger's verification: where it follows, or that it is off
    (``[verify] enabled``); ``several``: a job of several finger sets (a key per set)."""
    if not enabled:
        return "not verified: [verify] enabled is false"
    key = "verification/<set>" if several else "verification"
    return f"not verified yet: the verification follows on .../{key}"
