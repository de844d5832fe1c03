"""Candidate search: branch and bound finds the exhaustive optimum, screening ranks like the exact evaluation (METHOD
§8, §8b).
"""

import itertools

import numpy as np
import pytest

import fcso
from fcso.pipeline import prepare, screen_choice
from fcso.search import candidate_index, quality_upper_bound, rerank, search
from tests.conftest import REPO, data_path, small_config


def batch(single):
    """A batch evaluator from a one-choice evaluator."""
    return lambda choices: [single(c) for c in choices]


def _instance(seed):
    rng = np.random.default_rng(seed)
    counts = [int(c) for c in rng.integers(1, 6, size=rng.integers(1, 5))]
    # E of a scenario depends on its own sample and, downward only, on the others'
    own = [rng.uniform(10.0, 300.0, size=c) for c in counts]
    interaction = {
        choice: rng.uniform(0.5, 1.0, size=len(counts)) for choice in itertools.product(*(range(c) for c in counts))
    }
    if seed % 3 == 0:
        # plateaus: many equal qualities exercise the tie-break
        own = [np.round(e, -2) for e in own]
        interaction = {k: np.ones(len(counts)) for k in interaction}

    def effective_areas(choice):
        return np.array([own[m][k] for m, k in enumerate(choice)]) * interaction[choice]

    return counts, own, effective_areas


def _best(choices, effective_areas, counts):
    return max(
        choices, key=lambda c: (effective_areas(c).min(), effective_areas(c).mean(), -candidate_index(c, counts))
    )


@pytest.mark.parametrize("seed", range(40))
def test_branch_and_bound_matches_exhaustive(seed):
    counts, bounds, effective_areas = _instance(seed)
    calls = []

    def evaluate(choice):
        calls.append(choice)
        e = effective_areas(choice)
        return float(e.min()), float(e.mean())

    everything = list(itertools.product(*(range(c) for c in counts)))
    outcome = search(counts, bounds, batch(evaluate), max_exhaustive=1, max_evaluations=10**6)
    assert outcome.proven_optimal and outcome.total == len(everything)
    assert len(set(outcome.evaluated)) == len(outcome.evaluated) == len(calls)
    if outcome.total > 1:
        assert outcome.kind == "branch_and_bound"
    assert _best(outcome.evaluated, effective_areas, counts) == _best(everything, effective_areas, counts)


def test_rerank_orders_the_rescored_first_and_keeps_the_rest():
    counts = (3, 3)
    ranked = [(0, 0), (0, 1), (1, 0), (2, 2)]
    # (0, 1) and (1, 0) tie on Q and mean: the smaller candidate index, (0, 1) = 1 against (1, 0) = 3, goes first
    scores = {(0, 0): (0.2, 0.5), (0, 1): (0.9, 0.9), (1, 0): (0.9, 0.9)}
    assert rerank(ranked, scores, counts) == [(0, 1), (1, 0), (0, 0), (2, 2)]
    assert rerank(ranked, {}, counts) == ranked


def test_exhaustive_below_the_limit_and_budget_above_it():
    counts, bounds, effective_areas = _instance(7)
    evaluate = batch(lambda c: (float(effective_areas(c).min()), float(effective_areas(c).mean())))
    total = int(np.prod(counts))
    full = search(counts, bounds, evaluate, max_exhaustive=total, max_evaluations=1)
    assert full.kind == "exhaustive" and len(full.evaluated) == total
    assert [candidate_index(c, counts) for c in full.evaluated] == list(range(total))
    capped = search(
        [5, 5, 5], [np.full(5, 100.0)] * 3, batch(lambda c: (1.0, 1.0)), max_exhaustive=1, max_evaluations=10
    )
    assert 1 <= len(capped.evaluated) <= 10 and not capped.proven_optimal
    assert capped.kind == "branch_and_bound+coordinate_ascent"


def test_coordinate_ascent_climbs_when_bounds_cannot_prune():
    # bounds that say nothing (all equal) and one good region away from the
    # first candidates: branch and bound alone spends its half on the corner
    counts = [6, 6, 6]
    peak = (5, 4, 5)

    def evaluate(choice):
        quality = 100.0 - sum(abs(a - b) for a, b in zip(choice, peak))
        return quality, quality

    outcome = search(counts, [np.full(6, 1000.0)] * 3, batch(evaluate), max_exhaustive=1, max_evaluations=60)
    assert outcome.kind == "branch_and_bound+coordinate_ascent"
    assert peak in outcome.evaluated and len(outcome.evaluated) <= 60


