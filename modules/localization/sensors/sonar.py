"""The sonar ring (seed §3.4's walls; the Hamburg robot's eight sonars): ``sonar.data``'s sweep of
distances (cm, 255 without contact).

Synchronised as the newest distance of every sonar plus every wall the detector fitted in the
period, and the travel gauge's runs (:class:`~modules.localization.sync.SonarSync`; the core
builds the detector and the gauge). Logged as ``W``: our ``W R`` the distances, ``W C`` the
distances and the walls; the seed's (table B.7) the new flags, the obstacle points and nine wall
blocks with the global wall the filter matched. Built in: the wall corrections are the core's
(``walls.*``), so is the position ``W`` (one coordinate and the heading from a wall, stored after
the filter's), and table B.8's ``sonar.dat`` is a file of its own (:func:`~modules.localization.logs.convert_seed_dat`).
"""

from __future__ import annotations

from typing import Any

from modules.localization.records import (
    SeedContext,
    fields,
    integer,
    integers,
    num,
    number,
    numbers_or_none,
    seed_int,
    seed_obstacles,
    sonar_mounts,
)
from modules.localization.sensors.base import Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import NO_CONTACT_CM, SonarSync

#: the wall blocks every sonar line carries (table B.7: "für alle 9 Wände")
SEED_WALL_BLOCKS = 9
#: an empty wall block: no wall (flag 0), no angle, no distance, no global wall
SEED_NO_WALL = {"alpha": 0.0, "d": 0.0, "assoc": -1}


def _walls(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(w, dict) and number(w.get("alpha")) and number(w.get("d")) for w in value
    )


def _synchronised(p: Any) -> bool:
    return fields(distances_mm=numbers_or_none, count=integer)(p) and _walls(p.get("walls", []))


def _text(kind: str, v: dict[str, Any]) -> str:
    if kind == "R":
        return " ".join(num(d * 10 if d != NO_CONTACT_CM else 0, 5) for d in v["distances"])
    parts = [num(d, 5) for d in v["distances_mm"]]
    for w in v.get("walls", []):
        parts.append(f"1 {w['alpha']:.5f} {w['d']:.1f} {w.get('assoc', -1):>2}")
    return " ".join(parts) + f" {v['count']}"


def seed_sonar(
    distances_mm: list[float | None],
    previous: list[float | None] | None,
    mounts: list[tuple[float, float, float]],
    walls: list[dict[str, Any]],
) -> str:
    """A ``W R``/``W C`` body (table B.7): per sonar the new flag, then per sonar the obstacle's
    x and y (robot coordinates, mm), then per sonar the distance (mm, ``0`` without contact),
    then nine wall blocks ``flag α d association``. A value is new when it differs from the
    previous line's (our sonar channel has no per-sensor flag; the first line is all new)."""
    new = [
        int(previous is None or i >= len(previous) or previous[i] != d) for i, d in enumerate(distances_mm)
    ]
    points = seed_obstacles(distances_mm, mounts, 5)
    ranges = [f"{0:5d}" if d is None else seed_int(d, 5) for d in distances_mm]
    blocks = []
    for k, wall in enumerate(walls + [SEED_NO_WALL] * max(0, SEED_WALL_BLOCKS - len(walls))):
        found = int(k < len(walls))
        assoc = wall.get("assoc", -1)
        assoc = assoc if integer(assoc) else -1
        blocks.append(f"{found} {float(wall['alpha']):.5f} {float(wall['d']):.1f} {assoc:2d}")
    return " ".join([*(str(n) for n in new), *points, *ranges, *blocks])


def wall_associations(records: list[list[Any]]) -> dict[int, list[int]]:
    """For each ``W C`` record (by index) the global wall each of its walls was matched to:
    the ``K P`` of the same synchronisation lists them in order (``[wall, accepted]``)."""
    out: dict[int, list[int]] = {}
    matched: list[int] | None = None
    for i in range(len(records) - 1, -1, -1):
        _, source, kind, p = records[i]
        if source == "S" and kind == "S":
            matched = None  # going back: a synchronisation ends here, the one before starts
        elif source == "K" and kind == "P":
            walls = p.get("walls") if isinstance(p, dict) else None
            matched = [
                w[0] if isinstance(w, list) and w and integer(w[0]) else -1
                for w in (walls if isinstance(walls, list) else [])
            ]
        elif source == "W" and kind == "C":
            out[i] = matched or []
    return out


def _seed_text(kind: str, v: dict[str, Any], context: SeedContext) -> str:
    """Table B.7's sonar line; ``W C`` with the global walls the filter matched (its ``K P``)."""
    memo = context.memo("sonar")
    if "mounts" not in memo:
        memo["mounts"] = sonar_mounts(context.config)
        memo["associations"] = wall_associations(context.records)
    if kind == "R":
        distances: list[float | None] = [None if d == NO_CONTACT_CM else int(d) * 10 for d in v["distances"]]
        walls: list[dict[str, Any]] = []
    else:
        distances = list(v["distances_mm"])
        assoc = memo["associations"].get(context.index, [])
        walls = [
            {**w, "assoc": assoc[k] if k < len(assoc) else w.get("assoc", -1)}
            for k, w in enumerate(v.get("walls", []))
        ]
    body = seed_sonar(distances, memo.get(kind), memo["mounts"], walls)
    memo[kind] = distances
    return body + (f" {v['count']}" if kind == "C" else "")


def _synchroniser(context: SyncContext) -> SonarSync:
    return SonarSync(context.track, context.detector, context.gauge)


SONAR = register(
    Sensor(
        name="sonar",
        letter="W",
        title="sonar",
        rank=40,
        synchroniser=_synchroniser,
        channel="sonar.data",
        seq_field="sweep",
        value_fields=("distances",),
        settings=sensor_settings(use=True, filter=True),
        raw=fields(distances=integers),
        synchronised=_synchronised,
        text=_text,
        seed_text=_seed_text,
        position_name="walls",
        colour="tab:purple",
    )
)
