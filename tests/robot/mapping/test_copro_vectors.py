"""copro's side hypotheses and vector generation on synthetic sonar and pose sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from modules.mapping.vectorgen import (
    CORNER,
    DEGRESSIVE,
    LINEAR,
    NONE,
    OBSTACLE,
    PROGRESSIVE,
    WALL,
    PoseHistory,
    SeedEdgeFollower,
    SideHypothesis,
    SweepInput,
    VectorPostProcessor,
    WallTracker,
    classify_side,
    default_layout,
    observe_side,
)
from tests.support.sidesonar import BEHAVIOUR_NONE, SeedClassifier, side_readings

B = {"NONE": BEHAVIOUR_NONE, "LINEAR": LINEAR, "PROGRESSIVE": PROGRESSIVE, "DEGRESSIVE": DEGRESSIVE}
C = {"NONE": NONE, "WALL": WALL, "CORNER": CORNER, "OBSTACLE": OBSTACLE}

# the whole truth table of observe_side (front, rear) -> contact, as SPEC §3 copro states it
TRUTH_TABLE = [
    ("LINEAR", "LINEAR", "WALL"),
    ("DEGRESSIVE", "LINEAR", "CORNER"),
    ("LINEAR", "DEGRESSIVE", "CORNER"),
    ("PROGRESSIVE", "LINEAR", "OBSTACLE"),
    ("LINEAR", "PROGRESSIVE", "OBSTACLE"),
    ("NONE", "NONE", "NONE"),
    ("NONE", "LINEAR", "NONE"),
    ("LINEAR", "NONE", "NONE"),
    ("DEGRESSIVE", "DEGRESSIVE", "NONE"),
    ("PROGRESSIVE", "PROGRESSIVE", "NONE"),
    ("PROGRESSIVE", "DEGRESSIVE", "NONE"),
    ("DEGRESSIVE", "PROGRESSIVE", "NONE"),
    ("NONE", "DEGRESSIVE", "NONE"),
    ("PROGRESSIVE", "NONE", "NONE"),
]


@pytest.mark.parametrize(("front", "rear", "expected"), TRUTH_TABLE)
def test_observe_side_truth_table(front, rear, expected):
    assert classify_side(B[front], B[rear]) == C[expected]


def test_observe_side_counts_confidence_while_the_hypothesis_stays_and_takes_the_nearer_area():
    h = SideHypothesis()
    for expected in (1, 2, 3):
        h = observe_side(LINEAR, LINEAR, 3, 2, h)
        assert (h.contact, h.confidence, h.area) == (WALL, expected, 2)
    h = observe_side(DEGRESSIVE, LINEAR, 1, 4, h)
    assert (h.contact, h.confidence, h.area) == (CORNER, 1, 1)
    for _ in range(150):
        h = observe_side(DEGRESSIVE, LINEAR, 1, 4, h)
    assert h.confidence == 100


LAYOUT = default_layout()
SWEEP_MS = 120
SPEED_MM_S = 100.0
WALL_Y = 400.0


def drive(generator_cls, walls, start_x, end_x, y=0.0, sigma_cm=0.0, seed=1, use_contact=True):
    """Drive along +X at 10 cm/s past ``walls``, feeding one side's generator each sweep."""
    rng = np.random.default_rng(seed)
    vectors = []
    sensors = LAYOUT.left
    gen = generator_cls(sensors, vectors.append)
    front_cls, rear_cls = SeedClassifier(), SeedClassifier()
    hypothesis = SideHypothesis()
    x, t = start_x, 0
    step = SPEED_MM_S * SWEEP_MS / 1000.0
    while x <= end_x:
        pose = (x, y, 0.0)
        front, rear = side_readings(pose, sensors, walls, rng=rng, sigma_cm=sigma_cm)
        hypothesis = observe_side(front_cls.feed(front), rear_cls.feed(rear), 0, 0, hypothesis)
        gen.feed(SweepInput(t, pose, front, rear, hypothesis.contact if use_contact else NONE, True))
        x += step
        t += SWEEP_MS
    gen.feed(SweepInput(t, (x, y, 0.0), 255, 255, NONE, False))  # STOP_SCAN
    if isinstance(gen, WallTracker):
        gen.finish()  # FLUSH: ours keeps a run open over the stops between moves
    return vectors


def beam_bias(distance_mm: float) -> float:
    """How far past a wall's end a 30° beam still sees it: d·tan 15°."""
    return distance_mm * math.tan(math.radians(15.0))


def test_seed_edge_following_on_a_straight_wall_gives_one_vector_at_its_known_bias():
    walls = [(0.0, WALL_Y, 2000.0, WALL_Y)]
    vectors = drive(SeedEdgeFollower, walls, -600.0, 2600.0)
    assert len(vectors) == 1
    x1, y1, x2, y2 = vectors[0]
    d = WALL_Y - LAYOUT.left.front_xy[1]
    # the rear sensor starts the vector while the beam's edge still reaches the wall's start,
    # the front sensor ends it while its beam's edge still reaches the wall's end
    assert abs(x1 - (0.0 - beam_bias(d))) < 50.0, vectors
    assert abs(x2 - (2000.0 + beam_bias(d))) < 50.0, vectors
    assert abs(y1 - WALL_Y) < 50.0 and abs(y2 - WALL_Y) < 50.0


