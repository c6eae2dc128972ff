"""main's self-localisation corrects the motor (issue 20; seed 001 §4.3 item 5, §4.3.3).

Between moves, with copro's filter confident and motor.data off by more than the threshold, main
sends one SET_GLOBAL_POSITION with the filtered pose; mid-move or with an unconfident filter it
sends none. Expected poses are written out here from the wire conventions (mm, 1/100 degree
clockwise), not computed with the code under test.
"""

from __future__ import annotations

from typing import Any

import pytest

from modules import main as main_module
from modules.localization.pose_correction import ENV as SETPOS_ENV
from modules.localization.pose_correction import CorrectionSettings, PoseCorrector
from modules.localization.sync import OdometryParams, OdometrySync, OdometryTrack, Sample
from modules.mapping.vectorgen import default_layout
from modules.navigation.navigator import Navigator
from modules.navigation.pilot import FORWARD, Move, Outcome, Sensors
from modules.variants import ENV as ALGORITHMS_ENV
from tests.support.fakenode import FakeOS
from tokenring.contract.protocol import default_protocol

ENUMS = default_protocol().enums
IDLE, MOVING = ENUMS["motor_state"]["IDLE"], ENUMS["motor_state"]["MOVING"]
STOPPED = ENUMS["direction"]["STOPPED"]


def motor_data(x: int, y: int, cdeg: int, stamp: int, moving: bool = False) -> dict[str, Any]:
    return {
        "x_mm": x,
        "y_mm": y,
        "angle_cdeg": cdeg,
        "direction": FORWARD if moving else STOPPED,
        "speed_pct": 50 if moving else 0,
        "distance_mm": 0,
        "steps_left": 0,
        "steps_right": 0,
        "stamp_ms": stamp,
        "move_seq": 1,
        "state": MOVING if moving else IDLE,
        "glide_cfactor": 650,
    }


def copro_data(
    x: int, y: int, cdeg: int, stamp: int, sigma_mm: int = 20, sigma_cdeg: int = 100, source: int = 2
) -> dict[str, Any]:
    return {
        "left_contact": 0,
        "right_contact": 0,
        "pose_x_mm": x,
        "pose_y_mm": y,
        "pose_angle_cdeg": cdeg,
        "pose_valid": 7,
        "pose_source": source,
        "pose_stamp_ms": stamp,
        "sigma_x_mm": sigma_mm,
        "sigma_y_mm": sigma_mm,
        "sigma_angle_cdeg": sigma_cdeg,
        "flushes_done": 0,
    }


# -- the decision, on its own ------------------------------------------------------------------


def test_at_rest_far_off_and_confident_one_correction_with_the_filtered_pose() -> None:
    corrector = PoseCorrector()
    motor = motor_data(1000, 2000, 9000, stamp=5000)
    copro = copro_data(1150, 1940, 9450, stamp=5000)  # 162 mm and 4.5° away from the motor
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) == {"x_mm": 1150, "y_mm": 1940, "angle_cdeg": 9450}
    assert corrector.holding
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is None  # once: the first is still under way


def test_heading_alone_off_is_corrected_across_north() -> None:
    corrector = PoseCorrector()
    motor = motor_data(0, 0, 35900, stamp=100)  # 359°
    copro = copro_data(0, 0, 350, stamp=100)  # 3.5°: 4.5° away across 0
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) == {"x_mm": 0, "y_mm": 0, "angle_cdeg": 350}


@pytest.mark.parametrize(
    "copro",
    [
        copro_data(1150, 1940, 9450, 5000, sigma_mm=200),  # x and y not known well
        copro_data(1150, 1940, 9450, 5000, sigma_cdeg=800),  # 8°: the heading not known well
        copro_data(1150, 1940, 9450, 5000, sigma_mm=0, sigma_cdeg=0),  # no sigmas: no filter
        copro_data(1150, 1940, 9450, 5000, sigma_mm=0, sigma_cdeg=0, source=1),  # dead reckoning
        {**copro_data(1150, 1940, 9450, 5000), "pose_valid": 0b011},  # the angle not valid
    ],
    ids=["sigma-xy", "sigma-angle", "no-sigmas", "dead-reckoning", "angle-invalid"],
)
def test_unconfident_filter_no_correction(copro: dict[str, Any]) -> None:
    corrector = PoseCorrector()
    motor = motor_data(1000, 2000, 9000, stamp=5000)
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is None
    assert not corrector.holding


