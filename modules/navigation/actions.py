"""Action files (seed 000, §6.7 and table B.4): reproducible test drives that main executes.

One command per line, fields separated by blanks, ``#`` starts a comment::

    e                      motors on: MOTORS_ON to the motor
    s <mm>                 drive straight (negative: backwards)
    r <deg>                turn on the spot, counter-clockwise positive
    v <left> <right> <ms>  track speeds in mm/s for a time (100 mm/s = 100 %)
    c <radius> <speed> <ms>  drive a circle of radius mm (positive: to the left) at speed mm/s

By default every action is queued (the seed's queueing actions); ``v`` and ``c`` need the time.
``e`` sends MOTORS_ON ("Motoren an", non-queueing: the next action follows at once). With
``seed=True`` (main's ``--algorithms main=seed``) the file is the seed's (seed 000 §6.7): ``v``
and ``c`` without the time are non-queueing: they run until the next driving action starts, which
is at once (the file does not wait for them); the file's last one runs until main is stopped.
Errors name the file and line. :class:`ActionPlan` turns the actions into steps one at a time;
turns are closed-loop when a fused heading is available: ``r`` aims at the heading the previous
actions meant plus the angle, and up to three correcting turns follow while the fused heading is
off by more than the tolerance (the turn itself is open-loop: the floor's slip makes it ±10 %).
:class:`ActionNavigator` is the plan as one of main's navigators (its pilot drives the moves).

How main hosts it (``on_pc_request``)::

    if verb == "actions":
        actions = parse_actions(payload["text"], payload.get("name", "<actions>"), seed=self.seed)
        navigator = ActionNavigator(self.layout, actions, speed_pct=50, seed=self.seed)
        self.start(navigator, 1)  # stop_explore sends STOP while a non-queueing drive goes on
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tokenring import UsageError

MAX_SPEED_MM_S = 100.0  # 100 % = 10 cm/s, the start-stop limit
#: after a turn, wait this long at rest before judging it by the fused heading: the compass skips
#: readings while turning and its short mean lags, so the filter holds the turn's odometry (±10 %
#: slip) until a reading or two at rest came in (400 ms judged a 12° miss as on target)
SETTLE_MS = 1200
MAX_WHEELS_MS = 60_000  # one SET_WHEEL_SPEEDS lasts at most this long (duration_ms is u16)
#: the longest timed ``v``/``c`` action (an hour; main sends it as SET_WHEEL_SPEEDS of MAX_WHEELS_MS each)
MAX_ACTION_MS = 3_600_000
TRACK_HALF_WIDTH_MM = 6.5 * 0.5419 * 180.0 / math.pi  # track travel per radian of turn, glide 6.5
#: after a non-queueing SET_WHEEL_SPEEDS the next action waits until motor.data shows it running,
#: at most this long: the pilot takes the move number it sees as the old move's, and the wheels'
#: ABORTED would end its move at once if that were an older one (the seed's motor ignores wheels)
WHEELS_SEEN_MS = 1000

ARITY = {"e": 0, "s": 1, "r": 1, "v": 3, "c": 3}
#: seed 000 §6.7: ``v`` and ``c`` without the time are the non-queueing variants
SEED_ARITIES = {"e": (0,), "s": (1,), "r": (1,), "v": (2, 3), "c": (2, 3)}
SEED_USAGE = {
    "v": "v <left mm/s> <right mm/s> [<ms>] (no time: until the next action)",
    "c": "c <radius mm> <speed mm/s> [<ms>] (no time: until the next action)",
}
USAGE = {
    "e": "e",
    "s": "s <mm>",
    "r": "r <degrees>",
    "v": "v <left mm/s> <right mm/s> <ms>",
    "c": "c <radius mm> <speed mm/s> <ms>",
}


@dataclass(frozen=True)
class Action:
    """One line of an action file."""

    kind: str
    args: tuple[float, ...]
    line: int
    text: str

    @property
    def queued(self) -> bool:
        """False for the seed's non-queueing ``v``/``c`` (no time): they do not hold the file."""
        return not (self.kind in ("v", "c") and len(self.args) == 2)


