"""Demo of the fcsod daemon: ``python -m examples.demo_daemon`` from the repository root.

Makes the secure set-up with ``fcsod pki init`` in ``demo-out/daemon/pki``
(a local CA, the daemon's and the cell controller's certificates, zenoh
configs with mTLS and access control, the message-signing key), starts
``fcsod run`` on a fresh watch folder under ``demo-out/daemon/``, connects
``fcsod subscribe`` with the controller's certificate (the cell controller's
view, every message's signature checked), drops the bundled batch
``examples/jobs/batch-demo`` into the watch folder file by file, shows what
the subscriber receives (each finger set's finger on ``.../design/<set>`` and the
pick plan on ``.../plan``, as the cell gets them), shows that a client without a
certificate is
refused, audits the job's MCAP record and stops the daemon. ``[ros2]`` is
enabled: a zenoh session of the demo with the controller's certificate,
standing in for a ROS 2 cell on rmw_zenoh, lists the ROS 2 key expressions
and liveliness tokens the daemon published (unsigned: rmw_zenoh's format has
no room for a signature; mTLS and the access control cover them) and
decodes the grasps' PoseArrays. The outputs stay in
``demo-out/daemon/out/<job_id>/``.
"""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import zenoh
from rosbags.typesys import Stores, get_typestore

import fcso

REPO = Path(__file__).resolve().parents[1]
BATCH = REPO / "examples" / "jobs" / "batch-demo"
BASE = REPO / "demo-out" / "daemon"
ROS_DOMAIN_ID = 0


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _fcsod(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "fcsod", *args], cwd=REPO, text=True, **kwargs)


