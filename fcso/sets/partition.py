"""The split of a job's distinct parts into finger sets, searched under screening (METHOD §11)."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..progress import Progress
from .carving import carving_descriptors, farthest_point_order, nearest_neighbour_pairs
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
        ``"single_part"``, ``"exhaustive"``, ``"quick_screening+colouring+local_moves"`` (every pair screened) or
        ``"carving_neighbours+colouring+local_moves"`` (nearest pairs by carving).
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
        Distinct sets searched (:func:`screen_set`).
    fewest_sets_proven : bool
        By the figures the search used, the proposal reaches ``min_retained``
        and no partition reaching it has fewer sets: every partition was
        screened, or the proposal has as many sets as the certified conflict
        clique has parts (if a part never keeps more in a larger set).
    probed_parts : int
        Parts every pair of which was quick-screened (all parts, or the scaled search's most dissimilar ones).
    screened_pairs : int
        Pairs of parts quick-screened (the scaled search).
    unserved_by_truth : list of int
        Parts whose set's verified finger fails a scenario their own finger passes, left in that set (no set was
        left for them): not served (:func:`fcso.sets.judged.search_judged_exactly`'s ``truth``).
    moved_by_truth : list of int
        Parts such a verdict gave a set of their own.
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
    fewest_sets_proven: bool = False
    probed_parts: int = 0
    screened_pairs: int = 0
    unserved_by_truth: list[int] = dataclasses.field(default_factory=list)
    moved_by_truth: list[int] = dataclasses.field(default_factory=list)


def search_partition(screener: SetScreener, parts: int, config: DesignConfig, progress: Progress) -> PartitionOutcome:
    """Split ``parts`` parts into finger sets by the objective of METHOD §11, under screening.

    Up to ``[finger_sets] exhaustive_parts`` parts every partition into at
    most ``max`` sets is screened and the best taken (a proof under
    screening). Beyond, :func:`_scaled_search`: no step costs a set search
    per pair of parts.

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
    max_sets, threshold = settings.sets_allowed(parts), settings.min_retained

    def key(assignment: tuple[int, ...]) -> tuple:
        return partition_key(assignment, screener.partition_retained(assignment), threshold)

    if parts <= 1:
        assignment = tuple([0] * parts)
        return PartitionOutcome(
            assignment, screener.partition_retained(assignment), "single_part", True, {}, 1, [], None, [1], 0, True
        )
    if parts > settings.exhaustive_parts:
        return _scaled_search(screener, parts, config, progress)
    pairs = list(itertools.combinations(range(parts), 2))
    pair_values = screener.retained([frozenset(p) for p in pairs])
    pair_retained = {pair: (float(v[pair[0]].min()), float(v[pair[1]].min())) for pair, v in zip(pairs, pair_values)}
    conflicts = np.zeros((parts, parts), dtype=bool)
    for (i, j), values in pair_retained.items():
        conflicts[i, j] = conflicts[j, i] = min(values) < threshold
    clique = max_clique(conflicts)
    candidates = list(restricted_growth(parts, max_sets))
    progress("partition", 0, len(candidates), "every partition")
    screener.retained(list({s for a in candidates for s in sets_of(a)}))
    best = max(candidates, key=key)
    progress("partition", len(candidates), len(candidates), "every partition")
    return PartitionOutcome(
        assignment=best,
        retained=screener.partition_retained(best),
        method="exhaustive",
        proven=True,
        pair_retained=pair_retained,
        lower_bound_sets=max(1, len(clique)),
        conflict_clique=clique,
        worst_retained_bound=_clique_bound(clique, pair_retained, max_sets),
        sets_tried=sorted({max(a) + 1 for a in candidates}),
        set_screenings=len(screener.cache),
        fewest_sets_proven=key(best)[0] == 1,
    )


def _clique_bound(clique: list[int], pair_retained: dict, max_sets: int) -> float | None:
    """When more parts conflict pairwise than there are sets, two share one: no worst r above their best pair."""
    if len(clique) <= max_sets:
        return None
    return max(min(pair_retained[pair]) for pair in itertools.combinations(clique, 2))


