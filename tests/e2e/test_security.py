"""The secure bus: mTLS, access control and end-to-end signatures, with real zenoh sessions in separate processes on
loopback.

The daemon (``fcsod run``), the cell controller (``fcsod subscribe``) and the
attackers (``tests/zenoh_probe.py``) are separate processes; the
certificates come from :func:`fcsod.bus.pki.init_pki`.
"""

from __future__ import annotations

import base64
import datetime
import json
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from rosbags.typesys import Stores, get_typestore

import fcsod
from fcsod.bus.pki import add_client, init_pki
from fcsod.bus.signing import generate_signing_key
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import (
    DATA,
    REPO,
    Process,
    drop_job,
    finished,
    free_port,
    start_daemon,
    start_subscriber,
    write_config,
)

CUBE = DATA / "20mm-xyz-cube.stl"
TOPICS = {"status", "quality", "grasps", "design", "plan", "placement"}


def _query_replies(subscriber, job_id: str) -> tuple[set[str], set[str]]:
    """The topics of ``job_id`` whose query replies ``subscriber`` refused (failed verification), and those it
    accepted."""
    replies = [v for v in subscriber.json_lines() if v.get("source") == "query"]
    refused = {v["key"].rsplit("/", 1)[-1] for v in replies if "rejected" in v and f"/{job_id}/" in v["key"]}
    answered = {v["topic"] for v in replies if "rejected" not in v and v.get("job_id") == job_id}
    return refused, answered


