"""Verify a design in simulation: precision and holding tests, designed pads against flat ones (METHOD §12)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np
import trimesh

from ..finger import pad_to_finger
from ..pipeline import DesignResult, flat_finger
from ..progress import Progress
from ..report.models import DesignReport, GraspReport
from ..version import __version__
from .collision import ConvexPieces, finger_body_hull, pad_prism_pieces, part_shell_pieces, volume_errors
from .config import VerifyConfig
from .diskcache import evict
from .report import (
    Fidelity,
    FingerResult,
    PoseSnapshot,
    ScenarioVerification,
    TrialResult,
    VerificationReport,
    successes,
)
from .scene import GraspCase, Scene, build_scene, out_of_arena, with_arena
from .schedule import (
    ScenarioSimulations,
    as_own_control,
    is_own_control,
    scenario_simulations,
)
from .seats import nominal_miss, nominal_seats
from .trials import Frame, approach_opening_mm, perturbations, pose_error, seated_overlaps_mm


@dataclass
class DesignUnderTest:
    """What the simulation needs from a design.

    Attributes
    ----------
    cases : list of GraspCase
        One per scenario (part in a pose with its chosen grasp).
    fingerpad : trimesh.Trimesh
        The carved pad, pad frame, mm.
    finger_hull_mm : (n, 3) float
        Finger body behind the pad, pad frame, mm.
    """

    cases: list[GraspCase]
    fingerpad: trimesh.Trimesh
    finger_hull_mm: np.ndarray


def tcp_matrix(grasp: GraspReport) -> np.ndarray:
    """4x4 TCP pose (resting frame, mm) of a reported grasp."""
    matrix = trimesh.transformations.quaternion_matrix(grasp.quaternion_wxyz)
    matrix[:3, 3] = grasp.position_mm
    return matrix


def grasp_case(report: DesignReport, grasp: GraspReport, part_mesh_mm: trimesh.Trimesh) -> GraspCase:
    """The simulation case of one reported grasp.

    Parameters
    ----------
    report : DesignReport
        For the pad size and the gripper.
    grasp : GraspReport
    part_mesh_mm : trimesh.Trimesh
        The part in its file frame, scaled to mm.
    """
    sampler, gripper = report.settings.sampler, report.settings.gripper
    rest = np.asarray(grasp.rest_transform, dtype=float)
    mesh = part_mesh_mm.copy()
    mesh.apply_transform(rest)
    return GraspCase(
        name=f"{grasp.part} pose {grasp.pose_index}",
        part=mesh,
        tcp=tcp_matrix(grasp),
        pad_gap_mm=grasp.pad_gap_mm,
        pad_size_mm=(sampler.thickness_mm, sampler.length_mm, sampler.width_mm),
        penetration_mm=sampler.penetration_mm,
        opening_mm=(gripper.min_opening_mm, gripper.max_opening_mm),
        part_file=part_mesh_mm,
        rest_transform=rest,
    )


def design_under_test(result: DesignResult) -> DesignUnderTest:
    """The simulation's inputs from a design that was just run (no files needed)."""
    parts = {scenario.part.name: scenario.part.mesh for scenario in result.scenarios}
    cases = [grasp_case(result.report, g, parts[g.part]) for g in result.report.grasps]
    return DesignUnderTest(cases, result.fingerpad, finger_hull(result.report, result.finger))


def finger_hull(report: DesignReport, finger: trimesh.Trimesh) -> np.ndarray:
    """Hull of a design's finger body behind its pad (pad frame, mm)."""
    config = report.settings
    flat = flat_finger(config)
    return finger_body_hull(finger, pad_to_finger(flat, config.sampler), config.sampler.thickness_mm)


