"""The motor's SIP stream (issue 53): with ``TOKENRING_MOTOR_SIP_MS`` motor.data changes only at
the grid times k·100 ms of the motor's clock, each sample stamped with its grid time and holding
exactly the steps due by then; without it the motor samples on every loop tick as before.

The loop runs for real (``Program.run``) against an in-process simulator on a manual clock: the
fake node's ``receive_command`` is the only place time passes (the timeout asked for, plus a
seeded lateness), so every run is the same and takes no real time. A last test runs the motor on
an in-process ring on the real clock.
"""

from __future__ import annotations

import itertools
import math
import random
import threading
from dataclasses import dataclass, field
from typing import Any

import pytest

from modules.description import load_world
from modules.description.robot import MOTOR_SIP_ENV, SIP_PERIOD_MS, STEP_MM
from modules.motor import sip_period_ms
from modules.sensors.odometry import step_rate_hz, steps_for_angle, steps_for_distance
from modules.world.clients import MotorHardware
from modules.world.clock import ManualClock
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for
from tokenring.contract.protocol import default_protocol
from tokenring.node.channels import ReceivedCommand

MotorProgram = program("motor")
MAIN, MOTOR = 10, 20
DONE, ABORTED = 0, 1


@dataclass
class Outbox:
    done: threading.Event = field(default_factory=threading.Event)
    acknowledged: bool = True


class Channel:
    """motor.data as the fake node keeps it: every write, with the clock's time of the write."""

    def __init__(self, clock: ManualClock) -> None:
        self.clock = clock
        self.writes: list[tuple[float, dict[str, Any]]] = []

    def write(self, **values: Any) -> None:
        self.writes.append((self.clock.t, dict(values)))


class FakeOS:
    """The node the motor program talks to: commands due at given simulated times; time passes
    only while the program waits for a command (its timeout, plus up to ``late_ms`` more)."""

    name = "motor"
    stopping = False

    def __init__(
        self, clock: ManualClock, commands: list[tuple[float, str, dict]], end_ms: float, late_ms: float = 0.0
    ):
        self.clock = clock
        self.protocol = default_protocol()
        self.pending = sorted(commands, key=lambda c: c[0])
        self.end_ms = end_ms
        self.rng = random.Random(7)
        self.late_ms = late_ms
        self.channel = Channel(clock)
        self.replies: list[tuple[float, str, dict]] = []
        self.program: Any = None
        self.seq = 100

    def publish(self) -> Channel:
        return self.channel

    def set_own_input_id(self) -> None:
        pass

    def receive_command(self, timeout: float) -> ReceivedCommand | None:
        wake = self.clock.t + timeout * 1000.0 + self.rng.uniform(0.0, self.late_ms)
        if self.pending and self.pending[0][0] <= wake:
            at, name, args = self.pending.pop(0)
            self.clock.t = max(self.clock.t, at)
            self.seq += 1
            code = self.protocol.nodes["motor"].command.commands[name].code
            return ReceivedCommand(MAIN, name, code, self.seq, args)
        self.clock.t = wake
        if self.clock.t >= self.end_ms:
            self.program.stop_requested.set()
        return None

    def send_command(self, target: str, name: str, **args: Any) -> Outbox:
        self.replies.append((self.clock.t, name, args))
        box = Outbox()
        box.done.set()
        return box


def run_motor(
    monkeypatch: pytest.MonkeyPatch,
    commands: list[tuple[float, str, dict]],
    end_ms: float,
    sip: str | None = str(SIP_PERIOD_MS),
    late_ms: float = 0.0,
    start_ms: float = 1234.5,
) -> tuple[Any, FakeOS, Simulator]:
    """The motor program's real loop from ``start_ms`` to ``end_ms`` of simulated time."""
    if sip is None:
        monkeypatch.delenv(MOTOR_SIP_ENV, raising=False)
    else:
        monkeypatch.setenv(MOTOR_SIP_ENV, sip)
    clock = ManualClock(start_ms)
    sim = Simulator(load_world("empty"), seed=3, clock=clock)
    fake = FakeOS(clock, commands, end_ms, late_ms)
    motor = MotorProgram(fake, MotorHardware.local(sim))
    fake.program = motor
    motor.setup()
    motor.run()
    return motor, fake, sim


