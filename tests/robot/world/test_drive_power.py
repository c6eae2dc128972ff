"""The drive's power switch in the world (``hw/motor/power``, the motor's MOTORS_OFF/ON): while
it is off, steps that arrive are not made, the robot stands, and the truth counts them."""

from __future__ import annotations

import pytest

from modules.description import load_world
from modules.world.clients import HardwareError, MotorHardware
from modules.world.clock import ManualClock
from modules.world.sim import Simulator


def batch(sim: Simulator, steps: int, move: int = 1) -> dict:
    return sim.motor_steps({"left": steps, "right": steps, "rate_hz": 184.5, "move": move})


def test_steps_without_drive_power_are_counted_not_made_and_the_robot_stands():
    clock = ManualClock(1000.0)
    sim = Simulator(load_world("empty"), seed=5, clock=clock)  # start (1000, 1500) facing +X
    assert sim.truth()["drive"] is True  # on at power-on: the Hamburg drive has no switch
    moving = batch(sim, 18)
    assert moving["power"] and moving["drive"] and moving["moved_mm"] > 0
    driven = sim.truth()
    assert driven["moving"]

    motor = MotorHardware.local(sim)
    assert motor.power(False) == {"drive": False}
    clock.t += 20.0
    off = sim.truth()
    assert not off["drive"] and not off["moving"]
    assert off["x"] == pytest.approx(driven["x"], abs=1e-9)  # no coasting on the last batch's speed
    for _ in range(5):
        reply = batch(sim, 4)
        assert reply["power"] is False and reply["drive"] is False and reply["moved_mm"] == 0.0
        clock.t += 20.0
    reverse = sim.motor_steps({"left": -3, "right": 3, "rate_hz": 184.5, "move": 2})
    assert reverse["power"] is False
    stood = sim.truth()
    assert (stood["x"], stood["y"], stood["theta"]) == (off["x"], off["y"], off["theta"])
    assert stood["steps"] == driven["steps"] == [18, 18]  # none taken
    assert stood["steps_unpowered"] == [5 * 4 - 3, 5 * 4 + 3]
    assert stood["motors"]["a"] == 0.0  # no current in the coils

    assert motor.power(True) == {"drive": True}
    again = batch(sim, 18, move=3)
    assert again["power"] and again["moved_mm"] > 0
    assert sim.truth()["x"] > stood["x"] and sim.truth()["steps"] == [36, 36]


def test_the_power_switch_takes_true_or_false_only():
    sim = Simulator(load_world("empty"), seed=5, clock=ManualClock(0.0))
    with pytest.raises(HardwareError, match="on must be true or false"):
        MotorHardware.local(sim).request("motor/power", {"on": 1})
    assert sim.truth()["drive"] is True
