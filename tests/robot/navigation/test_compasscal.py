"""main's side of the compass's calibration turn (seed 001 §4.3: the turn goes through main's
pilot, the compass only listens): the navigator's eight 45° stops with a wait for the compass's
samples after each, its ends, and main's entry points (the compass's CALIBRATE_COMPASS, the PC
link's ``calibrate_compass``). Expected commands and moves are written out from protocol.yaml's
names, not taken from the code under test."""

from __future__ import annotations

from typing import Any, cast

import pytest

from modules import main as main_module
from modules.localization.pose_correction import ENV as SETPOS_ENV
from modules.mapping.vectorgen import default_layout
from modules.navigation.compass_turn import CompassCalibration
from modules.navigation.pilot import Move, Outcome, Sensors
from modules.variants import ENV as ALGORITHMS_ENV
from tests.support.fakenode import FakeOS
from tokenring.contract.protocol import default_protocol
from tokenring.errors import UsageError

ENUMS = default_protocol().enums
STOPPED, TURN_LEFT, TURN_RIGHT = (ENUMS["direction"][n] for n in ("STOPPED", "TURN_LEFT", "TURN_RIGHT"))
DONE, ALERT, TIMEOUT = (ENUMS["abort_reason"][n] for n in ("DONE", "ALERT", "TIMEOUT"))
UNCALIBRATED, OK, CALIBRATING = (ENUMS["compass_state"][n] for n in ("UNCALIBRATED", "OK", "CALIBRATING"))
NAV_CALIBRATE, NAV_DONE = ENUMS["navigator"]["CALIBRATE"], ENUMS["navigator"]["DONE"]
LISTEN_8 = ("compass", "CALIBRATE_LISTEN", {"stops": 8})
STOP_LISTENING = ("compass", "CALIBRATE_LISTEN", {"stops": 0})


def at(stamp_ms: int) -> Sensors:
    return Sensors(stamp_ms=stamp_ms)


def waited() -> Outcome:
    """What the pilot hands back after an empty plan (the navigator waited a visit)."""
    return Outcome(DONE)


class Bench:
    """The navigator stepped as main steps it, with compass.data as main last copied it."""

    def __init__(self, sample: int = 100) -> None:
        self.nav = CompassCalibration(default_layout())
        self.state, self.sample, self.now = UNCALIBRATED, sample, 1000

    def plan(self, last: Outcome | None = None, lock: int = STOPPED) -> list[Move] | None:
        self.now += 100
        self.nav.observe_compass({"state": self.state, "sample": self.sample & 0xFFFF, "heading_cdeg": 0})
        return self.nav.plan(last if last is not None else waited(), at(self.now), lock)

    def sent(self) -> list[tuple[str, str, dict[str, int]]]:
        out = list(self.nav.commands)
        self.nav.commands.clear()
        return out

    def start_listening(self) -> None:
        assert self.nav.plan(None, at(self.now), STOPPED) == []
        assert self.sent() == [LISTEN_8]
        assert self.plan() == []  # compass.data does not say CALIBRATING yet: wait
        self.state = CALIBRATING


def test_eight_45_degree_turns_each_after_eight_compass_samples_then_the_compass_ok() -> None:
    bench = Bench(sample=65530)  # the sample counter wraps on the way (u16)
    bench.start_listening()
    turns: list[Move] = []
    for stop in range(1, 9):
        moves = bench.plan()
        assert moves is not None and len(moves) == 1, (stop, moves)
        turn = moves[0]
        assert (turn.direction, turn.amount) == (TURN_LEFT, 45)
        turns.append(turn)
        assert bench.plan(Outcome(DONE, turn)) == []  # the turn is done: wait at rest
        if stop < 8:
            for _ in range(7):  # seven new samples: not yet
                bench.sample += 1
                assert bench.plan() == [], stop
            bench.sample += 1  # the eighth: the next plan turns on
    assert bench.sent() == []  # main told the compass nothing more than to listen
    for _ in range(3):  # the compass still fitting: main waits
        bench.sample += 1
        assert bench.plan() == []
    bench.state = OK
    assert bench.plan() is None
    nav = bench.nav
    assert nav.state == NAV_DONE and nav.result == {"turns": 8, "compass_state": "OK"}
    assert nav.note == "compass calibrated" and nav.mode == 4
    assert sum(t.amount for t in turns) == 360 and not nav.listening
    assert bench.sent() == []


def test_the_alert_lock_picks_the_turn_direction() -> None:
    bench = Bench()
    bench.start_listening()
    moves = bench.plan(lock=TURN_RIGHT)  # the pilot would refuse a left turn
    assert moves is not None and moves[0].direction == TURN_RIGHT
    bench.plan(Outcome(DONE, moves[0]))
    bench.sample += 8
    moves = bench.plan()  # the lock is gone; the turns keep their sense
    assert moves is not None and moves[0].direction == TURN_RIGHT


