"""A finger set's designs at the job's other pad sizes (METHOD §3b), for its choice by truth."""

from __future__ import annotations

from dataclasses import dataclass

from ..config import DesignConfig
from ..errors import GeometryError, NoGraspError
from ..parts import Part
from ..pipeline import DesignResult, design


def size_of(config: DesignConfig) -> tuple[float, float]:
    """The pad size of settings of one size: length and width, mm."""
    return config.sampler.length_mm, config.sampler.width_mm


@dataclass
class OtherSizes:
    """A set's designs at the job's other pad sizes (METHOD §3b), for the choice by truth
    (:func:`fcso.sim.choose.verify_top`): those the job designed, then each other size designed for the set's parts
    alone (:func:`fcso.pipeline.design`) the first time the choice asks for it, which it does only when no candidate
    of the sizes before passes. A set of one part is then chosen among the sizes a job of that part alone offers.

    Attributes
    ----------
    designed : list of DesignResult
        Designed so far, in the choice's order.
    parts : list of Part
        The set's parts.
    to_design : list of DesignConfig
        Settings of one pad size each, not designed yet.
    repair : bool
    """

    designed: list[DesignResult]
    parts: list[Part]
    to_design: list[DesignConfig]
    repair: bool

    @classmethod
    def of(
        cls,
        result: DesignResult,
        designed: list[DesignResult],
        parts: list[Part],
        config: DesignConfig,
        repair: bool,
        sizes: list[DesignConfig] | None = None,
    ) -> OtherSizes:
        """The other sizes of set design ``result``: ``designed``, then the sizes of ``sizes`` (default:
        ``config.pad_size_configs()``) neither has."""
        have = {size_of(d.report.settings) for d in [result, *designed]}
        to_design = [c for c in sizes or config.pad_size_configs() if size_of(c) not in have]
        return cls(list(designed), parts, to_design, repair)

    def __iter__(self):
        yield from list(self.designed)
        while self.to_design:
            sized = self.to_design.pop(0)
            try:
                self.designed.append(design(self.parts, sized, repair=self.repair))
            except (NoGraspError, GeometryError):
                # no finger of this size for these parts: the choice goes on to the next size
                continue
            yield self.designed[-1]
