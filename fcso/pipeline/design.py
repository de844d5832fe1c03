"""A design of one finger (METHOD §1-9), every pad size of ``[sampler]`` tried."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from ..config import DesignConfig
from ..errors import NoGraspError
from ..parts import Part
from ..progress import Progress, progress_with_note
from ..report.models import PadSizeReport
from ..report.ranking import chosen_candidate
from .choose import choose_candidate
from .finish import DesignResult, finish_design
from .prepare import Prepared, prepare
from .report import (
    rounded,
)

#: A design of one pad size: a finger's (:class:`DesignResult`) or a job's finger sets'.
Designed = TypeVar("Designed")


@dataclass(frozen=True)
class SizeScore:
    """How one pad size's design competes with the others' (:func:`best_pad_size`).

    Attributes
    ----------
    rank : tuple
        Compared as a tuple: the largest is delivered.
    quality : float
        Reported: the design's quality (for finger sets the worst set's).
    flat_pads : bool
        It delivered flat pads somewhere.
    """

    rank: tuple
    quality: float
    flat_pads: bool


def design(
    parts: Sequence[Part | str | Path],
    config: DesignConfig | None = None,
    progress: Progress | None = None,
    repair: bool = False,
) -> DesignResult:
    """Design one fingerpad and finger for a batch of parts (METHOD §1-9).

    Parameters
    ----------
    parts : sequence of Part or path
        The parts; paths are loaded in mm with :func:`fcso.load_parts` (a
        file may give several parts; load them yourself for other units or
        scaling).
    config : DesignConfig, optional
        Settings; the defaults are the product's (METHOD §7b's capture measure, the mjf-pa12 fit), and
        ``examples/paper.toml`` holds the paper's set-up (METHOD §10).
    progress : callable, optional
        ``progress(stage, done, total, note)``.
    repair : bool
        Repair part and finger meshes that are not closed volumes.

    Returns
    -------
    DesignResult

    Raises
    ------
    MeshError, ConfigError
        Bad input, naming the file and the defect.
    NoGraspError
        No scenario has a valid sample. Scenarios without one are left out
        and listed in the report's ``ungraspable`` when others can be served.
    """
    config = config or DesignConfig()

    made: list[DesignResult] = []

    def design_one_size(sized: DesignConfig) -> DesignResult:
        made.append(design_prepared(prepare(parts, sized, progress=progress, repair=repair), sized, progress))
        return made[-1]

    def score(result: DesignResult) -> SizeScore:
        chosen = chosen_candidate(result.report)
        flat = result.report.finger.flat_pads
        return SizeScore((not flat, chosen.quality, chosen.mean_effective_area), chosen.quality, flat)

    result, sizes = best_pad_size(config, design_one_size, score, progress)
    result.report = result.report.model_copy(update={"pad_sizes": sizes})
    result.other_sizes = sorted((r for r in made if r is not result), key=lambda r: score(r).rank, reverse=True)
    return result


def best_pad_size(
    config: DesignConfig,
    run: Callable[[DesignConfig], Designed],
    score: Callable[[Designed], SizeScore],
    progress: Progress | None = None,
    screened_out: Sequence[str | None] = (),
) -> tuple[Designed, list[PadSizeReport]]:
    """Design with every pad size of ``[sampler]`` and keep the best (METHOD §3b).

    The two fingers carry one pad box, so a size is a choice for the whole
    design: each size is designed in full and they compete by ``score``,
    except the sizes the caller's screen left out (``screened_out``).

    Parameters
    ----------
    config : DesignConfig
        Settings, ``length_mm`` / ``width_mm`` possibly lists.
    run : callable
        Designs with the settings of one size (:meth:`DesignConfig.pad_size_configs`).
    score : callable
        A result's :class:`SizeScore`: the largest rank is delivered, the first size on a tie.
    progress : callable, optional
        ``progress("pad size", done, total, note)`` when there are several sizes.
    screened_out : sequence of str or None, optional
        Per size of :meth:`DesignConfig.pad_size_configs`, why the caller's screen left it out (not designed: its
        entry says so, with this ``note``), or None to design it; every size is designed when empty.

    Returns
    -------
    result, sizes
        The best size's result and every size's entry for the report.

    Raises
    ------
    NoGraspError
        No size can grasp any part (the first size's error).
    """
    report_progress = progress_with_note(progress)
    sized = config.pad_size_configs()
    results: list[Designed | None] = []
    notes: list[str | None] = []
    for number, one in enumerate(sized):
        if screened_out and screened_out[number] is not None:
            results.append(None)
            notes.append(screened_out[number])
            continue
        if len(sized) > 1:
            report_progress(
                "pad size", number, len(sized), f"{one.sampler.length_mm:g} x {one.sampler.width_mm:g} mm pads"
            )
        try:
            results.append(run(one))
            notes.append(None)
        except NoGraspError as error:
            if len(sized) == 1:
                raise
            results.append(None)
            notes.append(f"no grasp: {error}")
    if all(r is None for r in results):
        raise NoGraspError(f"no pad size grasps any part: {notes[0]}")
    scores = [score(r) if r is not None else None for r in results]
    chosen = max((k for k in range(len(sized)) if scores[k] is not None), key=lambda k: (scores[k].rank, -k))
    if len(sized) > 1:
        report_progress("pad size", len(sized), len(sized), "")
    entries = [
        PadSizeReport(
            length_mm=one.sampler.length_mm,
            width_mm=one.sampler.width_mm,
            quality=rounded(scores[k].quality) if scores[k] is not None else None,
            flat_pads=scores[k] is not None and scores[k].flat_pads,
            chosen=k == chosen,
            screened_out=bool(screened_out) and screened_out[k] is not None,
            note=notes[k],
        )
        for k, one in enumerate(sized)
    ]
    return results[chosen], entries


def design_prepared(prepared: Prepared, config: DesignConfig, progress: Progress | None = None) -> DesignResult:
    """Search, re-evaluate and fuse: :func:`design` after :func:`prepare` (METHOD §6-9).

    Parameters
    ----------
    prepared : Prepared
        From :func:`prepare`, or a :func:`subset` of it.
    config : DesignConfig
        The settings ``prepared`` was made with.
    progress : callable, optional
        ``progress(stage, done, total, note)``.

    Returns
    -------
    DesignResult
    """
    return finish_design(prepared, choose_candidate(prepared, config, progress), config, progress)
