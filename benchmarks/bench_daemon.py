"""Daemon benchmark: ``python -m benchmarks.bench_daemon`` from the repository root (by hand; not a test).

Prints medians of:

- latency from a job's readiness (the daemon's "job queued" line) to its
  ``done`` status on zenoh, for jobs dropped one at a time;
- ``fcso design`` alone on the same batch (in-process: design and output
  files; and the ``fcso design`` command with its start-up), and the
  daemon's overhead over each;
- throughput for 20 jobs dropped at once (time from the drop to the last
  ``done``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

from tests.fcsod_helpers import DATA, FAST_DESIGN, REPO, free_port, start_daemon, start_subscriber, write_config

PART = DATA / "20mm-xyz-cube.stl"


def _stamp(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


def _design_alone(runs: int, base: Path) -> tuple[list[float], list[float]]:
    """Wall times of fcso's design + output files in-process, and of the ``fcso design`` command, s."""
    from fcso import DesignConfig, design, load_part, output_files

    settings = DesignConfig().updated(
        {
            "sampler": {"length_mm": 10, "width_mm": 10, "thickness_mm": 4, "penetration_mm": 3, "stride_mm": 5},
            "poses": {"count": 1, "select": "most_probable"},
        }
    )
    config_file = base / "design.toml"
    config_file.write_text(FAST_DESIGN.replace("[design.", "["))
    in_process, command = [], []
    for number in range(runs):
        started = time.perf_counter()
        output_files(design([load_part(PART)], settings))
        in_process.append(time.perf_counter() - started)
        started = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "fcso.cli",
                "design",
                str(PART),
                "--out",
                str(base / f"alone-{number}"),
                "--config",
                str(config_file),
                "--quiet",
            ],
            cwd=REPO,
            check=True,
            capture_output=True,
        )
        command.append(time.perf_counter() - started)
    return in_process, command


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5, help="single jobs for the latency median")
    parser.add_argument("--batch", type=int, default=20, help="jobs dropped at once for the throughput")
    parser.add_argument("--concurrency", type=int, default=2, help="jobs.concurrency of the daemon")
    args = parser.parse_args()

    base = Path(tempfile.mkdtemp(prefix="fcsod-bench-"))
    config = write_config(base, free_port(), settle_seconds=0.5, extra=f"[jobs]\nconcurrency = {args.concurrency}\n")
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, extra=["--no-query"])
    try:
        latencies = []
        for number in range(args.runs):
            folder = base / "watch" / f"single-{number}"
            folder.mkdir()
            shutil.copy(PART, folder / PART.name)
            done = subscriber.wait_for(
                lambda v, folder=folder: (
                    isinstance(v, dict)
                    and v.get("topic") == "status"
                    and v["body"]["state"] == "done"
                    and v["body"]["folder"] == str(folder)
                ),
                300,
            )
            received = time.time()
            queued = daemon.wait_for(
                lambda v, done=done: (
                    isinstance(v, dict) and v.get("message") == "job queued" and v.get("job_id") == done["job_id"]
                ),
                10,
            )
            latencies.append(received - _stamp(queued["time"]))

        batch_started = time.time()
        staging = base / "staging"
        for number in range(args.batch):
            (staging / f".batch-{number}").mkdir(parents=True)
            shutil.copy(PART, staging / f".batch-{number}" / PART.name)
        for number in range(args.batch):
            # a rename into the root makes every job appear at once
            (staging / f".batch-{number}").rename(base / "watch" / f"batch-{number}")
        finished: set[str] = set()
        deadline = time.monotonic() + 1800
        while len(finished) < args.batch and time.monotonic() < deadline:
            finished = {
                v["job_id"]
                for v in subscriber.json_lines()
                if v.get("topic") == "status" and v["body"]["state"] == "done" and "/batch-" in v["body"]["folder"]
            }
            time.sleep(0.1)
        batch_seconds = time.time() - batch_started
    finally:
        subscriber.stop()
        daemon.stop()

    in_process, command = _design_alone(args.runs, base)
    latency = statistics.median(latencies)
    print(json.dumps({"latencies_s": [round(x, 3) for x in latencies]}))
    print(f"part: {PART.name}, fast fcso settings, concurrency {args.concurrency}")
    print(f"readiness -> done on zenoh, median of {args.runs}: {latency:.2f} s")
    print(
        f"fcso design + output files in-process, median: {statistics.median(in_process):.2f} s -> daemon overhead "
        f"{latency - statistics.median(in_process):.2f} s"
    )
    print(
        f"'fcso design' command incl. start-up, median: {statistics.median(command):.2f} s -> daemon overhead "
        f"{latency - statistics.median(command):.2f} s"
    )
    print(
        f"{len(finished)} of {args.batch} jobs dropped at once done in {batch_seconds:.1f} s: "
        f"{len(finished) / batch_seconds * 60:.1f} jobs/min"
    )
    shutil.rmtree(base, ignore_errors=True)
    return 0 if len(finished) == args.batch else 1


if __name__ == "__main__":
    sys.exit(main())
