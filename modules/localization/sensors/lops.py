"""LOPS, the local positioning system (seed §3.5, §6.2.5; Darmstadt): lopscpp's data packets as
copro's WLAN receiver takes them (stamped on arrival, fed by the Localizer's ``feed_lops``, not a
data channel): a counter, the distances to the three receivers and the position it trilaterated.

Synchronised as table 3.1's newest distances and position, the newest measured by the sync time
(:class:`~modules.localization.sync.DueSync`: packets arrive ahead of the odometry that triggers it).
Logged as ``L``: ``L R`` and ``L C`` the three distances (0 where nothing was heard) and the
counter, ``L P`` the position when it has one (x and y valid, no heading); table B.8's
Entfernung 1-3, LOPS-X, LOPS-Y and LOPS-Valid; ``lops.png`` the distances per receiver. Its
corrections of the filter (each distance to its receiver) and the position initialisation by
LOPS are the core's (``lops.*`` settings).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from modules.localization.records import fields, integer, num, seed_int
from modules.localization.sensors.base import Analysis, Record, Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import DueSync

DISTANCES = ("d1", "d2", "d3")


def _values(values: Any) -> bool:
    """LOPS's counter, its three distances and its position (mm; None where it has none)."""
    if not fields(counter=integer)(values):
        return False
    return all(
        values.get(k) is None
        or (isinstance(values.get(k), int | float) and not isinstance(values.get(k), bool))
        for k in (*DISTANCES, "x", "y")
    )


def _text(kind: str, v: dict[str, Any]) -> str:
    """The three distances (mm; 0 where nothing was heard) and the counter, appendix B's order."""
    body = " ".join(num(v.get(k)) for k in DISTANCES) + f" {v.get('counter', 0):>8}"
    return body + (f" {v['count']}" if kind == "C" else "")


def _position(core: Any, record: dict[str, Any] | None) -> dict[str, Any] | None:
    if record is None or record.get("x") is None or record.get("y") is None:
        return None
    return {"x": record["x"], "y": record["y"], "psi": 0.0, "valid": [True, True, False]}


def _dat(p: dict[str, Any] | None) -> str:
    """Table B.8's LOPS columns: the three distances (mm, ``0`` where none was heard), the
    position LOPS computed (``0 0`` when it could not) and its valid flag."""
    if p is None:
        return " ".join([f"{0:8d}"] * 5) + " 0"
    distances = " ".join(num(p.get(k), 8) for k in DISTANCES)
    x, y = p.get("x"), p.get("y")
    valid = x is not None and y is not None and math.isfinite(float(x)) and math.isfinite(float(y))
    where = f"{seed_int(x, 8)} {seed_int(y, 8)}" if valid else f"{0:8d} {0:8d}"
    return f"{distances} {where} {int(valid)}"


# ---------------------------------------------------------------------------------------------
# the analyser's LOPS module (seed §9.2, table B.9 LOPS/Empfaenger n)


def _collect(records: list[Record]) -> list[tuple[int, float, float, float, bool]] | None:
    """The packets: (stamp, d1, d2, d3, has a position), NaN where nothing was heard."""
    packets: list[tuple[int, float, float, float, bool]] = []
    for stamp, kind, p in records:
        values = p.get("v", {})
        if kind == "R" and "counter" in values:
            d1, d2, d3 = (math.nan if values.get(k) is None else float(values[k]) for k in DISTANCES)
            packets.append((stamp, d1, d2, d3, values.get("x") is not None))
    return packets or None


def _summary(packets: list[tuple[int, float, float, float, bool]]) -> dict[str, Any]:
    """The seed's 404 of 2024 without a position, and its receivers' share heard."""
    lops = np.array(packets, dtype=float)
    return {
        "packets": len(lops),
        "without_position": float(np.mean(lops[:, 4] == 0)),
        "heard": [float(np.mean(~np.isnan(lops[:, i]))) for i in (1, 2, 3)],
    }


def _plot(packets: list[tuple[int, float, float, float, bool]], ax: Any, t0: float) -> None:
    lops = np.array(packets, dtype=float)
    times = (lops[:, 0] - t0) / 1000.0
    for i in range(3):
        ax.plot(times, lops[:, i + 1], ".", ms=2, label=f"receiver {i + 1}")
    lost = lops[:, 4] == 0
    if lost.any():
        ax.plot(times[lost], np.zeros(int(lost.sum())), "|", color="tab:red", ms=8,
                label=f"no position ({lost.mean():.0%} of {len(lops)} packets)")  # fmt: skip
    ax.set_xlabel("time [s] (on arrival)")
    ax.set_ylabel("distance [mm]")
    ax.set_title("LOPS: distances to the three receivers (nothing heard not drawn)")
    ax.legend(loc="upper right", fontsize=7, markerscale=3)


def _synchroniser(context: SyncContext) -> DueSync:
    # table 3.1: the newest distances and position - measured by the sync time
    return DueSync("lops", context.config["lops"]["delay_ms"])


LOPS = register(
    Sensor(
        name="lops",
        letter="L",
        title="LOPS",
        rank=70,
        synchroniser=_synchroniser,
        settings=sensor_settings(log_position=True),
        sets=("darmstadt",),
        raw=_values,
        synchronised=lambda p: _values(p) and fields(count=integer)(p),
        text=_text,
        seed_text=lambda kind, v, context: _text(kind, v),  # appendix B's LOPS lines are ours
        position=_position,
        dat=_dat,
        position_name="LOPS",
        colour="tab:orange",
        analysis=Analysis(_collect, _summary, _plot, "lops.png", (9.0, 5.0)),
    )
)
