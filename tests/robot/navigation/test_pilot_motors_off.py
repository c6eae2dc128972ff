"""The pilot and a motor whose drive is off (issue 54): a refused move, or one a MOTORS_OFF ended
under way, ends the sequence with abort reason MOTORS_OFF and a readable trigger; nothing is
retried. Synthetic sensor data, the scripted motor of ``test_navigator.py``."""

from __future__ import annotations

from modules.navigation.actions import ActionNavigator, parse_actions
from modules.navigation.pilot import (
    FORWARD,
    MOTOR_CODES,
    MOTOR_STATE,
    MOTORS_OFF_TRIGGER,
    MOVE_STATUS,
    REASON,
    TURN_LEFT,
    Move,
    Sensors,
)
from tests.robot.navigation.test_navigator import LAYOUT, Bench
from tokenring import default_protocol

ERROR_CODE = default_protocol().enums["error_code"]
OFF = MOTOR_STATE["OFF"]
SEQUENCE = [Move(FORWARD, 500, 80, scan=True), Move(TURN_LEFT, 90, 50)]


def off_bench() -> Bench:
    b = Bench()
    b.sensors.motor_state = OFF
    b.sensors.move_seq = 7
    return b


def test_a_move_refused_with_error_motors_off_ends_the_sequence_at_once():
    b = off_bench()
    b.pilot.start(SEQUENCE, b.sensors)
    assert b.names() == ["copro:START_SCAN", "motor:MOVE_FORWARD"]
    b.pilot.note_error(ERROR_CODE["MOTORS_OFF"], MOTOR_CODES["MOVE_FORWARD"])
    out = b.tick()
    assert out is not None and out.reason == REASON["MOTORS_OFF"] and out.reason_name == "MOTORS_OFF"
    assert out.trigger == MOTORS_OFF_TRIGGER == "motors are off: MOTORS_ON first"
    assert out.index == 0 and out.move == SEQUENCE[0]
    # no STOP for a move that never ran, no turn after it; the scan is ended
    assert b.names() == ["copro:START_SCAN", "motor:MOVE_FORWARD", "copro:STOP_SCAN"]
    assert not b.pilot.busy


def test_other_errors_do_not_end_the_move():
    b = Bench()
    b.pilot.start(SEQUENCE[:1], b.sensors)
    b.pilot.note_error(ERROR_CODE["MAP_FULL"], 202)  # the map's, about a VECTOR
    b.pilot.note_error(ERROR_CODE["MOTORS_OFF"], MOTOR_CODES["SET_WHEEL_SPEEDS"])  # not our move
    assert b.tick() is None and b.pilot.busy


def test_without_the_error_off_on_several_samples_after_the_send_is_a_refusal():
    """main may not hand the ERROR over: motor.data's state says it, once no sample seen can
    predate the motor taking the command."""
    b = off_bench()
    b.pilot.start(SEQUENCE, b.sensors)
    for _ in range(b.pilot.settings.off_samples - 1):
        assert b.tick() is None
    for _ in range(3):  # visits with no new motor sample (the same stamp) do not count
        assert b.pilot.step(b.sensors) is None
    out = b.tick()
    assert out is not None and out.reason == REASON["MOTORS_OFF"] and out.trigger == MOTORS_OFF_TRIGGER
    assert [n for n in b.names() if n.startswith("motor:")] == ["motor:MOVE_FORWARD"]


def test_an_off_that_predates_motors_on_is_not_a_refusal():
    """An action file's ``e`` and then a move: motor.data may still say OFF when the move is sent."""
    b = off_bench()
    b.pilot.start(SEQUENCE[:1], b.sensors)
    assert b.tick(2) is None
    b.motor_runs(8)
    assert b.tick(3) is None
    b.pilot.note_position_reached(MOVE_STATUS["DONE"], 8)
    b.sensors.motor_state = MOTOR_STATE["IDLE"]
    out = b.tick()
    assert out is not None and out.done


def test_motors_off_under_way_ends_the_sequence_not_as_done():
    b = Bench()
    b.pilot.start(SEQUENCE, b.sensors)
    b.motor_runs(1)
    assert b.tick(3, distance_mm=150) is None
    b.pilot.note_position_reached(MOVE_STATUS["ABORTED"], 1)  # as for STOP
    out = b.tick(motor_state=OFF)
    assert out is not None and out.reason == REASON["MOTORS_OFF"] and out.driven_mm == 150
    assert "motor:TURN_LEFT" not in b.names() and "motor:STOP" not in b.names()


def test_an_action_file_ends_on_motors_off_with_the_reason():
    nav = ActionNavigator(LAYOUT, parse_actions("s 500\nr 90\n"), closed_loop=False)
    sensors = Sensors(stamp_ms=0, motor_state=OFF)
    (move,) = nav.plan(None, sensors, 0)
    b = off_bench()
    b.pilot.start([move], b.sensors)
    b.pilot.note_error(ERROR_CODE["MOTORS_OFF"], MOTOR_CODES["MOVE_FORWARD"])
    out = b.tick()
    assert nav.plan(out, sensors, 0) is None
    assert nav.note == "action file aborted: MOTORS_OFF (motors are off: MOTORS_ON first)"
