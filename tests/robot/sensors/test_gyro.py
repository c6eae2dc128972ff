"""The Darmstadt gyroscope (seed 000 §3.2, §6.2.3): the world's model judged by its own numbers,
and the gyro module's zero-point calibration at rest (in-process: a fake node OS, the world's
device on a manual clock, no ring).

The judges' bounds come from the model's stated parameters: white noise σ per sample, rounding
to whole counts (whose mean is off the true value by at most Σ e^(−2π²k²σ²)/(πk) for Gaussian
noise of σ), the scale factor off the nominal one by at most 1 %."""

from __future__ import annotations

import math

import numpy as np

from modules.description.roomfile import load_world
from modules.sensors.gyro import SAMPLE_S, SCALE_RAD_S, rate
from modules.world import gyroscope as model
from modules.world.clock import ManualClock
from modules.world.gyroclient import GyroHardware
from modules.world.gyroscope import GyroDevice, RateGyro, gyro_rng
from modules.world.sim import Simulator
from tests.support.fakenode import FakeOS
from tests.support.hwprograms import program

GyroProgram = program("gyro")
SIGMA = model.NOISE_COUNTS
#: the largest mean offset of round(z + noise) from z, noise Gaussian with σ (Fourier series)
ROUNDING_BIAS = sum(math.exp(-2 * math.pi**2 * k**2 * SIGMA**2) / (math.pi * k) for k in range(1, 20))
#: the spread of one rounded sample (noise and quantisation), counts
SPREAD = math.sqrt(SIGMA**2 + 1 / 12)


def device(seed: int = 3) -> tuple[Simulator, ManualClock, GyroDevice]:
    clock = ManualClock()
    sim = Simulator(load_world("empty"), seed=seed, clock=clock)
    return sim, clock, GyroDevice(sim)


def test_the_scale_factor_is_the_seeds_bit_and_both_sides_agree() -> None:
    # figure 10.2: -0.000003835885 and 0.000013599955 rad per 20.48 ms sample are one bit apart
    bit = (0.000013599955 + 0.000003835885) / 0.02048
    assert math.isclose(model.SCALE_RAD_S, bit, rel_tol=1e-9)
    assert math.isclose(SCALE_RAD_S, bit, rel_tol=1e-5) and SAMPLE_S * 1000 == model.SAMPLE_MS
    assert math.isclose(math.degrees(bit) * 2048, 100.0, rel_tol=0.001)  # ±100 °/s full scale


def test_at_rest_the_mean_raw_value_is_the_zero_point_within_the_quantisation() -> None:
    gyro = RateGyro(gyro_rng(7))
    raw, zero = [], []
    for k in range(1, 3001):  # 61 s at rest
        t = k * model.SAMPLE_MS
        raw.append(gyro.sample(t, 0.0))
        zero.append(gyro.zero_point(t))
    raw_a = np.array(raw)
    assert np.all(raw_a == np.rint(raw_a)) and raw_a.dtype.kind == "i"
    # 1-bit steps, as in the seed's figure 10.2: the values at rest lie on neighbouring counts
    assert np.ptp(raw_a[:100]) <= 2 and np.all(np.abs(np.diff(raw_a)) <= 2)
    error = abs(raw_a.mean() - np.mean(zero))
    assert error <= ROUNDING_BIAS + 4 * SPREAD / math.sqrt(len(raw)), (error, ROUNDING_BIAS)
    # the zero point moves with the warm-up and the drift, but slowly: under a count a minute
    assert abs(zero[-1] - zero[0]) < 1.0, (zero[0], zero[-1])


