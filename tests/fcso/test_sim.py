"""Sanity cases of the grasp simulation (METHOD §12): each fails when the physics or the collision geometry is wrong."""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
from pathlib import Path

import manifold3d
import numpy as np
import pytest
import trimesh

from examples.batch_demo import DEMO_10MM_PADS, batch_demo_part_files, batch_demo_settings
from examples.part_families import draw
from examples.sim_parts import featured_cube, ridged_block
from fcso import DesignConfig, design
from fcso.geometry import box, to_manifold, to_trimesh
from fcso.output.verification_page import section_html
from fcso.parts import Part
from fcso.report.ranking import ranked_candidates
from fcso.sim import schedule as schedule_module
from fcso.sim import trials
from fcso.sim.choose import candidate_designs
from fcso.sim.collision import (
    MIN_PIECE_VOLUME_MM3,
    MIN_PIECE_WIDTH_MM,
    ConvexPieces,
    hull_width_mm,
    pad_prism_pieces,
    part_shell_pieces,
    volume_errors,
)
from fcso.sim.config import VerifyConfig
from fcso.sim.diskcache import ABANDONED_WRITE_S, evict
from fcso.sim.report import Fidelity, VerificationReport, verdict_text
from fcso.sim.scene import GraspCase, build_scene
from fcso.sim.schedule import nominal_grasp, nominal_grasps, scenario_simulations
from fcso.sim.seats import nominal_miss
from fcso.sim.trials import hold_forces, pose_error, run_grasp, seated_overlaps_mm, start_pose
from fcso.sim.verify import (
    DesignUnderTest,
    design_under_test,
    finger_hull,
    fitted_pieces,
    flat_pad,
    grasp_case,
    is_flat_control,
    part_pieces,
    seated_overlap_notes,
    verify,
    verify_case,
    weaker_than_flat,
)
from tests.conftest import data_path