#: Local moves tried per number of sets in the scaled search (a constant: the search stays linear in the parts).
_MOVES_PER_COUNT = 24
#: Best moves by the quick figure whose sets are searched to decide a move, once the sets in doubt are searched.
_SEARCHED_MOVES = 3
#: Least rise of the worst r that takes a searched move short of ``min_retained``: 1 % of a solo quality. Each such
#: move costs two set searches (seconds for sets of tens of parts), and a smaller rise is within screening's own error
#: (a set screened at 0.61 kept 0.32 designed exactly): at 60 parts the searched moves had spent 25 s raising the
#: worst r from 0.0006 to 0.0008.
_SEARCHED_MIN_GAIN = 0.01
#: Rounds of certifying the conflict clique by set searches before giving up the bound.
_CLIQUE_ROUNDS = 12
#: Parts probed pairwise for the conflict clique, per set allowed: the most dissimilar carvings (a constant).
PROBES_PER_SET = 2
#: Sets the scaled search probes for with ``[finger_sets] max = "auto"``: the default ``max``'s probes (the most
#: dissimilar parts are where conflicts are likeliest; the conflict clique grows beyond them by its own probes).
_AUTO_PROBED_SETS = 4
#: Pairs quick-screened between two progress reports.
_PAIRS_PER_PROGRESS = 2000


def _scaled_search(screener: SetScreener, parts: int, config: DesignConfig, progress: Progress) -> PartitionOutcome:
    """The partition search for many parts: a sparse conflict graph from quick screenings, set searches only where
    they leave doubt.

    1. Pairs of parts get a quick screening (:func:`quick_screen`: one
       candidate, each part's own best sample; one screening, not a set
       search): every pair while there are at most ``[finger_sets]
       pairs_per_part`` per part; beyond, each part is described by what it carves
       (:func:`carving_descriptors`) and only its ``pairs_per_part``
       nearest neighbours by carving are screened with it, plus every pair
       of the :data:`PROBES_PER_SET` x ``max`` most dissimilar parts
       (:func:`farthest_point_order`), where conflicts are likeliest. A
       screened pair that keeps ``min_retained`` is compatible (that
       candidate exists); the others are only suspected to conflict; an
       unscreened pair counts as the median screened pair when parts are
       placed.
    2. A clique of suspected conflicts, grown greedily (most suspected parts
       first), has each of its pairs searched as a set (:func:`screen_set`);
       pairs the search clears leave the clique and it is grown again. The
       clique that remains conflicts pairwise under screening: no partition
       reaching ``min_retained`` has fewer sets (if a part never keeps more
       of its quality in a larger set). With a sparse graph the clique is
       first grown by the parts most dissimilar to it whose quick pairs with
       all its parts are suspected (their pairs screened then, at most
       ``PROBES_PER_SET x max`` parts per round, until it exceeds ``max``);
       it is a lower bound among the screened pairs only.
    3. ``max`` sets first, then (only if they reach ``min_retained``) from
       the lower bound's number of sets up: parts go greedily, most suspected
       first, to the set they suit best, then parts of the worst scenario's
       set move while a move improves the objective (at most
       :data:`_MOVES_PER_COUNT` moves, judged by the best figure known for
       each set: exact, searched, else quick). Sets the quick figure leaves
       below ``min_retained`` are then searched, and the moves go on with the
       :data:`_SEARCHED_MOVES` best by the quick figure searched and deciding
       (a large set's quick figure is pessimistic and flat), taken only when
       they reach ``min_retained`` or raise the worst r. The fewest sets
       that reach ``min_retained`` are taken, else the best seen: when
       ``max`` sets miss it no other number is searched (if a part never
       keeps more in a larger set, a split into fewer sets refines into
       ``max`` sets that keep as much).

    Pair screenings grow linearly with the parts beyond ``2 pairs_per_part + 1`` of them; every other step costs
    quick screenings (a set's size each) or a bounded number of set searches.
    """
    settings = config.finger_sets
    threshold = settings.min_retained
    graph = _conflict_graph(screener, parts, config, progress)
    clique, pair_retained = _certified_clique(graph)
    lower = max(1, len(clique))
    screened = graph.compatibility[~np.isnan(graph.compatibility)]
    placing = np.nan_to_num(graph.compatibility, nan=float(np.median(screened)) if len(screened) else 1.0)
    best, tried = _partition_by_counts(screener, placing, lower, config, progress)
    return PartitionOutcome(
        assignment=best,
        retained=screener.partition_retained(best),
        method="quick_screening+colouring+local_moves"
        if graph.every_pair
        else "carving_neighbours+colouring+local_moves",
        proven=False,
        pair_retained=pair_retained,
        lower_bound_sets=lower,
        conflict_clique=sorted(clique),
        worst_retained_bound=_clique_bound(sorted(clique), pair_retained, settings.sets_allowed(parts)),
        sets_tried=tried,
        set_screenings=len(screener.cache),
        fewest_sets_proven=partition_key(best, screener.partition_retained(best), threshold)[0] == 1
        and max(best) + 1 == lower,
        probed_parts=len(graph.probes),
        screened_pairs=int((~np.isnan(graph.compatibility[np.triu_indices(parts, 1)])).sum()),
    )


