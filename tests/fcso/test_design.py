"""The whole pipeline on fixture meshes: report consistency, determinism, finger and grasps."""

import importlib
import json

import numpy as np
import pytest
import trimesh

import fcso
from examples.sim_parts import featured_cube, plain_box, two_ridge_block, upright_grasp_settings, zigzag_l_part
from fcso.config import DesignConfig
from fcso.errors import UnwritableSolidError
from fcso.finger import parametric_finger
from fcso.grasps import tcp_pose
from fcso.output.files import write_outputs
from fcso.parts import Part
from fcso.pipeline import choose_candidate, choose_candidates, finish_candidate, finish_candidates, prepare, subset
from fcso.sampler import GraspSample
from tests.conftest import data_path, small_config

#: The module that fuses the chosen candidates' fingers (fcso.pipeline's ``design`` is the function).
design_module = importlib.import_module("fcso.pipeline.finish")
TWO_PARTS = ("20mm-xyz-cube.stl", "solar_tracker.stl")


def two_part_config() -> DesignConfig:
    """The paper sampler, measure and exact pocket (METHOD §4): every candidate is listed, Q = min E, the pad keeps
    T - D and the grasps seat as the candidates were scored (the capture measure: below)."""
    return small_config(
        sampler={"stride_mm": 6.0, "feature_positions": False, "face_yaws": False},
        quality={"measure": "paper"},
        print={"profile": "custom"},
    )


@pytest.fixture(scope="module")
def two_part_design():
    return fcso.design([data_path(name) for name in TWO_PARTS], two_part_config())


def test_the_capture_measure_ranks_candidates_and_chooses_the_design():
    mesh = featured_cube(notch_mm=8.0)
    config = fcso.DesignConfig().updated(upright_grasp_settings(mesh)).updated({"sampler": {"length_mm": 20.0}})
    report = fcso.design([Part(name="cube", path="featured_cube", mesh=mesh)], config).report
    hold = config.verify.hold_force_n
    pad_area = config.sampler.length_mm * config.sampler.width_mm
    for candidate in report.candidates:
        for quality in candidate.per_scenario:
            assert 0.0 <= quality.capture <= 1.0
            if candidate.evaluation == "exact":
                assert len(quality.holding_n) == 6 and all(0.0 <= f <= hold for f in quality.holding_n)
                factor = quality.capture * min(1.0, min(quality.holding_n) / hold)
            else:
                assert quality.holding_n is None
                factor = quality.capture
            # capture x holding in bands of 1/20, E / (E + L W) within a band (METHOD §7b, docs/implementation.md)
            within = quality.effective_area / (quality.effective_area + pad_area)
            expected = (np.floor(20 * factor + 1e-9) + within) / 20
            assert quality.measure == pytest.approx(expected, rel=1e-4, abs=1e-4)
        assert candidate.quality == pytest.approx(min(q.measure for q in candidate.per_scenario), abs=1e-6)
    exact = [c for c in report.candidates if c.evaluation == "exact"]
    chosen = next(c for c in exact if c.index == report.best)
    # the best exact measure (the report rounds to 1e-6: ties there are broken by unrounded values)
    assert chosen.quality >= max(c.quality for c in exact) - 1e-6
    # the 8 mm notch is centred on: a pad there captures most start errors, flat pads few
    (scenario,) = report.scenarios
    assert scenario.capture >= 0.8 and scenario.flat_capture <= 0.2 and scenario.beats_flat
    assert any(sample.on_feature for sample in scenario.samples)