def test_search_finds_the_screened_optimum_on_a_real_design():
    config = small_config(sampler={"stride_mm": 8.0}, poses={"select": [0, 1]}, search={"jobs": 1})
    prepared = prepare([fcso.load_part(data_path("solar_tracker.stl"))], config)
    counts = [len(s.samples) for s in prepared.scenarios]
    bounds = [np.array([g.screened_bound for g in s.samples]) for s in prepared.scenarios]
    evaluate = batch(
        lambda c: (screen_choice(prepared, c, config).quality, screen_choice(prepared, c, config).mean_effective_area)
    )
    exhaustive = search(counts, bounds, evaluate, max_exhaustive=10**6, max_evaluations=1)
    searched = search(counts, bounds, evaluate, max_exhaustive=1, max_evaluations=10**6)
    assert exhaustive.kind == "exhaustive" and searched.kind == "branch_and_bound" and searched.proven_optimal
    assert len(searched.evaluated) < len(exhaustive.evaluated) == exhaustive.total
    key = lambda c: (exhaustive.evaluated[c][0], exhaustive.evaluated[c][1], -candidate_index(c, counts))  # noqa: E731
    assert max(searched.evaluated, key=key) == max(exhaustive.evaluated, key=key)
    # the screened bound behind the pruning holds for every candidate: on the measure that ranks (capture x E)
    for choice in exhaustive.evaluated:
        screened = screen_choice(prepared, choice, config)
        for scenario, (sample, quality) in enumerate(zip(choice, screened.scenarios)):
            assert quality.measure <= bounds[scenario][sample] + 1e-6


def test_exact_numbers_are_marked_and_never_above_the_upper_bound():
    # the paper's Q, whose upper bound is the samples' bounds on E (the capture measure's is in its own terms)
    config = small_config(
        sampler={"stride_mm": 8.0},
        poses={"select": [0, 1]},
        search={"exact_top_k": 12, "report_candidates": 5000},
        quality={"measure": "paper"},
    )
    report = fcso.design([data_path("solar_tracker.stl")], config).report
    exact = [c for c in report.candidates if c.evaluation == "exact"]
    assert len(exact) == report.search.exact == 12
    assert len(report.candidates) == report.search.screened == report.search.candidates_total
    assert next(c for c in report.candidates if c.index == report.best).evaluation == "exact"
    assert max(c.quality for c in exact) == next(c.quality for c in report.candidates if c.index == report.best)
    assert all(c.quality <= report.search.quality_upper_bound + 1e-6 for c in exact)
    bounds = [np.array([s.effective_area_bound for s in scenario.samples]) for scenario in report.scenarios]
    assert report.search.quality_upper_bound == pytest.approx(quality_upper_bound(bounds), abs=1e-5)
    assert 0 < report.search.gap <= 1
    for candidate in exact:
        for scenario, (sample, quality) in enumerate(zip(candidate.samples, candidate.per_scenario)):
            assert quality.effective_area <= report.scenarios[scenario].samples[sample].effective_area_bound + 1e-6


def test_screening_ranks_like_exact_evaluation():
    # METHOD §8b on a smaller configuration than the paper experiment (benchmarks/bench_fidelity.py runs that)
    import sys

    sys.path.insert(0, str(REPO))
    from benchmarks.bench_fidelity import fidelity, small_case

    parts, config = small_case()
    result = fidelity(parts, config.updated({"search": {"jobs": 1}}))
    assert result["candidates"] >= 40
    assert result["spearman"] >= 0.95
    assert result["chosen_ratio"] >= 0.98


def test_same_design_for_one_and_two_workers():
    config = small_config(
        sampler={"stride_mm": 8.0}, poses={"select": [0, 1]}, search={"max_exhaustive": 1, "max_evaluations": 200}
    )
    parts = [data_path("20mm-xyz-cube.stl"), data_path("solar_tracker.stl")]
    designs = [fcso.design(parts, config.updated({"search": {"jobs": jobs}})) for jobs in (1, 2)]
    one, two = (d.report for d in designs)
    assert one.search.jobs == 1 and two.search.jobs == 2
    strip = lambda r: r.model_dump(exclude={"timings_s": True, "settings": {"search": {"jobs"}}, "search": {"jobs"}})  # noqa: E731
    assert strip(one) == strip(two)
    # the files too, byte for byte: the pad is carved from geometries made in workers or here
    for mesh in ("finger", "fingerpad"):
        assert getattr(designs[0], mesh).export(file_type="stl") == getattr(designs[1], mesh).export(file_type="stl")


@pytest.mark.parametrize("seed", range(20))
def test_branch_and_bound_ranks_the_best_it_is_asked_to_keep_as_exhaustive_search_does(seed):
    # METHOD §8b re-evaluates the k best exactly and the choice by truth verifies the best few: a search that stops
    # once its first candidate reaches the bound ranks one
    counts, bounds, effective_areas = _instance(seed)
    everything = list(itertools.product(*(range(c) for c in counts)))
    evaluate = batch(lambda c: (float(effective_areas(c).min()), float(effective_areas(c).mean())))
    keep = min(8, len(everything))
    outcome = search(counts, bounds, evaluate, max_exhaustive=1, max_evaluations=10**6, keep=keep)
    assert outcome.proven_optimal

    def top(choices):
        return sorted((float(effective_areas(c).min()) for c in choices), reverse=True)[:keep]

    assert top(outcome.evaluated) == top(everything)
