"""The robot's topics in the live feed (modules/pc/feed.py), on synthetic samples and a real ring.

The judge packs frames from protocol.yaml read as plain YAML with ``struct`` and a bitwise
CRC-16/ARC of its own, works out expected poses, quaternions and beam ends by hand, and checks
every message against its topic's JSON Schema with the jsonschema package; the field names of
Foxglove's messages are written out here from Foxglove's documentation.
"""

from __future__ import annotations

import base64
import json
import math
import struct
import time
from pathlib import Path
from typing import Any

import jsonschema
import msgpack
import pytest
import yaml

from modules.pc.feed import (
    LcdSource,
    LocalizationSource,
    MainSource,
    RobotSource,
    WorldSource,
    robot_feed_sources,
    walls_messages,
)
from tests.support.ringjudge import crc16_arc  # the judge's own CRC, not tokenring's
from tests.support.ringutil import tap, wait_until
from tokenring.contract.protocol import default_protocol_path, load_protocol
from tokenring.host.pclink import PcLink
from tokenring.observe.feed import Feed, Message, RawSample, feed_sources

PROTOCOL_YAML = yaml.safe_load(Path(default_protocol_path()).read_text())
T0 = 1_700_000_000_123_456_789  # ns: sec 1700000000, nsec 123456789
FORMATS = {"u8": "B", "i8": "b", "u16": "H", "i16": "h", "u32": "I", "i32": "i", "u64": "Q", "i64": "q"}


def _type(spec: Any) -> str:
    return spec["type"] if isinstance(spec, dict) else spec


def _pack_fields(token: bytearray, at: int, fields: dict[str, Any], values: dict[str, Any]) -> int:
    """Pack ``values`` into consecutive fields starting at ``at``; returns the end offset."""
    for name, spec in fields.items():
        kind = _type(spec)
        if "[" in kind:
            base, count = kind.rstrip("]").split("[")
            fmt = f"<{count}s" if base == "str" else f"<{count}{FORMATS[base]}"
            value = values.get(name, b"" if base == "str" else [0] * int(count))
            struct.pack_into(fmt, token, at, *([value] if base == "str" else value))
        else:
            fmt = "<" + FORMATS[kind]
            struct.pack_into(fmt, token, at, values.get(name, 0))
        at += struct.calcsize(fmt)
    return at


class Token:
    """A token the judge fills channel by channel from protocol.yaml."""

    def __init__(self) -> None:
        self.token = bytearray(PROTOCOL_YAML["token"]["size"])
        header = PROTOCOL_YAML["token"]["header"]
        self.token[header["size_marker"]["offset"]] = header["size_marker"]["const"]

    def data(self, node: str, **values: Any) -> Token:
        spec = PROTOCOL_YAML["nodes"][node]["data"]
        assert set(values) <= set(spec["fields"]), set(values) - set(spec["fields"])
        _pack_fields(self.token, spec["address"], spec["fields"], values)
        return self

    def command(self, node: str, name: str, state: int = 1, **header_and_args: Any) -> Token:
        spec = PROTOCOL_YAML["nodes"][node]["command"]
        commands = {**PROTOCOL_YAML["common_commands"], **spec["commands"]}
        cmd = commands[name]
        head = PROTOCOL_YAML["command_channel"]["header"]
        values = {**header_and_args, "state": state, "code": cmd["code"]}
        end = _pack_fields(self.token, spec["address"], head, values)
        _pack_fields(self.token, end, cmd.get("args", {}), header_and_args)
        return self

    def frame(self, sid: int = 50, did: int = 60) -> bytes:
        header = PROTOCOL_YAML["token"]["header"]
        self.token[header["sid"]["offset"]] = sid
        self.token[header["did"]["offset"]] = did
        crc = crc16_arc(bytes(self.token))
        return bytes(self.token) + bytes([crc & 0xFF, crc >> 8])


