"""Which pad sizes a finger sets job designs in full: each size's screened partition, compared (issue 48).

Designing a job's sets in full takes minutes at farm scale (the partition's exact designs, the merges, the fingers),
so every size of ``[sampler]`` is first taken only to its screened partition (:func:`fcso.sets.search_partition`),
whose sets are judged by one exact evaluation each (:meth:`fcso.sets.SetScreener.probe`). Only the sizes whose
screened partition can compete are designed in full.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Share of the best size's projected sets (:attr:`SizeScreen.projected_sets`) another size may use beyond them and
#: still be designed in full, at least one set: the screened partition's count is an estimate, which the full design
#: changes both ways (losing parts moved to sets of their own, single-part sets merged; docs/benchmarks.md).
SETS_MARGIN_SHARE = 0.25


@dataclass(frozen=True)
class SizeScreen:
    """One pad size's screened partition, judged by the exact evaluation of each set's screened best candidate.

    Attributes
    ----------
    sets : int
        Sets of the screened partition.
    losing_parts : int
        Its parts with a graspable scenario below ``min_retained`` (probed ``r``).
    sets_allowed : int
        The most sets the job may use (``[finger_sets] max``, one per part with ``"auto"``).
    worst_retained : float
        Least probed ``r = E / E*`` over the graspable scenarios.
    worst_quality : float
        Least probed quality ``E`` over the graspable scenarios (that size's own measure).
    """

    sets: int
    losing_parts: int
    sets_allowed: int
    worst_retained: float
    worst_quality: float

    @classmethod
    def of(
        cls,
        assignment: Sequence[int],
        retained: np.ndarray,
        owners: Sequence[int],
        solo_qualities: np.ndarray,
        min_retained: float,
        sets_allowed: int,
    ) -> SizeScreen:
        """The screen of partition ``assignment`` (set of every part) whose scenarios, of parts ``owners``, keep
        ``retained`` of their solo qualities ``solo_qualities``."""
        losing = {owner for owner, r in zip(owners, retained) if r < min_retained}
        return cls(
            sets=max(assignment) + 1,
            losing_parts=len(losing),
            sets_allowed=sets_allowed,
            worst_retained=float(retained.min()),
            worst_quality=float((retained * solo_qualities).min()),
        )

    @property
    def projected_sets(self) -> int:
        """The sets once every losing part has a set of its own, as far as allowed: what the full design does with
        a partition whose designs miss ``min_retained`` (:func:`fcso.sets.search_judged_exactly`)."""
        return min(self.sets + self.losing_parts, self.sets_allowed)

    @property
    def reaches(self) -> bool:
        """Every part keeps ``min_retained`` once the losing parts have sets of their own."""
        return self.sets + self.losing_parts <= self.sets_allowed

    @property
    def rank(self) -> tuple:
        """Compared as a tuple, as the full designs are (:func:`fcso.sets.design_sets`): reaching ``min_retained``,
        then fewer sets, then the worst quality."""
        return (self.reaches, -self.projected_sets, self.worst_quality)

    def describe(self) -> str:
        """The screen's figures in words."""
        return (
            f"{self.sets} set(s) screened, {self.losing_parts} part(s) below min_retained (worst retained "
            f"{self.worst_retained:.3f}): {self.projected_sets} set(s) projected"
        )


def best_screened(screens: Sequence[SizeScreen | None]) -> int | None:
    """The size (index of ``screens``) whose screen ranks best, the first on a tie; None when every one is None (no
    size grasps a part)."""
    screened = [k for k, s in enumerate(screens) if s is not None]
    return max(screened, key=lambda k: (screens[k].rank, -k)) if screened else None


def sizes_to_design(screens: Sequence[SizeScreen | None]) -> list[int]:
    """The sizes (indices of ``screens``) to design in full: the best screened (:func:`best_screened`), and every
    other one the screen cannot separate from it: as far with ``min_retained`` and within :data:`SETS_MARGIN_SHARE`
    of its projected sets.

    Parameters
    ----------
    screens : sequence of SizeScreen or None
        Per pad size, its screen; None for a size that grasps no part.

    Returns
    -------
    list of int
        Size indices in order; empty when no size grasps a part.
    """
    best = best_screened(screens)
    if best is None:
        return []
    reaches, sets = screens[best].reaches, screens[best].projected_sets
    most = sets + max(1, round(SETS_MARGIN_SHARE * sets))
    return [k for k, s in enumerate(screens) if s is not None and s.reaches == reaches and s.projected_sets <= most]


def screened_out_note(screen: SizeScreen, best: SizeScreen, best_size: str) -> str:
    """Why a size was not designed in full, for its report entry: its screen against the best size's."""
    return f"not designed in full: {screen.describe()}; {best_size} pads {best.describe()}"
