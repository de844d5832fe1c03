"""Capture and holding (METHOD §7b) on parts whose answer is known by construction."""

from __future__ import annotations

import subprocess
import sys

import manifold3d
import numpy as np
import pytest
import trimesh

import fcso
from examples.sim_parts import (
    featured_cube,
    hex_prism,
    holed_notched_cube,
    plain_box,
    plain_cylinder,
    ribbed_block,
    two_ridge_block,
    upright_grasp_settings,
)
from fcso.capture import CandidateSqueeze, pad_landscapes, sliding_error_weights, squeeze, squeezed_part
from fcso.evaluate import printed_lead_in_deg, screen_on_pad
from fcso.grid import ScreenGrid
from fcso.holding import holding_forces_n
from fcso.measure import capture_measure, scenario_measure
from fcso.parts import Part
from fcso.pipeline import finish_candidate, prepare
from fcso.printed_heights import carved_heights, fitted_pad_heights
from fcso.screen import pad_case


def _prepared(mesh, name: str, **sections):
    config = (
        fcso.DesignConfig()
        .updated(upright_grasp_settings(mesh))
        .updated({"sampler": {"length_mm": 20.0, "stride_mm": 2.0}, **sections})
    )
    return prepare([Part(name=name, path=name, mesh=mesh)], config), config


def _sample_at(prepared, s_mm: float, h_mm: float):
    """The valid sample whose footprint centre and bottom are nearest to (s, h)."""
    samples = prepared.scenarios[0].samples
    return min(samples, key=lambda g: abs(g.sample.s_mm - s_mm) + abs(g.sample.h_mm - h_mm))


def _landscape(prepared, config, sample, flat: bool = False):
    return pad_landscapes(
        [sample.screen],
        [sample.centres_uv_mm],
        [sample.width_mm],
        [sample.sample.sliding_axis],
        ScreenGrid.for_config(config),
        config,
        flat=flat,
    )[0]


def _captured_at(landscape, offset_mm: float, yaw_deg: float = 0.0) -> bool:
    row = int(np.argmin(np.abs(landscape.offsets_mm - offset_mm)))
    column = int(np.argmin(np.abs(landscape.yaws_deg - yaw_deg)))
    return bool(landscape.captured[row, column])


def test_a_v_notch_captures_two_millimetres_and_flat_pads_capture_nothing():
    # 90-degree walls (slope 1 > friction 0.4), 8 mm deep: every start within +-2 mm slides into the notch
    prepared, config = _prepared(featured_cube(notch_mm=8.0), "cube")
    centred = _sample_at(prepared, 0.0, 5.0)
    assert centred.sample.on_feature or abs(centred.sample.s_mm) < 1e-6
    carved = _landscape(prepared, config, centred)
    assert all(_captured_at(carved, t) for t in (-2.0, -1.0, 1.0, 2.0))
    assert carved.fraction >= 0.9
    # flat pads: nothing moves the part along the pads, only starts already within 0.3 mm succeed
    flat = _landscape(prepared, config, centred, flat=True)
    assert not any(_captured_at(flat, t) for t in (-2.0, -1.0, -0.6, 0.6, 1.0, 2.0))
    assert flat.fraction <= (2 * 0.3 + 0.2) / 4.0


def test_flat_pads_turn_a_wide_part_into_line_but_do_not_centre_it():
    # 10 mm pads on a box 30 mm across the jaws: a turn θ raises the separation by about 2 x 5 mm x θ over
    # an arc of 15 mm x θ on two jaws, a slope of 0.33, below friction 0.4; yet squeezing between parallel jaws turns a
    # box into line (Goldberg's squeeze): the part pivots on a pad's edge instead of sliding along it
    prepared, config = _prepared(
        plain_box(30.0, 40.0, 20.0), "box", sampler={"length_mm": 10.0, "width_mm": 10.0, "stride_mm": 2.0}
    )
    flat = _landscape(prepared, config, _sample_at(prepared, 0.0, 5.0), flat=True)
    assert all(_captured_at(flat, 0.0, yaw) for yaw in (-3.0, -2.0, 2.0, 3.0))
    assert not any(_captured_at(flat, t, yaw) for t in (-2.0, -1.0, 1.0, 2.0) for yaw in (-3.0, 0.0, 3.0))


