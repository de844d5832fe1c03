"""Candidate search: branch and bound finds the exhaustive optimum (METHOD §8)."""

import itertools

import numpy as np
import pytest

import fcso
from fcso.search import candidate_index, search

from .conftest import data_path, small_config


def _instance(seed):
    rng = np.random.default_rng(seed)
    counts = [int(c) for c in rng.integers(1, 6, size=rng.integers(1, 5))]
    # E of a scenario depends on its own sample and, downward only, on the others'
    own = [rng.uniform(10.0, 300.0, size=c) for c in counts]
    interaction = {choice: rng.uniform(0.5, 1.0, size=len(counts)) for choice in itertools.product(*(range(c) for c in counts))}
    if seed % 3 == 0:
        # plateaus: many equal qualities exercise the tie-break
        own = [np.round(e, -2) for e in own]
        interaction = {k: np.ones(len(counts)) for k in interaction}

    def effective_areas(choice):
        return np.array([own[m][k] for m, k in enumerate(choice)]) * interaction[choice]

    return counts, own, effective_areas


def _best(choices, effective_areas, counts):
    return max(choices, key=lambda c: (effective_areas(c).min(), effective_areas(c).mean(), -candidate_index(c, counts)))


@pytest.mark.parametrize("seed", range(40))
def test_branch_and_bound_matches_exhaustive(seed):
    counts, bounds, effective_areas = _instance(seed)
    calls = []

    def evaluate(choice):
        calls.append(choice)
        e = effective_areas(choice)
        return float(e.min()), float(e.mean())

    everything = list(itertools.product(*(range(c) for c in counts)))
    outcome = search(counts, bounds, evaluate, max_exhaustive=1, max_evaluations=10**6)
    assert outcome.proven_optimal and outcome.total == len(everything)
    assert len(set(outcome.evaluated)) == len(outcome.evaluated) == len(calls)
    if outcome.total > 1:
        assert outcome.kind == "branch_and_bound"
    assert _best(outcome.evaluated, effective_areas, counts) == _best(everything, effective_areas, counts)


def test_exhaustive_below_the_limit_and_budget_above_it():
    counts, bounds, effective_areas = _instance(7)
    evaluate = lambda c: (float(effective_areas(c).min()), float(effective_areas(c).mean()))  # noqa: E731
    total = int(np.prod(counts))
    full = search(counts, bounds, evaluate, max_exhaustive=total, max_evaluations=1)
    assert full.kind == "exhaustive" and len(full.evaluated) == total
    assert [candidate_index(c, counts) for c in full.evaluated] == list(range(total))
    capped = search([5, 5, 5], [np.full(5, 100.0)] * 3, lambda c: (1.0, 1.0), max_exhaustive=1, max_evaluations=10)
    assert len(capped.evaluated) == 10 and not capped.proven_optimal
    assert capped.kind == "branch_and_bound+coordinate_ascent"


def test_coordinate_ascent_climbs_when_bounds_cannot_prune():
    # bounds that say nothing (all equal) and one good region away from the
    # first candidates: branch and bound alone spends its half on the corner
    counts = [6, 6, 6]
    peak = (5, 4, 5)

    def evaluate(choice):
        quality = 100.0 - sum(abs(a - b) for a, b in zip(choice, peak))
        return quality, quality

    outcome = search(counts, [np.full(6, 1000.0)] * 3, evaluate, max_exhaustive=1, max_evaluations=60)
    assert outcome.kind == "branch_and_bound+coordinate_ascent"
    assert peak in outcome.evaluated and len(outcome.evaluated) <= 60


def test_search_finds_the_exhaustive_optimum_on_a_real_design():
    config = small_config(sampler={"stride_mm": 8.0}, poses={"select": [0, 1]})
    part = fcso.load_part(data_path("solar_tracker.stl"))
    exhaustive = fcso.design([part], config).report
    searched = fcso.design([part], config.updated({"search": {"max_exhaustive": 1}})).report
    assert exhaustive.search.kind == "exhaustive" and searched.search.kind == "branch_and_bound"
    assert searched.search.proven_optimal
    assert searched.search.evaluated <= exhaustive.search.evaluated == exhaustive.search.candidates_total
    assert searched.best == exhaustive.best
    best = {c.index: c.quality for c in exhaustive.candidates}
    assert max(c.quality for c in searched.candidates) == best[exhaustive.best] == max(best.values())
    # the bound behind the pruning holds for every evaluated candidate
    for candidate in exhaustive.candidates:
        for scenario, (sample, quality) in enumerate(zip(candidate.samples, candidate.per_scenario)):
            assert quality.effective_area <= exhaustive.scenarios[scenario].samples[sample].effective_area_bound + 1e-6
