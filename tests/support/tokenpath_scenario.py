"""One node's token path driven through every branch; prints what it did as JSON.

Run as a program by tests/ring/node/test_tokenpath.py, once with ``TOKENRING_NATIVE=0`` (Python) and once
with the C path: the two outputs must be identical — every frame, ack and broadcast sent, every
counter and every piece of ring state after each step.
"""

from __future__ import annotations

import json
import queue
import random
import sys
import threading
import time
from typing import Any

import fastcrc

from tokenring.contract.frame import Token
from tokenring.contract.protocol import default_protocol
from tokenring.contract.ring import ACK_REQUESTED
from tokenring.node import tokenpath
from tokenring.node.node_os import NodeOS
from tokenring.transport.base import Transport

STATE = (
    "_epoch",
    "_origin",
    "_accepted_crc",
    "_accepted_sid",
    "_last_counter",
    "_retries",
    "_ack_pending",
    "_last_sent_did",
    "_last_sent_crc",
    "_has_sent",
    "_regeneration_streak",
    "system_busy",
)


class Recorder(Transport):
    """A transport that records what the node sends; one send can be made to fail."""

    kind = "recorder"

    def __init__(self, node_id: int) -> None:
        super().__init__("parity", node_id)
        self.log: list[list[Any]] = []
        self.fail_next_send = False

    def _open(self, on_frame: Any, on_message: Any, on_membership: Any) -> set[int]:
        return set()

    def _send_frame(self, did: int, frame: bytes | bytearray) -> None:
        if self.fail_next_send:
            self.fail_next_send = False
            raise OSError("link down")
        self.log.append(["frame", did, bytes(frame).hex()])

    def _send_message(self, did: int, payload: bytes) -> None:
        self.log.append(["message", did, payload.hex()])

    def _broadcast(self, payload: bytes) -> None:
        self.log.append(["broadcast", payload.hex()])

    def _announce(self) -> None:
        pass

    def _withdraw(self) -> None:
        pass

    def _close(self) -> None:
        pass


