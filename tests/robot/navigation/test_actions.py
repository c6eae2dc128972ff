"""Action files: the seed's syntax, clear errors, the step plan with closed-loop turns, main's navigator."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from modules.mapping.vectorgen import default_layout
from modules.navigation.actions import (
    WAIT,
    ActionNavigator,
    ActionPlan,
    Drive,
    MotorsOn,
    Wheels,
    circle_speeds,
    load_actions,
    parse_actions,
)
from modules.navigation.pilot import FORWARD, REASON, REVERSE, TURN_LEFT, TURN_RIGHT, Outcome, Sensors
from tokenring.errors import UsageError

SQUARE = """\
# the Darmstadt test drive: a 3 m square, counter-clockwise
e
s 3000
r 90   # left
s 3000
r 90
"""


def test_parse_the_seed_syntax() -> None:
    actions = parse_actions(SQUARE + "v 50 -50 2000\nc 500 40 10000\ns -200\n", "square.act")
    assert [a.kind for a in actions] == ["e", "s", "r", "s", "r", "v", "c", "s"]
    assert actions[1].args == (3000.0,) and actions[1].line == 3
    assert actions[2].text == "r 90"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x 10\n", "a.act:1: unknown action 'x'"),
        ("s\n", "a.act:1: 's' takes 1 values: s <mm>"),
        ("\n\nr 90 5\n", "a.act:3: 'r' takes 1 values"),
        ("v 50 50\n", "give the time"),
        ("s ten\n", "a.act:1: s <mm>: values must be numbers"),
        ("s 0\n", "a straight move is 1..65535 mm"),
        ("s 70000\n", "a straight move is 1..65535 mm"),
        ("r 0\n", "a turn is up to 3600 degrees"),
        ("v 150 0 1000\n", "track speeds are at most 100 mm/s"),
        ("v 0 0 1000\n", "nothing would move"),
        ("v 10 10 0\n", "the time must be positive"),
        ("c 0 50 1000\n", "radius cannot be 0"),
        ("c 100 90 1000\n", "needs a track at"),
        ("s nan\n", "finite"),
    ],
)
def test_errors_name_file_and_line(text: str, message: str) -> None:
    with pytest.raises(UsageError) as info:
        parse_actions(text, "a.act")
    assert message in str(info.value)
    assert info.value.exit_code == 2


def test_load_from_file(tmp_path: Path) -> None:
    path = tmp_path / "square.act"
    path.write_text(SQUARE)
    assert len(load_actions(path)) == 5
    with pytest.raises(UsageError, match="no such action file"):
        load_actions(tmp_path / "missing.act")


def test_circle_speeds_follow_the_track_geometry() -> None:
    left, right = circle_speeds(1000.0, 50.0)
    assert right > 50.0 > left
    assert (right - left) / 2 / 50.0 == pytest.approx(201.8 / 1000.0, rel=1e-3)
    assert circle_speeds(-1000.0, 50.0) == pytest.approx((right, left))


def test_plan_closes_the_loop_on_turns_with_the_fused_heading() -> None:
    plan = ActionPlan(parse_actions(SQUARE), speed_pct=60, turn_tolerance_deg=0.6, settle_ms=300)
    heading = 0.0
    assert plan.next(heading, 0) == MotorsOn("line 2: e")
    assert plan.next(heading, 0) == Drive("forward", 3000, 60, "line 3: s 3000")
    assert plan.next(heading, 100) == Drive("left", 90, 60, "line 4: r 90")
    heading = math.radians(84.0)  # the floor slipped: 6° short
    assert plan.next(heading, 200) == WAIT  # let the filter settle first
    step = plan.next(heading, 600)
    assert isinstance(step, Drive) and step.direction == "left" and step.amount == 6
    heading = math.radians(90.3)
    assert plan.next(heading, 700) == WAIT
    assert plan.next(heading, 1100).direction == "forward"  # within tolerance: next action
    step = plan.next(heading, 1200)
    assert step.direction == "left" and step.amount == 90
    # the target chains: 180°, not heading + 90 = 180.3°
    heading = math.radians(181.4)
    plan.next(heading, 1300)
    correction = plan.next(heading, 1700)
    assert correction.direction == "right" and correction.amount == 1
    heading = math.radians(180.2)
    assert plan.next(heading, 1800) == WAIT
    assert plan.next(heading, 2200) is None
    assert plan.finished and plan.progress()["corrections"] == 2


def test_plan_squares_up_to_the_heading_before_the_calibration_turn() -> None:
    """The compass's 360° calibration turn ended 11° short: the first leg would run 11° off
    (the 158 mm run of issue 21); the plan turns back to where the robot faced first."""
    before = math.radians(30.0)
    plan = ActionPlan(parse_actions(SQUARE), speed_pct=60, settle_ms=300, start_heading=before)
    heading = math.radians(19.0)
    assert plan.next(heading, 0) == WAIT  # settle at rest first, as after an ``r``
    step = plan.next(heading, 400)
    assert step.direction == "left" and step.amount == 11
    heading = math.radians(30.2)
    assert plan.next(heading, 500) == WAIT
    assert plan.next(heading, 900) == MotorsOn("line 2: e")
    assert plan.next(heading, 900) == Drive("forward", 3000, 60, "line 3: s 3000")
    # the first ``r 90`` aims at 120°, the start heading plus 90, not wherever the turn ended
    assert plan.next(heading, 1000).amount == 90
    plan.next(math.radians(118.0), 1100)
    assert plan.next(math.radians(118.0), 1500) == Drive("left", 2, 60, "correct +2.0°")


def test_plan_without_heading_is_open_loop_and_wheels_wait_for_their_time() -> None:
    plan = ActionPlan(parse_actions("r -45\nv 50 -50 70000\n"), speed_pct=50)
    assert plan.next(None, 0) == Drive("right", 45, 50, "line 1: r -45")
    first = plan.next(None, 100)
    assert first == Wheels(50, -50, 60000, "line 2: v 50 -50 70000")
    assert plan.next(None, 30000, motor_idle=False) == WAIT
    assert plan.next(None, 60100, motor_idle=False) == WAIT  # the motor still runs
    second = plan.next(None, 60150, motor_idle=True)
    assert second.duration_ms == 10000
    assert plan.next(None, 70150) is None


def test_navigator_drives_the_pilot_and_stops_on_an_abort() -> None:
    nav = ActionNavigator(default_layout(), parse_actions(SQUARE), speed_pct=40)
    sensors = Sensors(pose=(1000.0, 1000.0, 0.0), stamp_ms=0, motor_state=0)
    assert nav.plan(None, sensors, 0) == [] and nav.commands == [("motor", "MOTORS_ON", {})]  # e
    (move,) = nav.plan(None, sensors, 0)
    assert (move.direction, move.amount, move.speed_pct) == (FORWARD, 3000, 40)
    (turn,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert (turn.direction, turn.amount) == (TURN_LEFT, 90)
    sensors.pose = (4000.0, 1000.0, math.radians(90.2))
    assert nav.plan(Outcome(REASON["DONE"]), sensors, 0) == []  # settling
    sensors.stamp_ms = nav.plan_steps.settle_ms
    (move,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert move.direction == FORWARD
    assert nav.plan(Outcome(REASON["COLLISION"], trigger="motor"), sensors, 0) is None
    assert "aborted: COLLISION" in nav.note


def test_navigator_resumes_after_a_spurious_alert() -> None:
    """A stray 0 cm echo stops the pilot with ALERT: escape as the lock allows, then finish the drive."""
    nav = ActionNavigator(default_layout(), parse_actions("s 1000\nr 90\n"), speed_pct=50)
    sensors = Sensors(pose=(1000.0, 1000.0, 0.0), stamp_ms=0, motor_state=0)
    (drive,) = nav.plan(None, sensors, 0)
    assert drive.amount == 1000
    alert = Outcome(REASON["ALERT"], drive, driven_mm=400, trigger="alert on sonar [1]")
    (escape,) = nav.plan(alert, sensors, REVERSE)  # the lock allows only the opposite direction
    assert (escape.direction, escape.amount) == (REVERSE, 60)
    (rest,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert (rest.direction, rest.amount) == (FORWARD, 660)  # 1000 - 400 + the 60 backed off
    (turn,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert (turn.direction, turn.amount) == (TURN_LEFT, 90)
    # the turn is cut short at 32°: a 15° escape to the right, then the closed loop turns the rest
    alert = Outcome(REASON["ALERT"], turn, driven_mm=round(32 * nav.TURN_MM_PER_DEG))
    (escape,) = nav.plan(alert, sensors, TURN_RIGHT)
    assert (escape.direction, escape.amount) == (TURN_RIGHT, 15)
    sensors.pose = (2000.0, 1000.0, math.radians(17.0))
    assert nav.plan(Outcome(REASON["DONE"]), sensors, 0) == []  # settle
    sensors.stamp_ms = nav.plan_steps.settle_ms
    (rest,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert (rest.direction, rest.amount) == (TURN_LEFT, 73)
    assert nav.retries == 2
    for _ in range(nav.MAX_RETRIES - 2):
        nav.plan(Outcome(REASON["TIMEOUT"], rest), sensors, 0)
    assert nav.plan(Outcome(REASON["TIMEOUT"], rest), sensors, 0) is None
    assert "aborted: TIMEOUT" in nav.note


def test_navigator_sends_wheel_speeds_through_main() -> None:
    nav = ActionNavigator(default_layout(), parse_actions("c 1000 50 4000\n"))
    sensors = Sensors(stamp_ms=0, motor_state=0)
    assert nav.plan(None, sensors, 0) == []
    ((target, command, args),) = nav.commands
    assert (target, command) == ("motor", "SET_WHEEL_SPEEDS")
    assert args["duration_ms"] == 4000 and args["right_pct"] > args["left_pct"] > 0
    nav.commands.clear()
    sensors.stamp_ms = 4100
    assert nav.plan(Outcome(REASON["DONE"]), sensors, 0) is None
    assert nav.note == "action file done"