class Fed:
    """A feed of the robot's sources fed by hand (no session), collecting every message."""

    def __init__(self) -> None:
        self.protocol = load_protocol()
        self.sources = robot_feed_sources(self.protocol, "t")
        self.feed = Feed(None, "t", self.sources)
        self.messages: list[Message] = []
        self.feed.add_sink(self.messages.append)
        self.t = T0

    def frame(self, token: Token) -> None:
        self.t += 1_000_000
        self.feed.feed_raw(RawSample("tokenring/t/token/60", self.t, token.frame()))

    def truth(self, x_mm: float, y_mm: float, theta_rad: float) -> None:
        self.t += 1_000_000
        payload = msgpack.packb({"stamp_ms": 5, "x_mm": x_mm, "y_mm": y_mm, "theta_rad": theta_rad})
        self.feed.feed_raw(RawSample("tokenring/t/world/truth", self.t, payload))

    def on(self, topic: str) -> list[dict[str, Any]]:
        return [m.data for m in self.messages if m.topic == topic]

    def all_valid(self) -> None:
        schemas = {t.name: t.schema for t in self.feed.topics()}
        assert self.messages
        for message in self.messages:
            jsonschema.validate(message.data, schemas[message.topic])
            json.dumps(message.data)  # plain JSON values only


@pytest.fixture
def fed() -> Fed:
    return Fed()


def assert_pose(message: dict[str, Any], x_m: float, y_m: float, theta: float) -> None:
    """A PoseInFrame in the room at (x, y) facing theta (CCW from +x): q = (0, 0, sin, cos)(theta/2)."""
    assert message["frame_id"] == "room"
    position, q = message["pose"]["position"], message["pose"]["orientation"]
    assert position == pytest.approx({"x": x_m, "y": y_m, "z": 0.0}, abs=1e-9)
    expected = {"x": 0.0, "y": 0.0, "z": math.sin(theta / 2), "w": math.cos(theta / 2)}
    flipped = {k: -v for k, v in expected.items()}  # q and -q are the same rotation
    assert q == pytest.approx(expected, abs=1e-9) or q == pytest.approx(flipped, abs=1e-9), q


def test_true_odometry_and_filtered_poses_in_the_room_frame(fed: Fed) -> None:
    fed.truth(1200.0, 800.0, 2.0)
    # motor: 9000 cdeg on the wire is 90 degrees clockwise: -pi/2 counter-clockwise
    fed.frame(Token().data("motor", x_mm=1500, y_mm=-250, angle_cdeg=9000))
    # copro with dead reckoning only: no filtered pose, tf follows odometry
    fed.frame(Token().data("motor", x_mm=1500, y_mm=-250, angle_cdeg=9000).data("copro", pose_source=1))
    assert fed.on("/robot/pose/filtered") == [] and fed.on("/robot/uncertainty") == []
    # copro with the EKF: 33000 cdeg clockwise is +30 degrees counter-clockwise
    ekf = dict(pose_source=2, pose_x_mm=1210, pose_y_mm=790, pose_angle_cdeg=33000)
    sigmas = dict(sigma_x_mm=25, sigma_y_mm=30, sigma_angle_cdeg=150)
    fed.frame(Token().data("motor", x_mm=1500, y_mm=-250, angle_cdeg=9000).data("copro", **ekf, **sigmas))
    fed.frame(Token().data("motor", x_mm=1510, y_mm=-250, angle_cdeg=9000).data("copro", **ekf, **sigmas))

    (true,) = fed.on("/robot/pose/true")
    assert_pose(true, 1.2, 0.8, 2.0)
    assert true["timestamp"] == {"sec": 1_700_000_000, "nsec": 123_456_789 + 1_000_000}
    odometry = fed.on("/robot/pose/odometry")
    assert len(odometry) == 2  # motor.data changed twice (the repeats add nothing)
    assert_pose(odometry[0], 1.5, -0.25, -math.pi / 2)
    assert_pose(odometry[1], 1.51, -0.25, -math.pi / 2)
    (filtered,) = fed.on("/robot/pose/filtered")
    assert_pose(filtered, 1.21, 0.79, math.radians(30))
    (sigma,) = fed.on("/robot/uncertainty")
    assert sigma["source"] == "ekf"
    assert (sigma["sigma_x_m"], sigma["sigma_y_m"]) == pytest.approx((0.025, 0.030))
    assert sigma["sigma_theta_rad"] == pytest.approx(math.radians(1.5))
    # tf: odometry while there is no filter, the filter's pose once there is (not odometry then)
    tf = fed.on("/robot/tf")
    assert [v for t in tf for v in (t["translation"]["x"], t["translation"]["y"])] == pytest.approx(
        [1.5, -0.25, 1.21, 0.79]
    )
    assert all(t["parent_frame_id"] == "room" and t["child_frame_id"] == "robot" for t in tf)
    assert tf[1]["rotation"] == filtered["pose"]["orientation"]
    fed.all_valid()