def test_a_featureless_plate_gets_flat_pads_not_a_carving(tmp_path):
    # a plate's faces cage nothing: any pocket captures no more start errors than flat pads, so none is printed
    length, width, thickness, depth = 10.0, 10.0, 5.0, 4.0
    config = fcso.DesignConfig().updated(
        {
            "poses": {"count": 1},
            "sampler": {"length_mm": length, "width_mm": width, "thickness_mm": thickness, "penetration_mm": depth},
        }
    )
    result = fcso.design([Part(name="plate", path="plate", mesh=plain_box(40.0, 30.0, 6.0))], config)
    (scenario,) = result.report.scenarios
    assert not scenario.beats_flat and scenario.capture == scenario.flat_capture
    assert result.report.finger.flat_pads
    assert any("delivered with flat pads" in w for w in result.report.warnings)
    write_outputs(result, tmp_path)
    pad = trimesh.load_mesh(tmp_path / "fingerpad.stl")
    # the flat pad [D, T] x [0, L] x [0, W] of METHOD §5: a box of L W (T - D)
    assert pad.is_watertight and len(pad.faces) == 12
    assert pad.volume == pytest.approx(length * width * (thickness - depth), rel=1e-6)
    np.testing.assert_allclose(pad.bounds, [[depth, 0.0, 0.0], [thickness, length, width]], atol=1e-5)
    finger = trimesh.load_mesh(tmp_path / "finger.stl")
    assert finger.is_watertight and len(finger.split(only_watertight=False)) == 1
    # the notched cube keeps its carving
    mesh = featured_cube(notch_mm=8.0)
    carved = fcso.design(
        [Part(name="cube", path="cube", mesh=mesh)], fcso.DesignConfig().updated(upright_grasp_settings(mesh))
    )
    assert not carved.report.finger.flat_pads and carved.best.case != "bad"
    # its grasp on flat pads captures what the report says flat pads capture, not what its carving does
    flat, _, _, _ = finish_candidate(carved.scenarios, carved.best.choice, carved.report.settings, flat=True)
    assert flat.case == "bad"
    assert flat.scenarios[0].capture.fraction == pytest.approx(carved.report.scenarios[0].flat_capture, abs=1e-6)
    assert flat.scenarios[0].capture.fraction < carved.report.scenarios[0].capture


def test_a_v_notched_edge_is_found_by_the_default_sampler():
    # an L plate whose only cageable feature is two 2 mm V-notches in the outer edge of its long arm, at x in
    # [26, 34] of y = 0 (by construction): a 20 mm pad over them sees mostly straight edge, METHOD §5 labels that
    # bad and the design stays flat; the default pad sizes hold one short enough to carve the notches
    mesh = zigzag_l_part(teeth=2, tooth_mm=2.0)
    result = fcso.design([Part(name="zigzag", path="zigzag", mesh=mesh)], fcso.DesignConfig())
    report = result.report
    assert not report.finger.flat_pads
    length = report.settings.sampler.length_mm
    for grasp in report.grasps:
        to_part = np.linalg.inv(np.asarray(grasp.rest_transform))
        centre = to_part[:3, :3] @ grasp.position_mm + to_part[:3, 3]
        closing = to_part[:3, :3] @ grasp.closing_axis
        # closing across the long arm, the pad's footprint along x holds both notches
        assert abs(closing[1]) == pytest.approx(1.0, abs=1e-6)
        assert abs(centre[0] - 30.0) + 4.0 <= length / 2.0 + 1e-6


def notched_d_disc(notch_axis_deg: float = 60.0) -> trimesh.Trimesh:
    """A 10 mm thick disc (radius 15 mm) lying flat, cut flat at x = 11 mm, with a 4 mm deep 90-degree V-notch on each
    side along ``notch_axis_deg`` from x."""
    import manifold3d

    disc = manifold3d.Manifold.cylinder(10.0, 15.0, circular_segments=96)
    disc = disc - manifold3d.Manifold.cube([10.0, 40.0, 12.0]).translate([11.0, -20.0, -1.0])
    wedge = [[0.0, 0.0], [5.0, -5.0], [5.0, 5.0]]
    notch = manifold3d.Manifold.extrude(manifold3d.CrossSection([wedge]), 12.0).translate([11.0, 0.0, -1.0])
    for angle in (notch_axis_deg, notch_axis_deg + 180.0):
        disc = disc - notch.rotate([0.0, 0.0, angle])
    mesh = disc.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3]), np.asarray(mesh.tri_verts))


def test_pads_close_into_notches_that_lie_off_the_bounding_box_axes():
    # a disc whose flat sets its bounding box's axes (0 and 90 degrees) and whose only cageable features, two
    # V-notches, lie on an axis at 60 degrees (by construction): closing along the box's axes or square to a notch's
    # flank (15 or 105 degrees), the pads meet the round rim beside the notches; square to the convex hull's faces
    # over the notches they enter both
    mesh = notched_d_disc(60.0)
    result = fcso.design(
        [Part(name="disc", path="disc", mesh=mesh)], fcso.DesignConfig().updated({"poses": {"count": 1}})
    )
    report = result.report
    assert not report.finger.flat_pads
    (grasp,) = report.grasps
    closing = np.linalg.inv(np.asarray(grasp.rest_transform))[:3, :3] @ grasp.closing_axis
    notch_axis = [np.cos(np.radians(60.0)), np.sin(np.radians(60.0)), 0.0]
    assert abs(np.dot(closing, notch_axis)) == pytest.approx(1.0, abs=1e-3)


