"""How much a finger delivered before keeps of a new job's scenarios (METHOD §11b).

A cell keeps the fingers it printed. A new job whose parts are not the same
as the parts a finger was designed for may still be served by it: every
scenario of the new job (a part in a chosen stable pose) is found its solo
quality ``E*`` (METHOD §11, the finger designed for it alone) and its best
grasp on the delivered pad (:func:`fcso.evaluate.evaluate_on_pad`); the
finger serves the part when every one of its scenarios keeps
``retained = E / E*`` of at least ``[finger_sets] min_retained``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from .config import DesignConfig
from .evaluate import evaluate_on_pad
from .parallel import WorkerPool
from .parts import Part
from .pipeline import Prepared, prepare
from .pipeline.report import grasp_report
from .progress import Progress
from .report.models import GraspReport
from .sets.screening import solo_quality


@dataclass
class KeptScenario:
    """One scenario of the new job on a delivered pad.

    Attributes
    ----------
    part : str
    pose_index : int
    solo_quality : float
        ``E*``: its quality on a finger designed for it alone (METHOD §11).
    quality : float
        Its best quality on the delivered pad (0 when no sample touches it).
    retained : float
        ``quality / solo_quality``, 0..1 (may pass 1 a little: ``E*`` is searched, not proven best).
    grasp : GraspReport or None
        The grasp giving ``quality``, None when none touches.
    """

    part: str
    pose_index: int
    solo_quality: float
    quality: float
    retained: float
    grasp: GraspReport | None


@dataclass
class PadFit:
    """What one delivered pad keeps of a job: its graspable scenarios, part by part in the job's order.

    Attributes
    ----------
    scenarios : list of KeptScenario
    left_out : list of str
        Scenarios no finger could grasp (no valid sample, or no contact even
        alone): a design leaves them out too, so they do not count.
    """

    scenarios: list[KeptScenario]
    left_out: list[str]

    @property
    def worst_retained(self) -> float:
        """The smallest retained quality of any scenario (1.0 when there is none)."""
        return min((s.retained for s in self.scenarios), default=1.0)

    def part_worst_retained(self, part: str) -> float:
        """The smallest retained quality of ``part``'s scenarios (1.0 when it has none)."""
        return min((s.retained for s in self.scenarios if s.part == part), default=1.0)


def fit_pads(
    parts: Sequence[Part],
    pads: Sequence[trimesh.Trimesh],
    config: DesignConfig,
    progress: Progress | None = None,
) -> list[PadFit]:
    """What each of some delivered pads keeps of a job's scenarios (METHOD §11b).

    Parameters
    ----------
    parts : sequence of Part
        The new job's distinct parts, mm (:func:`fcso.load_parts`).
    pads : sequence of trimesh.Trimesh
        Delivered pads alone, each in its pad frame (mm), as
        :attr:`fcso.DesignResult.fingerpad` gives them.
    config : DesignConfig
        The settings the pads were designed with; the job's scenarios are
        chosen and sampled with them.
    progress : callable, optional

    Returns
    -------
    list of PadFit, one per pad.

    Raises
    ------
    NoGraspError
        No scenario of the job has a valid sample.
    """
    prepared = prepare(list(parts), config, progress=progress)
    count = len(prepared.scenarios)
    with WorkerPool((prepared, config), min(prepared.jobs, max(count, 1)), config.compute.scheduler) as pool:
        solos = pool.map(_solo_task, list(range(count)))
        left_out = [f"{u.part} pose {u.pose_index}" for u in prepared.ungraspable]
        left_out += [
            f"{s.part.name} pose {s.pose_index}" for s, solo in zip(prepared.scenarios, solos) if solo.exact <= 0
        ]
        graspable = [m for m in range(count) if solos[m].exact > 0]
        fits = []
        for pad in pads:
            tasks = [
                (m, np.asarray(pad.vertices, dtype=np.float64), np.asarray(pad.faces, dtype=np.int64))
                for m in graspable
            ]
            kept = []
            for m, best in zip(graspable, pool.map(_pad_task, tasks)):
                scenario, solo = prepared.scenarios[m], solos[m].exact
                quality = best[1].measure if best else 0.0
                kept.append(
                    KeptScenario(
                        part=scenario.part.name,
                        pose_index=scenario.pose_index,
                        solo_quality=solo,
                        quality=quality,
                        retained=quality / solo,
                        grasp=grasp_report(scenario, best[0], best[1], config) if best else None,
                    )
                )
            fits.append(PadFit(kept, left_out))
    return fits


def _solo_task(context: tuple[Prepared, DesignConfig], number: int):
    prepared, config = context
    return solo_quality(prepared, number, config)


def _pad_task(context: tuple[Prepared, DesignConfig], task: tuple[int, np.ndarray, np.ndarray]):
    prepared, config = context
    number, vertices, faces = task
    return evaluate_on_pad(prepared.scenarios[number], vertices, faces, config)
