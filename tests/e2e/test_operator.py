"""What the people around a running daemon use: ``fcsod jobs | cancel | retry``, the metrics, the live Foxglove view."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import struct
import threading
import urllib.request
from dataclasses import dataclass

from foxglove.messages import SceneUpdate
from prometheus_client.parser import text_string_to_metric_families
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from fcsod.cli import main
from fcsod.record.recorder import TOPIC_STATE, read_record
from fcsod.service.requests import CANCELLED_ERROR
from tests.conftest import HANG_GUARD_S
from tests.fcsod_helpers import (
    DATA,
    decode_foxglove,
    drop_job,
    foxglove_messages,
    free_port,
    slow_manifest,
    start_daemon,
    write_config,
)

SOLAR = DATA / "solar_tracker.stl"
CUBE = DATA / "20mm-xyz-cube.stl"


@dataclass
class Command:
    """What an fcsod command did: exit code and printed text."""

    returncode: int
    stdout: str
    stderr: str


def fcsod(*args: str) -> Command:
    """Run an fcsod command to its end (in this process: the daemon it talks to runs in its own)."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(list(args))
    return Command(code, stdout.getvalue(), stderr.getvalue())


def jobs(config, *args: str) -> dict[str, dict]:
    """``fcsod jobs --json``: job id -> row."""
    listed = fcsod("jobs", "--config", str(config), "--json", *args)
    assert listed.returncode == 0, listed.stderr
    return {row["job_id"]: row for row in map(json.loads, listed.stdout.splitlines())}


