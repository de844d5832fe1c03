"""Speed of fcso's method core against the targets of the speed issue (METHOD §8b).

Run from the repository root::

    python -m benchmarks.bench_design [--runs N] [--baseline COMMIT] [--skip-budget] [--paper-only] [--one-part-only]

Prints, as medians over N runs (the machine is shared and noisy):

- the default ``fcso design`` command on one part in two poses (the holed,
  notched 30 mm cube: capture and holding, pads on features, the MJF print
  fit) and, with ``--baseline``, the same command on that commit's code in
  turns (METHOD §7b's target: within 2x of the code before it);
- the paper experiment as a user runs it: the whole ``fcso design`` command
  in a subprocess, imports and report.html included (target <= 3 s), and,
  with ``--baseline``, the same command on the code of that commit, the two
  taking turns (the ratio);
- screening throughput with 2 scenarios (the paper experiment) and with 16
  (targets >= 1000 and >= 200 candidates/s, all cores);
- the whole design of 8 fixture parts x 2 poses = 16 scenarios (target
  <= 60 s), its peak memory (<= 2 GB) and the Q gained by 10 times the
  search budget (< 2 %);
- the four-part print job of the speed issue (target <= 20 s).
"""

from __future__ import annotations

import argparse
import itertools
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

import fcso
from examples.sim_parts import holed_notched_cube
from fcso.parallel import WorkerPool, resolve_jobs
from fcso.pipeline import prepare, screen_choice

REPO = Path(__file__).resolve().parent.parent
PARTS = REPO / "examples" / "parts"
DATA = REPO / "tests" / "data"

#: The 8 parts of the 16-scenario case, with the units tests/data/README.md gives
#: (DC-DC_case.stl holds two separate solids, so it gives two of the eight parts).
SIXTEEN_SCENARIO_PARTS = (
    ("20mm-xyz-cube.stl", "mm", None),
    ("solar_tracker.stl", "mm", None),
    ("capsela200_plug.stl", "mm", None),
    ("angle_block.STL", "inch", None),
    ("featuretype.STL", "inch", None),
    ("DC-DC_case.stl", "mm", None),
    ("stanford_bunny_closed.ply", "mm", 65.0),
)
#: The four-part job of the speed issue.
FOUR_PART_JOB = ("20mm-xyz-cube.stl", "solar_tracker.stl", "capsela200_plug.stl", "DC-DC_case.stl")


def paper_command(python: str, source: Path, out: Path) -> list[str]:
    return [
        python,
        "-m",
        "fcso.cli",
        "design",
        str(source / "examples" / "parts" / "stanford_bunny_closed.ply"),
        "--scale-to",
        "65",
        "--config",
        str(source / "examples" / "paper.toml"),
        "--out",
        str(out),
        "--quiet",
    ]


def one_part_command(python: str, part: Path, config: Path, out: Path) -> list[str]:
    """The default ``fcso design`` of one part in its two most probable poses (``[poses] select = [0, 1]``)."""
    return [python, "-m", "fcso.cli", "design", str(part), "--config", str(config), "--out", str(out), "--quiet"]


def timed_commands(commands: list[tuple[list[str], Path]], runs: int) -> list[list[float]]:
    """Seconds of each ``(command, cwd)`` over ``runs`` rounds, the commands taking turns within a round.

    Taking turns spreads the shared machine's slow spells over every command.
    """
    seconds: list[list[float]] = [[] for _ in commands]
    for _ in range(runs):
        for (command, cwd), timings in zip(commands, seconds):
            started = time.perf_counter()
            subprocess.run(command, cwd=cwd, check=True, capture_output=True)
            timings.append(time.perf_counter() - started)
    return seconds


