"""Do designed fingers beat flat ones on parts nobody tuned for? The product's defaults, judged by simulation.

METHOD §7b, §7c and §12. Run from the repository root::

    python -m benchmarks.bench_truth [--splits development,test,suite] [--seeds N] [--trials N] [--top-k K]
                                     [--families NAME,...] [--shared-only | --single-only] [--candidates K]
                                     [--bunny] [--as-shipped]

Three sets of parts, every one designed with ``fcso.DesignConfig()`` as it
ships: no part gets settings of its own, no pose or yaw is chosen for it.

- ``development``: parts drawn from the families the method may be tuned on
  (:mod:`examples.part_families`), with the development seeds, and jobs of
  2-4 of those parts sharing one finger (METHOD §11's N = 1 of many);
- ``test``: the same families with other seeds, the families held out of
  development (about a third), and jobs of 2-4 parts sharing one finger,
  held-out families among them. Reported, never tuned on;
- ``suite``: the hand-made parts of :mod:`examples.sim_parts`.

``--shared-only`` runs only the shared-finger jobs of the development and test
splits (:data:`SHARED_JOBS`; the suite has none), ``--single-only`` only the
one-part jobs. ``--as-shipped`` designs those jobs as the daemon does
(``deploy/fcsod.toml``'s ``[design]``: up to 4 finger sets, judged by truth)
instead of one finger for all; a part the job names ``not_served`` counts
its flat control's trials.

The delivered candidate is chosen as the daemon chooses it (``--top-k``
candidates verified in the measure's order, each stopped at its first failed
trial); then the delivered finger and its flat control run every trial and
the holding test (METHOD §12b). Per scenario it prints the capture measure,
designed against flat (success, median error, weakest hold) and why a miss
missed (dropped, off-centre, turned). Per split: caging scenarios where flat
is at most 3/10 and the design reaches 9/10, scenarios below flat, weaker
holding, the featureless controls, and the Spearman correlation of the
measure and of the paper's Q with simulated success over the verified
candidates. The machine is shared: this benchmark measures outcomes, not time.
"""

from __future__ import annotations

import argparse
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh
from scipy.stats import spearmanr

import fcso
from examples import part_families, sim_parts
from fcso.parts import Part
from fcso.sets import design_sets
from fcso.sim.choose import candidate_designs, verify_top
from fcso.sim.config import VerifyConfig
from fcso.sim.seats import nominal_miss
from fcso.sim.verify import verify, weaker_than_flat

#: Jobs of several parts sharing one finger, per split: family names (each split's first seed). The test split's
#: mix held-out and development families; the development split's, drawn from its own families, keep the two
#: splits alike (one single-part job per part and three shared-finger jobs of 2, 3 and 4 parts each).
SHARED_JOBS = {
    "development": (
        ("notched-bar", "polygon-prism"),
        ("spur-gear", "boss-block", "stepped-block"),
        ("knurled-knob", "dovetail-block", "holed-block", "slotted-block"),
    ),
    "test": (
        ("slotted-block", "dovetail-block"),
        ("tslot-nut", "d-shaft", "cam"),
        ("knurled-knob", "gusset-bracket", "polygon-prism", "holed-block"),
    ),
}


@dataclass
class Job:
    """Parts designed together (one finger), with their split and whether each can be caged."""

    name: str
    split: str
    parts: list[tuple[str, trimesh.Trimesh, bool]]


@dataclass
class Row:
    job: Job
    part: str
    caging: bool
    pose: int
    capture: float
    flat_capture: float
    beats_flat: bool
    designed: object
    flat: object
    weaker: bool


@dataclass
class SplitFigures:
    rows: list[Row] = field(default_factory=list)
    correlation: list[tuple[float, float, float]] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)


def suite_jobs() -> list[Job]:
    """The hand-made parts of :mod:`examples.sim_parts`, as they are (no settings of their own)."""
    made = [
        ("paper-cube", sim_parts.featured_cube(notch_mm=8.0), True),
        ("holed-notched-cube", sim_parts.holed_notched_cube(), True),
        ("ribbed-block", sim_parts.ribbed_block(), True),
        ("two-ridge-block", sim_parts.two_ridge_block(), True),
        ("zigzag-l-part", sim_parts.zigzag_l_part(), True),
        ("knurled-knob", sim_parts.knurled_knob(), True),
        ("spur-gear", sim_parts.spur_gear(), True),
        ("hex-prism", sim_parts.hex_prism(), True),
        ("plain-cube", sim_parts.plain_box(), False),
        ("plain-cylinder", sim_parts.plain_cylinder(), False),
    ]
    return [Job(name, "suite", [(name, mesh, caging)]) for name, mesh, caging in made]


