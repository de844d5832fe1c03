"""The design's fast paths give the answers of the computations they replace, on real parts (issue 48's time).

Each test makes a small job of parts built with manifold3d and checks a cached or vectorised step against the same
step computed from scratch the way it was before: equal bit for bit, not within a tolerance.
"""

import copy
import sys

import manifold3d
import numpy as np
import pytest

import fcso
from fcso.capture import CandidateSqueeze, pad_landscapes, sample_part, squeeze, squeeze_key
from fcso.evaluate import holding_n, screen_on_pad
from fcso.geometry import to_trimesh
from fcso.grid import ScreenGrid
from fcso.holding import holding_forces_n, merge_contacts, row_groups
from fcso.lead_in import printed_draft
from fcso.parallel import WorkerPool
from fcso.pipeline import evaluate_exact, prepare
from fcso.printed_heights import carved_heights, clearance_heights, drafted_heights
from fcso.screen import pad_case
from fcso.sets.screening import SetScreener, screening_pools, solo_picks, solo_quality
from tests.conftest import small_config


@pytest.fixture(scope="module")
def two_parts():
    """A hexagonal prism and a round part (the pair of test_sets' screening test), prepared with 10 mm pads."""
    hex_prism = manifold3d.Manifold.cylinder(16.0, 20.0 / np.sqrt(3.0), circular_segments=6)
    round_part = manifold3d.Manifold.cylinder(16.0, 7.0, circular_segments=128)
    parts = [
        fcso.Part(name="hex", path="hex.stl", mesh=to_trimesh(hex_prism)),
        fcso.Part(name="round", path="round.stl", mesh=to_trimesh(round_part)),
    ]
    config = small_config(search={"jobs": 1})
    return prepare(parts, config), config


def _contacts(prepared):
    """Every sample's contact samples as holding takes them: points, normals into the part, pads (both sides)."""
    for scenario in prepared.scenarios:
        for sample in scenario.samples[::7]:
            surfaces = sample.surfaces
            points = np.vstack([s.points @ f[:3, :3] for s, f in zip(surfaces, sample.frames)])
            normals = np.vstack([s.normals @ f[:3, :3] for s, f in zip(surfaces, sample.frames)])
            pads = np.concatenate([np.full(len(s.points), side) for side, s in enumerate(surfaces)])
            yield sample, points, normals, pads


def test_contacts_merged_by_one_integer_per_row_are_grouped_as_unique_rows(two_parts):
    # merge_contacts groups contacts by (pad, grid cell, normal direction): numbered in mixed radix, the groups and
    # their order are np.unique's on the rows, so the holding programmes keep their columns in the same order
    prepared, _ = two_parts
    checked = 0
    for _, points, normals, pads in _contacts(prepared):
        keys = np.column_stack([pads, np.floor(points / 1.5).astype(np.int64), np.rint(normals * 1.5).astype(np.int64)])
        assert np.array_equal(row_groups(keys), np.unique(keys, axis=0, return_inverse=True)[1].ravel())
        checked += len(keys) > 0
    assert checked > 10
    # columns whose ranges overflow one integer fall back to np.unique on the rows
    wide = np.array([[0, 2**40, -(2**40)], [1, -(2**40), 2**40], [0, 2**40, -(2**40)]], dtype=np.int64)
    assert np.array_equal(row_groups(wide), np.unique(wide, axis=0, return_inverse=True)[1].ravel())
    assert len(row_groups(np.zeros((0, 3), dtype=np.int64))) == 0


def test_holding_of_merged_contacts_is_the_holding_of_contacts_merged_as_unique_rows(two_parts):
    prepared, config = two_parts
    for sample, points, normals, pads in list(_contacts(prepared))[:6]:
        merged = merge_contacts(points, normals, pads)
        # merged as before: np.unique on the rows
        keys = np.column_stack([pads, np.floor(points / 1.5).astype(np.int64), np.rint(normals * 1.5).astype(np.int64)])
        group = np.unique(keys, axis=0, return_inverse=True)[1].ravel()
        count = np.bincount(group)
        before = np.column_stack([np.bincount(group, points[:, k]) for k in range(3)]) / count[:, None]
        assert np.array_equal(merged[0], before)
        forces = holding_forces_n(
            points, normals, pads, sample.sample.closing_axis, points.mean(axis=0), 0.05, 0.4, 60.0, 30.0
        )
        assert forces.shape == (6,) and np.all(forces >= 0.0)


