"""The motor's seed mode (issue 20) beside ours: the same command sequence, the outcome seed
§4.3.3 describes (``move_forward``'s loop, the main loop's ``switch``) against today's.

Each test drives the real motor program on an in-process memory ring with the simulator wired
in, as ``test_motor.py`` does; main listens with its inbox open so that a reply sent once (the
seed's way) is taken. Expected step counts come from the seed's numbers written out here: a
drive wheel of 216.77 mm per 400 half-steps, 6.5 half-steps per degree, 100 % = 10 cm/s.
"""

from __future__ import annotations

import math
import os
import time

import pytest

from modules.description import load_world
from modules.variants import ENV
from modules.world.clients import MotorHardware
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for

DONE, ABORTED, STALLED, COLLISION = range(4)
IDLE, MOVING, STALLED_STATE, COLLISION_STATE = range(4)
BAD_ARGUMENT = 2
HALF_STEP_MM = 216.77 / 400  # seed §4.3.3 / 3.3.1: the drive wheel with its track, per half-step
GLIDE = 6.5  # half-steps per degree on tiles (seed 4.2)
TIMEOUT = 30.0  # real seconds; generous for a loaded machine, never a pass/fail threshold

MotorProgram = program("motor")


def half_steps(mm: float) -> int:
    return round(mm / HALF_STEP_MM)


class SeedBench:
    """main + motor on a memory ring; the motor runs ``algorithm`` (seed or ours)."""

    def __init__(self, algorithm: str, world: str = "empty", listening: bool = True, speed: float = 50.0):
        self.algorithm = algorithm
        self.sim = Simulator(load_world(world), seed=3, speed=speed)
        self.ring = MemoryRing([10, 20])
        self.main = self.ring.nodes[10]
        self.main.set_own_input_id()
        if listening:  # the inbox starts closed; open, it takes the next command at once
            self.main.unlock_data(self.main.spec.command.name)
        self.motor_os = self.ring.nodes[20]
        before = os.environ.get(ENV)
        os.environ[ENV] = f"motor={algorithm}"
        try:
            self.motor_os.start_program(MotorProgram, MotorHardware.local(self.sim))
            wait_for(lambda: getattr(self.motor_os.program, "out", None), 10, "motor up")
        finally:  # the program read the choice in setup(); nothing else in this process sees it
            if before is None:
                del os.environ[ENV]
            else:
                os.environ[ENV] = before
        assert self.program.seed == (algorithm == "seed")
        self.data = self.main.subscribe("motor.data")

    @property
    def program(self):
        return self.motor_os.program

    def command(self, name: str, **args) -> None:
        assert self.main.deliver("motor", name, timeout=10, **args), f"{name} not acknowledged"

    def start(self, name: str, **args) -> int:
        """Send a move command and wait until the motor runs it; its ``move_seq``."""
        before = self.data.read()["move_seq"]
        self.command(name, **args)
        wait_for(lambda: self.data.read()["move_seq"] != before, TIMEOUT, f"{name} started")
        return self.data.read()["move_seq"]

    def moving(self, steps: int = 50) -> None:
        """Wait until the current move has issued some steps (the next command falls into it)."""
        wait_for(lambda: abs(self.data.read()["steps_right"]) > steps, TIMEOUT, "moving")

    def reply(self):
        cmd = self.main.receive_command(timeout=TIMEOUT)
        assert cmd is not None, "no reply"
        return cmd

    def replies_until(self, move_seq: int) -> list[tuple[int, int]]:
        """(status, move_seq) of every POSITION_REACHED up to the DONE of ``move_seq``."""
        got: list[tuple[int, int]] = []
        while not got or got[-1] != (DONE, move_seq):
            cmd = self.reply()
            assert cmd.name == "POSITION_REACHED", cmd
            got.append((cmd.args["status"], cmd.args["move_seq"]))
        return got

    def idle(self) -> dict:
        wait_for(lambda: self.data.read()["state"] != MOVING and self.program.move is None, TIMEOUT, "idle")
        return self.data.read()

    def close(self) -> None:
        self.motor_os.stop_program()
        self.ring.close()


