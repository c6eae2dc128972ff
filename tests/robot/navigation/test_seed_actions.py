"""Action files as the seed's (issue 20; seed 000 §6.7, table B.4): ``e`` switches the motors on
(MOTORS_ON), ``v``/``c`` without a time are non-queueing and run until the next action starts."""

from __future__ import annotations

import math

import pytest

from modules.description import load_world
from modules.mapping.vectorgen import default_layout
from modules.navigation.actions import (
    WAIT,
    ActionNavigator,
    ActionPlan,
    Drive,
    MotorsOn,
    Wheels,
    parse_actions,
)
from modules.navigation.pilot import FORWARD, REASON, Outcome, Sensors
from modules.world.clients import MotorHardware
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for
from tokenring.errors import UsageError

# the track half width the circle speeds come from, written out: glide 6.5 half-steps per degree,
# 0.5419 mm per half-step -> track travel per radian of turn
HALF_WIDTH_MM = 6.5 * 0.5419 * 180.0 / math.pi


# -- parsing ---------------------------------------------------------------------------------------


def test_seed_accepts_v_and_c_with_and_without_the_time() -> None:
    text = "e\nv 40 -20\nv 30 30 1500\nc 800 50\nc -800 50 2000\n"
    actions = parse_actions(text, "seed.act", seed=True)
    assert [(a.kind, a.args, a.queued) for a in actions] == [
        ("e", (), True),
        ("v", (40.0, -20.0), False),
        ("v", (30.0, 30.0, 1500.0), True),
        ("c", (800.0, 50.0), False),
        ("c", (-800.0, 50.0, 2000.0), True),
    ]
    assert actions[3].line == 4 and actions[3].text == "c 800 50"


def test_ours_still_wants_the_time() -> None:
    with pytest.raises(UsageError, match=r"a\.act:2: 'v' takes 3 values.*give the time"):
        parse_actions("e\nv 50 50\n", "a.act")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("s 100\nv 50\n", "a.act:2: 'v' takes 2 or 3 values: v <left mm/s> <right mm/s> [<ms>]"),
        ("c 500 40 10 20\n", "a.act:1: 'c' takes 2 or 3 values: c <radius mm> <speed mm/s> [<ms>]"),
        ("e 1\n", "a.act:1: 'e' takes 0 values: e"),
        ("\n# x\nv 150 0\n", "a.act:3: track speeds are at most 100 mm/s"),
        ("v 0 0\n", "a.act:1: both track speeds are 0"),
        ("c 0 50\n", "a.act:1: a circle's radius cannot be 0"),
        ("v fast 10\n", "a.act:1: v <left mm/s> <right mm/s> [<ms>] (no time: until the next "),
        ("v 10 10 0\n", "a.act:1: the time must be positive"),
    ],
)
def test_seed_bad_lines_give_one_clear_line_with_file_and_line(text: str, message: str) -> None:
    with pytest.raises(UsageError) as info:
        parse_actions(text, "a.act", seed=True)
    assert message in str(info.value)
    assert "\n" not in str(info.value)
    assert info.value.exit_code == 2


# -- the plan --------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [True, False])
def test_e_switches_the_motors_on(seed: bool) -> None:
    plan = ActionPlan(parse_actions("e\ns 200\n"), speed_pct=50, seed=seed)
    assert plan.next(None, 0) == MotorsOn("line 1: e")
    assert plan.next(None, 10) == Drive("forward", 200, 50, "line 2: s 200")  # e does not hold the file
    assert plan.next(None, 20) is None and plan.finished


def test_appended_actions_queue_behind_the_waiting_ones() -> None:
    plan = ActionPlan(parse_actions("s 200\nr 90\n", "a.act"), speed_pct=50)
    assert plan.next(None, 0) == Drive("forward", 200, 50, "line 1: s 200")
    plan.append(parse_actions("s 300\n", "b.act"))
    assert plan.queue() == ["s 200", "r 90", "s 300"]
    assert plan.next(None, 10) == Drive("left", 90, 50, "line 2: r 90")
    assert plan.next(None, 20) == Drive("forward", 300, 50, "line 1: s 300")
    assert plan.next(None, 30) is None and plan.queue() == []


def test_non_queued_v_runs_until_the_next_action_starts() -> None:
    plan = ActionPlan(parse_actions("v 40 -20\ns 300\n", seed=True), speed_pct=60, seed=True)
    step = plan.next(None, 0)
    assert isinstance(step, Wheels) and (step.left_pct, step.right_pct) == (40, -20)
    # the next action starts at once, the motor still running the wheels (no wait for time or idle)
    assert plan.next(None, 5, motor_idle=False) == Drive("forward", 300, 60, "line 2: s 300")
    assert plan.holding is None
    assert plan.next(None, 4000) is None and plan.finished


def test_the_next_action_waits_until_the_wheels_are_seen_running() -> None:
    """The pilot takes the move number it sees for the old move's: a drive sent before motor.data
    shows the wheels would be ended at once by the wheels' ABORTED."""
    plan = ActionPlan(parse_actions("v 40 40\ns 300\n", seed=True), speed_pct=60, seed=True)
    assert isinstance(plan.next(None, 0), Wheels)
    assert plan.next(None, 20, motor_idle=True) == WAIT
    assert plan.next(None, 40, motor_idle=False).direction == "forward"
    # a motor that ignores SET_WHEEL_SPEEDS (the seed's) does not hold the file for ever
    plan = ActionPlan(parse_actions("v 40 40\ns 300\n", seed=True), speed_pct=60, seed=True)
    plan.next(None, 0)
    assert plan.next(None, 999, motor_idle=True) == WAIT
    assert plan.next(None, 1000, motor_idle=True).direction == "forward"


