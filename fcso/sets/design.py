"""Designing a job's finger sets: identical parts once, solo qualities, the partition, every set's finger (METHOD
§11).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import DesignConfig
from ..errors import GeometryError, NoGraspError
from ..parallel import WorkerPool
from ..parts import Part
from ..pipeline import (
    ChosenCandidate,
    DesignResult,
    Prepared,
    SizeScore,
    best_pad_size,
    choose_candidates,
    design,
    finish_designs,
    load_batch,
    prepare,
    subset,
)
from ..pipeline.report import part_report
from ..pipeline.sets_report import exact_retained, sets_report, zero_quality_report
from ..progress import Progress, progress_with_note
from ..report.models import JobReport, UngraspableReport
from ..report.ranking import chosen_candidate
from ..version import __version__
from .identity import identical_groups
from .judged import PartitionAttempt, search_judged_exactly
from .other_sizes import OtherSizes, size_of
from .partition import PartitionOutcome, search_partition
from .result import SetsResult
from .screening import SetScreener, SoloQuality, keep_held, screening_pools, sets_of, solo_picks, solo_quality
from .sizes import SizeScreen, best_screened, screened_out_note, sizes_to_design
from .truth import SetsTruth


def design_sets(
    parts: Sequence[Part | str | Path],
    config: DesignConfig | None = None,
    progress: Progress | None = None,
    repair: bool = False,
) -> SetsResult:
    """Design the finger sets of a job (METHOD §11): at most ``[finger_sets] max`` fingers for its parts.

    Identical parts are designed once. Every scenario's solo quality ``E*``
    is found (:func:`solo_quality`), the distinct parts are partitioned
    (:func:`search_partition`, under screening), and every set's finger is
    designed exactly by METHOD §1-9 for that set alone
    (:func:`fcso.pipeline.design_prepared`). With several pad sizes, each is
    taken to its screened partition and only the sizes that screen can compete
    (:func:`sizes_to_design`) are designed in full; the best of those is delivered.

    Parameters
    ----------
    parts, config, progress, repair
        As for :func:`fcso.pipeline.design`.

    Returns
    -------
    SetsResult
        With ``[finger_sets] max = 1``, exactly :func:`fcso.pipeline.design` of every part.

    Raises
    ------
    MeshError, ConfigError, NoGraspError
        As :func:`fcso.pipeline.design`; NoGraspError also when no scenario keeps any contact.
    """
    config = config or DesignConfig()
    if config.finger_sets.max == 1:
        return SetsResult([design(parts, config, progress=progress, repair=repair)], None, None)

    def score(result: SetsResult) -> SizeScore:
        # retained shares are of each size's own solo qualities: sizes compete on what their fingers keep
        qualities = [chosen_candidate(d.report).quality for d in result.designs]
        flat = any(d.report.finger.flat_pads for d in result.designs)
        return SizeScore(
            (result.report.min_retained_reached, -len(result.designs), min(qualities)), min(qualities), flat
        )

    screened, screened_out = _screened_sizes(parts, config, progress, repair)
    named = {p.name: p for s in screened.values() if isinstance(s, _ScreenedSize) for p in s.loaded}
    made: list[SetsResult] = []

    def design_one_size(sized: DesignConfig) -> SetsResult:
        # popped: a size's screened job is freed once designed
        one = screened.pop(size_of(sized))
        if isinstance(one, NoGraspError):
            raise one
        made.append(_design_screened(one, config.pad_size_configs(), repair, progress))
        return made[-1]

    result, sizes = best_pad_size(config, design_one_size, score, progress, screened_out)
    finger_sets = result.report.model_copy(update={"pad_sizes": sizes})
    others = sorted((r for r in made if r is not result), key=lambda r: score(r).rank, reverse=True)
    for entry, one in zip(result.report.sets, result.designs):
        # a set's other sizes for the choice by truth: the sets of the same parts the other sizes designed, then the
        # sizes none did, designed for the set if the choice gets to them
        designed = [d for r in others for s, d in zip(r.report.sets, r.designs) if s.parts == entry.parts]
        # and those the truth's judgement of a part's own finger already designed for this set: not designed again
        judged = one.other_sizes.designed if isinstance(one.other_sizes, OtherSizes) else []
        have = {size_of(d.report.settings) for d in designed}
        designed += [d for d in judged if size_of(d.report.settings) not in have]
        one.other_sizes = OtherSizes.of(one, designed, [named[name] for name in entry.parts], config, repair)
    size_reports = {size_of(r.designs[0].report.settings): r.report for r in made}
    if result.several:
        job_report = result.job_report.model_copy(update={"finger_sets": finger_sets})
        return SetsResult(result.designs, finger_sets, job_report, size_reports)
    result.designs[0].report = result.designs[0].report.model_copy(update={"finger_sets": finger_sets})
    return SetsResult(result.designs, finger_sets, None, size_reports)


def _screened_sizes(
    parts: Sequence[Part | str | Path], config: DesignConfig, progress: Progress | None, repair: bool
) -> tuple[dict[tuple[float, float], _ScreenedSize | NoGraspError], list[str | None]]:
    """Every pad size of ``[sampler]`` taken to its screened partition (:func:`_screen_one_size`).

    Returns
    -------
    screened : dict
        Length and width in mm -> the size's screened job, for the sizes to design in full
        (:func:`sizes_to_design`), or why it grasps no part.
    screened_out : list of str or None
        Per size of :meth:`DesignConfig.pad_size_configs`, why it is not designed in full, or None.
    """
    report_progress = progress_with_note(progress)
    sized = config.pad_size_configs()
    screened: list[_ScreenedSize | NoGraspError] = []
    for number, one in enumerate(sized):
        if len(sized) > 1:
            report_progress(
                "pad size screen", number, len(sized), f"{one.sampler.length_mm:g} x {one.sampler.width_mm:g} mm pads"
            )
        try:
            screened.append(_screen_one_size(parts, one, progress, repair))
        except NoGraspError as error:
            # designing the size raises it again (fcso.pipeline.best_pad_size notes it, or raises it for one size)
            screened.append(error)
    if len(sized) > 1:
        report_progress("pad size screen", len(sized), len(sized), "")
    screens = [s.screen if isinstance(s, _ScreenedSize) else None for s in screened]
    best = best_screened(screens)
    kept = {k for k, s in enumerate(screens) if s is None} | set(sizes_to_design(screens))
    best_size = None if best is None else f"{sized[best].sampler.length_mm:g} x {sized[best].sampler.width_mm:g} mm"
    screened_out = [
        None if k in kept else screened_out_note(screens[k], screens[best], best_size) for k in range(len(sized))
    ]
    return {size_of(sized[k]): screened[k] for k in sorted(kept)}, screened_out


@dataclass
class _ScreenedSize:
    """A job with one pad size taken to its screened partition (:func:`_screen_one_size`): the size's screen, and
    what its full design goes on from (:func:`_design_screened`)."""

    config: DesignConfig
    loaded: list[Part]
    groups: list[list[int]]
    prepared: Prepared
    warnings: list[str]
    timings_s: dict[str, float]
    solos: list[SoloQuality]
    ungraspable: list[UngraspableReport]
    part_scenarios: list[list[int]]
    graspable: list[int]
    sets: _ExactSets
    first: PartitionOutcome
    screen: SizeScreen


def _screen_one_size(
    parts: Sequence[Part | str | Path], config: DesignConfig, progress: Progress | None, repair: bool
) -> _ScreenedSize:
    """A job with one pad size and ``[finger_sets] max`` above 1 up to its screened partition
    (:func:`search_partition`), each set of which is judged by the exact evaluation of its screened best candidate
    (:meth:`SetScreener.probe`, as the partition search's first proposal is).

    Raises
    ------
    NoGraspError
        No scenario keeps any contact.
    """
    report_progress = progress or (lambda stage, done, total, note="": None)
    clock = time.perf_counter()
    loaded = load_batch(parts, config, repair)
    groups = identical_groups([p.mesh for p in loaded])
    unique = [loaded[g[0]] for g in groups]
    dedup_s = time.perf_counter() - clock
    prepared = prepare(unique, config, progress=progress, repair=repair)
    warnings = list(prepared.warnings) + _identical_warnings(loaded, groups)
    timings = dict(prepared.timings_s, identical_parts=dedup_s)

    clock = time.perf_counter()
    solos = _solo_qualities(prepared, config, report_progress)
    timings["solo_quality"] = time.perf_counter() - clock
    ungraspable = list(prepared.ungraspable)
    part_scenarios = _scenarios_with_contact(prepared, solos, len(unique), ungraspable, warnings)
    graspable = [u for u in range(len(unique)) if part_scenarios[u]]
    if not graspable:
        raise NoGraspError(
            "no scenario of the job keeps any contact with a pad: "
            + "; ".join(f"{u.part} pose {u.pose_index}" for u in ungraspable)
        )

    clock = time.perf_counter()
    sets = _ExactSets(prepared, config, solos, [part_scenarios[u] for u in graspable], progress, report_progress)
    with _screening_pool(sets) as pool:
        sets.screener = SetScreener(prepared, sets.set_scenarios, solos, config, pool)
        first = search_partition(sets.screener, len(graspable), config, report_progress)
        sets.screener.probe(sets_of(first.assignment))
    timings["partition"] = time.perf_counter() - clock
    numbers = [m for members in sets.set_scenarios for m in members]
    screen = SizeScreen.of(
        first.assignment,
        sets.screener.partition_retained(first.assignment),
        [p for p, members in enumerate(sets.set_scenarios) for _ in members],
        np.array([solos[m].exact for m in numbers]),
        config.finger_sets.min_retained,
        config.finger_sets.sets_allowed(len(graspable)),
    )
    return _ScreenedSize(
        config,
        loaded,
        groups,
        prepared,
        warnings,
        timings,
        solos,
        ungraspable,
        part_scenarios,
        graspable,
        sets,
        first,
        screen,
    )


def _screening_pool(sets: _ExactSets) -> WorkerPool:
    """The workers of a job's set screenings (:class:`SetScreener`)."""
    prepared, config, solos = sets.prepared, sets.config, sets.solos
    # no more workers than sets to screen: one part has one partition
    return WorkerPool(
        (prepared, screening_pools(solos, config.finger_sets.screen_samples), solo_picks(solos), config),
        prepared.jobs if len(sets.set_scenarios) > 1 else 1,
        config.compute.scheduler,
    )


def _design_screened(
    size: _ScreenedSize, sizes: list[DesignConfig], repair: bool, progress: Progress | None
) -> SetsResult:
    """The finger sets of a job with one pad size, designed in full from its screened partition
    (:func:`search_judged_exactly`); ``sizes``: every pad size of the job's settings (a part's own finger judged by
    truth is chosen among them, :class:`OtherSizes`)."""
    report_progress = progress or (lambda stage, done, total, note="": None)
    config, prepared, sets, graspable, part_scenarios = (
        size.config,
        size.prepared,
        size.sets,
        size.graspable,
        size.part_scenarios,
    )
    unique, timings = [size.loaded[g[0]] for g in size.groups], size.timings_s
    clock = time.perf_counter()
    truth = _sets_truth(sets, [prepared.parts[u] for u in graspable], config, sizes, repair)
    with _screening_pool(sets) as pool:
        # the screener keeps every set screened and probed for the size's screen: none is screened again
        sets.screener.pool = pool
        outcome, attempts = search_judged_exactly(
            sets.screener,
            len(graspable),
            config,
            lambda stage, done, total, note="": report_progress(stage, done, total, note),
            sets.design_exactly,
            sets.finish_exactly,
            None if truth is None else truth.unserved,
            size.first,
        )
    # the partition's time includes the screened search and the exact designs of the sets it judged
    timings["partition"] += time.perf_counter() - clock

    clock = time.perf_counter()
    designs, members = _delivered_designs(outcome, graspable, part_scenarios, sets)
    report_progress("finger sets", len(designs), len(designs), "")
    timings["finger_sets"] = time.perf_counter() - clock
    screened = _screened_retained(outcome, attempts, graspable, part_scenarios, sets.screener)
    unserved = {graspable[p]: truth.reasons[p] for p in outcome.unserved_by_truth}
    finger_sets = sets_report(
        prepared,
        size.loaded,
        size.groups,
        size.solos,
        designs,
        members,
        outcome,
        attempts,
        graspable,
        screened,
        size.ungraspable,
        config,
        unserved,
    )
    if truth is not None:
        clock = time.perf_counter()
        finger_sets = finger_sets.model_copy(update={"truth": truth.report(outcome)})
        timings["truth"] = time.perf_counter() - clock
    timings = {k: round(v, 3) for k, v in timings.items()}
    if len(designs) == 1:
        design_report = designs[0].report
        designs[0].report = design_report.model_copy(
            update={
                "parts": [part_report(p) for p in unique],
                "ungraspable": size.ungraspable,
                "warnings": size.warnings + design_report.warnings,
                "timings_s": dict(timings, **design_report.timings_s),
                "finger_sets": finger_sets,
            }
        )
        return SetsResult(designs, finger_sets, None)
    set_warnings = [f"set {k}: {w}" for k, d in enumerate(designs, start=1) for w in d.report.warnings]
    job = JobReport(
        fcso_version=__version__,
        parts=[part_report(p) for p in unique],
        finger_sets=finger_sets,
        timings_s=timings,
        warnings=size.warnings + set_warnings,
        settings=config,
    )
    return SetsResult(designs, finger_sets, job)


def _sets_truth(
    sets: _ExactSets, parts: list[Part], config: DesignConfig, sizes: list[DesignConfig], repair: bool
) -> SetsTruth | None:
    """The sets of ``parts`` judged by truth with ``[finger_sets] truth_budget_s`` (:class:`SetsTruth`), or None
    when it is 0 or there are fewer than two distinct parts. A set's design carries the job's other pad ``sizes``
    (:class:`OtherSizes`): a part's own finger is chosen among them, as a job of that part alone chooses it."""
    # one distinct part has no finger to share and nothing to be judged against: its set is its own finger, which
    # the choice by truth after the design verifies (fcso.sim.choose.verify_top). Simulating it here, for the report,
    # ran every trial and the holding test of each pad size's finger, though one size is delivered (a daemon's job
    # of one plain block: 79 s of 3 sizes)
    if config.finger_sets.truth_budget_s <= 0 or len(parts) < 2:
        return None
    from ..sim.config import with_print_density

    def made(members: frozenset[int]) -> DesignResult | None:
        result = sets.made(members)
        if result is not None and not isinstance(result.other_sizes, OtherSizes):
            result.other_sizes = OtherSizes.of(result, [], [parts[p] for p in sorted(members)], config, repair, sizes)
        return result

    return SetsTruth(
        made, [p.name for p in parts], config.finger_sets.truth_budget_s, with_print_density(config.verify, config)
    )


def _identical_warnings(loaded: list[Part], groups: list[list[int]]) -> list[str]:
    """A warning per group of parts of the same geometry, designed once."""
    return [
        f"{', '.join(loaded[i].name for i in group)} have the same geometry: designed once as {loaded[group[0]].name}"
        for group in groups
        if len(group) > 1
    ]


def _solo_qualities(prepared: Prepared, config: DesignConfig, report_progress: Progress) -> list[SoloQuality]:
    """Every scenario's solo quality E* (:func:`solo_quality`), on workers; the contacts they found kept for the
    screening (:func:`keep_held`)."""
    report_progress("solo quality", 0, len(prepared.scenarios), "")
    # no more workers than tasks: forking costs more than one small task
    with WorkerPool((prepared, config), min(prepared.jobs, len(prepared.scenarios)), config.compute.scheduler) as pool:
        solos = pool.map(_solo_task, list(range(len(prepared.scenarios))))
    keep_held(prepared, {(m, k): entries for m, solo in enumerate(solos) for k, entries in solo.held.items()})
    report_progress("solo quality", len(prepared.scenarios), len(prepared.scenarios), "")
    return solos


def _scenarios_with_contact(
    prepared: Prepared,
    solos: list[SoloQuality],
    unique_parts: int,
    ungraspable: list[UngraspableReport],
    warnings: list[str],
) -> list[list[int]]:
    """Per distinct part, its scenarios that keep some contact (E* > 0); the others are added to ``ungraspable`` and
    ``warnings``."""
    for scenario, solo in zip(prepared.scenarios, solos):
        if solo.exact <= 0:
            ungraspable.append(zero_quality_report(scenario))
            warnings.append(
                f"{scenario.part.name} in stable pose {scenario.pose_index} keeps no contact with any pad and is left "
                f"out"
            )
    return [
        [m for m, s in enumerate(prepared.scenarios) if s.part_index == u and solos[m].exact > 0]
        for u in range(unique_parts)
    ]


@dataclass
class _ExactSets:
    """The sets the partition search judges exactly (:func:`search_judged_exactly`): each set's chosen candidate and
    finger, made once, and why a set could not be made.

    Attributes
    ----------
    set_scenarios : list of list of int
        Per graspable part (a set's member), its scenario numbers.
    screener : SetScreener
        Set when the search's workers start; told of each set's exact figures.
    """

    prepared: Prepared
    config: DesignConfig
    solos: list[SoloQuality]
    set_scenarios: list[list[int]]
    progress: Progress | None
    report_progress: Progress
    screener: SetScreener | None = None
    chosen_candidates: dict[frozenset[int], ChosenCandidate] = dataclasses.field(default_factory=dict)
    exact_designs: dict[frozenset[int], DesignResult] = dataclasses.field(default_factory=dict)
    failures: dict[frozenset[int], str] = dataclasses.field(default_factory=dict)

    def numbers_of(self, members: frozenset[int]) -> list[int]:
        return sorted(m for p in members for m in self.set_scenarios[p])

    def failed(self, members: frozenset[int], error: GeometryError) -> str:
        # such a set keeps nothing, so the search moves on from it
        self.failures[members] = str(error)
        self.screener.judge_exactly(members, np.zeros(len(self.numbers_of(members))))
        return self.failures[members]

    def design_exactly(self, sets: list[frozenset[int]], fallback: frozenset[int] | None = None) -> list[str | None]:
        """Sets' candidates by METHOD §6-8, each once, side by side (:func:`fcso.pipeline.choose_candidates`); the
        screener then judges each set by its exact figures.

        ``fallback`` (one finger for every part) is designed beside them as soon as one of them keeps less than
        ``min_retained`` in a scenario or cannot be designed: the partition is then compared with it. Its finger
        (printed-fit pockets, fusing) is made only if the set is delivered (:meth:`finish_exactly`): the retained
        qualities are the chosen candidate's exact ones either way. Returns per set why it cannot be designed (a pad
        Boolean that failed), or None.
        """
        chosen_candidates, failures, screener = self.chosen_candidates, self.failures, self.screener
        config, solos, numbers_of, report_progress = self.config, self.solos, self.numbers_of, self.report_progress
        todo = list(dict.fromkeys(m for m in sets if m not in chosen_candidates and m not in failures))
        if not todo:
            return [failures.get(members) for members in sets]
        # the sets by their scenario numbers, in the order their designs start: the worst by the exact figures known
        # (the probes of fcso.sets.screening.SetScreener.probe) first, as the likeliest to miss min_retained and so
        # to start the fallback's design early
        known = {m: float(screener.exact[m].min()) if m in screener.exact else np.inf for m in todo}
        wanted = {frozenset(numbers_of(m)): m for m in sorted(todo, key=lambda m: known[m])}
        compare = fallback is not None and fallback not in chosen_candidates and fallback not in failures
        compare = compare and fallback not in todo

        designed = 0

        def then(numbers: list[int], chosen: ChosenCandidate | GeometryError) -> list[list[int]]:
            nonlocal compare, designed
            designed += 1
            report_progress("finger sets", designed, len(wanted), f"set of {len(wanted[frozenset(numbers)])} parts")
            short = isinstance(chosen, GeometryError) or (
                min(exact_retained(chosen.candidate, numbers, solos)) < config.finger_sets.min_retained
            )
            if not (compare and short):
                return []
            compare = False
            wanted[frozenset(numbers_of(fallback))] = fallback
            return [numbers_of(fallback)]

        report_progress("finger sets", 0, len(wanted), f"designing {len(wanted)} set(s)")
        starting = [numbers_of(m) for m in wanted.values()]
        chosen_all = choose_candidates(self.prepared, starting, config, then if compare else None, self.progress)
        # the fallback, when asked for, came last
        made = dict(zip(wanted.values(), chosen_all))
        report_progress("finger sets", len(made), len(made), "")
        # judged in the order asked for (the sets, then the fallback), whichever finished first
        for members in todo + [m for m in made if m not in todo]:
            chosen = made[members]
            if isinstance(chosen, GeometryError):
                self.failed(members, chosen)
                continue
            chosen_candidates[members] = chosen
            numbers = numbers_of(members)
            kept = dict(zip(numbers, exact_retained(chosen.candidate, numbers, solos)))
            screener.judge_exactly(members, np.array([kept[m] for p in sorted(members) for m in self.set_scenarios[p]]))
        return [failures.get(members) for members in sets]

    def made(self, members: frozenset[int]) -> DesignResult | None:
        """Set ``members`` designed and its finger made (each once), or None when it cannot be: what
        :class:`SetsTruth` simulates (a part's own finger is its set alone)."""
        if self.design_exactly([members])[0] is None:
            self.finish_exactly([members])
        return self.exact_designs.get(members)

    def finish_exactly(self, sets: list[frozenset[int]]) -> list[str | None]:
        """The fingers of sets designed by :meth:`design_exactly`, each made once, together
        (:func:`fcso.pipeline.finish_designs`); per set why its finger could not be made (a pad so carved that the
        fused finger is not one printable body), or None."""
        todo = [members for members in sets if members not in self.exact_designs and members not in self.failures]
        if todo:
            made = finish_designs(
                [(subset(self.prepared, self.numbers_of(m)), self.chosen_candidates[m]) for m in todo],
                self.config,
                self.progress,
            )
            for members, result in zip(todo, made):
                if isinstance(result, GeometryError):
                    self.failed(members, result)
                else:
                    self.exact_designs[members] = result
        return [self.failures.get(members) for members in sets]


def _delivered_designs(
    outcome: PartitionOutcome, graspable: list[int], part_scenarios: list[list[int]], sets: _ExactSets
) -> tuple[list[DesignResult], list[tuple[list[int], list[int]]]]:
    """The chosen partition's designs, each grasp marked with its finger set, and per set its distinct parts and
    scenario numbers."""
    designs, members = [], []
    for label in range(max(outcome.assignment) + 1):
        group = frozenset(p for p, a in enumerate(outcome.assignment) if a == label)
        chosen = [graspable[p] for p in sorted(group)]
        numbers = sorted(m for u in chosen for m in part_scenarios[u])
        if group in sets.failures:  # every partition designed had a set that could not be made
            raise GeometryError(sets.failures[group])
        made = sets.exact_designs[group]
        # every grasp says which finger set makes it
        made = dataclasses.replace(
            made,
            report=made.report.model_copy(
                update={"grasps": [g.model_copy(update={"finger_set": label + 1}) for g in made.report.grasps]}
            ),
        )
        designs.append(made)
        members.append((chosen, numbers))
    return designs, members


def _screened_retained(
    outcome: PartitionOutcome,
    attempts: list[PartitionAttempt],
    graspable: list[int],
    part_scenarios: list[list[int]],
    screener: SetScreener,
) -> dict[int, float]:
    """Scenario number -> what screening says the delivered partition retains there; empty when it was never
    screened."""
    # one finger designed to compare was never screened as a set (fcso.sets.judged.PartitionAttempt): its
    # scenarios have no screened figure
    delivered = next(a for a in attempts if a.assignment == outcome.assignment)
    if delivered.screened_worst is None:
        return {}
    return dict(
        zip(
            [m for p in range(len(graspable)) for m in part_scenarios[graspable[p]]],
            screener.partition_retained(outcome.assignment, exact=False),
        )
    )


def _solo_task(context, number: int) -> SoloQuality:
    prepared, config = context
    return solo_quality(prepared, number, config)
