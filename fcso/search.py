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
        ``"exhaustive"`` or ``"branch_and_bound"``.
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
        Budget of the branch and bound.

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
    order = sorted(
        ((float(bound), scenario, sample) for scenario, bounds in enumerate(upper_bounds) for sample, bound in enumerate(bounds)),
        key=lambda item: (-item[0], item[1], item[2]),
    )
    admitted: list[list[int]] = [[] for _ in counts]
    evaluated: list[tuple[int, ...]] = []
    best_quality = -np.inf
    for bound, scenario, sample in order:
        if bound < best_quality:
            return SearchOutcome("branch_and_bound", evaluated, total, True)
        admitted[scenario].append(sample)
        pools = [pool if m != scenario else [sample] for m, pool in enumerate(admitted)]
        for choice in itertools.product(*pools):
            if len(evaluated) >= max_evaluations:
                return SearchOutcome("branch_and_bound", evaluated, total, False)
            quality, _ = evaluate(tuple(choice))
            evaluated.append(tuple(choice))
            best_quality = max(best_quality, quality)
    return SearchOutcome("branch_and_bound", evaluated, total, True)
