"""The chosen candidates' printed pads (METHOD §9b): printed-fit pockets carved on workers, each candidate's pad
made and opened as soon as its own pockets are, and evaluated on it."""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..config import DesignConfig
from ..evaluate import (
    CandidateEvaluation,
    SampleGeometry,
    Scenario,
    candidate_fingerpad,
    evaluate_candidate,
    fit_key,
    fitted_sample,
    opened_pad,
    printed_lead_in_deg,
)
from ..geometry import mesh_arrays, solid_from_mesh_arrays
from ..pad import Fingerpad, PadGeometry
from ..parallel import WorkerPool
from ..printfit import thinnest_wall_mm
from ..progress import Progress, progress_with_note
from ..report.models import (
    GraspReport,
    PrintFitReport,
)
from .report import (
    grasp_report,
    print_fit_report,
)


def finish_candidate(
    scenarios: list[Scenario],
    choice: Sequence[int],
    config: DesignConfig,
    flat: bool = False,
    jobs: int = 1,
    pads: dict[str, tuple] | None = None,
) -> tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """One candidate built as :func:`design` builds its choice: :func:`finish_candidates` of that one."""
    return finish_candidates([(scenarios, tuple(choice))], config, flat, jobs, pads)[0]


def finish_candidates(
    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]],
    config: DesignConfig,
    flat: bool = False,
    jobs: int = 1,
    pads: dict[str, tuple] | None = None,
    progress: Progress | None = None,
    exact: Sequence[CandidateEvaluation | None] | None = None,
    on_finished: Callable[[int, tuple], None] | None = None,
) -> list[tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]]:
    """Candidates built as :func:`design` builds its choice: carved with ``[print]``'s fit, their pads kept.

    ``flat`` builds flat pads on the candidates' grasps instead (:func:`fcso.evaluate.evaluate_candidate`).
    The printed-fit pockets of every candidate's samples (two Minkowski sums
    each) are made on ``jobs`` workers (``[compute] scheduler``'s when set),
    and each candidate's pad (their union, its thin walls opened) as soon as
    its own pockets are: a job's finger sets are finished side by side. Each
    pad is rebuilt from its mesh, so it is the same wherever it was made;
    its evaluations are made here as each pad arrives.

    Parameters
    ----------
    candidates : sequence of (list of Scenario, tuple of int)
        Each candidate's scenarios (samples shared between candidates are carved once) and sample index per
        scenario.
    config : DesignConfig
    flat : bool
    jobs : int
    pads : dict, optional
        Printed pads made before (:func:`pad_key`: mesh arrays, case, block depth); new ones are added. The choice
        by truth keeps one for the candidates of a design, which often carve the same pad.
    progress : callable, optional
    exact : sequence of CandidateEvaluation or None, optional
        Per candidate, its exact evaluation with ``config`` (``keep_pad=False``) when made before, as
        :func:`choose_candidate` makes its finalists': the print-fit report takes its figures and makes only its pad,
        instead of evaluating the candidate again.
    on_finished : callable, optional
        ``on_finished(number, finished)``, called in this process as each candidate is finished (its entry of the
        list returned), while the workers make the others' pads.

    Returns
    -------
    list of (CandidateEvaluation, list of GraspReport, PrintFitReport, list of str)
        Per candidate: the fitted evaluation, its grasps and print-fit report
        as ``report.json`` lists them, and the print-fit warnings.
    """
    finishing = _finishing(candidates, config, flat, pads, exact, on_finished)
    report_progress = progress_with_note(progress)
    report_progress("fingers", 0, len(candidates), f"{len(finishing.missing)} printed-fit pockets")
    tasks = [(_fit_task, item, ("pocket", m)) for m, item in enumerate(finishing.missing)]
    tasks += _pad_tasks(finishing, [c for c, needs in enumerate(finishing.waiting) if not needs])
    workers = min(jobs, len(finishing.missing) + len(candidates))
    with WorkerPool((finishing.shared, config, flat), workers, config.compute.scheduler) as pool:
        _finish_made(finishing)
        pool.run(tasks, lambda tag, result: _on_done(finishing, tag, result))
    _finish_made(finishing)
    report_progress("fingers", len(candidates), len(candidates), "")
    return [finishing.finished[c] for c in range(len(candidates))]


