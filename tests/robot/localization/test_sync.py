"""The synchronisation: shadow buffer under concurrent writers, trigger, every synchroniser, timing."""

from __future__ import annotations

import math
import threading

import pytest

from modules.localization.sync import (
    CompassSync,
    NewestSync,
    OdometryParams,
    OdometrySync,
    OdometryTrack,
    Sample,
    SampleTiming,
    ShadowBuffer,
    SonarSync,
    Trigger,
    sync_stamp,
)
from modules.localization.walls import DetectorParams, SonarMount, WallDetector


def odo(stamp: int, left: int, right: int) -> Sample:
    return Sample("odometry", stamp, {"steps_left": left, "steps_right": right})


def test_buffer_swap_under_concurrent_writers_loses_and_duplicates_nothing() -> None:
    buffer = ShadowBuffer()
    writers, per_writer = 4, 5000
    seen: list[tuple[int, int]] = []
    filed: dict[tuple[int, int], int] = {}
    done = threading.Event()

    def writer(w: int) -> None:
        for i in range(per_writer):
            filed[(w, i)] = buffer.write(Sample(f"s{w}", i, {"i": i}))

    def swapper() -> None:
        while not done.is_set():
            generation, half = buffer.swap()
            for samples in half.values():
                seen.extend((int(s.sensor[1:]), s.stamp_ms, generation) for s in samples)

    threads = [threading.Thread(target=writer, args=(w,)) for w in range(writers)]
    swap_thread = threading.Thread(target=swapper)
    swap_thread.start()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    done.set()
    swap_thread.join()
    generation, half = buffer.swap()
    for samples in half.values():
        seen.extend((int(s.sensor[1:]), s.stamp_ms, generation) for s in samples)

    assert len(seen) == writers * per_writer
    assert {(w, i) for w, i, _ in seen} == {(w, i) for w in range(writers) for i in range(per_writer)}
    # every sample was read in exactly the generation write() reported, and in order per writer
    assert all(filed[(w, i)] == g for w, i, g in seen)
    for w in range(writers):
        mine = [(g, i) for ww, i, g in seen if ww == w]
        assert mine == sorted(mine)
    assert buffer.generation > 2  # the swaps really interleaved with the writers


def test_trigger_after_n_samples_of_one_sensor() -> None:
    buffer = ShadowBuffer()
    trigger = Trigger("odometry", count=3)
    buffer.write(Sample("compass", 1, {}))
    buffer.write(odo(1, 0, 0))
    buffer.write(odo(2, 0, 0))
    assert not trigger.due(buffer)
    buffer.write(odo(3, 0, 0))
    assert trigger.due(buffer)
    buffer.swap()
    assert not trigger.due(buffer)


def test_trigger_every_k_rounds_wraps_the_u8_counter() -> None:
    trigger = Trigger(sensor=None, rounds=4)
    buffer = ShadowBuffer()
    assert not trigger.due(buffer, 254)
    assert not trigger.due(buffer, 255)
    assert trigger.due(buffer, 2)  # 254 -> 2 is four rounds
    assert not trigger.due(buffer, 3)
    with pytest.raises(ValueError):
        Trigger("odometry", rounds=2)


def test_odometry_sums_increments_and_wraps_int32() -> None:
    track = OdometryTrack(OdometryParams(model="straight"))
    sync = OdometrySync(track, baseline=None)  # the pose belongs to the first sample's counters
    first = sync.synchronise([odo(100, 1000, 1000), odo(200, 1100, 1100)], 200)
    assert (first["dl"], first["dr"], first["count"]) == (100, 100, 2)
    # by default the start pose belongs to counters (0, 0): steps before the first sample count
    late_start = OdometrySync(OdometryTrack(OdometryParams()))
    assert late_start.synchronise([odo(100, 1000, 1000)], 100)["dl"] == 1000
    second = sync.synchronise([odo(300, 1150, 1160)], 300)
    assert (second["dl"], second["dr"]) == (50, 60)
    empty = sync.synchronise([], 400)
    assert (empty["dl"], empty["dr"], empty["count"], empty["stamp_ms"]) == (0, 0, 0, 400)
    near = 2**31 - 10
    sync = OdometrySync(OdometryTrack(OdometryParams()), baseline=None)
    sync.synchronise([odo(0, near, -near)], 0)
    wrapped = sync.synchronise([odo(1, near + 20 - 2**32, -near - 20 + 2**32)], 1)
    assert (wrapped["dl"], wrapped["dr"]) == (20, -20)


def test_odometry_track_follows_straight_and_turn() -> None:
    params = OdometryParams(mm_per_step=0.5, steps_per_degree=6.5, model="arc")
    track = OdometryTrack(params)
    sync = OdometrySync(track)
    sync.synchronise([odo(0, 0, 0), odo(1000, 2000, 2000)], 1000)
    assert track.pose_at(1000) == pytest.approx((1000.0, 0.0, 0.0))
    assert track.pose_at(500) == pytest.approx((500.0, 0.0, 0.0))
    sync.synchronise([odo(2000, 2000 - 585, 2000 + 585)], 2000)  # 585 / 6.5 = 90 degrees
    assert track.pose_at(2000) == pytest.approx((1000.0, 0.0, math.pi / 2))


