"""The PC link: tools reach the ring only through main's serial line, and main relays via the token."""

from __future__ import annotations

import signal

import pytest

from tests.support.ringutil import tap, wait_ring, wait_until
from tokenring.errors import UsageError
from tokenring.host.pclink import PcLink

RECEIVER = """
from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        self.out = self.os.publish()
        self.out.write(x_mm=-1234, y_mm=5678, angle_cdeg=9000)
        self.os.set_own_input_id()
        self.got = []

    def run(self):
        while self.running:
            cmd = self.os.receive_command(timeout=0.1)
            if cmd is not None:
                self.got.append(cmd.args)

    def report(self):
        return {"got": self.got}
"""

MAIN = """
from tokenring import UserProgram


class Program(UserProgram):
    def on_pc_request(self, verb, payload):
        if verb == "echo":
            return {"echo": payload, "node": self.os.name}
        raise ValueError("no such request")
"""


@pytest.mark.slow
def test_pc_link_relays_commands_reads_data_and_program_requests(procs, ring_name, endpoint, tmp_path):
    (tmp_path / "motor.py").write_text(RECEIVER)
    (tmp_path / "main.py").write_text(MAIN)
    launcher = procs.tokenring(
        "up",
        "--ring",
        ring_name,
        "--listen",
        endpoint,
        "--nodes",
        "main,motor,sonar",
        "--bitrate",
        "max",
        "--programs",
        str(tmp_path),
    )
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30])
        link = PcLink(session, ring_name)
        result = link.command("motor", "MOVE_FORWARD", distance_mm=321, speed_pct=30)
        assert result["transmitted"] and result["acknowledged"]
        data = link.read("motor.data")
        assert (data["x_mm"], data["y_mm"], data["angle_cdeg"]) == (-1234, 5678, 9000)
        assert link.request("echo", a=1) == {"echo": {"a": 1}, "node": "main"}
        with pytest.raises(UsageError, match="unknown command 'FLY'"):
            link.command("motor", "FLY")
        with pytest.raises(UsageError, match="no such request"):
            link.request("nope")
        with pytest.raises(UsageError, match="unknown channel"):
            link.read("radar.data")
        # sonar's inbox is registered nowhere: transmitted, never acknowledged, no endless retry
        result = link.command("sonar", "SET_METHOD", timeout=0.5, tangent=1, seed_classifier=0)
        assert result["transmitted"] and not result["acknowledged"]
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(5) == 0


SLOW_MAIN = """
import os, time
from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        while not os.path.exists({gate!r}):  # the test opens the gate
            time.sleep(0.05)
        self.answer = "set up"

    def on_pc_request(self, verb, payload):
        return {{"state": self.answer}}
"""


@pytest.mark.slow
def test_a_request_before_the_program_is_set_up_is_refused_not_crashed_into(
    procs, ring_name, endpoint, tmp_path
):
    gate = tmp_path / "gate"
    programs = tmp_path / "programs"
    programs.mkdir()
    (programs / "main.py").write_text(SLOW_MAIN.format(gate=str(gate)))
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor",
        "--bitrate", "max", "--programs", str(programs),
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20])
        link = PcLink(session, ring_name)
        # the ring forms before main has its program on a loaded machine ("(none)" then): wait
        # for the program that is setting up, which must refuse, not crash
        refusal = wait_until(lambda: _refusal(link), 60, "main's program setting up")
        assert "still setting up" in refusal, refusal
        gate.write_text("")
        answered = wait_until(lambda: _answer(link), 60, "main's program set up")
        assert answered == {"state": "set up"}
    launcher.send_signal(signal.SIGTERM)
    assert launcher.wait(5) == 0


def _refusal(link: PcLink) -> str | None:
    """main's refusal of a request while its program sets up; None while it has no program yet."""
    try:
        link.request("state")
    except UsageError as exc:
        return None if "(none)" in str(exc) else str(exc)
    return "answered before its setup ended"


def _answer(link: PcLink) -> dict | None:
    try:
        return link.request("state")
    except UsageError as exc:
        assert "still setting up" in str(exc)
        return None
