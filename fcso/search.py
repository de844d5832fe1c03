"""Candidate search: exhaustive, best-first branch and bound, then coordinate ascent from seeds (METHOD §8, §8b).

The search ranks candidates by a quality function it is given (the
screening evaluation in :func:`fcso.pipeline.design`) and evaluates them in
batches, so a batch can be spread over worker processes. It never decides
the final design alone: the best candidates it returns are re-evaluated
exactly by the caller.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

#: ``evaluate(choices) -> [(Q, mean E), ...]``, one pair per choice, in order.
BatchEvaluate = Callable[[list[tuple[int, ...]]], list[tuple[float, float]]]


@dataclass
class SearchOutcome:
    """What a search evaluated.

    Attributes
    ----------
    kind : str
        ``"exhaustive"``, ``"branch_and_bound"`` or, when the budget ran out
        before a proof, ``"branch_and_bound+coordinate_ascent"``.
    evaluated : dict
        Every evaluated choice (one sample index per scenario) to ``(Q, mean E)``,
        in evaluation order.
    total : int
        Number of candidates ``C = Π N_s,m``.
    proven_optimal : bool
        True when the best evaluated candidate is the best of all ``C`` under
        the quality the search was given.
    """

    kind: str
    evaluated: dict[tuple[int, ...], tuple[float, float]]
    total: int
    proven_optimal: bool


def candidate_index(choice: Sequence[int], counts: Sequence[int]) -> int:
    """Position of a choice in the lexicographic enumeration (first scenario most significant)."""
    index = 0
    for chosen, count in zip(choice, counts):
        index = index * count + int(chosen)
    return index


def rerank(
    ranked: list[tuple[int, ...]], scores: dict[tuple[int, ...], tuple[float, float]], counts: Sequence[int]
) -> list[tuple[int, ...]]:
    """Candidates ranked again after some were scored again.

    Parameters
    ----------
    ranked : list of tuple of int
        Candidates, best first.
    scores : dict
        ``(Q, mean)`` of some of the first candidates of ``ranked``, scored again.
    counts : sequence of int
        Samples per scenario (:func:`candidate_index` breaks ties).

    Returns
    -------
    list of tuple of int
        The candidates of ``scores`` by larger Q, then larger mean, then smaller
        index; the other candidates after them, in their order.
    """
    first = sorted(scores, key=lambda c: (scores[c][0], scores[c][1], -candidate_index(c, counts)), reverse=True)
    return first + [c for c in ranked if c not in scores]


def quality_upper_bound(upper_bounds: Sequence[np.ndarray]) -> float:
    """An upper bound on every candidate's Q from per-sample bounds on E.

    ``Q = min_m E_m`` and ``E_m`` never exceeds its sample's bound, so no
    candidate beats ``min_m max_s bound[m][s]``.
    """
    return float(min(np.max(b) for b in upper_bounds)) if upper_bounds else 0.0


def search(
    counts: Sequence[int],
    upper_bounds: Sequence[np.ndarray],
    evaluate: BatchEvaluate,
    max_exhaustive: int,
    max_evaluations: int,
    batch_size: int = 256,
    keep: int = 1,
) -> SearchOutcome:
    """Find the candidates with the largest quality Q: the best, and as far as the budget allows the ``keep`` best.

    Parameters
    ----------
    counts : sequence of int
        ``N_s,m``: valid samples per scenario.
    upper_bounds : sequence of (N_s,m,) float
        For every sample, a value no candidate using it can exceed in its
        scenario's effective area E under ``evaluate``'s quality.
    evaluate : callable
        ``evaluate(choices)`` returns ``(Q, mean E)`` for every choice.
    max_exhaustive : int
        Evaluate all candidates when there are at most this many.
    max_evaluations : int
        Budget beyond ``max_exhaustive``: branch and bound may use half,
        coordinate ascent from seeds the rest.
    batch_size : int
        Choices handed to ``evaluate`` at once.
    keep : int
        How many of the best candidates the search must rank: branch and bound goes on until no candidate left can
        beat the ``keep``-th best found (METHOD §8b re-evaluates the ``exact_top_k`` best exactly, and the choice by
        truth verifies the best few), or the budget is spent with the best proven.

    Returns
    -------
    SearchOutcome

    Notes
    -----
    Branch and bound admits samples in decreasing order of their bound. The
    candidates that a newly admitted sample completes with the samples
    admitted before all have that sample's bound as theirs, so candidates
    are evaluated in non-increasing bound order, each exactly once, and the
    search stops as soon as the next bound falls below the ``keep``-th best Q
    found: whatever is left cannot beat it (nor tie it, which the tie-break
    needs). Stopping at the best alone would list one candidate wherever
    the first reaches the bound, leaving the exact re-evaluation and the
    choice by truth nothing else to compare.

    When the budget runs out first, coordinate ascent improves candidates
    one scenario at a time (every sample of that scenario is tried, the
    best move is taken) until no move helps. It starts from the best
    candidate found, then from seeds in turn: every scenario on its
    best-bound sample, then each scenario's best-bound samples with the
    others on the best candidate's choices. More budget reaches more seeds,
    so the result stops improving once the seeds' local optima are found.
    """
    total = int(np.prod([int(c) for c in counts], dtype=object)) if counts else 0
    results: dict[tuple[int, ...], tuple[float, float]] = {}
    if total == 0:
        return SearchOutcome("exhaustive", results, 0, True)
    if total <= max_exhaustive:
        choices = [tuple(choice) for choice in itertools.product(*(range(c) for c in counts))]
        for start in range(0, len(choices), batch_size):
            chunk = choices[start : start + batch_size]
            results.update(zip(chunk, evaluate(chunk)))
        return SearchOutcome("exhaustive", results, total, True)

    def key(choice: tuple[int, ...]) -> tuple[float, float, int]:
        quality, mean = results[choice]
        return quality, mean, -candidate_index(choice, counts)

    # the best so far, kept as results arrive: seeds ask for it often
    leader: list[tuple[int, ...]] = []

    def run(choices: list[tuple[int, ...]]) -> None:
        fresh = list(dict.fromkeys(c for c in choices if c not in results))
        for start in range(0, len(fresh), batch_size):
            chunk = fresh[start : start + batch_size]
            results.update(zip(chunk, evaluate(chunk)))
            best = max(chunk, key=key)
            if not leader or key(best) > key(leader[0]):
                leader[:] = [best]

    if _branch_and_bound(counts, upper_bounds, run, results, max(1, max_evaluations // 2), keep):
        return SearchOutcome("branch_and_bound", results, total, True)
    for seed in _seeds(counts, upper_bounds, lambda: leader[0] if leader else None):
        if len(results) >= max_evaluations:
            break
        _coordinate_ascent(seed, counts, run, results, key, max_evaluations)
    return SearchOutcome("branch_and_bound+coordinate_ascent", results, total, False)


def _branch_and_bound(counts, upper_bounds, run, results, budget: int, keep: int = 1) -> bool:
    """Best-first branch and bound; True when it proved its best optimal within ``budget``, having ranked the ``keep``
    best where the budget allowed."""
    order = sorted(
        (
            (float(bound), scenario, sample)
            for scenario, bounds in enumerate(upper_bounds)
            for sample, bound in enumerate(bounds)
        ),
        key=lambda item: (-item[0], item[1], item[2]),
    )
    admitted: list[list[int]] = [[] for _ in counts]
    # the keep best qualities found, ascending: the first is the bar the rest must beat
    best: list[float] = []
    for bound, scenario, sample in order:
        if len(best) == keep and bound < best[0]:
            return True
        admitted[scenario].append(sample)
        pools = [pool if m != scenario else [sample] for m, pool in enumerate(admitted)]
        size = int(np.prod([len(p) for p in pools], dtype=object))
        if size == 0:
            continue
        if len(results) + size > budget:
            # out of budget: the best is proven when nothing left can beat it
            return bool(best) and bound < best[-1]
        choices = [tuple(c) for c in itertools.product(*pools)]
        run(choices)
        best = sorted(best + [results[c][0] for c in choices])[-keep:]
    return True


def _seeds(counts, upper_bounds, leader):
    """Starting points of the ascent, best first (generated lazily: each sees the best found so far, ``leader()``)."""
    top = tuple(int(np.argmax(b)) for b in upper_bounds)
    if leader() is not None:
        yield leader()
    yield top
    ranked = [np.argsort(-np.asarray(b), kind="stable") for b in upper_bounds]
    for depth in range(1, max(counts)):
        for scenario, order in enumerate(ranked):
            best = leader()
            if depth < len(order) and best is not None:
                yield best[:scenario] + (int(order[depth]),) + best[scenario + 1 :]


def _coordinate_ascent(start, counts, run, results, key, budget: int) -> None:
    """Move one scenario's sample at a time to the best alternative until no move helps or the budget is spent."""
    run([start])
    current = start
    improved = True
    while improved:
        improved = False
        for scenario, count in enumerate(counts):
            moves = [current[:scenario] + (sample,) + current[scenario + 1 :] for sample in range(count)]
            fresh = [m for m in moves if m not in results]
            if len(results) + len(fresh) > budget:
                return
            run(moves)
            best = max(moves, key=key)
            if key(best) > key(current):
                current, improved = best, True
