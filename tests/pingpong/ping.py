"""Serves the ball: sends n to pong, waits for n + 1, counts the rally in its data channel."""

import os
from pathlib import Path

from tokenring.program import UserProgram


class Program(UserProgram):
    def setup(self):
        self.os.set_own_input_id()
        self.score = self.os.publish()
        self.log = Path(os.environ["PINGPONG_LOG"]) / "ping.log"

    def run(self):
        n, rallies = 1, 0
        while self.running:
            if not self.os.deliver("pong", "BALL", n=n, timeout=2.0):
                continue
            answer = self.os.receive_command(timeout=5.0)
            if answer is None or answer.name != "BALL":
                continue
            with self.log.open("a") as out:
                out.write(f"{n} {answer.args['n']}\n")
            rallies += 1
            self.score.write(rallies=rallies)
            n = answer.args["n"] + 1
