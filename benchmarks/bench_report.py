"""Rendering time of report.html for the paper's bunny experiment.

Usage::

    python -m benchmarks.bench_report            # designs the bunny first (~60 s)
    python -m benchmarks.bench_report --dir DIR  # an existing output folder of that design

Prints the median (and range) over ``--runs`` renderings of the whole page,
and of one grasp picture of the bunny subdivided to more than 50k faces
(drawing decimates it; the contact patch uses every face).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import trimesh

from fcso import design, load_config, load_part
from fcso.output.design_page import load_report_inputs, render_html, report_inputs
from fcso.output.pictures import grasp_picture

ROOT = Path(__file__).resolve().parents[1]


def _timed(function, runs: int) -> list[float]:
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return times


def _line(name: str, times: list[float]) -> str:
    return (
        f"{name:<44} median {statistics.median(times):6.2f} s  (min {min(times):.2f}, max {max(times):.2f}, "
        f"{len(times)} runs)"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", type=Path, help="output folder of the bunny design (default: design it now)")
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args(argv)
    if args.dir is None:
        config = load_config(ROOT / "examples" / "paper.toml")
        started = time.perf_counter()
        result = design(
            [load_part(ROOT / "examples" / "parts" / "stanford_bunny_closed.ply", scale_to_mm=65.0)], config
        )
        print(f"bunny design (not part of the rendering time): {time.perf_counter() - started:.1f} s")
        inputs = report_inputs(result)
    else:
        print(_line("fcso report: reload and re-seat", _timed(lambda: load_report_inputs(args.dir), args.runs)))
        inputs = load_report_inputs(args.dir)
    faces = [len(g.mesh.faces) for g in inputs.grasps]
    print(
        _line(
            f"report.html, bunny ({faces[0]} faces, {len(faces)} poses)", _timed(lambda: render_html(inputs), args.runs)
        )
    )
    grasp = inputs.grasps[0]
    vertices, big_faces = trimesh.remesh.subdivide(*trimesh.remesh.subdivide(grasp.mesh.vertices, grasp.mesh.faces))
    big = trimesh.Trimesh(vertices, big_faces, process=False)
    settings = inputs.report.settings.sampler
    pad_size = (settings.thickness_mm, settings.length_mm, settings.width_mm)
    print(
        _line(
            f"one grasp picture, bunny at {len(big.faces)} faces",
            _timed(
                lambda: grasp_picture(big, inputs.fingerpad, grasp.placements, pad_size, grasp.sample.closing_axis),
                args.runs,
            ),
        )
    )


if __name__ == "__main__":
    main()
