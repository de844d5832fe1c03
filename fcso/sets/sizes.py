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

#: Sets a size's screened partition may use beyond the best size's and still be designed in full. The full design
#: moves a probe's losing parts to sets of their own and merges single-part sets, so its count can differ from the
#: screened one by a few sets.
SETS_MARGIN = 1


@dataclass(frozen=True)
class SizeScreen:
    """One pad size's screened partition, judged by the exact evaluation of each set's screened best candidate.

    Attributes
    ----------
    sets : int
        Sets of the screened partition.
    reached : bool
        Every graspable scenario keeps at least ``min_retained`` of its solo quality (probed ``r``).
    worst_retained : float
        Least probed ``r = E / E*`` over the graspable scenarios.
    worst_quality : float
        Least probed quality ``E`` over the graspable scenarios (that size's own measure).
    """

    sets: int
    reached: bool
    worst_retained: float
    worst_quality: float

    @classmethod
    def of(cls, sets: int, retained: np.ndarray, solo_qualities: np.ndarray, min_retained: float) -> SizeScreen:
        """The screen of a partition into ``sets`` sets whose scenarios keep ``retained`` of ``solo_qualities``."""
        return cls(
            sets=sets,
            reached=bool(retained.min() >= min_retained),
            worst_retained=float(retained.min()),
            worst_quality=float((retained * solo_qualities).min()),
        )

    @property
    def rank(self) -> tuple:
        """Compared as a tuple, as the full designs are (:func:`fcso.sets.design_sets`): reaching ``min_retained``,
        then fewer sets, then the worst quality."""
        return (self.reached, -self.sets, self.worst_quality)

    def describe(self) -> str:
        """The screen's figures in words."""
        return (
            f"{self.sets} set(s) screened, worst retained {self.worst_retained:.3f}, "
            f"min_retained {'reached' if self.reached else 'missed'}"
        )


def best_screened(screens: Sequence[SizeScreen | None]) -> int | None:
    """The size (index of ``screens``) whose screen ranks best, the first on a tie; None when every one is None (no
    size grasps a part)."""
    screened = [k for k, s in enumerate(screens) if s is not None]
    return max(screened, key=lambda k: (screens[k].rank, -k)) if screened else None


def sizes_to_design(screens: Sequence[SizeScreen | None]) -> list[int]:
    """The sizes (indices of ``screens``) to design in full: the best screened (:func:`best_screened`), and every
    other one the screen cannot separate from it: as far with ``min_retained`` and at most :data:`SETS_MARGIN` sets
    more.

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
    reached, sets = screens[best].reached, screens[best].sets
    return [k for k, s in enumerate(screens) if s is not None and s.reached == reached and s.sets <= sets + SETS_MARGIN]


def screened_out_note(screen: SizeScreen, best: SizeScreen, best_size: str) -> str:
    """Why a size was not designed in full, for its report entry: its screen against the best size's."""
    return f"not designed in full: {screen.describe()}; {best_size} pads {best.describe()}"
