"""Eclipse Zenoh: the daemon's session, its publishers, the queryable for late joiners and the liveliness token.

Only the daemon's main process opens a session (a session does not survive
``fork``; workers never import this module).
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from pathlib import Path

import zenoh

from ..config import BusConfig, ZenohConfig
from .messages import BusMessage, StoredMessage, daemon_key, jobs_key

log = logging.getLogger("fcsod.bus")


def session_config(
    settings: ZenohConfig, listen: list[str] | None = None, connect: list[str] | None = None
) -> zenoh.Config:
    """A zenoh config: the config file if any, then the inline settings, then ``listen``/``connect`` overrides.

    Parameters
    ----------
    settings : ZenohConfig
        The ``[zenoh]`` section.
    listen, connect : list of str, optional
        Endpoints that replace the section's (command-line overrides).
    """
    config = zenoh.Config.from_file(str(settings.config_file)) if settings.config_file else zenoh.Config()
    if settings.mode is not None:
        config.insert_json5("mode", json.dumps(settings.mode))
    if settings.multicast_scouting is not None:
        config.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
    endpoints = {
        "listen": listen if listen is not None else settings.listen,
        "connect": connect if connect is not None else settings.connect,
    }
    for kind, values in endpoints.items():
        if values is not None:
            config.insert_json5(f"{kind}/endpoints", json.dumps(values))
    return config


def open_session(
    settings: ZenohConfig, listen: list[str] | None = None, connect: list[str] | None = None
) -> zenoh.Session:
    """Open a zenoh session from the ``[zenoh]`` section (see :func:`session_config`)."""
    return zenoh.open(session_config(settings, listen, connect))


def put(session: zenoh.Session, message: BusMessage) -> None:
    """Publish one message reliably, blocking rather than dropping when the link is congested."""
    publisher = session.declare_publisher(
        message.key_expr,
        encoding=zenoh.Encoding(message.encoding),
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )
    try:
        publisher.put(message.payload, attachment=message.attachment)
    finally:
        publisher.undeclare()


class Bus:
    """The daemon's presence on zenoh.

    Declares the liveliness token ``<prefix>/<cell>/daemon`` and a queryable
    on ``<prefix>/<cell>/jobs/**`` that answers from the stored messages
    (design payloads are read from the job's output folder).

    Parameters
    ----------
    bus : BusConfig
        Prefix and cell.
    settings : ZenohConfig
        Session settings.
    stored : callable
        The latest message of every topic of every job (the journal's), read at each query.
    """

    def __init__(self, bus: BusConfig, settings: ZenohConfig, stored: Callable[[], list[StoredMessage]]):
        self.bus = bus
        self.stored = stored
        self.session = open_session(settings)
        self._lock = threading.Lock()
        self._token = self.session.liveliness().declare_token(daemon_key(bus.prefix, bus.cell))
        self._queryable = self.session.declare_queryable(jobs_key(bus.prefix, bus.cell), self._answer, complete=True)

    def publish(self, message: BusMessage) -> None:
        """Publish one job message."""
        with self._lock:
            put(self.session, message)

    def _answer(self, query: zenoh.Query) -> None:
        """Reply with every stored message whose key the query's key expression intersects."""
        wanted = query.key_expr
        try:
            for stored in self.stored():
                if not wanted.intersects(zenoh.KeyExpr(stored.key_expr)):
                    continue
                payload = stored.payload
                if stored.file is not None:
                    path = Path(stored.file)
                    if not path.is_file():
                        continue
                    payload = path.read_bytes()
                attachment = stored.attachment.encode() if stored.attachment is not None else None
                query.reply(stored.key_expr, payload, encoding=zenoh.Encoding(stored.encoding), attachment=attachment)
        except Exception as exc:  # a failing reply must not kill zenoh's callback thread
            log.error("queryable: cannot answer %s: %s", wanted, exc)
            query.reply_err(f"fcsod cannot answer: {exc}")

    def close(self) -> None:
        """Undeclare everything and close the session."""
        self._queryable.undeclare()
        self._token.undeclare()
        self.session.close()
