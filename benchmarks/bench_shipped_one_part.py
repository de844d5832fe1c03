"""A job of one part with the shipped daemon's design settings: how long its design takes and what it simulates.

Usage::

    python -m benchmarks.bench_shipped_one_part [--runs N]

Designs a plain 30 x 20 x 15 mm block as ``fcsod`` would with
``deploy/fcsod.toml``'s ``[design]`` section (three pad sizes, finger sets
judged by truth for 300 s), in process, with an empty simulation cache per
run. Prints the median wall time of :func:`fcso.sets.design_sets` and the
simulation outcomes it wrote to the cache. A job of one distinct part has no
finger to share, so nothing should be simulated during its design: its
finger is verified by the choice by truth after it.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import tomllib
from pathlib import Path

import trimesh

import fcso
from fcso.parts import Part
from fcso.sets import design_sets

SHIPPED = Path(__file__).resolve().parents[1] / "deploy" / "fcsod.toml"


def one_run() -> tuple[float, int]:
    """Wall seconds of the block's design and the simulation outcomes it cached."""
    shipped = tomllib.loads(SHIPPED.read_text(encoding="utf-8"))["design"]
    with tempfile.TemporaryDirectory() as cache:
        config = fcso.DesignConfig().updated(shipped).updated({"verify": {"cache_dir": cache}})
        block = Part(name="block", path="block.stl", mesh=trimesh.creation.box([30.0, 20.0, 15.0]))
        started = time.perf_counter()
        design_sets([block], config)
        wall_s = time.perf_counter() - started
        return wall_s, sum(1 for _ in Path(cache).rglob("*.npz"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    runs = [one_run() for _ in range(args.runs)]
    print(
        f"one-part job, deploy/fcsod.toml [design]: design {statistics.median(w for w, _ in runs):.1f} s "
        f"(median of {args.runs}), {max(n for _, n in runs)} simulation outcomes cached during the design "
        "(target: 0)"
    )


if __name__ == "__main__":
    main()