def crc_twin(frame: bytes, target: bytes, token_size: int) -> bytes:
    """``frame`` with three bytes before its CRC changed so that its CRC-16/ARC is ``target``'s.

    CRC-16/ARC (init 0, no final XOR) is linear over GF(2): crc(a ^ d) = crc(a) ^ crc(d). The
    24 single-bit changes of the window span all 16 CRC bits; elimination picks the ones that
    XOR to the wanted difference."""
    arc = fastcrc.crc16.arc
    window = token_size - 3
    wanted = arc(target[:token_size]) ^ arc(frame[:token_size])
    basis: dict[int, tuple[int, int]] = {}  # leading CRC bit -> (syndrome, bits of the window)
    for bit in range(24):
        delta = bytearray(token_size)
        delta[window + bit // 8] = 1 << (bit % 8)
        syndrome, bits = arc(bytes(delta)), 1 << bit
        for lead in sorted(basis, reverse=True):
            if syndrome >> lead & 1:
                syndrome, bits = syndrome ^ basis[lead][0], bits ^ basis[lead][1]
        if syndrome:
            basis[syndrome.bit_length() - 1] = (syndrome, bits)
    bits = 0
    for lead in sorted(basis, reverse=True):
        if wanted >> lead & 1:
            wanted, bits = wanted ^ basis[lead][0], bits ^ basis[lead][1]
    assert wanted == 0
    body = bytearray(frame[:token_size])
    for bit in range(24):
        if bits >> bit & 1:
            body[window + bit // 8] ^= 1 << (bit % 8)
    crc = arc(bytes(body))
    twin = bytes(body) + bytes([crc & 0xFF, crc >> 8])
    assert twin != target and twin[token_size:] == target[token_size:]
    return twin


def main() -> int:
    random.seed(1)  # the system layer draws nonces at random
    protocol = default_protocol()
    main_id, motor_id, sonar_id = (protocol.nodes[n].id for n in ("main", "motor", "sonar"))
    transport = Recorder(motor_id)
    node = NodeOS(protocol, motor_id, transport, ack_mode="adaptive")
    node.incarnation = 0x5EED_0001  # drawn at random per process: fixed so both paths send the same bytes
    for member in (main_id, sonar_id):
        node.membership.set_live(member, True)
    steps: list[dict[str, Any]] = []

    def frame(sid: int = main_id, did: int = motor_id, counter: int = 7, epoch: int = 0, origin: int = 0,
              ack: bool = True, issuer: int = 0, fill: int = 0) -> bytes:  # fmt: skip
        token = Token(protocol)
        user, size = protocol.user_area_offset, protocol.token_size
        token.buffer[user:size] = bytes([fill]) * (size - user)
        token["sid"], token["did"], token["counter"] = sid, did, counter
        token["epoch"] = epoch | (ACK_REQUESTED if ack else 0)
        token["epoch_origin"], token["syscmd_issuer"] = origin, issuer
        return token.to_frame()

    def step(name: str, data: bytes | None = None) -> None:
        if data is not None:
            node._on_frame(data)
        node._recovery_until = 0.0  # the window after an epoch change depends on the clock
        steps.append(
            {
                "step": name,
                "sent": transport.log[:],
                "stats": node.stats.as_dict(),
                "state": {attribute: getattr(node, attribute) for attribute in STATE},
                "live": sorted(node.membership.active),
                # whether the step woke the watchdog (released its lock; no watchdog runs here)
                "woke": node._wake_lock.acquire(blocking=False),
            }
        )
        transport.log.clear()

    step("a pass", frame(fill=1))
    step("the same pass again", frame(fill=1))
    step("the same pass again, no ack asked", frame(fill=1, ack=False))
    good = frame(fill=2)
    step("too short", good[:-1])
    step("bad CRC", good[:100] + bytes([good[100] ^ 0xFF]) + good[101:])
    marker = bytearray(good)
    marker[protocol.header.offsets["size_marker"]] ^= 1
    step("bad marker", Token(protocol, bytes(marker)).to_frame())
    step("for another node", frame(did=sonar_id, fill=3))
    step("from a node not in the ring", frame(sid=99, fill=3))
    step("a pass from the successor: the ring wraps", frame(sid=sonar_id, fill=4))
    step("a newer epoch", frame(epoch=3, origin=main_id, counter=25, fill=5))
    step("an older epoch", frame(epoch=2, origin=main_id, fill=6))
    node.membership.exclude(main_id, retry_after=60.0)
    step("from an excluded node", frame(epoch=3, origin=main_id, counter=27, fill=7))
    step("a system command on the token", frame(epoch=3, origin=main_id, counter=28, issuer=sonar_id, fill=8))
    node.system_busy = True
    step("system busy, no hook", frame(epoch=3, origin=main_id, counter=29, fill=9))
    calls: list[int] = []
    node.system_handler = lambda work: calls.append(work[12]) or len(calls) % 2 == 1
    step("system hook says active", frame(epoch=3, origin=main_id, counter=30, fill=10))
    step("system hook says idle", frame(epoch=3, origin=main_id, counter=31, fill=11))
    node.system_busy = False
    step("system idle: the hook is skipped", frame(epoch=3, origin=main_id, counter=32, fill=12))
    node.system_handler = None
    motor_data = node.publish("motor.data")
    motor_data.raw[:4] = b"\x01\x02\x03\x04"
    main_data = node.subscribe("main.data")
    step("channels: publish motor.data, copy main.data", frame(epoch=3, origin=main_id, counter=33, fill=13))
    steps[-1]["main.data"] = bytes(main_data.raw[:8]).hex()
    node.set_own_input_id()
    node.unlock_data("motor.command")
    outbox = node.send_command("main", "STOP_EXPLORE")
    step("a command goes out", frame(epoch=3, origin=main_id, counter=34, fill=0))
    step("the next visit", frame(epoch=3, origin=main_id, counter=35, fill=0))
    steps[-1]["outbox"] = [outbox.transmitted, outbox.acknowledged]
    node._recovery_until = 1e18
    node._on_frame(frame(epoch=3, origin=main_id, counter=36, fill=0))
    step("inside the recovery window")
    step(
        "an older round of this epoch: a replay, dropped", frame(epoch=3, origin=main_id, counter=30, fill=14)
    )
    step(
        "the same round with other bytes: a second token, dropped",
        frame(epoch=3, origin=main_id, counter=36, fill=15),
    )
    taken = frame(epoch=3, origin=main_id, counter=37, fill=16)
    step("a pass before a CRC twin", taken)
    twin = crc_twin(frame(epoch=3, origin=main_id, counter=38, fill=16), taken, protocol.token_size)
    step("the next round, other bytes, the same CRC: visited, not a retry", twin)
    node.rx_fault = lambda data: data[protocol.header.offsets["counter"]] == 66
    step("rx fault drops it", frame(epoch=3, origin=main_id, counter=66))
    step("rx fault lets it pass", frame(epoch=3, origin=main_id, counter=67))
    node.rx_fault = None
    node.tx_fault = lambda did, work: True
    step("tx fault drops the pass", frame(epoch=3, origin=main_id, counter=68))
    node.tx_fault = None
    transport.fail_next_send = True
    step("the send fails", frame(epoch=3, origin=main_id, counter=69))
    with node._token_lock:
        node._transmit(sonar_id)
    step("the watchdog resends")
    with node._token_lock:
        node._forward(0.0)
    step("the watchdog passes again")
    node._regeneration_streak = 2
    step("the token is back after a regeneration", frame(epoch=3, origin=main_id, counter=70))
    node._leaving = True
    step("leaving: only passed on", frame(epoch=3, origin=main_id, counter=71))
    node._leaving = False
    node._departed = True
    step("departed: ignored", frame(epoch=3, origin=main_id, counter=72))
    node._departed = False
    node.membership.set_live(sonar_id, False)
    step("the successor is gone: passes to main", frame(epoch=3, origin=main_id, counter=73))
    node.membership.set_live(main_id, False)
    step("alone: passes to itself", frame(sid=motor_id, epoch=3, origin=main_id, counter=74, ack=False))
    for member in (main_id, sonar_id):
        node.membership.set_live(member, True)
    node._confirmed_did, node._confirmed_at = sonar_id, -1e9  # a link confirmed long ago
    step("a periodic confirmation: asks, wakes nobody", frame(epoch=3, origin=main_id, counter=75))
    json.dump({"native": tokenpath.NATIVE, "steps": steps, "calls": calls}, sys.stdout)
    return 0


def deferral() -> int:
    """A visit that may wait goes to the token thread, the frames after it follow in order, and
    once the queue is empty the visits are back on the receiving thread."""
    protocol = default_protocol()
    main_id, motor_id, sonar_id = (protocol.nodes[n].id for n in ("main", "motor", "sonar"))
    transport = Recorder(motor_id)
    node = NodeOS(protocol, motor_id, transport)
    for member in (main_id, sonar_id):
        node.membership.set_live(member, True)
    frames: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
    token_thread = threading.Thread(target=node._token_loop, args=(frames,), daemon=True)
    token_thread.start()
    node._defer = frames.put
    user = protocol.user_area_offset
    gate, entered, left, waited_on = threading.Event(), threading.Event(), threading.Event(), []

    def slow_hook(data: bytes) -> bool:  # a delay fault, say
        waited_on.append(threading.get_ident())
        entered.set()
        try:
            return not gate.wait(30)  # only this scenario sets it, after _on_frame returned
        finally:
            left.set()

    def frame(fill: int) -> bytes:  # one round each, as a ring delivers them
        token = Token(protocol)
        token["sid"], token["did"], token["epoch"] = main_id, motor_id, ACK_REQUESTED
        token["counter"] = fill
        token.buffer[user] = fill
        return token.to_frame()

    node.rx_fault = slow_hook
    node._on_frame(frame(1))
    # had the receiving thread run the hook, the hook would have ended (the gate timed out)
    returned_first = not left.is_set()
    entered.wait(30)  # frame 1 waits in the hook
    node.rx_fault = None
    node._on_frame(frame(2))  # no hook now, but frame 1 is still in flight: it must not overtake
    gate.set()
    deadline = time.monotonic() + 30
    while node.stats.visits < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    node._on_frame(frame(3))
    inline = node.stats.visits == 3  # visited before _on_frame returned
    frames.put(None)
    token_thread.join(30)
    sent = [bytes.fromhex(entry[2])[user] for entry in transport.log if entry[0] == "frame"]
    result = {
        "native": tokenpath.NATIVE,
        "returned_before_the_hook": returned_first,
        "order": sent,
        "inline_after": inline,
        "hook_ran_on_token_thread": waited_on == [token_thread.ident],
        "pending": node._deferred_pending,
    }
    json.dump(result, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(deferral() if sys.argv[1:] == ["deferral"] else main())
