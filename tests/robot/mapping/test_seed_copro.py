"""copro's seed mode (issue 20, seed §4.3.4): the 2001 edge follower on dead reckoning alone.

The expected vectors are written out here from the seed's text: when both side sensors turn
LINEAR (WALL) the **rear** sensor's reading and the robot's pose give the start point; the
**front** sensor's last reading of the WALL gives the end point; nothing closes corners. The
readings come from this file's own ray casting against the true walls, the behaviours from its
own stand-in for the sonar's classifier (three equal readings in a row: LINEAR).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import pytest

import modules.copro as copro_module
from modules.description import robot
from modules.mapping.vectorgen import OUR_METHOD, SEED_METHOD, Vectorizer, default_layout
from modules.variants import ENV
from tests.support.fakenode import FakeOS
from tokenring.contract.protocol import default_protocol

ENUMS = default_protocol().enums
LINEAR = ENUMS["behaviour"]["LINEAR"]
B_NONE = ENUMS["behaviour"]["NONE"]
FORWARD = ENUMS["direction"]["FORWARD"]
TURN_RIGHT = ENUMS["direction"]["TURN_RIGHT"]
NO_CONTACT_AREA = ENUMS["distance_area"]["NO_CONTACT"]
NO_CONTACT = 255
STEP_MM = 12.0  # 10 cm/s, one sweep every 120 ms
SWEEP_MS = 120
LF, LR = robot.LEFT_FRONT, robot.LEFT_REAR
FRONT_MOUNT, REAR_MOUNT = robot.SONAR_MOUNTS[LF], robot.SONAR_MOUNTS[LR]
#: each body's left pair (front, rear): today's 160 mm apart, the 2001 robot's 100 mm
LEFT_PAIR = {body: (robot.sonar_mounts(body)[LF], robot.sonar_mounts(body)[LR]) for body in ("ours", "seed")}

Pose = tuple[float, float, float]
Wall = tuple[float, float, float, float]


@pytest.mark.parametrize(("body", "apart_mm"), [("ours", 160.0), ("seed", 100.0)])
def test_the_side_pair_is_mounted_as_the_robot_description_says(body: str, apart_mm: float):
    """The follower computes with the mounts the world also uses: today's body has its side
    pairs 160 mm apart, the seed's ~10 cm (the minimum object size seed §4.3.4 gives), both on
    the body's outline."""
    front, rear = LEFT_PAIR[body]
    assert default_layout(body).left.front_xy == (front.x, front.y)
    assert default_layout(body).left.rear_xy == (rear.x, rear.y)
    assert front.x - rear.x == pytest.approx(apart_mm)
    assert front.angle == rear.angle == pytest.approx(math.pi / 2)
    assert math.hypot(front.x, front.y) == pytest.approx(188.0, abs=0.5)
    assert default_layout(body).mounts == robot.sonar_mounts(body)


# -- the test's own world ----------------------------------------------------------------------


def sensor_ray(pose: Pose, mount: Any) -> tuple[float, float, float, float]:
    """Where a sensor sits in the world and where it looks (unit vector)."""
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return (
        x + c * mount.x - s * mount.y,
        y + s * mount.x + c * mount.y,
        math.cos(th + mount.angle),
        math.sin(th + mount.angle),
    )


def reading_cm(pose: Pose, mount: Any, walls: list[Wall]) -> int:
    """The nearest wall along the sensor's axis in whole cm (255 beyond 1.5 m or none)."""
    px, py, dx, dy = sensor_ray(pose, mount)
    best = math.inf
    for x1, y1, x2, y2 in walls:
        ex, ey = x2 - x1, y2 - y1
        den = dx * ey - dy * ex
        if abs(den) < 1e-12:
            continue
        t = ((x1 - px) * ey - (y1 - py) * ex) / den  # along the ray
        u = ((x1 - px) * dy - (y1 - py) * dx) / den  # along the wall
        if t > 0 and 0.0 <= u <= 1.0:
            best = min(best, t)
    return round(best / 10.0) if best <= 1500.0 else NO_CONTACT


def seed_point(pose: Pose, mount: Any, cm: int) -> tuple[float, float]:
    """The seed's conversion to global coordinates: sensor mount + reading along its axis,
    turned by the pose's heading and moved by its position."""
    x, y, th = pose
    lx = mount.x + cm * 10.0 * math.cos(mount.angle)
    ly = mount.y + cm * 10.0 * math.sin(mount.angle)
    return x + lx * math.cos(th) - ly * math.sin(th), y + lx * math.sin(th) + ly * math.cos(th)


