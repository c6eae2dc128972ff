"""The world simulator between two batches of motor steps: the robot drives on.

The motor sends its steps in batches (every 20 simulated ms, but at speed 20 no more often than
every 4 real ms = 80 simulated ms, more under load); a sonar ping, a compass measurement or a
truth sample asked for in between must see the robot where it is at its stamp, not where the
last batch left it (the ring's sonar read ~10 mm short of the truth at 100 mm/s because of it).
"""

from __future__ import annotations

import math

import pytest

from modules.description import load_world
from modules.description.robot import SONAR_MOUNTS, STEP_MM
from modules.world.clock import ManualClock
from modules.world.sim import VELOCITY_HOLD_MS, Simulator


def driving(rate_hz: float = 184.5) -> tuple[Simulator, ManualClock, float]:
    """A simulator whose robot just got a batch of 100 ms of forward steps; (sim, clock, mm/ms)."""
    clock = ManualClock(1000.0)
    sim = Simulator(load_world("empty"), seed=5, clock=clock)  # start (1000, 1500) facing +X
    steps = round(rate_hz * 0.1)
    moved = sim.motor_steps({"left": steps, "right": steps, "rate_hz": rate_hz, "move": 1})["moved_mm"]
    assert moved == pytest.approx(steps * STEP_MM, rel=0.1)
    return sim, clock, moved / (1000.0 * steps / rate_hz)


def test_truth_between_batches_is_where_the_driving_robot_is_at_its_stamp():
    sim, clock, speed = driving()
    after_batch = sim.robot.pose
    clock.t += 60.0  # 60 ms after the batch, before the next one
    truth = sim.truth()
    assert truth["stamp_ms"] == 1060
    assert truth["x"] == pytest.approx(after_batch.x + 60.0 * speed * math.cos(after_batch.theta), abs=0.01)
    assert truth["y"] == pytest.approx(after_batch.y + 60.0 * speed * math.sin(after_batch.theta), abs=0.01)
    # the next batch brings the steps made meanwhile: the pose goes on from there, no jump back
    steps = round(184.5 * 0.06)
    sim.motor_steps({"left": steps, "right": steps, "rate_hz": 184.5, "move": 1})
    assert sim.truth()["x"] == pytest.approx(truth["x"], abs=1.0)


def test_a_sweep_between_batches_pings_from_where_the_robot_is_at_each_pairs_stamp(monkeypatch):
    import modules.world.sim as sim_module

    sim, clock, speed = driving()
    after_batch = sim.robot.pose
    used: list[float] = []
    real = sim_module.sonar_world_pose

    def recording(x: float, y: float, theta: float, sensor: int, mounts=SONAR_MOUNTS):
        used.append(x)
        return real(x, y, theta, sensor, mounts)

    monkeypatch.setattr(sim_module, "sonar_world_pose", recording)
    clock.t += 70.0
    reply = sim.sonar_ping({"sensors": list(range(8)), "slot_ms": 15.0})
    for x, stamp in zip(used, reply["stamps_ms"], strict=True):
        assert x == pytest.approx(after_batch.x + (stamp - 1000.0) * speed, abs=0.01)


def test_the_robot_stands_once_the_motors_stop_or_no_batch_came_for_a_while():
    sim, clock, _ = driving()
    after_batch = sim.robot.pose
    clock.t += VELOCITY_HOLD_MS + 10.0  # the motor sent nothing for longer than it ever pauses
    assert sim.truth()["x"] == pytest.approx(after_batch.x, abs=1e-9)
    sim, clock, _ = driving()
    sim.motor_steps({"left": 0, "right": 0, "rate_hz": 184.5, "move": 1, "energised": False})
    stopped = sim.robot.pose
    clock.t += 50.0
    assert sim.truth()["x"] == pytest.approx(stopped.x, abs=1e-9)


def test_without_power_the_robot_stands_between_batches_too():
    sim, clock, _ = driving()
    sim.charger_relay({"on": False, "reason": "test"})  # the relays drop: no power for the motors
    assert sim.motor_steps({"left": 10, "right": 10, "rate_hz": 184.5, "move": 1})["power"] is False
    standing = sim.robot.pose
    clock.t += 50.0
    assert sim.truth()["x"] == pytest.approx(standing.x, abs=1e-9)