def _captures_from_scratch(chosen, config) -> list[float]:
    """The captures :func:`printed_draft` measures for ``chosen`` samples, each squeezed anew."""
    _, captures, _ = printed_draft(
        [g.screen for g in chosen],
        [g.centres_uv_mm for g in chosen],
        [g.width_mm for g in chosen],
        [g.sample.sliding_axis for g in chosen],
        config,
    )
    return captures


def test_a_sample_squeezed_once_per_process_screens_candidates_as_squeezed_anew(two_parts):
    # SampleGeometry.squeezed_part keeps each sample squeezed (turned by every start yaw) for every candidate that
    # shares it: the captures on the candidates' pads are those of printed_draft squeezing every sample anew
    prepared, config = two_parts
    grid = ScreenGrid.for_config(config)
    hexes, rounds = (s.samples for s in prepared.scenarios)
    choices = [(h, r) for h in range(0, len(hexes), max(1, len(hexes) // 4)) for r in (0, len(rounds) // 2)]
    for choice in choices:
        chosen = [prepared.scenarios[m].samples[k] for m, k in enumerate(choice)]
        kept = [g.squeezed_part(grid, config) for g in chosen]
        assert all(g.squeezed_part(grid, config) is part for g, part in zip(chosen, kept))
        for g, part in zip(chosen, kept):
            anew = sample_part(g.screen, g.centres_uv_mm, g.width_mm, g.sample.sliding_axis, grid, config)
            for a, b in zip(part.sides, anew.sides):
                assert all(np.array_equal(x, y) for x, y in zip(a, b))
        screened = screen_on_pad(prepared.scenarios, choice, config, prepared.lattice, holding=True)
        assert [s.capture for s in screened.scenarios] == _captures_from_scratch(chosen, config)


def _drafted_in_passes(heights: np.ndarray, floor_mm: float, cell_mm: float, lead_in_deg: float) -> np.ndarray:
    """The drafted heights as they were computed before: passes over a copy of the whole grid (each cell from its
    neighbours' heights of the pass before) until none changes."""
    current = np.maximum(np.asarray(heights, dtype=np.float64), floor_mm)
    drop = cell_mm / np.tan(np.radians(lead_in_deg))
    rows, columns = current.shape
    for _ in range(rows + columns):
        padded = np.pad(current, 1, constant_values=-np.inf)
        straight = np.max([padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]], axis=0)
        corner = np.max([padded[:-2, :-2], padded[:-2, 2:], padded[2:, :-2], padded[2:, 2:]], axis=0)
        grown = np.maximum(current, np.maximum(straight - drop, corner - drop * np.sqrt(2.0)))
        if np.array_equal(grown, current):
            break
        current = grown
    return np.maximum(current, floor_mm)


def test_walls_drafted_in_alternating_sweeps_are_the_walls_drafted_in_passes(two_parts):
    # drafted_heights updates the grid in place, sweeping it in alternating orders: the heights of the passes over a
    # copy bit for bit, on the pads real candidates carve, at every draft the design compares
    prepared, config = two_parts
    grid = ScreenGrid.for_config(config)
    hexes, rounds = (s.samples for s in prepared.scenarios)
    clearance = config.print.resolved()["clearance_mm"]
    checked = 0
    for h, r in [(h, r) for h in range(0, len(hexes), max(1, len(hexes) // 5)) for r in (0, len(rounds) // 2)]:
        geometries = [*hexes[h].screen, *rounds[r].screen]
        floor = pad_case(geometries, config)[1]
        carved = carved_heights(geometries, grid)
        for drafted in (True, False):
            cleared = clearance_heights(carved, grid.cell_mm, clearance, drafted)
            for angle in (15.0, 30.0, 45.0):
                assert np.array_equal(
                    drafted_heights(cleared, floor, grid.cell_mm, angle),
                    _drafted_in_passes(cleared, floor, grid.cell_mm, angle),
                )
                checked += 1
    assert checked >= 12


def test_landscapes_of_a_carving_squeezed_before_are_those_squeezed_anew(two_parts):
    # CandidateSqueeze with ``known`` reuses a landscape where a part meets a carving already squeezed bit for bit:
    # a candidate of the same carving (the hex's pocket under the round part's, test_sets) gets the landscapes of a
    # squeeze from scratch, and one of another carving is squeezed anew
    prepared, config = two_parts
    grid = ScreenGrid.for_config(config)
    hexes, rounds = (s.samples for s in prepared.scenarios)
    known: dict = {}
    reused = 0
    for h in range(0, len(hexes), max(1, len(hexes) // 6)):
        for r in range(0, len(rounds), max(1, len(rounds) // 3)):
            chosen = [hexes[h], rounds[r]]
            arguments = (
                [g.screen for g in chosen],
                [g.centres_uv_mm for g in chosen],
                [g.width_mm for g in chosen],
                [g.sample.sliding_axis for g in chosen],
                grid,
                config,
            )
            parts = [g.squeezed_part(grid, config) for g in chosen]
            before = len(known)
            cached = CandidateSqueeze(*arguments, parts, known)
            anew = CandidateSqueeze(*arguments)
            for angle in (15.0, 30.0):
                for a, b in zip(cached.landscapes(angle), anew.landscapes(angle), strict=True):
                    assert a.fraction == b.fraction and a.pads_gap_mm == b.pads_gap_mm
                    assert np.array_equal(a.separation_mm, b.separation_mm) and np.array_equal(a.captured, b.captured)
            reused += before + 4 > len(known)
            # the whole screening as the set's screening runs it, with the landscapes known
            screened = screen_on_pad(prepared.scenarios, (h, r), config, prepared.lattice, landscapes=known)
            alone = screen_on_pad(prepared.scenarios, (h, r), config, prepared.lattice)
            assert [s.capture for s in screened.scenarios] == [s.capture for s in alone.scenarios]
            assert screened.quality == alone.quality
    # a carving met again (the same round sample under several hex samples' pockets) reused its landscapes
    assert reused > 0


def test_holding_measured_once_per_sample_and_contacts_is_the_holding_measured_anew(two_parts):
    # SampleGeometry.holding_n keeps the six holding forces of each set of contacts: the exact evaluation of a
    # finalist, whose contacts are often its screened ones, reads those the screening measured, and the same forces
    # as holding_n measures from scratch
    prepared, config = two_parts
    hexes, rounds = (s.samples for s in prepared.scenarios)
    reused = 0
    for choice in [(h, r) for h in range(0, len(hexes), max(1, len(hexes) // 4)) for r in (0, len(rounds) // 2)]:
        screened = screen_on_pad(prepared.scenarios, choice, config, prepared.lattice, holding=True)
        known = sum(len(prepared.scenarios[m].samples[k].forces) for m, k in enumerate(choice))
        exact = evaluate_exact(prepared, choice, config)
        reused += known == sum(len(prepared.scenarios[m].samples[k].forces) for m, k in enumerate(choice))
        for m, (k, evaluation) in enumerate(zip(choice, exact.scenarios)):
            sample, scenario = prepared.scenarios[m].samples[k], prepared.scenarios[m]
            contacts = [c.contact for c in evaluation.contacts]
            anew = holding_n(scenario, sample, sample.surfaces, contacts, evaluation.contact_normals, config)
            assert np.array_equal(evaluation.holding_n, anew)
        # its landscapes, with each sample squeezed once per process, are those of samples squeezed anew
        chosen = [prepared.scenarios[m].samples[k] for m, k in enumerate(choice)]
        landscapes = pad_landscapes(
            [g.screen for g in chosen],
            [g.centres_uv_mm for g in chosen],
            [g.width_mm for g in chosen],
            [g.sample.sliding_axis for g in chosen],
            ScreenGrid.for_config(config),
            config,
        )
        for landscape, evaluation in zip(landscapes, exact.scenarios, strict=True):
            assert np.array_equal(landscape.separation_mm, evaluation.capture.separation_mm)
            assert landscape.fraction == evaluation.capture.fraction
            # the screened share is the share of the forces measured anew for the screened contacts
            assert 0.0 <= screened.scenarios[m].measure
    assert reused > 0


def test_quick_screenings_sent_the_holding_measured_by_other_workers_are_those_measured_anew(two_parts):
    # SetScreener.quick sends each batch the holding shares other workers measured for its samples since the pool
    # was forked: the screenings are those of workers that measure every holding themselves
    prepared, config = two_parts
    clean = copy.deepcopy(prepared)
    solos = [solo_quality(prepared, m, config) for m in range(len(prepared.scenarios))]
    sets = [frozenset({0, 1}), frozenset({0}), frozenset({1})]

    def quick(job, learned=None):
        context = (job, screening_pools(solos, config.finger_sets.screen_samples), solo_picks(solos), config)
        with WorkerPool(context, 2) as pool:
            screener = SetScreener(job, [[0], [1]], solos, config, pool)
            screener.learned = copy.deepcopy(learned or {})
            return screener.quick(sets), screener.learned

    measured, learned = quick(copy.deepcopy(clean))
    assert learned  # the workers' holding shares came back
    sent, _ = quick(copy.deepcopy(clean), learned)
    for a, b in zip(measured, sent, strict=True):
        assert a.keys() == b.keys() and all(np.array_equal(a[p], b[p]) for p in a)


def test_a_squeeze_reads_of_the_pad_only_what_its_key_holds(two_parts):
    # squeeze_key names what squeeze reads: a pad changed elsewhere has the same key and gives the same landscape,
    # a pad changed where the part enters it has another key
    prepared, config = two_parts
    grid = ScreenGrid.for_config(config)
    sample = prepared.scenarios[0].samples[len(prepared.scenarios[0].samples) // 2]
    part = sample.squeezed_part(grid, config)
    pad = CandidateSqueeze(
        [sample.screen], [sample.centres_uv_mm], [sample.width_mm], [sample.sample.sliding_axis], grid, config
    ).pad(15.0)
    columns = np.arange(grid.count_w)
    unread = np.setdiff1d(columns, columns[part.rows_w])
    assert len(unread) > 0
    elsewhere = pad.copy()
    elsewhere[:, unread] += 1.0
    assert squeeze_key(elsewhere, part) == squeeze_key(pad, part)
    a, b = squeeze(pad, part), squeeze(elsewhere, part)
    assert a.fraction == b.fraction and np.array_equal(a.separation_mm, b.separation_mm)
    entered = columns[part.rows_w][part.sides[0][0]]
    inside = pad.copy()
    inside[:, entered[0]] += 1.0
    assert squeeze_key(inside, part) != squeeze_key(pad, part)


def test_a_process_keeps_the_samples_squeezed_last_and_screens_as_without(two_parts, monkeypatch):
    # at most SQUEEZED_KEPT samples keep their squeezed parts (1-2 MB each): the earliest are squeezed again when met
    # again, and the screenings are the same
    prepared, config = two_parts
    evaluate = sys.modules["fcso.evaluate"]
    monkeypatch.setattr(evaluate, "SQUEEZED_KEPT", 2)
    hexes, rounds = (s.samples for s in prepared.scenarios)
    choices = [(h, r) for h in range(0, len(hexes), max(1, len(hexes) // 4)) for r in (0, len(rounds) // 2)]
    kept = [screen_on_pad(prepared.scenarios, c, config, prepared.lattice, holding=True) for c in choices * 2]
    squeezed = [g for s in prepared.scenarios for g in s.samples if g.squeezed]
    assert len(squeezed) <= 2
    for choice, screened in zip(choices * 2, kept):
        chosen = [prepared.scenarios[m].samples[k] for m, k in enumerate(choice)]
        assert [s.capture for s in screened.scenarios] == _captures_from_scratch(chosen, config)
