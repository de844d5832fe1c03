"""The candidate search and exact re-evaluation (METHOD §6-8): a design's choice, before any finger is made, for
one batch or several subsets of it side by side."""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..errors import GeometryError
from ..evaluate import (
    CandidateEvaluation,
    evaluate_candidate,
    printed_lead_in_deg,
    screen_on_pad,
)
from ..measure import quality_words, scenario_measure
from ..parallel import WorkerPool
from ..progress import Progress, progress_with_note
from ..report.models import (
    CandidateReport,
)
from ..screen import ScreenedCandidate, carve_heights, screen
from ..search import SearchOutcome, candidate_index, quality_upper_bound, rerank, search
from .prepare import Prepared, subset
from .report import (
    candidate_reports,
)

_SCREEN_CHUNK = 64


#: Candidates per task screened on their whole pad (a few milliseconds each).
_PAD_CHUNK = 8


@dataclass
class ChosenCandidate:
    """A design's search and exact re-evaluation done (METHOD §6-8), its finger not yet made (:func:`finish_design`).

    Attributes
    ----------
    choice : tuple of int
        The chosen candidate: one sample per scenario.
    candidate : CandidateReport
        Its entry as ``report.json`` lists it (exact figures per scenario).
    """

    choice: tuple[int, ...]
    candidate: CandidateReport
    outcome: SearchOutcome = dataclasses.field(repr=False)
    ranked: list[tuple[int, ...]] = dataclasses.field(repr=False)
    exact: dict[tuple[int, ...], CandidateEvaluation] = dataclasses.field(repr=False)
    #: per-scenario screened values of the report's listed candidates kept from the search (:func:`listed_screens`
    #: screens the others)
    kept_screens: dict[tuple[int, ...], ScreenedCandidate] = dataclasses.field(repr=False)
    indices: dict[tuple[int, ...], int] = dataclasses.field(repr=False)
    upper_bound: float = 0.0
    warnings: list[str] = dataclasses.field(default_factory=list, repr=False)
    timings_s: dict[str, float] = dataclasses.field(default_factory=dict, repr=False)


def choose_candidate(prepared: Prepared, config: DesignConfig, progress: Progress | None = None) -> ChosenCandidate:
    """The search and exact re-evaluation of :func:`design_prepared`: its choice, before any finger is made.

    A finger set judged by its exact figures (METHOD §11 revision 3) needs only these; its printed-fit pockets and
    fused finger (:func:`finish_design`) are made when the set is delivered.

    Parameters
    ----------
    prepared, config, progress
        As for :func:`design_prepared`.

    Returns
    -------
    ChosenCandidate
    """
    report_progress = progress_with_note(progress)
    scenarios, jobs = prepared.scenarios, prepared.jobs
    warnings, timings = list(prepared.warnings), dict(prepared.timings_s)

    # one pool for the screening and the exact figures: its workers share the scenarios
    with WorkerPool(_screen_context(prepared, config), jobs, config.compute.scheduler) as pool:
        clock = time.perf_counter()
        outcome, indices, ranked, finalists, kept = _screened_ranking(prepared, config, report_progress, pool)
        timings["screening"] = time.perf_counter() - clock

        clock = time.perf_counter()
        report_progress("exact", 0, len(finalists))
        exact = dict(zip(finalists, pool.map(_exact_task, finalists)))
    report_progress(
        "exact",
        len(finalists),
        len(finalists),
        f"best {quality_words(max(e.quality for e in exact.values()), config.quality.measure)} (exact)",
    )
    best_choice = max(finalists, key=lambda c: (exact[c].quality, exact[c].mean_effective_area, -indices[c]))
    upper_bound = max(
        quality_upper_bound(
            [
                np.array([scenario_measure(1.0, 1.0, g.effective_area_bound, config) for g in s.samples])
                for s in scenarios
            ]
        ),
        exact[best_choice].quality,
    )
    if not outcome.proven_optimal:
        warnings.append(
            f"search screened {len(outcome.evaluated)} of {outcome.total} candidates (search.max_evaluations) "
            f"without proving the best optimal; Q is {exact[best_choice].quality / upper_bound:.0%} of its upper bound"
        )
    timings["exact"] = time.perf_counter() - clock
    candidate = candidate_reports([best_choice], {best_choice: exact[best_choice]}, {}, indices)[0]
    return ChosenCandidate(
        best_choice, candidate, outcome, ranked, exact, kept, indices, upper_bound, warnings, timings
    )


