"""Finger sets (METHOD §11) on print jobs of 12 and 30 different parts, against one finger for all; the curve to 200.

Run from the repository root::

    python -m benchmarks.bench_sets [--runs N] [--only 12|30]
    python -m benchmarks.bench_sets --curve 30 60 200 [--runs N]
    python -m benchmarks.bench_sets --baseline COMMIT [--runs N]

``--curve`` designs jobs of that many distinct parts with ``--finger-sets 4``
(targets of issue 24: 60 parts <= 90 s, 200 parts <= 10 min and peak memory
<= 4 GB on 2 cores, time per part growing at most like n log n) and prints,
per job, the time, the time per part, its growth against n log n, the worst
retained quality, the partition's time and the peak memory (the design's
process, its largest worker, all together). Every run designs in a fresh
process, as fcsod's workers do.

Each job is the fixture parts in their right units (tests/data/README.md)
plus parametric parts made here with manifold3d (boxes, cylinders, hexagonal
prisms, L brackets and plates with a tapered knob, of several sizes), one
stable pose each (the most probable), the default pad (L = W = 20, T = 5,
D = 4). Prints, medians over N runs (the machine is shared and noisy):

- the whole design with ``[finger_sets] max = 4`` (targets: 12 parts
  <= 60 s, 30 parts <= 180 s), the number of sets, the worst and median
  retained quality ``E / E*`` and how the partition was found;
- the same job with one finger (``max = 1``, the paper's method): its time
  and the worst and median ``E / E*`` (``E*`` from the sets run);
- the checks of the issue: the sets' worst retained is at least the single
  finger's, and reaches ``min_retained`` or the report says which pair blocks it;
- the verified success of each set's finger over its scenarios (issue 48):
  successful precision trials of the set's finger and of flat pads per
  scenario, from the report's ``truth`` with ``--truth SECONDS``
  (``[finger_sets] truth_budget_s``), else simulated after the design.

``--baseline COMMIT`` times the 12-part job (``max = 4``) on this code and
on that commit's code (git archive), whole fresh processes taking turns, wall
and CPU (process and workers): this code with its defaults, this code with
the method the code of b7cf7d7 had (:data:`FIRST_METHOD`: the paper's
measure, the exact pocket, the paper's sampler; METHOD revision 3 made
§7b, §9b and §3b the defaults since), and the commit with its defaults. The
second against the third is the cost of judging sets by their exact designs
(issue 23's target: within 1.5x of the code the issue was filed on, b7cf7d7).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import manifold3d
import numpy as np

import fcso
from fcso.geometry import to_trimesh
from fcso.report import chosen_candidate
from fcso.sets import design_sets

from .bench_design import baseline_tree

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "tests" / "data"

#: Fixture parts with the units tests/data/README.md gives (DC-DC_case.stl holds two solids: two parts).
FIXTURE_PARTS = (
    ("20mm-xyz-cube.stl", "mm", None),
    ("solar_tracker.stl", "mm", None),
    ("capsela200_plug.stl", "mm", None),
    ("DC-DC_case.stl", "mm", None),
    ("angle_block.STL", "inch", None),
    ("featuretype.STL", "inch", None),
    ("stanford_bunny_closed.ply", "mm", 65.0),
)


def box(x: float, y: float, z: float) -> manifold3d.Manifold:
    return manifold3d.Manifold.cube([x, y, z])


def cylinder(diameter: float, height: float) -> manifold3d.Manifold:
    return manifold3d.Manifold.cylinder(height, diameter / 2.0, circular_segments=64)


def hex_prism(across_flats: float, height: float) -> manifold3d.Manifold:
    return manifold3d.Manifold.cylinder(height, across_flats / np.sqrt(3.0), circular_segments=6)


def l_bracket(size: float, thickness: float, depth: float) -> manifold3d.Manifold:
    return box(size, depth, thickness) + box(thickness, depth, size)


def knob(base: float, top_scale: float) -> manifold3d.Manifold:
    """A 60 mm plate, too wide for the gripper, with a 16 mm knob tapering by ``top_scale``."""
    plate = box(60.0, 60.0, 6.0).translate([-30.0, -30.0, 0.0])
    square = manifold3d.CrossSection.square([base, base], center=True)
    return plate + manifold3d.Manifold.extrude(square, 16.0, scale_top=[top_scale, top_scale]).translate(
        [0.0, 0.0, 5.99]
    )


def plate_with_holes(side: float, holes: int) -> manifold3d.Manifold:
    """A square plate 8 mm thick with ``holes`` round holes along its diagonal."""
    plate = box(side, side, 8.0)
    for number in range(holes):
        at = side * (number + 1) / (holes + 1)
        plate = plate - cylinder(side / (2.5 * holes + 2), 8.0).translate([at, at, 0.0])
    return plate


def parametric_parts(count: int) -> list[fcso.Part]:
    """``count`` parametric parts. The first 36: six kinds in turn, each growing in size (the 12- and 30-part jobs).
    Beyond: seven kinds (plates with holes added) with sizes from low-discrepancy sequences inside the gripper's 50 mm
    opening, so large jobs stay graspable and every part differs.
    """
    growing = [
        ("box", lambda k: box(16.0 + 4 * k, 22.0 + 3 * k, 28.0 + 2 * k)),
        ("cylinder", lambda k: cylinder(18.0 + 4 * k, 24.0 + 3 * k)),
        ("knob-narrowing", lambda k: knob(14.0 + 2 * k, 0.7)),
        ("knob-widening", lambda k: knob(9.8 + 1.4 * k, 1 / 0.7)),
        ("hex", lambda k: hex_prism(16.0 + 4 * k, 20.0 + 4 * k)),
        ("bracket", lambda k: l_bracket(24.0 + 4 * k, 5.0, 18.0 + 2 * k)),
    ]
    spread = [
        ("box", lambda k, a, b: box(14 + 28 * a, 16 + 26 * b, 20 + 20 * a)),
        ("cylinder", lambda k, a, b: cylinder(14 + 28 * a, 16 + 24 * b)),
        ("knob-narrowing", lambda k, a, b: knob(10 + 16 * a, 0.6 + 0.3 * b)),
        ("knob-widening", lambda k, a, b: knob(8 + 10 * a, 1.2 + 0.4 * b)),
        ("hex", lambda k, a, b: hex_prism(14 + 26 * a, 16 + 24 * b)),
        ("bracket", lambda k, a, b: l_bracket(20 + 22 * a, 4 + 3 * b, 14 + 24 * b)),
        ("plate-holes", lambda k, a, b: plate_with_holes(30 + 14 * a, 1 + k % 3)),
    ]
    parts = []
    for number in range(count):
        if number < 36:
            name, make = growing[number % len(growing)]
            size = number // len(growing)
            mesh = to_trimesh(make(size))
        else:
            name, make = spread[(number - 36) % len(spread)]
            size = 6 + (number - 36) // len(spread)
            # golden- and silver-ratio sequences: sizes spread evenly without repeating
            mesh = to_trimesh(make(size, (size * 0.6180339887) % 1.0, (size * 0.4142135624) % 1.0))
        parts.append(fcso.Part(name=f"{name}-{size + 1}", path=f"{name}-{size + 1}.stl", mesh=mesh))
    return parts


def job(parts: int) -> list[fcso.Part]:
    """The fixture parts plus parametric ones, ``parts`` in all."""
    fixtures = [
        p for name, units, scale in FIXTURE_PARTS for p in fcso.load_parts(DATA / name, units=units, scale_to_mm=scale)
    ]
    return fixtures + parametric_parts(parts - len(fixtures))


def retained_of_single(single: fcso.DesignResult, stars: dict[tuple[str, int], float]) -> np.ndarray:
    """E / E* of every graspable scenario with one finger for all (E* from the sets run).

    E is read as the sets' report reads it (fcso.pipeline.sets_report.exact_retained): the chosen candidate's exact
    measure per scenario, E in mm² under the paper's measure, METHOD §7b's measure under the capture measure.
    """
    measures = [q.measure for q in chosen_candidate(single.report).per_scenario]
    values = [
        e / stars[(s.part, s.pose_index)]
        for s, e in zip(single.report.scenarios, measures)
        if stars.get((s.part, s.pose_index), 0) > 0
    ]
    return np.array(values)


def served_figures(report) -> str:
    """What issue 48 asks beside the time: worst and median retained, the worst of the served parts, the parts not
    served, the sets used of those allowed and how many the job needs."""
    served = [
        s.retained
        for s in report.scenarios
        if s.retained is not None and s.part not in {n.part for n in report.not_served}
    ]
    return (
        f"worst retained {report.worst_retained:.3f}, median {report.median_retained:.3f}, worst of the served parts "
        + (f"{min(served):.3f}" if served else "-")
        + f" (min_retained {report.min_retained:g}); {len(report.not_served)} parts not served"
        + (f" ({', '.join(n.part for n in report.not_served)})" if report.not_served else "")
        + f"; sets used {len(report.sets)} of {report.sets_allowed} allowed (max {report.max_sets}), the job needs "
        + (str(report.sets_needed) if report.sets_needed is not None else "more than allowed")
    )


def verified_lines(result, config: fcso.DesignConfig) -> tuple[list[str], float]:
    """The verified success of each set's finger over its scenarios (issue 48): per scenario the successful
    precision trials of the set's finger and of flat pads, and whether it passed. From the report's ``truth`` where
    the design simulated the set ([finger_sets] truth_budget_s), else simulated here in full
    (:func:`fcso.sim.verify.verify_delivered`, [verify] as configured). Returns the lines and the seconds simulated
    here."""
    from fcso.sim.config import with_print_density
    from fcso.sim.verify import design_under_test, successes, verify_delivered

    truth = result.report.truth
    known = {v.set: v.scenarios for v in truth.sets} if truth is not None else {}
    lines, clock = [], time.perf_counter()
    for number, design in enumerate(result.designs, start=1):
        if number not in known:
            verification = verify_delivered(design_under_test(design), with_print_density(config.verify, config))
            known[number] = [
                (
                    s.part,
                    successes(s.fcso.trials),
                    len(s.fcso.trials),
                    successes(s.flat.trials),
                    len(s.flat.trials),
                    s.passed,
                )
                for s in verification.scenarios
            ]
        else:
            known[number] = [
                (v.part, v.successes, v.trials, v.flat_successes, v.flat_trials, v.passed) for v in known[number]
            ]
        passed = sum(row[5] for row in known[number])
        lines.append(
            f"    set {number} verified: {passed} of {len(known[number])} scenarios pass; "
            + ", ".join(f"{part} {k}/{n} (flat {fk}/{fn})" for part, k, n, fk, fn, _ in known[number])
        )
    return lines, time.perf_counter() - clock


def run_case(parts: int, runs: int, target_s: float, max_sets: int | str = 4, truth_s: float = 0.0) -> None:
    config = fcso.DesignConfig().updated(
        {
            "poses": {"count": 1, "select": "most_probable"},
            "finger_sets": {"max": max_sets, "truth_budget_s": truth_s},
        }
    )
    single_config = config.updated({"finger_sets": {"max": 1}})
    loaded = job(parts)
    sets_seconds, single_seconds, sets_cpu = [], [], []
    for _ in range(runs):
        started, started_cpu = time.perf_counter(), cpu_seconds()
        result = design_sets(loaded, config)
        sets_seconds.append(time.perf_counter() - started)
        sets_cpu.append(cpu_seconds() - started_cpu)
        started = time.perf_counter()
        single = design_sets(loaded, single_config).designs[0]
        single_seconds.append(time.perf_counter() - started)
    report = result.report
    stars = {(s.part, s.pose_index): s.solo_quality for s in report.scenarios}
    single_retained = retained_of_single(single, stars)
    sets_median = statistics.median(sets_seconds)
    print(
        f"{parts}-part job ({len(report.scenarios)} scenarios, {len(report.ungraspable_parts)} ungraspable parts: "
        f"{', '.join(report.ungraspable_parts) or 'none'})"
    )
    print(
        f"  finger sets (max {report.max_sets}, min_retained {report.min_retained:g}): {sets_median:.1f} s median of "
        f"{runs} "
        f"(target <= {target_s:.0f} s: {'met' if sets_median <= target_s else 'NOT met'}), CPU (main + workers) "
        f"{statistics.median(sets_cpu):.1f} s; timings of the last run: "
        f"{result.designs[0].report.timings_s if result.job_report is None else result.job_report.timings_s}"
    )
    print(f"  {served_figures(report)}; partition: {report.search.method}")
    print(f"  pad sizes: {pad_sizes_figures(report.pad_sizes)}")
    print(
        f"  lower bound {report.search.lower_bound_sets} sets (pairwise conflicting: "
        f"{', '.join(report.search.conflict_clique)}), "
        f"{len(report.search.blocking_pairs)} conflicting pairs, {report.search.set_screenings} sets screened, sets "
        f"tried {report.search.sets_tried}"
    )
    for entry in report.sets:
        print(
            f"    set {entry.set}: {len(entry.parts)} parts, Q {entry.quality:.1f} mm², worst retained "
            f"{entry.worst_retained:.3f}: {', '.join(entry.parts)}"
        )
    if report.truth is not None:
        print(
            f"  judged by truth: {report.truth.spent_s:.0f} s of {report.truth.budget_s:g} s simulated, moved "
            f"{report.truth.moved_parts or 'none'}, not served by truth {report.truth.not_served_parts or 'none'}"
        )
    lines, simulated_s = verified_lines(result, config)
    print("\n".join(lines) + (f"\n    (simulated after the design: {simulated_s:.0f} s)" if simulated_s > 1 else ""))
    print(
        f"  one finger (--finger-sets 1): {statistics.median(single_seconds):.1f} s median of {runs}, Q "
        f"{single.best.quality:.1f} mm², "
        f"worst retained {single_retained.min():.3f}, median {np.median(single_retained):.3f}"
    )
    better = report.worst_retained >= single_retained.min() - 1e-9
    print(f"  sets' worst retained >= one finger's: {'yes' if better else 'NO'}")
    if report.min_retained_reached:
        print(f"  min_retained {report.min_retained:g} reached by every graspable scenario")
    else:
        print(f"  min_retained {report.min_retained:g} NOT reached; the report says: {report.search.explanation}")


#: The settings that give the method of b7cf7d7, before METHOD revision 3 changed its defaults: ranked by the
#: paper's Q (§7), the exact pocket (§9b's ``custom`` profile), the paper's sampler (no §3b positions or face yaws)
#: and the paper's filter (no wrapped faces).
FIRST_METHOD = {
    "quality": {"measure": "paper"},
    "print": {"profile": "custom"},
    "sampler": {"feature_positions": False, "face_yaws": False},
    "filter": {"wrapped_faces": False},
}

#: One design of a job in a fresh process, on whichever fcso its working folder holds: argv = the parts' folder and
#: the configuration changes as JSON; prints the wall and CPU seconds, the number of sets and the worst retained.
_JOB_CHILD = """
import glob, json, resource, sys, time
import fcso
parts = [p for f in sorted(glob.glob(sys.argv[1] + '/*.stl')) for p in fcso.load_parts(f)]
config = fcso.DesignConfig().updated(json.loads(sys.argv[2]))
started = time.perf_counter()
result = fcso.design_sets(parts, config)
wall = time.perf_counter() - started
cpu = sum(getattr(resource.getrusage(w), f) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
          for f in ('ru_utime', 'ru_stime'))
