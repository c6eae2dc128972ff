"""main's own jobs on a drive that is off (issue 54): ``up --sensors darmstadt`` boots the motor
off, as the Darmstadt Pioneer, which answered drive commands only after "Motoren an" (seed 000
§6.7, §8.2). Explore and the calibration runs are the Hamburg robot's, whose drive has no switch:
main sends MOTORS_ON once, logged, before their first move. An action file switches the drive on
itself with its ``e``, as the seed's did: main sends none for it.

main's program runs on the fake node of ``test_main_setpos.py``: one token visit at a time, with
motor.data and copro.data as the test sets them.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

from modules import main as main_module
from modules.navigation.actions import ActionNavigator, parse_actions
from modules.navigation.pilot import Sensors
from tests.robot.navigation.test_main_setpos import (
    before_calibration,
    copro_data,
    main_program,
    motor_data,
    sent,
    visit,
)
from tokenring.contract.protocol import default_protocol

ENUMS = default_protocol().enums
OFF, IDLE = ENUMS["motor_state"]["OFF"], ENUMS["motor_state"]["IDLE"]
MOVE_FORWARD = default_protocol().nodes["motor"].command.commands["MOVE_FORWARD"].code
MOVES = ("MOVE_FORWARD", "MOVE_REVERSE", "TURN_LEFT", "TURN_RIGHT", "SET_WHEEL_SPEEDS")


def off(stamp: int) -> dict[str, Any]:
    """motor.data of a drive that is off, at rest where the robot was put down."""
    return {**motor_data(1000, 2000, 0, stamp), "state": OFF}


def idle(stamp: int) -> dict[str, Any]:
    return motor_data(1000, 2000, 0, stamp)


#: a filter too unsure to correct the motor: nothing but the job's own commands is sent
UNSURE = copro_data(1000, 2000, 0, 5000, sigma_mm=300)


def moves(os: Any) -> list[str]:
    return [name for target, name, _ in os.delivered if target == "motor" and name in MOVES]


@pytest.mark.parametrize("choice", ["ours", "seed"])
def test_a_job_of_mains_own_switches_the_drive_on_once_before_its_first_move(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture, choice: str
) -> None:
    program, os, nav = main_program(monkeypatch, choice)
    with caplog.at_level(logging.INFO, logger="tokenring.main"):
        visit(program, off(5000), UNSURE)
    assert os.delivered == [("motor", "MOTORS_ON", {})] and nav.plans == 0
    assert any("the drive is off: MOTORS_ON for Forward" in r.getMessage() for r in caplog.records)
    # samples from before the motor took it still say OFF: main waits, and sends no second one
    for stamp in (5000, 5100, 5200):
        visit(program, off(stamp), UNSURE)
    assert nav.plans == 0 and len(sent(os, "MOTORS_ON")) == 1
    visit(program, idle(5300), UNSURE)  # on: the job plans and drives
    assert nav.plans == 1 and moves(os) == ["MOVE_FORWARD"]
    assert len(sent(os, "MOTORS_ON")) == 1 and program.report()["motors_on_sent"] == 1


def test_a_drive_that_stays_off_is_left_to_the_pilot_which_ends_the_job(monkeypatch) -> None:
    """The motor never shows the drive on: after a few samples main plans all the same, the motor
    refuses the move (ERROR MOTORS_OFF) and the pilot ends the job with the reason."""
    program, os, nav = main_program(monkeypatch, "ours")
    for stamp in range(5000, 5000 + 100 * (main_module.POWER_SAMPLES + 1), 100):
        visit(program, off(stamp), UNSURE)
    assert len(sent(os, "MOTORS_ON")) == 1 and nav.plans == 1 and moves(os) == ["MOVE_FORWARD"]
    program.handle_command("ERROR", {"error": ENUMS["error_code"]["MOTORS_OFF"], "about": MOVE_FORWARD})
    visit(program, off(5600), UNSURE)
    assert program.navigator is None
    assert program.finished is not None and program.finished["why"].startswith("failed: motors are off")
    assert len(sent(os, "MOTORS_ON")) == 1


def test_a_drive_switched_off_during_the_job_is_not_switched_on_again(monkeypatch) -> None:
    """The operator's d while main's job runs: main does not override it."""
    program, os, nav = main_program(monkeypatch, "ours")
    visit(program, idle(5000), UNSURE)
    assert nav.plans == 1 and sent(os, "MOTORS_ON") == []
    program.pilot.abort("USER")  # the move ended; the operator switches the drive off
    for stamp in range(5100, 6000, 100):
        visit(program, off(stamp), UNSURE)
    assert sent(os, "MOTORS_ON") == []


@pytest.mark.parametrize(("text", "switched"), [("s 300\n", 0), ("e\ns 300\n", 1)])
def test_an_action_file_switches_the_drive_on_itself_or_not_at_all(
    monkeypatch: pytest.MonkeyPatch, text: str, switched: int
) -> None:
    """No hidden MOTORS_ON for an action file: its own e sends one (the seed's files began so)."""
    program, os, _ = main_program(monkeypatch, "ours")
    program.start(ActionNavigator(program.layout, parse_actions(text, "a.act"), speed_pct=50), 1)
    for stamp in range(5000, 5400, 100):
        visit(program, off(stamp), UNSURE)
    assert len(sent(os, "MOTORS_ON")) == switched
    assert program.report()["motors_on_sent"] == 0


def test_explore_from_the_lcd_or_the_pc_switches_the_drive_on_first(monkeypatch) -> None:
    program, os, _ = main_program(monkeypatch, "ours")
    program.stop_explore("test")
    os.delivered.clear()
    program.handle_command("EXPLORE", {"mode": 1})
    visit(program, off(5000), UNSURE)
    assert os.delivered == [("motor", "MOTORS_ON", {})]
    visit(program, idle(5100), UNSURE)
    assert moves(os), os.delivered  # Explore 1 drives once the drive is on


def test_a_robot_standing_with_its_drive_off_is_at_rest_for_the_calibration_heading() -> None:
    """The heading an action file squares up to after the compass's turn is noted at rest: a
    drive that is off stands as well as an idle one."""
    main = before_calibration()
    main.sensors = Sensors(pose=(1000.0, 1000.0, 0.3), pose_filtered=True, motor_state=OFF)
    main_module.Program._note_calibration_turn(main)
    assert main.rest_heading == 0.3
