"""The motor's MOTORS_OFF / MOTORS_ON (issue 54, Darmstadt §6.7 and table 8.2): on at boot; off, a
move under way ends ABORTED, the world's drive is unpowered, motor.data says OFF and every move
command is refused with ERROR MOTORS_OFF; on again, it drives. Seed mode has no switch. With
``TOKENRING_MOTOR_POWER=off`` (``up --sensors darmstadt``) it boots off, as the Darmstadt Pioneer,
which answered drive commands only after "Motoren an" (the key e).

The motor's real loop runs against an in-process simulator on a manual clock (the fake node of
``test_motor_sip.py``: time passes only while the program waits for a command), so every run is
the same and takes no real time.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

import modules.motor as motor_module
from modules.description import load_world
from modules.description.robot import MOTOR_POWER_ENV, MOTOR_SIP_ENV
from modules.motor import powered_at_boot
from modules.sensors.odometry import steps_for_distance
from modules.variants import ENV
from modules.world.clients import MotorHardware
from modules.world.clock import ManualClock
from modules.world.sim import Simulator
from tests.robot.sensors.test_motor_sip import FakeOS, MotorProgram, Outbox
from tokenring.contract.protocol import default_protocol

ENUMS = default_protocol().enums
CODES = {name: c.code for name, c in default_protocol().nodes["motor"].command.commands.items()}
IDLE, MOVING, OFF = (ENUMS["motor_state"][k] for k in ("IDLE", "MOVING", "OFF"))
DONE, ABORTED = ENUMS["move_status"]["DONE"], ENUMS["move_status"]["ABORTED"]
MOTORS_OFF_ERROR = ENUMS["error_code"]["MOTORS_OFF"]


class WatchedOS(FakeOS):
    """The fake node, also noting the world's truth as each command arrives and each reply's target."""

    def __init__(self, sim: Simulator, *args: Any) -> None:
        super().__init__(*args)
        self.sim = sim
        self.arrivals: list[tuple[str, dict[str, Any]]] = []
        self.sent: list[tuple[str, str, dict[str, Any]]] = []

    def receive_command(self, timeout: float):
        command = super().receive_command(timeout)
        if command is not None:
            self.arrivals.append((command.name, self.sim.truth()))
        return command

    def send_command(self, target: str, name: str, **args: Any) -> Outbox:
        self.sent.append((target, name, args))
        return super().send_command(target, name, **args)


def run_motor(
    monkeypatch: pytest.MonkeyPatch,
    commands: list[tuple[float, str, dict]],
    end_ms: float,
    algorithm: str = "ours",
    power: str | None = None,
) -> tuple[Any, WatchedOS, Simulator]:
    """The motor's real loop to ``end_ms``; ``power``: its setting for the drive at boot (None: unset)."""
    monkeypatch.delenv(MOTOR_SIP_ENV, raising=False)
    if power is None:
        monkeypatch.delenv(MOTOR_POWER_ENV, raising=False)
    else:
        monkeypatch.setenv(MOTOR_POWER_ENV, power)
    monkeypatch.setenv(ENV, f"motor={algorithm}")
    clock = ManualClock(1000.0)
    sim = Simulator(load_world("empty"), seed=3, clock=clock)  # start (1000, 1500) facing +X
    fake = WatchedOS(sim, clock, commands, end_ms)
    motor = MotorProgram(fake, MotorHardware.local(sim))
    fake.program = motor
    motor.setup()
    motor.run()
    return motor, fake, sim


def states(fake: FakeOS, since_ms: float = 0.0, until_ms: float = float("inf")) -> set[int]:
    return {values["state"] for t, values in fake.channel.writes if since_ms <= t < until_ms}


FORWARD_1M = {"distance_mm": 1000, "speed_pct": 100}  # 1845 half-steps, 10 s


def test_motor_constants_are_protocol_yamls() -> None:
    m = motor_module
    mine = {
        "motor_state": {"IDLE": m.IDLE, "MOVING": m.MOVING, "STALLED": m.STALLED_STATE,
                        "COLLISION": m.COLLISION_STATE, "OFF": m.OFF},
        "move_status": {"DONE": m.DONE, "ABORTED": m.ABORTED, "STALLED": m.STALLED, "COLLISION": m.COLLISION},
        "error_code": {"BAD_ARGUMENT": m.BAD_ARGUMENT, "MOTORS_OFF": m.MOTORS_OFF},
    }  # fmt: skip
    for enum, values in mine.items():
        assert values == {name: ENUMS[enum][name] for name in values}, enum
    assert len(mine["motor_state"]) == len(ENUMS["motor_state"])
    moves = {"MOVE_FORWARD", "MOVE_REVERSE", "TURN_LEFT", "TURN_RIGHT", "SET_WHEEL_SPEEDS"}
    assert set(m.MOVE_COMMANDS) == moves


