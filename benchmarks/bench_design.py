"""Time fcso's stages on the paper experiment and on a four-part, two-pose batch.

Run from the repository root::

    python -m benchmarks.bench_design [--runs N]

Prints the median (and min-max) wall time of each stage over N runs. The
machine is shared and noisy: compare medians, not single runs.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import fcso

REPO = Path(__file__).resolve().parent.parent
PARTS = REPO / "examples" / "parts"
DATA = REPO / "tests" / "data"


def paper_case():
    """The paper's bunny experiment (METHOD §10) with examples/paper.toml."""
    parts = [fcso.load_part(PARTS / "stanford_bunny_closed.ply", scale_to_mm=65.0)]
    return parts, fcso.load_config(REPO / "examples" / "paper.toml")


def multi_part_case():
    """Four fixture parts, two most probable poses each, 10 x 10 mm pads and a search budget."""
    parts = [
        fcso.load_part(DATA / "20mm-xyz-cube.stl"),
        fcso.load_part(DATA / "solar_tracker.stl"),
        fcso.load_part(DATA / "DC-DC_case.stl"),
        fcso.load_part(DATA / "angle_block.STL", units="inch"),
    ]
    config = fcso.DesignConfig().updated(
        {
            "sampler": {"length_mm": 10.0, "width_mm": 10.0, "thickness_mm": 4.0, "penetration_mm": 3.0, "stride_mm": 8.0},
            "poses": {"count": 2, "select": "most_probable"},
            "search": {"max_exhaustive": 4096, "max_evaluations": 100},
        }
    )
    return parts, config


def measure(name: str, case, runs: int) -> None:
    parts, config = case()
    stages: dict[str, list[float]] = {}
    for _ in range(runs):
        started = time.perf_counter()
        result = fcso.design(parts, config)
        for stage, seconds in result.report.timings_s.items():
            stages.setdefault(stage, []).append(seconds)
        stages.setdefault("total", []).append(time.perf_counter() - started)
    report = result.report
    evaluated = report.search.evaluated
    print(f"\n{name}: {len(report.scenarios)} scenarios, valid samples {[s.valid_samples for s in report.scenarios]}, "
          f"C = {report.search.candidates_total}, {report.search.kind} evaluated {evaluated}, best Q = "
          f"{next(c.quality for c in report.candidates if c.index == report.best):.1f}")
    print(f"  {'stage':<16}{'median s':>10}{'min s':>9}{'max s':>9}   ({runs} runs)")
    for stage, seconds in stages.items():
        print(f"  {stage:<16}{statistics.median(seconds):>10.3f}{min(seconds):>9.3f}{max(seconds):>9.3f}")
    per_candidate = statistics.median(stages["search"]) / max(evaluated, 1)
    print(f"  {'per candidate':<16}{per_candidate:>10.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    measure("paper experiment (bunny, 65 mm, poses 1 and 3)", paper_case, args.runs)
    measure("multi-part (cube, solar tracker, DC-DC case, angle block; 2 poses each)", multi_part_case, args.runs)


if __name__ == "__main__":
    main()
