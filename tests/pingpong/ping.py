"""Serves the ball: sends n to pong, waits for n + 1, counts the rally in its data channel."""

import os
import time
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
            if not self._serve(n):
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

    def _serve(self, n: int, timeout: float = 2.0) -> bool:
        """Send n until pong's OS acknowledges it, as ``os.deliver`` does, noting each resend of a
        ball that was transmitted but not acknowledged: pong may have taken it (the token that
        carried the acknowledgement was lost), so it can come back twice."""
        deadline = time.monotonic() + timeout
        while self.running and time.monotonic() < deadline:
            self.os.wait_channel_free("pong", timeout)
            box = self.os.send_command("pong", "BALL", n=n)
            if not box.done.wait(max(0.0, deadline - time.monotonic())):
                box.cancel()
                self._note(f"again {n}")
                return False
            if box.acknowledged:
                return True
            if box.transmitted:
                self._note(f"again {n}")
        return False

    def _note(self, line: str) -> None:
        with self.log.open("a") as out:
            out.write(line + "\n")
