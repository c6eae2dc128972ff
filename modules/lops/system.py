"""The whole LOPS chain in one piece, without any transport: MCU → lopscpp → packet → WLAN.

:class:`LopsSystem` is what ``python -m modules.lops`` runs each 98 ms, and what a pure
simulation runs over a given path (:func:`simulate`, :func:`seed_drive`: chapter 10's three laps
of a 3 m square).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from modules.description.room import World
from modules.lops.config import LopsConfig
from modules.lops.lopscpp import Lopscpp, Measurement
from modules.lops.mcu import Hardware, Mcu, Reading
from modules.lops.packets import pack
from modules.lops.wlan import WlanLink, WlanModel


@dataclass(frozen=True)
class Sent:
    """One trigger's outcome: the reading, the measurement, and the bytes with their arrival time."""

    reading: Reading
    measurement: Measurement
    packets: tuple[tuple[float, bytes], ...]  # (arrival ms, packet), data first, then messages


class LopsSystem:
    """The MCU in ``world``, lopscpp and the WLAN, all from one seed."""

    def __init__(
        self,
        world: World,
        config: LopsConfig,
        seed: int = 1,
        hardware: Hardware | None = None,
        wlan: WlanModel | None = None,
    ) -> None:
        self.config = config
        self.mcu = Mcu(world, config, hardware, seed)
        self.lopscpp = Lopscpp(config)
        self.link = WlanLink(seed, wlan)

    def trigger(self, t_ms: float, x: float, y: float) -> Sent:
        """Measure with the robot's transmitter at (x, y) at ``t_ms``, process, send."""
        reading = self.mcu.measure(t_ms, x, y)
        measurement = self.lopscpp.process(t_ms, reading.times_us)
        out = [pack(measurement.packet()), *(pack(m) for m in self.lopscpp.take_messages())]
        return Sent(reading, measurement, tuple((self.link.deliver(t_ms), p) for p in out))


def simulate(
    system: LopsSystem, path: Callable[[float], tuple[float, float]], triggers: int, start_ms: float = 0.0
) -> list[tuple[tuple[float, float], Sent]]:
    """Run ``triggers`` triggers every Trigger period along ``path(t_ms) -> (x, y)``; each with the
    true position."""
    out = []
    for k in range(triggers):
        t = start_ms + k * system.config.trigger_period_ms
        x, y = path(t)
        out.append(((x, y), system.trigger(t, x, y)))
    return out


def seed_drive(
    start: tuple[float, float] = (1000.0, 1000.0),
    side_mm: float = 3000.0,
    laps: int = 3,
    speed_mm_s: float = 100.0,
    turn_s: float = 3.0,
    rest_s: float = 5.0,
) -> tuple[Callable[[float], tuple[float, float]], float]:
    """Chapter 10's test drive: ``laps`` laps of a square counter-clockwise from ``start``,
    turning on the spot at each corner, standing ``rest_s`` before and after. Returns the path
    (t_ms → x, y) and its duration in ms."""
    leg_s = side_mm / speed_mm_s
    corners = [(0.0, 0.0), (side_mm, 0.0), (side_mm, side_mm), (0.0, side_mm)]
    moving_s = laps * 4 * (leg_s + turn_s)
    total_ms = (2 * rest_s + moving_s) * 1000.0

    def path(t_ms: float) -> tuple[float, float]:
        t = t_ms / 1000.0 - rest_s
        if t <= 0 or t >= moving_s:
            return start
        within = math.fmod(t, leg_s + turn_s)
        leg = int(t // (leg_s + turn_s)) % 4
        ax, ay = corners[leg]
        bx, by = corners[(leg + 1) % 4]
        f = min(within / leg_s, 1.0)
        return (start[0] + ax + f * (bx - ax), start[1] + ay + f * (by - ay))

    return path, total_ms