def verify(design: DesignUnderTest, config: VerifyConfig, progress: Progress | None = None) -> VerificationReport:
    """Run the precision and holding tests on every scenario, designed pads and flat ones.

    With ``config.stop_early`` a design that can no longer pass is not
    simulated further: a scenario's trials stop at the deciding failure
    (:func:`scenario_simulations`), its holding test is skipped, and so are the
    later scenarios (``unverified_scenarios``); the verdict is the full run's.
    Before any trial it then judges every scenario's unperturbed grasp (:func:`nominal_seats`, METHOD §5b) and
    stops at the first that does not hold its part at its designed seat (timed as ``seats``); without
    ``stop_early`` such a scenario fails after its full run. Either way it is listed in ``unseated_scenarios``.
    With ``stop_early`` and ``reuse_simulations`` the designed finger's precision trials run first, scenario by
    scenario, and the flat control's trials and both fingers' holding tests only once every scenario has passed
    them (the designed trials then read back from the simulation cache): a design that fails costs its designed
    trials alone, and a failed scenario's flat control runs no trial (``flat.trials`` empty).

    Parameters
    ----------
    design : DesignUnderTest
    config : VerifyConfig
    progress : callable, optional
        ``progress("verification", done, total)`` per simulated grasp.

    Returns
    -------
    VerificationReport
    """
    report_progress = progress or (lambda stage, done, total: None)
    timings = {"decomposition": 0.0, "simulation": 0.0}
    total = len(design.cases) * 2 * (config.trials + 1)
    counter = [0]

    def advance() -> None:
        counter[0] += 1
        report_progress("verification", min(counter[0], total), total)

    report_progress("verification", 0, total)
    built, rejected, seat_checks = {}, None, {}
    if config.stop_early:
        clock = time.perf_counter()
        built = {number: fitted_pieces(case, design, config) for number, case in enumerate(design.cases)}
        rejected, seat_checks = nominal_seats(design.cases, built, design.finger_hull_mm, config)
        timings["seats"] = time.perf_counter() - clock
    if rejected is not None:
        name, why = rejected
        outcome = _Verified([], [f"{name}: {why}: the design cannot pass, no trial is run (METHOD §5b, stop_early)"])
        outcome.unseated, outcome.unverified = [name], [c.name for c in design.cases]
    else:
        precision_first = config.stop_early and config.reuse_simulations
        outcome = _verified_scenarios(design, config, built, timings, advance, precision_only=precision_first)
        if precision_first and not outcome.unverified and all(_precise(s, config) for s in outcome.scenarios):
            first = outcome
            outcome = _verified_scenarios(design, config, built, timings, advance, precision_only=False)
            outcome.scenarios = [_simulated_once(s, earlier) for s, earlier in zip(outcome.scenarios, first.scenarios)]
    # the seat check's grasps were simulated for this verification too
    outcome.scenarios = [
        s.model_copy(update={"reused_simulations": max(0, s.reused_simulations - seat_checks.get(number, 0))})
        for number, s in enumerate(outcome.scenarios)
    ]
    report_progress("verification", total, total)
    # once per verification, not per entry: a farm's cache holds many thousands of outcomes
    evict(config.cache_path())
    return VerificationReport(
        fcso_version=__version__,
        mujoco_version=mujoco.__version__,
        settings=config,
        scenarios=outcome.scenarios,
        passed=all(s.passed for s in outcome.scenarios) and not outcome.unverified,
        unverified_scenarios=outcome.unverified,
        unseated_scenarios=outcome.unseated,
        warnings=outcome.warnings,
        timings_s={k: round(v, 3) for k, v in timings.items()},
    )


@dataclass
class _Verified:
    """What :func:`_verified_scenarios` found: the scenarios simulated, warnings, the scenarios left unverified and
    those whose unperturbed grasp left the part off its seat."""

    scenarios: list[ScenarioVerification]
    warnings: list[str]
    unverified: list[str] = field(default_factory=list)
    unseated: list[str] = field(default_factory=list)


def _verified_scenarios(
    design: DesignUnderTest,
    config: VerifyConfig,
    built: dict,
    timings: dict[str, float],
    advance: Callable[[], None],
    precision_only: bool,
) -> _Verified:
    """:func:`verify_case` of each scenario in turn (``precision_only``: the designed finger's precision trials
    alone); with ``config.stop_early`` none after one that failed. ``built``: pieces and scenes already made
    (:func:`nominal_seats`); ``timings`` accumulates decomposition and simulation seconds."""
    outcome = _Verified([], [])
    kept_on = _precise if precision_only else lambda scenario, config: scenario.passed
    for stream, case in enumerate(design.cases):
        if outcome.scenarios and config.stop_early and not kept_on(outcome.scenarios[-1], config):
            # the design can no longer pass: the verdict is settled
            outcome.unverified = [c.name for c in design.cases[stream:]]
            outcome.warnings.append(
                f"not verified: {', '.join(outcome.unverified)}; {design.cases[stream - 1].name} had already failed, "
                "so the design cannot pass (stop_early)"
            )
            break
        clock = time.perf_counter()
        pieces, pad, seated = built.get(stream) or fitted_pieces(case, design, config)
        timings["decomposition"] += time.perf_counter() - clock
        clock = time.perf_counter()
        scenario = verify_case(
            case, pieces, pad, design.finger_hull_mm, config, stream, advance, seated, precision_only=precision_only
        )
        timings["simulation"] += time.perf_counter() - clock
        outcome.warnings.extend(seated_overlap_notes(case.name, scenario.fidelity, config))
        outcome.warnings.extend(_scenario_warnings(case.name, scenario, config))
        if _unseated(scenario, config) is not None:
            outcome.unseated.append(case.name)
        outcome.scenarios.append(scenario)
    return outcome


