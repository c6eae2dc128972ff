"""A running ring as named topics: what ``record``, ``play``, the web view and the Foxglove
bridge all read, so they show the same thing.

::

    Zenoh samples ──► Feed (its own thread) ──► FeedSource.translate() ──► Message ──► sinks
          │                                     FeedSource.poll()      ──►           (MCAP file,
          └─────────────────────────────────► RawSample (key, bytes)   ──► raw sinks  web view,
                                                                                      bridge)

A :class:`FeedSource` names the Zenoh keys it reads and the topics it writes, each topic with a
JSON Schema (messages are JSON objects). The ring's own source, :class:`RingSource`, covers
frames, decoded channels, the round trip, ring events and each node's counters and faults; an
extension adds its own (the robot's: poses, sonar, map) through
:meth:`tokenring.extensions.Extension.feed_sources`.

A feed only listens: it is a separate Zenoh session, and translation runs on the feed's thread,
never in Zenoh's callback, so nothing here can slow the token path.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import queue
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import msgpack
import zenoh

from tokenring._util.tables import json_default
from tokenring.contract import keys
from tokenring.contract.frame import frame_problem
from tokenring.contract.protocol import Channel, CommandChannel, Field, Protocol
from tokenring.contract.ring import RING_EVENT

log = logging.getLogger("tokenring.feed")


@dataclass(frozen=True)
class Topic:
    """A named stream of JSON messages of one schema (e.g. ``/ring/roundtrip``)."""

    name: str
    schema_name: str
    schema: dict[str, Any]
    doc: str = ""


@dataclass(frozen=True)
class Message:
    """One message on a topic; ``time_ns`` is the wall clock (ns since the epoch) it was seen."""

    topic: str
    time_ns: int
    data: dict[str, Any]

    @functools.cached_property
    def encoded(self) -> bytes:
        """``data`` as compact JSON bytes, encoded once for every sink that sends or stores it."""
        return json.dumps(self.data, separators=(",", ":"), default=json_default).encode()


@dataclass(frozen=True)
class RawSample:
    """One Zenoh sample exactly as it travelled: what ``play`` puts back on the same key."""

    key: str
    time_ns: int
    payload: bytes


class FeedSource:
    """Turns some Zenoh keys' samples (and periodic queries) into topic messages."""

    #: seconds between :meth:`poll` calls (0: never polled)
    poll_interval_s: float = 0.0

    def topics(self) -> list[Topic]:
        """Every topic this source may write."""
        return []

    def keys(self, ring: str) -> list[str]:
        """The Zenoh key expressions this source reads."""
        return []

    def translate(self, key: str, payload: bytes, time_ns: int) -> list[Message]:
        """The messages one sample on ``key`` makes (often none)."""
        return []

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        """Messages from asking the ring (queries), every :attr:`poll_interval_s` seconds."""
        return []


# --------------------------------------------------------------------------------------------
# JSON Schemas from protocol.yaml


def field_schema(spec: Field) -> dict[str, Any]:
    """A JSON Schema for one protocol field (integers, arrays of integers, text, floats)."""
    if spec.is_text:
        out: dict[str, Any] = {"type": "string"}
    else:
        base = spec.dtype.base if spec.dtype.subdtype is not None else spec.dtype
        scalar: dict[str, Any] = {"type": "number" if base.kind == "f" else "integer"}
        shape = spec.dtype.shape
        out = (
            {"type": "array", "items": scalar, "minItems": shape[0], "maxItems": shape[0]}
            if shape
            else scalar
        )
    described = ", ".join(
        p for p in (spec.unit and f"unit {spec.unit}", spec.enum and f"enum {spec.enum}", spec.doc) if p
    )
    if described:
        out["description"] = described
    return out


def channel_schema(channel: Channel) -> dict[str, Any]:
    """The JSON Schema of a channel's decoded message (``/channel/<name>``)."""
    properties = {f.name: field_schema(f) for f in channel.fields}
    if isinstance(channel, CommandChannel):
        properties["command"] = {"type": "string", "enum": sorted(channel.commands)}
        properties["args"] = {"type": "object"}
    return {
        "title": f"tokenring.{channel.name}",
        "type": "object",
        "properties": properties,
        "required": [f.name for f in channel.fields],
    }