print(json.dumps({'wall_s': wall, 'cpu_s': cpu, 'sets': len(result.designs), 'worst': result.report.worst_retained}))
"""


def run_baseline(commit: str, runs: int) -> None:
    """The 12-part job on this code and on ``commit``'s, fresh processes in turns (see the module's docstring)."""
    base = {"poses": {"count": 1, "select": "most_probable"}, "finger_sets": {"max": 4}}
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "job"
        folder.mkdir()
        for part in job(12):
            part.mesh.export(folder / f"{part.name}.stl")
        old_tree = baseline_tree(commit, Path(scratch) / "old")
        variants = [
            ("this code, its defaults", REPO, base),
            ("this code, the method of b7cf7d7 (FIRST_METHOD)", REPO, {**base, **FIRST_METHOD}),
            (f"{commit}, its defaults", old_tree, base),
        ]
        measured: list[list[dict]] = [[] for _ in variants]
        for _ in range(runs):
            for figures, (_, tree, changes) in zip(measured, variants):
                done = subprocess.run(
                    [sys.executable, "-c", _JOB_CHILD, str(folder), json.dumps(changes)],
                    cwd=tree,
                    env={**os.environ, "PYTHONPATH": str(tree)},
                    check=True,
                    capture_output=True,
                    text=True,
                )
                figures.append(json.loads(done.stdout.splitlines()[-1]))
    print(f"12-part job, max = 4 sets, {runs} runs of each in turns (fresh processes), medians:")
    walls = [statistics.median(m["wall_s"] for m in figures) for figures in measured]
    for (name, _, _), figures, wall in zip(variants, measured, walls):
        each = ", ".join(f"{m['wall_s']:.1f}" for m in figures)
        print(
            f"  {name}: {wall:.1f} s wall (runs {each}), "
            f"{statistics.median(m['cpu_s'] for m in figures):.1f} s CPU; {figures[-1]['sets']} sets, worst retained "
            f"{figures[-1]['worst']:.3f}"
        )
    print(
        f"  the same method on both codes: {walls[1] / walls[2]:.2f}x {commit}'s wall (issue 23's target <= 1.5x: "
        f"{'met' if walls[1] <= 1.5 * walls[2] else 'NOT met'}); this code's defaults: {walls[0] / walls[2]:.2f}x"
    )


def peak_memory_mb() -> tuple[float, float]:
    """Peak resident memory of this process and of its largest finished worker, MB (Linux reports KiB)."""
    return (
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0,
    )


def _descendants(pid: int) -> list[int]:
    """``pid`` and every process below it (Linux ``/proc/<pid>/task/<tid>/children``)."""
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        found.append(current)
        for task in Path(f"/proc/{current}/task").glob("*"):
            try:
                todo.extend(int(c) for c in (task / "children").read_text().split())
            except OSError:  # the process ended while it was read
                continue
    return found


def proportional_set_mb(pid: int) -> float:
    """The memory of ``pid`` and its worker processes together, MB: the sum of their proportional set sizes (PSS:
    each shared page counted once, split among the processes sharing it; forked workers share most of the job)."""
    total_kib = 0
    for process in _descendants(pid):
        try:
            for line in Path(f"/proc/{process}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    total_kib += int(line.split()[1])
                    break
        except OSError:
            continue
    return total_kib / 1024.0


class PeakProportionalSet:
    """Samples :func:`proportional_set_mb` of this process every ``interval_s`` in a thread while in a ``with``
    block; ``peak_mb`` is the largest sample (a sampled peak: a spike shorter than the interval can be missed)."""

    def __init__(self, interval_s: float = 0.5):
        self.interval_s, self.peak_mb = interval_s, 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while not self._stop.is_set():
            self.peak_mb = max(self.peak_mb, proportional_set_mb(os.getpid()))
            self._stop.wait(self.interval_s)

    def __enter__(self) -> PeakProportionalSet:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def cpu_seconds() -> float:
    """CPU time of this process and its finished workers, s: on a shared machine, wall time / cores understates it."""
    own, workers = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + workers.ru_utime + workers.ru_stime


def stage_log(stage: str, done: int, total: int, note: str = "", _last=[None]) -> None:  # noqa: B006
    """Stage changes on standard error with the time and this process's peak memory so far: where a long run spends
    them."""
    if stage != _last[0]:
        _last[0] = stage
        print(
            f"  [{time.strftime('%H:%M:%S')}, peak {peak_memory_mb()[0]:.0f} MB] {stage} {done}/{total} {note}",
            file=sys.stderr,
            flush=True,
        )


def curve_run(parts: int, max_sets: int | str = 4) -> dict:
    """One design of the curve's job of ``parts`` parts, in this process (a fresh one: :func:`run_curve`).

    Returns its wall and CPU seconds, the peak memory of this process, of its largest worker and of all of them
    together (PSS), and the report's figures as printed.
    """
    config = fcso.DesignConfig().updated(
        {"poses": {"count": 1, "select": "most_probable"}, "finger_sets": {"max": max_sets}}
    )
    loaded = job(parts)
    started, started_cpu = time.perf_counter(), cpu_seconds()
    with PeakProportionalSet() as memory:
        result = design_sets(loaded, config, progress=stage_log)
    seconds, cpu = time.perf_counter() - started, cpu_seconds() - started_cpu
    report = result.report
    attempts = "; ".join(
        f"{a.sets} sets screened "
        + ("-" if a.screened_worst_retained is None else f"{a.screened_worst_retained:.3f}")
        + f" exact {a.exact_worst_retained:.3f}"
        + (" chosen" if a.chosen else "")
        for a in report.search.attempts
    )
    return {
        "seconds": seconds,
        "cpu_s": cpu,
        "memory_mb": (*peak_memory_mb(), memory.peak_mb),
        "partition_s": result.job().timings_s.get("partition", 0.0),
        "figures": f"{len(report.sets)} | {report.worst_retained:.3f} (median {report.median_retained:.3f}) | "
        f"{report.search.method}",
        "served": served_figures(report),
        "details": f"timings {result.job().timings_s}; sets tried {report.search.sets_tried}, lower bound "
        f"{report.search.lower_bound_sets}, {report.search.set_screenings} set searches; attempts {attempts}; "
        f"pad sizes {pad_sizes_figures(report.pad_sizes)}",
    }


def pad_sizes_figures(sizes) -> str:
    """Each pad size's length, its quality when designed (the delivered one marked), else why not (issue 48)."""
    return "; ".join(
        f"{e.length_mm:g} mm "
        + (f"quality {e.quality:.3g}" if e.quality is not None else e.note or "")
        + (" (delivered)" if e.chosen else "")
        for e in sizes
    )


