"""Helpers of the fcsod tests: free ports, configs, daemon and subscriber subprocesses, slow job drops."""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from tests.conftest import HANG_GUARD_S

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"

#: The tiny fcso settings that design the test cube in well under a second.
FAST_DESIGN = """
[design.sampler]
length_mm = 10
width_mm = 10
thickness_mm = 4
penetration_mm = 3
stride_mm = 5

[design.poses]
count = 1
select = "most_probable"
"""


#: fcso settings under which one solar tracker's design runs for many minutes: a
#: 0.25 mm sampling step over six yaw angles in six poses, 400 surface samples
#: per mm² (``fcso design solar_tracker.stl`` with them had not finished after
#: 20 minutes on the 2-core development machine). A machine ten times faster
#: still takes minutes, far over the 1 s time limit the tests set, so tests that
#: must catch a job while it runs use these settings instead of hoping that a
#: quick job is still running.
SLOW_SECTIONS = {
    "sampler": "stride_mm = 0.25\nyaw_deg = [0, 30, 60, 90, 120, 150]",
    "poses": 'count = 6\nselect = "most_probable"',
    "contact": "sample_density_per_mm2 = 400",
}
SLOW_DESIGN = "\n".join(f"[design.{name}]\n{body}\n" for name, body in SLOW_SECTIONS.items())


#: The daemon's ``[verify]`` of every test that does not verify: verification is on by default.
VERIFY_OFF = "enabled = false\ntop_k = 0"

#: A ``[verify]`` under which verifying one design runs for hours whatever the machine: a million precision
#: trials, each a simulated grasp of thousands of physics steps. Tests that must catch a verification while it
#: runs use it instead of hoping that a quick one is still running.
SLOW_VERIFY = "enabled = true\ntop_k = 0\ntrials = 1000000"


def slow_manifest(part_file: str) -> str:
    """A job.toml of one part designed with :data:`SLOW_SECTIONS`."""
    return f'[[parts]]\nfile = "{part_file}"\n\n' + "\n".join(
        f"[{name}]\n{body}\n" for name, body in SLOW_SECTIONS.items()
    )


def without_design_notes(warnings: list[str]) -> list[str]:
    """``warnings`` but the design's notes on its pad: flat pads capture a scenario as well (METHOD §7b; plain
    cubes get them) or a pad section is thinner than ``T - D - clearance`` (a pad centred on a part's end).

    For tests of what follows the design (placement, the build), which those notes do not concern.
    """
    return [
        w for w in warnings if "no pad captures it better than flat pads" not in w and "thinnest pad section" not in w
    ]


