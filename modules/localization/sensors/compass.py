"""The magnetic compass (ours: the Hamburg robot's): ``compass.data``'s heading, synchronised as
the newest heading or the circular mean, each carried to the sync time along the odometry track
(:class:`~modules.localization.sync.CompassSync`). Its correction of the filter (the heading plus
the estimated compass offset, not while turning) is the core's; its position ``M`` is the heading.
"""

from __future__ import annotations

import math
from typing import Any

from modules.localization.records import fields, integer, num, number
from modules.localization.sensors.base import Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import CompassSync


def _synchroniser(context: SyncContext) -> CompassSync:
    settings = context.config["filter"]["compass"]
    return CompassSync(
        context.track,
        settings["mode"],
        settings["north_deg"],
        context.built["odometry"],  # when the motors started or stopped: their field settles
        settings["settle_ms"],
    )


def _text(kind: str, v: dict[str, Any]) -> str:
    if kind == "R":
        return f"{num(v['heading_cdeg'], 6)} {v.get('state', 1)}"
    return f"{num(v['heading'], 15, 12)} {v['count']}"


def _seed_text(kind: str, v: dict[str, Any], context: Any) -> str:
    """Ours: the compass's heading in the gyroscope's format (rad)."""
    if kind == "R":
        return f"{math.radians(float(v['heading_cdeg']) / 100.0):15.12f}"
    return f"{float(v['heading']):15.12f} {v['count']}"


def _position(core: Any, record: dict[str, Any] | None) -> dict[str, Any] | None:
    if record is None:
        return None
    return {"x": 0.0, "y": 0.0, "psi": record["heading"], "valid": [False, False, True]}


COMPASS = register(
    Sensor(
        name="compass",
        letter="M",
        title="compass",
        rank=10,
        synchroniser=_synchroniser,
        channel="compass.data",
        seq_field="sample",
        value_fields=("heading_cdeg", "state"),
        settings=sensor_settings(use=True, log_position=True, filter=True),
        raw=fields(heading_cdeg=number),
        synchronised=fields(heading=number, count=integer),
        text=_text,
        seed_text=_seed_text,
        position=_position,
        csv_columns=("compass_rad",),
        csv=lambda p: {"compass_rad": p["heading"]},
        position_name="compass",
        colour="tab:green",
        pose_topic="/robot/pose/compass",
    )
)