def baseline_tree(commit: str, into: Path) -> Path:
    """The repository at ``commit`` (git archive) with its bytecode compiled, as ``make setup`` leaves this one."""
    archive = subprocess.run(["git", "archive", commit], cwd=REPO, check=True, capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    subprocess.run([sys.executable, "-m", "compileall", "-q", "fcso"], cwd=into, check=True, capture_output=True)
    return into


def sixteen_scenarios() -> tuple[list, fcso.DesignConfig]:
    parts = [
        p
        for name, units, scale in SIXTEEN_SCENARIO_PARTS
        for p in fcso.load_parts(DATA / name, units=units, scale_to_mm=scale)
    ]
    # the second and third most probable poses: every part is graspable in both
    return parts, fcso.DesignConfig().updated({"poses": {"count": 2, "select": [1, 2]}})


def _screen_chunk(context, choices):
    prepared, config = context
    return [screen_choice(prepared, c, config).quality for c in choices]


def screening_rate(prepared, config, count: int, seed: int = 0) -> float:
    """Screened candidates per second over every core, on random candidates."""
    rng = np.random.default_rng(seed)
    counts = [len(s.samples) for s in prepared.scenarios]
    choices = [tuple(int(rng.integers(c)) for c in counts) for _ in range(count)]
    jobs = resolve_jobs(config.search.jobs)
    chunks = [choices[i : i + 64] for i in range(0, len(choices), 64)]
    with WorkerPool((prepared, config), jobs) as pool:
        started = time.perf_counter()
        pool.map(_screen_chunk, chunks)
        return count / (time.perf_counter() - started)


def design_figures(parts, config, runs: int) -> tuple[list[float], fcso.DesignResult]:
    seconds, result = [], None
    for _ in range(runs):
        started = time.perf_counter()
        result = fcso.design(parts, config)
        seconds.append(time.perf_counter() - started)
    return seconds, result


def peak_memory_mb() -> float:
    """Peak resident memory of this process and of its largest finished worker, MB.

    The process's own peak is VmHWM, which exec resets (``ru_maxrss`` keeps
    the peak of the process that started it). Forked workers share the
    parent's pages until they write them, so the sum over-counts: it is an
    upper bound.
    """
    status = Path("/proc/self/status").read_text()
    own_kb = int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:")))
    children_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return (own_kb + children_kb) / 1024.0


def sixteen_scenario_memory_mb() -> float:
    """Peak memory of the 16-scenario design alone, in a fresh process (:func:`peak_memory_mb` there)."""
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_design", "--memory-child"],
        cwd=REPO,
        check=True,
        capture_output=True,
        text=True,
    )
    return float(done.stdout.split()[-1])


def summary(seconds: list[float]) -> str:
    return (
        f"median {statistics.median(seconds):.2f} s (min {min(seconds):.2f}, max {max(seconds):.2f}, "
        f"{len(seconds)} runs)"
    )