def test_mid_move_no_correction() -> None:
    corrector = PoseCorrector()
    motor = motor_data(1000, 2000, 9000, stamp=5000, moving=True)
    copro = copro_data(1150, 1940, 9450, stamp=5000)
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is None
    stopping = {**motor, "direction": STOPPED}  # state still MOVING: not at rest yet
    assert corrector.correction(stopping, copro) is None


def test_small_offset_no_correction() -> None:
    corrector = PoseCorrector()
    motor = motor_data(1000, 2000, 9000, stamp=5000)
    copro = copro_data(1030, 1980, 9250, stamp=5000)  # 36 mm, 2.5°: within the thresholds
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is None


def test_switched_off_by_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(SETPOS_ENV, "off")
    corrector = PoseCorrector(CorrectionSettings.from_env())
    motor = motor_data(1000, 2000, 9000, stamp=5000)
    copro = copro_data(1500, 2000, 9000, stamp=5000)
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is None


def test_lagging_filter_pose_is_carried_over_the_motion_since() -> None:
    """The filter's pose is 200 ms old; since then the motor drove 100 mm straight along +X
    (its heading 0). In the filter's frame (heading 90° CCW = 27000 clockwise) that is 100 mm
    along +Y: the correction is the filter's pose moved there."""
    corrector = PoseCorrector()
    copro = copro_data(500, 800, 27000, stamp=1000)
    for stamp, x in ((1000, 0), (1100, 50), (1200, 100)):
        corrector.observe(motor_data(x, 0, 0, stamp, moving=stamp < 1200), copro)
    got = corrector.correction(motor_data(100, 0, 0, 1200), copro)
    assert got == {"x_mm": 500, "y_mm": 900, "angle_cdeg": 27000}


def test_filter_older_than_main_knows_no_correction() -> None:
    corrector = PoseCorrector()
    copro = copro_data(1500, 2000, 9000, stamp=100)
    corrector.observe(motor_data(1000, 2000, 9000, 5000), copro)  # main's history starts at 5000
    assert corrector.correction(motor_data(1000, 2000, 9000, 5000), copro) is None


def test_holds_until_motor_then_filter_show_the_correction() -> None:
    corrector = PoseCorrector()
    old = motor_data(1000, 2000, 9000, stamp=5000)
    copro = copro_data(1150, 1940, 9450, stamp=5000)
    corrector.observe(old, copro)
    assert corrector.correction(old, copro) is not None
    corrector.observe(motor_data(1000, 2000, 9000, 5100), copro)  # not taken yet
    assert corrector.holding
    jumped = motor_data(1150, 1940, 9450, 5200)
    corrector.observe(jumped, copro)  # the motor shows it; the filter last synced at 5000
    assert corrector.holding
    corrector.observe(motor_data(1150, 1940, 9450, 5300), copro_data(1150, 1940, 9450, 5250))
    assert not corrector.holding
    # after it, the jump is not motion to carry the filter's pose over: nothing more to correct
    later = motor_data(1150, 1940, 9450, 5400)
    copro_later = copro_data(1150, 1940, 9450, 5300)
    corrector.observe(later, copro_later)
    assert corrector.correction(later, copro_later) is None
    assert corrector.sent == 1


def test_lost_correction_released_after_the_timeout() -> None:
    corrector = PoseCorrector(CorrectionSettings(timeout_ms=1000))
    motor = motor_data(1000, 2000, 9000, stamp=5000)
    copro = copro_data(1150, 1940, 9450, stamp=5000)
    corrector.observe(motor, copro)
    assert corrector.correction(motor, copro) is not None
    corrector.observe(motor_data(1000, 2000, 9000, 5900), copro)
    assert corrector.holding
    corrector.observe(motor_data(1000, 2000, 9000, 6100), copro)
    assert not corrector.holding and corrector.gave_up == 1


