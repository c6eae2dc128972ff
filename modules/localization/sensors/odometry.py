"""Odometry (seed §3.1): the motor's cumulative half-step counters in ``motor.data``, synchronised
as the sum of the step increments since the last sync (:class:`~modules.localization.sync.OdometrySync`).

Built in and first (rank 0): its synchroniser drives the odometry track every other one carries
its samples along, and the core's dead reckoning and the EKF's prediction run on its sums — that
fusion stays in :class:`~modules.localization.localizer.LocalizationCore`. Its position ``O`` is
the core's dead reckoning.
"""

from __future__ import annotations

from typing import Any

from modules.localization.records import fields, integer, num, number, seed_int
from modules.localization.sensors.base import Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import OdometrySync


def _synchroniser(context: SyncContext) -> OdometrySync:
    # the counters the start pose belongs to: (0, 0), or the first sample's (the pose from the motor)
    from_motor = context.config["filter"]["initial_pose"] == "motor"
    return OdometrySync(context.track, None if from_motor else (0, 0), split_at_sync=context.on_grid)


def _raw(values: Any) -> bool:
    """Steps, and the motor's dead-reckoned pose with all three fields when it is there."""
    steps = fields(steps_left=integer, steps_right=integer)(values)
    pose = fields(x_mm=integer, y_mm=integer, angle_cdeg=integer)
    return steps and ("x_mm" not in values or pose(values))


def _text(kind: str, v: dict[str, Any]) -> str:
    if kind == "R":
        return f"{num(v['steps_left'])} {num(v['steps_right'])}"
    return f"{num(v['dl'])} {num(v['dr'])} {v['count']}"


def _seed_text(kind: str, v: dict[str, Any], context: Any) -> str:
    """Figure B.3's ``O R`` (the counters) and ``O C`` (the increments and the sample count)."""
    if kind == "R":
        return f"{seed_int(v['steps_left'], 6)} {seed_int(v['steps_right'], 6)}"
    return f"{seed_int(v['dl'], 6)} {seed_int(v['dr'], 6)} {v['count']}"


def _position(core: Any, record: dict[str, Any] | None) -> dict[str, Any] | None:
    """The core's dead reckoning, whenever it has one."""
    if core.dead_reckoning is None:
        return None
    x, y, psi = core.dead_reckoning
    return {"x": x, "y": y, "psi": psi, "valid": [True, True, True]}


def _dat(p: dict[str, Any] | None) -> str:
    """Table B.8's Enkoder links and rechts: the increments of the period."""
    if p is None:
        return f"{0:8d} {0:8d}"
    return f"{seed_int(p['dl'], 8)} {seed_int(p['dr'], 8)}"


ODOMETRY = register(
    Sensor(
        name="odometry",
        letter="O",
        title="odometry",
        rank=0,
        synchroniser=_synchroniser,
        channel="motor.data",
        value_fields=("steps_left", "steps_right", "x_mm", "y_mm", "angle_cdeg", "state"),
        settings=sensor_settings(use=True, log_position=True, filter=True),
        raw=_raw,
        synchronised=fields(dl=number, dr=number, count=integer),
        text=_text,
        seed_text=_seed_text,
        position=_position,
        dat=_dat,
        csv_columns=("steps_left", "steps_right"),
        csv=lambda p: {"steps_left": p["dl"], "steps_right": p["dr"]},
        position_name="dead reckoning",
        colour="tab:red",
        pose_topic="/robot/pose/odometry",
    )
)