def drawn_jobs(
    split: str, seeds: int, families: set[str] | None, shared_only: bool = False, single_only: bool = False
) -> list[Job]:
    """One job per drawn part of ``split`` (none with ``shared_only``), and the split's shared-finger jobs of
    :data:`SHARED_JOBS` (none with ``single_only``)."""
    drawn = [p for p in part_families.split(split, seeds) if not families or p.family in families]
    jobs = [] if shared_only else [Job(p.name, split, [(p.name, p.mesh, p.caging)]) for p in drawn]
    first = {p.family: p for p in part_families.split(split, 1)}
    for group in [] if single_only else SHARED_JOBS[split]:
        if families and not families & set(group):
            continue
        members = [first[f] for f in group]
        jobs.append(Job("+".join(p.name for p in members), split, [(p.name, p.mesh, p.caging) for p in members]))
    return jobs


def _weakest(holding: dict) -> float:
    """The weakest holding force of a finger (``held`` counts as the test's force; an empty dict: not tested)."""
    return min((30.0 if v is None else v for v in holding.values()), default=float("nan"))


def miss_reason(outcome, config: VerifyConfig) -> str:
    """Why the trials that failed failed: dropped, off-centre or turned (counts)."""
    failed = [t for t in outcome.trials if not t.success]
    if not failed:
        return ""
    dropped = sum(1 for t in failed if not t.held)
    turned = sum(1 for t in failed if t.held and t.error_deg > config.success_deg and t.error_mm <= config.success_mm)
    off = len(failed) - dropped - turned
    parts = [f"{n} {what}" for n, what in ((dropped, "dropped"), (off, "off-centre"), (turned, "turned")) if n]
    return ", ".join(parts)


def shipped_design_config() -> fcso.DesignConfig:
    """``deploy/fcsod.toml``'s ``[design]`` over fcso's defaults: the daemon's design as shipped (its finger sets
    judged by truth)."""
    with open(Path(__file__).resolve().parents[1] / "deploy" / "fcsod.toml", "rb") as shipped:
        return fcso.DesignConfig().updated(tomllib.load(shipped).get("design", {}))


def run_job(job: Job, args, choose: VerifyConfig, every: VerifyConfig, figures: SplitFigures) -> None:
    """Design ``job`` with the defaults (one finger; with ``args.as_shipped`` a job of several parts as the daemon
    ships, in finger sets judged by truth), choose by truth, verify each delivered finger fully; print its rows."""
    started = time.perf_counter()
    parts = [Part(name=name, path=name, mesh=mesh) for name, mesh, _ in job.parts]
    try:
        if args.as_shipped and len(parts) > 1:
            sets = design_sets(parts, shipped_design_config())
            results = sets.designs
            not_served = {entry.part: entry.fallback for entry in (sets.report.not_served if sets.report else [])}
        else:
            results, not_served = [fcso.design(parts, fcso.DesignConfig())], {}
    except fcso.NoGraspError as error:
        print(f"{job.name:<34} no grasp: {error}", flush=True)
        return
    except fcso.GeometryError as error:
        # a design that delivers no finger is an outcome of the method on this part, counted as such
        print(f"{job.name:<34} design failed: {error}", flush=True)
        figures.failed.append(job.name)
        return
    for number, result in enumerate(results, start=1):
        label = f"set {number}: " if len(results) > 1 else ""
        _delivered_rows(job, label, result, not_served, args, choose, every, figures)
    print(f"  ({time.perf_counter() - started:.0f} s)", flush=True)


