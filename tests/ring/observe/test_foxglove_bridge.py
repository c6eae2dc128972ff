"""The Foxglove bridge (tokenring/observe/foxglove.py, ``tokenring foxglove``, ``up --foxglove``).

The judge is a plain WebSocket client (the ``websockets`` package) speaking the Foxglove
WebSocket protocol as its specification writes it (github.com/foxglove/ws-protocol): JSON
``serverInfo`` and ``advertise`` ops, a JSON ``subscribe`` op, binary message data frames of
opcode 0x01, a little-endian uint32 subscription ID, a uint64 timestamp (ns) and the payload.
It shares no code with foxglove-sdk or the bridge. Where the robot is judged, the room comes
from its world file read as plain YAML; MCAP files are read with the ``mcap`` package's reader.
"""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import subprocess
import time
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import websockets
import yaml

from tests.support.processes import REPO, pid_alive, run_tokenring
from tests.support.ringutil import tap, wait_until
from tokenring.contract import keys
from tokenring.contract.protocol import default_protocol
from tokenring.observe.feed import Message, Topic
from tokenring.transport.session import free_port, query

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]  # the SDK's name, the original one
MESSAGE_DATA = 0x01
OFFICE = yaml.safe_load((REPO / "modules/description/rooms/office.yaml").read_text())


class FoxgloveClient:
    """The client side of the Foxglove WebSocket protocol, enough to subscribe and decode."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.server_info: dict[str, Any] = {}
        self.channels: dict[int, dict[str, Any]] = {}  # channel ID -> its advertisement
        self.subscriptions: dict[int, str] = {}  # our subscription ID -> topic
        self.received: dict[str, list[tuple[int, dict[str, Any]]]] = {}  # topic -> (time ns, message)
        self.wanted: set[str] = set()

    async def subscribe_when_advertised(self, topics: set[str]) -> None:
        self.wanted |= topics
        await self._subscribe_new()

    async def _subscribe_new(self) -> None:
        have = set(self.subscriptions.values())
        subs = []
        for channel_id, ad in sorted(self.channels.items()):
            if ad["topic"] in self.wanted and ad["topic"] not in have:
                sub_id = len(self.subscriptions) + 1
                self.subscriptions[sub_id] = ad["topic"]
                subs.append({"id": sub_id, "channelId": channel_id})
        if subs:
            await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def pump(self, timeout: float) -> None:
        """Handle what arrives for up to ``timeout`` seconds (or one message)."""
        try:
            frame = await asyncio.wait_for(self.ws.recv(), timeout)
        except TimeoutError:
            return
        if isinstance(frame, str):
            op = json.loads(frame)
            if op["op"] == "serverInfo":
                self.server_info = op
            elif op["op"] == "advertise":
                for ad in op["channels"]:
                    self.channels[ad["id"]] = ad
                await self._subscribe_new()
            elif op["op"] == "unadvertise":
                for channel_id in op["channelIds"]:
                    self.channels.pop(channel_id, None)
            return
        assert frame[0] == MESSAGE_DATA, f"unexpected binary opcode {frame[0]:#x}"
        sub_id, stamp = struct.unpack_from("<IQ", frame, 1)
        topic = self.subscriptions[sub_id]
        self.received.setdefault(topic, []).append((stamp, json.loads(frame[13:])))

    def on(self, topic: str) -> list[dict[str, Any]]:
        return [message for _, message in self.received.get(topic, [])]

    def advertised(self, topic: str) -> dict[str, Any]:
        return next(ad for ad in self.channels.values() if ad["topic"] == topic)


async def collect(url: str, topics: set[str], done: Any, timeout: float) -> FoxgloveClient:
    """Connect, subscribe to ``topics`` and read until ``done(client)`` or ``timeout`` seconds."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        client = FoxgloveClient(ws)
        await client.subscribe_when_advertised(topics)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not done(client):
            await client.pump(min(1.0, max(0.01, deadline - time.monotonic())))
        return client


def inside(x: float, y: float, polygon: list[list[float]]) -> bool:
    """Even-odd ray casting: is (x, y) inside the polygon?"""
    result = False
    for (x1, y1), (x2, y2) in zip(polygon, polygon[1:] + polygon[:1], strict=True):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            result = not result
    return result


def wait_port(port: int, timeout: float) -> None:
    def accepting() -> bool:
        with socket.socket() as probe:
            probe.settimeout(1.0)
            return probe.connect_ex(("127.0.0.1", port)) == 0

    wait_until(accepting, timeout, f"a server on port {port}", interval=0.2)


# --------------------------------------------------------------------------------------------
# a live ring