def test_sonar_beams_start_at_their_mounts_and_end_at_the_echo(fed: Fed) -> None:
    fed.truth(1000.0, 2000.0, math.pi / 2)  # facing +y: forward is +y, left is -x
    distances = [50, 255, 255, 255, 255, 80, 255, 255]
    fed.frame(Token().data("sonar", distances=distances))
    (beams,) = fed.on("/robot/sonar/beams")
    assert beams["pose"] == "true" and beams["distances_cm"] == distances
    assert beams["contact"] == [d != 255 for d in distances]
    c45 = math.sqrt(0.5)
    # pair 0, front-left: 133 mm forward, 133 mm left, looking 45 degrees left of forward
    start = (1000.0 - 133.0, 2000.0 + 133.0)
    end = (start[0] - 500.0 * c45, start[1] + 500.0 * c45)
    assert beams["segments_m"][0] == pytest.approx([v / 1000 for v in (*start, *end)])
    # pair 5, rear: 188 mm behind, looking backwards (-y), echo at 80 cm
    assert beams["segments_m"][5] == pytest.approx([1.0, 1.812, 1.0, 1.812 - 0.8])
    # pair 1, front, no contact: drawn to the 1.5 m range limit
    assert beams["segments_m"][1] == pytest.approx([1.0, 2.188, 1.0, 2.188 + 1.5])
    (update,) = fed.on("/robot/sonar")
    (entity,) = update["entities"]
    assert entity["frame_id"] == "room" and entity["id"] == "sonar"
    hits = entity["lines"][0]
    assert hits["type"] == 2  # LINE_LIST: each pair of points is one segment
    assert len(hits["points"]) == 4  # two beams with an echo
    assert hits["points"][3] == pytest.approx({"x": 1.0, "y": 1.012, "z": 0.0})
    fed.all_valid()


def vector(seq: int, x1: int, y1: int, x2: int, y2: int, state: int = 1, incarnation: int = 777) -> Token:
    return Token().command(
        "map", "VECTOR", state, sender=50, seq=seq, incarnation=incarnation, x1=x1, y1=y1, x2=x2, y2=y2
    )


@pytest.mark.slow
def test_the_map_accumulates_vectors_once_each_and_clears(fed: Fed) -> None:
    fed.frame(vector(1, 10, 20, 110, 20))
    fed.frame(vector(1, 10, 20, 110, 20, state=2))  # the map's acknowledgement: the same command
    fed.frame(vector(2, 110, 20, 110, -35))
    fed.frame(Token())  # the channel freed
    fed.frame(vector(2, 110, 20, 110, -35))  # an old copy of seq 2 seen again: not a new vector
    fed.frame(vector(1, 0, 0, 5, 5, incarnation=778))  # copro restarted: a new command
    maps = fed.on("/robot/map/vectors")
    assert maps == [
        {"vectors": [[100.0, 200.0, 1100.0, 200.0]]},
        {"vectors": [[100.0, 200.0, 1100.0, 200.0], [1100.0, 200.0, 1100.0, -350.0]]},
        {"vectors": [[100.0, 200.0, 1100.0, 200.0], [1100.0, 200.0, 1100.0, -350.0], [0.0, 0.0, 50.0, 50.0]]},
    ]
    scene = fed.on("/robot/map")[-1]["entities"][0]
    assert scene["id"] == "map" and scene["frame_id"] == "room"
    (lines,) = scene["lines"]
    assert [v for p in lines["points"] for v in (p["x"], p["y"])] == pytest.approx(
        [0.1, 0.2, 1.1, 0.2, 1.1, 0.2, 1.1, -0.35, 0.0, 0.0, 0.05, 0.05]
    )
    fed.frame(Token().command("map", "CLEAR_MAP", sender=10, seq=1, incarnation=9))
    assert fed.on("/robot/map/vectors")[-1] == {"vectors": []}
    assert fed.on("/robot/map")[-1]["entities"][0]["lines"][0]["points"] == []
    fed.frame(vector(3, 1, 2, 3, 4))
    assert fed.on("/robot/map/vectors")[-1] == {"vectors": [[10.0, 20.0, 30.0, 40.0]]}
    fed.all_valid()


