"""The localisation in the live feed: ``/robot/localization`` and ``/robot/messages``.

By hand, the source's translate and poll on msgpack payloads as copro puts them; then copro's
:class:`~modules.copro.LivePublisher` and a :class:`~tokenring.observe.feed.Feed` on two Zenoh
sessions over loopback, the feed opened after the messages were said; then a real ring (world,
motor, copro and the Darmstadt gyro as processes) with a feed opened once it runs.
Every message is checked against its topic's JSON Schema with the jsonschema package.
"""

from __future__ import annotations

import itertools
import json
import signal
import threading
import time
from typing import Any

import jsonschema
import msgpack
import pytest

from modules.copro import LivePublisher
from modules.localization.config import load_config
from modules.localization.liveview import SyncPeriods, snapshot
from modules.localization.localizer import LocalizationCore
from modules.pc.feed import MESSAGES_SHOWN, LocalizationSource, robot_feed_sources
from tests.support.hallway import ROOM, programs
from tests.support.locsim import drive
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.contract.protocol import load_protocol
from tokenring.host.pclink import open_link
from tokenring.observe.feed import Feed, Message, feed_sources
from tokenring.transport import make_config, open_session, query

STATE, MESSAGE = "tokenring/t/robot/localization/state", "tokenring/t/robot/localization/message"


def schemas() -> dict[str, dict[str, Any]]:
    return {t.name: t.schema for t in LocalizationSource(load_protocol()).topics()}


def valid(messages: list[Message]) -> None:
    validators = {name: jsonschema.Draft202012Validator(schema) for name, schema in schemas().items()}
    for m in messages:
        validators[m.topic].validate(m.data)
        json.dumps(m.data, allow_nan=False)  # plain JSON values only


def entry(n: int, text: str = "", run: str = "r1", cls: str = "I", stamp: int = 0) -> bytes:
    return msgpack.packb({"run": run, "n": n, "class": cls, "stamp_ms": stamp, "text": text or f"m{n}"})


def fed_snapshot() -> dict[str, Any]:
    core = LocalizationCore(load_config())
    periods = SyncPeriods()
    for sample in drive([("s", 300.0)], seed=2):
        core.feed(sample)
        core.maybe_sync()
        periods.observe(core)
    return snapshot(core, periods)


class Backlog:
    """A stand-in for copro's queryable: answers ``robot/localization/messages`` on a session."""

    def __init__(self, session: Any, run: str, messages: list[dict[str, Any]]) -> None:
        self.asked = 0
        reply = msgpack.packb({"ok": True, "result": {"run": run, "messages": messages}})

        def answer(q: Any) -> None:
            self.asked += 1
            q.reply(q.key_expr, reply)

        self.queryable = session.declare_queryable("tokenring/t/robot/localization/messages", answer)


def shown(messages: list[Message]) -> list[list[str]]:
    return [[m["text"] for m in x.data["messages"]] for x in messages if x.topic == "/robot/messages"]


# --------------------------------------------------------------------------------------------
# by hand


def test_the_topics_are_the_robots_with_valid_schemas() -> None:
    protocol = load_protocol()
    sources = robot_feed_sources(protocol, "t")
    (source,) = [s for s in sources if isinstance(s, LocalizationSource)]
    assert [t.name for t in source.topics()] == ["/robot/localization", "/robot/messages"]
    assert source.keys("t") == [STATE, MESSAGE]
    for topic in source.topics():
        jsonschema.Draft202012Validator.check_schema(topic.schema)
    # every topic once among the robot's sources, and the extension hands this one to a feed
    names = [t.name for s in sources for t in s.topics()]
    assert len(names) == len(set(names))
    assert any(isinstance(s, LocalizationSource) for s in feed_sources(protocol, "t"))


