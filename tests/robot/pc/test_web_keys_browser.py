"""The seed's keys (table 8.2) and the Localisation panel in the web view, in a real browser (the
OS's headless Chromium, driven by selenium) on a live ring with the world: with the focus on the
page, ``e``, ↑ ↑ and ← drive the simulated robot, the panel's odometry line follows, ``s`` queues
a square and space stops the robot and clears the queue; ``a`` runs the action file ``tokenring web
--action`` binds to it (300 mm straight on); ``d`` turns the motors off and the next ↑ is refused,
the robot standing, until ``e``; ``x`` has nothing to quit, ``z`` means nothing.

The judges of the motion are the world's ground truth (``world/truth`` on Zenoh, read here by
hand) and main's own state over its PC link, never the page; the page is read as a user reads
it (its text).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.ring.web.test_web_browser import chromium, read_url
from tests.support.processes import wait_gone
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tests.support.worldtruth import OPEN_HALL, Truth, close
from tokenring.host.pclink import PcLink


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_pages_keys_drive_the_robot_and_the_localisation_panel_follows(
    procs, ring_name, endpoint, tmp_path: Path
):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    room = tmp_path / "hall.yaml"
    room.write_text(OPEN_HALL)
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
        link = PcLink(session, ring_name, timeout=10)
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