#: TCP of a grasp closing along the table's x axis (TCP y), approaching from above.
CLOSING_ALONG_X = np.column_stack([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _config(tmp_path, **values) -> VerifyConfig:
    """Settings whose every grasp and push is simulated (the tests compare runs with each other), unless ``values``
    say ``reuse_simulations=True``."""
    return VerifyConfig(cache_dir=tmp_path / "cache", **{"reuse_simulations": False, **values})


def _hull(mesh: trimesh.Trimesh) -> list[tuple[np.ndarray, np.ndarray]]:
    """A convex part's collision pieces: its hull."""
    return [(np.asarray(mesh.convex_hull.vertices), np.asarray(mesh.convex_hull.faces))]


def _cube_case(size_mm: float = 20.0) -> GraspCase:
    """A cube on the table held across x by flat pads (T = 5, D = 4) at mid-height."""
    cube = trimesh.creation.box([size_mm] * 3)
    cube.apply_translation([0.0, 0.0, size_mm / 2.0])
    tcp = np.eye(4)
    tcp[:3, :3] = CLOSING_ALONG_X
    tcp[:3, 3] = [0.0, 0.0, size_mm / 2.0 + 1.0]
    # the flat pads' faces (u = D) touch the cube's faces at q = 0
    return GraspCase("cube", cube, tcp, size_mm - 8.0, (5.0, 20.0, 20.0), 4.0, (0.0, 50.0))


@pytest.fixture(scope="module")
def ridged(tmp_path_factory):
    """The ridged block designed across its ridges: the case, its pieces, the carved pad's pieces, the finger hull, the
    pad.
    """
    mesh = ridged_block()
    part = Part(name="ridged", path="ridged_block", mesh=mesh, scale=1.0, repairs=[])
    # the exact pocket: the pads close onto the seat the design scored (q = 0); the pad on the block's whole
    # width (stride positions only): a pad centred on the block's end would wrap it, and the pad's pieces leave
    # out what wraps behind the part (pad_prism_pieces)
    config = DesignConfig().updated(
        {
            "poses": {"count": 1, "select": "most_probable"},
            "sampler": {"length_mm": 20.0, "yaw_deg": [0.0], "feature_positions": False, "face_yaws": False},
            "print": {"profile": "custom"},
        }
    )
    result = design([part], config)
    assert result.report.candidates[0].pad_case != "bad"
    cache = tmp_path_factory.mktemp("cache")
    case = grasp_case(result.report, result.report.grasps[0], mesh)
    pieces = part_pieces(case, VerifyConfig(cache_dir=cache)).pieces
    pad = pad_prism_pieces(result.fingerpad, config.sampler.thickness_mm, cache).pieces
    return case, pieces, pad, finger_hull(result.report, result.finger), result.fingerpad


def test_cube_between_flat_pads_stays_put(tmp_path):
    case = _cube_case()
    config = _config(tmp_path)
    scene = build_scene(case, _hull(case.part), None, np.zeros((0, 3)), config)
    run = run_grasp(scene, case, np.eye(4), config)
    assert run.held
    moved, turned = pose_error(run.part_in_gripper, np.linalg.inv(case.tcp), case.part.center_mass)
    assert moved <= 0.05 and turned <= 0.05


def _creeping(velocity_mm_s, turn_deg_s, fingers_mm_s, steps=101, step_s=0.001):
    """Samples of a part creeping at constant rates: its centre of mass along x, its turn about z, both fingers."""
    times = np.arange(steps) * step_s
    coms = np.outer(times, [velocity_mm_s, 0.0, 0.0]) + [1.0, 2.0, 3.0]
    angles = np.radians(turn_deg_s) * times
    rotations = np.array([[[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]] for a in angles])
    fingers = np.outer(times, [fingers_mm_s, fingers_mm_s])
    return coms, rotations, fingers


def test_measured_creep_is_the_rate_of_a_creep_and_its_uncertainty_the_change_between_the_halves():
    creep = trials.measure_creep(*_creeping(0.15, 0.3, -0.002), 0.001)
    assert creep.velocity_mm_s == pytest.approx([0.15, 0.0, 0.0], abs=1e-9)
    assert creep.angular_velocity_rad_s == pytest.approx([0.0, 0.0, np.radians(0.3)], abs=1e-9)
    assert creep.fingers_mm_s == pytest.approx([-0.002, -0.002], abs=1e-9)
    assert creep.uncertainty_mm_s < 1e-9 and creep.uncertainty_deg_s < 1e-9
    # at rest: no creep
    still = trials.measure_creep(*_creeping(0.0, 0.0, 0.0), 0.001)
    assert np.abs(np.hstack([still.velocity_mm_s, still.angular_velocity_rad_s, still.fingers_mm_s])).max() < 1e-12
    # the second half of the samples moving faster in each of the three: the change is the uncertainty of its kind
    for faster, uncertainty in (
        ((0.03, 0.0, 0.0), (0.03, 0.0)),
        ((0.0, 0.05, 0.0), (0.0, 0.05)),
        ((0.0, 0.0, 0.02), (0.02, 0.0)),
    ):
        first = _creeping(0.15, 0.3, -0.002, steps=51)
        second = _creeping(*np.add((0.15, 0.3, -0.002), faster), steps=51)
        joined = (
            np.vstack([first[0], second[0][1:] - second[0][0] + first[0][-1]]),
            np.vstack([first[1], second[1][1:] @ first[1][-1]]),
            np.vstack([first[2], second[2][1:] - second[2][0] + first[2][-1]]),
        )
        creep = trials.measure_creep(*joined, 0.001)
        assert (creep.uncertainty_mm_s, creep.uncertainty_deg_s) == pytest.approx(uncertainty, abs=1e-9)


def _creep(velocity=(0.0, 0.0, 0.0), turn_deg_s=0.0, fingers=(0.0, 0.0), uncertainty_mm_s=0.0, uncertainty_deg_s=0.0):
    return trials.Creep(
        np.array(velocity),
        np.array([0.0, 0.0, np.radians(turn_deg_s)]),
        np.array(fingers),
        uncertainty_mm_s,
        uncertainty_deg_s,
    )


def test_a_creep_is_carried_on_until_it_has_moved_or_turned_the_part_by_its_limit_or_as_far_as_it_is_known():
    assert trials.creep_horizon_s(_creep()) == np.inf
    assert trials.creep_horizon_s(_creep(velocity=(0.0, 0.1, 0.0))) == pytest.approx(trials.CREEP_CARRY_MM / 0.1)
    assert trials.creep_horizon_s(_creep(fingers=(0.0, -0.2))) == pytest.approx(trials.CREEP_CARRY_MM / 0.2)
    assert trials.creep_horizon_s(_creep(velocity=(0.01, 0.0, 0.0), turn_deg_s=0.25)) == pytest.approx(
        min(trials.CREEP_CARRY_DEG / 0.25, trials.CREEP_CARRY_MM / 0.01)
    )
    # a creep known to 0.06 mm/s and 0.12 degrees/s (the bunny chattering in its pose 3 pads) is carried on as far as
    # that uncertainty stays within the errors allowed
    chattering = _creep(velocity=(0.05, 0.0, 0.0), turn_deg_s=0.08, uncertainty_mm_s=0.06, uncertainty_deg_s=0.12)
    assert trials.creep_horizon_s(chattering) == pytest.approx(
        min(trials.CREEP_ERROR_MM / 0.06, trials.CREEP_ERROR_DEG / 0.12)
    )
    assert trials.creep_horizon_s(_creep(uncertainty_mm_s=0.01)) == pytest.approx(trials.CREEP_ERROR_MM / 0.01)


def _lift_stretches(heights_mm):
    """:func:`trials.project_creep`, noting the heights of the lift it carries on (mm)."""
    project = trials.project_creep

    def noted(scene, data, seconds, speed_mm_s, creep):
        heights_mm.append(seconds * speed_mm_s)
        project(scene, data, seconds, speed_mm_s, creep)

    return noted


def test_the_skipped_steady_lift_ends_where_the_stepped_lift_ends(tmp_path, monkeypatch):
    case = _cube_case()
    config = _config(tmp_path)
    scene = build_scene(case, _hull(case.part), None, np.zeros((0, 3)), config)
    start = start_pose(case, np.array([1.5, -1.0, 2.0]))
    skips = []
    monkeypatch.setattr(trials, "project_creep", _lift_stretches(skips))
    skipped = run_grasp(scene, case, start, config, record=True)
    # the cube between flat pads moves with the gripper early in the 100 mm lift: most of it is skipped
    assert len(skips) == 1 and skips[0] > 80.0
    monkeypatch.setattr(trials, "CREEP_WINDOW_STEPS", 10**9)
    stepped = run_grasp(scene, case, start, config, record=True)
    assert skipped.held and stepped.held
    moved, turned = pose_error(skipped.part_in_gripper, stepped.part_in_gripper, case.part.center_mass)
    assert moved <= 0.01 and turned <= 0.01
    # the recorded frames cover the skipped stretch as the steps would, the part rising with the gripper
    # (stepped frames are taken at the first step at or after each frame time: up to one 1 ms step later)
    assert [f.time_s for f in skipped.frames] == pytest.approx([f.time_s for f in stepped.frames], abs=1.5e-3)
    for mine, theirs in zip(skipped.frames, stepped.frames):
        assert np.allclose(mine.gripper, theirs.gripper, atol=0.2)
        assert np.allclose(mine.part[:3, 3], theirs.part[:3, 3], atol=0.2)


def test_a_part_rocking_in_carved_pads_skips_the_lift_and_ends_where_the_stepped_lift_ends(tmp_path, monkeypatch):
    # the demo's xyz cube in its carved pads (its embossed letters) rocks in the lift, at 0.15 degrees/s 13 mm into it
    # and dying away
    result = design(batch_demo_part_files()[:1], batch_demo_settings().updated({"sampler": DEMO_10MM_PADS}))
    under_test = design_under_test(result)
    case, config = under_test.cases[0], _config(tmp_path)
    part, pad, _ = fitted_pieces(case, under_test, config)
    scene = build_scene(case, part.pieces, pad.pieces, under_test.finger_hull_mm, config)
    start = start_pose(case, np.array([0.5, -0.5, 1.0]))
    skips = []
    monkeypatch.setattr(trials, "project_creep", _lift_stretches(skips))
    skipped = run_grasp(scene, case, start, config)
    # in stretches: each carries at most CREEP_CARRY_DEG of its turn
    assert len(skips) >= 2 and sum(skips) > 50.0
    monkeypatch.setattr(trials, "CREEP_WINDOW_STEPS", 10**9)
    stepped = run_grasp(scene, case, start, config)
    assert skipped.held and stepped.held
    moved, turned = pose_error(skipped.part_in_gripper, stepped.part_in_gripper, case.part.center_mass)
    # within 1 % and 3 % of the success limits (0.3 mm, 1 degree)
    assert moved <= 0.003 and turned <= 0.03


def test_settles_and_holds_that_end_at_rest_end_where_the_whole_ones_end(ridged, tmp_path, monkeypatch):
    # the ridged block displaced in its carved pads: the settles after closing and after the lift end once it rests in
    # the gripper, and each holding push held at its largest force once its drift could not make it slip
    case, pieces, pad, hull, _ = ridged
    config = _config(tmp_path)
    scene = build_scene(case, pieces, pad, hull, config)
    start = start_pose(case, np.array([0.5, -0.5, 1.0]))
    steps = []
    step = trials.prescribed_step
    monkeypatch.setattr(trials, "prescribed_step", lambda *args: steps.append(1) or step(*args))
    early = run_grasp(scene, case, start, config)
    early_steps = len(steps)
    early_holds = hold_forces(scene, case, early, config)
    early_hold_steps = len(steps) - early_steps
    monkeypatch.setattr(trials, "REST_STEPS", 10**9)
    steps.clear()
    whole = run_grasp(scene, case, start, config)
    whole_steps = len(steps)
    whole_holds = hold_forces(scene, case, whole, config)
    whole_hold_steps = len(steps) - whole_steps
    # the settles' 100 + 200 steps, of which at least 50 each are simulated
    assert whole_steps - early_steps >= 100
    # held at the largest push in every direction, each hold ends after 50 of its 200 steps there
    held = [name for name, force in whole_holds.items() if force is None]
    assert held and early_hold_steps <= whole_hold_steps - 100 * len(held)
    moved, turned = pose_error(early.part_in_gripper, whole.part_in_gripper, case.part.center_mass)
    # within 1 % and 3 % of the success limits (0.3 mm, 1 degree)
    assert moved <= 0.003 and turned <= 0.03
    assert early_holds == whole_holds


def test_seated_overlaps_tell_the_part_from_the_other_pad(tmp_path):
    """The seated overlap of part and pads is the part's alone; the pads' overlap with each other is its own figure."""
    case, config, nothing = _cube_case(), _config(tmp_path), np.zeros((0, 3))
    # the flat pads' faces 0.5 mm inside the cube's faces
    pressed = dataclasses.replace(case, pad_gap_mm=case.pad_gap_mm - 1.0)
    part_pad, pad_pad = seated_overlaps_mm(build_scene(pressed, _hull(pressed.part), None, nothing, config))
    assert part_pad == pytest.approx(0.5, abs=0.01) and pad_pad == 0.0
    # the pads crossing by 1 mm (both span -0.5..0.5 mm across the closing axis), the cube 100 mm away
    away = case.part.copy()
    away.apply_translation([100.0, 0.0, 0.0])
    crossing = dataclasses.replace(case, part=away, pad_gap_mm=-9.0)
    part_pad, pad_pad = seated_overlaps_mm(build_scene(crossing, _hull(away), None, nothing, config))
    assert part_pad == 0.0 and pad_pad == pytest.approx(1.0, abs=0.01)


def test_seated_overlaps_beyond_the_limit_are_warned_of_by_scenario(tmp_path):
    """Each overlap over max_seated_penetration_mm (0.2 mm) is a warning naming the scenario and its figure."""
    fidelity = Fidelity(
        part_pieces=64,
        part_volume_error=0.0,
        part_missing_fraction=0.5,
        pad_pieces=296,
        pad_volume_error=0.0,
        seated_penetration_mm=0.15,
        seated_pads_overlap_mm=0.0,
        decomposition_cached=False,
    )
    config = _config(tmp_path)
    assert seated_overlap_notes("cube pose 0", fidelity, config) == []
    deep = fidelity.model_copy(update={"seated_penetration_mm": 0.25, "seated_pads_overlap_mm": 0.3})
    part_pad, pad_pad = seated_overlap_notes("cube pose 0", deep, config)
    assert part_pad.startswith("cube pose 0: part and pad pieces overlap 0.25 mm") and "pad 296" in part_pad
    assert pad_pad.startswith("cube pose 0: the two pads overlap each other 0.30 mm")
    # at the limit is within it
    assert seated_overlap_notes("cube pose 0", deep, config.model_copy(update={"max_seated_penetration_mm": 0.3})) == []


def test_carved_and_flat_pads_clear_the_part_alike_as_they_descend(ridged, tmp_path):
    """A carved pad's face is the penetration D inside the part's outermost point at the seated grasp, a flat pad's at
    it: the designed finger opens D further than the control, so both clear the part by open_margin_mm."""
    case, pieces, pad, hull, _ = ridged
    # within the block's 8 mm of finger travel beyond its seat
    config = _config(tmp_path, open_margin_mm=2.0)
    assert case.joint_range_mm[1] > case.penetration_mm + config.open_margin_mm
    carved = run_grasp(build_scene(case, pieces, pad, hull, config), case, np.eye(4), config, record=True)
    flat = run_grasp(build_scene(case, pieces, None, hull, config), case, np.eye(4), config, record=True)
    # the first frame: the gripper coming down, its fingers still where they started
    assert carved.frames[0].q_mm == pytest.approx(case.penetration_mm + config.open_margin_mm, abs=1e-3)
    assert flat.frames[0].q_mm == pytest.approx(config.open_margin_mm, abs=1e-3)
    assert carved.held and flat.held


def test_part_seated_in_its_pad_does_not_move(ridged, tmp_path):
    case, pieces, pad, hull, _ = ridged
    config = _config(tmp_path)
    run = run_grasp(build_scene(case, pieces, pad, hull, config), case, np.eye(4), config)
    assert run.held
    # the pads close onto their designed seat (q = 0), less the soft contacts' give
    assert abs(run.q_mm) <= 0.25
    moved, turned = pose_error(run.part_in_gripper, np.linalg.inv(case.tcp), case.part.center_mass)
    assert moved <= 0.05 and turned <= 0.1


def test_carved_pad_centres_a_displaced_part_and_flat_pad_does_not(ridged, tmp_path):
    case, pieces, pad, hull, _ = ridged
    config = _config(tmp_path)
    # 2 mm along the pads (the TCP's x axis): only the V-grooves of the carved pad can push it back
    along = case.tcp[:3, 0] * 2.0
    displaced = start_pose(case, np.array([along[0], along[1], 0.0]))
    errors = {}
    for kind, pad_pieces in (("carved", pad), ("flat", None)):
        run = run_grasp(build_scene(case, pieces, pad_pieces, hull, config), case, displaced, config)
        assert run.held
        errors[kind] = pose_error(run.part_in_gripper, np.linalg.inv(case.tcp), case.part.center_mass)
    assert errors["carved"][0] <= 0.1
    assert errors["flat"][0] >= 1.8


def test_a_scenario_whose_unperturbed_grasp_slides_off_its_seat_fails_and_is_rejected_before_any_trial(
    ridged, tmp_path
):
    # METHOD §5b in a finger shared by scenarios: the second one's designed seat is 2 mm along the pads from the
    # pocket (as a part resting beside another part's pocket), and the V-grooves slide its ridge into the pocket
    # (test_carved_pad_centres_a_displaced_part_and_flat_pad_does_not): its unperturbed grasp holds the part 2 mm off
    # its seat. The trial starts without error, so it ends where that grasp ends, a success judged against it.
    case, _, _, hull, fingerpad = ridged
    tcp = case.tcp.copy()
    tcp[:3, 3] -= 2.0 * case.tcp[:3, 0]
    shifted = dataclasses.replace(case, name="shifted pose 0", tcp=tcp)
    design_2 = DesignUnderTest([case, shifted], fingerpad, hull)
    settings = {"trials": 1, "position_error_mm": 0.0, "yaw_error_deg": 0.0, "lift_mm": 10.0}

    full = verify(design_2, _config(tmp_path, stop_early=False, reuse_simulations=True, **settings))

    seated, off = full.scenarios
    assert seated.passed and seated.fcso.nominal_offset_mm <= 0.3
    assert off.fcso.nominal_held and 1.7 <= off.fcso.nominal_offset_mm <= 2.3 and off.fcso.trials[0].success
    assert not off.passed and not full.passed and full.unseated_scenarios == ["shifted pose 0"]
    assert "OFF ITS SEAT in shifted pose 0" in verdict_text(full)
    assert any(w.startswith("shifted pose 0: the unperturbed grasp holds the part 2.0 mm") for w in full.warnings)

    # choosing among candidates (stop_early): every scenario's unperturbed grasp is judged before any trial, the
    # second rejects the design, and no trial is run
    chosen = verify(design_2, _config(tmp_path, reuse_simulations=True, **settings))
    assert not chosen.passed and chosen.scenarios == [] and chosen.unseated_scenarios == ["shifted pose 0"]
    assert chosen.unverified_scenarios == [case.name, "shifted pose 0"]


def test_a_design_that_fails_its_precision_trials_runs_no_control_trial_and_no_push(ridged, tmp_path, monkeypatch):
    # choosing (stop_early): the designed finger's trials run first and decide; the flat control's trials and both
    # fingers' pushes are for a design that passed them. Start errors of 6 mm along the pads put the ridges beyond
    # the grooves that centre them at 2 mm
    case, _, _, hull, fingerpad = ridged
    design_1 = DesignUnderTest([case], fingerpad, hull)
    settings = {"trials": 4, "position_error_mm": 6.0, "lift_mm": 10.0, "hold_ramp_n_s": 300.0}
    full = verify(design_1, _config(tmp_path / "full", stop_early=False, **settings))
    (whole,) = full.scenarios
    assert not full.passed and len(whole.flat.trials) == 4 and len(whole.flat.holding_n) == 6
    simulated = []
    grasp = schedule_module.run_grasp
    monkeypatch.setattr(
        schedule_module, "run_grasp", lambda scene, *args, **kw: simulated.append(scene) or grasp(scene, *args, **kw)
    )
    pushes = []
    push = schedule_module.hold_force
    monkeypatch.setattr(schedule_module, "hold_force", lambda *args: pushes.append(args) or push(*args))

    chosen = verify(design_1, _config(tmp_path, jobs=1, reuse_simulations=True, **settings))

    (stopped,) = chosen.scenarios
    assert not chosen.passed and stopped.stopped_after_trials is not None
    assert stopped.fcso.trials == whole.fcso.trials[: stopped.stopped_after_trials]
    assert stopped.flat.trials == [] and stopped.flat.nominal_held == whole.flat.nominal_held
    assert stopped.fcso.holding_n == stopped.flat.holding_n == {} and pushes == []
    # both fingers' unperturbed grasps (METHOD §5b), then the designed finger's trials to the deciding one
    designed = sum(scene.pad_geoms.size > 2 for scene in simulated)
    assert (designed, len(simulated) - designed) == (1 + stopped.stopped_after_trials, 1)
    # nor is the Boolean union of its collision pieces measured (a fifth of a second per part and pad): that figure
    # is told for a verification run in full, as the one without stopping
    assert stopped.fidelity.part_volume_error is stopped.fidelity.pad_volume_error is None
    assert not list((tmp_path / "cache").glob("*-volume.npz")) and list((tmp_path / "full").rglob("*-volume.npz"))


def test_a_design_that_passes_its_precision_trials_is_verified_in_full_as_without_stopping(ridged, tmp_path):
    case, _, _, hull, fingerpad = ridged
    design_1 = DesignUnderTest([case], fingerpad, hull)
    settings = {"trials": 2, "lift_mm": 10.0, "hold_ramp_n_s": 300.0}
    full = verify(design_1, _config(tmp_path / "full", stop_early=False, **settings))
    chosen = verify(design_1, _config(tmp_path / "chosen", reuse_simulations=True, **settings))
    assert full.passed and chosen.passed
    assert chosen.scenarios[0].model_dump(exclude={"reused_simulations"}) == full.scenarios[0].model_dump(
        exclude={"reused_simulations"}
    )
    # everything was simulated for this verification, none read from an earlier one: not the unperturbed grasp the
    # seat check (METHOD §5b) ran before the trials, nor the designed trials the full run reads back
    assert chosen.scenarios[0].reused_simulations == 0 and chosen.warnings == full.warnings


def test_a_part_that_flat_pads_cannot_hold_either_rejects_no_candidate_before_its_trials(ridged, tmp_path):
    # METHOD §5b is "never worse than flat" said of the seat: the ridged block 300 times as dense weighs more than the
    # 60 N grip's friction carries (2 x 0.4 x 60 N) and its V-grooves are vertical, so in the unperturbed grasp it
    # slides down the carved pads and the flat ones alike; a carving flat pads do no better than is not rejected
    # before its trials, which judge it
    case, _, _, hull, fingerpad = ridged
    design_1 = DesignUnderTest([case], fingerpad, hull)
    settings = {"trials": 1, "position_error_mm": 0.0, "yaw_error_deg": 0.0, "lift_mm": 10.0, "density_g_cm3": 300.0}

    chosen = verify(design_1, _config(tmp_path, reuse_simulations=True, **settings))

    (scenario,) = chosen.scenarios
    # both slide down in the pads: the carved ones end 4 mm off the seat, flat ones 0.6 mm (beyond the 0.3 mm)
    assert nominal_miss(scenario.fcso, chosen.settings) and nominal_miss(scenario.flat, chosen.settings)
    assert chosen.unseated_scenarios == [] and chosen.unverified_scenarios == []
    # its trial ran; the scenario still does not pass, its designed seat missed
    assert len(scenario.fcso.trials) == 1 and not scenario.passed and not chosen.passed


def test_flat_pad_holding_force_rises_with_friction(tmp_path):
    case = _cube_case()
    slips = {}
    for friction in (0.1, 0.2):
        config = _config(tmp_path, friction=friction, hold_force_n=40.0, hold_ramp_n_s=200.0, lift_mm=10.0)
        scene = build_scene(case, _hull(case.part), None, np.zeros((0, 3)), config)
        run = run_grasp(scene, case, np.eye(4), config)
        slips[friction] = hold_forces(scene, case, run, config)["+x"]
    # Coulomb: two contacts, each 60 N normal, slip along the pads at 2 mu N
    for friction, force in slips.items():
        assert force == pytest.approx(2.0 * friction * 60.0, rel=0.2)
    assert slips[0.2] > 1.6 * slips[0.1]


def test_a_finger_holds_as_well_as_flat_pads_only_in_every_direction():
    config = VerifyConfig(hold_force_n=30.0, hold_tolerance_n=1.0)
    flat = {"+x": 22.7, "-x": None, "+y": 22.5, "-y": None, "+z": 10.0, "-z": None}
    # +x slips 3.4 N earlier (the holed, notched cube's pad on its corner notches); -x 2 N short of flat's hold at the
    # test's 30 N; +y within the tolerance; +z better than flat
    designed = {"+x": 19.3, "-x": 28.0, "+y": 22.0, "-y": None, "+z": 12.0, "-z": None}
    assert weaker_than_flat(designed, flat, config) == {"+x": (19.3, 22.7), "-x": (28.0, 30.0)}
    assert weaker_than_flat(flat, flat, config) == {}
    assert weaker_than_flat({k: None for k in flat}, flat, config) == {}


def _stands_out_mm(vertices: np.ndarray, target: trimesh.Trimesh) -> float:
    """How far a convex piece's surface stands out of a mesh, mm."""
    import igl

    surface = trimesh.convex.convex_hull(vertices).sample(2000, seed=0)
    return float(
        igl.signed_distance(
            surface, np.asarray(target.vertices, dtype=float), np.asarray(target.faces, dtype=np.int64)
        )[0].max()
    )


def test_collision_pieces_hug_the_part_and_the_pad(ridged):
    """No convex piece may stand out of its mesh: a bulge fills the pad's pockets and stalls the fingers early."""
    case, pieces, pad, _, fingerpad = ridged
    for meshes, target in ((pieces, case.part), (pad, fingerpad)):
        for vertices, _ in meshes:
            # the prisms under the part's and the pad's faces by the 0.005 mm of the meshes' simplification at most
            # (CoACD's part pieces stood out up to ~0.12 mm here)
            assert _stands_out_mm(vertices, target) <= 0.01


def _union(pieces) -> manifold3d.Manifold:
    return manifold3d.Manifold.batch_boolean(
        [manifold3d.Manifold.hull_points(np.asarray(v, dtype=float)) for v, _ in pieces], manifold3d.OpType.Add
    )


def test_pad_prisms_are_the_pad_exactly_and_read_back_from_disk(tmp_path):
    """The pad's pieces fill the carved pad (a V-groove, a round pocket with its curved wall, a square one) and
    nothing else, and the same pieces come back from the cache.
    """
    pad_box = box((0.0, 0.0, 0.0), (5.0, 20.0, 20.0))
    groove = manifold3d.Manifold.hull_points(
        np.array([[-1, 3, -1], [-1, 9, -1], [3, 6, -1], [-1, 3, 21], [-1, 9, 21], [3, 6, 21.0]])
    )
    round_pocket = manifold3d.Manifold.cylinder(4.0, 3.0, 3.0, 48).rotate((0.0, 90.0, 0.0)).translate((-1.0, 14.0, 6.0))
    square_pocket = box((-1.0, 12.0, 12.0), (2.0, 18.0, 18.0))
    carved = to_trimesh(pad_box - groove - round_pocket - square_pocket)
    made = pad_prism_pieces(carved, 5.0, tmp_path)
    read = pad_prism_pieces(carved, 5.0, tmp_path)
    assert not made.cached and read.cached and len(read.pieces) == len(made.pieces)
    assert all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) for a, b in zip(made.pieces, read.pieces))
    # the curved wall alone needs a prism per facet; every flat face is one
    assert len(read.pieces) < 120
    union = _union(read.pieces)
    # trimesh measures the carved mesh on its own
    assert union.volume() == pytest.approx(carved.volume, rel=1e-5)
    # no piece pokes out of the pad, and no two overlap (their volumes add up to their union's)
    assert (union - to_manifold(carved)).volume() <= 1e-6 * carved.volume
    # the fidelity, measured once and read back from its own entry, is the union's against the pad
    assert len(list(tmp_path.glob("*.npz"))) == 1
    excess, missing = volume_errors(made, tmp_path)
    entry = tmp_path / f"{made.key}-volume.npz"
    assert entry.is_file() and len(list(tmp_path.glob("*.npz"))) == 2
    # what a second call returns is the entry on disk, not measured again
    np.savez(entry, volume_errors=np.array([0.5, 0.25]))
    assert volume_errors(read, tmp_path) == (0.5, 0.25)
    volume = to_manifold(carved).volume()
    assert excess == pytest.approx((union - to_manifold(carved)).volume() / volume, abs=1e-9)
    assert missing == pytest.approx((to_manifold(carved) - union).volume() / volume, abs=1e-9)
    total = sum(manifold3d.Manifold.hull_points(np.asarray(v, dtype=float)).volume() for v, _ in read.pieces)
    assert total == pytest.approx(union.volume(), rel=1e-6)
    assert abs(excess - missing) < 1e-5 and missing < 1e-5