def _delivered_rows(
    job: Job,
    label: str,
    result: fcso.DesignResult,
    not_served: dict[str, str],
    args,
    choose: VerifyConfig,
    every: VerifyConfig,
    figures: SplitFigures,
) -> None:
    """Choose ``result``'s finger by truth, verify it fully and print and keep a row per scenario. A part the job
    does not serve (``not_served``: part -> fallback) is picked without a finger of its own: its row counts the flat
    control's trials."""
    caging = {name: flag for name, _, flag in job.parts}
    # the delivered finger's verification is complete (METHOD §12b): every trial and the holding test
    delivered, verification, _, ranking = verify_top(result, args.top_k, choose)
    report = delivered.report
    best = next(c for c in report.candidates if c.index == report.best)
    pad = "flat" if report.finger.flat_pads else best.pad_case
    for scenario, outcome in zip(report.scenarios, verification.scenarios):
        designed, flat = outcome.fcso, outcome.flat
        if scenario.part in not_served:
            designed = flat
        row = Row(
            job,
            scenario.part,
            caging[scenario.part],
            scenario.pose_index,
            scenario.capture,
            scenario.flat_capture,
            scenario.beats_flat,
            designed,
            flat,
            weaker_than_flat(designed.holding_n, flat.holding_n, every),
        )
        figures.rows.append(row)
        notes = [] if scenario.beats_flat else ["design: flat is as good"]
        if nominal_miss(designed, every) is not None:
            notes.append(
                f"nominal grasp {designed.nominal_offset_mm:.1f} mm {designed.nominal_offset_deg:.1f} deg off"
                if designed.nominal_held
                else "nominal grasp dropped it"
            )
        if designed.success_rate < 0.9:
            notes.append(miss_reason(designed, every))
        if row.weaker:
            notes.append("holds less than flat")
        if scenario.part in not_served:
            notes.append(f"not served: {not_served[scenario.part]} (flat control's trials)")
        name = scenario.part if len(job.parts) == 1 else f"{label}{job.name[:16]}..{scenario.part}"
        print(
            f"{name:<34} {scenario.pose_index:>4} {pad:>6} {scenario.capture:>7.2f} {scenario.flat_capture:>5.2f} | "
            f"{designed.success_rate * 10:>4.0f}/10 {designed.median_error_mm:>6.3f}mm "
            f"{_weakest(designed.holding_n):>6.1f}"
            f" | {flat.success_rate * 10:>4.0f}/10 {flat.median_error_mm:>6.3f}mm {_weakest(flat.holding_n):>6.1f} | "
            + "; ".join(n for n in notes if n),
            flush=True,
        )
    for verified in ranking:
        candidate = next(c for c in report.candidates if c.index == verified.index)
        # a candidate rejected before its trials (METHOD §5b) ran none
        if verified.trials_run and all(n == every.trials for n in verified.trials_run):
            q = min(s.effective_area for s in candidate.per_scenario)
            figures.correlation.append((candidate.quality, q, float(np.mean(verified.success_rates))))
    if args.candidates:
        others = sorted(
            (c for c in report.candidates if c.index not in {r.index for r in ranking}), key=lambda c: c.quality
        )
        picks = (
            {
                others[int(k * (len(others) - 1) / max(args.candidates - 1, 1))].index: None
                for k in range(args.candidates)
            }
            if others
            else {}
        )
        chosen = [c for c in others if c.index in picks]
        for candidate_design, evaluation, *_ in candidate_designs(delivered, chosen):
            checked = verify(candidate_design, every)
            success = float(np.mean([s.fcso.success_rate for s in checked.scenarios]))
            q = min(s.effective_area for s in evaluation.scenarios)
            figures.correlation.append((evaluation.quality, q, success))


def summary(split: str, figures: SplitFigures, config: VerifyConfig) -> None:
    """Print a split's figures against the targets of the issue "Precise on parts nobody tuned for"."""
    rows = figures.rows
    caging = [r for r in rows if r.caging and r.flat.success_rate <= 0.3]
    good = [r for r in caging if r.designed.success_rate >= 0.9]
    several = [r for r in caging if len(r.job.parts) > 1]
    print(f"\n== {split}: {len(rows)} scenarios of {len({r.job.name for r in rows})} jobs")
    if figures.failed:
        print(f"designs that delivered no finger: {len(figures.failed)}: " + ", ".join(figures.failed))
    print(
        f"caging scenarios (a caging part, flat <= 3/10): designed >= 9/10 in {len(good)} of {len(caging)} "
        f"({len(good) / max(len(caging), 1):.0%}; target 80 %); of them in shared-finger jobs "
        f"{sum(1 for r in several if r.designed.success_rate >= 0.9)} of {len(several)}"
    )
    if caging:
        designed = np.mean([r.designed.success_rate for r in caging]) * 10
        flat = np.mean([r.flat.success_rate for r in caging]) * 10
        print(f"mean designed {designed:.1f}/10 against flat {flat:.1f}/10 (caging scenarios)")
    below = [r for r in rows if r.designed.success_rate < r.flat.success_rate]
    print(f"designed below flat: {len(below)} " + ", ".join(f"{r.part} pose {r.pose}" for r in below))
    weaker = [r for r in rows if r.weaker]
    print(
        f"designed holds less than flat (beyond {config.hold_tolerance_n:g} N, some direction): {len(weaker)} "
        + ", ".join(f"{r.part} pose {r.pose}" for r in weaker)
    )
    plain = [r for r in rows if not r.caging]
    print(
        f"featureless controls where the design says flat is as good: {sum(1 for r in plain if not r.beats_flat)} "
        f"of {len(plain)}"
    )
    misses = [r for r in caging if r.designed.success_rate < 0.9]
    for r in misses:
        print(
            f"  below 9/10: {r.part} pose {r.pose}: {r.designed.success_rate * 10:.0f}/10 "
            f"({miss_reason(r.designed, config)})"
        )
    if len(figures.correlation) >= 3:
        measures, qs, successes = (np.array([c[k] for c in figures.correlation]) for k in range(3))
        print(
            f"Spearman over {len(figures.correlation)} fully verified candidates: measure "
            f"{spearmanr(measures, successes).statistic:.2f}, paper Q {spearmanr(qs, successes).statistic:.2f} "
            "(target >= 0.6 and above Q's)"
        )