def test_a_damaged_frame_and_channels_nobody_wrote_yet_are_ignored(fed: Fed) -> None:
    broken = bytearray(Token().data("motor", x_mm=5, stamp_ms=3).frame())
    broken[200] ^= 0x55
    fed.feed.feed_raw(RawSample("tokenring/t/token/20", T0, bytes(broken)))
    assert fed.messages == []
    fed.truth(800.0, 800.0, 0.0)
    fed.frame(Token())  # the fresh token: motor and sonar have written nothing (all zero bytes)
    assert [m.topic for m in fed.messages] == ["/robot/pose/true", "/robot/navigator"]
    fed.frame(Token().data("motor", x_mm=800, y_mm=800, stamp_ms=3))
    assert_pose(fed.on("/robot/pose/odometry")[0], 0.8, 0.8, 0.0)


def test_navigator_names_from_the_protocol_and_only_on_change(fed: Fed) -> None:
    enums = PROTOCOL_YAML["enums"]
    main = dict(navigator=enums["navigator"]["FOLLOW_WALL"], explore_mode=2, steps_done=12)
    main |= dict(abort_reason=enums["abort_reason"]["CLOSE"], alert_lock=enums["direction"]["TURN_LEFT"])
    fed.frame(Token().data("main", **main, stamp_ms=100))
    fed.frame(Token().data("main", **main, stamp_ms=200))  # only the time stamp moved on
    fed.frame(Token().data("main", **(main | {"steps_done": 13}), stamp_ms=300))
    got = fed.on("/robot/navigator")
    assert got[0] == {
        "state": "FOLLOW_WALL",
        "explore_mode": 2,
        "abort_reason": "CLOSE",
        "alert_lock": "TURN_LEFT",
        "steps_done": 12,
        "stamp_ms": 100,
    }
    assert [g["steps_done"] for g in got] == [12, 13]
    fed.all_valid()


def test_walls_and_obstacles_from_the_worlds_info() -> None:
    info = {"name": "box", "walls": [[0, 0, 4000, 0], [4000, 0, 4000, 3000]], "circles": [[2000, 1000, 250]]}
    messages = {m.topic: m.data for m in walls_messages(info, T0)}
    vectors = messages["/robot/walls/vectors"]["vectors"]
    assert vectors[:2] == [[0, 0, 4000, 0], [4000, 0, 4000, 3000]]
    ring = vectors[2:]
    assert len(ring) >= 16  # the circle as a polygon, every corner on it, closed
    for x1, y1, x2, y2 in ring:
        assert math.hypot(x1 - 2000, y1 - 1000) == pytest.approx(250)
        assert math.hypot(x2 - 2000, y2 - 1000) == pytest.approx(250)
    assert ring[-1][2:] == pytest.approx(ring[0][:2])
    (entity,) = messages["/robot/walls"]["entities"]
    assert [(p["x"], p["y"]) for p in entity["lines"][0]["points"]] == [(0, 0), (4, 0), (4, 0), (4, 3)]
    (cylinder,) = entity["cylinders"]
    assert cylinder["pose"]["position"]["x"] == 2.0 and cylinder["pose"]["position"]["y"] == 1.0
    assert cylinder["size"]["x"] == cylinder["size"]["y"] == 0.5
    schemas = {t.name: t.schema for t in WorldSource(load_protocol()).topics()}
    for topic, data in messages.items():
        jsonschema.validate(data, schemas[topic])


def test_the_lcd_screen_as_an_image(fed: Fed) -> None:
    screen = bytearray(1024)  # 64 rows of 16 bytes, the leftmost pixel in the top bit
    screen[0] = 0b1000_0001  # row 0: pixels 0 and 7 lit
    screen[1023] = 0b0000_0001  # row 63: pixel 127 lit
    fed.feed.feed_raw(RawSample("tokenring/t/lcd/screen", T0, bytes(screen)))
    fed.feed.feed_raw(RawSample("tokenring/t/lcd/screen", T0, b"short"))  # not a screen
    (image,) = fed.on("/robot/lcd/image")
    assert (image["width"], image["height"], image["step"], image["encoding"]) == (128, 64, 128, "mono8")
    pixels = base64.b64decode(image["data"])
    assert len(pixels) == 128 * 64
    dark = [i for i, p in enumerate(pixels) if p == 0]
    assert dark == [0, 7, 64 * 128 - 1] and set(pixels) == {0, 255}
    fed.all_valid()