def test_no_pad_prism_stands_in_front_of_a_designed_pad():
    """The pad fcso designs for the spur gear lying flat (with its print clearance and lead-in): the pocket swept
    towards -u and subtracted from the pad's box (before issue 22's h26a) left slivers of the box in front of the pad,
    four prisms reaching 1 mm out of it (its seated pieces overlapped the gear's by 0.69 mm).
    """
    pad = trimesh.load(data_path("spur_gear_pad.stl"))
    pieces = pad_prism_pieces(pad, 5.0, None)
    assert min(float(vertices[:, 0].min()) for vertices, _ in pieces.pieces) >= -1e-6
    # the 0.005 mm simplification's few micrometres
    excess, missing = volume_errors(pieces, None)
    assert excess < 2e-5 and missing < 1e-6


def test_no_pad_prism_is_flat_under_a_sliver_of_the_face():
    """A wall 0.01 degrees off the closing axis faces the front by a sliver: the prism under it is under 0.1 um wide,
    which MuJoCo refuses as a flat mesh (a knurled knob's pad had such prisms, 17 nm wide). It is left out; the
    pieces still make up the pad.
    """
    wall_run_mm = 4.0 * np.tan(np.radians(0.01))
    # a step 4 mm deep across the pad, its wall leaning by 0.01 degrees
    step = manifold3d.Manifold.hull_points(
        np.array(
            [[-1.0, 10.0, -1.0], [4.0, 10.0, -1.0], [-1.0, 21.0, -1.0], [4.0, 21.0, -1.0]]
            + [[-1.0, 10.0 - wall_run_mm * 1.25, 21.0], [4.0, 10.0 + 0.0, 21.0]]
            + [[-1.0, 21.0, 21.0], [4.0, 21.0, 21.0]]
        )
    )
    carved = to_trimesh(box((0.0, 0.0, 0.0), (5.0, 20.0, 20.0)) - step)
    pieces = pad_prism_pieces(carved, 5.0, None).pieces
    assert pieces and min(hull_width_mm(v, f) for v, f in pieces) >= MIN_PIECE_WIDTH_MM
    assert _union(pieces).volume() == pytest.approx(carved.volume, rel=1e-3)
    # the width of a box is its least side; of a flat piece, nothing
    cube = to_trimesh(box((0.0, 0.0, 0.0), (3.0, 2.0, 0.5)))
    assert hull_width_mm(np.asarray(cube.vertices), np.asarray(cube.faces)) == pytest.approx(0.5)