# --------------------------------------------------------------------------------------------
# the ring's own topics

FRAME_SCHEMA: dict[str, Any] = {
    "title": "tokenring.Frame",
    "type": "object",
    "properties": {
        "did": {"type": "integer", "description": "the node the frame was passed to"},
        "sid": {"type": "integer"},
        "counter": {"type": "integer"},
        "epoch": {"type": "integer"},
        "crc_ok": {"type": "boolean"},
        "problem": {"type": "string"},
        "syscmd": {"type": "string"},
    },
    "required": ["did", "crc_ok"],
}
ROUNDTRIP_SCHEMA: dict[str, Any] = {
    "title": "tokenring.RoundTrip",
    "type": "object",
    "properties": {
        "ms": {"type": "number", "description": "since the token last reached the same node"},
        "node": {"type": "integer", "description": "where the ring wraps (the round counter's node)"},
    },
    "required": ["ms", "node"],
}
EVENT_SCHEMA: dict[str, Any] = {
    "title": "tokenring.RingEvent",
    "type": "object",
    "properties": {
        "kind": {
            "type": "string",
            "enum": ["excluded", "rejoin", "leaving", "regenerated", "stopping", "unknown"],
        },
        "node": {"type": "integer"},
        "by": {"type": "integer"},
        "epoch": {"type": "integer"},
        "origin": {"type": "integer"},
    },
    "required": ["kind", "node", "by"],
}
NODES_SCHEMA: dict[str, Any] = {
    "title": "tokenring.Nodes",
    "type": "object",
    "properties": {
        "nodes": {"type": "object", "description": "node ID -> its stats (the control plane's stats verb)"},
        "faults": {"type": "object", "description": "node ID -> its active faults"},
    },
    "required": ["nodes", "faults"],
}
EVENT_KINDS = {b"X": "excluded", b"J": "rejoin", b"L": "leaving", b"R": "regenerated", b"Q": "stopping"}


