"""Printed fit in simulation: what clearance and lead-in buy and cost in the paper's precision test (METHOD §12).

Run from the repository root::

    python -m benchmarks.bench_print_fit [--profile mjf-pa12] [--trials 10] [--quick] [--oversize MM]

For each part set, the finger is designed four times: clearance 0 or the
profile's, lead-in 0 or the profile's (the profile's minimum wall and
density throughout), and each design runs the in-silico precision test of
``fcso.sim`` (``--trials`` trials, the part placed +-2 mm and +-3 degrees
off, closing at 20 mm/s with 60 N, lift 100 mm, success within 0.3 mm and
1 degree) and the holding test (push ramping to 30 N in six directions).
Part sets (``--sets``): the paper's cube-like part (a 30 mm cube with 8 mm
V-notches and a hole, ``examples/sim_parts.featured_cube``, designed upright
across its notches), the demo parts (``examples/parts``: the 20 mm xyz cube
and the solar tracker with the batch demo's 10 mm pads; the capsela plug has no
grasp at 50 mm) and the bunny of the paper's experiment (``examples/paper.toml``). ``--oversize MM`` adds the cube
printed MM too large on every side (a process deviation the clearance is
meant to absorb), with clearance 0 and the profile's.

Prints one row per design and scenario: the design's Q with the exact pocket
and as printed, the seat offsets, the success rate, the median and worst
final errors, the weakest holding force, and the flat-pad control once per
scenario. The simulation is deterministic for a seed; the machine is shared,
so the wall times printed are indicative only.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

import fcso
from examples.batch_demo import DEMO_10MM_PADS
from examples.sim_parts import featured_cube, upright_grasp_settings
from fcso.config import PRINT_PROFILES
from fcso.geometry import to_manifold, to_trimesh
from fcso.parts import Part
from fcso.printfit import grow
from fcso.sim.config import VerifyConfig
from fcso.sim.verify import DesignUnderTest, design_under_test, verify

REPO = Path(__file__).resolve().parent.parent
PARTS = REPO / "examples" / "parts"

#: The demo parts with the batch-demo job's 10 mm pads: a fine carving, where clearance and walls matter most.
DEMO_SETTINGS = {"poses": {"count": 1, "select": "most_probable"}, "sampler": DEMO_10MM_PADS}


def cube_parts() -> tuple[list[Part], dict]:
    """The paper's cube-like part and the settings that design it upright, closing across its notches."""
    mesh = featured_cube(notch_mm=8.0)
    return [Part(name="cube30-notch8", path="featured_cube", mesh=mesh)], upright_grasp_settings(mesh)


def bunny_parts() -> tuple[list[Part], dict]:
    """The paper's experiment (METHOD §10): the bunny scaled to 65 mm with examples/paper.toml."""
    settings = fcso.load_config(REPO / "examples" / "paper.toml").model_dump(exclude={"finger", "print"})
    return [fcso.load_part(PARTS / "stanford_bunny_closed.ply", scale_to_mm=65.0)], settings


def demo_parts() -> tuple[list[Part], dict]:
    """The demo parts of examples/parts that a 50 mm gripper can hold, with the batch demo's 10 mm pads."""
    return [fcso.load_part(PARTS / "20mm-xyz-cube.stl"), fcso.load_part(PARTS / "solar_tracker.stl")], DEMO_SETTINGS


def design(parts: list[Part], settings: dict, profile: str, clearance: float, lead_in: float) -> fcso.DesignResult:
    config = fcso.DesignConfig().updated(
        {**settings, "print": {"profile": profile, "clearance_mm": clearance, "lead_in_deg": lead_in}}
    )
    return fcso.design(parts, config)


def oversized(under_test: DesignUnderTest, grown_mm: float) -> DesignUnderTest:
    """The same grasps on parts printed ``grown_mm`` too large on every side (an offset surface, as printing
    deviates).
    """
    cases = []
    for case in under_test.cases:
        part_file = to_trimesh(grow(to_manifold(case.part_file), grown_mm))
        part = part_file.copy()
        part.apply_transform(case.rest_transform)
        cases.append(dataclasses.replace(case, name=f"{case.name} +{grown_mm:g} mm", part=part, part_file=part_file))
    return dataclasses.replace(under_test, cases=cases)


def _weakest(holding: dict) -> str:
    forces = [v for v in holding.values() if v is not None]
    return (
        "held 30"
        if not forces
        else f"{min(forces):.0f} ({min(holding, key=lambda d: holding[d] if holding[d] is not None else np.inf)})"
    )


