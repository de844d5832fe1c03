"""MCAP recording of a job (``job.mcap``): writing as the job goes, reading back, salvaging a cut-off record.

Messages are JSON (``message_encoding="json"``) with JSON Schema schemas
(``encoding="jsonschema"``) generated from the pydantic models of
:mod:`fcsod.bus.messages`, plus the ROS 2 form of the published messages
(``cdr`` with ``ros2msg`` schemas, written by :func:`fcsod.bus.ros2.record_ros2`). Chunks are small and flushed after
every stage, so a
job cut off by a crash leaves a record readable up to the last flush.
"""

from __future__ import annotations

import json
import os
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel

from fcso.schema import schema_text

from .. import __version__
from ..bus.messages import (
    BusRecord,
    CandidateRecord,
    DecisionRecord,
    DesignRecord,
    GraspsMessage,
    InputHashesRecord,
    JobSpecRecord,
    LogRecord,
    OutputFilesRecord,
    PoseRecord,
    SamplesRecord,
    StateChangeRecord,
)
from ..plate.models import PlacementReport

#: The record of every job, in its output folder.
JOB_RECORD_NAME = "job.mcap"
#: The record of a job's verification, beside it (job.mcap is closed when the job is done).
VERIFICATION_RECORD_NAME = "verification.mcap"

TOPIC_SPEC = "/job/spec"
TOPIC_INPUTS = "/job/inputs"
TOPIC_STATE = "/job/state"
TOPIC_LOG = "/job/log"
TOPIC_OUTPUTS = "/job/outputs"
TOPIC_DECISION = "/job/decision"
TOPIC_POSES = "/design/poses"
TOPIC_SAMPLES = "/design/samples"
TOPIC_CANDIDATES = "/design/candidates"
TOPIC_DESIGN = "/design/finger"
TOPIC_GRASPS = "/design/grasps"
TOPIC_BUS = "/zenoh/published"
TOPIC_SCENE = "/scene"
#: The frame tree of the scene (``foxglove.FrameTransforms``, :mod:`fcsod.record.scene`).
TOPIC_TRANSFORMS = "/tf"
TOPIC_PLACEMENT = "/build/placement"
#: Channels of verification.mcap.
TOPIC_VERIFICATION = "/verification"
TOPIC_VERIFICATION_SCENE = "/verification/scene"

#: Channel -> model of its JSON messages (the Foxglove scenes and frames, ``TOPIC_SCENE``, ``TOPIC_TRANSFORMS`` and
#: ``TOPIC_VERIFICATION_SCENE``, are foxglove-sdk's protobuf messages: :meth:`Recorder.write_foxglove`).
CHANNELS: dict[str, type[BaseModel]] = {
    TOPIC_SPEC: JobSpecRecord,
    TOPIC_INPUTS: InputHashesRecord,
    TOPIC_STATE: StateChangeRecord,
    TOPIC_LOG: LogRecord,
    TOPIC_OUTPUTS: OutputFilesRecord,
    TOPIC_DECISION: DecisionRecord,
    TOPIC_POSES: PoseRecord,
    TOPIC_SAMPLES: SamplesRecord,
    TOPIC_CANDIDATES: CandidateRecord,
    TOPIC_DESIGN: DesignRecord,
    TOPIC_GRASPS: GraspsMessage,
    TOPIC_BUS: BusRecord,
    TOPIC_PLACEMENT: PlacementReport,
}

#: Channels every job has, done or failed.
ALWAYS_RECORDED = (TOPIC_SPEC, TOPIC_INPUTS, TOPIC_STATE, TOPIC_LOG, TOPIC_BUS)

#: Channels a finished design adds.
DESIGN_RECORDED = (
    TOPIC_POSES,
    TOPIC_SAMPLES,
    TOPIC_CANDIDATES,
    TOPIC_DESIGN,
    TOPIC_GRASPS,
    TOPIC_OUTPUTS,
    TOPIC_SCENE,
    TOPIC_TRANSFORMS,
    TOPIC_PLACEMENT,
)

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def schema_name(model: type[BaseModel]) -> str:
    """Name of a model's MCAP schema: ``fcsod.<Model>``."""
    return f"fcsod.{model.__name__}"