def test_a_round_boss_in_its_round_pocket_captures_no_rotation():
    # a cylinder turned about its own axis is the same cylinder: no pad shape can turn it back, so only the starts
    # already within the success test's 1 degree succeed, whatever the offset (METHOD §7c). The box of +-3 degrees
    # on 0.5-degree steps holds 13 yaws, 5 of them within 1 degree.
    prepared, config = _prepared(plain_cylinder(15.0, 30.0), "cylinder")
    carved = _landscape(prepared, config, _sample_at(prepared, 0.0, 5.0))
    assert not any(_captured_at(carved, t, yaw) for t in (-1.0, 0.0, 1.0) for yaw in (-3.0, -2.0, -1.5, 1.5, 2.0, 3.0))
    assert all(_captured_at(carved, t, yaw) for t in (-1.0, 0.0, 1.0) for yaw in (-0.5, 0.0, 0.5))
    assert carved.fraction <= 5 / 13 + 1e-9


def test_a_hex_prism_in_its_pocket_is_turned_back_into_its_seat():
    # the pocket of a hexagon's two opposite sides: a turned hexagon presses a corner into a wall, so closing turns
    # it back (the counterpart of the round boss above). Carved c deeper (METHOD §9c) the pocket fits the hexagon
    # without play; drafted by 15 degrees, a corner turned by 2 degrees meets the steep drafted wall where the turn
    # back and a shift along the pad must go together, finer than the grid's 0.2 mm shifts follow, and the design
    # prints the pad with the wider draft that captures every start (designed with these settings, the hexagon gets
    # a 30-degree pocket that the simulation seats 10/10, within 0.01 degrees)
    prepared, config = _prepared(hex_prism(24.0, 20.0), "hex")
    sample = _sample_at(prepared, 0.0, 5.0)
    angle, _ = printed_lead_in_deg(prepared.scenarios, [prepared.scenarios[0].samples.index(sample)], config)
    carved = _landscape(prepared, config.updated({"print": {"lead_in_deg": angle}}), sample)
    assert angle > 15.0
    assert all(_captured_at(carved, 0.0, yaw) for yaw in (-3.0, -2.0, 2.0, 3.0))


def test_pads_that_meet_each_other_before_they_squeeze_the_part_capture_nothing():
    # a T-slot nut's neck, 8.6 mm across: pads reaching D = 4 mm into it from both sides leave their uncarved rims
    # above the neck 0.6 mm apart; printed with MJF's 0.4 mm clearance each pad must close 0.4 mm before it touches
    # the neck, so the rims meet 0.2 mm before the part is squeezed (METHOD §5b). The exact pocket still holds.
    flange = manifold3d.Manifold.cube([20.0, 30.0, 4.0])
    neck = manifold3d.Manifold.cube([8.6, 30.0, 12.0]).translate([5.7, 0.0, 3.9])
    solid = (flange + neck).to_mesh()
    mesh = trimesh.Trimesh(np.asarray(solid.vert_properties[:, :3]), np.asarray(solid.tri_verts))
    for profile, holds in (("mjf-pa12", False), ("custom", True)):
        prepared, config = _prepared(mesh, "nut", print={"profile": profile})
        over_the_neck = _sample_at(prepared, 0.0, 13.0)
        assert over_the_neck.width_mm == pytest.approx(8.6, abs=0.01)
        landscape = _landscape(prepared, config, over_the_neck)
        expected_gap = 8.6 - 2 * 4.0 - (0.8 if profile == "mjf-pa12" else 0.0)
        assert landscape.pads_gap_mm == pytest.approx(expected_gap, abs=0.05)
        assert (landscape.fraction > 0) == holds


def test_the_capture_measure_ranks_by_capture_bands_then_by_e():
    # capture x holding share in bands of 1/20, E / (E + L W) within a band
    assert capture_measure(1.0, 1.0, 10.0, 100.0) == pytest.approx((20 + 10 / 110) / 20)
    assert capture_measure(0.9, 1.0, 1000.0, 100.0) == pytest.approx((18 + 1000 / 1100) / 20)
    assert capture_measure(1.0, 1.0, 10.0, 100.0) > capture_measure(0.9, 1.0, 1000.0, 100.0)
    # 0.52 and 0.53 share a band: the larger E wins
    assert capture_measure(0.52, 1.0, 50.0, 100.0) > capture_measure(0.53, 1.0, 20.0, 100.0)
    # holding half the test's force halves the band
    assert capture_measure(1.0, 0.5, 10.0, 100.0) == pytest.approx((10 + 10 / 110) / 20)
    paper = fcso.DesignConfig().updated({"quality": {"measure": "paper"}})
    assert scenario_measure(0.1, 0.1, 179.4, paper) == 179.4


