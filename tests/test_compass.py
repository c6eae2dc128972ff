"""The compass: heading from the two bridges over a full circle with the motors' field calibrated
out (the seed's compass never worked), and the module calibrating itself on an in-process ring."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hwprograms import program
from memring import MemoryRing, wait_for

from modules.common.compass import angle_difference, fit_circle, flip_measurement, heading_from_bridges
from modules.common.units import cdeg_to_heading
from tokenring.hw import CompassHardware, MotorHardware
from tokenring.world import load_world
from tokenring.world.magnetics import CompassBridges
from tokenring.world.sim import Simulator

CompassProgram = program("compass")
MotorProgram = program("motor")


def measure(bridges: CompassBridges, theta: float, comp=(0.0, 0.0), running=False, t=0.0) -> np.ndarray:
    plus = bridges.measure(0, 0, theta, running, 1, comp, 20, t)
    minus = bridges.measure(0, 0, theta, running, -1, comp, 20, t + 20)
    return flip_measurement(plus, minus, comp)[0]


def heading_errors(bridges, world, comp, running=False) -> list[float]:
    errors = []
    for i, deg in enumerate(range(0, 360, 10)):
        theta = math.radians(deg)
        field = measure(bridges, theta, comp, running, t=100.0 * i)
        heading, _ = heading_from_bridges(*field)
        errors.append(math.degrees(abs(angle_difference(heading, world.heading(theta)))))
    return errors


def test_heading_within_2_degrees_over_a_full_circle_once_the_motor_field_is_calibrated_out():
    world = load_world("empty")
    bridges = CompassBridges(world, np.random.default_rng(7))
    uncalibrated = heading_errors(bridges, world, (0.0, 0.0))
    assert max(uncalibrated) > 10  # the motors' static field is a third of the Earth's
    stops = np.array([measure(bridges, math.radians(a), t=5000 + a) for a in range(0, 360, 45)])
    cx, cy, radius = fit_circle(stops)
    assert (cx, cy) == pytest.approx((6.0, -4.0), abs=0.3)  # the simulated motors' static field
    assert radius == pytest.approx(world.earth_field_ut, rel=0.03)
    calibrated = heading_errors(bridges, world, (-cx, -cy))
    assert max(calibrated) <= 2.0, calibrated
    assert float(np.median(calibrated)) <= 1.0


def test_bridge_choice_uses_the_steep_one_and_arccos():
    h = 18.0
    for deg, bridge in ((0, 1), (30, 1), (60, 0), (90, 0), (135, 0), (180, 1), (250, 0), (330, 1)):
        psi = math.radians(deg)
        heading, used = heading_from_bridges(h * math.cos(psi), h * math.sin(psi))
        assert used == bridge and math.degrees(heading) == pytest.approx(deg)


def test_flip_removes_the_bridge_offset():
    world = load_world("empty")
    bridges = CompassBridges(world, np.random.default_rng(3))
    bridges.offsets[:] = [300.0, -250.0]  # big electrical offsets: the flip pair cancels them
    plus = bridges.measure(0, 0, 0.0, False, 1, (0.0, 0.0), 20, 0.0)
    minus = bridges.measure(0, 0, 0.0, False, -1, (0.0, 0.0), 20, 20.0)
    field, offsets = flip_measurement(plus, minus, (0.0, 0.0))
    assert offsets == pytest.approx([300, -250], abs=5)
    expected = bridges.field(0, 0, 0.0, False)
    assert field == pytest.approx(expected, abs=0.3)


def test_compass_module_calibrates_by_turning_and_then_follows_the_true_heading():
    sim = Simulator(load_world("empty"), seed=11, speed=40.0)
    ring = MemoryRing([10, 20, 40])
    main = ring.nodes[10]
    main.set_own_input_id()
    data = main.subscribe("compass.data")
    ring.nodes[20].start_program(MotorProgram, MotorHardware.local(sim))
    ring.nodes[40].start_program(CompassProgram, CompassHardware.local(sim))
    try:
        wait_for(lambda: data.visits and data.read()["sample"] > 2, 10, "compass samples")
        assert data.read()["state"] == 0  # UNCALIBRATED
        assert main.deliver("compass", "CALIBRATE", timeout=5)
        wait_for(lambda: data.read()["state"] == 1, 30, "calibration done")
        calibration = ring.nodes[40].program.report()["calibration"]
        assert calibration["static_ut"] == pytest.approx([6.0, -4.0], abs=0.5)
        assert calibration["running_ut"] == pytest.approx([2.0, 1.5], abs=0.7)
        errors = []
        for _ in range(4):
            assert main.deliver("motor", "TURN_RIGHT", angle_deg=70, speed_pct=100, timeout=5)
            cmd = main.receive_command(timeout=20)
            assert cmd is not None and cmd.name == "POSITION_REACHED"
            sample = data.read()["sample"]
            wait_for(lambda s=sample: data.read()["sample"] >= s + 4, 10, "fresh headings")
            heading = cdeg_to_heading(data.read()["heading_cdeg"])
            errors.append(math.degrees(abs(angle_difference(heading, sim.truth()["heading_rad"]))))
        assert max(errors) <= 2.5, errors
    finally:
        for node_id in (20, 40):
            ring.nodes[node_id].stop_program()
        ring.close()


def test_calibration_leaves_out_readings_taken_after_the_motor_stopped() -> None:
    """motor.data tells the compass of the stop a token round late: readings taken at rest in
    that time lie on the static circle and would pull the running field's estimate short."""

    class Stub:
        """Readings every 40 ms; the motor stops at 400 ms, motor.data says so at 560 ms."""

        def __init__(self) -> None:
            self.now = 0.0
            self.running = True
            self.period_real = 0.0
            self.clock = self
            self.os = self
            self.motor = {"stamp_ms": 0.0, "direction": 3}

        def now_ms(self) -> float:
            return self.now

        def read_field(self):
            stamp = self.now
            self.now += 40.0
            moving = stamp < 400.0
            field = np.array([2.0, 1.5]) if moving else np.zeros(2)  # running field or none
            if self.now <= 560.0:
                self.motor = {"stamp_ms": min(self.now, 400.0), "direction": 3}
            else:
                self.motor = {"stamp_ms": self.now, "direction": 0}
            return field, stamp

        def motors_moving(self) -> int:
            return int(self.motor["direction"])

        def receive_command(self, timeout=None):
            if self.motor["direction"] == 0:
                return type("Cmd", (), {"name": "POSITION_REACHED", "args": {"status": 0}})()
            return None

    turning: list[np.ndarray] = []
    assert CompassProgram._turn_and_listen(Stub(), turning)
    assert len(turning) >= 8
    assert all(field[0] == 2.0 for field in turning)  # none taken at rest