class Recorder:
    """Writes one job's MCAP file.

    Parameters
    ----------
    path : Path
        The file to create.
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression.
    chunk_size_bytes : int
        Uncompressed chunk size; a chunk is also closed at every :meth:`flush`.
    """

    def __init__(self, path: str | Path, compression: str = "zstd", chunk_size_bytes: int = 65536):
        self.path = Path(path)
        self._stream: IO[bytes] = open(self.path, "wb")
        self._writer = Writer(self._stream, chunk_size=chunk_size_bytes, compression=_COMPRESSION[compression])
        self._writer.start(profile="", library=f"fcsod {__version__}")
        self._schemas: dict[tuple[str, bytes], int] = {}
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self.finished = False

    def _channel(
        self,
        topic: str,
        name: str,
        schema: bytes,
        schema_encoding: str,
        message_encoding: str,
        metadata: dict[str, str] | None,
    ) -> int:
        if topic not in self._channels:
            key = (name, schema)
            if key not in self._schemas:
                self._schemas[key] = self._writer.register_schema(name=name, encoding=schema_encoding, data=schema)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding=message_encoding, schema_id=self._schemas[key], metadata=metadata or {}
            )
        return self._channels[topic]

    def write(self, topic: str, message: BaseModel, log_time_ns: int | None = None) -> None:
        """Record one message; the channel is registered on first use with the message model's schema."""
        model = type(message)
        self.write_raw(
            topic, schema_name(model), schema_text(model).encode(), message.model_dump_json().encode(), log_time_ns
        )

    def write_foxglove(self, topic: str, message, log_time_ns: int | None = None) -> bytes:
        """Record a foxglove-sdk message (``foxglove.messages.*``) as the SDK encodes it, under the SDK's own schema
        (protobuf); returns the encoded message.
        """
        schema = message.get_schema()
        data = message.encode()
        self.write_raw(topic, schema.name, schema.data, data, log_time_ns, schema.encoding, schema.encoding)
        return data

    def write_raw(
        self,
        topic: str,
        name: str,
        schema: bytes,
        data: bytes,
        log_time_ns: int | None = None,
        schema_encoding: str = "jsonschema",
        message_encoding: str = "json",
        metadata: dict[str, str] | None = None,
    ) -> None:
        """Record already-encoded ``data`` under a schema given by name and text.

        JSON with a JSON Schema by default; the ROS 2 channels pass ``ros2msg``
        and ``cdr`` (and channel ``metadata``, kept from a channel's first message).
        """
        channel = self._channel(topic, name, schema, schema_encoding, message_encoding, metadata)
        now = log_time_ns if log_time_ns is not None else time.time_ns()
        self._writer.add_message(channel_id=channel, log_time=now, data=data, publish_time=now, sequence=self._sequence)
        self._sequence += 1

    def flush(self) -> None:
        """Close the open chunk and push it to disk, so it survives a crash."""
        self._writer.flush()
        os.fsync(self._stream.fileno())

    def finish(self) -> None:
        """Write the summary and footer and close the file."""
        if self.finished:
            return
        self._writer.finish()
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self._stream.close()
        self.finished = True

    def close_unfinished(self) -> None:
        """Close the file without a summary (after a failure of the writer itself); never raises."""
        try:
            self._stream.close()
        except OSError:
            # closing flushes what the failed write left buffered: on a full disk that fails again, and the file is
            # abandoned anyway
            pass


@dataclass
class RecordedMessage:
    """A message read back from an MCAP file."""

    topic: str
    schema_name: str
    schema_data: bytes
    log_time_ns: int
    data: bytes
    schema_encoding: str = "jsonschema"
    message_encoding: str = "json"
    metadata: dict[str, str] = field(default_factory=dict)

    def json(self) -> dict:
        """The message body as a dict."""
        return json.loads(self.data)


@dataclass
class RecordContent:
    """What :func:`read_record` recovered from a file."""

    messages: list[RecordedMessage]
    channels: dict[str, str]
    truncated: bool
    problem: str | None

    def of(self, topic: str) -> list[dict]:
        """Bodies of the JSON messages on one channel, in order."""
        return [m.json() for m in self.messages if m.topic == topic and m.message_encoding == "json"]


def read_record(path: str | Path) -> RecordContent:
    """Read every message of a job record, also one cut off by a crash.

    Uses the non-seeking reader, which needs no summary section, so a file
    without footer yields every message up to its last complete chunk.

    Returns
    -------
    RecordContent
        Messages in file order, channel -> schema name, whether the file
        ended before its footer, and what stopped the reading if it did.
    """
    messages: list[RecordedMessage] = []
    channels: dict[str, str] = {}
    truncated, problem = False, None
    with open(path, "rb") as stream:
        reader = NonSeekingReader(stream)
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                channels[channel.topic] = schema.name if schema else ""
                messages.append(
                    RecordedMessage(
                        channel.topic,
                        schema.name if schema else "",
                        schema.data if schema else b"",
                        message.log_time,
                        message.data,
                        schema.encoding if schema else "",
                        channel.message_encoding,
                        dict(channel.metadata),
                    )
                )
        # the stream reader stops at the footer; anything raised before it
        # means the file was cut off (a short read surfaces as struct.error)
        except (McapError, EOFError, ValueError, OSError, struct.error) as exc:
            truncated, problem = True, f"{type(exc).__name__}: {exc}".strip()
    return RecordContent(messages, channels, truncated, problem)


def salvage(source: Path, target: Path, compression: str, chunk_size_bytes: int) -> Recorder:
    """Copy what a cut-off record holds into a new, open :class:`Recorder` so the caller can finish it.

    Parameters
    ----------
    source : Path
        The cut-off file (may be missing: the new record starts empty).
    target : Path
        The new file.

    Returns
    -------
    Recorder
        Open recorder holding every recovered message.
    """
    content = read_record(source) if source.is_file() else RecordContent([], {}, True, "no record was written")
    recorder = Recorder(target, compression, chunk_size_bytes)
    for message in content.messages:
        recorder.write_raw(
            message.topic,
            message.schema_name,
            message.schema_data,
            message.data,
            message.log_time_ns,
            message.schema_encoding,
            message.message_encoding,
            message.metadata,
        )
    return recorder