@dataclass
class _ConflictGraph:
    """The pairs of parts :func:`_scaled_search` has screened and what they keep.

    Attributes
    ----------
    every_pair : bool
        Every pair is screened; else each part's nearest neighbours by carving and the probes' pairs.
    descriptors : ndarray or None
        What each part carves (:func:`carving_descriptors`), when not every pair is screened.
    probes : list of int
        The most dissimilar parts, every pair of which is screened.
    compatibility : (parts, parts) float
        Least retained of a screened pair (quick screening, raised by a set search); NaN where not screened.
    suspected : (parts, parts) bool
        Pairs suspected to conflict: screened and below ``min_retained``.
    """

    screener: SetScreener
    parts: int
    max_sets: int
    probed_sets: int
    threshold: float
    progress: Progress
    every_pair: bool
    descriptors: np.ndarray | None
    probes: list[int]
    compatibility: np.ndarray
    suspected: np.ndarray

    def quick_pairs(self, chosen: list[tuple[int, int]]) -> None:
        """Quick screenings of pairs ``chosen``, recorded."""
        if not chosen:
            return
        compatibility, suspected, progress = self.compatibility, self.suspected, self.progress
        # in chunks, so a large job's progress line and log move while the pairs are screened
        for start in range(0, len(chosen), _PAIRS_PER_PROGRESS):
            progress("pair conflicts", start, len(chosen), "quick screening")
            chunk = chosen[start : start + _PAIRS_PER_PROGRESS]
            for (i, j), values in zip(chunk, self.screener.quick([frozenset(p) for p in chunk])):
                compatibility[i, j] = compatibility[j, i] = min(float(values[i].min()), float(values[j].min()))
                suspected[i, j] = suspected[j, i] = compatibility[i, j] < self.threshold
        progress("pair conflicts", len(chosen), len(chosen), "quick screening")

    def extended(self, clique: list[int]) -> list[int]:
        """The clique grown by parts whose quick pairs with all its parts are suspected (sparse graph): candidates
        the most dissimilar to the clique first, at most PROBES_PER_SET x max of them, until it exceeds ``max``."""
        if self.every_pair or not clique:
            return clique
        descriptors, suspected, compatibility = self.descriptors, self.suspected, self.compatibility
        apart = np.min([np.linalg.norm(descriptors - descriptors[q], axis=1) for q in clique], axis=0)
        # parts already suspected of conflicts first (they conflict with more), then the most dissimilar to the clique
        degree = suspected.sum(axis=1)
        order = sorted(range(self.parts), key=lambda p: (-int(degree[p]), -float(apart[p]), p))
        candidates = [p for p in order if p not in clique]
        for part in candidates[: 2 * PROBES_PER_SET * self.probed_sets]:
            if len(clique) > self.max_sets:
                break
            self.quick_pairs([(min(part, q), max(part, q)) for q in clique if np.isnan(compatibility[part, q])])
            if all(suspected[part, q] for q in clique):
                clique = clique + [part]
        return sorted(clique)


