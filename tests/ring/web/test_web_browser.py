"""The web view in a real browser: the OS's headless Chromium, driven by selenium, opens
``tokenring web`` on a live exploring ring, sees the token move, injects a fault with the page's
form (the ring's control plane confirms it), clears it with the page's button, and a screenshot
shows the map drawn.

The judges are the ring itself (each node's ``fault`` control key, main's PC link) and the
screenshot's pixels; nothing here shares code with the page.
"""

from __future__ import annotations

import io
import json
import threading
from pathlib import Path

import pytest

from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.contract import keys
from tokenring.host.pclink import PcLink
from tokenring.transport.session import query

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
#: the map's colour on the page (#1c7ed6), as a user sees it: strong blue
MAP_RGB = (28, 126, 214)
LCD = 70  # the node the fault goes to: its delay shows in its own counters


def chromium():
    """Headless Chromium from the OS packages (never a downloaded one)."""
    missing = [str(p) for p in (CHROMIUM, CHROMEDRIVER) if not p.exists()]
    if missing:
        pytest.fail(
            f"the browser test needs {', '.join(missing)}: apt-get install -y chromium chromium-driver"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1440,1150"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)


def read_url(proc, timeout: float) -> str:
    """The URL ``tokenring web --json`` prints once it listens."""
    found: list[str] = []

    def read() -> None:
        for line in proc.stdout:
            if line.startswith("{") and '"url"' in line:
                found.append(json.loads(line)["url"])
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    assert found, f"tokenring web printed no URL within {timeout} s (exit code {proc.poll()})"
    return found[0]


def node_faults(session, ring: str, node: int) -> dict:
    replies = query(session, keys.control(ring, node, "fault"), {"kind": "list"}, timeout=2.0)
    return replies[0][1]["result"] if replies and replies[0][1].get("ok") else {}


def blue_pixels(png: bytes, box: tuple[int, int, int, int]) -> int:
    """How many pixels of ``box`` in the screenshot are the map's blue."""
    import numpy as np
    from PIL import Image

    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB").crop(box), dtype=int)
    return int((np.abs(pixels - np.array(MAP_RGB)).sum(axis=2) < 30).sum())


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_chromium_follows_the_ring_injects_and_clears_a_fault_and_draws_the_map(
    procs, ring_name, endpoint, tmp_path
):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--explore", "2", "--speed", "5", "--duration", "400"
    )  # fmt: skip
    web = procs.tokenring("web", "--ring", ring_name, "-e", endpoint, "--port", "0", "--json")
    url = read_url(web, 60)
    driver = chromium()
    try:
        with tap(endpoint) as session:
            wait_ring(session, ring_name, [10, 20, 30, 40, 50, 60, 70, 80], timeout=120)
            procs.watch(launcher_pids(session, ring_name))
            driver.get(url)
            frames = driver.find_element(By.ID, "token-frames")

            def seen() -> int:
                return int(frames.get_attribute("data-frames") or 0)

            first = wait_until(seen, 60, "the page to count the token's passes")
            wait_until(lambda: seen() > first + 100, 60, "the page's token counter to move on")
            holder = driver.find_element(By.ID, "token-holder").get_attribute("data-holder")
            assert holder and int(holder) in {10, 20, 30, 40, 50, 60, 70, 80}

            # the page's fault form: delay every token at lcd by 20 ms
            assert "delay" not in node_faults(session, ring_name, LCD).get("faults", {})
            Select(driver.find_element(By.ID, "fault-node")).select_by_value(str(LCD))
            Select(driver.find_element(By.ID, "fault-kind")).select_by_value("delay")
            value = driver.find_element(By.ID, "fault-value")
            value.clear()
            value.send_keys("20")
            driver.find_element(By.ID, "fault-inject").click()
            active = wait_until(
                lambda: node_faults(session, ring_name, LCD).get("faults", {}).get("delay"),
                30,
                "lcd's delay fault on the ring",
            )
            assert active["ms"] == 20.0
            wait_until(
                lambda: node_faults(session, ring_name, LCD)["counts"]["delayed"] > 10,
                30,
                "lcd to delay tokens",
            )
            row_faults = driver.find_element(By.CSS_SELECTOR, f"#node-{LCD} td.faults")
            wait_until(lambda: row_faults.get_attribute("data-faults") == "delay", 30, "the page to show it")

            # the page's clear button on lcd's row
            driver.find_element(By.CSS_SELECTOR, f'button.clear-fault[data-node="{LCD}"]').click()
            wait_until(
                lambda: node_faults(session, ring_name, LCD).get("faults") == {}, 30, "lcd's faults cleared"
            )
            wait_until(
                lambda: row_faults.get_attribute("data-faults") == "", 30, "the page to show it cleared"
            )

            # the map: Explore 2 records vectors (main's PC link says so), the page draws them
            link = PcLink(session, ring_name, timeout=10)
            wait_until(lambda: link.read("map.data")["vector_count"] >= 2, 300, "two map vectors on the ring")
            count = driver.find_element(By.ID, "robot-map-count")
            wait_until(lambda: int(count.get_attribute("data-vectors") or 0) >= 2, 60, "the page's map")
            canvas = driver.find_element(By.ID, "robot-room")
            # two animation frames later the page has painted what it counted
            driver.execute_async_script(
                "const done = arguments[0];requestAnimationFrame(() => requestAnimationFrame(() => done()));"
            )
            png = driver.get_screenshot_as_png()
            (tmp_path / "web.png").write_bytes(png)
            ratio = driver.execute_script("return window.devicePixelRatio") or 1
            rect = canvas.rect
            box = (
                int(rect["x"] * ratio),
                int(rect["y"] * ratio),
                int((rect["x"] + rect["width"]) * ratio),
                int((rect["y"] + rect["height"]) * ratio),
            )
            inside = blue_pixels(png, box)
            assert inside >= 200, (
                f"the map canvas shows {inside} map-blue pixels (screenshot {tmp_path / 'web.png'})"
            )
            errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
            assert not errors, errors

            # the robot's Stop button ends Explore 2; its mission then stops the ring (exit 0)
            driver.find_element(By.CSS_SELECTOR, 'button[data-action="explore-stop"]').click()
            answer = driver.find_element(By.ID, "action-answer")
            wait_until(
                lambda: answer.get_attribute("data-ok") == "true", 30, f"Stop answered ({answer.text})"
            )
            assert launcher.wait(90) == 0
    finally:
        driver.quit()
    web.terminate()
    assert web.wait(15) == 0
