"""Screened quality of candidate finger sets: every scenario's solo quality E*, and a set's screened E (METHOD §11,
§8b).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..design import Prepared, evaluate_exact, screen_choice
from ..parallel import WorkerPool
from ..screen import screen
from ..search import candidate_index, search


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


def screen_set(
    prepared: Prepared, scenario_numbers: Sequence[int], pools: Sequence[np.ndarray], config: DesignConfig
) -> SetScreening:
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


class SetScreener:
    """Screened set designs of one job, cached by set, screened in batches over worker processes.

    Sets designed exactly (METHOD §11 revision 3) are judged by their exact
    retained qualities once :meth:`judge_exactly` has recorded them: the
    partition search then sees the exact figure, :meth:`screened_retained`
    still the screened one.

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

    def __init__(
        self,
        prepared: Prepared,
        part_scenarios: list[list[int]],
        solos: list[SoloQuality],
        config: DesignConfig,
        pool: WorkerPool,
    ):
        self.prepared = prepared
        self.part_scenarios = part_scenarios
        self.solos = solos
        self.config = config
        self.pool = pool
        self.cache: dict[frozenset[int], np.ndarray] = {}
        self.exact: dict[frozenset[int], np.ndarray] = {}

    def judge_exactly(self, members: frozenset[int], retained: np.ndarray) -> None:
        """Record a set's exact ``r = E / E*`` per scenario (its parts in order, their scenarios in order)."""
        self.exact[members] = np.asarray(retained, dtype=np.float64)

    def retained(self, sets: Sequence[frozenset[int]], exact: bool = True) -> list[dict[int, np.ndarray]]:
        """r of every scenario of every part, per set: ``{part: (scenarios,) r}``.

        Exact where the set was designed exactly and ``exact`` is true, screened otherwise.
        """
        known = self.exact if exact else {}
        fresh = list(dict.fromkeys(s for s in sets if s not in self.cache and s not in known))
        tasks = [tuple(m for p in sorted(s) for m in self.part_scenarios[p]) for s in fresh]
        for members, task, screening in zip(fresh, tasks, self.pool.map(_screen_set_task, tasks)):
            solo = np.array([self.solos[m].screened_best_mm2 for m in task])
            self.cache[members] = screening.effective_area_mm2 / np.where(solo > 0, solo, 1.0)
        result = []
        for members in sets:
            values, start = {}, 0
            figures = known.get(members, self.cache.get(members))
            for part in sorted(members):
                count = len(self.part_scenarios[part])
                values[part] = figures[start : start + count]
                start += count
            result.append(values)
        return result

    def partition_retained(self, assignment: Sequence[int], exact: bool = True) -> np.ndarray:
        """r of every graspable scenario (parts in order) under one partition, exact where known (``exact``)."""
        sets = sets_of(assignment)
        per_part: dict[int, np.ndarray] = {}
        for values in self.retained(sets, exact):
            per_part.update(values)
        return np.concatenate([per_part[p] for p in range(len(assignment))]) if assignment else np.zeros(0)


def sets_of(assignment: Sequence[int]) -> list[frozenset[int]]:
    """The sets of a partition (``assignment[p]`` is part ``p``'s set), as sets of parts."""
    return (
        [frozenset(p for p, a in enumerate(assignment) if a == label) for label in range(max(assignment) + 1)]
        if assignment
        else []
    )


def _screen_set_task(context, scenario_numbers: tuple[int, ...]) -> SetScreening:
    prepared, pools, config = context
    return screen_set(prepared, scenario_numbers, pools, config)
