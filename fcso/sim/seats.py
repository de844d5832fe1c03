"""A candidate holds the part as printed (METHOD §5b): does a finger's unperturbed grasp lift the part at the seat
its design gives it?"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from .collision import ConvexPieces
from .config import VerifyConfig
from .outcomes import TrialRun
from .report import FingerResult
from .scene import GraspCase, Scene, build_scene, out_of_arena, with_arena
from .schedule import nominal_grasp, nominal_grasps
from .trials import pose_error


def nominal_seats(
    cases: Sequence[GraspCase],
    built: dict[int, tuple[ConvexPieces, ConvexPieces, Scene]],
    finger_hull_mm: np.ndarray,
    config: VerifyConfig,
) -> tuple[tuple[str, str] | None, dict[int, int]]:
    """METHOD §5b, cheaply: the designed finger's unperturbed grasp of every scenario, one grasp each (two for a
    drop), side by side; the first scenario whose grasp does not hold its part at its designed seat
    (:func:`seat_miss`) where the flat control's unperturbed grasp does rejects the finger (never worse than flat: a
    part flat pads drop or hold off its seat too rejects nothing).

    Every scenario is checked, not only those the trials reach before a failure stops them (``stop_early``): in a
    finger shared by several parts, one part may slide off its seat into another part's pocket (the stepped block of
    bench_truth's development split, 9.6 mm off) while the first scenario's trials decide the verdict. The grasps are
    cached as the full run's own (:func:`fcso.sim.schedule.nominal_grasp`).

    Parameters
    ----------
    cases : sequence of GraspCase
    built : dict
        Scenario number -> its part's and pad's collision pieces and the designed finger's scene
        (:func:`fcso.sim.verify.fitted_pieces`).
    finger_hull_mm : (n, 3) float
        The finger body behind the pad (pad frame, mm).
    config : VerifyConfig

    Returns
    -------
    rejected : (str, str) or None
        The first scenario whose grasp misses its seat where flat pads' does not, and why; None when there is none
        (a scenario MuJoCo cannot simulate within its arena is left to the full run, which retries it).
    simulated : dict
        Scenario number -> the unperturbed grasps simulated here, not read from the cache: the trials read them back
        and should not count them as simulated before.
    """
    # every scenario's grasp side by side (one core each): one after the other they were most of a part's choice
    runs = nominal_grasps([built[n][2] for n in range(len(cases))], cases, config)
    simulated = {n: int(not run.reused) for n, run in enumerate(runs) if not isinstance(run, mujoco.FatalError)}
    for number, (case, run) in enumerate(zip(cases, runs)):
        pieces, _, scene = built[number]
        if isinstance(run, mujoco.FatalError):
            if out_of_arena(run):
                continue
            raise run
        try:
            missed = _nominal_seat_miss(scene, case, config, "fcso", run)
            # flat pads that cannot hold the part at its seat either leave nothing a carving would be worse than
            if missed is not None:
                flat = build_scene(case, pieces.pieces, None, finger_hull_mm, config)
                flat_run = nominal_grasp(flat, case, config, "flat")
                simulated[number] += not flat_run.reused
                if _nominal_seat_miss(flat, case, config, "flat", flat_run) is None:
                    return (case.name, missed), simulated
        except mujoco.FatalError as error:
            if not out_of_arena(error):
                raise
    return None, simulated


def _nominal_seat_miss(
    scene: Scene, case: GraspCase, config: VerifyConfig, kind: str, run: TrialRun | None = None
) -> str | None:
    """:func:`seat_miss` of a finger's (``kind``) unperturbed grasp in ``scene`` (``run``, when already simulated)."""
    run = run or nominal_grasp(scene, case, config, kind)
    if not run.held and config.arena_retry_factor > 1.0:
        # a grasp short of MuJoCo's arena drops the part with a warning, not an error: a drop is confirmed with the
        # full run's larger arena, simulated again (its outcome replaces the first in the cache)
        larger = with_arena(scene, int(scene.arena_bytes * config.arena_retry_factor))
        run = nominal_grasp(larger, case, config.model_copy(update={"reuse_simulations": False}), kind)
    offset = pose_error(run.part_in_gripper, np.linalg.inv(case.tcp), scene.part_com_mm)
    return seat_miss(run.held, *offset, config)


def seat_miss(held: bool, offset_mm: float, offset_deg: float, config: VerifyConfig) -> str | None:
    """Why a designed finger's unperturbed grasp does not hold its part as designed (METHOD §5b), or None when it does.

    It must lift the part (``held``) at the seat the design gives it: within ``config.success_mm`` and
    ``config.success_deg`` (``offset_mm``, ``offset_deg``: its centre of mass's distance and its rotation from there),
    the tolerance of a precision trial, whose pose is judged against this grasp's.
    """
    if not held:
        return "the unperturbed grasp drops the part"
    if offset_mm > config.success_mm or offset_deg > config.success_deg:
        return (
            f"the unperturbed grasp holds the part {offset_mm:.1f} mm and {offset_deg:.1f} deg off its designed seat "
            f"(tolerance {config.success_mm:g} mm, {config.success_deg:g} deg)"
        )
    return None


def nominal_miss(finger: FingerResult, config: VerifyConfig) -> str | None:
    """:func:`seat_miss` of a simulated finger's unperturbed grasp."""
    return seat_miss(finger.nominal_held, finger.nominal_offset_mm, finger.nominal_offset_deg, config)
