"""The pilot keeps straight moves clear of what the sonars have shown (issue 57): a move is
commanded no farther than the free way, one whose way closes while it runs is stopped, and both
say so (CLOSE, trigger ``clearance``) so the navigator treats the way as blocked.

The judge is geometry worked out here from the robot's outline (the collision circle, the ALERT
area), not the clearance code's own arithmetic: bounds the commanded distance must keep."""

from __future__ import annotations

import math

from modules.mapping.vectorgen import default_layout
from modules.navigation.pilot import (
    FORWARD,
    MOTOR_STATE,
    MOVE_STATUS,
    REASON,
    REVERSE,
    TURN_LEFT,
    Move,
    Pilot,
    SeedPilot,
    Sensors,
)
from tests.robot.navigation.test_navigator import Bench as PilotBench

LAYOUT = default_layout()
FAR = 255
BODY_MM = 190.0  # the simulator's collision circle
NOSE_MM = 188.0  # the front sonar's distance from the centre
ALERT_MM = 40.0  # the ALERT area: a sonar under 4 cm


def reading(**by_name: int) -> list[int]:
    names = {
        "front": LAYOUT.front[1],
        "rear": LAYOUT.rear[0],
        "left": LAYOUT.left_front,
        "right": LAYOUT.right_front,
    }
    out = [FAR] * 8
    for name, cm in by_name.items():
        out[names[name]] = cm
    return out


