"""The scaled partition search (quick screenings, set searches where in doubt) against every partition, on small jobs.

The parts are the knobs of tests/fcso/test_sets.py: plates too wide for the
gripper with one tapered knob each; knobs tapering the same way share a
finger, opposite tapers conflict.
"""

import numpy as np
import pytest

from fcso.parallel import WorkerPool
from fcso.pipeline import prepare
from fcso.sets import SetScreener, screening_pools, search_partition, solo_quality
from fcso.sets.screening import solo_picks
from tests.fcso.test_sets import NARROWING, NARROWING_BIG_PLATE, NARROWING_WIDER, WIDENING, config, knob_part

PARTS = [NARROWING, WIDENING, NARROWING_BIG_PLATE, NARROWING_WIDER, knob_part("widening-wider", 11.0, 1 / 0.75)]


@pytest.fixture(scope="module")
def screener():
    cfg = config().updated({"quality": {"measure": "paper"}})
    prepared = prepare(PARTS, cfg)
    solos = [solo_quality(prepared, m, cfg) for m in range(len(prepared.scenarios))]
    part_scenarios = [[m for m, s in enumerate(prepared.scenarios) if s.part_index == u] for u in range(len(PARTS))]
    pools = screening_pools(solos, cfg.finger_sets.screen_samples)
    with WorkerPool((prepared, pools, solo_picks(solos), cfg), 1) as pool:
        yield SetScreener(prepared, part_scenarios, solos, cfg, pool), cfg


def quiet(stage, done, total, note=""):
    pass


#: Every pair quick-screened (8 per part), or a sparse conflict graph: each part's nearest neighbour by carving and
#: the pairs of the 2 x max most dissimilar parts (1 per part).
SCALED = {
    "quick_screening+colouring+local_moves": {"pairs_per_part": 8},
    "carving_neighbours+colouring+local_moves": {"pairs_per_part": 1},
}


@pytest.mark.parametrize("method", list(SCALED))
@pytest.mark.parametrize("max_sets", [2, 3])
@pytest.mark.parametrize("min_retained", [0.5, 0.7, 0.95])
def test_scaled_search_finds_the_fewest_sets_where_it_claims_to(screener, max_sets, min_retained, method):
    screener, cfg = screener
    settings = {"max": max_sets, "min_retained": min_retained, **SCALED[method]}
    exhaustive = search_partition(
        screener, len(PARTS), cfg.updated({"finger_sets": {"exhaustive_parts": 5, **settings}}), quiet
    )
    scaled = search_partition(
        screener, len(PARTS), cfg.updated({"finger_sets": {"exhaustive_parts": 1, **settings}}), quiet
    )
    assert exhaustive.method == "exhaustive" and scaled.method == method
    best_sets = max(exhaustive.assignment) + 1
    reached = float(exhaustive.retained.min()) >= min_retained
    # the certified conflict clique: every pair in it was searched as a set and keeps less than min_retained
    for i, j in zip(scaled.conflict_clique, scaled.conflict_clique[1:]):
        assert min(scaled.pair_retained[(i, j)]) < min_retained
    if reached:
        assert scaled.lower_bound_sets <= best_sets
    if scaled.fewest_sets_proven:
        assert reached and max(scaled.assignment) + 1 == best_sets
        assert float(np.min(scaled.retained)) >= min_retained


@pytest.mark.parametrize("method", list(SCALED))
def test_the_claim_is_made_on_these_parts(screener, method):
    # without a claim the test above checks nothing: with two sets allowed and 0.5 to keep, the knobs tapering one way
    # and those tapering the other are two sets, and the conflicting pair bounds the count from below
    screener, cfg = screener
    settings = {"finger_sets": {"max": 2, "min_retained": 0.5, "exhaustive_parts": 1, **SCALED[method]}}
    scaled = search_partition(screener, len(PARTS), cfg.updated(settings), quiet)
    assert scaled.method == method
    assert scaled.fewest_sets_proven and scaled.lower_bound_sets == 2
    if method == "carving_neighbours+colouring+local_moves":
        assert scaled.screened_pairs < len(PARTS) * (len(PARTS) - 1) // 2
