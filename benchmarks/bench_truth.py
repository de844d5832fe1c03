"""Do designed fingers beat flat ones? The product's defaults on a suite of parts, judged by simulation.

METHOD §7b and §12.

Run from the repository root::

    python -m benchmarks.bench_truth [--trials N] [--candidates K] [--parts NAME,...] [--bunny]

For every part of the suite (parts with caging features: V-notches, holes,
a rib, ridges, teeth, knurls, a zig-zag edge; and parts without: a cube, a
cylinder, a plate), designed with the product's defaults in its most
probable pose, it prints per scenario the chosen pad's capture and the flat
pads' (METHOD §7b), and the simulated precision test (``--trials`` trials,
+-2 mm, +-3 degrees) and holding test, designed against flat: success
rate, median error, the weakest holding force. Then ``--candidates`` more
candidates of each part are built as printed and verified too, and the
Spearman rank correlation of the capture measure and of the paper's Q with
the simulated success is printed over all verified candidates.

``--bunny`` adds the paper's bunny (two poses; its cold verification takes
minutes). The machine is shared and noisy: this benchmark measures outcomes,
not time.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
from scipy.stats import spearmanr

import fcso
from examples.sim_parts import (
    featured_cube,
    hex_prism,
    holed_notched_cube,
    knurled_knob,
    plain_box,
    plain_cylinder,
    ribbed_block,
    spur_gear,
    two_ridge_block,
    upright_grasp_settings,
    zigzag_l_part,
)
from fcso.parts import Part
from fcso.sim.choose import candidate_designs, verify_top
from fcso.sim.config import VerifyConfig
from fcso.sim.verify import verify, weaker_than_flat

SMALL_PADS = {"sampler": {"length_mm": 10.0, "width_mm": 10.0, "thickness_mm": 5.0, "penetration_mm": 4.0}}
#: A cell with 10 mm wide pads that may be 10 or 20 mm long (METHOD §3b's short list): the design picks the length.
SMALL_PADS_TWO_LENGTHS = {"sampler": {**SMALL_PADS["sampler"], "length_mm": [10.0, 20.0]}}


@dataclass
class SuitePart:
    name: str
    make: object
    caging: bool
    settings: dict


def suite(bunny: bool) -> list[SuitePart]:
    """The parts: those with caging features first, then the featureless ones."""
    cube = featured_cube(notch_mm=8.0)
    ribbed = ribbed_block()
    ridges = two_ridge_block()
    parts = [
        SuitePart("paper cube (V-notches, hole)", lambda: cube, True, upright_grasp_settings(cube)),
        SuitePart("cube, holes and corner notches", holed_notched_cube, True, {"poses": {"count": 1}}),
        SuitePart("ribbed block", lambda: ribbed, True, upright_grasp_settings(ribbed)),
        SuitePart(
            "two-ridge block (10 mm pads)", lambda: ridges, True, {**upright_grasp_settings(ridges), **SMALL_PADS}
        ),
        SuitePart(
            "L-part, zig-zag (10|20 x 10 mm pads)",
            zigzag_l_part,
            True,
            {"poses": {"count": 1}, **SMALL_PADS_TWO_LENGTHS},
        ),
        SuitePart("knurled knob", knurled_knob, True, {"poses": {"count": 1}}),
        SuitePart("spur gear, lying flat", spur_gear, True, {"poses": {"count": 1}}),
        SuitePart("hex prism", hex_prism, True, {"poses": {"count": 1}}),
        SuitePart("plain cube", plain_box, False, {"poses": {"count": 1}}),
        SuitePart("plain cylinder", plain_cylinder, False, {"poses": {"count": 1}}),
        SuitePart("plain plate", lambda: plain_box(40.0, 30.0, 6.0), False, {"poses": {"count": 1}, **SMALL_PADS}),
    ]
    if bunny:
        bunny_mesh = fcso.load_part("examples/parts/stanford_bunny_closed.ply", scale_to_mm=65.0).mesh
        parts.append(SuitePart("Stanford bunny (paper poses)", lambda: bunny_mesh, True, {"poses": {"select": [1, 3]}}))
    return parts


def _merge(base: dict, extra: dict) -> dict:
    merged = {k: dict(v) for k, v in base.items()}
    for section, values in extra.items():
        merged.setdefault(section, {}).update(values)
    return merged


def _weakest(holding: dict) -> float:
    """The weakest holding force of a finger (``held`` counts as the test's force)."""
    return min(30.0 if v is None else v for v in holding.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument(
        "--candidates", type=int, default=2, help="more candidates per part verified for the correlation"
    )
    parser.add_argument("--parts", help="comma-separated name prefixes to run")
    parser.add_argument("--bunny", action="store_true", help="add the paper's bunny")
    parser.add_argument(
        "--top-k", type=int, default=3, help="candidates verified before delivery ([verify] top_k; 1: the measure's)"
    )
    args = parser.parse_args()
    # every trial of every candidate: the success rates are the figures (the product's stop_early gives the same
    # verdicts; when no candidate passes it may deliver another of the failing ones)
    config = VerifyConfig(trials=args.trials, stop_early=False)
    chosen_parts = [
        p for p in suite(args.bunny) if not args.parts or any(p.name.startswith(x) for x in args.parts.split(","))
    ]
    print(
        f"product defaults; simulation: {args.trials} trials, +-2 mm +-3 deg, friction 0.4, 60 N; "
        "success within 0.3 mm and 1 deg"
    )
    header = (
        f"{'part':<36} {'pose':>4} {'pad':>6} {'capture':>7} {'flat':>5} | "
        f"{'designed':>8} {'median':>8} {'hold N':>6} | {'flat':>5} {'median':>8} {'hold N':>6} | note"
    )
    print(header)
    rows, correlation = [], []
    for entry in chosen_parts:
        started = time.perf_counter()
        mesh = entry.make()
        part = Part(name=entry.name.split(" (")[0].replace(" ", "-").replace(",", ""), path=entry.name, mesh=mesh)
        try:
            result = fcso.design([part], fcso.DesignConfig().updated(entry.settings))
        except fcso.NoGraspError as error:
            print(f"{entry.name:<36} no grasp: {error}", flush=True)
            continue
        # the daemon's default: verify in the measure's order, deliver the first that passes (top_k)
        delivered, verification, _, ranking = verify_top(result, args.top_k, config)
        report = delivered.report
        best = next(c for c in report.candidates if c.index == report.best)
        for number, (scenario, outcome) in enumerate(zip(report.scenarios, verification.scenarios)):
            designed, flat = outcome.fcso, outcome.flat
            notes = [] if scenario.beats_flat else ["design says: flat is as good"]
            if len(report.pad_sizes) > 1:
                sampler = report.settings.sampler
                notes.append(f"{sampler.length_mm:g} x {sampler.width_mm:g} mm pads chosen")
            if ranking[0].index != best.index:
                notes.append(
                    f"measure's first choice {ranking[0].success_rates[number]:.0%}, "
                    f"delivered rank {next(r.rank_by_quality for r in ranking if r.chosen)}"
                )
            note = "; ".join(notes)
            row = (entry, scenario, best, designed, flat)
            rows.append(row)
            print(
                f"{entry.name:<36} {scenario.pose_index:>4} {'flat' if report.finger.flat_pads else best.pad_case:>6} "
                f"{scenario.capture:>7.2f} {scenario.flat_capture:>5.2f} | "
                f"{designed.success_rate:>8.0%} {designed.median_error_mm:>6.3f}mm "
                f"{_weakest(designed.holding_n):>6.1f} | "
                f"{flat.success_rate:>5.0%} {flat.median_error_mm:>6.3f}mm {_weakest(flat.holding_n):>6.1f} | {note}",
                flush=True,
            )
        for verified in ranking:
            candidate = next(c for c in report.candidates if c.index == verified.index)
            q = min(s.effective_area for s in candidate.per_scenario)
            correlation.append(
                (entry.name, candidate.index, candidate.quality, q, float(np.mean(verified.success_rates)))
            )
        # more candidates: the best by the paper's Q and spread over the measure, built as printed
        others = [c for c in report.candidates if c.index not in {r.index for r in ranking}]
        by_q = max(others, key=lambda c: min(s.effective_area for s in c.per_scenario), default=None)
        spread = sorted(others, key=lambda c: c.quality)
        picks = [
            c
            for c in [by_q]
            + [spread[int(k * (len(spread) - 1) / max(args.candidates - 1, 1))] for k in range(args.candidates - 1)]
            if c is not None
        ]
        for candidate in list({c.index: c for c in picks}.values())[: args.candidates]:
            design, evaluation, _, _, _ = candidate_designs(result, [candidate])[0]
            checked = verify(design, config)
            success = float(np.mean([s.fcso.success_rate for s in checked.scenarios]))
            q = min(s.effective_area for s in evaluation.scenarios)
            correlation.append((entry.name, candidate.index, evaluation.quality, q, success))
        print(f"  ({time.perf_counter() - started:.0f} s)", flush=True)

    caging = [r for r in rows if r[0].caging]
    plain = [r for r in rows if not r[0].caging]
    good = sum(1 for r in caging if r[3].success_rate >= 0.9)
    flat_low = sum(1 for r in caging if r[4].success_rate <= 0.3)
    print(
        f"\ncaging scenarios: designed >= 9/10 in {good} of {len(caging)} ({good / max(len(caging), 1):.0%}; "
        f"target 80 %), flat <= 3/10 in {flat_low} of {len(caging)}"
    )
    worse = [r for r in rows if r[3].success_rate < r[4].success_rate]
    print(
        f"scenarios where designed succeeds less often than flat: {len(worse)} " + ", ".join(r[0].name for r in worse)
    )
    weaker = [r for r in rows if weaker_than_flat(r[3].holding_n, r[4].holding_n, config)]
    print(
        f"scenarios where designed holds less than flat (some direction, beyond {config.hold_tolerance_n:g} N): "
        f"{len(weaker)} " + ", ".join(r[0].name for r in weaker)
    )
    told = sum(1 for r in plain if not r[1].beats_flat)
    print(f"featureless scenarios where the design says flat is as good: {told} of {len(plain)}")
    if len(correlation) >= 3:
        measures, qs, successes = (np.array([c[k] for c in correlation]) for k in (2, 3, 4))
        rho_measure = spearmanr(measures, successes).statistic
        rho_q = spearmanr(qs, successes).statistic
        print(
            f"Spearman over {len(correlation)} verified candidates: capture measure {rho_measure:.2f}, "
            f"paper Q {rho_q:.2f} (target >= 0.6 and above Q's)"
        )
        for name, index, measure, q, success in correlation:
            print(f"  {name:<36} candidate {index:>6}: measure {measure:8.1f}  Q {q:8.1f}  success {success:.0%}")


if __name__ == "__main__":
    main()