class Bench(PilotBench):
    """A pilot at a pose with a scripted motor; every tick is a new sweep 120 ms on."""

    def __init__(self, pilot_class: type[Pilot] = Pilot, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        super().__init__()
        self.pilot = pilot_class(LAYOUT, self.send)
        self.sensors = Sensors(distances=[FAR] * 8, pose=pose)

    def motor_commands(self) -> list[tuple[str, dict]]:
        return [(n, a) for t, n, a in self.sent if t == "motor"]

    def drive_to(self, x_mm: float, driven_mm: int, **changes):
        """The motor has taken the move and carried the robot to ``x_mm`` (heading 0)."""
        self.sensors.motor_state, self.sensors.move_seq = MOTOR_STATE["MOVING"], 1
        self.sensors.distance_mm = driven_mm
        self.sensors.pose = (x_mm, 0.0, self.sensors.pose[2])
        return self.tick(**changes)


def test_a_move_toward_a_wall_seen_ahead_is_commanded_only_up_to_the_margin_and_says_why():
    b = Bench()
    wall_mm = NOSE_MM + 700
    b.tick(2, distances=reading(front=70))  # a wall 700 mm in front of the nose
    b.pilot.start([Move(FORWARD, 3000, label="find")], b.sensors)
    name, args = b.motor_commands()[-1]
    assert name == "MOVE_FORWARD"
    # the body stops outside the ALERT area, and not needlessly far from it
    commanded = args["distance_mm"]
    assert wall_mm - BODY_MM - 150 <= commanded <= wall_mm - BODY_MM - ALERT_MM
    # the motor goes the capped distance by itself, the sonar reading the wall all the way
    for x in range(0, commanded + 1, 12):
        b.drive_to(float(x), x, distances=reading(front=round((wall_mm - NOSE_MM - x) / 10)))
        assert b.motor_commands()[-1][0] == "MOVE_FORWARD"  # no STOP needed: it stops there
    b.pilot.note_position_reached(MOVE_STATUS["DONE"], 1)
    b.sensors.motor_state = MOTOR_STATE["IDLE"]
    out = b.tick(3)
    # the outcome says the way is blocked
    assert out is not None and out.reason == REASON["CLOSE"] and out.trigger == "clearance"


def test_an_edge_seen_from_the_side_stops_a_move_that_no_sonar_sees_it_in_the_way_of():
    """A partition's bare end met edge-on returns no echo to the front sonars; seen from the side
    while passing, it is remembered and keeps the body off."""
    b = Bench(pose=(0.0, 0.0, math.pi / 2))  # heading +y, the partition's end on the left
    b.tick(2, distances=reading(left=40))  # left-front sonar: an echo 40 cm to the left
    b.tick(1, pose=(0.0, 0.0, 0.0), distances=[FAR] * 8)  # turned to +x: nothing ahead now
    # the echo lies at about x = -(side sonar's offset + 400) … it is behind: forward is free
    b.pilot.start([Move(FORWARD, 500, label="goto")], b.sensors)
    assert b.motor_commands()[-1] == ("MOVE_FORWARD", {"distance_mm": 500, "speed_pct": 100})
    b2 = Bench(pose=(0.0, 0.0, 0.0))
    b2.tick(2, distances=reading(left=40))  # the end on the left, heading +x
    b2.tick(1, pose=(0.0, 0.0, math.pi / 2), distances=[FAR] * 8)  # turned left toward it
    b2.pilot.start([Move(FORWARD, 1500, label="goto")], b2.sensors)
    name, args = b2.motor_commands()[-1]
    edge_mm = 188.0 + 400  # the side sonar's reach from the centre, about
    assert name == "MOVE_FORWARD" and args["distance_mm"] <= edge_mm - BODY_MM - ALERT_MM


def test_a_move_with_no_free_way_is_not_sent_and_ends_blocked():
    b = Bench()
    b.tick(2, distances=reading(front=8))  # 8 cm: inside the margin already
    assert b.pilot.start([Move(FORWARD, 600, label="follow")], b.sensors)
    out = b.tick()
    assert out is not None and out.reason == REASON["CLOSE"] and out.trigger == "clearance"
    assert not b.motor_commands()


def test_a_wall_that_appears_while_a_move_runs_stops_it_before_the_alert_area():
    b = Bench()
    b.pilot.start([Move(FORWARD, 3000, label="find")], b.sensors)
    assert b.motor_commands()[-1][1]["distance_mm"] == 3000  # nothing seen: as asked
    for x in range(0, 1200, 12):  # 100 mm/s: 12 mm a sweep
        # an obstacle at x = 1400 that no sweep showed until the nose was 700 mm from it
        if x >= 1400 - NOSE_MM - 700:
            b.sensors.distances = reading(front=round((1400 - NOSE_MM - x) / 10))
        b.drive_to(float(x), x)
        if b.motor_commands()[-1][0] == "STOP":
            break
    assert b.motor_commands()[-1][0] == "STOP"
    stopped_at = b.sensors.pose[0]
    # stopped with its reaction to spare: the body still out of the ALERT area
    assert 1400 - stopped_at - BODY_MM > ALERT_MM + b.pilot.stopping_mm(Move(FORWARD, 1), b.sensors) - 20
    b.sensors.motor_state = MOTOR_STATE["IDLE"]
    out = b.tick(3)
    assert out is not None and out.reason == REASON["CLOSE"] and out.trigger == "clearance"


def test_the_stopping_distance_follows_the_measured_reaction():
    quick, slow = Bench(), Bench()
    quick.tick(8)
    for _ in range(8):  # a ring four times slower: the pilot sees every third sweep
        slow.sensors.sweep += 3
        slow.sensors.stamp_ms += 360
        slow.pilot.step(slow.sensors)
    move = Move(FORWARD, 600)
    assert slow.pilot.stopping_mm(move, slow.sensors) > quick.pilot.stopping_mm(move, quick.sensors) + 40
    half = Move(FORWARD, 600, speed_pct=50)
    assert slow.pilot.stopping_mm(half, slow.sensors) < slow.pilot.stopping_mm(move, slow.sensors)
    # a pause while no navigator stepped the pilot (30 s) is no ring latency
    paused = Bench()
    paused.tick(8)
    paused.sensors.stamp_ms += 30_000
    paused.tick(8)
    assert paused.pilot.stopping_mm(move, paused.sensors) == quick.pilot.stopping_mm(move, quick.sensors)


def test_reverse_moves_look_behind_turns_are_never_capped_and_escapes_are_exempt():
    b = Bench()
    b.tick(2, distances=reading(rear=30))
    b.pilot.start([Move(REVERSE, 800, label="back")], b.sensors)
    assert b.motor_commands()[-1][1]["distance_mm"] <= NOSE_MM + 300 - BODY_MM - ALERT_MM
    b = Bench()
    b.tick(2, distances=reading(front=10))
    b.pilot.start([Move(TURN_LEFT, 90, label="turn")], b.sensors)
    assert b.motor_commands()[-1] == ("TURN_LEFT", {"angle_deg": 90, "speed_pct": 100})
    b = Bench()
    b.tick(2, distances=reading(rear=10))
    b.pilot.alert_lock = REVERSE  # a nose ALERT: the lock allows only the way back
    b.pilot.start([Move(REVERSE, 50, label="escape back")], b.sensors)
    assert b.motor_commands()[-1] == ("MOVE_REVERSE", {"distance_mm": 50, "speed_pct": 100})


def test_the_seed_pilot_keeps_no_clearance():
    b = Bench(SeedPilot)
    b.tick(2, distances=reading(front=30))
    b.pilot.start([Move(FORWARD, 3000, label="drive")], b.sensors)
    assert b.motor_commands()[-1] == ("MOVE_FORWARD", {"distance_mm": 3000, "speed_pct": 100})
