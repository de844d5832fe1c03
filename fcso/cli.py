"""Command line: ``fcso design``, ``fcso report``, ``fcso poses``, ``fcso schema``."""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import FcsoError, GeometryError
from .startup import collector_paused

with collector_paused():
    from .verify_cli import add_design_options, add_settings_options, add_verify_command

if TYPE_CHECKING:
    from .config import DesignConfig
    from .sets import SetsResult

# each command imports what it uses when it runs: ``fcso --help`` and the small commands load neither the pipeline
# (numba, its compiled kernels) nor the simulation nor matplotlib (tests/test_architecture.py)

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


class ProgressLine:
    """A one-line progress bar per stage on a terminal; silent elsewhere or when quiet.

    Parameters
    ----------
    stream : file
        Where to draw (standard error).
    enabled : bool
        Draw at all (a terminal, and not ``--quiet``).
    """

    def __init__(self, stream, enabled: bool):
        self.stream = stream
        self.enabled = enabled
        self.stage = None
        self.last = (0, 0)
        self.note = ""
        self.started = time.perf_counter()
        self.last_draw = 0.0

    def __call__(self, stage: str, done: int, total: int, note: str = "") -> None:
        """``progress(stage, done, total, note)`` as :func:`fcso.pipeline.design` calls it."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if stage != self.stage:
            if self.stage is not None:
                # the last count of a stage may have been throttled: show it before moving on
                self._draw(now)
                self.stream.write("\n")
            self.stage = stage
        elif done < total and now - self.last_draw < 0.1:
            self.last, self.note = (done, total), note
            return
        self.last = (done, total)
        self.note = note
        self._draw(now)

    def _draw(self, now: float) -> None:
        done, total = self.last
        fraction = min(done / total, 1.0) if total else 1.0
        bar = "#" * int(fraction * 30)
        note = f"  {self.note}" if self.note else ""
        self.stream.write(f"\r{self.stage:<15} [{bar:<30}] {done}/{total}  {now - self.started:6.1f} s{note}\033[K")
        self.stream.flush()
        self.last_draw = now

    def close(self) -> None:
        if self.enabled and self.stage is not None:
            self._draw(time.perf_counter())
            self.stream.write("\n")
            self.stream.flush()
            self.stage = None


def _finger_sets_count(text: str) -> int | str:
    """``--finger-sets``: a number of sets, at least 1, or ``auto``."""
    if text == "auto":
        return text
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise argparse.ArgumentTypeError(f"expected a number of sets (1 or more) or 'auto', got {text!r}")
    return count


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fcso", description="Custom gripper fingerpads for 3D-printed parts (FCSO).")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("design", help="design a fingerpad and finger for one or more parts")
    run.add_argument(
        "parts",
        nargs="+",
        type=Path,
        metavar="PART",
        help="part meshes (STL, 3MF, OBJ, PLY); a 3MF build gives one part per object",
    )
    run.add_argument("--out", required=True, type=Path, help="output folder")
    run.add_argument("--config", type=Path, help="settings (TOML)")
    add_part_options(run)
    run.add_argument("--poses", type=int, metavar="N", help="stable poses per part (poses.count)")
    run.add_argument("--seed", type=int, help="seed of the random pose choice (poses.seed)")
    run.add_argument(
        "--finger", type=Path, metavar="FINGER", help="flat finger mesh (finger.mesh; frame from --config)"
    )
    run.add_argument(
        "--jobs",
        type=int,
        metavar="N",
        help="worker processes (search.jobs; default: every core); results do not depend on it",
    )
    run.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the design's tasks on a Dask distributed cluster, e.g. tcp://host:8786 (compute.scheduler); "
        "results do not depend on it",
    )
    run.add_argument(
        "--finger-sets",
        type=_finger_sets_count,
        metavar="N|auto",
        help="most finger sets for the job (finger_sets.max, default 4); 1: one finger for every part; auto: the "
        "fewest that serve every part",
    )
    run.add_argument(
        "--min-retained",
        type=float,
        metavar="R",
        help="least E / E* every scenario should keep in its set (finger_sets.min_retained, default 0.5)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress and no table")
    add_design_options(run)
    add_settings_options(run)

    report = commands.add_parser("report", help="rebuild report.html in a design's output folder")
    report.add_argument(
        "directory",
        type=Path,
        metavar="DIR",
        help="output folder of fcso design (report.json, finger.stl, fingerpad.stl)",
    )
    report.add_argument("--quiet", action="store_true", help="no progress")

    poses = commands.add_parser("poses", help="list a part's stable poses with probabilities")
    poses.add_argument("part", type=Path, metavar="PART", help="a part mesh (STL, 3MF, OBJ, PLY)")
    add_part_options(poses)

    add_verify_command(commands)

    schema = commands.add_parser("schema", help="write the JSON Schemas of config and report")
    schema.add_argument("--out", required=True, type=Path)
    return parser


def add_part_options(parser) -> None:
    """How part files are read: ``--units``, ``--scale-to``, ``--repair`` (``design`` and ``poses``)."""
    parser.add_argument("--units", default="mm", help="unit of the part files: mm, inch, m or a factor to mm")
    parser.add_argument("--scale-to", type=float, metavar="MM", help="scale each part so its longest side is MM")
    parser.add_argument("--repair", action="store_true", help="repair meshes that are not closed volumes")


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (2 for bad input, 1 for a failed design, 3 for a design verified in simulation
    that did not pass: ``fcso verify``, ``fcso design --verify``)."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "design":
            return _design(args)
        if args.command == "poses":
            return _poses(args)
        if args.command == "report":
            return _report(args)
        if args.command == "verify":
            from .verify_cli import run_verify

            return run_verify(args, ProgressLine(sys.stderr, enabled=not args.quiet and sys.stderr.isatty()))
        from .schema import write_schemas

        for path in write_schemas(args.out):
            print(path)
        return 0
    except GeometryError as exc:
        print(f"fcso: design failed: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except FcsoError as exc:
        print(f"fcso: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def _config(args) -> DesignConfig:
    from .config import DesignConfig, format_validation_error, load_config

    config = load_config(args.config) if args.config else DesignConfig()
    overrides: dict = {}
    if args.poses is not None:
        overrides.setdefault("poses", {})["count"] = args.poses
    if args.seed is not None:
        overrides.setdefault("poses", {})["seed"] = args.seed
    if args.finger is not None:
        overrides.setdefault("finger", {})["mesh"] = args.finger
    if getattr(args, "jobs", None) is not None:
        overrides.setdefault("search", {})["jobs"] = args.jobs
    if getattr(args, "scheduler", None) is not None:
        overrides.setdefault("compute", {})["scheduler"] = args.scheduler
    if getattr(args, "finger_sets", None) is not None:
        overrides.setdefault("finger_sets", {})["max"] = args.finger_sets
    if getattr(args, "min_retained", None) is not None:
        overrides.setdefault("finger_sets", {})["min_retained"] = args.min_retained
    if not overrides:
        return config
    from pydantic import ValidationError

    from .errors import ConfigError

    try:
        return config.updated(overrides)
    except ValidationError as exc:
        raise ConfigError(args.config or "command line", format_validation_error(exc)) from None


def _design(args) -> int:
    with collector_paused():
        from .output.picture_process import PictureProcess

    # forked before the method's modules load: the drawing code loads on the other core while they load here
    with PictureProcess() as draw_pictures:
        with collector_paused():
            from .errors import NoGraspError
            from .output.files import write_set_outputs
            from .parts import load_parts, units_hint
            from .sets import design_sets

            # what is loaded lives until the command ends (run() ends the process at once): no collection walks it
            # again
            gc.freeze()

        config = _config(args)
        parts = [
            part
            for path in args.parts
            for part in load_parts(
                path,
                units=args.units,
                scale_to_mm=args.scale_to,
                repair=args.repair,
                split_bodies=config.parts.split_bodies,
                max_repair_volume_change_percent=config.parts.repair_max_volume_change_percent,
                max_repair_deviation_mm=config.parts.repair_max_deviation_mm,
            )
        ]
        progress = ProgressLine(sys.stderr, enabled=not args.quiet and sys.stderr.isatty())
        try:
            job = design_sets(parts, config, progress=progress, repair=args.repair)
            write_set_outputs(job, args.out, progress=progress, draw=draw_pictures)
        except (NoGraspError, GeometryError) as exc:
            # a part read in the wrong unit fails here: say which unit to try, in the error's one line
            hints = [hint for part in parts if (hint := units_hint(part, args.units, args.scale_to))]
            if not hints:
                raise
            raise type(exc)(f"{exc}; " + "; ".join(hints)) from None
        finally:
            progress.close()
    return _report_sets(job, args)


def _print_parts(parts, scenarios, ungraspable) -> None:
    """A line per part (volume, shell handling, the stable poses designed for with their probabilities).

    Then a line per ungraspable pose.
    """
    poses: dict[str, dict[int, float]] = {}
    for entry in [*scenarios, *ungraspable]:
        poses.setdefault(entry.part, {})[entry.pose_index] = entry.pose_probability
    for entry in parts:
        handling = f" ({entry.shell_handling})" if entry.shell_handling else ""
        chosen = ", ".join(
            f"{index} (p = {probability:.3f})" for index, probability in sorted(poses.get(entry.name, {}).items())
        )
        print(f"part {entry.name}: {entry.volume_mm3:.1f} mm³{handling}; stable poses {chosen}")
    for entry in ungraspable:
        print(f"ungraspable: {entry.part} in stable pose {entry.pose_index}: {entry.reason}")


def _report_sets(job: SetsResult, args) -> int:
    """Print what a job's finger sets (one or several) made, and verify each set's finger when asked."""
    from .output.sets_page import pad_sizes_line, pick_plan_text
    from .output.table import quality_table
    from .verify_cli import verify_job_outputs

    report, sets = job.job(), job.report
    if not args.quiet:
        _print_parts(report.parts, [s for d in job.designs for s in d.report.scenarios], (sets or report).ungraspable)
        if not job.several:
            print(quality_table(report))
        if sets is not None:
            print(pick_plan_text(sets))
        sizes = pad_sizes_line(sets.pad_sizes if sets is not None else report.pad_sizes)
        if sizes:
            print(sizes)
        for warning in report.warnings:
            print(f"warning: {warning}")
        if job.several:
            print(f"wrote {args.out}/report.json, report.html and " + ", ".join(f"{s.folder}/" for s in sets.sets))
        else:
            print(f"wrote {args.out}/finger.stl, fingerpad.stl, report.json, report.html")
    if args.verify or args.verify_top is not None:
        return verify_job_outputs(
            job, args, lambda: ProgressLine(sys.stderr, enabled=not args.quiet and sys.stderr.isatty())
        )
    return 0


def _report(args) -> int:
    from .output.design_page import rebuild_report
    from .output.files import rebuild_job_report
    from .output.read import is_job_folder
    from .verify_cli import restore_section

    progress = ProgressLine(sys.stderr, enabled=not args.quiet and sys.stderr.isatty())
    try:
        if is_job_folder(args.directory):
            paths = rebuild_job_report(args.directory, progress=progress)
        else:
            paths = [rebuild_report(args.directory, progress=progress)]
            restore_section(args.directory)
    finally:
        progress.close()
    if not args.quiet:
        for path in paths:
            print(f"wrote {path}")
    return 0


def _poses(args) -> int:
    from .parts import load_part
    from .poses import stable_poses

    part = load_part(args.part, units=args.units, scale_to_mm=args.scale_to, repair=args.repair)
    transforms, probabilities = stable_poses(part.mesh)
    print(f"{part.name}: {len(probabilities)} stable poses (extents in the resting frame, mm)")
    print(f"{'index':>5} {'probability':>12} {'extents x y z':>28}")
    for index, (transform, probability) in enumerate(zip(transforms, probabilities)):
        rested = part.mesh.copy()
        rested.apply_transform(transform)
        extents = " ".join(f"{x:8.2f}" for x in rested.extents)
        print(f"{index:>5} {probability:>12.4f} {extents:>28}")
    return 0


def run() -> None:
    """The ``fcso`` command: :func:`main`, then the process ends at once with its exit code.

    The imports alone leave about 130,000 objects the garbage collector
    tracks, and the interpreter's last collections at exit walk them all
    (0.2-0.3 s of the paper command's 4 s); a process about to end has
    nothing to gain from them. Every file is closed by then (the outputs are
    written and renamed, the worker pools and the picture process shut), so
    only the standard streams are flushed. Skipping the interpreter's end
    also skips nanobind's leak report of manifold3d objects still in
    reference cycles (about 60 lines after ``fcso design --verify``), which
    says nothing to a user.
    """
    code = main()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:  # the reader stopped reading (fcso poses PART | head): nothing to tell it
            pass
    os._exit(code)


if __name__ == "__main__":
    run()