def one_part_figures(scratch: Path, old_tree: Path | None, baseline: str | None, runs: int) -> None:
    """Time the default design of one part in two poses (the holed, notched 30 mm cube), and on ``old_tree``'s code."""
    part = scratch / "notched_cube.stl"
    holed_notched_cube().export(part)
    config = scratch / "two_poses.toml"
    config.write_text("[poses]\nselect = [0, 1]\n")
    commands = [(one_part_command(sys.executable, part, config, scratch / "one-new"), REPO)]
    if old_tree is not None:
        commands.append((one_part_command(sys.executable, part, config, scratch / "one-old"), old_tree))
    new, *old = timed_commands(commands, runs)
    print(f"one part, two poses, default fcso design command (holed notched cube): {summary(new)}")
    if old:
        print(
            f"  same command on {baseline}, in turns with it: {summary(old[0])}; ratio new/old "
            f"{statistics.median(new) / statistics.median(old[0]):.2f}x  (target <= 2x)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--baseline", metavar="COMMIT", help="also time the paper command on this commit's code")
    parser.add_argument("--skip-budget", action="store_true", help="skip the 10x-budget run of the 16-scenario case")
    parser.add_argument("--paper-only", action="store_true", help="time the paper command only")
    parser.add_argument(
        "--one-part-only",
        action="store_true",
        help="time the one-part, two-pose default command only (with --baseline)",
    )
    parser.add_argument("--memory-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child:
        fcso.design(*sixteen_scenarios())
        print(f"{peak_memory_mb():.1f}")
        return

    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        old_tree = baseline_tree(args.baseline, scratch / "old") if args.baseline else None
        if not args.paper_only:
            one_part_figures(scratch, old_tree, args.baseline, args.runs)
        if args.one_part_only:
            return
        commands = [(paper_command(sys.executable, REPO, scratch / "new"), REPO)]
        if old_tree is not None:
            commands.append((paper_command(sys.executable, old_tree, scratch / "old-out"), old_tree))
        new, *old = timed_commands(commands, args.runs)
        print(f"paper experiment, whole fcso design command: {summary(new)}")
        if old:
            # issue 21: the paper command "stays within 3 s" of its time before the capture measure came
            print(
                f"  same command on {args.baseline}, in turns with it: {summary(old[0])}; new - old "
                f"{statistics.median(new) - statistics.median(old[0]):+.2f} s (target <= +3 s)"
            )
    if args.paper_only:
        return

    parts, config = (
        [fcso.load_part(PARTS / "stanford_bunny_closed.ply", scale_to_mm=65.0)],
        fcso.load_config(REPO / "examples" / "paper.toml"),
    )
    prepared = prepare(parts, config)
    counts = [len(s.samples) for s in prepared.scenarios]
    everything = list(itertools.product(*(range(c) for c in counts)))
    rates = [screening_rate(prepared, config, 4 * len(everything), seed) for seed in range(args.runs)]
    print(
        f"screening, 2 scenarios: median {statistics.median(rates):.0f} candidates/s over {resolve_jobs(0)} cores  "
        f"(target >= 1000)"
    )

    parts, config = sixteen_scenarios()
    seconds, result = design_figures(parts, config, args.runs)
    report = result.report
    q = next(c.quality for c in report.candidates if c.index == report.best)
    print(
        f"8 parts x 2 poses: {len(report.scenarios)} scenarios, samples {[s.valid_samples for s in report.scenarios]}, "
        f"whole design {summary(seconds)}  (target <= 60 s)"
    )
    print(
        f"  Q = {q:.2f} mm², upper bound {report.search.quality_upper_bound:.2f} (gap {report.search.gap:.0%}), "
        f"screened {report.search.screened}, exact {report.search.exact}, {report.search.kind}; stages "
        f"{report.timings_s}"
    )
    prepared = prepare(parts, config)
    rates = [screening_rate(prepared, config, 2000, seed) for seed in range(args.runs)]
    print(
        f"screening, {len(prepared.scenarios)} scenarios: median {statistics.median(rates):.0f} candidates/s  (target "
        f">= 200)"
    )
    print(
        f"  peak memory of the 16-scenario design in a fresh process (process + largest worker): "
        f"{sixteen_scenario_memory_mb():.0f} MB  (target <= 2048)"
    )
    if not args.skip_budget:
        budget = config.search.max_evaluations * 10
        started = time.perf_counter()
        wide = fcso.design(parts, config.updated({"search": {"max_evaluations": budget}})).report
        wide_q = next(c.quality for c in wide.candidates if c.index == wide.best)
        print(
            f"  10x budget ({budget} screened): Q = {wide_q:.2f} mm², {(wide_q / q - 1) if q else 0:+.2%} "
            f"in {time.perf_counter() - started:.1f} s  (target < +2 %)"
        )

    job = [p for name in FOUR_PART_JOB for p in fcso.load_parts(DATA / name)]
    seconds, result = design_figures(job, fcso.DesignConfig().updated({"poses": {"count": 1}}), args.runs)
    report = result.report
    q = next(c.quality for c in report.candidates if c.index == report.best)
    print(
        f"four-part job (--poses 1): {len(report.scenarios)} scenarios, whole design {summary(seconds)}, Q = {q:.2f} "
        f"mm², "
        f"gap {report.search.gap:.0%}, ungraspable {[u.part for u in report.ungraspable]}  (target <= 20 s)"
    )


if __name__ == "__main__":
    main()