@dataclass
class Sweep:
    stamp_ms: int
    dead_reckoned: Pose  # what motor.data says
    truth: Pose  # where the robot is (the readings' origin)
    direction: int
    driven_mm: float  # since the move command
    front_cm: int = NO_CONTACT
    rear_cm: int = NO_CONTACT
    linear: bool = False  # both left sensors LINEAR

    @property
    def active(self) -> bool:
        """Vector generation applies (scanning on): a forward move past its first centimetre."""
        return self.direction == FORWARD and self.driven_mm > 10.0


def plan(
    moves: list[tuple[str, float]], walls: list[Wall], drift_rad_per_mm: float = 0.0, body: str = "ours"
) -> list[Sweep]:
    """Sweeps of a drive: ``("forward", mm)`` and ``("right", rad)`` moves from the origin along
    +X; the dead-reckoned heading drifts by ``drift_rad_per_mm`` of the way driven."""
    front_mount, rear_mount = LEFT_PAIR[body]
    sweeps: list[Sweep] = []
    truth = [0.0, 0.0, 0.0]
    dr = [0.0, 0.0, 0.0]
    stamp = 0
    for kind, amount in moves:
        history: list[tuple[int, int]] = []
        if kind == "forward":
            n = round(amount / STEP_MM)
            for k in range(n + 1):
                if k:
                    for pose, heading in ((truth, truth[2]), (dr, dr[2])):
                        pose[0] += STEP_MM * math.cos(heading)
                        pose[1] += STEP_MM * math.sin(heading)
                    dr[2] += drift_rad_per_mm * STEP_MM
                t = (truth[0], truth[1], truth[2])
                front, rear = reading_cm(t, front_mount, walls), reading_cm(t, rear_mount, walls)
                history.append((front, rear))
                last3 = history[-3:]
                linear = (
                    len(last3) == 3
                    and NO_CONTACT not in [v for pair in last3 for v in pair]
                    and all(last3[0][i] - 2 * last3[1][i] + last3[2][i] == 0 for i in (0, 1))
                )
                sweeps.append(
                    Sweep(stamp, (dr[0], dr[1], dr[2]), t, FORWARD, k * STEP_MM, front, rear, linear)
                )
                stamp += SWEEP_MS
        else:
            for k in range(1, 11):  # a turn on the spot in ten sweeps
                truth[2] -= amount / 10
                dr[2] -= amount / 10
                t = (truth[0], truth[1], truth[2])
                sweeps.append(Sweep(stamp, (dr[0], dr[1], dr[2]), t, TURN_RIGHT, k * 5.0))
                stamp += SWEEP_MS
    return sweeps


def expected_seed_vectors(sweeps: list[Sweep], body: str = "ours") -> list[tuple[float, float, float, float]]:
    """Seed §4.3.4 written out: the rear reading at the first WALL sweep starts a vector, the
    front reading at the last WALL sweep before it ends (or generation stops) ends it."""
    front_mount, rear_mount = LEFT_PAIR[body]
    vectors = []
    start: tuple[float, float] | None = None
    end: tuple[float, float] | None = None
    for sweep in sweeps:
        wall = sweep.active and sweep.linear
        if wall and start is None:
            start = seed_point(sweep.dead_reckoned, rear_mount, sweep.rear_cm)
        if wall:
            end = seed_point(sweep.dead_reckoned, front_mount, sweep.front_cm)
        elif start is not None and end is not None:
            vectors.append((*start, *end))
            start = end = None
    if start is not None and end is not None:
        vectors.append((*start, *end))
    return vectors


def sonar_data(sweep: Sweep) -> dict[str, Any]:
    """sonar.data as copro decodes it: only the left side pair reads anything."""
    distances = [NO_CONTACT] * 8
    behaviours = [B_NONE] * 8
    areas = [NO_CONTACT_AREA] * 8
    distances[LF], distances[LR] = sweep.front_cm, sweep.rear_cm
    if sweep.linear:
        behaviours[LF] = behaviours[LR] = LINEAR
    return {"stamp_ms": sweep.stamp_ms, "distances": distances, "behaviours": behaviours, "areas": areas}


def vectorize(
    sweeps: list[Sweep], method: int, body: str = "ours"
) -> tuple[list[tuple[float, float, float, float]], Vectorizer]:
    """The sweeps through copro's vectorizer on the dead-reckoned poses, then FLUSH."""
    vectors: list[tuple[float, float, float, float]] = []
    vectorizer = Vectorizer(default_layout(body), method, vectors.append)
    for sweep in sweeps:
        vectorizer.sweep(sonar_data(sweep), sweep.dead_reckoned, sweep.active)
    vectorizer.flush()
    return vectors, vectorizer