def run_curve(sizes: list[int], runs: int, max_sets: int | str = 4) -> None:
    """The scaling curve of issue 24: time, time per part, worst retained and peak memory per job size.

    Every run designs in a fresh process, as fcsod's workers do (one job each): a process that has designed a large
    job keeps its memory, and its next design forks workers from it and runs 15-20 % slower (60 parts: 77 s first,
    90 and 91 s after).
    """
    targets = {60: 90.0, 200: 600.0}
    first: tuple[int, float] | None = None
    print(
        "parts | whole design s (median of runs) | CPU s | s per part | growth vs n log n | partition s | sets | "
        "worst retained (median) | method | peak MB (main, largest worker) | peak MB of all processes together (PSS)"
    )
    for parts in sizes:
        measured = []
        for _ in range(runs):
            # not multiprocessing.Pool: its processes are daemons, which may not fork the design's workers
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as fresh:
                measured.append(fresh.submit(curve_run, parts, max_sets).result())
        median = statistics.median(m["seconds"] for m in measured)
        per_part = median / parts
        if first is None:
            first = (parts, per_part)
        # time per part against the n log n law from the first size (1.0: exactly n log n; below: better)
        growth = (per_part / first[1]) / (math.log(parts) / math.log(first[0]))
        main_mb, worker_mb, together_mb = (max(m["memory_mb"][k] for m in measured) for k in range(3))
        target = targets.get(parts)
        verdict = "" if target is None else f" (target <= {target:.0f} s: {'met' if median <= target else 'NOT met'})"
        print(
            f"{parts} | {median:.1f}{verdict} | {statistics.median(m['cpu_s'] for m in measured):.1f} | "
            f"{per_part:.2f} | {growth:.2f} | {statistics.median(m['partition_s'] for m in measured):.1f} | "
            f"{measured[-1]['figures']} | {main_mb:.0f}, {worker_mb:.0f} | {together_mb:.0f}",
            flush=True,
        )
        each = ", ".join(f"{m['seconds']:.1f}" for m in measured)
        print(f"    runs {each} s; {measured[-1]['served']}", flush=True)
        print(f"    {measured[-1]['details']}", flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per figure (medians)")
    parser.add_argument("--only", type=int, choices=(12, 30), help="one job only")
    parser.add_argument("--curve", type=int, nargs="+", help="job sizes (distinct parts) of the scaling curve")
    parser.add_argument("--baseline", metavar="COMMIT", help="the 12-part job on this code and on COMMIT's, in turns")
    parser.add_argument(
        "--max", default="4", help="[finger_sets] max of the sets runs and the curve: a number or auto (default 4)"
    )
    parser.add_argument(
        "--truth",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="[finger_sets] truth_budget_s of the 12- and 30-part sets runs (default 0: judged by the measure alone; "
        "the sets' fingers are then simulated after the design for the verified figures)",
    )
    args = parser.parse_args(argv)
    max_sets = args.max if args.max == "auto" else int(args.max)
    if args.baseline:
        run_baseline(args.baseline, args.runs)
        return
    if args.curve:
        run_curve(args.curve, args.runs, max_sets)
        return
    for parts, target in ((12, 60.0), (30, 180.0)):
        if args.only in (None, parts):
            run_case(parts, args.runs, target, max_sets, args.truth)


if __name__ == "__main__":
    main()