def test_every_pad_prism_of_a_slotted_blocks_candidates_is_a_mesh_mujoco_accepts(tmp_path):
    # the development split's slotted block in 35 mm pads: a candidate's pad had a prism 9.6e-7 mm³ small under a
    # sliver of its face (wider than MIN_PIECE_WIDTH_MM), and MuJoCo refused the scene ("mesh volume is too small"),
    # so choosing among the candidates by truth failed
    drawn = draw("slotted-block", 0)
    config = DesignConfig().updated({"sampler": {"length_mm": 35.0}})
    result = design([Part(name=drawn.name, path=drawn.name, mesh=drawn.mesh)], config)
    others = [c for c in ranked_candidates(result.report, 6) if c.index != result.report.best]
    for built in candidate_designs(result, others, jobs=1):
        under_test = built[0]
        pieces = pad_prism_pieces(under_test.fingerpad, config.sampler.thickness_mm, None).pieces
        assert min(manifold3d.Manifold.hull_points(v).volume() for v, _ in pieces) >= MIN_PIECE_VOLUME_MM3
        for case in under_test.cases:
            fitted_pieces(case, under_test, _config(tmp_path))


def test_pad_prisms_leave_out_what_the_part_overhangs(tmp_path):
    """A pad with material in front of a cavity (the part reaches behind it) is its columns: the material in front
    goes, as the design's column heights leave it out, and the volume error says so.
    """
    cavity = box((2.0, -1.0, 8.0), (3.0, 21.0, 12.0))
    carved = to_trimesh(box((0.0, 0.0, 0.0), (5.0, 20.0, 20.0)) - cavity)
    pieces = pad_prism_pieces(carved, 5.0, None)
    # 5 x 20 x 20 less the cavity and the 2 mm in front of it (3 x 20 x 4 mm)
    assert _union(pieces.pieces).volume() == pytest.approx(2000.0 - 240.0, rel=1e-6)
    assert carved.volume == pytest.approx(2000.0 - 80.0)
    assert volume_errors(pieces, None)[1] == pytest.approx(160.0 / 1920.0, rel=1e-4)