def test_ours_on_a_straight_wall_gives_one_vector_within_5_cm_even_with_sonar_noise():
    walls = [(0.0, WALL_Y, 2000.0, WALL_Y)]
    d = WALL_Y - LAYOUT.left.front_xy[1]
    for sigma in (0.0, 1.0):
        vectors = drive(WallTracker, walls, -600.0, 2600.0, sigma_cm=sigma, use_contact=False)
        assert len(vectors) == 1, (sigma, vectors)
        x1, y1, x2, y2 = vectors[0]
        # the wall came into view and went out of it: the beam's reach past its ends is taken off
        assert beam_bias(d) > 50.0
        assert abs(x1 - 0.0) < 50.0, vectors
        assert abs(x2 - 2000.0) < 50.0, vectors
        assert abs(y1 - WALL_Y) < 20.0 and abs(y2 - WALL_Y) < 20.0, vectors


def test_ours_keeps_the_ends_where_the_scan_started_and_stopped_beside_the_wall():
    walls = [(0.0, WALL_Y, 2000.0, WALL_Y)]
    vectors = drive(WallTracker, walls, 500.0, 1500.0, use_contact=False)
    assert len(vectors) == 1
    x1, _, x2, _ = vectors[0]
    front, rear = LAYOUT.left.front_xy[0], LAYOUT.left.rear_xy[0]
    assert abs(x1 - (500.0 + rear)) < 20.0 and abs(x2 - (1500.0 + front)) < 20.0, vectors


def test_ours_runs_on_over_the_stops_between_moves_along_one_wall():
    walls = [(0.0, WALL_Y, 3000.0, WALL_Y)]
    vectors: list = []
    gen = WallTracker(LAYOUT.left, vectors.append)
    t = 0
    for start in (200.0, 800.0, 1400.0):  # three 600 mm segments, a stop and a small turn between
        for k in range(50):
            pose = (start + k * 12.0, 0.0, math.radians(2.0 if start == 800.0 else 0.0))
            front, rear = side_readings(pose, LAYOUT.left, walls)
            gen.feed(SweepInput(t, pose, front, rear, NONE, True))
            t += SWEEP_MS
        gen.feed(SweepInput(t, pose, 255, 255, NONE, False))
        assert vectors == []
    gen.finish()
    assert len(vectors) == 1
    x1, y1, x2, y2 = vectors[0]
    assert x1 < 300.0 and x2 > 1900.0 and abs(y1 - WALL_Y) < 20 and abs(y2 - WALL_Y) < 20


def test_seed_method_breaks_up_under_noise_where_ours_does_not():
    walls = [(0.0, WALL_Y, 2000.0, WALL_Y)]
    seed_vectors = drive(SeedEdgeFollower, walls, -600.0, 2600.0, sigma_cm=1.0)
    ours = drive(WallTracker, walls, -600.0, 2600.0, sigma_cm=1.0, use_contact=False)
    assert len(seed_vectors) > len(ours) == 1


def test_two_walls_at_a_step_give_two_vectors():
    walls = [(0.0, WALL_Y, 1000.0, WALL_Y), (1000.0, WALL_Y + 300, 2000.0, WALL_Y + 300)]
    vectors = drive(WallTracker, walls, -300.0, 2300.0, use_contact=False)
    assert len(vectors) == 2
    assert abs(vectors[0][1] - WALL_Y) < 20 and abs(vectors[1][1] - WALL_Y - 300) < 20


def test_post_processor_merges_collinear_pieces_and_closes_a_corner():
    sent = []
    post = VectorPostProcessor(sent.append)
    post.add((0.0, 400.0, 900.0, 402.0))
    post.add((1100.0, 401.0, 2000.0, 399.0))  # same wall after a 20 cm gap
    assert sent == [] and post.merged == 1
    post.add((2300.0, 700.0, 2300.0, 1800.0))  # the next wall, perpendicular, 30 cm short of the corner
    assert len(sent) == 1 and post.corners_closed == 1
    first = sent[0]
    assert first[0] == pytest.approx(0.0, abs=5) and first[2] == pytest.approx(2300.0, abs=5)
    assert first[3] == pytest.approx(400.0, abs=5)
    post.flush()
    assert sent[1][:2] == pytest.approx(first[2:])
    assert sent[1][3] == 1800.0


def test_post_processor_does_not_close_far_or_backward_corners():
    sent = []
    post = VectorPostProcessor(sent.append)
    post.add((0.0, 0.0, 1000.0, 0.0))
    post.add((3000.0, 500.0, 3000.0, 1500.0))  # intersection 2 m past the end: not a corner
    post.flush()
    assert sent == [(0.0, 0.0, 1000.0, 0.0), (3000.0, 500.0, 3000.0, 1500.0)]


def test_pose_history_interpolates_position_and_heading_across_the_wrap():
    h = PoseHistory()
    h.add(0, (0.0, 0.0, math.pi - 0.1))
    h.add(100, (100.0, 50.0, -math.pi + 0.1))
    x, y, th = h.at(50)
    assert (x, y) == (50.0, 25.0)
    assert abs(abs(th) - math.pi) < 1e-9
    assert h.at(500) == (100.0, 50.0, -math.pi + 0.1)


def test_pose_history_carries_a_pose_by_the_recorded_motion_in_its_own_frame() -> None:
    from modules.mapping.vectorgen import PoseHistory

    history = PoseHistory()
    history.add(0, (0.0, 0.0, 0.0))
    history.add(1000, (100.0, 0.0, 0.0))  # 100 mm forward, then a quarter turn left on the spot
    history.add(2000, (100.0, 0.0, math.pi / 2))
    # a pose facing +Y at t=0 goes 100 mm forward (to +Y) and ends facing -X
    x, y, th = history.carry((500.0, 500.0, math.pi / 2), 0, 2000)
    assert (x, y) == pytest.approx((500.0, 600.0))
    assert th == pytest.approx(math.pi)
    assert PoseHistory().carry((1.0, 2.0, 3.0), 0, 10) == (1.0, 2.0, 3.0)  # nothing recorded