def _scenario_warnings(name: str, scenario: ScenarioVerification, config: VerifyConfig) -> list[str]:
    """Why scenario ``name`` does not pass: not simulated, off its seat, too few precision successes, or holding less
    than flat pads."""
    if scenario.failure_reason is not None:
        return [f"{name}: not simulated: {scenario.failure_reason}"]
    warnings = []
    if (missed := _unseated(scenario, config)) is not None:
        warnings.append(f"{name}: {missed} (METHOD §5b)")
    ran = len(scenario.fcso.trials)
    if scenario.fcso.success_rate < config.pass_success_rate - 1e-9:
        stop = (
            f"; stopped after {ran} of {config.trials}: it can no longer pass"
            if scenario.stopped_after_trials is not None
            else ""
        )
        flat = f" (flat pads: {successes(scenario.flat.trials)} of {len(scenario.flat.trials)})"
        warnings.append(
            f"{name}: {successes(scenario.fcso.trials)} of {ran} precision trials succeeded"
            f"{flat if scenario.flat.trials else ''}, below pass_success_rate {config.pass_success_rate:.0%}{stop}"
        )
    if scenario.holds_as_flat is False:
        weaker = weaker_than_flat(scenario.fcso.holding_n, scenario.flat.holding_n, config)
        warnings.append(
            f"{name}: the designed finger holds less than flat pads pushed "
            + ", ".join(f"{push} ({mine:.1f} N against {theirs:.1f} N)" for push, (mine, theirs) in weaker.items())
        )
    return warnings


def _unseated(scenario: ScenarioVerification, config: VerifyConfig) -> str | None:
    """Why a simulated scenario's designed finger holds its part off its seat where flat pads hold it there (METHOD
    §5b), or None."""
    missed = nominal_miss(scenario.fcso, config)
    if scenario.failure_reason is None and missed is not None and nominal_miss(scenario.flat, config) is None:
        return missed
    return None


def _precise(scenario: ScenarioVerification, config: VerifyConfig) -> bool:
    """Whether a scenario's designed finger passed what a precision-only run tells (:func:`verify_case`): simulated,
    its unperturbed grasp at its seat and enough precision trials successful."""
    return (
        scenario.failure_reason is None
        and nominal_miss(scenario.fcso, config) is None
        and scenario.fcso.success_rate >= config.pass_success_rate - 1e-9
    )


def _simulated_once(scenario: ScenarioVerification, precision: ScenarioVerification) -> ScenarioVerification:
    """``scenario`` of a complete run counting as read from the cache only what its precision-only run
    (``precision``) had not simulated itself: those grasps were simulated for this verification."""
    grasps = 2 + len(precision.fcso.trials) + len(precision.flat.trials)
    simulated_first = grasps - precision.reused_simulations
    return scenario.model_copy(update={"reused_simulations": max(0, scenario.reused_simulations - simulated_first)})


def verify_delivered(
    design: DesignUnderTest, config: VerifyConfig, progress: Progress | None = None
) -> VerificationReport:
    """The verification of a design that is delivered: every trial and the holding test of every scenario, designed
    and flat (METHOD §12b), whatever ``config.stop_early`` says (the choice among candidates may stop; what is
    delivered is told in full). Trials a stopped verification of the same design ran are read from the simulation
    cache (``reuse_simulations``), so completing one costs only the trials it had not run.
    """
    return verify(design, config.model_copy(update={"stop_early": False}), progress)