def test_part_shell_pieces_are_its_surface_where_the_pads_reach_and_hulls_elsewhere(tmp_path):
    """Where a pad can touch the part its pieces are prisms under its own facets (no concavity bridged, no part of the
    surface left out); elsewhere the part's material by cells is its hull, which never reaches where the pads act.
    """
    cube = featured_cube()
    # the zone of the notch in the face x = 0 (the cube spans 0..30 mm)
    zone = np.array([[[-1.0, -1.0, -1.0], [8.0, 31.0, 31.0]]])
    shell = part_shell_pieces(cube, np.eye(4), zone, 1.0, tmp_path)
    outside = [v for v, _ in shell.pieces if v[:, 0].min() >= 8.0 - 1e-4]
    prisms = [v for v, _ in shell.pieces if v[:, 0].min() < 8.0 - 1e-4]
    assert outside and prisms
    # the notch stays open: no prism stands out of the part (its hull would fill the notch by 8 mm) ...
    assert max(_stands_out_mm(v, cube) for v in prisms) <= 0.01
    # ... and every point of the surface in the zone is on a prism
    surface, _ = trimesh.sample.sample_surface_even(cube, 4000, seed=0)
    in_zone = surface[surface[:, 0] < 8.0]
    union = to_trimesh(_union([(v, None) for v in prisms]))
    import igl

    distance = igl.signed_distance(in_zone, np.asarray(union.vertices), np.asarray(union.faces, dtype=np.int64))[0]
    assert np.abs(distance).max() <= 0.01
    # a shell 1 mm deep: the face x = 0 (cut in two by the notch) is two prisms between x = 0 and x = 1
    assert sum(bool(np.all(np.isclose(v[:, 0], 0.0) | np.isclose(v[:, 0], 1.0))) for v in prisms) == 2
    # outside: hulls, which bridge the far notch and the hole
    assert max(_stands_out_mm(v, cube) for v in outside) > 1.0
    # the shell leaves the material under it out (the zone holds 8/30 of the cube), and reports it
    assert part_shell_pieces(cube, np.eye(4), zone, 1.0, tmp_path).cached
    assert not part_shell_pieces(cube, np.eye(4), zone, 0.5, tmp_path).cached
    assert len(list(tmp_path.glob("*.npz"))) == 2
    assert 0.1 < volume_errors(shell, tmp_path)[1] < 8.0 / 30.0


