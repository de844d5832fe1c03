"""How much a finger delivered before keeps of a new job's scenarios (METHOD §11b).

A cell keeps the fingers it printed. A new job whose parts are not the same
as the parts a finger was designed for may still be served by it: every
scenario of the new job (a part in a chosen stable pose) is found its solo
quality ``E*`` (METHOD §11, the finger designed for it alone) and its best
grasp on the delivered pad (:func:`evaluate_on_pad`); the
finger serves the part when every one of its scenarios keeps
``retained = E / E*`` of at least ``[finger_sets] min_retained``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from .capture import capture_landscape
from .config import DesignConfig
from .contact import seat
from .evaluate import Scenario, ScenarioEvaluation, holding_n
from .grid import ScreenGrid, column_heights
from .measure import scenario_measure
from .parallel import WorkerPool
from .parts import Part
from .pipeline import Prepared, prepare
from .pipeline.report import grasp_report
from .printfit import closing_travel_mm
from .progress import Progress
from .report.models import GraspReport
from .rles import rles
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


def pad_face_heights(
    pad_vertices: np.ndarray, pad_faces: np.ndarray, grid: ScreenGrid, thickness_mm: float
) -> np.ndarray:
    """The face heights ``P = {u >= H}`` of a pad mesh as it was printed: the smallest ``u`` on each cell's ray.

    Parameters
    ----------
    pad_vertices, pad_faces : ndarray
        The pad, pad frame (mm).
    grid : ScreenGrid
    thickness_mm : float
        Pad thickness T: the face where the pad is open through (a thin wall removed).

    Returns
    -------
    (count_v, count_w) float, mm
    """
    # the largest u' = T + 1 - u is the smallest u; 0 (no triangle on the ray) means open through
    flipped = np.column_stack([thickness_mm + 1.0 - pad_vertices[:, 0], pad_vertices[:, 1:]])
    top = column_heights(flipped, pad_faces, grid).astype(np.float64)
    heights = np.where(top > 0, thickness_mm + 1.0 - top, thickness_mm)
    return heights.reshape(grid.count_v, grid.count_w)


def evaluate_on_pad(
    scenario: Scenario, pad_vertices: np.ndarray, pad_faces: np.ndarray, config: DesignConfig
) -> tuple[int, ScenarioEvaluation] | None:
    """The best grasp of one scenario on a given printed pad (a finger delivered before, METHOD §11b).

    Every valid sample is seated against the pad (METHOD §6, with the closing
    travel of ``[print]``'s clearance, as the printed pad is evaluated); under
    the capture measure the ``search.exact_top_k`` samples of largest E are
    squeezed and pushed (METHOD §7b) and the best measure wins.

    Parameters
    ----------
    scenario : Scenario
        With its samples (:func:`fcso.pipeline.prepare`).
    pad_vertices, pad_faces : ndarray
        The printed pad, pad frame (mm), a closed mesh.
    config : DesignConfig
        The settings the pad was designed with (pad size, contact tolerance, fit, measure).

    Returns
    -------
    (sample index, ScenarioEvaluation), or None when no sample touches the pad.
    """
    if not scenario.samples:
        return None
    travel = closing_travel_mm(config.print.resolved()["clearance_mm"])
    drawn = [sample.surfaces for sample in scenario.samples]
    seated = seat([s for pair in drawn for s in pair], pad_vertices, pad_faces, config.contact.eps_mm, travel_mm=travel)
    results = []
    for index, sample in enumerate(scenario.samples):
        contacts = (seated[2 * index], seated[2 * index + 1])
        normals = np.vstack(
            [s.normals[c.contact] @ f[:3, :3] for s, c, f in zip(drawn[index], contacts, sample.frames)]
        )
        area = float(sum(c.contact_area_mm2 for c in contacts))
        radius = rles(normals) if len(normals) else 2.0
        effective = area / radius if area > 0 else 0.0
        results.append(ScenarioEvaluation(contacts, normals, radius, area, effective, measure=effective))
    if config.quality.measure == "capture":
        grid = ScreenGrid.for_config(config)
        pad = pad_face_heights(pad_vertices, pad_faces, grid, config.sampler.thickness_mm)
        shape = (grid.count_v, grid.count_w)
        ranked = np.argsort([-r.effective_area for r in results], kind="stable")[: config.search.exact_top_k]
        for index in ranked:
            sample, result = scenario.samples[index], results[index]
            landscape = capture_landscape(
                pad,
                (sample.screen[0].heights_mm.reshape(shape), sample.screen[1].heights_mm.reshape(shape)),
                sample.centres_uv_mm,
                grid.cell_mm,
                config.sampler.penetration_mm,
                sample.width_mm,
                config.verify,
                sample.sample.sliding_axis,
            )
            holding = holding_n(
                scenario, sample, drawn[index], [c.contact for c in result.contacts], result.contact_normals, config
            )
            holding_share = min(1.0, float(holding.min()) / config.verify.hold_force_n)
            measure = (
                scenario_measure(landscape.fraction, holding_share, result.effective_area, config)
                if landscape.pads_gap_mm > 0
                else 0.0
            )
            results[index] = dataclasses.replace(result, measure=measure, capture=landscape, holding_n=holding)
        # samples not squeezed keep no measure under the capture measure
        kept = set(int(i) for i in ranked)
        results = [r if i in kept else dataclasses.replace(r, measure=0.0) for i, r in enumerate(results)]
    best = int(np.argmax([r.measure for r in results]))
    if results[best].measure <= 0:
        return None
    return best, results[best]
