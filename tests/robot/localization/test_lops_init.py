"""Position initialisation by LOPS (seed 000 §8, figure B.2): the pose from LOPS's positions
before and after a straight drive, judged against the drive's own geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from modules.localization.config import ConfigError, load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.lops_init import LopsInitialiser
from modules.localization.sync import Sample
from tests.support.locsim import drive


def test_the_pose_is_the_second_rest_and_the_direction_from_the_first() -> None:
    """At (1000, 800) pointing 30°: five noisy fixes at rest, 400 mm straight on, five more; the
    pose is the second rest's mean, the heading the direction between the means."""
    rng = np.random.default_rng(7)
    heading = math.radians(30.0)
    start = np.array([1000.0, 800.0])
    end = start + 400.0 * np.array([math.cos(heading), math.sin(heading)])
    init = LopsInitialiser(fixes=5, drive_mm=300.0, settle_ms=500, sigma_mm=10.0)
    stamp, found = 0, None
    for _ in range(10):  # rest: fixes count from 500 ms on
        fix = start + rng.normal(0.0, 10.0, 2)
        assert init.step(stamp, False, 0.0, 0.0, (fix[0], fix[1])) is None
        stamp += 100
    for _ in range(8):  # 400 mm straight, no fix used
        assert init.step(stamp, True, 50.0, 0.0, (0.0, 0.0)) is None
        stamp += 100
    second = []
    for k in range(12):
        fix = end + rng.normal(0.0, 10.0, 2)
        found = init.step(stamp, False, 0.0, 0.0, (fix[0], fix[1]))
        if k >= 5:  # fixes from 500 ms after the stop on
            second.append(fix)
        stamp += 100
        if found is not None:
            break
    assert found is not None and len(second) == 5
    assert (found.x_mm, found.y_mm) == pytest.approx(tuple(np.mean(second, axis=0)))
    assert math.hypot(found.x_mm - end[0], found.y_mm - end[1]) < 3 * 10.0 / math.sqrt(5)
    assert abs(math.degrees(found.heading - heading)) < 3 * found.sigma_deg
    assert found.sigma_deg == pytest.approx(
        math.degrees(math.atan2(10.0 / math.sqrt(5) * math.sqrt(2), 400.0)), rel=0.05
    )


def test_a_turn_or_a_short_drive_does_not_initialise_and_backwards_points_the_other_way() -> None:
    def run(s_mm: float, omega: float) -> object:
        init = LopsInitialiser(fixes=2, drive_mm=300.0, settle_ms=0)
        for t in range(3):
            init.step(t * 100, False, 0.0, 0.0, (0.0, 0.0))
        for t in range(3, 7):
            init.step(t * 100, True, s_mm / 4, omega / 4, None)
        result = None
        for t in range(7, 10):
            result = init.step(t * 100, False, 0.0, 0.0, (s_mm if s_mm > 0 else -s_mm, 0.0)) or result
        return result

    assert run(200.0, 0.0) is None  # too short
    assert run(400.0, math.radians(10.0)) is None  # a turn: the direction is not the heading
    ahead = run(400.0, 0.0)
    assert ahead is not None and ahead.heading == pytest.approx(0.0)
    back = run(-400.0, 0.0)  # driven backwards to +X: the robot points to -X
    assert back is not None and abs(back.heading) == pytest.approx(math.pi)


def with_lops(samples, sigma_mm: float = 10.0, seed: int = 3):
    """The drive's samples plus a LOPS packet at every truth sample: the true position with noise."""
    rng = np.random.default_rng(seed)
    counter = 0
    for sample in samples:
        yield sample
        if sample.sensor == "truth":
            counter += 1
            x, y = (sample.values[k] + float(rng.normal(0.0, sigma_mm)) for k in ("x", "y"))
            values = {"counter": counter, "d1": None, "d2": None, "d3": None, "x": x, "y": y}
            yield Sample("lops", sample.stamp_ms + 40, values)


def test_the_localizer_starts_its_filter_after_the_first_straight_leg() -> None:
    """Told nothing of where it stands (initial_pose: lops), the Localizer runs on dead reckoning
    until the first leg is driven, then starts the filter where LOPS put it: at the leg's end the
    filter is within LOPS's error of the truth, dead reckoning (started from the motor's pose,
    which the test tampers 300 mm and 10° off) is not."""
    config = load_config({"sensors": {"lops": {"use": True}}, "filter": {"initial_pose": "lops"}})
    core = LocalizationCore(config)
    truth = None
    seen_before = False

    def tampered(samples):
        for sample in samples:
            if sample.sensor == "odometry" and "x_mm" in sample.values:
                v = dict(sample.values)
                v["x_mm"] += 300
                v["angle_cdeg"] = (v["angle_cdeg"] + 1000) % 36000
                sample = Sample(sample.sensor, sample.stamp_ms, v, sample.seq)
            yield sample

    for sample in with_lops(
        tampered(drive([("w", 2000), ("s", 800.0), ("w", 2000), ("r", 90.0), ("s", 300.0)], seed=2))
    ):
        truth = sample.values if sample.sensor == "truth" else truth
        core.feed(sample)
        core.maybe_sync()
        if core.ekf is None and sample.stamp_ms > 3000:
            seen_before = True
    assert seen_before and core.ekf is not None
    k, o = core.positions["K"], core.positions["O"]
    assert math.hypot(k["x"] - truth["x"], k["y"] - truth["y"]) < 30.0
    assert abs(math.degrees(math.remainder(k["psi"] - truth["theta"], 2 * math.pi))) < 3.0
    assert math.hypot(o["x"] - truth["x"], o["y"] - truth["y"]) > 200.0


def test_initialising_by_lops_needs_lops() -> None:
    with pytest.raises(ConfigError, match="initial_pose: lops: the position is initialised by LOPS"):
        load_config({"filter": {"initial_pose": "lops"}})