def _conflict_graph(screener: SetScreener, parts: int, config: DesignConfig, progress: Progress) -> _ConflictGraph:
    """Step 1 of :func:`_scaled_search`: the pairs to screen, screened quickly."""
    settings = config.finger_sets
    max_sets = settings.sets_allowed(parts)
    probed_sets = _AUTO_PROBED_SETS if settings.max == "auto" else settings.max
    every_pair = parts - 1 <= 2 * settings.pairs_per_part
    descriptors = None
    if every_pair:
        pairs, probes = list(itertools.combinations(range(parts), 2)), list(range(parts))
    else:
        descriptors = carving_descriptors(screener)
        probes = sorted(farthest_point_order(descriptors, PROBES_PER_SET * probed_sets))
        pairs = sorted(
            nearest_neighbour_pairs(descriptors, settings.pairs_per_part) | set(itertools.combinations(probes, 2))
        )
    graph = _ConflictGraph(
        screener,
        parts,
        max_sets,
        probed_sets,
        settings.min_retained,
        progress,
        every_pair,
        descriptors,
        probes,
        np.full((parts, parts), np.nan),
        np.zeros((parts, parts), dtype=bool),
    )
    graph.quick_pairs(pairs)
    return graph


def _certified_clique(graph: _ConflictGraph) -> tuple[list[int], dict[tuple[int, int], tuple[float, float]]]:
    """Step 2 of :func:`_scaled_search`: a clique of suspected conflicts whose pairs set searches confirm (empty when
    none is certified within :data:`_CLIQUE_ROUNDS`), and every searched pair's retained qualities."""
    screener, threshold = graph.screener, graph.threshold
    compatibility, suspected = graph.compatibility, graph.suspected
    pair_retained: dict[tuple[int, int], tuple[float, float]] = {}
    clique: list[int] = []
    for _ in range(_CLIQUE_ROUNDS):
        clique = graph.extended(sorted(_greedy_clique(suspected)))
        unsure = [pair for pair in itertools.combinations(clique, 2) if pair not in pair_retained]
        for pair, values in zip(unsure, screener.retained([frozenset(p) for p in unsure])):
            pair_retained[pair] = (float(values[pair[0]].min()), float(values[pair[1]].min()))
            compatibility[pair] = compatibility[pair[::-1]] = np.fmax(compatibility[pair], min(pair_retained[pair]))
        cleared = [pair for pair in itertools.combinations(clique, 2) if min(pair_retained[pair]) >= threshold]
        if not cleared:
            break
        for i, j in cleared:
            suspected[i, j] = suspected[j, i] = False
    else:
        clique = []  # not certified within the rounds allowed: no bound claimed
    return clique, pair_retained


def _partition_by_counts(
    screener: SetScreener, placing: np.ndarray, lower: int, config: DesignConfig, progress: Progress
) -> tuple[tuple[int, ...], list[int]]:
    """Step 3 of :func:`_scaled_search`: partitions into ``max`` sets, then from ``lower`` sets up, placed greedily
    by ``placing`` (pairs' compatibility) and improved by moves; the best seen and the numbers of sets tried.

    With ``max = "auto"`` the first partition may use one set per part: the greedy placing opens a set only for a
    part no set suits, so it uses as many as the conflicts need; fewer are then tried from ``lower`` up to it.
    """
    settings = config.finger_sets
    max_sets, threshold = settings.sets_allowed(len(placing)), settings.min_retained

    def key(assignment: tuple[int, ...]) -> tuple:
        return partition_key(assignment, screener.partition_estimate(assignment), threshold)

    def searched_key(assignment: tuple[int, ...]) -> tuple:
        return partition_key(assignment, screener.partition_retained(assignment), threshold)

    tried, seen = [], []
    first = min(lower, max_sets)
    counts = [max_sets]
    step = max_sets - first + 1
    # max first: if max sets miss min_retained, fewer miss it too (a part never keeping more in a larger set, as the
    # lower bound assumes, a split into fewer sets refines into max sets keeping as much), so no other count is
    # searched; else the fewest sets from the lower bound up (with "auto", up to the sets the first partition used)
    for number, count in enumerate(counts):
        tried.append(count)
        progress("partition", number, step, f"{count} sets")

        def moved(
            move: int, assignment: tuple[int, ...], count: int = count, number: int = number, step: int = step
        ) -> None:
            worst = float(screener.partition_estimate(assignment).min())
            progress("partition", number, step, f"{count} sets: move {move}, worst retained {worst:.2f}")

        current = _greedy_assignment(placing, count, threshold)
        current = _improve(screener, current, count, key, _MOVES_PER_COUNT, moved)
        # screen in doubt: a set the quick figure leaves short gets its own search
        doubt = [
            s for s, values in zip(sets_of(current), screener.estimate(sets_of(current))) if _short(values, threshold)
        ]
        progress("partition", number, step, f"{count} sets: {len(doubt)} set searches")
        screener.retained(doubt)
        current = _improve(screener, current, count, key, _MOVES_PER_COUNT, moved, searched_key)
        seen.append(current)
        reached = searched_key(current)[0] == 1
        if reached != (count == max_sets):
            break
        if number == 0:
            counts.extend(range(first, max(current) + 1 if settings.max == "auto" else max_sets))
            step = len(counts)
    progress("partition", step, step, f"{tried[-1]} sets")
    return max(seen, key=searched_key), tried


