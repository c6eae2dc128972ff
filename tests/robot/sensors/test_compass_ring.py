"""The compass's calibration turn on the whole ring (real nodes, the world simulator): asked over
the PC link as before (compass CALIBRATE), it goes through main (seed 001 §4.3) — main's pilot
turns the robot once round in eight 45° stops and the compass only listens — and the compass
ends OK with the simulated motors' fields.

Who commanded the motor is judged on the wire: every token frame the tap hears is read at the
inboxes' addresses in protocol.yaml (a stdlib/PyYAML reader, nothing from tokenring), so each
command's sender, code, sequence number and arguments are seen as the ring carried them."""

from __future__ import annotations

import math
import signal
import struct
import threading
from collections import defaultdict
from typing import Any

import pytest
import yaml

from modules.description import keys as robot_keys
from tests.support.processes import REPO
from tests.support.ringjudge import Header
from tests.support.ringutil import control, tap, wait_main_answers, wait_until
from tokenring.host.pclink import open_link
from tokenring.transport.session import query

PROTOCOL = yaml.safe_load((REPO / "protocol.yaml").read_text())
MAIN, COMPASS = PROTOCOL["nodes"]["main"]["id"], PROTOCOL["nodes"]["compass"]["id"]
FREE = PROTOCOL["enums"]["command_state"]["FREE"]
#: the command header as this reader decodes it: sender u8, state u8, code u8, seq u16, incarnation u32
HEADER_FIELDS = ["sender", "state", "code", "seq", "incarnation"]
HEADER_SIZE = 9
CALIBRATING, OK = PROTOCOL["enums"]["compass_state"]["CALIBRATING"], PROTOCOL["enums"]["compass_state"]["OK"]


def code_of(node: str, command: str) -> int:
    return PROTOCOL["nodes"][node]["command"]["commands"][command]["code"]


class InboxSniffer:
    """Every command the tap sees in the named nodes' inboxes: {node: {(sender, code, seq, args)}}."""

    def __init__(self, session: Any, ring: str, nodes: tuple[str, ...]) -> None:
        assert list(PROTOCOL["command_channel"]["header"]) == HEADER_FIELDS
        self.header = Header.from_protocol()
        self.inboxes = {name: PROTOCOL["nodes"][name]["command"]["address"] for name in nodes}
        self.seen: dict[str, set[tuple[int, int, int, bytes]]] = defaultdict(set)
        self.frames = 0
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(f"tokenring/{ring}/token/*", self._on)

    def _on(self, sample: Any) -> None:
        frame = sample.payload.to_bytes()
        if not self.header.valid(frame):
            return
        found = []
        for name, address in self.inboxes.items():
            sender, state, code, seq = struct.unpack_from("<BBBH", frame, address)
            if state != FREE:
                found.append((name, (sender, code, seq, frame[address + HEADER_SIZE : address + 25])))
        with self.lock:
            self.frames += 1
            for name, command in found:
                self.seen[name].add(command)

    def commands(self, node: str) -> set[tuple[int, int, int, bytes]]:
        with self.lock:
            return set(self.seen[node])

    def close(self) -> None:
        self.sub.undeclare()


def truth_heading(session: Any, ring: str) -> float:
    (_, reply), *_ = query(session, robot_keys.world(ring, "state"), timeout=2.0)
    return float(reply["result"]["theta_rad"])


@pytest.mark.slow
def test_the_compass_calibration_turn_is_mains_pilot_and_the_compass_only_listens(
    procs: Any, ring_name: str, endpoint: str
) -> None:
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "empty", "--speed", "10",
        "--bitrate", "10M", "--duration", "400",
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            sniffer = InboxSniffer(session, ring_name, ("main", "motor", "compass"))
            link = open_link(session, ring_name, wait=60.0)

            wait_main_answers(link)
            wait_until(lambda: sniffer.frames > 100, 30, "frames on the tap")
            before = truth_heading(session, ring_name)
            # the entry point as the PC side has used it: CALIBRATE into the compass's inbox
            assert link.command("compass", "CALIBRATE", timeout=10.0)["acknowledged"]
            states: list[int] = []

            def calibrated() -> bool:
                states.append(link.read("compass.data")["state"])
                return CALIBRATING in states and states[-1] == OK

            wait_until(calibrated, 180, "the compass calibrating, then OK", interval=0.3)
            finished = wait_until(
                lambda: link.request("state")["finished"], 30, "main's calibration navigator finished"
            )
            report = control(session, ring_name, COMPASS, "program")["report"]
            after = truth_heading(session, ring_name)
            sniffer.close()
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
    output, _ = launcher.communicate(timeout=60)
    assert "Traceback" not in output, output[-3000:]

    # the compass asked main, main told it to listen: both on the wire (a command resent after an
    # unacknowledged round carries a new sequence number)
    asked = [c for c in sniffer.commands("main") if c[1] == code_of("main", "CALIBRATE_COMPASS")]
    assert asked and {c[0] for c in asked} == {COMPASS}, asked
    listen = [c for c in sniffer.commands("compass") if c[1] == code_of("compass", "CALIBRATE_LISTEN")]
    assert listen and {(c[0], c[3][0]) for c in listen} == {(MAIN, 8)}, listen
    # main's navigator saw the compass end OK after its eight turns (a ninth only for a stop the
    # compass missed: a turn that never ran)
    assert finished["navigator"] == "CompassCalibration", finished
    assert finished["calibration"]["compass_state"] == "OK", finished
    made = finished["calibration"]["turns"]
    assert made in (8, 9), finished
    # main's pilot drove the turn: turns of 45° on the spot, all from main, none from the compass
    motor = sniffer.commands("motor")
    assert not [c for c in motor if c[0] == COMPASS], motor
    turns = [c for c in motor if c[1] in (code_of("motor", "TURN_LEFT"), code_of("motor", "TURN_RIGHT"))]
    assert len({c[2] for c in turns}) == made and {c[0] for c in turns} == {MAIN}, turns
    assert {struct.unpack_from("<H", c[3])[0] for c in turns} == {45}, turns
    # the robot really went round, counter-clockwise (the world's angle is not wrapped; the
    # floor's slip leaves a turn a little off: 11° in 360° seen)
    assert abs(math.degrees(after - before) - 45.0 * made) < 25.0, (before, after)
    calibration = report["calibration"]
    assert calibration["stops"] == 8 and calibration["turning_samples"] >= 8, calibration
    # the simulated motors' fields (the world's magnetics: static (6, -4) µT, running (2, 1.5) µT)
    # and the empty room's 18 µT Earth field
    assert all(abs(a - b) < 0.5 for a, b in zip(calibration["static_ut"], (6.0, -4.0), strict=True))
    assert all(abs(a - b) < 0.7 for a, b in zip(calibration["running_ut"], (2.0, 1.5), strict=True))
    assert abs(calibration["earth_ut"] - 18.0) < 0.6, calibration
