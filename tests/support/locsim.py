"""Sensor samples of a drive in a world, without a ring: fast, deterministic input for the core.

The robot's motion is the world simulator's own (``TrackedRobot``: step-length and glide-factor
noise per move) and the sonar readings come from its ray caster; only the hardware modules are
stood in for: step counters every ``odo_period_ms``, a compass heading with Gaussian noise, a
sweep of the eight sonars (nearest surface within the 30° beam, whole cm) every 120 ms.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from modules.description import load_world
from modules.description.robot import SONAR_BEAM_RAD, SONAR_MOUNTS, SONAR_RANGE_MM, STEP_MM, sonar_world_pose
from modules.localization.sync import Sample
from modules.world.physics import TrackedRobot, cast_rays


def square_moves(laps: int, side_mm: float) -> list[tuple[str, float]]:
    """Counter-clockwise laps: drive a side, turn left 90°, four times per lap."""
    return [move for _ in range(laps * 4) for move in (("s", side_mm), ("r", 90.0))]


def drive(
    moves: list[tuple[str, float]],
    world: str = "square",
    seed: int = 0,
    speed_mm_s: float = 50.0,
    odo_period_ms: int = 100,
    compass_period_ms: int = 50,
    sonar_period_ms: int = 120,
    compass_sigma_deg: float = 1.0,
    steps_per_degree: float = 6.5,
    truth_period_ms: int = 100,
    heading: Callable[[], float | None] | None = None,
    turn_tolerance_deg: float = 0.5,
    sonar_sigma_mm: float = 20.0,
    rest_ms: int = 500,
) -> Iterator[Sample]:
    """Samples in time order for ``moves`` (``s`` mm / ``r`` degrees CCW / ``w`` ms at rest),
    sensor-stamped.

    ``heading`` (the fused heading, rad CCW, or None) closes the loop on turns the way main's
    action runner does: a turn aims at the heading before it plus the angle, and up to three
    correcting turns follow while the fused heading is off by more than ``turn_tolerance_deg``.
    """
    room = load_world(world)
    rng = np.random.default_rng(seed)
    robot = TrackedRobot(room, rng)
    steps_per_s = speed_mm_s / STEP_MM
    per_tick = max(1, round(steps_per_s * odo_period_ms / 1000))
    state = {"left": 0, "right": 0, "now": 0, "compass": 0, "sonar": 0, "truth": 0, "sweep": 0, "sample": 0}
    rays = np.linspace(-SONAR_BEAM_RAD / 2, SONAR_BEAM_RAD / 2, 7)

    def tick(move_id: int, dl: int, dr: int) -> Iterator[Sample]:
        end = state["now"] + odo_period_ms
        while True:
            t = min(state["compass"], state["sonar"], state["truth"])
            if t >= end:
                break
            pose = robot.pose
            if t == state["truth"]:
                yield Sample("truth", t, {"x": pose.x, "y": pose.y, "theta": pose.theta})
                state["truth"] += truth_period_ms
            if t == state["compass"]:
                value = room.heading(pose.theta) + rng.normal(0.0, math.radians(compass_sigma_deg))
                cdeg = round(math.degrees(value) * 100) % 36000
                yield Sample("compass", t, {"heading_cdeg": cdeg, "state": 1}, seq=state["sample"] % 65536)
                state["sample"] += 1
                state["compass"] += compass_period_ms
            if t == state["sonar"]:
                distances = []
                for index in range(len(SONAR_MOUNTS)):
                    sx, sy, sa = sonar_world_pose(pose.x, pose.y, pose.theta, index)
                    d = float(np.min(cast_rays(room, sx, sy, sa + rays, SONAR_RANGE_MM).distance))
                    d += rng.normal(0.0, sonar_sigma_mm)
                    distances.append(min(254, max(1, round(d / 10))) if math.isfinite(d) else 255)
                yield Sample("sonar", t, {"distances": distances}, seq=state["sweep"] % 65536)
                state["sweep"] += 1
                state["sonar"] += sonar_period_ms
        if move_id >= 0:
            robot.apply_steps(dl, dr, steps_per_s, move_id)
        state["left"] += dl
        state["right"] += dr
        state["now"] = end
        values = {
            "steps_left": state["left"],
            "steps_right": state["right"],
            "x_mm": 0,
            "y_mm": 0,
            "angle_cdeg": 0,
        }
        yield Sample("odometry", end, {**values, "state": 1 if dl or dr else 0})

    def move(move_id: int, kind: str, amount: float) -> Iterator[Sample]:
        total = round(abs(amount) / STEP_MM) if kind == "s" else round(abs(amount) * steps_per_degree)
        sign = 1 if amount >= 0 else -1
        done = 0
        while done < total:
            n = min(per_tick, total - done)
            yield from (
                tick(move_id, sign * n, sign * n) if kind == "s" else tick(move_id, -sign * n, sign * n)
            )
            done += n

    move_id = 0
    for kind, amount in moves:
        if kind == "w":  # stand still for ``amount`` ms
            for _ in range(int(amount) // odo_period_ms):
                yield from tick(-1, 0, 0)
            continue
        target = None
        if kind == "r" and heading is not None and heading() is not None:
            target = heading() + math.radians(amount)
        yield from move(move_id, kind, amount)
        move_id += 1
        for _ in range(3 if target is not None else 0):
            yield from tick(-1, 0, 0)  # let the filter see the end of the turn
            error = math.degrees(math.remainder(target - heading(), 2 * math.pi))
            if abs(error) <= turn_tolerance_deg:
                break
            yield from move(move_id, "r", error)
            move_id += 1
    for _ in range(max(5, rest_ms // odo_period_ms)):  # stand still at the end
        yield from tick(-1, 0, 0)


def truth_at_end(moves: list[tuple[str, float]], **kwargs) -> tuple[float, float, float]:
    """The last truth sample of a drive."""
    last = None
    for s in drive(moves, **kwargs):
        if s.sensor == "truth":
            last = s.values
    assert last is not None
    return last["x"], last["y"], last["theta"]


def gyro_sample(stamp_ms: int, angle_rad: float, state: int = 2) -> Sample:
    """A gyro.data sample as the token carries it: the summed angle in whole mrad (state 2:
    RUNNING)."""
    return Sample("gyro", stamp_ms, {"angle_mrad": round(angle_rad * 1000), "rate_urad_s": 0, "state": state})


def with_gyro(samples: Iterator[Sample], scale: float = 1.0) -> Iterator[Sample]:
    """The drive's samples plus a gyro sample at every truth sample: the true summed turn times
    ``scale`` (a gyro's scale-factor error), whole mrad, as the gyro module publishes it."""
    previous: float | None = None
    summed = 0.0
    for sample in samples:
        yield sample
        if sample.sensor != "truth":
            continue
        theta = sample.values["theta"]
        if previous is None:
            previous = theta
        summed += math.remainder(theta - previous, 2 * math.pi)
        previous = theta
        yield gyro_sample(sample.stamp_ms, summed * scale)
