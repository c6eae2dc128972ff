"""What a data-log record holds and how its numbers are written: the pieces the logs
(:mod:`modules.localization.logs`) and every sensor's file (:mod:`modules.localization.sensors`)
build their checks and line formats from.

A *check* says whether a payload has what the readers take from it (a record failing it is
damage, reported like unreadable bytes); the *formats* are appendix B's fields: our right-aligned
numbers (:func:`num`) and the seed's (:func:`seed_int`, :func:`seed_position`,
:func:`seed_obstacles`). Nothing here knows a sensor by name.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

Check = Callable[[Any], bool]


# =============================================================================================
# checks


def number(value: Any) -> bool:
    """An int or a float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def integer(value: Any) -> bool:
    """An int (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool)


def text(value: Any) -> bool:
    """A str."""
    return isinstance(value, str)


def mapping(value: Any) -> bool:
    """A dict, whatever it holds."""
    return isinstance(value, dict)


def integers(value: Any) -> bool:
    """A list of ints."""
    return isinstance(value, list) and all(integer(v) for v in value)


def numbers_or_none(value: Any) -> bool:
    """A list of numbers, None where there is none."""
    return isinstance(value, list) and all(v is None or number(v) for v in value)


def flags(value: Any) -> bool:
    """Three valid flags (x, y, heading)."""
    return isinstance(value, list) and len(value) == 3 and all(isinstance(v, (bool, int)) for v in value)


def fields(**checks: Check) -> Check:
    """A mapping with at least these fields, each passing its check (more fields may follow)."""
    return lambda value: (
        isinstance(value, dict)
        and all(name in value and check(value[name]) for name, check in checks.items())
    )


# =============================================================================================
# formats


def num(value: Any, width: int = 8, digits: int = 0) -> str:
    """Our text's number: right-aligned in ``width``, rounded (or ``digits`` decimals); ``0`` for None."""
    if value is None:
        return f"{0:>{width}}"
    if isinstance(value, bool):
        return "1" if value else "0"
    if digits:
        return f"{float(value):>{width}.{digits}f}"
    return f"{round(float(value)):>{width}d}" if math.isfinite(float(value)) else f"{'nan':>{width}}"


def seed_int(value: Any, width: int) -> str:
    """An integer field right-aligned in ``width`` (the seed's ``%6d``), rounded from mm floats."""
    number_ = float(value)
    return f"{round(number_):{width}d}" if math.isfinite(number_) else f"{'nan':>{width}}"


def seed_position(p: dict[str, Any] | None, width: int = 6, angle_width: int = 7) -> str:
    """X, Y, rotation and the three valid flags (table B.7, ``x P`` and ``S S``); an unknown
    value is written as ``0`` (figure B.3: ``      0      0      0 0 0 0``). ``width``: X, Y and
    an unknown rotation's field, ``angle_width``: a known rotation's (figure B.3's 6 and 7 by
    default; table B.8's ``data.dat`` has 8 and 8)."""
    if p is None:
        return f"{0:{width}d} {0:{width}d} {0:{width}d} 0 0 0"
    vx, vy, vpsi = (bool(v) for v in p.get("valid", [True, True, True]))
    x = seed_int(p["x"], width) if vx else f"{0:{width}d}"
    y = seed_int(p["y"], width) if vy else f"{0:{width}d}"
    psi = f"{float(p['psi']):{angle_width}.5f}" if vpsi else f"{0:{width}d}"
    return f"{x} {y} {psi} {int(vx)} {int(vy)} {int(vpsi)}"


def sonar_mounts(config: Any) -> list[tuple[float, float, float]]:
    """Each sonar's (x mm, y mm, angle rad) on the robot: the log's config, else the robot's."""
    robot = config.get("robot") if isinstance(config, dict) else None
    sonars = robot.get("sonars") if isinstance(robot, dict) else None
    if isinstance(sonars, list) and all(
        isinstance(m, list) and len(m) == 3 and all(number(v) for v in m) for m in sonars
    ):
        return [(float(x), float(y), math.radians(float(a))) for x, y, a in sonars]
    from modules.description.robot import SONAR_MOUNTS

    return [(m.x, m.y, m.angle) for m in SONAR_MOUNTS]


def seed_obstacles(
    distances_mm: list[float | None], mounts: list[tuple[float, float, float]], width: int
) -> list[str]:
    """Per sonar the obstacle's x and y (robot coordinates, mm) right-aligned in ``width``: the
    mount plus the distance along the sonar's axis; ``0 0`` without contact or without a mount
    (table B.7's ``W R``/``W C`` with 5 characters, table B.8's ``sonar.dat`` with 6)."""
    points: list[str] = []
    for i, d in enumerate(distances_mm):
        if d is None or i >= len(mounts):
            points += [f"{0:{width}d}", f"{0:{width}d}"]
            continue
        mx, my, angle = mounts[i]
        points += [seed_int(mx + d * math.cos(angle), width), seed_int(my + d * math.sin(angle), width)]
    return points


@dataclass
class SeedContext:
    """What a sensor's seed-text hook may need beyond its own record: the log's configuration,
    all its records and the index of the one written, and a memo per sensor that lasts the
    conversion (what it worked out once, what the line before held)."""

    config: Any
    records: list[list[Any]]
    index: int = 0
    memos: dict[str, dict[str, Any]] = field(default_factory=dict)

    def memo(self, sensor: str) -> dict[str, Any]:
        """``sensor``'s memo (empty at the first record)."""
        return self.memos.setdefault(sensor, {})
