"""The robot's keys in the web view (modules/pc/web/keys.py): table 8.2 as the page lists them, the
action files ``tokenring web --action`` binds, what the handler answers (an Operator on a
recorded PC link), and the web server renewing a held speed only while a page is connected and
stopping the robot when the last page goes. The page in a browser on a live ring:
test_web_keys_browser.py."""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from modules.pc.operator import HOLD_MS, Operator
from modules.pc.web.keys import NOTHING_TO_QUIT, RobotKeys, add_options, web_keys
from tests.support.webserve import serve
from tokenring import UsageError


class Link:
    def __init__(self) -> None:
        self.calls: list[tuple[Any, ...]] = []

    def command(self, target: str, name: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        self.calls.append((target, name, args))
        return {"transmitted": True, "acknowledged": True}

    def request(self, verb: str, **payload: Any) -> dict[str, Any]:
        self.calls.append(("request", verb, payload))
        return {"running": False, "queue": []}

    def read(self, channel: str) -> dict[str, Any]:
        return {"state": 0}


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_options(parser)
    return parser.parse_args(list(argv))


def test_the_page_lists_table_8_2_with_the_browsers_names_and_the_unbound_files() -> None:
    keys = web_keys(parse())
    by_label = {k.label: k for k in keys.keys}
    assert list(by_label) == ["a", "b", "c", "d", "e", "x/q", "space", "↑", "↓", "←", "→", "k", "s"]
    assert by_label["space"].values == (" ",) and by_label["↑"].values == ("ArrowUp",)
    assert by_label["x/q"].values == ("x", "q") and "nothing to quit in a browser" in by_label["x/q"].meaning
    assert keys.note == "a, b, c are unbound (tokenring web --action FILE, up to three)"
    # watch's arguments have no --action: the same keys, nothing bound
    assert web_keys(argparse.Namespace()).note == keys.note


def test_action_files_are_bound_in_order_and_checked_before_serving(tmp_path: Path) -> None:
    leg = tmp_path / "leg.act"
    leg.write_text("s 300\n")
    assert web_keys(parse("--action", str(leg))).note == (
        "a leg.act; b, c are unbound (tokenring web --action FILE, up to three)"
    )
    assert web_keys(parse(*["--action", str(leg)] * 2)).note.endswith(
        "c is unbound (tokenring web --action FILE, up to three)"
    )
    assert web_keys(parse(*["--action", str(leg)] * 3)).note == "a leg.act, b leg.act, c leg.act"
    with pytest.raises(UsageError, match="up to three"):
        web_keys(parse(*["--action", str(leg)] * 4))
    with pytest.raises(UsageError, match="no such file"):
        web_keys(parse("--action", str(tmp_path / "gone.act")))
    bad = tmp_path / "bad.act"
    bad.write_text("s 300\nfly 3\n")
    with pytest.raises(UsageError, match=r"bad\.act:2"):
        web_keys(parse("--action", str(bad)))


def test_the_handler_answers_as_the_console_and_x_has_nothing_to_quit(tmp_path: Path) -> None:
    link = Link()
    handler = RobotKeys(Operator(link, []))
    assert handler.press("e") == {"text": "motors on", "ok": True}
    assert handler.press("ArrowUp")["text"].startswith("speed +25 mm/s")
    for key in ("x", "q", "Q"):
        assert handler.press(key) == {"text": NOTHING_TO_QUIT, "ok": False}
    unknown = handler.press("z")
    assert not unknown["ok"] and "means nothing" in unknown["text"]
    unbound = handler.press("a")
    assert not unbound["ok"] and "no action file is bound to a" in unbound["text"]
    handler.idle()  # nothing held long enough to renew: nothing sent
    assert [c[1] for c in link.calls if c[0] == "motor"] == ["MOTORS_ON", "SET_WHEEL_SPEEDS"]
    assert handler.unattended() == {"text": "stopped the robot, its held speed ended", "ok": True}
    assert link.calls[-1] == ("motor", "STOP", {}) and handler.unattended() is None


def motor_commands(link: Link) -> list[str]:
    return [c[1] for c in link.calls if c[0] == "motor"]


def serve_keys(link: Link, test: Callable[[str, aiohttp.ClientSession], Awaitable[None]]) -> None:
    """The robot's keys (on ``link``) in a web view on a free port, without a ring; ``test(url, client)``."""
    keys = web_keys(argparse.Namespace())
    keys.open = lambda session, ring: RobotKeys(Operator(link))
    serve(keys, test)


async def until(condition: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.02)


async def press(client: aiohttp.ClientSession, url: str, key: str) -> dict[str, Any]:
    async with client.post(url + "api/key", json={"key": key}) as answer:
        return dict(await answer.json())


def test_a_page_keeps_the_held_speed_renewed_and_its_closing_stops_the_robot(monkeypatch) -> None:
    monkeypatch.setattr("modules.pc.operator.RENEW_AFTER_S", 0.05)  # renewals seen in a moment
    link = Link()

    async def test(url: str, client: aiohttp.ClientSession) -> None:
        page = await client.ws_connect(url + "ws")
        assert (await press(client, url, "ArrowUp"))["ok"]
        await until(
            lambda: motor_commands(link).count("SET_WHEEL_SPEEDS") >= 4, "renewals while the page is open"
        )
        await page.close()
        await until(lambda: motor_commands(link)[-1] == "STOP", "the robot stopped as the page closed")

    serve_keys(link, test)
    after = motor_commands(link)
    assert after[after.index("STOP") :] == ["STOP"]  # no renewal after it, nor on the view's end


def test_keys_without_a_page_are_renewed_only_a_moment_after_the_last(monkeypatch) -> None:
    monkeypatch.setattr("modules.pc.operator.RENEW_AFTER_S", 0.05)
    monkeypatch.setattr("tokenring.web.server.KEY_LIFE_S", 0.5)
    link = Link()

    async def test(url: str, client: aiohttp.ClientSession) -> None:
        began = time.monotonic()
        assert (await press(client, url, "ArrowUp"))["ok"]  # a script: no page
        await until(lambda: "STOP" in motor_commands(link), "the robot stopped after the script fell silent")
        assert time.monotonic() - began < HOLD_MS / 1000 + 60  # a hang guard: it was let go
        assert motor_commands(link).count("SET_WHEEL_SPEEDS") >= 2  # renewed while the key was fresh

    serve_keys(link, test)
