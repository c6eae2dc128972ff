"""The Darmstadt floor correlator (seed 000 §3.3, table 3.1): the world's model judged by judges of
the tests' own, and the correlator module's running sum (in-process: a fake node OS, the world's
device on a manual clock, no ring).

The turn's excess is judged by following a floor patch in the robot's frame, step by step, from
the leading sensor until it passes nearest the trailing one (the model computes it in closed
form from the two sensors' velocities); shares of wrong directions by binomial bounds of four
standard deviations; the sum of a straight drive by the model's stated noise."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from modules.description.roomfile import load_world
from modules.sensors.correlator import TranslationSum, translation_between, wire_i32
from modules.world import correlator as model
from modules.world.clock import ManualClock
from modules.world.correlator import (
    CorrelatorDevice,
    FloorCorrelator,
    Mount,
    correlated_speed,
    correlator_rng,
)
from modules.world.correlatorclient import CorrelatorHardware, CorrelatorRead
from modules.world.sim import Simulator
from tests.support.fakenode import FakeOS
from tests.support.hwprograms import program

CorrelatorProgram = program("correlator")
STARTING, RUNNING, NO_DATA, DEFECTIVE = range(4)


def device(seed: int = 3, body: str = "ours") -> tuple[Simulator, ManualClock, CorrelatorDevice]:
    clock = ManualClock()
    sim = Simulator(load_world("empty"), seed=seed, clock=clock, body=body)
    return sim, clock, CorrelatorDevice(sim)


def followed_patch(v: float, omega: float, rear: float, front: float) -> tuple[float, float]:
    """The judge: the robot drives its arc from the origin (heading 0, pose (R sin ωt,
    R(1 − cos ωt), ωt)); the floor point under the leading sensor at t = 0 is followed in the
    robot's frame over a 5 µs grid until it passes nearest the trailing sensor. Returns (spacing /
    the time it took, mm/s; the distance it passed at, mm)."""
    lead, trail = (front, rear) if v > 0 else (rear, front)
    t = np.arange(1, int(3 * (front - rear) / abs(v) / 5e-6)) * 5e-6
    theta = omega * t
    if omega:
        x, y = v / omega * np.sin(theta), v / omega * (1 - np.cos(theta))
    else:
        x, y = v * t, np.zeros_like(t)
    dx, dy = lead - x, 0.0 - y  # the floor point, from the robot, in the world's axes ...
    px = np.cos(theta) * dx + np.sin(theta) * dy  # ... and in the robot's
    py = -np.sin(theta) * dx + np.cos(theta) * dy
    distance = np.hypot(px - trail, py)
    nearest = int(np.argmin(distance))
    return (front - rear) / float(t[nearest]), float(distance[nearest])


@pytest.mark.parametrize(
    ("v", "omega"), [(100.0, 0.0), (100.0, 0.1), (100.0, -0.2), (100.0, 0.28), (-100.0, 0.2), (50.0, 0.3)]
)
def test_a_turn_reads_too_large_as_the_followed_floor_says(v: float, omega: float) -> None:
    mount = Mount()
    speed, miss = correlated_speed(v, 0.0, omega, mount)
    judged, passed = followed_patch(v, omega, mount.rear_mm, mount.front_mm)
    # the judge's time resolution (5 µs of ~250 ms) and its nearest step bound the agreement
    assert speed == pytest.approx(judged, rel=2e-3), (speed, judged)
    assert miss == pytest.approx(passed, abs=0.02), (miss, passed)
    if omega:
        assert speed > abs(v)  # too large whichever way it turns (§3.3)
    else:
        assert speed == pytest.approx(abs(v)) and miss == 0.0


def test_on_the_spot_the_tracks_miss_by_the_spacing() -> None:
    mount = Mount()
    _, miss = correlated_speed(0.0, 0.0, 0.5, mount)
    assert miss == pytest.approx(mount.spacing_mm) and miss > mount.spot_mm
    # the tightest arc that still correlates, by the judge: the radius where the tracks miss by
    # the spot (bisected to 1 mm); the model agrees 5 mm either side of it
    low, high = 100.0, 1000.0
    while high - low > 1.0:
        mid = (low + high) / 2
        passed = followed_patch(100.0, 100.0 / mid, mount.rear_mm, mount.front_mm)[1]
        low, high = (low, mid) if passed <= mount.spot_mm else (mid, high)
    assert 300.0 < high < 400.0, high  # ours: arcs tighter than ~0.36 m read bogus
    assert correlated_speed(100.0, 0.0, 100.0 / (high + 5), mount)[1] <= mount.spot_mm
    assert correlated_speed(100.0, 0.0, 100.0 / (low - 5), mount)[1] > mount.spot_mm


def drive(
    sim: Simulator, clock: ManualClock, dev: CorrelatorDevice, poses: list[tuple[float, float, float]]
) -> tuple[list[int], list[float], list[model.SampleTruth]]:
    """Put the robot at each pose (relative to its start: x, y ahead and left, θ) 100 ms apart
    and read after each; the samples as read and as they were."""
    start = sim.robot.pose
    c, s = math.cos(start.theta), math.sin(start.theta)
    increments: list[int] = []
    stamps: list[float] = []
    truth: list[model.SampleTruth] = []
    hw = CorrelatorHardware.local(dev)
    for x, y, theta in poses:
        clock.advance(100.0)
        sim.set_pose(
            {
                "x_mm": start.x + c * x - s * y,
                "y_mm": start.y + s * x + c * y,
                "theta_rad": start.theta + theta,
            }
        )
        read = hw.read()
        assert read.lost == 0 and not read.defective
        increments += read.increments_um
        stamps += read.stamps_ms
        truth += dev.truth
    return increments, stamps, truth


def test_an_arc_reads_too_large_by_the_geometry_on_the_device() -> None:
    sim, clock, dev = device()
    clock.advance(1000.0)
    CorrelatorHardware.local(dev).read()
    radius, v = 500.0, 100.0  # 10 cm/s on a 0.5 m arc, counter-clockwise: 0.2 rad/s
    omega = v / radius
    poses = []
    for k in range(1, 601):  # 60 s
        theta = omega * k * 0.1
        poses.append((radius * math.sin(theta), radius * (1 - math.cos(theta)), theta))
    increments, stamps, _ = drive(sim, clock, dev, poses)
    dts = np.diff([1000.0, *stamps]) / 1000.0
    ratio = np.array(increments) / (v * dts * 1000.0)
    good = ratio[ratio > 0]  # forward: the backward ones are the wrong direction
    judged, _ = followed_patch(v, omega, dev.correlator.mount.rear_mm, dev.correlator.mount.front_mm)
    excess = judged / v
    assert excess > 1.05  # (1 + x1·x2/R²): 5.7 % on this arc
    bound = 4 * model.NOISE_REL / math.sqrt(len(good)) + 0.003  # noise, the µm rounding, the judge
    assert abs(good.mean() - excess) <= bound, (good.mean(), excess)
    assert len(good) >= 0.9 * len(ratio)


def test_on_the_spot_a_turn_reads_a_bogus_translation_either_way() -> None:
    sim, clock, dev = device()
    clock.advance(1000.0)
    CorrelatorHardware.local(dev).read()
    omega = 0.5  # rad/s, on the spot: the pivot does not move
    increments, stamps, _ = drive(sim, clock, dev, [(0.0, 0.0, omega * k * 0.1) for k in range(1, 401)])
    dts = np.diff([1000.0, *stamps]) / 1000.0
    inc = np.array(increments, dtype=float)
    floor = omega * abs(model.MOUNT_X_MM) * dts * 1000.0  # µm the floor moves under the pair
    n = len(inc)
    assert n > 600 and np.all(inc != 0)  # every sample a translation that is not there
    # its size: the floor's speed under the pair times U(0.5, 1.5), mean 1, σ 1/√12 a sample
    assert abs(np.mean(np.abs(inc) / floor) - 1.0) <= 4 / math.sqrt(12 * n)
    # its direction: a coin
    assert abs(np.mean(inc > 0) - 0.5) <= 4 * 0.5 / math.sqrt(n)


def test_wrong_directions_come_at_the_models_share_and_more_often_when_dynamic() -> None:
    sensor = FloorCorrelator(correlator_rng(11))
    n = 20_000
    steady = [sensor.sample(50.0 * k, 50.0, 100.0, 0.0, 0.0).increment_um for k in range(n)]
    share = np.mean(np.array(steady) < 0)  # all forward: a backward one is the wrong direction
    p = model.FLIP_P
    assert abs(share - p) <= 4 * math.sqrt(p * (1 - p) / n), share
    # speeds jumping 50 ↔ 150 mm/s every 50 ms: 2000 mm/s², a dynamic drive throughout
    m = 5_000
    dynamic = [
        sensor.sample(50.0 * k, 50.0, 100.0 + 50.0 * (-1) ** k, 0.0, 0.0).increment_um for k in range(m)
    ]
    share = np.mean(np.array(dynamic[1:]) < 0)
    p = model.FLIP_P_DYNAMIC
    assert abs(share - p) <= 4 * math.sqrt(p * (1 - p) / (m - 1)), share
    # a correct reading is the speed within its noise
    good = np.array([i for i in steady if i > 0]) / 5000.0
    assert abs(good.mean() - 1.0) <= 4 * model.NOISE_REL / math.sqrt(len(good))
    assert abs(good.std() - model.NOISE_REL) <= 0.1 * model.NOISE_REL


def test_samples_come_more_than_40_ms_apart_and_vary() -> None:
    _, clock, dev = device()
    hw = CorrelatorHardware.local(dev)
    stamps: list[float] = []
    for _ in range(300):
        clock.advance(100.0)
        stamps += hw.read().stamps_ms
    gaps = np.diff(stamps)
    assert np.all(gaps > model.SAMPLE_MIN_MS) and np.all(gaps <= model.SAMPLE_MIN_MS + model.SAMPLE_JITTER_MS)
    assert gaps.std() > 4.0  # variable (uniform over 20 ms: σ 5.8 ms)
    assert abs(gaps.mean() - 50.0) <= 4 * (20 / math.sqrt(12)) / math.sqrt(len(gaps))
    assert stamps[-1] <= clock.now_ms()


def test_a_straight_drive_sums_to_the_distance_within_the_noise() -> None:
    sim, clock, dev = device(seed=5)
    clock.advance(500.0)
    CorrelatorHardware.local(dev).read()
    distance = 2000.0  # 20 s at 10 cm/s, then 1 s standing: every moving sample read
    poses = [(min(distance, 10.0 * k), 0.0, 0.0) for k in range(1, 211)]
    increments, _, _ = drive(sim, clock, dev, poses)
    inc = np.array(increments)
    backward = -inc[inc < 0].sum()
    assert 0 < len(inc[inc < 0]) < 0.1 * len(inc)  # a few in the wrong direction
    magnitude = inc.sum() + 2 * backward  # the sum had each been read the right way
    bound = 4 * model.NOISE_REL * math.sqrt(float(np.sum(inc.astype(float) ** 2))) + len(inc)
    assert abs(magnitude / 1000.0 - distance) <= bound / 1000.0, (magnitude / 1000.0, bound / 1000.0)
    assert np.all(inc[-15:] == 0)  # standing: no signal


def test_the_correlator_is_deterministic_from_the_worlds_seed_and_loses_what_is_not_read() -> None:
    def run(seed: int) -> list[int]:
        sim, clock, dev = device(seed)
        return drive(sim, clock, dev, [(10.0 * k, 0.0, 0.0) for k in range(1, 30)])[0]

    assert run(5) == run(5)
    assert run(5) != run(6)
    _, clock, dev = device()
    clock.advance(60_000.0)
    read = CorrelatorHardware.local(dev).read()
    assert len(read.increments_um) == model.MAX_SAMPLES and read.lost > 900
    assert 60_000.0 - model.SAMPLE_MIN_MS - model.SAMPLE_JITTER_MS < read.stamps_ms[-1] <= 60_000.0


def test_the_seeds_body_has_a_defective_correlator() -> None:
    _, clock, dev = device(body="seed")
    clock.advance(1000.0)
    read = CorrelatorHardware.local(dev).read()
    assert read == CorrelatorRead([], [], 0, True)


def test_the_running_sum_wraps_as_the_wire_and_differences_stay_right() -> None:
    total = TranslationSum()
    total.add([2**31 - 10, 25], [1.0, 2.0])
    assert total.total_um == -(2**31) + 15 == wire_i32(2**31 + 15)
    assert translation_between(total.total_um, 2**31 - 10) == 25
    total.add([-40], [3.0])
    assert (total.newest_um, total.stamp_ms, total.samples, total.backward, total.backward_um) == (
        -40,
        3.0,
        3,
        1,
        40,
    )
    total.reset()
    assert total.total_um == 0 and total.samples == 3


class RecordingHardware(CorrelatorHardware):
    """The device's serial line, every read kept (what the program was given)."""

    reads: list[CorrelatorRead]

    def read(self) -> CorrelatorRead:
        result = super().read()
        self.reads.append(result)
        return result


