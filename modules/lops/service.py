"""LOPS on Zenoh: the stationary PC beside the ring, never on it and never in the token.

Every 98 simulated ms the MCU triggers: the process reads where the world has the robot
(``world/state``: the world acting as the hardware, the sound's physical input), measures,
runs lopscpp, and hands the packet to the WLAN model; when the model says it arrives, the raw
packet (tables 6.1/6.2) is put on ``tokenring/<ring>/robot/lops/packets``. Only what LOPS
measured leaves: distances, a position or none, the counter, lopscpp's messages. While it serves
it holds the liveliness token ``robot/lops/alive`` (a launcher's ``ready_key``).
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from modules.description import keys as robot_keys
from modules.lops.lopscpp import POSITION
from modules.lops.packets import MessagePacket
from modules.lops.system import LopsSystem
from modules.world.clock import SimClock

log = logging.getLogger("modules.lops")
#: the state query's timeout, real seconds: a trigger without an answer is skipped
STATE_TIMEOUT_S = 1.0


def packets_key(ring: str) -> str:
    """Where LOPS puts its packets, one per put."""
    return robot_keys.lops(ring, "packets")


def ready_key(ring: str) -> str:
    """The liveliness key LOPS holds while it serves (for a launcher's ``ServicePlan``)."""
    return robot_keys.lops(ring, "alive")


def service_argv(seed: int = 1, log_level: str = "info", zenoh_config: str | None = None) -> list[str]:
    """The argv after ``python -m`` that a launcher's ``ServicePlan("lops", ...)`` would run
    (``{ring}`` and ``{connect}`` filled in by the launcher)."""
    argv = ["modules.lops", "--ring", "{ring}", "--connect", "{connect}", "--seed", str(seed)]
    argv += ["--log-level", log_level]
    if zenoh_config:
        argv += ["--zenoh-config", zenoh_config]
    return argv


class LopsService:
    """Runs one :class:`LopsSystem` on a Zenoh session until ``stop`` is set.

    ``truth()`` returns the world's ``(t_ms, x_mm, y_mm)`` now, or None if it did not answer."""

    def __init__(
        self,
        system: LopsSystem,
        session: zenoh.Session,
        ring: str,
        clock: SimClock,
        truth: Callable[[], tuple[float, float, float] | None],
    ) -> None:
        self.system = system
        self.session = session
        self.ring = ring
        self.clock = clock
        self.truth = truth
        self.stop = threading.Event()
        self.counts = {"triggers": 0, "positions": 0, "skipped": 0, "sent": 0}
        self._queue: deque[tuple[float, bytes]] = deque()  # the link delivers in order
        self._publisher: Any = None
        self._token: Any = None

    def run(self) -> None:
        """Serve until :attr:`stop` is set (the caller's thread)."""
        self._publisher = self.session.declare_publisher(packets_key(self.ring))
        self._token = self.session.liveliness().declare_token(ready_key(self.ring))
        if not self._wait_for_the_robot():
            self.close()
            return
        period = self.system.config.trigger_period_ms
        receivers = ", ".join(f"({x:.0f}, {y:.0f})" for x, y in self.system.config.receivers)
        self.system.lopscpp.messages.append(
            MessagePacket(f"I lopscpp started: receivers {receivers} mm, trigger {period:g} ms")
        )
        next_trigger = self.clock.now_ms()
        try:
            while not self.stop.is_set():
                wake = min(next_trigger, self._queue[0][0]) if self._queue else next_trigger
                if not self.clock.sleep_until(wake, self.stop):
                    break
                now = self.clock.now_ms()
                self._send_due(now)
                if now >= next_trigger:
                    self._trigger(next_trigger)
                    next_trigger += period
                    behind = int((self.clock.now_ms() - next_trigger) // period)
                    if behind > 0:  # the machine cannot keep up with the speed-up: skip, never bunch
                        self.counts["skipped"] += behind
                        next_trigger += behind * period
        finally:
            self.close()

    def _wait_for_the_robot(self) -> bool:
        """Seed §6.2.5 / B6.3: LOPS waits for the robot's connection before lopscpp starts, so no
        packet, the start message least of all, goes out before anyone can take it. Here the
        connection is a subscriber of the packets' key; False if stopped first."""
        said = False
        while not self.stop.is_set():
            if self._publisher.matching_status.matching:
                return True
            if not said:
                log.info("lops: waiting for the robot on %s", packets_key(self.ring))
                said = True
            self.stop.wait(0.05)
        return False

    def close(self) -> None:
        for item in (self._token, self._publisher):
            if item is not None:
                with contextlib.suppress(zenoh.ZError):
                    item.undeclare()
        self._token = self._publisher = None

    def _trigger(self, t_ms: float) -> None:
        truth = self.truth()
        if truth is None:
            self.counts["skipped"] += 1
            return
        _, x, y = truth
        sent = self.system.trigger(t_ms, x, y)
        self.counts["triggers"] += 1
        self.counts["positions"] += sent.measurement.reason == POSITION
        for arrival, raw in sent.packets:
            self._queue.append((arrival, raw))

    def _send_due(self, now: float) -> None:
        while self._queue and self._queue[0][0] <= now:
            _, raw = self._queue.popleft()
            try:
                self._publisher.put(raw)
            except zenoh.ZError:
                if self.stop.is_set():
                    return
                raise
            self.counts["sent"] += 1
