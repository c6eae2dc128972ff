"""The seed's keys (table 8.2) as the operator carries them out: what reaches main's PC link, in
which order, and what the screen is told; the held speed's dead-man (short holds renewed while
the holder lives) and the release when it quits. The link is a recorder, the clock a counter;
the ring test is tests/robot/pc/test_console_tmux.py."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from modules.pc.operator import (
    HOLD_MS,
    KEYS,
    RENEW_AFTER_S,
    Operator,
    circle_text,
    key_name,
    square_text,
    track_speeds,
)
from tokenring import TransportError, default_protocol


class Link:
    """Records the PC link's calls; main's state says a navigator runs while ``running``."""

    def __init__(self, running: bool = False, motor_state: int = 0) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.running = running
        self.motor_state = motor_state
        self.fail: Exception | None = None

    def command(self, target: str, name: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        if self.fail:
            raise self.fail
        self.calls.append(("command", target, name, args))
        if name in ("MOTORS_OFF", "MOTORS_ON"):  # the motor's state follows, as on the ring
            self.motor_state = default_protocol().enums["motor_state"]["OFF"] if name == "MOTORS_OFF" else 0
        return {"transmitted": True, "acknowledged": True}

    def request(self, verb: str, **payload: Any) -> dict[str, Any]:
        if self.fail:
            raise self.fail
        self.calls.append(("request", verb, payload))
        if verb == "stop":
            self.running = False
        if verb == "actions":
            self.running = True
        return {"running": self.running, "queue": ["s 1000"] if self.running else []}

    def read(self, channel: str) -> dict[str, Any]:
        return {"state": self.motor_state}

    def commands(self) -> list[tuple[str, dict[str, Any]]]:
        return [(c[2], c[3]) for c in self.calls if c[0] == "command"]

    def verbs(self) -> list[str]:
        return [c[1] for c in self.calls if c[0] == "request"]


def test_the_keys_are_table_8_2() -> None:
    assert [k.name for k in KEYS] == [
        "a", "b", "c", "d", "e", "x", "q", "space", "up", "down", "left", "right", "k", "s",
    ]  # fmt: skip
    assert [key_name(k) for k in ("ArrowUp", " ", "ArrowLeft", "A", "up")] == [
        "up",
        "space",
        "left",
        "a",
        "up",
    ]


def test_e_and_d_switch_the_motors_and_d_clears_the_queue_first() -> None:
    link = Link(running=True)
    operator = Operator(link)
    assert operator.press("e").text == "motors on"
    assert link.commands() == [("MOTORS_ON", {})]
    outcome = operator.press("d")
    assert outcome.ok and "motors off" in outcome.text
    assert link.verbs()[-1] == "stop" and link.commands()[-1] == ("MOTORS_OFF", {})


def test_arrows_accelerate_brake_and_turn_as_a_curve() -> None:
    link = Link()
    operator = Operator(link)
    operator.press("up")
    operator.press("ArrowUp")
    assert link.commands()[-1] == (
        "SET_WHEEL_SPEEDS",
        {"left_pct": 50, "right_pct": 50, "duration_ms": HOLD_MS},
    )
    operator.press("left")
    name, args = link.commands()[-1]
    assert name == "SET_WHEEL_SPEEDS" and args["right_pct"] > 50 > args["left_pct"]
    assert args["left_pct"] + args["right_pct"] == 100  # the speed held, a turn added
    operator.press("right")
    operator.press("down")
    operator.press("down")
    assert link.commands()[-1] == ("STOP", {})  # both at 0: nothing held
    operator.press("down")
    assert link.commands()[-1][1]["left_pct"] == -25  # below 0 the robot backs up


def test_track_speeds_stay_within_the_start_stop_limit() -> None:
    for speed in (-100.0, 0.0, 100.0):
        for turn in (-30.0, 30.0):
            left, right = track_speeds(speed, turn)
            assert max(abs(left), abs(right)) <= 100


def test_space_stops_and_clears_the_queue() -> None:
    link = Link(running=True)
    operator = Operator(link)
    operator.press("up")
    outcome = operator.press("space")
    assert outcome.ok and "cleared" in outcome.text
    assert link.commands()[-1] == ("STOP", {}) and "stop" in link.verbs()
    operator.press("up")
    assert link.commands()[-1][1]["left_pct"] == 25  # the held speed started again from 0


def test_k_s_and_action_files_queue_behind_what_runs(tmp_path: Path) -> None:
    file = tmp_path / "a.act"
    file.write_text("# a short leg\ns 300\nr -45\n")
    link = Link()
    operator = Operator(link, [file, None])
    for key in ("a", "s", "k"):
        assert operator.press(key).ok
    sent = [c[2] for c in link.calls if c[:2] == ("request", "actions")]
    assert [p["append"] for p in sent] == [True, True, True]
    assert sent[0]["text"] == file.read_text() and sent[0]["name"] == str(file)
    assert sent[1]["text"] == square_text() and sent[2]["text"] == circle_text()
    assert square_text().count("r 90") == 4
    unbound = operator.press("b")
    assert not unbound.ok and "no action file is bound to b" in unbound.text


def test_a_queued_drive_starts_from_rest_not_inside_a_held_speed(tmp_path: Path) -> None:
    link = Link()
    operator = Operator(link)
    operator.press("up")
    operator.press("s")
    assert link.commands()[-1] == ("STOP", {})
    assert operator.speed_mm_s == 0


def test_a_bad_action_file_is_named_and_nothing_is_sent(tmp_path: Path) -> None:
    file = tmp_path / "bad.act"
    file.write_text("s 300\nfly 3\n")
    link = Link()
    outcome = Operator(link, [file]).press("a")
    assert not outcome.ok and f"{file}:2" in outcome.text and "unknown action 'fly'" in outcome.text
    assert "actions" not in link.verbs()


def test_moves_with_the_motors_off_say_why() -> None:
    from tokenring import default_protocol

    off = default_protocol().enums["motor_state"].get("OFF")
    if off is None:
        pytest.fail("protocol.yaml's motor_state has no OFF: the motors cannot be switched off")
    outcome = Operator(Link(motor_state=off)).press("up")
    assert not outcome.ok and "motors are off (press e)" in outcome.text


@pytest.mark.parametrize("key", ["z", "F1", "escape", "\x07"])
def test_a_key_that_means_nothing_says_so(key: str) -> None:
    link = Link()
    outcome = Operator(link).press(key)
    assert not outcome.ok and "means nothing" in outcome.text and "\n" not in outcome.text
    assert link.calls == []


def test_quit_keys_do_not_touch_the_ring() -> None:
    link = Link()
    assert Operator(link).press("x").quit and Operator(link).press("Q").quit
    assert link.calls == []


def test_an_unanswered_link_is_a_line_on_the_screen_not_a_traceback() -> None:
    link = Link()
    link.fail = TransportError("main did not answer on the PC link of ring 'r'")
    outcome = Operator(link).press("e")
    assert not outcome.ok and outcome.text == "e: main did not answer on the PC link of ring 'r'"


def test_d_says_so_when_the_motor_never_shows_its_motors_off(monkeypatch: pytest.MonkeyPatch) -> None:
    class DeafMotor(Link):
        def command(self, target: str, name: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
            self.calls.append(("command", target, name, args))
            return {"transmitted": True, "acknowledged": True}  # taken, its state never follows

    monkeypatch.setattr("modules.pc.operator.CONFIRM_S", 0.2)
    outcome = Operator(DeafMotor()).press("d")
    assert not outcome.ok and "not confirmed" in outcome.text


class Clock:
    """time.monotonic as the test sets it."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def driving(link: Link | None = None) -> tuple[Operator, Link, Clock]:
    """An operator that held 50 mm/s a moment ago, on a clock of the test's."""
    link = link or Link()
    operator = Operator(link)
    operator.clock = clock = Clock()
    operator.press("up")
    operator.press("up")
    return operator, link, clock


