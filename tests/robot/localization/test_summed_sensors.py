"""The summed sensors in the Localizer: table 3.1's mean of the gyroscope's rates and sum of the
floor correlator's increments, and the turn and distance they measure in the EKF."""

from __future__ import annotations

import math

import numpy as np
import pytest

from modules.localization.config import load_config
from modules.localization.ekf import EkfParams, PoseEKF
from modules.localization.localizer import LocalizationCore
from modules.localization.sensors.correlator import CorrelatorSync
from modules.localization.sensors.gyro import GyroSync
from modules.localization.sync import OdometryParams, OdometryTrack, Sample
from tests.support.locsim import drive, gyro_sample, square_moves, with_gyro

CALIBRATING = 1


def test_the_synchronised_turn_is_the_summed_angle_between_two_sync_times() -> None:
    """A steady 0.2 rad/s, its samples every 100 ms but 37 ms off the sync grid: each
    synchronisation's turn is 0.2 rad/s times the period, its rate 0.2 rad/s."""
    sync = GyroSync(OdometryTrack(OdometryParams()))
    rate = 0.2
    results = []
    for k in range(1, 8):
        stamps = [100 * k - 163, 100 * k - 63]  # two samples before the sync time ...
        samples = [gyro_sample(t, rate * t / 1000.0) for t in stamps if t >= 0]
        samples.append(gyro_sample(100 * k + 37, rate * (100 * k + 37) / 1000.0))  # ... one after
        results.append(sync.synchronise(samples, 100 * k))
    assert results[0] is None  # the first sync only sets where the turn is counted from
    for result in results[1:]:
        assert result is not None
        assert result["turn"] == pytest.approx(rate * 0.1, abs=0.0011)  # mrad resolution at both ends
        assert result["rate"] == pytest.approx(rate, abs=0.011)
    total = sum(r["turn"] for r in results[1:])
    assert total == pytest.approx(rate * 0.6, abs=0.0011)  # the ends' rounding does not add up


def test_a_sample_past_the_newest_is_carried_along_the_odometry_track() -> None:
    """No gyro sample after the sync time: the newest is carried to it by the odometry's turn."""
    track = OdometryTrack(OdometryParams())
    track.append(0, (0.0, 0.0, 0.0))
    track.append(200, (0.0, 0.0, 0.05))  # the odometry turned 0.05 rad in 200 ms
    sync = GyroSync(track)
    sync.synchronise([gyro_sample(0, 0.0)], 0)
    result = sync.synchronise([gyro_sample(100, 0.020)], 200)
    assert result is not None
    # 20 mrad to the sample at 100 ms, then the track's 0.025 rad from 100 to 200 ms
    assert result["turn"] == pytest.approx(0.020 + 0.025, abs=1e-9)


def test_a_calibration_or_a_silence_ends_the_sum() -> None:
    """While the gyro calibrates its sum starts again: no turn is measured across it; a gyro
    silent for longer than half a second gives no turn at all."""
    sync = GyroSync(OdometryTrack(OdometryParams()))
    sync.synchronise([gyro_sample(0, 0.0)], 0)
    assert sync.synchronise([gyro_sample(100, 0.5, CALIBRATING)], 100) is None
    assert sync.skipped == 1
    assert sync.synchronise([gyro_sample(200, 0.0)], 200) is None  # a new sum: counted from here
    assert sync.synchronise([gyro_sample(300, 0.010)], 300)["turn"] == pytest.approx(0.010)
    assert sync.synchronise([], 900) is None  # the newest sample is 600 ms old


def test_the_first_gyro_reading_sets_its_offset_and_the_next_measures_the_turn() -> None:
    """The gyro's sum as a heading ``ψ − offset``: the first reading only learns the offset; after
    a 90° turn by the steps that truly was 86° (the floor's glide), the next reading weighs the
    odometry's turn (σ 2 % of it) against the gyro's (its scale error, 1 % of a 90° turn, walks
    the offset): the heading lands where the variances put it, worked out here."""
    params = EkfParams(estimate=("gyro_offset",))
    ekf = PoseEKF(params, (0.0, 0.0, 0.3))
    sigma = math.radians(0.05)
    assert ekf.correct_gyro(0.125, sigma)  # the gyro's sum read 0.125 rad at the start
    i = ekf.index["gyro_offset"]
    assert ekf.x[i] == pytest.approx(0.3 - 0.125, abs=1e-4) and ekf.pose[2] == pytest.approx(0.3, abs=1e-4)
    ekf.predict(-585.0, 585.0, 1.0)  # 90° by the nominal glide factor
    assert math.degrees(ekf.pose[2] - 0.3) == pytest.approx(90.0, abs=0.01)
    assert ekf.correct_gyro(0.125 + math.radians(86.0), sigma)
    odometry_var = (params.rotation_noise_rel * 90.0) ** 2  # deg²
    gyro_var = (
        params.gyro_scale_rel**2 * 90.0**2
        + math.degrees(math.radians(params.gyro_offset_walk_deg_per_s)) ** 2
    )
    expected = 86.0 + 4.0 * gyro_var / (odometry_var + gyro_var)
    assert math.degrees(ekf.pose[2] - 0.3) == pytest.approx(expected, abs=0.05)
    assert ekf.gates.accepted["gyro"] == 2