def test_a_snapshot_becomes_the_localization_topic_as_it_is() -> None:
    source = LocalizationSource(load_protocol())
    shot = fed_snapshot()
    (message,) = source.translate(STATE, msgpack.packb(shot), 7)
    assert message.topic == "/robot/localization" and message.time_ns == 7 and message.data == shot
    valid([message])
    for bad in (b"\xc1", msgpack.packb([1, 2])):  # not msgpack; not a map
        assert source.translate(STATE, bad, 8) == []
    missing = {k: v for k, v in shot.items() if k != "sync"}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(missing, schemas()["/robot/localization"])


def test_messages_are_listed_once_each_newest_last_and_kept_to_the_newest_200() -> None:
    source = LocalizationSource(load_protocol())
    out = source.translate(MESSAGE, entry(0, "localisation started", cls="I"), 1)
    out += source.translate(MESSAGE, entry(1, "compass rejected", cls="W", stamp=900), 2)
    assert shown(out) == [["localisation started"], ["localisation started", "compass rejected"]]
    assert out[-1].data["messages"][-1] == {"n": 1, "class": "W", "stamp_ms": 900, "text": "compass rejected"}
    assert source.translate(MESSAGE, entry(1, "compass rejected"), 3) == []  # seen: nothing new
    assert source.translate(MESSAGE, msgpack.packb({"n": "x", "text": 5}), 4) == []  # not a message
    # a restarted copro numbers from 0 again: its messages follow the first one's
    (again,) = source.translate(MESSAGE, entry(0, "started again", run="r2"), 5)
    assert [m["text"] for m in again.data["messages"]] == [
        "localisation started",
        "compass rejected",
        "started again",
    ]
    for n in range(2, 400):
        last = source.translate(MESSAGE, entry(n, run="r2"), 6)
    texts = [m["text"] for m in last[-1].data["messages"]]
    assert len(texts) == MESSAGES_SHOWN and texts[-1] == "m399" and texts[0] == "m200"
    valid([*out, again, *last])


def test_poll_asks_for_the_backlog_once_and_the_next_sample_shows_it_without_duplicates(endpoint) -> None:
    said = [{"n": i, "class": "I", "stamp_ms": 10 * i, "text": f"m{i}"} for i in range(5)]
    with (
        open_session(make_config(listen=[endpoint], gossip=False)) as copro,
        open_session(make_config(connect=[endpoint], gossip=False)) as viewer,
    ):
        backlog = Backlog(copro, "r1", said)
        source = LocalizationSource(load_protocol())
        # message 4 arrived live before the backlog did
        assert shown(source.translate(MESSAGE, entry(4, "m4"), 1)) == [["m4"]]

        def answered(source: LocalizationSource, asked: int) -> bool:
            assert source.poll(viewer, "t", 2) == []  # the answer is held for the next sample
            return backlog.asked == asked  # (no answer yet: the sessions are still linking)

        wait_until(lambda: answered(source, 1), 30, "the backlog's answer")
        assert source.poll(viewer, "t", 3) == []
        # the next sample of either key brings it in, on the feed's thread, in order, once each
        out = source.translate(STATE, msgpack.packb(fed_snapshot()), 4)
        assert [m.topic for m in out] == ["/robot/localization", "/robot/messages"]
        assert shown(out) == [["m0", "m1", "m2", "m3", "m4"]]
        out = source.translate(MESSAGE, entry(5, "m5"), 5)
        assert shown(out) == [["m0", "m1", "m2", "m3", "m4", "m5"]]
        assert source.poll(viewer, "t", 6) == [] and source.poll(viewer, "t", 7) == []
        assert backlog.asked == 1  # asked once only
        valid(out)

        # a localisation that says nothing more: the second poll after the answer shows it
        quiet = LocalizationSource(load_protocol())
        wait_until(lambda: answered(quiet, 2), 30, "the backlog's answer")
        assert quiet.poll(viewer, "t", 8) == []  # a sample may still come within a poll interval
        (message,) = quiet.poll(viewer, "t", 9)
        assert [m["text"] for m in message.data["messages"]] == ["m0", "m1", "m2", "m3", "m4"]
        assert quiet.poll(viewer, "t", 10) == [] and backlog.asked == 2


