"""Hardware clients: how the motor, sonar, compass and charger programs reach their devices.

Each client talks to the world simulator over ``tokenring/<ring>/hw/<module>/...`` (the key space
is documented in :mod:`modules.world.service`) and shares the simulation clock (``.clock``,
synced once from ``hw/clock``). Clients connect lazily: a node whose program never touches its
hardware never needs a world.
"""

from __future__ import annotations

from typing import Any, Self

import msgpack
import numpy as np
import zenoh

from modules.description import keys as robot_keys
from modules.world.clock import SimClock
from modules.world.service import hw_key
from tokenring import TokenRingError
from tokenring.runtime import current as current_runtime

DEFAULT_TIMEOUT_S = 2.0
WORLD_WAIT_S = 10.0  # how long the first request waits for a world that is still starting


class HardwareError(TokenRingError):
    """The simulated hardware did not answer or refused a request."""


class HardwareClient:
    """Request/answer access to one module's simulated hardware, plus the shared clock."""

    module = ""

    def __init__(self, session: zenoh.Session, ring: str, timeout: float = DEFAULT_TIMEOUT_S) -> None:
        self.session = session
        self.ring = ring
        self.timeout = timeout
        self._clock: SimClock | None = None
        self._rt = current_runtime()
        self._clock_lock = self._rt.lock()
        self.requests = 0
        self.simulator: Any = None

    @classmethod
    def local(cls, simulator: Any) -> Self:
        """A client wired straight to an in-process :class:`~modules.world.sim.Simulator` or a
        device of its (fast tests): same requests, same answers, no Zenoh."""
        client = cls(None, "local")  # type: ignore[arg-type]
        client.simulator = simulator
        client._clock = simulator.clock
        return client

    def request(self, what: str, payload: dict[str, Any] | None = None, timeout: float | None = None) -> Any:
        """One hardware request (``what`` below ``hw/``); raises :class:`HardwareError`."""
        if self.simulator is not None:
            from modules.world.sim import HardwareRequestError

            self.requests += 1
            try:
                return msgpack.unpackb(msgpack.packb(self.simulator.handle(what, payload or {})))
            except HardwareRequestError as exc:
                raise HardwareError(f"hw/{what}: {exc}") from None
        key = hw_key(self.ring, what)
        try:
            replies = self.session.get(
                key, payload=msgpack.packb(payload or {}), timeout=timeout or self.timeout
            )
            answers = [r.ok for r in replies if r.ok is not None]
        except zenoh.ZError as exc:
            raise HardwareError(f"{key}: {exc}") from exc
        if not answers:
            raise HardwareError(f"no world simulator answered {key} (is the ring started with a world?)")
        self.requests += 1
        reply = msgpack.unpackb(answers[0].payload.to_bytes())
        if not reply.get("ok"):
            raise HardwareError(f"{key}: {reply.get('error', 'refused')}")
        return reply["result"]

    @property
    def clock(self) -> SimClock:
        """The simulation clock (synced from the world on first use)."""
        with self._clock_lock:
            if self._clock is None:
                self._clock = self._sync_clock()
            return self._clock

    def _sync_clock(self) -> SimClock:
        """Ask the world three times; keep the answer with the shortest round trip."""
        clock = self._rt.monotonic
        deadline = clock() + WORLD_WAIT_S
        best: tuple[float, SimClock] | None = None
        answered = 0
        while answered < 3:
            sent = clock()
            try:
                info = self.request("clock", timeout=1.0)
            except HardwareError:
                if clock() > deadline:
                    raise
                self._rt.sleep(0.1)
                continue
            received = clock()
            answered += 1
            if best is None or received - sent < best[0]:
                best = (received - sent, SimClock.synced(info["sim_ms"], info["speed"], sent, received))
        return best[1]


