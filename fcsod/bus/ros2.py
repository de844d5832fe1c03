"""ROS 2 topics over zenoh in rmw_zenoh's wire format, and the same messages in ``job.mcap``.

A ROS 2 cell that runs ``rmw_zenoh_cpp`` sees the daemon as the node
``<namespace>/<node_name>`` with these publishers, without any ROS 2
installation on the print server:

- ``~/grasps``: ``geometry_msgs/msg/PoseArray``, one per job, part and resting
  pose; ``header.frame_id`` is the part's resting frame (:func:`rest_frame_id`),
  each pose the TCP of the chosen grasp in that frame, in metres;
- ``~/grasp_details``: ``std_msgs/msg/String``, the native ``grasps`` body:
  what a PoseArray cannot carry and the cell reads before it moves (the job
  id, the approach opening, the finger set, the verdict). Its companion
  PoseArrays are published with one time: each PoseArray's ``header.stamp``
  is the source timestamp (rmw's ``MessageInfo.source_timestamp``) of the
  ``grasp_details`` message of its job, whose grasp with ``frame_id`` equal
  to the PoseArray's ``header.frame_id`` is its grasp: the job id, with the
  rest, of a PoseArray;
- ``~/placement``, ``~/plan``, ``~/quality``, ``~/status``, ``~/verification``:
  ``std_msgs/msg/String`` holding the JSON body of the native key of the same
  name (``plan``: the pick plan; ``placement``: the build placement;
  ``verification``: every finger set's, ``verification/<set>`` natively).

The wire format follows rmw_zenoh's sources (``liveliness_utils.cpp``,
``attachment_helpers.cpp``, ``rmw_publisher_data.cpp``, ``qos.cpp``) after
the zenoh 1.x port with AdvancedPublisher (ros2/rmw_zenoh #368) and the
key-less attachment (#601):

- data key expression ``<domain_id>/<topic without leading slash>/<DDS type
  name>/<RIHS01 type hash>``, payload CDR (little endian, encapsulation
  header), as :mod:`rosbags` serialises it;
- attachment: zenoh-ext serialisation of (int64 sequence number starting at
  1, int64 source timestamp in ns since the epoch, 16-byte GID as a sequence),
  that is ``<q`` ``<q`` ``0x10`` and the 16 GID bytes;
- GID: XXH3-128 of the publisher's liveliness key expression, low 64 bits
  then high 64 bits, little endian;
- liveliness tokens ``@ros2_lv/<domain_id>/<zid>/<node id>/<entity id>/<NN|MP>/
  <enclave>/<namespace>/<node name>[/<topic>/<DDS type>/<type hash>/<qos>]``,
  with ``/`` in names replaced by ``%``;
- QoS reliable, transient-local, keep-last ``history_depth``: an
  AdvancedPublisher with a cache of ``history_depth`` samples, publisher
  detection and sporadic heartbeats, as rmw_zenoh declares it, so a late
  subscriber with transient-local durability gets the latest samples.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING

import xxhash
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

from ..config import LIVELINESS_ADMIN_SPACE, Ros2Config
from .messages import ENCODING_JSON, BusMessage, rest_frame_id

if TYPE_CHECKING:
    from ..record.recorder import Recorder

#: ROS 2 message types, as ROS names them.
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
STRING = "std_msgs/msg/String"

#: Native job topic (its first level: ``verification/<set>`` is ``verification``) -> its ROS 2 topics: (topic relative
#: to the node's private namespace, ROS 2 type); each ROS 2 topic has the meaning of the native key it is named after.
ROS2_TOPICS: dict[str, list[tuple[str, str]]] = {
    "grasps": [("grasps", POSE_ARRAY), ("grasp_details", STRING)],
    "placement": [("placement", STRING)],
    "plan": [("plan", STRING)],
    "quality": [("quality", STRING)],
    "status": [("status", STRING)],
    "verification": [("verification", STRING)],
}

#: rmw_zenoh's stand-in for ``/`` inside one key chunk (names, namespaces, enclaves).
SLASH_REPLACEMENT = "%"
#: rmw_zenoh's QoS values (``rmw/types.h``) where they differ from its defaults.
_DURABILITY_TRANSIENT_LOCAL = 1
#: rmw_zenoh's default depth (``qos.cpp``): a depth equal to it is left out of the token.
_RMW_ZENOH_DEFAULT_DEPTH = 42
#: Period of the sporadic heartbeat rmw_zenoh gives reliable transient-local publishers, s.
_HEARTBEAT_PERIOD_S = 0.5


TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


# ------------------------------------------------------------------ names and keys


def node_fqn(config: Ros2Config) -> str:
    """Fully qualified node name, e.g. ``/cell1/fcsod``."""
    return f"{config.namespace.rstrip('/')}/{config.node_name}"


def topic_name(config: Ros2Config, relative: str) -> str:
    """The fully qualified name of ``~/<relative>`` (the node's private namespace), e.g. ``/cell1/fcsod/grasps``."""
    return f"{node_fqn(config)}/{relative}"


def dds_type_name(type_name: str) -> str:
    """The type name rmw_zenoh puts in keys: ``geometry_msgs/msg/PoseArray`` ->
    ``geometry_msgs::msg::dds_::PoseArray_``.
    """
    package, kind, name = type_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(type_name: str) -> str:
    """The type's ``RIHS01_<sha256 hex>`` hash (REP 2011), computed by rosbags."""
    return TYPESTORE.hash_rihs01(type_name)


@cache
def message_definition(type_name: str) -> str:
    """The ``ros2msg`` definition text of a type with its dependencies (an MCAP schema)."""
    return TYPESTORE.generate_msgdef(type_name, ros_version=2)[0]


def topic_key_expr(domain_id: int, name: str, type_name: str) -> str:
    """Key expression of a topic's data: ``<domain_id>/<name without slashes at the ends>/<DDS type>/<RIHS01 hash>``."""
    return f"{domain_id}/{name.strip('/')}/{dds_type_name(type_name)}/{type_hash(type_name)}"


def mangle(name: str) -> str:
    """A name as one key chunk: every ``/`` becomes ``%`` (rmw_zenoh's ``mangle_name``)."""
    return name.replace("/", SLASH_REPLACEMENT)


def qos_key_chunk(depth: int) -> str:
    """rmw_zenoh's QoS chunk of a reliable, transient-local, keep-last ``depth`` publisher.

    Fields equal to rmw_zenoh's defaults (reliable, volatile, keep-last 42,
    infinite deadline, lifespan and lease, automatic liveliness) are empty:
    ``reliability:durability:history,depth:deadline_s,ns:lifespan_s,ns:liveliness,lease_s,ns``.
    """
    depth_text = "" if depth == _RMW_ZENOH_DEFAULT_DEPTH else str(depth)
    return f":{_DURABILITY_TRANSIENT_LOCAL}:,{depth_text}:,:,:,,"


def liveliness_key_expr(
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    config: Ros2Config,
    topic: str | None = None,
    type_name: str | None = None,
) -> str:
    """A liveliness token of the node (``NN``, no topic) or of one of its publishers (``MP``).

    Parameters
    ----------
    domain_id : int
    zid : str
        The zenoh session id as zenoh prints it.
    node_id, entity_id : int
        The node's id and the entity's (equal for the node).
    config : Ros2Config
        Namespace and node name.
    topic, type_name : str, optional
        The publisher's fully qualified topic and ROS 2 type.
    """
    chunks = [
        LIVELINESS_ADMIN_SPACE,
        str(domain_id),
        zid,
        str(node_id),
        str(entity_id),
        "NN" if topic is None else "MP",
    ]
    # enclave "/" (the default), then namespace and node name, mangled
    chunks += [mangle("/"), mangle(config.namespace), mangle(config.node_name)]
    if topic is not None:
        chunks += [
            mangle(topic),
            mangle(dds_type_name(type_name)),
            type_hash(type_name),
            qos_key_chunk(config.history_depth),
        ]
    return "/".join(chunks)


def entity_gid(liveliness_key: str) -> bytes:
    """The entity's 16-byte GID: XXH3-128 of its liveliness key expression, low then high 64 bits, little endian."""
    return xxhash.xxh3_128_intdigest(liveliness_key.encode()).to_bytes(16, "little")


def encode_attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's attachment: zenoh-ext serialisation of (int64, int64, 16 bytes as a sequence)."""
    return zenoh.ext.z_serialize(
        (zenoh.ext.Int64(sequence_number), zenoh.ext.Int64(source_timestamp_ns), gid)
    ).to_bytes()


# ------------------------------------------------------------------ messages


def _stamp(time_ns: int):
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=time_ns // 1_000_000_000, nanosec=time_ns % 1_000_000_000)


def grasp_pose_arrays(grasps: list[dict], stamp_ns: int) -> list:
    """One ``PoseArray`` per grasp (part and resting pose): the TCP pose in the part's resting frame, metres.

    Parameters
    ----------
    grasps : list of dict
        The native grasps (``GraspReport`` bodies: ``part``, ``pose_index``,
        ``position_mm``, ``quaternion_wxyz``).
    stamp_ns : int
        Header stamp, ns since the epoch.
    """
    types = TYPESTORE.types
    header_type, pose_type = types["std_msgs/msg/Header"], types["geometry_msgs/msg/Pose"]
    point_type, quaternion_type, array_type = (
        types["geometry_msgs/msg/Point"],
        types["geometry_msgs/msg/Quaternion"],
        types[POSE_ARRAY],
    )
    arrays = []
    for grasp in grasps:
        x, y, z = (value / 1000.0 for value in grasp["position_mm"])
        w, qx, qy, qz = grasp["quaternion_wxyz"]
        pose = pose_type(position=point_type(x=x, y=y, z=z), orientation=quaternion_type(x=qx, y=qy, z=qz, w=w))
        header = header_type(stamp=_stamp(stamp_ns), frame_id=rest_frame_id(grasp["part"], grasp["pose_index"]))
        arrays.append(array_type(header=header, poses=[pose]))
    return arrays


def ros2_messages(message: BusMessage, stamp_ns: int) -> list[tuple[str, str, bytes]]:
    """The ROS 2 messages a native job message becomes.

    Parameters
    ----------
    message : BusMessage
        A native message; only JSON topics of :data:`ROS2_TOPICS` have a ROS 2 form.
    stamp_ns : int
        Header stamp of the PoseArrays, ns since the epoch.

    Returns
    -------
    list of (relative topic, ROS 2 type, CDR bytes)
    """
    topic = message.topic.partition("/")[0]
    if topic not in ROS2_TOPICS or message.encoding != ENCODING_JSON:
        return []
    forms = []
    for relative, type_name in ROS2_TOPICS[topic]:
        if type_name == POSE_ARRAY:
            bodies = grasp_pose_arrays(json.loads(message.payload)["grasps"], stamp_ns)
        else:
            bodies = [TYPESTORE.types[STRING](data=message.payload.decode())]
        forms.extend((relative, type_name, bytes(TYPESTORE.serialize_cdr(body, type_name))) for body in bodies)
    return forms


def record_ros2(recorder: Recorder, message: BusMessage, config: Ros2Config, log_time_ns: int | None = None) -> None:
    """Write the ROS 2 form of a native message to ``job.mcap``: ``cdr`` messages on ``ros2msg`` channels named like the
    live topics.

    The channels carry rosbag2's ``topic_type_hash`` metadata, so
    ``ros2 bag play`` (rosbag2's MCAP storage) replays them.
    """
    now = log_time_ns if log_time_ns is not None else time.time_ns()
    for relative, type_name, data in ros2_messages(message, now):
        recorder.write_raw(
            topic_name(config, relative),
            type_name,
            message_definition(type_name).encode(),
            data,
            now,
            schema_encoding="ros2msg",
            message_encoding="cdr",
            metadata={"topic_type_hash": type_hash(type_name)},
        )


# ------------------------------------------------------------------ the node on zenoh


@dataclass
class _Publisher:
    topic: str
    type_name: str
    key_expr: str
    liveliness_key: str
    gid: bytes
    publisher: object
    token: object
    sequence_number: int = 1


class Ros2Node:
    """The daemon as a ROS 2 node on an open zenoh session (rmw_zenoh's wire format).

    Declares the node's liveliness token and, per topic of
    :data:`ROS2_TOPICS`, an AdvancedPublisher (reliable, cache of
    ``history_depth`` samples, publisher detection, sporadic heartbeat) and
    its liveliness token.

    Parameters
    ----------
    session : zenoh.Session
        The daemon's session.
    config : Ros2Config
    """

    #: rmw_zenoh numbers a context's entities from 0: the node first, then its publishers.
    NODE_ID = 0

    def __init__(self, session: zenoh.Session, config: Ros2Config):
        self.config = config
        self._lock = threading.Lock()
        zid = str(session.info.zid())
        self.node_liveliness_key = liveliness_key_expr(config.domain_id, zid, self.NODE_ID, self.NODE_ID, config)
        self._node_token = session.liveliness().declare_token(self.node_liveliness_key)
        self.publishers: dict[str, _Publisher] = {}
        topics = [pair for pairs in ROS2_TOPICS.values() for pair in pairs]
        for entity_id, (relative, type_name) in enumerate(topics, start=self.NODE_ID + 1):
            name = topic_name(config, relative)
            key_expr = topic_key_expr(config.domain_id, name, type_name)
            token_key = liveliness_key_expr(config.domain_id, zid, self.NODE_ID, entity_id, config, name, type_name)
            publisher = zenoh.ext.declare_advanced_publisher(
                session,
                key_expr,
                reliability=zenoh.Reliability.RELIABLE,
                congestion_control=zenoh.CongestionControl.DROP,
                cache=zenoh.ext.CacheConfig(config.history_depth),
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=_HEARTBEAT_PERIOD_S
                ),
                publisher_detection=True,
            )
            token = session.liveliness().declare_token(token_key)
            self.publishers[relative] = _Publisher(
                name, type_name, key_expr, token_key, entity_gid(token_key), publisher, token
            )

    def publish(self, message: BusMessage) -> list[str]:
        """Publish the ROS 2 form of a native message; returns the key expressions put (none for other topics)."""
        published = []
        with self._lock:
            # one time for every form of the message: the PoseArrays' header stamp is their companion's source time
            now = time.time_ns()
            for relative, _type_name, data in ros2_messages(message, now):
                target = self.publishers[relative]
                attachment = encode_attachment(target.sequence_number, now, target.gid)
                target.publisher.put(data, attachment=attachment)
                target.sequence_number += 1
                published.append(target.key_expr)
        return published

    def close(self) -> None:
        """Undeclare the publishers and the tokens (the session stays open)."""
        with self._lock:
            for target in self.publishers.values():
                target.token.undeclare()
                target.publisher.undeclare()
            self._node_token.undeclare()