def launcher_status(session: Any, ring: str) -> dict[str, Any] | None:
    """The launcher's status, or None while this fresh session cannot reach it yet."""
    replies = query(session, keys.control(ring, "launcher", "status"), timeout=1.0)
    return replies[0][1]["result"] if replies and replies[0][1].get("ok") else None


def every_node(status: dict[str, Any] | None) -> dict[str, Any] | None:
    """The launcher's status once it lists every node of the default ring, else None."""
    wanted = {n.id for n in default_protocol().default_nodes}
    return status if status and {n["id"] for n in status["nodes"]} >= wanted else None


def map_lines(scene: dict[str, Any]) -> list[dict[str, Any]]:
    return [point for e in scene["entities"] for line in e["lines"] for point in line["points"]]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_foxglove_client_sees_poses_the_map_and_round_trips_of_an_exploring_ring(
    procs, ring_name, endpoint
):
    port = free_port()
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "office", "--speed", "20",
        "--bitrate", "max", "--explore", "2", "--duration", "240", "--foxglove", "--foxglove-port", str(port),
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_port(port, 90)  # a service: up before the nodes start
        # the service starts before the nodes: a status that lists every node
        status = wait_until(
            lambda: every_node(launcher_status(session, ring_name)),
            120,
            "the launcher's status with every node",
        )
        procs.watch([n["pid"] for n in status["nodes"]] + [s["pid"] for s in status["services"]])
        bridge = next(s for s in status["services"] if s["name"] == "watch")
        assert bridge["running"]

        def done(c: FoxgloveClient) -> bool:
            return (
                len(c.on("/robot/pose/true")) >= 50
                and len(c.on("/ring/roundtrip")) >= 20
                and any(map_lines(m) for m in c.on("/robot/map"))
            )

        wanted = {"/robot/pose/true", "/robot/pose/odometry", "/robot/map", "/ring/roundtrip"}
        client = asyncio.run(collect(f"ws://127.0.0.1:{port}", wanted, done, timeout=180))
        assert done(client), {t: len(m) for t, m in client.received.items()}

        # the channels are advertised as Foxglove expects them: JSON under the topic's JSON Schema
        pose_ad = client.advertised("/robot/pose/true")
        assert pose_ad["encoding"] == "json" and pose_ad["schemaEncoding"] == "jsonschema"
        assert pose_ad["schemaName"] == "foxglove.PoseInFrame"
        assert client.advertised("/robot/map")["schemaName"] == "foxglove.SceneUpdate"
        pose_schema = json.loads(pose_ad["schema"])
        outer, pillar = (w["polygon"] for w in OFFICE["walls"])
        outer_m = [[x / 1000 for x in p] for p in outer]
        pillar_m = [[x / 1000 for x in p] for p in pillar]
        for stamp, pose in client.received["/robot/pose/true"]:
            jsonschema.validate(pose, pose_schema)
            assert pose["frame_id"] == "room"
            where = pose["pose"]["position"]
            assert inside(where["x"], where["y"], outer_m) and not inside(where["x"], where["y"], pillar_m), (
                where
            )
            # the frame's timestamp is the time the pose was seen
            assert abs(stamp - (pose["timestamp"]["sec"] * 10**9 + pose["timestamp"]["nsec"])) < 10**9
        # the robot starts at the world's start pose and moves
        first = client.on("/robot/pose/true")[0]["pose"]["position"]
        xs = [p["pose"]["position"]["x"] for p in client.on("/robot/pose/true")]
        assert abs(first["x"] - OFFICE["start"]["x"] / 1000) < 1.5 and max(xs) - min(xs) > 0.05

        scene = next(m for m in reversed(client.on("/robot/map")) if map_lines(m))
        jsonschema.validate(scene, json.loads(client.advertised("/robot/map")["schema"]))
        points = map_lines(scene)
        assert len(points) >= 2 and len(points) % 2 == 0  # line segments: pairs of points
        xs_all, ys_all = [x for x, _ in outer_m], [y for _, y in outer_m]
        for point in points:  # mapped walls lie near the room's (dead reckoning may drift a little)
            assert min(xs_all) - 0.75 <= point["x"] <= max(xs_all) + 0.75, point
            assert min(ys_all) - 0.75 <= point["y"] <= max(ys_all) + 0.75, point

        trips = client.on("/ring/roundtrip")
        assert all(t["ms"] > 0 for t in trips), trips[:5]
        # measured where the ring wraps: its lowest member, main once it has joined (while the
        # ring forms, before main's boot, another node can be the lowest for a few rounds)
        ring_ids = {n["id"] for n in status["nodes"]}
        assert {t["node"] for t in trips} <= ring_ids, trips
        assert trips[-1]["node"] == 10, trips[-5:]
        # the odometry arrived too (advertised and subscribed: a second robot topic of the same schema)
        assert client.on("/robot/pose/odometry")

    # stopped mid-exploration (the explore job may report that as its failure): the launcher
    # stops its bridge by PID after the nodes, and the bridge ends cleanly
    launcher.terminate()
    output, _ = launcher.communicate(timeout=60)
    assert "watch | Foxglove:" in output, output[-3000:]
    wait_until(lambda: not pid_alive(bridge["pid"]), 10, "the bridge process gone")