def _screened_ranking(prepared: Prepared, config: DesignConfig, report_progress: Progress, pool: WorkerPool) -> tuple:
    """The screening of :func:`choose_candidate` (METHOD §8) on ``pool`` (its context :func:`_screen_context`): the
    search's outcome, each screened candidate's index, the candidates ranked, the exact finalists, and the listed
    candidates' screenings the search kept."""
    scenarios, jobs = prepared.scenarios, prepared.jobs
    counts = [len(s.samples) for s in scenarios]
    total = int(np.prod(counts, dtype=object))
    budget = config.search.max_exhaustive if total <= config.search.max_exhaustive else config.search.max_evaluations
    expected = min(total, budget)
    screened_bounds = [np.array([g.screened_bound for g in s.samples]) for s in scenarios]
    screened_count, best_screened = 0, 0.0
    screened_bound = quality_upper_bound(screened_bounds)
    # when every candidate the search screens is listed in the report, keep
    # their per-scenario values as they are screened instead of screening again
    keep_screens = expected <= config.search.report_candidates
    kept_screens: dict[tuple[int, ...], ScreenedCandidate] = {}

    def evaluate(choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
        nonlocal screened_count, best_screened
        # a batch under a chunk per worker is split among them: the coordinate ascent's batches are a few dozen
        # candidates, and one chunk ran in this process while the workers waited (the 12-part job: 200 such
        # batches, 1.2 s)
        size = min(_SCREEN_CHUNK, -(-len(choices) // jobs))
        chunks = [choices[i : i + size] for i in range(0, len(choices), size)]
        if keep_screens:
            screened = [c for chunk in pool.map(_screen_batch, chunks) for c in chunk]
            kept_screens.update(zip(choices, screened))
            scored = [(c.quality, c.mean_effective_area) for c in screened]
        else:
            scored = [pair for chunk in pool.map(_screen_task, chunks) for pair in chunk]
        screened_count += len(choices)
        best_screened = max([best_screened] + [q for q, _ in scored])
        report_progress(
            "screening",
            min(screened_count, expected),
            expected,
            f"best {quality_words(best_screened, config.quality.measure)} of bound {screened_bound:.3g} (screened)",
        )
        return scored

    outcome = search(
        counts,
        screened_bounds,
        evaluate,
        config.search.max_exhaustive,
        config.search.max_evaluations,
        keep=config.search.exact_top_k,
    )
    indices = {choice: candidate_index(choice, counts) for choice in outcome.evaluated}
    ranked = sorted(
        outcome.evaluated,
        key=lambda c: (outcome.evaluated[c][0], outcome.evaluated[c][1], -indices[c]),
        reverse=True,
    )
    if config.quality.measure == "capture":
        # the search ranked by each sample's own capture: the best are screened again on the candidate's pad
        top = ranked[: config.search.pad_top_k]
        chunks = [top[i : i + _PAD_CHUNK] for i in range(0, len(top), _PAD_CHUNK)]
        on_pad = dict(zip(top, (c for chunk in pool.map(_pad_batch, chunks) for c in chunk)))
        kept_screens.update(on_pad)
        ranked = rerank(ranked, {c: (s.quality, s.mean_effective_area) for c, s in on_pad.items()}, counts)
    finalists = ranked[: config.search.exact_top_k]
    # the report lists each screened candidate's per-scenario values: those not kept are screened again only
    # when the finger is made (:func:`listed_screens`): a finger set judged and not delivered never needs them
    listed = ranked[config.search.exact_top_k : config.search.report_candidates]
    kept = {c: kept_screens[c] for c in listed if c in kept_screens}
    report_progress("screening", expected, expected)
    return outcome, indices, ranked, finalists, kept


def choose_candidates(
    prepared: Prepared,
    subsets: Sequence[Sequence[int]],
    config: DesignConfig,
    then: Callable[[Sequence[int], ChosenCandidate | GeometryError], Sequence[Sequence[int]]] | None = None,
    progress: Progress | None = None,
) -> list[ChosenCandidate | GeometryError]:
    """:func:`choose_candidate` of several :func:`subset` s of one batch, side by side.

    Each design runs whole on one worker, as ``jobs = 1`` would run it: a
    design's coordinate ascent screens a few dozen candidates a batch, too
    few to share out without leaving the workers waiting on each other,
    while several designs keep every worker busy. A design's choice does
    not depend on its number of workers. With one design and no ``then``,
    or on a cluster (``[compute] scheduler``), the designs run one after
    another, each over every worker.

    Parameters
    ----------
    prepared : Prepared
    subsets : sequence of sequence of int
        Scenario numbers of each design (positions in ``prepared.scenarios``, increasing).
    config : DesignConfig
    then : callable, optional
        ``then(numbers, chosen)``, called in this process as each design
        finishes (in the order they finish): further subsets to design
        beside the others; its answer must not depend on that order.
    progress : callable, optional
        Hears of each design's stages when they run one after another.

    Returns
    -------
    list of ChosenCandidate or GeometryError
        Per design, ``subsets`` first, then those ``then`` asked for in the
        order asked: the choice, or the error of a pad Boolean that failed.
    """
    follow = then or (lambda numbers, chosen: [])
    designs = [list(numbers) for numbers in subsets]
    chosen: dict[int, ChosenCandidate | GeometryError] = {}
    side_by_side = prepared.jobs > 1 and not config.compute.scheduler and (len(designs) > 1 or then is not None)
    waiting = [(_choose_task, numbers, n) for n, numbers in enumerate(designs)]

    def on_done(number: int, result: ChosenCandidate | GeometryError) -> list[tuple]:
        chosen[number] = result
        tasks = []
        for numbers in follow(designs[number], result):
            designs.append(list(numbers))
            tasks.append((_choose_task, designs[-1], len(designs) - 1))
        if side_by_side and len(designs) - len(chosen) == len(tasks) == 1:
            # a design asked for when every other is done runs on every worker, after
            waiting.extend(tasks)
            return []
        return tasks

    while waiting:
        tasks, waiting[:] = list(waiting), []
        # side by side, the workers are not told of progress: they cannot reach whoever listens
        workers = min(prepared.jobs, len(tasks) + (then is not None)) if side_by_side else 1
        with WorkerPool((prepared, config, side_by_side, None if side_by_side else progress), workers) as pool:
            pool.run(tasks, on_done)
        side_by_side = False
    return [chosen[n] for n in range(len(designs))]


@contextlib.contextmanager
def listed_screens(
    designs: Sequence[tuple[Prepared, ChosenCandidate]], config: DesignConfig
) -> Iterator[Callable[[], list[dict[tuple[int, ...], ScreenedCandidate]]]]:
    """Per-scenario screened values of the candidates each design's ``report.json`` lists after its exact finalists,
    screened on workers while this process goes on.

    Those the search kept (:attr:`ChosenCandidate.kept_screens`) are taken as they are; the others are screened again
    (screening is a function of the candidate: the same values), every design's on one pool of workers, from entering
    the context on.

    Parameters
    ----------
    designs : sequence of (Prepared, ChosenCandidate)
    config : DesignConfig

    Yields
    ------
    callable
        Waits for the screenings and returns, per design, candidate (one sample per scenario) -> its screening; to be
        called once, inside the context.
    """
    listed = [chosen.ranked[config.search.exact_top_k : config.search.report_candidates] for _, chosen in designs]
    known = [dict(chosen.kept_screens) for _, chosen in designs]
    tasks = []
    for number, candidates in enumerate(listed):
        missing = [c for c in candidates if c not in known[number]]
        tasks += [(number, missing[i : i + _SCREEN_CHUNK]) for i in range(0, len(missing), _SCREEN_CHUNK)]
    contexts = [_screen_context(prepared, config) for prepared, _ in designs] if tasks else []
    jobs = min(max(prepared.jobs for prepared, _ in designs), len(tasks))
    with WorkerPool(contexts, jobs, config.compute.scheduler if tasks else None) as pool:
        screened = pool.map_later(_listed_batch, tasks)

        def results() -> list[dict[tuple[int, ...], ScreenedCandidate]]:
            for (number, chunk), screens in zip(tasks, screened()):
                known[number].update(zip(chunk, screens))
            return [{c: screens[c] for c in candidates} for candidates, screens in zip(listed, known)]

        yield results


def _screen_context(prepared: Prepared, config: DesignConfig) -> tuple:
    """What the screening workers share (:func:`_screen_batch`, :func:`_pad_batch`, :func:`_exact_task`): every
    sample's screening geometries, the scenarios, the settings and the normal lattice."""
    scenarios = prepared.scenarios
    return [[g.screen for g in s.samples] for s in scenarios], scenarios, config, prepared.lattice


def _screen_batch(context, choices: list[tuple[int, ...]]) -> list[ScreenedCandidate]:
    screens, _, config, lattice = context
    # a batch of coordinate moves shares every scenario but one: carve those once
    first = choices[0]
    shared = [m for m in range(len(first)) if all(choice[m] == first[m] for choice in choices)]
    carved = (
        carve_heights([screens[m][k] for m, k in enumerate(first)], shared)
        if len(choices) > 1 and len(shared) > 1
        else None
    )
    return [screen([screens[m][k] for m, k in enumerate(choice)], config, lattice, carved) for choice in choices]


def _listed_batch(contexts, task: tuple[int, list[tuple[int, ...]]]) -> list[ScreenedCandidate]:
    """:func:`_screen_batch` of one design of :func:`listed_screens`: ``task`` is (design number, candidates)."""
    number, choices = task
    return _screen_batch(contexts[number], choices)


def _pad_batch(context, choices: list[tuple[int, ...]]) -> list[ScreenedCandidate]:
    _, scenarios, config, lattice = context
    # the batch's candidates share most samples: each is squeezed once (fcso.capture.sample_part)
    squeezed: dict = {}
    # and a candidate whose carving is another's bit for bit is squeezed on its pad only where its samples are new
    known: dict = {}
    return [
        screen_on_pad(scenarios, choice, config, lattice, squeezed=squeezed, landscapes=known) for choice in choices
    ]


def _screen_task(context, choices: list[tuple[int, ...]]) -> list[tuple[float, float]]:
    return [(c.quality, c.mean_effective_area) for c in _screen_batch(context, choices)]


def _exact_task(context, choice: tuple[int, ...]) -> CandidateEvaluation:
    """A finalist's exact figures under the draft it would be printed with (:func:`printed_lead_in_deg`), on the
    screening's pool (:func:`_screen_context`).

    Ranked under the default lead-in only, a finalist that captures fully once its pocket is drafted wider lost to
    one that captures half at any draft (the ribbed block: closed square to its ribs, capture 0.48 at 15° and 1.0 at
    45°, lost to an oblique grasp of 0.53 whose trials missed by 2 mm): the measure scores the pocket as printed
    (METHOD §5b).
    """
    _, scenarios, config, _ = context
    angle, _ = printed_lead_in_deg(scenarios, choice, config)
    if angle != config.print.resolved()["lead_in_deg"]:
        config = config.updated({"print": {"lead_in_deg": angle}})
    return evaluate_candidate(scenarios, choice, config, keep_pad=False)


def _choose_task(context, numbers: list[int]) -> ChosenCandidate | GeometryError:
    """:func:`choose_candidate` of one subset of :func:`choose_candidates`, in this one process when side by side."""
    prepared, config, side_by_side, progress = context
    one = subset(prepared, numbers)
    try:
        return choose_candidate(dataclasses.replace(one, jobs=1) if side_by_side else one, config, progress)
    except GeometryError as error:
        return error