class MotorHardware(HardwareClient):
    """The two stepper motors' power stage: batches of half-steps out, what happened back."""

    module = "motor"

    def start_pose(self) -> tuple[float, float, float]:
        """Where the robot was put down at power-on: (x mm, y mm, theta rad CCW)."""
        start = self.request("motor/start")
        return float(start["x_mm"]), float(start["y_mm"]), float(start["theta_rad"])

    def power(self, on: bool) -> dict[str, Any]:
        """Switch the drive's power on (True) or off (False): off, no step is made."""
        return self.request("motor/power", {"on": bool(on)})

    def steps(
        self, left: int, right: int, rate_hz: float, move: int, current_ma: int, energised: bool = True
    ) -> dict[str, Any]:
        """Report half-steps made since the last batch (signed per track, + = forward);
        ``energised=False`` switches the motor driver off after them."""
        return self.request(
            "motor/steps",
            {
                "left": int(left),
                "right": int(right),
                "rate_hz": float(rate_hz),
                "move": int(move),
                "current_ma": int(current_ma),
                "energised": bool(energised),
            },
        )


class SonarHardware(HardwareClient):
    """The eight transmitter/receiver pairs and the envelope ADC."""

    module = "sonar"

    def ping(
        self, sensors: list[int], ping_samples: int = 60, slot_ms: float = 15.0
    ) -> tuple[list[np.ndarray], list[float]]:
        """Ping the pairs one after another; each one's 510 envelope samples and time stamp (ms)."""
        result = self.request(
            "sonar/ping", {"sensors": list(sensors), "ping_samples": ping_samples, "slot_ms": slot_ms}
        )
        envelopes = [np.frombuffer(e, dtype=np.uint8) for e in result["envelopes"]]
        return envelopes, list(result["stamps_ms"])


class CompassHardware(HardwareClient):
    """The two KMZ51 bridges with their flip and compensation coils, and the 12-bit ADC."""

    module = "compass"

    def measure(
        self, settings: list[tuple[int, tuple[float, float]]], samples: int = 20
    ) -> tuple[np.ndarray, float]:
        """For each (flip, (comp0, comp1)) setting, ``samples`` readings of both bridges:
        an array (settings, 2, samples) of ADC counts, and the time stamp of the first (ms)."""
        result = self.request(
            "compass/measure",
            {
                "settings": [{"flip": int(f), "comp_ut": [float(c[0]), float(c[1])]} for f, c in settings],
                "samples": int(samples),
            },
        )
        return np.asarray(result["adc"], dtype=float), float(result["stamp_ms"])


class ChargerHardware(HardwareClient):
    """The charger's ADC on both batteries and the power relays."""

    module = "charger"

    def adc(self) -> dict[str, Any]:
        """Raw counts of the electronics and motor battery dividers and the current shunt."""
        return self.request("charger/adc")

    def relay(self, on: bool, reason: str = "") -> dict[str, Any]:
        """Hold (True) or drop (False) the power relays."""
        return self.request("charger/relay", {"on": bool(on), "reason": reason})


class TruthFeed:
    """Copro's outside observer: the world's ground truth, for its logs only (source ``T``,
    logged beside the sensors and never fused)."""

    def __init__(self, session: zenoh.Session, ring: str) -> None:
        self.session = session
        self.ring = ring

    def subscribe(self, callback: Any) -> Any:
        """Call ``callback(stamp_ms, x_mm, y_mm, theta_rad)`` per truth message; returns the
        subscription (``undeclare()`` ends it). Malformed messages are skipped."""

        def on_sample(sample: Any) -> None:
            try:
                msg = msgpack.unpackb(bytes(sample.payload.to_bytes()), raw=False)
                stamp, x, y, theta = (
                    int(msg["stamp_ms"]),
                    float(msg["x"]),
                    float(msg["y"]),
                    float(msg["theta"]),
                )
            except Exception:  # a malformed message must not kill the subscriber thread
                return
            callback(stamp, x, y, theta)

        return self.session.declare_subscriber(robot_keys.world(self.ring, "truth"), on_sample)


CLIENTS: dict[str, type[HardwareClient]] = {
    c.module: c for c in (MotorHardware, SonarHardware, CompassHardware, ChargerHardware)
}
