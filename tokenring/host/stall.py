"""The launcher noticing that it did not run for a while (SIGSTOP, Ctrl-Z, a starved machine).

It says so in its output. When it is its nodes' router (``up --router``) every frame passes
through it, so while it stood still the token could not move and the nodes regenerated it: it
tells them the span (``ctl/*/faultnote`` with ``stalled``), and their ledgers count those
regenerations as the network's, not as spurious (:mod:`tokenring.node.regeneration`)."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from tokenring.contract import keys
from tokenring.errors import TokenRingError

log = logging.getLogger("tokenring.host")

#: how often the watch looks at the clock
TICK_S = 0.25
#: a wake this much later than planned was a stall (a node's watchdog calls the same a freeze)
STALL_S = 1.0


class StallWatch:
    """A thread that notices the launcher's own stalls and reports them."""

    def __init__(
        self,
        session: Any,
        ring: str,
        say: Callable[[str], None],
        *,
        router: bool,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.session = session
        self.ring = ring
        self.say = say
        self.router = router
        self.clock = clock
        self.stalls: list[tuple[float, float]] = []  # (wall-clock start, end) of each
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="launcher-stall-watch", daemon=True)

    def start(self) -> StallWatch:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)

    def _run(self) -> None:
        planned = self.clock() + TICK_S
        while not self._stop.wait(max(0.0, planned - self.clock())):
            late = self.clock() - planned
            if late >= STALL_S:
                self.stalled(late)
            planned = self.clock() + TICK_S  # after telling the nodes, which takes a moment

    def stalled(self, seconds: float) -> None:
        """The launcher did not run for ``seconds`` until now: say it, and tell the nodes whose
        router it is."""
        end = time.time()
        start = end - seconds
        self.stalls.append((start, end))
        line = f"the launcher did not run for {seconds:.1f} s (stopped by SIGSTOP or Ctrl-Z, or starved)"
        if self.router:
            line += "; it is its nodes' router, so the token stood still meanwhile"
        self.say(line)
        if self.router:
            self.tell_nodes(start, end)

    def tell_nodes(self, start: float, end: float) -> None:
        """``ctl/*/faultnote`` with the stalled span: the nodes recount its regenerations."""
        from tokenring.transport.session import query

        try:
            query(
                self.session,
                keys.control(self.ring, "*", "faultnote"),
                {"id": 0, "stalled": [start, end]},
                timeout=2.0,
            )
        except TokenRingError as exc:
            log.debug("telling the nodes of the stall: %s", exc)
