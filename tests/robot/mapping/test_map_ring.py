"""The map over real node processes: vectors in through main's PC link, GET_MAP out through main,
the LCD's screen and keypad from the command line."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.host.pclink import PcLink


@pytest.mark.slow
def test_get_map_round_trip_through_main_and_the_lcd_over_zenoh(procs, ring_name, endpoint, tmp_path):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,copro,map,lcd", "--no-world",
        "--duration", "40",
    )  # fmt: skip
    vectors = [(10 * i, -5 * i, 10 * i + 100, 7) for i in range(12)]
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 50, 60, 70])
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name, timeout=10)
        for x1, y1, x2, y2 in vectors:
            assert link.command("map", "VECTOR", x1=x1, y1=y1, x2=x2, y2=y2)["acknowledged"]
        wait_until(lambda: link.read("map.data")["vector_count"] == 12, 10, "12 vectors in map.data")
        got = link.request("get_map", timeout=20)
        assert [tuple(v) for v in got["vectors"]] == vectors
        wait_until(
            lambda: control(session, ring_name, 60, "program")["report"]["maps_sent"] >= 1, 5, "map's count"
        )

        # the keypad at the program's Main Menu: Components, map (3rd of main, copro, map, lcd) → ROBMAP fetches the map over the ring itself
        out = subprocess.run(
            [sys.executable, "-m", "tokenring", "lcd", "--ring", ring_name, "-e", endpoint, "--keys", "4 3"],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
        assert out.returncode == 0, out.stderr
        assert "█" in out.stdout or "▀" in out.stdout
        wait_until(
            lambda: control(session, ring_name, 70, "program")["report"]["map_vectors"] == 12,
            15,
            "the LCD's map",
        )
        assert control(session, ring_name, 70, "program")["report"]["menu"] == "robmap"
        png = tmp_path / "lcd.png"
        saved = subprocess.run(
            [sys.executable, "-m", "tokenring", "lcd", "--ring", ring_name, "-e", endpoint, "--png", str(png)],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
        assert saved.returncode == 0, saved.stderr
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

        link.request("clear_map")
        wait_until(lambda: link.read("map.data")["vector_count"] == 0, 10, "a cleared map")
        assert link.request("get_map")["vectors"] == []
        state = link.request("state")
        assert json.loads(json.dumps(state))["navigator"] == "IDLE"
    launcher.terminate()
    assert launcher.wait(60) == 0
