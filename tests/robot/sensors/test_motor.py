"""The motor module: the seed's glide-factor formula, dead reckoning, and its commands run on an
in-process ring against the simulator (memory transport, hardware wired straight in)."""

from __future__ import annotations

import math

import pytest

from modules.description import load_world
from modules.description.robot import STEP_MM
from modules.sensors.odometry import DeadReckoning, recalc_glide_factor, steps_for_angle, steps_for_distance
from modules.units import cdeg_to_rad, pose_from_wire
from modules.world.clients import MotorHardware
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for

DONE, ABORTED, STALLED, COLLISION = range(4)


MotorProgram = program("motor")


def test_glide_factor_formula_with_the_seeds_numbers():
    # μ_new = α_target / (α_target + Δα) · μ_old, μ = 6.5 on tiles (seed 4.2)
    assert recalc_glide_factor(6.5, 90, -10) == pytest.approx(6.5 * 90 / 80)
    assert recalc_glide_factor(6.5, 360, 36) == pytest.approx(6.5 / 1.1)
    assert recalc_glide_factor(6.5, -90, 10) == pytest.approx(6.5 * 90 / 80)  # turning the other way
    with pytest.raises(ValueError, match="cannot correct"):
        recalc_glide_factor(6.5, 90, -90)
    with pytest.raises(ValueError, match="implausible"):
        recalc_glide_factor(6.5, 90, -89)


def test_step_arithmetic_and_dead_reckoning():
    assert abs(STEP_MM - 0.5419) < 1e-4
    assert steps_for_distance(1000) == 1845
    assert steps_for_angle(90) == 585  # 6.5 half-steps per degree
    dr = DeadReckoning(100.0, 200.0, 0.0)
    dr.apply(1845, 1845)
    assert (dr.x, dr.y) == pytest.approx((100 + 1845 * STEP_MM, 200.0))
    dr.apply(-585, 585)  # turn left 90°
    assert dr.theta == pytest.approx(math.pi / 2)
    dr.apply(100, 100)
    assert dr.y == pytest.approx(200 + 100 * STEP_MM)


class Bench:
    """main + motor on a memory ring; motor runs its real program on a local simulator."""

    def __init__(self, world="empty", seed=3, speed=50.0):
        self.sim = Simulator(load_world(world) if isinstance(world, str) else world, seed=seed, speed=speed)
        self.ring = MemoryRing([10, 20])
        self.main = self.ring.nodes[10]
        self.main.set_own_input_id()
        self.motor_os = self.ring.nodes[20]
        self.motor_os.start_program(MotorProgram, MotorHardware.local(self.sim))
        self.data = self.main.subscribe("motor.data")
        wait_for(lambda: self.motor_os.program and getattr(self.motor_os.program, "out", None), 5, "motor up")

    def command(self, name, **args):
        assert self.main.deliver("motor", name, timeout=5, **args), f"{name} not acknowledged"

    def reached(self, timeout=10.0):
        cmd = self.main.receive_command(timeout=timeout)
        assert cmd is not None and cmd.name == "POSITION_REACHED", cmd
        return cmd.args

    def pose(self):
        d = self.data.read()
        return pose_from_wire(d["x_mm"], d["y_mm"], d["angle_cdeg"])

    def close(self):
        self.motor_os.stop_program()
        self.ring.close()


@pytest.fixture
def bench():
    b = Bench()
    yield b
    b.close()


def test_forward_move_reaches_with_dead_reckoning_within_slip_bounds(bench):
    start = bench.sim.truth()
    bench.command("MOVE_FORWARD", distance_mm=1000, speed_pct=100)
    reply = bench.reached()
    assert reply["status"] == DONE
    x, y, theta = bench.pose()
    d = bench.data.read()
    assert d["steps_left"] == d["steps_right"] == 1845 and d["state"] == 0 and d["distance_mm"] == 1000
    assert d["move_seq"] == reply["move_seq"]
    truth = bench.sim.truth()
    dead_reckoned = x - start["x_mm"]
    driven = truth["x_mm"] - start["x_mm"]
    assert dead_reckoned == pytest.approx(1845 * STEP_MM, abs=1)
    # true step length: +1 % systematic, 0.5 % random per move (3 sigma)
    assert 1.01 - 0.015 <= driven / dead_reckoned <= 1.01 + 0.015
    assert abs(truth["y_mm"] - start["y_mm"]) < 1e-6 and y == start["y_mm"] and theta == 0.0
    # simulated time: 1845 steps at 184.5 Hz take 10 s; the last counter sample is stamped with
    # the time its last step was due, not when the batch went out
    begun, ended = bench.motor_os.program.report()["last_move_ms"]
    assert ended - begun == pytest.approx(1845 / (100 / STEP_MM) * 1000, abs=0.01)


