"""main in seed mode (issue 20): the seed's pilot and strategies (seed 001 §4.3.6, §4.4) beside ours.

Every rule is checked both ways on synthetic sensor data: the seed's pilot aborts on ALERT at any
sonar and on the escape too, the seed's Explore 1 turn stops at the CLOSE area, the seed's
Explore 2 is the calibration run and then plain left-wall following. The thresholds are written
out here from the seed's text (ALERT 0-4 cm, CLOSE 4-12 cm, NEAR 10-30 cm), not taken from the code.
"""

from __future__ import annotations

from typing import Any

import pytest

from modules.mapping.vectorgen import default_layout
from modules.navigation.navigator import (
    NAV,
    ExploreAvoid,
    ExploreLeftWall,
    SeedCalibrated,
    SeedExploreAvoid,
    SeedLeftWall,
)
from modules.navigation.pilot import (
    FORWARD,
    MOTOR_STATE,
    MOVE_STATUS,
    REASON,
    REVERSE,
    STOPPED,
    TURN_LEFT,
    TURN_RIGHT,
    Move,
    Outcome,
    Pilot,
    SeedPilot,
    Sensors,
)
from tests.support.fakenode import FakeOS

LAYOUT = default_layout()
FAR = 255
SEED_ALERT_BELOW_CM = 4  # seed §4.3.6: "Bereichsunterschreitung von 4cm"
SEED_CLOSE_UP_TO_CM = 12  # seed §4.3.3: "CLOSE 4cm bis 12cm"
SEED_NEAR_UP_TO_CM = 30  # seed §4.3.3: "NEAR 10cm bis 30 cm"


class Bench:
    """A pilot with a scripted motor: records what it sends, plays the motor's answers."""

    def __init__(self, pilot_class: type[Pilot]) -> None:
        self.sent: list[tuple[str, str, dict[str, Any]]] = []
        self.pilot = pilot_class(LAYOUT, self.send)
        self.sensors = Sensors(distances=[FAR] * 8)
        self.seq = 0

    def send(self, target: str, name: str, **args: Any) -> None:
        self.sent.append((target, name, args))

    def names(self) -> list[str]:
        return [f"{t}:{n}" for t, n, _ in self.sent]

    def start(self, move: Move) -> bool:
        accepted = self.pilot.start([move], self.sensors)
        if accepted:
            self.seq += 1
        return accepted

    def motor_runs(self) -> None:
        self.sensors.move_seq = self.seq
        self.sensors.motor_state = MOTOR_STATE["MOVING"]

    def tick(self, sweeps: int = 1, **changes: Any) -> Outcome | None:
        for name, value in changes.items():
            setattr(self.sensors, name, value)
        out = None
        for _ in range(sweeps):
            self.sensors.sweep += 1
            self.sensors.stamp_ms += 120
            out = self.pilot.step(self.sensors) or out
        return out

    def settle_stop(self) -> Outcome | None:
        """The motor stands after the pilot's STOP: the outcome."""
        self.sensors.motor_state = MOTOR_STATE["IDLE"]
        return self.tick(3)


def one_sonar(index: int, cm: int) -> list[int]:
    d = [FAR] * 8
    d[index] = cm
    return d


# -- ALERT: which sonars ----------------------------------------------------------------------------
@pytest.mark.parametrize("index", range(8))
@pytest.mark.parametrize("direction", [FORWARD, REVERSE, TURN_LEFT])
def test_seed_pilot_aborts_any_move_on_alert_at_any_sonar(index: int, direction: int) -> None:
    b = Bench(SeedPilot)
    b.start(Move(direction, 500))
    b.motor_runs()
    assert b.tick() is None
    b.tick(distances=one_sonar(index, SEED_ALERT_BELOW_CM - 1))
    assert b.names()[-1] == "motor:STOP"
    out = b.settle_stop()
    assert out is not None and out.reason == REASON["ALERT"]
    opposite = {FORWARD: REVERSE, REVERSE: FORWARD, TURN_LEFT: TURN_RIGHT}[direction]
    assert b.pilot.alert_lock == opposite  # only the opposite of the aborted move


