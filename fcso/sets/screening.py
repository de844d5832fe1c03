"""Screened quality of candidate finger sets: every scenario's solo quality E*, and a set's screened E (METHOD §11,
§8b).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..evaluate import screen_on_pad
from ..parallel import WorkerPool
from ..pipeline import Prepared, evaluate_exact, screen_choice, subset
from ..screen import screen
from ..search import rerank, search

#: Landscapes the quick screenings of this process squeezed (:meth:`fcso.capture.CandidateSqueeze.known_landscape`),
#: at most :data:`_QUICK_LANDSCAPES_KEPT` (7 kB each): a set with a part moved in or out keeps most of its members' pad
#: where they meet it, and the partition's moves screen many such sets.
_QUICK_LANDSCAPES: dict = {}
_QUICK_LANDSCAPES_KEPT = 4096
#: Scenarios quick-screened per worker task: each measures its holding (six linear programs, 0.1-0.3 s, unless its
#: sample held the same contacts before), so a few make a task of a second or so and the workers share the pairs.
_QUICK_SCENARIOS_PER_TASK = 8


@dataclass
class SoloQuality:
    """A scenario designed alone (METHOD §11): its qualities are E in mm² under the paper's measure, METHOD §7b's
    measure (no unit) under the capture measure, as METHOD §11 reads ``E`` "as that scenario quality".

    Attributes
    ----------
    screened : (N,) float
        Screened quality of each valid sample as the scenario's only sample.
    screened_best : float
        The screened ``E*``: the best of the ``search.exact_top_k`` best
        screened samples with their holding measured
        (:func:`fcso.evaluate.screen_on_pad`), as a set's screening measures
        its finalists.
    exact : float
        ``E*``: the best exact quality (as printed) among the ``search.exact_top_k`` best screened samples.
    sample : int
        The sample giving ``E*``.
    held : dict
        Per sample index, the holding shares its finalists' screenings
        measured (:attr:`fcso.evaluate.SampleGeometry.held`), for the
        process that forks the next workers: a part's contacts in a pair are
        often its contacts alone, and holding is six linear programmes.
    """

    screened: np.ndarray
    screened_best: float
    exact: float
    sample: int
    held: dict[int, dict[tuple, float]] = dataclasses.field(default_factory=dict, repr=False)


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
    # the screened E* with holding, as a set's screening measures its finalists: the best sample may hold nothing
    # a sample's capture on its own pad is the one it was prepared with
    held = [
        screen_on_pad(
            alone.scenarios,
            (int(k),),
            config,
            prepared.lattice,
            True,
            [alone.scenarios[0].samples[k].screen[0].capture],
        ).quality
        for k in finalists
    ]
    samples = alone.scenarios[0].samples
    return SoloQuality(
        screened,
        float(max(held, default=0.0)),
        float(exact[best]),
        int(finalists[best]),
        {int(k): dict(samples[k].held) for k in finalists if samples[k].held},
    )


def keep_held(prepared: Prepared, held: dict[tuple[int, int], dict[tuple, float]]) -> None:
    """Record holding shares measured in worker processes on ``prepared``'s samples (``(scenario, sample)`` keys).

    Workers forked later, and a Dask cluster's context sent later, start with them: the same contacts are not
    measured again. A share depends only on its key (the contacts and settings), so a design is the same with or
    without them.
    """
    for (number, index), entries in held.items():
        prepared.scenarios[number].samples[index].held.update(entries)


def screening_pools(solos: Sequence[SoloQuality], size: int) -> list[np.ndarray]:
    """Per scenario, the ``size`` samples with the best solo screened E, in increasing sample order."""
    return [np.sort(np.argsort(-s.screened, kind="stable")[:size]) for s in solos]


@dataclass
class SetScreening:
    """A candidate finger set screened (METHOD §8b) during the partition search.

    Attributes
    ----------
    scenarios : tuple of int
        Scenario numbers of the set (job numbering).
    choice : tuple of int
        The best screened candidate: one sample per scenario (job sample numbering).
    quality : (n,) float
        Its screened quality per scenario (E in mm² under the paper's measure, METHOD §7b's measure otherwise).
    evaluated : int
        Candidates screened.
    """

    scenarios: tuple[int, ...]
    choice: tuple[int, ...]
    quality: np.ndarray
    evaluated: int


def screen_set(
    prepared: Prepared, scenario_numbers: Sequence[int], pools: Sequence[np.ndarray], config: DesignConfig
) -> SetScreening:
    """Screen the design of one finger set over each scenario's pool of samples.

    The search (:func:`fcso.search.search`) maximises the screened Q, as the
    set's own design will, ties by mean E then candidate index, within
    ``[finger_sets] screen_evaluations`` screened candidates; its
    ``[search] pad_top_k`` best are screened again on the set's pad
    (:func:`fcso.evaluate.screen_on_pad`, as the set's design does), the
    ``exact_top_k`` best of those with holding too, and the best of them is
    the set's.

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

    scenarios = [prepared.scenarios[m] for m in scenario_numbers]
    # the candidates screened on their pads share most samples: each is squeezed once (fcso.capture.sample_part)
    # and a candidate whose carving is another's bit for bit is squeezed on its pad only where its samples are new
    squeezed: dict = {}
    landscapes: dict = {}

    def on_pad(choice: tuple[int, ...], holding: bool = False, captures: list[float] | None = None):
        numbers = tuple(int(pools[m][k]) for m, k in zip(scenario_numbers, choice))
        return screen_on_pad(scenarios, numbers, config, prepared.lattice, holding, captures, squeezed, landscapes)

    budget = config.finger_sets.screen_evaluations
    outcome = search(counts, bounds, evaluate, budget, budget)
    ranked = rerank(list(outcome.evaluated), outcome.evaluated, counts)
    # the search ranked by each sample's own capture and full holding: its best are screened on the set's pad, the
    # best of those with holding too, as the set's design re-evaluates its exact_top_k
    top = {c: on_pad(c) for c in ranked[: config.search.pad_top_k]}
    ranked = rerank(ranked, {c: (s.quality, s.mean_effective_area) for c, s in top.items()}, counts)
    # the pad_top_k were screened on their pads: their captures stand, only holding is new
    held = {
        c: on_pad(c, True, [s.capture for s in top[c].scenarios] if c in top else None)
        for c in ranked[: config.search.exact_top_k]
    }
    best = rerank(ranked, {c: (s.quality, s.mean_effective_area) for c, s in held.items()}, counts)[0]
    areas = np.array([s.measure for s in held[best].scenarios], dtype=np.float64)
    choice = tuple(int(pools[m][k]) for m, k in zip(scenario_numbers, best))
    return SetScreening(scenario_numbers, choice, areas, len(outcome.evaluated))


def quick_screen(
    prepared: Prepared, scenario_numbers: Sequence[int], picks: Sequence[int], config: DesignConfig
) -> np.ndarray:
    """Screened E of one candidate of a set: every scenario's own best sample, on the set's pad with holding.

    Parameters
    ----------
    prepared : Prepared
    scenario_numbers : sequence of int
        The set's scenarios.
    picks : sequence of int
        Per job scenario, its sample of best solo screened E.
    config : DesignConfig

    Returns
    -------
    (n,) float
        Screened E per scenario, mm²: a candidate the set's search could
        choose, so the set can keep at least this much of each.
    """
    scenarios = [prepared.scenarios[m] for m in scenario_numbers]
    if len(_QUICK_LANDSCAPES) > _QUICK_LANDSCAPES_KEPT:
        _QUICK_LANDSCAPES.clear()
    choice = tuple(picks[m] for m in scenario_numbers)
    screened = screen_on_pad(scenarios, choice, config, prepared.lattice, True, landscapes=_QUICK_LANDSCAPES)
    return np.array([s.measure for s in screened.scenarios], dtype=np.float64)


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
        Whose context is ``(prepared, pools, solo_picks(solos), config)``.
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
        #: the candidate (job sample numbers, the set's scenarios in order) whose r ``cache`` holds
        self.choices: dict[frozenset[int], tuple[int, ...]] = {}
        self.picks = solo_picks(solos)
        self.quick_cache: dict[frozenset[int], np.ndarray] = {}
        self.exact: dict[frozenset[int], np.ndarray] = {}
        #: holding shares the workers measured since the screener began, by (scenario, sample): sent with the quick
        #: screenings of those samples, so a worker forked earlier does not measure what the other one did
        self.learned: dict[tuple[int, int], dict[tuple, float]] = {}

    def _scenarios(self, members: frozenset[int]) -> tuple[int, ...]:
        return tuple(m for p in sorted(members) for m in self.part_scenarios[p])

    def _ratios(self, members: frozenset[int], areas: np.ndarray) -> np.ndarray:
        solo = np.array([self.solos[m].screened_best for m in self._scenarios(members)])
        return np.asarray(areas, dtype=np.float64) / np.where(solo > 0, solo, 1.0)

    def _per_part(self, members: frozenset[int], figures: np.ndarray) -> dict[int, np.ndarray]:
        values, start = {}, 0
        for part in sorted(members):
            count = len(self.part_scenarios[part])
            values[part] = figures[start : start + count]
            start += count
        return values

    def quick(self, sets: Sequence[frozenset[int]]) -> list[dict[int, np.ndarray]]:
        """Quick r of every scenario of every part, per set (:func:`quick_screen`), batched over the workers."""
        fresh = list(dict.fromkeys(s for s in sets if s not in self.quick_cache))
        tasks = [self._scenarios(s) for s in fresh]
        # batched so a task carries well over ~100 ms and every worker gets tasks
        size = max(1, _QUICK_SCENARIOS_PER_TASK // max(1, max((len(t) for t in tasks), default=1)))
        batches = [tasks[i : i + size] for i in range(0, len(tasks), size)]
        known = [{(m, self.picks[m]) for numbers in batch for m in numbers} & self.learned.keys() for batch in batches]
        areas = []
        sent = [(batch, {key: self.learned[key] for key in keys}) for batch, keys in zip(batches, known)]
        for batch_areas, held in self.pool.map(_quick_task, sent):
            areas.extend(batch_areas)
            keep_held(self.prepared, held)
            for key, entries in held.items():
                self.learned.setdefault(key, {}).update(entries)
        for members, area in zip(fresh, areas):
            self.quick_cache[members] = self._ratios(members, area)
        return [self._per_part(members, self.quick_cache[members]) for members in sets]

    def estimate(self, sets: Sequence[frozenset[int]]) -> list[dict[int, np.ndarray]]:
        """The best r known of every scenario, per set, without a set search: exact, else screened, else quick."""
        self.quick([s for s in sets if s not in self.exact and s not in self.cache])
        return [
            self._per_part(members, self.exact.get(members, self.cache.get(members, self.quick_cache.get(members))))
            for members in sets
        ]

    def partition_estimate(self, assignment: Sequence[int]) -> np.ndarray:
        """:meth:`estimate` of every graspable scenario (parts in order) under one partition."""
        per_part: dict[int, np.ndarray] = {}
        for values in self.estimate(sets_of(assignment)):
            per_part.update(values)
        return np.concatenate([per_part[p] for p in range(len(assignment))]) if assignment else np.zeros(0)

    def probe(self, sets: Sequence[frozenset[int]]) -> None:
        """Judge sets not yet judged exactly by the exact evaluation (METHOD §6-7) of their screened best candidate.

        One exact evaluation per set, the sets over the workers, instead of each set's design (a screened search and
        ``exact_top_k`` exact evaluations): the partition search sees exact figures of real candidates of its
        proposals, and only the partition delivered is designed.
        """
        fresh = list(dict.fromkeys(s for s in sets if s not in self.exact))
        self.retained(fresh, exact=False)
        tasks = [(self._scenarios(s), self.choices[s]) for s in fresh]
        for members, (numbers, _), measures in zip(fresh, tasks, self.pool.map(_probe_task, tasks)):
            solo = np.array([self.solos[m].exact for m in numbers])
            self.judge_exactly(members, measures / np.where(solo > 0, solo, 1.0))

    def judge_exactly(self, members: frozenset[int], retained: np.ndarray) -> None:
        """Record a set's exact ``r = E / E*`` per scenario (its parts in order, their scenarios in order)."""
        self.exact[members] = np.asarray(retained, dtype=np.float64)

    def retained(self, sets: Sequence[frozenset[int]], exact: bool = True) -> list[dict[int, np.ndarray]]:
        """r of every scenario of every part, per set: ``{part: (scenarios,) r}``.

        Exact where the set was designed exactly and ``exact`` is true, screened otherwise.
        """
        known = self.exact if exact else {}
        fresh = list(dict.fromkeys(s for s in sets if s not in self.cache and s not in known))
        self.quick(fresh)
        tasks = [self._scenarios(s) for s in fresh]
        for members, numbers, screening in zip(fresh, tasks, self.pool.map(_screen_set_task, tasks)):
            searched = self._ratios(members, screening.quality)
            quick = self.quick_cache[members]
            # the search ranks by Q = min E; the quick candidate may keep a better worst r: a set keeps the better
            ranks = [(round(float(r.min()), 9), float(r.mean())) for r in (searched, quick)]
            if ranks[0] >= ranks[1]:
                self.cache[members], self.choices[members] = searched, screening.choice
            else:
                self.cache[members], self.choices[members] = quick, tuple(self.picks[m] for m in numbers)
        return [self._per_part(members, known.get(members, self.cache.get(members))) for members in sets]

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
    prepared, pools, picks, config = context
    return screen_set(prepared, scenario_numbers, pools, config)


def _probe_task(context, task: tuple[tuple[int, ...], tuple[int, ...]]) -> np.ndarray:
    prepared, pools, picks, config = context
    numbers, choice = task
    evaluation = evaluate_exact(subset(prepared, numbers), choice, config)
    return np.array([s.measure for s in evaluation.scenarios], dtype=np.float64)


def _quick_task(
    context, task: tuple[list[tuple[int, ...]], dict[tuple[int, int], dict[tuple, float]]]
) -> tuple[list[np.ndarray], dict[tuple[int, int], dict[tuple, float]]]:
    """Quick screenings of a batch of sets, given the holding shares its samples have been measured with since this
    worker was forked, and the holding shares they know afterwards (:func:`keep_held`)."""
    prepared, pools, picks, config = context
    batch, known = task
    keep_held(prepared, known)
    areas = [quick_screen(prepared, numbers, picks, config) for numbers in batch]
    touched = {(m, picks[m]) for numbers in batch for m in numbers}
    return areas, {key: dict(prepared.scenarios[key[0]].samples[key[1]].held) for key in sorted(touched)}


def solo_picks(solos: Sequence[SoloQuality]) -> list[int]:
    """Per scenario, its sample of best solo screened E (the first of equals)."""
    return [int(np.argmax(s.screened)) if len(s.screened) else 0 for s in solos]
