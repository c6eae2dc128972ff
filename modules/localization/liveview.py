"""The localisation's live state: what the seed's screen showed while it ran (seed 000 §6.6).

The Darmstadt program's ncurses screen showed the data of every sensor, the synchronisation and
the positions computed (§4.1 "Daten ausgeben"), and below them the MessageHandler's messages
(§6.8.3, kept in :attr:`~modules.localization.localizer.LocalizationCore.messages`).
:func:`snapshot` is the first part as one small dict of plain values (msgpack and JSON alike);
copro publishes it beside the ring a few times a second, and the live feed shows it as
``/robot/localization`` (:mod:`modules.pc.feed`, where its JSON Schema is):

============  ==================================================================================
key           what
============  ==================================================================================
stamp_ms      the last synchronisation's time (sensor time, ms; None before the first)
sensors       every sensor configured: its newest raw sample (``values`` by field name,
              ``stamp_ms``, ``seq``: its own sample number or None), ``samples`` taken into
              synchronisations, ``missed`` (None when the sensor numbers no samples and has no
              period to tell a gap by) and ``late``
sync          the trigger (``mode`` period / count / rounds, ``sensor``, ``count``, ``period_ms``,
              ``rounds``), ``syncs`` done, ``last_sync_ms``, ``last_period_ms`` and
              ``mean_period_ms`` (sensor time between synchronisations, :class:`SyncPeriods`),
              ``skipped`` grid times
positions     the position store by source name (``odometry``, ``compass``, ``gyro``, ``lops``,
              ``truth``, ``filter``, ``walls``): ``x_mm``, ``y_mm``, ``heading_rad`` with the
              X/Y/ψ validity bits of table B.7's ``P`` records (``x_valid``, ``y_valid``,
              ``heading_valid``), its log ``letter`` and ``stamp_ms``
filter        the best pose (:meth:`~LocalizationCore.pose`): ``source`` ekf / odometry / none,
              ``x_mm``, ``y_mm``, ``heading_rad``, the validity bits, ``stamp_ms`` and ``sigma``
              (``x_mm``, ``y_mm``, ``heading_rad``; None without a filter)
logs          the log files in use: ``data``, ``errors`` (paths, None: not kept) and ``failure``
              (the line saying a log was cut short, or None)
message_count every message said so far (the newest are in the backlog)
============  ==================================================================================

Angles are radians counter-clockwise from +X, lengths mm, as in the core. The snapshot reads the
core's own state, so it is taken on the thread that synchronises (copro's program loop).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from modules.localization.sensors import sensor_of_letter

if TYPE_CHECKING:
    from modules.localization.localizer import LocalizationCore

#: the position store's sources that are no sensor's (table B.6: K the Kalman filter; W the walls'
#: fix, seed §6.2.4, under the sonar's letter)
STORE_NAMES = {"K": "filter", "W": "walls"}


class SyncPeriods:
    """The synchronisation's period in sensor time, seen from outside the core: :meth:`observe`
    after every step of it. The last period is the time between the last two synchronisations
    (the mean of those in one step when a late token made it catch up several); the mean runs
    from the first synchronisation observed."""

    def __init__(self) -> None:
        self.first: tuple[int, int] | None = None  # (syncs, stamp) when first seen
        self.seen: tuple[int, int] | None = None  # (syncs, stamp) at the last observation
        self.last_period_ms: float | None = None

    def observe(self, core: LocalizationCore) -> None:
        syncs, stamp = core.syncs, core.last_sync_ms
        if stamp is None or syncs == 0:
            return
        if self.seen is None:
            self.first = self.seen = (syncs, stamp)
            return
        seen_syncs, seen_stamp = self.seen
        if syncs > seen_syncs:
            self.last_period_ms = (stamp - seen_stamp) / (syncs - seen_syncs)
            self.seen = (syncs, stamp)

    @property
    def mean_period_ms(self) -> float | None:
        if self.first is None or self.seen is None or self.seen[0] <= self.first[0]:
            return None
        return (self.seen[1] - self.first[1]) / (self.seen[0] - self.first[0])


def plain(value: Any) -> Any:
    """``value`` as msgpack and JSON both carry it: numbers (a non-finite float as None), text,
    bools, None, lists and string-keyed maps of those; anything else as its text."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if hasattr(value, "item"):  # a numpy scalar
        return plain(value.item())
    return str(value)


