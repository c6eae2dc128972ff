"""Ring and channel semantics on the in-memory transport (fast, one process)."""

from __future__ import annotations

import itertools
import threading
import time

import pytest

from tests.support.memring import MemoryRing, wait_for
from tokenring.contract.frame import Token
from tokenring.contract.protocol import default_protocol
from tokenring.errors import ChannelError


@pytest.fixture
def ring():
    r = MemoryRing(bitrate=None)
    r.wait_rounds(20)
    yield r
    r.close()


def test_ring_forms_in_id_order_and_main_counts_rounds(ring):
    successors = {n.node_id: n.membership.successor for n in ring.nodes.values()}
    assert successors == {10: 20, 20: 30, 30: 40, 40: 50, 50: 60, 60: 70, 70: 80, 80: 10}
    main = ring.by_name("main")
    lcd = ring.by_name("lcd")
    # every pass to lcd on the wire (a waiting thread may miss visits on a loaded machine)
    ring.hub.wire.clear()
    ring.hub.tapping = True
    wait_for(
        lambda: sum(1 for _, did, _ in list(ring.hub.wire) if did == lcd.node_id) >= 30,
        10,
        "30 passes to lcd",
    )
    ring.hub.tapping = False
    offset = ring.protocol.header.counter
    counters = [frame[offset] for _, did, frame in list(ring.hub.wire) if did == lcd.node_id]
    steps = {(b - a) & 0xFF for a, b in itertools.pairwise(counters)}
    assert 1 in steps and steps <= {0, 1}, steps  # main adds one per round (0: a pass retried)
    assert main.stats.rounds >= 20
    assert ring.regenerated() == 1  # main started the one token


def test_data_is_read_by_every_node_that_unlocked_it(ring):
    sonar = ring.by_name("sonar")
    out = sonar.publish()
    out.write(distances=[11, 12, 13, 14, 15, 16, 17, 255], sweep=42)
    readers = {name: ring.by_name(name).subscribe("sonar.data") for name in ("main", "copro", "lcd")}
    locked = ring.by_name("map").get_data("sonar.data")  # registered but never unlocked
    ring.wait_rounds(3)
    for name, buffer in readers.items():
        assert buffer.read()["distances"] == [11, 12, 13, 14, 15, 16, 17, 255], name
        assert buffer["sweep"] == 42
    assert locked.read()["sweep"] == 0
    assert locked.visits == 0


def test_command_transmitted_and_acknowledged_exactly_once(ring):
    main, motor = ring.by_name("main"), ring.by_name("motor")
    motor.set_own_input_id()
    motor.unlock_data("motor.command")
    outbox = main.send_command("motor", "MOVE_FORWARD", distance_mm=500, speed_pct=40)
    assert outbox.done.wait(30)
    assert main.command_transmitted("motor") and main.command_acknowledged("motor")
    assert motor.command_received()
    cmd = motor.get_command()
    assert (cmd.name, cmd.sender, cmd.args) == ("MOVE_FORWARD", 10, {"distance_mm": 500, "speed_pct": 40})
    motor.unlock_data("motor.command")
    ring.wait_rounds(5)
    assert motor.stats.commands_received == 1
    assert main.stats.commands_acknowledged == 1


def test_locked_inbox_gives_transmitted_but_not_acknowledged_and_the_channel_is_freed(ring):
    main, sonar = ring.by_name("main"), ring.by_name("sonar")
    sonar.set_own_input_id()  # registered, never unlocked: the flap stays closed
    outbox = main.send_command("sonar", "SET_METHOD", tangent=1, seed_classifier=0)
    assert outbox.done.wait(30)
    assert main.command_transmitted("sonar")
    assert not main.command_acknowledged("sonar")
    assert not sonar.command_received()
    ring.wait_rounds(2)
    channel = default_protocol().channel("sonar.command")
    assert not any(main._work[channel.address : channel.end])  # cleared by the sender on return
    assert sonar.stats.inbox_full >= 1


def test_no_retry_and_a_busy_inbox_makes_the_next_sender_wait(ring):
    main, lcd, motor = ring.by_name("main"), ring.by_name("lcd"), ring.by_name("motor")
    motor.set_own_input_id()
    first = main.send_command("motor", "STOP")
    second = lcd.send_command("motor", "STOP")
    assert first.done.wait(30) and second.done.wait(30)
    assert first.acknowledged != second.acknowledged or not second.acknowledged
    assert main.stats.commands_sent == 1 and lcd.stats.commands_sent == 1


def test_receive_command_reopens_the_inbox(ring):
    main, motor = ring.by_name("main"), ring.by_name("motor")
    motor.set_own_input_id()
    got: list[int] = []

    def receiver() -> None:  # a user program's loop, beside the handler
        while len(got) < 3:
            cmd = motor.receive_command(timeout=30)
            if cmd is None:
                return
            got.append(cmd.args["distance_mm"])

    thread = threading.Thread(target=receiver)
    thread.start()
    for distance in (100, 200, 300):
        assert main.deliver("motor", "MOVE_FORWARD", distance_mm=distance, speed_pct=10, timeout=30)
    thread.join(30)
    assert got == [100, 200, 300]
    assert motor.stats.commands_received == 3