def heading_of(v: tuple[float, float, float, float]) -> float:
    return math.atan2(v[3] - v[1], v[2] - v[0])


# -- the vectorizer --------------------------------------------------------------------------

CORNER = (2200.0, 400.0)
ROOM_CORNER = [(-1000.0, 400.0, 2200.0, 400.0), (2200.0, 400.0, 2200.0, -3000.0)]
TO_THE_CORNER = [("forward", 2004.0), ("right", math.pi / 2), ("forward", 1500.0)]


def test_seed_rear_starts_front_ends_and_the_corner_stays_open():
    sweeps = plan(TO_THE_CORNER, ROOM_CORNER)
    expected = expected_seed_vectors(sweeps)
    assert len(expected) == 2
    vectors, vectorizer = vectorize(sweeps, SEED_METHOD)
    assert len(vectors) == 2
    for got, want in zip(vectors, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-6)
    first, second = vectors
    # along the first wall (+X): the rear sensor's start lies behind the robot where WALL began
    onset = next(s for s in sweeps if s.active and s.linear)
    assert first[0] == pytest.approx(onset.dead_reckoned[0] + REAR_MOUNT.x)
    last = [s for s in sweeps if s.direction == FORWARD and s.dead_reckoned[2] == 0.0][-1]
    assert first[2] == pytest.approx(last.dead_reckoned[0] + FRONT_MOUNT.x)  # the front ends it
    assert first[1] == first[3] == pytest.approx(400.0)
    # the corner is not recorded: both vectors stop short of it (seed §4.3.6 results)
    assert math.dist(first[2:], CORNER) > 100.0 and math.dist(second[:2], CORNER) > 100.0
    assert vectorizer.corners_closed == 0 and vectorizer.merged == 0


def test_the_seed_body_follows_the_corner_with_its_own_side_pair():
    """On the 2001 robot's body the same rule holds with its pairs 100 mm apart: the start lies
    the seed rear pair's 50 mm behind the reference point, the end 50 mm ahead of it."""
    sweeps = plan(TO_THE_CORNER, ROOM_CORNER, body="seed")
    expected = expected_seed_vectors(sweeps, "seed")
    vectors, _ = vectorize(sweeps, SEED_METHOD, "seed")
    assert len(vectors) == len(expected) == 2
    for got, want in zip(vectors, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-6)
    onset = next(s for s in sweeps if s.active and s.linear)
    assert vectors[0][0] == pytest.approx(onset.dead_reckoned[0] - 50.0)


BOX_BESIDE_THE_PATH = [(1000.0, 400.0, 1150.0, 400.0)]  # 15 cm long, 40 cm to the left


@pytest.mark.parametrize(("body", "mapped"), [("seed", True), ("ours", False)])
def test_an_object_must_span_both_side_pairs_to_be_mapped(body: str, mapped: bool):
    """Seed §4.3.4: an object is mapped only while both side sensors see it, so the objects the
    follower maps are at least about as long as the pairs are apart ("etwa 10cm"). A 15 cm box
    beside the path is a vector on the seed's 10 cm body and nothing on today's 16 cm body."""
    sweeps = plan([("forward", 2000.0)], BOX_BESIDE_THE_PATH, body=body)
    vectors, _ = vectorize(sweeps, SEED_METHOD, body)
    assert [v[1] for v in vectors] == pytest.approx([400.0] * len(vectors), abs=1.0)
    assert bool(vectors) is mapped
    expected = expected_seed_vectors(sweeps, body)
    assert len(vectors) == len(expected)
    for got, want in zip(vectors, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-6)


def test_ours_closes_the_same_corner_the_seed_leaves_open():
    vectors, vectorizer = vectorize(plan(TO_THE_CORNER, ROOM_CORNER), OUR_METHOD)
    assert len(vectors) == 2 and vectorizer.corners_closed == 1
    assert math.dist(vectors[0][2:], CORNER) < 30.0 and math.dist(vectors[1][:2], CORNER) < 30.0


WALL_WITH_A_GAP = [(-500.0, 400.0, 1000.0, 400.0), (2000.0, 400.0, 4000.0, 400.0)]
DRIFT = math.radians(2.0) / 1000.0  # the dead-reckoned heading turns 2° per metre driven


def test_seed_angle_error_grows_with_the_distance_driven_on_a_drifting_heading():
    sweeps = plan([("forward", 4200.0)], WALL_WITH_A_GAP, DRIFT)
    expected = expected_seed_vectors(sweeps)
    vectors, _ = vectorize(sweeps, SEED_METHOD)
    assert len(vectors) == len(expected) == 2
    for got, want in zip(vectors, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-6)
    # the true walls run along +X: each vector's angle is the error, about the drifted heading
    # midway along it, so the later wall is the more slanted one
    errors = [heading_of(v) for v in vectors]
    for v, error in zip(vectors, errors, strict=True):
        mid_x = (v[0] + v[2]) / 2
        assert error == pytest.approx(DRIFT * mid_x, abs=math.radians(0.5)), (v, math.degrees(error))
    assert errors[1] > errors[0] + math.radians(3.0)