def test_seed_pilot_takes_4_cm_for_no_alert() -> None:
    b = Bench(SeedPilot)
    b.start(Move(FORWARD, 500))
    b.motor_runs()
    b.tick(3, distances=one_sonar(LAYOUT.rear[0], SEED_ALERT_BELOW_CM))  # the area ends under 4 cm
    assert "motor:STOP" not in b.names()


def test_ours_watches_only_the_sonars_facing_the_move() -> None:
    """Ours: forward watches the front three, reverse the rear one; a side or rear echo under
    4 cm does not stop a forward drive (the seed's pilot stops it, above)."""
    for index in (LAYOUT.rear[0], LAYOUT.left_front, LAYOUT.right_rear):
        b = Bench(Pilot)
        b.start(Move(FORWARD, 500))
        b.motor_runs()
        b.tick(3, distances=one_sonar(index, SEED_ALERT_BELOW_CM - 1))
        assert "motor:STOP" not in b.names(), index
    b = Bench(Pilot)
    b.start(Move(FORWARD, 500))
    b.motor_runs()
    b.tick(distances=one_sonar(LAYOUT.front[1], SEED_ALERT_BELOW_CM - 1))
    assert b.names()[-1] == "motor:STOP"


# -- ALERT: the escape ------------------------------------------------------------------------------
def _forward_alert(pilot_class: type[Pilot]) -> Bench:
    """A forward drive stopped by an echo 3 cm ahead: locked to REVERSE."""
    b = Bench(pilot_class)
    b.start(Move(FORWARD, 3000))
    b.motor_runs()
    b.tick(distances=one_sonar(LAYOUT.front[1], SEED_ALERT_BELOW_CM - 1))
    out = b.settle_stop()
    assert out is not None and out.reason == REASON["ALERT"] and b.pilot.alert_lock == REVERSE
    return b


def test_seed_escape_still_in_alert_is_sent_then_aborted_and_locks_the_other_way() -> None:
    """seed pilot_1: the move is sent, then "if(Ein Sensor auf ALERT) Fahrt auf jeden Fall
    abbrechen" — the escape too; the lock is now the opposite of the escape."""
    b = _forward_alert(SeedPilot)
    for refused in (FORWARD, TURN_LEFT, TURN_RIGHT):
        assert not b.start(Move(refused, 100))
        assert b.tick().trigger == "locked"
    assert b.start(Move(REVERSE, 60))
    assert b.names()[-1] == "motor:MOVE_REVERSE"  # sent first, as the seed does
    b.motor_runs()
    b.tick()
    assert b.names()[-1] == "motor:STOP"
    out = b.settle_stop()
    assert out is not None and out.reason == REASON["ALERT"]
    assert b.pilot.alert_lock == FORWARD


def test_ours_lets_the_escape_run_while_the_alert_it_escapes_lasts() -> None:
    b = _forward_alert(Pilot)
    assert b.start(Move(REVERSE, 60))
    b.motor_runs()
    assert b.tick(2) is None and "motor:STOP" not in b.names()[-1:]
    b.pilot.note_position_reached(MOVE_STATUS["DONE"], b.seq)
    out = b.tick()
    assert out is not None and out.done and b.pilot.alert_lock == STOPPED


# -- Explore 1: the turn's abort --------------------------------------------------------------------
def _turn_of(nav: ExploreAvoid) -> Move:
    s = Sensors(distances=[FAR] * 8)
    drive = nav.plan(None, s, STOPPED)
    assert drive is not None and drive[0].direction == FORWARD
    turn = nav.plan(Outcome(REASON["CLOSE"], drive[0], trigger="front_within"), s, STOPPED)
    assert turn is not None and turn[0].direction in (TURN_LEFT, TURN_RIGHT) and turn[0].amount == 90
    return turn[0]