def test_turn_is_off_by_the_glide_error_and_recalc_reduces_it():
    floor_world = load_world("empty")
    from dataclasses import replace

    world = replace(floor_world, floor=replace(floor_world.floor, glide_factor=7.8, glide_spread=0.0))
    bench = Bench(world)
    try:
        before = bench.sim.truth()["theta_rad"]
        bench.command("TURN_LEFT", angle_deg=90, speed_pct=100)
        assert bench.reached()["status"] == DONE
        turned = math.degrees(bench.sim.truth()["theta_rad"] - before)
        assert turned == pytest.approx(90 * 6.5 / 7.8, abs=0.5)  # 75°: the robot believes 90°
        assert math.degrees(bench.pose()[2]) == pytest.approx(90, abs=0.1)
        bench.command("RECALC_GLIDE_FACTOR", target_deg=90, error_cdeg=round((turned - 90) * 100))
        wait_for(lambda: bench.data.read()["glide_cfactor"] != 650, 5, "new glide factor")
        assert bench.data.read()["glide_cfactor"] == pytest.approx(780, abs=2)
        before = bench.sim.truth()["theta_rad"]
        bench.command("TURN_RIGHT", angle_deg=90, speed_pct=100)
        assert bench.reached()["status"] == DONE
        turned_after = math.degrees(before - bench.sim.truth()["theta_rad"])
        assert abs(turned_after - 90) < 0.5 < abs(turned - 90)
    finally:
        bench.close()


def test_new_command_aborts_stop_and_set_global_position(bench):
    bench.command("MOVE_FORWARD", distance_mm=2000, speed_pct=50)
    wait_for(lambda: bench.data.read()["steps_left"] > 100, 5, "moving")
    bench.command("STOP")
    assert bench.reached()["status"] == ABORTED
    wait_for(lambda: bench.data.read()["state"] == 0, 5, "stopped")
    steps = bench.data.read()["steps_left"]
    assert 0 < steps < 3690
    bench.command("SET_GLOBAL_POSITION", x_mm=-500, y_mm=250, angle_cdeg=27000)  # 270° clockwise = +90° CCW
    wait_for(lambda: bench.data.read()["x_mm"] == -500, 5, "new pose")
    x, y, theta = bench.pose()
    assert (x, y) == (-500, 250) and theta == pytest.approx(cdeg_to_rad(27000)) == pytest.approx(math.pi / 2)
    assert bench.data.read()["steps_left"] == steps  # the counters are cumulative, never reset


def test_bad_speed_is_refused_and_nothing_moves(bench):
    start = bench.sim.truth()
    bench.command("MOVE_FORWARD", distance_mm=500, speed_pct=150)
    reply = bench.main.receive_command(timeout=5)
    assert reply is not None and reply.name == "ERROR" and reply.args["error"] == 2
    assert bench.motor_os.program.refused == 1
    assert bench.sim.truth()["x_mm"] == start["x_mm"] and bench.data.read()["steps_left"] == 0


def test_collision_stops_the_robot_and_is_reported():
    bench = Bench("empty")  # start (1000, 1500) facing +X, wall at x = 4000
    try:
        bench.command("MOVE_FORWARD", distance_mm=5000, speed_pct=100)
        assert bench.reached(timeout=20)["status"] == COLLISION
        truth = bench.sim.truth()
        assert truth["collisions"] == 1
        assert truth["x_mm"] == pytest.approx(4000 - bench.sim.world.robot_radius, abs=1)
        assert bench.data.read()["state"] == 3
    finally:
        bench.close()