def wheels(link: Link) -> int:
    return sum(name == "SET_WHEEL_SPEEDS" for name, _ in link.commands())


def test_the_hold_is_a_dead_man_short_and_renewed_every_second_while_called() -> None:
    assert HOLD_MS / 1000 >= 3 * RENEW_AFTER_S  # two renewals may fail or be late before it stops
    operator, link, clock = driving()
    assert wheels(link) == 2
    clock.t += RENEW_AFTER_S / 2
    assert operator.keep_alive() is None and wheels(link) == 2  # not yet
    for _ in range(5):
        clock.t += RENEW_AFTER_S / 2
        operator.keep_alive()
    assert wheels(link) == 2 + 3  # three seconds, six calls: every second, not every call
    assert link.commands()[-1] == (
        "SET_WHEEL_SPEEDS",
        {"left_pct": 50, "right_pct": 50, "duration_ms": HOLD_MS},
    )


def test_a_failed_renewal_is_retried_while_the_hold_runs_then_the_hold_is_forgotten() -> None:
    operator, link, clock = driving()
    link.fail = TransportError("main did not answer")
    clock.t += RENEW_AFTER_S
    assert operator.keep_alive() is None  # the hold still runs: tried again at the next call
    clock.t += HOLD_MS / 1000
    lapsed = operator.keep_alive()
    assert lapsed is not None and not lapsed.ok and "the robot stopped" in lapsed.text
    link.fail = None
    clock.t += 10 * RENEW_AFTER_S
    assert operator.keep_alive() is None and wheels(link) == 2  # it does not start again by itself
    assert operator.press("up").text.startswith("speed +25 mm/s")  # from rest