def fitted_pieces(
    case: GraspCase, design: DesignUnderTest, config: VerifyConfig
) -> tuple[ConvexPieces, ConvexPieces, Scene]:
    """The pad's convex pieces (prisms under its face) and the part's (prisms under its surface where the pads reach
    it), and the designed finger's scene of them.

    Both are built from the meshes' own facets (:func:`pad_prism_pieces`,
    :func:`part_shell_pieces`), so their overlap (METHOD §12's fidelity) is
    that of the meshes themselves: a design whose pad cuts into its part, or
    the simplification's few micrometres.

    Returns
    -------
    part, pad : ConvexPieces
    scene : Scene
        The designed finger's scene of these pieces (for :func:`verify_case`: one compilation).
    """
    pad = pad_prism_pieces(design.fingerpad, case.pad_size_mm[0], config.cache_path())
    part = part_pieces(case, config)
    # a design delivered with flat pads is the control itself: simulated as the control is, since prisms under the
    # same face meet the part in other contacts and a borderline trial could end the other way (the plain cube of
    # bench_truth: 0/10 against the control's 1/10, one finger)
    flat = is_flat_control(design.fingerpad, case.pad_size_mm, case.penetration_mm)
    return part, pad, build_scene(case, part.pieces, None if flat else pad.pieces, design.finger_hull_mm, config)


def seated_overlap_notes(name: str, fidelity: Fidelity, config: VerifyConfig) -> list[str]:
    """Warnings of a scenario ``name`` whose part and pad pieces, or whose two pads, overlap at the nominal seated
    grasp by more than ``config.max_seated_penetration_mm``; none when they do not."""
    notes = []
    if fidelity.seated_penetration_mm > config.max_seated_penetration_mm:
        notes.append(
            f"{name}: part and pad pieces overlap {fidelity.seated_penetration_mm:.2f} mm at the seated grasp "
            f"(part {fidelity.part_pieces} pieces, pad {fidelity.pad_pieces}); precision errors below that are not "
            "resolved"
        )
    if fidelity.seated_pads_overlap_mm > config.max_seated_penetration_mm:
        notes.append(
            f"{name}: the two pads overlap each other {fidelity.seated_pads_overlap_mm:.2f} mm at the seated grasp: "
            "the fingers meet before the part is seated"
        )
    return notes


def part_pieces(case: GraspCase, config: VerifyConfig) -> ConvexPieces:
    """The part's convex pieces in its resting frame: prisms under its surface where the pads can reach it, hulls by
    cells elsewhere (:func:`pad_reach_boxes`, :func:`part_shell_pieces`).
    """
    return part_shell_pieces(
        case.part, np.linalg.inv(case.tcp), pad_reach_boxes(case, config), config.part_shell_mm, config.cache_path()
    )


def pad_reach_boxes(case: GraspCase, config: VerifyConfig) -> np.ndarray:
    """Where each pad can touch the part in the tests: a box per pad in the TCP frame, mm.

    The pad's box (T x L x W) at its seated grasp, stretched across the
    finger's opening before it closes and upwards over the part (the
    approach), grown by how far a point of the part near the pads moves in
    the trials: the start error (its x-y distance and its turn about the
    centre of mass) and the holding test's slip limits.

    Returns
    -------
    (2, 2, 3) float
        Lower and upper corners of the "+" and "-" pads' boxes.
    """
    thickness, length, width = case.pad_size_mm
    half_gap = case.pad_gap_mm / 2.0
    # the designed finger's opening, the wider
    opening = approach_opening_mm(case, case.penetration_mm, config)
    reach = np.array([length / 2.0, half_gap + thickness + opening])
    to_tcp = np.linalg.inv(case.tcp)
    com = to_tcp[:3, :3] @ np.asarray(case.part.center_mass, dtype=float) + to_tcp[:3, 3]
    radius = float(np.hypot(np.abs(com[0]) + reach[0], np.abs(com[1]) + reach[1]))
    turn = np.radians(config.yaw_error_deg + config.slip_deg)
    margin = float(
        np.hypot(config.position_error_mm, config.position_error_mm) + radius * np.sin(turn) + config.slip_mm
    )
    top = float((np.asarray(case.part.vertices) @ to_tcp[2, :3] + to_tcp[2, 3]).min()) - margin
    return np.array(
        [
            [
                [-length / 2.0 - margin, half_gap - margin, top],
                [length / 2.0 + margin, half_gap + thickness + opening + margin, width / 2.0 + margin],
            ],
            [
                [-length / 2.0 - margin, -half_gap - thickness - opening - margin, top],
                [length / 2.0 + margin, -half_gap + margin, width / 2.0 + margin],
            ],
        ]
    )