def test_after_a_timeout_the_jump_is_not_carried_into_a_new_correction() -> None:
    """The motor took the correction but the filter's stamp stayed behind it until the timeout:
    main's history starts at the jump, so the old filter pose is not carried across it."""
    corrector = PoseCorrector(CorrectionSettings(timeout_ms=1000))
    copro = copro_data(1150, 1940, 9450, stamp=5000)
    corrector.observe(motor_data(1000, 2000, 9000, 5000), copro)
    assert corrector.correction(motor_data(1000, 2000, 9000, 5000), copro) is not None
    corrector.observe(motor_data(1150, 1940, 9450, 5100), copro)
    corrector.observe(motor_data(1150, 1940, 9450, 6200), copro)
    assert not corrector.holding and corrector.gave_up == 1
    assert corrector.correction(motor_data(1150, 1940, 9450, 6200), copro) is None


def test_the_jump_is_no_motion_for_the_filters_odometry() -> None:
    """The filter integrates the step counters: SET_GLOBAL_POSITION moves x/y/angle on
    motor.data, not the counters, so the jump adds no increment."""
    sync = OdometrySync(OdometryTrack(OdometryParams()), baseline=None)
    before = Sample("odometry", 1000, {"steps_left": 400, "steps_right": 400, "x_mm": 0, "y_mm": 0})
    jumped = Sample("odometry", 1100, {"steps_left": 400, "steps_right": 400, "x_mm": 900, "y_mm": -300})
    sync.synchronise([before], 1000)
    result = sync.synchronise([jumped], 1100)
    assert (result["dl"], result["dr"]) == (0, 0)
    assert sync.pose == (0.0, 0.0, 0.0)


# -- main's program: when it sends ------------------------------------------------------------


class Forward(Navigator):
    """A navigator that plans one forward move each time it is asked (and counts the asks)."""

    def __init__(self) -> None:
        super().__init__(default_layout())
        self.plans = 0

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.plans += 1
        return [Move(FORWARD, 300, speed_pct=50)]


def main_program(monkeypatch: pytest.MonkeyPatch, choice: str) -> tuple[Any, FakeOS, Forward]:
    monkeypatch.setenv(ALGORITHMS_ENV, f"main={choice}")
    monkeypatch.delenv(SETPOS_ENV, raising=False)
    os = FakeOS()
    program = main_module.Program(os)
    program.setup()
    assert program.seed == (choice == "seed")
    sonar = os.buffers["sonar.data"]
    sonar.set({"distances": [200] * 8, "sweep": 1, "stamp_ms": 5000})
    os.buffers["compass.data"].set({"heading_cdeg": 0, "state": 0, "stamp_ms": 5000})
    nav = Forward()
    program.start(nav, 1)
    return program, os, nav


def visit(program: Any, motor: dict[str, Any], copro: dict[str, Any]) -> None:
    """One token visit as main's loop runs it (the parts that matter here)."""
    program.motor.set(motor)
    program.copro.set(copro)
    program.sensors = program._read_sensors()
    program._observe_poses()
    program._cooperate()


def sent(os: FakeOS, command: str) -> list[dict[str, Any]]:
    return [args for _, name, args in os.delivered if name == command]


