"""The split of a job's distinct parts into finger sets, searched under screening (METHOD §11)."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..progress import Progress
from .screening import SetScreener, sets_of


def canonical_assignment(assignment: Sequence[int]) -> tuple[int, ...]:
    """Sets renumbered by their first part (METHOD §11): ``(2, 0, 2, 1)`` becomes ``(0, 1, 0, 2)``."""
    numbers: dict[int, int] = {}
    return tuple(numbers.setdefault(a, len(numbers)) for a in assignment)


def partition_key(assignment: Sequence[int], retained: Sequence[float], min_retained: float) -> tuple:
    """Order of partitions by the objective of METHOD §11; the larger key is the better partition.

    Parameters
    ----------
    assignment : sequence of int
        Set of every part, canonical (:func:`canonical_assignment`).
    retained : sequence of float
        ``r = E / E*`` of every graspable scenario in its set.
    min_retained : float

    Returns
    -------
    tuple
        Partitions where every ``r >= min_retained`` rank above all others,
        by fewer sets, then larger mean r; the others by larger worst r, then
        larger mean r, then fewer sets; last, the lexicographically smallest
        assignment.
    """
    values = np.asarray(retained, dtype=np.float64)
    worst = round(float(values.min()), 9) if len(values) else 1.0
    mean = round(float(values.mean()), 9) if len(values) else 1.0
    sets = max(assignment) + 1 if len(assignment) else 0
    smallest = tuple(-a for a in assignment)
    if worst >= min_retained:
        return (1, -sets, mean, 0.0, smallest)
    return (0, worst, mean, -sets, smallest)


def restricted_growth(parts: int, max_sets: int):
    """Every partition of ``parts`` items into at most ``max_sets`` sets, as canonical assignments in lexicographic
    order.
    """
    if parts == 0:
        yield ()
        return

    def grow(prefix: list[int], used: int):
        if len(prefix) == parts:
            yield tuple(prefix)
            return
        for label in range(min(used + 1, max_sets)):
            yield from grow(prefix + [label], max(used, label + 1))

    yield from grow([0], 1)


def max_clique(adjacent: np.ndarray) -> list[int]:
    """A largest clique of a small undirected graph (Bron–Kerbosch with pivoting).

    Parameters
    ----------
    adjacent : (n, n) bool
        Symmetric adjacency, False on the diagonal.

    Returns
    -------
    list of int
        Its vertices in increasing order (the lexicographically first of the largest).
    """
    best: list[int] = []
    neighbours = [set(np.flatnonzero(row).tolist()) for row in adjacent]

    def expand(clique: list[int], candidates: set[int], excluded: set[int]) -> None:
        nonlocal best
        if not candidates and not excluded:
            if len(clique) > len(best) or (len(clique) == len(best) and sorted(clique) < best):
                best = sorted(clique)
            return
        if len(clique) + len(candidates) < len(best):
            return
        pivot = max(candidates | excluded, key=lambda v: len(neighbours[v] & candidates))
        for vertex in sorted(candidates - neighbours[pivot]):
            expand(clique + [vertex], candidates & neighbours[vertex], excluded & neighbours[vertex])
            candidates = candidates - {vertex}
            excluded = excluded | {vertex}

    expand([], set(range(len(adjacent))), set())
    return best


@dataclass
class PartitionOutcome:
    """How the parts were split and what is known about the split.

    Attributes
    ----------
    assignment : tuple of int
        Set of every part (canonical), parts in job order.
    retained : (scenarios,) float
        ``r`` of every graspable scenario in its set: exact where the set was
        designed exactly (:meth:`SetScreener.judge_exactly`), screened otherwise.
    method : str
        ``"single_part"``, ``"exhaustive"`` or ``"conflict_graph_colouring+local_moves"``.
    proven : bool
        Every partition into at most ``max`` sets was screened: the choice is
        the best under screening.
    pair_retained : dict
        ``(i, j) -> (r_i, r_j)``: worst screened r of each part of a pair designed together.
    lower_bound_sets : int
        Size of the largest set of parts that pairwise conflict (``min(r) < min_retained``).
    conflict_clique : list of int
        Those parts.
    worst_retained_bound : float or None
        When that clique is larger than ``max``, two of its parts must share a
        set: no partition keeps more than this worst r (the best pair of the clique).
    sets_tried : list of int
        Numbers of sets the search tried.
    set_screenings : int
        Distinct sets screened.
    """

    assignment: tuple[int, ...]
    retained: np.ndarray
    method: str
    proven: bool
    pair_retained: dict[tuple[int, int], tuple[float, float]]
    lower_bound_sets: int
    conflict_clique: list[int]
    worst_retained_bound: float | None
    sets_tried: list[int]
    set_screenings: int


def search_partition(screener: SetScreener, parts: int, config: DesignConfig, progress: Progress) -> PartitionOutcome:
    """Split ``parts`` parts into finger sets by the objective of METHOD §11, under screening.

    Up to ``[finger_sets] exhaustive_parts`` parts every partition into at
    most ``max`` sets is screened and the best taken (a proof under
    screening). Beyond, every pair of parts is screened as a set; pairs whose
    worse part keeps less than ``min_retained`` conflict. The largest clique
    of conflicting parts bounds the number of sets from below (assuming a
    part keeps no more of its quality in a larger set). From that many sets
    up to ``max``: parts go greedily, most conflicted first, to the set they
    conflict with least (a new set while any is left), then the part of the
    worst scenario moves to the set that improves the objective most, until
    no move does; the first number of sets that reaches ``min_retained`` is
    taken, else the best partition seen.

    Parameters
    ----------
    screener : SetScreener
    parts : int
        Distinct graspable parts.
    config : DesignConfig
    progress : callable

    Returns
    -------
    PartitionOutcome
    """
    settings = config.finger_sets
    max_sets, threshold = settings.max, settings.min_retained
    pairs = list(itertools.combinations(range(parts), 2))
    progress("pair conflicts", 0, len(pairs), "")
    pair_values = screener.retained([frozenset(p) for p in pairs])
    pair_retained = {pair: (float(v[pair[0]].min()), float(v[pair[1]].min())) for pair, v in zip(pairs, pair_values)}
    progress("pair conflicts", len(pairs), len(pairs), "")
    conflicts = np.zeros((parts, parts), dtype=bool)
    for (i, j), values in pair_retained.items():
        conflicts[i, j] = conflicts[j, i] = min(values) < threshold
    clique = max_clique(conflicts) if parts else []
    lower = max(1, len(clique))
    bound = None
    if len(clique) > max_sets:
        bound = max(min(pair_retained[pair]) for pair in itertools.combinations(clique, 2))

    def outcome(assignment, method, proven, tried) -> PartitionOutcome:
        return PartitionOutcome(
            assignment=assignment,
            retained=screener.partition_retained(assignment),
            method=method,
            proven=proven,
            pair_retained=pair_retained,
            lower_bound_sets=lower,
            conflict_clique=clique,
            worst_retained_bound=bound,
            sets_tried=tried,
            set_screenings=len(screener.cache),
        )

    def key(assignment: tuple[int, ...]) -> tuple:
        return partition_key(assignment, screener.partition_retained(assignment), threshold)

    if parts <= 1:
        return outcome(tuple([0] * parts), "single_part", True, [1] if parts else [])
    if parts <= settings.exhaustive_parts:
        candidates = list(restricted_growth(parts, max_sets))
        progress("partition", 0, len(candidates), "every partition")
        screener.retained(list({s for a in candidates for s in sets_of(a)}))
        best = max(candidates, key=key)
        progress("partition", len(candidates), len(candidates), "every partition")
        return outcome(best, "exhaustive", True, sorted({max(a) + 1 for a in candidates}))

    compatibility = np.ones((parts, parts))
    for (i, j), values in pair_retained.items():
        compatibility[i, j] = compatibility[j, i] = min(values)
    tried, seen = [], []
    for count in range(min(lower, max_sets), max_sets + 1):
        tried.append(count)
        progress("partition", len(tried), max_sets - min(lower, max_sets) + 1, f"{count} sets")
        current = _greedy_assignment(compatibility, count, threshold)
        current = _improve(screener, current, count, threshold, key)
        seen.append(current)
        if key(current)[0] == 1:
            break
    return outcome(max(seen, key=key), "conflict_graph_colouring+local_moves", False, tried)


def _greedy_assignment(compatibility: np.ndarray, max_sets: int, threshold: float) -> tuple[int, ...]:
    """Most conflicted parts first, each to the set whose worst pair with it is best (a new set while any is left and
    none is good enough).
    """
    parts = len(compatibility)
    conflicts = (compatibility < threshold).sum(axis=1)
    order = sorted(range(parts), key=lambda p: (-conflicts[p], p))
    members: list[list[int]] = []
    assignment = [0] * parts
    for part in order:
        scores = [min(compatibility[part, q] for q in group) for group in members]
        good = [s for s in scores if s >= threshold]
        if members and (good or len(members) >= max_sets):
            label = int(np.argmax(scores))
        else:
            label = len(members)
            members.append([])
        members[label].append(part)
        assignment[part] = label
    return canonical_assignment(assignment)


def _improve(
    screener: SetScreener, assignment: tuple[int, ...], max_sets: int, threshold: float, key
) -> tuple[int, ...]:
    """Move parts of the worst set to other sets (or a new one) while a move improves the objective."""
    current = assignment
    for _ in range(4 * len(assignment)):
        if key(current)[0] == 1:
            return current
        retained = screener.partition_retained(current)
        worst_part = _worst_parts(screener, current, retained)
        moves = []
        for part in worst_part:
            for label in range(min(max(current) + 2, max_sets)):
                if label != current[part]:
                    moved = list(current)
                    moved[part] = label
                    moves.append(canonical_assignment(moved))
        moves = [m for m in dict.fromkeys(moves) if m != current]
        if not moves:
            return current
        screener.retained(list({s for m in moves for s in sets_of(m)}))
        best = max(moves, key=key)
        if key(best) <= key(current):
            return current
        current = best
    return current


def _worst_parts(screener: SetScreener, assignment: tuple[int, ...], retained: np.ndarray, count: int = 3) -> list[int]:
    """The ``count`` parts of the set holding the worst scenario, by their worst r."""
    owners = np.concatenate([[p] * len(screener.part_scenarios[p]) for p in range(len(assignment))]).astype(int)
    worst_set = assignment[owners[int(np.argmin(retained))]]
    members = [p for p in range(len(assignment)) if assignment[p] == worst_set]
    return sorted(members, key=lambda p: (float(retained[owners == p].min()), p))[:count]


@dataclass
class PartitionAttempt:
    """A partition whose every set was designed exactly (METHOD §11 revision 3).

    Attributes
    ----------
    assignment : tuple of int
        Set of every part (canonical).
    screened_worst : float
        Least screened ``r`` over its graspable scenarios.
    exact_worst : float
        Least exact ``r`` (its sets' exact designs).
    source : str
        ``"search"``: proposed by the partition search; ``"one_finger"``:
        every part in one set, designed to compare.
    """

    assignment: tuple[int, ...]
    screened_worst: float
    exact_worst: float
    source: str


def search_judged_exactly(
    screener: SetScreener,
    parts: int,
    config: DesignConfig,
    progress: Progress,
    design_exactly: Callable[[frozenset[int]], object],
) -> tuple[PartitionOutcome, list[PartitionAttempt]]:
    """The partition search of :func:`search_partition`, its proposals judged by their exact sets (METHOD §11 rev. 3).

    The sets of each proposed partition are designed exactly
    (``design_exactly`` records their exact ``r`` in ``screener``), so the next
    search sees the exact figure of every set designed so far: a set whose
    exact design misses ``min_retained`` no longer looks feasible, and the
    search moves its parts or tries more sets. It stops when the exact sets
    reach ``min_retained``, when the search proposes only sets already
    designed, or after ``[finger_sets] max`` proposals. If ``min_retained`` is
    then not reached, one finger for every part is designed too; the chosen
    partition is the best of those designed by the exact objective, so it
    never keeps less in its worst scenario than one finger does.

    Parameters
    ----------
    screener : SetScreener
    parts : int
        Distinct graspable parts.
    config : DesignConfig
    progress : callable
    design_exactly : callable
        ``design_exactly(set_of_parts)``: designs the set by METHOD §1-9 and
        calls ``screener.judge_exactly`` with its exact retained qualities.

    Returns
    -------
    PartitionOutcome
        Of the chosen partition, ``retained`` exact.
    list of PartitionAttempt
        Every partition designed, in the order designed.
    """
    threshold = config.finger_sets.min_retained
    attempts: list[PartitionAttempt] = []

    def attempt(assignment: tuple[int, ...], source: str) -> PartitionAttempt:
        for members in sets_of(assignment):
            design_exactly(members)
        screened = screener.partition_retained(assignment, exact=False)
        exact = screener.partition_retained(assignment)
        attempts.append(PartitionAttempt(assignment, float(screened.min()), float(exact.min()), source))
        return attempts[-1]

    outcome = search_partition(screener, parts, config, progress)
    for _ in range(config.finger_sets.max):
        if any(a.assignment == outcome.assignment for a in attempts):
            break
        if attempt(outcome.assignment, "search").exact_worst >= threshold:
            break
        outcome = search_partition(screener, parts, config, progress)
    single = tuple([0] * parts)
    if max(a.exact_worst for a in attempts) < threshold and all(a.assignment != single for a in attempts):
        attempt(single, "one_finger")
    best = max(
        attempts, key=lambda a: partition_key(a.assignment, screener.partition_retained(a.assignment), threshold)
    )
    chosen = dataclasses.replace(
        outcome, assignment=best.assignment, retained=screener.partition_retained(best.assignment)
    )
    return chosen, attempts
