"""The world simulator: kinematics with the SPEC §5 slip model, stalls, collisions, ray casting,
determinism, the clock, and the simulator process serving the hardware keys over Zenoh."""

from __future__ import annotations

import math
import sys
import time
from dataclasses import replace

import msgpack
import numpy as np
import pytest

from modules.description import Floor, Pose, Wall, World, load_world
from modules.description import keys as robot_keys
from modules.description.robot import MAX_STEP_RATE_HZ, SONAR_MOUNTS, STEP_MM
from modules.world.clients import HardwareError, MotorHardware, SonarHardware
from modules.world.clock import ManualClock, SimClock
from modules.world.physics import TrackedRobot, cast_rays
from modules.world.service import ready_key
from modules.world.sim import HardwareRequestError, Simulator
from tests.support.ringutil import tap, wait_until


def steps(sim: Simulator, left: int, right: int, move: int, rate: float = MAX_STEP_RATE_HZ) -> dict:
    return sim.motor_steps({"left": left, "right": right, "rate_hz": rate, "move": move})


def test_straight_steps_follow_the_slip_model_per_move():
    world = load_world("empty")
    ratios = []
    for move in range(1, 41):
        robot = TrackedRobot(world, np.random.default_rng(move))
        result = robot.apply_steps(1000, 1000, MAX_STEP_RATE_HZ, move)
        ratios.append(result.distance / (1000 * STEP_MM))
    assert np.mean(ratios) == pytest.approx(1.01, abs=0.002)  # +1 % systematic
    assert np.std(ratios) == pytest.approx(0.005, rel=0.35)  # 0.5 % random per move


def test_turns_draw_their_glide_factor_within_10_percent_and_keep_it_during_the_move():
    robot = TrackedRobot(load_world("empty"), np.random.default_rng(4))
    glides = []
    for move in range(1, 60):
        a = robot.apply_steps(-300, 300, MAX_STEP_RATE_HZ, move)
        b = robot.apply_steps(-285, 285, MAX_STEP_RATE_HZ, move)  # same move: same floor contact
        glide = 585 / math.degrees(a.rotation + b.rotation)
        assert math.degrees(a.rotation) / 300 == pytest.approx(math.degrees(b.rotation) / 285)
        glides.append(glide)
    assert min(glides) >= 6.5 * 0.9 and max(glides) <= 6.5 * 1.1
    assert max(glides) - min(glides) > 0.8  # really drawn, not fixed


def test_stall_above_the_start_stop_limit_counts_steps_but_does_not_move():
    sim = Simulator(load_world("empty"), seed=1)
    reply = steps(sim, 200, 200, 1, rate=MAX_STEP_RATE_HZ * 1.2)
    truth = sim.truth()
    assert reply["stalled"] and reply["moved_mm"] == 0 and truth["stalls"] == 1
    assert truth["x_mm"] == 1000 and truth["steps"] == [200, 200]


def test_collision_stops_at_the_wall_and_backing_off_works():
    sim = Simulator(load_world("empty"), seed=1)  # start (1000, 1500) facing +X, wall at x = 4000
    reply = steps(sim, 10000, 10000, 1)
    radius = sim.world.robot_radius
    assert reply["blocked"] and sim.truth()["x_mm"] == pytest.approx(4000 - radius, abs=0.2)
    assert sim.truth()["collisions"] == 1
    back = steps(sim, -200, -200, 2)
    assert not back["blocked"] and back["moved_mm"] < 0
    turn = steps(sim, -585, 585, 3)  # turning on the spot never collides (round robot)
    assert not turn["blocked"] and turn["turned_rad"] > 0


def test_ray_casting_hits_walls_and_circles_with_incidence():
    world = World(
        "t",
        (Wall(1000, -500, 1000, 500),),
        Pose(0, 0, 0),
        circles=(replace(load_world("slanted").circles[0], x=0.0, y=800.0, r=200.0),),
    )
    hits = cast_rays(world, 0, 0, np.array([0.0, math.radians(20), math.pi / 2, math.pi]))
    assert hits.distance[0] == pytest.approx(1000) and hits.incidence[0] == pytest.approx(0)
    assert hits.distance[1] == pytest.approx(1000 / math.cos(math.radians(20)))
    assert hits.incidence[1] == pytest.approx(math.radians(20))
    assert hits.distance[2] == pytest.approx(600) and hits.incidence[2] == pytest.approx(0, abs=1e-6)
    assert math.isinf(hits.distance[3])


def test_the_simulator_is_deterministic_given_its_seed():
    def run(seed: int) -> tuple:
        sim = Simulator(load_world("office"), seed=seed, clock=ManualClock(step_ms=10.0))
        steps(sim, 500, 500, 1)
        steps(sim, -300, 300, 2)
        ping = sim.sonar_ping({"sensors": list(range(8))})["envelopes"]
        compass = sim.compass_measure({"settings": [{"flip": 1, "comp_ut": [0, 0]}], "samples": 5})["adc"]
        truth = sim.truth()
        return truth["x_mm"], truth["y_mm"], truth["theta_rad"], ping, compass

    assert run(7) == run(7)
    assert run(7)[:3] != run(8)[:3]


