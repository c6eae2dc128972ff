"""The hardware modules over the real ring at a high speed-up: a test client's commands (through
main's PC link) move the simulated robot; dead reckoning vs truth, the glide-factor error and its
correction, sonar against known walls, and the charger stopping the ring on an empty battery."""

from __future__ import annotations

import itertools
import math
import statistics
import sys

import pytest

from modules.description import keys as robot_keys
from modules.description.robot import FRONT, RIGHT_FRONT, SONAR_MOUNTS, STEP_MM
from tests.support.hallway import ROOM, programs
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tokenring.errors import TransportError
from tokenring.host.pclink import PcLink


def world_state(session, ring: str) -> dict:
    """The world's ground truth right now (world/state), after every hardware request so far."""
    from tokenring.transport.session import query_one

    return query_one(session, robot_keys.world(ring, "state"))


def read(link: PcLink, channel: str) -> dict:
    """main's copy of a data channel; an empty one while the PC link is still coming up."""
    try:
        return link.read(channel)
    except TransportError:
        return {"stamp_ms": 0}


def run_move(link: PcLink, name: str, **args) -> dict:
    """Send a motion command through main and wait until the motor finished it."""
    before = link.read("motor.data")
    reply = link.command("motor", name, **args)
    assert reply["acknowledged"], reply

    def finished():
        data = link.read("motor.data")
        return data if data["move_seq"] != before["move_seq"] and data["state"] != 1 else None

    return wait_until(finished, 30, f"{name} to finish", interval=0.02)


def sonar_sweeps(link: PcLink, count: int) -> list[dict]:
    sweeps: list[dict] = []

    def collect():
        data = link.read("sonar.data")
        if not sweeps or data["sweep"] != sweeps[-1]["sweep"]:
            sweeps.append(data)
        return len(sweeps) >= count

    wait_until(collect, 20, f"{count} sonar sweeps", interval=0.01)
    return sweeps


@pytest.mark.slow
def test_commands_move_the_robot_dead_reckoning_glide_factor_and_sonar(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    directory = programs(tmp_path, ["motor", "sonar", "compass", "charger"])
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar,compass,charger",
        "--programs", str(directory), "--world", str(room), "--speed", "20", "--seed", "4",
        "--bitrate", "max", "--duration", "90",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30, 40, 80], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name)
        start = wait_until(
            lambda: link.read("motor.data")["stamp_ms"] > 0 and link.read("motor.data"), 10, "motor"
        )
        assert (start["x_mm"], start["y_mm"], start["angle_cdeg"]) == (1000, 600, 0)

        # 1 m straight: the motor believes 1845 half-steps x 0.5419 mm; the floor adds 1 % +- 0.5 %
        t0 = world_state(session, ring_name)
        done = run_move(link, "MOVE_FORWARD", distance_mm=1000, speed_pct=100)
        t1 = world_state(session, ring_name)
        assert done["steps_left"] - start["steps_left"] == 1845 == done["steps_right"] - start["steps_right"]
        believed = done["x_mm"] - start["x_mm"]
        driven = t1["x_mm"] - t0["x_mm"]
        assert believed == pytest.approx(1845 * STEP_MM, abs=1)
        assert 1.01 - 0.015 <= driven / believed <= 1.01 + 0.015
        assert abs(t1["y_mm"] - 600) < 1e-6 and abs(t1["theta_rad"]) < 1e-9

        # sonar against the known walls, from the true pose: front to x = 2700, right-front to y = 0
        sweeps = sonar_sweeps(link, 12)
        x, y = t1["x_mm"], t1["y_mm"]
        expected_front = (2700 - x - SONAR_MOUNTS[FRONT].x) / 10
        expected_right = (y + SONAR_MOUNTS[RIGHT_FRONT].y) / 10
        assert abs(statistics.median(s["distances"][FRONT] for s in sweeps) - expected_front) <= 2
        assert abs(statistics.median(s["distances"][RIGHT_FRONT] for s in sweeps) - expected_right) <= 2
        stamps = [s["stamp_ms"] for s in sweeps]
        assert all(b > a for a, b in itertools.pairwise(stamps))

        # a 90° turn on a floor with glide factor 7.8 turns only 75°; the robot believes 90°
        done = run_move(link, "TURN_LEFT", angle_deg=90, speed_pct=100)
        t2 = world_state(session, ring_name)
        turned = math.degrees(t2["theta_rad"] - t1["theta_rad"])
        assert done["angle_cdeg"] == 27000  # 90° counter-clockwise on the wire (clockwise angles)
        assert turned == pytest.approx(90 * 6.5 / 7.8, rel=0.03)
        error_before = turned - 90
        # RECALC_GLIDE_FACTOR with the seed's formula, the error measured (here: from the truth)
        assert link.command(
            "motor", "RECALC_GLIDE_FACTOR", target_deg=90, error_cdeg=round(error_before * 100)
        )["acknowledged"]
        wait_until(lambda: link.read("motor.data")["glide_cfactor"] != 650, 5, "new glide factor")
        assert link.read("motor.data")["glide_cfactor"] == pytest.approx(650 * 90 / turned, abs=2)
        run_move(link, "TURN_RIGHT", angle_deg=90, speed_pct=100)
        t3 = world_state(session, ring_name)
        error_after = math.degrees(t2["theta_rad"] - t3["theta_rad"]) - 90
        assert abs(error_after) < abs(error_before) / 3 and abs(error_after) < 4

        # the compass and the charger publish on the ring with simulated time stamps
        compass = link.read("compass.data")
        charger = link.read("charger.data")
        assert compass["sample"] > 0 and charger["motors_pct"] > 90 and charger["state"] == 0
        assert abs(charger["stamp_ms"] - t3["t_ms"]) < 5000

        # bad input: speed over 100 %: refused with ERROR to the sender (main), nothing moves
        before = link.read("motor.data")
        assert link.command("motor", "MOVE_FORWARD", distance_mm=300, speed_pct=150)["acknowledged"]
        report = lambda: next(iter(ringutil_control(session, ring_name, 10)))  # noqa: E731
        wait_until(lambda: any(g[0] == "ERROR" for g in report()["got"]), 10, "ERROR at main")
        assert link.read("motor.data")["steps_left"] == before["steps_left"]
        got = report()["got"]
        assert ["POSITION_REACHED", {"status": 0, "move_seq": before["move_seq"]}] in got
    launcher.terminate()
    assert launcher.wait(60) == 0


