"""Candidate enumeration: exhaustive, or best-first branch and bound (METHOD §8)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np


@dataclass
class SearchOutcome:
    """What a search evaluated.

    Attributes
    ----------
    kind : str
        ``"exhaustive"``, ``"branch_and_bound"`` or, when the budget ran out
        before a proof, ``"branch_and_bound+coordinate_ascent"``.
    evaluated : list of tuple of int
        The sample choices evaluated, in evaluation order.
    total : int
        Number of candidates ``C = Π N_s,m``.
    proven_optimal : bool
        True when the best evaluated candidate is the best of all ``C``.
    """

    kind: str
    evaluated: list[tuple[int, ...]]
    total: int
    proven_optimal: bool


def candidate_index(choice: Sequence[int], counts: Sequence[int]) -> int:
    """Position of a choice in the lexicographic enumeration (first scenario most significant)."""
    index = 0
    for chosen, count in zip(choice, counts):
        index = index * count + int(chosen)
    return index


def search(
    counts: Sequence[int],
    upper_bounds: Sequence[np.ndarray],
    evaluate: Callable[[tuple[int, ...]], tuple[float, float]],
    max_exhaustive: int,
    max_evaluations: int,
) -> SearchOutcome:
    """Find the candidate with the largest quality Q.

    Parameters
    ----------
    counts : sequence of int
        ``N_s,m``: valid samples per scenario.
    upper_bounds : sequence of (N_s,m,) float
        For every sample, a value no candidate using it can exceed in its
        scenario's effective area E (so ``min`` over a candidate's samples
        bounds its Q).
    evaluate : callable
        Maps a choice (one sample index per scenario) to ``(Q, mean E)``.
    max_exhaustive : int
        Evaluate all candidates when there are at most this many.
    max_evaluations : int
        Budget beyond ``max_exhaustive``: branch and bound may use half, a
        coordinate ascent from its best candidate the rest.

    Returns
    -------
    SearchOutcome

    Notes
    -----
    Branch and bound admits samples in decreasing order of their bound. The
    candidates that a newly admitted sample completes with the samples
    admitted before all have that sample's bound as theirs, so candidates
    are evaluated in non-increasing bound order, each exactly once, and the
    search stops as soon as the next bound falls below the best Q found:
    whatever is left cannot beat it (nor tie it, which the tie-break needs).
    """
    total = int(np.prod([int(c) for c in counts], dtype=object)) if counts else 0
    if total == 0:
        return SearchOutcome("exhaustive", [], 0, True)
    if total <= max_exhaustive:
        evaluated = [tuple(choice) for choice in itertools.product(*(range(c) for c in counts))]
        for choice in evaluated:
            evaluate(choice)
        return SearchOutcome("exhaustive", evaluated, total, True)
    results: dict[tuple[int, ...], tuple[float, float]] = {}

    def scored(choice: tuple[int, ...]) -> tuple[float, float, int]:
        if choice not in results:
            results[choice] = evaluate(choice)
        quality, mean = results[choice]
        return quality, mean, -candidate_index(choice, counts)

    proven = _branch_and_bound(counts, upper_bounds, scored, results, max(1, max_evaluations // 2))
    if proven:
        return SearchOutcome("branch_and_bound", list(results), total, True)
    _coordinate_ascent(counts, scored, results, max_evaluations)
    return SearchOutcome("branch_and_bound+coordinate_ascent", list(results), total, False)


def _branch_and_bound(counts, upper_bounds, scored, results, budget: int) -> bool:
    """Best-first branch and bound; True when it proved its best optimal within ``budget``."""
    order = sorted(
        ((float(bound), scenario, sample) for scenario, bounds in enumerate(upper_bounds) for sample, bound in enumerate(bounds)),
        key=lambda item: (-item[0], item[1], item[2]),
    )
    admitted: list[list[int]] = [[] for _ in counts]
    best_quality = -np.inf
    for bound, scenario, sample in order:
        if bound < best_quality:
            return True
        admitted[scenario].append(sample)
        pools = [pool if m != scenario else [sample] for m, pool in enumerate(admitted)]
        for choice in itertools.product(*pools):
            if len(results) >= budget:
                return False
            best_quality = max(best_quality, scored(tuple(choice))[0])
    return True


def _coordinate_ascent(counts, scored, results, budget: int) -> None:
    """Improve the best candidate one scenario at a time until no change helps or the budget is spent.

    Used when branch and bound cannot prove optimality within half the budget:
    large batches have far more candidates than can be evaluated, and a grasp
    that suits the other scenarios' carving is found by changing one choice
    at a time.
    """
    current = max(results, key=scored)
    improved = True
    while improved:
        improved = False
        for scenario, count in enumerate(counts):
            for sample in range(count):
                choice = current[:scenario] + (sample,) + current[scenario + 1 :]
                if choice not in results and len(results) >= budget:
                    return
                if scored(choice) > scored(current):
                    current, improved = choice, True
