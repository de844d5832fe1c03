"""The simulations of one scenario on forked workers: every finger's nominal grasp, precision trials and holding
test, started in an order that keeps the workers busy and judged in order (METHOD §12).

The workers are kept busy, at most one task each. Grasps go first,
trial by trial (every finger's nominal grasp, then every finger's first
trial, ...; the designed finger's first: its contacts make them the
longest), each started as soon as a worker frees up; a finger's pushes
start once its nominal grasp has held, on workers no grasp can use, so
they fill what would be the trials' tail. With ``config.stop_early``
the designed finger's (``fcso``) trials stop at the failure after which
it can no longer reach ``pass_success_rate``: that trial is the last
kept, of every finger (the flat control is compared on the same start
errors); later grasps are not started and those already running are
dropped (their workers stopped once the kept grasps are judged), as
are the pushes, since the finger cannot pass; and at most
two grasps per worker are started ahead of the first not yet judged,
so a finger that fails early takes few grasps beyond its deciding
one. What is kept does not depend on the number of workers or on the
machine's speed. A designed finger that fails its first trial takes
its nominal grasps and first trials, and at most the parts of the
grasps and pushes in flight beside them that ran until those were
judged.

A precision-only run (``precision_only``) simulates the designed finger's
nominal grasp and trials and the other fingers' nominal grasps alone: no
control trials and no pushes. A verification that stops early runs it
first for every scenario and the rest only where every scenario passes
it (:func:`fcso.sim.verify.verify`), so a candidate the choice rejects
costs its designed trials alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from ..parallel import WorkerPool, resolve_jobs
from .config import VerifyConfig
from .outcomes import (
    TrialRun,
    grasp_key,
    hold_key,
    restored_state,
    reuse_or_simulate_grasp,
    reuse_or_simulate_hold,
    saved_state,
    scene_key,
)
from .report import TrialResult, successes
from .scene import GraspCase, Scene
from .trials import HOLD_DIRECTIONS, hold_force, pose_error, run_grasp, start_pose


def needed_successes(trials: int, config: VerifyConfig) -> int:
    """Fewest successful trials out of ``trials`` that reach ``config.pass_success_rate``."""
    return math.ceil((config.pass_success_rate - 1e-9) * trials)


def below_pass_rate(trials: list[TrialResult] | None, config: VerifyConfig) -> bool:
    """Whether a finger's precision ``trials`` succeed below ``config.pass_success_rate`` (False without them: no
    such finger)."""
    return trials is not None and (
        (successes(trials) / len(trials) if trials else 0.0) < config.pass_success_rate - 1e-9
    )


def trial_result(run: TrialRun, error: np.ndarray, reference: np.ndarray, com_mm, config: VerifyConfig) -> TrialResult:
    """One precision trial judged against the pose of the part in the gripper after the unperturbed grasp
    (``reference``, 4x4, mm)."""
    moved, turned = pose_error(run.part_in_gripper, reference, com_mm)
    return TrialResult(
        dx_mm=round(float(error[0]), 4),
        dy_mm=round(float(error[1]), 4),
        yaw_deg=round(float(error[2]), 4),
        held=run.held,
        error_mm=round(moved, 4),
        error_deg=round(turned, 4),
        success=bool(run.held and moved <= config.success_mm and turned <= config.success_deg),
    )


@dataclass
class ScenarioSimulations:
    """What :func:`scenario_simulations` ran and kept.

    Attributes
    ----------
    runs : dict
        Finger kind -> its nominal grasp (unperturbed, with its state after the lift; recorded for the designed
        finger) then its kept trials in the order of the start errors (the first recorded).
    trials : dict
        Finger kind -> its kept trials' results.
    stopped_after : int or None
        How many trials were kept when the trials stopped early; None when every trial ran.
    holding : dict
        Finger kind -> push direction -> slip force, N (None: held; 0.0 in every direction when the nominal grasp
        did not hold); every kind's is empty when the holding test is not run (the designed finger failed its
        precision trials, ``stop_early``).
    precision_failed : bool
        The designed finger's success rate is below ``pass_success_rate`` (False without a designed finger).
    reused : int
        Grasps and pushes kept whose outcome was read from the cache (:mod:`fcso.sim.outcomes`).
    """

    runs: dict[str, list[TrialRun]]
    trials: dict[str, list[TrialResult]]
    stopped_after: int | None
    holding: dict[str, dict[str, float | None]]
    precision_failed: bool
    reused: int


def scenario_simulations(
    scenes: dict[str, Scene],
    case: GraspCase,
    errors: np.ndarray,
    config: VerifyConfig,
    advance: Callable[[], None],
    precision_only: bool = False,
) -> ScenarioSimulations:
    """Every finger's nominal grasp, precision trials and holding test (:func:`fcso.sim.trials.hold_force`, six
    pushes from the nominal grasp's state after the lift) on ``config.jobs`` forked workers, the trials judged in
    order: the results of one process. The order of the tasks and where they stop: this module's docstring.

    Parameters
    ----------
    scenes : dict
        Finger kind -> its scene (``fcso``: the designed finger, judged for the stop).
    case : GraspCase
    errors : (n, 3) float
        Start errors (x, y mm, yaw degrees) of the trials.
    config : VerifyConfig
    advance : callable
        Called after every kept grasp.
    precision_only : bool
        The designed finger's trials and every finger's nominal grasp alone (no pushes: ``holding`` empty).
    """
    items = _grasp_items(scenes, errors, precision_only)
    # no more workers than tasks: the grasps and every finger's pushes
    jobs = min(resolve_jobs(config.jobs), len(items) + (0 if precision_only else len(scenes) * len(HOLD_DIRECTIONS)))
    runs, trials = {kind: [] for kind in scenes}, {kind: [] for kind in scenes}
    forces = {kind: {name: 0.0 for name in HOLD_DIRECTIONS} for kind in scenes}
    allowed_failures = len(errors) - needed_successes(len(errors), config)
    # the last trial kept, the next grasp to judge and the next to start; the grasps not judged yet by index;
    # the pushes whose nominal grasp held, not started yet; tasks running
    kept, judged, started, running, reused = len(errors), 0, 0, 0, 0
    finished: dict[int, TrialRun] = {}
    pushes: list[tuple[str, str, np.ndarray]] = []
    # grasps started and not judged yet, at most (stop_early: one beyond a deciding failure is seldom started)
    ahead = 2 * jobs if config.stop_early else len(items)

    def judge(index: int, run: TrialRun) -> None:
        nonlocal kept, reused
        kind, number, error = items[index]
        if number > kept:
            return
        runs[kind].append(run)
        reused += run.reused
        advance()
        if number == 0:
            if run.held and not precision_only:
                pushes.extend((kind, name, run.lifted) for name in HOLD_DIRECTIONS)
            return
        nominal = runs[kind][0]
        reference = nominal.part_in_gripper if nominal.held else np.linalg.inv(case.tcp)
        trials[kind].append(trial_result(run, error, reference, scenes[kind].part_com_mm, config))
        failed = kind == "fcso" and not trials[kind][-1].success
        if config.stop_early and failed and len(trials[kind]) - successes(trials[kind]) > allowed_failures:
            kept = number
            pushes.clear()

    def next_tasks() -> list[tuple]:
        nonlocal started, running
        tasks = []
        while running + len(tasks) < jobs:
            if started < len(items) and items[started][1] <= kept and started - judged < ahead:
                tasks.append((_simulated_grasp, items[started], ("grasp", started)))
                started += 1
            elif pushes and kept == len(errors):
                push = pushes.pop(0)
                tasks.append((_hold_force, push, ("push", push[:2])))
            else:
                break
        running += len(tasks)
        return tasks

    def on_done(tag: tuple, result) -> list[tuple]:
        nonlocal judged, running, reused
        running -= 1
        stage, index = tag
        if stage == "push":
            force, from_cache = result
            if kept == len(errors):
                forces[index[0]][index[1]] = force
                reused += from_cache
            return next_tasks()
        finished[index] = result
        while judged in finished:
            judge(judged, finished.pop(judged))
            judged += 1
        return next_tasks()

    def settled() -> bool:
        # stopped early, and every grasp up to the deciding trial judged: what still runs would be dropped
        return kept < len(errors) and judged >= sum(number <= kept for _, number, _ in items)

    keys = {kind: scene_key(scene, case, config) for kind, scene in scenes.items()}
    with WorkerPool((scenes, case, config, keys), jobs) as pool:
        pool.run(next_tasks(), on_done, settled)
    precision_failed = below_pass_rate(trials.get("fcso"), config)
    holding = {kind: {} for kind in scenes} if precision_only or (config.stop_early and precision_failed) else forces
    return ScenarioSimulations(runs, trials, kept if kept < len(errors) else None, holding, precision_failed, reused)


def _grasp_items(scenes: dict[str, Scene], errors: np.ndarray, precision_only: bool) -> list[tuple]:
    """The grasps of :func:`scenario_simulations` in the order they start, ``(kind, number, error)`` (number 0: the
    nominal grasp, error None): trial by trial, the designed finger's first; ``precision_only``: the designed
    finger's and the other fingers' nominal grasps alone."""
    kinds = sorted(scenes, key=lambda kind: kind != "fcso")
    return [
        (kind, number, error)
        for number, error in enumerate([None, *errors])
        for kind in kinds
        if not precision_only or kind == "fcso" or number == 0
    ]


def is_own_control(designed: Scene, flat: Scene) -> bool:
    """Whether the designed finger's scene is the flat control's to the last bit (the same model source: a design
    delivered with flat pads, :func:`fcso.sim.verify.fitted_pieces`)."""
    return designed.model_sha256 == flat.model_sha256


def as_own_control(designed: ScenarioSimulations, advance: Callable[[], None]) -> ScenarioSimulations:
    """:func:`scenario_simulations` of the designed finger alone, when it is its own flat control
    (:func:`is_own_control`), with the control's taken from them.

    MuJoCo repeats a simulation to the last bit, so the control's grasps and
    pushes, from the same starts in the same model, end as the designed
    finger's: they are not simulated a second time (both fingers' would
    otherwise run side by side, each missing the other's cache entry). They
    count as read from the cache when the designed finger's were, and each
    kept grasp of the control is reported to ``advance`` as simulated.
    """
    for _ in designed.runs["fcso"]:
        advance()
    return ScenarioSimulations(
        runs={"fcso": designed.runs["fcso"], "flat": list(designed.runs["fcso"])},
        trials={"fcso": designed.trials["fcso"], "flat": [t.model_copy() for t in designed.trials["fcso"]]},
        stopped_after=designed.stopped_after,
        holding={"fcso": designed.holding["fcso"], "flat": dict(designed.holding["fcso"])},
        precision_failed=designed.precision_failed,
        reused=2 * designed.reused,
    )


def nominal_grasp(scene: Scene, case: GraspCase, config: VerifyConfig, kind: str = "fcso") -> TrialRun:
    """A finger's (``scene``; ``kind`` "fcso" or "flat") unperturbed grasp alone, in this process:
    :func:`scenario_simulations`' first grasp, read from or written to its cache entry, so the full run reads it
    back."""
    keys = {kind: scene_key(scene, case, config)}
    return _simulated_grasp(({kind: scene}, case, config, keys), (kind, 0, None))


def nominal_grasps(
    scenes: Sequence[Scene], cases: Sequence[GraspCase], config: VerifyConfig, kind: str = "fcso"
) -> list[TrialRun | mujoco.FatalError]:
    """:func:`nominal_grasp` of several scenarios (``scenes[k]`` grasps ``cases[k]``) side by side on ``config.jobs``
    forked workers, in order: a run each, or the error of a scenario MuJoCo refused (the caller decides)."""
    jobs = min(resolve_jobs(config.jobs), len(cases))
    with WorkerPool((list(scenes), list(cases), config, kind), jobs) as pool:
        return pool.map(_nominal_task, range(len(cases)))


def _nominal_task(context, number: int) -> TrialRun | mujoco.FatalError:
    scenes, cases, config, kind = context
    try:
        return nominal_grasp(scenes[number], cases[number], config, kind)
    except mujoco.FatalError as error:
        return error


def _grasp_plan(
    case: GraspCase, scene_key_hex: str, kind: str, number: int, error: np.ndarray | None
) -> tuple[np.ndarray, bool, str]:
    """Grasp ``number`` (0: the nominal one) of a finger ``kind``: the part's start pose (4x4, mm), whether its frames
    are kept (the designed finger's nominal grasp and every finger's first trial: the report's pictures) and its
    cache key (:func:`fcso.sim.outcomes.grasp_key`)."""
    pose = np.eye(4) if number == 0 else start_pose(case, error)
    record = number == 1 or (number == 0 and kind == "fcso")
    return pose, record, grasp_key(scene_key_hex, pose, record)


def _simulated_grasp(context, item) -> TrialRun:
    scenes, case, config, keys = context
    kind, number, error = item
    scene = scenes[kind]
    pose, record, key = _grasp_plan(case, keys[kind], kind, number, error)

    def simulate() -> TrialRun:
        run = run_grasp(scene, case, pose, config, record=record)
        lifted = saved_state(scene.model, run.data) if number == 0 else None
        return TrialRun(run.held, run.part_in_gripper, run.frames if record else None, lifted)

    return reuse_or_simulate_grasp(config.cache_path(), key, config.reuse_simulations, scene.model, simulate)


def _hold_force(context, item) -> tuple[float | None, bool]:
    scenes, case, config, keys = context
    kind, name, state = item
    _, _, nominal_key = _grasp_plan(case, keys[kind], kind, 0, None)
    return reuse_or_simulate_hold(
        config.cache_path(),
        hold_key(nominal_key, name),
        config.reuse_simulations,
        lambda: hold_force(scenes[kind], case, restored_state(scenes[kind].model, state), name, config),
    )
