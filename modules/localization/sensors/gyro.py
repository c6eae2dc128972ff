"""The gyroscope (seed §3.2, §6.2.3; Darmstadt): ``gyro.data``'s rate and summed angle.

Synchronised as table 3.1's mean of the rates since the last sync and the turn they make, from
the difference of the summed angle between two sync times (:class:`GyroSync`). Logged as ``G``:
``G R`` the rate and its state, ``G C`` the mean rate, the turn and the count; in the seed's text
``G R`` is the angle of one 20.48 ms sample and ``G C`` the turn of the period (figure B.3), the
turn is table B.8's Gyroskop column. Its position ``G`` is the heading by summing its turns (the
core's), ``gyro.png`` its raw and synchronised rates. Its correction of the filter (its summed
angle as a heading, at rest and on straight legs, with the offset the filter learns) is the core's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from modules.localization.records import fields, integer, number
from modules.localization.sensors.base import Analysis, Record, Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import SummedSync

#: the gyroscope's sample period (seed §3.2): the seed logged a rate as the angle of one sample
GYRO_SAMPLE_S = 0.02048
COLOUR = "tab:olive"


class GyroSync(SummedSync):
    """Table 3.1's mean of the gyroscope's rates: ``rate`` (rad/s) and the ``turn`` (rad) it
    makes, from the gyro module's summed angle (``angle_mrad``: ω·T of every raw value)."""

    sensor = "gyro"
    field, scale = "angle_mrad", 0.001
    running_state = 2  # gyro_state RUNNING
    amount_key, rate_key = "turn", "rate"

    def track_change(self, older: tuple[float, float, float], newer: tuple[float, float, float]) -> float:
        return newer[2] - older[2]


def _text(kind: str, v: dict[str, Any]) -> str:
    if kind == "R":
        return f"{float(v['rate_urad_s']) / 1e6:15.12f} {v.get('state', 2)}"
    return f"{float(v['rate']):15.12f} {float(v['turn']):15.12f} {v['count']}"


def _seed_text(kind: str, v: dict[str, Any], context: Any) -> str:
    """The seed's "Drehrate": the angle of one sample; ... and the angle of the period (figure
    B.3's sums)."""
    if kind == "R":
        return f"{float(v['rate_urad_s']) / 1e6 * GYRO_SAMPLE_S:15.12f}"
    return f"{float(v['turn']):15.12f} {v['count']}"


def _position(core: Any, record: dict[str, Any] | None) -> dict[str, Any] | None:
    """The heading by summing the gyroscope's turns from the start pose's (the core keeps it)."""
    if record is None or core.gyro_heading is None:
        return None
    return {"x": 0.0, "y": 0.0, "psi": core.gyro_heading, "valid": [False, False, True]}


def _dat(p: dict[str, Any] | None) -> str:
    """Table B.8's Gyroskop: the turn of the period (rad), as the seed's ``G C``."""
    return f"{float(p['turn']):15.12f}" if p is not None else f"{0:15d}"


# ---------------------------------------------------------------------------------------------
# the analyser's gyroscope module (seed §9.2, table B.9 Gyroskop)


def _collect(records: list[Record]) -> dict[str, list[tuple[int, float]]] | None:
    """The raw rates and the synchronised mean rates (stamp, rad/s); None without raw rates."""
    raw = [
        (stamp, float(p["v"]["rate_urad_s"]) / 1e6)
        for stamp, kind, p in records
        if kind == "R" and "rate_urad_s" in p.get("v", {})
    ]
    synced = [(stamp, float(p["rate"])) for stamp, kind, p in records if kind == "C"]
    return {"raw": raw, "sync": synced} if raw else None


def _summary(data: dict[str, list[tuple[int, float]]]) -> dict[str, Any]:
    """At rest the seed's figure 10.2: one bit of noise around the zero point."""
    rates = np.degrees(np.array([r for _, r in data["raw"]], dtype=float))
    return {
        "samples": len(rates),
        "mean_rate_deg_s": float(rates.mean()),
        "sd_rate_deg_s": float(rates.std()),
    }


def _plot(data: dict[str, list[tuple[int, float]]], ax: Any, t0: float) -> None:
    raw = np.array(data["raw"], dtype=float)
    ax.plot((raw[:, 0] - t0) / 1000.0, np.degrees(raw[:, 1]), ".", ms=1.5, color=COLOUR,
            label="raw (the newest sample a token visit carried)")  # fmt: skip
    if data["sync"]:
        synced = np.array(data["sync"], dtype=float)
        ax.plot((synced[:, 0] - t0) / 1000.0, np.degrees(synced[:, 1]), lw=0.8, color="black",
                label="synchronised (mean of every rate since the last synchronisation)")  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel("rate [°/s, ccw]")
    ax.set_title("gyroscope: rates")
    ax.legend(loc="best", fontsize=8)


def _synchroniser(context: SyncContext) -> GyroSync:
    return GyroSync(context.track)


GYRO = register(
    Sensor(
        name="gyro",
        letter="G",
        title="gyroscope",
        rank=20,
        synchroniser=_synchroniser,
        channel="gyro.data",
        value_fields=("rate_urad_s", "angle_mrad", "raw", "state"),
        settings=sensor_settings(log_position=True, filter=True),
        sets=("darmstadt",),
        raw=fields(rate_urad_s=number, angle_mrad=number),
        synchronised=fields(rate=number, turn=number, count=integer),
        text=_text,
        seed_text=_seed_text,
        position=_position,
        dat=_dat,
        csv_columns=("gyro_rad_s",),
        csv=lambda p: {"gyro_rad_s": p["rate"]},
        position_name="gyroscope",
        colour=COLOUR,
        pose_topic="/robot/pose/gyroscope",
        analysis=Analysis(_collect, _summary, _plot, "gyro.png", (9.0, 4.0)),
    )
)