DRIVE = [
    (1_517.0, "MOVE_FORWARD", {"distance_mm": 300, "speed_pct": 100}),  # 554 half-steps, 3.00 s
    (5_003.0, "TURN_LEFT", {"angle_deg": 90, "speed_pct": 50}),  # 585 half-steps, 6.34 s
    (11_420.0, "MOVE_REVERSE", {"distance_mm": 500, "speed_pct": 70}),  # stopped half-way
    (13_151.0, "STOP", {}),
]


def test_the_sip_period_setting_is_read_from_the_environment() -> None:
    assert sip_period_ms({}) == 0
    assert sip_period_ms({MOTOR_SIP_ENV: " 100 "}) == 100
    assert sip_period_ms({MOTOR_SIP_ENV: "0"}) == 0
    for bad in ("ten", "-100", "99.5"):
        with pytest.raises(ValueError, match=MOTOR_SIP_ENV):
            sip_period_ms({MOTOR_SIP_ENV: bad})


@pytest.mark.parametrize("late_ms", [0.0, 40.0])
def test_sip_samples_are_100_ms_apart_and_every_step_is_in_them(monkeypatch, late_ms) -> None:
    motor, fake, sim = run_motor(monkeypatch, DRIVE, end_ms=15_000.0, late_ms=late_ms)
    samples = [values for _, values in fake.channel.writes]
    stamps = [s["stamp_ms"] for s in samples]
    # one sample per grid time, from the first at or before the start to the end, none missed
    assert stamps == list(range(1200, 15_001, SIP_PERIOD_MS))
    # each written at or after its grid time, within the wake-up's lateness (the first at setup)
    assert all(0 <= t - s["stamp_ms"] <= 0.5 + late_ms + 1e-6 for t, s in fake.channel.writes[1:])
    # every half-step issued is in the samples, and the sum is what the moves issued
    forward, turn = steps_for_distance(300), steps_for_angle(90)
    left = sum(b["steps_left"] - a["steps_left"] for a, b in itertools.pairwise(samples))
    right = sum(b["steps_right"] - a["steps_right"] for a, b in itertools.pairwise(samples))
    assert (left, right) == (samples[-1]["steps_left"], samples[-1]["steps_right"]) == tuple(motor.steps)
    reverse = forward - turn - left  # the stopped move's steps
    assert right == forward + turn - reverse
    assert 0 < reverse < steps_for_distance(500)
    assert sim.steps_total == [left, right]  # what the hardware was told to do
    assert motor.moves == {"done": 2, "aborted": 1, "stalled": 0, "collision": 0}


def test_sip_counters_are_the_steps_due_at_the_grid_time(monkeypatch) -> None:
    start, rate = DRIVE[0][0], step_rate_hz(100)
    total = steps_for_distance(300)
    _, fake, _ = run_motor(monkeypatch, DRIVE[:1], end_ms=6_000.0, late_ms=30.0)
    x0 = fake.channel.writes[0][1]["x_mm"]
    for _, sample in fake.channel.writes:
        due = min(total, max(0, math.floor((sample["stamp_ms"] - start) / 1000.0 * rate)))
        assert sample["steps_left"] == sample["steps_right"] == due, sample
        # the pose is the dead reckoning of exactly those steps (whole mm on the wire)
        assert abs(sample["x_mm"] - (x0 + due * STEP_MM)) <= 0.5
        moving = sample["stamp_ms"] < start + 1000.0 * total / rate
        assert sample["state"] == (1 if start <= sample["stamp_ms"] and moving else 0)