def _wait_for_line(stream, text: str, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = stream.readline()
        if text in line:
            return
        if not line:
            time.sleep(0.1)
    raise SystemExit(f"demo: gave up waiting for {text!r}")


def _show(line: str) -> str:
    """One received message, in a few words; returns its topic ("" for liveliness and rejected messages)."""
    message = json.loads(line)
    if "daemon" in message:
        print(f"  daemon liveliness: {message['daemon']}")
        return ""
    if "rejected" in message:
        print(f"  REJECTED {message['key']}: {message['rejected']}")
        return ""
    topic, body = message["topic"], message.get("body") or {}
    if topic == "status":
        extra = body.get("error") or ", ".join(body.get("outputs", []))
        print(f"  {message['key']}: {body['state']}" + (f" ({extra})" if extra else ""))
    elif topic.partition("/")[0] == "verification":
        if body.get("state", "done") != "done":
            print(f"  {message['key']}: verification {body['state']}: {body.get('error')}")
        else:
            rates = ", ".join(
                f"{s['part']} pose {s['pose_index']}: {s['success_rate']:.0%} (flat {s['flat_success_rate']:.0%})"
                for s in body["scenarios"]
            )
            print(f"  {message['key']}: {'passed' if body['passed'] else 'did not pass'}; success {rates}")
    elif topic == "quality":
        print(
            f"  {message['key']}: {fcso.quality_words(body['quality'], body['quality_measure'])}, "
            f"{body['candidates_evaluated']} candidates, pad {body['pad_case']}"
        )
    elif topic == "grasps":
        for grasp in body["grasps"]:
            position = ", ".join(f"{x:.1f}" for x in grasp["position_mm"])
            print(
                f"  {message['key']}: {grasp['part']} pose {grasp['pose_index']} (finger set {grasp['finger_set']}): "
                f"TCP ({position}) mm, close to {grasp['closing_width_mm']:.2f} mm"
            )
    elif topic == "placement":
        fit = "fingers placed" if body["fingers_fit"] else "FINGERS DO NOT FIT"
        print(
            f"  {message['key']}: {fit} ({body['finger_copies_placed']}/{body['finger_copies_requested']}), "
            f"build height {body['build_height_mm']:.1f} mm, density {body['packing_density']:.3f}, {body['file']}"
        )
    elif topic == "design" or topic.startswith("design/"):
        print(
            f"  {message['key']}: {message['bytes']} bytes of STL, sha256 {message['sha256'][:16]}… matches: "
            f"{message['sha256_ok']}, saved {message['saved']}"
        )
    elif topic == "plan":
        reached = "reached" if body["min_retained_reached"] else "NOT reached"
        print(
            f"  {message['key']}: pick plan, {len(body['sets'])} finger set(s), min_retained {body['min_retained']:g} "
            f"{reached}"
        )
        for entry in body["sets"]:
            print(
                f"    mount set {entry['set']}: {entry['finger_key']} (sha256 {entry['finger_sha256'][:16]}…, "
                f"{entry['finger_copies']} copies in build.3mf, "
                f"{fcso.quality_words(entry['quality'], entry['quality_measure'])})"
            )
            for part in entry["parts"]:
                for grasp in part["grasps"]:
                    position = ", ".join(f"{x:.1f}" for x in grasp["position_mm"])
                    print(
                        f"      pick {part['quantity']} x {part['part']} lying in pose {grasp['pose_index']}: TCP "
                        f"({position}) mm, close to {grasp['closing_width_mm']:.2f} mm"
                    )
        for entry in body.get("not_served", []):
            print(f"    not served: {entry['quantity']} x {entry['part']} to {entry['fallback']} ({entry['reason']})")
        if body["ungraspable_parts"]:
            print(f"    not picked (no finger can grasp them): {', '.join(body['ungraspable_parts'])}")
    if (
        "signature_ok" in message
        and message["topic"] == "status"
        and (message.get("body") or {}).get("state") == "queued"
    ):
        print(
            f"  (every message is signed: key {message['attachment']['signature']['key_id']}, checked with the "
            f"daemon's public key, signing.pub)"
        )
    return topic


def _try_without_certificate(config: Path, controller: Path, port: int) -> None:
    """A client with the CA but no certificate of its own tries to listen in: the daemon refuses the TLS link."""
    intruder = BASE / "no-certificate.json5"
    settings = {
        "mode": "client",
        "connect": {"endpoints": [f"tls/127.0.0.1:{port}"]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": {"root_ca_certificate": str(controller / "ca.pem")}}},
    }
    intruder.write_text(json.dumps(settings), encoding="utf-8")
    attempt = subprocess.run(
        [
            sys.executable,
            "-m",
            "fcsod",
            "subscribe",
            "--config",
            str(config),
            "--zenoh-config",
            str(intruder),
            "--verify-key",
            str(controller / "signing.pub"),
            "--timeout",
            "3",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    print(
        f"a client without a certificate: exit code {attempt.returncode}, "
        f"{attempt.stderr.strip().splitlines()[-1][:140]}"
    )


class Ros2Cell:
    """What a ROS 2 cell on rmw_zenoh sees of the daemon: data on ``<domain>/**`` and liveliness tokens under
    ``@ros2_lv/<domain>/**``.
    """

    def __init__(self, zenoh_config: Path):
        self.session = zenoh.open(zenoh.Config.from_file(str(zenoh_config)))
        self.samples: list[tuple[str, bytes]] = []
        self.tokens: list[str] = []
        self._subscriber = self.session.declare_subscriber(
            f"{ROS_DOMAIN_ID}/**", lambda s: self.samples.append((str(s.key_expr), s.payload.to_bytes()))
        )
        self._tokens = self.session.liveliness().declare_subscriber(
            f"@ros2_lv/{ROS_DOMAIN_ID}/**", lambda s: self.tokens.append(str(s.key_expr)), history=True
        )

    def show(self) -> None:
        typestore = get_typestore(Stores.ROS2_JAZZY)
        print(
            "ROS 2 (rmw_zenoh wire format, read over TLS with the controller's certificate through the access control;"
            " unsigned: rmw_zenoh's attachment has no room for a signature)"
        )
        print("liveliness tokens: what `ros2 node list` / `ros2 topic list` read")
        for token in dict.fromkeys(self.tokens):
            print(f"  {token}")
        print("ROS 2 key expressions published (CDR payloads):")
        for key, count in Counter(key for key, _ in self.samples).items():
            print(f"  {key}  ({count} messages)")
        for key, payload in self.samples:
            if "/grasps/" in key:
                message = typestore.deserialize_cdr(payload, "geometry_msgs/msg/PoseArray")
                for pose in message.poses:
                    p, q = pose.position, pose.orientation
                    print(
                        f"  PoseArray in frame {message.header.frame_id}: position ({p.x:.4f}, {p.y:.4f}, {p.z:.4f}) "
                        f"m, "
                        f"orientation xyzw ({q.x:.3f}, {q.y:.3f}, {q.z:.3f}, {q.w:.3f})"
                    )

    def close(self) -> None:
        self.session.close()


#: The tables of deploy/fcsod.toml that name the print server's folders, keys and network: the demo's own.
SITE_TABLES = ("watch", "output", "state", "bus", "zenoh", "ros2")


def _demo_config(port: int) -> str:
    """deploy/fcsod.toml as shipped (repair, reuse, verification, sets judged by truth), with the demo's folders,
    keys and loopback endpoint in place of the print server's."""
    shipped, kept, site = (REPO / "deploy" / "fcsod.toml").read_text(encoding="utf-8").splitlines(), [], False
    for line in shipped:
        if line.startswith("["):
            site = line.strip("[] ") in SITE_TABLES
        if not site:
            kept.append(line)
    return (
        "\n".join(kept)
        + f"""

# the demo's site: folders under demo-out/daemon, the keys of fcsod pki init, zenoh on loopback
[watch]
roots = ["watch"]
settle_seconds = 1.0

[output]
root = "out"

[state]
dir = "state"

[bus]
prefix = "fcso"
cell = "demo"
signing_key = "pki/daemon/signing.key"

[zenoh]
config_file = "pki/daemon/zenoh.json5"
listen = ["tls/127.0.0.1:{port}"]
multicast_scouting = false

[ros2]
enabled = true
domain_id = {ROS_DOMAIN_ID}
namespace = "/demo"
"""
    )


def main() -> int:
    shutil.rmtree(BASE, ignore_errors=True)
    (BASE / "watch").mkdir(parents=True)
    port = _free_port()
    pki = BASE / "pki"
    print(
        f"making the secure set-up: fcsod pki init {pki} --cell demo --client demo-controller --host 127.0.0.1 --port "
        f"{port} --ros2-domain-id {ROS_DOMAIN_ID}"
    )
    subprocess.run(
        [
            sys.executable,
            "-m",
            "fcsod",
            "pki",
            "init",
            str(pki),
            "--cell",
            "demo",
            "--client",
            "demo-controller",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--ros2-domain-id",
            str(ROS_DOMAIN_ID),
        ],
        cwd=REPO,
        check=True,
    )
    controller = pki / "clients" / "demo-controller"
    config = BASE / "fcsod.toml"
    config.write_text(_demo_config(port), encoding="utf-8")
    print(f"\nstarting fcsod (config {config}, zenoh tls/127.0.0.1:{port}, log {BASE / 'daemon.log'})")
    with open(BASE / "daemon.log", "w") as log:
        daemon = _fcsod("run", "--config", str(config), stdout=log, stderr=subprocess.STDOUT)
        try:
            with open(BASE / "daemon.log") as reader:
                _wait_for_line(reader, '"fcsod started"', 120)
            subscriber = _fcsod(
                "subscribe",
                "--config",
                str(config),
                "--save",
                str(BASE / "received"),
                # a guard against a hung daemon, not a speed guess: the demo ends at its verification
                "--timeout",
                "7200",
                "--zenoh-config",
                str(controller / "zenoh.json5"),
                "--verify-key",
                str(controller / "signing.pub"),
                stdout=subprocess.PIPE,
            )
            _wait_for_line(subscriber.stdout, '"alive"', 120)
            ros2_cell = Ros2Cell(controller / "zenoh.json5")
            print("cell controller connected with its certificate; dropping the batch file by file")
            job = BASE / "watch" / BATCH.name
            job.mkdir()
            for path in sorted(BATCH.iterdir()):
                shutil.copy(path, job / path.name)
                print(f"  copied {path.name}")
                time.sleep(0.3)
            print("what the cell controller receives:")
            # verification is on: every finger set's finger is verified (one inside the design step, several
            # after done), one message on .../verification each; the pick plan says how many sets there are
            sets, verifications = None, 0
            for line in subscriber.stdout:
                topic = _show(line)
                sets = len(json.loads(line)["body"]["sets"]) if topic == "plan" else sets
                verifications += topic.partition("/")[0] == "verification"
                if sets is not None and verifications >= sets:
                    break
            subscriber.terminate()
            subscriber.wait()
            time.sleep(0.5)
            ros2_cell.show()
            ros2_cell.close()
            _try_without_certificate(config, controller, port)
        finally:
            daemon.send_signal(signal.SIGTERM)
            daemon.wait(timeout=60)
    results = sorted(p for p in (BASE / "out").iterdir() if p.is_dir())
    for result in results:
        print(f"\naudit of {result / 'job.mcap'}:")
        subprocess.run(
            [sys.executable, "-m", "fcsod", "audit", str(result / "job.mcap"), "--verify", str(result)], cwd=REPO
        )
        print(f"\noutputs to open: {result}")
        for path in sorted(p for p in result.rglob("*") if p.is_file()):
            print(f"  {path.relative_to(result)}  ({path.stat().st_size} bytes)")
    print("job.mcap opens in any MCAP viewer (Foxglove, Lichtblick): the /scene channel shows part, pads and fingers")
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
