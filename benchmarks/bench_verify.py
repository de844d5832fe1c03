"""Grasp verification in simulation (METHOD §12): the paper's precision experiment in silico, the fixtures, and the
time.

Run from the repository root::

    python -m benchmarks.bench_verify [--trials N] [--runs N] [--quick] [--fixtures demo bunny] [--stop-early]
    python -m benchmarks.bench_verify --choice [--runs N]

``--quick``: the paper cube and the timing only; ``--fixtures``: which of
the fixture jobs to verify (default both); every trial of every scenario
runs (the success rates are the figures) unless ``--stop-early`` (the
product's default: a design's trials stop once it can no longer pass).
``--choice``: only the daemon's whole job for the demo batch against its
design alone, twice: in this process, the design, then the choice by truth
among ``top_k = 3`` candidates as the daemon makes it (cold cache of
collision pieces), wall and CPU seconds (this process and its workers)
and the choice's floor (its CPU over the available cores: no schedule of
the same work ends sooner) against the half of the design's time the
target leaves it;
then through a real ``fcsod``, the job with the product's ``[verify]``
against the same job with verification off, as the daemon times it
(:func:`daemon_job_against_design`); medians of ``--runs``.

Prints

- the paper's precision experiment: a 30 mm cube with a deep V-notch in
  two opposite faces and a through hole, designed upright and closed
  across its notches, ``--trials`` perturbed trials (+-2 mm, +-3 degrees)
  with the designed fingers and with flat ones: success rates, the sorted
  final errors, the holding forces; the same cube with a 7 mm notch, for
  which the method keeps the pad flat;
- every fixture part of the demo (the batch-demo job: xyz cube and solar
  tracker with one pair of fingers) and the paper's bunny experiment
  (poses 1 and 3): per scenario the collision geometry's fidelity (pieces
  of part and pad; the volume the part's pieces add outside it and the
  share of it under their shell; the pad's volume error; the seated
  overlap of part and pad pieces and of the two pads), the success
  rate, median error and holding forces, designed against flat, and the
  design's verification time with a cold cache, a warm cache of collision
  pieces (every grasp and push simulated again) and run again (the
  outcomes of the simulations reused, as a restarted or repeated job);
- the wall and CPU time of a one-part verification (the paper cube,
  ``--trials`` trials and the holding test) with the same three caches
  (medians of ``--runs``).

The machine is shared and noisy: compare medians, not single runs.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import fcso
from examples.batch_demo import batch_demo_part_files, batch_demo_settings
from examples.sim_parts import featured_cube, upright_grasp_settings
from fcso.parallel import resolve_jobs
from fcso.parts import Part
from fcso.sim.choose import verify_top
from fcso.sim.config import VerifyConfig
from fcso.sim.report import VerificationReport
from fcso.sim.verify import design_under_test, verify

REPO = Path(__file__).resolve().parent.parent
#: A warm run that simulates every grasp and push again (only the collision pieces come from the cache).
SIMULATED = {"reuse_simulations": False}
PARTS = REPO / "examples" / "parts"


def cube_design(notch_mm: float) -> fcso.DesignResult:
    """The paper cube designed upright, closing across its notches, default (paper) pad settings."""
    mesh = featured_cube(notch_mm=notch_mm)
    part = Part(name=f"cube30-notch{notch_mm:g}", path="featured_cube", mesh=mesh)
    return fcso.design([part], fcso.DesignConfig().updated(upright_grasp_settings(mesh)))


def demo_design() -> fcso.DesignResult:
    """The batch-demo job's design: its parts and its manifest's settings (one finger for both parts)."""
    return fcso.design(batch_demo_part_files(), batch_demo_settings())


def paper_design() -> fcso.DesignResult:
    return fcso.design(
        [fcso.load_part(PARTS / "stanford_bunny_closed.ply", scale_to_mm=65.0)],
        fcso.load_config(REPO / "examples" / "paper.toml"),
    )


def _holding(values: dict) -> str:
    return " ".join(f"{d}:{'held' if v is None else f'{v:.0f}'}" for d, v in values.items())


def _share(value: float | None, spec: str) -> str:
    """A volume share, "-" where a precision-only run did not measure it."""
    return "-" if value is None else f"{value:{spec}}"


def print_verification(name: str, verification: VerificationReport, errors: bool = False) -> None:
    print(f"\n{name}  ({verification.timings_s})")
    for s in verification.scenarios:
        f = s.fidelity
        print(
            f"  {s.part} pose {s.pose_index}: pieces part {f.part_pieces} pad {f.pad_pieces}, volume error part "
            f"{_share(f.part_volume_error, '+.2%')} (under the shell {_share(f.part_missing_fraction, '.1%')}) "
            f"pad {_share(f.pad_volume_error, '+.2%')}, seated overlap part/pad {f.seated_penetration_mm:.3f} mm "
            f"pad/pad {f.seated_pads_overlap_mm:.3f} mm"
        )
        for label, r in (("designed", s.fcso), ("flat", s.flat)):
            print(
                f"    {label:<8} success {r.success_rate:4.0%}  median {r.median_error_mm:.3f} mm "
                f"{r.median_error_deg:.2f} deg  "
                f"worst {r.worst_error_mm:.3f} mm {r.worst_error_deg:.2f} deg  held after lift "
                f"{sum(t.held for t in r.trials)}/{len(r.trials)}  "
                f"holding N {_holding(r.holding_n)}"
            )
            if errors:
                print(f"             errors mm  {np.round(sorted(t.error_mm for t in r.trials), 3).tolist()}")
                print(f"             errors deg {np.round(sorted(t.error_deg for t in r.trials), 2).tolist()}")
    for warning in verification.warnings:
        print(f"  warning: {warning}")


def cpu_s() -> float:
    """CPU seconds of this process and its finished workers."""
    own, workers = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + workers.ru_utime + workers.ru_stime


def timed(function, *args):
    """``function(*args)``, its wall seconds and its CPU seconds (this process and its workers)."""
    wall, cpu = time.perf_counter(), cpu_s()
    result = function(*args)
    return result, time.perf_counter() - wall, cpu_s() - cpu


def _spread(times: list[tuple[float, float]]) -> str:
    """Median, least and most of (wall s, CPU s) pairs."""
    walls, cpus = [t[0] for t in times], [t[1] for t in times]
    return (
        f"median {statistics.median(walls):.1f} s wall (min {min(walls):.1f}, max {max(walls):.1f}), "
        f"{statistics.median(cpus):.1f} s CPU"
    )


def choice_against_design(runs: int, scratch: Path) -> None:
    """The demo batch: design alone, then the choice by truth among 3 candidates with the product's settings."""
    design_s, choice_s = [], []
    for run in range(runs):
        result, *design_times = timed(demo_design)
        design_s.append(design_times)
        (_, verification, _, ranking), *choice_times = timed(
            verify_top, result, 3, VerifyConfig(cache_dir=scratch / f"choice{run}")
        )
        choice_s.append(choice_times)
        print(
            f"run {run + 1}: design {design_s[-1][0]:.1f} s, choice {choice_s[-1][0]:.1f} s wall; {verification.choice}"
        )
        for r in ranking:
            print(
                f"  rank {r.rank_by_quality} candidate {r.index}: designed {r.success_rates}, flat "
                f"{r.flat_success_rates}, trials run {r.trials_run}, passed {r.passed}"
            )
    design_wall, design_cpu = (statistics.median(t[k] for t in design_s) for k in (0, 1))
    choice_wall, choice_cpu = (statistics.median(t[k] for t in choice_s) for k in (0, 1))
    cores = resolve_jobs(0)
    print(
        f"\ndemo batch, median of {runs}: design alone {design_wall:.1f} s wall ({design_cpu:.1f} s CPU); choice by "
        f"truth {choice_wall:.1f} s wall ({choice_cpu:.1f} s CPU); whole job / design "
        f"{(design_wall + choice_wall) / design_wall:.2f}x wall, {(design_cpu + choice_cpu) / design_cpu:.2f}x CPU "
        "(target <= 1.5x)"
    )
    # however well its work were spread, the choice cannot end sooner than its CPU time over the cores
    print(
        f"the choice's floor on {cores} cores: {choice_cpu / cores:.1f} s wall (its CPU over the cores); the target "
        f"leaves it {0.5 * design_wall:.1f} s (half the design alone)"
    )


