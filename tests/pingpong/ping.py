"""Serves the ball: sends n to pong, waits for n + 1, counts the rally in its data channel."""

import os
from pathlib import Path

from tokenring import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.score = self.os.publish()
        self.log = Path(os.environ["PINGPONG_LOG"]) / "ping.log"

    def run(self):
        n, rallies = 1, 0
        while self.running:
            # deliver resends n as the same command until pong's OS acknowledges it, so pong
            # takes it once even when an acknowledgement is lost with a token. Not acknowledged
            # in time, pong may have it: n is served again as a new command and can come back
            # twice
            if not self.os.deliver("pong", "BALL", n=n, timeout=2.0):
                self._note(f"again {n}")
                continue
            answer = self.os.receive_command(timeout=5.0)
            # a ball served again comes back twice: the late answer is stale
            while answer is not None and answer.name == "BALL" and answer.args["n"] != n + 1:
                self._note(f"stale {answer.args['n']}")
                answer = self.os.receive_command(timeout=5.0)
            if answer is None or answer.name != "BALL":
                self._note(f"again {n}")  # no answer in time (a loaded machine): serve n again
                continue
            self._note(f"{n} {answer.args['n']}")
            rallies += 1
            self.score.write(rallies=rallies)
            n = answer.args["n"] + 1

    def _note(self, line: str) -> None:
        with self.log.open("a") as out:
            out.write(line + "\n")