def test_on_at_boot_and_nobody_switching_changes_nothing(monkeypatch) -> None:
    motor, fake, sim = run_motor(monkeypatch, [(1100.0, "MOVE_FORWARD", FORWARD_1M)], end_ms=12_000.0)
    assert motor.powered and sim.truth()["drive"]
    assert [(n, a["status"]) for _, n, a in fake.sent] == [("POSITION_REACHED", DONE)]
    assert states(fake) == {IDLE, MOVING} and motor.steps == [1845, 1845]


def test_motors_off_ends_the_move_unpowers_the_drive_and_refuses_moves(monkeypatch, caplog) -> None:
    commands = [
        (1100.0, "MOVE_FORWARD", FORWARD_1M),
        (3000.0, "MOTORS_OFF", {}),
        (4000.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 50}),
        (4500.0, "TURN_LEFT", {"angle_deg": 90, "speed_pct": 50}),
        (5000.0, "SET_WHEEL_SPEEDS", {"left_pct": 40, "right_pct": -40, "duration_ms": 1500}),
        (5200.0, "MOVE_REVERSE", {"distance_mm": 100, "speed_pct": 150}),  # off comes first
        (5500.0, "STOP", {}),
        (5600.0, "SET_GLOBAL_POSITION", {"x_mm": 1500, "y_mm": 1500, "angle_cdeg": 0}),
    ]
    with caplog.at_level(logging.INFO, logger="tokenring.motor"):
        motor, fake, sim = run_motor(monkeypatch, commands, end_ms=7_000.0)

    # the move under way ends as for STOP; each refused move gets ERROR MOTORS_OFF, STOP nothing
    reached, *errors = fake.sent
    assert reached == ("main", "POSITION_REACHED", {"status": ABORTED, "move_seq": 101})
    refused = ["MOVE_FORWARD", "TURN_LEFT", "SET_WHEEL_SPEEDS", "MOVE_REVERSE"]
    assert errors == [("main", "ERROR", {"error": MOTORS_OFF_ERROR, "about": CODES[n]}) for n in refused]
    why = [r.getMessage() for r in caplog.records if "motors are off: MOTORS_ON first" in r.getMessage()]
    assert len(why) == 4 and all(n in line for n, line in zip(refused, why, strict=True))

    # motor.data says OFF from the switch on, and no step was issued after it
    assert states(fake, since_ms=3000.0) == {OFF}
    off_at = next(v for t, v in fake.channel.writes if t >= 3000.0)
    assert 0 < off_at["steps_left"] < 1845 and off_at["direction"] == 0 and off_at["speed_pct"] == 0
    last = fake.channel.writes[-1][1]
    assert (last["steps_left"], last["steps_right"]) == (off_at["steps_left"], off_at["steps_right"])
    assert (last["x_mm"], last["angle_cdeg"]) == (1500, 0)  # SET_GLOBAL_POSITION needs no power

    # the world: the drive unpowered, the robot where it stopped, no step arrived
    truth = sim.truth()
    assert not truth["drive"] and not truth["moving"]
    assert truth["steps"] == [off_at["steps_left"], off_at["steps_right"]]
    assert truth["steps_unpowered"] == [0, 0]
    assert [name for name, _ in fake.arrivals[:2]] == ["MOVE_FORWARD", "MOTORS_OFF"]
    poses_while_off = {(t["x"], t["y"], t["theta"]) for _, t in fake.arrivals[2:]}
    assert poses_while_off == {(truth["x"], truth["y"], truth["theta"])}
    assert motor.report()["powered"] is False and motor.report()["motors_off"] == 1
    assert motor.moves["aborted"] == 1 and motor.refused == 4


def test_motors_on_powers_the_drive_again_and_it_moves(monkeypatch) -> None:
    commands = [
        (1100.0, "MOTORS_OFF", {}),
        (1500.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 100}),
        (2000.0, "MOTORS_ON", {}),
        (2500.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 100}),
    ]
    motor, fake, sim = run_motor(monkeypatch, commands, end_ms=6_000.0)
    assert [n for _, n, _ in fake.sent] == ["ERROR", "POSITION_REACHED"]
    assert fake.sent[-1][2] == {"status": DONE, "move_seq": 104}
    assert states(fake, 1100.0, 2000.0) == {OFF}
    assert states(fake, since_ms=2000.0) == {IDLE, MOVING}
    assert motor.powered and sim.truth()["drive"]
    assert motor.steps == [steps_for_distance(200)] * 2
    assert sim.truth()["x"] - 1000.0 == pytest.approx(200 * 1.01, abs=5)


def test_motors_on_while_on_leaves_a_move_alone(monkeypatch) -> None:
    commands = [(1100.0, "MOVE_FORWARD", FORWARD_1M), (3000.0, "MOTORS_ON", {})]
    motor, fake, _ = run_motor(monkeypatch, commands, end_ms=12_000.0)
    assert [(n, a["status"]) for _, n, a in fake.sent] == [("POSITION_REACHED", DONE)]
    assert motor.motors_on == 1 and motor.steps == [1845, 1845]


