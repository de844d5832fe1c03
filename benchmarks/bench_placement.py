"""Benchmark of the build placement against bounding-box packing.

``python -m benchmarks.bench_placement [--runs N] [--voxel-mm V]`` packs 30
fixture parts (scaled so their bounding boxes fill a third of the HP MJF 5200
volume) plus the two built-in fingers, with fcsod's placer and with trimesh's
bounding-box packing (``trimesh.path.packing.meshes``, the simplest baseline),
then adds the fingers to the packed build as the daemon does for a placed job.
Prints the median time and build height of each.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import trimesh
from trimesh.path import packing

from fcso.config import DesignConfig
from fcso.finger import parametric_finger
from fcsod.plate.build3mf import Build, BuildItem
from fcsod.plate.models import BuildConfig
from fcsod.plate.placement import place_fingers

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
#: Fixture meshes and their length in mm per file unit.
FIXTURES = {
    "20mm-xyz-cube.stl": 1.0,
    "DC-DC_case.stl": 1.0,
    "capsela200_plug.stl": 1.0,
    "solar_tracker.stl": 1.0,
    "stanford_bunny_closed.ply": 1.0,
    "box.STL": 25.4,
    "busted.STL": 25.4,
    "angle_block.STL": 25.4,
    "featuretype.STL": 25.4,
    "idler_riser.STL": 25.4,
}
PART_COUNT = 30
FILL_FRACTION = 1.0 / 3.0


def benchmark_parts(config: BuildConfig) -> list[BuildItem]:
    """30 unplaced parts whose bounding boxes fill a third of the volume.

    The fixtures are cycled and scaled uniformly to three sizes (0.5, 1 and
    1.5 times the mean box volume), each kept inside the volume minus margins.
    """
    volume = np.prod(config.volume_mm)
    mean_box = FILL_FRACTION * volume / PART_COUNT
    room = min(config.volume_mm) - 2.0 * config.wall_margin_mm - 10.0
    names = list(FIXTURES)
    parts = []
    for index in range(PART_COUNT):
        name = names[index % len(names)]
        mesh = trimesh.load(DATA / name, force="mesh")
        mesh.apply_scale(FIXTURES[name])
        target = mean_box * (0.5, 1.0, 1.5)[index % 3]
        scale = min((target / np.prod(mesh.extents)) ** (1.0 / 3.0), room / mesh.extents.max())
        mesh.apply_scale(scale)
        parts.append(BuildItem(f"{Path(name).stem}_{index}", mesh))
    return parts


def baseline_bounding_boxes(meshes: list[trimesh.Trimesh], config: BuildConfig) -> tuple[float, int]:
    """Box packing of the meshes into the volume minus margins; (build height mm, items packed)."""
    inner = np.array(config.volume_mm) - 2.0 * config.wall_margin_mm
    placed, _, consumed = packing.meshes(meshes, size=inner, spacing=config.spacing_mm, seed=0)
    height = config.wall_margin_mm + max(float(mesh.bounds[1, 2]) for mesh in placed)
    return height, int(np.sum(consumed))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per method; the median is printed")
    parser.add_argument("--voxel-mm", type=float, default=2.0, help="voxel size of fcsod's placer, mm")
    args = parser.parse_args(argv)

    config = BuildConfig(voxel_mm=args.voxel_mm)
    design = DesignConfig().updated({"sampler": {"length_mm": 20.0}})
    finger = parametric_finger(design.sampler, design.gripper).mesh
    parts = benchmark_parts(config)
    box_fill = sum(np.prod(item.mesh.extents) for item in parts) / np.prod(config.volume_mm)
    print(
        f"{len(parts)} parts + {config.finger_copies} fingers, part boxes fill {box_fill:.0%} of "
        f"{config.volume_mm} mm; spacing {config.spacing_mm} mm, wall margin {config.wall_margin_mm} mm, "
        f"voxel {config.voxel_mm} mm, median of {args.runs} runs"
    )

    pack_times, pack_heights, add_times = [], [], []
    result = None
    for _ in range(args.runs):
        started = time.perf_counter()
        result = place_fingers(Build(items=[BuildItem(p.name, p.mesh) for p in parts]), finger, config)
        pack_times.append(time.perf_counter() - started)
        pack_heights.append(result.report.build_height_mm)
        placed_parts = Build(items=[item for item in result.items if item.kind == "part"])
        started = time.perf_counter()
        place_fingers(placed_parts, finger, config)
        add_times.append(time.perf_counter() - started)

    meshes = [item.mesh for item in parts] + [finger] * config.finger_copies
    base_times, base_heights, base_counts = [], [], []
    for _ in range(args.runs):
        started = time.perf_counter()
        height, count = baseline_bounding_boxes(meshes, config)
        base_times.append(time.perf_counter() - started)
        base_heights.append(height)
        base_counts.append(count)

    report = result.report
    print(f"{'method':<44} {'time s':>8} {'build height mm':>16} {'items':>6}")
    print(
        f"{'fcsod voxel/FFT packing (parts + fingers)':<44} {statistics.median(pack_times):>8.2f} "
        f"{statistics.median(pack_heights):>16.1f} {len(result.items):>6}"
    )
    print(
        f"{'trimesh bounding-box packing (baseline)':<44} {statistics.median(base_times):>8.2f} "
        f"{statistics.median(base_heights):>16.1f} {int(statistics.median(base_counts)):>6}"
    )
    print(f"{'fcsod: add 2 fingers to the placed build':<44} {statistics.median(add_times):>8.2f}")
    print(f"fcsod packing density {report.packing_density:.3f}, all items placed: {report.all_items_placed}")


if __name__ == "__main__":
    main()
