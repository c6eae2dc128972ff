"""The echo memory's free way ahead (modules/navigation/clearance.py), judged against geometry
worked out by hand here: a wall ahead, a wall alongside, a partition's bare end met edge-on."""

from __future__ import annotations

import math

import pytest

from modules.description.robot import (
    FRONT,
    LEFT_FRONT,
    LEFT_REAR,
    REAR,
    RIGHT_FRONT,
    RIGHT_REAR,
    SONAR_MOUNTS,
)
from modules.navigation.clearance import NO_CONTACT_CM, ClearanceSettings, EchoMemory

R = 190.0  # the collision circle
MARGIN = 60.0


def readings(**cm: int) -> list[int]:
    """Eight readings, NO_CONTACT but for the named pairs."""
    out = [NO_CONTACT_CM] * 8
    for index, value in cm.items():
        out[int(index.removeprefix("s"))] = value
    return out


def memory() -> EchoMemory:
    return EchoMemory(ClearanceSettings(margin_mm=MARGIN))


def test_nothing_seen_leaves_the_way_open():
    echoes = memory()
    echoes.add((0.0, 0.0, 0.0), readings(), 0)
    assert echoes.free_mm((0.0, 0.0, 0.0)) == math.inf


def test_a_wall_ahead_leaves_its_distance_less_the_radius_and_the_margin():
    echoes = memory()
    nose = SONAR_MOUNTS[FRONT].x  # 188 mm ahead of the centre
    echoes.add((0.0, 0.0, 0.0), readings(**{f"s{FRONT}": round((900 - nose) / 10)}), 0)
    # the echo on the beam's axis is at x = 900: the circle reaches it within the margin at
    # 900 - 190 - 60; the arc's other points lie nearer but off the axis, which frees more
    assert echoes.free_mm((0.0, 0.0, 0.0)) == pytest.approx(900 - R - MARGIN, abs=3)
    # and from 300 mm nearer, 300 less; looking away, nothing in the way
    assert echoes.free_mm((300.0, 0.0, 0.0)) == pytest.approx(900 - R - MARGIN - 300, abs=3)
    assert echoes.free_mm((0.0, 0.0, math.pi)) == math.inf
    assert echoes.free_mm((0.0, 0.0, 0.0), reverse=True) == math.inf


def test_a_wall_followed_on_the_left_is_not_in_the_way():
    echoes = memory()
    # the side pairs read 30 cm: the wall runs 170 + 300 mm to the left of the centre
    for x in range(0, 1000, 50):
        echoes.add((float(x), 0.0, 0.0), readings(**{f"s{LEFT_FRONT}": 30, f"s{LEFT_REAR}": 30}), x)
    assert echoes.free_mm((1000.0, 0.0, 0.0)) == math.inf


def test_a_partition_end_met_edge_on_is_known_from_its_face_seen_in_passing():
    """A zero-thickness partition runs east from (1000, -100). Driving east along its north face
    earlier, the right side pairs saw it square-on; coming back from the west on a line 100 mm
    north of it, the nose meets its bare end edge-on (no echo): the memory stops the way short."""
    echoes = memory()
    # earlier, heading east 230 mm north of the face, both right pairs over it: they look south
    # onto it from 130 - 170 = -40 mm, 60 mm away (the rear pair is 80 mm behind the centre)
    for x in range(1700, 1079, -20):
        echoes.add((float(x), 130.0, 0.0), readings(**{f"s{RIGHT_FRONT}": 6, f"s{RIGHT_REAR}": 6}), 0)
    start = (0.0, 0.0, 0.0)  # 100 mm north of the partition's line, heading east at its end
    contact = 1000.0 - math.sqrt(R**2 - 100.0**2)  # where the circle would touch the bare end
    free = echoes.free_mm(start)
    assert free < contact - 40.0, (free, contact)  # stopped well short of touching
    assert free > contact - 200.0, (free, contact)  # but not absurdly far away


def test_backing_off_looks_behind_the_robot():
    echoes = memory()
    tail = -SONAR_MOUNTS[REAR].x
    echoes.add((0.0, 0.0, 0.0), readings(**{f"s{REAR}": round((500 - tail) / 10)}), 0)
    assert echoes.free_mm((0.0, 0.0, 0.0), reverse=True) == pytest.approx(
        500 - R - MARGIN, abs=6
    )  # 1-cm readings, the arc
    assert echoes.free_mm((0.0, 0.0, 0.0)) == math.inf