def scrape(port: int) -> dict[tuple, float]:
    """The metrics endpoint's samples, parsed by prometheus-client's parser: (name, sorted labels) -> value."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=HANG_GUARD_S) as response:
        text = response.read().decode()
    return {
        (sample.name, tuple(sorted(sample.labels.items()))): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


class FoxgloveClient:
    """A Foxglove WebSocket client in a thread, on ``socket`` (opened with the subprotocol foxglove.sdk.v1):
    subscribes to ``topics`` as they are advertised and keeps each message it receives with its channel.
    """

    def __init__(self, socket, topics: set[str]):
        self.socket = socket
        self.topics = topics
        self.channels: dict[int, dict] = {}
        self.received: list[tuple[dict, bytes]] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        subscriptions: dict[int, dict] = {}
        with contextlib.suppress(ConnectionClosed):
            for frame in self.socket:
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message["op"] != "advertise":
                        continue
                    wanted = [c for c in message["channels"] if c["topic"] in self.topics]
                    for channel in wanted:
                        subscriptions[channel["id"]] = channel
                    self.socket.send(
                        json.dumps(
                            {
                                "op": "subscribe",
                                "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in wanted],
                            }
                        )
                    )
                elif frame[0] == 1:  # message data: opcode, subscription id (u32), log time (u64), payload
                    (subscription,) = struct.unpack_from("<I", frame, 1)
                    self.received.append((subscriptions[subscription], frame[13:]))

    def join(self) -> None:
        """Wait for the end of the connection (the caller closed the socket)."""
        self.thread.join(timeout=10)


def test_cancel_retry_metrics_and_live_foxglove_on_a_running_daemon(tmp_path):
    metrics_port, foxglove_port = free_port(), free_port()
    extra = (
        f'[metrics]\nenabled = true\nlisten = "127.0.0.1:{metrics_port}"\n'
        f'[foxglove]\nenabled = true\nlisten = "127.0.0.1:{foxglove_port}"\n'
    )
    config = write_config(tmp_path, free_port(), extra=extra)
    out = tmp_path / "out"
    daemon = start_daemon(config)
    try:
        with connect(
            f"ws://127.0.0.1:{foxglove_port}", subprotocols=["foxglove.sdk.v1"], open_timeout=HANG_GUARD_S
        ) as socket:
            client = FoxgloveClient(socket, {"/scene", "/fcsod/status"})
            for topic in ("/scene", "/fcsod/status"):
                daemon.wait_for(
                    lambda v, topic=topic: (
                        isinstance(v, dict) and v.get("message") == "Foxglove client subscribed" and v["topic"] == topic
                    )
                )
            before = scrape(metrics_port)
            # a design of many minutes (SLOW_SECTIONS in its job.toml): surely still running when cancelled
            drop_job(tmp_path / "watch" / "slow", {"job.toml": slow_manifest("solar.stl"), "solar.stl": SOLAR})
            started = daemon.wait_for(lambda v: isinstance(v, dict) and v.get("message") == "job started")
            daemon.wait_for(lambda v: isinstance(v, dict) and v.get("stage") == "load")
            # one job at a time: the second waits in the queue behind the running one
            drop_job(tmp_path / "watch" / "cube", {"cube.stl": CUBE})
            queued = daemon.wait_for(
                lambda v: isinstance(v, dict) and v.get("message") == "job queued" and v["folder"].endswith("/cube")
            )
            running_id, queued_id = started["job_id"], queued["job_id"]

            listed = jobs(config)
            assert {k: v["state"] for k, v in listed.items()} == {running_id: "running", queued_id: "queued"}
            assert listed[running_id]["folder"] == str(tmp_path / "watch" / "slow")
            assert list(jobs(config, "--state", "queued")) == [queued_id]
            during = scrape(metrics_port)

            cancelled_queued = fcsod("cancel", queued_id[:10], "--config", str(config))
            assert cancelled_queued.returncode == 0, cancelled_queued.stdout + cancelled_queued.stderr
            cancelled_running = fcsod("cancel", running_id, "--config", str(config))
            assert cancelled_running.returncode == 0, cancelled_running.stdout + cancelled_running.stderr
            # a job that already ended cannot be cancelled; an unknown one is bad input
            assert fcsod("cancel", running_id, "--config", str(config)).returncode == 1
            assert fcsod("cancel", "no-such-job", "--config", str(config)).returncode == 2
            after_cancel = scrape(metrics_port)
            cancelled = jobs(config, "--state", "failed")
            # nothing partial: each cancelled job's folder holds its finished record only, no work folder is left
            assert sorted(p.name for p in out.iterdir()) == sorted([running_id, queued_id])
            assert all(sorted(p.name for p in (out / j).iterdir()) == ["job.mcap"] for j in (running_id, queued_id))

            # the cancelled cube retried: a new run and a new record, the cancelled run's record kept (the wait skips
            # the log of its cancellation)
            retried = fcsod("retry", queued_id, "--config", str(config))
            assert retried.returncode == 0, retried.stdout + retried.stderr
            done = daemon.wait_for(
                lambda v: (
                    isinstance(v, dict)
                    and v.get("job_id") == queued_id
                    and v.get("state") in ("done", "failed")
                    and str(v.get("message")).startswith("job ")
                    and CANCELLED_ERROR not in v["message"]
                ),
                120,
            )
            finished = scrape(metrics_port)
            # a done job is not retried
            assert fcsod("retry", queued_id, "--config", str(config)).returncode == 1
            final = jobs(config)
        client.join()
    finally:
        assert daemon.stop() == 0

    assert before[("fcsod_jobs", (("state", "running"),))] == 0
    assert during[("fcsod_jobs", (("state", "running"),))] == 1
    assert during[("fcsod_queue_depth", ())] == 1
    assert after_cancel[("fcsod_jobs", (("state", "failed"),))] == 2
    assert after_cancel[("fcsod_queue_depth", ())] == 0
    # cancelled is its own result, not a failure
    assert after_cancel[("fcsod_jobs_finished_total", (("state", "cancelled"),))] == 2
    assert after_cancel[("fcsod_jobs_finished_total", (("state", "failed"),))] == 0
    assert {k: v["error"] for k, v in cancelled.items()} == {running_id: CANCELLED_ERROR, queued_id: CANCELLED_ERROR}
    solar = read_record(out / running_id / "job.mcap")
    assert not solar.truncated
    last = solar.of(TOPIC_STATE)[-1]
    assert (last["state"], last["error"]) == ("failed", CANCELLED_ERROR)
    assert any(line["message"].startswith("loaded solar.stl") for line in solar.of("/job/log"))

    assert done["state"] == "done", done
    assert final[queued_id]["state"] == "done" and final[queued_id]["error"] is None
    assert final[running_id]["state"] == "failed", "the other failed job stays as it was"
    kept = read_record(out / "attempts" / queued_id / "1" / "job.mcap")
    assert [s["state"] for s in kept.of(TOPIC_STATE)] == ["failed"]
    assert kept.of(TOPIC_STATE)[-1]["error"] == CANCELLED_ERROR
    assert [s["state"] for s in read_record(out / queued_id / "job.mcap").of(TOPIC_STATE)] == [
        "queued",
        "running",
        "done",
    ]
    assert finished[("fcsod_jobs", (("state", "done"),))] == 1
    assert finished[("fcsod_jobs", (("state", "failed"),))] == 1
    assert finished[("fcsod_jobs_finished_total", (("state", "done"),))] == 1
    assert finished[("fcsod_stage_duration_seconds_count", (("stage", "design"),))] == 1
    assert finished[("fcsod_stage_duration_seconds_sum", (("stage", "design"),))] > 0

    # live: every status of the cube's job, and the scene of its run (the bytes of its record) before it was done
    statuses = [json.loads(data) for channel, data in client.received if channel["topic"] == "/fcsod/status"]
    assert [s["state"] for s in statuses if s["job_id"] == queued_id] == [
        "queued",
        "failed",
        "queued",
        "running",
        "done",
    ]
    topics = [channel["topic"] for channel, _ in client.received]
    assert topics.count("/scene") == 2, "the grasps, then the placed build"
    assert topics.index("/scene") < len(topics) - 1 - topics[::-1].index("/fcsod/status")
    scene_channel, scene = next((c, d) for c, d in client.received if c["topic"] == "/scene")
    assert (scene_channel["schemaName"], scene_channel["encoding"]) == ("foxglove.SceneUpdate", "protobuf")
    assert base64.b64decode(scene_channel["schema"]) == SceneUpdate.get_schema().data
    assert (
        decode_foxglove("foxglove.SceneUpdate", scene) == foxglove_messages(out / queued_id / "job.mcap")["/scene"][0]
    )
