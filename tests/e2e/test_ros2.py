"""ROS 2 over zenoh: ``fcsod run`` with ``[ros2]`` and a cell process on loopback reading rmw_zenoh's wire format.

The expected wire format is written out here from rmw_zenoh's sources
(``liveliness_utils.cpp``, ``attachment_helpers.cpp``, ``qos.cpp``): the key
expression layout, the attachment bytes, the GID as XXH3-128 of the
liveliness key and the token layout; the type hashes and CDR come from
rosbags.
"""

from __future__ import annotations

import json
import re
import struct
import time

import pytest
import xxhash
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fcso.errors import ConfigError
from fcsod.cli import main
from fcsod.config import load_daemon_config
from tests.fcsod_helpers import DATA, Process, drop_job, free_port, start_daemon, write_config

CUBE = DATA / "20mm-xyz-cube.stl"
DOMAIN = 7
ROS2 = f'[ros2]\nenabled = true\ndomain_id = {DOMAIN}\nnamespace = "/cell1"\n'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POSE_ARRAY_HASH = TYPESTORE.hash_rihs01("geometry_msgs/msg/PoseArray")
STRING_HASH = TYPESTORE.hash_rihs01("std_msgs/msg/String")
# a reliable, transient-local, keep-last-10 publisher in rmw_zenoh's QoS chunk (defaults left empty)
QOS = ":1:,10:,:,:,,"


def _start_cell(port: int, late: str | None = None) -> Process:
    args = ["--connect", f"tcp/127.0.0.1:{port}", "--domain", str(DOMAIN), *(["--late", late] if late else [])]
    cell = Process(args, module="tests.ros2_cell")
    cell.wait_for(lambda v: isinstance(v, dict) and v.get("event") == "ready")
    return cell


def _samples(cell: Process, source: str, key_part: str) -> list[dict]:
    return [
        v
        for v in cell.json_lines()
        if v.get("event") == "sample" and v["source"] == source and key_part in v["key_expr"]
    ]


@pytest.fixture(scope="module")
def ros2_job(tmp_path_factory):
    """A daemon with [ros2] enabled, a ROS 2 cell process that saw a two-cube job through, and the job's outputs."""
    base = tmp_path_factory.mktemp("ros2")
    port = free_port()
    config = write_config(base, port, extra=ROS2)
    daemon = start_daemon(config)
    cell = _start_cell(port)
    started_ns = time.time_ns()
    manifest = '[[parts]]\nfile = "cube.stl"\nquantity = 2\n'
    drop_job(base / "watch" / "cubes", {"job.toml": manifest, "cube.stl": CUBE})

    def done_on_ros2(value) -> bool:
        if not (
            isinstance(value, dict)
            and value.get("event") == "sample"
            and "/status/" in value["key_expr"]
            and value["source"] == "ros2"
        ):
            return False
        message = TYPESTORE.deserialize_cdr(bytes.fromhex(value["payload"]), "std_msgs/msg/String")
        return json.loads(message.data)["state"] in ("done", "failed")

    def done_natively(value) -> bool:
        if not (
            isinstance(value, dict)
            and value.get("event") == "sample"
            and value["key_expr"].endswith("/status")
            and value["source"] == "native"
        ):
            return False
        return json.loads(bytes.fromhex(value["payload"]))["state"] in ("done", "failed")

    # the daemon publishes each message natively, then on ROS 2:
    # the last of both forms of the final status closes the job
    cell.wait_for(done_on_ros2)
    cell.wait_for(done_natively)
    finished_ns = time.time_ns()
    job_id = next(path.name for path in (base / "out").iterdir() if not path.name.startswith("."))
    yield {
        "base": base,
        "port": port,
        "daemon": daemon,
        "cell": cell,
        "job_id": job_id,
        "out": base / "out" / job_id,
        "window_ns": (started_ns, finished_ns),
    }
    cell.stop()
    assert daemon.stop() == 0, "daemon did not stop cleanly on SIGTERM"


def test_grasps_arrive_on_the_rmw_zenoh_key_as_pose_arrays_equal_to_the_native_grasps(ros2_job):
    cell = ros2_job["cell"]
    expected_key = f"{DOMAIN}/cell1/fcsod/grasps/geometry_msgs::msg::dds_::PoseArray_/{POSE_ARRAY_HASH}"
    assert POSE_ARRAY_HASH == "RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4c9ed328d3d5004aa0"
    received = _samples(cell, "ros2", "/grasps/")
    assert received and {v["key_expr"] for v in received} == {expected_key}
    native = _samples(cell, "native", "/grasps")
    assert len(native) == 1
    grasps = json.loads(bytes.fromhex(native[0]["payload"]))["grasps"]
    assert len(received) == len(grasps) >= 1, "one PoseArray per part and resting pose"
    for sample, grasp in zip(received, grasps):
        message = TYPESTORE.deserialize_cdr(bytes.fromhex(sample["payload"]), "geometry_msgs/msg/PoseArray")
        assert message.header.frame_id == f"fcso_{grasp['part']}_rest{grasp['pose_index']}"
        (pose,) = message.poses
        assert [pose.position.x, pose.position.y, pose.position.z] == pytest.approx(
            [c / 1000.0 for c in grasp["position_mm"]], abs=1e-12
        )
        w, x, y, z = grasp["quaternion_wxyz"]
        assert [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w] == pytest.approx(
            [x, y, z, w], abs=1e-12
        )


