"""Finger sets: a job's parts split over a few fingers (METHOD §11).

A finger designed for every part of a batch carves every part's pocket into
one pad and can bury one part's contact under another's carving. Here the
distinct parts of a job are partitioned into at most ``[finger_sets] max``
sets, each served by its own finger designed by METHOD §1-9 for that set
alone, so that every graspable scenario keeps ``retained = E / E*`` of its
solo quality ``E*``.

Sampling and pad geometries depend on a scenario alone, so they are made
once for the whole job (:func:`fcso.design.prepare`); the partition search
only screens candidate sets (:func:`screen_set`) and the chosen sets are
designed exactly (:func:`fcso.design.design_prepared`). Every quality is an
effective area E in mm²; retained qualities are ratios (0..1).
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from . import __version__
from .config import DesignConfig
from .design import DesignResult, Prepared, _part_report, design, design_prepared, evaluate_exact, prepare, screen_choice, subset
from .errors import NoGraspError
from .parallel import WorkerPool
from .parts import Part, load_parts
from .report import UngraspableReport
from .screen import screen
from .search import candidate_index, search
from .sets_report import (
    FingerSetReport,
    FingerSetsReport,
    IdenticalPartsReport,
    JobReport,
    PairConflictReport,
    PartitionSearchReport,
    PickPart,
    PickStep,
    SetScenarioReport,
)

#: ``progress(stage, done, total, note)`` as for :func:`fcso.design.design`.
Progress = Callable[[str, int, int, str], None]

#: Largest distance between matching vertices of identical parts, mm (STL stores float32: ~1e-5 mm at 100 mm).
SAME_GEOMETRY_TOLERANCE_MM = 1e-3


def same_geometry(a: trimesh.Trimesh, b: trimesh.Trimesh, tolerance_mm: float = SAME_GEOMETRY_TOLERANCE_MM) -> bool:
    """Whether two parts have the same geometry up to a translation.

    Parameters
    ----------
    a, b : trimesh.Trimesh
        Parts in mm, after units and shell union (:func:`fcso.load_parts`).
    tolerance_mm : float
        Every vertex of each, moved so the bounding boxes' minimum corners
        meet, lies within this distance of a vertex of the other.

    Returns
    -------
    bool
        Equal face counts, volumes within 10⁻⁶ relative and matching vertices.
        Rotated copies are not the same: they rest differently and are
        designed as parts of their own.
    """
    if len(a.faces) != len(b.faces) or len(a.vertices) != len(b.vertices):
        return False
    if not np.isclose(a.volume, b.volume, rtol=1e-6, atol=1e-6):
        return False
    va = np.asarray(a.vertices) - np.asarray(a.vertices).min(axis=0)
    vb = np.asarray(b.vertices) - np.asarray(b.vertices).min(axis=0)
    return bool(cKDTree(vb).query(va)[0].max() <= tolerance_mm and cKDTree(va).query(vb)[0].max() <= tolerance_mm)


def identical_groups(meshes: Sequence[trimesh.Trimesh]) -> list[list[int]]:
    """Indices of the meshes grouped by :func:`same_geometry`, groups and members in input order."""
    groups: list[list[int]] = []
    for index, mesh in enumerate(meshes):
        group = next((g for g in groups if same_geometry(meshes[g[0]], mesh)), None)
        if group is None:
            groups.append([index])
        else:
            group.append(index)
    return groups


@dataclass
class SoloQuality:
    """A scenario designed alone (METHOD §11).

    Attributes
    ----------
    screened_mm2 : (N,) float
        Screened E of each valid sample as the scenario's only sample, mm².
    screened_best_mm2 : float
        Their maximum: the screened ``E*``, mm².
    exact_mm2 : float
        ``E*``: the best exact E among the ``search.exact_top_k`` best screened samples, mm².
    sample : int
        The sample giving ``E*``.
    """

    screened_mm2: np.ndarray
    screened_best_mm2: float
    exact_mm2: float
    sample: int


def solo_quality(prepared: Prepared, scenario_number: int, config: DesignConfig) -> SoloQuality:
    """``E*`` of one scenario: every sample screened alone, the best re-evaluated exactly (METHOD §8b, §11).

    Parameters
    ----------
    prepared : Prepared
        The whole job (samples and pad geometries of every scenario).
    scenario_number : int
        Position in ``prepared.scenarios``.
    config : DesignConfig

    Returns
    -------
    SoloQuality
        Ties of exact E go to the sample screened better, then the smaller index.
    """
    alone = dataclasses.replace(prepared, scenarios=[prepared.scenarios[scenario_number]])
    count = len(alone.scenarios[0].samples)
    screened = np.array([screen_choice(alone, (k,), config).quality for k in range(count)], dtype=np.float64)
    finalists = np.argsort(-screened, kind="stable")[: config.search.exact_top_k]
    exact = [evaluate_exact(alone, (int(k),), config).quality for k in finalists]
    best = int(np.argmax(exact))
    return SoloQuality(screened, float(screened.max()) if count else 0.0, float(exact[best]), int(finalists[best]))


def screening_pools(solos: Sequence[SoloQuality], size: int) -> list[np.ndarray]:
    """Per scenario, the ``size`` samples with the best solo screened E, in increasing sample order."""
    return [np.sort(np.argsort(-s.screened_mm2, kind="stable")[:size]) for s in solos]


@dataclass
class SetScreening:
    """A candidate finger set screened (METHOD §8b) during the partition search.

    Attributes
    ----------
    scenarios : tuple of int
        Scenario numbers of the set (job numbering).
    choice : tuple of int
        The best screened candidate: one sample per scenario (job sample numbering).
    effective_area_mm2 : (n,) float
        Its screened E per scenario, mm².
    evaluated : int
        Candidates screened.
    """

    scenarios: tuple[int, ...]
    choice: tuple[int, ...]
    effective_area_mm2: np.ndarray
    evaluated: int


def screen_set(prepared: Prepared, scenario_numbers: Sequence[int], pools: Sequence[np.ndarray], config: DesignConfig) -> SetScreening:
    """Screen the design of one finger set over each scenario's pool of samples.

    The search (:func:`fcso.search.search`) maximises the screened Q, as the
    set's own design will, ties by mean E then candidate index, within
    ``[finger_sets] screen_evaluations`` screened candidates.

    Parameters
    ----------
    prepared : Prepared
    scenario_numbers : sequence of int
        The set's scenarios.
    pools : sequence of (k,) int
        Per job scenario, the samples to choose from (:func:`screening_pools`).
    config : DesignConfig

    Returns
    -------
    SetScreening
    """
    scenario_numbers = tuple(scenario_numbers)
    samples = [[prepared.scenarios[m].samples[int(k)] for k in pools[m]] for m in scenario_numbers]
    counts = [len(s) for s in samples]
    bounds = [np.array([g.screened_bound for g in s]) for s in samples]

    def screened(choice: tuple[int, ...]):
        return screen([samples[i][k].screen for i, k in enumerate(choice)], config, prepared.lattice)

    def evaluate(choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
        return [(c.quality, c.mean_effective_area) for c in map(screened, choices)]

    budget = config.finger_sets.screen_evaluations
    outcome = search(counts, bounds, evaluate, budget, budget)
    best = max(outcome.evaluated, key=lambda c: (*outcome.evaluated[c], -candidate_index(c, counts)))
    areas = np.array([s.effective_area for s in screened(best).scenarios], dtype=np.float64)
    choice = tuple(int(pools[m][k]) for m, k in zip(scenario_numbers, best))
    return SetScreening(scenario_numbers, choice, areas, len(outcome.evaluated))


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
    """Every partition of ``parts`` items into at most ``max_sets`` sets, as canonical assignments in lexicographic order."""
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
        Screened ``r`` of every graspable scenario in its set.
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


class SetScreener:
    """Screened set designs of one job, cached by set, screened in batches over worker processes.

    Parameters
    ----------
    prepared : Prepared
    part_scenarios : list of list of int
        Graspable scenario numbers of every part (job part order).
    solos : list of SoloQuality
        Per job scenario.
    config : DesignConfig
    pool : WorkerPool
        Whose context is ``(prepared, pools, config)``.
    """

    def __init__(self, prepared: Prepared, part_scenarios: list[list[int]], solos: list[SoloQuality], config: DesignConfig, pool: WorkerPool):
        self.prepared = prepared
        self.part_scenarios = part_scenarios
        self.solos = solos
        self.config = config
        self.pool = pool
        self.cache: dict[frozenset[int], np.ndarray] = {}

    def retained(self, sets: Sequence[frozenset[int]]) -> list[dict[int, np.ndarray]]:
        """Screened r of every scenario of every part, per set: ``{part: (scenarios,) r}``."""
        fresh = list(dict.fromkeys(s for s in sets if s not in self.cache))
        tasks = [tuple(m for p in sorted(s) for m in self.part_scenarios[p]) for s in fresh]
        for members, task, screening in zip(fresh, tasks, self.pool.map(_screen_set_task, tasks)):
            solo = np.array([self.solos[m].screened_best_mm2 for m in task])
            self.cache[members] = screening.effective_area_mm2 / np.where(solo > 0, solo, 1.0)
        result = []
        for members in sets:
            values, start = {}, 0
            for part in sorted(members):
                count = len(self.part_scenarios[part])
                values[part] = self.cache[members][start : start + count]
                start += count
            result.append(values)
        return result

    def partition_retained(self, assignment: Sequence[int]) -> np.ndarray:
        """Screened r of every graspable scenario (parts in order) under one partition."""
        sets = _sets_of(assignment)
        per_part: dict[int, np.ndarray] = {}
        for values in self.retained(sets):
            per_part.update(values)
        return np.concatenate([per_part[p] for p in range(len(assignment))]) if assignment else np.zeros(0)


def _sets_of(assignment: Sequence[int]) -> list[frozenset[int]]:
    return [frozenset(p for p, a in enumerate(assignment) if a == label) for label in range(max(assignment) + 1)] if assignment else []


def _screen_set_task(context, scenario_numbers: tuple[int, ...]) -> SetScreening:
    prepared, pools, config = context
    return screen_set(prepared, scenario_numbers, pools, config)


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
        screener.retained(list({s for a in candidates for s in _sets_of(a)}))
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
    """Most conflicted parts first, each to the set whose worst pair with it is best (a new set while any is left and none is good enough)."""
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


def _improve(screener: SetScreener, assignment: tuple[int, ...], max_sets: int, threshold: float, key) -> tuple[int, ...]:
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
        screener.retained(list({s for m in moves for s in _sets_of(m)}))
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
class SetsResult:
    """What :func:`design_sets` returns.

    Attributes
    ----------
    designs : list of DesignResult
        One finger design per set, set order.
    report : FingerSetsReport or None
        The sets and the pick plan; None with ``[finger_sets] max = 1``.
    job_report : JobReport or None
        The job's ``report.json`` with two or more sets; with one, the
        design's own report (``designs[0].report``, whose ``finger_sets`` is ``report``).
    """

    designs: list[DesignResult]
    report: FingerSetsReport | None
    job_report: JobReport | None


def design_sets(
    parts: Sequence[Part | str | Path], config: DesignConfig | None = None, progress: Progress | None = None, repair: bool = False
) -> SetsResult:
    """Design the finger sets of a job (METHOD §11): at most ``[finger_sets] max`` fingers for its parts.

    Identical parts are designed once. Every scenario's solo quality ``E*``
    is found (:func:`solo_quality`), the distinct parts are partitioned
    (:func:`search_partition`, under screening), and every set's finger is
    designed exactly by METHOD §1-9 for that set alone
    (:func:`fcso.design.design_prepared`).

    Parameters
    ----------
    parts, config, progress, repair
        As for :func:`fcso.design.design`.

    Returns
    -------
    SetsResult
        With ``[finger_sets] max = 1``, exactly :func:`fcso.design.design` of every part.

    Raises
    ------
    MeshError, ConfigError, NoGraspError
        As :func:`fcso.design.design`; NoGraspError also when no scenario keeps any contact.
    """
    config = config or DesignConfig()
    if config.finger_sets.max == 1:
        return SetsResult([design(parts, config, progress=progress, repair=repair)], None, None)
    report_progress = progress or (lambda stage, done, total, note="": None)
    clock = time.perf_counter()
    loaded = [
        one
        for p in parts
        for one in ([p] if isinstance(p, Part) else load_parts(p, repair=repair, split_bodies=config.parts.split_bodies))
    ]
    groups = identical_groups([p.mesh for p in loaded])
    unique = [loaded[g[0]] for g in groups]
    dedup_s = time.perf_counter() - clock
    prepared = prepare(unique, config, progress=progress, repair=repair)
    warnings = list(prepared.warnings)
    timings = dict(prepared.timings_s, identical_parts=dedup_s)
    for group in groups:
        if len(group) > 1:
            names = ", ".join(loaded[i].name for i in group)
            warnings.append(f"{names} have the same geometry: designed once as {loaded[group[0]].name}")

    clock = time.perf_counter()
    report_progress("solo quality", 0, len(prepared.scenarios), "")
    # no more workers than tasks: forking costs more than one small task
    with WorkerPool((prepared, config), min(prepared.jobs, len(prepared.scenarios))) as pool:
        solos = pool.map(_solo_task, list(range(len(prepared.scenarios))))
    report_progress("solo quality", len(prepared.scenarios), len(prepared.scenarios), "")
    timings["solo_quality"] = time.perf_counter() - clock
    ungraspable = list(prepared.ungraspable)
    for number, (scenario, solo) in enumerate(zip(prepared.scenarios, solos)):
        if solo.exact_mm2 <= 0:
            ungraspable.append(_zero_quality_report(scenario))
            warnings.append(f"{scenario.part.name} in stable pose {scenario.pose_index} keeps no contact with any pad and is left out")
    part_scenarios = [
        [m for m, s in enumerate(prepared.scenarios) if s.part_index == u and solos[m].exact_mm2 > 0] for u in range(len(unique))
    ]
    graspable = [u for u in range(len(unique)) if part_scenarios[u]]
    if not graspable:
        raise NoGraspError("no scenario of the job keeps any contact with a pad: " + "; ".join(f"{u.part} pose {u.pose_index}" for u in ungraspable))

    clock = time.perf_counter()
    pools = screening_pools(solos, config.finger_sets.screen_samples)
    # one part has one partition: nothing to screen in parallel
    with WorkerPool((prepared, pools, config), prepared.jobs if len(graspable) > 1 else 1) as pool:
        screener = SetScreener(prepared, [part_scenarios[u] for u in graspable], solos, config, pool)
        outcome = search_partition(screener, len(graspable), config, lambda stage, done, total, note="": report_progress(stage, done, total, note))
    timings["partition"] = time.perf_counter() - clock

    clock = time.perf_counter()
    labels = max(outcome.assignment) + 1
    designs, members = [], []
    for label in range(labels):
        chosen = [graspable[p] for p, a in enumerate(outcome.assignment) if a == label]
        numbers = sorted(m for u in chosen for m in part_scenarios[u])
        report_progress("finger sets", label, labels, f"set {label + 1} of {labels}")
        made = design_prepared(subset(prepared, numbers), config, progress)
        # every grasp says which finger set makes it
        made.report = made.report.model_copy(update={"grasps": [g.model_copy(update={"finger_set": label + 1}) for g in made.report.grasps]})
        designs.append(made)
        members.append((chosen, numbers))
    report_progress("finger sets", labels, labels, "")
    timings["finger_sets"] = time.perf_counter() - clock
    screened = dict(zip([m for p in range(len(graspable)) for m in part_scenarios[graspable[p]]], outcome.retained))
    sets_report = _sets_report(
        prepared, loaded, groups, solos, designs, members, outcome, graspable, screened, ungraspable, config
    )
    timings = {k: round(v, 3) for k, v in timings.items()}
    if labels == 1:
        design_report = designs[0].report
        designs[0].report = design_report.model_copy(
            update={
                "parts": [_part_report(p) for p in unique],
                "ungraspable": ungraspable,
                "warnings": warnings + design_report.warnings,
                "timings_s": dict(timings, **design_report.timings_s),
                "finger_sets": sets_report,
            }
        )
        return SetsResult(designs, sets_report, None)
    set_warnings = [f"set {k}: {w}" for k, d in enumerate(designs, start=1) for w in d.report.warnings]
    job = JobReport(
        fcso_version=__version__,
        parts=[_part_report(p) for p in unique],
        finger_sets=sets_report,
        timings_s=timings,
        warnings=warnings + set_warnings,
        settings=config,
    )
    return SetsResult(designs, sets_report, job)


def _solo_task(context, number: int) -> SoloQuality:
    prepared, config = context
    return solo_quality(prepared, number, config)


def _zero_quality_report(scenario) -> UngraspableReport:
    result = scenario.sampler_result
    return UngraspableReport(
        part=scenario.part.name,
        pose_index=scenario.pose_index,
        pose_probability=round(float(scenario.probability), 6),
        tried_samples=result.tried,
        rejected=dict(result.rejected),
        reason="every valid sample loses all contact when its pad is carved and the part seated (E* = 0)",
    )


def _ratio(value: float, reference: float) -> float:
    return round(float(value) / float(reference), 6)


def _sets_report(prepared, loaded, groups, solos, designs, members, outcome, graspable, screened, ungraspable, config) -> FingerSetsReport:
    """The report of the sets, their scenarios, identical parts and the pick plan."""
    settings = config.finger_sets
    several = len(designs) > 1
    exact: dict[int, tuple[int, float]] = {}
    sets, pick_plan = [], []
    for label, (design_result, (chosen, numbers)) in enumerate(zip(designs, members), start=1):
        areas = design_result.report.print_fit.exact.effective_area
        for m, area in zip(numbers, areas):
            exact[m] = (label, area)
        retained = [area / solos[m].exact_mm2 for m, area in zip(numbers, areas)]
        folder = f"set-{label}" if several else "."
        sets.append(
            FingerSetReport(
                set=label,
                folder=folder,
                parts=[prepared.parts[u].name for u in chosen],
                quality=round(design_result.best.quality, 6),
                worst_retained=round(min(retained), 6),
                mean_retained=round(float(np.mean(retained)), 6),
                pad_case=design_result.best.case,
            )
        )
        grasps = dict(zip(numbers, design_result.report.grasps))
        pick_plan.append(
            PickStep(
                set=label,
                finger=f"{folder}/finger.stl" if several else "finger.stl",
                parts=[
                    PickPart(
                        part=prepared.parts[u].name,
                        copies=[loaded[i].name for i in groups[u]],
                        quantity=sum(len(loaded[i].instances) for i in groups[u]),
                        grasps=[grasps[m] for m in numbers if prepared.scenarios[m].part_index == u],
                    )
                    for u in chosen
                ],
            )
        )
    scenarios = []
    for m, scenario in enumerate(prepared.scenarios):
        label, area = exact.get(m, (None, 0.0))
        star = solos[m].exact_mm2
        scenarios.append(
            SetScenarioReport(
                part=scenario.part.name,
                pose_index=scenario.pose_index,
                set=label,
                effective_area=round(float(area), 6),
                solo_effective_area=round(star, 6),
                retained=_ratio(area, star) if star > 0 else None,
                screened_retained=round(float(screened[m]), 6) if m in screened else None,
            )
        )
    for entry in prepared.ungraspable:
        scenarios.append(SetScenarioReport(part=entry.part, pose_index=entry.pose_index, set=None, effective_area=0.0, solo_effective_area=0.0, retained=None, screened_retained=None))
    kept = [s.retained for s in scenarios if s.retained is not None]
    served = {prepared.parts[u].name for u in graspable}
    names = [prepared.parts[u].name for u in graspable]
    pairs = sorted(outcome.pair_retained.items())
    blocking = [
        PairConflictReport(parts=[names[i], names[j]], retained=[round(a, 6), round(b, 6)])
        for (i, j), (a, b) in pairs
        if min(a, b) < settings.min_retained
    ]
    reached = min(kept) >= settings.min_retained
    return FingerSetsReport(
        max_sets=settings.max,
        min_retained=settings.min_retained,
        sets=sets,
        scenarios=scenarios,
        worst_retained=round(min(kept), 6),
        median_retained=round(float(np.median(kept)), 6),
        min_retained_reached=reached,
        identical_parts=[
            IdenticalPartsReport(
                part=loaded[g[0]].name, copies=[loaded[i].name for i in g], quantity=sum(len(loaded[i].instances) for i in g)
            )
            for g in groups
            if len(g) > 1
        ],
        ungraspable_parts=[p.name for p in prepared.parts if p.name not in served],
        ungraspable=ungraspable,
        pick_plan=pick_plan,
        search=PartitionSearchReport(
            method=outcome.method,
            description=_search_description(outcome, len(graspable), settings),
            proven=outcome.proven,
            sets_tried=outcome.sets_tried,
            set_screenings=outcome.set_screenings,
            lower_bound_sets=outcome.lower_bound_sets,
            conflict_clique=[names[i] for i in outcome.conflict_clique],
            worst_retained_bound=None if outcome.worst_retained_bound is None else round(outcome.worst_retained_bound, 6),
            blocking_pairs=blocking,
            explanation=None if reached else _explanation(scenarios, blocking, outcome, names, settings),
        ),
    )


def _search_description(outcome: PartitionOutcome, parts: int, settings) -> str:
    if outcome.method == "single_part":
        return "one distinct graspable part: one finger set"
    if outcome.method == "exhaustive":
        return (
            f"every partition of the {parts} distinct parts into at most {settings.max} sets was screened "
            f"({outcome.set_screenings} distinct sets): the chosen one is the best under screening; its sets were then designed exactly"
        )
    clique = len(outcome.conflict_clique)
    return (
        f"the {parts * (parts - 1) // 2} pairs of parts were screened as sets; the largest group of pairwise conflicting parts "
        f"has {clique} parts, so no partition reaching min_retained = {settings.min_retained:g} has fewer than {outcome.lower_bound_sets} sets "
        f"(if a part never keeps more of its quality in a larger set); for {', '.join(map(str, outcome.sets_tried))} sets, parts were "
        f"placed greedily (most conflicted first, with the parts they conflict with least) and the worst set's parts moved while the "
        f"objective improved ({outcome.set_screenings} distinct sets screened); not proven optimal"
    )


def _explanation(scenarios, blocking, outcome: PartitionOutcome, names, settings) -> str:
    worst = min((s for s in scenarios if s.retained is not None), key=lambda s: s.retained)
    words = [f"{worst.part} in stable pose {worst.pose_index} keeps {worst.retained:.2f} of its solo quality in set {worst.set}"]
    if len(outcome.conflict_clique) > settings.max:
        group = ", ".join(names[i] for i in outcome.conflict_clique)
        words.append(f"parts {group} conflict pairwise: they need {len(outcome.conflict_clique)} sets, more than max = {settings.max}")
    if blocking:
        pairs = "; ".join(f"{b.parts[0]} + {b.parts[1]} ({b.retained[0]:.2f}, {b.retained[1]:.2f})" for b in blocking[:8])
        words.append(f"pairs that cannot share a finger (screened retained of each): {pairs}")
    if worst.screened_retained is not None and worst.screened_retained >= settings.min_retained:
        words.append(f"under screening it kept {worst.screened_retained:.2f}: the exact design keeps less")
    return "; ".join(words)