def test_a_holder_silent_longer_than_the_hold_does_not_restart_the_robot() -> None:
    operator, link, clock = driving()
    clock.t += HOLD_MS / 1000 + 1  # nobody called keep_alive (a page gone, a frozen screen)
    lapsed = operator.keep_alive()
    assert lapsed is not None and "not renewed in time" in lapsed.text
    assert wheels(link) == 2 and operator.speed_mm_s == 0


def test_release_stops_a_held_speed_as_space_does() -> None:
    operator, link, _ = driving(Link(running=False))
    outcome = operator.release()
    assert outcome is not None and outcome.ok and outcome.text == "stopped the robot, its held speed ended"
    assert link.commands()[-1] == ("STOP", {}) and operator.speed_mm_s == 0
    calls = len(link.calls)
    assert operator.release() is None and len(link.calls) == calls  # nothing held any more


def test_release_stops_the_queue_this_operator_started_only_while_it_runs(tmp_path: Path) -> None:
    link = Link()
    assert Operator(link).release() is None and link.calls == []  # nothing started: nothing asked
    operator = Operator(link)
    operator.press("s")
    outcome = operator.release()
    assert outcome is not None and outcome.text == "stopped the robot, its queue cleared"
    assert link.verbs()[-2:] == ["state", "stop"] and link.commands()[-1] == ("STOP", {})
    operator.press("k")
    link.running = False  # the circle was driven to its end meanwhile
    calls = len(link.commands())
    assert operator.release() is None and len(link.commands()) == calls and link.verbs()[-1] == "state"


def test_release_on_a_ring_that_is_gone_says_so_and_raises_nothing() -> None:
    operator, link, _ = driving()
    link.fail = TransportError("main did not answer on the PC link of ring 'r'")
    outcome = operator.release()
    assert outcome is not None and not outcome.ok
    assert (
        "could not stop the robot" in outcome.text and f"runs out within {HOLD_MS // 1000} s" in outcome.text
    )


def test_a_key_that_means_nothing_lists_the_keys() -> None:
    text = Operator(Link()).press("z").text
    assert text == "key z means nothing here (the keys: a b c d e x q space ↑ ↓ ← → k s)"