def test_a_pocket_without_lead_in_jams_where_the_same_pocket_with_one_does_not():
    exact, config_exact = _prepared(ribbed_block(), "ribbed", print={"profile": "custom"})
    drafted, config_drafted = _prepared(ribbed_block(), "ribbed", print={"profile": "custom", "lead_in_deg": 30.0})
    # the rib's centre: the pad's pocket holds the whole rib
    jammed = _landscape(exact, config_exact, _sample_at(exact, 0.0, 5.0))
    guided = _landscape(drafted, config_drafted, _sample_at(drafted, 0.0, 5.0))
    assert not _captured_at(jammed, 1.0) and not _captured_at(jammed, -1.0)
    assert _captured_at(guided, 1.0) and _captured_at(guided, -1.0)
    assert guided.fraction > jammed.fraction + 0.3


def test_a_wider_lead_in_is_printed_where_the_default_draft_cannot_reach_the_start_errors():
    # the rib's pocket, carved c deeper (METHOD §9c), opens by (D + c) tan 15 = 1.18 mm per side at the pad face
    # with a 15 degree draft, short of the test's 2 mm start errors; 30 degrees opens it by 2.54 mm
    prepared, config = _prepared(ribbed_block(), "ribbed")
    scenarios, rib = prepared.scenarios, _sample_at(prepared, 0.0, 5.0)
    choice = [scenarios[0].samples.index(rib)]
    assert not _captured_at(_landscape(prepared, config, rib), 2.0)
    angle, why = printed_lead_in_deg(scenarios, choice, config)
    assert angle == 30.0 and "30° instead of 15°" in why
    drafted = config.updated({"print": {"lead_in_deg": angle}})
    assert _captured_at(_landscape(prepared, drafted, rib), 2.0) and _captured_at(
        _landscape(prepared, drafted, rib), -2.0
    )
    # the candidate is built and reported with it
    _, _, print_fit, warnings = finish_candidate(scenarios, choice, config)
    assert print_fit.lead_in_deg == 30.0 and any("30° instead of 15°" in w for w in warnings)
    # only the listed drafts, and never a draft where the profile has none (the paper's exact pocket)
    assert (
        printed_lead_in_deg(scenarios, choice, config.updated({"print": {"lead_in_alternatives_deg": [30.0]}}))[0]
        == 30.0
    )
    assert printed_lead_in_deg(scenarios, choice, config.updated({"print": {"lead_in_alternatives_deg": []}})) == (
        15.0,
        None,
    )
    assert printed_lead_in_deg(scenarios, choice, config.updated({"print": {"profile": "custom"}})) == (0.0, None)


def test_a_candidate_squeezed_once_gives_at_every_draft_the_landscapes_of_its_pad_printed_with_that_draft():
    # CandidateSqueeze carves the candidate, grows the carving and turns its parts once for every draft
    # printed_draft compares: the same pads and landscapes as a pad printed with each draft from scratch
    prepared, config = _prepared(ribbed_block(), "ribbed")
    samples = [_sample_at(prepared, 0.0, 5.0), _sample_at(prepared, 3.0, 5.0)]
    arguments = (
        [s.screen for s in samples],
        [s.centres_uv_mm for s in samples],
        [s.width_mm for s in samples],
        [s.sample.sliding_axis for s in samples],
        ScreenGrid.for_config(config),
    )
    squeezed = CandidateSqueeze(*arguments, config)
    geometries = [g for s in samples for g in s.screen]
    for angle in (15.0, 30.0, 45.0, 15.0):
        # the carving grown by the clearance once, then drafted: the pad printed with that draft from its carving
        fit = config.print.resolved()
        printed = fitted_pad_heights(
            carved_heights(geometries, arguments[-1]),
            pad_case(geometries, config)[1],
            arguments[-1].cell_mm,
            fit["clearance_mm"],
            angle,
        )
        assert np.array_equal(squeezed.pad(angle), printed)
        once = squeezed.landscapes(angle)
        anew = pad_landscapes(*arguments, config.updated({"print": {"lead_in_deg": angle}}))
        for a, b in zip(once, anew, strict=True):
            assert a.fraction == b.fraction and a.pads_gap_mm == b.pads_gap_mm
            assert np.array_equal(a.separation_mm, b.separation_mm) and np.array_equal(a.captured, b.captured)