def test_a_repeated_command_is_never_taken_twice(ring):
    main, motor = ring.by_name("main"), ring.by_name("motor")
    motor.set_own_input_id()
    motor.unlock_data("motor.command")
    outbox = main.send_command("motor", "STOP")
    assert outbox.done.wait(30) and outbox.acknowledged
    motor.unlock_data("motor.command")
    # replay the exact command image into the token once, as a stale copy of the token would
    channel = default_protocol().channel("motor.command")
    replayed = threading.Event()

    def replay_once(work: bytearray) -> bool:
        if not replayed.is_set():
            work[channel.address : channel.end] = outbox.image
            replayed.set()
        return False

    # past main's post-start recovery window, where it sweeps its own old commands
    wait_for(lambda: time.perf_counter() > main._recovery_until, 30, "main's recovery window to end")
    main.system_handler = replay_once
    main.system_busy = True  # the hook is called at every visit, not only when a command is about
    assert replayed.wait(30)
    ring.wait_rounds(3)
    assert motor.stats.commands_received == 1
    assert motor.stats.duplicate_commands >= 1


def test_bad_commands_are_refused_with_clear_messages(ring):
    main = ring.by_name("main")
    with pytest.raises(ChannelError, match="unknown command 'FLY'"):
        main.send_command("motor", "FLY")
    with pytest.raises(ChannelError, match="missing argument"):
        main.send_command("motor", "MOVE_FORWARD", distance_mm=5)
    with pytest.raises(ChannelError, match="does not fit u8"):
        main.send_command("motor", "MOVE_FORWARD", distance_mm=5, speed_pct=300)
    with pytest.raises(ChannelError, match="only its owner"):
        main.store_data("sonar.data")
    with pytest.raises(ChannelError, match="unknown channel"):
        main.subscribe("radar.data")


def test_late_joiner_is_inserted_and_leaver_removed_without_losing_the_token():
    ring = MemoryRing([10, 30, 50], bitrate=None)
    try:
        ring.wait_rounds(20)
        ring.add(40)
        joined = ring.nodes[40]
        wait_for(lambda: joined.stats.visits > 10, 30, "the joiner to receive the token")
        assert ring.nodes[30].membership.successor == 40
        ring.nodes[30].leave()
        ring.wait_rounds(20, node_id=10)
        assert ring.nodes[10].membership.successor == 40
        assert ring.nodes[50].membership.successor == 10
        assert ring.regenerated() == 1  # never lost, never duplicated
        assert sum(n.stats.stale_tokens for n in ring.nodes.values()) == 0
    finally:
        ring.close()


def test_malformed_frames_are_dropped_and_counted(ring):
    sonar = ring.by_name("sonar")
    token = Token()
    token.sid, token.did = 20, sonar.node_id
    good = token.to_frame()
    before = sonar.stats.as_dict()
    sonar._on_frame(good[:100])  # short
    sonar._on_frame(good[:200] + bytes([good[200] ^ 1]) + good[201:])  # bad CRC
    token.sid = 99
    sonar._on_frame(token.to_frame())  # foreign SID
    token.sid, token.did = 20, 40
    sonar._on_frame(token.to_frame())  # wrong DID
    after = sonar.stats.as_dict()
    assert after["rejected_length"] == before["rejected_length"] + 1
    assert after["rejected_crc"] == before["rejected_crc"] + 1
    assert after["rejected_sid"] == before["rejected_sid"] + 1
    assert after["rejected_did"] == before["rejected_did"] + 1
    ring.wait_rounds(5)  # still circulating


@pytest.mark.slow
def test_bitrate_paces_the_ring():
    # a lower bound only: a loaded machine makes rounds slower, never faster than the wire
    ring = MemoryRing([10, 20, 30, 40], bitrate=2.5e6)
    try:
        ring.wait_rounds(10, timeout=30)
        t0 = time.monotonic()
        ring.wait_rounds(20, timeout=30)
        per_round = (time.monotonic() - t0) / 20
        assert per_round >= 4 * 2.2e-3  # four hops of ~2.29 ms wire time each
    finally:
        ring.close()


def test_the_handler_time_is_how_long_the_token_is_held_not_the_put_after_it():
    """``handler`` (bench, status, monitor) runs from a frame's arrival to the put that passes it
    on: a slow put after that point, and the visit's bookkeeping, are not in it."""
    ring = MemoryRing([10, 20, 30], bitrate=None)
    try:
        ring.wait_rounds(20)
        slow = ring.nodes[20]

        put_s = 0.010  # far above what a handler takes, loaded or not: the two cannot be confused

        def slow_put(_did: int, _work: bytearray) -> bool:
            time.sleep(put_s)  # the transport takes 10 ms to send ...
            return False  # ... and sends

        slow.tx_fault = slow_put
        ring.wait_rounds(60, node_id=20, timeout=60)
        rounds = slow.timing.rounds.percentile(50, last=40)
        held = slow.timing.handler.percentile(50, last=40)
        # the baseline: the handler time of the other two nodes over the same rounds, on the
        # same machine under the same load, whose puts are quick
        others = max(ring.nodes[i].timing.handler.percentile(50, last=40) for i in (10, 30))
        assert rounds > put_s  # every round waits for the slow put
        # with the put in it, the slow node's handler would take put_s more than theirs
        assert held < others + put_s / 2, f"handler {held * 1e6:.0f} us (others {others * 1e6:.0f} us)"
        assert sum(n.stats.tokens_regenerated for n in ring.nodes.values()) <= 1  # the boot token only
    finally:
        ring.close()
