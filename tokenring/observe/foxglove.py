"""A running ring's feed on a Foxglove WebSocket server: connect Foxglove to ``ws://host:port``.

::

    Feed (tokenring.observe.feed) ──► FoxgloveBridge (a feed sink) ──► foxglove-sdk server ──► Foxglove
                               one channel per feed topic,      (its own Rust threads)
                               schema = the topic's JSON Schema

Every topic of the feed becomes one JSON channel whose schema is the topic's JSON Schema under
the topic's schema name, so the well-known ``foxglove.*`` shapes an application publishes (the
robot's poses, map, walls) are drawn by Foxglove without configuration.

The bridge keeps its channels in a private :class:`foxglove.Context`: an MCAP writer opened on
the SDK's global context in the same process (``foxglove.open_mcap``) never receives them, and
the bridge never writes a file. A message is encoded only while some client is subscribed to
its channel. A client that subscribes is sent the last message of that topic at once, with its
original time (as a latched topic in ROS): the room's walls, the map so far and the node table
appear without waiting for them to change.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Iterable
from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener

from tokenring.errors import UsageError
from tokenring.observe.defaults import FOXGLOVE_PORT
from tokenring.observe.feed import Message, Topic

log = logging.getLogger("tokenring.foxglove")

DEFAULT_PORT = FOXGLOVE_PORT


class FoxgloveBridge:
    """A :class:`tokenring.observe.feed.Feed` sink serving every feed topic over the Foxglove WebSocket
    protocol (``foxglove-sdk``); call it with each :class:`~tokenring.observe.feed.Message`."""

    def __init__(
        self,
        topics: Iterable[Topic],
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        name: str = "",
        port_option: str = "--port",
    ) -> None:
        self.context = foxglove.Context()  # private: no MCAP sink of the global context sees us
        self.counts: dict[str, int] = {}
        self.subscriptions = 0
        self._lock = threading.Lock()
        self._last: dict[str, Message] = {}
        self._channels: dict[str, Any] = {}
        self._by_id: dict[int, str] = {}
        try:
            self.server = foxglove.start_server(
                name=name or "tokenring",
                host=host,
                port=port,
                context=self.context,
                server_listener=_Listener(self),
            )
        except RuntimeError as exc:  # the SDK's FoxgloveError: bind or address lookup failed
            reason = str(exc).removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
            raise UsageError(
                f"--host {host} {port_option} {port}: cannot serve Foxglove there ({reason})"
            ) from None
        for topic in topics:
            self._channel(topic)

    @property
    def topics(self) -> list[str]:
        """The topics served (one channel each)."""
        return list(self._channels)

    @property
    def port(self) -> int:
        """The port the server listens on (the one the OS chose for port 0)."""
        return int(self.server.port)

    def _channel(self, topic: Topic) -> Any:
        channel = self._channels.get(topic.name)
        if channel is None:
            schema = foxglove.Schema(
                name=topic.schema_name, encoding="jsonschema", data=json.dumps(topic.schema).encode("utf-8")
            )
            channel = foxglove.Channel(
                topic.name, schema=schema, message_encoding="json", context=self.context
            )
            self._channels[topic.name] = channel
            self._by_id[int(channel.id())] = topic.name
        return channel

    def __call__(self, message: Message) -> None:
        """Publish one feed message (the feed's thread); cheap while nobody is subscribed."""
        channel = self._channels.get(message.topic)
        if channel is None:  # a topic no source declared: publish it schemaless rather than lose it
            channel = self._channel(Topic(message.topic, "", {}))
        with self._lock:
            self._last[message.topic] = message
        if channel.has_sinks():
            channel.log(message.encoded, log_time=message.time_ns)
            self.counts[message.topic] = self.counts.get(message.topic, 0) + 1

    def replay(self, channel_id: int) -> None:
        """Send the last message of a channel again (with its original time): a new subscriber
        sees the state of a topic that changes rarely (walls, map, node table) at once."""
        topic = self._by_id.get(channel_id)
        if topic is None:
            return
        with self._lock:
            last = self._last.get(topic)
        if last is not None:
            self._channels[topic].log(last.encoded, log_time=last.time_ns)

    def close(self) -> None:
        """Stop the server (clients see the connection close) and close the channels."""
        self.server.stop()
        for channel in self._channels.values():
            channel.close()


class _Listener(ServerListener):
    """The SDK's server callbacks (its threads): subscriptions counted, last message replayed."""

    def __init__(self, bridge: FoxgloveBridge) -> None:
        self.bridge = bridge

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.bridge.subscriptions += 1
        log.debug("client %s subscribed to %s", client.id, channel.topic)
        try:
            self.bridge.replay(int(channel.id))
        except Exception:  # never let a replay break the SDK's callback
            log.exception("replaying %s failed", channel.topic)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        log.debug("client %s unsubscribed from %s", client.id, channel.topic)
