"""One simulated clock for the whole ring, running ``speed`` times faster than real time.

The world simulator owns it: simulated milliseconds since the world started are
``(monotonic() - start) * speed``. Modules get a copy through their hardware client, which asks
the world once (``hw/clock``) and from then on runs its own copy on its own monotonic clock, so
motor step timing, sonar sweeps, compass and charger sampling and every ``stamp_ms`` follow it.
That monotonic clock is the runtime's (:func:`tokenring.runtime.current`): the operating system's
in a process, the virtual one in ``tokenring sim``.
"""

from __future__ import annotations

from typing import Any

from tokenring.runtime import current as current_runtime


class SimClock:
    """Simulated time in ms: ``origin_ms + (monotonic() - origin_mono) * speed``, on the clock of
    the runtime in force when it was made."""

    def __init__(self, speed: float = 1.0, origin_ms: float = 0.0, origin_mono: float | None = None) -> None:
        if not speed > 0:
            raise ValueError(f"the clock's speed-up factor must be positive, not {speed!r}")
        self._rt = current_runtime()
        self._monotonic = self._rt.monotonic
        self.speed = float(speed)
        self.origin_ms = float(origin_ms)
        self.origin_mono = self._monotonic() if origin_mono is None else origin_mono

    def now_ms(self) -> float:
        """Simulated milliseconds since the world started."""
        return self.origin_ms + (self._monotonic() - self.origin_mono) * 1000.0 * self.speed

    def now_s(self) -> float:
        return self.now_ms() / 1000.0

    def stamp(self) -> int:
        """Now as a ``stamp_ms`` field value (u32, wraps after 49.7 simulated days)."""
        return int(self.now_ms()) & 0xFFFFFFFF

    def to_real(self, sim_seconds: float) -> float:
        """Real seconds that ``sim_seconds`` of simulated time take."""
        return sim_seconds / self.speed

    def sleep(self, sim_seconds: float, stop: Any = None) -> bool:
        """Sleep ``sim_seconds`` of simulated time; False if ``stop`` (an event) was set meanwhile."""
        real = max(0.0, sim_seconds / self.speed)
        if stop is None:
            self._rt.sleep(real)
            return True
        return not stop.wait(real)

    def sleep_until(self, sim_ms: float, stop: Any = None) -> bool:
        """Sleep until simulated time ``sim_ms``; False if ``stop`` was set meanwhile."""
        return self.sleep(max(0.0, (sim_ms - self.now_ms()) / 1000.0), stop)

    @classmethod
    def synced(cls, sim_ms: float, speed: float, sent_mono: float, received_mono: float) -> SimClock:
        """A copy of the world's clock from a ``hw/clock`` answer, read half-way through the round trip."""
        return cls(speed, sim_ms, (sent_mono + received_mono) / 2)


class ManualClock(SimClock):
    """Simulated time that moves only when told (``t`` or :meth:`advance`), or by ``step_ms`` at
    every reading: the simulator tested deterministically, whatever the real clock does."""

    def __init__(self, start_ms: float = 0.0, step_ms: float = 0.0) -> None:
        super().__init__(1.0)
        self.t = float(start_ms)
        self.step_ms = float(step_ms)

    def now_ms(self) -> float:
        self.t += self.step_ms
        return self.t

    def advance(self, ms: float) -> None:
        self.t += ms