def test_seed_explore1_turn_aborts_at_the_close_area_ours_at_half_of_it() -> None:
    """seed navigator_1 TURN: "Drehe links 90 Grad; Abbruch bei Annaeherung im CLOSE-Bereich"."""
    seed_turn, our_turn = _turn_of(SeedExploreAvoid(LAYOUT)), _turn_of(ExploreAvoid(LAYOUT))
    assert [(a.kind, a.cm) for a in seed_turn.abort] == [("front_within", SEED_CLOSE_UP_TO_CM)]
    assert [(a.kind, a.cm) for a in our_turn.abort] == [("front_within", SEED_CLOSE_UP_TO_CM // 2)]
    # run through the pilots: a wall 10 cm ahead (in CLOSE) stops the seed's turn, not ours
    for turn, pilot_class, stops in ((seed_turn, SeedPilot, True), (our_turn, Pilot, False)):
        b = Bench(pilot_class)
        b.start(turn)
        b.motor_runs()
        b.tick(distances=one_sonar(LAYOUT.front[0], 10))
        assert (b.names()[-1] == "motor:STOP") is stops
        if stops:
            out = b.settle_stop()
            assert out is not None and out.reason == REASON["CLOSE"]


def test_seed_explore1_is_the_seed_automaton_and_ends_when_the_lock_refuses_everything() -> None:
    nav = SeedExploreAvoid(LAYOUT)
    s = Sensors(distances=[FAR] * 8)
    drive = nav.plan(None, s, STOPPED)
    assert drive is not None and drive[0].scan and nav.state == NAV["TURN"]
    back = nav.plan(Outcome(REASON["ALERT"], drive[0]), s, REVERSE)
    assert back is not None and back[0].direction == REVERSE  # TURN on ALERT: drive back a little
    # the escape hit ALERT too (seed pilot): locked to FORWARD; neither escape is accepted now
    plans = []
    refused = Outcome(REASON["ALERT"], back[0], trigger="locked")
    for _ in range(10):
        plan = nav.plan(refused, s, FORWARD)
        if plan is None:
            break
        plans.append(plan[0].direction)
    assert plan is None and nav.state == NAV["DONE"] and "stuck" in nav.note
    assert set(plans) <= {REVERSE, TURN_LEFT, TURN_RIGHT} and len(plans) >= 2


# -- Explore 2: the calibration run first -----------------------------------------------------------
def test_seed_explore2_begins_with_the_calibration_run_ours_does_not() -> None:
    """seed §4.4: "Sie versucht am Anfang den Gleitfaktor durch eine 360° Drehung zu bestimmen"."""
    nav = SeedCalibrated(LAYOUT, SeedLeftWall(LAYOUT))
    assert nav.mode == 2
    s = Sensors(distances=[FAR] * 8, heading_cdeg=9000)
    turn = nav.plan(None, s, STOPPED)
    assert turn is not None and [(m.direction, m.amount) for m in turn] == [(TURN_LEFT, 360)]
    assert nav.state == NAV["CALIBRATE"]
    # the turn came out 8.5° short: a left turn lowers the clockwise heading, so it reads 90 + 8.5
    s.heading_cdeg = 9850
    back = nav.plan(Outcome(REASON["DONE"], turn[0]), s, STOPPED)
    assert nav.commands == [("motor", "RECALC_GLIDE_FACTOR", {"target_deg": 360, "error_cdeg": -850})]
    assert back is not None and [(m.direction, m.amount) for m in back] == [(TURN_LEFT, 9)]  # face 90° again
    s.heading_cdeg = 9000
    find = nav.plan(Outcome(REASON["DONE"], back[0]), s, STOPPED)
    assert nav.result == {"error_deg": -8.5}
    assert find is not None and find[0].direction == FORWARD and find[0].label == "find"
    ours = ExploreLeftWall(LAYOUT).plan(None, Sensors(distances=[FAR] * 8, heading_cdeg=9000), STOPPED)
    assert ours is not None and all(m.amount != 360 for m in ours) and ours[0].direction == FORWARD


def test_seed_explore2_without_a_compass_still_follows_after_the_turn() -> None:
    nav = SeedCalibrated(LAYOUT, SeedLeftWall(LAYOUT))
    s = Sensors(distances=[FAR] * 8)
    turn = nav.plan(None, s, STOPPED)
    assert turn is not None and turn[0].amount == 360
    find = nav.plan(Outcome(REASON["DONE"], turn[0]), s, STOPPED)
    assert nav.commands == [] and nav.result is None
    assert find is not None and find[0].label == "find"


# -- Explore 2: plain left-wall following -----------------------------------------------------------
def _sensors(**cm: int) -> Sensors:
    d = [FAR] * 8
    for name, value in cm.items():
        d[getattr(LAYOUT, name)] = value
    return Sensors(distances=d, pose=(0.0, 0.0, 0.0))


def test_seed_left_wall_is_the_labyrinth_rule_with_the_seeds_distance_areas() -> None:
    nav = SeedLeftWall(LAYOUT)
    open_ = _sensors()
    wall = _sensors(left_front=15, left_rear=15)
    find = nav.plan(None, open_, STOPPED)
    assert find is not None and [(m.label, m.direction) for m in find] == [("find", FORWARD)]
    assert [(a.kind, a.cm) for a in find[0].abort] == [("front_within", SEED_CLOSE_UP_TO_CM)]
    # nothing in the way for the whole drive: drive on
    again = nav.plan(Outcome(REASON["DONE"], find[0]), open_, STOPPED)
    assert again is not None and again[0].label == "find"
    # blocked ahead: turn right 90°, the wall is on the left
    inner = nav.plan(Outcome(REASON["CLOSE"], find[0], trigger="front_within"), wall, STOPPED)
    assert inner is not None and [(m.direction, m.amount) for m in inner] == [(TURN_RIGHT, 90)]
    follow = nav.plan(Outcome(REASON["DONE"], inner[0]), wall, STOPPED)
    assert follow is not None and len(follow) == 1 and follow[0].scan and follow[0].direction == FORWARD
    kinds = {(a.kind, a.cm) for a in follow[0].abort}
    assert kinds == {("front_within", SEED_CLOSE_UP_TO_CM), ("left_beyond", SEED_NEAR_UP_TO_CM)}
    assert all(a.sweeps == 1 for a in follow[0].abort)  # no dropout filter
    # inner corner
    turn = nav.plan(Outcome(REASON["CLOSE"], follow[0], trigger="front_within"), wall, STOPPED)
    assert turn is not None and [(m.direction, m.amount) for m in turn] == [(TURN_RIGHT, 90)]
    follow = nav.plan(Outcome(REASON["DONE"], turn[0]), wall, STOPPED)
    # the wall ended: past its end, turn left, drive until the left sees a wall
    outer = nav.plan(Outcome(REASON["CORNER"], follow[0], trigger="left_beyond"), open_, STOPPED)
    assert outer is not None
    assert [(m.label, m.direction) for m in outer] == [
        ("clear", FORWARD),
        ("outer", TURN_LEFT),
        ("reacquire", FORWARD),
    ]
    assert outer[1].amount == 90
    assert ("left_within", SEED_NEAR_UP_TO_CM) in {(a.kind, a.cm) for a in outer[2].abort}
    # no wall came: the end of a thin wall, turn left again
    round_ = nav.plan(Outcome(REASON["DONE"], outer[2], index=3), open_, STOPPED)
    assert round_ is not None and [(m.label, m.direction) for m in round_] == [
        ("outer", TURN_LEFT),
        ("reacquire", FORWARD),
    ]
    found = nav.plan(Outcome(REASON["NONE"], round_[1], index=1, trigger="left_within"), wall, STOPPED)
    assert found is not None and [m.label for m in found] == ["follow"]
    # ALERT: the move the lock allows
    esc = nav.plan(Outcome(REASON["ALERT"], found[0]), wall, REVERSE)
    assert esc is not None and esc[0].direction == REVERSE and nav.state == NAV["BACK_OFF"]


def test_seed_left_wall_makes_no_course_correction_ours_does() -> None:
    """A segment that drifted away from the wall by 1 cm per 10 cm: ours turns left before the
    next segment, the seed's drives on as it is."""
    drift = [(d, [FAR] * 8) for d in range(0, 600, 12)]
    for d, readings in drift:
        readings[LAYOUT.left_front] = 30 + d // 100
    wall = _sensors(left_front=30, left_rear=30)
    seed = SeedLeftWall(LAYOUT)
    seed.phase = "follow"
    seg = seed.plan(
        Outcome(REASON["DONE"], Move(FORWARD, 3000, scan=True, label="follow"), driven_mm=600, samples=drift),
        wall,
        STOPPED,
    )
    assert seg is not None and [m.label for m in seg] == ["follow"]
    ours = ExploreLeftWall(LAYOUT)
    ours.phase = "follow"
    nxt = ours.plan(
        Outcome(REASON["DONE"], Move(FORWARD, 600, scan=True, label="follow"), driven_mm=600, samples=drift),
        wall,
        STOPPED,
    )
    assert nxt is not None and nxt[0].direction == TURN_LEFT


def test_seed_left_wall_never_ends_by_itself() -> None:
    """No lap end, no islands, no way home: four inner corners round a square room and on."""
    nav = SeedLeftWall(LAYOUT)
    wall = _sensors(left_front=15, left_rear=15)
    plan = nav.plan(None, wall, STOPPED)
    for _ in range(40):
        assert plan is not None
        move = plan[-1]
        if move.label == "follow":
            last = Outcome(REASON["CLOSE"], move, trigger="front_within", driven_mm=2000)
        else:
            last = (
                Outcome(REASON["DONE"], move)
                if move.label != "find"
                else Outcome(REASON["CLOSE"], move, trigger="front_within")
            )
        plan = nav.plan(last, wall, STOPPED)
    assert plan is not None and nav.state != NAV["DONE"]


@pytest.mark.parametrize("nav_class", [SeedLeftWall, SeedExploreAvoid])
def test_seed_strategies_end_when_every_escape_is_aborted_by_another_alert(nav_class) -> None:
    """Any sonar aborts any move: a robot within 4 cm of a wall rocks between the two directions
    the lock allows in turn. The strategy gives up after a dozen ALERTs in a row, not forever."""
    nav = nav_class(LAYOUT)
    close = _sensors(left_front=2)
    plan = nav.plan(None, close, STOPPED)
    lock, plans = REVERSE, 0
    while plan is not None and plans < 50:
        last = Outcome(REASON["ALERT"], plan[0], trigger="alert on sonar [1]")
        lock = FORWARD if lock == REVERSE else REVERSE  # the opposite of the aborted escape
        plan = nav.plan(last, close, lock)
        plans += 1
    assert plan is None and nav.state == NAV["DONE"] and "ALERTs in a row" in nav.note
    assert 10 <= plans <= 14
    # one move that ends otherwise starts the count again
    nav = nav_class(LAYOUT)
    plan = nav.plan(None, close, STOPPED)
    for k in range(30):
        reason = REASON["DONE"] if k % 5 == 4 else REASON["ALERT"]
        plan = nav.plan(Outcome(reason, plan[0], trigger="x"), close, REVERSE)
        assert plan is not None


# -- main: the switch -------------------------------------------------------------------------------
@pytest.mark.parametrize("choice", ["main=seed", "seed", "main=ours", ""])
def test_main_reads_the_switch_once_and_builds_the_pairs_and_strategies(
    monkeypatch: pytest.MonkeyPatch, choice: str
) -> None:
    from modules.main import Program

    monkeypatch.setenv("TOKENRING_ALGORITHMS", choice)
    program = Program(FakeOS())  # type: ignore[arg-type]
    program.setup()
    monkeypatch.setenv("TOKENRING_ALGORITHMS", "ours" if "seed" in choice else "seed")  # read once
    seed = "seed" in choice
    assert all((type(p) is SeedPilot) is seed for p in program.pilots.values())
    assert all(type(p) in (Pilot, SeedPilot) for p in program.pilots.values())
    program.start_explore(1)
    assert type(program.navigator) is (SeedExploreAvoid if seed else ExploreAvoid) and program.pair == 1
    program.start_explore(2)
    nav = program.navigator
    assert program.pair == 2 and program.pilot is program.pilots[2]
    if seed:
        assert isinstance(nav, SeedCalibrated) and type(nav.strategy) is SeedLeftWall
    else:
        assert type(nav) is ExploreLeftWall
    program.stop_explore("stopped")
    assert program.finished is not None and ("calibration" in program.finished) is seed