def test_the_rates_of_a_known_turn_sum_to_the_turn_within_the_scale_error() -> None:
    sim, clock, dev = device()
    hw = GyroHardware.local(dev)
    clock.advance(1000.0)
    hw.read()
    raw: list[int] = []
    stamps: list[float] = []
    start = sim.robot.pose
    turn = math.radians(90.0)
    for step in range(1, 91):  # 90° counter-clockwise in 1° steps, 50 ms apart: 20 °/s
        clock.advance(50.0)
        sim.set_pose({"x_mm": start.x, "y_mm": start.y, "theta_rad": start.theta + turn * step / 90})
        r, s, lost = hw.read()
        assert lost == 0
        raw += r
        stamps += s
    clock.advance(500.0)  # and stands again
    r, s, _ = hw.read()
    raw += r
    stamps += s
    zero = [dev.gyro.zero_point(t) for t in stamps]  # the true one (drift is slow: ~the sample's)
    integrated = sum(rate(v, z) * SAMPLE_S for v, z in zip(raw, zero, strict=True))
    # the nominal scale factor is off the true one by the model's ≤ 1 %; noise and rounding add
    # a random walk of √N samples' spread
    bound = model.SCALE_ERROR * turn + 4 * math.sqrt(len(raw)) * SPREAD * SCALE_RAD_S * SAMPLE_S
    assert abs(integrated - turn) <= bound, (math.degrees(integrated), math.degrees(bound))
    # with the true scale factor it is the turn within the noise alone
    exact = sum((v - z) * dev.gyro.true_scale * SAMPLE_S for v, z in zip(raw, zero, strict=True))
    assert abs(exact - turn) <= 4 * math.sqrt(len(raw)) * SPREAD * dev.gyro.true_scale * SAMPLE_S
    # a sample every 20.48 ms, none twice, none missing
    assert np.allclose(np.diff(stamps), model.SAMPLE_MS)


def test_the_gyro_is_deterministic_from_the_worlds_seed_and_loses_what_is_not_read() -> None:
    def run(seed: int) -> list[int]:
        _, clock, dev = device(seed)
        hw = GyroHardware.local(dev)
        out = []
        for _ in range(20):
            clock.advance(97.0)
            out += hw.read()[0]
        return out

    assert run(5) == run(5)
    assert run(5) != run(6)
    _, clock, dev = device()
    clock.advance(10_000.0)
    raw, stamps, lost = GyroHardware.local(dev).read()
    assert len(raw) == model.MAX_SAMPLES and lost == math.floor(10_000 / model.SAMPLE_MS) - model.MAX_SAMPLES
    assert stamps[-1] == math.floor(10_000 / model.SAMPLE_MS) * model.SAMPLE_MS


def run_program(dev: GyroDevice, clock: ManualClock, reads: int, os: FakeOS | None = None) -> object:
    """The gyro's program as its loop runs it: a read every 100 simulated ms, then publish."""
    os = os or FakeOS()
    prog = GyroProgram(os, GyroHardware.local(dev))  # type: ignore[arg-type]
    prog.setup()
    prog.calibrate()
    for _ in range(reads):
        clock.advance(100.0)
        raw, stamps, lost = prog.hw.read()
        prog.take(raw, stamps, lost)
        prog.publish()
    return prog


def test_the_module_calibrates_the_zero_point_at_rest_within_its_noise() -> None:
    for seed in (1, 2, 3):
        _, clock, dev = device(seed)
        prog = run_program(dev, clock, 30)  # 3 s: the 100 samples of the calibration, and on
        out = prog.out.fields  # type: ignore[attr-defined]
        assert out["state"] == 2, out  # RUNNING
        n = prog.calibrated["samples"]  # type: ignore[attr-defined]
        assert n == 100
        truth = dev.gyro.zero_point(clock.now_ms())
        error = abs(prog.zero_point - truth)  # type: ignore[attr-defined]
        # the mean of n rounded samples: the rounding's bias plus 4 standard errors (and the
        # drift's part of a count over the 3 s)
        assert error <= ROUNDING_BIAS + 4 * SPREAD / math.sqrt(n) + 0.05, (seed, error)
        assert abs(out["zero_mcounts"] - 1000 * prog.zero_point) <= 0.5  # type: ignore[attr-defined]
        # at rest after calibration: rates of a bit or so, the summed angle near zero
        assert abs(out["rate_urad_s"]) <= 2.5 * SCALE_RAD_S * 1e6, out
        assert abs(out["angle_mrad"]) <= 5, out


def test_motion_seen_on_motor_data_restarts_the_calibration() -> None:
    _, clock, dev = device()
    os = FakeOS()
    os.subscribe("motor.data").set({"direction": 3})  # TURN_LEFT
    prog = run_program(dev, clock, 20, os)
    assert prog.out.fields["state"] == 1 and prog.restarts == 0  # type: ignore[attr-defined]
    assert not prog.calibration.values  # type: ignore[attr-defined]
    os.subscribe("motor.data").set({"direction": 0})
    for _ in range(25):
        clock.advance(100.0)
        prog.take(*prog.hw.read())  # type: ignore[attr-defined]
    prog.publish()  # type: ignore[attr-defined]
    assert prog.out.fields["state"] == 2  # type: ignore[attr-defined]
