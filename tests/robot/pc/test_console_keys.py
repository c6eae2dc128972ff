"""The console's key thread and its ends (modules/pc/console/keys.py, plain.py): the held speed is
renewed between keys however fast they come, quitting stops what the keys left driving, a signal
(SIGTERM, SIGHUP) ends the console as ``x`` does, and a ring that does not answer never holds the
console up longer than its bound. An Operator on a recorded PC link; the ring test is
test_console_tmux.py."""

from __future__ import annotations

import io
import os
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from modules.pc.console.keys import KeyRunner
from modules.pc.console.plain import run_plain
from modules.pc.console.state import ConsoleState
from modules.pc.operator import HOLD_MS, Operator, Outcome
from tests.robot.pc.test_operator import Link


def wait(condition: Any, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def motor(link: Link) -> list[str]:
    return [name for name, _ in link.commands()]


def test_the_held_speed_is_renewed_even_while_keys_keep_coming(monkeypatch) -> None:
    monkeypatch.setattr("modules.pc.operator.RENEW_AFTER_S", 0.05)
    link = Link()
    seen: list[Outcome] = []
    runner = KeyRunner(Operator(link), seen.append, renew_s=10.0).start()  # the queue never falls idle
    runner.press("up")
    for _ in range(100):
        runner.press("z")  # a key that does nothing, pressed again and again
        time.sleep(0.01)
        if motor(link).count("SET_WHEEL_SPEEDS") >= 3:
            break
    assert motor(link).count("SET_WHEEL_SPEEDS") >= 3
    released = runner.stop()
    assert released is not None and released.text == "stopped the robot, its held speed ended"
    assert motor(link)[-1] == "STOP"


def test_stop_carries_out_the_keys_before_it_then_releases() -> None:
    link = Link()
    seen: list[Outcome] = []
    runner = KeyRunner(Operator(link), seen.append).start()
    for key in ("up", "up", "space", "up"):
        runner.press(key)
    released = runner.stop()
    assert [o.key for o in seen] == ["up", "up", "space", "up"]
    assert released is not None and released.ok and motor(link)[-1] == "STOP"
    assert runner.stop() is released  # said once, not done twice
    assert motor(link).count("STOP") == 2  # space, then the release


def test_a_ring_that_does_not_answer_holds_up_the_end_only_as_long_as_the_bound() -> None:
    class Hung(Link):
        def __init__(self) -> None:
            super().__init__()
            self.gone = threading.Event()

        def command(self, target: str, name: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
            if name == "STOP":
                self.gone.wait(120)  # main never answers
            return super().command(target, name, timeout, **args)

    link = Hung()
    runner = KeyRunner(Operator(link), lambda outcome: None).start()
    runner.press("up")
    wait(lambda: "SET_WHEEL_SPEEDS" in motor(link), "the held speed")
    began = time.monotonic()
    released = runner.stop(timeout=0.5)
    assert time.monotonic() - began < 30  # a hang guard: the bound is 0.5 s
    assert (
        released is not None and not released.ok and f"runs out within {HOLD_MS // 1000} s" in released.text
    )
    link.gone.set()


def keys_then_wait(keys: list[str], pressed: threading.Event) -> Iterator[str]:
    """A terminal's keys: these, then nothing (the console waits for the next key)."""
    yield from keys
    pressed.set()
    while True:
        time.sleep(0.05)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_ends_the_stdout_console_and_stops_the_robot(signum: int) -> None:
    link = Link()
    out = io.StringIO()
    pressed = threading.Event()
    operator = Operator(link)

    def kill_when_driving() -> None:
        pressed.wait(60)
        wait(lambda: "SET_WHEEL_SPEEDS" in motor(link), "the held speed")
        os.kill(os.getpid(), signum)

    threading.Thread(target=kill_when_driving, daemon=True).start()
    before = signal.getsignal(signum)
    code = run_plain(ConsoleState(), operator, show=True, out=out, keys=keys_then_wait(["e", "up"], pressed))
    assert code == 128 + signum
    assert motor(link)[-1] == "STOP" and operator.speed_mm_s == 0
    assert out.getvalue().splitlines()[-1] == "stopped the robot, its held speed ended"
    assert signal.getsignal(signum) == before  # the console's handlers are gone with it


def test_the_end_of_the_keys_stops_the_robot_and_x_after_space_says_only_quit() -> None:
    link, out = Link(), io.StringIO()
    assert run_plain(ConsoleState(), Operator(link), show=True, out=out, keys=iter(["e", "up"])) == 0
    assert out.getvalue().splitlines() == [
        "motors on",
        "speed +25 mm/s, turn +0 °/s",
        "stopped the robot, its held speed ended",
    ]
    link, out = Link(), io.StringIO()
    run_plain(ConsoleState(), Operator(link), show=True, out=out, keys=iter(["e", "up", "space", "x"]))
    assert out.getvalue().splitlines()[-2:] == ["stopped; the queue is cleared", "quit"]
