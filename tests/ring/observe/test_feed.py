"""The ring's live feed (tokenring/observe/feed.py) on synthetic frames, and on a real ring.

The judge builds frames from protocol.yaml read as plain YAML and a bitwise CRC-16/ARC of its
own, so it shares no decoding code with the feed; every message is checked against its
topic's JSON Schema with the jsonschema package.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from tests.support.ringjudge import crc16_arc  # the judge's own CRC, not tokenring's
from tokenring.contract.protocol import default_protocol_path, load_protocol
from tokenring.observe.feed import Feed, Message, RawSample, RingSource

PROTOCOL_YAML = yaml.safe_load(Path(default_protocol_path()).read_text())


def make_frame(sid: int, did: int, counter: int, motor_x_mm: int = 0, motor_y_mm: int = 0) -> bytes:
    """A 514-byte frame with the header bytes and motor.data's x/y set, CRC appended."""
    header = PROTOCOL_YAML["token"]["header"]
    token = bytearray(PROTOCOL_YAML["token"]["size"])
    token[header["sid"]["offset"]] = sid
    token[header["did"]["offset"]] = did
    token[header["size_marker"]["offset"]] = header["size_marker"]["const"]
    token[header["counter"]["offset"]] = counter
    motor = PROTOCOL_YAML["nodes"]["motor"]["data"]
    assert list(motor["fields"])[:2] == ["x_mm", "y_mm"]  # the judge's own reading of the layout
    struct.pack_into("<ii", token, motor["address"], motor_x_mm, motor_y_mm)
    crc = crc16_arc(bytes(token))
    return bytes(token) + bytes([crc & 0xFF, crc >> 8])


class Collector:
    def __init__(self) -> None:
        self.messages: list[Message] = []

    def __call__(self, message: Message) -> None:
        self.messages.append(message)

    def on(self, topic: str) -> list[dict[str, Any]]:
        return [m.data for m in self.messages if m.topic == topic]


@pytest.fixture
def fed() -> tuple[Feed, Collector, RingSource]:
    source = RingSource(load_protocol())
    feed = Feed(None, "t", [source])  # fed by hand: no session
    collector = Collector()
    feed.add_sink(collector)
    return feed, collector, source


def test_frames_channels_and_round_trips(fed: tuple[Feed, Collector, RingSource]) -> None:
    feed, got, source = fed
    ring = [10, 20, 30]
    t = 1_000_000_000
    for lap in range(3):
        for i, did in enumerate(ring):
            sid = ring[i - 1]
            frame = make_frame(sid, did, lap, motor_x_mm=100 * lap, motor_y_mm=-7)
            feed.feed_raw(RawSample(f"tokenring/t/token/{did}", t, frame))
            t += 2_000_000  # 2 ms a hop: 6 ms a lap
    frames = got.on("/ring/frame")
    assert len(frames) == 9 and all(f["crc_ok"] for f in frames)
    assert [f["did"] for f in frames] == ring * 3 and [f["sid"] for f in frames][:3] == [30, 10, 20]
    # the round trip is measured at the lowest node: two full laps seen after the first
    assert [r["node"] for r in got.on("/ring/roundtrip")] == [10, 10]
    assert [round(r["ms"], 6) for r in got.on("/ring/roundtrip")] == [6.0, 6.0]
    # motor.data only when its bytes change: once per lap
    motor = got.on("/channel/motor.data")
    assert [(m["x_mm"], m["y_mm"]) for m in motor] == [(0, -7), (100, -7), (200, -7)]
    schemas = {topic.name: topic.schema for topic in source.topics()}
    for message in got.messages:
        jsonschema.validate(message.data, schemas[message.topic])


def test_round_trips_only_over_whole_rounds_seen_where_the_ring_wraps(
    fed: tuple[Feed, Collector, RingSource],
) -> None:
    """A new subscriber hears some senders before others, and may miss a frame: no round trip
    is then reported at the wrong node or over two rounds."""
    feed, got, _ = fed
    ring = [10, 20, 30, 40]
    t = 0
    for lap in range(6):
        for i, did in enumerate(ring):
            t += 1_000_000  # 1 ms a hop: 4 ms a lap
            if did != 10 or lap in (2, 4, 5):  # laps 0-1: not subscribed at 40 yet; lap 3: lost
                frame = make_frame(ring[i - 1], did, lap, motor_x_mm=lap * 10 + i)
                feed.feed_raw(RawSample(f"tokenring/t/token/{did}", t, frame))
    trips = got.on("/ring/roundtrip")
    # wraps heard at 10 in laps 2, 4 and 5: only 4 -> 5 is one round
    assert trips == [{"ms": 4.0, "node": 10}]


def test_a_damaged_or_repeated_frame_adds_nothing_but_its_header(
    fed: tuple[Feed, Collector, RingSource],
) -> None:
    feed, got, _ = fed
    frame = make_frame(10, 20, 1, motor_x_mm=5)
    feed.feed_raw(RawSample("tokenring/t/token/20", 1, frame))
    feed.feed_raw(RawSample("tokenring/t/token/20", 2, frame))  # a repeated pass
    broken = bytearray(make_frame(20, 30, 1, motor_x_mm=9))
    broken[100] ^= 0xFF
    feed.feed_raw(RawSample("tokenring/t/token/30", 3, bytes(broken)))
    frames = got.on("/ring/frame")
    assert [f.get("problem") for f in frames] == [None, None, "crc"] and not frames[2]["crc_ok"]
    assert [m["x_mm"] for m in got.on("/channel/motor.data")] == [5]


def test_ring_events_are_named(fed: tuple[Feed, Collector, RingSource]) -> None:
    feed, got, _ = fed
    feed.feed_raw(RawSample("tokenring/t/ring/event", 1, struct.pack("<cBBBB", b"X", 30, 20, 4, 20)))
    assert got.on("/ring/event") == [{"kind": "excluded", "node": 30, "by": 20, "epoch": 4, "origin": 20}]


def test_every_channel_has_a_topic_with_a_schema() -> None:
    topics = {t.name: t for t in RingSource(load_protocol()).topics()}
    for node, spec in PROTOCOL_YAML["nodes"].items():
        for kind in ("command", "data"):
            topic = topics[f"/channel/{node}.{kind}"]
            assert topic.schema["type"] == "object"
            if kind == "data":
                assert set(topic.schema["properties"]) == set(spec["data"]["fields"])
    for topic in topics.values():
        jsonschema.Draft202012Validator.check_schema(topic.schema)
