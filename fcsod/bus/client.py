"""A small cell-controller client (``fcsod subscribe``): print every message the daemon publishes, checked.

Written to be read, like zenoh-python's ``examples/z_sub.py``: open a session,
declare a subscriber on ``<prefix>/<cell>/jobs/**`` and a liveliness
subscriber on the daemon's token, and each time the daemon appears ask it
(``session.get``) for what it published while this client was away. Every
sample's signature is checked before it is shown; a forged or altered one is
printed as rejected, never as a result. One JSON object per line on stdout.
"""

from __future__ import annotations

import hashlib
import json
import re
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from ..config import DaemonConfig, ZenohConfig
from .messages import ENCODING_JSON, daemon_key, jobs_key
from .signing import SignatureError, verify_message


def subscriber_endpoints(config: DaemonConfig, override: list[str] | None) -> list[str]:
    """Where the subscriber connects: the override, the config's connect endpoints, or its listen endpoints on this
    host.
    """
    if override:
        return override
    if config.zenoh.connect:
        return config.zenoh.connect
    return [re.sub(r"/(0\.0\.0\.0|\[::\]):", "/127.0.0.1:", e) for e in config.zenoh.listen or []]


def sample_line(sample: zenoh.Sample, source: str, jobs_prefix: str, verify_key: Ed25519PublicKey) -> dict:
    """One received sample as the JSON line the client prints: its job, topic, body or hash, and its checks.

    ``source`` says how it arrived: ``live`` or ``query``. A sample whose
    signature does not verify gives ``{"source", "key", "rejected"}`` only.
    """
    key = str(sample.key_expr)
    payload = sample.payload.to_bytes()
    attachment_bytes = sample.attachment.to_bytes() if sample.attachment is not None else None
    try:
        attachment = verify_message(key, payload, attachment_bytes, verify_key)
    except SignatureError as exc:
        return {"source": source, "key": key, "rejected": str(exc)}
    # <prefix>/<cell>/jobs/<job_id>/<topic>, where a finger set's design is the topic design/<set>
    job_id, _, topic = (
        key.removeprefix(jobs_prefix).partition("/")
        if key.startswith(jobs_prefix)
        else (None, "", key.rsplit("/", 1)[-1])
    )
    line: dict = {"source": source, "key": key, "topic": topic, "encoding": str(sample.encoding), "bytes": len(payload)}
    line["job_id"] = job_id
    if str(sample.encoding).startswith(ENCODING_JSON):
        line["body"] = json.loads(payload)
    else:
        line["sha256"] = hashlib.sha256(payload).hexdigest()
    line["attachment"] = attachment
    line["signature_ok"] = True
    if "sha256" in attachment:
        line["sha256_ok"] = attachment["sha256"] == line.get("sha256")
    return line


def save_design(line: dict, payload: bytes, folder: Path) -> None:
    """Write a received design's STL as ``<job_id>.stl`` (one set) or ``<job_id>-set-<k>.stl``, and say where."""
    folder.mkdir(parents=True, exist_ok=True)
    topic = line["topic"]
    name = f"{line['job_id']}.stl" if topic == "design" else f"{line['job_id']}-set-{topic.partition('/')[2]}.stl"
    target = folder / name
    target.write_bytes(payload)
    line["saved"] = str(target)


@dataclass
class Enough:
    """When the client has seen enough: N jobs finished (done or failed), N verification messages, or neither."""

    finished_jobs: int | None = None
    verifications: int | None = None
    finished: set[str] = field(default_factory=set)
    verified: set[tuple[str, str]] = field(default_factory=set)

    @property
    def bounded(self) -> bool:
        """The client stops on a count (rather than on a timeout or Ctrl-C)."""
        return self.finished_jobs is not None or self.verifications is not None

    def seen(self, line: dict) -> bool:
        """Count one printed line; True once either count is reached."""
        body = line.get("body") or {}
        topic = line.get("topic", "")
        reached = False
        if topic == "status" and body.get("state") in ("done", "failed"):
            self.finished.add(line["job_id"])
            reached |= self.finished_jobs is not None and len(self.finished) >= self.finished_jobs
        if topic.partition("/")[0] == "verification":
            self.verified.add((line["job_id"], topic))
            reached |= self.verifications is not None and len(self.verified) >= self.verifications
        return reached