# --------------------------------------------------------------------------------------------
# copro's publisher and a feed, two sessions on loopback


def test_a_feed_opened_late_sees_the_messages_said_before_and_after_it_once_each(endpoint) -> None:
    core = LocalizationCore(load_config())  # says "localisation started" as it is built
    core.message("W", 100, "said before anyone published")
    protocol = load_protocol()
    with (
        open_session(make_config(listen=[endpoint], gossip=False)) as copro,
        open_session(make_config(connect=[endpoint], gossip=False)) as viewer,
    ):
        live = LivePublisher(copro, "t", core, period_s=0.05)
        try:
            core.message("I", 200, "said before the feed opened")
            # the backlog answers on the ring's key, with this copro's run
            (_, reply), *_ = wait_until(
                lambda: query(viewer, "tokenring/t/robot/localization/messages", timeout=2.0),
                30,
                "the backlog",
            )
            assert reply["ok"] and reply["result"]["run"] == live.run
            assert [m["n"] for m in reply["result"]["messages"]] == [0, 1, 2]

            messages: list[Message] = []
            arrived = threading.Event()

            def sink(m: Message) -> None:
                messages.append(m)
                if m.topic == "/robot/messages" and m.data["messages"][-1]["text"] == "said after":
                    arrived.set()

            feed = Feed(
                viewer,
                "t",
                [s for s in robot_feed_sources(protocol, "t") if isinstance(s, LocalizationSource)],
            )
            feed.add_sink(sink)
            with feed:
                samples = iter(drive([("s", 400.0)], seed=5))

                def steps() -> bool:  # copro's loop: samples in, a step, the publisher after it
                    for sample in samples:
                        core.feed(sample)
                        if sample.sensor == "odometry":
                            core.maybe_sync()
                            live.step()
                            return False
                    return True

                def shows_backlog() -> bool:
                    steps()
                    return any(
                        m.topic == "/robot/messages" and len(m.data["messages"]) >= 3 for m in messages
                    )

                wait_until(shows_backlog, 60, "the backlog in the feed", interval=0.06)
                core.message("E", 300, "said after")
                assert arrived.wait(30), shown(messages)[-3:]
                while not steps():  # the rest of the drive, a snapshot now and then
                    time.sleep(0.002)

                def last_shown() -> bool:
                    live.step()  # at most every period_s: until one goes out after the last sync
                    return any(
                        m.topic == "/robot/localization" and m.data["sync"]["syncs"] == core.syncs
                        for m in messages
                    )

                wait_until(last_shown, 30, "the last snapshot", interval=0.06)
        finally:
            live.close()
    assert core.message_listeners == []  # closed: the core tells it nothing more
    assert feed.dropped == 0
    lists = [m.data["messages"] for m in messages if m.topic == "/robot/messages"]
    final = [m["text"] for m in lists[-1]]
    assert final[0].startswith("localisation started")
    said = ["said before anyone published", "said before the feed opened", "said after"]
    assert [t for t in final if t in said] == said
    assert len(lists[-1]) == core.messages_said  # all of them (the drive's own too, if any)
    for listed in lists:  # every list in order, each message once, none lost from one to the next
        assert [m["n"] for m in listed] == sorted({m["n"] for m in listed})
    for before, after in itertools.pairwise(lists):
        assert before == after[: len(before)]
    states = [m.data for m in messages if m.topic == "/robot/localization"]
    steps_seen = [
        s["sensors"]["odometry"]["values"]["steps_left"] for s in states if s["sensors"]["odometry"]["values"]
    ]
    assert len(set(steps_seen)) >= 2 and steps_seen == sorted(steps_seen)  # the drive moved on
    assert states[-1]["sync"]["last_period_ms"] == 100.0
    assert states[-1]["message_count"] == core.messages_said
    assert live.stats["messages"] >= 1 and live.stats["dropped"] == 0
    valid(messages)


