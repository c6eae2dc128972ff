"""The Darmstadt program's keys (seed 000 table 8.2) and its ActionHandler (§6.7), for the operator's
console and the web view alike.

=========  ===================================================================================
key        what it does
=========  ===================================================================================
a, b, c    queue the first, second, third action file (``[ACTION]`` of the seed's configuration)
d          motors off: the queue is cleared, the drive unpowered (moves are refused until ``e``)
e          motors on
x, q       quit
space      stop at once: the move under way ends, every queued command is cleared
↑, ↓       accelerate, brake (25 mm/s a press, as Saphira's keys; below 0 the robot backs up)
←, →       turn left, right (10 °/s a press, added to the drive as a curve)
k          queue a circle (radius 500 mm at 50 mm/s)
s          queue a square (four legs of 1 m, turning left)
=========  ===================================================================================

Queueing and non-queueing, as the seed's ActionHandler had it: ``a``/``b``/``c``/``k``/``s`` queue
their drives behind those under way (main's action runner, ``actions`` with ``append``); the
others act at once, and a move key or the space bar clears the queue first. The arrows drive both
tracks at the held speeds: a dead-man, SET_WHEEL_SPEEDS for :data:`HOLD_MS` renewed every
:data:`RENEW_AFTER_S` by :meth:`Operator.keep_alive` while its holder lives, so a console or web
view that dies without a word leaves the robot standing within the hold. Quitting calls
:meth:`Operator.release`: what the keys started stops. Everything reaches the robot through
main's PC link, as ``tokenring drive`` does; an answer that does not come is reported on the
screen, never raised.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tokenring import TokenRingError, UsageError

#: Saphira's keyboard drive steps (ARIA's ArActionKeydrive: 25 mm/s a press), within the robot's
#: start-stop limit of 100 mm/s; a turn key adds this much rate of turn
SPEED_STEP_MM_S = 25.0
TURN_STEP_DEG_S = 10.0
MAX_TRACK_MM_S = 100.0
MAX_TURN_DEG_S = 30.0
#: one SET_WHEEL_SPEEDS of the held speed lasts this long, and is renewed this often: a renewal
#: may take four of the five seconds to reach the motor before the robot stops (with two, a
#: renewal on a loaded machine came too late now and then and the robot stood)
HOLD_MS = 5_000
RENEW_AFTER_S = 1.0
#: how long d and e wait for the motor's state to show them (a loaded ring takes a few rounds)
CONFIRM_S = 5.0
#: what ``k`` and ``s`` queue (action-file lines, table B.4)
CIRCLE_RADIUS_MM, CIRCLE_SPEED_MM_S = 500, 50
SQUARE_SIDE_MM = 1000
#: the speed of queued drives (% of 10 cm/s)
ACTION_SPEED_PCT = 50


@dataclass(frozen=True)
class Key:
    """One key of table 8.2: its name (as :func:`key_name` gives it), how it is shown, its meaning."""

    name: str
    label: str
    meaning: str


KEYS: tuple[Key, ...] = (
    Key("a", "a", "run the first action file"),
    Key("b", "b", "run the second action file"),
    Key("c", "c", "run the third action file"),
    Key("d", "d", "motors off"),
    Key("e", "e", "motors on"),
    Key("x", "x", "quit"),
    Key("q", "q", "quit"),
    Key("space", "space", "stop the robot, clear the queue"),
    Key("up", "↑", "accelerate"),
    Key("down", "↓", "brake"),
    Key("left", "←", "left"),
    Key("right", "→", "right"),
    Key("k", "k", "drive a circle"),
    Key("s", "s", "drive a square"),
)
KEY_NAMES = tuple(k.name for k in KEYS)
KEY_LABELS = " ".join(k.label for k in KEYS)
#: what a browser's ``KeyboardEvent.key`` and a terminal library call the keys, where they differ
_ALIASES = {
    " ": "space",
    "Space": "space",
    "ArrowUp": "up",
    "ArrowDown": "down",
    "ArrowLeft": "left",
    "ArrowRight": "right",
}


def key_name(raw: str) -> str:
    """The key's name in :data:`KEYS` (browser and terminal spellings alike; letters lower-cased)."""
    name = _ALIASES.get(raw, raw)
    return name.lower() if len(name) == 1 else name


def keys_help() -> str:
    """The keys in one line, as the screen shows them."""
    return "  ".join(f"{k.label} {k.meaning}" for k in KEYS if k.name != "q").replace("x quit", "x/q quit")


@dataclass(frozen=True)
class Outcome:
    """What a key did, in one line for the screen; ``ok`` False: it did nothing (and why)."""

    key: str
    text: str
    ok: bool = True
    quit: bool = False


