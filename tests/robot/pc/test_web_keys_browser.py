"""The seed's keys (table 8.2) and the Localisation panel in the web view, in a real browser (the
OS's headless Chromium, driven by selenium) on a live ring with the world: with the focus on the
page, ``e``, ↑ ↑ and ← drive the simulated robot, the panel's odometry line follows, ``s`` queues
a square and space stops the robot and clears the queue; ``a`` runs the action file ``tokenring web
--action`` binds to it (300 mm straight on); ``d`` turns the motors off and the next ↑ is refused,
the robot standing, until ``e``; ``x`` has nothing to quit, ``z`` means nothing.

The Localisation panel's other parts on the same ring, as the seed's screen showed them: the
synchronisation (its trigger and period as copro's localisation states them, a count that
grows), the position store (every source copro keeps, with its X/Y/ψ validities; the filter's
pose and σ, its pose moving with the drive), the messages (the Localizer's "localisation started",
said before the page was opened) and the sonar's distances (the robot starts beside a wall, in the
sonar's range), which change as the robot drives and turns.

The judges of the motion are the world's ground truth (``world/truth`` on Zenoh, read here by
hand) and main's own state over its PC link, never the page; what the panels should say is read
by hand from copro's localisation on Zenoh (its ``state`` and its ``messages``); the page is read
as a user reads it (its text).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest

from tests.ring.web.test_web_browser import chromium, read_url
from tests.support.processes import wait_gone
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tests.support.worldtruth import Truth, close
from tokenring.host.pclink import PcLink
from tokenring.transport import query

#: a 6 m square hall; the robot starts 800 mm from its south wall, on its right: the sonar has the
#: wall in range (1.5 m) and the drive (on, then turning left) changes what it sees
HALL_BY_A_WALL = """
name: hall-by-a-wall
start: {x: 3000, y: 800, angle_deg: 0}
walls:
  - polygon: [[0, 0], [6000, 0], [6000, 6000], [0, 6000]]
"""

#: the panels' lines as localisation.js writes them (read from the page's text, matched here)
TRIGGER = re.compile(r"trigger +(.+?), every (\d+) (ms|sample\(s\)|round\(s\)) \((period|count|rounds)\)")
SYNCS = re.compile(r"syncs +(\d+)(, \d+ grid times skipped)?")
PERIOD = re.compile(r"period +last (\d+) ms, mean (\d+) ms")
NUMBER = r"(-?\d+(?:\.\d+)?)"
PLACED = rf"x +{NUMBER} mm +y +{NUMBER} mm +ψ +{NUMBER}°"
STORED = re.compile(rf"(\S+) +{PLACED} +([X-][Y-][P-])")
BEST = re.compile(rf"best +{PLACED} +σ {NUMBER}/{NUMBER} mm {NUMBER}° +\((ekf|odometry|none)\)")
STARTED = re.compile(r"I +(\d+) (localisation started: .+)")
SONAR = re.compile(r"sonar +((?:(?:\d+|--) )+)cm +sweep \d+ +\(\d+\)")


class Localization:
    """copro's localisation as it publishes it (``robot/localization/state``), read by hand."""

    def __init__(self, session, ring: str) -> None:
        self.state: dict[str, Any] | None = None
        self._sub = session.declare_subscriber(f"tokenring/{ring}/robot/localization/state", self._on)

    def _on(self, sample) -> None:
        self.state = msgpack.unpackb(sample.payload.to_bytes(), raw=False, strict_map_key=False)


