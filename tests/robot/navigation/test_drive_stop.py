"""``tokenring drive stop``: a STOP starts no move, so the tool follows none. At rest it answers at
once with exit 0; during a move it ends the move and returns once the motor is at rest."""

from __future__ import annotations

import json
import subprocess

import pytest

from tests.support.hallway import ROOM, programs
from tests.support.processes import TOKENRING
from tests.support.ringutil import launcher_pids, tap, wait_ring


def drive(endpoint: str, ring: str, *args: str) -> tuple[int, dict | str]:
    # --timeout 90: the old drive stop at rest waited all of it and failed; the subprocess's own
    # timeout is only the hang guard
    proc = subprocess.run(
        [*TOKENRING, "drive", *args, "--ring", ring, "--connect", endpoint, "--json", "--timeout", "90"],
        capture_output=True,
        text=True,
        timeout=180,
    )
    out = proc.stdout.strip()
    return proc.returncode, json.loads(out) if proc.returncode in (0, 1) and out else proc.stderr


@pytest.mark.slow
def test_drive_stop_at_rest_answers_at_once_and_mid_move_ends_the_move(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--programs",
        str(programs(tmp_path, ["motor"])), "--world", str(room), "--bitrate", "max", "--duration", "600",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))

    code, result = drive(endpoint, ring_name, "stop")
    assert code == 0, result
    assert isinstance(result, dict) and result["command"] == "STOP" and result["status"] == "done"
    assert result["dead_reckoned"]["x_mm"] == 1000  # nothing moved

    # the hall is 2.7 m wide and the robot at x = 1 m: a 1.5 m move at 1 cm/s lasts minutes
    code, result = drive(endpoint, ring_name, "forward", "1500", "--speed", "10", "--no-wait")
    assert code == 0, result
    code, result = drive(endpoint, ring_name, "stop")
    assert code == 0, result
    assert isinstance(result, dict) and result["status"] == "done"
    stopped_at = result["dead_reckoned"]["x_mm"]
    assert 1000 <= stopped_at < 2500
    code, result = drive(endpoint, ring_name, "pose")
    assert code == 0 and isinstance(result, dict), result
    assert result["dead_reckoned"]["x_mm"] == pytest.approx(stopped_at, abs=1)  # at rest since
    launcher.terminate()
    assert launcher.wait(60) == 0