def test_counts_qualities_and_best_are_consistent(two_part_design):
    report = two_part_design.report
    assert [s.part for s in report.scenarios] == ["20mm-xyz-cube", "solar_tracker"]
    counts = [s.valid_samples for s in report.scenarios]
    assert all(s.valid_samples == len(s.samples) for s in report.scenarios)
    assert report.search.candidates_total == int(np.prod(counts)) == len(report.candidates)
    assert report.search.kind == "exhaustive" and report.search.evaluated == len(report.candidates)
    assert [c.index for c in report.candidates] == list(range(len(report.candidates)))
    for candidate in report.candidates:
        assert len(candidate.samples) == len(candidate.per_scenario) == len(report.scenarios)
        assert candidate.index == candidate.samples[0] * counts[1] + candidate.samples[1]
        for quality in candidate.per_scenario:
            assert 0.0 < quality.rles <= 2.0
            assert quality.effective_area == pytest.approx(quality.contact_area_mm2 / quality.rles, rel=1e-5, abs=1e-5)
        assert candidate.quality == min(q.effective_area for q in candidate.per_scenario)
    # the design is the best exactly re-evaluated candidate (METHOD §8b)
    exact = [c for c in report.candidates if c.evaluation == "exact"]
    assert len(exact) == report.search.exact == report.settings.search.exact_top_k
    best = max(exact, key=lambda c: (c.quality, c.mean_effective_area, -c.index))
    assert report.best == best.index
    assert {c.pad_case for c in report.candidates} == {"good", "bad", "mixed"}
    for scenario in report.scenarios:
        assert set(scenario.rejected) == {"contact", "fit", "collision_pads", "collision_finger", "collision_descent"}
        assert scenario.tried_samples == scenario.valid_samples + sum(scenario.rejected.values())
    assert set(report.timings_s) >= {"poses", "sampling", "pad_geometries", "screening", "exact", "finger"}
    assert report.settings.sampler.length_mm == 10.0
    assert all(s.capture is None and s.beats_flat for s in report.scenarios)


def test_finger_is_one_watertight_body_with_the_pad(two_part_design):
    finger = two_part_design.finger
    assert finger.is_watertight and finger.volume > 0
    assert len(finger.split(only_watertight=False)) == 1
    flat = parametric_finger(two_part_design.report.settings.sampler, two_part_design.report.settings.gripper).mesh
    assert finger.volume > flat.volume
    assert two_part_design.report.finger.bodies == 1
    sampler = two_part_design.report.settings.sampler
    assert two_part_design.report.finger.min_pad_thickness_mm >= sampler.thickness_mm - sampler.penetration_mm - 0.05


def test_grasps_follow_the_chosen_samples(two_part_design):
    report = two_part_design.report
    best = next(c for c in report.candidates if c.index == report.best)
    thickness, depth = report.settings.sampler.thickness_mm, report.settings.sampler.penetration_mm
    assert len(report.grasps) == len(report.scenarios)
    for grasp, scenario, sample_index, quality in zip(report.grasps, report.scenarios, best.samples, best.per_scenario):
        sample = scenario.samples[sample_index]
        assert grasp.sample == sample_index and grasp.pose_index == scenario.pose_index
        gap = sample.a_max_mm - sample.a_min_mm - 2 * depth + sum(quality.seat_offsets_mm)
        assert grasp.pad_gap_mm == pytest.approx(gap, abs=1e-5)
        assert grasp.closing_width_mm == pytest.approx(gap + 2 * thickness, abs=1e-5)
        rotation = trimesh.transformations.quaternion_matrix(grasp.quaternion_wxyz)[:3, :3]
        assert rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-6)
        assert rotation[:, 1] == pytest.approx(grasp.closing_axis, abs=1e-6)
        assert grasp.position_mm[2] == pytest.approx(sample.h_mm + report.settings.sampler.width_mm / 2, abs=1e-5)


