"""The udp and zmq transports: the same node OS and ring semantics over plain sockets.

In-process rings (fast) check the ring logic over each backend; one multi-process test per
backend runs real ``tokenring node --transport ...`` processes and kills one.
"""

from __future__ import annotations

import signal
import socket
import sys
import threading

import pytest

from tests.support.memring import wait_for
from tests.support.ringutil import stats, wait_until
from tokenring.contract.protocol import default_protocol
from tokenring.errors import TransportError, UsageError
from tokenring.node.node_os import NodeOS
from tokenring.transport.factory import make_transport
from tokenring.transport.registry import MembershipRegistry, RegistryClient, parse_address
from tokenring.transport.sockets import BACKENDS
from tokenring.transport.zenoh_config import make_config, open_session

sys.setswitchinterval(0.0005)  # several nodes in one process, as in tests/support/memring.py
IDS = [10, 20, 30, 40]


class SocketRing:
    """NodeOS instances in this process, talking over one socket backend and a registry."""

    def __init__(self, kind: str, ids: list[int] = IDS) -> None:
        self.protocol = default_protocol()
        self.registry = MembershipRegistry().start()
        self.kind = kind
        self.nodes: dict[int, NodeOS] = {}
        for node_id in ids:
            self.add(node_id)

    def add(self, node_id: int) -> NodeOS:
        transport = BACKENDS[self.kind]("sock", node_id, self.registry.address)
        node = NodeOS(self.protocol, node_id, transport, bitrate=None)
        node.start()
        self.nodes[node_id] = node
        return node

    def by_name(self, name: str) -> NodeOS:
        return self.nodes[self.protocol.node(name).id]

    def wait_rounds(self, rounds: int, timeout: float = 30.0) -> None:
        node = self.nodes[min(self.nodes)]
        start = node.stats.visits
        wait_for(lambda: node.stats.visits >= start + rounds, timeout, f"{rounds} rounds over {self.kind}")

    def close(self) -> None:
        for node in self.nodes.values():
            node.close()
        self.registry.close()


@pytest.fixture(params=sorted(BACKENDS))
def ring(request):
    r = SocketRing(request.param)
    r.wait_rounds(20)
    yield r
    r.close()


def test_ring_forms_in_id_order_and_counts_rounds(ring):
    successors = {n.node_id: n.membership.successor for n in ring.nodes.values()}
    assert successors == {10: 20, 20: 30, 30: 40, 40: 10}
    main = ring.by_name("main")
    before = main.stats.rounds

    def counts() -> tuple[int, int, int]:
        nodes = ring.nodes.values()
        return (
            sum(n.stats.tokens_regenerated for n in nodes),
            sum(n.stats.rejected_crc for n in nodes),
            sum(n.stats.send_errors for n in nodes),
        )

    # main started the ring; on two loaded cores a first pass may meet a peer whose socket is
    # not connected yet (zmq: EAGAIN) and the token is regenerated once more while it forms
    formed = counts()
    assert formed[0] >= 1 and formed[1] == 0
    ring.wait_rounds(50)
    assert main.stats.rounds >= before + 50
    assert counts() == formed  # once circulating: no regeneration, no bad frame, no failed send