def free_port() -> int:
    """A TCP port on loopback that nothing listens on now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def write_config(
    base: Path,
    port: int,
    settle_seconds: float = 0.7,
    extra: str = "",
    scheme: str = "tcp",
    zenoh_extra: str = "",
    bus_extra: str = "",
    design: str = FAST_DESIGN,
    reuse: bool = False,
    verify: str = VERIFY_OFF,
) -> Path:
    """Write an fcsod.toml for a daemon listening on ``<scheme>/127.0.0.1:<port>`` with folders below ``base``.

    ``zenoh_extra`` and ``bus_extra`` are lines added to the ``[zenoh]`` and ``[bus]`` sections;
    ``design`` the daemon's ``[design.*]`` sections (:data:`FAST_DESIGN` or :data:`SLOW_DESIGN`);
    ``reuse`` keeps finger reuse on (the daemon's default); off, tests that
    drop the same part twice see it designed twice;
    ``verify`` the body of its ``[verify]`` (off unless a test verifies: it is on by default).

    Returns
    -------
    Path
        The config file; watch root ``base/watch``, outputs ``base/out``, state ``base/state``.
    """
    (base / "watch").mkdir(parents=True, exist_ok=True)
    path = base / "fcsod.toml"
    path.write_text(
        f"""
[watch]
roots = ["watch"]
settle_seconds = {settle_seconds}
rescan_seconds = 5

[output]
root = "out"

[state]
dir = "state"

[bus]
prefix = "fcso"
cell = "test"
{bus_extra}

[zenoh]
listen = ["{scheme}/127.0.0.1:{port}"]
multicast_scouting = false
{zenoh_extra}

[mcap]
chunk_size_bytes = 4096

[reuse]
enabled = {str(reuse).lower()}

[verify]
{verify}
{extra}
{design}
""",
        encoding="utf-8",
    )
    return path


class Process:
    """A subprocess whose stdout lines are collected by a thread.

    Parameters
    ----------
    args : list of str
        Arguments after ``python -m <module>``.
    env : dict, optional
        Extra environment variables.
    module : str
        The module to run (``fcsod``, or a test helper such as ``tests.ros2_cell``).
    program : list of str, optional
        The program to run instead of ``python -m <module>`` (such as ``["node", "script.js"]``).
    """

    def __init__(
        self, args: list[str], env: dict | None = None, module: str = "fcsod", program: list[str] | None = None
    ):
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        self.popen = subprocess.Popen(
            [*(program or [sys.executable, "-m", module]), *args],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, **(env or {})},
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))
            self._queue.put(line)

    def wait_for(self, predicate, timeout: float = HANG_GUARD_S) -> dict | str:
        """The first line (parsed JSON if it is) for which ``predicate`` is true; AssertionError after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        seen = 0
        while time.monotonic() < deadline:
            while seen < len(self.lines):
                line = self.lines[seen]
                seen += 1
                value = _parse(line)
                if predicate(value):
                    return value
            if self.popen.poll() is not None and seen >= len(self.lines):
                time.sleep(0.2)
                if seen >= len(self.lines):
                    break
            time.sleep(0.05)
        raise AssertionError(f"no matching line within {timeout} s; output:\n" + "\n".join(self.lines[-60:]))

    def json_lines(self) -> list[dict]:
        return [v for v in map(_parse, self.lines) if isinstance(v, dict)]

    def stop(self, sig: int = signal.SIGTERM, timeout: float = HANG_GUARD_S) -> int:
        """Send ``sig``, wait, kill if needed; returns the exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(timeout=10)
        self._reader.join(timeout=5)
        return self.popen.returncode


def _parse(line: str):
    try:
        return json.loads(line)
    except ValueError:
        return line


def start_daemon(config: Path, env: dict | None = None) -> Process:
    """Start ``fcsod run`` and wait until it logged its start."""
    daemon = Process(["run", "--config", str(config)], env=env)
    daemon.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "fcsod started")
    return daemon


def start_subscriber(config: Path, save: Path | None = None, extra: list[str] | None = None) -> Process:
    """Start ``fcsod subscribe`` and wait until it sees the daemon's liveliness token."""
    args = ["subscribe", "--config", str(config), *(["--save", str(save)] if save else []), *(extra or [])]
    subscriber = Process(args)
    subscriber.wait_for(lambda v: isinstance(v, dict) and v.get("daemon") == "alive")
    return subscriber


def drop_job(
    folder: Path, files: dict[str, Path | str | bytes], pause_s: float = 0.0, hidden_first: bool = False
) -> None:
    """Create a job folder file by file.

    Parameters
    ----------
    folder : Path
        The job folder to create.
    files : dict
        Relative name -> source file, text or bytes.
    pause_s : float
        Pause between files and between the halves of each file, s, so the
        daemon sees a folder still being written.
    hidden_first : bool
        Build the folder under a hidden name and rename it into place.
    """
    target = folder.parent / f".{folder.name}.partial" if hidden_first else folder
    target.mkdir(parents=True)
    for name, source in files.items():
        data = (
            source.read_bytes() if isinstance(source, Path) else source.encode() if isinstance(source, str) else source
        )
        path = target / name
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as stream:
            stream.write(data[: len(data) // 2])
            stream.flush()
            time.sleep(pause_s)
            stream.write(data[len(data) // 2 :])
        time.sleep(pause_s)
    if hidden_first:
        target.rename(folder)


def copy_tree(source: Path, target: Path) -> None:
    shutil.copytree(source, target)


def finished(subscriber, folder_name: str, timeout: float = HANG_GUARD_S) -> dict:
    """The done/failed status line the subscriber printed for the job of ``folder_name``."""
    return subscriber.wait_for(
        lambda v: (
            isinstance(v, dict)
            and v.get("topic") == "status"
            and v["body"]["folder"].endswith("/" + folder_name)
            and v["body"]["state"] in ("done", "failed")
        ),
        timeout,
    )


def decode_foxglove(schema_name: str, data: bytes) -> dict:
    """A protobuf message of foxglove-sdk's schema ``schema_name`` decoded by Google's protobuf runtime, as a dict.

    The message must hold nothing the schema does not know: it is encoded
    again from the decoded fields only and must give ``data`` back.
    """
    import foxglove.messages
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory

    schema = getattr(foxglove.messages, schema_name.removeprefix("foxglove.")).get_schema()
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    decoded = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(data)
    # every field, empty lists and zeros included (a build scene without finger copies has no triangles)
    fields = json_format.MessageToDict(
        decoded, preserving_proto_field_name=True, always_print_fields_with_no_presence=True
    )
    again = json_format.ParseDict(fields, type(decoded)())
    assert again.SerializeToString(deterministic=True) == data, f"{schema_name}: fields the schema does not know"
    return fields


def foxglove_messages(record: Path) -> dict[str, list[dict]]:
    """Every Foxglove message of an MCAP file, checked against foxglove-sdk's schema: topic -> messages as dicts.

    A channel whose schema is named ``foxglove.*`` must carry the SDK's own
    schema (the same FileDescriptorSet bytes) and protobuf messages, each of
    which :func:`decode_foxglove` decodes.
    """
    import foxglove.messages
    from mcap.reader import make_reader

    found: dict[str, list[dict]] = {}
    with open(record, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if schema is None or not schema.name.startswith("foxglove."):
                continue
            sdk = getattr(foxglove.messages, schema.name.removeprefix("foxglove.")).get_schema()
            assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf"), channel.topic
            assert schema.data == sdk.data, f"{channel.topic}: not the schema of foxglove-sdk's {schema.name}"
            found.setdefault(channel.topic, []).append(decode_foxglove(schema.name, message.data))
    return found
