"""The partition search with its proposals judged exactly, the best designed and delivered (METHOD §11 revision 3)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from ..config import DesignConfig
from ..progress import Progress
from .partition import PartitionOutcome, partition_key, search_partition
from .screening import SetScreener, sets_of


@dataclass
class PartitionAttempt:
    """A partition judged exactly (METHOD §11 revision 3).

    Attributes
    ----------
    assignment : tuple of int
        Set of every part (canonical).
    screened_worst : float or None
        Least screened ``r`` over its graspable scenarios; None for one finger designed to compare (a set search of
        every part, seconds to minutes at farm scale, would only be reported: its design judges it).
    exact_worst : float
        Least exact ``r``: of its sets' designs when ``designed``, else of the exact evaluation of each set's
        screened best candidate (:meth:`SetScreener.probe`).
    source : str
        ``"search"``: proposed by the partition search; ``"one_finger"``:
        every part in one set, designed to compare.
    failure : str or None
        Why a set's finger could not be made (it then keeps nothing), or None.
    designed : bool
        Its sets' candidates were designed by METHOD §6-8 (the partition delivered, and one finger when compared);
        only the delivered partition's fingers are made (METHOD §9).
    """

    assignment: tuple[int, ...]
    screened_worst: float | None
    exact_worst: float
    source: str
    failure: str | None = None
    designed: bool = False


def search_judged_exactly(
    screener: SetScreener,
    parts: int,
    config: DesignConfig,
    progress: Progress,
    design_exactly: Callable[[list[frozenset[int]], frozenset[int] | None], list[str | None]],
    finish_exactly: Callable[[list[frozenset[int]]], list[str | None]],
) -> tuple[PartitionOutcome, list[PartitionAttempt]]:
    """The partition search of :func:`search_partition`, its proposals judged exactly (METHOD §11 rev. 3).

    Each proposed partition's sets are judged by the exact evaluation of
    their screened best candidates (:meth:`SetScreener.probe`, one exact
    evaluation per set), so the next search sees the exact figure of every
    set judged so far: a set whose exact figure misses ``min_retained`` no
    longer looks feasible, and the search moves its parts or tries more sets.
    It goes on only while a proposal that screening said reaches
    ``min_retained`` misses it exactly and has fewer than ``max`` sets, and
    stops when the search proposes a partition already judged, or after
    ``[finger_sets] max`` proposals. The best proposal by the exact objective
    is then designed (``design_exactly`` on each of its sets: search and
    exact re-evaluation, METHOD §6-8); if its designed sets miss
    ``min_retained`` (or a set cannot be made), one finger for every part is
    designed too, and the better of the two designed partitions by the exact
    objective is chosen, so the sets never keep less in their worst scenario
    than one finger does. Only the chosen partition's fingers are made
    (``finish_exactly``, METHOD §9): the figures that judge a partition are
    its chosen candidates' exact ones, which making the finger does not change.

    Parameters
    ----------
    screener : SetScreener
    parts : int
        Distinct graspable parts.
    config : DesignConfig
    progress : callable
    design_exactly : callable
        ``design_exactly(sets_of_parts, fallback)``: chooses each set's
        candidate by METHOD §6-8 and calls ``screener.judge_exactly`` with
        its exact retained qualities (zeros when it cannot be designed);
        returns per set why not, or None. ``fallback`` (every part in one
        set, or None) is to be designed and judged too, beside the sets,
        when one of them misses ``min_retained`` or cannot be designed: it
        is then compared.
    finish_exactly : callable
        ``finish_exactly(sets_of_parts)``: makes the fingers of sets
        ``design_exactly`` designed (METHOD §9), together, called only for the
        sets of the partition delivered; per set, when its finger cannot be
        made it judges the set at zeros and says why (else None), and the next
        best designed partition is delivered instead.

    Returns
    -------
    PartitionOutcome
        Of the chosen partition, ``retained`` exact (its designed sets).
    list of PartitionAttempt
        Every partition judged, in the order judged.
    """
    judging = _Judging(screener, progress, design_exactly, config.finger_sets.min_retained)
    first = search_partition(screener, parts, config, progress)
    outcome = _proposals(judging, first, parts, config)
    chosen = _delivered(judging, parts, finish_exactly)
    outcome = dataclasses.replace(
        outcome,
        assignment=chosen.assignment,
        retained=screener.partition_retained(chosen.assignment),
        fewest_sets_proven=first.fewest_sets_proven,
    )
    return outcome, judging.attempts


@dataclass
class _Judging:
    """The partitions :func:`search_judged_exactly` has judged, in the order judged, and how it judges one."""

    screener: SetScreener
    progress: Progress
    design_exactly: Callable[[list[frozenset[int]], frozenset[int] | None], list[str | None]]
    threshold: float
    attempts: list[PartitionAttempt] = dataclasses.field(default_factory=list)

    def key(self, assignment: tuple[int, ...]) -> tuple:
        return partition_key(assignment, self.screener.partition_retained(assignment), self.threshold)

    def judge(
        self, assignment: tuple[int, ...], source: str, failure: str | None = None, designed: bool = False
    ) -> None:
        # a partition designed after its probe replaces the probe's row and keeps its source
        source = next((a.source for a in self.attempts if a.assignment == assignment), source)
        screener = self.screener
        screened = float(screener.partition_retained(assignment, exact=False).min()) if source == "search" else None
        exact = screener.partition_retained(assignment)
        judged = PartitionAttempt(assignment, screened, float(exact.min()), source, failure, designed)
        self.attempts[:] = [a for a in self.attempts if a.assignment != assignment] + [judged]

    def design(
        self, assignment: tuple[int, ...], source: str, fallback: frozenset[int] | None = None
    ) -> PartitionAttempt:
        self.progress("exact sets", 0, 1, f"designing {max(assignment) + 1} set(s)")
        failures = [f for f in self.design_exactly(sets_of(assignment), fallback) if f is not None]
        self.judge(assignment, source, failures[0] if failures else None, designed=True)
        return self.attempts[-1]


def _proposals(judging: _Judging, outcome: PartitionOutcome, parts: int, config: DesignConfig) -> PartitionOutcome:
    """The search's proposals, each probed and judged exactly, while one screening said reaches ``min_retained``
    misses it exactly (:func:`search_judged_exactly`); the last proposal's outcome."""
    screener, progress, threshold, attempts = judging.screener, judging.progress, judging.threshold, judging.attempts
    proposals = config.finger_sets.max
    for proposal in range(proposals):
        if any(a.assignment == outcome.assignment for a in attempts):
            break
        progress("exact sets", proposal, proposals, f"proposal {proposal + 1}: {max(outcome.assignment) + 1} sets")
        screener.probe(sets_of(outcome.assignment))
        judging.judge(outcome.assignment, "search")
        judged = attempts[-1]
        progress(
            "exact sets",
            proposal + 1,
            proposals,
            f"proposal {proposal + 1}: worst retained screened {judged.screened_worst:.2f}, "
            f"exact {judged.exact_worst:.2f}",
        )
        # METHOD §11 rev. 3: go on only where screening promised min_retained, the exact sets missed it, and max
        # allows more sets; a proposal screening already found short is as good as the search can tell
        if (
            judged.exact_worst >= threshold
            or judged.screened_worst < threshold
            or max(outcome.assignment) + 1 >= proposals
            or proposal + 1 == proposals
        ):
            break
        outcome = search_partition(screener, parts, config, progress)
    return outcome