# Foxglove's messages as its documentation lists their fields
FOXGLOVE_FIELDS = {
    "foxglove.PoseInFrame": {"timestamp", "frame_id", "pose"},
    "foxglove.FrameTransform": {"timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"},
    "foxglove.SceneUpdate": {"deletions", "entities"},
    "foxglove.RawImage": {"timestamp", "frame_id", "width", "height", "encoding", "step", "data"},
}
SCENE_ENTITY_FIELDS = {
    "timestamp", "frame_id", "id", "lifetime", "frame_locked", "metadata", "arrows", "cubes",
    "spheres", "cylinders", "lines", "triangles", "texts", "models",
}  # fmt: skip
LINE_FIELDS = {"type", "pose", "thickness", "scale_invariant", "points", "color", "colors", "indices"}


def test_topics_carry_foxgloves_schemas_under_foxgloves_names() -> None:
    protocol = load_protocol()
    topics = {t.name: t for s in robot_feed_sources(protocol, "t") for t in s.topics()}
    for name in ("/robot/pose/true", "/robot/pose/odometry", "/robot/pose/filtered"):
        assert topics[name].schema_name == "foxglove.PoseInFrame"
    assert topics["/robot/tf"].schema_name == "foxglove.FrameTransform"
    for name in ("/robot/sonar", "/robot/map", "/robot/walls"):
        assert topics[name].schema_name == "foxglove.SceneUpdate"
    assert topics["/robot/lcd/image"].schema_name == "foxglove.RawImage"
    for topic in topics.values():
        jsonschema.Draft202012Validator.check_schema(topic.schema)
        if topic.schema_name in FOXGLOVE_FIELDS:
            assert topic.schema["title"] == topic.schema_name
            assert set(topic.schema["required"]) == FOXGLOVE_FIELDS[topic.schema_name]
    pose = topics["/robot/pose/true"].schema["properties"]
    assert pose["timestamp"]["properties"]["nsec"]["maximum"] == 999_999_999
    assert set(pose["pose"]["properties"]["orientation"]["required"]) == {"x", "y", "z", "w"}
    entity = topics["/robot/map"].schema["properties"]["entities"]["items"]
    assert set(entity["required"]) == SCENE_ENTITY_FIELDS
    assert set(entity["properties"]["lines"]["items"]["required"]) == LINE_FIELDS
    # a message missing a field, or with a string for a number, is refused by the schema
    bad = {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": "room", "pose": {"position": {"x": 1}}}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, topics["/robot/pose/true"].schema)
    # the ring's extension hands the robot's sources to every feed, after the ring's own
    names = [type(s).__name__ for s in feed_sources(protocol, "t")]
    assert names[0] == "RingSource" and {"RobotSource", "WorldSource", "LcdSource"} <= set(names)
    robot = {RobotSource, WorldSource, LcdSource, LocalizationSource, MainSource}
    assert robot == {type(s) for s in robot_feed_sources(protocol, "t")}


# --------------------------------------------------------------------------------------------
# a real ring


def _heading(message: dict[str, Any]) -> float:
    q = message["pose"]["orientation"]
    return 2 * math.atan2(q["z"], q["w"])


def _nearest(messages: list[Message], t: int) -> Message:
    return min(messages, key=lambda m: abs(m.time_ns - t))


def explored_enough(messages: list[Message]) -> bool:
    """The feed holds, with room to spare, what the test below judges of an exploring ring."""
    seen: dict[str, int] = {}
    contact = False
    vectors = 0
    for m in list(messages):
        seen[m.topic] = seen.get(m.topic, 0) + 1
        if m.topic == "/robot/sonar/beams":
            contact = contact or any(m.data["contact"])
        elif m.topic == "/channel/map.data":
            vectors = m.data["vector_count"]
    topics = ("/robot/sonar", "/robot/tf", "/robot/walls", "/robot/lcd", "/robot/navigator")
    return (
        contact
        and vectors >= 1
        and min(seen.get("/robot/pose/true", 0), seen.get("/robot/pose/odometry", 0)) > 60
        and seen.get("/robot/pose/filtered", 0) not in range(1, 20)  # none (no EKF) or plenty
        and all(seen.get(topic) for topic in topics)
    )


@pytest.mark.slow
def test_a_feed_on_an_exploring_ring_sees_poses_sonar_and_the_map(procs, ring_name, endpoint, tmp_path):
    out = tmp_path / "map.json"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "office", "--speed", "20",
        "--bitrate", "max", "--explore", "2", "--duration", "400", "--map-out", str(out),
    )  # fmt: skip  # --duration: a hang guard; exploring is stopped once the feed has seen enough
    protocol = load_protocol()
    session = None
    messages: list[Message] = []
    try:
        session = wait_until(lambda: _try_tap(endpoint), 30, "the ring's endpoint")
        feed = Feed(session, ring_name, feed_sources(protocol, ring_name))
        feed.add_sink(messages.append)
        with feed:
            # Explore 2 runs (past the compass's calibration) until the feed has seen more than
            # is judged below; Stop then ends it as --duration's end would: the mission fetches
            # the map, writes it and stops the ring
            link = PcLink(session, ring_name, timeout=10)
            wait_until(lambda: explored_enough(messages), 240, "the feed to see the robot explore", 0.5)
            wait_until(lambda: link.request("state")["mode"] == 2, 120, "Explore 2 running (calibrated)")
            link.request("stop")
            output, _ = launcher.communicate(timeout=150)
        assert launcher.returncode == 0, output[-3000:]
        assert feed.dropped == 0
    finally:
        if session is not None:
            session.close()

    def on(topic: str) -> list[Message]:
        return [m for m in messages if m.topic == topic]

    true, odometry, filtered = on("/robot/pose/true"), on("/robot/pose/odometry"), on("/robot/pose/filtered")
    assert len(true) > 50 and len(odometry) > 50 and on("/robot/sonar") and on("/robot/tf")
    assert on("/robot/walls") and on("/robot/lcd") and on("/robot/navigator")
    assert any(b.data["contact"].count(True) for b in on("/robot/sonar/beams"))
    # the feed was there before the first vector: main's map was still empty when it started
    first_map = on("/channel/map.data")[0].data
    assert first_map["vector_count"] == 0, first_map
    # the feed's map is the map module's: as many vectors as it reports holding at the end ...
    seen = on("/robot/map/vectors")[-1].data["vectors"]
    assert len(seen) == on("/channel/map.data")[-1].data["vector_count"]
    # ... and the map handed out at the end is the feed's, in order: main waits for copro's
    # flush to reach the map before it asks the map for its vectors
    doc = json.loads(out.read_text())
    assert len(doc["vectors"]) >= 1, output[-3000:]
    assert seen == doc["vectors"]
    # the three poses agree in the room frame: odometry at the start, the filter throughout
    start = odometry[: max(5, len(odometry) // 20)]
    for m in start:
        t = _nearest(true, m.time_ns).data["pose"]
        p = m.data["pose"]["position"]
        assert math.dist((p["x"], p["y"]), (t["position"]["x"], t["position"]["y"])) < 0.15
    if filtered:  # the EKF runs in exploration unless it is configured away
        errors = sorted(
            math.dist(
                (m.data["pose"]["position"]["x"], m.data["pose"]["position"]["y"]),
                (_nearest(true, m.time_ns).data["pose"]["position"]["x"],
                 _nearest(true, m.time_ns).data["pose"]["position"]["y"]),
            )
            for m in filtered
        )  # fmt: skip
        assert errors[len(errors) // 2] < 0.25, errors[len(errors) // 2]
        turn = [
            abs(math.remainder(_heading(m.data) - _heading(_nearest(true, m.time_ns).data), 2 * math.pi))
            for m in filtered
        ]
        assert sorted(turn)[len(turn) // 2] < math.radians(10)
        assert on("/robot/uncertainty")
    schemas = {}
    for source in feed_sources(protocol, ring_name):
        schemas.update({t.name: t.schema for t in source.topics()})
    for m in messages[:: max(1, len(messages) // 2000)]:
        if m.topic.startswith("/robot/"):
            jsonschema.validate(m.data, schemas[m.topic])


def _try_tap(endpoint: str) -> Any:
    try:
        session = tap(endpoint)
    except Exception:
        time.sleep(0.2)
        return None
    return session