def test_candidates_screened_on_their_pads_with_their_samples_squeezed_once_screen_as_each_alone():
    # screen_on_pad keeps each sample squeezed (turned by every start yaw) for the next candidates that share it
    prepared, config = _prepared(ribbed_block(), "ribbed")
    samples = prepared.scenarios[0].samples
    picks = [samples.index(_sample_at(prepared, s, 5.0)) for s in (0.0, 3.0, 0.0, -3.0, 3.0)]
    squeezed: dict = {}
    for k in picks:
        kept = screen_on_pad(prepared.scenarios, (k,), config, prepared.lattice, squeezed=squeezed)
        alone = screen_on_pad(prepared.scenarios, (k,), config, prepared.lattice)
        assert kept.quality == alone.quality and kept.mean_effective_area == alone.mean_effective_area
        assert [s.capture for s in kept.scenarios] == [s.capture for s in alone.scenarios]
    assert len(squeezed) == len(set(picks)) == 3


def test_the_gap_of_pad_rows_alike_is_measured_once_and_is_the_gap_of_every_row_measured_alone():
    # the squeeze measures one clearance per kind of pad row (rows alike bit for bit, most of a pocket along v)
    # and turned part row: the separation of the straightforward sum over every start, row and column
    prepared, config = _prepared(ribbed_block(), "ribbed")
    sample = _sample_at(prepared, 0.0, 5.0)
    grid = ScreenGrid.for_config(config)
    shape = (grid.count_v, grid.count_w)
    part = squeezed_part(
        (sample.screen[0].heights_mm.reshape(shape), sample.screen[1].heights_mm.reshape(shape)),
        sample.centres_uv_mm,
        grid.cell_mm,
        config.sampler.penetration_mm,
        sample.width_mm,
        config.verify,
        sample.sample.sliding_axis,
    )
    geometries = list(sample.screen)
    fit = config.print.resolved()
    pad = fitted_pad_heights(
        carved_heights(geometries, grid),
        pad_case(geometries, config)[1],
        grid.cell_mm,
        fit["clearance_mm"],
        fit["lead_in_deg"],
    )
    rows = pad[:, part.rows_w]
    assert len(np.unique(rows, axis=0)) < len(rows) / 2  # most rows are alike: the case the sharing is for
    gap = np.zeros((len(part.offsets_mm), len(part.yaws_deg)))
    for entered, turned, whole, fraction in part.sides:
        count_v = len(rows)
        for offset, (shift, share) in enumerate(zip(whole, fraction)):
            here, beyond = (np.clip(np.arange(count_v) - k, 0, count_v - 1) for k in (shift, shift + 1))
            for yaw in range(len(part.yaws_deg)):
                # np.fmin skips what inf - inf gives, as the squeeze reads it: no contact
                least = [
                    np.fmin.reduce(rows[:, entered] - turned[yaw, source], axis=1, initial=np.inf)
                    for source in (here, beyond)
                ]
                shifted = (1.0 - share) * least[0] + share * least[1]
                gap[offset, yaw] += np.min(np.where(np.isnan(shifted), np.inf, shifted))
    centre = (len(part.offsets_mm) // 2, len(part.yaws_deg) // 2)
    with np.errstate(invalid="ignore"):
        expected = -(gap - gap[centre])
    expected[~np.isfinite(expected)] = np.inf
    assert np.array_equal(squeeze(pad, part).separation_mm, expected)


def test_capture_chooses_the_ridge_that_centres_where_q_chooses_the_larger_area():
    mesh = two_ridge_block()
    part = Part(name="two-ridge", path="two-ridge", mesh=mesh)
    settings = (
        fcso.DesignConfig()
        .updated(upright_grasp_settings(mesh))
        .updated({"sampler": {"length_mm": 10.0, "width_mm": 10.0, "stride_mm": 2.0}})
    )
    by_q = fcso.design([part], settings.updated({"quality": {"measure": "paper"}}))
    by_capture = fcso.design([part], settings)
    # the vertical ridge runs up to 20 mm, the horizontal ones from 24 mm: a pad from h to h + 10 mm
    # (the grasp at its middle) holds some of the vertical ridge when h < 20
    assert by_q.report.grasps[0].position_mm[2] - 5.0 >= 20.0
    assert by_capture.report.grasps[0].position_mm[2] - 5.0 < 20.0
    chosen = next(c for c in by_capture.report.candidates if c.index == by_capture.report.best)
    assert chosen.per_scenario[0].capture >= 0.8


def test_a_cube_with_chamfered_edges_is_closed_on_square_to_its_chamfers_and_captured_from_both_sides():
    # 30 mm cube, vertical edges chamfered 45 degrees: closing along the bounding box, a 20 mm pad reaches one
    # chamfer per side, both on the same side of the part, so it centres displaced parts from that side only;
    # closing square to a chamfer (45 or 135 degrees from the faces), the two faces beside it make a 90-degree V
    # on each pad, which centres +-2 mm starts from both sides. The paper's filter: with wrapped faces a 35 mm pad
    # along the bounding box also wraps the 30 mm faces' ends and competes with the chamfers' V
    mesh = holed_notched_cube()
    result = fcso.design(
        [Part(name="chamfered", path="chamfered", mesh=mesh)],
        fcso.DesignConfig().updated({"poses": {"count": 1}, "filter": {"wrapped_faces": False}}),
    )
    scenario = result.report.scenarios[0]
    chosen = scenario.samples[next(c for c in result.report.candidates if c.index == result.report.best).samples[0]]
    # the cube's bounding-box frame is its faces' frame (yaw 0 and 90)
    assert min(abs(chosen.yaw_deg - 45.0), abs(chosen.yaw_deg - 135.0)) < 0.5
    assert chosen.on_feature
    # flat pads capture only the starts already within the success tolerance: at 45 degrees to the table's axes the
    # start errors along the sliding axis pile up near the centre (a trapezoid reaching 2.83 mm), about a fifth
    assert scenario.capture >= 0.95 and scenario.flat_capture <= 0.25


def test_start_errors_along_an_oblique_sliding_axis_reach_the_box_corners_and_pile_up_at_the_centre():
    offsets = np.arange(-12, 13) * 0.25
    along_x = sliding_error_weights(offsets, 2.0, np.array([1.0, 0.0]))
    # along a table axis: uniform over +-2 mm, the edge included
    assert np.array_equal(along_x, (np.abs(offsets) <= 2.0).astype(float))
    diagonal = sliding_error_weights(offsets, 2.0, np.array([np.sqrt(0.5), np.sqrt(0.5)]))
    # dx / sqrt 2 + dy / sqrt 2 with dx, dy uniform in +-2: a triangle of half-width 2 sqrt 2 = 2.83 mm, peak
    # 1 / 2.83 at the centre
    assert diagonal[offsets == 0.0][0] == pytest.approx(1.0 / (2.0 * np.sqrt(2.0)))
    assert diagonal[offsets == 2.5][0] == pytest.approx((2.0 * np.sqrt(2.0) - 2.5) / 8.0)
    assert diagonal[offsets == 2.75][0] > 0.0 and diagonal[offsets == 3.0][0] == 0.0
    # a 30-degree axis: a trapezoid, flat up to 2 (cos 30 - sin 30) = 0.73 mm
    turned = sliding_error_weights(offsets, 2.0, np.array([np.cos(np.radians(30)), np.sin(np.radians(30))]))
    assert turned[offsets == 0.0][0] == pytest.approx(turned[offsets == 0.5][0])
    assert turned[offsets == 1.0][0] < turned[offsets == 0.5][0]


def test_a_pad_longer_than_the_face_wraps_both_chamfers_and_is_chosen_from_the_size_list():
    # the same cube closed along its faces only: a 20 mm pad reaches one chamfer per side (the part centres
    # from one side), a 34 mm pad reaches past both ends of the 30 mm face and holds both chamfers (METHOD §3b)
    mesh = holed_notched_cube()
    config = fcso.DesignConfig().updated(
        {"poses": {"count": 1}, "sampler": {"length_mm": [20.0, 34.0], "face_yaws": False}}
    )
    result = fcso.design([Part(name="chamfered", path="chamfered", mesh=mesh)], config)
    sizes = {entry.length_mm: entry for entry in result.report.pad_sizes}
    assert set(sizes) == {20.0, 34.0} and sizes[34.0].chosen and not sizes[20.0].chosen
    assert result.report.settings.sampler.length_mm == 34.0
    assert result.report.scenarios[0].capture >= 0.95
    # the 20 mm pad's best capture: one side of the +-2 mm box and the seat's own strip
    assert sizes[20.0].quality < 0.7
    # the finger as written carries the longer pad: 34 mm along the pad's length
    assert result.fingerpad.extents[1] == pytest.approx(34.0, abs=1e-3)


def test_the_holding_solver_writes_nothing_to_the_terminal():
    # HiGHS writes its banner from C++ once per process, so a fresh interpreter is the only clean witness;
    # highspy 1.16 printed it before the output flag could be set, into every `fcso design --quiet`
    script = (
        "import numpy as np\n"
        "from fcso.holding import holding_forces_n\n"
        "points = np.array([[10.0, 0, 0], [10.0, 1, 0], [-10.0, 0, 0], [-10.0, 1, 0]])\n"
        "normals = np.array([[-1.0, 0, 0]] * 2 + [[1.0, 0, 0]] * 2)\n"
        "forces = holding_forces_n(points, normals, np.array([0, 0, 1, 1]), np.array([1.0, 0, 0]), np.zeros(3), "
        "0.05, 0.4, 60.0, 30.0)\n"
        "assert forces.max() > 0\n"
    )
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert run.stdout == "" and run.stderr == ""


def test_holding_of_a_grasp_at_the_centre_of_mass_and_far_above_it():
    # two 10 x 10 mm flat patches squeezing a box along x, 60 N each, friction 0.4
    grid = np.stack(np.meshgrid(np.linspace(-4.5, 4.5, 10), np.linspace(-4.5, 4.5, 10)), -1).reshape(-1, 2)
    plus = np.column_stack([np.full(len(grid), 10.0), grid])
    minus = np.column_stack([np.full(len(grid), -10.0), grid])
    points = np.vstack([plus, minus])
    normals = np.vstack([np.tile([-1.0, 0.0, 0.0], (len(grid), 1)), np.tile([1.0, 0.0, 0.0], (len(grid), 1))])
    pads = np.repeat([0, 1], len(grid))
    at_centre = holding_forces_n(points, normals, pads, np.array([1.0, 0.0, 0.0]), np.zeros(3), 0.05, 0.4, 60.0, 30.0)
    # friction alone resists 2 x 0.4 x 60 = 48 N in any direction along the pads: the 30 N test is held
    assert at_centre == pytest.approx(np.full(6, 30.0), abs=1e-6)
    below = holding_forces_n(
        points, normals, pads, np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -25.0]), 0.05, 0.4, 60.0, 30.0
    )
    # a push 25 mm below the patches turns the part about x, which only friction over the patches resists:
    # at most 0.4 x 120 N at the corners, 6.36 mm from the centre, 0.305 N m, so F <= 0.305 / 0.025 = 12.2 N;
    # spread evenly (mean distance 3.83 mm) the same friction gives 7.4 N,
    # 6.8 N inside the eight-edged cones (x cos 22.5°)
    sideways = below[:2]
    assert np.all(sideways >= 6.8) and np.all(sideways <= 12.2)
    # along the closing axis the coupled fingers hold the part whatever the lever
    assert below[2:4] == pytest.approx([30.0, 30.0], abs=1e-6)


def test_a_drafted_pocket_falls_by_the_lead_in_over_side_and_corner_cells():
    # one carved cell 5 mm high on a floor at 0, 1 mm cells and a 45 degree draft: the wall falls 1 mm per side step
    # and sqrt(2) mm per corner step (8 neighbours), down to the floor
    carved = np.full((7, 7), -np.inf)
    carved[3, 3] = 5.0
    heights = fitted_pad_heights(carved, 0.0, 1.0, 0.0, 45.0)
    root2 = np.sqrt(2.0)
    assert heights[3, 3] == 5.0
    assert heights[3, 4] == pytest.approx(4.0) and heights[2, 2] == pytest.approx(5.0 - root2)
    assert heights[3, 6] == pytest.approx(2.0) and heights[0, 0] == pytest.approx(5.0 - 3 * root2)
    # one corner then one side step: the fastest fall to (1, 2) from the peak
    assert heights[1, 2] == pytest.approx(5.0 - root2 - 1.0)
    assert heights.min() >= 0.0