def test_no_localizer_no_publisher() -> None:
    from modules.copro import open_live

    class Hardware:
        session, ring = object(), "t"

    assert open_live(Hardware(), None) is None  # seed mode, or $TOKENRING_LOCALIZER=off
    assert open_live(None, object()) is None  # no session to publish on


# --------------------------------------------------------------------------------------------
# a real ring


@pytest.mark.slow
@pytest.mark.timeout(600)  # a hang guard: five interpreters boot and drive on a loaded machine
def test_a_feed_opened_on_a_running_ring_sees_earlier_messages_and_the_odometry_move(
    procs, ring_name, endpoint, tmp_path
) -> None:
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,copro,gyro",
        "--programs", str(programs(tmp_path, ["motor", "copro", "gyro"])), "--world", str(room),
        "--sensors", "darmstadt", "--algorithms", "body=seed", "--speed", "5", "--bitrate", "max",
        "--duration", "500",
    )  # fmt: skip  # body=seed: the Darmstadt set without the correlator; --duration a hang guard
    protocol = load_protocol()
    messages: list[Message] = []
    try:
        with tap(endpoint) as session:
            wait_ring(session, ring_name, [10, 20, 50, 90], timeout=240)
            procs.watch(launcher_pids(session, ring_name))
            # the localisation has spoken before any feed is open
            key = f"tokenring/{ring_name}/robot/localization/messages"
            wait_until(lambda: query(session, key, timeout=2.0), 120, "copro's localisation")

            feed = Feed(session, ring_name, feed_sources(protocol, ring_name))
            feed.add_sink(messages.append)
            with feed:

                def on(topic: str) -> list[dict[str, Any]]:
                    return [m.data for m in list(messages) if m.topic == topic]

                def odometry_steps() -> list[Any]:
                    return [
                        (s["sensors"]["odometry"]["values"] or {}).get("steps_left")
                        for s in on("/robot/localization")
                    ]

                wait_until(lambda: on("/robot/messages"), 60, "/robot/messages")
                wait_until(lambda: odometry_steps() and odometry_steps()[-1] is not None, 60, "odometry")
                before = odometry_steps()[-1]
                link = open_link(session, ring_name, wait=60.0)
                # the Darmstadt drive is off at boot: "Motoren an" first (the operator's e, §6.7)
                assert link.command("motor", "MOTORS_ON", timeout=30.0)["acknowledged"]
                sent = link.command("motor", "MOVE_FORWARD", timeout=30.0, distance_mm=300, speed_pct=60)
                assert sent["acknowledged"], sent
                wait_until(lambda: odometry_steps()[-1] != before, 120, "the odometry sample to move")
            assert feed.dropped == 0
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
    output, _ = launcher.communicate(timeout=120)
    assert "Traceback" not in output, output[-3000:]

    lists = [m.data["messages"] for m in messages if m.topic == "/robot/messages"]
    texts = [m["text"] for m in lists[-1]]
    assert any(t.startswith("localisation started: sensors odometry") for t in texts), texts
    assert all([m["n"] for m in listed] == sorted({m["n"] for m in listed}) for listed in lists)
    states = [m.data for m in messages if m.topic == "/robot/localization"]
    assert {"odometry", "gyro"} <= set(states[-1]["sensors"])  # the Darmstadt set's gyro
    assert states[-1]["sensors"]["gyro"]["samples"] > 0
    moved = {
        s["sensors"]["odometry"]["values"]["steps_left"] for s in states if s["sensors"]["odometry"]["values"]
    }
    assert len(moved) >= 2
    assert states[-1]["sync"]["syncs"] > states[0]["sync"]["syncs"]
    valid([m for m in messages if m.topic in ("/robot/localization", "/robot/messages")])