def test_tcp_pose_on_a_known_sample():
    sampler = DesignConfig().sampler
    sample = GraspSample(
        yaw_deg=90.0, s_mm=3.0, h_mm=6.0, a_max_mm=15.0, a_min_mm=-13.0, area_plus_mm2=1.0, area_minus_mm2=1.0
    )
    pose = tcp_pose(sample, 0.5, 0.25, sampler)
    # a = +y, b = z x a = -x; centre along a: (15 - 13) / 2 + (0.5 - 0.25) / 2
    assert pose["position_mm"] == pytest.approx([-3.0, 1.125, 16.0])
    assert pose["pad_gap_mm"] == pytest.approx(28.0 - 8.0 + 0.75)
    assert pose["closing_width_mm"] == pytest.approx(28.0 - 8.0 + 0.75 + 10.0)
    rotation = trimesh.transformations.quaternion_matrix(pose["quaternion_wxyz"])[:3, :3]
    assert rotation @ [0, 1, 0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)
    assert rotation @ [0, 0, 1] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)


def test_same_inputs_and_seed_give_identical_reports(two_part_design):
    again = fcso.design([data_path(name) for name in TWO_PARTS], two_part_config()).report
    first = json.loads(two_part_design.report.model_dump_json())
    second = json.loads(again.model_dump_json())
    first.pop("timings_s"), second.pop("timings_s")
    assert first == second


def test_user_finger_mesh_with_its_frame(tmp_path):
    config = small_config(sampler={"stride_mm": 8.0})
    built_in = fcso.design([data_path("20mm-xyz-cube.stl")], config)
    # the same flat finger as a user's file, turned so its frame is not the identity
    flat = parametric_finger(config.sampler, config.gripper).mesh.copy()
    turn = trimesh.transformations.rotation_matrix(np.radians(90.0), [0, 0, 1])
    flat.apply_transform(turn)
    path = tmp_path / "flat_finger.stl"
    flat.export(path)
    origin = trimesh.transform_points([[0.0, 0.0, config.sampler.width_mm / 2]], turn)[0]
    normal = turn[:3, :3] @ [-1.0, 0.0, 0.0]
    user = config.updated(
        {
            "finger": {
                "mesh": path,
                "contact_origin_mm": origin.tolist(),
                "contact_normal": normal.tolist(),
                "up": [0, 0, 1],
            }
        }
    )
    result = fcso.design([data_path("20mm-xyz-cube.stl")], user)
    assert result.report.finger.source == str(path)
    assert result.finger.is_watertight and len(result.finger.split(only_watertight=False)) == 1
    assert result.finger.volume == pytest.approx(built_in.finger.volume, rel=1e-4)


def test_part_too_wide_for_the_gripper_has_no_grasp():
    with pytest.raises(fcso.NoGraspError, match="capsela200_plug.stl: no valid grasp"):
        fcso.design([data_path("capsela200_plug.stl")], small_config(poses={"select": [0]}))


def test_ungraspable_part_is_listed_and_the_rest_designed():
    # the plug is too wide for the gripper in its first pose; the cube is not
    config = small_config(poses={"select": [0]})
    report = fcso.design([data_path("20mm-xyz-cube.stl"), data_path("capsela200_plug.stl")], config).report
    assert [s.part for s in report.scenarios] == ["20mm-xyz-cube"]
    assert [g.part for g in report.grasps] == ["20mm-xyz-cube"]
    assert len(report.ungraspable) == 1
    entry = report.ungraspable[0]
    assert (entry.part, entry.pose_index) == ("capsela200_plug", 0)
    assert entry.rejected["fit"] > 0 and entry.tried_samples == sum(entry.rejected.values())
    assert "too wide for the open gripper" in entry.reason
    assert any("capsela200_plug in stable pose 0 cannot be grasped" in w for w in report.warnings)


def test_separate_solids_of_one_file_are_designed_as_separate_parts():
    config = small_config(sampler={"stride_mm": 8.0}, search={"max_exhaustive": 1, "max_evaluations": 8})
    report = fcso.design([data_path("DC-DC_case.stl")], config).report
    assert [p.name for p in report.parts] == ["DC-DC_case#1", "DC-DC_case#2"]
    assert [p.solid_index for p in report.parts] == [1, 2]
    assert all(p.shell_handling.startswith(f"solid {k} of 2") for k, p in zip((1, 2), report.parts))
    assert [s.part for s in report.scenarios] == ["DC-DC_case#1", "DC-DC_case#2"]
    assert any("holds 2 separate solids" in w for w in report.warnings)
    refused = config.updated({"parts": {"split_bodies": False}})
    with pytest.raises(fcso.MeshError, match="DC-DC_case.stl: holds 2 separate solids"):
        fcso.design([data_path("DC-DC_case.stl")], refused)