def parse_actions(text: str, source: str = "<actions>", seed: bool = False) -> list[Action]:
    """Parse an action file's text; raises :class:`UsageError` naming ``source:line``.

    ``seed``: also accept the seed's non-queueing ``v``/``c`` without the time (seed 000 §6.7)."""
    actions: list[Action] = []
    # a Windows editor's byte-order mark is no action (the PC strips it; a text sent over the ring may not)
    for number, raw in enumerate(text.removeprefix("\ufeff").splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split()
        kind = fields[0]
        where = f"{source}:{number}"
        if kind not in ARITY:
            raise UsageError(f"{where}: unknown action {kind!r} (known: e, s, r, v, c, # comment)")
        if seed and len(fields) - 1 not in SEED_ARITIES[kind]:
            counts = " or ".join(str(n) for n in SEED_ARITIES[kind])
            usage = SEED_USAGE.get(kind, USAGE[kind])
            raise UsageError(f"{where}: {kind!r} takes {counts} values: {usage}")
        if not seed and len(fields) - 1 != ARITY[kind]:
            hint = (
                " (this runner queues every action: give the time)"
                if kind in "vc" and len(fields) == 3
                else ""
            )
            raise UsageError(f"{where}: {kind!r} takes {ARITY[kind]} values: {USAGE[kind]}{hint}")
        try:
            args = tuple(float(v) for v in fields[1:])
        except ValueError:
            usage = SEED_USAGE.get(kind, USAGE[kind]) if seed else USAGE[kind]
            raise UsageError(f"{where}: {usage}: values must be numbers, got {line!r}") from None
        if not all(math.isfinite(a) for a in args):
            raise UsageError(f"{where}: values must be finite numbers")
        _check(kind, args, where)
        actions.append(Action(kind, args, number, line))
    if not actions:
        raise UsageError(f"{source}: no actions (only blank lines and comments): nothing to drive")
    return actions


def load_actions(path: str | Path, seed: bool = False) -> list[Action]:
    """Read and parse an action file (``seed``: as :func:`parse_actions`)."""
    from tokenring import read_text

    file = Path(path)
    text = read_text(file, "action file")
    return parse_actions(text, str(file), seed)


def _check(kind: str, args: tuple[float, ...], where: str) -> None:
    if kind == "s" and not 1 <= abs(args[0]) <= 65535:
        raise UsageError(f"{where}: a straight move is 1..65535 mm (either sign), got {args[0]:g}")
    if kind == "r" and not 0 < abs(args[0]) <= 3600:
        raise UsageError(f"{where}: a turn is up to 3600 degrees (either sign, not 0), got {args[0]:g}")
    if kind in "vc" and len(args) == 3 and not 1 <= args[2] <= MAX_ACTION_MS:
        raise UsageError(f"{where}: the time must be positive, 1..{MAX_ACTION_MS} ms, got {args[2]:g} ms")
    if kind == "v":
        left, right = args[0], args[1]
        if max(abs(left), abs(right)) > MAX_SPEED_MM_S:
            raise UsageError(
                f"{where}: track speeds are at most {MAX_SPEED_MM_S:g} mm/s (start-stop, no ramps)"
            )
        if left == 0 and right == 0:
            raise UsageError(f"{where}: both track speeds are 0: nothing would move")
    if kind == "c":
        radius, speed = args[0], args[1]
        if radius == 0:
            raise UsageError(f"{where}: a circle's radius cannot be 0 (use r to turn on the spot)")
        left, right = circle_speeds(radius, speed)
        if max(abs(left), abs(right)) > MAX_SPEED_MM_S:
            raise UsageError(
                f"{where}: radius {radius:g} mm at {speed:g} mm/s needs a track at "
                f"{max(abs(left), abs(right)):.0f} mm/s; at most {MAX_SPEED_MM_S:g}"
            )
        if round(left) == 0 and round(right) == 0:
            raise UsageError(f"{where}: speed 0: nothing would move")


def circle_speeds(radius_mm: float, speed_mm_s: float) -> tuple[float, float]:
    """Left and right track speeds (mm/s) for a circle of ``radius_mm`` (+ left) at ``speed_mm_s``."""
    b = TRACK_HALF_WIDTH_MM
    return speed_mm_s * (1.0 - b / radius_mm), speed_mm_s * (1.0 + b / radius_mm)


# =============================================================================================
# the plan: one step at a time


@dataclass(frozen=True)
class Drive:
    """A move for the pilot / motor: ``direction`` forward, reverse, left, right; mm or degrees."""

    direction: str
    amount: int
    speed_pct: int
    label: str = ""


@dataclass(frozen=True)
class Wheels:
    """SET_WHEEL_SPEEDS: both tracks in % (100 % = 100 mm/s) for ``duration_ms``."""

    left_pct: int
    right_pct: int
    duration_ms: int
    label: str = ""


@dataclass(frozen=True)
class MotorsOn:
    """The seed's ``e`` (seed 000 §6.7, "Motoren an"): MOTORS_ON to the motor."""

    label: str = ""


WAIT = "wait"  # nothing to start now: ask again at the next step


class ActionPlan:
    """The actions as a sequence of steps; ``next()`` is called whenever the previous step ended."""

    def __init__(
        self,
        actions: list[Action],
        speed_pct: int = 50,
        turn_tolerance_deg: float = 0.6,
        max_corrections: int = 3,
        settle_ms: int = SETTLE_MS,
        start_heading: float | None = None,
        seed: bool = False,
    ) -> None:
        """``start_heading`` (rad, CCW): square up to it before the first action, as after an
        ``r`` (the compass's calibration turn ends a few degrees off where it began); ``seed``:
        the seed's non-queueing ``v``/``c`` without a time (seed 000 §6.7)."""
        if not 1 <= speed_pct <= 100:
            raise UsageError(f"action speed must be 1..100 %, got {speed_pct}")
        self.actions = actions
        self.speed_pct = speed_pct
        self.tolerance = math.radians(turn_tolerance_deg)
        self.max_corrections = max_corrections
        self.settle_ms = settle_ms
        self.index = 0
        self.target: float | None = start_heading  # the heading the actions so far meant (rad, CCW)
        self.checking = start_heading is not None
        self.corrections = 0
        self.settle_until: int | None = None
        self.wheels_until: int | None = None
        self.pending_wheels: list[Wheels] = []
        self.done_actions = 0
        self.corrections_total = 0
        self.current: Action | None = None
        self.active: Drive | None = None  # the drive handed out last
        self.resume: list[Drive] = []  # the rest of an interrupted drive, before anything else
        self.interruptions = 0
        self.seed = seed
        #: the seed's non-queueing ``v``/``c`` that runs until the next driving action, and when
        #: its current piece ends (the last one of the file is renewed until main is stopped)
        self.holding: Wheels | None = None
        self.hold_until = 0
        self.seen_until: int | None = None  # waiting for motor.data to show the held wheels

    @property
    def finished(self) -> bool:
        return (
            self.index >= len(self.actions)
            and not self.checking
            and not self.resume
            and not self.pending_wheels
            and self.wheels_until is None
            and self.holding is None
        )

    def next(
        self, heading: float | None, now_ms: int, motor_idle: bool = True
    ) -> Drive | Wheels | MotorsOn | str | None:
        """The next step: a :class:`Drive`, :class:`Wheels`, :class:`MotorsOn`, :data:`WAIT`, or
        None when done.

        ``heading``: the fused heading (rad, CCW; None: no closed loop); ``now_ms``: simulated
        time (the motor's stamp); ``motor_idle``: the motor stands still."""
        if self.seen_until is not None:
            if motor_idle and now_ms < self.seen_until:
                return WAIT
            self.seen_until = None
        if self.wheels_until is not None:
            if now_ms < self.wheels_until or not motor_idle:
                return WAIT
            self.wheels_until = None
        if self.pending_wheels:
            step = self.pending_wheels.pop(0)
            self.wheels_until = now_ms + step.duration_ms
            return step
        if self.resume:
            return self._hand_out(self.resume.pop(0))
        if self.checking:
            step = self._check_turn(heading, now_ms)
            if step is not None:
                return step if step == WAIT else self._hand_out(step)
        while self.index < len(self.actions):
            action = self.actions[self.index]
            self.index += 1
            self.current = action
            self.done_actions += 1
            step = self._start(action, heading, now_ms)
            if step is not None:
                return self._hand_out(step) if isinstance(step, Drive) else step
        if self.holding is not None:  # the file ended on a non-queueing drive: it goes on
            if now_ms < self.hold_until or not motor_idle:
                return WAIT
            self.hold_until = now_ms + self.holding.duration_ms
            return self.holding
        return None

    def _hand_out(self, step: Drive) -> Drive:
        self.active = step
        return step

    def interrupted(self, done: int, escape: Drive | None = None) -> None:
        """The last drive ended early after ``done`` mm or degrees (a transient abort): finish it
        after ``escape`` (the small move the pilot's ALERT lock allows), which is undone as well."""
        step = self.active
        self.interruptions += 1
        if step is None:
            return
        opposite = {"forward": "reverse", "reverse": "forward", "left": "right", "right": "left"}
        straight = step.direction in ("forward", "reverse")
        rest = step.amount - max(0, done)
        if escape is not None:
            if (escape.direction in ("forward", "reverse")) == straight:
                rest += escape.amount if escape.direction == opposite[step.direction] else -escape.amount
            else:  # an escape of the other kind (a turn out of a straight move): undo it first
                self.resume.append(
                    Drive(opposite[escape.direction], escape.amount, step.speed_pct, "undo escape")
                )
        if not straight and self.target is not None:
            self.checking, self.corrections, self.settle_until = True, 0, None  # the loop turns the rest
            return
        if rest >= 1:
            self.resume.append(Drive(step.direction, int(rest), step.speed_pct, f"{step.label} (rest)"))

    def _check_turn(self, heading: float | None, now_ms: int) -> Drive | str | None:
        if heading is None or self.target is None:
            self.checking = False
            return None
        if self.settle_until is None:
            self.settle_until = now_ms + self.settle_ms
        if now_ms < self.settle_until:
            return WAIT
        self.settle_until = None
        error = math.degrees(math.remainder(self.target - heading, 2 * math.pi))
        degrees = round(abs(error))
        if (
            abs(math.radians(error)) <= self.tolerance
            or degrees == 0
            or self.corrections >= self.max_corrections
        ):
            self.checking = False
            return None
        self.corrections += 1
        self.corrections_total += 1
        return Drive(
            "left" if error > 0 else "right", degrees, self.speed_pct, label=f"correct {error:+.1f}°"
        )

    def _start(self, action: Action, heading: float | None, now_ms: int) -> Drive | Wheels | MotorsOn | None:
        label = f"line {action.line}: {action.text}"
        if action.kind == "e":
            return MotorsOn(label)
        self.holding = None  # seed §6.7: a non-queueing drive ends when the next one starts
        if action.kind == "s":
            mm = action.args[0]
            return Drive("forward" if mm > 0 else "reverse", round(abs(mm)), self.speed_pct, label)
        if action.kind == "r":
            degrees = action.args[0]
            if heading is not None:
                base = self.target if self.target is not None else heading
                self.target = base + math.radians(degrees)
                self.checking, self.corrections, self.settle_until = True, 0, None
            return Drive("left" if degrees > 0 else "right", round(abs(degrees)), self.speed_pct, label)
        if action.kind == "v":
            left, right = action.args[0], action.args[1]
        else:
            left, right = circle_speeds(action.args[0], action.args[1])
        self.target = None  # a free drive: the heading it ends in is whatever it is
        if not action.queued:  # seed §6.7: started at once, the next action does not wait for it
            self.holding = Wheels(round(left), round(right), MAX_WHEELS_MS, label)
            self.hold_until, self.seen_until = now_ms + MAX_WHEELS_MS, now_ms + WHEELS_SEEN_MS
            return self.holding
        ms = action.args[2]
        total = round(ms)
        pieces = []
        while total > 0:
            part = min(total, MAX_WHEELS_MS)
            pieces.append(Wheels(round(left), round(right), part, label))
            total -= part
        first, self.pending_wheels = pieces[0], pieces[1:]
        self.wheels_until = now_ms + first.duration_ms
        return first

    def append(self, actions: list[Action]) -> None:
        """Queue more actions behind the ones not yet started (seed 000 §6.7: queueing actions)."""
        self.actions.extend(actions)

    def queue(self) -> list[str]:
        """The action under way (while it runs) and those still waiting, as their files wrote them."""
        running = [self.current.text] if self.current is not None and not self.finished else []
        return running + [a.text for a in self.actions[self.index :]]

    def progress(self) -> dict[str, Any]:
        return {
            "actions": len(self.actions),
            "done": self.done_actions,
            "line": self.current.line if self.current else 0,
            "corrections": self.corrections_total,
            "finished": self.finished,
        }


# =============================================================================================
# main's side: the plan as a navigator


def _navigator_base() -> type:
    from modules.navigation.navigator import Navigator

    return Navigator


class ActionNavigator(_navigator_base()):  # type: ignore[misc]
    """The action plan as one of main's navigators: the pilot drives, the copro pose closes turns.

    Its straight moves keep clear of what the sonars showed (the pilot's clearance): a drive
    toward a wall stops outside the ALERT area, CLOSE/clearance.

    A transient abort (a spurious ALERT echo, CLOSE, a timeout) does not end the file: the pilot's
    ALERT lock is honoured with the small escape move it allows, then the interrupted drive is
    finished (turns by the closed loop); after :attr:`MAX_RETRIES` such aborts, or on a
    collision or stall, the file is given up.
    """

    keeps_clear = True
    powers_the_drive = False  # its e does, as the seed's files did (§6.7)

    mode = 0
    MAX_RETRIES = 5
    TURN_MM_PER_DEG = TRACK_HALF_WIDTH_MM * math.pi / 180.0  # track travel per degree turned

    def __init__(
        self,
        layout: Any,
        actions: list[Action],
        speed_pct: int = 50,
        closed_loop: bool = True,
        start_heading: float | None = None,
        seed: bool = False,
    ) -> None:
        from modules.navigation.navigator import NAV

        super().__init__(layout)
        self.plan_steps = ActionPlan(
            actions, speed_pct, start_heading=start_heading if closed_loop else None, seed=seed
        )
        self.closed_loop = closed_loop
        self.state = NAV["ACTIONS"]
        self._nav = NAV
        self.retries = 0

    def plan(self, last: Any, sensors: Any, alert_lock: int) -> list[Any] | None:
        from modules.navigation.pilot import (
            FORWARD,
            MOTOR_STATE,
            REASON,
            REVERSE,
            TURN_LEFT,
            TURN_RIGHT,
            Move,
        )

        names = {FORWARD: "forward", REVERSE: "reverse", TURN_LEFT: "left", TURN_RIGHT: "right"}
        codes = {name: code for code, name in names.items()}
        if last is not None and last.reason != REASON["DONE"]:
            transient = last.reason in (REASON["ALERT"], REASON["CLOSE"], REASON["TIMEOUT"])
            if not transient or self.retries >= self.MAX_RETRIES:
                self.note = f"action file aborted: {last.reason_name} ({last.trigger})"
                self.state = self._nav["DONE"]
                return None
            self.retries += 1
            escape = self.escape(alert_lock) if last.reason == REASON["ALERT"] else []
            active = self.plan_steps.active
            turning = active is not None and active.direction in ("left", "right")
            done = round(last.driven_mm / self.TURN_MM_PER_DEG) if turning else last.driven_mm
            speed = active.speed_pct if active is not None else self.plan_steps.speed_pct
            undo = Drive(names[escape[0].direction], int(escape[0].amount), speed) if escape else None
            self.plan_steps.interrupted(done, undo)
            if escape:
                return escape
        heading = sensors.pose[2] if self.closed_loop and sensors.pose is not None else None
        idle = sensors.motor_state == MOTOR_STATE["IDLE"]
        step = self.plan_steps.next(heading, sensors.stamp_ms, idle)
        if step is None:
            self.note = "action file done"
            self.state = self._nav["DONE"]
            return None
        if step == WAIT:
            return []
        self.steps += 1
        if isinstance(step, MotorsOn):
            self.commands.append(("motor", "MOTORS_ON", {}))
            return []
        if isinstance(step, Wheels):
            args = {"left_pct": step.left_pct, "right_pct": step.right_pct, "duration_ms": step.duration_ms}
            self.commands.append(("motor", "SET_WHEEL_SPEEDS", args))
            return []
        return [Move(codes[step.direction], step.amount, step.speed_pct, label=step.label)]
