"""What a delivered pad keeps of parts that are not the ones it was designed for (METHOD §11b, fcso.fit_pads).

The parts are test_sets' knobs on plates (manifold3d): a finger designed for
the narrowing knob is evaluated on that knob, on the same knob on a plate
one stride wider (the pads meet the knob at the same places), and on the
knob that widens upwards (the opposite slope: it touches the narrowing
pocket only along its rim).
"""

import numpy as np
import pytest

import fcso
from tests.fcso.test_sets import NARROWING, NARROWING_BIG_PLATE, WIDENING, config


@pytest.fixture(scope="module")
def narrowing_design():
    return fcso.design([NARROWING], config())


def test_a_pad_keeps_its_own_part_and_the_same_knob_on_a_wider_plate(narrowing_design):
    settings = config()
    (fit,) = fcso.fit_pads([NARROWING, NARROWING_BIG_PLATE, WIDENING], [narrowing_design.fingerpad], settings)
    by_part = {s.part: s for s in fit.scenarios}
    assert set(by_part) == {"narrowing", "narrowing-big-plate", "widening"} and fit.left_out == []
    # the design's own grasp is among those tried: at least its E (exact pockets, the paper's measure)
    (designed,) = narrowing_design.report.print_fit.fitted.effective_area
    own = by_part["narrowing"]
    assert own.quality >= designed * (1 - 1e-6) and own.grasp is not None
    # the knob is the same and the pads meet it at the same places: the same quality, and the same solo quality
    wider = by_part["narrowing-big-plate"]
    assert wider.quality == pytest.approx(own.quality, rel=1e-6)
    assert wider.solo_quality == pytest.approx(own.solo_quality, rel=1e-6)
    assert fit.part_worst_retained("narrowing-big-plate") == pytest.approx(own.retained, rel=1e-6)
    assert own.retained >= settings.finger_sets.min_retained
    # the opposite slope keeps less than min_retained: the finger does not serve it
    widening = by_part["widening"]
    assert widening.retained < settings.finger_sets.min_retained
    assert fit.worst_retained == pytest.approx(widening.retained)
    assert np.isclose(widening.retained, widening.quality / widening.solo_quality)