def test_a_burst_of_frames_to_one_zmq_node_all_arrive():
    import zmq

    # a fast ring passes many frames a millisecond to its successor; ZeroMQ tells the sender what
    # left its pipe late, so a small send queue refused some (EAGAIN) and lost the token: 7-101
    # regenerations in 20 s of an in-process 4-node ring with a queue of 16, none with 1000
    registry = MembershipRegistry().start()
    sender = BACKENDS["zmq"]("burst", 1, registry.address)
    receiver = BACKENDS["zmq"]("burst", 2, registry.address)
    got: list[bytes] = []
    all_arrived = threading.Event()
    sender_sees_receiver = threading.Event()
    burst = 300

    def on_frame(frame: bytes) -> None:
        got.append(frame)
        if len(got) == burst:
            all_arrived.set()

    def on_membership(node_id: int, live: bool) -> None:
        if node_id == 2 and live:
            sender_sees_receiver.set()

    try:
        receiver.open(on_frame, lambda _m: None, lambda _n, _l: None)
        receiver.announce()
        if 2 in sender.open(lambda _f: None, lambda _m: None, on_membership):
            sender_sees_receiver.set()
        sender.announce()
        assert sender_sees_receiver.wait(30), "the sender never learnt the receiver's address"
        send = sender.sender(2)

        def connected() -> bool:  # a send before the connection is up is refused, not queued
            try:
                send(bytes(514))
            except zmq.Again:
                return False
            return True

        wait_until(connected, 30, "a connection to the receiver")
        wait_until(lambda: got, 30, "the first frame")
        got.clear()
        frames = [bytes([i % 256]) * 514 for i in range(burst)]
        for frame in frames:
            send(frame)  # as fast as the token path would: no pause between sends
        assert all_arrived.wait(30), f"{len(got)} of {burst} frames arrived"
        assert got == frames  # all of them, in order
    finally:
        sender.close()
        receiver.close()
        registry.close()


def test_data_and_commands_keep_the_seed_semantics(ring):
    sonar, main, motor = ring.by_name("sonar"), ring.by_name("main"), ring.by_name("motor")
    sonar.publish().write(distances=[1, 2, 3, 4, 5, 6, 7, 8], sweep=9)
    reader = main.subscribe("sonar.data")
    motor.set_own_input_id()
    motor.unlock_data("motor.command")
    outbox = main.send_command("motor", "MOVE_FORWARD", distance_mm=300, speed_pct=20)
    assert outbox.done.wait(30)
    assert outbox.transmitted and outbox.acknowledged
    assert motor.get_command().args == {"distance_mm": 300, "speed_pct": 20}
    ring.wait_rounds(3)
    assert reader.read()["distances"] == [1, 2, 3, 4, 5, 6, 7, 8]
    assert motor.stats.commands_received == 1


def test_a_leaver_is_removed_and_a_late_joiner_inserted(ring):
    ring.nodes.pop(30).leave(grace=0.5)
    wait_for(lambda: ring.by_name("motor").membership.successor == 40, 30.0, "motor routes around sonar")
    ring.wait_rounds(20)
    ring.add(30)
    wait_for(lambda: ring.by_name("motor").membership.successor == 30, 30.0, "sonar back after motor")
    ring.wait_rounds(20)
    assert ring.registry.live() == IDS


def test_a_vanished_node_is_seen_at_once_and_skipped(ring):
    """A closed registry connection is what a crash looks like (the process's sockets close).

    "At once" is counted in the ring's own rounds, which a loaded machine slows down as much as
    it slows the registry: the victim keeps passing the token meanwhile, so the ring goes on
    at full pace, and motor must drop it within a few rounds (0-3 seen, loaded or not) - two thread wakes (the registry's,
    motor's registry reader) against a round's four hops. A timeout-based detection (a lease,
    a heartbeat) would take hundreds of rounds."""
    main, motor = ring.by_name("main"), ring.by_name("motor")
    victim = ring.nodes.pop(30)
    victim.paused = True  # its watchdog stands still, like a dead process
    assert victim.transport.registry is not None and motor.transport.registry is not None
    seen_at: list[int] = []  # main's round count when motor hears that sonar is gone
    told = motor.transport.registry.on_live
    assert told is not None

    def recording(node_id: int, alive: bool) -> None:
        if node_id == 30 and not alive:
            seen_at.append(main.stats.rounds)
        told(node_id, alive)

    motor.transport.registry.on_live = recording
    closed_at = main.stats.rounds
    victim.transport.registry.close()
    wait_for(lambda: 30 not in motor.membership.live, 30.0, "motor sees sonar gone")
    assert seen_at and seen_at[0] - closed_at <= 30, (closed_at, seen_at)
    ring.wait_rounds(20)
    victim.close()


