"""A held wheel speed renewed (issue 54's dead-man: the operator's arrows send SET_WHEEL_SPEEDS
for 3 s and renew it every second): the motor extends the move under way instead of aborting and
restarting it, so the drive steps on without a pause, the coils stay energised and the commander
hears nothing until the last renewal's time runs out; other speeds still replace the move.

The motor's real loop against an in-process simulator on a manual clock (the fake node of
``test_motor_power.py``): every run is the same and takes no real time.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

import modules.motor as motor_module
from modules.description import load_world
from modules.description.robot import MOTOR_SIP_ENV
from modules.sensors.odometry import step_rate_hz
from modules.variants import ENV
from modules.world.clients import MotorHardware
from modules.world.clock import ManualClock
from modules.world.sim import Simulator
from tests.robot.sensors.test_motor_power import ABORTED, DONE, IDLE, MOVING, WatchedOS, states
from tests.robot.sensors.test_motor_sip import MotorProgram


def run_motor(
    monkeypatch: pytest.MonkeyPatch, commands: list[tuple[float, str, dict]], end_ms: float
) -> tuple[Any, WatchedOS, list[bool]]:
    """The motor's loop from 1000 ms to ``end_ms``; also every batch's ``energised`` flag."""
    monkeypatch.delenv(MOTOR_SIP_ENV, raising=False)
    monkeypatch.setenv(ENV, "motor=ours")
    clock = ManualClock(1000.0)
    sim = Simulator(load_world("empty"), seed=3, clock=clock)
    energised: list[bool] = []
    steps = sim.motor_steps

    def recorded(request: dict[str, Any]) -> dict[str, Any]:
        energised.append(bool(request.get("energised", True)))
        return steps(request)

    monkeypatch.setattr(sim, "motor_steps", recorded)
    fake = WatchedOS(sim, clock, commands, end_ms)
    motor = MotorProgram(fake, MotorHardware.local(sim))
    fake.program = motor
    motor.setup()
    motor.run()
    return motor, fake, energised


def wheels(left: int, right: int, ms: int = 3000) -> dict[str, int]:
    return {"left_pct": left, "right_pct": right, "duration_ms": ms}


def test_a_renewal_extends_the_wheel_move_without_a_pause(monkeypatch) -> None:
    renewals = [(t, "SET_WHEEL_SPEEDS", wheels(50, 50)) for t in (3000.0, 4000.0, 5000.0)]
    motor, fake, energised = run_motor(
        monkeypatch, [(2000.0, "SET_WHEEL_SPEEDS", wheels(50, 50)), *renewals], end_ms=10_000.0
    )
    # one move from 2 s to 3 s after the last renewal, one reply at its end
    assert motor.renewals == 3 and motor.moves["aborted"] == 0 and motor.moves["done"] == 1
    assert [(n, a["status"]) for _, n, a in fake.sent] == [("POSITION_REACHED", DONE)]
    assert motor.steps == [math.floor(step_rate_hz(50) * 6.0)] * 2
    assert states(fake, 2000.0, 7990.0) == {MOVING} and states(fake, since_ms=8100.0) == {IDLE}
    # the coils were switched off once: at the end, never between renewals
    assert energised.count(False) == 1 and energised[-1] is False


def test_other_speeds_replace_the_move_and_it_stops_when_renewals_stop(monkeypatch) -> None:
    commands = [
        (2000.0, "SET_WHEEL_SPEEDS", wheels(50, 50)),
        (3000.0, "SET_WHEEL_SPEEDS", wheels(75, 75)),  # ↑ pressed: a new move at the new speed
        (4000.0, "SET_WHEEL_SPEEDS", wheels(75, 75)),
    ]
    motor, fake, _ = run_motor(monkeypatch, commands, end_ms=10_000.0)
    assert motor.renewals == 1 and motor.moves["aborted"] == 1 and motor.moves["done"] == 1
    assert [a["status"] for _, _, a in fake.sent] == [ABORTED, DONE]
    # the last renewal at 4 s held the drive for 3 s: it stands from 7 s on
    assert states(fake, 3000.0, 6990.0) == {MOVING} and states(fake, since_ms=7100.0) == {IDLE}
    # the replaced move's steps up to its last tick (an abort does not issue those due since)
    full = math.floor(step_rate_hz(50) * 1.0) + math.floor(step_rate_hz(75) * 4.0)
    tick = math.ceil(step_rate_hz(50) * motor_module.TICK_SIM_S)
    assert motor.steps[0] == motor.steps[1] and full - tick <= motor.steps[0] <= full