def test_verification_takes_the_part_density_from_the_print_profile():
    from fcso.config import DesignConfig
    from fcso.sim.config import VerifyConfig, with_print_density

    fdm = DesignConfig().updated({"print": {"profile": "fdm-pla"}})
    # PLA, 1.24-1.25 g/cm³ (the profile's cited sheet), unless [verify] sets a density itself
    assert with_print_density(VerifyConfig(trials=3), fdm).density_g_cm3 == pytest.approx(1.25)
    assert with_print_density(VerifyConfig(trials=3, density_g_cm3=1.1), fdm).density_g_cm3 == pytest.approx(1.1)
    explicit = DesignConfig().updated({"print": {"profile": "fdm-pla", "density_g_cm3": 1.3}})
    assert with_print_density(VerifyConfig(), explicit).density_g_cm3 == pytest.approx(1.3)


#: The zone of the cache tests: the end x <= 8 mm of the part.
_ZONE = np.array([[[-1.0, -1.0, -1.0], [8.0, 31.0, 31.0]]])


def _pieces_in_process(mesh, cache: Path) -> int:
    return len(part_shell_pieces(mesh, np.eye(4), _ZONE, 1.0, cache).pieces)


def test_the_pieces_cache_survives_concurrent_writers_damage_and_a_size_bound(tmp_path):
    mesh, cache = featured_cube(), tmp_path / "cache"
    # two workers write the same entry at once: both get the pieces, one whole entry stays, no temporary file
    with multiprocessing.get_context("fork").Pool(2) as pool:
        counts = pool.starmap(_pieces_in_process, [(mesh, cache), (mesh, cache)])
    assert counts[0] == counts[1] > 1 and [e.suffix for e in cache.iterdir()] == [".npz"]
    first = part_shell_pieces(mesh, np.eye(4), _ZONE, 1.0, cache)
    assert first.cached and len(first.pieces) == counts[0]
    entries = sorted(cache.iterdir())
    # a damaged entry (a disk that filled up, a crash of an older version) is made again, not trusted
    entries[0].write_bytes(entries[0].read_bytes()[:100])
    again = part_shell_pieces(mesh, np.eye(4), _ZONE, 1.0, cache)
    assert not again.cached and len(again.pieces) == len(first.pieces)
    assert part_shell_pieces(mesh, np.eye(4), _ZONE, 1.0, cache).cached
    # beyond its size the least recently used entries go; one just used stays
    other = part_shell_pieces(mesh, np.eye(4), _ZONE, 0.5, cache)
    assert not other.cached and len(list(cache.glob("*.npz"))) == 2
    old = time.time() - 3600
    os.utime(entries[0], (old, old))
    assert part_shell_pieces(mesh, np.eye(4), _ZONE, 0.5, cache).cached
    newer = next(e for e in cache.glob("*.npz") if e != entries[0])
    # a writer killed before its rename left its temporary file: removed once abandoned, not while it may be written
    abandoned, writing = cache / ".abandoned.1.tmp", cache / ".writing.2.tmp"
    abandoned.write_bytes(b"half an entry")
    writing.write_bytes(b"an entry being written")
    os.utime(abandoned, (old - ABANDONED_WRITE_S, old - ABANDONED_WRITE_S))
    evict(cache, newer.stat().st_size)
    assert list(cache.glob("*.npz")) == [newer]
    assert not abandoned.exists() and writing.exists()