def test_a_gyro_reading_far_off_is_gated_and_a_new_calibration_forgets_the_offset() -> None:
    ekf = PoseEKF(EkfParams(estimate=("gyro_offset",)), (0.0, 0.0, 0.0))
    sigma = math.radians(0.05)
    assert ekf.correct_gyro(0.0, sigma)
    assert not ekf.correct_gyro(math.radians(30.0), sigma)  # 30° at rest: not a turn
    assert ekf.gates.rejected["gyro"] == 1
    ekf.restart_gyro()  # the gyro calibrated again: its sum starts at 0 wherever the robot points
    assert ekf.correct_gyro(math.radians(30.0), sigma) and ekf.pose[2] == pytest.approx(0.0, abs=1e-3)


def heading_error_deg(position: dict, truth: dict) -> float:
    return abs(math.degrees(math.remainder(position["psi"] - truth["theta"], 2 * math.pi)))


def odometry_and_gyro_core(use_gyro: bool) -> LocalizationCore:
    """The seed's early filter's sensors: odometry and gyro (compass and walls not fused)."""
    return LocalizationCore(
        load_config(
            {
                "sensors": {
                    "compass": {"filter": False},
                    "sonar": {"filter": False},
                    "gyro": {"use": use_gyro},
                },
            }
        )
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_a_lap_with_the_gyro_keeps_the_heading_the_turns_glide_loses(seed: int) -> None:
    """One lap of the 3 m square, each turn's glide drawn ±10 %: dead reckoning ends degrees
    off; with the gyro's turns the filter's heading ends within its resolution and scale error
    (the filter without the gyro, ends[False][0], is what the gyro improves on: reported)."""
    cores = {use: odometry_and_gyro_core(use) for use in (False, True)}
    ends = {}
    for use, core in cores.items():
        truth = None
        for sample in with_gyro(drive(square_moves(1, 3000), seed=seed)):
            truth = sample.values if sample.sensor == "truth" else truth
            core.feed(sample)
            core.maybe_sync()
        assert truth is not None
        ends[use] = (
            heading_error_deg(core.positions["K"], truth),
            heading_error_deg(core.positions["O"], truth),
        )
    dead_reckoning = ends[False][1]
    with_gyro_error = ends[True][0]
    assert dead_reckoning > 1.0, "this seed's turns did not slip: nothing to judge"
    assert with_gyro_error < dead_reckoning / 4, ends
    assert with_gyro_error < 1.0, ends
    core = cores[True]
    assert core.report()["gates"]["accepted"]["gyro"] > 100
    g = core.positions["G"]  # the gyro's own summed heading, the store's G position
    assert g["valid"] == [False, False, True]
    assert np.isfinite(g["psi"])


def correlator_sample(stamp_ms: int, forward_mm: float, state: int = 1) -> Sample:
    """A correlator.data sample: the running sum in whole µm, wrapped as the i32 on the wire."""
    um = (round(forward_mm * 1000) + 2**31) % 2**32 - 2**31
    return Sample("correlator", stamp_ms, {"forward_um": um, "increment_um": 0, "state": state})


def test_the_correlators_distance_is_the_sum_between_two_sync_times_across_the_wrap() -> None:
    """50 mm/s, samples every 50 ms off the grid, the running sum crossing the i32's wrap
    (2147.48 m): every synchronisation's distance is 5 mm, its speed 50 mm/s."""
    sync = CorrelatorSync(OdometryTrack(OdometryParams()))
    start_mm = 2**31 / 1000.0 - 12.0  # 12 mm before the wrap
    results = []
    for k in range(1, 8):
        samples = [
            correlator_sample(t, start_mm + 0.05 * t) for t in (100 * k - 73, 100 * k - 23, 100 * k + 27)
        ]
        results.append(sync.synchronise(samples, 100 * k))
    assert results[0] is None
    for result in results[1:]:
        assert result is not None
        assert result["distance"] == pytest.approx(5.0, abs=1e-6)
        assert result["speed"] == pytest.approx(50.0, abs=1e-4)


def test_the_filter_weighs_the_correlators_distance_against_the_steps() -> None:
    """A straight step without optional states: the distance moved along the heading is the
    steps' and the correlator's, weighted by the inverse of their variances (worked out here)."""
    params = EkfParams(estimate=())
    heading = 0.7
    ekf = PoseEKF(params, (100.0, 200.0, heading))
    steps = 200.0
    odometry = steps * params.odometry.mm_per_step
    odometry_var = (params.distance_noise_rel * odometry) ** 2
    measured, sigma = odometry * 1.005, 0.5
    assert ekf.predict(steps, steps, 0.1, (measured, sigma)) is True
    weight = odometry_var / (odometry_var + sigma**2)
    fused = odometry + weight * (measured - odometry)
    x, y, psi = ekf.pose
    assert math.hypot(x - 100.0, y - 200.0) == pytest.approx(fused, abs=1e-6)
    assert math.atan2(y - 200.0, x - 100.0) == pytest.approx(heading, abs=1e-9) and psi == pytest.approx(
        heading
    )
    assert len(ekf.x) == 3 and ekf.P.shape == (3, 3)


def test_a_turning_robots_correlator_is_not_fused() -> None:
    """Seed §3.3: turning, the correlator reads too much (on the spot, nonsense): the Localizer
    does not fuse it above filter.correlator.max_turn_rate_deg_s."""
    config = load_config({"sensors": {"correlator": {"use": True, "filter": True}}})
    core = LocalizationCore(config)
    assert core._correlator_travel({"distance": 40.0}, math.radians(1.0), 0.1) is None
    assert core.correlator_skipped_turning == 1
    distance, sigma = core._correlator_travel({"distance": 40.0}, 0.0, 0.1)
    assert distance == 40.0 and sigma == pytest.approx(math.hypot(1.0, 0.03 * 40.0))


def test_a_gyro_parted_from_the_heading_is_learned_afresh_after_five_rejections() -> None:
    """Rejected readings never move the offset: a sum that parted from the filter's heading (here
    a 20° bump at rest) would be locked out for good. After five rejections in a row the offset
    is learned afresh, and the readings count again."""
    from modules.localization.localizer import GYRO_RELEARN_AFTER
    from tests.support.locsim import gyro_sample as sample

    core = LocalizationCore(
        load_config({"sensors": {"gyro": {"use": True}}, "filter": {"gyro": {"settle_ms": 0}}})
    )
    odometry = {"steps_left": 0, "steps_right": 0, "state": 0}
    for k in range(40):
        stamp = 1000 + 100 * k
        core.feed(Sample("odometry", stamp, odometry))
        core.feed(sample(stamp, 0.0 if k < 10 else math.radians(20.0)))
        core.maybe_sync()
    report = core.report()
    assert report["gyro_relearned"] == 1
    assert report["gates"]["rejected"]["gyro"] == GYRO_RELEARN_AFTER
    assert report["gates"]["accepted"]["gyro"] > 20


def test_a_lops_packet_measured_after_the_sync_time_waits_for_the_next_one() -> None:
    """On a ring at speed 10 the odometry that triggers a sync comes by token, hundreds of ms of
    emulated time after its stamp, while LOPS's packets come straight over Zenoh: the half
    synchronised at S holds packets measured after S. Taken as at S they put the filter ahead of
    the robot (30 mm at 50 mm/s); each waits for the first sync after it was measured."""
    from modules.localization.sync import DueSync

    sync = DueSync("lops", delay_ms=15.0)

    def packet(stamp: int, counter: int) -> Sample:
        return Sample("lops", stamp, {"counter": counter, "x": float(stamp), "y": 0.0})

    first = sync.synchronise([packet(90, 1), packet(130, 2)], 100)
    assert first is not None and (first["counter"], first["count"], first["stamp_ms"]) == (1, 1, 90)
    second = sync.synchronise([packet(210, 3), packet(230, 4)], 200)  # 210 was measured at 195
    assert second is not None and (second["counter"], second["count"]) == (3, 2)
    assert sync.synchronise([], 300)["counter"] == 4
    assert sync.synchronise([], 400) is None
