"""main and a motor whose drive is off: a refused move ends the navigator with the reason."""

from __future__ import annotations

import pytest

from modules.navigation.pilot import MOTOR_CODES, REASON
from tests.robot.navigation.test_main_setpos import copro_data, main_program, motor_data, sent
from tokenring import default_protocol

ENUMS = default_protocol().enums
OFF = ENUMS["motor_state"]["OFF"]


@pytest.mark.parametrize("error_handed_over", [True, False])
def test_a_move_refused_for_motors_off_ends_the_navigator(monkeypatch, error_handed_over) -> None:
    program, os, nav = main_program(monkeypatch, "ours")
    copro = copro_data(1000, 1000, 0, 5000, source=0)  # no filter: no self-localisation
    for stamp in range(5000, 5000 + 20 * 120, 120):
        motor = motor_data(1000, 1000, 0, stamp) | {"state": OFF}
        program.motor.set(motor)
        program.copro.set(copro)
        program.sensors = program._read_sensors()
        program._cooperate()
        if error_handed_over and sent(os, "MOVE_FORWARD"):
            error = {"error": ENUMS["error_code"]["MOTORS_OFF"], "about": MOTOR_CODES["MOVE_FORWARD"]}
            program.handle_command("ERROR", error)
        if program.navigator is None:
            break
    assert program.navigator is None and nav.plans == 1
    assert len(sent(os, "MOVE_FORWARD")) == 1
    assert program.finished["why"] == "failed: motors are off: MOTORS_ON first"
    assert program.abort_reason == REASON["MOTORS_OFF"]
