"""The robot at work: tokenring up explores a bundled room with Explore 2 and writes the map."""

from __future__ import annotations

import json
import math

import pytest

from modules.description import load_world
from modules.pc.mapscore import score_map
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.host.pclink import PcLink


@pytest.mark.slow
def test_up_explores_with_explore_2_and_writes_the_scored_map(procs, ring_name, endpoint, tmp_path):
    out = tmp_path / "map.json"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--world", "empty", "--speed", "20",
        "--bitrate", "max", "--explore", "2", "--duration", "400", "--map-out", str(out),
    )  # fmt: skip  # --duration: a hang guard; exploring is stopped once the map holds vectors
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30, 40, 50, 60, 70, 80], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        # Explore 2 runs (past the compass's calibration) until the map module holds a few
        # vectors; Stop then ends it as --duration's end would: the mission fetches the map,
        # scores it, writes it and stops the ring
        link = PcLink(session, ring_name, timeout=10)
        wait_until(lambda: link.request("state")["mode"] == 2, 120, "Explore 2 running (calibrated)")
        wait_until(lambda: link.read("map.data")["vector_count"] >= 4, 240, "4 vectors in map.data", 0.5)
        link.request("stop")
    output, _ = launcher.communicate(timeout=120)
    assert launcher.returncode == 0, output[-3000:]
    assert "Explore 2 started" in output
    assert f"vectors to {out}" in output
    doc = json.loads(out.read_text())
    assert doc["units"] == "mm" and doc["world"] == "empty"
    assert len(doc["vectors"]) >= 1, output[-3000:]
    walls = load_world("empty").outline()
    score = score_map(doc["vectors"], walls)
    assert score == doc["score"]
    # the robot found walls: some of what it mapped lies on them
    assert score["precision"] > 0.2, (score, output[-3000:])
    # the robot's end pose against the world's truth, as the simulator reported it
    end = doc["end_pose"]
    (ex, ey, _), (tx, ty, _) = end["estimate"], end["truth"]
    assert end["error_mm"] == pytest.approx(math.hypot(ex - tx, ey - ty), abs=0.2)  # (rounded to 0.1 mm)
    assert f"the robot's pose ends {end['error_mm']:.0f} mm" in output
    xs = [v for w in walls for v in (w[0], w[2])]
    assert min(xs) < tx < max(xs)  # the truth is inside the room
