"""The live Foxglove server (``[foxglove] enabled``): the scenes and statuses of jobs as they run, to the Foxglove app.

foxglove-sdk's WebSocket server in the daemon's process, with a context of
its own so nothing else of the process logs into it, behind a front that
speaks both subprotocols of the one Foxglove WebSocket protocol (v1): the
SDK's ``foxglove.sdk.v1`` (the Foxglove app) and ``foxglove.websocket.v1``
(the reference client ``@foxglove/ws-protocol``, Lichtblick, older Foxglove
Studio). The SDK's server accepts only the first and answers the others
HTTP 400, in every release, with no option to change it; the messages of the
two are the same, so the front (``websockets``) accepts either on
``[foxglove] listen`` and relays each client's frames, unchanged, to and from
a connection of its own to the SDK's server on a loopback port of its own.
Channels, advertised from the start so a client can subscribe before a job
runs:

- ``/scene``: ``foxglove.SceneUpdate`` (protobuf, the SDK's schema), the
  same bytes the job's worker recorded in ``job.mcap``;
- ``/tf``: ``foxglove.FrameTransforms``, the frames the scene is drawn in,
  likewise;
- ``/fcsod/status``: the zenoh status messages (JSON, fcsod's
  ``StatusMessage`` schema), every state change of every job;
- ``/fcsod/plan`` and ``/fcsod/verification``: the zenoh ``plan`` and
  ``verification[/<set>]`` messages (JSON, ``PlanMessage`` and
  ``VerificationMessage``), under the names their ROS 2 forms have in
  ``job.mcap`` with the default ``[ros2]`` node, so one layout
  (``deploy/foxglove-layout.json``) opens both.

Clients only watch: the server offers no services, parameters or publishing.
"""

from __future__ import annotations

import logging
import threading

import foxglove
from foxglove.messages import FrameTransforms, SceneUpdate
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect
from websockets.sync.server import ServerConnection, serve

from fcso.schema import schema_text

from ..bus.messages import BusMessage, PlanMessage, StatusMessage, VerificationMessage
from ..config import FoxgloveConfig, split_host_port
from ..record.recorder import TOPIC_SCENE, TOPIC_TRANSFORMS

#: The live server's JSON channels: native topic (its first level) -> channel and the model of its messages.
LIVE_JSON_CHANNELS = {
    "status": ("/fcsod/status", StatusMessage),
    "plan": ("/fcsod/plan", PlanMessage),
    "verification": ("/fcsod/verification", VerificationMessage),
}

#: The subprotocols the live server accepts, the preferred first: foxglove-sdk's, then the protocol's first name.
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")

log = logging.getLogger("fcsod")


class SubscriptionLog:
    """Logs Foxglove clients subscribing and unsubscribing (foxglove-sdk's ``ServerListener``; the SDK's thread)."""

    def on_subscribe(self, client, channel) -> None:
        log.info("Foxglove client subscribed", extra={"client_id": client.id, "topic": channel.topic})

    def on_unsubscribe(self, client, channel) -> None:
        log.info("Foxglove client unsubscribed", extra={"client_id": client.id, "topic": channel.topic})


def _pump(source, sink) -> None:
    """Send every frame of the WebSocket ``source`` on to ``sink`` until either closes, then close both."""
    try:
        for frame in source:
            sink.send(frame)
    except ConnectionClosed:
        pass
    finally:
        source.close()
        sink.close()


class FoxgloveLive:
    """The server and its channels; :meth:`close` stops it.

    Parameters
    ----------
    config : FoxgloveConfig
        Where to listen.
    """

    def __init__(self, config: FoxgloveConfig):
        host, port = split_host_port(config.listen)
        self.context = foxglove.Context()
        self.scene = foxglove.Channel(
            TOPIC_SCENE, schema=SceneUpdate.get_schema(), message_encoding="protobuf", context=self.context
        )
        self.transforms = foxglove.Channel(
            TOPIC_TRANSFORMS, schema=FrameTransforms.get_schema(), message_encoding="protobuf", context=self.context
        )
        self.json_channels = {
            native: foxglove.Channel(
                topic,
                schema=foxglove.Schema(
                    name=f"fcsod.{model.__name__}", encoding="jsonschema", data=schema_text(model).encode()
                ),
                message_encoding="json",
                context=self.context,
            )
            for native, (topic, model) in LIVE_JSON_CHANNELS.items()
        }
        self.server = foxglove.start_server(
            name="fcsod", host="127.0.0.1", port=0, context=self.context, server_listener=SubscriptionLog()
        )
        self.front = serve(self._relay, host, port, subprotocols=list(SUBPROTOCOLS), max_size=None, compression=None)
        threading.Thread(target=self.front.serve_forever, name="foxglove-front", daemon=True).start()

    def _relay(self, client: ServerConnection) -> None:
        """One client's connection: its frames to its own connection to the SDK's server and back (a front thread)."""
        with connect(
            f"ws://127.0.0.1:{self.server.port}", subprotocols=[SUBPROTOCOLS[0]], max_size=None, compression=None
        ) as sdk:
            back = threading.Thread(target=_pump, args=(sdk, client), daemon=True)
            back.start()
            _pump(client, sdk)
            back.join()

    def publish(self, message: BusMessage) -> None:
        """Send a status, plan or verification message on; other bus messages are not the live view's."""
        channel = self.json_channels.get(message.topic.partition("/")[0])
        if channel is not None:
            channel.log(message.payload)

    def log_scene(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send an encoded ``SceneUpdate`` or ``FrameTransforms`` a worker recorded on ``/scene`` or ``/tf``."""
        (self.scene if topic == TOPIC_SCENE else self.transforms).log(data, log_time=log_time_ns)

    def close(self) -> None:
        """Stop the front (its clients' connections close), then the SDK's server."""
        self.front.shutdown()
        self.server.stop()