@pytest.fixture
def benches():
    made: list[SeedBench] = []

    def make(algorithm: str, **kwargs) -> SeedBench:
        made.append(SeedBench(algorithm, **kwargs))
        return made[-1]

    yield make
    for bench in made:
        bench.close()


# -- both tracks always step together -----------------------------------------------------------


def test_seed_has_no_differential_drive_only_straight_moves_and_turns(benches):
    """Seed §4.3.3: "beide Motoren immer gleichzeitig bearbeitet": straight or on the spot.
    SET_WHEEL_SPEEDS (a curve) is ours; the seed's main loop drops it as an unknown command."""
    seconds, left_pct, right_pct = 2.0, 60, 20
    ours = benches("ours")
    seq = ours.start("SET_WHEEL_SPEEDS", left_pct=left_pct, right_pct=right_pct, duration_ms=2000)
    assert ours.replies_until(seq) == [(DONE, seq)]
    d = ours.data.read()
    rate = 100.0 / HALF_STEP_MM  # half-steps per second at 100 %
    assert (d["steps_left"], d["steps_right"]) == (
        math.floor(rate * left_pct / 100 * seconds),
        math.floor(rate * right_pct / 100 * seconds),
    )
    assert d["steps_left"] != d["steps_right"]  # a curve
    assert ours.sim.truth()["y_mm"] != 1500  # it drove off its line

    seed = benches("seed")
    seed.command("SET_WHEEL_SPEEDS", left_pct=left_pct, right_pct=right_pct, duration_ms=2000)
    seq = seed.start("TURN_LEFT", angle_deg=90, speed_pct=20)
    samples = []
    while seed.program.move is not None:  # every published sample: the tracks in lock-step
        d = seed.data.read()
        samples.append((d["steps_left"], d["steps_right"]))
        time.sleep(0.002)
    assert seed.replies_until(seq) == [(DONE, seq)]  # nothing for SET_WHEEL_SPEEDS
    assert seed.program.ignored == 1
    assert samples and all(left == -right for left, right in samples)
    d = seed.data.read()
    assert (d["steps_left"], d["steps_right"]) == (-round(90 * GLIDE), round(90 * GLIDE))
    truth = seed.sim.truth()
    assert (truth["x_mm"], truth["y_mm"]) == pytest.approx((1000, 1500), abs=1e-6)  # on the spot


# -- a command of the same kind during a move ---------------------------------------------------


@pytest.mark.slow
def test_seed_ignores_a_command_of_the_moves_own_kind(benches):
    """Seed §4.3.3: ``if(Befehl ungleich MOVE_FORWARD) abort; else /* Befehl falsch */`` — a
    second MOVE_FORWARD leaves the first running; ours replaces the move with the new one."""
    total = half_steps(2000)
    ours = benches("ours")
    first = ours.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
    ours.moving()
    second = ours.start("MOVE_FORWARD", distance_mm=100, speed_pct=100)
    assert ours.replies_until(second) == [(ABORTED, first), (DONE, second)]
    d = ours.data.read()
    assert d["steps_left"] < total and d["distance_mm"] == round(half_steps(100) * HALF_STEP_MM)

    seed = benches("seed")
    first = seed.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
    seed.moving()
    seed.command("MOVE_FORWARD", distance_mm=100, speed_pct=100)
    # acknowledged is in the inbox, not yet taken: wait until the motor has taken (and dropped) it
    wait_for(lambda: seed.program.ignored, TIMEOUT, "the second MOVE_FORWARD taken")
    assert seed.program.ignored == 1 and seed.data.read()["move_seq"] == first
    assert seed.replies_until(first) == [(DONE, first)]
    d = seed.data.read()
    assert d["steps_left"] == d["steps_right"] == total
    assert d["distance_mm"] == round(total * HALF_STEP_MM) == 2000


# -- SET_GLOBAL_POSITION and RECALC_GLIDE_FACTOR abort a move -----------------------------------


