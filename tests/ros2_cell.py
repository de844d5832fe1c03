"""A stand-in for a ROS 2 cell on rmw_zenoh, run as its own process by the ROS 2 tests.

It connects to the daemon's zenoh endpoint (scouting off) and prints one JSON
line per event: the daemon's zenoh id (``peer``), every liveliness token
under ``@ros2_lv/<domain>/**`` (``token``), and every sample on
``<domain>/**`` and on the native ``fcso/**`` keys (``sample``, payload and
attachment in hex). With ``--late KEY`` it instead declares an
AdvancedSubscriber with history on KEY, the way rmw_zenoh subscribes with
transient-local durability, and prints what the history brings.

``python -m tests.ros2_cell --connect tcp/127.0.0.1:PORT --domain 7 [--late KEY]``;
``--zenoh-config FILE`` instead of ``--connect`` opens the session with a
client config of ``fcsod pki init`` (TLS with that client's certificate).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time

import zenoh
import zenoh.ext

from tests.conftest import HANG_GUARD_S


def _emit(**fields) -> None:
    sys.stdout.write(json.dumps(fields) + "\n")
    sys.stdout.flush()


def _sample(sample: zenoh.Sample, source: str) -> None:
    attachment = sample.attachment.to_bytes().hex() if sample.attachment is not None else None
    _emit(
        event="sample",
        source=source,
        key_expr=str(sample.key_expr),
        payload=sample.payload.to_bytes().hex(),
        attachment=attachment,
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    endpoint = parser.add_mutually_exclusive_group(required=True)
    endpoint.add_argument("--connect")
    endpoint.add_argument("--zenoh-config")
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--late", help="key expression to subscribe to with history (transient local)")
    args = parser.parse_args()
    if args.zenoh_config:
        config = zenoh.Config.from_file(args.zenoh_config)
    else:
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps("peer"))
        config.insert_json5("connect/endpoints", json.dumps([args.connect]))
        config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    deadline = time.monotonic() + HANG_GUARD_S
    while not list(session.info.peers_zid()) and not list(session.info.routers_zid()) and time.monotonic() < deadline:
        time.sleep(0.05)
    _emit(event="peer", zids=[str(zid) for zid in [*session.info.peers_zid(), *session.info.routers_zid()]])
    keep = []
    if args.late:
        history = zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=10)
        keep.append(
            zenoh.ext.declare_advanced_subscriber(session, args.late, lambda s: _sample(s, "history"), history=history)
        )
    else:

        def token(sample: zenoh.Sample) -> None:
            _emit(event="token", key_expr=str(sample.key_expr), kind=str(sample.kind))

        keep.append(session.liveliness().declare_subscriber(f"@ros2_lv/{args.domain}/**", token, history=True))
        keep.append(session.declare_subscriber(f"{args.domain}/**", lambda s: _sample(s, "ros2")))
        keep.append(session.declare_subscriber("fcso/**", lambda s: _sample(s, "native")))
    _emit(event="ready")
    stop = threading.Event()
    try:
        stop.wait(600)
    except KeyboardInterrupt:
        pass
    finally:
        session.close()


if __name__ == "__main__":
    main()
