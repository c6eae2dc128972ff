"""Command-latency benchmark program (``python -m bench``): sends commands or takes them.

Any node can run it; its role comes from ``$TOKENRING_CMDBENCH`` (JSON, set by the suite before
it launches the ring): ``{"send": {"main": ["motor.command", ...]}, "count": 50}``. A node with
targets sends ``count`` rounds of one command to each target, one at a time, and records per
command the time and this node's token visits from ``send_command`` to the answer, the rounds
its outbox waited for a free inbox, and whether it was acknowledged. Every other node keeps its
inbox open and takes whatever arrives. ``report()`` returns the samples.
"""

from __future__ import annotations

import json
import os
import time
from typing import Any

from tokenring import UserProgram


class Program(UserProgram):
    def setup(self) -> None:
        plan = json.loads(os.environ.get("TOKENRING_CMDBENCH", "{}"))
        self.targets: list[str] = plan.get("send", {}).get(self.os.name, [])
        self.count = int(plan.get("count", 50))
        self.samples: list[dict[str, Any]] = []
        self.taken = 0
        self.finished = False

    def run(self) -> None:
        if not self.targets:
            while self.running:
                if self.os.receive_command(timeout=0.1) is not None:
                    self.taken += 1
            return
        self.os.wait_visit(5.0)
        self.sleep(float(json.loads(os.environ.get("TOKENRING_CMDBENCH", "{}")).get("settle_s", 1.0)))
        for k in range(self.count):
            for target in self.targets:
                if not self.running:
                    return
                visits0 = self.os.stats.visits
                t0 = time.perf_counter()
                outbox = self.os.send_command(target, "VECTOR_COUNTER", count=k)
                if not outbox.done.wait(5.0):
                    outbox.cancel()
                    self.samples.append({"target": target, "ms": None})
                    continue
                self.samples.append(
                    {
                        "target": target,
                        "ms": (time.perf_counter() - t0) * 1e3,
                        "visits": self.os.stats.visits - visits0,
                        "waited": outbox.rounds_waited,
                        "acked": bool(outbox.acknowledged),
                    }
                )
        self.finished = True
        while self.running:
            self.sleep(0.1)

    def report(self) -> dict[str, Any]:
        return {
            "finished": self.finished,
            "taken": self.taken,
            "samples": self.samples if self.finished else [],
        }