HEADER = (
    f"{'scenario':<34} {'c mm':>5} {'lead°':>5} {'Q exact':>8} {'Q print':>8} {'seat mm':>13} "
    f"{'success':>8} {'median mm':>9} {'worst mm':>9} {'median°':>8} {'worst°':>7} {'weakest hold N':>16}"
)


def run(label: str, parts, settings, profile: str, combos, config: VerifyConfig, grown_mm: float = 0.0) -> None:
    print(f"\n{label}")
    print(HEADER)
    flat_rows = {}
    for clearance, lead_in in combos:
        started = time.perf_counter()
        result = design(parts, settings, profile, clearance, lead_in)
        designed = time.perf_counter() - started
        under_test = design_under_test(result)
        if grown_mm > 0:
            under_test = oversized(under_test, grown_mm)
        started = time.perf_counter()
        verification = verify(under_test, config)
        simulated = time.perf_counter() - started
        fit = result.report.print_fit
        for m, scenario in enumerate(verification.scenarios):
            r = scenario.fcso
            seat = fit.fitted.seat_offsets_mm[m]
            print(
                f"{under_test.cases[m].name[:34]:<34} {clearance:>5.2f} {lead_in:>5.0f} {fit.exact.quality:>8.1f} "
                f"{fit.fitted.quality:>8.1f} "
                f"{seat[0]:>+6.2f},{seat[1]:>+6.2f} {r.success_rate:>8.0%} {r.median_error_mm:>9.3f} "
                f"{r.worst_error_mm:>9.3f} "
                f"{r.median_error_deg:>8.2f} {r.worst_error_deg:>7.2f} {_weakest(r.holding_n):>16}"
            )
            flat_rows.setdefault(under_test.cases[m].name, scenario.flat)
        print(
            f"{'':<34} (design {designed:.0f} s, simulation {simulated:.0f} s, seated penetration "
            f"{max(s.fidelity.seated_penetration_mm for s in verification.scenarios):.3f} mm)"
        )
    for name, r in flat_rows.items():
        print(
            f"{'flat pads: ' + name:<34.34} {'':>5} {'':>5} {'':>8} {'':>8} {'':>13} {r.success_rate:>8.0%} "
            f"{r.median_error_mm:>9.3f} {r.worst_error_mm:>9.3f} {r.median_error_deg:>8.2f} {r.worst_error_deg:>7.2f} "
            f"{_weakest(r.holding_n):>16}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="mjf-pa12", choices=[p for p in PRINT_PROFILES if p != "custom"])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--quick", action="store_true", help="the paper's cube only")
    parser.add_argument("--sets", default="cube,demo,bunny", help="comma-separated part sets: cube, demo, bunny")
    parser.add_argument(
        "--oversize", type=float, default=0.0, help="also simulate the cube printed this much too large per side, mm"
    )
    args = parser.parse_args()
    values = PRINT_PROFILES[args.profile]
    clearance, lead_in = values["clearance_mm"], values["lead_in_deg"]
    combos = [(0.0, 0.0), (clearance, 0.0), (0.0, lead_in), (clearance, lead_in)]
    with tempfile.TemporaryDirectory() as scratch:
        # every trial: the success rates are the figures compared
        config = VerifyConfig(
            trials=args.trials, density_g_cm3=values["density_g_cm3"], cache_dir=Path(scratch), stop_early=False
        )
        print(
            f"profile {args.profile}: clearance {clearance} mm, lead-in {lead_in} deg, min wall "
            f"{values['min_wall_mm']} mm, "
            f"density {values['density_g_cm3']} g/cm3; {args.trials} trials per scenario, +-2 mm +-3 deg, success "
            f"within 0.3 mm and 1 deg"
        )
        sets = ["cube"] if args.quick else args.sets.split(",")
        if "cube" in sets:
            run(
                "paper's cube-like part: 30 mm cube, 8 mm V-notches, 8 mm hole",
                *cube_parts(),
                args.profile,
                combos,
                config,
            )
            if args.oversize > 0:
                run(
                    f"the same cube printed {args.oversize:g} mm too large per side",
                    *cube_parts(),
                    args.profile,
                    [(0.0, 0.0), (clearance, 0.0), (clearance, lead_in)],
                    config,
                    grown_mm=args.oversize,
                )
        if "demo" in sets:
            run(
                "demo parts: 20 mm xyz cube and solar tracker, one finger (10 mm pads)",
                *demo_parts(),
                args.profile,
                combos,
                config,
            )
        if "bunny" in sets:
            run(
                "paper experiment: bunny 65 mm, poses 1 and 3 (examples/paper.toml)",
                *bunny_parts(),
                args.profile,
                combos,
                config,
            )


if __name__ == "__main__":
    main()