class ScriptedOS(FakeOS):
    """The node OS of a loop run: each wait for a command is 100 simulated ms in which ``step``
    moves the world; ``commands`` are handed over at their step; after ``steps`` it stops."""

    def __init__(self, clock: ManualClock, steps: int, step: Any, commands: dict[int, str]) -> None:
        super().__init__()
        self.clock, self.steps, self.step, self.commands, self.k = clock, steps, step, commands, 0

    def receive_command(self, timeout: float = 0) -> Any:
        self.k += 1
        self.clock.advance(100.0)
        self.step(self.k)
        if self.k >= self.steps:
            self.stopping = True
        name = self.commands.get(self.k)
        return None if name is None else type("Command", (), {"name": name, "sender": 10, "args": {}})()


def run_program(
    dev: CorrelatorDevice, clock: ManualClock, steps: int, step: Any, commands: dict[int, str]
) -> Any:
    os = ScriptedOS(clock, steps, step, commands)
    hw = RecordingHardware.local(dev)
    hw.reads = []  # type: ignore[attr-defined]
    prog = CorrelatorProgram(os, hw)
    prog.setup()
    prog.run()
    return prog


def test_the_module_publishes_the_running_sum_of_what_it_read() -> None:
    sim, clock, dev = device(seed=2)
    start = sim.robot.pose

    def forward(k: int) -> None:  # 10 cm/s for 5 s, then standing
        sim.set_pose({"x_mm": start.x + 10.0 * min(k, 50), "y_mm": start.y, "theta_rad": start.theta})

    prog = run_program(dev, clock, 80, forward, {})
    out = prog.out.fields
    reads = prog.hw.reads
    increments = [i for r in reads for i in r.increments_um]
    stamps = [s for r in reads for s in r.stamps_ms]
    assert out["state"] == RUNNING
    assert out["forward_um"] == wire_i32(sum(increments))
    assert out["sample"] == len(increments) and out["increment_um"] == increments[-1]
    assert out["stamp_ms"] == int(stamps[-1])
    assert abs(out["forward_um"] / 1000.0 - 500.0) < 0.25 * 500.0  # the drive, flips and all
    report = prog.report()
    assert report["backward"] == sum(i < 0 for i in increments) and report["lost"] == 0


def test_reset_starts_the_sum_from_zero_and_the_counter_runs_on() -> None:
    sim, clock, dev = device(seed=2)
    start = sim.robot.pose

    def forward(k: int) -> None:
        sim.set_pose({"x_mm": start.x + 10.0 * k, "y_mm": start.y, "theta_rad": start.theta})

    prog = run_program(dev, clock, 30, forward, {20: "RESET"})
    reads = prog.hw.reads
    after = [i for r in reads[20:] for i in r.increments_um]  # the reads after the RESET
    out = prog.out.fields
    assert out["forward_um"] == sum(after) and prog.resets == 1
    assert out["sample"] == sum(len(r.increments_um) for r in reads)


def test_without_power_the_module_says_no_data_and_on_the_seeds_body_defective() -> None:
    sim, clock, dev = device()

    def cut(k: int) -> None:
        sim.relay_on = k < 5

    prog = run_program(dev, clock, 20, cut, {})
    assert prog.out.fields["state"] == NO_DATA and prog.out.fields["sample"] > 0
    _, clock, dev = device(body="seed")
    prog = run_program(dev, clock, 5, lambda k: None, {})
    assert prog.out.fields["state"] == DEFECTIVE and prog.out.fields["sample"] == 0
