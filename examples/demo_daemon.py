"""Demo of the fcsod daemon: ``python -m examples.demo_daemon`` from the repository root.

Starts ``fcsod run`` on a fresh watch folder under ``demo-out/daemon/``,
connects ``fcsod subscribe`` (the cell controller's view), drops the bundled
batch ``examples/jobs/batch-demo`` into the watch folder file by file, shows
what the subscriber receives, audits the job's MCAP record and stops the
daemon. The outputs stay in ``demo-out/daemon/out/<job_id>/``.
"""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BATCH = REPO / "examples" / "jobs" / "batch-demo"
BASE = REPO / "demo-out" / "daemon"


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


def _show(line: str) -> None:
    """One received message, in a few words."""
    message = json.loads(line)
    if "daemon" in message:
        print(f"  daemon liveliness: {message['daemon']}")
        return
    topic, body = message["topic"], message.get("body") or {}
    if topic == "status":
        extra = body.get("error") or ", ".join(body.get("outputs", []))
        print(f"  {message['key']}: {body['state']}" + (f" ({extra})" if extra else ""))
    elif topic == "quality":
        print(f"  {message['key']}: Q = {body['quality_mm2']:.2f} mm², {body['candidates_evaluated']} candidates, pad {body['pad_case']}")
    elif topic == "grasps":
        for grasp in body["grasps"]:
            position = ", ".join(f"{x:.1f}" for x in grasp["position_mm"])
            print(f"  {message['key']}: {grasp['part']} pose {grasp['pose_index']}: TCP ({position}) mm, close to {grasp['closing_width_mm']:.2f} mm")
    elif topic == "placement":
        fit = "fingers placed" if body["fingers_fit"] else "FINGERS DO NOT FIT"
        print(f"  {message['key']}: {fit} ({body['finger_copies_placed']}/{body['finger_copies_requested']}), "
              f"build height {body['build_height_mm']:.1f} mm, density {body['packing_density']:.3f}, {body['file']}")
    elif topic == "design":
        print(f"  {message['key']}: {message['bytes']} bytes of STL, sha256 {message['sha256'][:16]}… matches: {message['sha256_ok']}, saved {message['saved']}")


def main() -> int:
    shutil.rmtree(BASE, ignore_errors=True)
    (BASE / "watch").mkdir(parents=True)
    port = _free_port()
    config = BASE / "fcsod.toml"
    config.write_text(
        f"""[watch]
roots = ["watch"]
settle_seconds = 1.0

[output]
root = "out"

[state]
dir = "state"

[bus]
prefix = "fcso"
cell = "demo"

[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
""",
        encoding="utf-8",
    )
    print(f"starting fcsod (config {config}, zenoh tcp/127.0.0.1:{port}, log {BASE / 'daemon.log'})")
    with open(BASE / "daemon.log", "w") as log:
        daemon = _fcsod("run", "--config", str(config), stdout=log, stderr=subprocess.STDOUT)
        try:
            with open(BASE / "daemon.log") as reader:
                _wait_for_line(reader, '"fcsod started"', 120)
            subscriber = _fcsod(
                "subscribe", "--config", str(config), "--save", str(BASE / "received"), "--exit-after", "1", "--timeout", "600",
                stdout=subprocess.PIPE,
            )
            _wait_for_line(subscriber.stdout, '"alive"', 120)
            print("subscriber connected; dropping the batch file by file")
            job = BASE / "watch" / BATCH.name
            job.mkdir()
            for path in sorted(BATCH.iterdir()):
                shutil.copy(path, job / path.name)
                print(f"  copied {path.name}")
                time.sleep(0.3)
            print("what the cell controller receives:")
            for line in subscriber.stdout:
                _show(line)
            subscriber.wait()
        finally:
            daemon.send_signal(signal.SIGTERM)
            daemon.wait(timeout=60)
    results = sorted(p for p in (BASE / "out").iterdir() if p.is_dir())
    for result in results:
        print(f"\naudit of {result / 'job.mcap'}:")
        subprocess.run([sys.executable, "-m", "fcsod", "audit", str(result / "job.mcap"), "--verify", str(result)], cwd=REPO)
        print(f"\noutputs to open: {result}")
        for path in sorted(result.iterdir()):
            print(f"  {path.name}  ({path.stat().st_size} bytes)")
    print("job.mcap opens in any MCAP viewer (Foxglove, Lichtblick): the /scene channel shows part, pads and fingers")
    return 0 if results else 1


if __name__ == "__main__":
    sys.exit(main())