def circle_text() -> str:
    """``k``: one full circle to the left, as an action-file line."""
    ms = round(2 * math.pi * CIRCLE_RADIUS_MM / CIRCLE_SPEED_MM_S * 1000)
    return f"c {CIRCLE_RADIUS_MM} {CIRCLE_SPEED_MM_S} {ms}\n"


def square_text() -> str:
    """``s``: a square of four 1 m legs, turning left, as action-file lines."""
    return f"s {SQUARE_SIDE_MM}\nr 90\n" * 4


def track_speeds(speed_mm_s: float, turn_deg_s: float) -> tuple[int, int]:
    """Left and right track speeds in % (1 % = 1 mm/s) for a speed and a rate of turn."""
    from modules.navigation.actions import TRACK_HALF_WIDTH_MM

    differential = math.radians(turn_deg_s) * TRACK_HALF_WIDTH_MM
    left, right = speed_mm_s - differential, speed_mm_s + differential
    scale = max(1.0, abs(left) / MAX_TRACK_MM_S, abs(right) / MAX_TRACK_MM_S)
    return round(left / scale), round(right / scale)


class Operator:
    """Table 8.2's keys on a ring, through main's PC link (a :class:`tokenring.host.PcLink`).

    ``action_files``: the three files bound to ``a``, ``b``, ``c`` (None: unbound); they are read
    when their key is pressed, so an edit between two runs counts."""

    def __init__(self, link: Any, action_files: Sequence[str | Path | None] = (), seed: bool = False) -> None:
        self.link = link
        files = list(action_files)[:3]
        self.action_files: list[Path | None] = [
            Path(f) if f else None for f in files + [None] * (3 - len(files))
        ]
        self.seed = seed
        self.speed_mm_s = 0.0
        self.turn_deg_s = 0.0
        self.clock = time.monotonic
        self.held_since: float | None = None  # when the held speed's last sending began
        self.held_until = 0.0  # when the last hold the motor took runs out, at the latest
        self.queued = False  # this operator's keys queued drives (not stopped since)

    # -- keys ----------------------------------------------------------------------------------
    def press(self, raw: str) -> Outcome:
        """Carry out one key; every failure comes back as an :class:`Outcome` with ``ok`` False."""
        key = key_name(raw)
        if key not in KEY_NAMES:
            shown = raw if raw.isprintable() and raw.strip() else repr(raw)
            return Outcome(key, f"key {shown} means nothing here (the keys: {KEY_LABELS})", ok=False)
        if key in ("x", "q"):
            return Outcome(key, "quit", quit=True)
        try:
            return self._press(key)
        except (TokenRingError, UsageError) as exc:
            return Outcome(key, f"{key}: {exc}", ok=False)

    def _press(self, key: str) -> Outcome:
        if key == "space":
            self._stop()
            return Outcome(key, "stopped; the queue is cleared")
        if key == "d":
            self._clear_queue()
            self._drop_hold()
            self._motor("MOTORS_OFF")
            if not self._motor_state_is_off(True):
                return Outcome(key, "motors off sent; the motor has not confirmed it yet", ok=False)
            return Outcome(key, "motors off: moves are refused until e")
        if key == "e":
            self._motor("MOTORS_ON")
            if not self._motor_state_is_off(False):
                return Outcome(key, "motors on sent; the motor has not confirmed it yet", ok=False)
            return Outcome(key, "motors on")
        if key in ("up", "down", "left", "right"):
            return self._steer(key)
        if key in ("a", "b", "c"):
            file = self.action_files["abc".index(key)]
            if file is None:
                return Outcome(
                    key, f"no action file is bound to {key} ([ACTION] of the configuration)", ok=False
                )
            from tokenring import read_text

            return self._queue(key, read_text(file, "action file"), str(file))
        if key == "k":
            return self._queue(key, circle_text(), "k: circle")
        return self._queue(key, square_text(), "s: square")

    def _steer(self, key: str) -> Outcome:
        if key == "up":
            self.speed_mm_s = min(MAX_TRACK_MM_S, self.speed_mm_s + SPEED_STEP_MM_S)
        elif key == "down":
            self.speed_mm_s = max(-MAX_TRACK_MM_S, self.speed_mm_s - SPEED_STEP_MM_S)
        elif key == "left":
            self.turn_deg_s = min(MAX_TURN_DEG_S, self.turn_deg_s + TURN_STEP_DEG_S)
        else:
            self.turn_deg_s = max(-MAX_TURN_DEG_S, self.turn_deg_s - TURN_STEP_DEG_S)
        self._clear_queue()
        refused = self._motors_off()
        self._send_held()
        drive = f"speed {self.speed_mm_s:+.0f} mm/s, turn {self.turn_deg_s:+.0f} °/s"
        if refused:
            self._drop_hold()  # the motor refuses it: nothing to renew, and e starts from rest
            return Outcome(key, f"{drive}: refused, the motors are off (press e)", ok=False)
        return Outcome(key, drive)

    def keep_alive(self) -> Outcome | None:
        """Renew the held speed every :data:`RENEW_AFTER_S` (call it several times a second while
        the holder lives). A hold that ran out before a renewal reached the motor is forgotten
        (the robot stood; it does not start again by itself): that is said, otherwise None."""
        if self.held_since is None or self.clock() - self.held_since < RENEW_AFTER_S:
            return None
        if self.clock() >= self.held_until:
            return self._lapsed("not renewed in time")
        try:
            self._send_held()
            return None
        except (TokenRingError, UsageError) as exc:
            if self.clock() < self.held_until:
                return None  # tried again at the next call, the hold still runs
            return self._lapsed(str(exc))

    def _lapsed(self, why: str) -> Outcome:
        self._drop_hold()
        return Outcome(
            "hold", f"the held speed ran out ({why}): the robot stopped; ↑ ↓ drive again", ok=False
        )

    def release(self) -> Outcome | None:
        """Stop what this operator's keys keep going (a held speed, a queue of drives), as space
        does; None when nothing is. Called when its console quits or the last web page closes."""
        held = self.held_since is not None
        try:
            if not held and not (self.queued and self._queue_runs()):
                self.queued = False
                return None
            self._stop()
        except (TokenRingError, UsageError) as exc:
            self._drop_hold()
            self.queued = False
            why = f"its held speed runs out within {HOLD_MS / 1000:.0f} s" if held else "its queue runs on"
            return Outcome("release", f"could not stop the robot ({exc}); {why}", ok=False)
        return Outcome(
            "release", "stopped the robot" + (", its held speed ended" if held else ", its queue cleared")
        )

    def _stop(self) -> None:
        """Space: the queue cleared, the motor stopped, nothing held."""
        self._clear_queue()
        self._motor("STOP")
        self._drop_hold()
        self.queued = False

    def _drop_hold(self) -> None:
        self.speed_mm_s = self.turn_deg_s = 0.0
        self.held_since = None

    def _send_held(self) -> None:
        left, right = track_speeds(self.speed_mm_s, self.turn_deg_s)
        if left == 0 and right == 0:
            self._motor("STOP")
            self.held_since = None
            return
        self.held_since = self.clock()  # a failed renewal is retried at the next call, not at once
        self._motor(
            "SET_WHEEL_SPEEDS", left_pct=left, right_pct=right, duration_ms=HOLD_MS, timeout=HOLD_MS / 1000
        )
        self.held_until = self.clock() + HOLD_MS / 1000

    def _queue(self, key: str, text: str, name: str) -> Outcome:
        from modules.navigation.actions import parse_actions

        actions = parse_actions(text, name, seed=self.seed)  # a bad file is named here, nothing sent
        if self.held_since is not None:  # a queued drive starts from rest, not inside a held one
            self._motor("STOP")
            self._drop_hold()
        state = self.link.request("actions", text=text, name=name, append=True, speed_pct=ACTION_SPEED_PCT)
        self.queued = True
        waiting = len(state.get("queue") or ()) if isinstance(state, dict) else len(actions)
        return Outcome(key, f"queued {Path(name).name} ({len(actions)} actions; {waiting} waiting)")

    # -- the link --------------------------------------------------------------------------------
    def _clear_queue(self) -> None:
        """The seed's non-queueing actions clear the list first: main's runner stops, if it runs."""
        state = self.link.request("state")
        if isinstance(state, dict) and state.get("running"):
            self.link.request("stop")

    def _queue_runs(self) -> bool:
        """main runs an action file with actions still to do (not an exploration)."""
        state = self.link.request("state")
        return isinstance(state, dict) and bool(state.get("running")) and bool(state.get("queue"))

    def _motors_off(self) -> bool:
        from tokenring import default_protocol

        off = default_protocol().enums["motor_state"].get("OFF")
        return off is not None and self.link.read("motor.data").get("state") == off

    def _motor_state_is_off(self, off: bool) -> bool:
        """Wait until main's copy of motor.data shows the motors off (or on): the command was
        acknowledged into the motor's inbox, its state follows a visit or two later, and what
        the screen says next (a move refused or not) must not race it."""
        deadline = time.monotonic() + CONFIRM_S
        while self._motors_off() != off:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True

    def _motor(self, name: str, timeout: float = 5.0, **args: Any) -> None:
        reply = self.link.command("motor", name, timeout=timeout, **args)
        if not reply.get("acknowledged"):
            raise TokenRingError(f"the motor did not take {name} (transmitted: {reply.get('transmitted')})")
