"""``tokenring drive motors off|on`` on a real ring with a world (issue 54, the Darmstadt operator's
keys ``d``/``e``): off, the tool sends no move and says why, a move that reaches the motor anyway
is refused with ERROR MOTORS_OFF and the robot stays where it is; on again, it drives. With the
Darmstadt sensors (``up --sensors darmstadt``) the drive is off from boot, as the Pioneer's, until
``motors on`` (seed 000 §6.7, §8.2)."""

from __future__ import annotations

import json
import subprocess

import pytest

from modules.pc.commands.drive import _until_switched
from tests.robot.world.test_world_ring import world_state
from tests.support.hallway import ROOM, programs
from tests.support.processes import TOKENRING
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring import TokenRingError, default_protocol
from tokenring.host.pclink import PcLink
from tokenring.transport.session import free_port

ENUMS = default_protocol().enums
OFF = ENUMS["motor_state"]["OFF"]
MOTORS_OFF_ERROR = ENUMS["error_code"]["MOTORS_OFF"]
REFUSAL = (
    "tokenring drive: error: the motors are off: `tokenring drive motors on` first "
    "(in tokenring console: key e)"
)


def drive(endpoint: str, ring: str, *args: str) -> tuple[int, dict | str]:
    """Exit status and the JSON result, or stderr when there is none. (The subprocess's timeout
    is a hang guard only: every wait in the tool ends on what motor.data shows.)"""
    proc = subprocess.run(
        [*TOKENRING, "drive", *args, "--ring", ring, "--connect", endpoint, "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = proc.stdout.strip()
    return proc.returncode, json.loads(out) if proc.returncode in (0, 1) and out else proc.stderr


def pose(truth: dict) -> tuple[float, float, float]:
    return truth["x_mm"], truth["y_mm"], truth["theta_rad"]


@pytest.mark.slow
def test_drive_motors_off_refuses_moves_and_motors_on_drives_again(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor", "--programs",
        str(programs(tmp_path, ["motor"])), "--world", str(room), "--speed", "20", "--bitrate", "max",
        "--duration", "600",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20], timeout=120)
        procs.watch(launcher_pids(session, ring_name))

        code, result = drive(endpoint, ring_name, "motors", "off")
        assert code == 0, result
        assert isinstance(result, dict) and result["command"] == "MOTORS_OFF" and result["motors"] == "off"
        before = world_state(session, ring_name)
        assert before["drive"] is False

        # the tool sends nothing and says why, in one line
        code, message = drive(endpoint, ring_name, "forward", "200")
        assert code == 1 and isinstance(message, str), message
        assert REFUSAL in message.splitlines() and "Traceback" not in message

        # a move that reaches the motor anyway: ERROR MOTORS_OFF to its sender (main), no step
        link = PcLink(session, ring_name)
        assert link.command("motor", "MOVE_FORWARD", distance_mm=200, speed_pct=100)["acknowledged"]

        def errors() -> list:
            got = control(session, ring_name, 10, "program")["report"]["got"]
            return [args for name, args in got if name == "ERROR" and args["error"] == MOTORS_OFF_ERROR]

        wait_until(errors, 60, "ERROR MOTORS_OFF at main")
        assert link.read("motor.data")["state"] == OFF
        after = world_state(session, ring_name)
        assert pose(after) == pose(before) and after["steps"] == before["steps"]
        assert after["steps_unpowered"] == [0, 0]  # the motor sent none

        code, result = drive(endpoint, ring_name, "motors", "on")
        assert code == 0 and isinstance(result, dict) and result["motors"] == "on", result
        assert world_state(session, ring_name)["drive"] is True
        code, result = drive(endpoint, ring_name, "forward", "200", "--speed", "100")
        assert code == 0 and isinstance(result, dict) and result["status"] == "done", result
        assert result["true"]["x_mm"] == pytest.approx(before["x_mm"] + 200 * 1.01, abs=5)
    launcher.terminate()
    assert launcher.wait(60) == 0


@pytest.mark.slow
def test_the_darmstadt_drive_is_off_at_boot_until_motors_on(procs, ring_name, endpoint, tmp_path):
    room = tmp_path / "hall.yaml"
    room.write_text(ROOM)
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,gyro,correlator",
        "--programs", str(programs(tmp_path, ["motor", "gyro", "correlator"])), "--world", str(room),
        "--sensors", "darmstadt", "--speed", "20", "--bitrate", "max", "--duration", "600",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 90, 100], timeout=180)
        procs.watch(launcher_pids(session, ring_name))
        link = PcLink(session, ring_name)
        wait_until(lambda: link.read("motor.data")["state"] == OFF, 60, "motor.data saying OFF")
        before = world_state(session, ring_name)
        assert before["drive"] is False  # the world's drive unpowered from boot

        code, message = drive(endpoint, ring_name, "forward", "200", "--speed", "100")
        assert code == 1 and isinstance(message, str), message
        assert REFUSAL in message.splitlines() and "Traceback" not in message
        after = world_state(session, ring_name)
        assert pose(after) == pose(before) and after["steps"] == before["steps"] == [0, 0]

        code, result = drive(endpoint, ring_name, "motors", "on")
        assert code == 0 and isinstance(result, dict) and result["motors"] == "on", result
        code, result = drive(endpoint, ring_name, "forward", "200", "--speed", "100")
        assert code == 0 and isinstance(result, dict) and result["status"] == "done", result
        moved = world_state(session, ring_name)
        assert moved["x_mm"] == pytest.approx(before["x_mm"] + 200 * 1.01, abs=5), (before, moved)
        assert moved["y_mm"] == pytest.approx(before["y_mm"], abs=5) and moved["collisions"] == 0
    launcher.terminate()
    assert launcher.wait(60) == 0


@pytest.mark.parametrize("values", [[], ["up"], ["on", "off"]])
def test_drive_motors_takes_on_or_off_before_sending(values):
    # no ring runs on this port: the check happens before anything is sent
    proc = subprocess.run(
        [*TOKENRING, "drive", "motors", *values, "--connect", f"tcp/127.0.0.1:{free_port()}"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 2 and "drive motors takes on or off" in proc.stderr
    assert "Traceback" not in proc.stderr


class ScriptedLink:
    """main's PC link as ``_until_switched`` reads it: motor.data samples in turn, the last one kept."""

    def __init__(self, samples: list[dict]) -> None:
        self.samples = iter(samples)
        self.last: dict = {}

    def read(self, channel: str) -> dict:
        self.last = next(self.samples, self.last)
        return self.last


def samples(states: list[int], stamps: list[int]) -> list[dict]:
    return [{"state": s, "stamp_ms": t} for s, t in zip(states, stamps, strict=True)]


def test_motors_off_waits_through_samples_from_before_the_switch():
    link = ScriptedLink(samples([0, 0, 0, 0, OFF], [100, 100, 150, 200, 250]))
    assert _until_switched(link, off=True, timeout=600)["state"] == OFF
    link = ScriptedLink(samples([OFF, OFF, 0], [100, 150, 200]))
    assert _until_switched(link, off=False, timeout=600)["state"] == 0


def test_a_motor_without_a_switch_is_named_after_a_few_samples_not_a_timeout():
    link = ScriptedLink(samples([0] * 6, [100, 100, 150, 200, 250, 300]))  # seed mode: stays idle
    with pytest.raises(TokenRingError, match=r"took MOTORS_OFF but its state stays idle .*seed mode"):
        _until_switched(link, off=True, timeout=600)