@pytest.mark.slow
def test_seed_set_global_position_aborts_the_move(benches):
    """Seed §4.3.3: any command but the move's own ends ``move_forward`` (``return FALSE``), then
    the main loop takes the new position. Ours corrects the pose and drives on."""
    total = half_steps(2000)
    ours = benches("ours")
    seq = ours.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
    ours.moving()
    ours.command("SET_GLOBAL_POSITION", x_mm=-500, y_mm=250, angle_cdeg=0)
    assert ours.replies_until(seq) == [(DONE, seq)]
    d = ours.data.read()
    assert d["steps_left"] == total and d["x_mm"] > -500 and d["y_mm"] == 250

    seed = benches("seed")
    aborted = seed.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
    seed.moving()
    seed.command("SET_GLOBAL_POSITION", x_mm=-500, y_mm=250, angle_cdeg=0)
    d = seed.idle()
    assert 50 < d["steps_left"] < total and d["state"] == IDLE
    assert (d["x_mm"], d["y_mm"], d["angle_cdeg"]) == (-500, 250, 0)  # no step after the new pose
    follow = seed.start("MOVE_FORWARD", distance_mm=100, speed_pct=100)
    assert seed.replies_until(follow) == [(DONE, follow)] and follow != aborted  # nothing for the first
    d = seed.data.read()
    assert d["x_mm"] == round(-500 + half_steps(100) * HALF_STEP_MM)


@pytest.mark.slow
def test_seed_recalc_glide_factor_aborts_the_turn(benches):
    """As above for RECALC_GLIDE_FACTOR: the seed's turn stops where it was, ours finishes it.
    Both apply μ_new = α/(α+Δα)·μ_old (seed 4.2): 90° wanted, 80° turned."""
    total = round(360 * GLIDE)
    new_glide = 90 / (90 - 10) * GLIDE
    ours = benches("ours")
    seq = ours.start("TURN_LEFT", angle_deg=360, speed_pct=20)
    ours.moving()
    ours.command("RECALC_GLIDE_FACTOR", target_deg=90, error_cdeg=-1000)
    assert ours.replies_until(seq) == [(DONE, seq)]
    d = ours.data.read()
    assert d["steps_right"] == total and d["glide_cfactor"] == round(new_glide * 100)

    seed = benches("seed")
    aborted = seed.start("TURN_LEFT", angle_deg=360, speed_pct=20)
    seed.moving()
    seed.command("RECALC_GLIDE_FACTOR", target_deg=90, error_cdeg=-1000)
    d = seed.idle()
    assert 50 < d["steps_right"] < total and d["steps_left"] == -d["steps_right"]
    wait_for(lambda: seed.data.read()["glide_cfactor"] == round(new_glide * 100), TIMEOUT, "new glide")
    follow = seed.start("TURN_RIGHT", angle_deg=10, speed_pct=100)
    assert seed.replies_until(follow) == [(DONE, follow)] and follow != aborted
    assert seed.data.read()["steps_right"] == d["steps_right"] - round(10 * new_glide)


# -- POSITION_REACHED: only after a completed move, and once ------------------------------------


def test_seed_reports_only_completed_moves(benches):
    """Seed §4.3.3: "Ist ein Befehl, bis auf STOP, erfolgreich abgearbeitet worden, sendet das
    Modul ein POSITION-REACHED": a move cut short by another command or STOP says nothing.
    Ours reports those as ABORTED."""
    got = {}
    for algorithm in ("ours", "seed"):
        bench = benches(algorithm)
        s1 = bench.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
        bench.moving()
        s2 = bench.start("MOVE_REVERSE", distance_mm=100, speed_pct=100)  # another kind: aborts
        first = bench.replies_until(s2)
        s3 = bench.start("MOVE_FORWARD", distance_mm=2000, speed_pct=20)
        bench.moving()
        bench.command("STOP")
        bench.idle()
        s4 = bench.start("TURN_RIGHT", angle_deg=5, speed_pct=100)
        got[algorithm] = (first + bench.replies_until(s4), (s1, s2, s3, s4))
    replies, (s1, s2, s3, s4) = got["ours"]
    assert replies == [(ABORTED, s1), (DONE, s2), (ABORTED, s3), (DONE, s4)]
    replies, (s1, s2, s3, s4) = got["seed"]
    assert replies == [(DONE, s2), (DONE, s4)]