def test_hardware_requests_are_checked():
    sim = Simulator(load_world("empty"))
    with pytest.raises(HardwareRequestError, match="sensors must be a list"):
        sim.handle("sonar/ping", {"sensors": [9]})
    with pytest.raises(HardwareRequestError, match="no hardware at hw/motor/fly"):
        sim.handle("motor/fly", {})
    with pytest.raises(HardwareRequestError, match="inside a wall"):
        sim.set_pose({"x_mm": 10.0, "y_mm": 10.0})
    with pytest.raises(HardwareRequestError, match="rate_hz must be positive"):
        sim.handle("motor/steps", {"left": 1, "right": 1, "rate_hz": 0})


def bracketed(read):
    """``read()`` with the real clock just before and just after it: on a loaded machine the
    thread may be preempted anywhere, so a reading is only known to lie between the two."""
    before = time.monotonic()
    value = read()
    return before, value, time.monotonic()


def test_sim_clock_runs_k_times_faster_and_copies_agree():
    clock = SimClock(speed=50.0)
    a0, t0, b0 = bracketed(clock.now_ms)
    time.sleep(0.05)
    a1, t1, b1 = bracketed(clock.now_ms)
    # 50 simulated ms per real ms, exactly: bounds from the brackets, not a tolerance on speed
    assert (a1 - b0) * 1000 * 50 <= t1 - t0 <= (b1 - a0) * 1000 * 50
    # a copy takes the world's reading as made half-way through the request's round trip
    before = time.monotonic()  # asked 0.2 s before the answer came back: read 0.1 s ago
    copy = SimClock.synced(1000.0, 50.0, time.monotonic() - 0.2, time.monotonic())
    _, reading, after = bracketed(copy.now_ms)
    assert 1000 + 0.1 * 50_000 <= reading <= 1000 + (0.1 + after - before) * 50_000
    # a copy synced from a real request agrees within half its round trip (simulated)
    sent, sim_ms, received = bracketed(clock.now_ms)
    copy = SimClock.synced(sim_ms, clock.speed, sent, received)
    r0, ours, theirs, r1 = time.monotonic(), copy.now_ms(), clock.now_ms(), time.monotonic()
    assert abs(ours - theirs) <= ((received - sent) / 2 + (r1 - r0)) * 1000 * 50
    assert clock.to_real(1.0) == pytest.approx(0.02)
    with pytest.raises(ValueError):
        SimClock(speed=0)


def test_floor_parameters_come_from_the_world():
    world = replace(
        load_world("empty"), floor=Floor(glide_factor=8.0, glide_spread=0.0, step_scale=1.0, step_noise=0.0)
    )
    sim = Simulator(world, seed=1)
    assert steps(sim, 1000, 1000, 1)["moved_mm"] == pytest.approx(1000 * STEP_MM)
    assert math.degrees(steps(sim, -800, 800, 2)["turned_rad"]) == pytest.approx(100)