# -- the program --------------------------------------------------------------------------


class FakeLocalizer:
    """A filter that knows the truth: ours maps on it, the seed must not."""

    def __init__(self) -> None:
        self.pose_now: Pose = (0.0, 0.0, 0.0)
        self.stamp_ms = 0
        self.walls: list[tuple[float, ...]] = []

    def step(self) -> None:
        pass

    def pose(self) -> dict[str, Any]:
        x, y, th = self.pose_now
        return {
            "x_mm": x,
            "y_mm": y,
            "heading_rad": th,
            "valid": 7,
            "source": copro_module.POSE_EKF,
            "stamp_ms": self.stamp_ms,
            "sigmas": (10.0, 10.0, 0.01),
        }

    def add_map_wall(self, *vector: float) -> None:
        self.walls.append(vector)


def run_copro(
    monkeypatch: pytest.MonkeyPatch, choice: str, sweeps: list[Sweep]
) -> tuple[Any, list, FakeLocalizer, int]:
    """copro's program over the sweeps (motor.data = dead reckoning, a filter that knows the
    truth offered), START_SCAN first and FLUSH last; the VECTORs it delivered, in mm."""
    monkeypatch.setenv(ENV, f"copro={choice}")
    monkeypatch.delenv("TOKENRING_COPRO_METHOD", raising=False)
    localizer = FakeLocalizer()
    opened = []
    monkeypatch.setattr(copro_module, "open_localizer", lambda os, truth=None: opened.append(1) or localizer)
    os = FakeOS()
    program = copro_module.Program(os)
    program.setup()
    try:
        program.handle_command("START_SCAN", {})
        motor = os.buffers["motor.data"]
        for sweep in sweeps:
            x, y, th = sweep.dead_reckoned
            cdeg = round(-math.degrees(th) * 100) % 36000  # the wire's heading: clockwise
            motor.values = {
                "x_mm": round(x),
                "y_mm": round(y),
                "angle_cdeg": cdeg,
                "direction": sweep.direction,
                "distance_mm": round(sweep.driven_mm),
                "stamp_ms": sweep.stamp_ms,
            }
            motor.published = True
            localizer.pose_now, localizer.stamp_ms = sweep.truth, sweep.stamp_ms
            pose = program._update_pose()
            program.process_sweep(sonar_data(sweep), motor.read(), pose)
        program.handle_command("FLUSH", {})
        deadline = time.monotonic() + 30.0
        while program.stats["flushes_done"] < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert program.stats["flushes_done"] == 1
    finally:
        program.teardown()
        program.stop_requested.set()
        program.sender.join(10.0)
    vectors = [(a["x1"] * 10.0, a["y1"] * 10.0, a["x2"] * 10.0, a["y2"] * 10.0) for m, c, a in os.delivered]
    assert all((m, c) == ("map", "VECTOR") for m, c, _ in os.delivered)
    return program, vectors, localizer, len(opened)


ONE_WALL = [(-500.0, 400.0, 3500.0, 400.0)]


def test_seed_mode_maps_on_motor_data_alone_where_ours_maps_on_the_filter(monkeypatch):
    sweeps = plan([("forward", 3000.0)], ONE_WALL, DRIFT)
    program, vectors, localizer, opened = run_copro(monkeypatch, "seed", sweeps)
    assert program.method == SEED_METHOD and program.localizer is None and opened == 0
    assert program.report()["pose_source"] == copro_module.POSE_DEAD_RECKONING
    expected = expected_seed_vectors(sweeps)
    assert len(vectors) == len(expected) == 1
    assert vectors[0] == pytest.approx(expected[0], abs=8.0)  # whole cm on the wire
    assert heading_of(vectors[0]) > math.radians(2.0)  # the drift, mapped as it was in 2001
    assert localizer.walls == []

    program, ours, localizer, opened = run_copro(monkeypatch, "ours", sweeps)
    assert program.method == OUR_METHOD and opened == 1
    assert len(ours) == 1 and abs(heading_of(ours[0])) < math.radians(0.5)
    assert ours[0][1] == pytest.approx(400.0, abs=20.0) and ours[0][3] == pytest.approx(400.0, abs=20.0)
    assert len(localizer.walls) == 1  # ours hands its walls to the filter