def test_a_turn_that_does_not_end_done_ends_the_run_and_the_compass_stops_listening() -> None:
    bench = Bench()
    bench.start_listening()
    moves = bench.plan()
    assert moves is not None
    assert bench.plan(Outcome(ALERT, moves[0], trigger="alert on sonar [3]")) is None
    assert bench.sent() == [STOP_LISTENING]
    assert bench.nav.state == NAV_DONE and "ALERT" in bench.nav.note
    assert bench.nav.result is not None and bench.nav.result["turns"] == 0


def turn_and_dwell(bench: Bench, last: Outcome | None = None, samples: int = 8) -> Move:
    """One turn planned, ended (DONE unless ``last`` says otherwise), ``samples`` samples seen."""
    moves = bench.plan()
    assert moves is not None and len(moves) == 1, moves
    ending = last if last is not None else Outcome(DONE, moves[0])
    assert bench.plan(ending) == []
    bench.sample += samples
    return moves[0]


def test_a_turn_stopped_for_taking_too_long_is_a_stop_like_any_other() -> None:
    bench = Bench()
    bench.start_listening()
    first = bench.plan()
    assert first is not None
    assert bench.plan(Outcome(TIMEOUT, first[0], trigger="move took too long")) == []
    bench.sample += 8
    moves = bench.plan()
    assert moves is not None and moves[0].label == "compass stop 2"
    assert bench.sent() == []


def test_a_stop_the_compass_missed_gets_one_more_turn_after_three_dwells() -> None:
    bench = Bench()
    bench.start_listening()
    for _ in range(8):
        turn_and_dwell(bench)
    bench.sample += 15  # 23 samples since the eighth turn: still waiting for the compass
    assert bench.plan() == []
    bench.sample += 1
    moves = bench.plan()
    assert moves is not None and moves[0].label == "compass stop 9"
    bench.plan(Outcome(DONE, moves[0]))
    bench.state = OK
    assert bench.plan() is None
    assert bench.nav.result == {"turns": 9, "compass_state": "OK"}
    assert bench.nav.note == "compass calibrated"


def test_a_compass_that_never_finishes_gets_four_more_turns_then_the_run_ends() -> None:
    bench = Bench()
    bench.start_listening()
    for _ in range(8):
        turn_and_dwell(bench)
    for _ in range(4):
        bench.sample += 16
        turn_and_dwell(bench)
    bench.sample += 16
    assert bench.plan() is None
    assert bench.sent() == [STOP_LISTENING]
    assert bench.nav.note == "the compass did not finish after 12 turns"


def test_a_compass_that_gives_up_mid_turn_ends_the_run_without_more_turns() -> None:
    bench = Bench()
    bench.start_listening()
    turn_and_dwell(bench, samples=2)
    bench.state = UNCALIBRATED  # the compass ended its listening (it saw a straight move, say)
    assert bench.plan() is None
    assert bench.sent() == []  # it is not listening any more: nothing to tell it
    assert bench.nav.result == {"turns": 1, "compass_state": "UNCALIBRATED"}
    assert bench.nav.note == "the compass ended the turn UNCALIBRATED after 1 turn"


def test_an_old_copy_of_compass_data_neither_ends_the_run_nor_counts_as_samples() -> None:
    """A token regenerated from an old copy brings back compass.data from before the listening
    (UNCALIBRATED, an older sample count): the past, left out."""
    bench = Bench(sample=3)
    bench.start_listening()
    bench.sample = 10
    turn_and_dwell(bench, samples=2)  # at 12, the turn's end seen at 10
    state, sample = bench.state, bench.sample
    bench.state, bench.sample = UNCALIBRATED, 3  # the old copy
    assert bench.plan() == []  # not "the compass ended", not 65529 samples
    bench.state, bench.sample = state, sample + 5  # 17: seven since the turn's end
    assert bench.plan() == []
    bench.sample += 1
    moves = bench.plan()
    assert moves is not None and moves[0].label == "compass stop 2"


def test_a_compass_that_never_listens_ends_the_run_after_the_timeout() -> None:
    nav = CompassCalibration(default_layout(), timeout_ms=10_000)
    assert nav.plan(None, at(0), STOPPED) == []
    nav.commands.clear()
    nav.observe_compass(None)  # the compass has not spoken
    assert nav.plan(waited(), at(10_000), STOPPED) == []
    assert nav.plan(waited(), at(10_001), STOPPED) is None
    assert nav.commands == [STOP_LISTENING]
    assert nav.note == "the compass did not start listening"