def test_seed_sends_position_reached_once(benches):
    """Seed §4.3.3 ``position_reached()``: one message; a commander not listening (inbox closed)
    never hears of the move. Ours offers it again until taken (``NOTICE_PATIENCE_S``)."""
    ours = benches("ours", listening=False)
    seq = ours.start("MOVE_FORWARD", distance_mm=50, speed_pct=100)
    wait_for(lambda: ours.motor_os.stats.commands_unacknowledged >= 1, TIMEOUT, "a reply not taken")
    assert ours.replies_until(seq) == [(DONE, seq)]  # receive_command opens the inbox: taken now

    seed = benches("seed", listening=False)
    lost = seed.start("MOVE_FORWARD", distance_mm=50, speed_pct=100)
    wait_for(lambda: seed.program.report()["notices_lost"] == 1, TIMEOUT, "the reply given up")
    assert not seed.program.notices and not seed.program.in_flight  # nothing left to send
    assert seed.motor_os.stats.commands_unacknowledged == 1
    seed.main.unlock_data(seed.main.spec.command.name)
    follow = seed.start("MOVE_FORWARD", distance_mm=50, speed_pct=100)
    assert seed.replies_until(follow) == [(DONE, follow)] and follow != lost
    assert seed.program.report()["notices_lost"] == 1


# -- no feedback: no bumper, no stall -----------------------------------------------------------


@pytest.mark.slow
def test_seed_has_no_bumper_and_drives_its_steps_into_the_wall(benches):
    """Seed §4.3.3: "da es keine Rückmeldung zwischen tatsächlicher Bewegung und der gewünschten
    (berechneten) Bewegung gibt": the seed issues every step against the wall and reports DONE,
    its dead reckoning 500 mm beyond it. Ours stops at the contact and reports COLLISION."""
    # empty world: start (1000, 1500) facing +X, wall at x = 4000
    total = half_steps(3500)
    ours = benches("ours")
    ours.start("MOVE_FORWARD", distance_mm=3500, speed_pct=100)
    reply = ours.reply()
    assert reply.name == "POSITION_REACHED" and reply.args["status"] == COLLISION
    d = ours.data.read()
    assert d["state"] == COLLISION_STATE and d["steps_left"] < total

    seed = benches("seed")
    seq = seed.start("MOVE_FORWARD", distance_mm=3500, speed_pct=100)
    assert seed.replies_until(seq) == [(DONE, seq)]
    d = seed.data.read()
    assert d["state"] == IDLE and d["steps_left"] == d["steps_right"] == total
    assert d["x_mm"] == round(1000 + total * HALF_STEP_MM) > 4000  # it believes it is in the wall
    truth = seed.sim.truth()
    assert truth["collisions"] >= 1
    assert truth["x_mm"] == pytest.approx(4000 - seed.sim.world.robot_radius, abs=1)


def test_seed_does_not_hear_of_lost_steps_above_100_percent(benches):
    """The seed did not check the speed (seed §4.3.3 only says 100 % is the start-stop limit):
    150 % stalls the steppers (no motion, steps counted) and it reports DONE. Ours refuses."""
    ours = benches("ours")
    ours.command("MOVE_FORWARD", distance_mm=100, speed_pct=150)
    reply = ours.reply()
    assert reply.name == "ERROR" and reply.args["error"] == BAD_ARGUMENT
    assert ours.data.read()["steps_left"] == 0

    seed = benches("seed")
    start = seed.sim.truth()["x_mm"]
    seq = seed.start("MOVE_FORWARD", distance_mm=100, speed_pct=150)
    assert seed.replies_until(seq) == [(DONE, seq)]
    assert seed.data.read()["steps_left"] == half_steps(100)
    assert seed.sim.truth()["x_mm"] == start  # stalled: not a millimetre
    # speed 0 stays refused in seed mode too (a move that never ends; see motor.py)
    seed.command("MOVE_FORWARD", distance_mm=100, speed_pct=0)
    reply = seed.reply()
    assert reply.name == "ERROR" and reply.args["error"] == BAD_ARGUMENT
