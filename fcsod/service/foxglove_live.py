"""The live Foxglove server (``[foxglove] enabled``): the scenes and statuses of jobs as they run, to the Foxglove app.

foxglove-sdk's WebSocket server (subprotocol ``foxglove.sdk.v1``) in the
daemon's process, with a context of its own so nothing else of the process
logs into it. Channels, advertised from the start so a client can subscribe
before a job runs:

- ``/scene``: ``foxglove.SceneUpdate`` (protobuf, the SDK's schema), the
  same bytes the job's worker recorded in ``job.mcap``;
- ``/fcsod/status``: the zenoh status messages (JSON, fcsod's
  ``StatusMessage`` schema), every state change of every job.

Clients only watch: the server offers no services, parameters or publishing.
"""

from __future__ import annotations

import logging

import foxglove
from foxglove.messages import SceneUpdate

from fcso.schema import schema_text

from ..bus.messages import BusMessage, StatusMessage
from ..config import FoxgloveConfig, split_host_port
from ..record.recorder import TOPIC_SCENE

#: The status channel of the live server.
TOPIC_LIVE_STATUS = "/fcsod/status"

log = logging.getLogger("fcsod")


class SubscriptionLog:
    """Logs Foxglove clients subscribing and unsubscribing (foxglove-sdk's ``ServerListener``; the SDK's thread)."""

    def on_subscribe(self, client, channel) -> None:
        log.info("Foxglove client subscribed", extra={"client_id": client.id, "topic": channel.topic})

    def on_unsubscribe(self, client, channel) -> None:
        log.info("Foxglove client unsubscribed", extra={"client_id": client.id, "topic": channel.topic})


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
        self.status = foxglove.Channel(
            TOPIC_LIVE_STATUS,
            schema=foxglove.Schema(
                name="fcsod.StatusMessage", encoding="jsonschema", data=schema_text(StatusMessage).encode()
            ),
            message_encoding="json",
            context=self.context,
        )
        self.server = foxglove.start_server(
            name="fcsod", host=host, port=port, context=self.context, server_listener=SubscriptionLog()
        )

    def publish(self, message: BusMessage) -> None:
        """Send a status message on; other bus messages are not the live view's."""
        if message.topic == "status":
            self.status.log(message.payload)

    def log_scene(self, data: bytes, log_time_ns: int) -> None:
        """Send an encoded ``SceneUpdate`` a worker recorded on ``/scene``."""
        self.scene.log(data, log_time=log_time_ns)

    def close(self) -> None:
        self.server.stop()
