"""ROBMAP, the map computer (seed §4.3.5): stores the vectors copro finds and hands the map out.

Commands: CLEAR_MAP empties the store; VECTOR (x1, y1, x2, y2 in cm) stores one vector — into a
full store (4096 vectors) it stores nothing and answers ERROR MAP_FULL to the sender; GET_MAP
answers VECTOR_COUNTER n to the requester and then each VECTOR, one after the other. Replies go
out from their own thread so that the inbox keeps taking vectors while a long map streams out
(the stream is a snapshot of the map at the moment of the request).
"""

from __future__ import annotations

import logging
import queue
from typing import Any

from modules.mapping.vectormap import CAPACITY, MapFull, VectorStore
from tokenring import UserProgram
from tokenring.runtime import current as current_runtime

log = logging.getLogger("tokenring.map")

#: how long one reply may wait for the requester's inbox before the stream is given up
REPLY_TIMEOUT_S = 5.0


class Program(UserProgram):
    module = "map"

    def setup(self) -> None:
        self.store = VectorStore(CAPACITY)
        self.data = self.os.publish()
        self.os.set_own_input_id()
        self.rt = current_runtime()  # the queue and thread: the process's, or a simulation's
        self.replies: queue.Queue[tuple[str, list[tuple[str, dict[str, int]]]] | None] = self.rt.queue()
        self.stats = {"vectors_received": 0, "refused_full": 0, "maps_sent": 0, "streams_failed": 0}
        self.error_codes = self.os.protocol.enums["error_code"]
        self.vector_code = self.os.protocol.common_commands["VECTOR"].code
        self._publish()
        self.sender = self.rt.spawn(self._send_replies, "map-replies")

    def _publish(self) -> None:
        self.data.write(vector_count=self.store.count, capacity_left=self.store.left)

    def run(self) -> None:
        while self.running:
            command = self.os.receive_command(timeout=0.2)
            if command is None:
                continue
            self.handle(command.sender, command.name, command.args)

    def handle(self, sender: int, name: str, args: dict[str, Any]) -> None:
        """Execute one command (also the unit the tests drive)."""
        requester = self.os.protocol.by_id.get(sender)
        if name == "VECTOR":
            self.stats["vectors_received"] += 1
            try:
                self.store.add(args["x1"], args["y1"], args["x2"], args["y2"])
            except MapFull:
                self.stats["refused_full"] += 1
                log.warning("map full (%d vectors): refused a vector from node %d", CAPACITY, sender)
                if requester is not None:
                    error = {"error": self.error_codes["MAP_FULL"], "about": self.vector_code}
                    self.replies.put((requester.name, [("ERROR", error)]))
        elif name == "CLEAR_MAP":
            self.store.clear()
        elif name == "GET_MAP":
            if requester is None:
                log.warning("GET_MAP from unknown node %d ignored", sender)
                return
            vectors = self.store.vectors()
            messages: list[tuple[str, dict[str, int]]] = [("VECTOR_COUNTER", {"count": len(vectors)})]
            messages += [("VECTOR", {"x1": a, "y1": b, "x2": c, "y2": d}) for a, b, c, d in vectors]
            self.replies.put((requester.name, messages))
        else:
            log.info("map: ignoring %s from node %d", name, sender)
        self._publish()

    def _send_replies(self) -> None:
        """Send each queued answer in order; a requester that stops taking them ends its stream."""
        while self.running:
            try:
                job = self.replies.get(timeout=0.2)
            except queue.Empty:
                continue
            if job is None:
                break
            target, messages = job
            for name, args in messages:
                if not self.os.deliver(target, name, timeout=REPLY_TIMEOUT_S, **args):
                    if self.running:
                        self.stats["streams_failed"] += 1
                        log.warning(
                            "%s did not take %s within %.0f s: stream ended", target, name, REPLY_TIMEOUT_S
                        )
                    break
            else:
                if messages and messages[0][0] == "VECTOR_COUNTER":
                    self.stats["maps_sent"] += 1

    def teardown(self) -> None:
        self.replies.put(None)

    def report(self) -> dict[str, Any]:
        return {"vector_count": self.store.count, "capacity_left": self.store.left, **self.stats}