def test_a_point_inside_the_margin_ahead_leaves_no_way_at_all():
    echoes = memory()
    echoes.add((0.0, 0.0, 0.0), readings(**{f"s{FRONT}": 3}), 0)  # 3 cm off the nose
    assert echoes.free_mm((0.0, 0.0, 0.0)) == 0.0


def test_echoes_long_ago_are_forgotten_and_far_ones_kept_for_coming_back():
    echoes = EchoMemory(ClearanceSettings(keep_ms=10_000.0))
    echoes.add((0.0, 0.0, 0.0), readings(**{f"s{FRONT}": 50}), 0)  # a wall at about 690 mm
    assert len(echoes.points) > 0
    echoes.add((5000.0, 0.0, 0.0), readings(), 1000)  # the robot is 5 m away now
    assert echoes.free_mm((0.0, 0.0, 0.0)) < 690 - R  # back where it saw it: still known
    echoes.add((0.0, 0.0, math.pi), readings(), 11_000)  # 11 s after it was seen
    assert len(echoes.points) == 0
    assert echoes.free_mm((0.0, 0.0, 0.0)) == math.inf


def test_a_wall_passed_for_minutes_is_kept_as_a_line_not_a_heap():
    """The same wall seen on every sweep for two minutes: one point per cell, whatever the time."""
    echoes = EchoMemory(ClearanceSettings(merge_mm=20.0))
    for k in range(1000):  # 1000 sweeps, 3 mm apart: 3 m of wall, 30 cm off the left pairs
        x = 3.0 * k
        echoes.add((x, 0.0, 0.0), readings(**{f"s{LEFT_FRONT}": 30, f"s{LEFT_REAR}": 30}), 120 * k)
    # the arcs of both pairs span about 3 m by 80 mm: at most a few cells across the wall
    assert len(echoes.points) <= (3000 / 20 + 10) * (80 / 20 + 2)
    assert echoes.free_mm((3000.0, 0.0, 0.0)) == math.inf  # and still beside the way, not in it


def test_an_echo_farther_along_a_beam_clears_what_lay_short_of_it_and_no_echo_clears_nothing():
    """An arc is where the surface may be: a later beam whose echo came from beyond a point went
    through it. No echo says nothing: a surface at a grazing angle answers none."""
    nose = SONAR_MOUNTS[FRONT].x
    sweep = [math.radians(d) for d in range(-25, 30, 5)]  # the nose swept across the old arc
    cleared, kept = memory(), memory()
    for echoes in (cleared, kept):
        echoes.add((0.0, 0.0, 0.0), readings(**{f"s{FRONT}": 50}), 0)  # something 50 cm ahead
    before = cleared.free_mm((0.0, 0.0, 0.0))
    assert before < 500 + nose - R  # the arc's near points: at most the echo's distance
    for heading in sweep:  # then echoes from 100 cm on every bearing across it: it has gone
        cleared.add((0.0, 0.0, heading), readings(**{f"s{FRONT}": 75}), 1)
        kept.add((0.0, 0.0, heading), readings(), 1)
    # the way now ends short of the far echoes (750 mm past the nose), not of the old ones
    assert cleared.free_mm((0.0, 0.0, 0.0)) > 750 + nose - R - MARGIN - 60
    assert kept.free_mm((0.0, 0.0, 0.0)) == pytest.approx(before)


def test_a_wall_beside_the_lane_is_passed_and_one_in_it_is_not():
    """The circle passes an echo beside it at the side margin; one inside its width it stops at."""
    beside, inside = memory(), memory()
    # a wall 230 mm right of the centre line (60 mm off the right side pairs at y = -170)
    for x in range(0, 600, 40):
        beside.add((float(x), 0.0, 0.0), readings(**{f"s{RIGHT_FRONT}": 6, f"s{RIGHT_REAR}": 6}), x)
    assert beside.free_mm((0.0, 0.0, 0.0)) == math.inf
    for x in range(0, 600, 40):  # 30 mm off them: 200 mm from the centre line, inside the lane
        inside.add((float(x), 0.0, 0.0), readings(**{f"s{RIGHT_FRONT}": 3, f"s{RIGHT_REAR}": 3}), x)
    assert inside.free_mm((-400.0, 0.0, 0.0)) < 400 - MARGIN