def test_a_move_ending_between_grid_times_replies_at_its_end(monkeypatch) -> None:
    motor, fake, _ = run_motor(monkeypatch, DRIVE[:2], end_ms=12_000.0)
    ends = []
    t = DRIVE[0][0]
    ends.append(t + 1000.0 * steps_for_distance(300) / step_rate_hz(100))
    t = DRIVE[1][0]
    ends.append(t + 1000.0 * steps_for_angle(90) / step_rate_hz(50))
    assert all(end % SIP_PERIOD_MS for end in ends)  # neither ends on a grid time
    replies = [(at, args) for at, name, args in fake.replies if name == "POSITION_REACHED"]
    assert [args["status"] for _, args in replies] == [DONE, DONE]
    for (at, _), end in zip(replies, ends, strict=True):
        assert 0 <= at - end <= 20.0 + 1.0  # within a motor tick, not held to the next grid time
    # the move's time is its own, not the grid's
    assert motor.report()["last_move_ms"] == pytest.approx([DRIVE[1][0], ends[1]])
    # and the first grid sample after each end shows the move complete, the motor idle
    for end in ends:
        after = next(v for _, v in fake.channel.writes if v["stamp_ms"] >= end)
        assert after["state"] == 0 and after["stamp_ms"] - end < SIP_PERIOD_MS


@pytest.mark.parametrize("sip", [None, "0"])
def test_without_the_setting_the_motor_samples_every_tick(monkeypatch, sip) -> None:
    motor, fake, _ = run_motor(monkeypatch, DRIVE[:1], end_ms=6_000.0, sip=sip)
    writes = fake.channel.writes
    stamps = [v["stamp_ms"] for _, v in writes]
    assert "sips" not in motor.report()
    assert len(writes) > 6_000 / 50  # a sample every tick: 20 ms moving, 50 ms at rest
    assert any(s % SIP_PERIOD_MS for s in stamps)
    # stamped at the time of the sample (moving: when its last step was due)
    assert all(0 <= t - v["stamp_ms"] < 20.0 for t, v in writes[1:])
    assert writes[-1][1]["steps_left"] == steps_for_distance(300)


def test_the_sip_stream_on_an_in_process_ring(monkeypatch) -> None:
    """The real clock and a memory ring: main reads stamps on the grid, and the move ends."""
    monkeypatch.setenv(MOTOR_SIP_ENV, str(SIP_PERIOD_MS))
    sim = Simulator(load_world("empty"), seed=3, speed=5.0)
    ring = MemoryRing([MAIN, MOTOR])
    try:
        main = ring.nodes[MAIN]
        main.set_own_input_id()
        ring.nodes[MOTOR].start_program(MotorProgram, MotorHardware.local(sim))
        data = main.subscribe("motor.data")
        wait_for(lambda: data.published, 5, "motor.data")
        assert main.deliver("motor", "MOVE_FORWARD", timeout=5, distance_mm=200, speed_pct=100)
        seen = set()
        reply = None
        while reply is None:
            seen.add(data.read()["stamp_ms"])
            reply = main.receive_command(timeout=0.002)
        assert reply.name == "POSITION_REACHED" and reply.args["status"] == DONE
        wait_for(lambda: data.read()["steps_left"] == steps_for_distance(200), 2, "the last steps")
        assert len(seen) > 5 and all(stamp % SIP_PERIOD_MS == 0 for stamp in seen)
        assert ring.nodes[MOTOR].program.report()["sips"] >= len(seen)
    finally:
        ring.nodes[MOTOR].stop_program()
        ring.close()


@pytest.mark.parametrize(
    ("sensors", "environ", "told"),
    [("hamburg", None, None), ("darmstadt", None, "100"), ("darmstadt", "0", "0")],
)
def test_up_sensors_darmstadt_turns_the_sip_stream_on(monkeypatch, sensors, environ, told) -> None:
    """``up --sensors darmstadt`` tells the motor to send SIPs; a setting of the caller's wins."""
    from tests.robot.test_plugin import motor_setting

    assert motor_setting(monkeypatch, sensors, MOTOR_SIP_ENV, environ) == told