def test_a_pose_array_finds_its_job_in_its_grasp_details_companion(ros2_job):
    """A PoseArray has no field for the job id: its header.stamp is the source timestamp (the attachment's) of the
    ~/grasp_details message of its job, and that message's grasp whose frame_id is the PoseArray's header.frame_id
    carries the job id, the approach opening and the verdict."""
    cell = ros2_job["cell"]
    details = {}
    for sample in _samples(cell, "ros2", "/grasp_details/"):
        message = TYPESTORE.deserialize_cdr(bytes.fromhex(sample["payload"]), "std_msgs/msg/String")
        details[_attachment(sample["attachment"])[1]] = json.loads(message.data)
    arrays = _samples(cell, "ros2", "/grasps/")
    assert arrays and len(details) == 1
    for sample in arrays:
        array = TYPESTORE.deserialize_cdr(bytes.fromhex(sample["payload"]), "geometry_msgs/msg/PoseArray")
        stamp = array.header.stamp.sec * 1_000_000_000 + array.header.stamp.nanosec
        assert stamp == _attachment(sample["attachment"])[1], "the header stamp is the PoseArray's own source time"
        (grasp,) = [g for g in details[stamp]["grasps"] if g["frame_id"] == array.header.frame_id]
        assert grasp["job_id"] == details[stamp]["job_id"] == ros2_job["job_id"]
        assert grasp["approach_opening_mm"] > grasp["closing_width_mm"]


def _attachment(hex_text: str) -> tuple[int, int, bytes]:
    """rmw_zenoh's attachment: int64 LE sequence number, int64 LE source timestamp, 16-byte GID as a zenoh sequence
    (length 0x10).
    """
    data = bytes.fromhex(hex_text)
    assert len(data) == 8 + 8 + 1 + 16
    sequence, stamp = struct.unpack_from("<qq", data)
    assert data[16] == 16, "the GID is serialised as a sequence of 16 bytes"
    return sequence, stamp, data[17:]


def test_attachments_carry_increasing_sequence_numbers_timestamps_and_the_publisher_gid(ros2_job):
    cell = ros2_job["cell"]
    start, end = ros2_job["window_ns"]
    tokens = [v["key_expr"] for v in cell.json_lines() if v.get("event") == "token"]
    status = _samples(cell, "ros2", "/status/")
    states = [
        json.loads(TYPESTORE.deserialize_cdr(bytes.fromhex(v["payload"]), "std_msgs/msg/String").data)["state"]
        for v in status
    ]
    assert states == ["queued", "running", "done"]
    decoded = [_attachment(v["attachment"]) for v in status]
    assert [sequence for sequence, _, _ in decoded] == [1, 2, 3], "rmw_zenoh numbers a publisher's samples from 1"
    stamps = [stamp for _, stamp, _ in decoded]
    assert stamps == sorted(stamps) and start <= stamps[0] and stamps[-1] <= end, (
        "source timestamps are ns since the epoch"
    )
    (status_token,) = [t for t in tokens if "/%cell1%fcsod%status/" in t]
    expected_gid = xxhash.xxh3_128_intdigest(status_token.encode()).to_bytes(16, "little")
    assert {gid for _, _, gid in decoded} == {expected_gid}, (
        "GID = XXH3-128 of the publisher's liveliness key, low then high 64 bits"
    )
    grasp_gids = {_attachment(v["attachment"])[2] for v in _samples(cell, "ros2", "/grasps/")}
    assert len(grasp_gids) == 1 and grasp_gids != {expected_gid}


def test_string_topics_hold_the_native_json_bodies(ros2_job):
    cell = ros2_job["cell"]
    # each ROS 2 topic carries the native key of its name; the grasps' details beside their PoseArrays
    for native_topic, ros2_topic in (
        ("quality", "quality"),
        ("placement", "placement"),
        ("plan", "plan"),
        ("status", "status"),
        ("grasps", "grasp_details"),
    ):
        ros2 = _samples(cell, "ros2", f"/cell1/fcsod/{ros2_topic}/")
        assert ros2 and {v["key_expr"] for v in ros2} == {
            f"{DOMAIN}/cell1/fcsod/{ros2_topic}/std_msgs::msg::dds_::String_/{STRING_HASH}"
        }
        native = [v for v in _samples(cell, "native", "/jobs/") if v["key_expr"].endswith(f"/{native_topic}")]
        bodies = [
            json.loads(TYPESTORE.deserialize_cdr(bytes.fromhex(v["payload"]), "std_msgs/msg/String").data) for v in ros2
        ]
        assert bodies == [json.loads(bytes.fromhex(v["payload"])) for v in native]
        if native_topic == "grasps":
            # what the cell reads before the robot moves: the job, the finger set, the approach opening, the verdict
            for grasp in bodies[0]["grasps"]:
                assert grasp["job_id"] == ros2_job["job_id"] and grasp["finger_set"] == 1
                assert grasp["approach_opening_mm"] > grasp["closing_width_mm"]
                assert grasp["verified"] is None and grasp["verdict"] == "not verified: [verify] enabled is false"