def test_seed_mode_has_no_switch_motors_off_only_aborts_the_move(monkeypatch) -> None:
    commands = [
        (1100.0, "MOVE_FORWARD", FORWARD_1M),
        (3000.0, "MOTORS_OFF", {}),
        (4000.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 100}),
    ]
    motor, fake, sim = run_motor(monkeypatch, commands, end_ms=8_000.0, algorithm="seed")
    # the first move aborted without a reply (seed §4.3.3), the second one driven
    assert fake.sent == [("main", "POSITION_REACHED", {"status": DONE, "move_seq": 103})]
    assert OFF not in states(fake) and motor.powered and sim.truth()["drive"]
    assert motor.report()["ignored"] == 1 and motor.motors_off == 1
    assert motor.moves == {"done": 1, "aborted": 1, "stalled": 0, "collision": 0}


@pytest.mark.parametrize("power", [None, "on", " ON "])
def test_on_at_boot_without_the_setting_or_with_on(monkeypatch, power) -> None:
    motor, fake, sim = run_motor(monkeypatch, [(1100.0, "MOVE_FORWARD", FORWARD_1M)], 12_000.0, power=power)
    assert fake.channel.writes[0][1]["state"] == IDLE
    assert motor.powered and sim.truth()["drive"] and motor.steps == [1845, 1845]
    assert [(n, a["status"]) for _, n, a in fake.sent] == [("POSITION_REACHED", DONE)]


def test_off_at_boot_with_the_setting_until_motors_on(monkeypatch, caplog) -> None:
    """The Darmstadt Pioneer: off from the first sample on, a move refused and nothing stepped;
    after MOTORS_ON (the operator's e) the same move drives."""
    commands = [
        (1100.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 100}),
        (2000.0, "MOTORS_ON", {}),
        (2500.0, "MOVE_FORWARD", {"distance_mm": 200, "speed_pct": 100}),
    ]
    with caplog.at_level(logging.INFO, logger="tokenring.motor"):
        motor, fake, sim = run_motor(monkeypatch, commands, end_ms=6_000.0, power="off")
    assert fake.channel.writes[0] == (1000.0, {**fake.channel.writes[0][1], "state": OFF})
    assert states(fake, until_ms=2000.0) == {OFF}
    assert fake.arrivals[0][1]["drive"] is False  # the world's drive unpowered from boot
    assert fake.arrivals[1][1]["x"] == 1000.0 and fake.arrivals[1][1]["steps"] == [0, 0]
    assert fake.sent[0] == ("main", "ERROR", {"error": MOTORS_OFF_ERROR, "about": CODES["MOVE_FORWARD"]})
    assert fake.sent[1] == ("main", "POSITION_REACHED", {"status": DONE, "move_seq": 103})
    assert states(fake, since_ms=2000.0) == {IDLE, MOVING}
    assert motor.powered and sim.truth()["drive"] and sim.truth()["steps_unpowered"] == [0, 0]
    assert motor.steps == [steps_for_distance(200)] * 2
    assert sim.truth()["x"] - 1000.0 == pytest.approx(200 * 1.01, abs=5)
    assert motor.report()["motors_on"] == 1 and motor.refused == 1
    assert any("off at boot (TOKENRING_MOTOR_POWER=off)" in r.getMessage() for r in caplog.records)


def test_seed_mode_has_no_switch_and_boots_on_whatever_the_setting(monkeypatch) -> None:
    motor, fake, sim = run_motor(
        monkeypatch, [(1100.0, "MOVE_FORWARD", FORWARD_1M)], 12_000.0, algorithm="seed", power="off"
    )
    assert motor.powered and sim.truth()["drive"] and OFF not in states(fake)
    assert fake.sent == [("main", "POSITION_REACHED", {"status": DONE, "move_seq": 101})]


def test_the_power_setting_is_on_or_off() -> None:
    assert powered_at_boot({}) and powered_at_boot({MOTOR_POWER_ENV: "on"})
    assert powered_at_boot({MOTOR_POWER_ENV: ""})
    assert not powered_at_boot({MOTOR_POWER_ENV: "off"}) and not powered_at_boot({MOTOR_POWER_ENV: " Off"})
    for bad in ("0", "no", "of", "false"):
        with pytest.raises(ValueError, match=f"{MOTOR_POWER_ENV}=.*on or off"):
            powered_at_boot({MOTOR_POWER_ENV: bad})


@pytest.mark.parametrize(
    ("sensors", "environ", "told"),
    [("hamburg", None, None), ("darmstadt", None, "off"), ("darmstadt", "on", "on")],
)
def test_up_sensors_darmstadt_boots_the_drive_off(monkeypatch, sensors, environ, told) -> None:
    """``up --sensors darmstadt`` tells the motor to boot off; a setting of the caller's wins."""
    from tests.robot.test_plugin import motor_setting

    assert motor_setting(monkeypatch, sensors, MOTOR_POWER_ENV, environ) == told


def test_up_refuses_a_bad_power_setting_before_anything_starts(monkeypatch) -> None:
    from tests.robot.test_plugin import plan
    from tokenring import UsageError

    monkeypatch.setenv(MOTOR_POWER_ENV, "maybe")
    with pytest.raises(UsageError, match=f"{MOTOR_POWER_ENV}='maybe': on or off"):
        plan("--sensors", "darmstadt")