def test_world_process_serves_hardware_truth_and_info_over_zenoh(procs, ring_name, endpoint, tmp_path):
    world = procs.start(
        [sys.executable, "-m", "modules.world", "--ring", ring_name, "--listen", endpoint, "--world", "square",
         "--speed", "20", "--seed", "3", "--body", "seed"]
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_until(
            lambda: any(r.ok for r in session.liveliness().get(ready_key(ring_name), timeout=0.5)),
            30,
            "world up",
        )
        truths: list[dict] = []
        clocks: list = []  # the motor's copy of the clock, once synced
        received: list[tuple[float, float]] = []  # (stamp_ms, the motor's clock when it arrived)

        def on_truth(sample) -> None:
            truth = msgpack.unpackb(sample.payload.to_bytes())
            truths.append(truth)
            if clocks:
                received.append((truth["stamp_ms"], clocks[0].now_ms()))

        sub = session.declare_subscriber(robot_keys.world(ring_name, "truth"), on_truth)
        motor = MotorHardware(session, ring_name)
        assert motor.start_pose() == (1000.0, 1000.0, 0.0)
        assert motor.clock.speed == 20.0
        clocks.append(motor.clock)
        reply = motor.steps(1845, 1845, MAX_STEP_RATE_HZ, 1, 1000, energised=False)
        assert reply["moved_mm"] == pytest.approx(1010, abs=20) and reply["power"]
        envelopes, stamps = SonarHardware(session, ring_name).ping([0, 1, 2])
        assert [len(e) for e in envelopes] == [510] * 3 and stamps[1] - stamps[0] == 15.0
        with pytest.raises(HardwareError, match="sensors must be a list"):
            SonarHardware(session, ring_name).ping([12])
        wait_until(lambda: len(received) >= 20, 30, "truth messages")
        last = truths[-1]
        assert last["x_mm"] == pytest.approx(1000 + reply["moved_mm"]) and last["world"] == "square"
        assert {"stamp_ms", "theta_rad", "heading_rad", "electronics", "motors"} <= set(last)
        # same clock: the message that came quickest (a loaded machine delays some) was stamped
        # within 200 ms real of its arrival by the motor's copy; a clock of its own would be off
        # by all the time the world had run before the copy was made
        assert min(abs(stamp - at) for stamp, at in received) < 20 * 200
        info = next(iter(session.get(robot_keys.world(ring_name, "info"), timeout=2))).ok
        info = msgpack.unpackb(info.payload.to_bytes())["result"]
        assert info["name"] == "square" and len(info["walls"]) == 8 and info["speed"] == 20.0
        assert info["body"] == "seed"  # the 2001 robot's body, as `up --algorithms seed` asks
        sub.undeclare()
    world.terminate()
    assert world.wait(30) == 0


def test_world_process_refuses_a_bad_world_file(procs, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("walls:\n  - [0, 0, 1000, 0]\n  - [5, 5, 5, 5]\nstart: {x: 500, y: 500}\n")
    proc = procs.start([sys.executable, "-m", "modules.world", "--world", str(bad)])
    out, _ = proc.communicate(timeout=15)
    assert proc.returncode == 2
    assert f"{bad}:3: wall 2 has zero length" in out


@pytest.mark.parametrize(("body", "side_x"), [("ours", 80.0), ("seed", 50.0)])
def test_the_simulator_pings_from_its_bodys_mounts(monkeypatch, body: str, side_x: float):
    """The simulator builds the body it is given (``up`` passes ``--body`` from ``--algorithms``):
    every pair is pinged from that body's mount, the side pairs 2 x side_x apart."""
    import modules.world.sim as sim_module

    sim = Simulator(load_world("empty"), seed=1, clock=ManualClock(0.0), body=body)
    real = sim_module.sonar_world_pose
    used: list[tuple[float, float]] = []

    def recording(x: float, y: float, theta: float, sensor: int, mounts=SONAR_MOUNTS):
        sx, sy, direction = real(x, y, theta, sensor, mounts)
        used.append((sx - x, sy - y))
        return sx, sy, direction

    monkeypatch.setattr(sim_module, "sonar_world_pose", recording)
    start = sim.robot.pose
    assert start.theta == 0.0  # the offsets below are in the robot frame
    sim.sonar_ping({"sensors": list(range(8)), "slot_ms": 0.0})
    assert [round(dx, 6) for dx, _ in used][3:8] == [side_x, -side_x, -188.0, -side_x, side_x]
    assert all(math.hypot(dx, dy) == pytest.approx(188.0, abs=0.5) for dx, dy in used)


def test_a_sweep_pings_each_pair_from_where_the_driving_robot_is_by_then(monkeypatch):
    import modules.world.sim as sim_module

    # time stands still between the batch and the sweep: the robot has not driven on meanwhile
    sim = Simulator(load_world("empty"), seed=3, clock=ManualClock(1000.0))
    used: list[tuple[float, float, float]] = []
    real = sim_module.sonar_world_pose

    def recording(x: float, y: float, theta: float, sensor: int, mounts=SONAR_MOUNTS):
        used.append((x, y, theta))
        return real(x, y, theta, sensor, mounts)

    monkeypatch.setattr(sim_module, "sonar_world_pose", recording)
    rate = 200.0  # half-steps per second: 50 steps are 250 ms of driving
    moved = steps(sim, 50, 50, 1, rate)["moved_mm"]
    start = sim.robot.pose
    speed_mm_per_ms = moved / 250.0
    slot = 15.0
    sim.sonar_ping({"sensors": list(range(8)), "slot_ms": slot})
    for i, (x, y, theta) in enumerate(used):
        ahead = speed_mm_per_ms * slot * i  # pair 7 is pinged 105 ms after pair 0
        assert x == pytest.approx(start.x + ahead * math.cos(start.theta), abs=0.01)
        assert y == pytest.approx(start.y + ahead * math.sin(start.theta), abs=0.01)
        assert theta == pytest.approx(start.theta, abs=1e-9)
    # once the motors stop, every pair is pinged from where the robot stands
    sim.motor_steps({"left": 0, "right": 0, "rate_hz": rate, "move": 1, "energised": False})
    used.clear()
    sim.sonar_ping({"sensors": list(range(8)), "slot_ms": slot})
    assert {(round(x, 6), round(y, 6)) for x, y, _ in used} == {(round(start.x, 6), round(start.y, 6))}
