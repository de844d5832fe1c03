"""Screening (METHOD §8b) on candidates built by hand: which contact samples touch the pad the others carve."""

import numpy as np
import pytest

import fcso
from fcso.screen import NormalLattice, ScreenGeometry, screen

#: One row of four 1 mm cells.
SHAPE = (1, 4)
AREA_MM2 = 0.25
#: The product's settings with one pad size (screening takes one; the default designs two lengths apart).
CONFIG = fcso.DesignConfig().updated({"sampler": {"length_mm": 20.0}})


def geometry(heights, high, good, points_u, points_cell, depth_mm=10.0) -> ScreenGeometry:
    """A geometry whose window is the whole row; its low map is ``heights``, its high map ``high``."""
    return ScreenGeometry(
        grid_shape=SHAPE,
        window=(0, 1, 0, 4),
        window_heights_mm=np.array([heights], dtype=np.float32),
        window_low_mm=np.array([heights], dtype=np.float32),
        window_high_mm=np.array([high], dtype=np.float32),
        good=good,
        depth_mm=depth_mm,
        point_u_mm=np.array(points_u, dtype=np.float32),
        point_cell=np.array(points_cell, dtype=np.int32),
        point_bin=np.arange(len(points_u), dtype=np.int32),
        area_per_point_mm2=AREA_MM2,
    )


def empty() -> ScreenGeometry:
    return geometry([0, 0, 0, 0], [0, 0, 0, 0], True, [], [])


def test_samples_buried_by_another_scenario_carving_do_not_touch():
    # scenario 0 carves 1 mm everywhere and samples each cell at its top; scenario 1 carves 2 mm in cells 2 and 3
    first = geometry([1, 1, 1, 1], [1, 1, 1, 1], True, [1.0, 1.0, 1.0, 1.0], [0, 1, 2, 3])
    second = geometry([0, 0, 2, 2], [0, 0, 2, 2], True, [2.0, 2.0], [2, 3])
    screened = screen([(first, empty()), (second, empty())], CONFIG, NormalLattice())
    # the first keeps cells 0 and 1; the second's own carving buries none of its samples, the first's is lower
    assert [s.contact_area_mm2 for s in screened.scenarios] == [2 * AREA_MM2, 2 * AREA_MM2]
    assert screened.case == "good"
    assert [s.seat_offsets_mm for s in screened.scenarios] == [(0.0, 0.0), (0.0, 0.0)]


def test_a_bad_geometry_is_seated_on_the_high_map_and_touches_between_the_maps():
    config = CONFIG
    eps = config.contact.eps_mm
    carving = geometry([1, 1, 1, 1], [1.5, 1.5, 1.5, 1.5], True, [1.0], [0])
    # highest sample 1.5 mm above the high map: seated 1.5 mm - eps back; then 3.0 -> 1.5 + eps (the high map's
    # edge), 2.8 -> 1.3 + eps (between the maps), 0.5 -> below the low map
    bad = geometry([0, 0, 0, 0], [0, 0, 0, 0], False, [3.0, 2.8, 0.5], [0, 1, 1], depth_mm=1.0)
    screened = screen([(carving, bad)], config, NormalLattice())
    # a good geometry 10 mm deep with K = 1.5 puts the block's face at 0
    assert screened.case == "mixed"
    (scenario,) = screened.scenarios
    assert scenario.seat_offsets_mm[0] == 0.0
    assert scenario.seat_offsets_mm[1] == pytest.approx(1.5 - eps, abs=1e-6)
    assert scenario.contact_area_mm2 == (1 + 2) * AREA_MM2