def test_registry_addresses_and_errors():
    assert parse_address("tcp/127.0.0.1:7000") == ("127.0.0.1", 7000)
    for bad in ("localhost", "host:port", "host:70000", ":12"):
        with pytest.raises(UsageError, match="HOST:PORT"):
            parse_address(bad)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(TransportError, match="cannot reach the membership registry"):
        RegistryClient(f"127.0.0.1:{port}", 5, "127.0.0.1:1", timeout=1.0).connect()
    with pytest.raises(UsageError, match="needs --registry"):
        make_transport("udp", None, "r", 5, 514)
    with pytest.raises(UsageError, match="unknown"):
        make_transport("carrier-pigeon", None, "r", 5, 514)


def test_registry_refuses_a_live_id_takes_a_respawned_node_and_reports_live_changes():
    registry = MembershipRegistry().start()
    seen: list[tuple[int, bool]] = []
    try:
        watcher = RegistryClient(registry.address, 1, "127.0.0.1:1001")
        watcher.on_live = lambda node_id, alive: seen.append((node_id, alive))
        assert watcher.connect() == set()
        first = RegistryClient(registry.address, 7, "127.0.0.1:1007")
        first.connect()
        first.announce()
        wait_for(lambda: (7, True) in seen, 30.0, "7 announced")
        # a second process under a live ID (a second ring, a node started by hand) is refused
        twin = RegistryClient(registry.address, 7, "127.0.0.1:3007")
        with pytest.raises(UsageError, match="node ID 7 is already live"):
            twin.connect()
        assert watcher.addrs.get(7) == "127.0.0.1:1007" and registry.live() == [7]
        # a crashed holder whose connection's end the registry has not read yet: its respawn
        # is taken, and the old end withdraws nothing of the new process
        first._sock.shutdown(socket.SHUT_RDWR)  # type: ignore[union-attr]
        second = RegistryClient(registry.address, 7, "127.0.0.1:2007")
        second.connect()
        second.announce()
        wait_for(lambda: watcher.addrs.get(7) == "127.0.0.1:2007", 30.0, "the new address")
        first.close()
        # a barrier instead of a sleep: the registry tells the watcher everything in order, so
        # once it has told it about 8, 7's last change before it is known
        barrier = RegistryClient(registry.address, 8, "127.0.0.1:1008")
        barrier.connect()
        barrier.announce()
        wait_for(lambda: (8, True) in seen, 30.0, "8 announced")
        assert seen[-3:] == [(7, False), (7, True), (8, True)], seen  # the crash, the respawn
        assert registry.live() == [7, 8]
        barrier.close()
        wait_for(lambda: seen[-1] == (8, False), 30.0, "8 gone")
        second.close()
        wait_for(lambda: seen[-1] == (7, False), 30.0, "7 gone")
        watcher.close()
    finally:
        registry.close()


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(BACKENDS))
def test_node_processes_over_sockets_form_a_ring_and_survive_a_kill(kind, procs, ring_name, endpoint):
    registry = MembershipRegistry().start()
    session = open_session(make_config(listen=[endpoint]))  # the control plane stays on Zenoh
    try:
        nodes = {
            node_id: procs.tokenring(
                "node",
                "--id",
                str(node_id),
                "--ring",
                ring_name,
                "--bitrate",
                "max",
                "--no-store",
                "--transport",
                kind,
                "--registry",
                registry.address,
                "--connect",
                endpoint,
            )
            for node_id in (10, 20, 30)
        }

        def formed():
            found = stats(session, ring_name, 10)
            return found.get(10, {}).get("active") == [10, 20, 30] and found[10]["stats"]["visits"] > 50

        wait_until(formed, 20.0, f"a ring of three over {kind}")
        nodes[20].send_signal(signal.SIGKILL)
        nodes[20].wait(30)

        def healed():
            found = stats(session, ring_name, 10)
            return found.get(10, {}).get("active") == [10, 30] and found[10]["successor"] == 30

        wait_until(healed, 30.0, "node 10 routes around the killed node 20")
        before = stats(session, ring_name, 10)[10]["stats"]["visits"]
        wait_until(
            lambda: stats(session, ring_name, 10)[10]["stats"]["visits"] > before + 50, 30.0, "circulating"
        )
        for node_id in (10, 30):
            nodes[node_id].send_signal(signal.SIGTERM)
        for node_id in (10, 30):
            assert nodes[node_id].wait(30) == 0
    finally:
        session.close()
        registry.close()