def verify_case(
    case: GraspCase,
    pieces: ConvexPieces,
    pad: ConvexPieces,
    finger_hull_mm: np.ndarray,
    config: VerifyConfig,
    stream: int,
    advance: Callable[[], None] = lambda: None,
    designed_scene: Scene | None = None,
    precision_only: bool = False,
) -> ScenarioVerification:
    """Both fingers' precision and holding tests on one grasp case.

    Parameters
    ----------
    case : GraspCase
    pieces : ConvexPieces
        The part's collision geometry.
    pad : ConvexPieces
        The designed pad's collision geometry (pad frame).
    finger_hull_mm : (n, 3) float
    config : VerifyConfig
    stream : int
        Seeds this scenario's perturbations (same for both fingers).
    advance : callable
        Called after every simulated grasp.
    designed_scene : Scene, optional
        The designed finger's scene of these pieces when already compiled (:func:`fitted_pieces`).
    precision_only : bool
        The designed finger's precision trials and both fingers' unperturbed grasps alone
        (:func:`scenario_simulations`): the flat control runs no trial, no holding test runs, and the scenario does
        not pass (``holds_as_flat`` null).
    """
    errors = perturbations(config.trials, config, stream)
    scenes = {
        "fcso": designed_scene or build_scene(case, pieces.pieces, pad.pieces, finger_hull_mm, config),
        "flat": build_scene(case, pieces.pieces, None, finger_hull_mm, config),
    }
    penetration, pads_overlap = seated_overlaps_mm(scenes["fcso"])
    # the volumes of a precision-only run's pieces are not reported: measured when the scenario is run in full
    part_volume = None if precision_only else volume_errors(pieces, config.cache_path())
    pad_volume = None if precision_only else volume_errors(pad, config.cache_path())
    fidelity = Fidelity(
        part_pieces=len(pieces.pieces),
        part_volume_error=None if part_volume is None else round(part_volume[0], 6),
        part_missing_fraction=None if part_volume is None else round(part_volume[1], 6),
        pad_pieces=len(pad.pieces),
        pad_volume_error=None if pad_volume is None else round(pad_volume[0] - pad_volume[1], 6),
        seated_penetration_mm=round(penetration, 4),
        seated_pads_overlap_mm=round(pads_overlap, 4),
        decomposition_cached=pieces.cached,
    )
    part_name, _, pose = case.name.rpartition(" pose ")
    pose_index = int(pose) if pose.isdigit() else 0
    # a design delivered with flat pads is the control itself: its simulations are the control's
    own_control = is_own_control(scenes["fcso"], scenes["flat"])
    simulated = simulations_within_arena(
        {"fcso": scenes["fcso"]} if own_control else scenes, case, errors, config, advance, precision_only
    )
    if own_control and not isinstance(simulated, str):
        simulated = as_own_control(simulated, advance)
    if isinstance(simulated, str):
        unsimulated = {kind: _finger_result(kind, False, (0.0, 0.0), [], {}, None) for kind in scenes}
        return ScenarioVerification(
            part=part_name,
            pose_index=pose_index,
            fidelity=fidelity,
            fcso=unsimulated["fcso"],
            flat=unsimulated["flat"],
            holds_as_flat=None,
            passed=False,
            frames=[],
            failure_reason=simulated,
        )
    runs, trials, stopped, holding = simulated.runs, simulated.trials, simulated.stopped_after, simulated.holding
    precision_failed = simulated.precision_failed
    results = {}
    for kind, (nominal, *perturbed) in runs.items():
        offset = pose_error(nominal.part_in_gripper, np.linalg.inv(case.tcp), scenes[kind].part_com_mm)
        pictured = perturbed[0].frames if perturbed else None
        results[kind] = _finger_result(kind, nominal.held, offset, trials[kind], holding[kind], pictured)
    frames = runs["fcso"][0].frames or []
    holds = (
        not weaker_than_flat(results["fcso"].holding_n, results["flat"].holding_n, config)
        if results["fcso"].holding_n
        else None
    )
    return ScenarioVerification(
        part=part_name,
        pose_index=pose_index,
        fidelity=fidelity,
        fcso=results["fcso"],
        flat=results["flat"],
        holds_as_flat=holds,
        stopped_after_trials=stopped,
        passed=not precision_failed and bool(holds) and nominal_miss(results["fcso"], config) is None,
        frames=[_snapshot(f) for f in frames],
        reused_simulations=simulated.reused,
    )