def _sensors(core: LocalizationCore) -> dict[str, Any]:
    latest = core.buffer.latest()
    out: dict[str, Any] = {}
    for name in core.sensors:
        sample = latest.get(name)
        timing = core.timing[name]
        numbered = timing.last_seq is not None or (sample is not None and sample.seq is not None)
        out[name] = {
            "values": plain(sample.values) if sample is not None else None,
            "stamp_ms": sample.stamp_ms if sample is not None else None,
            "seq": sample.seq if sample is not None else None,
            "samples": timing.samples,
            "missed": timing.missed if numbered or timing.period_ms else None,
            "late": timing.late,
        }
    return out


def _sync(core: LocalizationCore, periods: SyncPeriods | None) -> dict[str, Any]:
    trigger = core.trigger
    mode = "rounds" if trigger.sensor is None else "period" if trigger.period_ms else "count"
    return {
        "mode": mode,
        "sensor": trigger.sensor,
        "count": trigger.count if mode == "count" else None,
        "period_ms": trigger.period_ms if mode == "period" else None,
        "rounds": trigger.rounds,
        "syncs": core.syncs,
        "last_sync_ms": core.last_sync_ms,
        "last_period_ms": plain(periods.last_period_ms) if periods is not None else None,
        "mean_period_ms": plain(periods.mean_period_ms) if periods is not None else None,
        "skipped": trigger.skipped,
    }


def _position(x: float, y: float, psi: float, valid: Any) -> dict[str, Any]:
    vx, vy, vpsi = (bool(v) for v in valid)
    return {
        "x_mm": plain(float(x)),
        "y_mm": plain(float(y)),
        "heading_rad": plain(float(psi)),
        "x_valid": vx,
        "y_valid": vy,
        "heading_valid": vpsi,
    }


def _positions(core: LocalizationCore) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for letter, stored in core.positions.items():
        sensor = sensor_of_letter(letter)
        name = STORE_NAMES.get(letter) or (sensor.name if sensor is not None else letter)
        entry = _position(stored["x"], stored["y"], stored["psi"], stored["valid"])
        out[name] = {**entry, "letter": letter, "stamp_ms": stored.get("stamp_ms")}
    return out


def _filter(core: LocalizationCore) -> dict[str, Any]:
    pose = core.pose()
    sigma = None
    if pose.sigmas is not None:
        sx, sy, spsi = pose.sigmas
        sigma = {"x_mm": plain(float(sx)), "y_mm": plain(float(sy)), "heading_rad": plain(float(spsi))}
    valid = (pose.valid_x, pose.valid_y, pose.valid_heading)
    return {
        "source": pose.source,
        **_position(pose.x_mm, pose.y_mm, pose.heading, valid),
        "stamp_ms": pose.stamp_ms,
        "sigma": sigma,
    }


def _logs(core: LocalizationCore) -> dict[str, Any]:
    streams = (core.data_log, core.error_log)
    failures = [s.failure for s in streams if s is not None and s.failure]
    return {
        "data": str(core.data_log.path) if core.data_log is not None else None,
        "errors": str(core.error_log.path) if core.error_log is not None else None,
        "failure": failures[0] if failures else None,
    }


def snapshot(core: LocalizationCore, periods: SyncPeriods | None = None) -> dict[str, Any]:
    """The live state of ``core`` (the table above); ``periods`` gives the synchronisation's
    last and mean period (None: not watched)."""
    return {
        "stamp_ms": core.last_sync_ms,
        "sensors": _sensors(core),
        "sync": _sync(core, periods),
        "positions": _positions(core),
        "filter": _filter(core),
        "logs": _logs(core),
        "message_count": core.messages_said,
    }
