"""``tokenring drive``: motor commands through main's PC link, with the dead-reckoned and true pose."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.support.hallway import ROOM, programs
from tests.support.ringutil import launcher_pids, tap, wait_ring
from tokenring.transport.session import free_port

DRIVE = [sys.executable, "-m", "tokenring", "drive"]


def drive(endpoint: str, ring: str, *args: str) -> tuple[int, dict | str]:
    proc = subprocess.run(
        [*DRIVE, *args, "--ring", ring, "--connect", endpoint, "--json"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    out = proc.stdout.strip()
    return proc.returncode, json.loads(out) if proc.returncode in (0, 1) and out else proc.stderr


@pytest.mark.slow
def test_drive_moves_the_robot_and_prints_both_poses(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--programs",
        str(programs(tmp_path, ["motor"])), "--world", str(room), "--speed", "20", "--bitrate", "max",
        "--duration", "60",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
    code, result = drive(endpoint, ring_name, "forward", "300", "--speed", "100")
    assert code == 0, result
    assert result["status"] == "done" and result["dead_reckoned"]["x_mm"] == 1300
    assert result["true"]["x_mm"] == pytest.approx(1000 + 300 * 1.01, abs=6)
    code, result = drive(endpoint, ring_name, "turn", "left", "90", "--speed", "100")
    assert code == 0 and result["dead_reckoned"]["angle_deg"] == pytest.approx(90)
    assert 75 <= result["true"]["angle_deg"] <= 77  # this floor's glide factor is 7.8, not 6.5
    code, result = drive(endpoint, ring_name, "glide", "90", str(result["true"]["angle_deg"] - 90))
    assert code == 0 and result["glide_factor"] == pytest.approx(6.5 * 90 / 76, abs=0.15)
    code, result = drive(endpoint, ring_name, "set-pose", "1300", "600", "76")
    assert code == 0 and result["dead_reckoned"]["angle_deg"] == pytest.approx(76)
    # the room is 2 m deep: driving 3 m ends at the wall
    code, result = drive(endpoint, ring_name, "forward", "3000", "--speed", "100")
    assert code == 1 and result["status"] == "collision" and result["true"]["collisions"] == 1
    launcher.terminate()
    assert launcher.wait(60) == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["forward", "-100"], "must not be negative"),
        (["forward", "500", "--speed", "101"], "--speed 101 must be a whole number of percent within 1..100"),
        (["turn", "left"], "turn left|right DEGREES"),
        (["wheels", "150", "0", "100"], "must be within -100..100 %"),
        (["glide", "0", "5"], "target angle (non-zero)"),
    ],
)
def test_drive_refuses_bad_input_before_sending(args, message):
    # no ring runs on this port: the check happens before anything is sent
    proc = subprocess.run(
        [*DRIVE, *args, "--connect", f"tcp/127.0.0.1:{free_port()}"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