def test_grasps_and_holding_on_forked_workers_give_the_results_of_one_process(tmp_path):
    case = _cube_case()
    # friction 0.1: pushed along the pads the cube slips at about 12 N, inside the test's 30 N
    settings = {"lift_mm": 10.0, "friction": 0.1, "hold_ramp_n_s": 300.0}
    scenes = {"flat": build_scene(case, _hull(case.part), None, np.zeros((0, 3)), _config(tmp_path, **settings))}
    errors = np.array([[1.5, -1.0, 2.0], [-2.0, 0.5, -3.0], [0.0, 2.0, 1.0]])
    runs, holding, advanced = {}, {}, []
    for jobs in (1, 2):
        config = _config(tmp_path, jobs=jobs, **settings)
        simulated = scenario_simulations(scenes, case, errors, config, lambda jobs=jobs: advanced.append(jobs))
        assert simulated.stopped_after is None and simulated.reused == 0
        runs[jobs], holding[jobs] = simulated.runs["flat"], simulated.holding
    assert advanced == [1] * 4 + [2] * 4
    for one, forked in zip(runs[1], runs[2]):
        assert one.held == forked.held and np.array_equal(one.part_in_gripper, forked.part_in_gripper)
    assert holding[1] == holding[2]
    # the push along the closing axis is held, the others slip: the holding test ran from the lifted state
    assert holding[2]["flat"]["+y"] is None and holding[2]["flat"]["+x"] > 0.0
    # the nominal grasp keeps its lifted state; only the first trial keeps its frames (the report's picture)
    assert runs[2][0].lifted is not None and [bool(r.frames) for r in runs[2][1:]] == [True, False, False]
    runs[2] = runs[2][1:]
    # the start errors matter: the trials end in different poses
    assert not np.allclose(runs[2][0].part_in_gripper, runs[2][1].part_in_gripper)


def test_unperturbed_grasps_side_by_side_are_those_of_one_process(tmp_path):
    config = _config(tmp_path, jobs=2, lift_mm=10.0)
    cases = [_cube_case(20.0), _cube_case(16.0)]
    scenes = [build_scene(case, _hull(case.part), None, np.zeros((0, 3)), config) for case in cases]

    side_by_side = nominal_grasps(scenes, cases, config, "flat")

    for scene, case, run in zip(scenes, cases, side_by_side):
        alone = nominal_grasp(scene, case, config, "flat")
        assert run.held == alone.held and np.array_equal(run.part_in_gripper, alone.part_in_gripper)
    # two outcomes: the 20 mm cube is lifted (its lifted state kept for the holding test), the 16 mm one dropped
    assert side_by_side[0].held and np.array_equal(
        side_by_side[0].lifted, nominal_grasp(*scenes[:1], cases[0], config, "flat").lifted
    )
    assert not side_by_side[1].held


#: Start errors of the cube between flat pads: along the closing axis (table x) the pads centre it, along the pads
#: (table y) nothing brings it back.
_CENTRED, _OFF_ALONG_PADS = [0.4, 0.0, 0.0], [0.0, 1.5, 0.0]


def test_precision_trials_stop_at_the_deciding_failure_whatever_the_workers(tmp_path):
    case = _cube_case()
    settings = {"lift_mm": 10.0}
    # the flat pads stand in for a designed finger that centres across the pads and not along them
    scene = build_scene(case, _hull(case.part), None, np.zeros((0, 3)), _config(tmp_path, **settings))
    scenes = {"fcso": scene, "flat": scene}
    errors = np.array([_CENTRED, _OFF_ALONG_PADS, [-0.4, 0.0, 0.0], [0.0, -1.5, 0.0], [0.3, 0.0, 1.0]])
    whole = scenario_simulations(scenes, case, errors, _config(tmp_path, stop_early=False, **settings), lambda: None)
    full = whole.trials
    assert whole.stopped_after is None and whole.precision_failed and len(whole.holding["fcso"]) == 6
    assert [t.success for t in full["fcso"]] == [True, False, True, False, True] == [t.success for t in full["flat"]]
    kept = {}
    for jobs in (1, 2):
        config = _config(tmp_path, jobs=jobs, **settings)
        simulated = scenario_simulations(scenes, case, errors, config, lambda: None)
        kept[jobs] = simulated.trials
        # all 5 must succeed: the first failure (trial 2) decides; both fingers keep trials 1 and 2 as the full run,
        # and no holding test: the finger cannot pass
        assert simulated.stopped_after == 2 and [len(r) for r in simulated.runs.values()] == [3, 3]
        assert simulated.holding == {"fcso": {}, "flat": {}}
        assert kept[jobs] == {kind: trials[:2] for kind, trials in full.items()}
    assert kept[1] == kept[2]
    # at 0.6 (3 of 5) two failures are allowed and every trial runs; at 0.7 (4 of 5) the second, trial 4, decides
    for rate, expected in ((0.6, None), (0.7, 4)):
        config = _config(tmp_path, jobs=2, pass_success_rate=rate, **settings)
        simulated = scenario_simulations(scenes, case, errors, config, lambda: None)
        assert simulated.stopped_after == expected and simulated.trials["fcso"] == full["fcso"][: expected or 5]
        # 3 of 5 pass at 0.6: the pushes ran beside the trials, as in the full run
        assert simulated.holding == (whole.holding if expected is None else {"fcso": {}, "flat": {}})


def test_grasps_after_the_deciding_failure_are_not_started(tmp_path, monkeypatch):
    # in one process every grasp ends before the next starts: exactly the kept grasps are simulated, the nominal
    # grasps and trials 1 and 2 of both fingers, and nothing after the deciding failure (trial 2)
    case = _cube_case()
    config = _config(tmp_path, jobs=1, lift_mm=10.0)
    scene = build_scene(case, _hull(case.part), None, np.zeros((0, 3)), config)
    simulated = []
    grasp = schedule_module.run_grasp
    monkeypatch.setattr(
        schedule_module,
        "run_grasp",
        lambda scene, case, pose, *args, **kw: simulated.append(pose) or grasp(scene, case, pose, *args, **kw),
    )
    errors = np.array([_CENTRED, _OFF_ALONG_PADS, [-0.4, 0.0, 0.0], [0.0, -1.5, 0.0]])
    assert scenario_simulations({"fcso": scene, "flat": scene}, case, errors, config, lambda: None).stopped_after == 2
    # both fingers' nominal grasps, then both fingers' trials 1 and 2
    expected = [np.eye(4)] * 2 + [start_pose(case, errors[0])] * 2 + [start_pose(case, errors[1])] * 2
    assert len(simulated) == len(expected) and all(np.allclose(a, b) for a, b in zip(simulated, expected))