# --------------------------------------------------------------------------------------------
# the bridge in this process


def test_a_new_subscriber_gets_the_last_message_at_once_and_no_mcap_sink_sees_the_bridge(tmp_path: Path):
    import foxglove
    from mcap.reader import make_reader

    from tokenring.observe.foxglove import FoxgloveBridge

    topic = Topic(
        "/robot/walls",
        "test.Walls",
        {"type": "object", "properties": {"n": {"type": "integer"}}, "required": ["n"]},
    )
    # an MCAP writer on the SDK's global context, as a record in the same process could open
    mcap_path = tmp_path / "global.mcap"
    writer = foxglove.open_mcap(str(mcap_path))
    bridge = FoxgloveBridge([topic], host="127.0.0.1", port=0)
    try:
        bridge(Message("/robot/walls", 1_234_567_890_123, {"n": 7}))  # before anybody listens
        client = asyncio.run(
            collect(f"ws://127.0.0.1:{bridge.port}", {"/robot/walls"}, lambda c: c.on("/robot/walls"), 30)
        )
        assert client.server_info["op"] == "serverInfo"
        ad = client.advertised("/robot/walls")
        assert ad["schemaName"] == "test.Walls" and json.loads(ad["schema"]) == topic.schema
        assert client.received["/robot/walls"] == [(1_234_567_890_123, {"n": 7})]  # its original time
        bridge(Message("/robot/walls", 1_300_000_000_000, {"n": 8}))
    finally:
        bridge.close()
        writer.close()
    with open(mcap_path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        channels = [] if summary is None else [c.topic for c in summary.channels.values()]
        assert channels == [] and list(reader.iter_messages()) == []


def test_a_port_in_use_is_one_line_and_exit_2(procs, ring_name):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = run_tokenring("foxglove", "--ring", ring_name, "-e", "tcp/127.0.0.1:1", "--port", str(port))
        assert out.returncode == 2, out
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and f"--port {port}" in lines[0] and "in use" in lines[0], out.stderr
        assert "Traceback" not in out.stderr
        up = run_tokenring(
            "up", "--ring", ring_name, "--no-world", "--foxglove", "--foxglove-port", str(port)
        )
        assert up.returncode == 2, up
        assert up.stderr.strip().count("\n") == 0 and f"--foxglove-port {port}" in up.stderr, up.stderr
    bad = run_tokenring("foxglove", "--port", "70000")
    assert bad.returncode == 2 and "70000" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.slow
def test_the_bridge_serves_the_ring_topics_and_stops_on_ctrl_c(procs, ring_name, endpoint):
    import signal

    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar", "--no-world",
        "--no-programs", "--duration", "120",
    )  # fmt: skip
    port = free_port()
    bridge = procs.tokenring(
        "foxglove", "--ring", ring_name, "-e", endpoint, "--port", str(port), "--json", stderr=subprocess.PIPE
    )  # the SDK logs its clients on stderr
    assert bridge.stdout is not None
    first = json.loads(bridge.stdout.readline())
    assert first == {"ring": ring_name, "url": f"ws://127.0.0.1:{port}", "topics": first["topics"]}

    def done(c: FoxgloveClient) -> bool:
        return len(c.on("/ring/roundtrip")) >= 10 and bool(c.on("/ring/nodes"))

    client = asyncio.run(collect(first["url"], {"/ring/roundtrip", "/ring/nodes", "/ring/frame"}, done, 120))
    assert done(client), {t: len(m) for t, m in client.received.items()}
    nodes = client.on("/ring/nodes")[-1]
    assert set(nodes["nodes"]) <= {"10", "20", "30"} and nodes["nodes"], nodes
    assert {f["did"] for f in client.on("/ring/frame")} >= {10, 20, 30}
    bridge.send_signal(signal.SIGINT)
    assert bridge.wait(30) == 130
    launcher.terminate()
    assert launcher.wait(30) == 0
