"""The world's ground truth (ours): the simulator's pose, fed over Zenoh (``world/truth``, not a
data channel), synchronised as the pose at the sync time (:class:`~modules.localization.sync.TruthSync`
on the period trigger's grid, else the newest). Logged as ``T``, a reference for scoring and plots
only — never fused (``sensors.truth.filter`` must stay false); the analyser judges every other
position by its raw samples.
"""

from __future__ import annotations

from typing import Any

from modules.localization.records import fields, integer, num, number, seed_position
from modules.localization.sensors.base import Fail, Sensor, SyncContext, register, sensor_settings
from modules.localization.sync import NewestSync, TruthSync


def _synchroniser(context: SyncContext) -> TruthSync | NewestSync:
    # on the grid a sync is stamped before the newest samples: the truth is interpolated there
    return TruthSync() if context.on_grid else NewestSync("truth")


def _check(config: dict[str, Any], fail: Fail) -> None:
    if config["sensors"]["truth"]["filter"]:
        raise fail(
            ("sensors", "truth", "filter"), "the ground truth is a reference only, never fed to the filter"
        )


def _text(kind: str, v: dict[str, Any]) -> str:
    return f"{num(v['x'])} {num(v['y'])} {num(v['theta'], 8, 5)}" + (f" {v['count']}" if kind == "C" else "")


def _seed_text(kind: str, v: dict[str, Any], context: Any) -> str:
    """A position as table B.7 writes one."""
    body = seed_position({"x": v["x"], "y": v["y"], "psi": v["theta"]})
    return body + (f" {v['count']}" if kind == "C" else "")


def _position(core: Any, record: dict[str, Any] | None) -> dict[str, Any] | None:
    if record is None:
        return None
    return {"x": record["x"], "y": record["y"], "psi": record["theta"], "valid": [True, True, True]}


TRUTH = register(
    Sensor(
        name="truth",
        letter="T",
        title="truth",
        rank=60,
        synchroniser=_synchroniser,
        settings=sensor_settings(use=True, log_position=True),
        check_settings=_check,
        raw=fields(x=number, y=number, theta=number),
        synchronised=fields(x=number, y=number, theta=number, count=integer),
        text=_text,
        seed_text=_seed_text,
        position=_position,
        position_name="truth",
        colour="black",
        pose_topic="/robot/pose/true",
    )
)