FORGED = '{"job_id": "forged", "grasps": [{"closing_width_mm": 0.0}]}'
ROS2_DOMAIN = 7
ROS2 = f'[ros2]\nenabled = true\ndomain_id = {ROS2_DOMAIN}\nnamespace = "/cell1"\n'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def probe(config: Path, *args: str, timeout: float = HANG_GUARD_S) -> list[dict]:
    """Run ``tests/zenoh_probe.py`` to its end; its JSON lines."""
    done = subprocess.run(
        [sys.executable, "-m", "tests.zenoh_probe", "--config", str(config), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]


def start_probe(config: Path, *args: str) -> tuple[subprocess.Popen, list[dict]]:
    """Start ``tests/zenoh_probe.py --hold`` in the background.

    Returns it once every action is done, with its lines so far.
    """
    process = subprocess.Popen(
        [sys.executable, "-m", "tests.zenoh_probe", "--config", str(config), *args, "--hold"],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    lines = []
    while not lines or lines[-1]["event"] != "ready":
        line = process.stdout.readline()
        assert line, f"the probe ended early: {lines}"
        lines.append(json.loads(line))
    assert lines[0]["event"] == "open"
    return process, lines


def probe_output(probe: tuple[subprocess.Popen, list[dict]]) -> list[dict]:
    """Every line of a background probe, after closing its standard input (which ends it)."""
    process, lines = probe
    out, _ = process.communicate(timeout=HANG_GUARD_S)
    return lines + [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def client_args(pki: Path, name: str) -> list[str]:
    folder = pki / "clients" / name
    return ["--zenoh-config", str(folder / "zenoh.json5"), "--verify-key", str(folder / "signing.pub")]


def _ros2_cell(pki: Path, name: str, late: str | None = None) -> Process:
    """``tests/ros2_cell.py`` (a ROS 2 cell on rmw_zenoh) with the zenoh config and certificate of client ``name``."""
    args = [
        "--zenoh-config",
        str(pki / "clients" / name / "zenoh.json5"),
        "--domain",
        str(ROS2_DOMAIN),
        *(["--late", late] if late else []),
    ]
    cell = Process(args, module="tests.ros2_cell")
    cell.wait_for(lambda v: isinstance(v, dict) and v.get("event") == "ready")
    return cell


def _cell(base: Path, acl: bool) -> dict:
    """A daemon on TLS with the PKI of ``init_pki`` (access control on or off) and ``[ros2]`` enabled, a subscriber
    ``ctl1``, ROS 2 cells with the certificates of ``ctl1`` and of ``outsider`` (of the CA, not in the access
    control) and one finished job."""
    port = free_port()
    pki = base / "pki"
    files = init_pki(
        pki, "test", ["ctl1", "ctl2"], hosts=["127.0.0.1", "localhost"], port=port, acl=acl, ros2_domain_id=ROS2_DOMAIN
    )
    add_client(pki, "outsider", [f"tls/127.0.0.1:{port}"])
    config = write_config(
        base,
        port,
        scheme="tls",
        zenoh_extra=f'config_file = "{files.daemon_zenoh_config}"',
        bus_extra=f'signing_key = "{files.signing_key}"',
        extra=ROS2,
    )
    daemon = start_daemon(config)
    subscriber = start_subscriber(config, save=base / "received", extra=client_args(pki, "ctl1"))
    ros2_cells = {name: _ros2_cell(pki, name) for name in ("ctl1", "outsider")}
    drop_job(base / "watch" / "cube", {"cube.stl": CUBE})
    done = finished(subscriber, "cube")
    assert done["body"]["state"] == "done", done
    return {
        "base": base,
        "port": port,
        "pki": pki,
        "config": config,
        "daemon": daemon,
        "subscriber": subscriber,
        "ros2_cells": ros2_cells,
        "job_id": done["job_id"],
    }


def _stop(cell: dict) -> None:
    for process in (cell["subscriber"], *cell["ros2_cells"].values()):
        process.stop()
    assert cell["daemon"].stop() == 0


@pytest.fixture(scope="module")
def secure(tmp_path_factory):
    """The default set-up: mTLS and access control; ``outsider`` holds a certificate of the same CA but is not in the
    ACL.
    """
    cell = _cell(tmp_path_factory.mktemp("secure"), acl=True)
    yield cell
    _stop(cell)


def _lines(cell: dict, job_id: str) -> list[dict]:
    return [v for v in cell["subscriber"].json_lines() if v.get("job_id") == job_id]


def test_client_with_a_valid_certificate_receives_every_topic_signed(secure):
    lines = [v for v in _lines(secure, secure["job_id"]) if v["source"] == "live"]
    assert TOPICS <= {v["topic"] for v in lines}
    assert all(v["signature_ok"] for v in lines)
    design = next(v for v in lines if v["topic"] == "design")
    assert (
        design["sha256_ok"] is True
        and Path(design["saved"]).read_bytes()
        == (secure["base"] / "out" / secure["job_id"] / "finger.stl").read_bytes()
    )
    grasps = next(v for v in lines if v["topic"] == "grasps")["body"]["grasps"]
    assert grasps and grasps[0]["closing_width_mm"] > 0
    assert not [v for v in secure["subscriber"].json_lines() if "rejected" in v]
    daemon = secure["daemon"].json_lines()
    assert not [v for v in daemon if "insecure bus" in str(v.get("message"))], "the secure set-up must not warn"


def _ros2_samples(cell: Process, topic: str) -> list[dict]:
    return [
        v
        for v in cell.json_lines()
        if v.get("event") == "sample" and v["source"] == "ros2" and f"/fcsod/{topic}/" in v["key_expr"]
    ]


def test_ros2_topics_pass_the_access_control_unsigned_to_listed_clients_only(secure):
    """With ``pki init --ros2-domain-id`` a listed certificate gets the ROS 2 data and tokens; rmw_zenoh's attachment
    has no signature.
    """
    listed, outsider = secure["ros2_cells"]["ctl1"], secure["ros2_cells"]["outsider"]
    status = listed.wait_for(lambda v: isinstance(v, dict) and '"done"' in _cdr_string(v, "/fcsod/status/"))
    assert status["key_expr"].startswith(f"{ROS2_DOMAIN}/cell1/fcsod/status/std_msgs::msg::dds_::String_/RIHS01_")
    assert len(bytes.fromhex(status["attachment"])) == 8 + 8 + 1 + 16, (
        "rmw_zenoh's attachment: sequence number, timestamp, GID"
    )
    native = next(v for v in _lines(secure, secure["job_id"]) if v["source"] == "live" and v["topic"] == "grasps")
    poses = [
        TYPESTORE.deserialize_cdr(bytes.fromhex(v["payload"]), "geometry_msgs/msg/PoseArray")
        for v in _ros2_samples(listed, "grasps")
    ]
    assert [p.header.frame_id for p in poses] == [
        f"fcso_{g['part']}_rest{g['pose_index']}" for g in native["body"]["grasps"]
    ]
    tokens = {v["key_expr"] for v in listed.json_lines() if v.get("event") == "token"}
    assert any(t.startswith(f"@ros2_lv/{ROS2_DOMAIN}/") and "/0/0/NN/%/%cell1/fcsod" in t for t in tokens), tokens
    # a publisher per topic: status, grasps, grasp_details, quality, plan, placement, verification
    assert len([t for t in tokens if "/MP/" in t]) == 7, tokens
    seen_by_outsider = [v for v in outsider.json_lines() if v.get("event") in ("sample", "token")]
    assert seen_by_outsider == [], "a certificate outside the access control read ROS 2 data or tokens"


def test_a_late_transient_local_ros2_subscriber_gets_the_last_job_through_the_access_control(secure):
    """rmw_zenoh's transient-local subscription queries the AdvancedPublisher's cache: that passes the access control
    too.
    """
    (key,) = {v["key_expr"] for v in _ros2_samples(secure["ros2_cells"]["ctl1"], "grasps")}
    late = _ros2_cell(secure["pki"], "ctl2", late=key)
    try:
        value = late.wait_for(lambda v: isinstance(v, dict) and v.get("event") == "sample")
    finally:
        late.stop()
    assert value["source"] == "history" and value["key_expr"] == key


def _cdr_string(value, key_part: str) -> str:
    """The text of a std_msgs/String sample of a ROS 2 cell line on a key containing ``key_part``; "" for any other
    line.
    """
    if not (
        isinstance(value, dict)
        and value.get("event") == "sample"
        and value["source"] == "ros2"
        and key_part in value["key_expr"]
    ):
        return ""
    return TYPESTORE.deserialize_cdr(bytes.fromhex(value["payload"]), "std_msgs/msg/String").data


def _expire(folder: Path, ca_dir: Path) -> None:
    """Re-issue the certificate in ``folder`` (same subject and key) valid from 10 days ago to yesterday."""
    ca = x509.load_pem_x509_certificate((ca_dir / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((ca_dir / "ca.key").read_bytes(), password=None)
    current = x509.load_pem_x509_certificate((folder / "cert.pem").read_bytes())
    now = datetime.datetime.now(datetime.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(current.subject)
        .issuer_name(ca.subject)
        .public_key(current.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=10))
        .not_valid_after(now - datetime.timedelta(days=1))
    )
    for extension in current.extensions:
        builder = builder.add_extension(extension.value, extension.critical)
    (folder / "cert.pem").write_bytes(builder.sign(ca_key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM))


@pytest.mark.parametrize("client", ["no-certificate", "other-ca", "plain-tcp", "expired"])
def test_clients_without_a_certificate_of_the_ca_cannot_connect(secure, client):
    folder = secure["pki"] / "clients" / "ctl1"
    config = json.loads((folder / "zenoh.json5").read_text().split("\n", 2)[2])
    tls = config["transport"]["link"]["tls"]
    if client == "no-certificate":
        del tls["connect_certificate"], tls["connect_private_key"]
        tls["enable_mtls"] = False
    elif client == "other-ca":
        other = init_pki(secure["base"] / "other-ca", "test", ["ctl1"], hosts=["127.0.0.1"], port=secure["port"])
        config = json.loads((other.clients["ctl1"] / "zenoh.json5").read_text().split("\n", 2)[2])
    elif client == "plain-tcp":
        config = {
            "mode": "client",
            "connect": {"endpoints": [f"tcp/127.0.0.1:{secure['port']}"]},
            "scouting": {"multicast": {"enabled": False}},
        }
    else:
        # ctl2 is in the access control: only the expiry can keep it out
        expired = secure["base"] / "ctl2-expired"
        shutil.copytree(secure["pki"] / "clients" / "ctl2", expired)
        _expire(expired, secure["pki"] / "ca")
        text = (
            (expired / "zenoh.json5")
            .read_text()
            .replace(str((secure["pki"] / "clients" / "ctl2").resolve()), str(expired.resolve()))
        )
        config = json.loads(text.split("\n", 2)[2])
    path = secure["base"] / f"{client}.json5"
    path.write_text(json.dumps(config))
    attempt = Process(
        [
            "subscribe",
            "--config",
            str(secure["config"]),
            "--zenoh-config",
            str(path),
            "--verify-key",
            str(folder / "signing.pub"),
            "--timeout",
            "5",
        ]
    )
    assert attempt.popen.wait(timeout=HANG_GUARD_S) == 2
    attempt.stop()
    assert any("zenoh session cannot open" in line for line in attempt.lines), attempt.lines
    assert not [line for line in attempt.lines if '"topic"' in line]


def test_forged_publish_and_queryable_are_denied_by_access_control(secure):
    """ctl2 holds a valid certificate and publishes forged grasps under the daemon's keys; ctl1 never sees a byte of
    them.
    """
    pki, job_id = secure["pki"], secure["job_id"]
    key = f"fcso/test/jobs/{job_id}/grasps"
    watcher = start_probe(pki / "clients" / "ctl1" / "zenoh.json5", "--subscribe", "fcso/test/jobs/**")
    # returns once its 30 forged puts (paced 50 ms apart) are sent: its queryable and token were declared before them
    forging = start_probe(
        pki / "clients" / "ctl2" / "zenoh.json5",
        "--put",
        key,
        "--payload",
        FORGED,
        "--count",
        "30",
        "--queryable",
        "fcso/test/jobs/**",
        "--token",
        "fcso/test/daemon",
    )
    # ctl1 asks while ctl2's queryable is declared: only the daemon answers
    replies = [
        e
        for e in probe(pki / "clients" / "ctl1" / "zenoh.json5", "--query", "fcso/test/jobs/**")
        if e["event"] == "reply"
    ]
    forger = probe_output(forging)
    assert [e["event"] for e in forger][1:2] == ["put"], forger
    # a job published while the raw watcher listens shows that it receives what passes the daemon
    drop_job(secure["base"] / "watch" / "after-forgery", {"cube.stl": DATA / "capsela200_plug.stl"})
    finished(secure["subscriber"], "after-forgery")
    seen = probe_output(watcher)

    received = [e for e in seen if e["event"] == "received"]
    assert any(e["key"].endswith("/status") for e in received), "the watcher received nothing at all"
    assert not [e for e in received if "forged" in e["payload"]], "a forged publication passed the access control"
    assert not [e for e in forger if e["event"] == "queried_by"], "a client's queryable was reached through the daemon"
    assert {r["key"].rsplit("/", 1)[-1] for r in replies if job_id in r["key"]} == TOPICS
    public_key = fcsod.load_verify_key(pki / "daemon" / "signing.pub")
    for reply in replies:
        fcsod.verify_message(
            reply["key"], base64.b64decode(reply["payload_base64"]), reply["attachment"].encode(), public_key
        )
    assert not [
        v for v in secure["subscriber"].json_lines() if "rejected" in v or "forged" in json.dumps(v.get("body"))
    ]


def test_queryable_and_liveliness_refuse_clients_outside_the_acl(secure):
    outsider = probe(
        secure["pki"] / "clients" / "outsider" / "zenoh.json5",
        "--liveliness",
        "fcso/test/daemon",
        "--query",
        "fcso/test/jobs/**",
    )
    named = probe(
        secure["pki"] / "clients" / "ctl2" / "zenoh.json5",
        "--liveliness",
        "fcso/test/daemon",
        "--query",
        "fcso/test/jobs/**",
    )
    assert outsider[0]["event"] == "open", "a certificate of the CA opens the TLS link"
    assert next(e for e in outsider if e["event"] == "liveliness")["holders"] == []
    assert not [e for e in outsider if e["event"] == "reply"]
    assert next(e for e in named if e["event"] == "liveliness")["holders"] == ["fcso/test/daemon"]
    assert len([e for e in named if e["event"] == "reply"]) >= len(TOPICS)


def test_verify_message_rejects_altered_unsigned_and_foreign_messages(secure, tmp_path):
    replies = [
        e
        for e in probe(
            secure["pki"] / "clients" / "ctl2" / "zenoh.json5", "--query", f"fcso/test/jobs/{secure['job_id']}/*"
        )
        if e["event"] == "reply"
    ]
    public_key = fcsod.load_verify_key(secure["pki"] / "clients" / "ctl2" / "signing.pub")
    grasps = next(r for r in replies if r["key"].endswith("/grasps"))
    key, payload, attachment = grasps["key"], base64.b64decode(grasps["payload_base64"]), grasps["attachment"].encode()
    assert fcsod.verify_message(key, payload, attachment, public_key)["job_id"] == secure["job_id"]
    status = next(r for r in replies if r["key"].endswith("/status"))
    attacker = generate_signing_key(tmp_path / "attacker.key")
    forged = {
        "payload changed": (key, FORGED.encode(), attachment),
        "key changed": (status["key"], payload, attachment),
        "unsigned": (key, payload, None),
        "no signature": (key, payload, json.dumps({"job_id": secure["job_id"]}).encode()),
        "other key": (key, payload, attacker.attachment(key, secure["job_id"], payload, None)),
    }
    for what, (k, p, a) in forged.items():
        with pytest.raises(fcsod.SignatureError):
            fcsod.verify_message(k, p, a, public_key)
            pytest.fail(what)


def test_without_access_control_forged_messages_fail_signature_verification(tmp_path):
    """With the ACL off the forgeries reach the cell controller, and fcsod subscribe rejects every one."""
    cell = _cell(tmp_path, acl=False)
    try:
        pki, job_id = cell["pki"], cell["job_id"]
        warnings = [v["message"] for v in cell["daemon"].json_lines() if v.get("level") == "warning"]
        assert any("access control is off" in w for w in warnings), warnings
        real = {v["topic"]: v for v in _lines(cell, job_id) if v["source"] == "live"}
        key = f"fcso/test/jobs/{job_id}/grasps"
        attacker = generate_signing_key(tmp_path / "attacker.key")
        real_grasps = json.dumps(real["grasps"]["body"])
        attempts = {
            "unsigned": [],
            "stolen signature": ["--attachment", json.dumps(real["grasps"]["attachment"])],
            "signature of another key expression": ["--attachment", json.dumps({**real["status"]["attachment"]})],
            "attacker's key": ["--attachment", attacker.attachment(key, job_id, FORGED.encode(), None).decode()],
        }
        for what, extra in attempts.items():
            payload = real_grasps if what == "signature of another key expression" else FORGED
            # every forgery must reach the subscriber for the count below: each probe waits until it matches
            lines = probe(
                pki / "clients" / "ctl2" / "zenoh.json5",
                "--put",
                key,
                "--payload",
                payload,
                "--count",
                "3",
                "--await-subscriber",
                *extra,
            )
            assert [e["event"] for e in lines][:2] == ["open", "put"], (what, lines)
        rejected = cell["subscriber"].wait_for(
            lambda v: isinstance(v, dict) and len([w for w in cell["subscriber"].json_lines() if "rejected" in w]) >= 12
        )
        assert rejected

        # messages are signed once, when published: what is changed on disk afterwards fails verification in a late
        # joiner
        finger = cell["base"] / "out" / job_id / "finger.stl"
        finger.write_bytes(finger.read_bytes()[:-50] + bytes(50))
        with sqlite3.connect(cell["base"] / "state" / "journal.sqlite3") as db:
            db.execute(
                "UPDATE messages SET payload = ? WHERE job_id = ? AND topic = 'grasps'", (FORGED.encode(), job_id)
            )
        late = start_subscriber(cell["config"], extra=[*client_args(pki, "ctl1")])
        # every topic's query reply, accepted or refused, in whatever order they arrive
        late.wait_for(lambda v: set().union(*_query_replies(late, job_id)) >= TOPICS)
        late.stop()
    finally:
        _stop(cell)
    reasons = [v["rejected"] for v in cell["subscriber"].json_lines() if "rejected" in v]
    assert (
        any("unsigned" in r for r in reasons)
        and any("bad signature" in r for r in reasons)
        and any("signed by key" in r for r in reasons)
    ), reasons
    accepted = [v for v in cell["subscriber"].json_lines() if v.get("topic") == "grasps" and v.get("job_id") == job_id]
    assert accepted and all(v["body"] == real["grasps"]["body"] for v in accepted), (
        "a forged grasps message was accepted"
    )
    refused, answered = _query_replies(late, job_id)
    assert refused == {"design", "grasps"} and answered == TOPICS - refused, (refused, answered)