def ringutil_control(session, ring, node):
    from tests.support.ringutil import control

    yield control(session, ring, node, "program")["report"]


@pytest.mark.slow
def test_the_charger_stops_the_ring_on_a_nearly_empty_battery(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "flat.yaml"
    room.write_text(ROOM.replace("name: hall", "name: flat\nbatteries: {motors: 0.035}"))
    directory = programs(tmp_path, ["motor", "charger"])
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,charger",
        "--programs", str(directory), "--world", str(room), "--speed", "40", "--bitrate", "max",
        "--duration", "60",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 80], timeout=120)
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name)
        wait_until(lambda: read(link, "charger.data")["stamp_ms"] > 0, 10, "charger data")
        assert link.read("charger.data")["state"] == 1  # LOW
        assert link.command("motor", "MOVE_FORWARD", distance_mm=1500, speed_pct=100)["acknowledged"]
    out, _ = launcher.communicate(timeout=40)
    assert launcher.returncode == 0, out
    assert "ring shutdown requested: deep discharge: motor battery" in out
    assert "every node has exited" not in out


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("walls:\n  - [0, 0, 1000, 0\n", "room.yaml:3: YAML syntax error"),
        (
            "walls:\n  - [0, 0, 3000, 0]\n  - [9, 9, 9, 9]\nstart: {x: 1000, y: 500}\n",
            "room.yaml:3: wall 2 has zero length",
        ),
        (
            "walls:\n  - [0, 0, 3000, 0]\nstart: {x: 1000, y: 100}\n",
            "room.yaml:3: start pose (1000, 100) is inside wall 1",
        ),
    ],
)
def test_up_refuses_a_bad_world_before_anything_starts(procs, tmp_path, text, message):
    room = tmp_path / "room.yaml"
    room.write_text(text)
    proc = procs.start([sys.executable, "-m", "tokenring", "up", "--world", str(room), "--ring", "nothing"])
    out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 2
    assert message in out and "Traceback" not in out and "starting" not in out