def test_a_verification_stopped_early_has_the_verdict_of_the_full_run(tmp_path):
    case = _cube_case()
    settings = {"lift_mm": 10.0, "trials": 4, "hold_ramp_n_s": 300.0}
    part = ConvexPieces(_hull(case.part), case.part, "", False)
    pad = pad_prism_pieces(flat_pad(case.pad_size_mm, case.penetration_mm), case.pad_size_mm[0], tmp_path / "cache")
    results = {
        stop: verify_case(case, part, pad, np.zeros((0, 3)), _config(tmp_path, stop_early=stop, **settings), 0)
        for stop in (False, True)
    }
    full, stopped = results[False], results[True]
    assert not full.passed and not stopped.passed
    first_failure = next(k for k, t in enumerate(full.fcso.trials, 1) if not t.success)
    assert first_failure < 4 and stopped.stopped_after_trials == first_failure and full.stopped_after_trials is None
    assert stopped.fcso.trials == full.fcso.trials[:first_failure]
    assert stopped.flat.trials == full.flat.trials[:first_failure]
    # the holding test ran in full only
    assert len(full.fcso.holding_n) == 6 and full.holds_as_flat is not None
    assert stopped.fcso.holding_n == {} and stopped.holds_as_flat is None
    # the report says so
    report = VerificationReport(
        fcso_version="",
        mujoco_version="",
        settings=_config(tmp_path, **settings),
        scenarios=[stopped],
        passed=False,
        unverified_scenarios=["other pose 1"],
        warnings=[],
        timings_s={},
    )
    page = section_html(report, {"trial 0": b"", "errors 0": b""})
    assert f"<td>{first_failure - 1} of {first_failure} (stopped; 4 planned)</td>" in page
    assert "Holding test not run" in page and '<td class="text">other pose 1</td>' in page


def _outcome_entries(cache: Path, kind: str) -> list[Path]:
    """The cache's entries of grasps (``kind="held"``) or holding pushes (``"force_n"``)."""
    entries = []
    for entry in sorted(cache.glob("*.npz")):
        with np.load(entry) as stored:
            if kind in stored.files:
                entries.append(entry)
    return entries


def test_a_verification_run_again_reads_its_simulations_from_the_cache_and_reports_the_same(tmp_path):
    case = _cube_case()
    # friction 0.1: pushed along the pads the cube slips inside the test's 30 N, so the pushes have forces to compare
    settings = {"lift_mm": 10.0, "trials": 3, "hold_ramp_n_s": 300.0, "friction": 0.1, "stop_early": False}
    part = ConvexPieces(_hull(case.part), case.part, "", False)
    pad = pad_prism_pieces(flat_pad(case.pad_size_mm, case.penetration_mm), case.pad_size_mm[0], tmp_path / "pad")
    nothing = np.zeros((0, 3))

    def run(**values):
        return verify_case(case, part, pad, nothing, _config(tmp_path, **{**settings, **values}), 0)

    first, again = run(reuse_simulations=True), run(reuse_simulations=True)
    simulated = run()
    assert first.reused_simulations == 0 and simulated.reused_simulations == 0
    # 2 fingers x (the nominal grasp + 3 trials), and 6 pushes of each finger that held
    pushes = 6 * (first.fcso.nominal_held + first.flat.nominal_held)
    assert pushes == 12 and again.reused_simulations == 8 + pushes
    report = {"exclude": {"reused_simulations"}}
    assert again.model_dump(**report) == first.model_dump(**report) == simulated.model_dump(**report)
    assert any(force is not None for force in first.flat.holding_n.values())
    # a setting that only judges the trials reuses them all; one that changes the physics simulates them again
    assert run(reuse_simulations=True, success_mm=0.5, pass_success_rate=0.5).reused_simulations == 8 + pushes
    assert run(reuse_simulations=True, friction=0.2).reused_simulations == 0
    # the pushes run again from a nominal grasp read from the cache (its state after the lift) push as before
    cache = tmp_path / "cache"
    for entry in _outcome_entries(cache, "force_n"):
        entry.unlink()
    from_cached_grasps = run(reuse_simulations=True)
    assert from_cached_grasps.reused_simulations == 8
    assert from_cached_grasps.model_dump(**report) == first.model_dump(**report)
    # damaged entries are simulated again and written over
    for entry in _outcome_entries(cache, "held"):
        entry.write_bytes(b"not a cache entry")
    assert run(reuse_simulations=True).reused_simulations == pushes
    assert run(reuse_simulations=True).reused_simulations == 8 + pushes


def test_a_design_delivered_with_flat_pads_is_simulated_as_the_flat_control(tmp_path):
    # a plain cube whose faces are longer than the longest default pad (35 mm), so no pad wraps its edges: nothing
    # beats flat, so flat pads are delivered; the designed finger's trials are the control's
    result = design(
        [Part(name="plain cube", path="plain cube", mesh=trimesh.creation.box(extents=(36.0, 36.0, 36.0)))],
        DesignConfig().updated({"poses": {"count": 1}}),
    )
    assert result.report.finger.flat_pads
    under_test = design_under_test(result)
    case = under_test.cases[0]
    assert is_flat_control(under_test.fingerpad, case.pad_size_mm, case.penetration_mm)
    report = verify(under_test, _config(tmp_path, trials=3, stop_early=False))
    scenario = report.scenarios[0]
    assert [t.model_dump() for t in scenario.fcso.trials] == [t.model_dump() for t in scenario.flat.trials]
    assert scenario.fcso.holding_n == scenario.flat.holding_n
    # a carved pad is not the control
    carved = trimesh.creation.box(bounds=[[case.penetration_mm, 0.0, 0.0], [case.pad_size_mm[0], 20.0, 20.0]])
    carved = carved.difference(trimesh.creation.box(bounds=[[3.0, 5.0, 5.0], [4.5, 10.0, 10.0]]))
    assert not is_flat_control(carved, case.pad_size_mm, case.penetration_mm)


def test_a_scenario_out_of_mujocos_arena_is_simulated_again_with_a_larger_one_or_fails_with_the_reason(tmp_path):
    case = _cube_case()
    under_test = DesignUnderTest([case], flat_pad(case.pad_size_mm, case.penetration_mm), np.zeros((0, 3)))
    settings = {"lift_mm": 10.0, "trials": 2, "hold_ramp_n_s": 300.0}
    sized = verify(under_test, _config(tmp_path, **settings))
    assert sized.scenarios[0].failure_reason is None and sized.scenarios[0].fcso.trials
    # 30 kB is too little for the cube's contacts (MuJoCo's FatalError "mj_stackAlloc: out of memory"), 120 kB is
    # enough: the scenario is simulated again and ends as it does with the arena sized from its pieces
    retried = verify(under_test, _config(tmp_path, arena_mb=0.03, **settings))
    pieces_cached = {"fidelity": {"decomposition_cached"}}
    assert retried.scenarios[0].model_dump(exclude=pieces_cached) == sized.scenarios[0].model_dump(
        exclude=pieces_cached
    )
    assert retried.warnings == sized.warnings
    # without a retry, or when the larger arena runs out too (20 kB, then 80 kB), the scenario fails with the reason
    # (run in full: choosing, a grasp short of its arena that drops the part rejects the design before its trials)
    for arena in ({"arena_mb": 0.03, "arena_retry_factor": 1.0}, {"arena_mb": 0.02}):
        report = verify(under_test, _config(tmp_path, stop_early=False, **arena, **settings))
        scenario = report.scenarios[0]
        assert not report.passed and not scenario.passed and scenario.fcso.trials == scenario.flat.trials == []
        assert scenario.failure_reason.startswith("MuJoCo ran out of its memory arena (")
        assert "out of memory" in scenario.failure_reason and "raise [verify] arena_mb" in scenario.failure_reason
        assert report.warnings == [f"cube: not simulated: {scenario.failure_reason}"]
    assert "0.02 MiB then 0.08 MiB" in scenario.failure_reason
