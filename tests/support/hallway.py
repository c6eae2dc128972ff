"""A hall for the hardware modules' ring tests: a 2.7 m x 2 m room and a programs folder whose
main is a test program that records what reaches its inbox, beside the real modules asked for."""

from __future__ import annotations

from pathlib import Path

from tests.support.processes import REPO

MAIN = '''
from tokenring import UserProgram


class Program(UserProgram):
    """Test main: keeps its inbox open and records what arrives (POSITION_REACHED, ERROR)."""

    module = "main"

    def setup(self):
        self.os.set_own_input_id()
        self.got = []

    def run(self):
        while self.running:
            cmd = self.os.receive_command(timeout=0.05)
            if cmd is not None:
                self.got.append([cmd.name, cmd.args])

    def report(self):
        return {"got": self.got}
'''
# a 2.7 m x 2 m room; the robot starts 600 mm from the lower wall facing +X; a floor where the
# true glide factor is 7.8 (the motor starts with 6.5) with little spread
ROOM = """
name: hall
start: {x: 1000, y: 600, angle_deg: 0}
floor: {glide_factor: 7.8, glide_spread: 0.02}
walls:
  - polygon: [[0, 0], [2700, 0], [2700, 2000], [0, 2000]]
"""


def programs(tmp_path: Path, modules: list[str]) -> Path:
    directory = tmp_path / "programs"
    directory.mkdir()
    (directory / "main.py").write_text(MAIN)
    for name in modules:
        (directory / f"{name}.py").write_text((REPO / "modules" / f"{name}.py").read_text())
    return directory