def test_compass_newest_and_circular_mean_carried_to_the_sync_time() -> None:
    track = OdometryTrack(OdometryParams())
    track.append(0, (0.0, 0.0, 0.0))
    track.append(100, (0.0, 0.0, 0.0))
    # north along +Y: a navigation heading of 0 is +90 degrees CCW from +X
    sync = CompassSync(track, mode="newest", north_deg=90.0)
    samples = [Sample("compass", 10, {"heading_cdeg": 35900, "state": 1})]
    samples.append(Sample("compass", 20, {"heading_cdeg": 100, "state": 1}))
    assert math.degrees(sync.synchronise(samples, 100)["heading"]) == pytest.approx(89.0)
    mean = CompassSync(track, mode="mean", north_deg=90.0).synchronise(samples, 100)
    assert math.degrees(mean["heading"]) == pytest.approx(90.0)  # mean of 91 and 89 across north
    assert mean["count"] == 2
    # a sample taken while the robot turned is carried forward by the odometry's rotation
    track.append(200, (0.0, 0.0, math.radians(10)))
    late = sync.synchronise([Sample("compass", 100, {"heading_cdeg": 0, "state": 1})], 200)
    assert math.degrees(late["heading"]) == pytest.approx(100.0)
    disturbed = sync.synchronise([Sample("compass", 150, {"heading_cdeg": 0, "state": 2})], 200)
    assert disturbed is None and sync.skipped == 1


def test_sonar_newest_values_and_fitted_walls() -> None:
    track = OdometryTrack(OdometryParams())
    mounts = [SonarMount(0.0, 100.0, math.pi / 2)]  # one sensor looking left
    detector = WallDetector(mounts, DetectorParams(side_sensors=(0,), min_points_side=5, min_span_side_mm=40))
    sync = SonarSync(track, detector)
    samples = []
    for i in range(10):
        track.append(i * 100, (i * 10.0, 0.0, 0.0))
        samples.append(Sample("sonar", i * 100, {"distances": [50]}))
    result = sync.synchronise(samples, 900)
    assert result["distances_mm"] == [500]
    assert result["count"] == 10
    (wall,) = result["walls"]
    # wall at y = 600 in the odometry frame; robot at x = 90 looking along +X: normal +90 degrees
    assert math.degrees(wall["alpha"]) == pytest.approx(90.0)
    assert wall["d"] == pytest.approx(600.0)
    assert wall["n"] == 10
    none = sync.synchronise([Sample("sonar", 1000, {"distances": [255]})], 1000)
    assert none["distances_mm"] == [None] and none["walls"] == []


def test_newest_sync_for_battery_and_truth() -> None:
    sync = NewestSync("battery")
    assert sync.synchronise([], 5) is None
    out = sync.synchronise([Sample("battery", 1, {"mv": 12000}), Sample("battery", 2, {"mv": 11900})], 5)
    assert out == {"mv": 11900, "count": 2, "stamp_ms": 2}


def test_timing_counts_missed_by_sequence_and_by_stamp_gap_and_late_samples() -> None:
    by_seq = SampleTiming("compass", seq_modulo=65536)
    for seq in (65534, 65535, 1, 2):  # 0 missing across the wrap
        by_seq.observe(Sample("compass", seq, {}, seq=seq), None)
    assert by_seq.missed == 1
    by_stamp = SampleTiming("odometry", period_ms=100)
    for stamp in (0, 100, 400, 500):
        by_stamp.observe(odo(stamp, 0, 0), None)
    assert by_stamp.missed == 2
    by_stamp.observe(odo(450, 0, 0), last_sync_ms=480)
    assert by_stamp.late == 1


def test_sync_stamp_prefers_the_trigger_sensor() -> None:
    half = {"odometry": [odo(100, 0, 0), odo(200, 0, 0)], "compass": [Sample("compass", 250, {})]}
    assert sync_stamp(half, "odometry", 0) == 200
    assert sync_stamp(half, None, 0) == 250
    assert sync_stamp({}, "odometry", 77) == 77


def test_trigger_with_a_minimum_period_of_sensor_time() -> None:
    buffer = ShadowBuffer()
    trigger = Trigger("odometry", count=1, min_period_ms=100)
    buffer.write(odo(20, 0, 0))
    assert trigger.due(buffer)  # the first sync runs at once
    buffer.swap()
    trigger.last_sync_ms = 20
    buffer.write(odo(40, 0, 0))
    buffer.write(odo(100, 0, 0))
    assert not trigger.due(buffer)
    buffer.write(odo(120, 0, 0))
    assert trigger.due(buffer)