def test_queued_v_holds_the_file_for_its_time() -> None:
    plan = ActionPlan(parse_actions("v 40 -20 1000\ns 300\n", seed=True), speed_pct=60, seed=True)
    assert plan.next(None, 0) == Wheels(40, -20, 1000, "line 1: v 40 -20 1000")
    assert plan.next(None, 500, motor_idle=False) == WAIT
    assert plan.next(None, 1000, motor_idle=True).direction == "forward"


def test_the_last_non_queued_drive_goes_on_until_stopped() -> None:
    """Nothing follows: the seed's robot kept driving until the next command (the stop key); our
    motor takes at most 65 s per SET_WHEEL_SPEEDS, so the plan renews it while the file holds."""
    plan = ActionPlan(parse_actions("s 100\nc 1000 50\ne\n", seed=True), speed_pct=50, seed=True)
    assert plan.next(None, 0).direction == "forward"
    circle = plan.next(None, 1000)
    assert isinstance(circle, Wheels)
    # the circle's track speeds from its geometry: v (1 -/+ b / R)
    assert circle.left_pct == round(50 * (1 - HALF_WIDTH_MM / 1000))
    assert circle.right_pct == round(50 * (1 + HALF_WIDTH_MM / 1000))
    assert plan.next(None, 1010, motor_idle=False) == MotorsOn("line 3: e")  # e does not end it
    assert plan.holding == circle
    assert plan.next(None, 30_000, motor_idle=False) == WAIT and not plan.finished
    assert plan.next(None, 1000 + circle.duration_ms, motor_idle=False) == WAIT  # still stepping
    again = plan.next(None, 1000 + circle.duration_ms + 40, motor_idle=True)
    assert again == circle and not plan.finished
    assert plan.progress()["done"] == 3


def test_a_non_queued_drive_replaces_the_previous_one() -> None:
    plan = ActionPlan(parse_actions("v 20 20\nv -30 -30\n", seed=True), speed_pct=50, seed=True)
    assert (plan.next(None, 0).left_pct, plan.next(None, 1, motor_idle=False).left_pct) == (20, -30)
    assert plan.holding is not None and plan.holding.left_pct == -30


# -- main's navigator ------------------------------------------------------------------------------


def test_navigator_sends_motors_on_then_wheels_then_the_move() -> None:
    actions = parse_actions("e\nv 50 50\ns 400\n", seed=True)
    nav = ActionNavigator(default_layout(), actions, speed_pct=40, closed_loop=False, seed=True)
    sensors = Sensors(stamp_ms=0, motor_state=0)
    assert nav.plan(None, sensors, 0) == []
    assert nav.commands == [("motor", "MOTORS_ON", {})]
    nav.commands.clear()
    assert nav.plan(Outcome(REASON["DONE"]), sensors, 0) == []
    ((target, command, args),) = nav.commands
    assert (target, command) == ("motor", "SET_WHEEL_SPEEDS")
    assert (args["left_pct"], args["right_pct"]) == (50, 50)
    nav.commands.clear()
    sensors.motor_state = 1  # MOVING: the wheels run, the next action does not wait for them
    (move,) = nav.plan(Outcome(REASON["DONE"]), sensors, 0)
    assert (move.direction, move.amount, move.speed_pct) == (FORWARD, 400, 40)
    assert nav.commands == []


def test_navigator_in_ours_mode_sends_motors_on_for_e() -> None:
    nav = ActionNavigator(default_layout(), parse_actions("e\ns 400\n"), closed_loop=False)
    assert nav.plan(None, Sensors(stamp_ms=0, motor_state=0), 0) == []
    assert nav.commands == [("motor", "MOTORS_ON", {})]
    (move,) = nav.plan(None, Sensors(stamp_ms=10, motor_state=0), 0)
    assert move.amount == 400


# -- the motor takes MOTORS_ON ---------------------------------------------------------------------


def test_motor_takes_motors_on_without_touching_a_move() -> None:
    sim = Simulator(load_world("empty"), seed=3, speed=10.0)  # 2 m at 50 %: 40 s, 4 s real
    ring = MemoryRing([10, 20])
    main, motor = ring.nodes[10], ring.nodes[20]
    try:
        main.set_own_input_id()
        motor.start_program(program("motor"), MotorHardware.local(sim))
        data = main.subscribe("motor.data")
        wait_for(lambda: motor.program and getattr(motor.program, "out", None), 5, "motor up")
        assert main.deliver("motor", "MOVE_FORWARD", timeout=5, distance_mm=2000, speed_pct=50)
        wait_for(lambda: data.read()["steps_left"] > 0, 5, "moving")
        seq = data.read()["move_seq"]
        assert main.deliver("motor", "MOTORS_ON", timeout=5)
        wait_for(lambda: motor.program.report()["motors_on"] == 1, 5, "MOTORS_ON taken")
        assert motor.program.move is not None and motor.program.move.seq == seq  # still running
        assert main.receive_command(timeout=0.2) is None  # no POSITION_REACHED: nothing aborted
        assert main.deliver("motor", "STOP", timeout=5)
        reply = main.receive_command(timeout=10)
        assert reply is not None and reply.name == "POSITION_REACHED"
        assert (reply.args["status"], reply.args["move_seq"]) == (1, seq)  # ABORTED by the STOP
    finally:
        motor.stop_program()
        ring.close()
