"""bench.mapping's figures from a recorded drive and the world's truth (no ring)."""

from __future__ import annotations

import math

import pytest

from bench.mapping import compass_error
from modules.units import heading_to_cdeg


def test_the_compass_error_on_straight_moves_is_fitted_as_a_harmonic_of_the_heading() -> None:
    """A running field misjudged by the calibration bends the heading on the move by
    b cos(heading) + c sin(heading); at rest the heading is right."""
    north = math.pi / 2
    truth, motor_log, compass_log = [], [], []
    for k in range(400):
        stamp = 1000 + 100 * k
        theta = (k // 50) * math.pi / 4  # eight legs, one per heading
        moving = k % 50 >= 10
        error = math.radians(0.4 * math.cos(theta) - 0.3 * math.sin(theta)) if moving else 0.0
        truth.append((stamp, 0.0, 0.0, theta))
        motor_log.append({"stamp_ms": stamp - 1, "direction": 1 if moving else 0, "state": int(moving)})
        heading = (north - theta + error) % (2 * math.pi)
        compass_log.append({"stamp_ms": stamp, "state": 1, "heading_cdeg": heading_to_cdeg(heading)})
    out = compass_error({"truth": truth, "motor_log": motor_log, "compass_log": compass_log}, settle_ms=0)
    assert out["moving_harmonic_deg"] == pytest.approx(0.5, abs=0.02)


def _straight_move(seq: int, t0: int, steps0: int, stall: tuple[int, int] | None = None) -> tuple[list, list]:
    """A 6 s forward move at 100 mm/s counted by the motor every 100 ms, and the world's truth
    every 100 ms: 1 % longer than counted, or standing still through ``stall`` and caught up after."""
    motor, truth = [], []
    rate = 100.0 / 0.5419  # half-steps per second per track at 100 mm/s
    for k in range(61):
        t = t0 + 100 * k
        steps = steps0 + round(rate * (t - t0) / 1000.0)
        motor.append(
            {"stamp_ms": t, "direction": 1, "move_seq": seq, "steps_left": steps, "steps_right": steps}
        )
        held = stall[0] if stall is not None and stall[0] <= t < stall[1] else t
        truth.append((t + 50, 1.01 * 100.0 * (held + 50 - t0) / 1000.0, 0.0, 0.0))
    return motor, truth


def test_ring_timing_counts_missed_sweeps_slow_rounds_and_a_world_held_by_a_stall() -> None:
    """Sweeps 1, 2, 3, 5, (4 and 5 again: stale,) 6 seen: one of five sweeps missed. A move whose truth stood for 1.2 s
    near its end reads far below the others' 1.01 and is counted off by 2 %."""
    from bench.mapping import ring_timing

    moves = [
        _straight_move(1, 0, 0),
        _straight_move(2, 7000, 20000),
        _straight_move(3, 14000, 40000, (18500, 19700)),
    ]
    moves.append(_straight_move(4, 21000, 60000))
    motor = [m for ms, _ in moves for m in ms]
    truth = [t for _, ts in moves for t in ts]
    # the rounds: 100 ms apart within a move; between moves 1 s (the gap of 1000 ms counted as max)
    records = [({"sweep": s}, {}, {}) for s in (1, 2, 3, 5, 4, 5, 6)]  # 4, then 5 again: stale frames
    out = ring_timing({"motor_log": motor, "truth": truth, "records": records})
    assert out["sweeps_missed_fraction"] == pytest.approx(0.2)
    assert out["stale_sweeps"] == 2
    assert out["motor_sample_ms"]["median"] == 100
    assert out["motor_sample_ms"]["max"] == 1000
    straight = out["straight_moves"]
    assert straight["moves"] == 4
    assert straight["true_over_counted_median"] == pytest.approx(1.01, abs=0.002)
    assert straight["off_by_2pct"] == 1


class _Session:
    """Just enough of a Zenoh session for the recorder: subscribers that are never called."""

    class _Subscriber:
        def undeclare(self) -> None:
            pass

    def declare_subscriber(self, _key: str, _handler: object) -> _Subscriber:
        return self._Subscriber()


class _Sample:
    def __init__(self, message: dict) -> None:
        import msgpack

        packed = msgpack.packb(message)
        self.payload = type("Payload", (), {"to_bytes": lambda _self: packed})()


def test_each_run_counts_the_worlds_collisions_and_closest_approach_from_its_truth() -> None:
    """The world's truth stream carries its own collision count and the body's closest approach:
    the recorder keeps the latest of each (an infinite approach, nothing near yet, is none)."""
    from bench.mapping import Recorder

    recorder = Recorder(_Session(), "r")
    truth = {"stamp_ms": 0, "x": 0.0, "y": 0.0, "theta": 0.0, "collisions": 0, "closest_mm": math.inf}
    recorder._on_truth(_Sample(truth))
    assert (recorder.collisions, recorder.closest_mm) == (0, None)
    recorder._on_truth(_Sample({**truth, "stamp_ms": 100, "collisions": 2, "closest_mm": 0.0}))
    recorder._on_truth(_Sample({**truth, "stamp_ms": 200, "collisions": 2, "closest_mm": 0.0}))
    assert (recorder.collisions, recorder.closest_mm) == (2, 0.0)
    assert len(recorder.truth) == 3


def test_the_collision_line_sums_the_runs_that_counted_and_names_the_closest() -> None:
    from bench.closedloop import contact_summary

    rooms = [
        {"collisions": 0, "closest_mm": 60.0},
        {"collisions": 3, "closest_mm": 0.0},
        {"collisions": 1, "closest_mm": 20.0},
        {"collisions": None, "closest_mm": None},  # recorded before runs counted them
    ]
    line = contact_summary(rooms)
    assert line == "3 runs: 4 collisions in 2 runs; closest approach median 20 mm, worst 0 mm", line
    assert contact_summary([{"collisions": None}]) == ""