def passing_shares(figures: SplitFigures) -> tuple[float, float]:
    """The share of caging scenarios (flat <= 3/10) the design seats >= 9/10: over all jobs, and over single-part
    jobs only (0..1; 0 without such scenarios)."""
    caging = [r for r in figures.rows if r.caging and r.flat.success_rate <= 0.3]
    single = [r for r in caging if len(r.job.parts) == 1]
    return tuple(sum(r.designed.success_rate >= 0.9 for r in rows) / max(len(rows), 1) for rows in (caging, single))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--splits", default="development,test,suite", help="comma-separated: development, test, suite")
    parser.add_argument("--seeds", type=int, default=1, help="parts drawn per family and split (1 or 2)")
    parser.add_argument("--families", help="comma-separated family names to run (default: all)")
    only = parser.add_mutually_exclusive_group()
    only.add_argument(
        "--shared-only", action="store_true", help="only the shared-finger jobs (SHARED_JOBS; no suite parts)"
    )
    only.add_argument("--single-only", action="store_true", help="only the one-part jobs")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--top-k", type=int, default=3, help="candidates verified by the choice ([verify] top_k)")
    parser.add_argument(
        "--candidates", type=int, default=0, help="more candidates per job verified fully for the correlation"
    )
    parser.add_argument("--bunny", action="store_true", help="add the paper's bunny to the suite")
    parser.add_argument(
        "--as-shipped",
        action="store_true",
        help="jobs of several parts as the daemon designs them (deploy/fcsod.toml's [design]: finger sets judged by "
        "truth), not one finger",
    )
    args = parser.parse_args()
    families = set(args.families.split(",")) if args.families else None
    choose = VerifyConfig(trials=args.trials)
    every = VerifyConfig(trials=args.trials, stop_early=False)
    print(
        f"product defaults (fcso.DesignConfig()); simulation: {args.trials} trials, +-2 mm +-3 deg, friction 0.4, "
        "60 N; success within 0.3 mm and 1 deg; choice by truth over "
        f"{args.top_k} candidates, the delivered finger verified with every trial"
        + ("; jobs of several parts as shipped (deploy/fcsod.toml [design], finger sets)" if args.as_shipped else "")
    )
    shares: dict[str, tuple[float, float]] = {}
    for split in args.splits.split(","):
        if split == "suite":
            jobs = suite_jobs()
            if args.bunny:
                bunny = fcso.load_part("examples/parts/stanford_bunny_closed.ply", scale_to_mm=65.0).mesh
                jobs.append(Job("stanford-bunny", "suite", [("stanford-bunny", bunny, True)]))
            if families:
                jobs = [j for j in jobs if j.name in families]
            if args.shared_only:
                jobs = []
        else:
            jobs = drawn_jobs(split, args.seeds, families, args.shared_only, args.single_only)
        print(f"\n== {split}")
        print(
            f"{'part':<34} {'pose':>4} {'pad':>6} {'capture':>7} {'flat':>5} | {'designed':>7} {'median':>8} "
            f"{'hold N':>6} | {'flat':>7} {'median':>8} {'hold N':>6} | note"
        )
        figures = SplitFigures()
        for job in jobs:
            run_job(job, args, choose, every, figures)
        summary(split, figures, every)
        shares[split] = passing_shares(figures)
    if {"development", "test"} <= shares.keys():
        (dev_all, dev_single), (test_all, test_single) = shares["development"], shares["test"]
        print(
            f"\ndevelopment - test, caging scenarios at >= 9/10: all {dev_all - test_all:+.0%} "
            f"({dev_all:.0%} - {test_all:.0%}; target within 10 points); single-part jobs only "
            f"{dev_single - test_single:+.0%} ({dev_single:.0%} - {test_single:.0%})"
        )


if __name__ == "__main__":
    main()