@dataclass
class _Finishing:
    """What :func:`finish_candidates` keeps while its workers carve pockets and make pads.

    Attributes
    ----------
    candidates, config, flat, on_finished
        As given to :func:`finish_candidates`.
    configs : list of DesignConfig
        Per candidate, ``config`` with the lead-in it is printed with.
    fits : list of (float, str or None)
        Per candidate, its lead-in and why it differs from ``config``'s (None when it does not).
    known : list of CandidateEvaluation or None
        Per candidate, its exact evaluation made before, when it holds for the printed candidate.
    shared : list of Scenario
        Every scenario of the candidates once: the workers' shared context.
    number : dict
        ``id(scenario)`` -> its position in ``shared``.
    missing : list of (int, int, float)
        The printed-fit pockets to carve: scenario number in ``shared``, sample index, lead-in.
    waiting : list of set of int
        Per candidate, the positions in ``missing`` of the pockets it still waits for.
    cache : dict
        :func:`pad_key` -> the printed pad made (mesh arrays, case, block depth).
    keys : list of str or None
        Per candidate, its :func:`pad_key` once its pad is asked for.
    started : set of str
        Pads asked of the workers.
    finished : dict
        Candidate number -> its entry of the list returned.
    """

    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]]
    config: DesignConfig
    flat: bool
    on_finished: Callable[[int, tuple], None] | None
    configs: list[DesignConfig]
    fits: list[tuple[float, str | None]]
    known: list[CandidateEvaluation | None]
    shared: list[Scenario]
    number: dict[int, int]
    missing: list[tuple[int, int, float]]
    waiting: list[set[int]]
    cache: dict[str, tuple]
    keys: list[str | None]
    started: set[str] = dataclasses.field(default_factory=set)
    finished: dict[int, tuple] = dataclasses.field(default_factory=dict)


def _finishing(
    candidates: Sequence[tuple[list[Scenario], tuple[int, ...]]],
    config: DesignConfig,
    flat: bool,
    pads: dict[str, tuple] | None,
    exact: Sequence[CandidateEvaluation | None] | None,
    on_finished: Callable[[int, tuple], None] | None,
) -> _Finishing:
    """The start of :func:`finish_candidates`: each candidate's lead-in, the pockets to carve, who waits for which."""
    fits = [
        (config.print.lead_in_deg, None) if flat else printed_lead_in_deg(scenarios, choice, config)
        for scenarios, choice in candidates
    ]
    configs = [config if why is None else _with_lead_in(config, angle) for angle, why in fits]
    # every scenario of the candidates once: the workers' shared context
    shared = list({id(s): s for scenarios, _ in candidates for s in scenarios}.values())
    number = {id(s): n for n, s in enumerate(shared)}
    missing = list(
        dict.fromkeys(
            (number[id(scenarios[m])], k, fitted_config.print.lead_in_deg)
            for (scenarios, choice), fitted_config in zip(candidates, configs)
            if not flat and fit_key(fitted_config) is not None
            for m, k in enumerate(choice)
            if fit_key(fitted_config) not in scenarios[m].samples[k].fitted
        )
    )
    # an exact evaluation made before holds for a candidate printed with config's own lead-in
    known = [None if exact is None or flat or why is not None else exact[c] for c, (_, why) in enumerate(fits)]
    # each candidate's pad is built and opened as soon as its own pockets are carved, while other pockets are still
    # being carved: one long carving or one large pad no longer leaves the other workers waiting (the union of a large
    # set's pockets is minutes of Booleans)
    waiting: list[set[int]] = []  # per candidate, the missing pockets it waits for
    for (scenarios, choice), fitted_config in zip(candidates, configs):
        used = {(number[id(s)], k) for s, k in zip(scenarios, choice)}
        angle = fitted_config.print.lead_in_deg
        waiting.append({m for m, (n, k, a) in enumerate(missing) if (n, k) in used and a == angle})
    cache = {} if pads is None else pads
    return _Finishing(
        candidates,
        config,
        flat,
        on_finished,
        configs,
        fits,
        known,
        shared,
        number,
        missing,
        waiting,
        cache,
        [None] * len(candidates),
    )


def _pad_tasks(finishing: _Finishing, ready: list[int]) -> list[tuple]:
    """The workers' tasks making the pads of candidates ``ready``, whose pockets are all carved."""
    tasks = []
    keys, number = finishing.keys, finishing.number
    for c in ready:
        (scenarios, choice), fitted_config = finishing.candidates[c], finishing.configs[c]
        samples = [s.samples[k] for s, k in zip(scenarios, choice)]
        keys[c] = pad_key(samples, fitted_config, finishing.flat)
        # a pad carved by several candidates is made once
        if keys[c] in finishing.cache or keys[c] in finishing.started:
            continue
        finishing.started.add(keys[c])
        fit = fit_key(fitted_config)
        pockets = (
            {}
            if finishing.flat or fit is None
            else {(number[id(s)], k): s.samples[k].fitted[fit] for s, k in zip(scenarios, choice)}
        )
        item = ([number[id(s)] for s in scenarios], choice, fitted_config.print.lead_in_deg, pockets)
        tasks.append((_pad_task, item, ("pad", keys[c])))
    return tasks


def _finish_made(finishing: _Finishing) -> None:
    """Each candidate whose pad is made evaluated on it, here, while the workers open the others'."""
    for c, ((scenarios, choice), fitted_config, (_, why)) in enumerate(
        zip(finishing.candidates, finishing.configs, finishing.fits)
    ):
        key = finishing.keys[c]
        if c not in finishing.finished and key in finishing.cache:
            fingerpad = Fingerpad(solid_from_mesh_arrays(*finishing.cache[key][0]), *finishing.cache[key][1:])
            finishing.finished[c] = _finished(
                scenarios, choice, fitted_config, finishing.flat, fingerpad, why, finishing.known[c]
            )
            if finishing.on_finished is not None:
                finishing.on_finished(c, finishing.finished[c])