def test_liveliness_tokens_show_the_node_and_its_publishers(ros2_job):
    cell = ros2_job["cell"]
    (peer,) = [v for v in cell.json_lines() if v.get("event") == "peer"]
    (zid,) = peer["zids"]
    tokens = {v["key_expr"] for v in cell.json_lines() if v.get("event") == "token" and v["kind"] == "SampleKind.PUT"}
    assert f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%cell1/fcsod" in tokens
    publishers = {
        "grasps": ("geometry_msgs::msg::dds_::PoseArray_", POSE_ARRAY_HASH),
        "grasp_details": ("std_msgs::msg::dds_::String_", STRING_HASH),
        "placement": ("std_msgs::msg::dds_::String_", STRING_HASH),
        "plan": ("std_msgs::msg::dds_::String_", STRING_HASH),
        "quality": ("std_msgs::msg::dds_::String_", STRING_HASH),
        "status": ("std_msgs::msg::dds_::String_", STRING_HASH),
        "verification": ("std_msgs::msg::dds_::String_", STRING_HASH),
    }
    pattern = re.compile(
        rf"^@ros2_lv/{DOMAIN}/{zid}/0/(\d+)/MP/%/%cell1/fcsod/%cell1%fcsod%(\w+)/([\w:]+)/(RIHS01_[0-9a-f]{{64}})/(.*)$"
    )
    found = {}
    for token in tokens - {f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%cell1/fcsod"}:
        match = pattern.match(token)
        assert match, token
        entity, topic, dds_type, type_hash, qos = match.groups()
        found[topic] = (dds_type, type_hash)
        assert qos == QOS and int(entity) > 0
    assert found == publishers


def test_a_late_transient_local_subscriber_gets_the_last_job(ros2_job):
    """An AdvancedSubscriber with history, as rmw_zenoh declares a transient-local subscription, joining after the
    job.
    """
    key = f"{DOMAIN}/cell1/fcsod/grasps/geometry_msgs::msg::dds_::PoseArray_/{POSE_ARRAY_HASH}"
    late = _start_cell(ros2_job["port"], late=key)
    try:
        value = late.wait_for(lambda v: isinstance(v, dict) and v.get("event") == "sample")
    finally:
        late.stop()
    live = _samples(ros2_job["cell"], "ros2", "/grasps/")
    assert value["key_expr"] == key and value["payload"] in {v["payload"] for v in live}
    assert _attachment(value["attachment"])[0] >= 1


def test_job_mcap_carries_the_ros2_messages_for_ros2_bag_play(ros2_job, capsys):
    out = ros2_job["out"]
    report = json.loads((out / "report.json").read_text())
    channels: dict[str, list] = {}
    with open(out / "job.mcap", "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if channel.message_encoding != "cdr":
                continue
            assert schema.encoding == "ros2msg"
            # the schema text is a valid ros2msg definition: a fresh typestore learns the types from it alone
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg(schema.data.decode(), schema.name))
            channels.setdefault(channel.topic, []).append(store.deserialize_cdr(message.data, schema.name))
            assert channel.metadata["topic_type_hash"] == TYPESTORE.hash_rihs01(schema.name)
    topics = ("grasps", "grasp_details", "placement", "plan", "quality", "status")
    assert set(channels) == {f"/cell1/fcsod/{topic}" for topic in topics}
    assert [json.loads(m.data)["state"] for m in channels["/cell1/fcsod/status"]] == ["running", "done"]
    arrays = channels["/cell1/fcsod/grasps"]
    assert len(arrays) == len(report["grasps"])
    (details,) = [json.loads(m.data) for m in channels["/cell1/fcsod/grasp_details"]]
    for array, grasp in zip(arrays, report["grasps"]):
        assert array.header.frame_id == f"fcso_{grasp['part']}_rest{grasp['pose_index']}"
        assert array.poses[0].position.x == pytest.approx(grasp["position_mm"][0] / 1000.0)
        # the PoseArray's job: its grasp in the companion, by frame
        (detail,) = [g for g in details["grasps"] if g["frame_id"] == array.header.frame_id]
        assert detail["job_id"] == ros2_job["job_id"] and detail["part"] == grasp["part"]
    assert json.loads(channels["/cell1/fcsod/quality"][0].data)["job_id"] == ros2_job["job_id"]
    code = main(["audit", str(out / "job.mcap"), "--verify", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "ROS 2 /cell1/fcsod/grasps (geometry_msgs/msg/PoseArray, cdr)" in text


def test_ros2_section_is_checked(tmp_path):
    for number, (extra, key) in enumerate(
        (('[ros2]\nnamespace = "cell1/"\n', "ros2.namespace"), ("[ros2]\ndomain_id = 300\n", "ros2.domain_id"))
    ):
        with pytest.raises(ConfigError, match=key):
            load_daemon_config(write_config(tmp_path / str(number), free_port(), extra=extra))
