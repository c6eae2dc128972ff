"""The seed's ``[LOPS]`` configuration (seed 000 table B.1), which ``lopscpp`` shares with syncaria.

Table B.1 lists, in order: Robotername, Port, Schnittstelle, then Steigung n and Offset n for each
of the three receivers, then X-Position n and Y-Position n for each, then Gewichten,
Positionsfilter and Historienlänge. The filter's Grundwert is "in der Konfigurationsdatei
einstellbar" (§6.2.5) but missing from the table: here it may follow Historienlänge.
The seed gives none of the numbers; the defaults are ours.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

from modules.description.room import World

Point = tuple[float, float]

#: the MCU's radio trigger period (§3.5: "Die MCU sendet alle 98 ms ein Funksignal aus")
TRIGGER_PERIOD_MS = 98.0
#: Steigung: the speed of sound, mm per µs (the house's 330 m/s, modules.description.robot)
DEFAULT_SLOPE_MM_PER_US = 0.330
#: Offset n: negative (§6.2.5: the MCUs' processing, the wires and the radio's time of flight)
DEFAULT_OFFSETS_MM = (-42.0, -37.0, -45.0)
#: Grundwert of dist_ok = (t_akt − t_alt) · Grundwert, mm per ms of age: 0.1 = 10 cm/s, the
#: robot's top speed (modules.description.robot.MAX_SPEED_MM_S)
DEFAULT_GRUNDWERT_MM_PER_MS = 0.1
#: how far inside the room's bounding box the default receivers hang, mm
RECEIVER_INSET_MM = 100.0


class LopsConfigError(ValueError):
    """A ``[LOPS]`` section that cannot be read."""


@dataclass(frozen=True)
class LopsConfig:
    """What ``lopscpp`` reads from ``[LOPS]``; the seed's names in the field comments."""

    receivers: tuple[Point, Point, Point]  # X-Position n, Y-Position n (mm, room frame)
    slopes: tuple[float, float, float] = (DEFAULT_SLOPE_MM_PER_US,) * 3  # Steigung n (mm/µs)
    offsets: tuple[float, float, float] = DEFAULT_OFFSETS_MM  # Offset n (mm, negative)
    weighting: bool = False  # Gewichten
    position_filter: bool = True  # Positionsfilter
    history_length: int = 10  # Historienlänge
    grundwert: float = DEFAULT_GRUNDWERT_MM_PER_MS  # Grundwert (mm per ms)
    robot_name: str = "robot-pc"  # Robotername (the seed's TCP peer; unused here)
    port: int = 4554  # Port (seed B.4's log: "Lopsmodul is waiting for connection on port 4554")
    interface: str = "/dev/ttyS0"  # Schnittstelle (the MCU's serial line; unused here)
    #: ours: the largest |measured − fitted| distance a trilateration may leave, mm
    residual_tolerance_mm: float = 30.0
    trigger_period_ms: float = TRIGGER_PERIOD_MS

    def __post_init__(self) -> None:
        if len(self.receivers) != 3 or len(self.slopes) != 3 or len(self.offsets) != 3:
            raise LopsConfigError("LOPS has three receivers: three positions, slopes and offsets")
        if self.history_length < 2:
            raise LopsConfigError(f"Historienlänge {self.history_length}: the filter needs two halves")
        if not all(s > 0 for s in self.slopes):
            raise LopsConfigError(f"Steigung must be positive, not {self.slopes}")


def default_receivers(world: World) -> tuple[Point, Point, Point]:
    """Three receivers at three corners of the room's bounding box, :data:`RECEIVER_INSET_MM`
    inside: bottom left, bottom right, top left (the seed gives no positions)."""
    xmin, ymin, xmax, ymax = world.bounds()
    i = RECEIVER_INSET_MM
    return ((xmin + i, ymin + i), (xmax - i, ymin + i), (xmin + i, ymax - i))


def for_world(world: World, **changes: object) -> LopsConfig:
    """The default configuration with receivers in ``world``'s corners, and ``changes``."""
    return replace(LopsConfig(receivers=default_receivers(world)), **changes)  # type: ignore[arg-type]


_FIELDS = 18  # the values table B.1 lists for [LOPS] (Grundwert may follow as a 19th)


def parse_lops_section(text: str) -> LopsConfig:
    """The ``[LOPS]`` section of a syncaria/lopscpp configuration file (figure B.1's layout: a
    section heading, ``#`` comments, one value per line) as a :class:`LopsConfig`."""
    values = _section_values(text, "lops")
    if len(values) < _FIELDS:
        raise LopsConfigError(f"[LOPS] has {len(values)} values; table B.1 lists {_FIELDS}")
    try:
        name, port, interface = values[0], int(values[1]), values[2]
        pairs = [float(v) for v in values[3:15]]
        slopes = (pairs[0], pairs[2], pairs[4])
        offsets = (pairs[1], pairs[3], pairs[5])
        receivers = ((pairs[6], pairs[7]), (pairs[8], pairs[9]), (pairs[10], pairs[11]))
        weighting, position_filter = _yes(values[15]), _yes(values[16])
        history = int(values[17])
        grundwert = float(values[18]) if len(values) > _FIELDS else DEFAULT_GRUNDWERT_MM_PER_MS
    except ValueError as exc:
        raise LopsConfigError(f"[LOPS]: {exc}") from None
    if not all(math.isfinite(v) for v in (*pairs, grundwert)):
        raise LopsConfigError("[LOPS]: every number must be finite")
    return LopsConfig(
        receivers=receivers,
        slopes=slopes,
        offsets=offsets,
        weighting=weighting,
        position_filter=position_filter,
        history_length=history,
        grundwert=grundwert,
        robot_name=name,
        port=port,
        interface=interface,
    )


def format_lops_section(config: LopsConfig) -> str:
    """``config`` as a ``[LOPS]`` section that :func:`parse_lops_section` reads back."""
    lines = ["[LOPS]", "# Robotername, Port, Schnittstelle", config.robot_name, str(config.port)]
    lines += [config.interface, "# Steigung n, Offset n"]
    for slope, offset in zip(config.slopes, config.offsets, strict=True):
        lines += [repr(slope), repr(offset)]
    lines.append("# X-Position n, Y-Position n")
    for x, y in config.receivers:
        lines += [repr(float(x)), repr(float(y))]
    lines += ["# Gewichten, Positionsfilter, Historienlänge, Grundwert"]
    lines += [_yes_no(config.weighting), _yes_no(config.position_filter), str(config.history_length)]
    lines.append(repr(config.grundwert))
    return "\n".join(lines) + "\n"


def _section_values(text: str, section: str) -> list[str]:
    inside, values = False, []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        heading = re.fullmatch(r"\[\s*([^\]]+?)\s*\]", line)
        if heading:
            if inside:
                break
            inside = heading.group(1).lower() == section
            continue
        if inside and line:
            values.append(line.strip('"'))
    if not inside and not values:
        raise LopsConfigError(f"no [{section.upper()}] section")
    return values


def _yes(value: str) -> bool:
    word = value.lower()
    if word not in ("yes", "no", "ja", "nein"):
        raise ValueError(f"{value!r} is not yes or no")
    return word in ("yes", "ja")


def _yes_no(flag: bool) -> str:
    return "yes" if flag else "no"