def _delivered(
    judging: _Judging, parts: int, finish_exactly: Callable[[list[frozenset[int]]], list[str | None]]
) -> PartitionAttempt:
    """The best proposal designed, one finger for every part beside it when it misses ``min_retained``, and the best
    designed partition whose fingers can be made (:func:`search_judged_exactly`)."""
    attempts = judging.attempts
    single = tuple([0] * parts)
    # one finger for every part is designed beside the partition's sets as soon as one of them misses min_retained
    best = judging.design(
        max(attempts, key=lambda a: judging.key(a.assignment)).assignment, "search", frozenset(range(parts))
    )
    if (best.failure is not None or best.exact_worst < judging.threshold) and best.assignment != single:
        judging.design(single, "one_finger")
    while True:
        # a partition with a finger that cannot be made is delivered only when every one designed has one
        chosen = max(
            (a for a in attempts if a.designed),
            key=lambda a: (a.failure is None, judging.key(a.assignment)),
        )
        if chosen.failure is not None:
            break
        failures = [f for f in finish_exactly(sets_of(chosen.assignment)) if f is not None]
        if not failures:
            break
        judging.judge(chosen.assignment, chosen.source, failures[0], designed=True)
        if not any(a.assignment == single and a.designed for a in attempts):
            judging.design(single, "one_finger")
    return chosen