@pytest.mark.parametrize("choice", ["ours", "seed"])
def test_main_stopped_and_off_sends_one_set_global_position_then_plans(
    monkeypatch: pytest.MonkeyPatch, choice: str
) -> None:
    program, os, nav = main_program(monkeypatch, choice)
    copro = copro_data(1150, 1940, 9450, stamp=5000)
    visit(program, motor_data(1000, 2000, 9000, 5000), copro)
    assert sent(os, "SET_GLOBAL_POSITION") == [{"x_mm": 1150, "y_mm": 1940, "angle_cdeg": 9450}]
    assert [t for t, _, _ in os.delivered] == ["motor"]
    assert nav.plans == 0  # held: no move before the motor and the filter show the new pose
    visit(program, motor_data(1150, 1940, 9450, 5100), copro)  # the motor took it
    assert nav.plans == 0
    visit(program, motor_data(1150, 1940, 9450, 5200), copro_data(1150, 1940, 9450, stamp=5150))
    assert nav.plans == 1
    assert len(sent(os, "SET_GLOBAL_POSITION")) == 1
    assert sent(os, "MOVE_FORWARD"), os.delivered
    # the move under way: a filter far from the motor again sends nothing mid-move
    visit(program, motor_data(1200, 1940, 9450, 5400, moving=True), copro_data(1400, 1700, 9900, 5400))
    assert len(sent(os, "SET_GLOBAL_POSITION")) == 1


@pytest.mark.parametrize("choice", ["ours", "seed"])
def test_main_unconfident_filter_sends_nothing_and_plans_at_once(
    monkeypatch: pytest.MonkeyPatch, choice: str
) -> None:
    program, os, nav = main_program(monkeypatch, choice)
    visit(program, motor_data(1000, 2000, 9000, 5000), copro_data(1150, 1940, 9450, 5000, sigma_mm=300))
    assert sent(os, "SET_GLOBAL_POSITION") == []
    assert nav.plans == 1 and sent(os, "MOVE_FORWARD")


@pytest.mark.parametrize("choice", ["ours", "seed"])
def test_main_pilot_busy_sends_nothing(monkeypatch: pytest.MonkeyPatch, choice: str) -> None:
    """The motor reports rest for a moment after the move was sent (it has not started it yet):
    the pilot is busy, so main does not correct — the seed's motor would abort the move."""
    program, os, nav = main_program(monkeypatch, choice)
    visit(program, motor_data(1000, 2000, 9000, 5000), copro_data(1010, 2000, 9000, 5000))
    assert nav.plans == 1 and program.pilot.busy
    visit(program, motor_data(1000, 2000, 9000, 5100), copro_data(1400, 1700, 9900, 5100))
    assert sent(os, "SET_GLOBAL_POSITION") == []
    assert program.corrector.sent == 0


# -- the heading an action file squares up to after the compass's calibration turn ---------------


def before_calibration() -> Any:
    """The state :meth:`Program._note_calibration_turn` reads and writes, before any heading was
    noted (its ``sensors`` are the test's to set)."""
    from types import SimpleNamespace

    return SimpleNamespace(
        navigator=None,
        rest_heading=None,
        rest_filtered=False,
        calibration_heading=None,
        compass_calibrating=False,
    )


def test_before_copro_filters_the_calibration_turn_keeps_the_motors_heading() -> None:
    """The turn began before copro's filter published a pose (a slow start with --sensors
    darmstadt): the heading kept is the motor's, where the robot was put down; once a fused
    heading came, only a fused one replaces it."""

    def sensors(heading: float, filtered: bool) -> Sensors:
        return Sensors(pose=(1000.0, 1000.0, heading), pose_filtered=filtered, motor_state=IDLE)

    main = before_calibration()
    note = main_module.Program._note_calibration_turn
    main.sensors = sensors(0.0, filtered=False)
    note(main)
    assert main.rest_heading == 0.0
    main.sensors = sensors(0.02, filtered=True)
    note(main)
    main.sensors = sensors(0.5, filtered=False)  # a dead-reckoned pose no longer counts
    note(main)
    assert main.rest_heading == 0.02
    main.compass_calibrating = True
    main.sensors = sensors(0.9, filtered=True)  # turning
    note(main)
    assert main.calibration_heading == 0.02
    without_filter = before_calibration()
    without_filter.sensors = sensors(0.0, filtered=False)
    note(without_filter)
    without_filter.compass_calibrating = True
    note(without_filter)
    assert without_filter.calibration_heading == 0.0  # before: None, and no squaring up