def _on_done(finishing: _Finishing, tag: tuple, result) -> list[tuple]:
    """A worker's pocket or pad arrived: keep it, finish what it completes; the pads now ready to make."""
    kind, what = tag
    if kind == "pad":
        finishing.cache[what] = result
        _finish_made(finishing)
        return []
    n, k, angle = finishing.missing[what]
    finishing.shared[n].samples[k].fitted[fit_key(_with_lead_in(finishing.config, angle))] = result
    ready = []
    for c, needs in enumerate(finishing.waiting):
        if what in needs:
            needs.discard(what)
            if not needs:
                ready.append(c)
    return _pad_tasks(finishing, ready)


def pad_key(samples: Sequence[SampleGeometry], config: DesignConfig, flat: bool) -> str:
    """What a candidate's printed pad depends on: its samples' printed-fit pockets (their exact meshes), the pad box,
    ``[filter]`` and ``[print]``'s minimum wall; or only the box for flat pads."""
    sampler, key = config.sampler, fit_key(config)
    sizes = [sampler.thickness_mm, sampler.length_mm, sampler.width_mm, sampler.penetration_mm]
    sizes += [config.filter.block_factor, config.print.resolved()["min_wall_mm"]]
    digest = hashlib.sha256(np.array(sizes + [float(flat)], dtype="<f8").tobytes())
    geometries = (
        [] if flat else [g for sample in samples for g in (sample.geometries if key is None else sample.fitted[key])]
    )
    for geometry in geometries:
        vertices, triangles = mesh_arrays(geometry.intersection)
        digest.update(np.array([geometry.good, geometry.depth_mm], dtype="<f8").tobytes())
        digest.update(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
        digest.update(np.ascontiguousarray(triangles, dtype="<i8").tobytes())
    return digest.hexdigest()


def _finished(
    scenarios: list[Scenario],
    choice: tuple[int, ...],
    config: DesignConfig,
    flat: bool,
    fingerpad: Fingerpad,
    why: str | None,
    known: CandidateEvaluation | None = None,
) -> tuple[CandidateEvaluation, list[GraspReport], PrintFitReport, list[str]]:
    """One candidate of :func:`finish_candidates` evaluated on its opened pad (``config`` with its lead-in);
    ``known`` its exact evaluation made before, if any."""
    fitted = evaluate_candidate(scenarios, choice, config, keep_pad=True, fitted=True, flat=flat, fingerpad=fingerpad)
    fit, sampler = config.print.resolved(), config.sampler
    if not any(v > 0 for k, v in fit.items() if k != "density_g_cm3"):
        exact = fitted
    elif known is not None:
        # the same evaluation: its figures, and the exact pad the report measures
        exact = dataclasses.replace(known, fingerpad=candidate_fingerpad(scenarios, choice, config))
    else:
        exact = evaluate_candidate(scenarios, choice, config, keep_pad=True, flat=flat)
    thinnest = thinnest_wall_mm(fitted.fingerpad.pad, sampler.thickness_mm, sampler.length_mm, sampler.width_mm)
    warnings: list[str] = [] if why is None else [why]
    # the opening's ball is a polyhedron and the wall is measured by rays: 0.05 mm of slack
    if fit["min_wall_mm"] > 0 and thinnest < fit["min_wall_mm"] - 0.05:
        warnings.append(
            f"the pad keeps a wall of {thinnest:.3f} mm, thinner than print.min_wall_mm = {fit['min_wall_mm']:.3f} mm"
        )
    print_fit = print_fit_report(config, exact, fitted, thinnest)
    return (
        fitted,
        [grasp_report(s, k, e, config) for s, k, e in zip(scenarios, choice, fitted.scenarios)],
        print_fit,
        warnings,
    )


def _with_lead_in(config: DesignConfig, lead_in_deg: float) -> DesignConfig:
    """``config`` with the pockets drafted by ``lead_in_deg`` (a candidate printed with a wider lead-in)."""
    return (
        config if lead_in_deg == config.print.lead_in_deg else config.updated({"print": {"lead_in_deg": lead_in_deg}})
    )


def _fit_task(context, task: tuple[int, int, float]) -> list[PadGeometry]:
    scenarios, config, _ = context
    number, index, lead_in_deg = task
    config = _with_lead_in(config, lead_in_deg)
    return fitted_sample(scenarios[number], scenarios[number].samples[index], config)


def _pad_task(context, task: tuple[list[int], tuple[int, ...], float, dict]) -> tuple:
    """A candidate's printed pad, built and opened from its samples' printed-fit pockets (scenario number, sample
    index -> carved geometries, carved after this worker was forked): its mesh arrays, case and block depth."""
    scenarios, config, flat = context
    numbers, choice, lead_in_deg, pockets = task
    config = _with_lead_in(config, lead_in_deg)
    for (number, index), carved in pockets.items():
        scenarios[number].samples[index].fitted[fit_key(config)] = carved
    pad = candidate_fingerpad([scenarios[n] for n in numbers], choice, config, fitted=True, flat=flat)
    return mesh_arrays(opened_pad(pad.pad, config)), pad.case, pad.block_depth_mm
