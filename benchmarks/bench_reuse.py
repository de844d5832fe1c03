"""Finger reuse benchmark: ``python -m benchmarks.bench_reuse`` from the repository root (by hand; not a test).

Drops a job (a real part) into a fresh daemon, then the same part in new
folders, one at a time, and prints the time from each job's readiness (the
daemon's "job queued" line) to its ``done`` status on zenoh: the first job
designs and prints a finger, the repeated ones reuse it from the cell's
finger library (METHOD §11b). Target: a repeated job under 20 % of the
first. ``--fast`` uses the tests' quick design settings instead of fcso's
defaults. ``--near-scale F`` (default 0.99) then drops the part scaled by F
(``scale_to_mm`` in a job.toml): not the same geometry, it is evaluated on
the delivered pad (``fcso.fit_pads``) and reuses the finger when it keeps
``min_retained``; its time and worst retained are printed (no target: it
costs about a design's sampling and solo qualities, and saves the print).
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import fcso
from tests.fcsod_helpers import DATA, FAST_DESIGN, free_port, start_daemon, start_subscriber, write_config

#: Repeated jobs take at most this share of the first job's time (issue 23's target).
TARGET_SHARE = 0.20


def _stamp(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


def _job_seconds(
    daemon, subscriber, folder: Path, part: Path, timeout: float, manifest: str | None = None
) -> tuple[float, dict]:
    """Drop ``part`` (and a ``job.toml`` of ``manifest``) into ``folder``; readiness -> done on zenoh, s, and the done
    status line."""
    folder.mkdir()
    shutil.copy(part, folder / part.name)
    if manifest is not None:
        (folder / "job.toml").write_text(manifest)
    done = subscriber.wait_for(
        lambda v: (
            isinstance(v, dict)
            and v.get("topic") == "status"
            and v["body"]["state"] in ("done", "failed")
            and v["body"]["folder"] == str(folder)
        ),
        timeout,
    )
    received = time.time()
    queued = daemon.wait_for(
        lambda v: isinstance(v, dict) and v.get("message") == "job queued" and v.get("job_id") == done["job_id"], 10
    )
    return received - _stamp(queued["time"]), done


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", type=Path, default=DATA / "20mm-xyz-cube.stl", help="the job's part")
    parser.add_argument("--runs", type=int, default=3, help="repeated jobs")
    parser.add_argument("--fast", action="store_true", help="the tests' quick design settings")
    parser.add_argument("--near-scale", type=float, default=0.99, help="a last job of the part scaled by this")
    args = parser.parse_args()

    base = Path(tempfile.mkdtemp(prefix="fcsod-bench-reuse-"))
    config = write_config(base, free_port(), settle_seconds=0.5, design=FAST_DESIGN if args.fast else "", reuse=True)
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        first, done = _job_seconds(daemon, subscriber, base / "watch" / "first", args.part, 3600)
        if done["body"]["state"] != "done":
            print(f"first job failed: {done['body']['error']}")
            return 1
        repeated = []
        for number in range(args.runs):
            seconds, done = _job_seconds(daemon, subscriber, base / "watch" / f"again-{number}", args.part, 600)
            assert done["body"]["state"] == "done", done["body"]["error"]
            assert not (base / "out" / done["job_id"] / "finger.stl").exists(), "a repeated job printed a finger"
            repeated.append(seconds)
        longest_mm = float(fcso.load_part(args.part).mesh.extents.max())
        manifest = f'[[parts]]\nfile = "{args.part.name}"\nscale_to_mm = {longest_mm * args.near_scale}\n'
        near, done = _job_seconds(daemon, subscriber, base / "watch" / "near", args.part, 3600, manifest)
        assert done["body"]["state"] == "done", done["body"]["error"]
        report = json.loads((base / "out" / done["job_id"] / "report.json").read_text())
    finally:
        subscriber.stop()
        daemon.stop()
    shutil.rmtree(base, ignore_errors=True)
    median = statistics.median(repeated)
    print(f"part: {args.part.name}, {'fast' if args.fast else 'default'} fcso settings")
    print(f"first job (designs and prints a finger), readiness -> done: {first:.2f} s")
    print(
        f"repeated job (reuses it), median of {args.runs}: {median:.2f} s = {100 * median / first:.1f} % of the first "
        f"(target < {100 * TARGET_SHARE:.0f} %); all: {', '.join(f'{s:.2f}' for s in repeated)} s"
    )
    kept = "designs and prints its own finger"
    if "reused" in report:
        (finger,) = report["reused"]
        kept = f"reuses finger {finger['finger_id']}, worst retained {finger['worst_retained']:.3f}"
    share = 100 * near / first
    print(f"part scaled by {args.near_scale}: {kept}; readiness -> done {near:.2f} s = {share:.1f} % of the first")
    return 0 if median < TARGET_SHARE * first else 1


if __name__ == "__main__":
    sys.exit(main())