def test_designs_side_by_side_choose_as_one_at_a_time():
    """choose_candidates runs each design whole on one worker and starts the designs ``then`` asks for: every choice is
    the one choose_candidate makes alone, over every worker."""
    config = small_config(search={"jobs": 2})
    prepared = prepare([data_path(name) for name in (*TWO_PARTS, "box.STL")], config)
    subsets = [[0], [1, 2], [2]]
    asked = []

    def then(numbers, chosen):
        # the whole batch, once, after the first design to finish
        asked.append(list(numbers))
        return [list(range(len(prepared.scenarios)))] if len(asked) == 1 else []

    side_by_side = choose_candidates(prepared, subsets, config, then)
    assert len(asked) == len(subsets) + 1
    for numbers, made in zip([*subsets, list(range(len(prepared.scenarios)))], side_by_side):
        alone = choose_candidate(subset(prepared, numbers), config)
        assert made.choice == alone.choice
        assert made.candidate == alone.candidate
        assert made.ranked == alone.ranked
        assert {c: e.quality for c, e in made.exact.items()} == {c: e.quality for c, e in alone.exact.items()}


def test_a_finish_given_the_exact_evaluation_reports_as_one_that_evaluates_again():
    """finish_candidates takes a design's exact evaluation of its choice instead of making it again: the same
    print-fit report (exact figures and pad measured)."""
    config = small_config()
    prepared = prepare([data_path(name) for name in TWO_PARTS], config)
    chosen = choose_candidate(prepared, config)
    candidates = [(prepared.scenarios, chosen.choice)]
    given = finish_candidates(candidates, config, exact=[chosen.exact[chosen.choice]])[0]
    again = finish_candidates(candidates, config)[0]
    assert given[2].exact.quality > 0
    assert given[1:] == again[1:]


def _exact_ranking(report) -> list[int]:
    """The report's exactly evaluated candidates, best first (quality, then mean effective area, then index)."""
    exact = [c for c in report.candidates if c.evaluation == "exact"]
    return [c.index for c in sorted(exact, key=lambda c: (-c.quality, -c.mean_effective_area, c.index))]


def test_a_candidate_whose_finger_is_not_one_body_as_written_gives_way_to_the_next(monkeypatch):
    # no real part is known whose fused finger is still refused as written (the two-ridge block's was, until its
    # pinches were kept apart): the written check is made to refuse the chosen candidate's finger, recognised by its
    # pad (a pad of the same volume, another candidate's, would be refused too)
    part = Part(name="two-ridge block", path="two-ridge block", mesh=two_ridge_block())
    config = fcso.DesignConfig().updated({"poses": {"count": 1}})
    first = fcso.design([part], config)
    ranking = _exact_ranking(first.report)
    assert ranking[0] == first.report.best and len(ranking) > 1
    refused_pad_mm3 = first.best.fingerpad.pad.volume()
    refuse_every_pad = [False]
    real_fuse = design_module.fuse
    fused_pads = []

    def fuse(finger, pad, sampler, overlap_mm):
        fused_pads.append(pad.volume())
        if refuse_every_pad[0] or abs(pad.volume() - refused_pad_mm3) <= 1e-9 * refused_pad_mm3:
            raise UnwritableSolidError("built-in: fused finger is not one watertight body as written to STL: 2 bodies")
        return real_fuse(finger, pad, sampler, overlap_mm)

    monkeypatch.setattr(design_module, "fuse", fuse)
    second = fcso.design([part], config)
    assert second.report.best == ranking[1] and second.report.finger.watertight and second.finger.is_watertight
    assert second.report.candidates == first.report.candidates
    assert (
        f"candidate {ranking[0]} is not delivered: built-in: fused finger is not one watertight body as written to "
        f"STL: 2 bodies; candidate {ranking[1]}, the next by its exact figures, is tried instead"
    ) in second.report.warnings
    # when no candidate's finger can be written, the design fails after the chosen one and WRITTEN_FALLBACKS more
    fused_pads.clear()
    refuse_every_pad[0] = True
    with pytest.raises(UnwritableSolidError, match="not one watertight body as written"):
        fcso.design([part], config)
    assert len(fused_pads) == 1 + min(design_module.WRITTEN_FALLBACKS, len(ranking) - 1)