#: The daemon's ``[verify]`` as ``deploy/fcsod.toml`` ships it, and verification off.
DAEMON_VERIFY = {"verified": "enabled = true\ntrials = 10\ntop_k = 3", "design alone": "enabled = false\ntop_k = 0"}


def daemon_job_against_design(runs: int, scratch: Path) -> None:
    """The demo batch through a real ``fcsod``: its whole job with the product's ``[verify]`` against verification off.

    Each run starts a daemon on a fresh watch and state folder (so the
    verification's caches are cold and no finger is reused), drops the
    batch and takes the job's time from its start to ``done`` as the daemon
    logs it (``job done``'s seconds; the demo's one finger is verified
    before ``done``); the two settings alternate, median of ``runs`` each.
    """
    from tests.fcsod_helpers import copy_tree, free_port, start_daemon, write_config

    seconds: dict[str, list[float]] = {name: [] for name in DAEMON_VERIFY}
    for run in range(runs):
        for name, verify_body in DAEMON_VERIFY.items():
            base = scratch / f"daemon-{run}-{name.replace(' ', '-')}"
            config = write_config(base, free_port(), settle_seconds=0.5, design="", verify=verify_body)
            daemon = start_daemon(config)
            try:
                copy_tree(REPO / "examples" / "jobs" / "batch-demo", base / "watch" / "batch-demo")
                done = daemon.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "job done", 600)
            finally:
                daemon.stop()
            seconds[name].append(done["seconds"])
            print(f"daemon run {run + 1}, {name}: job {done['seconds']:.1f} s", flush=True)
    verified, alone = (statistics.median(seconds[name]) for name in DAEMON_VERIFY)
    print(
        f"\ndemo batch in fcsod, median of {runs}: job with verification (top_k 3) {verified:.1f} s, without "
        f"{alone:.1f} s: whole job / design alone {verified / alone:.2f}x (target <= 1.5x)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--runs", type=int, default=3, help="timing runs per cache state")
    parser.add_argument("--quick", action="store_true", help="the paper cube and the timing only")
    parser.add_argument(
        "--fixtures", nargs="+", choices=["demo", "bunny"], default=["demo", "bunny"], help="fixture jobs to verify"
    )
    parser.add_argument("--stop-early", action="store_true", help="stop a design's trials once it cannot pass")
    parser.add_argument("--choice", action="store_true", help="only the demo job's choice by truth against its design")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        if args.choice:
            choice_against_design(args.runs, Path(scratch))
            daemon_job_against_design(args.runs, Path(scratch))
            return
        cache = Path(scratch) / "warm"
        config = VerifyConfig(trials=args.trials, cache_dir=cache, stop_early=args.stop_early)
        print(
            f"MuJoCo verification, {args.trials} trials per scenario, +-2 mm +-3 deg, 60 N, friction 0.4, lift 100 mm"
        )

        cube = design_under_test(cube_design(8.0))
        print_verification(
            "paper precision experiment in silico: 30 mm cube, 8 mm V-notches, 8 mm hole",
            verify(cube, config),
            errors=True,
        )
        shallow = cube_design(7.0)
        case = next(c for c in shallow.report.candidates if c.index == shallow.report.best).pad_case
        print_verification(
            f"the same cube with 7 mm notches (pad case {case!r})",
            verify(design_under_test(shallow), config),
            errors=True,
        )

        if not args.quick:
            fixtures = {
                "demo": ("batch-demo job: xyz cube + solar tracker", demo_design),
                "bunny": ("paper experiment: bunny 65 mm, poses 1 and 3", paper_design),
            }
            for name, make in (fixtures[f] for f in args.fixtures):
                design = design_under_test(make())
                fixture_cache = config.model_copy(update={"cache_dir": Path(scratch) / name})
                verification, cold_s, cold_cpu = timed(verify, design, fixture_cache)
                _, warm_s, warm_cpu = timed(verify, design, fixture_cache.model_copy(update=SIMULATED))
                again = timed(verify, design, fixture_cache)
                print_verification(
                    f"{name}: verification cold cache {cold_s:.1f} s wall ({cold_cpu:.1f} s CPU), warm cache of "
                    f"pieces {warm_s:.1f} s wall ({warm_cpu:.1f} s CPU), again (outcomes reused, "
                    f"{sum(s.reused_simulations for s in again[0].scenarios)} simulations) {again[1]:.1f} s wall "
                    f"({again[2]:.1f} s CPU)",
                    verification,
                )

        cold = [
            timed(verify, cube, config.model_copy(update={"cache_dir": Path(scratch) / f"cold{run}"}))[1:]
            for run in range(args.runs)
        ]
        warm = [timed(verify, cube, config.model_copy(update=SIMULATED))[1:] for _ in range(args.runs)]
        again = [timed(verify, cube, config)[1:] for _ in range(args.runs)]
        print(
            f"\none-part verification (paper cube, {args.trials} trials x 2 fingers + holding): "
            f"cold cache {_spread(cold)}, warm cache of pieces {_spread(warm)}, again (outcomes reused) "
            f"{_spread(again)}; target cold <= 10 s"
        )


if __name__ == "__main__":
    main()