def simulations_within_arena(
    scenes: dict[str, Scene],
    case: GraspCase,
    errors: np.ndarray,
    config: VerifyConfig,
    advance: Callable[[], None],
    precision_only: bool = False,
) -> ScenarioSimulations | str:
    """:func:`scenario_simulations`, run again once with ``config.arena_retry_factor`` times the arena when MuJoCo
    runs out of it (a part of many pieces in many contacts).

    Returns
    -------
    ScenarioSimulations, or str
        Why the scenario could not be simulated: it ran out of its arena again, or there was no retry.
    """
    arenas = []
    while True:
        arenas.append(max(scene.arena_bytes for scene in scenes.values()))
        try:
            return scenario_simulations(scenes, case, errors, config, advance, precision_only)
        except mujoco.FatalError as error:
            if not out_of_arena(error):
                raise
            message = str(error).splitlines()[0]
        if len(arenas) > 1 or config.arena_retry_factor <= 1.0:
            sizes = " then ".join(f"{arena / 2**20:.3g} MiB" for arena in arenas)
            return (
                f"MuJoCo ran out of its memory arena ({sizes}; {message}): the part's contacts need more, raise "
                "[verify] arena_mb"
            )
        scenes = {
            kind: with_arena(scene, int(scene.arena_bytes * config.arena_retry_factor))
            for kind, scene in scenes.items()
        }


def weaker_than_flat(
    designed: dict[str, float | None], flat: dict[str, float | None], config: VerifyConfig
) -> dict[str, tuple[float, float]]:
    """The push directions where the designed finger slips more than ``hold_tolerance_n`` before flat pads do.

    Parameters
    ----------
    designed, flat : dict
        Push direction -> slip force, N (None: held at ``hold_force_n``), as :func:`fcso.sim.trials.hold_forces`.
    config : VerifyConfig

    Returns
    -------
    dict
        Direction -> (designed, flat) force, N; empty when it holds as well as flat pads.
    """
    held = {name: tuple(config.hold_force_n if f is None else f for f in (designed[name], flat[name])) for name in flat}
    return {name: pair for name, pair in held.items() if pair[0] < pair[1] - config.hold_tolerance_n}


def _finger_result(
    kind, held, offset, trials: list[TrialResult], holding, pictured: list[Frame] | None
) -> FingerResult:
    moved = np.array([t.error_mm for t in trials])
    turned = np.array([t.error_deg for t in trials])
    any_trials = len(trials) > 0
    return FingerResult(
        kind=kind,
        nominal_held=held,
        nominal_offset_mm=round(offset[0], 4),
        nominal_offset_deg=round(offset[1], 4),
        trials=trials,
        success_rate=float(np.mean([t.success for t in trials])) if any_trials else 0.0,
        median_error_mm=round(float(np.median(moved)), 4) if any_trials else None,
        worst_error_mm=round(float(moved.max()), 4) if any_trials else None,
        median_error_deg=round(float(np.median(turned)), 4) if any_trials else None,
        worst_error_deg=round(float(turned.max()), 4) if any_trials else None,
        holding_n=holding,
        trial_start=_snapshot(pictured[0]) if pictured else None,
        trial_end=_snapshot(pictured[-1]) if pictured else None,
    )


def _snapshot(frame: Frame) -> PoseSnapshot:
    return PoseSnapshot(
        time_s=round(frame.time_s, 4),
        part_pose=np.round(frame.part, 5).tolist(),
        gripper_pose=np.round(frame.gripper, 5).tolist(),
        opening_mm=round(frame.q_mm, 4),
    )


def flat_pad(pad_size_mm, penetration_mm: float) -> trimesh.Trimesh:
    """The flat control's pad: a plain pad of thickness T - D in the pad frame, mm."""
    thickness, length, width = pad_size_mm
    pad = trimesh.creation.box(bounds=[[penetration_mm, 0.0, 0.0], [thickness, length, width]])
    return pad


def is_flat_control(pad: trimesh.Trimesh, pad_size_mm, penetration_mm: float) -> bool:
    """Whether ``pad`` (pad frame, mm) is the flat control's pad (:func:`flat_pad`): a design delivered with flat pads.

    A solid within the control's box that has the box's volume fills it.
    """
    control = flat_pad(pad_size_mm, penetration_mm)
    return bool(
        np.allclose(pad.bounds, control.bounds, rtol=0.0, atol=1e-6)
        and abs(pad.volume - control.volume) <= 1e-6 * control.volume
    )
