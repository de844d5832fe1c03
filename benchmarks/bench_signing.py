"""Cost of the end-to-end signatures: signing and verifying one message, per topic size.

Usage::

    python -m benchmarks.bench_signing [--runs N]

Prints the median time (and range) over ``--runs`` rounds of 200 messages of
the daemon signing (:meth:`fcsod.bus.signing.Signer.attachment`) and a cell
controller verifying (:func:`fcsod.verify_message`) a status-sized JSON
message and a design-sized STL payload (a real part mesh).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from fcsod.bus.signing import generate_signing_key, load_verify_key, verify_message

ROOT = Path(__file__).resolve().parents[1]
MESSAGES_PER_ROUND = 200


def _per_message_us(function, runs: int) -> list[float]:
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        for _ in range(MESSAGES_PER_ROUND):
            function()
        times.append((time.perf_counter() - started) / MESSAGES_PER_ROUND * 1e6)
    return times


def _line(name: str, times: list[float]) -> str:
    return (
        f"{name:<46} median {statistics.median(times):8.1f} us  (min {min(times):.1f}, max {max(times):.1f}, "
        f"{len(times)} runs)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        signer = generate_signing_key(Path(folder) / "signing.key")
        public_key = load_verify_key(Path(folder) / "signing.pub")
    job_id = "batch-demo-9f6de0335e5b"
    payloads = {
        "status (JSON, 372 bytes)": (f"fcso/cell1/jobs/{job_id}/status", b"x" * 372, None),
        "design (solar_tracker.stl, 78884 bytes)": (
            f"fcso/cell1/jobs/{job_id}/design",
            (ROOT / "tests" / "data" / "solar_tracker.stl").read_bytes(),
            b'{"job_id": "batch-demo-9f6de0335e5b", "sha256": "0", "size_bytes": 78884}',
        ),
    }
    for name, (key, payload, attachment) in payloads.items():
        signed = signer.attachment(key, job_id, payload, attachment)
        print(
            _line(
                f"sign   {name}",
                _per_message_us(lambda k=key, p=payload, a=attachment: signer.attachment(k, job_id, p, a), args.runs),
            )
        )
        print(
            _line(
                f"verify {name}",
                _per_message_us(lambda k=key, p=payload, s=signed: verify_message(k, p, s, public_key), args.runs),
            )
        )


if __name__ == "__main__":
    main()