@dataclass
class RingSource(FeedSource):
    """Frames, decoded channels (when their bytes change), round trips, events, node counters.

    ``channels_decoded`` False leaves the channels undecoded (a watcher that only counts and
    captures frames); ``poll_interval_s`` 0 asks the nodes nothing (no ``/ring/nodes``): every
    question is answered by a node process between its token visits."""

    protocol: Protocol
    poll_interval_s: float = 0.5
    channels_decoded: bool = True
    _last_channel: dict[str, bytes] = field(default_factory=dict)
    _last_frame: bytes = b""
    _wraps: dict[int, tuple[int, int]] = field(default_factory=dict)  # node -> (time, counter)

    def channels(self) -> list[Channel]:
        return [ch for node in self.protocol.nodes.values() for ch in (node.command, node.data)]

    def topics(self) -> list[Topic]:
        out = [
            Topic("/ring/frame", "tokenring.Frame", FRAME_SCHEMA, "every frame's header and CRC verdict"),
            Topic("/ring/roundtrip", "tokenring.RoundTrip", ROUNDTRIP_SCHEMA, "the token's round trip"),
            Topic("/ring/event", "tokenring.RingEvent", EVENT_SCHEMA, "exclusions, rejoins, regenerations"),
            Topic("/ring/nodes", "tokenring.Nodes", NODES_SCHEMA, "per-node counters and active faults"),
        ]
        out += [
            Topic(
                f"/channel/{ch.name}",
                f"tokenring.{ch.name}",
                channel_schema(ch),
                f"{ch.name} when it changes",
            )
            for ch in self.channels()
            if self.channels_decoded
        ]
        return out

    def keys(self, ring: str) -> list[str]:
        return [keys.token(ring, "*"), keys.ring_event(ring)]

    def translate(self, key: str, payload: bytes, time_ns: int) -> list[Message]:
        if key.rsplit("/", 2)[-2] == "token":
            return self._frame(keys.id_from_key(key), payload, time_ns)
        if len(payload) == RING_EVENT.size:
            kind, node_id, by, epoch, origin = RING_EVENT.unpack(payload)
            data = {
                "kind": EVENT_KINDS.get(kind, "unknown"),
                "node": node_id,
                "by": by,
                "epoch": epoch,
                "origin": origin,
            }
            return [Message("/ring/event", time_ns, data)]
        return []

    def _frame(self, did: int | None, frame: bytes, time_ns: int) -> list[Message]:
        problem = frame_problem(frame, self.protocol)
        header: dict[str, Any] = {
            "did": did if did is not None else -1,
            "crc_ok": problem not in ("crc", "length"),
        }
        if problem:
            header["problem"] = problem
        if len(frame) != self.protocol.frame_size:
            return [Message("/ring/frame", time_ns, header)]
        offsets = self.protocol.header.offsets
        header.update(
            sid=frame[offsets["sid"]], counter=frame[offsets["counter"]], epoch=frame[offsets["epoch"]]
        )
        if frame[offsets["syscmd_issuer"]]:
            header["syscmd"] = self.protocol.system_command_name(frame[offsets["syscmd_code"]])
        out = [Message("/ring/frame", time_ns, header)]
        if frame == self._last_frame or problem:
            return out  # a repeated pass (late acknowledgement) or a damaged frame: nothing new
        self._last_frame = frame
        sid, counter = header["sid"], header["counter"]
        if did is not None and sid >= did:
            # the token reaches the node where the ring wraps: one round since the last such
            # arrival if the round counter moved on by one (none missed by this subscriber)
            before = self._wraps.get(did)
            self._wraps[did] = (time_ns, counter)
            if before is not None and (counter - before[1]) & 0xFF == 1:
                trip = {"ms": (time_ns - before[0]) / 1e6, "node": did}
                out.append(Message("/ring/roundtrip", time_ns, trip))
        if not self.channels_decoded:
            return out
        for ch in self.channels():
            raw = frame[ch.address : ch.end]
            if self._last_channel.get(ch.name) == raw:
                continue
            self._last_channel[ch.name] = raw
            decoded = ch.decode_command(frame) if isinstance(ch, CommandChannel) else ch.decode(frame)
            out.append(Message(f"/channel/{ch.name}", time_ns, decoded))
        return out

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        nodes, faults, _ = ask_nodes(session, ring, ["faults"])
        return [Message("/ring/nodes", time_ns, {"nodes": nodes, "faults": faults})]


