"""A stand-in user program: publishes a heartbeat in its data channel and logs its commands.

Used for modules whose real program is not written yet, so the launched ring carries traffic
on every channel from the start.
"""

from __future__ import annotations

import logging
import time

from tokenring import UserProgram

log = logging.getLogger("tokenring.program")


class PlaceholderProgram(UserProgram):
    """Heartbeat in ``stamp_ms`` (if the data channel has it); every command is logged."""

    def setup(self) -> None:
        self.data = self.os.publish()
        self.has_stamp = any(f.name == "stamp_ms" for f in self.data.channel.fields)
        self.os.set_own_input_id()
        self.started = time.monotonic()

    def run(self) -> None:
        while self.running:
            command = self.os.receive_command(timeout=0.1)
            if command is not None:
                log.info(
                    "%s: received %s %s from node %d",
                    self.os.name,
                    command.name,
                    command.args,
                    command.sender,
                )
            if self.has_stamp:
                self.data.write(stamp_ms=int((time.monotonic() - self.started) * 1000) & 0xFFFFFFFF)
