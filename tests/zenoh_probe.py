"""A zenoh client the security tests run as a separate process: ``python -m tests.zenoh_probe --config FILE [actions]``.

It opens a session from a zenoh config file, then does what it is told and
prints one JSON line per event: ``open`` (or ``open_failed`` and exit 3),
``liveliness``, ``reply``, ``received``, ``put``, ``queried_by``, and with
``--hold`` ``ready`` once every action is done, staying until its standard
input closes. An attacker
in these tests is this script holding a certificate.
"""

from __future__ import annotations

import argparse
import base64
import json
import sys
import time

import zenoh


def _print(**line) -> None:
    print(json.dumps(line), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--config", required=True)
    parser.add_argument("--liveliness", metavar="KEY", help="ask who holds liveliness tokens on KEY")
    parser.add_argument("--query", metavar="KEY", help="query KEY and print the replies")
    parser.add_argument("--subscribe", metavar="KEY", help="print what arrives on KEY")
    parser.add_argument("--put", metavar="KEY", help="publish forged payloads on KEY")
    parser.add_argument("--payload", default='{"job_id": "x", "grasps": []}', help="the forged payload")
    parser.add_argument("--attachment", help="attachment to send with it (JSON text); default none")
    parser.add_argument("--count", type=int, default=20)
    parser.add_argument(
        "--await-subscriber",
        action="store_true",
        help="put only once a subscriber matches the key: a put before the routes are known is dropped",
    )
    parser.add_argument("--queryable", metavar="KEY", help="answer queries on KEY with the forged payload")
    parser.add_argument("--token", metavar="KEY", help="declare a liveliness token on KEY")
    parser.add_argument(
        "--hold", action="store_true", help="after the actions print 'ready' and stay until standard input closes"
    )
    args = parser.parse_args()
    try:
        session = zenoh.open(zenoh.Config.from_file(args.config))
    except zenoh.ZError as exc:
        _print(event="open_failed", error=str(exc))
        return 3
    _print(event="open")
    attachment = args.attachment.encode() if args.attachment else None
    keep = []
    if args.subscribe:

        def received(sample) -> None:
            raw = sample.attachment.to_bytes() if sample.attachment is not None else None
            _print(
                event="received",
                key=str(sample.key_expr),
                payload=sample.payload.to_bytes().decode(errors="replace"),
                attachment=raw.decode() if raw else None,
            )

        keep.append(session.declare_subscriber(args.subscribe, received))
    if args.queryable:

        def answer(query) -> None:
            _print(event="queried_by", key=str(query.key_expr))
            query.reply(args.queryable.replace("**", "forged/grasps"), args.payload.encode(), attachment=attachment)

        keep.append(session.declare_queryable(args.queryable, answer))
    if args.token:
        keep.append(session.liveliness().declare_token(args.token))
    if args.liveliness:
        holders = [
            str(r.ok.key_expr) for r in session.liveliness().get(args.liveliness, timeout=3.0) if r.ok is not None
        ]
        _print(event="liveliness", holders=holders)
    if args.query:
        for reply in session.get(args.query, timeout=3.0):
            if reply.ok is not None:
                raw = reply.ok.attachment.to_bytes() if reply.ok.attachment is not None else None
                _print(
                    event="reply",
                    key=str(reply.ok.key_expr),
                    payload_base64=base64.b64encode(reply.ok.payload.to_bytes()).decode(),
                    attachment=raw.decode() if raw else None,
                )
            else:
                _print(event="reply_error", error=reply.err.payload.to_bytes().decode(errors="replace"))
        _print(event="query_done")
    if args.put:
        publisher = session.declare_publisher(
            args.put, reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.BLOCK
        )
        # a condition, not a clock: the test's own guard ends a probe that never sees one
        while args.await_subscriber and not publisher.matching_status.matching:
            time.sleep(0.01)
        for _ in range(args.count):
            publisher.put(args.payload.encode(), attachment=attachment)
            time.sleep(0.05)
        _print(event="put", count=args.count)
    if args.hold:
        # the test, not a clock, decides how long this client stays
        _print(event="ready")
        sys.stdin.read()
    session.close()
    _print(event="closed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