def test_samples_that_stop_coming_end_the_run_after_the_timeout() -> None:
    nav = CompassCalibration(default_layout(), timeout_ms=10_000)
    nav.observe_compass({"state": CALIBRATING, "sample": 5})
    nav.plan(None, at(0), STOPPED)
    moves = nav.plan(waited(), at(100), STOPPED)
    assert moves is not None
    assert nav.plan(Outcome(DONE, moves[0]), at(5000), STOPPED) == []
    assert nav.plan(waited(), at(15_000), STOPPED) == []
    assert nav.plan(waited(), at(15_001), STOPPED) is None
    assert nav.commands == [LISTEN_8, STOP_LISTENING]
    assert "stop 1" in nav.note


def test_cancel_tells_a_listening_compass_once_and_nothing_before_it_was_asked() -> None:
    nav = CompassCalibration(default_layout())
    assert nav.cancel() == []  # not asked to listen yet
    nav.plan(None, at(0), STOPPED)
    assert nav.cancel() == [STOP_LISTENING]
    assert nav.cancel() == []


# -- main's entry points ------------------------------------------------------------------------
def motor_at_rest(stamp: int) -> dict[str, Any]:
    return {
        "x_mm": 0,
        "y_mm": 0,
        "angle_cdeg": 0,
        "direction": STOPPED,
        "speed_pct": 0,
        "distance_mm": 0,
        "steps_left": 0,
        "steps_right": 0,
        "stamp_ms": stamp,
        "move_seq": 0,
        "state": 0,
        "glide_cfactor": 650,
    }


NO_FILTER = {
    "left_contact": 0,
    "right_contact": 0,
    "pose_x_mm": 0,
    "pose_y_mm": 0,
    "pose_angle_cdeg": 0,
    "pose_valid": 0,
    "pose_source": 0,
    "pose_stamp_ms": 0,
    "sigma_x_mm": 0,
    "sigma_y_mm": 0,
    "sigma_angle_cdeg": 0,
    "flushes_done": 0,
}


@pytest.fixture
def main(monkeypatch: pytest.MonkeyPatch) -> tuple[Any, FakeOS]:
    monkeypatch.delenv(ALGORITHMS_ENV, raising=False)
    monkeypatch.delenv(SETPOS_ENV, raising=False)
    os = FakeOS()
    program = main_module.Program(cast(Any, os))  # the programs' stand-in node OS
    program.setup()
    os.buffers["sonar.data"].set({"distances": [200] * 8, "sweep": 1, "stamp_ms": 5000})
    os.buffers["copro.data"].set(NO_FILTER)
    return program, os


def visit(program: Any, stamp: int, compass_state: int, sample: int) -> None:
    """One token visit as main's loop runs it: the channels copied, sensors read, cooperate."""
    program.motor.set(motor_at_rest(stamp))
    program.compass.set({"heading_cdeg": 0, "state": compass_state, "sample": sample, "stamp_ms": stamp})
    program.sensors = program._read_sensors()
    program._cooperate()


def test_main_runs_the_compass_calibration_on_the_compass_request_with_pair_1(main) -> None:
    program, os = main
    program.handle_command("CALIBRATE_COMPASS", {})
    assert isinstance(program.navigator, CompassCalibration) and program.pair == 1
    visit(program, 5000, UNCALIBRATED, 10)
    assert os.delivered == [LISTEN_8]
    visit(program, 5100, CALIBRATING, 11)
    assert os.delivered[1:] == [("motor", "TURN_LEFT", {"angle_deg": 45, "speed_pct": 50})]
    assert program.state()["navigator"] == "CALIBRATE"


def test_main_serves_calibrate_compass_on_the_pc_link_and_names_it_among_its_verbs(main) -> None:
    program, _os = main
    state = program._serve("calibrate_compass", {})
    assert isinstance(program.navigator, CompassCalibration) and state["running"]
    with pytest.raises(UsageError, match="calibrate_compass"):
        program.on_pc_request("calibrate_the_compass", {})


def test_main_stopped_mid_calibration_tells_the_compass_to_stop_listening(main) -> None:
    program, os = main
    program.handle_command("CALIBRATE_COMPASS", {})
    visit(program, 5000, UNCALIBRATED, 10)
    program.handle_command("STOP_EXPLORE", {})
    assert STOP_LISTENING in os.delivered
    assert program.navigator is None and program.finished["navigator"] == "CompassCalibration"


def test_main_starting_another_navigator_mid_calibration_tells_the_compass_too(main) -> None:
    program, os = main
    program.handle_command("CALIBRATE_COMPASS", {})
    visit(program, 5000, UNCALIBRATED, 10)
    program.handle_command("EXPLORE", {"mode": 1})
    assert os.delivered[-1] == STOP_LISTENING
    assert not isinstance(program.navigator, CompassCalibration)