def ask_nodes(
    session: Any, ring: str, extras: list[str], timeout: float = 0.5
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """Every answering node's ``stats`` by ID, and the ``extras`` it was asked to add (one
    question a node: ``faults``, ``system``) split off into their own tables by ID."""
    from tokenring.transport.session import query

    tables: dict[str, dict[str, Any]] = {"nodes": {}, "faults": {}, "system": {}}
    request = {"with": extras} if extras else None
    for _, reply in query(session, keys.control(ring, "*", "stats"), request, timeout=timeout):
        result = reply.get("result") if reply.get("ok") else None
        if not isinstance(result, dict) or "id" not in result:
            continue
        node_id = str(result["id"])
        for extra in extras:
            if extra in result:
                tables[extra][node_id] = result.pop(extra)
        tables["nodes"][node_id] = result
    return tables["nodes"], tables["faults"], tables["system"]


# --------------------------------------------------------------------------------------------
# the feed


MessageSink = Callable[[Message], None]
RawSink = Callable[[RawSample], None]


class Feed:
    """Reads every source's keys on one session and hands messages and raw samples to sinks.

    Sinks run on the feed's thread, in arrival order; a slow sink delays only the feed (the
    queue from Zenoh's callback is bounded and drops, counting ``dropped``, rather than grow).
    """

    def __init__(
        self, session: Any, ring: str, sources: Iterable[FeedSource], *, backlog: int = 65536
    ) -> None:
        self.session = session
        self.ring = ring
        self.sources = list(sources)
        self.dropped = 0
        self._queue: queue.Queue[RawSample | list[Message] | None] = queue.Queue(backlog)
        self._sinks: list[MessageSink] = []
        self._raw_sinks: list[RawSink] = []
        self._subscribers: list[Any] = []
        self._thread: threading.Thread | None = None
        self._poller: threading.Thread | None = None
        self._stop = threading.Event()
        self._routes: list[tuple[Any, FeedSource]] = [
            (zenoh.KeyExpr(expr), source) for source in self.sources for expr in source.keys(ring)
        ]

    def topics(self) -> list[Topic]:
        """Every topic of every source (names are unique)."""
        seen: dict[str, Topic] = {}
        for source in self.sources:
            for topic in source.topics():
                seen.setdefault(topic.name, topic)
        return list(seen.values())

    def add_sink(self, sink: MessageSink) -> None:
        self._sinks.append(sink)

    def add_raw_sink(self, sink: RawSink) -> None:
        self._raw_sinks.append(sink)

    def start(self) -> Feed:
        for expr in {str(k) for k, _ in self._routes}:
            self._subscribers.append(self.session.declare_subscriber(expr, self._on_sample))
        self._thread = threading.Thread(target=self._run, name="tokenring-feed", daemon=True)
        self._thread.start()
        if any(s.poll_interval_s > 0 for s in self.sources):
            self._poller = threading.Thread(target=self._poll, name="tokenring-feed-poll", daemon=True)
            self._poller.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        for subscriber in self._subscribers:
            with contextlib.suppress(Exception):  # the session may already be closed
                subscriber.undeclare()
        self._subscribers.clear()
        with contextlib.suppress(queue.Full):
            self._queue.put(None, timeout=2.0)
        for thread in (self._thread, self._poller):
            if thread is not None:
                thread.join(timeout=5.0)

    def __enter__(self) -> Feed:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _on_sample(self, sample: Any) -> None:
        try:
            self._queue.put_nowait(RawSample(str(sample.key_expr), time.time_ns(), sample.payload.to_bytes()))
        except queue.Full:
            self.dropped += 1

    def feed_raw(self, raw: RawSample) -> None:
        """Hand one sample to the sources and sinks as if it had just arrived (``play``, tests)."""
        for sink in self._raw_sinks:
            sink(raw)
        key = zenoh.KeyExpr(raw.key)
        for expr, source in self._routes:
            if expr.intersects(key):
                self._emit(source.translate(raw.key, raw.payload, raw.time_ns))

    def _emit(self, messages: list[Message]) -> None:
        for message in messages:
            for sink in self._sinks:
                try:
                    sink(message)
                except Exception:
                    log.exception("feed sink failed on %s", message.topic)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if isinstance(item, RawSample):
                self.feed_raw(item)
            else:
                self._emit(item)

    def _poll(self) -> None:
        """Queries on a thread of their own: a hung node's silent reply never holds up the feed."""
        next_poll = {id(s): 0.0 for s in self.sources if s.poll_interval_s > 0}
        while not self._stop.wait(0.05):
            now = time.monotonic()
            for source in self.sources:
                due = next_poll.get(id(source))
                if due is None or now < due:
                    continue
                next_poll[id(source)] = now + source.poll_interval_s
                try:
                    messages = source.poll(self.session, self.ring, time.time_ns())
                except Exception as exc:  # a ring that went away answers nothing; keep feeding
                    log.debug("poll failed: %s", exc)
                    continue
                if messages and not self._stop.is_set():
                    try:
                        self._queue.put_nowait(messages)
                    except queue.Full:
                        self.dropped += 1


def decode_msgpack(payload: bytes) -> Any:
    """msgpack payloads (the world's truth, control replies) as plain Python."""
    return msgpack.unpackb(payload, raw=False, strict_map_key=False)


def feed_sources(protocol: Protocol, ring: str) -> list[FeedSource]:
    """The ring's own feed source followed by every extension's."""
    from tokenring import extensions

    sources: list[FeedSource] = [RingSource(protocol)]
    for extension in extensions.loaded():
        sources += extension.feed_sources(protocol, ring)
    return sources