def _short(values: dict[int, np.ndarray], threshold: float) -> bool:
    return min(float(v.min()) for v in values.values()) < threshold


def _greedy_clique(adjacent: np.ndarray) -> list[int]:
    """A clique grown greedily: vertices by decreasing degree (then index), each kept if adjacent to all kept."""
    order = sorted(range(len(adjacent)), key=lambda v: (-int(adjacent[v].sum()), v))
    clique: list[int] = []
    for vertex in order:
        if all(adjacent[vertex, other] for other in clique):
            clique.append(vertex)
    return clique


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
    screener: SetScreener,
    assignment: tuple[int, ...],
    max_sets: int,
    key,
    moves_allowed: int,
    on_move=None,
    searched_key=None,
) -> tuple[int, ...]:
    """Move parts of the worst set to other sets (or a new one) while a move improves the objective, at most
    ``moves_allowed`` moves; ``on_move(number, assignment)`` hears of each.

    Moves are ranked by ``key``; with ``searched_key``, the best :data:`_SEARCHED_MOVES` of them and the current
    partition are compared by it instead (their sets searched): the quick figure of a large set is pessimistic and
    flat, so it ranks moves but does not decide them. A searched move is taken only when it reaches
    ``min_retained`` or raises the worst r by :data:`_SEARCHED_MIN_GAIN`: each costs set searches of its two sets
    (seconds of CPU for sets of tens of parts), and the mean r, a tie-break of the objective, is left to the quick
    moves.
    """
    decide = searched_key or key
    current = assignment
    for number in range(moves_allowed):
        if on_move is not None:
            on_move(number, current)
        if decide(current)[0] == 1:
            return current
        retained = screener.partition_estimate(current)
        moves = []
        for part in _worst_parts(screener, current, retained):
            for label in range(min(max(current) + 2, max_sets)):
                if label != current[part]:
                    moved = list(current)
                    moved[part] = label
                    moves.append(canonical_assignment(moved))
        moves = [m for m in dict.fromkeys(moves) if m != current]
        if not moves:
            return current
        screener.estimate(list({s for m in moves for s in sets_of(m)}))
        ranked = sorted(moves, key=key, reverse=True)[: _SEARCHED_MOVES if searched_key else 1]
        if searched_key:
            screener.retained(list({s for m in ranked for s in sets_of(m)}))
        best = max(ranked, key=decide)
        if searched_key:
            # current misses min_retained (else returned above): the objective's next term is the worst r
            gained = decide(best)[0] == 1 or decide(best)[1] >= decide(current)[1] + _SEARCHED_MIN_GAIN
        else:
            gained = decide(best) > decide(current)
        if not gained:
            return current
        current = best
    return current


def _worst_parts(screener: SetScreener, assignment: tuple[int, ...], retained: np.ndarray, count: int = 3) -> list[int]:
    """The ``count`` parts of the set holding the worst scenario, by their worst r."""
    owners = np.concatenate([[p] * len(screener.part_scenarios[p]) for p in range(len(assignment))]).astype(int)
    worst_set = assignment[owners[int(np.argmin(retained))]]
    members = [p for p in range(len(assignment)) if assignment[p] == worst_set]
    return sorted(members, key=lambda p: (float(retained[owners == p].min()), p))[:count]