def said(session, ring: str, start: str) -> dict[str, Any] | None:
    """The localisation's message starting with ``start`` if it was said (its backlog, asked by
    hand)."""
    for _, reply in query(session, f"tokenring/{ring}/robot/localization/messages", timeout=2.0):
        for message in (reply.get("result") or {}).get("messages", []) if reply.get("ok") else []:
            if str(message.get("text", "")).startswith(start):
                return message
    return None


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_pages_keys_drive_the_robot_and_the_localisation_panel_follows(
    procs, ring_name, endpoint, tmp_path: Path
):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    room = tmp_path / "hall.yaml"
    room.write_text(HALL_BY_A_WALL)
    action = tmp_path / "leg.act"
    action.write_text("# bound to a\ns 300\n")
    # the sonar too: main plans no drive (the action file's, the square's) before it has spoken
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar,copro",
        "--world", str(room), "--bitrate", "max", "--duration", "900",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30, 50], timeout=180)
        procs.watch(launcher_pids(session, ring_name))
        truth = Truth(session, ring_name)
        localization = Localization(session, ring_name)
        link = PcLink(session, ring_name, timeout=10)
        # the page opens after the Localizer said it started: the panel has it from the backlog
        started = wait_until(
            lambda: said(session, ring_name, "localisation started"), 120, "the localisation's first message"
        )
        web = procs.tokenring(
            "web", "--ring", ring_name, "-e", endpoint, "--port", "0", "--json", "--action", str(action)
        )
        url = read_url(web, 60)
        driver = chromium()
        driver_pid = driver.service.process.pid
        try:
            driver.get(url)
            wait_until(
                lambda: driver.find_element(By.TAG_NAME, "body").get_attribute("data-ready"), 60, "the page"
            )
            status = driver.find_element(By.ID, "key-status")
            note = driver.find_element(By.ID, "key-note").text
            assert note.startswith("a leg.act; b, c are unbound"), note

            def text(selector: str) -> str:
                """An element's text now (the panel redraws its lines: no element is kept)."""
                script = "const e = document.querySelector(arguments[0]); return e ? e.innerText : '';"
                return str(driver.execute_script(script, selector))

            def line(name: str) -> str:
                return text(f'#panel-localisation [data-line="{name}"]')

            def queue() -> str:
                return text("#loc-queue")

            def lines(panel: str) -> list[str]:
                """A panel's lines as the page shows them (each line a div)."""
                script = (
                    "return Array.from(document.querySelectorAll(arguments[0])).map((e) => e.textContent);"
                )
                return [str(t) for t in driver.execute_script(script, f"{panel} > div")]

            def eventually(condition: Callable[[], Any], what: str, shown: Callable[[], Any]) -> Any:
                """``condition``'s value once it holds; else what ``shown`` says at the end."""
                try:
                    return wait_until(condition, 60, what)
                except AssertionError as exc:
                    raise AssertionError(f"{exc}; the page: {shown()!r}") from None

            def matching(panel: str, pattern: re.Pattern[str]) -> list[re.Match[str]]:
                return [m for m in map(pattern.fullmatch, lines(panel)) if m]

            def syncs() -> int:
                found = matching("#loc-sync", SYNCS)
                return int(found[0][1]) if found else -1

            def best() -> tuple[float, float, float] | None:
                """The filter's pose on the page (mm, mm, degrees)."""
                found = matching("#loc-positions", BEST)
                return (
                    (float(found[0][1]), float(found[0][2]), float(found[0][3])) if len(found) == 1 else None
                )

            def sonar() -> list[str]:
                found = SONAR.fullmatch(line("sonar"))
                return found[1].split() if found else []

            # the messages: the Localizer's first, said before the page was opened
            message = eventually(
                lambda: matching("#loc-messages", STARTED),
                f"the panel's messages to show {started!r}",
                lambda: lines("#loc-messages"),
            )[0]
            assert (int(message[1]), message[2]) == (started["stamp_ms"], started["text"]), message[0]

            # the synchronisation: copro's trigger and its period, and a count
            sync = wait_until(
                lambda: (localization.state or {}).get("sync"), 60, "copro's localisation state"
            )
            trigger = eventually(
                lambda: matching("#loc-sync", TRIGGER), "the trigger line", lambda: lines("#loc-sync")
            )[0]
            every = {"period": sync["period_ms"], "count": sync["count"], "rounds": sync["rounds"]}[
                sync["mode"]
            ]
            assert trigger.groups()[::3] == (sync["sensor"] or "the token", sync["mode"]), trigger[0]
            assert int(trigger[2]) == every, (trigger[0], sync)
            period = eventually(
                lambda: matching("#loc-sync", PERIOD), "the period line", lambda: lines("#loc-sync")
            )
            assert 0 < int(period[0][2]) < 10 * (sync["period_ms"] or 1000), period[0][0]
            counted = eventually(lambda: syncs() > 0 and syncs(), "a sync count", lambda: lines("#loc-sync"))

            # the position store: every source copro keeps, with its validities; the filter's pose and σ
            def validities() -> tuple[dict[str, str], dict[str, str]]:
                on_page = {m[1]: m[5] for m in matching("#loc-positions", STORED)}
                kept = ((localization.state or {}).get("positions")) or {}
                bits = {
                    name: "".join(
                        c if p[f"{v}_valid"] else "-" for c, v in (("X", "x"), ("Y", "y"), ("P", "heading"))
                    )
                    for name, p in kept.items()
                }
                return on_page, bits

            eventually(
                lambda: validities()[1] and validities()[0] == validities()[1],
                "the store's sources with copro's validities (page, copro)",
                validities,
            )
            assert {"odometry", "filter"} <= set(validities()[0]), lines("#loc-positions")
            pose = eventually(best, "the filter's pose and σ", lambda: lines("#loc-positions"))
            sigma = matching("#loc-positions", BEST)[0]
            assert all(float(sigma[i]) > 0 for i in (4, 5, 6)), sigma[0]

            # the sonar: distances to the wall beside the robot
            seen = eventually(
                lambda: any(d.isdigit() for d in sonar()) and sonar(),
                "the sonar's distances to the wall",
                lambda: line("sonar"),
            )

            odometry = wait_until(lambda: line("odometry"), 120, "the panel's odometry line")
            assert odometry.startswith("odometry") and "steps" in odometry, odometry
            start = truth.wait(lambda p: True, "reported a pose")

            answered = 0

            def press(*keys: str, expect: str) -> str:
                """Press ``keys`` with the focus on the page; the last one's answer on the page."""
                nonlocal answered
                ActionChains(driver).send_keys(*keys).perform()
                answered += len(keys)
                wait_until(
                    lambda: int(status.get_attribute("data-count") or 0) >= answered,
                    60,
                    f"the page's answer to {keys!r} (it says {status.text!r})",
                )
                assert expect in status.text, (keys, status.text)
                return status.text

            driver.find_element(By.TAG_NAME, "h1").click()  # the focus on the page, in no field
            press("e", expect="motors on")
            press(Keys.ARROW_UP, Keys.ARROW_UP, expect="↑: speed +50 mm/s")
            moved = truth.wait(lambda p: p[0] > start[0] + 30, "drove forward on ↑ ↑")
            press(Keys.ARROW_LEFT, expect="turn +10 °/s")
            truth.wait(lambda p: p[2] > moved[2] + math.radians(3), "turned left on ←")
            wait_until(lambda: line("odometry") != odometry, 60, "the odometry line to follow the drive")
            # the other panels follow too: the syncs go on, the filter's pose leaves its start
            # forward and turns left as the robot did, the sonar sees the wall from elsewhere
            eventually(
                lambda: syncs() > counted,
                f"the sync count to grow from {counted}",
                lambda: lines("#loc-sync"),
            )
            eventually(
                lambda: (p := best()) and p[0] > pose[0] + 30 and p[2] > pose[2] + 1,
                f"the filter's pose to follow the drive from {pose}",
                lambda: lines("#loc-positions"),
            )
            eventually(
                lambda: (d := sonar()) and d != seen and any(v.isdigit() for v in d),
                f"the sonar's distances to change from {seen}",
                lambda: line("sonar"),
            )

            press("s", expect="queued s: square")
            wait_until(lambda: link.request("state").get("queue"), 60, "the square in main's queue")
            wait_until(
                lambda: "▶ s 1000" in queue(), 60, f"the page's queue to show the square ({queue()!r})"
            )
            driver.save_screenshot(str(tmp_path / "web-keys.png"))  # the page driving, for a failure's story
            press(" ", expect="stopped; the queue is cleared")
            assert link.request("state").get("queue") == [], "main's queue after space"
            wait_until(lambda: "(queue empty)" in queue(), 60, f"the page's queue to empty ({queue()!r})")
            stopped = truth.settled()
            assert close(truth.settled(), stopped), "the robot went on after space"

            press("a", expect="a: queued leg.act (1 actions")  # the action file: 300 mm straight on
            truth.wait(lambda p: math.dist(p[:2], stopped[:2]) > 250, "drove the action file's leg")
            wait_until(
                lambda: link.request("state").get("navigator") in ("IDLE", "DONE"),
                120,
                "main's navigator to finish the action file",
            )
            leg_end = truth.settled()
            assert math.dist(leg_end[:2], stopped[:2]) == pytest.approx(300, abs=40), (stopped, leg_end)

            press("d", expect="motors off: moves are refused until e")
            refusal = press(Keys.ARROW_UP, expect="refused, the motors are off (press e)")
            assert refusal.startswith("↑: "), refusal
            assert status.get_attribute("data-ok") == "false", refusal
            assert close(truth.settled(), leg_end), "the robot moved with its motors off"

            press("e", expect="motors on")
            drive = press(Keys.ARROW_UP, expect="↑: speed +")
            assert "refused" not in drive, drive
            truth.wait(lambda p: math.dist(p[:2], leg_end[:2]) > 30, "drove again on e then ↑")
            press(" ", expect="stopped; the queue is cleared")
            truth.settled()

            press("x", expect="nothing to quit in a browser")
            press("z", expect="key z means nothing")
            errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
            assert not errors, errors
            assert launcher.poll() is None  # the ring runs on
        finally:
            driver.quit()
            assert not wait_gone([driver_pid], 15.0), "chromedriver outlived the test"
        web.terminate()
        assert web.wait(30) == 0
    launcher.terminate()
    assert launcher.wait(60) == 0