def subscribe(
    session: zenoh.Session,
    prefix: str,
    cell: str,
    verify_key: Ed25519PublicKey,
    enough: Enough,
    *,
    save: Path | None = None,
    query: bool = True,
    timeout_seconds: float | None = None,
) -> bool:
    """Print the daemon's messages until ``enough`` is reached, the timeout passes or Ctrl-C; True if enough was.

    Parameters
    ----------
    session : zenoh.Session
        Open, connected towards the daemon; the caller closes it.
    prefix, cell : str
        The daemon's ``[bus]`` key prefix and cell.
    verify_key : Ed25519PublicKey
        The daemon's public key: every sample is checked against it.
    enough : Enough
        When to stop.
    save : Path, optional
        Folder for the received designs' STL files.
    query : bool
        Ask the daemon for its earlier messages at start and whenever it reappears.
    timeout_seconds : float, optional
        Stop after this long.
    """
    jobs_prefix = f"{prefix}/{cell}/jobs/"
    lock = threading.Lock()  # zenoh calls back on its own threads: one line at a time
    all_done = threading.Event()
    ask = threading.Event()

    def show(sample: zenoh.Sample, source: str) -> None:
        line = sample_line(sample, source, jobs_prefix, verify_key)
        if save is not None and "rejected" not in line and line["topic"].partition("/")[0] == "design":
            save_design(line, sample.payload.to_bytes(), save)
        with lock:
            print(json.dumps(line), flush=True)
            if "rejected" not in line and enough.seen(line):
                all_done.set()

    def liveliness(sample: zenoh.Sample) -> None:
        # every time the daemon appears (at start, or after it or the network was down) ask it for what was missed
        state = "alive" if sample.kind == zenoh.SampleKind.PUT else "gone"
        with lock:
            print(json.dumps({"source": "liveliness", "key": str(sample.key_expr), "daemon": state}), flush=True)
        if state == "alive" and query:
            ask.set()

    deadline = time.monotonic() + timeout_seconds if timeout_seconds is not None else None
    try:
        subscriber = session.declare_subscriber(jobs_key(prefix, cell), lambda s: show(s, "live"))
        watcher = session.liveliness().declare_subscriber(daemon_key(prefix, cell), liveliness, history=True)
        while not all_done.is_set() and (deadline is None or time.monotonic() < deadline):
            if ask.is_set():
                ask.clear()
                for reply in session.get(jobs_key(prefix, cell), timeout=5.0):
                    if reply.ok is not None:
                        show(reply.ok, "query")
            all_done.wait(timeout=0.2)
        subscriber.undeclare()
        watcher.undeclare()
    except KeyboardInterrupt:
        pass
    return all_done.is_set()


def nothing_listens(endpoints: list[str] | None) -> bool:
    """Whether no socket accepts a connection at any of zenoh ``endpoints`` (``proto/host:port``).

    A session that cannot open because nothing listens yet is worth waiting for; one refused by a listener (TLS
    without a certificate of its CA, an expired one, plain TCP to a TLS port) is not. False when the endpoints are
    not known (they are in a zenoh configuration file).
    """
    if not endpoints:
        return False
    for endpoint in endpoints:
        address = endpoint.split("/", 1)[-1].split("#", 1)[0]
        host, _, port = address.rpartition(":")
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=2.0):
                return False
        except (OSError, ValueError):
            continue
    return True


def configured_endpoints(settings: ZenohConfig) -> list[str] | None:
    """The ``connect`` endpoints of a zenoh configuration file (``[zenoh] config_file`` or ``--zenoh-config``), None
    without a file or when it names none."""
    if settings.config_file is None:
        return None
    try:
        endpoints = json.loads(zenoh.Config.from_file(str(settings.config_file)).get_json("connect/endpoints"))
    except (zenoh.ZError, ValueError):
        return None
    return [str(e) for e in endpoints] or None
